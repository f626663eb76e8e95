"""The exact RTD's tail closed by a Krylov projection (markov.tail_closure): the same RTD as
the lag-by-lag propagation to within its tolerance, a bound on its error that holds even
where the projection is poor, and the dense block elimination of the entry chain equal to
the sparse one."""

import numpy as np
import pytest
import scipy.sparse as sp

import cfbmarkov.markov.entry_chain as entry_chain
import cfbmarkov.markov.first_passage as fp
import cfbmarkov.markov.tail_closure as tc

LAG = 0.05


def slow_column(states=24, stay=0.985, seed=3):
    """A periodic riser's chain of ``states`` states in a column whose residences last
    hundreds of lags: a lazy walk up and down the column (probability ``stay`` of staying
    put), random rates; the top state passes up through the top, the bottom one down
    through the bottom. Returns P and the up and down fractions."""
    rng = np.random.default_rng(seed)
    p = np.zeros((states, states))
    up, down = np.zeros_like(p), np.zeros_like(p)
    for i in range(states):
        move = 1.0 - stay
        rise = rng.uniform(0.45, 0.75) * move
        fall = move - rise
        p[i, i] += stay
        above, below = (i + 1) % states, (i - 1) % states
        p[i, above] += rise
        p[i, below] += fall
        if i == states - 1:
            up[i, above] = 1.0                    # through the top into the bottom state
        if i == 0:
            down[i, below] = 1.0                  # through the bottom into the top state
    return p, up, down


def without_closure(monkeypatch):
    monkeypatch.setattr(fp, "krylov_dimension", lambda *args: 0)


def test_the_closed_tail_is_the_propagated_one_within_its_tolerance(monkeypatch):
    p, up, down = slow_column()
    taken = []
    original = fp.try_closure

    def counting(*args, **kwargs):
        result = original(*args, **kwargs)
        taken.append(result[0] >= 0)
        return result

    monkeypatch.setattr(fp, "try_closure", counting)
    closed = fp.exact_rtd(p, up, down, LAG)
    assert any(taken)                                       # the closure was taken
    without_closure(monkeypatch)
    taken.clear()
    propagated = fp.exact_rtd(p, up, down, LAG)
    assert not taken
    assert propagated.probability.size > 2 * tc.FIRST_TRY     # a long tail
    size = max(closed.probability.size, propagated.probability.size)
    a = np.zeros(size)
    b = np.zeros(size)
    a[:closed.probability.size] = closed.probability
    b[:propagated.probability.size] = propagated.probability
    assert np.abs(a - b).sum() <= 1e-10
    assert closed.mean == pytest.approx(propagated.mean, rel=1e-9)
    assert closed.sd == pytest.approx(propagated.sd, rel=1e-8)
    assert closed.unresolved <= propagated.unresolved + 1e-10


def open_column(states=30, stay=0.98, seed=5):
    """An open riser's Q = diag(1 - r) P and r for a column leaving through its top."""
    p, _, _ = slow_column(states, stay, seed)
    p[0, -1] = 0.0                                 # no wrap-around through the bottom
    p[0] /= p[0].sum()
    exits = np.zeros(states)
    exits[-1] = p[-1, 0]                            # leaving through the top
    q = p.copy()
    q[-1, 0] = 0.0
    entry = np.zeros(states)
    entry[0] = 1.0
    return q, exits, entry


def test_an_open_risers_closed_tail_is_its_matrix_powers():
    q, exits, entry = open_column()
    rtd = fp.open_rtd(q, exits, entry, LAG)
    v = entry.copy()
    direct = []
    while v.sum() >= 1e-10:
        direct.append(v @ exits)
        v = v @ q
    direct = np.array(direct)
    assert direct.size > 2 * tc.FIRST_TRY
    assert rtd.probability.size == pytest.approx(direct.size, abs=2)
    n = min(rtd.probability.size, direct.size)
    assert np.abs(rtd.probability[:n] - direct[:n]).max() < 1e-13
    assert np.abs(rtd.probability[:n] - direct[:n]).sum() < 1e-10


@pytest.mark.parametrize("dimension", [2, 4])
def test_the_bound_holds_where_the_projection_is_poor(dimension):
    """A Krylov space of 2 or 4 vectors cannot hold the tail 40 lags in: the closed tail is
    off by far more than round-off, and the bound it returns still covers the error."""
    q, exits, entry = open_column()
    n = q.shape[0]
    nothing = sp.csr_matrix((n, n))
    arrays = fp._transposed_parts((nothing, sp.csr_matrix(q), nothing))
    first, steps = 40, 3000
    v = entry.copy()
    truth = np.zeros(steps)
    for k in range(steps):
        if k == first:
            start = v.copy()
        truth[k] = v @ exits
        v = v @ q
    out = np.zeros(steps)
    falls = np.zeros(1)
    reached, bound = tc.try_closure(arrays, np.ones((n, 1), np.bool_), start.reshape(n, 1),
                                    exits, np.zeros(n), first, 0.0, np.inf, steps, out,
                                    falls, dimension)
    assert reached == steps
    error = np.abs(out[first:] - truth[first:]).sum()
    assert error > 1e-6                              # a poor closure ...
    assert error <= bound                            # ... whose bound says so


def test_next_try_extrapolates_the_bound():
    assert tc.next_try([(512, 1e-5)], 1e-10) == 1024
    # 1e-5 at 512 lags, 1e-7 at 1024: 3.3e-11 needs 1024 + 512 * ln(3000) / ln(100) lags
    assert tc.next_try([(512, 1e-5), (1024, 1e-7)], 1e-10) == 1024 + int(
        np.ceil(512 * np.log(3000.0) / np.log(100.0)))
    assert tc.next_try([(512, 1e-5), (1024, 2e-5)], 1e-10) == 2048      # not falling
    assert tc.next_try([(512, 1e-5), (1024, 1e-12)], 1e-10) == 1024 + 64  # at least 64
    assert tc.next_try([(512, 1.0), (1024, 0.5)], 1e-10) == 2048          # at most twice


def test_dense_block_elimination_is_the_sparse_one(monkeypatch):
    p, up, down = slow_column(states=40, stay=0.6, seed=11)
    rng = np.random.default_rng(2)
    p = p + np.where(p > 0, 0.0, rng.uniform(0, 1, p.shape) < 0.1) * 0.01   # more links
    p /= p.sum(axis=1, keepdims=True)
    p_up, p_down, p_stay = fp.split_by_pass(sp.csr_matrix(p), up, down)
    levels = 6
    live = np.ones((levels, p.shape[0]), bool)
    live[3, 5] = False                               # a pair that cannot reach the top
    entries = np.flatnonzero(np.asarray(p_up.sum(axis=0)).ravel() > 0)
    dense = entry_chain.entry_matrix(p_up, p_down, p_stay, live, entries, True, True)
    monkeypatch.setattr(entry_chain, "DENSE_STATES", 0)
    sparse = entry_chain.entry_matrix(p_up, p_down, p_stay, live, entries, True, True)
    np.testing.assert_allclose(dense[0], sparse[0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(dense[1], sparse[1], rtol=0, atol=1e-13)
    assert dense[2] == pytest.approx(sparse[2], rel=1e-10)
    assert dense[1].max() > 1e-6                     # something falls below the levels
