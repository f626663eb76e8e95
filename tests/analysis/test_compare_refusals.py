"""``compare`` refuses what would give a meaningless summary, in one line and before any
output: a side without a complete residence in the window, RTD bins too wide for an MD,
a prediction given as the reference of a run; and its messages name its own options."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.observed.residence import residence_times
from cfbmarkov.report.compare import compare
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

from ..observed.conftest import HEIGHT, WIDTH, generate_run


def refused(capsys, argv, out):
    """Run ``cfbmarkov compare`` with ``argv`` into ``out``; the one line it says on stderr
    after checking it exits 2 and prints nothing on stdout."""
    code = main(["compare", *map(str, argv), "-o", str(out), "--resamples", "0",
                 "--no-figures"])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and captured.out == "", captured
    assert "Traceback" not in captured.err
    return lines[0]


def folder_bytes(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def prediction(path, run):
    return write_trajectories(path, run.times, run.positions, width=WIDTH, height=HEIGHT,
                              source="markov-prediction", parameters={"columns": 6, "rows": 38})


# -- 1. a side without residences ------------------------------------------------------------

def test_a_window_without_residences_is_refused_leaving_the_output_as_it_was(pair, tmp_path,
                                                                            capsys):
    ref, pred = pair
    out = tmp_path / "c"
    assert main(["compare", str(ref), str(pred), "--window", "0.5:3", "-o", str(out), "-q",
                 "--resamples", "0"]) == 0
    capsys.readouterr()
    before = folder_bytes(out)
    assert "summary.json" in before and "rtd.png" in before
    # without -q too: the refusal comes before the progress line
    for quiet in (["-q"], []):
        err = refused(capsys, [ref, pred, "--window", "0.5:0.6", *quiet], out)
        assert err.startswith("cfbmarkov compare: error: no residence begins and ends in "
                              "0.5-0.6 s on the reference side")
        assert "compare over a longer window (both files cover 0.5 to 3 s, e.g. --window " \
               "0.5:3)" in err
        assert folder_bytes(out) == before
    new = tmp_path / "new"
    refused(capsys, [ref, pred, "--window", "0.5:0.6"], new)
    assert not new.exists()


def test_a_prediction_shorter_than_its_residences_asks_for_a_longer_one(tmp_path, capsys):
    ref = generate_run(seed=1)
    short = generate_run(seed=2, t0=0.5, t1=0.6, initial=ref.positions[20])
    ref_path = write_trajectories(tmp_path / "ref.h5", ref.times, ref.positions, width=WIDTH,
                                  height=HEIGHT, source="cfd-dem")
    pred_path = prediction(tmp_path / "pred.h5", short)
    err = refused(capsys, [ref_path, pred_path, "--window", "0.5:0.6", "-q"], tmp_path / "c")
    assert "both files cover only 0.5 to 0.6 s: predict a longer --duration" in err
    assert not (tmp_path / "c").exists()


def test_a_model_side_without_residences_is_refused(tmp_path, capsys):
    ref = generate_run(seed=1)
    still = generate_run(seed=2, rise=0.0, spread=1e-4, t0=0.5, initial=ref.positions[20])
    ref_path = write_trajectories(tmp_path / "ref.h5", ref.times, ref.positions, width=WIDTH,
                                  height=HEIGHT, source="cfd-dem")
    pred_path = prediction(tmp_path / "pred.h5", still)
    with Trajectories(ref_path) as r, Trajectories(pred_path) as p:
        assert residence_times(r, (0.5, 3.0)).count > 30
        assert residence_times(p, (0.5, 3.0)).count == 0
    err = refused(capsys, [ref_path, pred_path, "--window", "0.5:3", "-q"], tmp_path / "c")
    assert "no residence begins and ends in 0.5-3 s on the model side" in err
    assert not (tmp_path / "c").exists()


def test_a_window_of_one_frame_is_refused(pair, tmp_path, capsys):
    ref, pred = pair
    err = refused(capsys, [ref, pred, "--window", "1:1.01", "-q"], tmp_path / "c")
    assert ("window 1:1.01 s (0.01 s long) holds fewer than two RTD bins of 0.025 s (the "
            "reference's frame interval): compare over a window of 0.05 s or more") in err
    # bins finer than the frames add only empty ones (and would hide the few-bins warning)
    err = refused(capsys, [ref, pred, "--window", "1:1.01", "--bin-width", "0.001", "-q"],
                  tmp_path / "c")
    assert ("--bin-width 0.001 s is narrower than the residence times' step, 0.025 s (the "
            "model's lag and the reference's frames read at it): they are whole numbers of "
            "it") in err
    assert "give --bin-width 0.025 or more" in err
    assert not (tmp_path / "c").exists()
    # a width of no whole number of frames bins one or two frame times alternately: warned
    summary = compare(ref, pred, window=(0.5, 3.0), output=tmp_path / "comb", bin_width=0.03,
                      figures=False)
    assert any("--bin-width 0.03 s is no whole number of the residence times' step, 0.025 s"
               in w and "e.g. 0.025 or 0.05" in w for w in summary["warnings"])
    summary = compare(ref, pred, window=(0.5, 3.0), output=tmp_path / "whole", bin_width=0.05,
                      figures=False)
    assert not any("no whole number" in w for w in summary["warnings"])


def test_the_baseline_line_of_an_undefined_md_is_not_judged():
    from cfbmarkov.cli.analysis import baseline_line

    line = baseline_line({"windows": [[0.0, 1.0], [1.0, 2.0]], "md_rtd": math.nan}, 0.1)
    assert "not judged" in line and "nan" not in line
    assert "a tie" not in baseline_line({"windows": [[0.0, 1.0], [1.0, 2.0]], "md_rtd": 0.2},
                                        math.nan)


# -- 2. bins too wide for an MD -------------------------------------------------------------

def test_a_bin_wider_than_half_the_window_is_refused(pair, tmp_path, capsys):
    ref, pred = pair
    out = tmp_path / "c"
    err = refused(capsys, [ref, pred, "--window", "0.5:3", "--bin-width", "100", "-q"], out)
    assert ("--bin-width 100 s leaves one RTD bin over the window 0.5:3 s (2.5 s long)"
            in err)
    assert "give --bin-width 1.25 s or less" in err
    assert not out.exists()
    with pytest.raises(InputError, match="leaves one RTD bin"):
        compare(ref, pred, window=(0.5, 3.0), output=out, bin_width=2.5, figures=False)
    assert not out.exists()


def test_bins_that_hold_all_but_a_stray_residence_in_one_are_refused():
    """300 residences of 0.1-0.9 s and one of 1.5 s: bins of 1 s put 99.7 % in the first
    (the RTD spans one bin from its 1 % to its 99 % quantile) and are refused, naming a
    width from that range; bins of 0.4 s span three and pass."""
    from types import SimpleNamespace

    from cfbmarkov.analysis.compare import _check_bins_resolve

    samples = np.append(np.linspace(0.1, 0.9, 300), 1.5)
    rt = SimpleNamespace(count=samples.size, samples=samples)
    with pytest.raises(InputError, match=r"98 % or more of the 301 residences .* fall in one "
                                         r"RTD bin of 1 s.*give --bin-width 0.39 s or less"):
        _check_bins_resolve(rt, 1.0, "given", (0.0, 5.0))
    _check_bins_resolve(rt, 0.4, "given", (0.0, 5.0))


def test_bins_that_hold_all_the_references_residences_in_one_are_refused(pair, tmp_path,
                                                                         capsys):
    ref, pred = pair
    with Trajectories(ref) as r:
        samples = residence_times(r, (0.5, 3.0)).samples
    assert samples.size > 30 and samples.max() < 1.2        # two bins over the window
    spread = samples.max() - samples.min()
    err = refused(capsys, [ref, pred, "--window", "0.5:3", "--bin-width", "1.2", "-q"],
                  tmp_path / "c")
    assert f"all {samples.size} residences of the reference in 0.5-3 s" in err
    assert "fall in one RTD bin of 1.2 s" in err
    width = float(err.split("give --bin-width ")[1].split(" s or less")[0])
    assert width == pytest.approx(spread / 2, rel=0.05)
    assert not (tmp_path / "c").exists()
    summary = compare(ref, pred, window=(0.5, 3.0), output=tmp_path / "ok", bin_width=width,
                      figures=False, resamples=0)                # the width it names works
    assert summary["rtd_bins"]["count"] >= 2 and summary["md_rtd"] > 0


# -- 3. a prediction given as the reference --------------------------------------------------

def test_a_prediction_given_as_the_reference_of_a_run_is_refused(pair, tmp_path, capsys):
    ref, pred = pair
    for window in (["--window", "0.5:3"], []):       # also before the default window's line
        err = refused(capsys, [pred, ref, *window], tmp_path / "c")
        assert f"the reference {pred} is a Markov prediction and the prediction {ref} is not" \
               in err
        assert "look swapped; give the run first" in err
    assert not (tmp_path / "c").exists()
    with pytest.raises(InputError, match="look swapped"):
        compare(pred, ref, window=(0.5, 3.0), output=tmp_path / "c", figures=False)


def test_two_predictions_are_compared_as_given(pair, tmp_path):
    ref, pred = pair
    with Trajectories(ref) as r:
        start = r.positions(20)
    other = prediction(tmp_path / "other.h5", generate_run(seed=5, rise=1.5, t0=0.5,
                                                           initial=start))
    one = compare(pred, other, window=(0.5, 3.0), output=tmp_path / "a", figures=False,
                  resamples=0)
    two = compare(other, pred, window=(0.5, 3.0), output=tmp_path / "b", figures=False,
                  resamples=0)
    assert np.isfinite(one["pd_rt_mean"]) and one["pd_rt_mean"] != 0
    assert np.sign(one["pd_rt_mean"]) == -np.sign(two["pd_rt_mean"])
    # and said to be two models, not a model against the flow
    for summary, reference in ((one, pred), (two, other)):
        [said] = [w for w in summary["warnings"] if "is itself a Markov prediction" in w]
        assert said.startswith(f"the reference {reference} is itself")
    run = compare(ref, pred, window=(0.5, 3.0), output=tmp_path / "c", figures=False,
                  resamples=0)
    assert not any("itself a Markov prediction" in w for w in run["warnings"])


def test_two_imported_runs_compare_though_their_columns_name_csv_columns(tmp_path):
    """An imported file's parameters name its source's columns (``columns`` = the CSV
    header, a list): compared with another import it is no grid width to read (a
    TypeError traceback once), and the comparison runs on the paper's grid."""
    from cfbmarkov.io import import_file
    from cfbmarkov.synthetic import RiserFlow, write_run

    imported = []
    for seed in (1, 2):
        run = write_run(tmp_path / f"run{seed}.h5", RiserFlow(), 150, 3.0, seed=seed)
        with Trajectories(run) as t:
            times, positions = t.times, t.positions()
            width, height = t.width, t.height
        rows = ["t,id,x,y"] + [f"{time:.4f},{i},{x:.6f},{y:.6f}"
                               for time, frame in zip(times, positions)
                               for i, (x, y) in enumerate(frame)]
        source = tmp_path / f"run{seed}.csv"
        source.write_text("\n".join(rows) + "\n")
        imported.append(import_file(source, "csv", tmp_path / f"imported{seed}.h5",
                                    width=width, height=height))
    with Trajectories(imported[1]) as t:
        assert isinstance(t.parameters["columns"], list)
    summary = compare(*imported, window=(0.5, 3.0), output=tmp_path / "c", figures=False,
                      resamples=0)
    assert summary["cluster_index"]["grid"] == [6, 38] and np.isfinite(summary["pd_rt_mean"])


