"""Estimators: recovery of a known chain, the paper's Eq. 2-4 by hand, deeptime cross-check."""

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.errors import InputError
from cfbmarkov.markov import (CellGrid, MaximumLikelihoodEstimator, PaperEstimator, discretize,
                              estimator_from_name, fit_model)


def test_mle_recovers_known_chain_within_sampling_error(markov_flow, markov_run):
    true = synthetic.cell_chain(markov_flow)
    grid = markov_flow.grid
    model = MaximumLikelihoodEstimator(grid, markov_flow.lag).fit(
        discretize(markov_run, grid, markov_flow.lag, (0, 8)))
    n_i = model.counts.sum(axis=1, keepdims=True)
    p = true.transition_matrix
    sigma = np.sqrt(p * (1 - p) / np.maximum(n_i, 1)) + 1e-12
    z = np.abs(model.transition_matrix - p) / sigma
    visited = (n_i[:, 0] > 200)
    assert visited.sum() > 0.9 * grid.n_states
    assert np.max(z[visited]) < 6.0
    # nothing is estimated where the generator has no transition
    assert np.all(model.transition_matrix[p == 0] == 0)


def test_fitted_model_exact_rtd_matches_generator(markov_flow, markov_run):
    true = synthetic.cell_chain(markov_flow)
    for name in ("mle", "paper"):
        model = fit_model(markov_run, markov_flow.grid, markov_flow.lag, estimator=name)
        assert model.rtd().mean == pytest.approx(true.rtd().mean, rel=0.02)
        assert model.rtd().sd == pytest.approx(true.rtd().sd, rel=0.05)


def _hand_example(tmp_path, write_states):
    # 1 column x 2 rows; 3 particles; 4 frames one second apart
    states = [[0, 0, 1],
              [0, 1, 1],
              [1, 1, 1],
              [1, 1, 1]]
    return write_states(tmp_path / "hand.h5", states, columns=1, rows=2)


def test_paper_estimator_hand_worked(tmp_path, write_states):
    """P'(0) = [[1/2, 1/2], [0, 1]], P'(1) = [[0, 1], [0, 1]], P'(2) = [[0, 0], [0, 1]]
    (state 0 empty at t = 2). Plain average row 0 = [1/6, 1/2], divided by its sum 2/3:
    [1/4, 3/4]. The pooled counts give [1/3, 2/3] instead."""
    path = _hand_example(tmp_path, write_states)
    grid = CellGrid(1, 2, width=1.0, height=2.0)
    discrete = discretize(path, grid, 1.0)
    paper = PaperEstimator(grid, lag=1.0).fit(discrete)
    mle = MaximumLikelihoodEstimator(grid, lag=1.0).fit(discrete)
    np.testing.assert_allclose(paper.transition_matrix, [[0.25, 0.75], [0.0, 1.0]])
    np.testing.assert_allclose(mle.transition_matrix, [[1 / 3, 2 / 3], [0.0, 1.0]])
    np.testing.assert_array_equal(paper.counts, [[1, 2], [0, 6]])
    np.testing.assert_array_equal(paper.counts, mle.counts)
    assert paper.frame_pairs == 3 and paper.n_transitions == 9


def test_lag_of_two_frames_counts_sliding_pairs(tmp_path, write_states):
    path = _hand_example(tmp_path, write_states)
    model = fit_model(path, CellGrid(1, 2, 1.0, 2.0), 2.0)
    # pairs (0,2) and (1,3): 0->1, 0->1, 1->1 ; 0->1, 1->1, 1->1
    np.testing.assert_array_equal(model.counts, [[0, 3], [0, 3]])


def test_unvisited_states_stay_in_place_and_are_reported(tmp_path, write_states):
    states = [[0, 1], [1, 0], [0, 1]]          # state 2 and 3 never visited (2x2 grid)
    path = write_states(tmp_path / "u.h5", states, columns=2, rows=2)
    model = fit_model(path, CellGrid(2, 2, 1.0, 2.0), 1.0)
    np.testing.assert_array_equal(model.unvisited_states, [2, 3])
    assert model.transition_matrix[2, 2] == 1 and model.transition_matrix[3, 3] == 1
    assert "states never visited: 2 of 4 (row 1)" in model.summary()


