"""Frame times on awkward data: a file of one frame (no frame interval), times printed to a
few decimals (judged the same from any time origin), and spacing that is genuinely uneven."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.io import import_csv
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import FRAME_SPACING_TOLERANCE, estimate_frame_interval
from cfbmarkov.trajectory_writer import TrajectoryWriter, write_trajectories

WIDTH, HEIGHT = 0.09, 0.95


def positions(n_frames: int, n_particles: int = 4, seed: int = 3) -> np.ndarray:
    """Random walks [T, N, 2] inside the riser, steps of about 1 cm a frame (no particle
    passes the top or the bottom: laps 0 fit them)."""
    rng = np.random.default_rng(seed)
    start = np.stack([rng.uniform(0.001, WIDTH - 0.001, n_particles),
                      rng.uniform(0.1, HEIGHT - 0.1, n_particles)], axis=-1)
    walk = start + np.cumsum(rng.normal(0.0, 0.01, (n_frames, n_particles, 2)), axis=0)
    return np.clip(walk, 0.001, [WIDTH - 0.001, HEIGHT - 0.001])


def printed(t0: float, rate: float, n_frames: int, decimals: int = 5) -> np.ndarray:
    """Times of frames at ``rate`` Hz from ``t0``, as a text file prints them."""
    return np.array([float(f"{t0 + k / rate:.{decimals}f}") for k in range(n_frames)])


def write(path, times, **options):
    # laps 0: the walks never reach the top or the bottom
    options.setdefault("laps", np.zeros((len(times), 4), np.int32))
    return write_trajectories(path, times, positions(len(times)), width=WIDTH, height=HEIGHT,
                              **options)


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_exit_2(code, err, *absent):
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    for path in absent:
        assert not path.exists()


# -- a file of one frame ---------------------------------------------------------------------
@pytest.fixture
def one_frame(tmp_path):
    return write(tmp_path / "one.h5", [0.5])


def test_one_frame_file_has_no_interval_and_says_so(one_frame):
    with Trajectories(one_frame) as t:
        assert t.n_frames == 1 and np.isnan(t.frame_interval)
        assert "x 1 frame," in repr(t) and "nan" not in repr(t)
        for lag in (0.025, 1.0):
            with pytest.raises(InputError, match=r"one.h5 holds one frame: no frame interval, so "
                                                 r"no transition can be counted"):
                t.lag_frames(lag)
        assert t.time_tolerance == pytest.approx(1e-6)       # 1e-6 x max(|0.5 s|, 1 s)
        assert t.frame_index(0.5) == 0
        assert t.frame_index(0.5 + 5e-7) == 0
        with pytest.raises(InputError, match=r"no frame at t = 0.6 s \(.*one.h5 holds one frame, "
                                             r"at t = 0.5 s\)") as info:
            t.frame_index(0.6)
        assert "nan" not in str(info.value)
        assert t.window(0.4999999, 0.5000001) == slice(0, 1)
        with pytest.raises(InputError, match=r"window 0.5:0.6 s lies outside the data"):
            t.window(0.5, 0.6)
        with pytest.raises(InputError, match=r"window 0.4:0.5 s lies outside the data"):
            t.window(0.4, 0.5)


def test_one_frame_with_a_stored_interval_counts_lags(tmp_path):
    with TrajectoryWriter(tmp_path / "one.h5", [1, 2], width=WIDTH, height=HEIGHT, source="test",
                          frame_interval=0.025) as w:
        w.append(0.5, positions(1, 2)[0])
    with Trajectories(tmp_path / "one.h5") as t:
        assert t.frame_interval == 0.025 and t.lag_frames(0.05) == 2
        assert t.time_tolerance == pytest.approx(0.005 * 0.025)


def test_one_frame_csv_imports_and_reads(tmp_path):
    source = tmp_path / "one.csv"
    source.write_text("t,id,x,y\n0.5,1,0.01,0.1\n0.5,2,0.02,0.2\n")
    with Trajectories(import_csv(source, tmp_path / "one.h5", width=0.09, height=0.95)) as t:
        assert t.n_frames == 1 and np.isnan(t.frame_interval) and t.frame_index(0.5) == 0


NO_INTERVAL = "one.h5 holds one frame: no frame interval, so no transition can be counted"


@pytest.mark.parametrize("argv, message", [
    (["--cells", "6x38", "--lag", "0.025"], NO_INTERVAL),
    (["--cells", "6x38", "--lag", "0.025", "--window", "0:1"], NO_INTERVAL),
    (["--states", "cells-previous", "--lag", "0.025"], NO_INTERVAL),
    # the selection too names the one frame (it had said the window lies outside the data)
    (["--states", "auto", "--lag", "0.025"], NO_INTERVAL),
], ids=["fit", "fit-window", "fit-previous", "fit-auto"])
def test_cli_fit_on_one_frame_is_one_line_and_exit_2(tmp_path, capsys, one_frame, argv, message):
    out = tmp_path / "m.h5"
    code, _, err = run_cli(capsys, "fit", one_frame, *argv, "-o", out)
    assert message in err and "one.h5" in err
    assert_one_line_exit_2(code, err, out)


def test_cli_predict_from_one_frame(tmp_path, capsys, one_frame):
    """A one-frame file is an initial condition: a model on cells predicts from it (its
    state needs no frame before), a model with memory cannot (one line, exit 2)."""
    run = write(tmp_path / "run.h5", 0.025 * np.arange(41))
    model = tmp_path / "m.h5"
    code, _, err = run_cli(capsys, "fit", run, "--cells", "3x5", "--lag", "0.025", "--window",
                           "0:1", "-o", model)
    assert code == 0, err
    pred = tmp_path / "p.h5"
    code, _, err = run_cli(capsys, "predict", model, "--init", one_frame, "--start", 0.5,
                           "--duration", 0.1, "-o", pred, "-q")
    assert code == 0, err
    with Trajectories(pred) as p, Trajectories(one_frame) as first:
        assert p.n_frames == 5
        np.testing.assert_array_equal(p.positions(0), first.positions(0))
    memory = tmp_path / "memory.h5"
    code, _, err = run_cli(capsys, "fit", run, "--cells", "3x5", "--lag", "0.025", "--window",
                           "0.025:1", "--states", "cells-direction", "-o", memory)
    assert code == 0, err
    pred = tmp_path / "p2.h5"
    code, _, err = run_cli(capsys, "predict", memory, "--init", one_frame, "--start", 0.5,
                           "--duration", 0.1, "-o", pred, "-q")
    assert "holds one frame: no frame interval" in err
    assert_one_line_exit_2(code, err, pred)


# -- times printed to a few decimals ---------------------------------------------------------
@pytest.mark.parametrize("t0", [0.0, 10.0, 1000.0])
def test_120_hz_printed_to_5_decimals_is_accepted_from_any_origin(tmp_path, t0):
    times = printed(t0, 120.0, 241)
    assert set(np.round(np.diff(times), 8)) == {0.00833, 0.00834}      # as printed
    with Trajectories(write(tmp_path / "run.h5", times)) as t:
        # least-squares slope of the printed times: 1/120 s to better than 1e-7 relative
        assert t.frame_interval == pytest.approx(1 / 120, rel=1e-7)
        assert t.frame_interval == pytest.approx(estimate_frame_interval(printed(0.0, 120.0, 241)),
                                                 rel=1e-9)
        assert t.lag_frames(0.025) == 3 and t.lag_frames(1 / 120) == 1
        assert t.lag_frames(0.1) == 12 and t.lag_frames(1.0) == 120
        with pytest.raises(InputError, match="not a whole multiple"):
            t.lag_frames(0.03)
        # frames 12 (t0 + 0.1 s) to 60 (t0 + 0.5 s), printed t0 + 0.1 and t0 + 0.5 exactly
        assert t.window(t0 + 0.1, t0 + 0.5) == slice(12, 61)
        assert t.frame_index(t0 + 0.1) == 12 and t.frame_index(t0 + 1 / 120) == 1
        assert t.frame_index(t0 + 0.00833) == 1
        with pytest.raises(InputError, match="no frame at"):
            t.frame_index(t0 + 0.1 + 0.5 / 120)


def test_rounded_times_same_interval_and_lag_from_0_and_10(tmp_path):
    found = []
    for t0 in (0.0, 10.0):
        with Trajectories(write(tmp_path / f"run{t0:g}.h5", printed(t0, 120.0, 121))) as t:
            found.append((t.frame_interval, t.lag_frames(0.025), t.window(t0 + 0.1, t0 + 0.5)))
    (a, lag_a, win_a), (b, lag_b, win_b) = found
    assert abs(a - b) <= 1e-9 * a and lag_a == lag_b == 3 and win_a == win_b == slice(12, 61)


@pytest.mark.parametrize("t0", [0.0, 10.0])
def test_csv_of_120_hz_printed_to_5_decimals_imports_and_fits(tmp_path, capsys, t0):
    times = printed(t0, 120.0, 241)
    pos = positions(241, 3)
    lines = ["t,id,x,y"] + [f"{t:.5f},{i + 1},{pos[k, i, 0]:.17g},{pos[k, i, 1]:.17g}"
                            for k, t in enumerate(times) for i in range(3)]
    (tmp_path / "run.csv").write_text("\n".join(lines) + "\n")
    run = tmp_path / "run.h5"
    code, _, err = run_cli(capsys, "import", tmp_path / "run.csv", "--format", "csv",
                           "--width", "0.09", "--height", "0.95",
                           "-o", run)
    assert code == 0, err
    with Trajectories(run) as t:
        assert t.frame_interval == pytest.approx(1 / 120, rel=1e-7) and t.lag_frames(0.025) == 3
    model = tmp_path / "m.h5"
    code, _, err = run_cli(capsys, "fit", run, "--cells", "3x5", "--lag", "0.025", "--window",
                           f"{t0 + 0.1}:{t0 + 1.9}", "-o", model)
    assert code == 0, err
    from cfbmarkov.markov import MarkovModel
    m = MarkovModel.load(model)
    # frames 12 .. 228 (217 frames), lag of 3 frames: 214 frame pairs of 3 particles
    assert (m.lag, m.frame_pairs, m.n_transitions) == (0.025, 214, 642)


@pytest.mark.parametrize("t0", [0.0, 10.0])
def test_900_hz_printed_to_5_decimals_is_accepted(tmp_path, t0):
    # steps of 0.00111 and 0.00112 s: 0.9 % apart, inside the 1 % tolerance
    times = printed(t0, 900.0, 200)
    with Trajectories(write(tmp_path / "run.h5", times)) as t:
        assert t.frame_interval == pytest.approx(1 / 900, rel=1e-6) and t.lag_frames(0.01) == 9


def test_tolerance_is_one_per_cent():
    assert FRAME_SPACING_TOLERANCE == 0.01


def test_estimate_frame_interval():
    assert estimate_frame_interval([2.0, 2.5, 3.0, 3.5]) == 0.5
    assert estimate_frame_interval([0.0, 0.01, 0.03]) == pytest.approx(0.015)   # slope, not median
    assert np.isnan(estimate_frame_interval([1.0]))


# -- genuinely uneven spacing ----------------------------------------------------------------
def uneven(t0: float, kind: str) -> np.ndarray:
    """120 Hz printed to 5 decimals from t0, with frame 50 3 % of a step late, or missing."""
    times = printed(t0, 120.0, 101)
    if kind == "late":
        times[50:] += 0.03 / 120
    else:
        times = np.delete(times, 50)
    return np.round(times, 5)


@pytest.mark.parametrize("t0", [0.0, 10.0])
@pytest.mark.parametrize("kind, message", [
    ("late", r"frames unevenly spaced: 0.0085\d s between t = {a} and {b} s, expected 0.0083\d* s "
             r"\(the median step, within 1%\)"),
    ("missing", r"frames unevenly spaced: 0.01667 s between t = {a} and {c} s, expected "
                r"0.0083\d* s \(the median step, within 1%\)"),
])
@pytest.mark.parametrize("by_frame", [False, True], ids=["block", "frame-by-frame"])
def test_uneven_spacing_is_refused_naming_the_time(tmp_path, t0, kind, message, by_frame):
    times = uneven(t0, kind)
    a, b, c = (f"{t0 + k / 120:.5f}".rstrip("0").rstrip(".") for k in (49, 50, 51))
    b = f"{float(b) + 0.00025:.5f}".rstrip("0")       # frame 50, 3 % of a step late
    expected = message.format(a=a, b=b, c=c)
    with pytest.raises(InputError, match=expected) as info:
        if by_frame:
            with TrajectoryWriter(tmp_path / "bad.h5", np.arange(4), width=WIDTH, height=HEIGHT,
                                  source="test") as w:
                for k, t in enumerate(times):
                    w.append(t, positions(len(times))[k])
        else:
            write(tmp_path / "bad.h5", times)
    assert "\n" not in str(info.value)
    assert list(tmp_path.iterdir()) == []
    # a whole frame with no row is named as such, with the way to read it as an empty one
    assert ("(1 frame(s) missing: a CSV track file of an open riser writes no row while "
            "no particle is in view" in str(info.value)) == (kind == "missing")


@pytest.mark.parametrize("t0", [0.0, 10.0])
def test_uneven_csv_is_refused_naming_the_time(tmp_path, capsys, t0):
    times = uneven(t0, "missing")
    lines = ["t,id,x,y"] + [f"{t:.5f},1,0.01,0.1" for t in times]
    (tmp_path / "run.csv").write_text("\n".join(lines) + "\n")
    out = tmp_path / "run.h5"
    code, _, err = run_cli(capsys, "import", tmp_path / "run.csv", "--format", "csv",
                           "--width", "0.09", "--height", "0.95",
                           "-o", out)
    a = f"{t0 + 49 / 120:.5f}".rstrip("0")
    assert f"frames unevenly spaced: 0.01667 s between t = {a} and" in err
    assert_one_line_exit_2(code, err, out)


def test_slow_drift_is_refused_when_the_file_is_closed(tmp_path):
    # each step 0.02 % longer than the one before: within 1 % of the median of the steps just
    # before it, but the first step is 2 % off the median of all 200 steps
    steps = 0.01 * (1 + 0.0002 * np.arange(200))
    times = np.concatenate([[0.0], np.cumsum(steps)])
    with pytest.raises(InputError, match=r"frames unevenly spaced: 0.01 s between t = 0 and 0.01 s, "
                                         r"expected 0.0101\d* s \(the median step"):
        with TrajectoryWriter(tmp_path / "drift.h5", [1], width=WIDTH, height=HEIGHT,
                              source="test") as w:
            for t in times:
                w.append(t, [[0.01, 0.1]])
    assert list(tmp_path.iterdir()) == []


def test_given_frame_interval_is_the_reference(tmp_path):
    times = printed(10.0, 120.0, 61)
    with Trajectories(write(tmp_path / "ok.h5", times, source="test")) as t:
        inferred = t.frame_interval
    with TrajectoryWriter(tmp_path / "given.h5", np.arange(4), width=WIDTH, height=HEIGHT,
                          source="test", frame_interval=1 / 120) as w:
        w.append_frames(times, positions(61))
    with Trajectories(tmp_path / "given.h5") as t:
        assert t.frame_interval == 1 / 120 and inferred == pytest.approx(1 / 120, rel=1e-6)
    late = times.copy()
    late[30:] += 0.03 / 120
    with pytest.raises(InputError, match=r"0.00858 s between t = 10.24167 and 10.25025 s, "
                                         r"expected 0.008333333333 s \(the frame interval"):
        _write_given(tmp_path / "bad.h5", late)
    with pytest.raises(InputError, match="frame interval 0.0 s must be a positive number"):
        TrajectoryWriter(tmp_path / "zero.h5", [1], width=WIDTH, height=HEIGHT, source="test",
                         frame_interval=0.0)


def _write_given(path, times):
    with TrajectoryWriter(path, np.arange(4), width=WIDTH, height=HEIGHT, source="test",
                          frame_interval=1 / 120) as w:
        w.append_frames(times, positions(len(times)))
