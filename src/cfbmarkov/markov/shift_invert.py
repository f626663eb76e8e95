"""The Krylov space of (I - Q^T)^-1 for the exact RTD's tail closure (shift and invert at 1).

The tail of a riser's RTD decays as the eigenvalues of Q nearest 1 (moduli 0.9986, 0.9981,
0.9973, ... on a paper-scale 3 m/s model's 33 lap-deficit levels): close together, so a
Krylov space of Q itself (:func:`cfbmarkov.markov.tail_closure.arnoldi_levels`) separates
them only after the propagation has let the faster modes die out, thousands of lags in. The
space of B = (I - A)^-1, A = Q^T acting on columns, maps them to 1 / (1 - lambda) (700,
530, 370, ...), far apart: Arnoldi on B finds them in a few tens of steps from the mass left
hundreds of lags earlier (Saad, Numerical Methods for Large Eigenvalue Problems, 2nd ed.,
SIAM (2011), Sec. 9.4: shift-and-invert). Each step is one solve with the sparse LU of
I - Q on the live (level, state) pairs, factored once per RTD in the levels' natural order
(block tridiagonal: its fill stays within the envelope, which decides whether the LU is
worth its cost, :data:`FILL_LIMIT`).

From B V_m = V_m H_m + h q_(m+1) e_m^T, multiplied by I - A:

    A V_m = V_m T + u c^T,   T = I - H_m^-1,   u = (I - A) q_(m+1),   c^T = h e_m^T H_m^-1,

a rank-one residual, like the Arnoldi relation of A itself; the tail then follows from T as
it does from the Hessenberg matrix (:mod:`cfbmarkov.markov.tail_closure`). The relation is
not taken on trust: with the computed T, c and u, E = A V_m - V_m T - u c^T is formed
explicitly and its column norms (plus the rounding of forming it) join the bound, so
neither the LU's accuracy nor the Arnoldi's orthogonality has to be assumed.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from cfbmarkov._blas import one_blas_thread

#: the shift-and-invert closure is used where the envelope (profile) of I - Q on the live
#: pairs, in the levels' natural order, which holds its LU's fill, is at most this many
#: times the propagation's multiply-adds a lag: 1.8 on the paper-scale 3 m/s models of
#: 228 states (a solve costs about 7 lags, the LU about 230), 5.5 on the 1824-state
#: velocity memory at 3 m/s (a solve about 28 lags, the LU about 400: it closes at lag 512
#: instead of 4096); a 1596-state previous-cell memory's envelope, 30 times its lag, keeps
#: :func:`~cfbmarkov.markov.tail_closure.arnoldi_levels`
FILL_LIMIT = 8

#: the most memory the LU may take, counted as 12 bytes (a value and an index) an entry of
#: the envelope (the 1824-state velocity memory's: 17.6 million entries, 212 MB)
LU_BYTES = 512 * 2 ** 20


@nb.njit(cache=True)
def envelope(indptr, indices):
    """The envelope of a square sparse matrix given as CSC arrays: the entries between each
    column's first row and the diagonal and between each row's first column and the
    diagonal, the diagonal once (Numba kernel). An LU without pivoting fills in only
    there (George and Liu, Computer Solution of Large Sparse Positive Definite Systems,
    Prentice-Hall (1981), Ch. 4)."""
    n = indptr.size - 1
    first_row = np.arange(n)
    first_column = np.arange(n)
    for j in range(n):
        for q in range(indptr[j], indptr[j + 1]):
            i = indices[q]
            if i < first_row[j]:
                first_row[j] = i
            if j < first_column[i]:
                first_column[i] = j
    total = n
    for j in range(n):
        total += (j - first_row[j]) + (j - first_column[j])
    return total


class LevelInverse:
    """I - Q on the live (level, state) pairs, factored: solves with I - Q^T.

    Parameters
    ----------
    indptr, indices, data : ndarray
        I - Q as CSC arrays, the pairs numbered level by level among the live ones
        (:func:`cfbmarkov.markov.first_passage._level_system`); read as CSR they are
        I - Q^T = I - A.
    live : ndarray of bool, shape (S, L)
        The live pairs.
    """

    def __init__(self, indptr, indices, data, live):
        n = indptr.size - 1
        self.indptr, self.indices, self.data = indptr, indices, data
        levels_first = np.flatnonzero(live.T.ravel())        # level-major numbering
        self.pair_state = (levels_first % live.shape[0]).astype(np.int64)
        self.pair_level = (levels_first // live.shape[0]).astype(np.int64)
        self.row_terms = int(np.diff(indptr).max(initial=0))
        self.factors = splu(sp.csc_matrix((data, indices, indptr), shape=(n, n)),
                            permc_spec="NATURAL")

    @property
    def size(self) -> int:
        return self.indptr.size - 1

    def solve(self, x: np.ndarray) -> np.ndarray:
        """(I - A)^-1 x."""
        return self.factors.solve(x, trans="T")


def level_inverse(indptr, indices, data, live, work: int) -> LevelInverse | None:
    """The factored I - Q where its envelope is at most :data:`FILL_LIMIT` times ``work``
    (the propagation's multiply-adds a lag) and within :data:`LU_BYTES`, else None.

    Parameters
    ----------
    indptr, indices, data : ndarray
        I - Q on the live pairs as CSC arrays (:class:`LevelInverse`).
    live : ndarray of bool, shape (S, L)
    work : int

    Returns
    -------
    LevelInverse or None
        None also where SuperLU finds I - Q singular (states that leak less than the
        round-off: the space of Q^T is used there).
    """
    filled = envelope(indptr, indices)
    if filled > FILL_LIMIT * work or 12 * filled > LU_BYTES:
        return None
    try:
        return LevelInverse(indptr, indices, data, live)
    except RuntimeError:     # singular in floating point (a closed loop that leaks 1e-17)
        return None


@nb.njit(cache=True)
def gather_pairs(v, pair_state, pair_level):
    """The live pairs' entries of ``v`` [S, L], level by level."""
    out = np.empty(pair_state.size)
    for p in range(pair_state.size):
        out[p] = v[pair_state[p], pair_level[p]]
    return out


@nb.njit(cache=True)
def dot(x, y):
    """sum x * y over 1-D arrays, in four interleaved partial sums (a fixed order that the
    compiler can vectorise: the same bits on any thread count)."""
    size = x.size
    s0 = s1 = s2 = s3 = 0.0
    whole = size - size % 4
    for i in range(0, whole, 4):
        s0 += x[i] * y[i]
        s1 += x[i + 1] * y[i + 1]
        s2 += x[i + 2] * y[i + 2]
        s3 += x[i + 3] * y[i + 3]
    for i in range(whole, size):
        s0 += x[i] * y[i]
    return (s0 + s1) + (s2 + s3)


def orthogonalise(basis, j, w, hessenberg):
    """Classical Gram-Schmidt, twice, of ``w`` against basis[0 .. j] (two BLAS products a
    sweep, on the caller's one BLAS thread); the coefficients are added to
    hessenberg[:j + 1, j], ``w`` is overwritten; returns |w|_2 after."""
    rows = basis[:j + 1]
    for _sweep in range(2):
        h = rows @ w
        hessenberg[:j + 1, j] += h
        w -= h @ rows
    return math.sqrt(dot(w, w))


@nb.njit(cache=True)
def _identity_less_a(indptr, indices, data, x, out):
    """out = (I - A) x, (I - A) as the CSR arrays of I - Q^T."""
    for r in range(indptr.size - 1):
        acc = 0.0
        for q in range(indptr[r], indptr[r + 1]):
            acc += data[q] * x[indices[q]]
        out[r] = acc


def relation_error(indptr, indices, data, basis, dim, small, residual_direction,
                   residual_vector):
    """The columns of E = A V - V T - u c^T (module docstring), as 1-norms, and beside each
    the 1-norm of the terms it sums (for the bound on the rounding of forming it).

    ``basis`` [m + 1, n] (V's columns as rows), ``small`` T [dim, dim],
    ``residual_direction`` c [dim], ``residual_vector`` u [n]. A q_j is formed as
    q_j - (I - A) q_j, (I - A) V by one sparse product and V T by one BLAS product (on the
    caller's one BLAS thread): each entry of E a sum of the row's terms of I - A, the dim
    of V T, u c^T and q_j, whatever their order, as the bound counts them.
    Returns (norms, magnitudes), float64 [dim] each."""
    n = basis.shape[1]
    rows = basis[:dim]
    identity_less_a = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    error = (rows - np.asarray(identity_less_a @ rows.T).T
             - residual_direction[:, None] * residual_vector[None, :] - small.T @ rows)
    norms = np.abs(error).sum(axis=1)
    one_norms = np.abs(rows).sum(axis=1)
    magnitudes = (3.0 * one_norms + np.abs(residual_vector).sum() * np.abs(residual_direction)
                  + np.abs(small).T @ one_norms)
    return norms, magnitudes


@nb.njit(cache=True)
def pair_functionals(basis, dim, pair_state, pair_level, levels, exit_probability,
                     down_probability):
    """The tail's functionals on the basis (rows over its first ``dim`` vectors): exits
    (from level 0), passes down from each level, the mass left."""
    exits = np.zeros(dim)
    falls = np.zeros((levels, dim))
    mass = np.zeros(dim)
    for k in range(dim):
        for p in range(pair_state.size):
            x = basis[k, p]
            i = pair_state[p]
            g = pair_level[p]
            if g == 0:
                exits[k] += exit_probability[i] * x
            falls[g, k] += down_probability[i] * x
            mass[k] += x
    return exits, falls, mass


class InverseArnoldi:
    """The Arnoldi process of (I - A)^-1 from a start vector, extended on demand.

    Parameters
    ----------
    inverse : LevelInverse
    start : ndarray of float64, shape (n,)
        The live pairs' mass, level by level (not all zero).
    dimension : int
        The largest m it may be extended to.
    """

    def __init__(self, inverse: LevelInverse, start: np.ndarray, dimension: int):
        self.inverse = inverse
        self.basis = np.zeros((dimension + 1, start.size))
        self.hessenberg = np.zeros((dimension + 1, dimension))
        self.norm = math.sqrt(dot(start, start))
        self.basis[0] = start / self.norm
        self.dim = 0                  # the columns of H formed
        self.invariant = False        # the space is invariant: no residual
        self.failed = False           # a solve gave a number that is not finite

    def extend(self, dimension: int) -> None:
        """Extend the basis to ``dimension`` vectors (fewer where the space is invariant),
        on one BLAS thread (the same bits on any thread count)."""
        with one_blas_thread():
            self._extend(dimension)

    def _extend(self, dimension: int) -> None:
        for j in range(self.dim, min(dimension, self.hessenberg.shape[1])):
            if self.invariant or self.failed:
                return
            w = self.inverse.solve(self.basis[j])
            if not np.all(np.isfinite(w)):
                self.failed = True
                return
            next_norm = orthogonalise(self.basis, j, w, self.hessenberg)
            self.dim = j + 1
            if next_norm == 0.0:
                self.invariant = True
                return
            self.hessenberg[j + 1, j] = next_norm
            self.basis[j + 1] = w / next_norm

    def relation(self, with_error: bool) -> dict | None:
        """The relation A V_m = V_m T + u c^T + E at the dimension reached (module
        docstring).

        Parameters
        ----------
        with_error : bool
            Also form E's columns (:func:`relation_error`; zeros without).

        Returns
        -------
        dict or None
            ``dim``, ``norm`` (|start|_2), ``small`` T [dim, dim], ``direction`` c [dim],
            ``residual`` ||u||_1, ``error_norms`` and ``magnitudes`` [dim]; None where a
            solve failed, H_m is singular or a number is not finite (no closure).
        """
        dim = self.dim
        if self.failed or dim == 0:
            return None
        n = self.basis.shape[1]
        h = np.ascontiguousarray(self.hessenberg[:dim, :dim])
        try:
            h_inverse = np.linalg.inv(h)
        except np.linalg.LinAlgError:
            return None
        small = np.ascontiguousarray(np.identity(dim) - h_inverse)
        residual_vector = np.zeros(n)
        direction = np.zeros(dim)
        if not self.invariant:
            direction = np.ascontiguousarray(self.hessenberg[dim, dim - 1] * h_inverse[dim - 1])
            inverse = self.inverse
            _identity_less_a(inverse.indptr, inverse.indices, inverse.data, self.basis[dim],
                             residual_vector)
        if not (np.all(np.isfinite(small)) and np.all(np.isfinite(direction))):
            return None
        if with_error:
            error_norms, magnitudes = relation_error(
                self.inverse.indptr, self.inverse.indices, self.inverse.data, self.basis, dim,
                small, direction, residual_vector)
        else:
            error_norms = magnitudes = np.zeros(dim)
        return {"dim": dim, "norm": self.norm, "small": small, "direction": direction,
                "residual": float(np.abs(residual_vector).sum()),
                "error_norms": error_norms, "magnitudes": magnitudes}
