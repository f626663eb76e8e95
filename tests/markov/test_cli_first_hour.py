"""What a new user meets on the command line: errors that name a working value, progress
lines every few seconds of work, compare's lines that judge, demos that never mix."""

from __future__ import annotations

import json
import re

import pytest

from cfbmarkov import _console
from cfbmarkov.cli import build_parser, main
from cfbmarkov.trajectories import Trajectories


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(code, err):
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="session")
def fitted(tmp_path_factory, markov_run):
    """A model on 1-5 s of ``markov_run`` (0-8 s, frames every 0.025 s) and its prediction
    of 5-7 s."""
    folder = tmp_path_factory.mktemp("first-hour")
    model, pred = folder / "model.h5", folder / "pred.h5"
    assert main(["fit", str(markov_run), "--cells", "4x16", "--window", "1:5", "-q",
                 "--resamples", "20", "-o", str(model)]) == 0
    assert main(["predict", str(model), "--init", str(markov_run), "--start", "5",
                 "--duration", "2", "-q", "-o", str(pred)]) == 0
    return model, pred


# -- errors that name a working value ------------------------------------------------------

def test_predict_off_a_frame_names_the_nearest(tmp_path, capsys, markov_run, fitted):
    model, _ = fitted
    line = one_line_error(*run_cli(capsys, "predict", model, "--init", markov_run, "--start",
                                   "5.01", "--duration", "1", "-o", tmp_path / "p.h5")[::2])
    assert "no frame at t = 5.01 s" in line and "the nearest is at 5 s" in line
    # far beyond the frames the differences round alike: the nearest is the last frame
    with Trajectories(markov_run) as t:
        last = float(t.times[-1])
    line = one_line_error(*run_cli(capsys, "predict", model, "--init", markov_run, "--start",
                                   "1e15", "--duration", "1", "-o", tmp_path / "p.h5")[::2])
    assert f"the nearest is at {last:g} s" in line, line


def test_rtd_of_a_trajectory_file_says_fit_first(capsys, markov_run):
    line = one_line_error(*run_cli(capsys, "rtd", markov_run)[::2])
    assert "is a trajectory file" in line and f"cfbmarkov fit {markov_run}" in line


def test_rtd_at_another_level_names_a_number_of_resamples(capsys, fitted):
    model, _ = fitted
    line = one_line_error(*run_cli(capsys, "rtd", model, "--level", "0.95")[::2])
    assert "--resamples 100" in line and "--resamples N" not in line


def test_fit_refuses_a_level_that_no_interval_uses(tmp_path, capsys, markov_run):
    """--level with --resamples 0 sets the coverage of an interval that is not formed: one
    line, nothing written (it was taken and ignored)."""
    out = tmp_path / "m.h5"
    line = one_line_error(*run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--window",
                                   "1:5", "--resamples", "0", "--level", "0.95",
                                   "-o", out)[::2])
    assert "--level 0.95 sets the interval's coverage, which --resamples 0 leaves out" in line
    assert not out.exists()


def test_compare_without_window_compares_over_the_span_both_cover(tmp_path, capsys,
                                                                  markov_run, fitted):
    _, pred = fitted
    code, _, err = run_cli(capsys, "compare", markov_run, pred, "-o", tmp_path / "c",
                           "--no-figures", "--resamples", "0")
    assert code == 0, err
    assert "no --window given: comparing over 5:7 s, the span both files cover" in err
    assert "covers 0 to 8 s" in err and "5 to 7 s" in err
    summary = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert summary["window"] == [5.0, 7.0]


def test_window_partly_outside_names_the_part_inside(tmp_path, capsys, markov_run):
    line = one_line_error(*run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--window",
                                   "6:10", "-o", tmp_path / "m.h5")[::2])
    assert "only 6:8 s lies inside" in line and "e.g. 4:8" in line


# -- progress: a line at the start of each stage and every few seconds of work -------------

