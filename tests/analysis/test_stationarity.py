"""Sliding-window statistics of a run and the long-run baseline (analysis/stationarity.py,
``cfbmarkov stationarity``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cfbmarkov.observed.metrics import minkowski_distance
from cfbmarkov.observed.residence import residence_times, rtd_histogram
from cfbmarkov.analysis.stationarity import long_run_baseline, window_statistics
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

from ..observed.conftest import HEIGHT, WIDTH, generate_run


def _stationary(tmp_path, seed=3):
    run = generate_run(n_particles=200, t1=4.0, seed=seed)
    return write_trajectories(tmp_path / "steady.h5", run.times, run.positions, width=WIDTH,
                              height=HEIGHT)


def _surging(tmp_path):
    """The same particles rise at 1.6 m/s for 2 s, then at 0.8 m/s for 2 s."""
    fast = generate_run(n_particles=200, t0=0.0, t1=2.0, seed=4, rise=1.6)
    slow = generate_run(n_particles=200, t0=2.0, t1=4.0, seed=5, rise=0.8,
                        initial=fast.positions[-1])
    times = np.concatenate([fast.times, slow.times[1:]])
    positions = np.concatenate([fast.positions, slow.positions[1:]])
    return write_trajectories(tmp_path / "surging.h5", times, positions, width=WIDTH,
                              height=HEIGHT)


def test_window_statistics_are_each_windows_residence_times(tmp_path):
    path = _stationary(tmp_path)
    with Trajectories(path) as traj:
        stats = window_statistics(traj, window_length=1.0, step=0.5, span=(0.5, 4.0))
        assert np.allclose(stats.starts, [0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
        for start, mean, sd, count in zip(stats.starts, stats.rt_mean, stats.rt_sd,
                                          stats.rt_count):
            rt = residence_times(traj, (start, start + 1.0), use_events=False)
            assert count == rt.count > 20
            assert mean == pytest.approx(rt.mean, rel=1e-12)
            assert sd == pytest.approx(rt.sd, rel=1e-12)
        assert stats.direction == ("up",) * 6 and not stats.exact
        assert stats.relative_sd_rt_mean == pytest.approx(
            np.std(stats.rt_mean, ddof=1) / np.mean(stats.rt_mean), rel=1e-12)
        summary = stats.summary()
        assert summary["windows"][0] == [0.5, 1.5] and len(summary["rt_mean"]) == 6
        json.dumps(summary)
        # each window's flux E(RT): its particle-time over its net passes, by hand
        times = np.asarray(traj.times)
        for start, flux in zip(stats.starts, stats.flux_rt_mean):
            i, j = (int(np.argmin(np.abs(times - t))) for t in (start, start + 1.0))
            passes = (traj.laps(j).astype(np.int64) - traj.laps(i).astype(np.int64)).sum()
            assert flux == pytest.approx(traj.n_particles * (times[j] - times[i]) / passes)
        assert summary["flux_rt_mean"] == pytest.approx(list(stats.flux_rt_mean))


def test_a_surging_flow_scatters_more_than_a_steady_one(tmp_path):
    with Trajectories(_stationary(tmp_path)) as steady, Trajectories(_surging(tmp_path)) as surge:
        calm = window_statistics(steady, window_length=1.0, step=0.5)
        moving = window_statistics(surge, window_length=1.0, step=0.5)
    # particles at half the speed stay about twice as long: E(RT) moves by tens of per cent
    assert moving.relative_sd_rt_mean > 0.2
    assert moving.relative_sd_rt_mean > 3 * calm.relative_sd_rt_mean


def test_long_run_baseline_pools_the_other_whole_windows(tmp_path):
    path = _stationary(tmp_path)
    with Trajectories(path) as traj:
        judged = (2.0, 3.0)
        result = long_run_baseline(traj, judged, span=(0.3, 4.0), bin_width=0.025)
        # tiles aligned with 2-3 s inside 0.3-4 s: 1-2 and 3-4 (0-1 starts before the span)
        pooled = np.concatenate([residence_times(traj, w, use_events=False).samples
                                 for w in ((1.0, 2.0), (3.0, 4.0))])
        observed = residence_times(traj, judged, use_events=False)
        assert result.windows == ((1.0, 4.0), judged)     # the pooled windows and the judged
        assert result.predicted.count == pooled.size
        assert result.predicted.mean == pytest.approx(pooled.mean(), rel=1e-12)
        assert result.pd_rt_mean == pytest.approx(100 * (pooled.mean() / observed.mean - 1),
                                                  rel=1e-9)
        _, a = rtd_histogram(pooled, 0.025, window_length=1.0)
        _, b = rtd_histogram(observed.samples, 0.025, window_length=1.0)
        assert result.md_rtd == pytest.approx(minkowski_distance(a, b), rel=1e-12)


def test_the_long_run_of_a_surging_flow_misses_each_half(tmp_path):
    """Pooled over both regimes, the long run sits between them: it understates E(RT) of the
    slow half's windows by tens of per cent and overstates the fast half's."""
    with Trajectories(_surging(tmp_path)) as traj:
        slow = long_run_baseline(traj, (3.0, 4.0), bin_width=0.025)
        fast = long_run_baseline(traj, (0.0, 1.0), bin_width=0.025)
    assert slow.pd_rt_mean < -15 and fast.pd_rt_mean > 0


def test_bad_windows_are_refused(tmp_path):
    path = _stationary(tmp_path)
    with Trajectories(path) as traj:
        with pytest.raises(InputError, match="two at least"):
            window_statistics(traj, window_length=3.0, step=2.0)
        with pytest.raises(InputError, match="outside the frames"):
            window_statistics(traj, span=(1.0, 9.0), window_length=1.0)
        with pytest.raises(InputError, match="no other whole"):
            long_run_baseline(traj, (1.0, 3.0), span=(0.5, 4.0), bin_width=0.025)
        with pytest.raises(InputError, match="outside the span"):
            long_run_baseline(traj, (3.0, 4.0), span=(0.0, 3.0), bin_width=0.025)


def test_a_run_whose_particles_never_circulate_is_refused(tmp_path, capsys):
    """Particles that jitter below the top and never pass the boundary: no window holds a
    residence, and the run is refused in one line (not a table of empty windows, each
    labelled as an upflow); windows merely shorter than the residences keep their table."""
    rng = np.random.default_rng(0)
    times = 0.025 * np.arange(161)
    positions = np.stack([rng.uniform(0.0, WIDTH, (161, 50)),
                          rng.uniform(0.01, 0.3, (161, 50))], axis=-1)
    path = write_trajectories(tmp_path / "still.h5", times, positions, width=WIDTH,
                              height=HEIGHT)
    with Trajectories(path) as traj, pytest.raises(InputError, match="no particle passes the "
                                                                      "periodic boundary"):
        window_statistics(traj, window_length=1.0, step=0.5)
    assert main(["stationarity", str(path), "--window-length", "1", "--step", "0.5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "its lap counters never change" in err


def test_cli_prints_the_windows_and_the_judged_window(tmp_path, capsys):
    path = _stationary(tmp_path)
    assert main(["stationarity", str(path), "--window-length", "1", "--step", "0.5",
                 "--judge", "3:4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    with Trajectories(path) as traj:
        stats = window_statistics(traj, window_length=1.0, step=0.5)
        persistence = residence_times(traj, (2.0, 3.0), use_events=False)
        judged = residence_times(traj, (3.0, 4.0), use_events=False)
    assert out["rt_mean"] == pytest.approx(list(stats.rt_mean), rel=1e-12)
    assert out["judged"]["long_run"]["windows"] == [[0.0, 4.0], [3.0, 4.0]]
    assert out["judged"]["persistence"]["pd_rt_mean"] == pytest.approx(
        100 * (persistence.mean / judged.mean - 1), rel=1e-9)
    assert main(["stationarity", str(path), "--window-length", "1", "--judge", "3:4"]) == 0
    text = capsys.readouterr().out
    assert "relative SD" in text and "long run" in text and "persistence" in text
    assert "flux E(RT) (s)" in text and "net passes" in text
    assert "the long run's one window" not in text
    # the flux E(RT)'s scatter, which a chain fitted on one window follows, summarised too
    assert main(["stationarity", str(path), "--window-length", "1", "--judge", "3:4",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    flux = np.asarray(out["flux_rt_mean"], float)
    assert out["relative_sd_flux_rt_mean"] == pytest.approx(flux.std(ddof=1) / flux.mean(),
                                                            rel=1e-9)
    assert (f"flux E(RT) from {flux.min():.4g} to {flux.max():.4g} s (median "
            f"{np.median(flux):.4g} s, relative SD {100 * flux.std(ddof=1) / flux.mean():.1f} "
            "%): the throughput a chain fitted on one 1 s window carries") in text
    # a span of two windows: the long run is the persistence window, said once
    assert main(["stationarity", str(path), "--window-length", "1", "--span", "2:4",
                 "--judge", "3:4"]) == 0
    text = capsys.readouterr().out
    assert "persistence (the 2-3 s window): the long run's one window, so the same figures" in text


def test_cli_refuses_a_window_longer_than_the_file_in_one_line(tmp_path, capsys):
    path = _stationary(tmp_path)
    assert main(["stationarity", str(path), "--window-length", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "two at least" in err[0]


def test_an_open_riser_counts_entries_to_exits_in_each_window(tmp_path):
    from cfbmarkov.synthetic import RiserFlow, write_open_run

    path = write_open_run(tmp_path / "open.h5", RiserFlow(), 600, 6.0, seed=4)
    with Trajectories(path) as traj:
        stats = window_statistics(traj, window_length=2.0, step=2.0)
        assert stats.starts.size == 3 and stats.direction == ("up",) * 3
        assert stats.flux_rt_mean is None and stats.summary()["flux_rt_mean"] is None
        for start, count, mean in zip(stats.starts, stats.rt_count, stats.rt_mean):
            rt = residence_times(traj, (start, start + 2.0), use_events=False)
            assert count == rt.count > 5 and mean == pytest.approx(rt.mean, rel=1e-12)
        long_run = long_run_baseline(traj, (4.0, 6.0), bin_width=0.025)
        assert long_run.predicted.count == sum(
            residence_times(traj, w, use_events=False).count for w in ((0.0, 2.0), (2.0, 4.0)))


def test_cli_refusals_and_undefined_values(tmp_path, capsys):
    """A lag as long as the window, exact events a file does not hold, a judged window outside
    the span: one line, exit code 2. Windows without residences: n/d in the table, null in
    the JSON (strict JSON, no NaN)."""
    path = _stationary(tmp_path)
    for args, message in ((["--lag", "1"], "no residence time inside"),
                          (["--basis", "events"], "no exact pass events"),
                          (["--judge", "3:5"], "--judge 3:5 s lies outside the span")):
        assert main(["stationarity", str(path), "--window-length", "1", *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    # windows of 0.4 s, most of which hold no residence (a residence lasts about 0.19 s,
    # frames every 0.025 s)
    tiny = ["stationarity", str(path), "--window-length", "0.4", "--step", "0.05", "--lag",
            "0.025", "--judge", "0:0.4"]
    assert main([*tiny, "--json"]) == 0

    def no_nan(name):
        raise AssertionError(f"{name} in the JSON")
    out = json.loads(capsys.readouterr().out, parse_constant=no_nan)
    assert out["windows"][5] == [0.25, 0.65]          # no round-off in the window times
    assert None in out["rt_mean"] and out["judged"]["persistence"] is None
    assert main(tiny) == 0
    text = capsys.readouterr().out
    assert "n/d" in text and "nan" not in text and "fewer than 100 residences" in text
    assert "persistence: no whole 0.4 s window before 0 s in the span" in text


def test_options_of_the_other_mode_and_a_percentage_tolerance_are_refused(tmp_path, capsys):
    """Each option belongs to the sliding windows or to --sample-length; given to the other
    it would be ignored without a word, so it is refused in one line naming it. A tolerance
    of 10 (meaning 10 %) would judge within 1000 %: refused naming 0.1."""
    path = str(_stationary(tmp_path))
    for args, message in (
            (["--start", "1"], "--start: of --sample-length only"),
            (["--states", "cells-direction", "--tolerance", "0.2"],
             "--tolerance, --states: of --sample-length only"),
            (["--sample-length", "--step", "2"], "--step: of the sliding windows"),
            (["--sample-length", "--basis", "events"], "--basis: of the sliding windows"),
            (["--sample-length", "--tolerance", "10"], "(0.1 for 10 %)")):
        assert main(["stationarity", path, *args]) == 2, args
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert main(["stationarity", path, "--window-length", "1", "--step", "1"]) == 0
    capsys.readouterr()


def test_a_face_band_on_a_periodic_riser_is_refused(tmp_path, capsys):
    from cfbmarkov.cli import main
    from cfbmarkov.synthetic import RiserFlow, write_run

    run = write_run(tmp_path / "r.h5", RiserFlow(), 100, 3.0, seed=1)
    assert main(["stationarity", str(run), "--window-length", "1", "--cells", "4x10"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a periodic riser: a face band (--cells)" in err


def test_an_open_riser_without_residences_in_a_thin_face_band_names_the_band(tmp_path,
                                                                           capsys):
    """An open riser read with a face band thinner than a particle's step per frame: the
    refusal of windows without residences names the band beside a longer window."""
    from cfbmarkov.synthetic import RiserFlow, write_open_run

    run = write_open_run(tmp_path / "open.h5", RiserFlow(), 100, 4.0, seed=2)
    assert main(["stationarity", str(run), "--window-length", "1", "--cells", "6x500"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no residence begins and ends in any of the" in err
    assert "farther than the face band" in err and err.strip().endswith(
        "and a residence must fit in a window: give a longer --window-length (several mean "
        "residence times)")


def test_windows_that_hold_no_residence_are_refused(tmp_path, capsys):
    """Windows too short for any residence would print a table of n/d: refused in one line
    naming --window-length, as compare refuses a window without residences."""
    from cfbmarkov.cli import main

    path = str(_stationary(tmp_path))
    assert main(["stationarity", path, "--window-length", "0.05", "--step", "0.05",
                 "--span", "1:1.2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no residence begins and ends in any of the 4 windows" in err
    assert "give a longer --window-length" in err
    assert main(["stationarity", path, "--window-length", "1", "--step", "1"]) == 0
    capsys.readouterr()


def test_windows_of_both_directions_are_warned_of_as_not_one_flows_figures():
    """A span whose net flow turns: its windows count residences in both directions, and
    their average and scatter mix them; the warning names each direction's windows. Windows
    of one direction give none."""
    from types import SimpleNamespace

    from cfbmarkov.analysis.stationarity import turned_direction_warning

    stats = SimpleNamespace(direction=("up", "down", "down"),
                            starts=np.array([1.5, 2.5, 3.5]), window_length=1.0)
    line = turned_direction_warning(stats)
    assert line.startswith("the net solids flow turns within the span: 1 window(s) count "
                           "residences up through the top (1.5-2.5 s), 2 down through the "
                           "bottom (2.5-3.5, 3.5-4.5 s)")
    assert "mix the two directions" in line
    assert turned_direction_warning(SimpleNamespace(
        direction=("up", "up"), starts=np.array([0.0, 1.0]), window_length=1.0)) is None
