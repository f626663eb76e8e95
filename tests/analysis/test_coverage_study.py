"""benchmarks/interval_coverage.py, the coverage study, on a small generated riser: its long-run
residences are residence_times' over the span, with their times; the study's table and
JSON."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.observed.residence import net_flow_direction, residence_times
from cfbmarkov.trajectories import Trajectories

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "interval_coverage.py"
FLOW = synthetic.RiserFlow(columns=3, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)


@pytest.fixture(scope="session")
def coverage():
    spec = importlib.util.spec_from_file_location("coverage_study", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def run(tmp_path_factory):
    return synthetic.write_run(tmp_path_factory.mktemp("coverage") / "run.h5", FLOW, 200, 6.0,
                               seed=2)


def test_residence_intervals_are_residence_times_with_their_times(coverage, run):
    with Trajectories(run) as traj:
        span = (0.5, 6.0)
        got = coverage.residence_intervals(traj, span, 0.05)
        want = residence_times(traj, span, use_events=False, lag_frames=traj.lag_frames(0.05),
                               direction=net_flow_direction(traj, span)).samples
    assert got.shape[0] == want.size > 50
    np.testing.assert_allclose(np.sort(got[:, 1] - got[:, 0]), np.sort(want), atol=1e-9)
    assert np.all(got[:, 0] >= span[0] - 1e-9) and np.all(got[:, 1] <= span[1] + 1e-9)
    outside = coverage.long_run_outside(got, (2.0, 3.0))
    inside = (got[:, 1] > 2.0) & (got[:, 0] < 3.0)
    assert outside.size == got.shape[0] - inside.sum() and inside.any()


def test_study_table_and_json(coverage, run, tmp_path, capsys):
    out = tmp_path / "cov.json"
    assert coverage.main([str(run), "--settle", "0.5", "--cells", "3x8", "--lag", "0.05",
                          "--lengths", "1,2", "--starts", "2", "--resamples", "10", "-q",
                          "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "coverage" in printed and str(out) in printed
    data = json.loads(out.read_text())
    assert [r["length"] for r in data["table"]] == [1.0, 2.0]
    assert len(data["fits"]) == 4
    for fit in data["fits"]:
        assert fit["long_run"] > 0 and fit["rt_mean"] > 0 and "warnings" in fit
        lo, hi = fit["rt_mean_interval"]
        assert lo <= fit["rt_mean"] <= hi
    for row in data["table"]:
        assert row["fits"] == 2 and 0.0 <= row["coverage"] <= 1.0
        assert row["off_warned"] <= row["off"]
        assert row["fits_flux"] == 2 and 0.0 <= row["coverage_flux"] <= 1.0
    with Trajectories(run) as traj:
        for fit in data["fits"]:
            # the flux long run: the particle-time of the span outside the window over its
            # net passes, by hand from the lap counters of the window's edges and the span's
            a, b = fit["window"]
            end = float(traj.times[-1])
            frames = [int(np.argmin(np.abs(np.asarray(traj.times) - t))) for t in (0.5, a, b, end)]
            laps = [traj.laps(k).astype(np.int64) for k in frames]
            passes = (laps[1] - laps[0]).sum() + (laps[3] - laps[2]).sum()
            time = (a - 0.5) + (end - b)
            assert fit["long_run_flux"] == pytest.approx(traj.n_particles * time / passes)
    # the references formed again for the study's fits, without fitting
    again = tmp_path / "again.json"
    assert coverage.main([str(run), "--rescore", str(out), "-o", str(again)]) == 0
    assert "net flux" in capsys.readouterr().out
    rescored = json.loads(again.read_text())
    assert rescored["table"] == data["table"]
    assert coverage.main([str(run), "--rescore", str(run), "-o", str(again)]) == 2
    assert "not a study's JSON" in capsys.readouterr().err
    assert coverage.main([str(run), "--lengths", "0,1", "-o", str(out)]) == 2
    assert "--lengths" in capsys.readouterr().err


def test_pooled_study_fits_every_window_on_all_runs(coverage, run, tmp_path, capsys):
    second = synthetic.write_run(tmp_path / "second.h5", FLOW, 200, 6.0, seed=5)
    out = tmp_path / "pool.json"
    assert coverage.main([str(run), str(second), "--pool", "--settle", "0.5", "--cells",
                          "3x8", "--lag", "0.05", "--lengths", "2", "--starts", "2",
                          "--resamples", "10", "-q", "-o", str(out)]) == 0
    data = json.loads(out.read_text())
    assert [r["model"] for r in data["table"]] == ["pool2"] and len(data["fits"]) == 2
    from cfbmarkov.markov.estimate import estimator_from_name
    from cfbmarkov.markov.pooling import discretize_runs

    space = synthetic.RiserFlow(columns=3, rows=8).grid
    fitter = estimator_from_name("paper", space, 0.05)
    with Trajectories(run) as a, Trajectories(second) as b:
        for fit in data["fits"]:
            window = tuple(fit["window"])
            # the model fit A B --window makes, on both runs' counts
            pooled = fitter.fit(discretize_runs([a, b], space, 0.05, [window]))
            assert fit["rt_mean"] == pytest.approx(pooled.rtd().mean, rel=1e-12)
            single = fitter.fit(discretize_runs([a], space, 0.05, [window]))
            assert fit["rt_mean"] != pytest.approx(single.rtd().mean, rel=1e-6)
            lo, hi = fit["rt_mean_interval"]
            assert lo <= fit["rt_mean"] <= hi
            # the flux long run: both runs' particle-time outside the window over their
            # net passes there
            times = np.asarray(a.times)
            frames = [int(np.argmin(np.abs(times - t))) for t in (0.5, *window, times[-1])]
            passes = sum((t.laps(frames[1]).astype(np.int64) - t.laps(frames[0])).sum()
                         + (t.laps(frames[3]).astype(np.int64) - t.laps(frames[2])).sum()
                         for t in (a, b))
            span = (window[0] - 0.5) + (times[-1] - window[1])
            assert fit["long_run_flux"] == pytest.approx(2 * 200 * span / passes)
    assert coverage.main([str(run), str(second), "--pool", "--auto", "-o", str(out)]) == 2
    assert "--pool" in capsys.readouterr().err
    assert coverage.main([str(run), str(second), "--rescore", str(out), "-o",
                          str(tmp_path / "again.json")]) == 2
    assert "run it again with --pool" in capsys.readouterr().err