def test_heartbeat_writes_lines_while_the_block_works():
    import time

    lines = []
    with _console.heartbeat("compare", write=lines.append, every=0.05):
        time.sleep(0.3)
    assert len(lines) >= 2
    assert all(re.fullmatch(r"compare: still working, 0:0\d so far", line) for line in lines)
    quiet = []
    with _console.heartbeat("", write=quiet.append, every=0.01):
        time.sleep(0.05)
    assert quiet == []


def test_fit_names_its_stages_and_is_silent_with_q(tmp_path, capsys, markov_run):
    code, _, err = run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--window", "1:5",
                           "--resamples", "20", "-o", tmp_path / "m.h5")
    assert code == 0
    assert "fit: the model's 90 % interval: 20 bootstrap resamples" in err
    assert "fit: the fitting sample's verdict" in err
    code, _, err = run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--window", "1:5",
                           "--resamples", "20", "-q", "-o", tmp_path / "q.h5")
    assert code == 0 and not [l for l in err.splitlines() if l.startswith("fit")]


def test_compare_says_it_is_alive_every_few_seconds(tmp_path, capsys, markov_run, fitted,
                                                   monkeypatch):
    import importlib
    import time

    report_compare = importlib.import_module("cfbmarkov.report.compare")

    _, pred = fitted
    monkeypatch.setattr(_console, "HEARTBEAT_EVERY", 0.05)
    real = report_compare.compare

    def slow_compare(*args, **kwargs):      # at least a few beats long on any machine
        time.sleep(0.3)
        return real(*args, **kwargs)

    monkeypatch.setattr(report_compare, "compare", slow_compare)
    code, out, err = run_cli(capsys, "compare", markov_run, pred, "--window", "5:7",
                             "--no-figures", "--resamples", "0", "-o", tmp_path / "c")
    assert code == 0
    assert "compare: still working" in err
    code, out, err = run_cli(capsys, "compare", markov_run, pred, "--window", "5:7",
                             "--no-figures", "--resamples", "0", "-q", "-o", tmp_path / "d")
    assert code == 0 and "still working" not in err


# -- compare's printed lines judge --------------------------------------------------------

def test_compare_prints_counts_baseline_and_whether_inside(tmp_path, capsys, markov_run,
                                                           fitted, monkeypatch):
    _, pred = fitted
    code, out, _ = run_cli(capsys, "compare", markov_run, pred, "--window", "5:7",
                           "--no-figures", "--resamples", "20", "-q", "-o", tmp_path / "c")
    assert code == 0
    summary = json.loads((tmp_path / "c" / "summary.json").read_text())
    ref, model = summary["reference"], summary["model"]
    assert (f"residences counted: reference {ref['rt_count']}, model {model['rt_count']}"
            in out)
    baseline = summary["baseline"]
    assert f"MD {baseline['md_rtd']:.4g} against the model's {summary['md_rtd']:.4g}" in out
    lo, hi = model["rt_mean_interval"]
    place = "inside" if lo <= ref["rt_mean"] <= hi else "below" if ref["rt_mean"] < lo else "above"
    assert f"the reference's E(RT) {ref['rt_mean']:.4g} s lies {place} the model's interval" in out
    # the verdict is given the reference's own intervals where the flow's term is left out
    from cfbmarkov.cli import analysis

    given = []
    real = analysis.interval_verdict
    monkeypatch.setattr(analysis, "interval_verdict",
                        lambda *a, **k: given.append(a) or real(*a, **k))
    assert main(["compare", str(markov_run), str(pred), "--window", "5:7", "--no-figures",
                 "--resamples", "20", "-q", "-o", str(tmp_path / "c2")]) == 0
    capsys.readouterr()
    flow = (summary.get("intervals") or {}).get("flow_sd") is not None
    assert given and given[0][4] == (None if flow else (ref["rt_mean_interval"],
                                                          ref["rt_sd_interval"]))


