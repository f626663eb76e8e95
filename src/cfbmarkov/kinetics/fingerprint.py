"""A property's definition on a state space at a lag, as one short text: what a prediction
stores beside ``/properties/NAME`` so that a later ``compare --kinetics`` can tell whether
the stored values are those of its own kinetics (``docs/kinetics-reference.md``, Stored
values and their definition).

The fingerprint is ``sha256:`` and the SHA-256 (hex) of, in order:

1. a header, UTF-8 JSON with sorted keys: the method name (:data:`FINGERPRINT_METHOD`),
   the law's key, the start rule, the entry value, the lag (s), the number of states and
   the direction residences are counted in (``entries``: ``up``, or ``down`` for a model of
   a net downflow, whose entries are passes down through the bottom) (floats written as
   ``repr`` of the value quantised as below);
2. for a linear law, the per-state rate k_s (1/s) and target v_inf,s; for a custom law its
   function's name and definition (the SHA-256 of its source text, or of its code object
   where Python has no source for it, :func:`function_digest`), its RK4 sub-steps and its
   per-state parameters: each number quantised
   to 40 significant bits of mantissa (:func:`quantised`; about 12 decimal digits) and
   written as little-endian int64 mantissas then int32 exponents.

Hashing the rates and targets rather than the lag's affine maps (exp(-k lag) ...) and
quantising them keeps the fingerprint the same where two machines' exponentials or two
builds' arithmetic differ in the last bits, while any change of a rate, a target, the law,
the start rule, the entry value, the direction or the lag beyond 1e-12 relative changes it.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np

#: the name of the fingerprint's recipe, stored with it (module docstring)
FINGERPRINT_METHOD = "cfbmarkov-kinetics-2"
#: mantissa bits kept before hashing
MANTISSA_BITS = 40


def quantised(values) -> tuple[np.ndarray, np.ndarray]:
    """Numbers reduced to :data:`MANTISSA_BITS` bits of mantissa.

    Parameters
    ----------
    values : array_like of float64
        Any shape; NaN and infinities allowed.

    Returns
    -------
    mantissa : ndarray of int64
        round(m 2^40) with values = m 2^e, 0.5 <= |m| < 1 (0 for zero; a NaN is
        -2^62, +inf 2^62 and -inf -2^62 + 1).
    exponent : ndarray of int32
        e (0 for zero and non-finite values).
    """
    x = np.ascontiguousarray(values, dtype=np.float64).ravel()
    finite = np.isfinite(x)
    m, e = np.frexp(np.where(finite, x, 0.0))
    mantissa = np.rint(m * 2.0 ** MANTISSA_BITS).astype(np.int64)
    # a mantissa rounded up to 2^40 is 0.5 * 2^(e + 1): one form for both
    up = np.abs(mantissa) == 2 ** MANTISSA_BITS
    mantissa[up] //= 2
    e = e.astype(np.int32)
    e[up] += 1
    mantissa[np.isnan(x)] = -(2 ** 62)
    mantissa[np.isposinf(x)] = 2 ** 62
    mantissa[np.isneginf(x)] = -(2 ** 62) + 1
    e[~finite] = 0
    return mantissa, e


def _number(value: float) -> str:
    m, e = quantised([value])
    return repr(float(np.ldexp(m[0] / 2.0 ** MANTISSA_BITS, int(e[0]))))


def property_fingerprint(state_kinetics, index: int, lag: float, direction: str = "up") -> str:
    """The fingerprint of property ``index`` of ``state_kinetics`` at ``lag``.

    Parameters
    ----------
    state_kinetics : StateKinetics
        Kinetics resolved on a model's states.
    index : int
        The property's position.
    lag : float
        The lag (s) its Monte Carlo steps by.
    direction : {"up", "down"}, optional
        The model's residence direction (``MarkovModel.flow_direction``): where an
        ``entry`` start resets the value.

    Returns
    -------
    str
        ``sha256:`` and 64 hex digits (module docstring).
    """
    sk = state_kinetics
    law = sk.laws[index]
    linear = bool(sk.linear[index])
    header = {"method": FINGERPRINT_METHOD, "law": law.key, "start": sk.starts[index],
              "initial": _number(float(sk.initial[index])), "lag": _number(float(lag)),
              "states": int(np.shape(sk.rate)[1]), "entries": str(direction)}
    if not linear:
        header["function"] = str(getattr(law.function, "__name__", "?"))
        header["definition"] = function_digest(law.function)
        header["substeps"] = int(law.substeps)
    digest = hashlib.sha256(json.dumps(header, sort_keys=True).encode())
    arrays = ((sk.rate[index], sk.target[index]) if linear
              else (np.asarray(sk.parameters[index], dtype=np.float64),))
    for values in arrays:
        mantissa, exponent = quantised(values)
        digest.update(mantissa.astype("<i8").tobytes())
        digest.update(exponent.astype("<i4").tobytes())
    return "sha256:" + digest.hexdigest()


def kinetics_digest(kinetics) -> str | None:
    """The SHA-256 of a whole kinetics definition as loaded (every property's name, law,
    start rule, entry value and parameters, the per-cell tables' numbers among them): what
    ``reproduce`` records beside a comparison so that a rerun with another kinetics file
    redoes it rather than report the earlier one's results.

    Parameters
    ----------
    kinetics : Kinetics

    Returns
    -------
    str or None
        ``sha256:`` and 64 hex digits; None for a definition that cannot be serialised (a
        custom law's compiled function), which is then never taken as the same.
    """
    import pickle

    try:
        text = pickle.dumps(tuple(kinetics.properties), protocol=4)
    except Exception:       # noqa: BLE001 - a compiled rate function: no stable form
        return None
    return "sha256:" + hashlib.sha256(text).hexdigest()


def function_digest(function) -> str:
    """The SHA-256 (hex) of a rate function's definition: its source text where Python can
    find it (a module, a notebook cell), else its code object's bytecode, constants and
    names; two functions of one name but different bodies differ.

    Parameters
    ----------
    function : numba dispatcher or function
        The rate function (its ``py_func`` where compiled).

    Returns
    -------
    str
    """
    import inspect

    func = getattr(function, "py_func", function)
    try:
        text = inspect.getsource(func).encode()
    except (OSError, TypeError):
        code = getattr(func, "__code__", None)
        text = b"" if code is None else (code.co_code + repr(code.co_consts).encode()
                                         + repr(code.co_names).encode())
    return hashlib.sha256(text).hexdigest()


__all__ = ["FINGERPRINT_METHOD", "MANTISSA_BITS", "function_digest", "kinetics_digest",
           "property_fingerprint",
           "quantised"]
