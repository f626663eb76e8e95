"""What the command line prints and where: a reader that closes standard output early stops
the verb quietly; ``import`` prints only the output path on stdout; the advice in errors
names options the verb has; lists of files are printed as names."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cfbmarkov import synthetic
from cfbmarkov._console import CLOSED_PIPE
from cfbmarkov.cli import main

SRC = str(Path(__file__).resolve().parents[1] / "src")


def _env():
    return {**os.environ, "PYTHONPATH": SRC, "NUMBA_NUM_THREADS": "1"}


@pytest.fixture(scope="session")
def model(tmp_path_factory):
    """A 4x8-cell model fitted on 300 synthetic particles x 3 s, and its run."""
    folder = tmp_path_factory.mktemp("pipe")
    flow = synthetic.RiserFlow(columns=4, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)
    run = synthetic.write_run(folder / "run.h5", flow, 300, 3.0, seed=3)
    path = folder / "model.h5"
    assert main(["fit", str(run), "--cells", "4x8", "--lag", "0.05", "--window", "0:3",
                 "--no-adequacy", "-o", str(path)]) == 0
    return path


@pytest.mark.parametrize("verb", [["info"], ["rtd", "--json"], ["rtd"]])
def test_closed_stdout_stops_quietly(model, verb):
    """Standard output a pipe whose reader has already gone: every write fails (EPIPE)."""
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-m", "cfbmarkov", verb[0], str(model), *verb[1:]],
                              stdout=write, stderr=subprocess.PIPE, text=True, env=_env(),
                              timeout=300)
    finally:
        os.close(write)
    assert done.stderr == "" and done.returncode == CLOSED_PIPE == 141, done.stderr


@pytest.mark.parametrize("repeat", range(3))
def test_reader_closing_after_one_line(model, repeat):
    """``cfbmarkov info model.h5 | head -1``: the reader takes one line and closes."""
    for verb in (["info"], ["rtd", "--json"]):
        proc = subprocess.Popen([sys.executable, "-m", "cfbmarkov", verb[0], str(model),
                                 *verb[1:]], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                env=_env())
        first = proc.stdout.readline()
        proc.stdout.close()
        err = proc.stderr.read().decode()
        code = proc.wait(timeout=300)
        assert first.strip()
        assert err == "" and code in (0, CLOSED_PIPE), err


def test_import_prints_only_the_path_on_stdout(tmp_path, capsys):
    """``run=$(cfbmarkov import ...)`` holds the path; the summary and notes go to stderr."""
    source = tmp_path / "spots.csv"
    source.write_text("ID,TRACK_ID,POSITION_X,POSITION_Y,POSITION_T\n1,0,0.01,0.2,0\n"
                      "2,1,0.03,0.4,0\n3,0,0.012,0.25,0.1\n4,1,0.031,0.45,0.1\n"
                      "5,-1,0.02,0.3,0.1\n")
    for fmt in (["--format", "csv"], []):
        output = tmp_path / f"run{len(fmt)}.h5"
        code = main(["import", str(source), *fmt, "--width", "0.09", "--height", "0.95", "-o",
                     str(output)])
        out, err = capsys.readouterr()
        assert code == 0 and out == f"{output}\n"
        lines = err.splitlines()
        told = "--format" if fmt else "detected from the content"
        assert lines[0].startswith(f"cfbmarkov import: read 2 frames of 2 particles as CSV "
                                   f"({told}") and "ids from column 'TRACK_ID'" in lines[0]
        assert lines[1:] == ["  particle ids from column 'TRACK_ID'; not from 'ID'",
                             "  1 row with TRACK_ID -1 or empty (noise, or no track) dropped"]


def _options(verb: str) -> set[str]:
    import argparse

    from cfbmarkov.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return set(sub.choices[verb]._option_string_actions)


def _advised(message: str, verb: str) -> list[tuple[str, str]]:
    """(verb, option) for each option an error line advises: inside a quoted command line
    `cfbmarkov VERB ...` the options of VERB, elsewhere the failing verb's."""
    import re

    advised = []
    for quoted in re.findall(r"`cfbmarkov ([a-z-]+) ([^`]*)`", message):
        advised += [(quoted[0], o) for o in re.findall(r"(?<![\w-])--[a-z][a-z-]*", quoted[1])]
    rest = re.sub(r"`cfbmarkov [^`]*`", "", message)
    return advised + [(verb, o) for o in re.findall(r"(?<![\w-])--[a-z][a-z-]*", rest)]