def test_boundary_passes_are_counted_by_direction(tmp_path, write_states):
    # 1 x 4 grid; particle 0 rises 3 -> 0 through the top, particle 1 falls 0 -> 3
    states = [[3, 0], [0, 3], [1, 3]]
    path = write_states(tmp_path / "p.h5", states, columns=1, rows=4, height=4.0)
    model = fit_model(path, CellGrid(1, 4, 1.0, 4.0), 1.0)
    assert model.counts_up[3, 0] == 1 and model.counts_up.sum() == 1
    assert model.counts_down[0, 3] == 1 and model.counts_down.sum() == 1
    assert model.up_fraction[3, 0] == 1.0 and model.up_fraction[0, 1] == 0.0


def test_mle_equals_deeptime(markov_flow, markov_run):
    import deeptime
    from deeptime.markov import TransitionCountEstimator
    from deeptime.markov.msm import MaximumLikelihoodMSM

    grid = markov_flow.grid
    discrete = discretize(markov_run, grid, 2 * markov_flow.lag, (1, 5))
    ours = MaximumLikelihoodEstimator(grid, 2 * markov_flow.lag).fit(discrete)
    dtrajs = discrete.trajectories()
    counts = TransitionCountEstimator(lagtime=2, count_mode="sliding",
                                      n_states=grid.n_states).fit(dtrajs).fetch_model()
    np.testing.assert_array_equal(counts.count_matrix, ours.counts)
    msm = MaximumLikelihoodMSM(reversible=False).fit(counts).fetch_model()
    symbols = msm.count_model.state_symbols
    assert symbols.size == grid.n_states, deeptime.__version__
    np.testing.assert_allclose(ours.transition_matrix[np.ix_(symbols, symbols)],
                               msm.transition_matrix, atol=1e-12)


def test_bad_lag_and_window(markov_run, markov_flow):
    with pytest.raises(InputError, match="not a whole multiple of the frame interval"):
        fit_model(markov_run, markov_flow.grid, 0.03)
    with pytest.raises(InputError, match="outside the data"):
        fit_model(markov_run, markov_flow.grid, 0.025, (5, 12))
    with pytest.raises(InputError, match="domain|covers"):
        fit_model(markov_run, CellGrid(4, 16, 0.1, 0.95), 0.025)
    with pytest.raises(InputError, match="unknown estimator"):
        estimator_from_name("bayes", markov_flow.grid)


def test_estimators_take_discrete_trajectories_made_at_their_lag(markov_run, markov_flow):
    """Arrays in, model out: a path is refused with the way to discretise it, and discrete
    trajectories made at another lag or in another state space are refused, not refitted."""
    grid = markov_flow.grid
    est = MaximumLikelihoodEstimator(grid, lag=0.025)
    with pytest.raises(InputError, match="discretize"):
        est.fit(markov_run)
    with pytest.raises(InputError, match="lag of 0.05 s"):
        est.fit(discretize(markov_run, grid, 0.05, (0, 4)))
    with pytest.raises(InputError, match="state space"):
        est.fit(discretize(markov_run, CellGrid(2, 8, grid.width, grid.height), 0.025, (0, 4)))
    # two windows pool their counts exactly
    a, b = (discretize(markov_run, grid, 0.025, w) for w in ((0, 2), (3, 5)))
    both = est.fit([a, b])
    np.testing.assert_array_equal(both.counts, est.fit(a).counts + est.fit(b).counts)


