"""The tail of an exact RTD from a Krylov projection, with a bound on its error.

Past its first few hundred lags a residence-time distribution f(k) = s Q^(k-1) e decays as
a handful of Q's slowest modes, and on a real riser's chain those modes are slow and close
together (``benchmarks/exact_rtd_closure.py --eigenvalues 4`` prints them for a model):
propagating the tail lag by lag to a mass of 1e-10 takes thousands of lags, most of the
exact RTD's cost. Here, once the fast modes have
died out, the state vector v = s Q^k0 is projected on the Krylov space of dimension m that
it spans (Arnoldi with classical Gram-Schmidt applied twice: A V_m = V_m H_m +
h q_(m+1) e_m^T, A = Q^T acting on columns), and the rest of the tail follows from the m x m
Hessenberg matrix: v Q^k ~ V_m H_m^k (|v| e_1), f(k0 + k + 1) ~ (e^T V_m) H_m^k |v| e_1.

The error of that tail is bounded, not estimated. With z_k = V_m H_m^k y_0, the Arnoldi
relation gives z_(k+1) = A z_k - rho_k with rho_k = h q_(m+1) (H_m^k y_0)_m (plus the
relation's rounding, bounded per column as in Higham, Accuracy and Stability of Numerical
Algorithms, 2nd ed., SIAM (2002), Ch. 3). The error e_k = A^k v - z_k then obeys
e_(k+1) = A e_k + rho_k, and as Q is sub-stochastic (its rows sum to at most one) A does
not grow any vector's 1-norm, and a mass x is absorbed, by the top or below the deepest
lap deficit, at most ||x||_1 in all later lags: the tail's distribution and its loss below
the deepest deficit together are off by at most sum_k ||rho_k||_1 (the sum of |error| over
all its lags). Left out of the bound is the rounding of evaluating the tail itself, the
m x m product H y and the functionals e^T V a lag, relative errors of order m times the
unit round-off, as in the propagation's own sums. The closure is taken only where the
bound, accumulated as the tail is evaluated, stays below a given tolerance; elsewhere the
propagation goes on and tries again later.

Where I - Q is cheap to factor, a long tail's space is that of (I - A)^-1 instead
(:mod:`cfbmarkov.markov.shift_invert`), whose relation A V_m = V_m T + u c^T + E has the
same form with a dense T and a residual along c rather than e_m; the bound is then
sum_k ||u||_1 |c^T y_k| + sum_j ||E_j||_1 |y_k,j|, the same argument.

References
----------
W. E. Arnoldi, "The principle of minimized iterations in the solution of the matrix
eigenvalue problem", Quart. Appl. Math. 9, 17 (1951); Y. Saad, Numerical Methods for Large
Eigenvalue Problems, 2nd ed., SIAM (2011), Ch. 6 (the Arnoldi relation, Gram-Schmidt applied
twice); L. Giraud, J. Langou, M. Rozloznik, "The loss of orthogonality in the Gram-Schmidt
orthogonalization process", Comput. Math. Appl. 50, 1069 (2005).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from cfbmarkov._blas import one_blas_thread
from cfbmarkov.markov.shift_invert import (InverseArnoldi, LevelInverse, dot, gather_pairs,
                                           pair_functionals)

#: the dimension of the Krylov space (fewer where the chain has fewer live pairs, or where
#: its basis would take more than :data:`BASIS_BYTES`)
DIMENSION = 40

#: the smallest Krylov dimension worth a try (a chain that allows fewer is propagated)
MIN_DIMENSION = 8

#: the most tries of the closure in one RTD (refused tries cost an Arnoldi each)
MAX_TRIES = 6

#: the most memory the Krylov basis may take (bytes)
BASIS_BYTES = 64 * 2 ** 20

#: the first lag at which the closure is tried; then at twice as many lags, and so on
FIRST_TRY = 512

#: before :data:`FIRST_TRY`, the closure is tried at the first multiple of
#: :data:`EARLY_STEP` lags from :data:`EARLY_STEP` x 2 on where the mass not yet absorbed is
#: below this, unless the decay of the last :data:`EARLY_STEP` lags, continued, ends the
#: propagation before :data:`FIRST_TRY` (no try is made then, as none would be without
#: the early check): the tail of a chain that empties fast is closed early (the bound on
#: the closure's error scales with the mass it projects, and a try refused there costs one
#: Arnoldi); the paper-scale 3 m/s models measured hold more than this at lag 512 and are
#: tried there first
EARLY_MASS = 1e-2

#: the lags between the checks of the mass before :data:`FIRST_TRY`
EARLY_STEP = 64

#: unit round-off of float64 (with a margin for the rounding of the bound itself)
ROUND_OFF = 1.2e-16


@nb.njit(cache=True, inline="always")
def level_row(j, down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr, up_idx,
              up_val, live, v, w, acc):
    """One lag of the chain on the lap-deficit levels into destination state ``j``, every
    level (Numba kernel, inlined).

    Parameters
    ----------
    j : int
        The destination state.
    down_ptr, down_idx, down_val : ndarray
        P_down as the CSR arrays of its transpose (rows: destinations; int64 pointers and
        indices, float64 values).
    stay_ptr, stay_idx, stay_val, up_ptr, up_idx, up_val : ndarray
        P_stay and P_up likewise.
    live : ndarray of bool, shape (S, L)
        The (state, level) pairs from which the top can be reached.
    v : ndarray of float64, shape (S, L)
        The mass on each state and level.
    w : ndarray of float64, shape (S, L)
        Row ``j`` is overwritten: ``w[j, g]`` = the mass arriving from level g - 1 by
        P_down, from level g by P_stay and from level g + 1 by P_up, or 0 where
        ``live[j, g]`` is false.
    acc : ndarray of float64, shape (L,)
        Scratch space, overwritten: the sums are gathered here, an array of its own that
        the compiler knows ``v`` does not share, so that the loops over the levels run in
        vector registers (10-20 % faster a lag than gathering in ``w``; the same terms in
        the same order, so the same bits).
    """
    levels = v.shape[1]
    for g in range(levels):
        acc[g] = 0.0
    for q in range(down_ptr[j], down_ptr[j + 1]):      # from level g - 1
        value = down_val[q]
        i = down_idx[q]
        for g in range(1, levels):
            acc[g] += value * v[i, g - 1]
    for q in range(stay_ptr[j], stay_ptr[j + 1]):
        value = stay_val[q]
        i = stay_idx[q]
        for g in range(levels):
            acc[g] += value * v[i, g]
    for q in range(up_ptr[j], up_ptr[j + 1]):          # from level g + 1
        value = up_val[q]
        i = up_idx[q]
        for g in range(levels - 1):
            acc[g] += value * v[i, g + 1]
    for g in range(levels):
        w[j, g] = acc[g] if live[j, g] else 0.0


@nb.njit(cache=True)
def _dot(a, b):
    """sum a * b over [S, L] arrays, in four interleaved partial sums
    (:func:`~cfbmarkov.markov.shift_invert.dot`: a fixed order that the compiler can
    vectorise, the same bits on any machine of the same instruction set)."""
    return dot(a.ravel(), b.ravel())


@nb.njit(cache=True)
def _subtract(w, h, q):
    """w -= h q, [S, L] arrays."""
    x = w.ravel()
    y = q.ravel()
    for i in range(x.size):
        x[i] -= h * y[i]


@nb.njit(cache=True)
def _norm1(a):
    n, levels = a.shape
    total = 0.0
    for i in range(n):
        for g in range(levels):
            total += abs(a[i, g])
    return total


@nb.njit(cache=True, nogil=True)
def arnoldi_levels(down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr,
                   up_idx, up_val, live, v, basis, hessenberg, rounding, row_terms):
    """The Arnoldi relation of the chain on the levels from ``v`` (Numba kernel).

    Parameters
    ----------
    down_ptr, down_idx, down_val : ndarray
        P_down as the CSR arrays of its transpose (:func:`level_row`).
    stay_ptr, stay_idx, stay_val, up_ptr, up_idx, up_val : ndarray
        P_stay and P_up likewise.
    live : ndarray of bool, shape (S, L)
        The (state, level) pairs from which the top can be reached.
    v : ndarray of float64, shape (S, L)
        The start vector (not all zero).
    basis : ndarray of float64, shape (m + 1, S, L)
        Filled with the orthonormal basis q_1 .. q_(m+1).
    hessenberg : ndarray of float64, shape (m + 1, m)
        Zeros on entry; filled with H.
    rounding : ndarray of float64, shape (m,)
        Filled with a bound on the 1-norm of the rounding error of each column of the
        Arnoldi relation.
    row_terms : int
        The most terms a destination's sum can have (for the rounding bound).

    Returns
    -------
    (int, float, float)
        The dimension reached (m, or fewer where the Krylov space is invariant), |v|_2, and
        ||q_(dim+1)||_1 (0 where the space is invariant).
    """
    dim = hessenberg.shape[1]
    n, levels = v.shape
    norm = math.sqrt(_dot(v, v))
    one_norms = np.zeros(dim + 1)
    for i in range(n):
        for g in range(levels):
            basis[0, i, g] = v[i, g] / norm
    one_norms[0] = _norm1(basis[0])
    w = np.empty((n, levels))
    acc = np.empty(levels)
    for j in range(dim):
        for r in range(n):
            level_row(r, down_ptr, down_idx, down_val, stay_ptr, stay_idx, stay_val, up_ptr,
                      up_idx, up_val, live, basis[j], w, acc)
        for _sweep in range(2):                       # classical Gram-Schmidt, twice
            for i in range(j + 1):
                h = _dot(basis[i], w)
                hessenberg[i, j] += h
                _subtract(w, h, basis[i])
        spread = one_norms[j]                        # ||A|| |q_j| <= ||q_j||_1 (Q sub-stochastic)
        for i in range(j + 1):
            spread += abs(hessenberg[i, j]) * one_norms[i]
        rounding[j] = (row_terms + 4 * (j + 2)) * ROUND_OFF * spread
        next_norm = math.sqrt(_dot(w, w))
        if next_norm == 0.0:                         # an invariant subspace: exact
            return j + 1, norm, 0.0
        hessenberg[j + 1, j] = next_norm
        for r in range(n):
            for g in range(levels):
                basis[j + 1, r, g] = w[r, g] / next_norm
        one_norms[j + 1] = _norm1(basis[j + 1])
    return dim, norm, one_norms[dim]


@nb.njit(cache=True, nogil=True)
def _projections(basis, dim, exit_probability, down_probability):
    """The functionals of the tail on the basis: exits (from level 0), passes down from
    each level, and the mass left, each as a row over the first ``dim`` basis vectors."""
    levels = basis.shape[2]
    n = basis.shape[1]
    exits = np.zeros(dim)
    falls = np.zeros((levels, dim))
    mass = np.zeros(dim)
    for k in range(dim):
        for i in range(n):
            exits[k] += exit_probability[i] * basis[k, i, 0]
            for g in range(levels):
                falls[g, k] += down_probability[i] * basis[k, i, g]
                mass[k] += basis[k, i, g]
    return exits, falls, mass


#: the lags of the closed tail evaluated from one state of the projected vector: each lag's
#: functionals come from the rows e^T T^j precomputed for j < TAIL_BLOCK, the vector moves
#: TAIL_BLOCK lags at once (about 4 m + 2 m^2 / TAIL_BLOCK multiply-adds a lag instead of
#: m^2 + 4 m)
TAIL_BLOCK = 32


@nb.njit(cache=True, nogil=True)
def _closed_tail(small, dim, residual, direction, rounding, exits, falls_on, mass, norm,
                 first, tol, error_tol, max_steps, out, falls, bound, decay):
    """The RTD's tail from lag ``first`` by the Krylov projection (Numba kernel).

    ``out[k]`` for k = first .. (the mass absorbed on transition k + 1), ``falls[g]``
    gathers the mass passing down from level g, as the propagation does. ``small`` is the
    projected matrix T; the relation A V = V T + u c^T + E has ``residual`` = ||u||_1,
    ``direction`` = c and ``rounding`` bounding the 1-norms of E's columns; ``bound`` is
    the error of the start vector's projection. With y_k = T^k y_0 the tail's error grows
    a lag by at most ||u||_1 |c^T y_k| + rounding^T |y_k|, and |y_(k+j)| <= |T^j| |y_k|:
    the lags are taken :data:`TAIL_BLOCK` at a time from one y_k, with the rows e^T T^j,
    c^T T^j, mass^T T^j and rounding^T |T^j| formed once. Stops where the projected mass
    left falls below ``tol`` or at ``max_steps``. Gives up (returns -1) wherever the bound
    on the tail's error exceeds ``error_tol``; it then follows the bound on until the last
    lag's increment, continued as a geometric series of ratio ``decay`` (the largest
    modulus of T's eigenvalues), would add less than a tenth of it (or until the bound is a
    million times too large), and returns the bound reached plus that rest: an estimate of
    the whole tail's bound, which tells the caller when to try again. Returns the number
    of lags reached (-1: refused) and the bound (the 1-norm of the tail's error, summed
    over its lags, at most)."""
    block = TAIL_BLOCK
    powers = np.zeros((block + 1, dim, dim))
    for i in range(dim):
        powers[0, i, i] = 1.0
    for j in range(1, block + 1):
        for r in range(dim):
            for i in range(dim):
                value = small[r, i]
                if value != 0.0:
                    for c in range(dim):
                        powers[j, r, c] += value * powers[j - 1, i, c]
    exit_rows = np.zeros((block, dim))
    along_rows = np.zeros((block, dim))
    rounding_rows = np.zeros((block, dim))
    mass_rows = np.zeros((block + 1, dim))
    block_sum = np.zeros((dim, dim))
    for j in range(block + 1):
        for r in range(dim):
            for c in range(dim):
                value = powers[j, r, c]
                mass_rows[j, c] += mass[r] * value
                if j < block:
                    exit_rows[j, c] += exits[r] * value
                    along_rows[j, c] += direction[r] * value
                    rounding_rows[j, c] += rounding[r] * abs(value)
                    block_sum[r, c] += value
    y = np.zeros(dim)
    z = np.empty(dim)
    summed = np.zeros(dim)          # sum of y over the lags: the passes down at the end
    y[0] = norm
    levels = falls.shape[0]
    reached = max_steps
    k = first
    while k < max_steps:
        taken = min(block, max_steps - k)
        stopped = -1
        for j in range(taken):
            absorbed = 0.0
            along = 0.0
            step = 0.0
            left = 0.0
            for i in range(dim):
                absorbed += exit_rows[j, i] * y[i]
                along += along_rows[j, i] * y[i]
                step += rounding_rows[j, i] * abs(y[i])
                left += mass_rows[j + 1, i] * y[i]
            out[k + j] = absorbed
            step += residual * abs(along)
            bound += step
            if bound > error_tol:   # refused: followed on while the bound still grows
                rest = step * decay / (1.0 - decay)
                if rest < 0.1 * bound or bound > 1e6 * error_tol:
                    return -1, bound + rest
            if left < tol:          # (the projected mass: taken only if the bound holds)
                stopped = j
                break
        last = taken - 1 if stopped < 0 else stopped
        if stopped >= 0 or last < block - 1:    # a part of a block: its own sums
            for j in range(last + 1):
                for r in range(dim):
                    acc = 0.0
                    for i in range(dim):
                        acc += powers[j, r, i] * y[i]
                    summed[r] += acc
        else:
            for r in range(dim):
                acc = 0.0
                for i in range(dim):
                    acc += block_sum[r, i] * y[i]
                summed[r] += acc
        if stopped >= 0:
            reached = k + stopped + 1
            break
        for r in range(dim):
            acc = 0.0
            for i in range(dim):
                acc += powers[block, r, i] * y[i]
            z[r] = acc
        y, z = z, y
        k += taken
    if bound > error_tol:
        return -1, bound
    for g in range(levels):
        for i in range(dim):
            falls[g] += falls_on[g, i] * summed[i]
    return reached, bound


def krylov_dimension(live_pairs: int, states: int, levels: int, work: int) -> int:
    """The Krylov dimension used for a chain on the levels.

    A lag of the closed tail is counted as m^2 / 2 + (L + 4) m multiply-adds (a lag of H
    on the vector, the exits, passes down per level and mass on the basis; an upper count:
    the lags are taken :data:`TAIL_BLOCK` at a time and the passes down summed once at
    the end), a lag of the propagation ``work``: the closure is used only where its lags
    cost at most a quarter of the propagation's, with m as large as that allows up to
    :data:`DIMENSION`.

    Parameters
    ----------
    live_pairs : int
        The live (state, level) pairs.
    states, levels : int
        S and L.
    work : int
        The propagation's multiply-adds a lag (the parts' non-zeros times L).

    Returns
    -------
    int
        m: at most :data:`DIMENSION`, ``live_pairs`` and what :data:`BASIS_BYTES` holds of
        (m + 1) x S x L float64 values, and within the cost above; 0 (no closure) where
        that leaves fewer than :data:`MIN_DIMENSION`.
    """
    fits = BASIS_BYTES // (8 * states * levels) - 1
    dimension = max(0, min(DIMENSION, live_pairs, fits))
    while dimension and dimension * dimension / 2 + (levels + 4) * dimension > work / 4:
        dimension -= 1
    return int(dimension) if dimension >= MIN_DIMENSION else 0


def try_closure(arrays, live, v, exit_probability, down_probability, first: int, tol: float,
                error_tol: float, max_steps: int, out: np.ndarray, falls: np.ndarray,
                dimension: int, inverse: LevelInverse | None = None) -> tuple[int, float]:
    """Close the tail of a propagation at lag ``first`` from its state ``v`` [S, L].

    Parameters
    ----------
    arrays : list of ndarray
        The parts' transposes as CSR arrays (down, stay, up), as the propagation takes them.
    live : ndarray of bool, shape (S, L)
        The (state, level) pairs from which the top can be reached.
    v : ndarray of float64, shape (S, L)
        The mass not yet absorbed, ``first`` lags after the start.
    exit_probability : ndarray of float64, shape (S,)
        Each state's probability of passing up through the top in a lag (from level 0:
        the residence's end).
    down_probability : ndarray of float64, shape (S,)
        Each state's probability of passing down through the bottom in a lag.
    first : int
        The lag the tail starts at.
    tol : float
        The mass left at which the tail stops.
    error_tol : float
        The largest bound on the tail's error accepted.
    max_steps : int
        The last lag.
    out, falls : ndarray of float64
        As the propagation's (written only where the closure is taken).
    dimension : int
        The Krylov dimension (:func:`krylov_dimension`).
    inverse : LevelInverse, optional
        I - Q factored (:func:`~cfbmarkov.markov.shift_invert.level_inverse`): the Krylov
        space is then that of (I - Q^T)^-1 (:mod:`cfbmarkov.markov.shift_invert`), else
        that of Q^T.

    Returns
    -------
    (int, float)
        The lags reached and the bound on the tail's error; the lags are -1 where the bound
        exceeded ``error_tol`` (``out`` beyond ``first`` then holds nothing of use,
        ``falls`` is unchanged), the bound then as far as it was followed.
    """
    n, levels = v.shape
    scale = float(np.abs(v).max())
    if not 0.0 < scale < np.inf or not error_tol > 0.0:
        return -1, np.inf
    # V y_0 = fl(fl(v / scale) / |.|) fl(|.| scale): three roundings of each entry
    start_bound = 4.0 * ROUND_OFF * float(np.abs(v).sum())
    if inverse is not None:
        return _try_inverse_closure(inverse, v, scale, exit_probability, down_probability,
                                    first, tol, error_tol, max_steps, out, falls, dimension,
                                    start_bound)
    basis = np.zeros((dimension + 1, n, levels))
    hessenberg = np.zeros((dimension + 1, dimension))
    rounding = np.zeros(dimension)
    row_terms = 3 * int(max(np.diff(arrays[3 * p]).max(initial=0) for p in range(3))) + 1
    # on v scaled to a largest entry of 1: the 2-norm of a tiny mass does not underflow
    dim, norm, next_one_norm = arnoldi_levels(*arrays, live, v / scale, basis, hessenberg,
                                              rounding, row_terms)
    exits, falls_on, mass = _projections(basis, dim, exit_probability, down_probability)
    residual = float(hessenberg[dim, dim - 1]) * next_one_norm if dim == dimension else 0.0
    small = np.ascontiguousarray(hessenberg[:dim, :dim])
    with one_blas_thread():
        decay = float(np.abs(np.linalg.eigvals(small)).max())
    direction = np.zeros(dim)
    direction[dim - 1] = 1.0
    gathered = np.zeros_like(falls)
    steps, bound = _closed_tail(small, dim, residual, direction, rounding[:dim].copy(),
                                exits, falls_on, mass, norm * scale, first, tol, error_tol,
                                max_steps, out, gathered, start_bound, min(decay, 1.0 - 1e-9))
    if steps >= 0:
        falls += gathered
    return steps, bound


#: the Krylov dimensions the shift-and-invert closure tries, from the smallest on, up to
#: the dimension allowed (each try extends the last one's basis; the bound's rank-one part
#: is checked first, E's columns formed only where it holds)
INVERSE_DIMENSIONS = (16, 24, 32, 40)


def _try_inverse_closure(inverse: LevelInverse, v, scale, exit_probability, down_probability,
                         first, tol, error_tol, max_steps, out, falls, dimension, start_bound
                         ) -> tuple[int, float]:
    """:func:`try_closure` on the Krylov space of (I - Q^T)^-1
    (:class:`~cfbmarkov.markov.shift_invert.InverseArnoldi`), at the smallest dimension of
    :data:`INVERSE_DIMENSIONS` (or ``dimension``) whose bound holds. E's columns are
    bounded by their computed 1-norms plus the rounding of forming them (each entry a sum
    of the row's terms of I - A, the m of V T, u c^T and q_j: Higham's gamma on the 1-norm
    of its terms)."""
    start = gather_pairs(v / scale, inverse.pair_state, inverse.pair_level)
    dimension = min(dimension, start.size)
    arnoldi = InverseArnoldi(inverse, start, dimension)
    sizes = sorted({size for size in INVERSE_DIMENSIONS if size < dimension} | {dimension})
    bound = np.inf
    for size in sizes:
        arnoldi.extend(size)
        last = size == sizes[-1] or arnoldi.invariant
        for with_error in (False, True):
            with one_blas_thread():
                relation = arnoldi.relation(with_error)
                if relation is None:
                    return -1, np.inf
                small = relation["small"]
                decay = float(np.abs(np.linalg.eigvals(small)).max())
            dim = relation["dim"]
            terms = inverse.row_terms + dim + 4
            rounding = relation["error_norms"] + terms * ROUND_OFF * relation["magnitudes"]
            exits, falls_on, mass = pair_functionals(arnoldi.basis, dim, inverse.pair_state,
                                                     inverse.pair_level, falls.size,
                                                     exit_probability, down_probability)
            gathered = np.zeros_like(falls)
            steps, bound = _closed_tail(small, dim, relation["residual"],
                                        relation["direction"], rounding, exits, falls_on,
                                        mass, relation["norm"] * scale, first, tol,
                                        error_tol, max_steps, out, gathered, start_bound,
                                        min(decay, 1.0 - 1e-9))
            if steps < 0:
                break
            if with_error:
                falls += gathered
                return steps, bound
        if last:
            break
    return -1, bound


def next_try(tries: list[tuple[int, float]], error_tol: float) -> int:
    """The lag to try the closure at next, from the tries refused so far.

    The bound falls about geometrically with the lag it is taken at (the fast modes left
    outside the Krylov space die out), so from two tries the next lag is where it would be
    a third of ``error_tol``, at least 64 lags and at most twice as far as the last try;
    from one try (or a bound that did not fall), twice as far.

    Parameters
    ----------
    tries : list of (int, float)
        The (lag, bound) of each refused try, in order.
    error_tol : float
        The bound accepted.

    Returns
    -------
    int
        The lag of the next try.
    """
    last, bound = tries[-1]
    if len(tries) < 2 or not 0.0 < bound < np.inf or not error_tol > 0.0:
        return 2 * last
    before, bound_before = tries[-2]
    if not bound < bound_before:
        return 2 * last
    rate = np.log(bound / bound_before) / (last - before)
    ahead = np.log(error_tol / (3.0 * bound)) / rate
    return int(last + min(max(64, np.ceil(ahead)), last))
