"""compare --kinetics: the reference along its paths, the chain and the segregated-flow
baseline; the segregated-flow model by hand."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from cfbmarkov.analysis.segregated_flow import bed_averaged, segregated_flow
from cfbmarkov.errors import InputError
from cfbmarkov.synthetic import RiserFlow, write_run

# a chain on cells whose wall columns fall slowly: particles that stay long stay at the walls
FLOW = RiserFlow(columns=6, rows=10, lag=0.02, persistence=False, rise_velocity=2.0,
                 fall_velocity=-2.0)


def test_bed_averaged_law_by_hand():
    k, v = bed_averaged([1.0, 3.0], [0.0, 1.0], [3, 1])
    assert k == pytest.approx(0.75 * 1 + 0.25 * 3)
    assert v == pytest.approx(0.25 * 3 * 1.0 / 1.5)
    assert bed_averaged([0.0, 0.0], [2.0, 4.0], [1, 1]) == (0.0, 3.0)
    with pytest.raises(InputError):
        bed_averaged([1.0], [1.0], [0.0])


def test_segregated_flow_by_hand():
    tau = np.array([0.5, 1.0, 2.0])
    seg = segregated_flow(tau, np.full(2, 2.0), np.ones(2), [1, 1], 0.0, name="X")
    np.testing.assert_allclose(seg.exit_values, 1 - np.exp(-2 * tau), rtol=1e-14)
    assert seg.exit_mean == pytest.approx(np.mean(1 - np.exp(-2 * tau)), rel=1e-14)
    # mean over the bed's age distribution: sum_i int_0^tau_i (1 - e^-2a) da / sum_i tau_i
    integral = tau - (1 - np.exp(-2 * tau)) / 2
    assert seg.bed_mean == pytest.approx(integral.sum() / tau.sum(), rel=1e-14)
    # sampled at the frames, as the chain's exact bed mean and the reference's are: each
    # lag's start, the entry frame holding v0 (the continuous form lay k lag / 2 above)
    frames = segregated_flow(tau, np.full(2, 2.0), np.ones(2), [1, 1], 0.0, name="X",
                             lag=0.1)
    by_hand = [1 - np.exp(-2 * j * 0.1) for t in tau for j in range(round(t / 0.1))]
    assert frames.bed_mean == pytest.approx(np.mean(by_hand), rel=1e-13)
    assert frames.bed_mean < seg.bed_mean
    np.testing.assert_array_equal(frames.exit_values, seg.exit_values)


def _kinetics(tmp_path, name, rate_lines):
    path = tmp_path / f"{name}.toml"
    path.write_text(f'[[property]]\nname = "X"\nlaw = "first-order"\n{rate_lines}\n')
    return path


@pytest.fixture(scope="session")
def prediction(tmp_path_factory):
    from cfbmarkov.markov import CellGrid, fit_model

    tmp = tmp_path_factory.mktemp("kin")
    run = write_run(tmp / "run.h5", FLOW, 400, 12.0, seed=2)
    model = fit_model(run, CellGrid(FLOW.columns, FLOW.rows), FLOW.lag, (0.0, 6.0), "mle")
    pred = model.predict(run, start=6.0, duration=6.0, seed=4, output=tmp / "pred.h5")
    return run, pred, tmp


def _compare(run, pred, kinetics, out):
    from cfbmarkov.report.compare import compare

    return compare(run, pred, window=(6.0, 12.0), output=out, figures=False, resamples=0,
                   kinetics=kinetics)["kinetics"]["X"]


def test_zone_dependent_rate_the_chain_beats_the_segregated_flow(prediction, tmp_path):
    run, pred, _ = prediction
    # tenfold faster in the wall columns (within one column of the walls)
    kin = _kinetics(tmp_path, "zones", 'rate_from = "wall_distance"\nrate_dense = 4.0\n'
                    'rate_dilute = 0.4\nthreshold = 0.01')
    got = _compare(run, pred, kin, tmp_path / "zones")
    ref, mod, seg = got["reference"], got["model"], got["segregated_flow"]
    assert ref["exit_count"] > 300 and mod["values_from"] == "paths"
    chain_error = abs(mod["exit_mean"] - ref["exit_mean"])
    seg_error = abs(seg["exit_mean"] - ref["exit_mean"])
    assert seg_error > 2 * chain_error
    assert seg_error > 3 * math.hypot(ref["exit_mean_interval"][1] - ref["exit_mean"],
                                      seg["exit_mean_interval"][1] - seg["exit_mean"]) / 1.645
    assert len(ref["bed_mean_by_cell"]) == FLOW.columns * FLOW.rows
    assert np.isfinite(mod["md_exit"]) and np.isfinite(seg["md_exit"])


def test_uniform_rate_the_chain_and_the_segregated_flow_agree(prediction, tmp_path):
    run, pred, _ = prediction
    got = _compare(run, pred, _kinetics(tmp_path, "uniform", "rate = 1.0"), tmp_path / "u")
    ref, mod, seg = got["reference"], got["model"], got["segregated_flow"]
    for side in (mod, seg):
        half = side["exit_mean_interval"][1] - side["exit_mean"]
        ref_half = ref["exit_mean_interval"][1] - ref["exit_mean"]
        assert abs(side["exit_mean"] - ref["exit_mean"]) < 3 * math.hypot(half, ref_half) / 1.645
    assert seg["rate"] == pytest.approx(1.0)


def test_a_segregated_flow_of_another_window_length_is_warned_of(prediction, tmp_path):
    """The baseline's residences come from the 6 s fitting window: compared on 3 s, a
    warning says it is not like for like (as for the persistence baseline); on 6 s none."""
    from cfbmarkov.report.compare import compare

    run, pred, _ = prediction
    kin = _kinetics(tmp_path, "uniform", "rate = 1.0")
    short = compare(run, pred, window=(6.0, 9.0), output=tmp_path / "s", figures=False,
                    resamples=0, kinetics=kin)["warnings"]
    assert any("segregated-flow baseline's residences are those of the 6 s fitting window"
               in w and "compared window is 3 s long" in w for w in short), short
    same = compare(run, pred, window=(6.0, 12.0), output=tmp_path / "t", figures=False,
                   resamples=0, kinetics=kin)["warnings"]
    # a lag shorter (as a model with memory's comparison starts a lag late): like for like
    lag_short = compare(run, pred, window=(6.02, 12.0), output=tmp_path / "u", figures=False,
                        resamples=0, kinetics=kin)["warnings"]
    assert not any("segregated-flow baseline's residences" in w for w in lag_short), lag_short
    assert not any("segregated-flow baseline's residences" in w for w in same), same


def test_cli_compare_kinetics_prints_and_writes_the_block(prediction, tmp_path, capsys):
    from cfbmarkov.cli import main

    run, pred, _ = prediction
    kin = _kinetics(tmp_path, "uniform", "rate = 1.0")
    code = main(["compare", str(run), str(pred), "--window", "6:12", "-o", str(tmp_path / "c"),
                 "--resamples", "0", "--kinetics", str(kin), "-q"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "X at the exit: reference" in printed and "segregated flow" in printed
    summary = json.loads((tmp_path / "c" / "summary.json").read_text())
    block = summary["kinetics"]["X"]
    # the bed's line tells the window means from the segregated flow's steady state
    bed = next(line for line in printed.splitlines() if "X in the bed" in line)
    assert bed == (f"  X in the bed: mean over the window, reference "
                   f"{block['reference']['bed_mean']:.4g}, model {block['model']['bed_mean']:.4g}; "
                   f"segregated flow {block['segregated_flow']['bed_mean']:.4g} (its steady "
                   "state over the age distribution, where the window's means carry its start "
                   "from the first frame's values)")
    assert set(block) >= {"reference", "model", "segregated_flow"}
    assert block["reference"]["exit_mean"] > 0
    assert "kinetics-X.png" in summary["figures"]
    assert (tmp_path / "c" / "kinetics-X.png").stat().st_size > 1000


def test_cli_compare_bad_kinetics_file_is_one_line(prediction, tmp_path, capsys):
    from cfbmarkov.cli import main

    run, pred, _ = prediction
    bad = tmp_path / "bad.toml"
    bad.write_text('[[property]]\nname = "X"\nlaw = "zeroth-order"\nrate = 1.0\n')
    code = main(["compare", str(run), str(pred), "--window", "6:12", "-o", str(tmp_path / "b"),
                 "--kinetics", str(bad), "-q"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown law" in err[0]
    assert not (tmp_path / "b" / "summary.json").exists()


def test_kinetics_resamples_fall_with_the_square_of_the_states():
    from cfbmarkov.analysis.kinetics_compare import kinetics_resamples

    assert kinetics_resamples(228, 100) == 100 and kinetics_resamples(500, 100) == 100
    assert kinetics_resamples(1000, 100) == 25          # (500 / 1000)^2 of them
    assert kinetics_resamples(1824, 100) == 20          # never fewer than 20
    assert kinetics_resamples(1824, 10) == 10 and kinetics_resamples(1824, 0) == 0


def test_the_kinetics_interval_says_how_many_resamples_it_took(prediction, tmp_path,
                                                               monkeypatch):
    """All the resamples asked for on a small space; fewer, said in a warning and in the
    summary, where the rule takes fewer (here forced by a lowered state threshold)."""
    from cfbmarkov.analysis import kinetics_compare
    from cfbmarkov.report.compare import compare

    run, pred, _ = prediction
    kin = _kinetics(tmp_path, "u", "rate = 1.0")
    got = compare(run, pred, window=(6.0, 12.0), output=tmp_path / "a", figures=False,
                  resamples=10, kinetics=kin)
    block = got["kinetics"]["X"]["model"]
    assert block["interval_resamples"] == 10 and len(block["exit_mean_interval"]) == 2
    monkeypatch.setattr(kinetics_compare, "KINETICS_FULL_STATES", 1)
    monkeypatch.setattr(kinetics_compare, "KINETICS_MIN_RESAMPLES", 4)
    got = compare(run, pred, window=(6.0, 12.0), output=tmp_path / "b", figures=False,
                  resamples=10, kinetics=kin)
    assert got["kinetics"]["X"]["model"]["interval_resamples"] == 4
    assert any("interval from 4 of 10 bootstrap resamples" in w
               for w in got.get("warnings", [])), got.get("warnings")


def test_the_segregated_flow_comes_from_the_fitting_file_not_one_of_its_name(tmp_path,
                                                                            monkeypatch):
    """A model fitted on run.h5 in one folder, compared from another folder that holds a
    different run.h5: the segregated-flow baseline and the model's interval of the exit
    mean are formed from the fitting window found by its identity (beside the prediction),
    as at home: not from the file of that name, nor (the fitting file not found) from
    Monte Carlo noise alone."""
    from cfbmarkov.cli import main

    home, elsewhere = tmp_path / "a", tmp_path / "b"
    home.mkdir()
    elsewhere.mkdir()
    flow = RiserFlow(columns=6, rows=10, lag=0.02, persistence=False)
    write_run(home / "run.h5", flow, 200, 4.0, seed=2)
    write_run(elsewhere / "run.h5", flow, 200, 4.0, seed=9)
    monkeypatch.chdir(home)
    assert main(["fit", "run.h5", "--cells", "6x10", "--lag", "0.02", "--window", "0:2",
                 "--estimator", "mle", "--resamples", "0", "-o", "model.h5"]) == 0
    assert main(["predict", "model.h5", "--init", "run.h5", "--start", "2", "--duration", "2",
                 "-q", "-o", "pred.h5"]) == 0
    kinetics = _kinetics(tmp_path, "uniform", "rate = 1.0")

    def baseline():
        from cfbmarkov.report.compare import compare

        got = compare(home / "run.h5", home / "pred.h5", window=(2.0, 4.0),
                      output=tmp_path / "out", figures=False, resamples=10,
                      kinetics=kinetics)
        assert not any("no model intervals" in w for w in got.get("warnings", [])), got
        block = got["kinetics"]["X"]
        assert block["model"]["interval_resamples"] == 10
        return block["segregated_flow"]["exit_mean"], block["model"]["exit_mean_interval"]

    at_home = baseline()
    monkeypatch.chdir(elsewhere)
    assert baseline() == at_home



def test_an_interval_not_formed_says_why_and_the_verdict_line_repeats_it(prediction, tmp_path):
    """A carried activity that never relaxes has no exact answers, nor then has the other
    property of the file: with resamples asked for, neither model block has the bootstrap's
    interval, each says why (not "`--resamples 100` forms it", which they were given), and
    the verdict line repeats the reason."""
    from cfbmarkov.cli.analysis import kinetics_verdict
    from cfbmarkov.report.compare import compare

    run, pred, _ = prediction
    kin = tmp_path / "two.toml"
    kin.write_text('[[property]]\nname = "A"\nlaw = "deactivation"\nrate = 0.0\n'
                   'start = "carried"\n\n[[property]]\nname = "X"\nlaw = "first-order"\n'
                   'rate = 1.0\n')
    got = compare(run, pred, window=(6.0, 12.0), output=tmp_path / "c", figures=False,
                  resamples=10, kinetics=kin)
    assert any("kinetics: no exact answers" in w and "use start = entry" in w
               for w in got["warnings"]), got["warnings"]
    carried, entry = got["kinetics"]["A"]["model"], got["kinetics"]["X"]["model"]
    assert "exact" not in carried and "exact" not in entry
    assert carried["interval_not_formed"] == "not formed for a carried property"
    assert entry["interval_not_formed"] == ("not formed without the chain's exact answers, "
                                            "which the bootstrap spreads")
    reference = got["kinetics"]["X"]["reference"]["exit_mean"]
    line = kinetics_verdict("X", reference, entry, 0.9)
    assert line.endswith("is not in this interval (not formed without the chain's exact "
                         "answers, which the bootstrap spreads), so no verdict is drawn from "
                         "it"), line
    # with the exact answers and resamples: the bootstrap's interval, no reason
    kin.write_text('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\n')
    got = compare(run, pred, window=(6.0, 12.0), output=tmp_path / "d", figures=False,
                  resamples=10, kinetics=kin)
    assert "interval_not_formed" not in got["kinetics"]["X"]["model"]
    assert got["kinetics"]["X"]["model"]["interval_method"].startswith("block bootstrap")


def test_a_rate_table_off_the_models_grid_is_one_line_before_the_progress_line(
        prediction, tmp_path, capsys):
    """Without -q, compare prints a progress line once its inputs are checked: a rate table
    that misses cells of the model's grid is refused before it, in one line."""
    from cfbmarkov.cli import main

    run, pred, _ = prediction
    (tmp_path / "few.csv").write_text("col,row,rate\n0,0,1.0\n")
    kin = _kinetics(tmp_path, "few", 'rate_by_cell = "few.csv"')
    code = main(["compare", str(run), str(pred), "--window", "6:12", "-o", str(tmp_path / "c"),
                 "--kinetics", str(kin)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "the table misses 59 cell(s) of the grid 6x10" in err
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("options, message", [
    ({"level": 2.0}, "interval level 2.0 must be a number strictly between 0 and 1"),
    ({"level": float("nan"), "resamples": 0}, "interval level nan must be a number"),
    ({"resamples": -1}, "resamples -1: a whole number, 0 (no intervals) or at least 10"),
    ({"resamples": 5}, "intervals need at least 2 blocks and 10 resamples"),
    ({"resamples": 10.5}, "resamples 10.5: a whole number")])
def test_compare_in_python_refuses_interval_options_as_the_command_line(prediction, tmp_path,
                                                                       options, message):
    """A level of 2 or 5 resamples dropped the intervals with one line among the summary's
    warnings; refused as `compare --level 2` is, before anything is written."""
    from cfbmarkov.report.compare import compare

    run, pred, _ = prediction
    with pytest.raises(InputError, match=re.escape(message)):
        compare(run, pred, window=(6.0, 12.0), output=tmp_path / "c", figures=False,
                **options)
    assert not (tmp_path / "c").exists()


def test_the_models_exit_interval_carries_the_flow_term_its_rtd_interval_carries(tmp_path):
    """Where the comparison's RTD interval carries the flow's variability between windows,
    the model's exit-mean interval carries it too, as a stretch of every residence (its
    relative SD of E(RT) times |d(exit mean)/d(ln s)|, on the same degrees of freedom), and
    the interval method and the console verdict say so."""
    from cfbmarkov.analysis.kinetics_compare import stretch_sensitivity
    from cfbmarkov.cli.analysis import kinetics_verdict
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.markov import CellGrid, fit_model
    from cfbmarkov.report.compare import compare

    # E(RT) near 0.5 s: a 4 s fitting window holds two blocks of three of them
    fast = RiserFlow(columns=4, rows=8, lag=0.02, persistence=False, rise_velocity=4.0,
                     fall_velocity=-1.0)
    run = write_run(tmp_path / "run.h5", fast, 150, 8.0, seed=2)
    model = fit_model(run, CellGrid(fast.columns, fast.rows), fast.lag, (0.0, 4.0), "mle")
    pred = model.predict(run, start=4.0, duration=4.0, seed=4, output=tmp_path / "pred.h5")
    kin = _kinetics(tmp_path, "u", "rate = 1.0")
    got = compare(run, pred, window=(4.0, 8.0), output=tmp_path / "a", figures=False,
                  resamples=10, kinetics=kin)
    flow = got["intervals"]["flow_sd"]
    assert flow is not None, "the set-up's RTD interval carries a flow term"
    block = got["kinetics"]["X"]["model"]
    relative = flow["rt_mean"] / got["model"]["rt_mean"]
    slope = stretch_sensitivity(model, load_kinetics(kin).per_state(model.state_space),
                                model.flow_direction)["X"]
    assert block["flow_sd"]["rt_mean_relative"] == pytest.approx(relative, rel=1e-9)
    assert block["flow_sd"]["exit_mean"] == pytest.approx(abs(slope) * relative, rel=1e-9)
    assert block["flow_sd"]["degrees_of_freedom"] == flow["degrees_of_freedom"]
    assert "the flow's variability between windows" in block["interval_method"]
    verdict = kinetics_verdict("X", got["kinetics"]["X"]["reference"]["exit_mean"], block,
                               got["level"])
    assert "with the flow's variability between windows" in verdict
    assert "left out" not in verdict