@pytest.mark.parametrize("name", ["cells", "cells-direction", "cells-velocity", "cells-previous"])
def test_sparse_counts_and_split_chain_equal_the_dense_ones(tmp_path, markov_flow, name):
    """Cross-validation's sparse path (counts as CSR, the chain split by pass direction
    without an S x S array) gives the dense path's counts exactly and its chain and exact
    RTD to rounding, for both estimators, with states never left filled from their cell
    (40 particles leave some) and with the largest connected set."""
    from cfbmarkov.markov.counting import count_transitions
    from cfbmarkov.markov.estimate import estimator_from_name, pass_fractions
    from cfbmarkov.markov.first_passage import exact_rtd, rtd_of_split_chain, split_by_pass
    from cfbmarkov.markov.spaces import state_space_from_name

    space = state_space_from_name(name, markov_flow.columns, markov_flow.rows,
                                  markov_flow.width, markov_flow.height)
    run = tmp_path / "few.h5"       # 40 particles: states with memory go unvisited
    synthetic.write_run(run, markov_flow, 40, 1.2, seed=3)
    window = discretize(run, space, 0.05, (0.2, 1.2))
    checked_fill = False
    for frame_average in (False, True):
        dense = count_transitions(window, frame_average=frame_average)
        sparse = count_transitions([window, window], frame_average=frame_average, sparse=True)
        doubled = count_transitions([window, window], frame_average=frame_average)
        for field in ("counts", "counts_up", "counts_down", "frame_average_sum"):
            if getattr(dense, field) is None:
                assert getattr(sparse, field) is None
                continue
            # two windows: summed window by window (the float sums to rounding)
            assert np.allclose(getattr(sparse, field).toarray(), getattr(doubled, field),
                               rtol=1e-14, atol=0)
        assert np.array_equal(sparse.occupied_frames, doubled.occupied_frames)
        assert sparse.frame_pairs == doubled.frame_pairs == 2 * dense.frame_pairs
        sparse = count_transitions(window, frame_average=frame_average, sparse=True)
        for field in ("counts", "counts_up", "counts_down", "frame_average_sum"):
            if getattr(dense, field) is not None:       # one window: the same bits
                assert np.array_equal(getattr(sparse, field).toarray(), getattr(dense, field))
        estimators = ["mle", "paper"] if frame_average else ["mle"]
        for est_name in estimators:
            for connected in (False, True):
                est = estimator_from_name(est_name, window.state_space, 0.05, connected)
                matrix, fractions = est.chain(dense)
                up, down = fractions if fractions is not None else pass_fractions(dense)
                expected = split_by_pass(matrix, up, down)
                got = est.split_chain(sparse)
                for a, b in zip(got, expected):
                    assert np.abs(a.toarray() - b.toarray()).max() < 1e-14
                total = (got[0] + got[1] + got[2]).toarray()
                assert np.allclose(total.sum(axis=1), 1.0, atol=1e-13)
                checked_fill |= fractions is not None
                rtd = rtd_of_split_chain(*got, 0.05, entry=dense.counts_up.sum(axis=0) + 1e-3)
                ref = exact_rtd(matrix, up, down, 0.05, entry=dense.counts_up.sum(axis=0) + 1e-3)
                assert rtd.probability.size == ref.probability.size
                assert np.abs(rtd.probability - ref.probability).max() < 1e-12
    # 40 particles leave some states of a visited cell never left: the fill was checked
    assert checked_fill == (name in ("cells-velocity", "cells-previous"))


def test_sparse_counts_of_an_open_riser_count_each_face_crossing_once(tmp_path, markov_flow):
    """Open riser, two windows counted together: the sparse counts hold the dense ones'
    exits, entries and censored tracks exactly once, and the same transitions."""
    from cfbmarkov.markov.counting import count_transitions

    path = synthetic.write_open_run(tmp_path / "open.h5", markov_flow, 200, 1.5, seed=4)
    windows = [discretize(path, markov_flow.grid, markov_flow.lag, w)
               for w in ((0.0, 0.7), (0.7, 1.5))]
    dense = count_transitions(windows, frame_average=False)
    sparse = count_transitions(windows, frame_average=False, sparse=True)
    assert dense.faces.exits.sum() > 0 and dense.faces.entries.sum() > 0
    for field in ("exits", "entries", "vanished", "appeared"):
        assert np.array_equal(getattr(sparse.faces, field), getattr(dense.faces, field))
    assert np.array_equal(sparse.counts.toarray(), dense.counts)


def test_sparse_count_kernel_is_the_same_for_any_number_of_chunks():
    """The threads' frame and row chunks (1, 2, 3 or 7) give the same counts, frame-average
    sums (bit for bit: every row is summed in time order) and occupied frames."""
    from cfbmarkov.markov.counting import _sparse_count_kernel

    rng = np.random.default_rng(5)
    n_states = 40
    states = (np.cumsum(rng.integers(-1, 2, size=(31, 300)), axis=0) % n_states).astype(np.int32)
    states[rng.random(states.shape) < 0.05] = -1
    vertical = rng.uniform(0.0, 1.0, size=states.shape)
    results = []
    for chunks in (1, 2, 3, 7):
        occupied = np.zeros(n_states, np.int64)
        out = _sparse_count_kernel(states, vertical, 2, 1.0, n_states, True, occupied, chunks)
        results.append((out, occupied))
    (first, occupied_first) = results[0]
    assert first[6] == 29 and first[2].sum() == ((states[:-2] >= 0) & (states[2:] >= 0)).sum()
    for out, occupied in results[1:]:
        for a, b in zip(first[:6], out[:6]):
            assert np.array_equal(a, b)
        assert out[6] == first[6] and np.array_equal(occupied, occupied_first)
