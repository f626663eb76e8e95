"""The fit / predict / rtd / info verbs through cfbmarkov.cli.main, and their bad input."""

import h5py
import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.markov import MarkovModel
from cfbmarkov.trajectories import Trajectories


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_clean_failure(code, err, *absent):
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for path in absent:
        assert not path.exists()
        assert not any(p.name.startswith(f".{path.name}") for p in path.parent.iterdir())


def test_fit_predict_rtd_info(tmp_path, capsys, markov_run):
    model_path = tmp_path / "model.h5"
    code, out, _ = run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--lag", "0.05",
                           "--window", "1:5", "--estimator", "mle", "-o", model_path)
    assert code == 0 and "estimator 'mle'" in out and "states never visited: 0" in out
    model = MarkovModel.load(model_path)
    assert (model.state_space.columns, model.state_space.rows) == (4, 16)
    assert model.lag == 0.05 and model.window == (1.0, 5.0)
    assert model.frame_pairs == 4 / 0.025 + 1 - 2      # 161 frames, lag of 2 frames
    pred = tmp_path / "pred.h5"
    code, out, _ = run_cli(capsys, "predict", model_path, "--init", markov_run, "--start", 5,
                           "--duration", 2, "--seed", 7, "-o", pred, "-q")
    assert code == 0
    with Trajectories(pred) as t:
        assert t.n_frames == 41 and t.frame_interval == pytest.approx(0.05)
        first = t.positions()
    code, *_ = run_cli(capsys, "predict", model_path, "--init", markov_run, "--start", 5,
                       "--duration", 2, "--seed", 7, "-o", tmp_path / "again.h5", "-q")
    with Trajectories(tmp_path / "again.h5") as t:
        np.testing.assert_array_equal(t.positions(), first)        # seeded, reproducible
    code, out, _ = run_cli(capsys, "rtd", model_path, "--window-length", 5)
    assert code == 0 and "E(RT) =" in out
    # a window length between lags: refused with the lengths that are, not rounded silently
    code, out, err = run_cli(capsys, "rtd", model_path, "--window-length", 5.02)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "--window-length 5.02 s is not a whole multiple of the model's lag 0.05 s " \
           "(e.g. 5 or 5.05 s)" in err
    # the batch leaves as its residences end: the fraction left is the exact RTD's survival
    # from the batch's states (none leaves before the shortest residence)
    code, out, _ = run_cli(capsys, "maps", model_path, "--times", "0,0.5,2", "--outflow",
                           "-o", tmp_path / "maps.png")
    fractions = [float(line.split()[-1]) for line in out.splitlines()[:3]]
    assert code == 0 and fractions[0] == 1.0 and fractions[2] < fractions[1] <= 1.0
    assert (tmp_path / "maps.png").stat().st_size > 5000
    code, _, err = run_cli(capsys, "maps", model_path, "--times", "0.07", "-o", tmp_path / "x.png")
    assert "not a whole multiple of the model's lag" in err
    assert_clean_failure(code, err, tmp_path / "x.png")
    # an empty entry between commas (a typo) and a time given twice: refused
    for times, said in (("0.05,,0.1", "hold an empty entry between commas"),
                        ("0.1,0.1", "repeat a time: give each once")):
        code, _, err = run_cli(capsys, "maps", model_path, "--times", times, "-o",
                               tmp_path / "x.png")
        assert said in err
        assert_clean_failure(code, err, tmp_path / "x.png")
    code, out, _ = run_cli(capsys, "info", model_path)
    assert code == 0 and "Markov chain model" in out
    code, out, _ = run_cli(capsys, "info", pred)
    assert code == 0 and "markov-prediction" in out