def test_errors_advise_only_options_the_verb_has(model, tmp_path, capsys):
    """The lag of a model that does not fit a file's frames is refitted with ``fit --lag``;
    ``predict`` has no ``--lag``."""
    coarse = synthetic.write_run(tmp_path / "coarse.h5", synthetic.RiserFlow(
        columns=4, rows=8, lag=0.1, persistence=False), 20, 1.0, seed=1)
    run = model.parent / "run.h5"
    cases = [("predict", [str(model), "--init", str(coarse), "--start", "0", "--duration",
                          "0.2", "-o", str(tmp_path / "p.h5")], "refit the model"),
             ("fit", [str(run), "--cells", "4x8", "--lag", "0.03", "--window", "0:3", "-o",
                      str(tmp_path / "m.h5")], "use --lag 0.025 or a multiple"),
             ("stationarity", [str(run), "--lag", "0.03", "--window-length", "1"],
              "use --lag 0.025")]
    for verb, argv, expected in cases:
        assert main([verb, *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and expected in err, err
        advised = _advised(err, verb)
        assert advised, err
        for where, option in advised:
            assert option in _options(where), f"{verb}: advises {where} {option}: {err}"


def test_pooled_fit_names_its_runs(model, tmp_path, capsys):
    """``fit A B`` says ``fitted on A, B``, not a Python list."""
    first = model.parent / "run.h5"
    second = synthetic.write_run(tmp_path / "second.h5", synthetic.RiserFlow(
        columns=4, rows=8, persistence=False), 300, 3.0, seed=4)
    pooled = tmp_path / "pooled.h5"
    assert main(["fit", str(first), str(second), "--cells", "4x8", "--lag", "0.05", "--window",
                 "0:3", "--no-adequacy", "-o", str(pooled)]) == 0
    fit_out = capsys.readouterr().out
    assert main(["info", str(pooled)]) == 0
    info_out = capsys.readouterr().out
    for out in (fit_out, info_out):
        assert f"fitted on {first}, {second} window 0:3 s" in out, out
        assert "['" not in out


def test_trackpy_file_without_times_is_told_what_to_add(tmp_path, capsys):
    """trackpy writes ``frame`` and ``particle`` (x, y in pixels) and no time."""
    source = tmp_path / "trackpy.csv"
    source.write_text("y,x,mass,size,ecc,signal,raw_mass,ep,frame,particle\n"
                      "10.0,5.0,100,1.5,0.1,5,200,0.1,0,0\n20.0,6.0,100,1.5,0.1,5,200,0.1,0,1\n"
                      "11.0,5.2,100,1.5,0.1,5,200,0.1,1,0\n21.0,6.1,100,1.5,0.1,5,200,0.1,1,1\n")
    output = tmp_path / "t.h5"
    assert main(["import", str(source), "--width", "0.09", "--height", "0.95", "-o",
                 str(output)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and not output.exists()
    assert "missing column 't'" in err
    assert "frame numbers in 'frame' and particle ids in 'particle'" in err
    assert "add a column t = frame / frame rate (s)" in err and "pixels" in err
    for option in _advised(err, "import"):
        assert option[1] in _options("import"), err


def test_history_advice_names_the_verbs_own_option(model, capsys):
    """A window short of a memory state space's history: ``fit`` moves it with ``--window``,
    ``stationarity --sample-length`` (no ``--window``) with ``--start``."""
    run = str(model.parent / "run.h5")
    cases = [("fit", [run, "--states", "cells-direction", "--cells", "4x8", "--lag", "0.05",
                      "--window", "0:3", "-o", str(model.parent / "d.h5")], "(--window 0.05:3)"),
             ("stationarity", [run, "--sample-length", "--start", "0", "--states",
                               "cells-direction", "--cells", "4x8", "--lag", "0.05"],
              "(--start 0.05)")]
    for verb, argv, expected in cases:
        assert main([verb, *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.rstrip().endswith(expected), err
        for where, option in _advised(err, verb):
            assert option in _options(where), f"{verb}: advises {where} {option}: {err}"


def test_sample_length_without_a_start_begins_where_the_history_is(model, capsys):
    """``stationarity --sample-length`` names no start by default: a memory state space then
    starts the windows at the first frame with its history, says so on stderr, and gives
    the table that ``--start`` there gives."""
    run = str(model.parent / "run.h5")
    argv = [run, "--sample-length", "--states", "cells-direction", "--cells", "4x8", "--lag",
            "0.05", "--json"]
    assert main(["stationarity", *argv]) == 0
    out, err = capsys.readouterr()
    assert err == ("note: the windows start at 0.05 s, the first frame with the history that "
                   "cells-direction needs (--start sets another)\n")
    assert main(["stationarity", *argv, "--start", "0.05"]) == 0
    again, err = capsys.readouterr()
    assert json.loads(out) == json.loads(again) and err == ""


def test_a_model_file_for_a_trajectory_names_the_fix(model, capsys):
    assert main(["stationarity", str(model)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a cfbmarkov model file, not a trajectory file; give a " \
        "trajectory file" in err and "cfbmarkov info MODEL" in err


def test_an_output_named_as_another_format_is_refused(model, tmp_path, capsys):
    """A model named .txt, a prediction .csv, a map .h5, a folder of VTK files .h5: refused
    naming the suffix to use, nothing written; a name without a suffix is taken as given."""
    run = str(model.parent / "run.h5")
    for argv, message in (
            (["fit", run, "--cells", "4x8", "-o", str(tmp_path / "m.txt")],
             "the output is an HDF5 file, not a .txt file; name it m.h5"),
            (["predict", str(model), "--init", run, "--start", "0", "--duration", "0.1",
              "-q", "-o", str(tmp_path / "p.csv")], "not a .csv file; name it p.h5"),
            (["maps", str(model), "-o", str(tmp_path / "maps.h5")],
             "the output is a PNG image, not a .h5 file; name it maps.png"),
            (["export-vtk", run, "-o", str(tmp_path / "vtk.h5")],
             "the output is a folder of files, not a .h5 file; name the folder without the "
             "suffix (e.g. vtk)")):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == []
