"""Two rate functions of one name and different bodies (a module, so that Python finds
their source), for the fingerprint test."""

import numba


def _make():
    @numba.njit
    def rate(v, parameters, values):
        return parameters[0] * (1.0 - v)

    first = rate

    @numba.njit
    def rate(v, parameters, values):    # noqa: F811 -- the same name, another body
        return parameters[0] * (1.0 - v) * (1.0 - v)

    return first, rate


FIRST, SECOND = _make()
