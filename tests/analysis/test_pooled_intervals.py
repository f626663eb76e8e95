"""Intervals of a model fitted on several runs (a pooled fit): each run's blocks resampled
within that run, the flow's term over all runs' blocks; a run pooled with itself refused."""

import contextlib
import json
import shutil

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.analysis.intervals import model_intervals
from cfbmarkov.cli import main
from cfbmarkov.markov import MarkovModel, fit_model
from cfbmarkov.markov.estimate import estimator_from_name
from cfbmarkov.markov.pooling import discretize_runs
from cfbmarkov.trajectories import Trajectories

FLOW = synthetic.RiserFlow(columns=3, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)
WINDOW = (0.5, 2.5)
RUNS = 4


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    """Four independent 3 s runs (seeds 10-13) of one stationary chain, 300 particles."""
    folder = tmp_path_factory.mktemp("pooled-intervals")
    return [synthetic.write_run(folder / f"run{k}.h5", FLOW, 300, 3.0, seed=10 + k)
            for k in range(RUNS)]


def _width(interval):
    return interval[1] - interval[0]


def test_pooling_n_independent_runs_narrows_the_interval_as_one_over_sqrt_n(runs):
    """The pooled model's E(RT) interval is 1/sqrt(4) = 0.5 times the median of the single
    runs' widths, within 0.3-0.75 (40 resamples: each width scatters by about 15 %); it
    holds the generating chain's E(RT), and each run keeps its weight: every resample has
    10 blocks of each run."""
    single = []
    for path in runs:
        model = fit_model(path, FLOW.grid, FLOW.lag, WINDOW, "mle")
        single.append(_width(model_intervals(model, resamples=40).rt_mean_interval))
    with contextlib.ExitStack() as stack:
        opened = [stack.enter_context(Trajectories(p)) for p in runs]
        data = discretize_runs(opened, FLOW.grid, FLOW.lag, [WINDOW])
    pooled = estimator_from_name("mle", FLOW.grid, FLOW.lag).fit(data)
    assert pooled.run_windows == (WINDOW,) * RUNS
    u = model_intervals(pooled, resamples=40)
    assert u.blocks == 10 * RUNS
    ratio = _width(u.rt_mean_interval) / np.median(single)
    assert 0.3 < ratio < 0.75, (ratio, single, u.rt_mean_interval)
    truth = synthetic.cell_chain(FLOW).rtd().mean
    lo, hi = u.rt_mean_interval
    assert lo <= pooled.rtd().mean <= hi
    assert lo - 0.5 * (hi - lo) <= truth <= hi + 0.5 * (hi - lo)


