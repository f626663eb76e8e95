"""Issue 16, the input side: damaged files, inexact ids, truncated text, unstable metrics and
bad numeric options all end in one line on stderr and exit code 2, with no output."""

import shutil

import h5py
import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.observed.metrics import minkowski_distance
from cfbmarkov.cli import main
from cfbmarkov.trajectories import Trajectories

FLOW = synthetic.RiserFlow(columns=3, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)


@pytest.fixture(scope="session")
def good(tmp_path_factory):
    """A small run (60 particles x 3 s from t = 0) and a model fitted on it."""
    folder = tmp_path_factory.mktemp("good")
    run = synthetic.write_run(folder / "run.h5", FLOW, 60, 3.0, seed=4)
    model = folder / "model.h5"
    assert main(["fit", str(run), "--cells", "3x8", "--window", "0:2.5", "-o", str(model)]) == 0
    return run, model


def one_line_error(capsys, argv, output=None):
    """Run the CLI: exit code 2, one line on stderr, no traceback, no output."""
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    if output is not None:
        assert not output.exists()
    return err


def damaged_copy(src, tmp_path, edit):
    path = tmp_path / ("bad-" + src.name)
    shutil.copy(src, path)
    with h5py.File(path, "r+") as f:
        edit(f)
    return path


def _set(name, index, value):
    def edit(f):
        data = f[name][()]
        data[index] = value
        f[name][...] = data
    return edit


def _attr(name, value):
    def edit(f):
        f.attrs[name] = value
    return edit


def _replace(name, value):
    def edit(f):
        del f[name]
        f[name] = value
    return edit


# -- item 5, 9: damaged trajectory files ------------------------------------------------------
TRAJECTORY_DAMAGE = {
    "nan-time": (_set("frames/time", 30, np.nan), "frame times must be finite"),
    "decreasing-time": (_set("frames/time", 30, 0.1), "do not increase"),
    "uneven-time": (_set("frames/time", 30, 30 * 0.025 + 0.005), "not evenly spaced"),
    "nan-position": (_set("frames/position", (60, 3, 1), np.nan), "not a finite number"),
    "out-of-domain": (_set("frames/position", (60, 3, 0), 5.0), "outside the domain"),
    "lap-jump": (_set("frames/lap", (60, 3), 7), "laps inconsistent"),
    "frame-interval-0": (_attr("frame_interval", 0.0), "frame_interval 0 is not"),
    # as a reader writes it, not numpy's repr (np.float64(nan))
    "frame-interval-nan": (_attr("frame_interval", np.nan), "frame_interval nan is not"),
    "width-0": (_attr("width", 0.0), "width"),
    "height-nan": (_attr("height", np.nan), "height"),
    "parameters-not-json": (_attr("parameters", "{not json"), "not JSON"),
    "lap-shape": (_replace("frames/lap", np.zeros((3, 3), np.int32)), "do not match"),
    "duplicate-ids": (_replace("particles/id", np.zeros(60, np.int64)), "appears twice"),
    "float-laps": (_replace("frames/lap", np.zeros((121, 60))), "whole numbers"),
    "dimensions-nan": (_attr("dimensions", np.nan), "dimensions"),
}


@pytest.mark.parametrize("damage", TRAJECTORY_DAMAGE, ids=list(TRAJECTORY_DAMAGE))
def test_damaged_trajectory_refused_in_one_line(good, tmp_path, capsys, damage):
    run, model = good
    edit, message = TRAJECTORY_DAMAGE[damage]
    bad = damaged_copy(run, tmp_path, edit)
    out = tmp_path / "pred.h5"
    err = one_line_error(capsys, ["predict", model, "--init", bad, "--start", 1.5,
                                  "--duration", 0.5, "-q", "-o", out], out)
    assert message in err and "bad-run.h5" in err
    err = one_line_error(capsys, ["fit", bad, "--cells", "3x8", "--window", "0:2.5",
                                  "-o", tmp_path / "m.h5"], tmp_path / "m.h5")
    assert message in err


def test_nan_time_no_longer_moves_the_start(good, tmp_path, capsys):
    """The issue's case: a NaN time made --start pick another frame; now it is refused."""
    run, model = good
    bad = damaged_copy(run, tmp_path, _set("frames/time", 60, np.nan))
    err = one_line_error(capsys, ["predict", model, "--init", bad, "--start", 1.5,
                                  "--duration", 0.5, "-o", tmp_path / "p.h5"])
    assert "frame 60 has time nan" in err