def test_interval_verdict_says_outside_means_a_miss():
    from cfbmarkov.cli.analysis import baseline_line, interval_verdict

    assert interval_verdict(0.74, 0.53, (0.81, 0.86), (0.28, 0.30)).endswith(
        "the model misses the reference's E(RT) and SD(RT) beyond its uncertainty")
    assert "lies inside" in interval_verdict(0.83, 0.29, (0.81, 0.86), (0.28, 0.30))
    assert "SD(RT) 0.35 s above" in interval_verdict(0.83, 0.35, (0.81, 0.86), (0.28, 0.30))
    assert "consistent" in interval_verdict(0.83, 0.29, (0.81, 0.86), (0.28, 0.30))
    # where the model's interval leaves the reference's sampling out, a reference figure
    # whose own interval overlaps it is not told apart (not a miss)
    own = ((0.70, 0.80), (0.50, 0.56))
    apart = interval_verdict(0.74, 0.53, (0.78, 0.86), (0.28, 0.30), own)
    assert "misses the reference's SD(RT) beyond" in apart and "E(RT) and SD(RT)" not in apart
    assert ("its E(RT) is not told apart: the reference's own 90 % interval (E(RT) "
            "0.7000-0.8000 s;") in apart
    both = interval_verdict(0.74, 0.53, (0.78, 0.86), (0.54, 0.60), own, level=0.95)
    assert both.endswith("overlaps it: the two are not told apart") and "95 %" in both
    assert "misses" not in both
    far = interval_verdict(0.74, 0.53, (0.81, 0.86), (0.28, 0.30), own)
    assert far.endswith("misses the reference's E(RT) and SD(RT) beyond its uncertainty")
    # an interval wider than its centre holds almost anything: said, not called consistent
    wide = interval_verdict(2.0, 0.5, (0.0, 7.8), (0.0, 2.3))
    assert "consistent" not in wide and "200 % of its centre wide, so this says little" in wide
    line = baseline_line({"windows": [[10, 15], [15, 20]], "md_rtd": 0.0122,
                          "pd_rt_mean": -0.5}, 0.2021)
    assert "10-15 s" in line and "MD 0.0122 against the model's 0.2021" in line
    # without the halves' MD (a half without residences) the tie margin alone judges: said
    assert line.endswith("the baseline is closer (judged against no measure of the "
                         "reference's own variability, only beyond a 1 % tie: the reference "
                         "window's halves give none, as where a half holds no residence in "
                         "the window's direction)")
    assert baseline_line({"windows": [[10, 15], [15, 20]], "md_rtd": 0.0122,
                          "pd_rt_mean": -0.5}, 0.2021, 0.01).endswith("the baseline is closer")
    # the report's rule: a gap within the reference halves' MD cannot be told apart
    close = baseline_line({"windows": [[10, 15], [15, 20]], "md_rtd": 0.01225,
                           "pd_rt_mean": -0.5}, 0.01343, 0.02154)
    assert close.endswith("not told apart (the gap is within the reference's own "
                          "variability, its halves' MD 0.02154)")
    assert baseline_line({"windows": [[10, 15], [15, 20]], "md_rtd": 0.1,
                          "pd_rt_mean": -0.5}, 0.1005, 0.0).endswith("a tie (within 1 %)")


def test_compare_with_an_undefined_model_md_prints_no_baseline_verdict(
        tmp_path, capsys, monkeypatch, markov_run, fitted):
    """A window where the prediction has no residence (its MD undefined) while the
    baseline's is defined: the baseline line says it is not judged, no traceback."""
    import importlib

    from cfbmarkov.report.compare import compare as real_compare

    def undefined_md(*args, **kwargs):
        summary = real_compare(*args, **kwargs)
        summary["md_rtd"] = float("nan")
        summary["baseline"] = {"windows": [[3, 5], [5, 7]], "md_rtd": 0.05, "pd_rt_mean": 1.0}
        return summary

    monkeypatch.setattr(importlib.import_module("cfbmarkov.report.compare"), "compare",
                        undefined_md)
    _, pred = fitted
    code, out, err = run_cli(capsys, "compare", markov_run, pred, "--window", "5:7",
                             "--resamples", "0", "--no-figures", "-q", "-o", tmp_path / "c")
    assert code == 0 and "Traceback" not in err
    assert "persistence baseline not judged: the model's MD is undefined" in out


