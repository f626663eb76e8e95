"""Banded Cholesky factorisation for the pressure equation (numba kernels).

The pressure matrix of an nx x ny grid that is periodic in y is block-tridiagonal with
corner blocks. Numbering the cell rows in the *folded* order j = 0, ny-1, 1, ny-2, 2, ...
puts every y-neighbour (the periodic one included) at most two rows away, so the matrix
is banded with half-bandwidth 2 nx and a plain banded Cholesky (no pivoting: the matrix is
symmetric positive definite once one cell is pinned) solves it. For 9 x 95 cells this is
855 unknowns, half-bandwidth 18: about 6e-5 s per factorisation on one core.

Storage is by columns of the lower triangle: ``band[k, o] = A[k + o, k]`` for o = 0..b.
"""

from __future__ import annotations

import numba as nb
import numpy as np


def folded_row_order(ny: int) -> np.ndarray:
    """Position of each cell row j in the folded order (shape (ny,), int64)."""
    j = np.arange(ny)
    return np.where(2 * j <= ny - 1, 2 * j, 2 * (ny - 1 - j) + 1).astype(np.int64)


def cell_numbering(nx: int, ny: int) -> np.ndarray:
    """Unknown number of cell (i, j): folded_row_order(ny)[j] * nx + i, shape (nx, ny)."""
    pos = folded_row_order(ny)
    return (pos[None, :] * nx + np.arange(nx)[:, None]).astype(np.int64)


@nb.njit(cache=True)
def band_cholesky(band, invdiag):
    """In-place Cholesky L L^T of the SPD band matrix (right-looking, column band storage).

    Returns -1 on success, or the index of the first non-positive pivot.
    """
    n, bp1 = band.shape
    b = bp1 - 1
    for k in range(n):
        s = band[k, 0]
        if not s > 0.0:  # also catches NaN
            return k
        d = np.sqrt(s)
        band[k, 0] = d
        r = 1.0 / d
        invdiag[k] = r
        w = b if k + b < n else n - 1 - k
        for i in range(1, w + 1):
            band[k, i] *= r
        for j in range(1, w + 1):
            ljk = band[k, j]
            if ljk != 0.0:
                kj = k + j
                for i in range(j, w + 1):
                    band[kj, i - j] -= band[k, i] * ljk
    return -1


@nb.njit(cache=True)
def band_solve2(band, invdiag, r1, r2):
    """Solve L L^T x = r for two right-hand sides in place (after :func:`band_cholesky`)."""
    n, bp1 = band.shape
    b = bp1 - 1
    for k in range(n):
        y1 = r1[k] * invdiag[k]
        y2 = r2[k] * invdiag[k]
        r1[k] = y1
        r2[k] = y2
        w = b if k + b < n else n - 1 - k
        for i in range(1, w + 1):
            lik = band[k, i]
            r1[k + i] -= lik * y1
            r2[k + i] -= lik * y2
    for k in range(n - 1, -1, -1):
        w = b if k + b < n else n - 1 - k
        s1 = r1[k]
        s2 = r2[k]
        for i in range(1, w + 1):
            lik = band[k, i]
            s1 -= lik * r1[k + i]
            s2 -= lik * r2[k + i]
        r1[k] = s1 * invdiag[k]
        r2[k] = s2 * invdiag[k]