# -- 4. messages naming compare's own options -------------------------------------------------

def test_a_long_run_span_outside_the_reference_names_compares_option(pair, tmp_path, capsys):
    ref, pred = pair
    err = refused(capsys, [ref, pred, "--window", "0.5:3", "--long-run-span", "0:40", "-q"],
                  tmp_path / "c")
    assert "give --long-run-span inside them, e.g. --long-run-span 0:3" in err
    assert "--span" not in err.replace("--long-run-span", "")
    err = refused(capsys, [ref, pred, "--window", "0.5:3", "--long-run-span", "0:3", "-q"],
                  tmp_path / "c")
    assert "(give a longer --long-run-span)" in err
    assert not (tmp_path / "c").exists()
    # one other whole window beside the judged one would be a persistence baseline again
    err = refused(capsys, [ref, pred, "--window", "2:3", "--long-run-span", "0.5:3", "-q"],
                  tmp_path / "c")
    assert ("span 0.5:3 s holds only 1 other whole 1 s window beside 2:3 s: one window is a "
            "persistence baseline again, not a long run; give a longer --long-run-span (at "
            "least 2 other windows)") in err
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("order, text", [
    ("nan", "'nan' is not a number: give a finite number >= 1 (or inf"),
    ("0.5", "'0.5' must be a finite number >= 1 (or inf"),
    ("-inf", "'-inf' must be a finite number >= 1 (or inf")])
