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
import warnings

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


#: a level system whose pairs are all live, of at most this many states, is factored by its
#: block structure (:class:`LevelBlocks`) where a solve's dense multiply-adds, S^2 L, are at
#: most :data:`BLOCK_ADVANTAGE` times the envelope SuperLU's solve runs through: LAPACK's
#: dense triangular solves on a few hundred states do about ten times the multiply-adds a
#: second of SuperLU's sparse ones (on the paper-scale 3 m/s mle model, S^2 L is 5.1 times
#: the envelope; a solve took 0.87 ms with SuperLU, 0.4 ms by blocks, and the factoring
#: 23 ms against 3 ms)
BLOCK_STATES = 512
#: see :data:`BLOCK_STATES`
BLOCK_ADVANTAGE = 8


@nb.njit(cache=True, nogil=True)
def _boundary_solve(inverses, lower, upper, right):
    """The block-tridiagonal system on the boundary states (Numba kernel), by the factors
    of :class:`LevelBlocks`: ``right`` [L, r] the right-hand side level by level; returns
    u [L, r]. Forward e_g = c_g + H_g e_(g-1), back u_g = F_g e_g + J_g u_(g+1), the
    blocks given transposed (``lower`` H^T, ``inverses`` F^T, ``upper`` J^T, each
    [L, r, r]) so that each column's terms are added to a whole row at once (in SIMD);
    sums in a fixed order."""
    levels, r = right.shape
    forward = right.copy()
    for g in range(1, levels):
        for b in range(r):
            x = forward[g - 1, b]
            for a in range(r):
                forward[g, a] += lower[g, b, a] * x
    out = np.zeros((levels, r))
    for g in range(levels - 1, -1, -1):
        for b in range(r):
            x = forward[g, b]
            for a in range(r):
                out[g, a] += inverses[g, b, a] * x
        if g < levels - 1:
            for b in range(r):
                x = out[g + 1, b]
                for a in range(r):
                    out[g, a] += upper[g, b, a] * x
    return out


@nb.njit(cache=True, nogil=True)
def _level_blocks(indptr, indices, data, states, levels):
    """I - P_stay^T, P_down^T and P_up^T as dense [S, S] blocks (Numba kernel), read from
    I - Q's CSC arrays (every pair live, numbered g S + i): level 0's diagonal block, the
    block of level 1's columns on level 0's rows (passes down) and of level 0's columns on
    level 1's rows (passes up), transposed. Zeros for the passes where L = 1."""
    stay = np.zeros((states, states))
    down = np.zeros((states, states))
    up = np.zeros((states, states))
    for column in range(min(2, levels) * states):
        j = column % states
        for q in range(indptr[column], indptr[column + 1]):
            row = indices[q]
            if column < states and row < states:
                stay[j, row] = data[q]
            elif column < states and row < 2 * states:
                up[j, row - states] = -data[q]
            elif column >= states and row < states:
                down[j, row] = -data[q]
    return stay, down, up


@nb.njit(cache=True, nogil=True)
def _boundary_factors(below, above, levels):
    """Block Gaussian elimination of the boundary system u_g - G_down u_(g-1) - G_up
    u_(g+1) = c_g (Numba kernel; ``below`` G_down, ``above`` G_up, [r, r]): Schur
    complements D_0 = I, D_g = I - H_g G_up with H_g = G_down D_(g-1)^-1; returns
    (F^T, H^T, J^T), each [L, r, r], F_g = D_g^-1 and J_g = F_g G_up, transposed for
    :func:`_boundary_solve`. Raises numpy's LinAlgError where a D_g is singular."""
    r = below.shape[0]
    inverses = np.zeros((levels, r, r))
    lower = np.zeros((levels, r, r))
    upper = np.zeros((levels, r, r))
    schur = np.identity(r)
    for g in range(levels):
        if g > 0:
            h = below @ inverses[g - 1].T
            lower[g] = h.T
            schur = np.identity(r) - h @ above
        f = np.linalg.inv(schur)
        inverses[g] = f.T
        upper[g] = (f @ above).T
    return inverses, lower, upper