def test_per_frame_checks_run_on_read_only(good, tmp_path):
    """Opening is cheap: a bad position deep in the file is found when its frame is read."""
    run, _ = good
    bad = damaged_copy(run, tmp_path, _set("frames/position", (100, 0, 1), -1.0))
    with Trajectories(bad) as t:
        t.positions(slice(0, 50))
        t.laps(10)
        with pytest.raises(Exception, match="outside the domain"):
            t.positions(slice(90, 110))


def test_a_read_that_starts_after_a_lap_jump_checks_the_step_into_it(good, tmp_path):
    """Frames read from frame 60 on are checked against frame 59: a lap jump between 59
    and 60 is found by a read of 60-80 alone, and reported before a bad position later in
    the block (the first problem, in frame order)."""
    run, _ = good

    def jump_and_outside(f):
        laps = f["frames/lap"][()]
        laps[60:, 3] += 2                   # one jump, between frames 59 and 60 only
        f["frames/lap"][...] = laps
        _set("frames/position", (70, 0, 1), -1.0)(f)

    bad = damaged_copy(run, tmp_path, jump_and_outside)
    with Trajectories(bad) as t:
        t.positions(slice(0, 59))
        with pytest.raises(Exception, match="laps inconsistent") as caught:
            t.positions(slice(60, 80))
    assert "particle" in str(caught.value) and "outside the domain" not in str(caught.value)
    with Trajectories(bad) as t:
        with pytest.raises(Exception, match="outside the domain"):
            t.positions(slice(61, 80))


def test_one_frame_file_refused_for_a_fit(good, tmp_path, capsys):
    run, _ = good
    with Trajectories(run) as t:
        times, pos, laps = t.times[:1], t.positions(slice(0, 1)), t.laps(slice(0, 1))
    from cfbmarkov.trajectory_writer import write_trajectories

    one = write_trajectories(tmp_path / "one.h5", times, pos, width=FLOW.width,
                             height=FLOW.height, laps=laps)
    err = one_line_error(capsys, ["fit", one, "--window", "0:1", "-o", tmp_path / "m.h5"])
    assert "one frame" in err or "outside the data" in err


# -- item 5, 9: damaged model files -----------------------------------------------------------
def _rows_not_one(f):
    p = f["transition_matrix"][()]
    p[0] *= 0.5
    del f["transition_matrix"]
    f["transition_matrix"] = p


MODEL_DAMAGE = {
    "rows-not-1": (_rows_not_one, "rows do not sum to 1"),
    "pass-fraction-7": (_set("pass_up_fraction", (0, 0), 7.0), "pass fractions"),
    "pass-up-plus-down": (lambda f: (_set("pass_up_fraction", (1, 1), 0.7)(f),
                                     _set("pass_down_fraction", (1, 1), 0.7)(f)), "up + down"),
    "negative-counts": (_set("counts", (0, 0), -3), "negative counts"),
    "lag-0": (_attr("lag", 0.0), "lag"),
    "lag-nan": (_attr("lag", np.nan), "lag"),
    "lag-text": (_attr("lag", "fast"), "lag"),
    "state-space-not-json": (_attr("state_space", "cells 3x8"), "JSON"),
    "state-space-unknown": (_attr("state_space", '{"kind": "nope"}'), "unknown state space"),
    "matrix-shape": (_replace("transition_matrix", np.eye(5)), "shape"),
    "counts-missing": (lambda f: f.__delitem__("counts"), "missing the dataset 'counts'"),
    "lag-missing": (lambda f: f.attrs.__delitem__("lag"), "missing the attribute 'lag'"),
    "window-nan-one": (_attr("window", [1.0, np.inf]), "window"),
    # a layout version that is none, not read as version 1
    "version-0": (_attr("version", 0), "damaged model file (layout version 0: this cfbmarkov"),
    "version-nan": (_attr("version", np.nan), "damaged model file (layout version nan"),
    # a newer layout is no damage: it names the upgrade
    "version-2": (_attr("version", 2), "model file layout version 2, written by a newer "
                                       "cfbmarkov (this one reads version 1); upgrade"),
    # valid JSON of another shape: one line from info too, no traceback
    "selection-a-list": (_attr("selection", "[1, 2]"), "selection is not a record"),
    "selection-candidates-text": (_attr("selection", '{"candidates": "cells"}'),
                                  "selection is not a record"),
    # NaN marks a cell never visited: in a visited one a kinetics law took the cell for
    # another, silently (NaN compares false with every threshold)
    "cell-velocity-nan": (_set("cell_vertical_velocity", (0,), np.nan),
                          "cell_vertical_velocity is not a number in cell 0, which the fit "
                          "saw particles leave"),
    "cell-solids-inf": (_set("cell_solids_fraction", (3,), np.inf),
                        "cell_solids_fraction is not a number in cell 3"),
}