# -- the two demos never share a folder ----------------------------------------------------

def test_demos_have_distinct_default_folders():
    from cfbmarkov.cli.run import demo_output

    assert demo_output(None, False) != demo_output(None, True)
    assert demo_output("x", True) == "x"
    demo = next(a for a in build_parser()._subparsers._group_actions[0].choices["demo"]._actions
                if "--output" in a.option_strings)
    assert "cfbmarkov-demo-synthetic" in demo.help


def test_synthetic_demo_refuses_the_cfd_dem_demo_folder(tmp_path, capsys, monkeypatch):
    import cfbmarkov.demo

    def no_run(*args, **kwargs):            # were it not refused: fail at once, not run
        raise AssertionError("the synthetic demo started in the CFD-DEM demo's folder")

    monkeypatch.setattr(cfbmarkov.demo, "run_demo", no_run)
    folder = tmp_path / "cfbmarkov-demo"
    folder.mkdir()
    (folder / "reproduce.json").write_text("{}")
    line = one_line_error(*run_cli(capsys, "demo", "--synthetic", "-o", folder)[::2])
    assert "holds the CFD-DEM demo" in line and "-o cfbmarkov-demo-synthetic" in line
    assert sorted(p.name for p in folder.iterdir()) == ["reproduce.json"]


def test_cfd_dem_demo_refuses_the_synthetic_demo_folder(tmp_path, capsys, monkeypatch):
    import cfbmarkov.reproduce

    def no_run(*args, **kwargs):            # were it not refused: fail at once, not run
        raise AssertionError("the CFD-DEM demo started in the synthetic demo's folder")

    monkeypatch.setattr(cfbmarkov.reproduce, "reproduce", no_run)
    folder = tmp_path / "synth"
    folder.mkdir()
    (folder / "demo.json").write_text("{}")
    line = one_line_error(*run_cli(capsys, "demo", "-o", folder)[::2])
    assert "holds the synthetic demo" in line and "-o cfbmarkov-demo" in line
    assert sorted(p.name for p in folder.iterdir()) == ["demo.json"]


def test_demo_help_gives_jobs_default_and_synthetic_span():
    demo = build_parser()._subparsers._group_actions[0].choices["demo"]
    helps = {a.option_strings[0]: a.help for a in demo._actions if a.option_strings}
    assert "default" in helps["--jobs"]
    assert "0-20 s" in helps["--synthetic"] and "(30 s)" not in helps["--synthetic"]
    compare = build_parser()._subparsers._group_actions[0].choices["compare"]
    basis = next(a.help for a in compare._actions if "--basis" in a.option_strings)
    assert basis.count("default") == 1


# -- fit --states auto: what its percentages are against ----------------------------------

def test_auto_choice_says_what_its_percentages_are_against(markov_run):
    from cfbmarkov.markov.select import select_model

    model = select_model(markov_run, window=(2.0, 6.0), columns=4, rows=16, lag=0.05,
                         states=("cells", "cells-direction"))
    reason = model.selection["reason"]
    found = re.search(r"as seen in a 4 s window \(E\(RT\) ([\d.]+) s\)"
                      r" against the residences the window holds whole, E\(RT\) ([\d.]+) s",
                      reason)
    assert found, reason
    seen, observed = map(float, found.groups())
    chosen = model.selection["chosen"]       # the winner's PD, as its row of the table shows
    pd = next(c["pd_rt_mean"] for c in model.selection["candidates"]
              if c["states"] == chosen["states"] and c["lag"] == chosen["lag"])
    assert pd == pytest.approx(100 * (seen / observed - 1), abs=0.6)   # 3-digit rounding


def test_fit_without_a_window_says_10_15_is_the_default(markov_run, tmp_path, capsys):
    """A run shorter than 15 s fitted without --window: the refusal says that 10:15 s is
    the default, not a window the user gave."""
    from cfbmarkov.cli import main

    assert main(["fit", str(markov_run), "--cells", "4x16", "--lag", "0.1", "-o",
                 str(tmp_path / "m.h5")]) == 2
    err = capsys.readouterr().err
    assert "window 10:15 s lies outside" in err and "no --window was given: 10:15 s is its " \
        "default" in err


