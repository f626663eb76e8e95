"""The model: exact RTD against analytical and Monte Carlo results, propagation, Monte Carlo,
prediction files, persistence."""

import numba
import numpy as np
import pytest
from scipy import stats

from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov import CellGrid, MarkovModel, fit_model
from cfbmarkov.markov.connectivity import states_reaching
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import lap_increments


def ladder_model(rows, p_up, p_fall=0.0, lag=0.01):
    """1 column: move one row up with p_up, from row 0 fall through the bottom with
    p_fall, else stay. Row rows-1 -> 0 passes up through the top."""
    s = rows
    p = np.zeros((s, s))
    up = np.zeros((s, s))
    down = np.zeros((s, s))
    for r in range(rows):
        p[r, (r + 1) % rows] += p_up
        if r == 0 and p_fall > 0:
            p[0, rows - 1] += p_fall
            down[0, rows - 1] = 1.0
        p[r, r] += 1.0 - p_up - (p_fall if r == 0 else 0.0)
    up[rows - 1, 0] = 1.0
    zeros = np.zeros((s, s), np.int64)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(1, rows, 0.1, 1.0), lag,
                       estimator="given", pass_fractions=(up, down))


def test_exact_rtd_is_negative_binomial_for_a_ladder():
    n, p, lag = 10, 0.4, 0.01
    model = ladder_model(n, p, lag=lag)
    rtd = model.rtd()
    k = np.arange(1, rtd.probability.size + 1)
    expected = stats.nbinom.pmf(k - n, n, p)     # k trials for n successes
    np.testing.assert_allclose(rtd.probability, expected, atol=1e-12)
    assert rtd.mean == pytest.approx(lag * n / p, rel=1e-8)
    assert rtd.sd == pytest.approx(lag * np.sqrt(n * (1 - p)) / p, rel=1e-6)
    assert rtd.unresolved < 1e-9
    assert rtd.entry_distribution[0] == pytest.approx(1.0)


@pytest.mark.parametrize("lag", [0.025, 0.01, 0.1])
def test_histogram_puts_whole_lags_in_the_bin_they_start(lag):
    """Bins three lags wide, whose edges carry round-off (3 * 0.025 = 0.07500000000000001):
    a residence of k lags lies in bin k // 3, as the sample histogram's edge rule puts it."""
    model = ladder_model(10, 0.4, lag=lag)
    rtd = model.rtd()
    edges, probability = rtd.histogram(3 * lag, 60 * lag)
    k = np.arange(1, rtd.probability.size + 1)
    share = rtd.probability / rtd.probability.sum()
    expected = np.bincount(k // 3, weights=share)[:probability.size]
    np.testing.assert_allclose(probability, expected, rtol=0, atol=1e-15)


def _walk(model, start_states, steps, rng):
    """Walkers of ``model``'s chain (dense P, pass fractions 0 or 1): states and lap counters
    [steps + 1, N] (independent of the package's Monte Carlo)."""
    p = np.asarray(model.transition_matrix)
    cumulative = np.cumsum(p, axis=1)
    states = np.empty((steps + 1, start_states.size), np.int64)
    laps = np.zeros((steps + 1, start_states.size), np.int64)
    states[0] = start_states
    for t in range(steps):
        i = states[t]
        j = np.minimum((rng.random(i.size)[:, None] > cumulative[i]).sum(axis=1), p.shape[0] - 1)
        states[t + 1] = j
        laps[t + 1] = laps[t] + np.rint(model.up_fraction[i, j] - model.down_fraction[i, j])
    return states, laps


def two_column_model(rows=4, to_fall=0.25, to_rise=0.3, lag=0.01):
    """Column 0 rises a row a lag (through the top: an up pass), column 1 falls a row a lag
    (through the bottom: a down pass); each switches to the other with ``to_fall`` /
    ``to_rise``: a net upflow whose particles often fall a lap before they climb back."""
    s = 2 * rows
    p, up, down = np.zeros((s, s)), np.zeros((s, s)), np.zeros((s, s))
    for r in range(rows):
        rising, falling = 2 * r, 2 * r + 1
        above, below = 2 * ((r + 1) % rows), 2 * ((r - 1) % rows) + 1
        p[rising, above] += 1 - to_fall
        p[rising, falling] += to_fall
        p[falling, below] += 1 - to_rise
        p[falling, rising] += to_rise
        up[rising, above] = float(r == rows - 1)
        down[falling, below] = float(r == 0)
    zeros = np.zeros((s, s), np.int64)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(2, rows, 0.1, 1.0), lag,
                       estimator="given", pass_fractions=(up, down))


@pytest.mark.parametrize("falls", [False, True])
def test_the_rtd_a_window_sees_counts_records_from_its_first_frame(falls):
    """A window's samples count records of the lap counter from its first frame: with falls
    through the bottom, a particle below its past maximum makes records that are not its
    history's, and the window's mean residence is longer than the intrinsic f(k) weighted
    by n_W - k says (in_window: 6.8 % here). model.rtd(window=W, occupancy=where the
    walkers start) equals the walkers' window samples within 3 standard errors; without
    falls it is the weighted f(k) to round-off."""
    from cfbmarkov.observed.residence import residence_times_from_laps

    model = two_column_model() if falls else ladder_model(10, 0.4, lag=0.01)
    window = 0.6                                        # 60 lags
    pi = np.asarray(model.stationary_distribution)
    seen = model.rtd(window=window, occupancy=pi)
    weighted = model.rtd().in_window(window)
    if not falls:
        np.testing.assert_allclose(seen.probability, weighted.probability, rtol=0, atol=1e-13)
        return
    rng = np.random.default_rng(7)
    start = rng.choice(pi.size, size=40_000, p=pi)
    _, laps = _walk(model, start, 60, rng)
    samples = residence_times_from_laps(0.01 * np.arange(61), laps)
    se = samples.std() / np.sqrt(samples.size)
    assert abs(samples.mean() - seen.mean) < 3 * se, (samples.mean(), seen.mean, se)
    assert abs(samples.std() - seen.sd) < 0.01 * seen.sd
    assert samples.mean() - weighted.mean > 10 * se     # the weighted f(k) falls short


