"""The embedded chain of a periodic riser's entry states and its stationary distribution.

A residence starts in the state a particle lands in after the pass up through the top that
ends the previous one (:mod:`cfbmarkov.markov.first_passage`). From entry state e, the next
entry is e' with probability B[e, e'], B = N_00 R: N = (I - Q)^-1 is the fundamental
matrix of the transient chain on (lap-deficit level, state), N_00 its block from level 0 to
level 0, and R = P_up restricted to level 0's rows and the entry states' columns. The
entry states of a steady riser are distributed as B's stationary distribution.

Q is block tridiagonal in the levels g = 0 .. L-1 (P_stay within a level, P_down one level
deeper, P_up one level up), so N_00 is the inverse of the Schur complement of the deeper
levels onto level 0, formed from the deepest level up (block Gaussian elimination):

    T_(L-1) = I - S_(L-1),   T_g = I - S_g - D_g T_(g+1)^-1 U_(g+1),   N_00 = T_0^-1,

with S_g, D_g, U_g the blocks of P_stay, P_down and P_up between the levels' states that
can still reach the top (the others trap their mass and are left out). T_g differs from
A_g = I - S_g only in the few columns where up passes land (U's non-zero columns), so it
is applied through A_g's LU and the Sherman-Morrison-Woodbury formula rather than factored:
A_g is factored once for all the levels that keep the same states, and a level costs a
product and a solve with as many right-hand sides as those columns. The [S L, S L] matrix
is never formed or factored (its LU fills in across the levels).

References
----------
J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton (1960), Ch. III
(absorbing chains, B = N R). G. H. Golub and C. F. Van Loan, Matrix Computations, 4th ed.,
Johns Hopkins (2013), Sec. 4.5.1 (block tridiagonal systems), Sec. 2.1.4 (the
Sherman-Morrison-Woodbury formula).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.linalg import get_lapack_funcs
from scipy.sparse.linalg import splu

from cfbmarkov._blas import one_blas_thread


def entry_matrix(p_up, p_down, p_stay, live: np.ndarray, entries: np.ndarray,
                 with_falls: bool = False, with_decay: bool = False,
                 elimination: "DepthElimination | None" = None):
    """B, the embedded chain of entry states (module docstring), dense; with ``with_falls``
    also the probability of falling below the deepest level, and with ``with_decay`` how
    fast that probability falls with the depth.

    The probability h of falling below the deepest level L - 1 before the residence ends
    solves h = Q h + f, with f the down passes from level L - 1 (P_down's row sums there):
    the same block elimination carries f up the levels, c_(L-1) = f_(L-1),
    c_g = D_g T_(g+1)^-1 c_(g+1), and h_0 = T_0^-1 c_0, one more solve per level with the
    factors B already needs (Kemeny and Snell's absorption probabilities, the fall below
    the levels taken as a second absorbing state).

    The decay: T_g^-1 c_g is, from each state of level g, the probability of falling below
    the deepest level before passing up from level g; one level nearer the top it is one
    more level of depth to fall through. Far from the deepest level the Schur complements
    T_g converge (to those of the unbounded levels, a quasi-birth-death process's), and the
    ratio of those probabilities summed over a level's states, level 1 over level 2,
    converges to the factor rho by which each further level multiplies the loss
    (lost(K) ~ c rho^K; Latouche and Ramaswami 1999, Ch. 6: the level-crossing matrices of
    a QBD). :func:`cfbmarkov.markov.first_passage.deeper_levels` uses it to choose the next
    depth from one try.

    Parameters
    ----------
    p_up, p_down, p_stay : scipy.sparse.csr_matrix, shape (S, S)
        P split by pass direction.
    live : ndarray of bool, shape (L, S)
        The (level, state) pairs from which the top can be reached from level 0.
    entries : ndarray of int, shape (M,)
        The entry states (columns of P_up with a non-zero).
    with_falls : bool, optional
        Also return h_0.
    with_decay : bool, optional
        With ``with_falls``, also return the decay (NaN where there are fewer than three
        levels or nothing falls).
    elimination : DepthElimination, optional
        The same chain's elimination at other depths, whose steps this call reuses where
        the levels keep the same states, and extends (the same results, bit for bit).

    Returns
    -------
    ndarray of float64, shape (M, M)
        B[e, e']: from entry state entries[e] (at level 0), the probability that the
        residence ends landing in entries[e']; rows of entries that are not live are zero.
        Rows sum to 1 less the mass lost beyond the deepest level.
    ndarray of float64, shape (S,)
        With ``with_falls``: h_0, from each state at level 0 the probability that the
        residence passes down from the deepest level (0 for a state not live there).
    float
        With ``with_decay``: rho, the factor by which one more level multiplies the loss.

    References
    ----------
    G. Latouche and V. Ramaswami, Introduction to Matrix Analytic Methods in Stochastic
    Modeling, SIAM, Philadelphia (1999), Ch. 6 (quasi-birth-death processes).
    """
    shared = elimination if elimination is not None else DepthElimination(p_up, p_down,
                                                                           p_stay)
    with shared.algebra.context():
        return _eliminate(shared.algebra, live, entries, with_falls, with_decay,
                          shared.steps if elimination is not None else None)


class DepthElimination:
    """The block elimination of one chain shared by :func:`entry_matrix`'s calls at several
    depths (the tries of :func:`cfbmarkov.markov.first_passage.deeper_levels`).

    The elimination runs from the deepest level up, and its step at a level depends only
    on the states kept at that level and its two neighbours and on the step below: at the
    same distance from the deepest level, a deeper try repeats a shallower one's steps
    wherever the levels keep the same states (every level but the top, as a rule). Each
    step's result (U's non-zero columns, T^-1 U on them, T^-1 c) is kept by its distance
    from the deepest level and reused while the states agree, with the same bits; the
    first step that differs and all above it are computed again. The blocks (and the
    dense parts) are formed once for all the calls.

    Parameters
    ----------
    p_up, p_down, p_stay : scipy.sparse matrix, shape (S, S)
        P split by pass direction, as :func:`entry_matrix` takes them.
    """

    def __init__(self, p_up, p_down, p_stay):
        s = p_stay.shape[0]
        dense = s <= DENSE_STATES and sum(sp.csr_matrix(part).nnz for part in
                                          (p_up, p_down, p_stay)) >= DENSE_FILL * s * s
        self.algebra = (_DenseBlocks if dense else _SparseBlocks)(p_up, p_down, p_stay)
        self.steps: list = []     # (key, (up_cols, up_block, carried)) by distance


def _eliminate(algebra, live, entries, with_falls, with_decay, steps=None):
    """:func:`entry_matrix`'s block elimination, its blocks' arithmetic by ``algebra``
    (:class:`_SparseBlocks` or :class:`_DenseBlocks`); ``steps`` a
    :class:`DepthElimination`'s steps, reused and extended.

    T_g is never formed or factored: it differs from A_g = I - S_g only in the C columns
    (``up_cols``) where level g + 1's up passes land, T_g = A_g - W E^T with
    W = D_g T_(g+1)^-1 U_(g+1) and E those columns of the identity, so by the
    Sherman-Morrison-Woodbury formula

        T_g^-1 x = y + Z K^-1 y[up_cols],  y = A_g^-1 x,  Z = A_g^-1 W,  K = I - Z[up_cols]

    (Golub and Van Loan, Sec. 2.1.4). A_g is factored once for all the levels that keep
    the same states, and A_g^-1 on the columns of the states that pass down (D_g's
    non-zero rows) once for each pair of such levels: a level costs two small products
    with C columns and a C x C solve instead of an LU of T_g. K is the identity
    less the probabilities of leaving level g down and coming back to it, landing in the
    columns: a non-singular M-matrix wherever level g's states can reach the top."""
    levels, s = live.shape
    kept = [np.flatnonzero(live[g]) for g in range(levels)]
    up_cols = up_block = None     # U_(g+1)'s non-zero columns, T_(g+1)^-1 U_(g+1) on them
    carried = None                # T_(g+1)^-1 c_(g+1) on level g + 1's rows
    down_probability = algebra.down_probability() if with_falls else None
    carried_sums = {}             # level g: the sum of T_g^-1 c_g over its states
    inverse = None                # T_0^-1 (as a function) once the loop ends
    for g in range(levels - 1, -1, -1):
        rows = kept[g]
        distance = levels - 1 - g
        key = None
        if steps is not None and g > 0:
            key = (with_falls, rows.tobytes(), kept[g - 1].tobytes(),
                   kept[g + 1].tobytes() if g + 1 < levels else b"deepest")
            if distance < len(steps) and steps[distance][0] == key:
                up_cols, up_block, carried = steps[distance][1]
                if with_falls and g <= 2:
                    carried_sums[g] = float(carried.sum())
                continue
            del steps[distance:]
        if rows.size == 0:
            up_cols = up_block = carried = None
            inverse = None
            if key is not None:
                steps.append((key, (up_cols, up_block, carried)))
            continue
        falls = None                              # A_g^-1 c_g
        if with_falls:
            falls = (algebra.stay_solved(rows, down_probability[rows]) if g == levels - 1
                     else np.zeros(rows.size))
        inverse = _woodbury(algebra, rows, kept[g + 1] if g + 1 < levels else None,
                            up_block, up_cols)
        if with_falls and carried is not None:
            falls = falls + algebra.down_solved(rows, kept[g + 1], carried)
        if g == 0:
            break
        up_cols = algebra.up_columns(rows, kept[g - 1])
        up_block = inverse(algebra.up_solved(rows, kept[g - 1], up_cols)) if up_cols.size \
            else None
        carried = inverse(falls) if with_falls else None
        if with_falls and g <= 2:
            carried_sums[g] = float(carried.sum())
        if key is not None:
            steps.append((key, (up_cols, up_block, carried)))
    out = np.zeros((entries.size, entries.size))
    h0 = np.zeros(s)
    rows = kept[0]
    decay = (carried_sums[1] / carried_sums[2]
             if carried_sums.get(1, 0.0) > 0 and carried_sums.get(2, 0.0) > 0 else float("nan"))
    if rows.size == 0:
        return ((out, h0, decay) if with_decay else (out, h0)) if with_falls else out
    position = -np.ones(s, np.int64)
    position[rows] = np.arange(rows.size)
    solved = inverse(algebra.up_solved(rows, entries, None))            # N_00 R
    live_entries = position[entries] >= 0
    out[live_entries] = solved[position[entries[live_entries]]]
    if not with_falls:
        return out
    h0[rows] = inverse(falls)
    return (out, h0, decay) if with_decay else (out, h0)


def _woodbury(algebra, rows, below, up_block, up_cols):
    """T_g^-1 as a function of A_g^-1 x (:func:`_eliminate`): the identity where nothing
    comes back from level g + 1 (``up_block`` None), else y -> y + Z K^-1 y[up_cols]."""
    if up_block is None:
        return lambda solved: solved
    z = algebra.down_solved(rows, below, up_block)                 # A_g^-1 D_g X, [rows, C]
    k = np.identity(up_cols.size) - z[up_cols]
    lu, pivots, info = _GETRF(k)
    if info != 0:         # (K is an M-matrix wherever level g's states can reach the top)
        raise RuntimeError(f"entry chain: LAPACK getrf returned {info} on a level's return")

    def apply(solved):
        x, info = _GETRS(lu, pivots, solved[up_cols].reshape(up_cols.size, -1))
        if info != 0:
            raise RuntimeError(f"entry chain: LAPACK getrs returned {info}")
        return solved + (z @ x).reshape(solved.shape)
    return apply


_GETRF, _GETRS = get_lapack_funcs(("getrf", "getrs"), (np.zeros(1),))


#: SuperLU's column ordering for a level's block A_g = I - S_g: the states' own order
#: (cells row by row, their memory or regime within a cell) keeps its fill near its band,
#: and ordering it anew cost more than the fill it saved (measured on a 1824-state velocity
#: memory and a 1596-state previous-cell memory, with COLAMD, SuperLU's default)
ORDERING = "NATURAL"

#: chains of at most this many states, with transitions to at least :data:`DENSE_FILL` of
#: the pairs of states, are eliminated with dense blocks (LAPACK's LU on one thread): a
#: riser's chain of a few hundred cells (13 % filled at 6 x 38 cells) costs a sparse LU
#: more in bookkeeping than in arithmetic, a banded chain of 500 states (0.6 % filled) ten
#: times less than a dense one
DENSE_STATES = 512

#: the share of the [S, S] transitions a chain must hold to be eliminated densely
DENSE_FILL = 0.05


class _SparseBlocks:
    """The elimination's blocks as scipy.sparse matrices, A_g = I - S_g factored by
    SuperLU; each sub-matrix part[rows][:, cols] and each A_g's factors formed once (the
    levels usually keep the same states), the whole part where both are every state."""

    def __init__(self, p_up, p_down, p_stay):
        self.up_part, self.down_part, self.stay_part = (sp.csr_matrix(part) for part in
                                                        (p_up, p_down, p_stay))
        self.s = self.stay_part.shape[0]
        self.memo = {}

    def context(self):
        return one_blas_thread()             # the dense products: the same bits on any count

    def _block(self, part, rows, cols):
        if rows.size == self.s and cols.size == self.s:
            return part
        key = (id(part), rows.tobytes(), cols.tobytes())
        if key not in self.memo:
            self.memo[key] = part[rows][:, cols]
        return self.memo[key]

    def _factors(self, rows):
        key = ("A", rows.tobytes())
        if key not in self.memo:
            a = sp.identity(rows.size, format="csc") - self._block(self.stay_part, rows, rows)
            self.memo[key] = splu(sp.csc_matrix(a), permc_spec=ORDERING)
        return self.memo[key]

    def down_probability(self):
        return np.asarray(self.down_part.sum(axis=1)).ravel()

    def stay_solved(self, rows, x):
        """A_g^-1 x."""
        return self._factors(rows).solve(x)

    def down_solved(self, rows, below, x):
        """A_g^-1 D_g x, D_g the passes down from ``rows`` to level g + 1's ``below``: D_g
        has rows only for the few states that pass down (the bottom row's), so it is
        A_g^-1 on those columns (solved once, dense) times those rows of D_g x."""
        key = ("W", rows.tobytes(), below.tobytes())
        if key not in self.memo:
            d = self._block(self.down_part, rows, below).tocsr()
            passing = np.flatnonzero(np.diff(d.indptr))
            unit = np.zeros((rows.size, passing.size))
            unit[passing, np.arange(passing.size)] = 1.0
            self.memo[key] = (self._factors(rows).solve(unit), d[passing])
        solved, d = self.memo[key]
        return solved @ np.asarray(d @ x)

    def up_columns(self, rows, above):
        """The columns (positions in ``above``) of U_g that an up pass lands in."""
        return np.flatnonzero(np.diff(self._block(self.up_part, rows, above).tocsc().indptr))

    def up_solved(self, rows, above, cols):
        """A_g^-1 U_g on the columns ``cols`` (every column where None), dense."""
        key = ("P", rows.tobytes(), above.tobytes(), None if cols is None else cols.tobytes())
        if key not in self.memo:
            u = self._block(self.up_part, rows, above).tocsc()
            self.memo[key] = self._factors(rows).solve((u if cols is None
                                                        else u[:, cols]).toarray())
        return self.memo[key]


class _DenseBlocks:
    """The elimination's blocks as dense arrays, A_g = I - S_g factored by LAPACK (getrf,
    getrs) on one BLAS thread, and A_g^-1 on the columns of the states that pass down
    formed once for each pair of levels' states, so that a level's step is two small
    matrix products."""

    def __init__(self, p_up, p_down, p_stay):
        self.up_part, self.down_part, self.stay_part = (sp.csr_matrix(part).toarray() for part
                                                        in (p_up, p_down, p_stay))
        self.s = self.stay_part.shape[0]
        self.memo = {}

    def context(self):
        return one_blas_thread()             # the same bits on any thread count

    def _block(self, part, rows, cols):
        if rows.size == self.s and cols.size == self.s:
            return part
        return part[np.ix_(rows, cols)]

    def _factors(self, rows):
        key = ("A", rows.tobytes())
        if key not in self.memo:
            lu, pivots, info = _GETRF(np.identity(rows.size)
                                      - self._block(self.stay_part, rows, rows))
            if info != 0:     # (a live level's block is never singular: it reaches the top)
                raise RuntimeError(f"entry chain: LAPACK getrf returned {info} on a level's "
                                   "block")
            self.memo[key] = (lu, pivots)
        return self.memo[key]

    def _solve(self, rows, x):
        x, info = _GETRS(*self._factors(rows), x)
        if info != 0:
            raise RuntimeError(f"entry chain: LAPACK getrs returned {info}")
        return x

    def down_probability(self):
        return self.down_part.sum(axis=1)

    def stay_solved(self, rows, x):
        return self._solve(rows, x)

    def down_solved(self, rows, below, x):
        key = ("W", rows.tobytes(), below.tobytes())
        if key not in self.memo:
            d = self._block(self.down_part, rows, below)
            passing = np.flatnonzero(d.any(axis=1))
            unit = np.zeros((rows.size, passing.size))
            unit[passing, np.arange(passing.size)] = 1.0
            self.memo[key] = (self._solve(rows, unit), np.ascontiguousarray(d[passing]))
        solved, d = self.memo[key]
        return solved @ (d @ x)

    def up_columns(self, rows, above):
        return np.flatnonzero(self._block(self.up_part, rows, above).any(axis=0))

    def up_solved(self, rows, above, cols):
        key = ("P", rows.tobytes(), above.tobytes(), None if cols is None else cols.tobytes())
        if key not in self.memo:
            u = self._block(self.up_part, rows, above)
            self.memo[key] = self._solve(rows, np.ascontiguousarray(u if cols is None
                                                                    else u[:, cols]))
        return self.memo[key]


def embedded_stationary(embedded: np.ndarray, live_entries: np.ndarray) -> np.ndarray:
    """Stationary distribution of the embedded entry chain B (dense [M, M]).

    For more than 8 entry states, B's dominant left eigenvector where its eigenvalue is 1
    within 1e-6 (B is then stochastic but for a negligible loss); else that of B with its
    rows normalised (the chain conditioned on a next entry).

    Parameters
    ----------
    embedded : ndarray of float64, shape (M, M)
        B (:func:`entry_matrix`).
    live_entries : ndarray of bool, shape (M,)
        The entries whose rows are live.

    Returns
    -------
    ndarray of float64, shape (M,)
        Non-negative, summing to 1.
    """
    m = embedded.shape[0]
    if m > 8:
        b = np.where(live_entries[:, None], embedded, 0.0)
        with one_blas_thread():
            values, vectors = np.linalg.eig(b.T)
        lead = int(np.argmax(np.abs(values)))
        nu = np.abs(vectors[:, lead].real)
        if abs(values[lead] - 1.0) < 1e-6 and nu.sum() > 0:
            return nu / nu.sum()
    return stationary(embedded)


def stationary(embedded: np.ndarray) -> np.ndarray:
    """Stationary distribution of a (sub)stochastic matrix with its rows normalised (the
    dominant left eigenvector), non-negative and summing to 1."""
    rows = embedded.sum(axis=1, keepdims=True)
    k = np.divide(embedded, rows, out=np.zeros_like(embedded), where=rows > 0)
    with one_blas_thread():    # a small dense eig: threads only contend (100x slower
        values, vectors = np.linalg.eig(k.T)             # on a busy 2-core machine)
    lead = int(np.argmax(values.real))
    nu = np.abs(vectors[:, lead].real)
    return nu / nu.sum()
