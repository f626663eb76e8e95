"""Intervals of a prediction (``docs/definitions.md``, Intervals): the model's expected mixing
curve and its Monte Carlo spread, the block bootstrap against deeptime's Bayesian MSM, and
the coverage of the intervals over many independent synthetic windows."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from cfbmarkov import synthetic
from cfbmarkov.analysis.intervals import block_bootstrap_models, prediction_intervals
from cfbmarkov.analysis.mixing import model_mixing_curve
from cfbmarkov.observed.residence import residence_times, residence_times_from_laps, rtd_histogram
from cfbmarkov.errors import InputError
from cfbmarkov.markov import CellGrid, fit_model
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

#: a small chain on cells (no hidden direction): the fitted model can recover it exactly
FLOW = synthetic.RiserFlow(columns=4, rows=16, persistence=False)


def _stationary(P: np.ndarray) -> np.ndarray:
    values, vectors = np.linalg.eig(P.T)
    pi = np.abs(vectors[:, int(np.argmin(np.abs(values - 1.0)))].real)
    return pi / pi.sum()


def _left_columns(model) -> np.ndarray:
    columns = model.state_space.columns
    return model.state_space.cell_of_state % columns < columns // 2


def test_model_mixing_curve_is_the_monte_carlo_mean_and_spread():
    """The expected curve and its SD from P^k equal the mean and SD of many Monte Carlo runs
    (Eq. 7) from the same states."""
    model = synthetic.cell_chain(FLOW)
    rng = np.random.default_rng(0)
    states = rng.choice(model.n_states, 200, p=_stationary(model.transition_matrix))
    left_cols = _left_columns(model)
    left = left_cols[states]
    steps, runs = 40, 300
    mean, sd = model_mixing_curve(model, states, left, steps)
    assert mean[0] == pytest.approx(left.mean()) and sd[0] == 0.0
    curves = np.array([(left_cols[model.monte_carlo(states, steps, seed=s)[0]] & left).mean(axis=1)
                       for s in range(runs)])
    # the mean within 4 standard errors at every lag; the SD within 15 % (chi-square, 299 dof:
    # about 4 % relative standard error per lag)
    assert np.all(np.abs(curves.mean(axis=0) - mean)[1:] < 4 * sd[1:] / np.sqrt(runs))
    ratio = curves.std(axis=0, ddof=1)[1:] / sd[1:]
    assert 0.85 < ratio.min() and ratio.max() < 1.15 and abs(np.median(ratio) - 1) < 0.05
    # the curve tends to (left group's share) x (the stationary share of the left half)
    far, _ = model_mixing_curve(model, states, left, 2000)
    pi_left = _stationary(model.transition_matrix)[left_cols].sum()
    assert far[-1] == pytest.approx(left.mean() * pi_left, rel=1e-3)


def test_model_mixing_curve_of_an_open_riser(tmp_path):
    """An open riser: the ratio of the left group's tracers present at x < W/2 to the tracers
    present, against Monte Carlo runs of the absorbing chain."""
    path = synthetic.write_open_run(tmp_path / "open.h5", FLOW, 300, 2.0, seed=2)
    model = fit_model(path, FLOW.grid, FLOW.lag, (0.0, 2.0), "mle")
    states, positions, _ = model.initial_states(path, 1.0)
    present = states >= 0
    left = present & (np.where(present, positions[:, 0], np.inf) < 0.5 * FLOW.width)
    steps, runs = 30, 200
    mean, sd = model_mixing_curve(model, states, left, steps)
    left_cols = _left_columns(model)
    tracers, group = states[present], left[present]
    curves = []
    for s in range(runs):
        run = model.monte_carlo(tracers, steps, seed=s)[0][:, :tracers.size]   # no newcomers
        here = run >= 0
        inside = here & group & left_cols[np.maximum(run, 0)]
        curves.append(inside.sum(axis=1) / here.sum(axis=1))
    curves = np.array(curves)
    assert np.all(np.abs(curves.mean(axis=0) - mean)[1:] < 4 * sd[1:] / np.sqrt(runs) + 2e-3)
    ratio = curves.std(axis=0, ddof=1)[1:] / sd[1:]
    assert 0.8 < np.median(ratio) < 1.2


def test_model_mixing_curve_refuses_bad_input():
    model = synthetic.cell_chain(FLOW)
    states = np.zeros(5, dtype=np.int64)
    with pytest.raises(InputError, match="shape"):
        model_mixing_curve(model, states, np.ones(4, dtype=bool), 3)
    with pytest.raises(InputError, match="outside"):
        model_mixing_curve(model, states + model.n_states, np.ones(5, dtype=bool), 3)
    with pytest.raises(InputError, match="no tracer"):
        model_mixing_curve(model, states - 1, np.ones(5, dtype=bool), 3)
    odd = synthetic.cell_chain(synthetic.RiserFlow(columns=3, rows=8, persistence=False))
    with pytest.raises(InputError, match="odd column count"):
        model_mixing_curve(odd, states, np.ones(5, dtype=bool), 3)
    # the band needs the curve and the tracers together, the curve on whole lags
    samples, edges = np.array([0.5, 0.7, 0.9]), np.linspace(0.0, 2.0, 21)
    times = 1.0 + model.lag * np.arange(4)
    with pytest.raises(InputError, match="needs both"):
        prediction_intervals(model, samples, edges, 2.0, mixing=(times, np.zeros(4)))
    with pytest.raises(InputError, match="whole lags"):
        prediction_intervals(model, samples, edges, 2.0, mixing=(times * 1.01, np.zeros(4)),
                             tracers=(states, np.ones(5, dtype=bool)))


# -- the block bootstrap against deeptime's Bayesian MSM ---------------------------------------
def _chain_file(path, seed: int, n_particles: int = 200, n_frames: int = 101):
    """A random 6-state chain on a 2 x 3 grid (1 x 3 m, frames 1 s apart) sampled from its
    stationary distribution; the particles sit at their cells' centres. Returns the file,
    the states [T, N] and the matrix."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(0.2, 1.0, (6, 6)) * (rng.uniform(size=(6, 6)) < 0.6)
    P[np.arange(6), (np.arange(6) + 1) % 6] += 0.5          # irreducible whatever was drawn
    P[np.arange(6), np.arange(6)] += 1.0
    P /= P.sum(axis=1, keepdims=True)
    states = np.empty((n_frames, n_particles), dtype=np.int64)
    states[0] = rng.choice(6, n_particles, p=_stationary(P))
    cumulative = P.cumsum(axis=1)
    for t in range(1, n_frames):
        u = rng.uniform(size=n_particles)[:, None]
        states[t] = np.minimum((u > cumulative[states[t - 1]]).sum(axis=1), 5)
    positions = np.stack([(states % 2 + 0.5) / 2, states // 2 + 0.5], axis=-1)
    write_trajectories(path, np.arange(n_frames, dtype=np.float64), positions, width=1.0,
                       height=3.0)
    return path, states, P


def _mfpt_to_0(P: np.ndarray) -> np.ndarray:
    """Mean first-passage times (lags) from states 1..S-1 to state 0."""
    keep = np.arange(1, P.shape[0])
    return np.linalg.solve(np.eye(keep.size) - P[np.ix_(keep, keep)], np.ones(keep.size))


def _spreads(matrices) -> dict[str, np.ndarray]:
    matrices = np.asarray(matrices)
    return {"P": matrices.std(axis=0),
            "pi": np.std([_stationary(P) for P in matrices], axis=0),
            "mfpt": np.std([_mfpt_to_0(P) for P in matrices], axis=0)}


def _sd_ratios(path, states, blocks: int, seed: int, samples: int = 400) -> dict[str, np.ndarray]:
    """SD of our block bootstrap / SD of deeptime's Bayesian posterior (non-reversible, the
    same counts), for P_ij > 0.05, the stationary distribution and the MFPT to state 0."""
    from deeptime.markov.msm import BayesianMSM

    model = fit_model(path, CellGrid(2, 3, 1.0, 3.0), 1.0, (0.0, states.shape[0] - 1.0), "mle")
    ours = _spreads([m.transition_matrix for m in block_bootstrap_models(
        model, blocks=blocks, resamples=samples, seed=seed)])
    # every frame pair of every particle, as our count does (sliding, lag 1): deeptime would
    # refuse sliding counts as correlated at a longer lag; at lag 1 they are the plain counts
    posterior = BayesianMSM(n_samples=samples, reversible=False).fit_from_discrete_timeseries(
        [states[:, p] for p in range(states.shape[1])], lagtime=1, count_mode="sliding",
        ignore_counting_mode=True).fetch_model()
    assert np.array_equal(posterior.prior.count_model.count_matrix, model.counts)
    theirs = _spreads([q.transition_matrix for q in posterior.samples])
    significant = model.transition_matrix > 0.05
    return {"P": ours["P"][significant] / theirs["P"][significant],
            "pi": ours["pi"] / theirs["pi"], "mfpt": ours["mfpt"] / theirs["mfpt"]}


def test_block_bootstrap_spread_agrees_with_deeptime_bayesian_msm(tmp_path):
    """Peer check (issue 14): on a known 6-state chain (200 particles x 100 transitions), the
    spread of the block bootstrap of the fitting window matches the posterior spread of
    deeptime's Bayesian MSM (Dirichlet posterior of the rows, Trendelkamp-Schroer et al.,
    J. Chem. Phys. 143, 174101 (2015)) for every transition probability above 0.05, every
    stationary probability and every mean first-passage time to state 0.

    With 50 blocks the bootstrap's own spread is well estimated: each ratio of SDs must lie in
    0.6-1.6 and the median over the transition probabilities within 15 % of 1 (measured:
    0.79-1.26 over the 38 ratios, median 1.00). With the default 10 blocks it is noisier (9
    degrees of freedom between blocks, about 24 % per ratio) and on average sqrt(9/10) lower
    (the plug-in variance of B block sums): the median over three chains must lie in 0.7-1.2
    (measured: 0.92, single ratios 0.36-1.42). Blocks that dropped the frame pair across
    each edge (the first version) count half the transitions with 50 blocks of 2 frames and
    fail this: median 1.42 over the transition probabilities, up to 1.78.
    """
    path, states, _ = _chain_file(tmp_path / "chain0.h5", seed=0)
    ratios = _sd_ratios(path, states, blocks=50, seed=0)
    for name, ratio in ratios.items():
        assert 0.6 < ratio.min() and ratio.max() < 1.6, (name, ratio)
    assert 0.85 < np.median(ratios["P"]) < 1.15, ratios["P"]
    pooled = []
    for seed in range(3):
        path, states, _ = _chain_file(tmp_path / f"chain{seed}.h5", seed=seed)
        pooled += [np.concatenate(list(_sd_ratios(path, states, blocks=10, seed=seed).values()))]
    assert 0.7 < np.median(np.concatenate(pooled)) < 1.2, np.median(np.concatenate(pooled))


def test_block_bootstrap_counts_every_frame_pair_once(tmp_path):
    """The blocks partition the frame pairs: with blocks of equal size every resample holds
    exactly the window's transitions (none lost at a block's edge); with unequal ones, on
    average."""
    path, states, _ = _chain_file(tmp_path / "chain.h5", seed=4, n_particles=20, n_frames=37)
    model = fit_model(path, CellGrid(2, 3, 1.0, 3.0), 1.0, (0.0, 36.0), "mle")
    assert model.counts.sum() == 20 * 36
    for blocks in (12, 36):                  # 3 and 1 frame pairs per block
        totals = {int(m.counts.sum()) for m in block_bootstrap_models(model, blocks=blocks,
                                                                      resamples=20)}
        assert totals == {20 * 36}
    totals = [m.counts.sum() for m in block_bootstrap_models(model, blocks=7, resamples=200)]
    assert np.mean(totals) == pytest.approx(20 * 36, rel=0.02)
    with pytest.raises(InputError, match="fewer than the 40 bootstrap blocks"):
        next(block_bootstrap_models(model, blocks=40, resamples=1))


# -- coverage over independent windows ------------------------------------------------------------
#: windows, particles, fitting and analysis window (s), resamples of the coverage test
WINDOWS, PARTICLES, FIT, LENGTH, RESAMPLES = 40, 300, 12.0, 2.0, 30


@pytest.mark.slow
def test_interval_coverage_on_independent_windows(tmp_path):
    """Issue 14: over independent synthetic windows of a known stationary chain, the 90 %
    intervals hold the chain's exact values (the model's own intervals, without the flow
    term) and the values observed in the analysis window (the full intervals, with the
    flow's variability) in a fraction close to 0.9.

    Each window: 300 particles sampled from the chain for 14 s; a model fitted on the first
    12 s (cells, the generator's own state space; 12 s so that the flow's variability is
    measured on four blocks of three mean residence times), a Monte Carlo prediction of the
    next 2 s from the frame at 12 s, and its intervals (30 resamples, 10 blocks). The
    truths: the generator's exact E(RT) and SD(RT) in a 2 s window, its expected mixing
    curve from the window's initial states (:func:`model_mixing_curve` of the generator) at
    the middle frame, and the E(RT) and SD(RT) the sampled particles show in 12-14 s. With 40 windows a
    coverage of 0.9 gives 36 +- 1.9 hits; the test asks for 30-39 per quantity (0.75-0.975;
    outside with probability 1.6 % at the level, binomial: 0.15 % below, 1.5 % above), and
    for 168-194 of the 200 together (0.84-0.97; outside with probability about 1 % were
    they independent). Measured: 33 and 38 of 40 for the chain's values, the mixing
    curve (37), 36 and 38 for the observed E(RT) and SD(RT). On a stationary flow the flow
    term is the reference's own sampling noise, small beside the model's; on a
    non-stationary one it is not (``docs/results``).
    """
    import numba

    true = synthetic.cell_chain(FLOW)
    exact = true.rtd(LENGTH)
    left_cols = _left_columns(true)
    hits = {"E(RT)": 0, "SD(RT)": 0, "mixing": 0, "observed E(RT)": 0, "observed SD(RT)": 0}
    threads = numba.get_num_threads()
    numba.set_num_threads(1)     # 40 x 41 tiny parallel placements wait long on a busy machine
    try:
        for w in range(WINDOWS):
            _coverage_window(tmp_path / f"w{w}.h5", w, true, exact, left_cols, hits)
    finally:
        numba.set_num_threads(threads)
    # at the level, 30-39 hits of 40 fail with probability 1.6 % (binomial)
    assert binom.cdf(29, WINDOWS, 0.9) + binom.sf(39, WINDOWS, 0.9) < 0.02
    for name, count in hits.items():
        assert 30 <= count <= 39, (name, count / WINDOWS)
    assert 168 <= sum(hits.values()) <= 194, hits


def _coverage_window(path, w: int, true, exact, left_cols, hits: dict) -> None:
    """One window of the coverage test: fit, predict, intervals; count the hits."""
    run = synthetic.write_run(path, FLOW, PARTICLES, FIT + LENGTH, seed=1000 + w)
    model = fit_model(run, FLOW.grid, FLOW.lag, (0.0, FIT), "mle")
    with Trajectories(run) as traj:
        observed = residence_times(traj, (FIT, FIT + LENGTH), use_events=False)
    times, states, laps = model.predict(run, FIT, LENGTH, seed=w)
    samples = residence_times_from_laps(times, laps)
    left = left_cols[states[0]]          # x < W/2 at the start: the cell's column
    curve = (left_cols[states] & left).mean(axis=1)
    edges, _ = rtd_histogram(samples, 0.1, window_length=LENGTH)
    iv = prediction_intervals(model, samples, edges, LENGTH, resamples=RESAMPLES, seed=w,
                              mixing=(times, curve), tracers=(states[0], left))
    truth, _ = model_mixing_curve(true, states[0], left, times.size - 1)
    middle = times.size // 2
    hits["E(RT)"] += iv.model_rt_mean[0] <= exact.mean <= iv.model_rt_mean[1]
    hits["SD(RT)"] += iv.model_rt_sd[0] <= exact.sd <= iv.model_rt_sd[1]
    hits["observed E(RT)"] += iv.rt_mean[0] <= observed.mean <= iv.rt_mean[1]
    hits["observed SD(RT)"] += iv.rt_sd[0] <= observed.sd <= iv.rt_sd[1]
    hits["mixing"] += iv.mixing[0, middle] <= truth[middle] <= iv.mixing[1, middle]


def test_compare_leaves_out_only_the_mixing_band_without_the_tracers_states(tmp_path):
    """A state space with memory needs the frames before the window start: where neither
    the reference nor the prediction has them, the mixing band is left out with a warning
    and the other intervals are given."""
    from cfbmarkov.markov import state_space_from_name
    from cfbmarkov.report.compare import compare
    from cfbmarkov.trajectories import Trajectories

    flow = synthetic.RiserFlow()
    run = synthetic.write_run(tmp_path / "run.h5", flow, 100, 3.0, seed=5)
    model = fit_model(run, state_space_from_name("cells-direction", 6, 38), flow.lag,
                      (0.5, 2.0), "mle")
    pred = model.predict(run, 2.0, 1.0, seed=1, output=tmp_path / "pred.h5")
    with Trajectories(run) as t:             # the reference from the window start on
        frames = t.window(2.0, 3.0)
        reference = write_trajectories(tmp_path / "ref.h5", t.times[frames],
                                       t.positions(frames), width=flow.width,
                                       height=flow.height, laps=t.laps(frames))
    summary = compare(reference, pred, window=(2.0, 3.0), output=tmp_path / "cmp",
                      figures=False, resamples=20)
    assert "rt_mean_interval" in summary["model"] and "mixing_interval" not in summary["model"]
    from cfbmarkov.markov.uncertainty import bootstrap_widening

    # the summary records the factor its bootstrap part was widened by (10 blocks, 1 run)
    assert summary["intervals"]["bootstrap_widening"] == pytest.approx(
        bootstrap_widening(0.9, 10))
    assert summary["units"]["flow_sd"].startswith("s (intervals.flow_sd")   # not relative
    assert any(w.startswith("no mixing interval: the tracers' states at 2 s") for w in
               summary["warnings"]), summary["warnings"]


# -- the flow's variability ---------------------------------------------------------------------
def _rising_run(path, speeds, dt=0.05, n=60, height=1.0):
    """Particles spread over the height, all rising at speeds[k] during frame step k (m/s),
    with lap counters: a flow whose residence time is H / speed."""
    rng = np.random.default_rng(0)
    y = np.empty((speeds.size + 1, n))
    y[0] = rng.uniform(0.0, height, n)
    for k, v in enumerate(speeds):
        y[k + 1] = y[k] + v * dt
    laps = np.floor(y / height).astype(np.int32)
    positions = np.stack([np.full_like(y, 0.05), y - laps * height], axis=-1)
    return write_trajectories(path, dt * np.arange(speeds.size + 1), positions, width=0.1,
                              height=height, laps=laps)


def test_flow_variability_sees_a_change_of_speed_and_no_steady_flow(tmp_path):
    """A steady flow (every residence 0.5 s) shows no variability of E(RT) between blocks; one whose
    solids rise twice as fast in the second half of the fitting window does, and the
    intervals of its E(RT) widen by it (the model's own do not). Blocks are at least three
    mean residences long: a window of 2 s has none to compare."""
    from cfbmarkov.analysis.intervals import flow_variability

    steady = _rising_run(tmp_path / "steady.h5", np.full(400, 2.0))            # 20 s
    change = _rising_run(tmp_path / "change.h5", np.repeat([2.0, 4.0], 200))
    grid = CellGrid(1, 4, 0.1, 1.0)
    m_steady = fit_model(steady, grid, 0.05, (0.0, 20.0), "mle")
    rel = flow_variability(m_steady, 20.0)
    assert rel is not None and rel[0] < 0.01        # (a frame's round-off moves a few by one frame)
    m_change = fit_model(change, grid, 0.05, (0.0, 20.0), "mle")
    variability = flow_variability(m_change, 20.0)
    rel_mean = variability.mean
    assert variability.degrees_of_freedom == 3      # four 5 s blocks, each against the rest
    # blocks 0-1 see 0.5 s, blocks 2-3 0.25 s: each block differs from the others' pooled
    # by a third or more, and sqrt(3 / 4) of that RMS is one block's relative SD, kept for
    # the 20 s window (a longer window is not taken as independent blocks: not halved)
    assert 0.3 < rel_mean < 0.7, rel_mean
    # windows at least a block (5 s) long keep it; a shorter one adds sampling noise
    assert flow_variability(m_change, 5.0)[0] == pytest.approx(rel_mean)
    assert flow_variability(m_change, 1.25)[0] == pytest.approx(2.0 * rel_mean)  # sqrt(5/1.25)
    assert flow_variability(fit_model(change, grid, 0.05, (0.0, 2.0), "mle"), 2.0) is None
    samples = np.full(50, 0.3) + np.linspace(-0.01, 0.01, 50)
    edges = np.linspace(0.0, 2.0, 41)
    with_flow = prediction_intervals(m_change, samples, edges, 2.0, resamples=10)
    without = prediction_intervals(m_change, samples, edges, 2.0, resamples=10, flow=False)
    assert with_flow.flow is not None and without.flow is None
    assert with_flow.model_rt_mean == without.rt_mean == without.model_rt_mean
    assert with_flow.rt_mean[1] - with_flow.rt_mean[0] > 2 * (without.rt_mean[1] - without.rt_mean[0])
    # a flow term larger than the value itself: the lower bounds stop at 0 (the 3 m/s paper
    # run's first window gave -0.89 s before they were cut)
    short = prediction_intervals(m_change, samples, np.linspace(0.0, 1.25, 26), 1.25,
                                 resamples=10)
    assert short.flow[0] > 0.3 / 2.3534       # t(3) * flow beyond the value: uncut, below 0
    assert short.flow_degrees_of_freedom == 3
    assert short.rt_mean[0] == 0.0 and short.rt_sd[0] >= 0.0 and short.rt_mean[1] > 0.3


def test_the_flow_term_takes_students_t_with_its_blocks_less_one():
    """A standard deviation from B blocks has B - 1 degrees of freedom: the flow term's
    multiplier is Student's t quantile with them (tables: t_0.95(1) = 6.314, t_0.95(3) =
    2.353, t_0.975(9) = 2.262), the normal one only where none are recorded; the interval
    adds t times the flow's SD to the bootstrap's half-widths in quadrature."""
    from cfbmarkov.analysis.bootstrap import flow_quantile, interval_bounds

    assert flow_quantile(0.9, 1) == pytest.approx(6.3138, abs=1e-4)
    assert flow_quantile(0.9, 3) == pytest.approx(2.3534, abs=1e-4)
    assert flow_quantile(0.95, 9) == pytest.approx(2.2622, abs=1e-4)
    assert flow_quantile(0.9, None) == pytest.approx(1.6449, abs=1e-4)
    assert flow_quantile(0.9, 10 ** 6) == pytest.approx(1.6449, abs=1e-4)
    with pytest.raises(InputError, match="degree of freedom"):
        flow_quantile(0.9, 0)
    boot = np.array([0.9, 1.0, 1.1])
    lo, hi = interval_bounds(1.0, boot, 1.0, 0.9, 0.0, 0.05, 1, blocks=10)
    q = np.quantile(boot, [0.05, 0.95])
    w = 1.1747         # the bootstrap's widening for 10 blocks (the test below)
    assert hi - 1.0 == pytest.approx(np.hypot(w * (q[1] - 1.0), 6.3138 * 0.05), abs=1e-4)
    assert 1.0 - lo == pytest.approx(np.hypot(w * (1.0 - q[0]), 6.3138 * 0.05), abs=1e-4)


def test_the_bootstraps_spread_is_widened_for_its_blocks():
    """The block bootstrap's spread from B blocks is sqrt((B - 1) / B) of the sum's standard
    error and an estimate with R (B - 1) degrees of freedom: its half-widths are widened by
    sqrt(B / (B - 1)) t_{R(B-1)} / z (t_0.95(9) = 1.8331, t_0.95(4) = 2.1318, t_0.95(18) =
    1.7341, z = 1.6449; tables), the Monte Carlo term is not."""
    from cfbmarkov.analysis.bootstrap import interval_bounds
    from cfbmarkov.markov.uncertainty import bootstrap_widening

    assert bootstrap_widening(0.9, 10) == pytest.approx(np.sqrt(10 / 9) * 1.8331 / 1.6449,
                                                        abs=1e-4)
    assert bootstrap_widening(0.9, 5) == pytest.approx(np.sqrt(5 / 4) * 2.1318 / 1.6449,
                                                       abs=1e-4)
    assert bootstrap_widening(0.9, 10, runs=2) == pytest.approx(
        np.sqrt(10 / 9) * 1.7341 / 1.6449, abs=1e-4)
    with pytest.raises(InputError, match="at least 2 blocks"):
        bootstrap_widening(0.9, 1)
    boot = np.array([0.8, 1.0, 1.2])
    q = np.quantile(boot, [0.05, 0.95])
    lo, hi = interval_bounds(1.0, boot, 1.0, 0.9, blocks=5)
    assert hi - 1.0 == pytest.approx(bootstrap_widening(0.9, 5) * (q[1] - 1.0))
    lo, hi = interval_bounds(1.0, np.ones(3), 1.0, 0.9, se=0.1, blocks=5)
    assert hi - 1.0 == pytest.approx(1.6449 * 0.1, abs=1e-4)


def test_model_mixing_curve_equals_the_matrix_powers(tmp_path):
    """The kernel's curve and SD equal the formulas evaluated with dense matrix powers, for
    a periodic and an open riser (to rounding)."""
    def reference(matrix, left_states, states, left, steps, is_open):
        present = states >= 0
        n_left = np.bincount(states[present & left], minlength=left_states.size)
        n_all = np.bincount(states[present], minlength=left_states.size)
        total = present.sum()
        mean, sd = [], []
        for k in range(steps + 1):
            power = np.linalg.matrix_power(matrix, k)
            h, g = power @ left_states, power @ np.ones(left_states.size)
            expected, spread = n_left @ h, n_left @ (h * (1 - h))
            if not is_open:
                mean.append(expected / total)
                sd.append(np.sqrt(spread) / total)
                continue
            alive = n_all @ g
            f = expected / alive
            mean.append(f)
            sd.append(np.sqrt(max(spread - 2 * f * (n_left @ (h * (1 - g)))
                                  + f * f * (n_all @ (g * (1 - g))), 0)) / alive)
        return np.array(mean), np.array(sd)

    model = synthetic.cell_chain(FLOW)
    rng = np.random.default_rng(3)
    states = rng.choice(model.n_states, 150)
    left = rng.random(150) < 0.5
    left_states = _left_columns(model).astype(float)
    mean, sd = model_mixing_curve(model, states, left, 25)
    want = reference(model.transition_matrix, left_states, states, left, 25, False)
    assert np.allclose(mean, want[0], rtol=1e-12, atol=1e-15)
    assert np.allclose(sd, want[1], rtol=1e-10, atol=1e-15)
    path = synthetic.write_open_run(tmp_path / "open.h5", FLOW, 200, 1.5, seed=5)
    opened_model = fit_model(path, FLOW.grid, FLOW.lag, (0.0, 1.5), "mle")
    states, positions, _ = opened_model.initial_states(path, 0.75)
    present = states >= 0
    left = present & (np.where(present, positions[:, 0], np.inf) < 0.5 * FLOW.width)
    mean, sd = model_mixing_curve(opened_model, states, left, 20)
    want = reference(np.asarray(opened_model.absorbing_matrix), left_states, states, left, 20,
                     True)
    assert np.allclose(mean, want[0], rtol=1e-12, atol=1e-15)
    assert np.allclose(sd, want[1], rtol=1e-10, atol=1e-15)


@pytest.mark.parametrize("estimator", ["mle", "paper"])
def test_sparse_bootstrap_chains_are_the_bootstrap_models(tmp_path, estimator):
    """The periodic intervals' resamples as sparse split chains: the same draws as
    block_bootstrap_models, with the same RTD in the window (both directions) and the same
    mixing curve to rounding, for both estimators and a space with memory."""
    from cfbmarkov.analysis.intervals import _bootstrap_chains, _resampled_rtd
    from cfbmarkov.markov import DirectionCells

    path = tmp_path / "run.h5"
    synthetic.write_run(path, FLOW, 300, 3.0, seed=6)
    space = DirectionCells(FLOW.columns, FLOW.rows, FLOW.width, FLOW.height)
    model = fit_model(path, space, FLOW.lag, (0.5, 2.5), estimator)
    entry = model.rtd(1.0).entry_distribution
    from cfbmarkov.markov.model_rtd import window_start_occupancy

    occupancy = window_start_occupancy(model)
    states, positions, _ = model.initial_states(path, 2.5)
    left = positions[:, 0] < 0.5 * FLOW.width
    dense = list(block_bootstrap_models(model, blocks=6, resamples=8, seed=3))
    sparse = list(_bootstrap_chains(model, 6, 8, 3))
    assert len(dense) == len(sparse) == 8
    for a, b in zip(dense, sparse):
        assert np.abs(a.transition_matrix - b.transition_matrix.toarray()).max() < 1e-14
        for direction in ("up", "down"):
            ra = _resampled_rtd(a, 1.0, direction, entry, None, occupancy)
            rb = _resampled_rtd(b, 1.0, direction, entry, None, occupancy)
            assert ra.mean == pytest.approx(rb.mean, rel=1e-10)
            assert ra.sd == pytest.approx(rb.sd, rel=1e-10)
        ma = model_mixing_curve(a, states, left, 12)[0]
        mb = model_mixing_curve(b, states, left, 12)[0]
        assert np.allclose(ma, mb, rtol=1e-12, atol=1e-15)