def _samples_from_laps(laps, lag):
    """Residence times from lap counters [T, N] by SPEC section 3, written independently."""
    out = []
    for series in laps.T:
        best, last = series[0], None
        for t in range(1, series.size):
            while series[t] > best:
                best += 1
                if last is not None:
                    out.append((t - last) * lag)
                last = t
    return np.asarray(out)


def test_exact_rtd_with_falls_matches_monte_carlo_in_a_window():
    model = ladder_model(8, 0.5, p_fall=0.15, lag=0.01)
    n_steps = 300
    rng = np.random.default_rng(3)
    start = rng.choice(model.n_states, size=4000, p=model.stationary_distribution)
    _, laps = model.monte_carlo(start, n_steps, seed=5)
    samples = _samples_from_laps(laps, model.lag)
    exact = model.rtd(window=n_steps * model.lag)
    se = samples.std(ddof=1) / np.sqrt(samples.size)
    assert abs(samples.mean() - exact.mean) < 5 * se
    assert samples.std(ddof=1) == pytest.approx(exact.sd, rel=0.05)
    # the whole distribution: Kolmogorov distance between sample and exact CDFs
    cdf_exact = np.cumsum(exact.probability)
    k = np.rint(samples / model.lag).astype(int)
    cdf_sample = np.cumsum(np.bincount(k, minlength=cdf_exact.size + 1)[1:]) / k.size
    assert np.max(np.abs(cdf_sample[: cdf_exact.size] - cdf_exact)) < 1.63 / np.sqrt(k.size) * 1.5
    # falling out of the bottom lengthens residences beyond the no-fall ladder
    assert model.rtd().mean > ladder_model(8, 0.5, lag=0.01).rtd().mean


def test_exact_rtd_from_a_given_entry_distribution():
    """Started from the chain's own stationary entry distribution, the RTD is the default one;
    from another entry distribution (a particle entering lower rungs) it differs."""
    from cfbmarkov.markov import exact_rtd

    model = ladder_model(8, 0.5, p_fall=0.15, lag=0.01)
    own = model.rtd()
    given = exact_rtd(model.transition_matrix, model.up_fraction, model.down_fraction,
                      model.lag, entry=own.entry_distribution * 7.0)   # normalised inside
    np.testing.assert_allclose(given.probability, own.probability, atol=1e-12)
    np.testing.assert_allclose(given.entry_distribution, own.entry_distribution, atol=1e-12)
    lower = np.zeros(model.n_states)
    lower[model.n_states // 2] = 1.0
    later = exact_rtd(model.transition_matrix, model.up_fraction, model.down_fraction,
                      model.lag, entry=lower)
    assert later.mean < own.mean - 0.01      # halfway up, a residence is shorter
    with pytest.raises(CfbmarkovError, match="entry distribution"):
        exact_rtd(model.transition_matrix, model.up_fraction, model.down_fraction, model.lag,
                  entry=np.zeros(model.n_states))


def test_window_censoring_weights_short_residences():
    model = ladder_model(10, 0.4)
    intrinsic, seen = model.rtd(), model.rtd(window=0.5)
    assert seen.mean < intrinsic.mean
    assert seen.times.max() < 0.5
    with pytest.raises(Exception, match="fits in a window"):
        model.rtd(window=0.05)


def test_propagation_eq6_and_outflow_matches_rtd():
    model = ladder_model(6, 0.3)
    s0 = np.zeros(6)
    s0[0] = 1.0
    hist = model.propagate(s0, 25)
    np.testing.assert_allclose(hist[25], s0 @ np.linalg.matrix_power(model.transition_matrix, 25))
    np.testing.assert_allclose(hist.sum(axis=1), 1.0)
    remaining = model.propagate(s0, 60, outflow=True).sum(axis=1)
    cdf = np.concatenate([[0.0], np.cumsum(model.rtd().probability)])[:61]
    np.testing.assert_allclose(remaining, 1.0 - cdf, atol=1e-12)


def test_outflow_of_a_periodic_riser_leaves_as_residences_end(markov_flow, markov_run):
    """With particles that fall out of the bottom (and come back at the top), the batch
    leaves where its residences end, not at its first pass up through the top: propagated
    from the exact RTD's entry distribution, the mass left is the RTD's survival to
    round-off (1e-12), while removing every pass up (what the maps did) loses more than
    a tenth of the batch too early; the maps' batch splits each bottom cell over its states as the window's
    particles entered them (cells: one state a cell, 1/m each)."""
    from cfbmarkov.markov.propagation import inlet_batch

    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag)
    assert model.counts_down.sum() > 0                 # particles do fall out of the bottom
    rtd = model.rtd()
    left = model.propagate(rtd.entry_distribution, 80, outflow=True).sum(axis=1)
    survival = np.concatenate([[1.0], 1.0 - np.cumsum(rtd.probability)])[:81]
    np.testing.assert_allclose(left, survival, atol=1e-12)
    every_pass = rtd.entry_distribution.copy()
    first_pass = [1.0]
    p = model.transition_matrix * (1.0 - model.up_fraction)
    for _ in range(80):
        every_pass = every_pass @ p
        first_pass.append(every_pass.sum())
    assert np.max(survival - np.asarray(first_pass)) > 0.1
    np.testing.assert_array_equal(inlet_batch(model), model.state_space.inlet_distribution())


