"""Imports whose speeds betray a wrong time step or time unit warn; a one-tracer file is
stored without padding."""

import numpy as np

from cfbmarkov.cli import main


def _dump(path, steps, dy_per_frame, vy):
    """Two particles rising ``dy_per_frame`` m a frame at timesteps ``steps``, velocity
    ``vy`` stored; no ITEM: TIME (the time step gives the times)."""
    lines = []
    for k, step in enumerate(steps):
        lines += ["ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ATOMS", "2",
                  "ITEM: BOX BOUNDS pp pp pp", "0 0.09", "0 0.95", "-0.0005 0.0005",
                  "ITEM: ATOMS id x y z vx vy vz"]
        for i in (1, 2):
            y = (0.1 + 0.3 * i + dy_per_frame * k) % 0.95
            lines.append(f"{i} {0.02 * i} {y!r} 0 0 {vy} 0")
    path.write_text("\n".join(lines) + "\n")
    return path


def _warnings(capsys, *argv):
    assert main(["import", *map(str, argv), "--force"]) == 0
    return [line for line in capsys.readouterr().err.splitlines()
            if line.startswith("warning:")]


def test_a_time_step_that_contradicts_the_dumps_velocities_warns(tmp_path, capsys):
    """Frames 1000 steps apart, particles rising 0.02 m a frame at a stored 2 m/s: right
    with --time-step 1e-5 (0.01 s a frame); a time step 100 times too long makes the moves
    0.02 m/s, and the warning names the factor and --time-step."""
    dump = _dump(tmp_path / "run.dump", range(0, 20000, 1000), 0.02, 2.0)
    out = tmp_path / "run.h5"
    assert _warnings(capsys, dump, "--time-step", "1e-5", "-o", out) == []
    lines = _warnings(capsys, dump, "--time-step", "1e-3", "-o", out)
    assert any("the file's velocities (median 2 m/s) disagree with the particles' moves "
               "between frames (median 0.02 m/s) by a factor 100" in line
               and "--time-step" in line for line in lines), lines


def test_a_sparse_tracer_read_in_the_wrong_time_unit_warns_and_is_stored_small(
        tmp_path, capsys):
    """One tracer sampled every 2 ms at 2.5 m/s, its times written in ms: read as seconds
    and resampled every 5 ms with a 20 ms gap limit, no two consecutive frames hold it; the
    speed between its observations (unwrapped by its laps) still shows 2.5 mm/s and warns.
    Read in ms, no warning; and the file of one tracer carries no 256-particle padding."""
    t = np.arange(0, 400, 2.0)                         # ms
    y = (2.5 * t) % 950.0                              # mm
    rows = ["t,x,y"] + [f"{a:g},45,{b:.6g}" for a, b in zip(t, y)]
    source = tmp_path / "tracer.csv"
    source.write_text("\n".join(rows) + "\n")
    common = ["--length-unit", "mm", "--width", "0.09", "--height", "0.95", "--max-gap", "0.02"]
    slow = _warnings(capsys, source, *common, "--resample", "0.005", "-o", tmp_path / "s.h5")
    assert any("the particles move at a median 0.0025 m/s between frames: times in "
               "milliseconds read as seconds" in line for line in slow), slow
    right = tmp_path / "ms.h5"
    assert _warnings(capsys, source, *common, "--time-unit", "ms", "--resample", "0.001",
                     "-o", right) == []
    # 399 frames of one tracer: about 10 kB of positions, laps and presence, not 256-fold
    assert right.stat().st_size < 100_000


def test_a_riser_wider_than_high_warns_of_the_vertical_axis(tmp_path, capsys):
    """A 2D dump of a 0.09 m x 0.95 m riser imported with --vertical-axis x: a riser
    0.95 m across and 0.09 m high, which the import warns of, naming --vertical-axis; with
    its right axis, no such warning."""
    dump = _dump(tmp_path / "run.dump", range(0, 20000, 1000), 0.02, 2.0)
    lines = _warnings(capsys, dump, "--time-step", "1e-5", "--vertical-axis", "x", "-o",
                      tmp_path / "x.h5")
    assert any(line.startswith("warning: the riser is 0.95 m across and 0.09 m high "
                               "(vertical axis x): a riser is taller than it is wide")
               and "--vertical-axis x|y|z" in line for line in lines), lines
    lines = _warnings(capsys, dump, "--time-step", "1e-5", "-o", tmp_path / "y.h5")
    assert not any("taller than it is wide" in line for line in lines), lines