@pytest.mark.parametrize("argv, message", [
    (["--cells", "6by38"], "cells '6by38' is not COLUMNSxROWS"),
    (["--cells", "0x38"], "at least one column"),
    (["--lag", "0.03"], "not a whole multiple of the frame interval"),
    (["--lag", "-1"], "must be positive"),
    (["--window", "7:12"], "lies partly outside the data"),
    (["--window", "7:12"], "only 7:8 s lies inside: choose one within it, e.g. 3:8"),
    (["--window", "5:2"], "STOP must exceed START"),
    (["--window", "a:b"], "is not START:STOP"),
])
def test_fit_bad_options(tmp_path, capsys, markov_run, argv, message):
    out = tmp_path / "m.h5"
    code, _, err = run_cli(capsys, "fit", markov_run, "--cells", "4x16", *argv, "-o", out)
    assert message in err
    assert_clean_failure(code, err, out)


def test_fit_bad_files(tmp_path, capsys, markov_run):
    out = tmp_path / "m.h5"
    truncated = tmp_path / "cut.h5"
    truncated.write_bytes(markov_run.read_bytes()[:5000])
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["data"] = np.arange(3)
    empty = tmp_path / "empty.h5"
    empty.write_bytes(b"")
    for src, message in ((truncated, "not a readable HDF5 file"),
                         (foreign, "not a cfbmarkov trajectory file"),
                         (empty, "empty file"), (tmp_path / "none.h5", "no such file")):
        code, _, err = run_cli(capsys, "fit", src, "-o", out)
        assert message in err
        assert_clean_failure(code, err, out)


def test_predict_bad_start(tmp_path, capsys, markov_run):
    model_path = tmp_path / "model.h5"
    run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--window", "1:5", "-o", model_path)
    out = tmp_path / "p.h5"
    code, _, err = run_cli(capsys, "predict", model_path, "--init", markov_run, "--start", 9.5,
                           "--duration", 1, "-o", out)
    assert "no frame at t = 9.5" in err
    assert_clean_failure(code, err, out)
    code, _, err = run_cli(capsys, "predict", markov_run, "--init", markov_run, "--start", 5,
                           "--duration", 1, "-o", out)
    assert "not a cfbmarkov model file" in err
    assert_clean_failure(code, err, out)
    # a start typed a little off its frame (within the file's tolerance) is read there and
    # dated there (not 5.0001 s, which compare could not match with the file's frames)
    code, _, err = run_cli(capsys, "predict", model_path, "--init", markov_run, "--start",
                           "5.0001", "--duration", 3, "-q", "-o", out)
    assert code == 0, err
    with Trajectories(out) as t:
        assert t.times[0] == 5.0 and np.allclose(np.diff(t.times), 0.025, rtol=0, atol=1e-12)
    code, _, err = run_cli(capsys, "compare", markov_run, out, "--no-figures", "--resamples",
                           "0", "-o", tmp_path / "cmp")
    assert code == 0, err


def test_predict_progress_is_whole_lines_off_a_terminal(tmp_path, capsys, markov_run,
                                                      monkeypatch):
    """stderr captured (not a terminal, as in a log file): whole lines starting with
    ``predict:``, no carriage return; -q: nothing."""
    from cfbmarkov.markov import prediction

    model_path = tmp_path / "model.h5"
    # no interval: its warning (a window shorter than the flow term needs) is not the point
    run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--lag", "0.05", "--window", "1:5",
            "--resamples", "0", "-o", model_path)
    monkeypatch.setattr(prediction, "LINE_INTERVAL", 0.0)      # a line at every block
    out = tmp_path / "p.h5"
    code, stdout, err = run_cli(capsys, "predict", model_path, "--init", markov_run,
                                "--start", 5, "--duration", 3, "-o", out)
    assert code == 0 and stdout.strip() == str(out)
    assert "\r" not in err and err.endswith("\n")
    lines = err.splitlines()
    assert all(line.startswith("predict: ") for line in lines), err
    assert lines[0] == ("predict: 3 s from t = 5 s (60 lags of 0.05 s), 2000 particles: "
                        "Monte Carlo, then the frames written")
    assert lines[1].startswith("predict: Monte Carlo done in 0:")
    assert "writing 61 frames" in lines[1]
    assert lines[2].startswith("predict: 1.55/3 s written, ")     # frames 0-31: 31 lags of 0.05 s
    assert "about" in lines[2] and lines[2].endswith(" left")
    assert lines[-1].startswith(f"predict: 3 s written to {out} in 0:")
    code, _, err = run_cli(capsys, "predict", model_path, "--init", markov_run, "--start", 5,
                           "--duration", 1, "-o", tmp_path / "q.h5", "-q")
    assert code == 0 and err == ""