def test_the_batch_of_a_state_space_with_memory_enters_as_particles_did(markov_flow,
                                                                       markov_run):
    """cells-direction: each bottom cell's 1/m is split over its rising and falling states
    by the window's landings of passes up through the top (particles enter rising), not
    evenly; a cell without landings keeps the even split."""
    from cfbmarkov.markov import PaperEstimator, discretize, state_space_from_name
    from cfbmarkov.markov.propagation import inlet_batch

    space = state_space_from_name("cells-direction", markov_flow.columns, markov_flow.rows,
                                  markov_flow.width, markov_flow.height)
    model = PaperEstimator(space, markov_flow.lag).fit(
        discretize(markov_run, space, markov_flow.lag, (1.0, 6.0)))
    batch = inlet_batch(model)
    cell = space.cell_of_state
    bottom = cell < space.cells_per_row
    landings = model.counts_up.sum(axis=0)
    assert batch.sum() == pytest.approx(1.0) and batch[~bottom].sum() == 0
    np.testing.assert_allclose(np.bincount(cell[bottom], batch[bottom]),
                               1.0 / space.cells_per_row)
    for c in range(space.cells_per_row):
        members = np.flatnonzero(cell == c)
        share = landings[members] / landings[members].sum()
        np.testing.assert_allclose(batch[members], share / space.cells_per_row)
    assert not np.allclose(batch, space.inlet_distribution())


def test_batch_injection_maps(markov_flow, markov_run):
    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag)
    maps = model.batch_injection_maps([0.0, 0.1, 0.25])
    assert maps.shape == (3, markov_flow.rows, markov_flow.columns)
    np.testing.assert_allclose(maps[0, 0], 1.0 / markov_flow.columns)
    assert maps[0, 1:].sum() == 0
    np.testing.assert_allclose(maps.sum(axis=(1, 2)), 1.0)
    rows_mean = [(m.sum(axis=1) * np.arange(markov_flow.rows)).sum() for m in maps]
    assert rows_mean[0] < rows_mean[1] < rows_mean[2]       # the batch rises
    with pytest.raises(InputError, match="whole multiple of the model's lag"):
        model.batch_injection_maps([0.01])


def test_monte_carlo_follows_the_matrix_and_is_reproducible(markov_flow, markov_run):
    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag)
    start = np.random.default_rng(0).integers(0, model.n_states, 20000)
    states, laps = model.monte_carlo(start, 50, seed=9)
    again, laps_again = model.monte_carlo(start, 50, seed=9)
    np.testing.assert_array_equal(states, again)
    np.testing.assert_array_equal(laps, laps_again)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        single, _ = model.monte_carlo(start, 50, seed=9)
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(states, single)
    assert not np.array_equal(states, model.monte_carlo(start, 50, seed=10)[0])
    counts = np.zeros((model.n_states, model.n_states))
    np.add.at(counts, (states[:-1].ravel(), states[1:].ravel()), 1)
    n_i = counts.sum(axis=1, keepdims=True)
    p = model.transition_matrix
    sigma = np.sqrt(p * (1 - p) / np.maximum(n_i, 1)) + 1e-12
    busy = n_i[:, 0] > 500
    assert np.max(np.abs(counts / np.maximum(n_i, 1) - p)[busy] / sigma[busy]) < 6.0


def test_predict_writes_a_trajectory_file(tmp_path, markov_flow, markov_run):
    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag, (0, 4))
    out = model.predict(markov_run, start=4.0, duration=1.0, seed=7, output=tmp_path / "pred.h5")
    # a prediction loaded as a model: named as one, with where its model is
    with pytest.raises(InputError, match=r"is a prediction \(a trajectory file\), not a "
                                         r"cfbmarkov model file: give the model file it was "
                                         r"predicted with"):
        MarkovModel.load(out)
    with Trajectories(out) as pred, Trajectories(markov_run) as run:
        assert pred.n_frames == 41 and pred.source == "markov-prediction"
        np.testing.assert_allclose(pred.times, 4.0 + 0.025 * np.arange(41))
        np.testing.assert_array_equal(pred.ids, run.ids)
        np.testing.assert_array_equal(pred.positions(0), run.positions(run.frame_index(4.0)))
        np.testing.assert_array_equal(pred.laps(0), run.laps(run.frame_index(4.0)))
        # Monte Carlo lap counters agree with the boundary passes of the written positions
        y, laps = pred.positions()[:, :, 1], pred.laps()
        passes = np.array([lap_increments(y[k - 1], y[k], pred.height) for k in range(1, 41)])
        np.testing.assert_array_equal(np.diff(laps, axis=0), passes)
        assert np.abs(np.diff(laps, axis=0)).sum() > 100
        attached = MarkovModel.from_trajectories(pred)
        np.testing.assert_array_equal(attached.transition_matrix, model.transition_matrix)
        assert pred.parameters["seed"] == 7
    # by its path too (a review met weakref's TypeError), anything else in one line
    np.testing.assert_array_equal(MarkovModel.from_trajectories(out).transition_matrix,
                                  model.transition_matrix)
    assert MarkovModel.from_trajectories(str(markov_run)) is None
    with pytest.raises(InputError, match=r"from_trajectories\(3\): give a prediction file's"):
        MarkovModel.from_trajectories(3)
    times, states, _ = model.predict(markov_run, start=4.0, duration=1.0, seed=7)
    np.testing.assert_array_equal(model.state_space.discretize(Trajectories(out).positions(5)),
                                  states[5])
    with pytest.raises(InputError, match="no frame at t = 4.01"):
        model.predict(markov_run, start=4.01, duration=1.0, output=tmp_path / "bad.h5")
    assert not (tmp_path / "bad.h5").exists()


