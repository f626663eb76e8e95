"""Between the caller's particle order and the engine's cell order (numba): the external
force scattered into cell order, the inverse permutation, and positions or velocities
gathered back into the caller's order (see :mod:`~cfbmarkov.simulate.dem.layout`).
"""

from __future__ import annotations

from numba import njit, prange


@njit(parallel=True, cache=True)
def scatter_external(ext, ids, aux):
    """``aux[k, 2:4] = ext[ids[k]]``: external force (N, (N, 2)) from the caller's order to
    cell order."""
    N = ids.shape[0]
    for k in prange(N):
        i = ids[k]
        aux[k, 2] = ext[i, 0]
        aux[k, 3] = ext[i, 1]


@njit(cache=True)
def internal_index(ids, where):
    """``where[ids[k]] = k``: the cell-order index of each of the caller's particles (the
    inverse of the permutation ``ids``).

    Serial: threads scattering to random places of one array write to the same cache lines
    (four int64 a line) and pass them back and forth; one thread is faster than two here.
    """
    for k in range(ids.shape[0]):
        where[ids[k]] = k


@njit(parallel=True, cache=True)
def gather_pairs(values, where, out):
    """``out[i] = values[where[i], 0:2]``: two columns (positions, velocities) from cell
    order to the caller's order (``where``: :func:`internal_index`).

    A gather: each thread writes its own contiguous rows of ``out`` and reads at random.
    The scatter ``out[ids[k]] = values[k]`` it replaces had both threads write at random
    into the same cache lines, and took 110 us on two threads for 27000 particles against
    49 us on one (docs/performance.md).
    """
    for i in prange(where.shape[0]):
        k = where[i]
        out[i, 0] = values[k, 0]
        out[i, 1] = values[k, 1]


@njit(parallel=True, cache=True)
def clear_external(aux):
    """Zero the external force columns of ``aux`` (N, 4)."""
    N = aux.shape[0]
    for k in prange(N):
        aux[k, 2] = 0.0
        aux[k, 3] = 0.0