def test_prediction_progress_bar_and_modes(capsys):
    """On a terminal a bar redrawn in place, counted in whole lags (never past the end);
    a mode that is none of True, False, 'bar' or 'lines' is refused."""
    from cfbmarkov.errors import InputError
    from cfbmarkov.markov.prediction import PredictionProgress

    shown = PredictionProgress("bar", 0.0, 40, 0.025, 10)
    shown.ran(20)
    assert shown.run_bar.n == 20 and shown.run_bar.total == 40      # the lags run
    shown.ran(40)
    shown.carried(30, 80)
    assert (shown.run_bar.n, shown.run_bar.total) == (30, 80)       # then the properties
    assert shown.run_bar.desc.startswith("predict 1 s: properties")
    shown.chain_done()
    for k in (32, 40):
        shown.written(k)
    shown.close("x.h5")
    err = capsys.readouterr().err
    assert "\r" in err and "40/40 lags written" in err and "predict 1 s" in err
    assert "predict 1 s: Monte Carlo" in err and "/40 lags run" in err
    assert "s/s" not in err and "-00:00" not in err
    quiet = PredictionProgress(False, 0.0, 40, 0.025, 10)
    quiet.chain_done()
    quiet.written(40)
    quiet.close("x.h5")
    assert capsys.readouterr().err == ""
    with pytest.raises(InputError, match="progress 'yes'"):
        PredictionProgress("yes", 0.0, 40, 0.025, 10)


def test_bench_only_a_whole_name_measures_that_figure_alone(capsys):
    """--only with a figure's whole name: that figure alone (mcm-exact-rtd-long-tail needs
    no trajectory file); a prefix keeps every figure it starts."""
    code, out, _ = run_cli(capsys, "bench", "--only", "mcm-exact-rtd-long-tail", "--repeat",
                           "1")
    assert code == 0
    lines = out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("mcm-exact-rtd-long-tail: ")
    from cfbmarkov.bench import run_benchmarks

    names = [row[0] for row in run_benchmarks(only=["mcm-exact-rtd"], repeat=1, particles=300)]
    assert names == ["mcm-exact-rtd"]


def test_bench_prints_one_line_per_figure(capsys):
    code, out, _ = run_cli(capsys, "bench", "--only", "mcm", "--repeat", "1", "--particles", "300")
    assert code == 0
    names = [line.split(":")[0] for line in out.strip().splitlines()]
    assert names[:7] == ["mcm-fit", "mcm-predict", "mcm-predict-file",
                         "mcm-predict-file-kinetics", "mcm-exact-rtd",
                         "mcm-exact-rtd-long-tail", "mcm-fit-intervals"]
    names = names[:3] + names[4:5] + names[7:]
    assert names[4:8] == ["mcm-fit-open", "mcm-fit-open-ratio", "mcm-predict-open",
                          "mcm-predict-open-ratio"]
    assert names[8] == "mcm-fit-auto" and names[9].startswith("mcm-fit-chosen-cells")
    assert names[10:] == ["mcm-predict-file-auto", "mcm-fit-auto-coherent",
                          "mcm-predict-file-auto-coherent", "mcm-fit-predict-auto-coherent",
                          "mcm-fit-regime", "mcm-predict-file-regime"]
    for line in out.strip().splitlines():
        name = line.split(":")[0]
        value, unit = line.split(": ")[1].split()
        assert float(value) > 0 and unit == ("x" if name.endswith("-ratio") else "s")