def test_save_load_round_trip_and_bad_files(tmp_path, markov_flow, markov_run):
    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag, (1, 3))
    path = model.save(tmp_path / "m.h5")
    back = MarkovModel.load(path)
    for name in ("transition_matrix", "counts", "counts_up", "counts_down"):
        np.testing.assert_array_equal(getattr(back, name), getattr(model, name))
    assert back.state_space == model.state_space and back.window == (1.0, 3.0)
    assert back.lag == model.lag and back.estimator == "mle"
    assert back.rtd().mean == pytest.approx(model.rtd().mean, rel=1e-12)
    with pytest.raises(ValueError):
        model.transition_matrix[0, 0] = 0.5            # immutable
    with pytest.raises(InputError, match="not a cfbmarkov model file"):
        MarkovModel.load(markov_run)
    import h5py

    with h5py.File(tmp_path / "foreign.h5", "w") as f:
        f["x"] = [1.0]
    with pytest.raises(InputError, match=r"not a cfbmarkov model file \(an HDF5 file without "
                                         r"cfbmarkov's 'format' attribute\): give a model that "
                                         "cfbmarkov fit wrote"):
        MarkovModel.load(tmp_path / "foreign.h5")
    truncated = tmp_path / "t.h5"
    truncated.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(InputError, match="not a readable HDF5 file"):
        MarkovModel.load(truncated)


def test_derived_models_share_the_validated_arrays_and_new_arrays_are_checked():
    """with_selection / with_coherence keep the validated read-only arrays (no [S, S]
    copies); a model made from arrays checks and copies them."""
    import dataclasses

    model = ladder_model(6, 0.5, 0.1)
    derived = model.with_selection({"reason": "test"}).with_coherence(0.2)
    for name in ("transition_matrix", "counts", "counts_up", "counts_down"):
        assert getattr(derived, name) is getattr(model, name)
        assert not getattr(derived, name).flags.writeable
    if model.pass_fractions is not None:
        assert derived.pass_fractions[0] is model.pass_fractions[0]
    with pytest.raises(InputError, match="must lie in"):
        model.with_coherence(1.5)
    doubled = np.array(model.transition_matrix) * 2.0
    with pytest.raises(InputError, match="rows do not sum to 1"):
        dataclasses.replace(model, transition_matrix=doubled)
    # within 1e-9 as documented: a leak of 1e-6 a lag (numpy's default rtol would pass it)
    leaking = np.array(model.transition_matrix) * (1.0 - 1e-6)
    with pytest.raises(InputError, match="rows do not sum to 1"):
        dataclasses.replace(model, transition_matrix=leaking)
    dataclasses.replace(model, transition_matrix=np.array(model.transition_matrix)
                        * (1.0 - 1e-12))                  # round-off: accepted
    negative = np.array(model.counts)
    negative[0, 0] = -1
    with pytest.raises(InputError, match="negative counts"):
        dataclasses.replace(model, counts=negative)
    given = np.array(model.transition_matrix)
    copied = dataclasses.replace(model, transition_matrix=given)
    assert copied.transition_matrix is not given and np.array_equal(copied.transition_matrix, given)


def test_state_spaces_are_immutable_so_a_fitted_model_keeps_its_states(markov_run):
    """A model holds the grid it was fitted with: the grid cannot be changed after (it was
    a plain object, and a caller's ``grid.rows = 19`` turned the 228-state model's repr,
    predictions and saved file into a 114-state one's); ``with_size`` still gives a sized
    copy, itself immutable."""
    from cfbmarkov.markov.spaces import state_space_from_name

    grid = CellGrid(6, 38, 0.09, 0.95)
    model = fit_model(markov_run, grid, 0.025, (0.5, 2.0), "mle")
    for name, value in (("rows", 19), ("width", 0.2), ("new_attribute", 1)):
        with pytest.raises(AttributeError, match="CellGrid is immutable"):
            setattr(grid, name, value)
    assert model.state_space.n_states == 228 and grid.rows == 38
    sized = CellGrid(6, 38).with_size(0.09, 0.95)
    assert (sized.width, sized.height) == (0.09, 0.95)
    with pytest.raises(AttributeError, match="immutable"):
        sized.height = 1.0
    for kind in ("cells-direction", "cells-previous"):
        space = state_space_from_name(kind, 6, 38, 0.09, 0.95)
        with pytest.raises(AttributeError, match="is immutable"):
            space.per_cell = 1


def test_adopted_arrays_are_kept_and_others_copied():
    """A model made with adopt=True keeps the given arrays (checked, made read-only); without
    it a caller's arrays are copied and stay the caller's."""
    import dataclasses

    model = ladder_model(5, 0.5, 0.1)
    mine = np.array(model.transition_matrix)
    copied = dataclasses.replace(model, transition_matrix=mine)
    assert copied.transition_matrix is not mine and mine.flags.writeable
    given = np.array(model.transition_matrix)
    adopted = dataclasses.replace(model, transition_matrix=given, adopt=True)
    assert np.shares_memory(adopted.transition_matrix, given) and not given.flags.writeable
    with pytest.raises(ValueError):        # what a model returns cannot be made writeable
        adopted.transition_matrix.setflags(write=True)
    bad = np.array(model.transition_matrix) * 3.0      # adopted, still checked
    with pytest.raises(InputError, match="rows do not sum to 1"):
        dataclasses.replace(model, transition_matrix=bad, adopt=True)


@pytest.mark.parametrize("falls", [0.0, 0.15])
def test_level_propagation_equals_the_full_deficit_matrix(markov_flow, markov_run, falls):
    """The exact RTD propagated level by level (each non-zero of P read once a lag for every
    lap deficit) equals the propagation through the full [S L, S L] matrix of the module
    docstring, restricted to the states that reach an exit, to 1e-14 per lag: for a fitted
    chain (from the observed entries and from its stationary ones) and a ladder with falls
    through the bottom."""
    import scipy.sparse as sp

    from cfbmarkov.markov.first_passage import (_finish, deficit_matrix, exact_rtd,
                                      split_by_pass)

    def full(p_up, p_down, p_stay, start_level0, levels=9, steps=200_000):
        s = p_up.shape[0]
        q, exits = deficit_matrix(sp.csr_matrix(p_up), sp.csr_matrix(p_down),
                                  sp.csr_matrix(p_stay), levels)
        live = states_reaching(q, np.flatnonzero(exits > 0))
        idx = np.flatnonzero(live)
        start = np.zeros(s * levels)
        start[:s] = start_level0
        start = start[idx] / start[idx].sum()
        return _finish(q[idx][:, idx], exits[idx], start, 1e-10, steps, 0.01, None).probability

    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag, (1.0, 5.0), "mle")
    ladder = ladder_model(8, 0.6, falls)
    for chain in (model, ladder):
        parts = split_by_pass(chain.transition_matrix, chain.up_fraction, chain.down_fraction)
        for entry in (None, chain.counts_up.sum(axis=0).astype(float) + 0.5):
            rtd = exact_rtd(chain.transition_matrix, chain.up_fraction, chain.down_fraction,
                            chain.lag, entry=entry)
            want = full(*parts, rtd.entry_distribution)
            assert rtd.probability.size == want.size
            assert np.abs(rtd.probability - want).max() < 1e-14