@pytest.mark.parametrize("damage", MODEL_DAMAGE, ids=list(MODEL_DAMAGE))
def test_damaged_model_refused_in_one_line(good, tmp_path, capsys, damage):
    run, model = good
    edit, message = MODEL_DAMAGE[damage]
    bad = damaged_copy(model, tmp_path, edit)
    for verb in ("rtd", "info"):
        err = one_line_error(capsys, [verb, bad])
        assert message in err and "bad-model.h5" in err
    out = tmp_path / "p.h5"
    one_line_error(capsys, ["predict", bad, "--init", run, "--start", 1.5, "--duration", 0.5,
                            "-o", out], out)


# -- item 6: exact ids, truncated CSV -----------------------------------------------------------
def _csv(ids, frames=4):
    rows = ["t,id,x,y"]
    for k in range(frames):
        for j, pid in enumerate(ids):
            rows.append(f"{k * 0.025:.3f},{pid},{0.01 + 0.01 * j:.4f},{0.10 + 0.01 * k:.4f}")
    return "\n".join(rows) + "\n"


def test_csv_ids_beyond_2_53_stay_distinct(tmp_path, capsys):
    big = 2 ** 53
    src = tmp_path / "ids.csv"
    src.write_text(_csv([big, big + 1, -big - 3]))
    assert main(["import", str(src), "--format", "csv", "--width", "0.09", "--height", "0.95",
                "-o", str(tmp_path / "ids.h5")]) == 0
    with Trajectories(tmp_path / "ids.h5") as t:
        assert sorted(t.ids.tolist()) == [-big - 3, big, big + 1]


def test_csv_id_outside_int64_refused(tmp_path, capsys):
    src = tmp_path / "ids.csv"
    src.write_text(_csv([1, 2 ** 64]))
    err = one_line_error(capsys, ["import", src, "--format", "csv", "-o", tmp_path / "o.h5"],
                         tmp_path / "o.h5")
    assert "64-bit" in err


@pytest.mark.parametrize("cut, message", [(2, "shorter than in every row"), (5, "incomplete"),
                                          (8, "3 values")])
def test_csv_cut_inside_its_last_row_refused(tmp_path, capsys, cut, message):
    src = tmp_path / "cut.csv"
    src.write_text(_csv([1, 2])[:-cut])      # the last row 0.075,2,0.0200,0.1300 cut
    err = one_line_error(capsys, ["import", src, "--format", "csv", "-o", tmp_path / "o.h5"],
                         tmp_path / "o.h5")
    assert message in err and "line 9" in err and "truncated" in err


def test_csv_without_final_newline_but_complete_is_read(tmp_path):
    src = tmp_path / "ok.csv"
    src.write_text(_csv([1, 2])[:-1])
    assert main(["import", str(src), "--format", "csv", "--width", "0.09", "--height", "0.95",
                "-o", str(tmp_path / "o.h5")]) == 0


def _dump(ids, frames=3, atoms_line=None, timestep=None):
    text = []
    for k in range(frames):
        text += ["ITEM: TIMESTEP", str(timestep if timestep is not None else 100 * k),
                 "ITEM: TIME", f"{k * 0.025:g}",
                 "ITEM: NUMBER OF ATOMS", atoms_line or str(len(ids)),
                 "ITEM: BOX BOUNDS ff pp pp", "0 0.09", "0 0.95", "-0.01 0.01",
                 "ITEM: ATOMS id x y z"]
        text += [f"{pid} {0.01 + 0.01 * j:.4f} {0.1 + 0.01 * k:.4f} 0" for j, pid in enumerate(ids)]
    return "\n".join(text) + "\n"


def test_dump_ids_beyond_2_53_stay_distinct(tmp_path):
    big = 2 ** 53
    src = tmp_path / "dump.txt"
    src.write_text(_dump([big, big + 1]))
    assert main(["import", str(src), "--format", "lammps", "-o", str(tmp_path / "d.h5")]) == 0
    with Trajectories(tmp_path / "d.h5") as t:
        assert sorted(t.ids.tolist()) == [big, big + 1]


@pytest.mark.parametrize("atoms, timestep, message", [
    ("-1", None, "NUMBER OF ATOMS value -1"), ("1e20", None, "not a whole number"),
    ("100000000000000000000", None, "NUMBER OF ATOMS"), ("2", "9" * 400, "400 digits")])
def test_dump_header_values_bounded(tmp_path, capsys, atoms, timestep, message):
    src = tmp_path / "dump.txt"
    src.write_text(_dump([1, 2], atoms_line=atoms, timestep=timestep))
    err = one_line_error(capsys, ["import", src, "--format", "lammps", "-o", tmp_path / "d.h5"],
                         tmp_path / "d.h5")
    assert message in err