def test_an_interval_without_the_flows_variability_is_warned_and_none_is_said(
        tmp_path, capsys, markov_run):
    """A window too short for the flow's term (two blocks of three mean residence times):
    the interval is the window's sampling alone, and a `warning:` line says so in fit,
    rtd and the model's verdict; a window long enough carries the term and no such line.
    A model fitted with --resamples 0 says it has no interval in fit and rtd; compare
    refuses 1-9 resamples as fit does."""
    from cfbmarkov import synthetic
    from cfbmarkov.markov import MarkovModel

    fast = synthetic.write_run(tmp_path / "fast.h5", synthetic.RiserFlow(
        columns=4, rows=16, rise_velocity=4.0, fall_velocity=-0.6, vertical_spread=0.5,
        persistence=False), 400, 6.0, seed=3)              # E(RT) 0.45 s
    said = "the model's interval leaves out the flow's variability between windows"
    for window, short in (("1:2", True), ("1:6", False)):
        model = tmp_path / f"m{window.replace(':', '-')}.h5"
        code, _, err = run_cli(capsys, "fit", fast, "--cells", "4x16", "--window", window,
                               "-o", model, "-q")
        assert code == 0
        u = MarkovModel.load(model).uncertainty
        assert (u.flow_sd is None) == short, (window, u.flow_sd)
        assert (f"warning: {said}" in err) == short, err
        _, _, err = run_cli(capsys, "rtd", model)
        assert (said in err) == short
    bare = tmp_path / "bare.h5"
    code, out, _ = run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--lag", "0.05",
                           "--window", "1:3", "--resamples", "0", "-o", bare, "-q")
    assert code == 0 and "(no interval: the model carries none;" in out
    _, out, _ = run_cli(capsys, "rtd", bare)
    assert "no interval: the model carries none" in out
    _, _, err = run_cli(capsys, "rtd", bare, "--resamples", "20", "-q")  # formed here: said
    assert f"warning: {said}" in err
    pred = tmp_path / "p.h5"
    assert run_cli(capsys, "predict", bare, "--init", markov_run, "--start", 3,
                   "--duration", 1, "-o", pred, "-q")[0] == 0
    code, _, err = run_cli(capsys, "compare", markov_run, pred, "--window", "3:4",
                           "--resamples", "5", "-o", tmp_path / "c")
    assert code == 2 and err.count("\n") == 1 and "at least 10 bootstrap resamples" in err
    assert not (tmp_path / "c").exists()


def test_a_window_between_frames_is_said_with_the_frames_it_holds(tmp_path, capsys,
                                                                    markov_run):
    """A fitting window whose ends fall between the run's frames: a note names the frames
    the model is fitted on; a window on frames gives none."""
    code, _, err = run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--lag", "0.05",
                           "--window", "1.01:4.99", "--resamples", "0", "-q",
                           "-o", tmp_path / "m.h5")
    notes = [line for line in err.splitlines() if line.startswith("note: the window")]
    assert code == 0 and len(notes) == 1, err
    assert notes[0].endswith("falls between the frames of " + str(markov_run) + " (every "
                             "0.025 s): the model is fitted on those it holds, 1.025 to "
                             "4.975 s")
    # and stores them as its window: its figures "as the window sees it" are of 3.95 s of
    # frames (79 lags), not of the 3.98 s typed (80 lags)
    from cfbmarkov.markov.model import MarkovModel

    model = MarkovModel.load(tmp_path / "m.h5")
    assert model.window == pytest.approx((1.025, 4.975))
    assert "window 1.025:4.975 s" in model.summary()
    code, _, err = run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--lag", "0.05",
                           "--window", "1:5", "--resamples", "0", "-q", "-o", tmp_path / "n.h5")
    assert code == 0 and "falls between the frames" not in err
