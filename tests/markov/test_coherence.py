"""Coherent moves (the cluster model): particles that share a state take one common draw
with probability rho, so patches of particles move together; each particle alone still
follows the chain."""

import dataclasses

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.markov import MarkovModel, discretize, estimator_from_name, fit_model
from cfbmarkov.markov.coherence import estimate_coherence
from cfbmarkov.markov.montecarlo import run_chain
from cfbmarkov.markov.states import place_in_cells
from cfbmarkov.trajectory_writer import write_trajectories

FLOW = synthetic.RiserFlow(columns=4, rows=16, persistence=False, vertical_spread=0.5)
PARTICLES, STEPS = 1500, 400


def _index_of_dispersion(cells, n_cells):
    """Mean over frames of var / mean of the particle counts per cell."""
    counts = np.stack([np.bincount(c, minlength=n_cells) for c in cells])
    return float((counts.var(axis=1) / counts.mean(axis=1)).mean())


def _coherent_run(path, rho, seed):
    """The generator's chain run with coherence ``rho`` from its stationary distribution,
    written as a trajectory file."""
    true = synthetic.cell_chain(FLOW)
    pi = true.stationary_distribution
    initial = np.random.default_rng(seed).choice(pi.size, PARTICLES, p=pi)
    states, laps = run_chain(true._chain, initial, STEPS, seed, coherence=rho)
    positions = np.stack([place_in_cells(states[k], FLOW.grid, seed + 1, k)
                          for k in range(STEPS + 1)])
    write_trajectories(path, FLOW.lag * np.arange(STEPS + 1), positions, width=FLOW.width,
                       height=FLOW.height, laps=laps)
    return path, states


@pytest.fixture(scope="session")
def coherent(tmp_path_factory):
    return _coherent_run(tmp_path_factory.mktemp("coherence") / "run.h5", 0.6, 3)


def test_the_coherence_is_recovered_and_zero_for_independent_particles(coherent, tmp_path):
    run, _ = coherent
    model = fit_model(run, FLOW.grid, FLOW.lag, None, "mle", coherent=True)
    assert model.coherence == pytest.approx(0.6, abs=0.05)
    independent, _ = _coherent_run(tmp_path / "independent.h5", 0.0, 4)
    assert fit_model(independent, FLOW.grid, FLOW.lag, None, "mle", coherent=True
                     ).coherence < 0.05
    # the chain is the same whether the coherence is fitted or not
    plain = fit_model(run, FLOW.grid, FLOW.lag, None, "mle")
    np.testing.assert_array_equal(plain.transition_matrix, model.transition_matrix)
    assert plain.coherence == 0.0


def test_coherent_monte_carlo_keeps_the_clusters_and_the_single_particle_chain(coherent):
    run, observed = coherent
    model = fit_model(run, FLOW.grid, FLOW.lag, None, "mle", coherent=True)
    n_cells = FLOW.columns * FLOW.rows
    start = observed[200]
    together, laps = model.monte_carlo(start, 200, seed=9)
    apart, apart_laps = model.with_coherence(0.0).monte_carlo(start, 200, seed=9)
    data_index = _index_of_dispersion(observed[200:], n_cells)
    assert data_index > 3.0                                     # the data are clustered
    assert abs(_index_of_dispersion(together, n_cells) / data_index - 1) < 0.3
    assert _index_of_dispersion(apart, n_cells) < 1.5           # independent: about Poisson
    # each particle alone still follows P: occupancy and net passes as without coherence
    occupancy = np.bincount(together[100:].ravel(), minlength=n_cells) / together[100:].size
    expected = model.stationary_distribution
    assert 0.5 * np.abs(occupancy - expected).sum() < 0.08      # total variation
    flux_together = (laps[-1] - laps[0]).mean()
    flux_apart = (apart_laps[-1] - apart_laps[0]).mean()
    assert flux_together == pytest.approx(flux_apart, rel=0.15)