@pytest.mark.parametrize("falls", [0.0, 0.2])
def test_entry_chain_by_level_elimination_equals_the_full_fundamental_matrix(falls):
    """B = (I - Q)^-1 R formed level by level (markov.entry_chain) equals B from one LU of
    the full [S L, S L] matrix to 1e-13, for the long-tail chain (laps down through the
    bottom) and a ladder, with and without falls; the exact RTD keeps its mean."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    from cfbmarkov.markov.entry_chain import entry_matrix
    from cfbmarkov.markov.first_passage import deficit_matrix, split_by_pass
    from cfbmarkov.synthetic import long_tail_chain

    for chain in (long_tail_chain(columns=3, rows=8), ladder_model(8, 0.6, falls)):
        p_up, p_down, p_stay = split_by_pass(chain.transition_matrix, chain.up_fraction,
                                             chain.down_fraction)
        s, levels = chain.n_states, 9
        q, exits = deficit_matrix(p_up, p_down, p_stay, levels)
        live = states_reaching(q, np.flatnonzero(exits > 0))
        idx = np.flatnonzero(live)
        entries = np.flatnonzero(np.asarray(p_up.sum(axis=0)).ravel() > 0)
        lu = splu(sp.csc_matrix(sp.identity(idx.size) - q[idx][:, idx]))
        r = np.zeros((idx.size, entries.size))
        top = idx[idx < s]
        r[np.searchsorted(idx, top)] = p_up[top][:, entries].toarray()
        full = lu.solve(r)[np.searchsorted(idx, entries)]
        got = entry_matrix(p_up, p_down, p_stay, live.reshape(levels, s), entries)
        assert np.abs(got - full).max() < 1e-13


@pytest.mark.parametrize("falls", [0.0, 0.2])
def test_the_fall_below_the_levels_solved_equals_the_full_matrix_and_the_propagation(falls):
    """h_0, the probability of passing down from the deepest level kept, carried up the
    levels by the block elimination (entry_matrix(with_falls=True)), equals the full
    [S L, S L] solve of h = Q h + f to 1e-13, and the residences' loss it gives equals the
    loss the exact RTD's propagation counts (deficit_unresolved) to 1e-9; the levels the
    exact RTD chooses are those a loss below 1e-7 needs."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    from cfbmarkov.markov.entry_chain import entry_matrix
    from cfbmarkov.markov.first_passage import (DEFICIT_TOL, _rtd_on_levels,
                                                deficit_matrix, rtd_of_split_chain,
                                                split_by_pass)
    from cfbmarkov.synthetic import long_tail_chain

    seen = []
    for chain in (long_tail_chain(columns=3, rows=8), ladder_model(8, 0.6, falls)):
        p_up, p_down, p_stay = split_by_pass(chain.transition_matrix, chain.up_fraction,
                                             chain.down_fraction)
        s, whole = chain.n_states, (p_up + p_down + p_stay).tocsr()
        for levels in (2, 3, 9):
            q, exits = deficit_matrix(p_up, p_down, p_stay, levels)
            live = states_reaching(q, np.flatnonzero(exits > 0))
            idx = np.flatnonzero(live)
            f = np.zeros(s * levels)
            f[(levels - 1) * s:] = np.asarray(p_down.sum(axis=1)).ravel()
            lu = splu(sp.csc_matrix(sp.identity(idx.size) - q[idx][:, idx]))
            full = np.zeros(s * levels)
            full[idx] = lu.solve(f[idx])
            entries = np.flatnonzero(np.asarray(p_up.sum(axis=0)).ravel() > 0)
            _, h0 = entry_matrix(p_up, p_down, p_stay, live.reshape(levels, s), entries,
                                 with_falls=True)
            assert np.abs(h0 - full[:s]).max() < 1e-13
            rtd, lost = _rtd_on_levels(p_up, p_down, p_stay, chain.lag, levels - 1, 1e-14,
                                       200_000, None, None, whole)
            assert abs(rtd.entry_distribution @ h0 - lost[-1]) < 1e-9
            seen.append(lost[-1])
        rtd = rtd_of_split_chain(p_up, p_down, p_stay, chain.lag)
        assert rtd.deficit_unresolved <= DEFICIT_TOL
        shallower = _rtd_on_levels(p_up, p_down, p_stay, chain.lag, rtd.deficit_levels - 8,
                                   1e-10, 200_000, None, None, whole)[1][-1]
        assert rtd.deficit_levels == 8 or shallower > DEFICIT_TOL
    assert max(seen) > 1e-3                     # the test sees a loss


