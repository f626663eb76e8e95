"""Counter-based random numbers for parallel kernels.

Each draw is a pure function of (seed, stream, particle, step), so results are identical
whatever the number of threads and whatever the order in which particles are processed.
The mixer is SplitMix64 (Steele, Lea & Flood 2014) applied to a combined counter; its
output passes BigCrush when used this way for independent counters.
"""

import numba as nb
import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_P1 = np.uint64(0xD1B54A32D192ED03)
_P2 = np.uint64(0xAEF17502108EF2D9)
_P3 = np.uint64(0x8CB92BA72F3D8DD7)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0  # 2**-53


@nb.njit(cache=True, inline="always")
def _mix64(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@nb.njit(cache=True, inline="always")
def uniform(seed, stream, particle, step):
    """A uniform double in [0, 1) determined by its four integer coordinates.

    The same four integers always give the same number, whichever thread asks and in
    whichever order, which makes every Monte Carlo run reproducible bit for bit.

    Parameters
    ----------
    seed : int
        The run's seed (non-negative, taken as uint64).
    stream : int
        Which kind of draw (e.g. next state, x or y placement, pass direction), so that
        the draws of one particle and step are independent of one another.
    particle : int
        Index of the particle.
    step : int
        Index of the step (lag) of the run.

    Returns
    -------
    float
        A number u with 0 <= u < 1, on a grid of 2**-53.

    References
    ----------
    G. L. Steele, D. Lea and C. H. Flood, "Fast splittable pseudorandom number
    generators", OOPSLA 2014, doi:10.1145/2660193.2660195 (the SplitMix64 mixer).
    """
    z = _mix64(np.uint64(seed) * _GOLDEN + np.uint64(stream) * _P1)
    z = _mix64(z ^ (np.uint64(particle) * _P2))
    z = _mix64(z ^ (np.uint64(step) * _P3 + _GOLDEN))
    return float(z >> _S11) * _INV53