def test_fit_pooled_stores_and_prints_the_interval_and_refuses_a_run_with_itself(
        runs, tmp_path, capsys):
    out = tmp_path / "pooled.h5"
    assert main(["fit", str(runs[0]), str(runs[1]), "--cells", "3x8", "--estimator", "mle",
                 "--window", "0.5:2.5,0.4:2.4", "--resamples", "20", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "90 % interval" in printed and "fitting windows of 2 runs" in printed
    assert "windows 0.5:2.5, 0.4:2.4 s" in printed
    # the factor the bootstrap's spread was widened by, for 2 runs of 10 blocks: 18 dof
    assert "(their spread widened 1.11 times, for its 18 degrees of freedom)" in printed
    assert "10 blocks of each run, about 0.2 s long" in printed
    model = MarkovModel.load(out)
    assert model.run_windows == ((0.5, 2.5), (0.4, 2.4))
    assert model.uncertainty is not None and model.uncertainty.blocks == 20
    assert main(["rtd", str(out), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    lo, hi = data["rt_mean_interval"]
    assert lo <= data["rt_mean"] <= hi
    assert main(["info", str(out)]) == 0
    assert "fitting windows of 2 runs" in capsys.readouterr().out
    # windows of other lengths: their blocks' lengths by run, not one figure for both
    assert main(["fit", str(runs[0]), str(runs[1]), "--cells", "3x8", "--estimator", "mle",
                 "--window", "0.5:2.5,0.5:1.5", "--resamples", "20", "-q",
                 "-o", str(tmp_path / "unequal.h5")]) == 0
    assert "10 blocks of each run, 0.1 to 0.2 s long by run" in capsys.readouterr().out
    # the same run twice, a copy of it, or overlapping windows of one file: one line, exit 2
    copy = tmp_path / "copy.h5"
    shutil.copy(runs[0], copy)
    for argv, said in ([str(runs[0]), str(runs[0])], "same data"), \
                      ([str(runs[0]), str(copy)], "same data"), \
                      ([str(runs[0]), str(runs[0]), "--window", "0.5:2.5,1:2.8"], "overlap"):
        bad = tmp_path / "bad.h5"
        assert main(["fit", *argv, "--cells", "3x8", "-o", str(bad)]
                    + ([] if "--window" in argv else ["--window", "0.5:2.5"])) == 2
        err = capsys.readouterr().err
        assert said in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
        assert not bad.exists()


def test_a_copy_or_link_of_a_run_with_another_window_or_a_prediction_is_refused(
        runs, tmp_path, capsys):
    """A copy (or hard link) of a run pooled with it under another window counts the common
    frames twice (overlap) or takes one run's windows as independent flow (apart): refused
    as for one file given twice, naming the frame that shows it; a prediction pooled with a
    run is refused; independent runs of the same times and ids still pool."""
    copy, link = tmp_path / "copy.h5", tmp_path / "link.h5"
    shutil.copy(runs[0], copy)
    link.hardlink_to(runs[0])
    model = tmp_path / "m.h5"
    assert main(["fit", str(runs[0]), "--cells", "3x8", "--window", "0.5:2.5",
                 "--resamples", "0", "-o", str(model)]) == 0
    prediction = tmp_path / "p.h5"
    assert main(["predict", str(model), "--init", str(runs[0]), "--start", "0.5",
                 "--duration", "2", "--seed", "1", "-o", str(prediction)]) == 0
    capsys.readouterr()
    for other, windows, said in (
            (copy, "0.5:2.5,0.6:2.6", "overlap"), (copy, "0.2:1.4,1.5:2.9", "are both of"),
            (link, "0.5:2.5,0.6:2.6", "overlap"), (prediction, "0.5:2.5,0.5:1.9",
                                                   "is a Markov chain's prediction")):
        bad = tmp_path / "bad.h5"
        assert main(["fit", str(runs[0]), str(other), "--cells", "3x8", "--window", windows,
                     "-o", str(bad)]) == 2, (other, windows)
        err = capsys.readouterr().err
        assert said in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
        assert not bad.exists()
        if other != prediction:
            assert "which hold one run (their frames at t = 3 s hold the same particles" in err, err
    assert main(["fit", str(runs[0]), str(runs[1]), "--cells", "3x8", "--window",
                 "0.5:2.5,0.6:2.6", "--resamples", "0", "-o", str(tmp_path / "ok.h5")]) == 0


def test_pooled_fit_of_a_space_fitted_to_its_window(runs, tmp_path, capsys):
    """cells-velocity and cells-regime fit their bins on the window: pooled, the first run's
    bins are used for every run (the same states), and the interval is formed."""
    for states in ("cells-velocity", "cells-regime"):
        out = tmp_path / f"{states}.h5"
        assert main(["fit", str(runs[0]), str(runs[1]), "--cells", "3x8", "--states", states,
                     "--window", "0.5:2.5", "--resamples", "10", "-o", str(out)]) == 0, \
            capsys.readouterr().err
        model = MarkovModel.load(out)
        one = fit_model(runs[0], model.state_space, FLOW.lag, WINDOW, "paper")
        assert one.state_space == model.state_space
        assert model.uncertainty is not None


def test_compare_baseline_of_a_pooled_model_pools_its_runs_windows(tmp_path, capsys):
    """compare's persistence baseline for a pooled model: the residences of both runs'
    fitting windows pooled (as many as the two windows hold together)."""
    from dataclasses import replace

    from cfbmarkov.observed.residence import residence_times

    flow = replace(FLOW, columns=4)             # mixing by halves needs an even count
    runs = [synthetic.write_run(tmp_path / f"r{k}.h5", flow, 200, 3.0, seed=30 + k)
            for k in range(2)]
    model = tmp_path / "pooled.h5"
    assert main(["fit", str(runs[0]), str(runs[1]), "--cells", "4x8", "--window", "0.5:2",
                 "--resamples", "0", "--no-adequacy", "-o", str(model)]) == 0
    pred = tmp_path / "pred.h5"
    assert main(["predict", str(model), "--init", str(runs[0]), "--start", "2", "--duration",
                 "1", "-o", str(pred), "-q"]) == 0
    out = tmp_path / "cmp"
    assert main(["compare", str(runs[0]), str(pred), "--window", "2:3", "-o", str(out),
                 "--no-figures", "--resamples", "0"]) == 0
    printed = capsys.readouterr().out
    baseline = json.loads((out / "summary.json").read_text())["baseline"]
    assert baseline["runs"] == 2
    assert ("persistence baseline (the observed RTD of the model's fitting windows in its 2 "
            "runs, pooled as it was fitted, taken as the prediction)") in printed
    counts = []
    for path in runs[:2]:
        with Trajectories(path) as traj:
            counts.append(residence_times(traj, (0.5, 2.0), use_events=False,
                                          lag_frames=traj.lag_frames(FLOW.lag)).count)
    assert baseline["rt_count"] == sum(counts) and min(counts) > 0


def test_assess_fit_of_a_pooled_model_takes_each_run_and_its_window(runs):
    """``assess_fit`` of a model fitted on two runs with different windows, without
    ``runs=`` or ``windows=``: the runs and windows the model records, the same interval as
    given them by hand."""
    from cfbmarkov.analysis.fit_checks import assess_fit

    windows = [(0.5, 2.5), (0.25, 2.75)]
    with contextlib.ExitStack() as stack:
        opened = [stack.enter_context(Trajectories(p)) for p in runs[:2]]
        data = discretize_runs(opened, FLOW.grid, FLOW.lag, windows)
    pooled = estimator_from_name("mle", FLOW.grid, FLOW.lag).fit(data)
    assert list(pooled.run_windows) == windows
    found = assess_fit(pooled, resamples=20, verdict=False)
    given = assess_fit(pooled, [str(p) for p in runs[:2]], windows, resamples=20,
                       verdict=False)
    assert found.uncertainty is not None
    assert found.uncertainty.rt_mean_interval == given.uncertainty.rt_mean_interval
    # once the model records its windows' content, other data are refused: one of its
    # runs alone, or another run in its place
    from cfbmarkov.errors import InputError

    for other in ([str(runs[0])], [str(runs[0]), str(runs[2])]):
        with pytest.raises(InputError, match="not the data the model was fitted on"):
            assess_fit(found, other, windows[:len(other)], resamples=20, verdict=False)


def test_a_run_whose_window_is_too_short_to_halve_is_judged_with_the_others(runs, tmp_path,
                                                                           capsys):
    """One run's window of one lag beside another's of seconds: the verdict's pooled halves
    leave the short one out rather than refuse the fit naming a half-window never given."""
    out = tmp_path / "m.h5"
    long = [synthetic.write_run(tmp_path / f"long{k}.h5", FLOW, 500, 6.0, seed=30 + k)
            for k in range(2)]
    assert main(["fit", str(long[0]), str(long[1]), "--cells", "3x8", "--window",
                 "1:5,1:1.025", "--estimator", "mle", "--resamples", "0", "-o",
                 str(out)]) == 0
    assert out.exists() and "1.0125" not in capsys.readouterr().err


def test_a_copy_of_a_tracer_out_of_view_at_its_end_is_one_run(tmp_path):
    """One tracer out of view for its last 100 frames (a PEPT track's way): a copy of its
    file is still found to hold the same run (the latest common frame with the tracer in
    view), and runs of another seed are not."""
    from cfbmarkov.errors import InputError
    from cfbmarkov.markov.pooling import check_runs_distinct, same_run_frame
    from cfbmarkov.trajectory_writer import write_trajectories

    def track(path, seed):
        rng = np.random.default_rng(seed)
        t = 0.01 * np.arange(400)
        y = np.mod(0.3 + np.cumsum(rng.normal(0.01, 0.004, t.size)), 0.95)
        x = 0.045 + 0.01 * np.sin(t + seed)
        present = np.ones((t.size, 1), bool)
        present[-100:] = False
        return write_trajectories(path, t, np.stack([x, y], axis=-1)[:, None, :], width=0.09,
                                  height=0.95, present=present)

    one, other = track(tmp_path / "a.h5", 1), track(tmp_path / "b.h5", 2)
    copy = tmp_path / "copy.h5"
    shutil.copy(one, copy)
    with contextlib.ExitStack() as stack:
        a, b, c = (stack.enter_context(Trajectories(p)) for p in (one, copy, other))
        assert same_run_frame(a, b) == pytest.approx(2.99)
        assert same_run_frame(a, c) is None
        with pytest.raises(InputError, match="which hold one run"):
            check_runs_distinct([a, b], [(0.0, 1.5), (1.6, 3.0)])
        check_runs_distinct([a, c], [(0.0, 1.5), (1.6, 3.0)])


def test_a_copy_with_its_clock_shifted_is_one_run(tmp_path, capsys):
    """The same particles and positions under times shifted by 10 s (a copy re-exported
    from another origin) share no frame time, so no frame of one time shows them one run;
    the frames as far into each window do, or, for windows offset from each other, the
    frames of one index: refused in one line, nothing written. An
    independent run under the shifted clock still pools."""
    original = synthetic.write_run(tmp_path / "a.h5", FLOW, 300, 3.0, seed=20)
    shifted = synthetic.write_run(tmp_path / "b.h5", FLOW, 300, 3.0, seed=20,
                                  start_time=10.0)
    bad = tmp_path / "bad.h5"
    assert main(["fit", str(original), str(shifted), "--cells", "3x8", "--window",
                 "0.5:2.5,10.5:12.5", "-o", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "hold the same particles at the same positions at 2.5 s and 12.5 s" in err, err
    assert "one run under two clocks" in err and len(err.strip().splitlines()) == 1
    assert not bad.exists()
    # windows offset from each other (0.5-2.5 s against the copy's 11-13 s, its 1-3 s):
    # no frames as far into each are one run's, but frames of one index are (a review
    # pooled such a copy into an interval narrower than the run's own, "the runs agree")
    assert main(["fit", str(original), str(shifted), "--cells", "3x8", "--window",
                 "0.5:2.5,11:13", "-o", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "one run under two clocks" in err and len(err.strip().splitlines()) == 1
    assert not bad.exists()
    other = synthetic.write_run(tmp_path / "c.h5", FLOW, 300, 3.0, seed=21, start_time=10.0)
    assert main(["fit", str(original), str(other), "--cells", "3x8", "--window",
                 "0.5:2.5,10.5:12.5", "--resamples", "0", "-o", str(tmp_path / "ok.h5")]) == 0


def test_a_pooled_chain_is_held_against_its_runs_windows_together(runs):
    """The pooled model against its own fitting windows: each run's window seen by the
    chain, pooled (the residences' counts add, their mean and SD from the runs' moments);
    windows of different lengths give none."""
    import math

    from cfbmarkov.analysis.adequacy import _on_window, _pooled_on_window

    windows = [WINDOW, WINDOW]
    with contextlib.ExitStack() as stack:
        opened = [stack.enter_context(Trajectories(p)) for p in runs[:2]]
        data = discretize_runs(opened, FLOW.grid, FLOW.lag, windows)
        model = estimator_from_name("mle", FLOW.grid, FLOW.lag).fit(data)
        each = [_on_window(model, run, d) for run, d in zip(opened, data)]
        pooled = _pooled_on_window(model, opened, data)
        assert len(pooled) == 6 and all(len(e) == 6 for e in each)
        assert pooled[0] == pytest.approx(2.0) and pooled[5] == each[0][5] + each[1][5]
        n = np.array([e[5] for e in each])
        # E(RT), SD(RT): the chain's, a mixture of distributions
        mean = float(n @ [e[1] for e in each]) / n.sum()
        second = float(n @ [e[2] ** 2 + e[1] ** 2 for e in each]) / n.sum()
        assert pooled[1] == pytest.approx(mean, rel=1e-12)
        assert pooled[2] == pytest.approx(math.sqrt(second - mean ** 2), rel=1e-12)
        # the residences': samples whose SDs are with ddof = 1, pooled as all of them would
        # give it (a review found the mixture's divisor n - runs, not n - 1)
        mean = float(n @ [e[3] for e in each]) / n.sum()
        squares = sum((m - 1) * e[4] ** 2 + m * (e[3] - mean) ** 2 for m, e in zip(n, each))
        assert pooled[3] == pytest.approx(mean, rel=1e-12)
        assert pooled[4] == pytest.approx(math.sqrt(squares / (n.sum() - 1)), rel=1e-12)
        # a chain on the cells of a flow that is a chain on them: within the limit
        assert abs(pooled[2] / pooled[4] - 1) < 0.25
        other = discretize_runs(opened, FLOW.grid, FLOW.lag, [WINDOW, (0.5, 2.0)])
        assert _pooled_on_window(model, opened, other) == ()


@pytest.mark.parametrize("change", ["reordered", "renumbered", "a part", "rounded"])
def test_a_copy_reordered_renumbered_or_in_part_is_one_run(runs, tmp_path, capsys, change):
    """A copy of a run written with its particles in another order, under other ids, with
    half of them, or with its coordinates rounded to 0.1 mm (written again to fewer
    decimals), holds the same positions: pooled as a second run it narrowed the interval as
    independent flow would (4.6 times on the tutorial's run; 0.79 times for a copy rounded
    to 10 um). Refused in one line, nothing written; coordinates shared by chance (a few of
    an independent run's, set equal) are not taken for one run."""
    from cfbmarkov.markov.pooling import shared_positions
    from cfbmarkov.trajectory_writer import write_trajectories

    with Trajectories(runs[0]) as t:
        times, positions = np.asarray(t.times), np.asarray(t.positions(slice(None)))
        laps, ids = np.asarray(t.laps(slice(None))), np.asarray(t.ids)
    order = np.random.default_rng(3).permutation(ids.size)
    if change == "a part":
        order = order[: ids.size // 2]
    if change == "rounded":             # written again to 4 decimals (0.1 mm)
        positions = np.round(positions, 4)
    copy = write_trajectories(tmp_path / "copy.h5", times, positions[:, order],
                              laps=laps[:, order],
                              ids=ids[order] + (10000 if change == "renumbered" else 0),
                              width=0.09, height=0.95, source="synthetic")
    bad = tmp_path / "bad.h5"
    assert main(["fit", str(runs[0]), str(copy), "--cells", "3x8", "--window", "0.5:2.5",
                 "-o", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "which hold one run" in err and len(err.strip().splitlines()) == 1, err
    assert not bad.exists()
    # an independent run with a tenth of its particles put where the first run's are
    with Trajectories(runs[1]) as t:
        other_positions = np.array(t.positions(slice(None)))
        other_laps = np.array(t.laps(slice(None)))
    other_positions[:, : ids.size // 10] = positions[:, : ids.size // 10]
    other_laps[:, : ids.size // 10] = laps[:, : ids.size // 10]
    near = write_trajectories(tmp_path / "near.h5", times, other_positions, laps=other_laps,
                              ids=ids, width=0.09, height=0.95, source="synthetic")
    with Trajectories(runs[0]) as a, Trajectories(near) as b, Trajectories(copy) as c:
        last = len(times) - 1
        assert not shared_positions(a, last, b, last)
        assert shared_positions(a, last, c, last)


def test_members_started_from_one_state_are_independent_runs(tmp_path):
    """Two random walks from one first frame (an ensemble's members) share that frame and
    nothing later: pooled, whatever their windows (the check of frames of one index had
    refused them as one run under two clocks, at 0 s and 0 s)."""
    from cfbmarkov.markov.pooling import check_runs_distinct
    from cfbmarkov.trajectory_writer import write_trajectories

    rng = np.random.default_rng(0)
    start = np.stack([rng.uniform(0, 0.09, 50), rng.uniform(0, 0.95, 50)], -1)
    paths = []
    for member in range(2):
        steps = np.random.default_rng(100 + member).normal(0, 1e-3, (199, 50, 2))
        pos = np.concatenate([start[None], start[None] + np.cumsum(steps, axis=0)])
        pos[..., 0] = np.clip(pos[..., 0], 0, 0.09)
        pos[..., 1] = np.mod(pos[..., 1], 0.95)
        paths.append(write_trajectories(tmp_path / f"m{member}.h5", np.arange(200) * 0.01,
                                        pos, width=0.09, height=0.95))
    with contextlib.ExitStack() as stack:
        runs = [stack.enter_context(Trajectories(p)) for p in paths]
        for windows in ([(0.5, 1.99)] * 2, [(0.0, 1.99)] * 2):
            check_runs_distinct(runs, windows)          # no refusal


def test_a_pooled_summary_names_the_pooled_rule_for_the_flow_term(runs, tmp_path):
    """A pooled fit whose 2 s windows hold no block of three mean residence times: its
    summary's interval line names the pooled rule (a block of each run's window), as its
    warning does, not the single window's two blocks."""
    model = tmp_path / "pooled.h5"
    assert main(["fit", *map(str, runs[:2]), "--cells", "3x8", "--window", "0.5:2.5",
                 "--resamples", "20", "-q", "-o", str(model)]) == 0
    fitted = MarkovModel.load(model)
    assert fitted.uncertainty.flow_sd is None
    text = fitted.summary(warnings=False)
    assert ("the flow's variability left out (fewer than two of the runs' windows hold a "
            "block of three mean residence times)") in text


def test_copies_on_a_decimal_grid_are_one_run_and_packed_independent_runs_are_not(tmp_path):
    """A copy written to 4 decimals (or 6 significant digits) of a small riser's run is one
    run; two independent
    dense packings of 0.5 mm discs in a 3 m riser are not (compared within a tolerance set
    by the riser's size, 64 % of their particles would match and they would be refused)."""
    from cfbmarkov.markov.pooling import rounding_step, shared_positions
    from cfbmarkov.trajectory_writer import write_trajectories

    rng = np.random.default_rng(4)

    def write(name, xy, width, height):
        times = np.array([0.0, 0.01])
        positions = np.stack([xy, xy])
        return write_trajectories(tmp_path / name, times, positions, width=width,
                                  height=height, source="synthetic")

    small = np.stack([rng.uniform(0, 0.04, 3000), rng.uniform(0, 0.3, 3000)], -1)
    run, copy = write("run.h5", small, 0.04, 0.3), write("copy.h5", np.round(small, 4), 0.04,
                                                         0.3)
    # packed grains: on a grid of 0.5 mm with a little jitter, two seeds
    grid = np.stack(np.meshgrid(np.arange(0.00025, 0.1, 0.0005),
                                np.arange(0.00025, 3.0, 0.0005)), -1).reshape(-1, 2)
    packed = [write(f"p{s}.h5", grid + np.random.default_rng(s).normal(0, 5e-5, grid.shape)
                    .clip(-2e-4, 2e-4), 0.1, 3.0) for s in (1, 2)]
    with Trajectories(run) as a, Trajectories(copy) as b:
        assert rounding_step(np.asarray(b.positions(1))) == pytest.approx(1e-4)
        assert rounding_step(np.asarray(a.positions(1))) is None
        assert shared_positions(a, 1, b, 1)
    # written to 6 significant digits ('%.6g': a step per magnitude), to 10, or as
    # float32: one run too
    for name, copied in (("g6", [[float(f"{v:.6g}") for v in row] for row in small]),
                         ("g10", [[float(f"{v:.10g}") for v in row] for row in small]),
                         ("f32", small.astype(np.float32).astype(np.float64))):
        with Trajectories(run) as a, Trajectories(write(f"{name}.h5", np.array(copied), 0.04,
                                                        0.3)) as b:
            assert shared_positions(a, 1, b, 1), name
    with Trajectories(packed[0]) as a, Trajectories(packed[1]) as b:
        assert not shared_positions(a, 1, b, 1)