@pytest.mark.parametrize("falls", [0.0, 0.2])
def test_the_level_system_and_its_live_pairs_equal_the_full_deficit_matrixs(falls):
    """I - Q on the live (level, state) pairs built by the kernel from the parts'
    transposes equals the full [S L, S L] matrix restricted to them, entry for entry, and
    the live pairs found backwards through the transposes equal those of the full matrix's
    graph, on the long-tail chain, a ladder, and a chain with a trap (a state entered but
    never left reaches no exit: dead on every level)."""
    import scipy.sparse as sp

    from cfbmarkov.markov.first_passage import (_level_system, _live_from_transposes,
                                                _transposed_parts, deficit_matrix,
                                                split_by_pass)
    from cfbmarkov.synthetic import long_tail_chain

    trap = ladder_model(8, 0.6, falls)
    matrix = np.array(trap.transition_matrix, dtype=float)
    matrix[3] = 0.0
    matrix[3, 3] = 1.0                  # state 3 entered, never left
    for chain, p in ((long_tail_chain(columns=3, rows=8), None), (ladder_model(8, 0.6, falls), None),
                     (trap, matrix)):
        p = chain.transition_matrix if p is None else p
        p_up, p_down, p_stay = split_by_pass(p, chain.up_fraction, chain.down_fraction)
        s, levels = chain.n_states, 9
        q, exits = deficit_matrix(p_up, p_down, p_stay, levels)
        live = states_reaching(q, np.flatnonzero(exits > 0))
        arrays = _transposed_parts((p_down, p_stay, p_up))
        assert np.array_equal(_live_from_transposes(*arrays, levels, exits[:s] > 0), live)
        idx = np.flatnonzero(live)
        indptr, indices, data = _level_system(*arrays, np.ascontiguousarray(
            live.reshape(levels, s).T))
        got = sp.csc_matrix((data, indices, indptr), shape=(idx.size, idx.size))
        full = sp.csc_matrix(sp.identity(idx.size) - q[idx][:, idx])
        assert abs(got - full).max() == 0.0
        assert got.has_sorted_indices and (p is not matrix or idx.size < s * levels)


def test_states_reaching_equals_the_transitive_closure():
    """One search from a hub joined to every target finds the states that reach any of
    them (targets included): the same as the transitive closure of P_ij > 0, with stored
    zeros no transitions and targets given twice or not at all."""
    import scipy.sparse as sp

    rng = np.random.default_rng(7)
    for trial in range(20):
        n = int(rng.integers(2, 30))
        dense = (rng.random((n, n)) < 0.08) * rng.random((n, n))
        matrix = sp.csr_matrix(dense)
        if matrix.nnz:                                  # stored zeros: no transition
            matrix.data[rng.integers(0, matrix.nnz, size=2)] = 0.0
        stored = matrix.toarray() > 0
        closure = stored | np.eye(n, dtype=bool)
        for _ in range(n):
            closure = closure | ((closure.astype(int) @ closure.astype(int)) > 0)
        targets = rng.integers(0, n, size=int(rng.integers(0, 4)))
        expected = closure[:, targets].any(axis=1) if targets.size else np.zeros(n, bool)
        got = states_reaching(matrix, np.concatenate([targets, targets]))
        assert np.array_equal(got, expected), trial