def test_coherent_monte_carlo_is_the_same_for_any_thread_count(coherent):
    import numba

    run, observed = coherent
    model = fit_model(run, FLOW.grid, FLOW.lag, None, "mle").with_coherence(0.5)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = model.monte_carlo(observed[0], 50, seed=4)
        numba.set_num_threads(max(2, threads) if numba.config.NUMBA_NUM_THREADS > 1 else 1)
        two = model.monte_carlo(observed[0], 50, seed=4)
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])
    # coherence 0 is exactly the independent Monte Carlo of before (same draws)
    np.testing.assert_array_equal(model.with_coherence(0.0).monte_carlo(observed[0], 50, seed=4)[0],
                                  run_chain(model._chain, observed[0], 50, 4)[0])


def test_estimate_coherence_by_hand():
    # 2 states; frame 0: four particles in state 0; frame 1: three of them in state 1
    states = np.array([[0, 0, 0, 0], [1, 1, 1, 0]], dtype=np.int32)

    class Window:                       # the two fields the estimate reads
        pass
    window = Window()
    window.states, window.lag_frames = states, 1
    p = np.array([[0.5, 0.5], [0.5, 0.5]])
    # pairs 6, same-target pairs 3 + 0 = 3, q = 0.5: rho^2 = (3 - 3) / (6 - 3) = 0
    from cfbmarkov.markov import discrete

    original = discrete.as_discrete_list
    try:
        discrete.as_discrete_list = lambda data: [data]
        assert estimate_coherence(window, p) == 0.0
        window.states = np.array([[0, 0, 0, 0], [1, 1, 1, 1]], dtype=np.int32)
        assert estimate_coherence(window, p) == pytest.approx(1.0)   # (6 - 3) / (6 - 3)
    finally:
        discrete.as_discrete_list = original


def test_model_file_cli_and_refusals(coherent, tmp_path, capsys):
    run, _ = coherent
    out = tmp_path / "model.h5"
    assert main(["fit", str(run), "--cells", "4x16", "--lag", "0.025", "--window", "0:10",
                 "--estimator", "mle", "--coherent", "-o", str(out)]) == 0
    assert "coherent moves (the cluster model): coherence 0.6" in capsys.readouterr().out
    model = MarkovModel.load(out)
    assert model.coherence == pytest.approx(0.6, abs=0.05)
    assert model.describe()["coherence"] == model.coherence
    with pytest.raises(InputError, match="coherence"):
        model.with_coherence(1.5)
    open_run = synthetic.write_open_run(tmp_path / "open.h5", FLOW, 200, 2.0, seed=1)
    assert main(["fit", str(open_run), "--cells", "4x16", "--window", "0:2", "--coherent",
                 "-o", str(tmp_path / "open-model.h5")]) == 2
    assert "periodic risers only" in capsys.readouterr().err
    space_estimator = estimator_from_name("mle", FLOW.grid, FLOW.lag, coherent=True)
    with pytest.raises(InputError, match="periodic risers only"):
        space_estimator.fit(discretize(open_run, FLOW.grid, FLOW.lag, (0.0, 2.0)))


def test_intervals_of_a_coherent_model_measure_its_monte_carlo_noise(coherent):
    from cfbmarkov.analysis.intervals import prediction_intervals
    from cfbmarkov.observed.residence import residence_times_from_laps, rtd_histogram

    run, _ = coherent
    model = fit_model(run, FLOW.grid, FLOW.lag, (0.0, 5.0), "mle", coherent=True)
    times, states, laps = model.predict(run, 5.0, 4.0, seed=2)
    samples = residence_times_from_laps(times, laps)
    edges, _ = rtd_histogram(samples, 0.1, window_length=4.0)
    left = states[0] % FLOW.columns < FLOW.columns // 2
    with pytest.raises(InputError, match="states at the window start"):
        prediction_intervals(model, samples, edges, 4.0, resamples=10)
    widths = {}
    for rho in (0.0, model.coherence):
        iv = prediction_intervals(model.with_coherence(rho), samples, edges, 4.0, resamples=10,
                                  tracers=(states[0], left),
                                  mixing=(times, np.zeros(times.size)))
        widths[rho] = iv.rt_mean[1] - iv.rt_mean[0]
    # correlated residences: the replicate runs spread more than independent samples would
    assert widths[model.coherence] > 1.2 * widths[0.0], widths