# -- item 7: Minkowski distance of a high order ---------------------------------------------------
def test_minkowski_distance_of_order_1000_is_stable():
    rng = np.random.default_rng(0)
    e, f = rng.uniform(0, 0.2, 40), rng.uniform(0, 0.2, 40)
    d = np.abs(e - f)
    from fractions import Fraction

    m = max(d)                 # direct computation in higher precision (exact rationals)
    total = sum(Fraction(float(x / m)) ** 1000 for x in d)
    expected = float(m) * float(total) ** (1 / 1000)
    got = minkowski_distance(e, f, 1000)
    assert got > 0.1 and got == pytest.approx(expected, rel=1e-12)
    assert minkowski_distance(e, f, np.inf) == pytest.approx(d.max())
    assert minkowski_distance(e, f, 2) == pytest.approx(np.sqrt(np.sum(d ** 2)))


# -- item 8: numeric options ------------------------------------------------------------------------
BAD_OPTIONS = [
    ["fit", "{run}", "--lag", "inf"], ["fit", "{run}", "--lag", "nan"],
    ["fit", "{run}", "--lag", "-0.025"], ["fit", "{run}", "--window", "0:inf"],
    ["fit", "{run}", "--window", "nan:1"], ["fit", "{run}", "--cells", "0x8"],
    ["predict", "{model}", "--init", "{run}", "--start", "1", "--duration", "1", "--seed", "-1"],
    ["predict", "{model}", "--init", "{run}", "--start", "1", "--duration", "1", "--seed",
     str(2 ** 70)],
    ["predict", "{model}", "--init", "{run}", "--start", "1", "--duration", "1e9"],
    ["predict", "{model}", "--init", "{run}", "--start", "nan", "--duration", "1"],
    ["predict", "{model}", "--init", "{run}", "--start", "1", "--duration", "inf"],
    ["rtd", "{model}", "--window-length", "inf"], ["rtd", "{model}", "--window-length", "1e9"],
    ["maps", "{model}", "--times", "nan"], ["maps", "{model}", "--times", "1e9"],
    ["compare", "{run}", "{run}", "--window", "0:2", "--bin-width", "1e-12"],
    ["compare", "{run}", "{run}", "--window", "0:2", "--md-order", "nan"],
    ["compare", "{run}", "{run}", "--window", "0:2", "--md-order", "0"],
    ["simulate", "paper-u3", "--until", "inf"], ["simulate", "paper-u3", "--particles", "-5"],
    ["simulate", "paper-u3", "--checkpoint-every", "nan"],
    ["import", "{run}", "--format", "csv", "--width", "inf"],
    ["import", "{run}", "--format", "csv", "--resample", "1e-400"],
    # subnormal: a quotient by it overflows (a later fit ended in an OverflowError)
    ["import", "{run}", "--format", "csv", "--time-step", "1e-320"],
    ["demo", "--synthetic", "--particles", "0"], ["demo", "--synthetic", "--seed", "-3"],
    ["export-vtk", "{run}", "--every", "0"], ["export-vtk", "{run}", "--start", "inf"],
    ["bench", "--repeat", "0"], ["reproduce", "--velocities", "inf"],
    ["reproduce", "--jobs", "0"],
]


@pytest.mark.parametrize("argv", BAD_OPTIONS, ids=[" ".join(a[:1] + a[-2:]) for a in BAD_OPTIONS])
def test_bad_numeric_option_refused_in_one_line(good, tmp_path, capsys, argv):
    run, model = good
    out = tmp_path / "out"
    argv = [a.format(run=run, model=model) for a in argv]
    if argv[0] not in ("rtd", "bench", "demo", "reproduce"):
        argv += ["-o", str(out)]
    elif argv[0] in ("demo", "reproduce"):
        argv += ["-o", str(out)]
    one_line_error(capsys, argv, out)


def test_fit_of_too_many_cells_refused_quickly_with_the_estimate(good, tmp_path, capsys):
    import time

    run, _ = good
    begin = time.perf_counter()
    err = one_line_error(capsys, ["fit", run, "--cells", "300x300", "-o", tmp_path / "m.h5"],
                         tmp_path / "m.h5")
    assert time.perf_counter() - begin < 5
    assert "90000 states" in err and "842 GB" in err and "--cells" in err


def test_memory_limit_from_the_environment(good, tmp_path, capsys, monkeypatch):
    run, _ = good
    monkeypatch.setenv("CFBMARKOV_MEMORY_LIMIT", "1e6")     # 1 MB: 3x8 cells still fit
    err = one_line_error(capsys, ["fit", run, "--cells", "30x30", "-o", tmp_path / "m.h5"])
    assert "CFBMARKOV_MEMORY_LIMIT" in err and "84.2 MB" in err
