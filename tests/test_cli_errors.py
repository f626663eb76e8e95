"""Errors of the command line name the working value: the file's frame interval for a lag,
its time span for a window, a span or an export range."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.trajectory_writer import write_trajectories


@pytest.fixture
def run(tmp_path):
    """2 s of 50 particles, frames 0.002 s apart, in a 0.04 x 0.3 m riser."""
    rng = np.random.default_rng(1)
    t = 0.002 * np.arange(1001)
    x = np.broadcast_to(rng.uniform(0.0, 0.04, 50), (t.size, 50))
    y = np.mod(rng.uniform(0.0, 0.3, 50) + 1.0 * t[:, None], 0.3)
    return write_trajectories(tmp_path / "r.h5", t, np.stack([x, y], axis=-1), width=0.04,
                              height=0.3, source="cfd-dem")


@pytest.mark.parametrize("args, expected", [
    (("fit", "--lag", "0.025", "--window", "0.5:1.5", "-o", "m.h5"),
     "its frames are 0.002 s apart: use --lag 0.002 or a multiple (lag=0.002 from Python; "
     "the nearest: 0.024)"),
    (("fit", "--lag", "0.002", "--window", "10:15", "-o", "m.h5"),
     "window 10:15 s lies outside the data of {run} (0 to 2 s)"),
    (("stationarity", "--span", "5:20"), "span 5:20 s lies outside the frames of {run} (0 to 2 s)"),
    (("stationarity", "--span", "1:20"),
     "span 1:20 s lies partly outside the frames of {run} (0 to 2 s; only 1:2 s lies inside)"),
    (("stationarity", "--window-length", "5"), "a --window-length of at most half the span's 2 s"),
    (("stationarity", "--window-length", "0.5", "--span", "0:1.5", "--judge", "3:4"),
     "--judge 3:4 s lies outside the span 0:1.5 s"),
    # windows hold whole frames: a step or judged end between frames labelled its rows with
    # times its figures were not of
    (("stationarity", "--window-length", "0.5", "--step", "0.003"),
     "--step 0.003 s is not a whole number of the file's frame intervals (0.002 s): give "
     "0.002 or 0.004 s"),
    (("stationarity", "--window-length", "0.5011"),
     "--window-length 0.5011 s is not a whole number of the file's frame intervals"),
    (("stationarity", "--window-length", "0.5", "--judge", "1:1.5011"),
     "--judge 1:1.5011 s: 1.5011 s falls between the file's frames (the nearest at 1.502 s)"),
    (("export-vtk", "--start", "15", "--stop", "16", "-o", "v"),
     "window 15:16 s lies outside the data of {run} (0 to 2 s)"),
    (("export-vtk", "--start", "15", "-o", "v"),
     "--start 15 s lies outside the data of {run}, after its end (0 to 2 s)"),
    (("export-vtk", "--stop", "-1", "-o", "v"),
     "--stop -1 s lies outside the data of {run}, before its start (0 to 2 s)"),
])
def test_errors_name_the_working_value(run, tmp_path, capsys, monkeypatch, args, expected):
    monkeypatch.chdir(tmp_path)
    verb, *rest = args
    assert main([verb, str(run), *rest]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert expected.format(run=run) in err, err


def test_a_window_no_residence_fits_names_the_shortest_that_does(run, tmp_path, capsys):
    """rtd --window-length shorter than every residence of the model: one line with the
    length from which one fits (the chain on 38 rows moves at most a row a lag of 0.002 s:
    38 lags at least)."""
    model = tmp_path / "m.h5"
    assert main(["fit", str(run), "--lag", "0.002", "--window", "0.5:1.5", "--resamples", "0",
                 "--no-adequacy", "-q", "-o", str(model)]) == 0
    capsys.readouterr()
    assert main(["rtd", str(model), "--window-length", "0.01"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no residence of this model fits in a window of 0.01 s" in err
    shortest = float(err.split("give a window of at least ")[1].split(" s")[0])
    assert shortest == pytest.approx(0.078)
    assert main(["rtd", str(model), "--window-length", f"{shortest:g}"]) == 0
    # --resamples forms the intrinsic RTD's interval: with a window, refused in one line
    capsys.readouterr()
    assert main(["rtd", str(model), "--window-length", "0.2", "--resamples", "20"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "leave out --window-length" in err
    # so does --level (not sent to --resamples, which is then refused)
    assert main(["rtd", str(model), "--window-length", "0.2", "--level", "0.5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "window sees it has none: leave out --window-length" in err
    assert "add --resamples" not in err


def test_a_mistyped_option_names_the_verb_and_the_option_it_may_mean(capsys):
    assert main(["fit", "run.h5", "--cels", "6x38", "-o", "m.h5"]) == 2
    err = capsys.readouterr().err
    assert err == ("cfbmarkov fit: error: unrecognized arguments: --cels 6x38 (--cels: did "
                   "you mean --cells?); see cfbmarkov fit --help\n")
    assert main(["rtd", "m.h5", "surplus"]) == 2
    assert capsys.readouterr().err.startswith("cfbmarkov rtd: error: unrecognized arguments: "
                                              "surplus; see")


@pytest.mark.parametrize("typed, meant", [("fitt", "fit"), ("compar", "compare"),
                                           ("stationarty", "stationarity"), ("zzz", None)])
def test_a_mistyped_verb_names_the_verb_it_may_mean(capsys, typed, meant):
    assert main([typed, "x.h5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"invalid choice: '{typed}'" in err
    assert (err.endswith(f"; did you mean {meant}?\n") if meant else "did you mean" not in err)


def test_a_model_given_to_import_and_a_folder_given_as_a_file(run, tmp_path, capsys):
    model = tmp_path / "m.h5"
    assert main(["fit", str(run), "--lag", "0.002", "--window", "0.5:1.5", "--cells", "2x4",
                 "--resamples", "0", "-o", str(model)]) == 0
    capsys.readouterr()
    assert main(["import", str(model), "-o", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "it is a cfbmarkov model file (from fit)" in err
    # a truncated HDF5 file: named as truncated, not HDF5's own words
    truncated = tmp_path / "cut.h5"
    truncated.write_bytes(run.read_bytes()[:1000])
    assert main(["import", str(truncated), "-o", str(tmp_path / "y.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot read as HDF5 (the file is truncated" in err, err
    assert "sblock" not in err
    for verb in ("info", "rtd"):
        assert main([verb, str(tmp_path)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "is a folder, not a file" in err, err


def test_a_model_without_residence_time_is_saved_and_said_so(tmp_path, capsys):
    """Particles that move but never pass through the top: the fit is saved (exit 0) and
    one warning line says the model has no residence time and which verbs refuse it; rtd
    then refuses it in one line."""
    t = 0.01 * np.arange(201)
    rng = np.random.default_rng(2)
    x = np.broadcast_to(rng.uniform(0.0, 0.04, 30), (t.size, 30))
    y = 0.15 + 0.05 * np.sin(2 * np.pi * (t[:, None] + rng.uniform(0, 1, 30)))
    run = write_trajectories(tmp_path / "still.h5", t, np.stack([x, y], axis=-1), width=0.04,
                             height=0.3, source="cfd-dem")
    model = tmp_path / "m.h5"
    assert main(["fit", str(run), "--cells", "2x6", "--lag", "0.01", "--window", "0:2",
                 "-q", "-o", str(model)]) == 0
    err = capsys.readouterr().err
    said = [line for line in err.splitlines() if "the model has no residence time" in line]
    assert len(said) == 1 and said[0].startswith("warning: ") and "`rtd`" in said[0]
    assert main(["rtd", str(model)]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_an_abbreviated_option_is_refused_with_its_whole_name(tmp_path, capsys):
    """Options are given whole: fit's `--resample 50` (a prefix of --resamples, and the name
    of another option of import) is refused in one line naming --resamples, exit 2, not
    taken as --resamples."""
    from cfbmarkov.cli import main

    code = main(["fit", str(tmp_path / "run.h5"), "--resample", "50", "-o",
                 str(tmp_path / "m.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "--resample: did you mean --resamples?" in err
    assert not (tmp_path / "m.h5").exists()


def test_a_required_option_typed_short_is_named_not_reported_missing(tmp_path, capsys):
    """`fit RUN --out m.h5`: the mistyped --output is named (argparse alone said that
    -o/--output is required)."""
    from cfbmarkov.cli import main

    assert main(["fit", str(tmp_path / "run.h5"), "--out", str(tmp_path / "m.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out: did you mean --output?" in err
    assert "required" not in err


def test_an_option_of_one_value_given_twice_is_refused(tmp_path, capsys):
    """argparse keeps the last of a repeated option silently (`fit --window 5:10 --window
    10:15` would fit 10:15): refused in one line naming it, nothing written; an option's
    value that looks like an option is not counted as one."""
    from cfbmarkov.cli import main

    out = tmp_path / "m.h5"
    for argv, named in ((["--window", "5:10", "--window", "10:15"], "--window given 2 times"),
                        (["--cells", "6x38", "--cells=4x10"], "--cells given 2 times"),
                        (["-o", str(tmp_path / "a.h5"), "--output", str(out)],
                         "-o and --output given 2 times"),
                        ([f"-o{tmp_path / 'a.h5'}", "-o", str(out)], "-o given 2 times")):
        code = main(["fit", str(tmp_path / "run.h5"), *argv] + (["-o", str(out)] if
                                                                 "-o" not in argv else []))
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and named in err, err
        assert not out.exists()
    from cfbmarkov.cli.command import _refuse_repeated, build_parser

    parser = build_parser()
    _refuse_repeated(parser, "import", ["import", "d.dump", "--width", "0.09", "--region",
                                        "--width", "-o", "x.h5"])   # the value "--width"


def test_an_empty_output_name_is_named_as_such(tmp_path, capsys):
    """`-o ''` is named as empty, not taken as the current folder."""
    from cfbmarkov.cli import main

    assert main(["fit", str(tmp_path / "run.h5"), "-o", ""]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "an empty output name (-o '')" in err


@pytest.mark.parametrize("argv", [["info", ""], ["fit", "", "-o", "m.h5"], ["rtd", ""],
                                  ["compare", "", "p.h5", "-o", "c"],
                                  ["import", "", "-o", "x.h5"]])
def test_an_empty_input_name_is_named_as_such(tmp_path, capsys, monkeypatch, argv):
    """An empty input path is named as empty, not read as the current folder."""
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "an empty file name ('')" in err, err


def test_info_of_a_foreign_hdf5_file_names_both_kinds_it_reads(tmp_path, capsys):
    """info reads trajectory and model files: a foreign format is named as neither."""
    import h5py

    with h5py.File(tmp_path / "foreign.h5", "w") as f:
        f.attrs["format"] = "h5md"
    assert main(["info", str(tmp_path / "foreign.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "neither a cfbmarkov trajectory nor model file (its " \
        "format attribute is 'h5md'); import particle data first" in err


def test_a_time_beyond_the_floats_is_one_line_not_an_overflow(run, tmp_path, capsys,
                                                             monkeypatch):
    """1e308 s over a lag is inf lags, which int() refused with a 40-line OverflowError
    traceback in seven commands; each is now one line, exit 2, nothing written."""
    monkeypatch.chdir(tmp_path)
    assert main(["fit", str(run), "--lag", "0.002", "--window", "0.5:1.5", "--resamples", "0",
                 "-o", "m.h5", "-q"]) == 0
    capsys.readouterr()
    for argv, said in (
            (["fit", str(run), "--lag", "1e308", "-o", "x.h5"], "lag 1e+308 s is inf frame"),
            (["stationarity", str(run), "--lag", "1e308"], "lag 1e+308 s is inf frame"),
            (["rtd", "m.h5", "--window-length", "1e308"],
             "--window-length 1e+308 s is inf lags"),
            (["maps", "m.h5", "--times", "1e308", "-o", "x.png"], "time 1e+308 s is inf lags"),
            (["predict", "m.h5", "--init", str(run), "--start", "1", "--duration", "1e308",
              "-o", "x.h5"], "duration 1e+308 s is inf lags"),
            (["simulate", "paper-u3", "--until", "1e308", "-o", "x.h5"],
             "--until (the run's end) 1e+308 s is inf gas steps")):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and said in err, err
        assert not list(tmp_path.glob("x.*")), argv


@pytest.mark.parametrize("args", [("stationarity",), ("stationarity", "--sample-length"),
                                  ("fit", "--states", "auto", "--estimator", "mle", "-o",
                                   "m.h5")])
def test_a_one_frame_file_is_named_as_such(tmp_path, capsys, monkeypatch, args):
    """One frame: these verbs had said "start 0 s lies outside the frames (0 to 0 s)",
    suggested the empty window 0:0, or a window length of at most half of 0 s."""
    monkeypatch.chdir(tmp_path)
    one = write_trajectories(tmp_path / "one.h5", np.array([0.0]), np.full((1, 3, 2), 0.01),
                             width=0.04, height=0.3)
    verb, *rest = args
    assert main([verb, str(one), *rest]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{one} holds one frame: no frame interval" in err, err


@pytest.mark.parametrize("argv, said", [
    (["compare", "r.h5", "p.h5", "--md-order", "-inf", "-o", "c"],
     "argument --md-order: '-inf' must be a finite number >= 1"),
    (["fit", "r.h5", "--lag", "-inf", "-o", "m.h5"], "argument --lag: '-inf' is not a finite"),
    (["fit", "r.h5", "--lag", "-nan", "-o", "m.h5"], "argument --lag: '-nan' is not a finite")])
def test_a_negative_infinity_is_judged_by_the_option_not_read_as_an_option(capsys, argv,
                                                                          said):
    """-inf and -nan reach the option's own check (argparse read them as options and said
    'expected one argument')."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err and "expected one argument" not in err, err