def test_calibrated_coherence_matches_the_windows_cluster_index(coherent, tmp_path):
    """The snapshots fit (what ``coherent=True`` fits): Monte Carlo snapshots with the
    calibrated rho show the window's own cluster index (within the 5 % tolerance, the same
    trial as the calibration's); the index from cells is that of the file's positions
    (:func:`cluster_index`); too few steps and a window without a complete frame are refused."""
    from cfbmarkov.observed.clusters import cluster_index, snapshot_cluster_index
    from cfbmarkov.markov.coherence import (CALIBRATION_BURN_IN, CALIBRATION_STEPS,
                                            calibrate_coherence)
    from cfbmarkov.trajectories import Trajectories

    run, observed = coherent
    n_cells = FLOW.columns * FLOW.rows
    with Trajectories(run) as traj:
        from_file = cluster_index(traj, slice(0, STEPS + 1), FLOW.columns, FLOW.rows)[0]
    assert np.nanmean(snapshot_cluster_index(observed, n_cells)) == pytest.approx(from_file,
                                                                                rel=1e-12)
    window = discretize(run, FLOW.grid, FLOW.lag, (0.0, 100 * FLOW.lag))
    plain = fit_model(run, FLOW.grid, FLOW.lag, (0.0, 100 * FLOW.lag), "mle")
    rho = calibrate_coherence(plain, window)
    assert 0.4 < rho < 0.8
    target = np.nanmean(snapshot_cluster_index(window.states, n_cells))
    trial, _ = plain.with_coherence(rho).monte_carlo(window.states[0], CALIBRATION_STEPS, seed=0)
    index = np.nanmean(snapshot_cluster_index(trial[CALIBRATION_BURN_IN + 1:], n_cells))
    assert abs(np.log(index / target)) <= 0.05
    # rho = 0 where the window is no more clustered than the independent chain
    calm = plain.with_coherence(0.0).monte_carlo(window.states[0], 100, seed=1)[0]
    calm_window = dataclasses.replace(window, states=calm.astype(np.int32))
    assert calibrate_coherence(plain, calm_window) < 0.25
    with pytest.raises(InputError, match="more than"):
        calibrate_coherence(plain, window, steps=CALIBRATION_BURN_IN)
    holes = window.states.copy()
    holes[:, 0] = -1
    with pytest.raises(InputError, match="every particle has a state"):
        calibrate_coherence(plain, dataclasses.replace(window, states=holes))


def test_a_model_with_another_coherence_keeps_what_its_chain_derived(coherent):
    """with_coherence / with_selection carry the sampling chain and the exact RTD over
    (the calibration's trials reuse them), and the Monte Carlo is the one of a model made
    afresh with that coherence."""
    run, states = coherent
    model = fit_model(run, FLOW.grid, FLOW.lag, None, "mle")
    model.monte_carlo(states[0], 3, seed=1)             # derives the sampling chain
    rtd = model.rtd()
    trial = model.with_coherence(0.4)
    assert trial._chain is model._chain and trial.coherence == 0.4
    assert trial.rtd().probability is rtd.probability
    assert model.with_selection({"how": "test"})._chain is model._chain
    fresh = dataclasses.replace(model, coherence=0.4)       # a cache of its own
    assert "_chain" not in fresh.__dict__ and fresh._cache == {}
    for a, b in zip(trial.monte_carlo(states[0], 20, seed=5),
                    fresh.monte_carlo(states[0], 20, seed=5)):
        np.testing.assert_array_equal(a, b)


def test_a_coherence_calibrated_to_zero_is_said(tmp_path, capsys):
    """fit --coherent whose calibration finds no coherence says so (the model is then the
    plain chain, and a plain fit's output alone would not tell)."""
    run = synthetic.write_run(tmp_path / "run.h5", synthetic.RiserFlow(), 300, 4.0, seed=1)
    assert main(["fit", str(run), "--window", "0:4", "--coherent", "--resamples", "0",
                 "--no-adequacy", "-o", str(tmp_path / "m.h5")]) == 0
    out = capsys.readouterr().out
    assert MarkovModel.load(tmp_path / "m.h5").coherence == 0.0
    assert "coherent moves: calibrated to a coherence of 0 on the fitting window" in out
    assert main(["fit", str(run), "--window", "0:4", "--resamples", "0", "--no-adequacy",
                 "-o", str(tmp_path / "p.h5")]) == 0
    assert "coherent moves" not in capsys.readouterr().out