def test_md_order_refusals_say_what_is_wanted(pair, tmp_path, capsys, order, text):
    ref, pred = pair
    err = refused(capsys, [ref, pred, "--window", "0.5:3", f"--md-order={order}", "-q"],
                  tmp_path / "c")
    assert "argument --md-order: " + text in err
    assert not (tmp_path / "c").exists()


def test_a_file_compared_with_itself_or_its_copy_is_refused(pair, tmp_path, capsys):
    import shutil

    ref, _ = pair
    copy = shutil.copy(ref, tmp_path / "copy.h5")
    for other in (ref, copy):
        err = refused(capsys, [ref, other, "--window", "0.5:3"], tmp_path / "c")
        assert "hold the same trajectories: a file compared with itself gives MD 0" in err
    assert not (tmp_path / "c").exists()


def test_the_default_windows_note_comes_only_after_the_checks(pair, tmp_path, capsys):
    """Without --window, a refusal stays the one line (the note on the window chosen is
    printed once the inputs are checked)."""
    ref, pred = pair
    err = refused(capsys, [ref, pred, "--bin-width", "100"], tmp_path / "c")
    assert "--bin-width 100 s" in err
    assert main(["compare", str(ref), str(pred), "-o", str(tmp_path / "d"), "--resamples", "0",
                 "--no-figures", "-q"]) == 0
    assert "no --window given: comparing over 0.5:3 s" in capsys.readouterr().err


def test_an_output_folder_holding_other_files_is_refused_before_any_line(pair, tmp_path,
                                                                          capsys):
    """A folder holding files a comparison did not write: refused in one line before the
    default window's note or the progress line, the files left as they were."""
    ref, pred = pair
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "keep.txt").write_text("mine")
    for quiet in (["-q"], []):           # without --window: the note would come first
        err = refused(capsys, [ref, pred, *quiet], busy)
        assert "keep.txt" in err and "give a new or empty folder" in err, err
    assert folder_bytes(busy) == {"keep.txt": b"mine"}