def test_a_window_of_a_matrix_model_with_a_trap_starts_where_records_can_happen():
    """A model given by its matrix (no counts) whose long run lies in a state never left:
    the window's default start is every state from which the top is reached, alike (its
    stationary distribution, all in the trap, let no residence begin); a start with all its
    particles in the trap is refused saying so."""
    import warnings

    from cfbmarkov.errors import CfbmarkovError

    p = np.zeros((6, 6))            # state = row x 2 + column, one row up a lag
    p[0, 2] = p[2, 4] = 1.0
    p[1, 3] = p[1, 5] = 0.5
    p[3, 3] = 1.0                   # the trap
    up = np.zeros((6, 6))
    p[4, :2] = p[5, :2] = up[4, :2] = up[5, :2] = 0.5
    zeros = np.zeros((6, 6), np.int64)
    model = MarkovModel(p, zeros, zeros, zeros, CellGrid(2, 3, 0.2, 1.0), 0.1,
                        estimator="given", pass_fractions=(up, np.zeros((6, 6))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seen = model.rtd(window=4.0)
    reaching = np.array([1, 1, 1, 0, 1, 1], float)
    assert seen.mean == pytest.approx(model.rtd(window=4.0, occupancy=reaching).mean, rel=1e-12)
    with pytest.raises(CfbmarkovError, match="holds no particle in a state from which the top"):
        model.rtd(window=4.0, occupancy=np.array([0, 0, 0, 1.0, 0, 0]))


def test_batch_share_fallen_through_the_bottom_is_the_monte_carlos(markov_flow, markov_run):
    """The report's Fig. 4-7 caption gives, for a net downflow, the share of the batch that
    has fallen through the bottom: the chain with the passes down taken out, checked
    against walkers counting a lap lost (first passages down)."""
    from cfbmarkov.analysis.reproduction import batch_injection

    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag)
    steps = 10
    batch = batch_injection(model, [steps * model.lag])
    inlet = model.state_space.inlet_distribution()
    start = np.random.default_rng(1).choice(model.n_states, 40000, p=inlet / inlet.sum())
    _, laps = model.monte_carlo(start, steps, seed=3)
    fallen = float((laps.min(axis=0) < laps[0]).mean())
    se = np.sqrt(fallen * (1 - fallen) / start.size)
    assert 0.0 < batch.fallen_share < 1.0 and se > 0
    assert abs(batch.fallen_share - fallen) < 4 * se, (batch.fallen_share, fallen, se)


@pytest.mark.parametrize("coherence, regimes", [(0.0, False), (0.4, False), (0.0, True)])
def test_a_run_in_pieces_draws_what_one_piece_draws(monkeypatch, coherence, regimes):
    """run_chain runs a long Monte Carlo in pieces, so that a Ctrl-C is taken between them;
    the draws depend on the step alone, so any piece size gives the same states and laps
    bit for bit (with coherent moves, and with a regime path's row offsets)."""
    from cfbmarkov.markov import montecarlo
    from cfbmarkov.markov.montecarlo import SparseChain, run_chain

    rng = np.random.default_rng(3)
    s = 12
    matrix = rng.random((2 * s if regimes else s, s)) * (rng.random((2 * s if regimes else s,
                                                                     s)) < 0.4)
    matrix[np.arange(matrix.shape[0]), np.arange(matrix.shape[0]) % s] += 0.1
    matrix /= matrix.sum(axis=1, keepdims=True)
    up = np.where(rng.random(matrix.shape) < 0.2, 0.5, 0.0)
    down = np.where(rng.random(matrix.shape) < 0.1, 0.3, 0.0)
    chain = SparseChain.from_matrix(matrix, up, down)
    initial = rng.integers(0, s, 50)
    steps = 97
    offset = (rng.integers(0, 2, steps + 1) * s) if regimes else None
    whole = run_chain(chain, initial, steps, 11, row_offset=offset, coherence=coherence)
    monkeypatch.setattr(montecarlo, "PIECE_PARTICLE_STEPS", 50 * 7)     # pieces of 7 steps
    pieces = run_chain(chain, initial, steps, 11, row_offset=offset, coherence=coherence)
    assert np.array_equal(whole[0], pieces[0]) and np.array_equal(whole[1], pieces[1])
    assert np.any(whole[1] != 0)                                         # laps moved


@pytest.mark.parametrize("coherence", [0.0, 0.4])
def test_an_open_riser_run_in_pieces_draws_what_one_piece_draws(monkeypatch, coherence):
    """run_open_chain also runs in pieces (a Ctrl-C between them): any piece size gives the
    same states, newcomers and exits bit for bit, and its progress counts the lags run up
    to the end."""
    from cfbmarkov.markov import montecarlo
    from cfbmarkov.markov.montecarlo import SparseChain
    from cfbmarkov.markov.open_montecarlo import run_open_chain

    rng = np.random.default_rng(5)
    s = 9
    matrix = rng.random((s, s)) * (rng.random((s, s)) < 0.5) + 0.05 * np.eye(s)
    matrix /= matrix.sum(axis=1, keepdims=True)
    zeros = np.zeros((s, s))
    chain = SparseChain.from_matrix(matrix, zeros, zeros)
    exit_probability = np.where(np.arange(s) >= s - 3, 0.3, 0.0)
    entry = np.where(np.arange(s) < 3, 1.0, 0.0)
    initial = rng.integers(0, s, 40)
    steps = 83
    whole, start = run_open_chain(chain, exit_probability, entry, 2.5, initial, steps, 13,
                                  coherence=coherence)
    shown = []
    monkeypatch.setattr(montecarlo, "PIECE_PARTICLE_STEPS", 5 * whole.shape[1])
    pieces, start_p = run_open_chain(chain, exit_probability, entry, 2.5, initial, steps, 13,
                                     coherence=coherence, progress=shown.append)
    assert np.array_equal(whole, pieces) and np.array_equal(start, start_p)
    assert shown == list(range(4, steps, 5)) + [steps]
    assert (whole[-1] == -1).sum() > 40 and whole.shape[1] > 150     # exits and newcomers


def test_exact_rtd_and_a_models_pass_counts_are_checked_as_the_model_checks_p():
    """The public exact_rtd refuses what MarkovModel refuses (a negative lag gave a negative
    E(RT), a doubled P a NaN, a short fraction array an IndexError), and a model whose pass
    counts exceed its transition counts is refused (its fractions, their shares, exceeded 1:
    E(RT) one lag)."""
    from cfbmarkov.markov import exact_rtd

    model = ladder_model(6, 0.4)
    p, up, down = model.transition_matrix, model.up_fraction, model.down_fraction
    assert exact_rtd(p, up, down, 0.01).mean == pytest.approx(model.rtd().mean, rel=1e-12)
    for args, match in (((p, up, down, -0.01), "lag -0.01 s must be a positive"),
                        ((2 * p, up, down, 0.01), "rows do not sum to 1"),
                        ((p, up[:3], down, 0.01), r"up_fraction has shape \(3, 6\)"),
                        ((p, 2 * up, down, 0.01), r"pass fractions must lie in \[0, 1\]")):
        with pytest.raises(InputError, match=match):
            exact_rtd(*args)
    counts = np.diag(np.full(6, 50)) + np.roll(np.diag(np.full(6, 30)), 1, axis=1)
    p_counts = counts / counts.sum(axis=1, keepdims=True)
    passed = np.zeros((6, 6), np.int64)
    passed[5, 0] = 30
    grid = CellGrid(1, 6, 0.1, 1.0)
    fitted = MarkovModel(p_counts, counts, passed, 0 * passed, grid, 0.01)
    assert fitted.rtd().mean > 0.05
    with pytest.raises(InputError, match=r"counts_up \+ counts_down exceed counts \(90 passes "
                                         r"of the 30 transitions 5 -> 0\)"):
        MarkovModel(p_counts, counts, 3 * passed, 0 * passed, grid, 0.01)


def test_python_api_guards_name_the_argument():
    """From a notebook user's review: a tuple for a grid, an estimator's state space set
    after construction, a file name for assess_fit, one state-space name as a string, a
    grid of no cells and a cell beyond the grid are refused in one line (they ended in an
    AttributeError, letters read as names, cells numbered -7 or a height of 4.15 m in a
    0.95 m riser); an RTD window between whole lags says the length it used."""
    from cfbmarkov.analysis.fit_checks import assess_fit
    from cfbmarkov.markov import PaperEstimator, cell_index
    from cfbmarkov.markov.select.candidates import candidate_spaces
    from cfbmarkov.markov.states import place_in_cells

    model = ladder_model(6, 0.4)
    arrays = [model.transition_matrix, model.counts, model.counts_up, model.counts_down]
    with pytest.raises(InputError, match=r"state_space \(1, 6\) is a tuple"):
        MarkovModel(*arrays, (1, 6), 0.01)
    estimator = PaperEstimator(CellGrid(1, 6, 0.1, 1.0), 0.01)
    estimator.state_space = (1, 6)
    with pytest.raises(InputError, match="is a tuple, not a state space"):
        estimator.fit(None)
    with pytest.raises(InputError, match="assess_fit takes a fitted MarkovModel, not a str"):
        assess_fit("model.h5")

    class Riser:
        width, height = 0.1, 1.0

    assert [k[0] for k in candidate_spaces(Riser(), "cells", [1], 0.01, 1, 6)] == ["cells"]
    with pytest.raises(InputError, match="columns -6 must be a whole number >= 1"):
        cell_index(np.zeros((5, 2)), 0.09, 0.95, -6, 38)
    with pytest.raises(InputError, match="cell 999 outside the grid's 6 cells"):
        place_in_cells(np.array([999]), CellGrid(1, 6, 0.1, 1.0), seed=1, step=0)
    assert model.rtd(window=0.503).window == pytest.approx(0.5)
    assert model.rtd(window=0.5).window == 0.5


def test_the_dense_to_sparse_conversion_equals_scipys():
    """exact_rtd reads a dense P in two Numba passes: the same CSR matrix as scipy's
    (sorted indices, no explicit zeros), and a NaN is kept for the checks to refuse."""
    import scipy.sparse as sp

    from cfbmarkov.markov import exact_rtd
    from cfbmarkov.markov.first_passage import csr_of

    rng = np.random.default_rng(8)
    dense = rng.random((37, 37)) * (rng.random((37, 37)) < 0.2)
    dense[5] = 0.0                                   # an empty row
    ours, theirs = csr_of(dense), sp.csr_matrix(dense)
    assert ours.has_sorted_indices and ours.nnz == theirs.nnz
    np.testing.assert_array_equal(ours.toarray(), dense)
    assert (ours != theirs).nnz == 0
    model = ladder_model(6, 0.4)
    p = model.transition_matrix.copy()
    p[2, 3] = np.nan
    with pytest.raises(InputError, match="negative or non-finite"):
        exact_rtd(p, model.up_fraction, model.down_fraction, 0.01)


def test_an_exact_rtd_beyond_the_memory_limit_is_refused_before_it_runs(monkeypatch):
    """A model too large for its exact RTD (13 dense [S, S] arrays at its peak, measured)
    is refused in one line naming the estimate, before any work (a 16416-state model's
    `rtd` was killed by the system after 68 s with nothing said); small models are not
    checked."""
    from cfbmarkov import limits

    model = ladder_model(800, 0.4)
    need = limits.RTD_ARRAYS * 8.0 * 800 ** 2
    monkeypatch.setenv(limits.MEMORY_ENV, str(int(need / 2)))
    with pytest.raises(InputError, match=r"the exact RTD of a model of 800 states \(about 13 "
                                         r"dense 800 x 800 arrays of 8 bytes\) would need"):
        model.rtd()
    monkeypatch.setenv(limits.MEMORY_ENV, str(int(need * 2)))
    assert model.rtd().mean > 0
    monkeypatch.setenv(limits.MEMORY_ENV, "1000")
    assert ladder_model(6, 0.4).rtd().mean > 0              # far below RTD_CHECK_FROM


def test_propagate_and_monte_carlo_beyond_memory_are_refused_in_one_line():
    """As predict and the maps refuse work the memory cannot hold: a numpy MemoryError
    (1.66 TiB asked for) is an InputError naming the size and what to shorten."""
    model = ladder_model(4, 0.5)
    with pytest.raises(InputError, match=r"the distribution over 4 states at 1000000000001 "
                       r"lags would need about .* of memory.*; propagate fewer steps"):
        model.propagate(np.full(4, 0.25), 10 ** 12)
    with pytest.raises(InputError, match=r"a Monte Carlo of 1000000 particles over 1000000 "
                       r"lags would need .*; run fewer particles or lags"):
        model.monte_carlo(np.zeros(10 ** 6, int), 10 ** 6)
    assert model.propagate(np.full(4, 0.25), 3).shape == (4, 4)


def test_an_rtd_already_seen_in_a_window_is_not_weighted_again():
    """in_window() weights the intrinsic f(k) by (n_W - k)+; on an RTD that is already a
    window's it would weight twice (E(RT) 8 % low on the demo's model with no word):
    refused, naming the model's rtd(window=...)."""
    model = ladder_model(10, 0.4, lag=0.01)
    seen = model.rtd(window=0.6)
    assert seen.window == pytest.approx(0.6)
    with pytest.raises(InputError, match=r"already the one a 0\.6 s window sees.*"
                                         r"model\.rtd\(window=\.\.\.\)"):
        seen.in_window(0.8)
    intrinsic = model.rtd()
    assert intrinsic.in_window(0.6).mean == pytest.approx(seen.mean, rel=1e-12)


@pytest.mark.parametrize("window, message", [
    (float("nan"), "window length nan s is not a finite number"),
    (-1.0, "window length -1 s must be positive"),
    ((0.1, 0.6), r"window \(0\.1, 0\.6\) is not a length"),
    ("0.6", "is not a number"),
    (1e9, "more than 10000000"),
])
def test_in_window_refuses_what_is_not_a_length(window, message):
    with pytest.raises(InputError, match=message):
        ladder_model(10, 0.4, lag=0.01).rtd().in_window(window)


def test_a_window_shorter_than_a_lag_holds_no_residence():
    with pytest.raises(CfbmarkovError, match="no residence of this model fits in a window of "
                                             "0.001 s"):
        ladder_model(10, 0.4, lag=0.01).rtd().in_window(0.001)


@pytest.mark.parametrize("bin_width, upper, message", [
    (0.0, 1.0, "RTD bin width 0 s must be positive"),
    (-0.05, 1.0, "RTD bin width -0.05 s must be positive"),
    (float("nan"), 1.0, "RTD bin width nan s is not a finite number"),
    (0.05, -1.0, "upper edge -1 s must be positive"),
    (1e-9, 1.0, r"1e\+09 bins, more than 10000000; give a bin width of at least 1e-07 s"),
    (1.0, 0.5, "RTD bin width 1 s is wider than the histogram's upper edge 0.5 s"),
])
def test_rtd_histogram_refuses_bins_it_cannot_draw(bin_width, upper, message):
    with pytest.raises(InputError, match=message):
        ladder_model(10, 0.4, lag=0.01).rtd().histogram(bin_width, upper)
