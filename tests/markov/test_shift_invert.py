"""The exact RTD's tail closed on the Krylov space of (I - Q^T)^-1 (markov.shift_invert): it
closes where the Krylov space of Q cannot yet, within its bound of the propagated RTD; the
bound holds where the factored matrix is not the chain's; the closed tail's lags taken a
block at a time are the lag-by-lag ones; the LU's fill stays within the envelope."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import splu

import cfbmarkov.markov.first_passage as fp
import cfbmarkov.markov.shift_invert as si
import cfbmarkov.markov.tail_closure as tc

from tests.markov.test_tail_closure import LAG, open_problem, slow_column


def closure_lags(monkeypatch, p, up, down, fill_limit):
    """The lags of the closure's tries on the exact RTD with ``si.FILL_LIMIT`` set, and
    the RTD."""
    tries = []
    original = fp.try_closure

    def recording(*args, **kwargs):
        result = original(*args, **kwargs)
        tries.append((args[5], result[0] >= 0, args[12] is not None, result[1]))
        return result

    with monkeypatch.context() as m:
        m.setattr(fp, "try_closure", recording)
        m.setattr(si, "FILL_LIMIT", fill_limit)
        rtd = fp.exact_rtd(p, up, down, LAG, deficit_levels=8)
    return tries, rtd


def test_the_inverse_closes_a_tail_of_close_slow_modes_where_arnoldi_cannot_yet(monkeypatch):
    """A lazy column whose slowest modes lie close together: the Krylov space of Q is
    refused at lag 512 and its closure taken four tries later (3234); that of (I - Q^T)^-1
    is taken at 512, and both are the propagated RTD within their bounds."""
    p, up, down = slow_column(states=120, stay=0.99, seed=4, reach=3, bias=2.0)
    arnoldi, by_arnoldi = closure_lags(monkeypatch, p, up, down, 0.0)
    inverse, by_inverse = closure_lags(monkeypatch, p, up, down, si.FILL_LIMIT)
    assert not any(t[2] for t in arnoldi) and all(t[2] for t in inverse)
    assert arnoldi[0][:2] == (tc.FIRST_TRY, False) and arnoldi[-1][1]
    assert arnoldi[-1][0] > 4 * tc.FIRST_TRY
    assert inverse == [inverse[0]] and inverse[0][:2] == (tc.FIRST_TRY, True)
    monkeypatch.setattr(fp, "krylov_dimension", lambda *args: 0)
    propagated = fp.exact_rtd(p, up, down, LAG, deficit_levels=8)
    for tries, rtd in ((arnoldi, by_arnoldi), (inverse, by_inverse)):
        size = max(rtd.probability.size, propagated.probability.size)
        a, b = np.zeros(size), np.zeros(size)
        a[:rtd.probability.size] = rtd.probability
        b[:propagated.probability.size] = propagated.probability
        assert 0 < tries[-1][3] <= fp.CLOSURE_TOL
        assert np.abs(a - b).sum() <= tries[-1][3]
        assert rtd.mean == pytest.approx(propagated.mean, rel=1e-8)
        assert abs(rtd.deficit_unresolved - propagated.deficit_unresolved) <= tries[-1][3]


def _closure(arrays, q, exits, start, first, steps, dimension, inverse):
    n = q.shape[0]
    out = np.zeros(steps)
    reached, bound = tc.try_closure(arrays, np.ones((n, 1), np.bool_), start.reshape(n, 1),
                                    exits, np.zeros(n), first, 0.0, np.inf, steps, out,
                                    np.zeros(1), dimension, inverse)
    return reached, bound, out


def _inverse_of(matrix, factored=None):
    """A LevelInverse of I - ``matrix`` (one level, every pair live), its solves with
    I - ``factored`` where given."""
    system = sp.csc_matrix(np.identity(matrix.shape[0]) - matrix)
    system.sort_indices()
    inverse = si.LevelInverse(system.indptr.astype(np.int64),
                              system.indices.astype(np.int64), system.data,
                              np.ones((matrix.shape[0], 1), np.bool_))
    if factored is not None:
        inverse.factors = splu(sp.csc_matrix(np.identity(matrix.shape[0]) - factored))
    return inverse


@pytest.mark.parametrize("dimension", [2, 4])
def test_the_inverse_closures_bound_holds_where_its_space_is_poor(dimension):
    """2 or 4 vectors of (I - Q^T)^-1's space cannot hold the tail 40 lags in: off by far
    more than round-off, and the bound covers it."""
    q, exits, arrays, start, truth = open_problem()
    reached, bound, out = _closure(arrays, q, exits, start, 40, 3000, dimension,
                                   _inverse_of(q))
    assert reached == 3000
    error = np.abs(out[40:] - truth[40:]).sum()
    assert error > 1e-6
    assert error <= bound


def test_the_bound_holds_where_the_factored_matrix_is_not_the_chains():
    """The relation is formed, not assumed: with I - 0.98 Q factored instead of I - Q (an
    LU that solves another system) the space is a poor one, and the bound (from
    E = A V - V T - u c^T formed with the chain's A) still covers the error, where the
    true inverse's bound is far smaller."""
    q, exits, arrays, start, truth = open_problem(first=200)
    _, true_bound, _ = _closure(arrays, q, exits, start, 200, 3000, 16, _inverse_of(q))
    reached, bound, out = _closure(arrays, q, exits, start, 200, 3000, 16,
                                   _inverse_of(q, 0.98 * q))
    error = np.abs(out[200:] - truth[200:]).sum()
    assert reached == 3000
    assert error > 1e3 * true_bound
    assert error <= bound


def test_the_closed_tails_blocks_are_its_lags():
    """The tail taken TAIL_BLOCK lags at a time from one projected vector: each lag's
    exit, the passes down summed and the lag it stops at are those of y_(k+1) = T y_k lag
    by lag, and its bound is at least the lag-by-lag one (|T^j y| <= |T^j| |y|), within a
    few times it; in whole blocks, a block cut short by the end, and one cut by the stop."""
    rng = np.random.default_rng(7)
    dim, levels = 6, 3
    small = rng.uniform(0, 0.005, (dim, dim)) + np.diag(rng.uniform(0.9, 0.97, dim))
    exits, mass = rng.uniform(0, 1, dim), rng.uniform(0.5, 1, dim)
    direction, rounding = rng.uniform(-1, 1, dim), rng.uniform(0, 1e-12, dim)
    falls_on = rng.uniform(0, 1, (levels, dim))
    for max_steps, tol in ((10 * tc.TAIL_BLOCK, 0.0), (7 * tc.TAIL_BLOCK + 5, 0.0),
                           (100_000, 1e-6)):
        first = 3
        out = np.zeros(max_steps)
        falls = np.zeros(levels)
        reached, bound = tc._closed_tail(small, dim, 1e-9, direction, rounding, exits,
                                         falls_on, mass, 2.0, first, tol, np.inf, max_steps,
                                         out, falls, 0.0, 0.99)
        y = np.zeros(dim)
        y[0] = 2.0
        expected = np.zeros(max_steps)
        summed = np.zeros(dim)
        lag_bound = 0.0
        stop = max_steps
        for k in range(first, max_steps):
            expected[k] = exits @ y
            summed += y
            lag_bound += 1e-9 * abs(direction @ y) + rounding @ np.abs(y)
            y = small @ y
            if mass @ y < tol:
                stop = k + 1
                break
        assert reached == stop
        np.testing.assert_allclose(out[first:stop], expected[first:stop], rtol=1e-12,
                                   atol=1e-15)
        np.testing.assert_allclose(falls, falls_on @ summed, rtol=1e-12)
        assert lag_bound <= bound * (1 + 1e-12) and bound <= 10 * lag_bound
    assert 7 * tc.TAIL_BLOCK < stop < 100_000 and stop % tc.TAIL_BLOCK


def test_an_lu_in_the_levels_order_fills_only_its_envelope():
    """The envelope the choice rests on holds SuperLU's L and U in the natural order, on a
    level system of a chain (its pivots the diagonal); and a chain whose envelope is more
    than FILL_LIMIT lags is left to the Krylov space of Q."""
    p, up, down = slow_column(states=80, stay=0.9, seed=2, reach=4)
    p_up, p_down, p_stay = fp.split_by_pass(sp.csr_matrix(p), up, down)
    arrays = fp._transposed_parts((p_down, p_stay, p_up))
    live = np.ones((80, 5), np.bool_)
    indptr, indices, data = fp._level_system(*arrays, live)
    n = indptr.size - 1
    factors = splu(sp.csc_matrix((data, indices, indptr), shape=(n, n)),
                   permc_spec="NATURAL")
    assert np.array_equal(factors.perm_r, np.arange(n))
    fill = factors.L.nnz + factors.U.nnz - n
    envelope = si.envelope(indptr, indices)
    assert fill <= envelope
    dense = np.zeros((n, n), bool)
    dense[indices, np.repeat(np.arange(n), np.diff(indptr))] = True
    rows = np.arange(n)
    first_row = np.array([np.flatnonzero(dense[:, j] | (rows == j))[0] for j in range(n)])
    first_col = np.array([np.flatnonzero(dense[i] | (rows == i))[0] for i in range(n)])
    assert envelope == n + (rows - first_row).sum() + (rows - first_col).sum()
    work = sum(array.size for array in arrays[2::3]) * 5
    assert si.level_inverse(indptr, indices, data, live, work) is not None
    assert si.level_inverse(indptr, indices, data, live, envelope // (si.FILL_LIMIT + 1)) \
        is None
    with pytest.MonkeyPatch.context() as m:          # nor one whose LU would not fit
        m.setattr(si, "LU_BYTES", 12 * envelope - 1)
        assert si.level_inverse(indptr, indices, data, live, work) is None


def test_a_chain_singular_in_floating_point_keeps_the_space_of_q():
    """A closed 2-cycle that leaks 1e-17 a lag makes I - Q exactly singular in floating
    point: SuperLU refuses it, and the RTD goes on without the inverse (half the entries
    never leave: unresolved), as it did before there was one."""
    states = 40
    rng = np.random.default_rng(1)
    q = np.zeros((states, states))
    block = rng.uniform(0, 1, (states - 2, states - 2))
    block *= 0.99 / block.sum(axis=1, keepdims=True)
    q[2:, 2:] = block
    exits = np.zeros(states)
    exits[2:] = 0.01
    q[0, 1] = q[1, 0] = 1.0
    q[1, 2] = 1e-17
    entry = np.zeros(states)
    entry[0] = entry[5] = 0.5
    system = sp.csc_matrix(np.identity(states) - q)
    system.sort_indices()
    arguments = (system.indptr.astype(np.int64), system.indices.astype(np.int64),
                 system.data, np.ones((states, 1), np.bool_))
    with pytest.raises(RuntimeError):
        si.LevelInverse(*arguments)
    with pytest.raises(RuntimeError):
        si.LevelInverse(*arguments, blocks=True)
    assert si.level_inverse(*arguments, work=10 ** 9) is None
    rtd = fp.open_rtd(q, exits, entry, 0.01, max_steps=5000)
    assert rtd.unresolved == pytest.approx(0.5, abs=1e-9)


def _column_system(levels, states=80, live=None):
    p, up, down = slow_column(states=states, stay=0.9, seed=2, reach=4)
    p_up, p_down, p_stay = fp.split_by_pass(sp.csr_matrix(p), up, down)
    arrays = fp._transposed_parts((p_down, p_stay, p_up))
    if live is None:
        live = np.ones((states, levels), np.bool_)
    work = sum(array.size for array in arrays[2::3]) * levels
    return fp._level_system(*arrays, live), live, work


@pytest.mark.parametrize("levels", [1, 2, 7])
def test_the_block_factorisation_solves_the_level_system(levels):
    """By blocks (one level: no boundary system; two: a single block step; seven), the
    solve with I - Q^T leaves a residual of round-off and equals SuperLU's to 1e-12; it
    is the one taken for such a chain on several levels (whose passes span the envelope
    across a level), not on one."""
    (indptr, indices, data), live, work = _column_system(levels)
    blocks = si.LevelInverse(indptr, indices, data, live, blocks=True)
    sparse = si.LevelInverse(indptr, indices, data, live)
    assert isinstance(blocks.factors, si.LevelBlocks)
    assert blocks.factors.boundary.size == (0 if levels == 1 else 8)   # 4 + 4 cells
    n = indptr.size - 1
    identity_less_a = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    x = np.random.default_rng(5).random(n)
    y = blocks.solve(x)
    assert np.abs(identity_less_a @ y - x).max() <= 1e-12 * np.abs(x).max()
    assert np.abs(y - sparse.solve(x)).max() <= 1e-12 * np.abs(y).max()
    chosen = si.level_inverse(indptr, indices, data, live, work)
    # one level of a banded column: its envelope is small, the sparse LU cheaper
    assert isinstance(chosen.factors, si.LevelBlocks) == (levels > 1)
    # and with I - Q itself (the moments' solves), its boundary eliminated on demand
    direct = si.LevelBlocks(indptr, indices, data, 80, levels, trans="N")
    for factors in (blocks.factors, direct):
        z = factors.solve(x, "N")
        assert np.abs(identity_less_a.T @ z - x).max() <= 1e-12 * np.abs(x).max()
        assert np.abs(z - sparse.factors.solve(x, "N")).max() <= 1e-12 * np.abs(z).max()
    with pytest.raises(ValueError, match="trans"):
        direct.solve(x, "H")


def test_the_moments_by_blocks_are_superlus(monkeypatch):
    """rtd_moments on a column's chain on eight lap deficits: by blocks (its default) the
    same figures as by SuperLU to 1e-12."""
    p, up, down = slow_column(states=60, stay=0.9, seed=2, reach=4)
    p_up, p_down, p_stay = fp.split_by_pass(sp.csr_matrix(p), up, down)
    entry = np.asarray(p_up.sum(axis=0)).ravel()
    entry /= entry.sum()
    by_blocks = fp.rtd_moments(p_up, p_down, p_stay, LAG, 8, entry)
    calls = []

    def refused(*args, **kwargs):
        calls.append(args)
        raise RuntimeError("refused")

    monkeypatch.setattr(si, "LevelBlocks", refused)
    by_superlu = fp.rtd_moments(p_up, p_down, p_stay, LAG, 8, entry)
    assert calls                               # the blocks were tried, and refused
    assert by_blocks == pytest.approx(by_superlu, rel=1e-12)


def test_superlu_factors_where_blocks_do_not_apply(monkeypatch):
    """A pair not live, a chain above BLOCK_STATES, one whose dense solve would cost more
    than BLOCK_ADVANTAGE times the envelope, or blocks that refuse: SuperLU's LU."""
    (indptr, indices, data), live, work = _column_system(5)
    assert isinstance(si.level_inverse(indptr, indices, data, live, work).factors,
                      si.LevelBlocks)
    monkeypatch.setattr(si, "BLOCK_STATES", 79)
    assert not isinstance(si.level_inverse(indptr, indices, data, live, work).factors,
                          si.LevelBlocks)
    monkeypatch.setattr(si, "BLOCK_STATES", 80)
    monkeypatch.setattr(si, "BLOCK_ADVANTAGE", 80 * 80 * 5 / si.envelope(indptr, indices) - 1e-9)
    assert not isinstance(si.level_inverse(indptr, indices, data, live, work).factors,
                          si.LevelBlocks)
    monkeypatch.setattr(si, "BLOCK_ADVANTAGE", 8)
    live = np.ones((80, 5), np.bool_)
    live[3, 4] = False
    (indptr, indices, data), live, work = _column_system(5, live=live)
    assert not isinstance(si.level_inverse(indptr, indices, data, live, work).factors,
                          si.LevelBlocks)
    with pytest.raises(ValueError, match="every pair live"):
        si.LevelInverse(indptr, indices, data, live, blocks=True)
    # blocks that refuse (I - P_stay singular in floating point): SuperLU decides, as
    # factor_levels does for the moments
    (indptr, indices, data), live, work = _column_system(5)

    def refused(*args, **kwargs):
        raise RuntimeError("refused")

    blocks = si.LevelBlocks
    monkeypatch.setattr(si, "LevelBlocks", refused)
    fallback = si.level_inverse(indptr, indices, data, live, work)
    assert fallback is not None and not isinstance(fallback.factors, blocks)