def test_an_rtd_window_that_would_not_fit_in_memory_is_refused(tmp_path, capsys, monkeypatch):
    """rtd --window-length holds a few numbers a lag and state: a window that would need more
    memory than there is is refused in one line with the longest that fits (it ran out of
    memory with a traceback)."""
    from cfbmarkov import synthetic
    from cfbmarkov.cli import main

    run = synthetic.write_run(tmp_path / "r.h5", synthetic.RiserFlow(), 100, 6.0, seed=1)
    model = tmp_path / "m.h5"
    assert main(["fit", str(run), "--window", "1:5", "--resamples", "0", "--no-adequacy",
                 "-q", "-o", str(model)]) == 0
    capsys.readouterr()
    monkeypatch.setenv("CFBMARKOV_MEMORY_LIMIT", "50000000")
    assert main(["rtd", str(model), "--window-length", "1000"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the RTD as a 1000 s window sees it (40000 lags x 228 " \
        "states) would need about" in err and "give a window length of at most 114 s" in err
    assert main(["rtd", str(model), "--window-length", "5"]) == 0


def test_rtd_says_it_is_alive_while_the_exact_rtd_runs(tmp_path, capsys, fitted, monkeypatch):
    """A long exact RTD (a long tail, a long --window-length) prints `rtd (exact RTD): still
    working` lines; -q prints none."""
    import time

    from cfbmarkov.markov.model import MarkovModel

    model, _ = fitted
    monkeypatch.setattr(_console, "HEARTBEAT_EVERY", 0.05)
    real = MarkovModel.rtd

    def slow_rtd(self, *args, **kwargs):        # at least a few beats long on any machine
        time.sleep(0.3)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(MarkovModel, "rtd", slow_rtd)
    code, _, err = run_cli(capsys, "rtd", model, "--window-length", "2")
    assert code == 0 and "rtd (exact RTD): still working, 0:0" in err
    code, _, err = run_cli(capsys, "rtd", model, "--window-length", "2", "-q")
    assert code == 0 and "still working" not in err


def test_ctrl_c_after_the_comparison_is_published_says_it_is_whole(tmp_path, capsys,
                                                                    markov_run, fitted,
                                                                    monkeypatch):
    """Ctrl-C after compare's folder was renamed into place (while the lines are printed):
    the one line says the folder is complete, as fit's says of its file."""
    import importlib

    report_compare = importlib.import_module("cfbmarkov.report.compare")
    _, pred = fitted
    real = report_compare.compare

    def then_interrupted(*args, **kwargs):
        real(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(report_compare, "compare", then_interrupted)
    out = tmp_path / "c"
    code, _, err = run_cli(capsys, "compare", markov_run, pred, "--window", "5:7",
                           "--no-figures", "--resamples", "0", "-o", out)
    assert code == 130 and (out / "summary.json").is_file()
    assert err.splitlines()[-1] == (f"cfbmarkov compare: interrupted after {out} was written "
                                    "whole (the folder is complete; only the lines printed "
                                    "after it were cut short)")


def test_compare_refuses_a_level_without_intervals(tmp_path, capsys, markov_run, fitted):
    """--level with --resamples 0 sets the coverage of intervals that are not formed: refused
    in one line, as fit refuses it, before any output."""
    _, pred = fitted
    line = one_line_error(*run_cli(capsys, "compare", markov_run, pred, "--window", "5:7",
                                   "--no-figures", "--resamples", "0", "--level", "0.5",
                                   "-o", tmp_path / "c")[::2])
    assert "--level 0.5 sets the intervals' coverage" in line and "--resamples 0" in line
    assert not (tmp_path / "c").exists()
    code, _, _ = run_cli(capsys, "compare", markov_run, pred, "--window", "5:7",
                         "--no-figures", "--resamples", "0", "-q", "-o", tmp_path / "d")
    assert code == 0