class _BlockSystem:
    """D y_g - B_prev y_(g-1) - B_next y_(g+1) = x_g on L levels, y_(-1) = y_L = 0, D
    given by the LU of D (``trans`` 0) or of D^T (``trans`` 1), its boundary eliminated
    (:class:`LevelBlocks`)."""

    def __init__(self, lu, trans: int, previous, following, levels: int):
        from scipy.linalg import lu_solve

        self._lu_solve, self.lu, self.trans, self.levels = lu_solve, lu, trans, levels
        self.states = previous.shape[0]
        self.boundary = np.flatnonzero(np.any(previous != 0.0, axis=0)
                                       | np.any(following != 0.0, axis=0))
        self.from_previous = lu_solve(lu, previous[:, self.boundary], trans=trans,
                                      check_finite=False)
        self.from_following = lu_solve(lu, following[:, self.boundary], trans=trans,
                                       check_finite=False)
        try:
            self.inverses_t, self.lower_t, self.upper_t = _boundary_factors(
                np.ascontiguousarray(self.from_previous[self.boundary]),
                np.ascontiguousarray(self.from_following[self.boundary]), levels)
        except np.linalg.LinAlgError:
            raise RuntimeError("a Schur complement is singular") from None
        if not all(np.all(np.isfinite(a)) for a in (self.inverses_t, self.lower_t,
                                                    self.upper_t, self.from_previous,
                                                    self.from_following)):
            raise RuntimeError("the block factors are not finite")

    def solve(self, x: np.ndarray) -> np.ndarray:
        s, levels = self.states, self.levels
        t = self._lu_solve(self.lu, x.reshape(levels, s).T, trans=self.trans,
                           check_finite=False)
        if self.boundary.size:
            u = _boundary_solve(self.inverses_t, self.lower_t, self.upper_t,
                                np.ascontiguousarray(t[self.boundary].T))
            t[:, 1:] += self.from_previous @ u[:-1].T
            t[:, :-1] += self.from_following @ u[1:].T
        return np.ascontiguousarray(t.T).ravel()


class LevelBlocks:
    """I - Q on every (level, state) pair factored by its block structure: solves with
    I - Q^T or I - Q (the interface of SuperLU's ``solve(x, trans)``).

    On level g, (I - Q^T) y = x reads

        (I - P_stay^T) y_g - P_down^T y_(g-1) - P_up^T y_(g+1) = x_g,

    with y_(-1) = y_L = 0 (an up pass from level 0 ends the residence, a down pass from the
    deepest level is lost), every level's diagonal block the same. P_down^T and P_up^T
    have non-zero columns only on the r boundary states that pass down or up (41 of 228 on
    the paper-scale 3 m/s mle model). With D = I - P_stay^T factored once (LAPACK's LU),
    t_g = D^-1 x_g and Z = D^-1 [P_down^T, P_up^T] on those columns, y_g = t_g +
    Z_down u_(g-1) + Z_up u_(g+1), where u_g = y_g on the boundary states solves

        u_g - G_down u_(g-1) - G_up u_(g+1) = t_g (on the boundary),   G = Z's boundary rows,

    a block-tridiagonal system of L blocks of r, eliminated once by blocks (block Gaussian
    elimination without pivoting: its matrix is a non-singular M-matrix, I less a
    non-negative matrix of spectral radius below 1, whose Schur complements stay
    M-matrices; Golub and Van Loan, Matrix Computations, 4th ed., Sec. 4.5.4). A solve is
    then one LU solve with L right-hand sides, the boundary system's two sweeps and two
    products of Z. (I - Q) y = x is the same with D^T = I - P_stay (the same LU, solved
    transposed), P_up coupling level g - 1 and P_down level g + 1 (on the states where
    passes land); its boundary is eliminated on the first such solve. The tail closure
    does not take the solves' accuracy on trust (:func:`relation_error`).

    Parameters
    ----------
    indptr, indices, data : ndarray
        I - Q as CSC arrays, the pairs numbered g S + i (every pair live).
    states, levels : int
        S and L.
    trans : {"T", "N"}, optional
        The system whose boundary is eliminated here (I - Q^T or I - Q); the other's is
        on its first solve.

    Raises
    ------
    RuntimeError
        If I - P_stay^T or a Schur complement of ``trans``'s boundary system is singular in
        floating point (a pivot at most S times the machine epsilon of the largest) or not
        finite.
    """

    def __init__(self, indptr, indices, data, states: int, levels: int, trans: str = "T"):
        from scipy.linalg import LinAlgWarning, lu_factor

        s = states
        stay, down, up = _level_blocks(indptr, indices, data, s, levels)
        self.states, self.levels = s, levels
        self._passes = (down, up)
        self._systems = {}
        with one_blas_thread():
            with warnings.catch_warnings():       # a zero pivot: refused just below
                warnings.simplefilter("ignore", LinAlgWarning)
                self.lu = lu_factor(stay, check_finite=False)
            pivots = np.abs(np.diag(self.lu[0]))
            if not (np.all(np.isfinite(pivots))
                    and pivots.min() > s * np.finfo(np.float64).eps * pivots.max()):
                raise RuntimeError("I - P_stay is singular in floating point")
            self._system(trans)         # its boundary's failures are the constructor's

    def _system(self, trans: str) -> _BlockSystem:
        """The system of ``trans`` ("T": I - Q^T, "N": I - Q), its boundary eliminated on
        the first call."""
        if trans not in self._systems:
            down, up = self._passes
            with one_blas_thread():
                if trans == "T":
                    self._systems[trans] = _BlockSystem(self.lu, 0, down, up, self.levels)
                else:
                    self._systems[trans] = _BlockSystem(
                        self.lu, 1, np.ascontiguousarray(up.T), np.ascontiguousarray(down.T),
                        self.levels)
        return self._systems[trans]

    @property
    def boundary(self) -> np.ndarray:
        """The states that pass down or up (int64 [r]), I - Q^T's boundary."""
        return self._system("T").boundary

    def solve(self, x: np.ndarray, trans: str = "T") -> np.ndarray:
        """(I - Q^T)^-1 x (``trans`` "T") or (I - Q)^-1 x ("N"), x level by level [S L]
        (on the caller's BLAS threads).

        Raises
        ------
        RuntimeError
            Where a Schur complement of the other system's boundary (not the
            constructor's ``trans``) is singular or its factors are not finite (on its
            first solve).
        """
        if trans not in ("T", "N"):
            raise ValueError(f"trans is 'T' or 'N', not {trans!r}")
        return self._system(trans).solve(x)


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
    blocks : bool, optional
        Factor it by its block structure (:class:`LevelBlocks`; every pair must be live)
        instead of SuperLU's sparse LU in the levels' natural order.

    Raises
    ------
    RuntimeError
        If I - Q is singular in floating point.
    """

    def __init__(self, indptr, indices, data, live, blocks: bool = False):
        n = indptr.size - 1
        self.indptr, self.indices, self.data = indptr, indices, data
        levels_first = np.flatnonzero(live.T.ravel())        # level-major numbering
        self.pair_state = (levels_first % live.shape[0]).astype(np.int64)
        self.pair_level = (levels_first // live.shape[0]).astype(np.int64)
        self.row_terms = int(np.diff(indptr).max(initial=0))
        if blocks:
            if not live.all():
                raise ValueError("the block factorisation needs every pair live")
            self.factors = LevelBlocks(indptr, indices, data, *live.shape)
        else:
            self.factors = splu(sp.csc_matrix((data, indices, indptr), shape=(n, n)),
                                permc_spec="NATURAL")

    @property
    def size(self) -> int:
        return self.indptr.size - 1

    def solve(self, x: np.ndarray) -> np.ndarray:
        """(I - A)^-1 x."""
        return self.factors.solve(x, trans="T")


def by_blocks(live: np.ndarray, filled: int) -> bool:
    """Whether I - Q on the levels is factored by :class:`LevelBlocks`: every pair live
    (``live`` bool [S, L]), S at most :data:`BLOCK_STATES`, and S^2 L at most
    :data:`BLOCK_ADVANTAGE` times ``filled``, the envelope (:func:`envelope`)."""
    states, levels = live.shape
    return bool(live.all() and states <= BLOCK_STATES
                and states * states * levels <= BLOCK_ADVANTAGE * filled)


def factor_levels(indptr, indices, data, live: np.ndarray, trans: str = "N"):
    """I - Q on the live pairs factored for a few solves with it (``trans`` "N") or with
    I - Q^T ("T") (``solve(x, trans)``, as SuperLU's):
    by :class:`LevelBlocks` where :func:`by_blocks`, else (or where the blocks are singular
    in floating point) by SuperLU in the levels' natural order.

    Parameters
    ----------
    indptr, indices, data : ndarray
        I - Q on the live pairs as CSC arrays (:class:`LevelInverse`).
    live : ndarray of bool, shape (S, L)
    trans : {"N", "T"}, optional

    Returns
    -------
    LevelBlocks or scipy.sparse.linalg.SuperLU

    Raises
    ------
    RuntimeError
        From SuperLU, where I - Q is exactly singular.
    """
    if by_blocks(live, envelope(indptr, indices)):
        try:
            return LevelBlocks(indptr, indices, data, *live.shape, trans=trans)
        except RuntimeError:
            pass
    n = indptr.size - 1
    return splu(sp.csc_matrix((data, indices, indptr), shape=(n, n)), permc_spec="NATURAL")


def level_inverse(indptr, indices, data, live, work: int) -> LevelInverse | None:
    """The factored I - Q where its envelope is at most :data:`FILL_LIMIT` times ``work``
    (the propagation's multiply-adds a lag) and within :data:`LU_BYTES`, else None;
    factored by blocks (:class:`LevelBlocks`) where every pair is live and the chain is
    small and dense enough (:data:`BLOCK_STATES`, :data:`BLOCK_ADVANTAGE`), else by
    SuperLU.

    Parameters
    ----------
    indptr, indices, data : ndarray
        I - Q on the live pairs as CSC arrays (:class:`LevelInverse`).
    live : ndarray of bool, shape (S, L)
    work : int

    Returns
    -------
    LevelInverse or None
        None also where I - Q is singular in floating point for SuperLU (states that leak
        less than the round-off: the space of Q^T is used there); where only the blocks
        are (I - P_stay singular in floating point), SuperLU's factors, as for
        :func:`factor_levels`.
    """
    filled = envelope(indptr, indices)
    if filled > FILL_LIMIT * work or 12 * filled > LU_BYTES:
        return None
    if by_blocks(live, filled):
        try:
            return LevelInverse(indptr, indices, data, live, blocks=True)
        except RuntimeError:     # I - P_stay or the boundary singular: SuperLU decides
            pass
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


@nb.njit(cache=True, nogil=True)
def _error_columns(indptr, indices, data, columns, products, direction, residual_vector):
    """The columns' 1-norms of E = A V - V T - u c^T (Numba kernel): ``columns`` V [n, m]
    (a pair's entries of the m vectors side by side), ``products`` V T [n, m], (I - A) as
    CSR arrays; each entry q_j - sum of the row's terms of (I - A) q_j - (V T) - u c^T,
    a row's m entries at once (in SIMD)."""
    n, dim = columns.shape
    norms = np.zeros(dim)
    acc = np.empty(dim)
    for r in range(n):
        row = columns[r]
        product = products[r]
        u = residual_vector[r]
        for k in range(dim):
            acc[k] = row[k] - product[k] - direction[k] * u
        for q in range(indptr[r], indptr[r + 1]):
            x = data[q]
            source = columns[indices[q]]
            for k in range(dim):
                acc[k] -= x * source[k]
        for k in range(dim):
            norms[k] += abs(acc[k])
    return norms


def relation_error(indptr, indices, data, basis, dim, small, residual_direction,
                   residual_vector):
    """The columns of E = A V - V T - u c^T (module docstring), as 1-norms, and beside each
    the 1-norm of the terms it sums (for the bound on the rounding of forming it).

    ``basis`` [m + 1, n] (V's columns as rows), ``small`` T [dim, dim],
    ``residual_direction`` c [dim], ``residual_vector`` u [n]. A q_j is formed as
    q_j - (I - A) q_j, V T by one BLAS product (on the caller's one BLAS thread), the rest
    by :func:`_error_columns`: each entry of E a sum of the row's terms of I - A, the dim
    of V T, u c^T and q_j, whatever their order, as the bound counts them.
    Returns (norms, magnitudes), float64 [dim] each."""
    columns = np.ascontiguousarray(basis[:dim].T)
    norms = _error_columns(indptr, indices, data, columns, columns @ small,
                           np.ascontiguousarray(residual_direction), residual_vector)
    one_norms = np.abs(basis[:dim]).sum(axis=1)
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
