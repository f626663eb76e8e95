"""The accuracy-goal script (benchmarks/kinetics_goals.py) on a tiny generated run, and the
chain's windowed exit mean it judges."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.kinetics import Constant, FirstOrder, Kinetics, Property
from cfbmarkov.markov import CellGrid, fit_model
from cfbmarkov.markov.kinetics_exact import exact_kinetics, windowed_exit_means
from cfbmarkov.synthetic import RiserFlow, write_run

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "kinetics_goals.py"


def _script():
    spec = importlib.util.spec_from_file_location("kinetics_goals", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("goals")
    return write_run(folder / "run.h5", RiserFlow(columns=4, rows=10, persistence=False), 200,
                     4.0, seed=1)


def test_windowed_exit_mean_is_the_rtd_weighted_by_the_window(run):
    model = fit_model(run, CellGrid(4, 10, 0.09, 0.95), 0.025, (0.0, 4.0), "paper")
    k = 1.3
    kin = Kinetics((Property("X", FirstOrder(), {"rate": Constant(k)}),))
    for length in (1.0, 2.0):
        # the RTD as the window sees it (records counted from its first frame), averaged
        seen = model.rtd(window=length)
        n = np.arange(1, seen.probability.size + 1)
        by_hand = np.sum(seen.probability * (1 - np.exp(-k * n * model.lag)))
        assert windowed_exit_means(model, kin, length)["X"] == pytest.approx(by_hand,
                                                                             rel=1e-10)
    # a long window sees the chain's own exits
    assert windowed_exit_means(model, kin, 200.0)["X"] == pytest.approx(
        exact_kinetics(model, kin)["X"].exit_mean, rel=2e-3)


def test_windowed_exit_mean_with_a_history_counts_what_the_reference_counts(run):
    model = fit_model(run, CellGrid(4, 10, 0.09, 0.95), 0.025, (0.0, 4.0), "paper")
    k = 1.3
    kin = Kinetics((Property("X", FirstOrder(), {"rate": Constant(k)}),))
    exact = exact_kinetics(model, kin)["X"].exit_mean
    for length, history in ((1.0, 0.5), (1.0, 1.0), (0.5, 2.0)):
        got = windowed_exit_means(model, kin, length, history=history)["X"]
        # longer residences count more than without the history: a higher conversion,
        # towards the chain's own exit mean (a walk's check: test_exact.py)
        assert windowed_exit_means(model, kin, length)["X"] < got < exact
    with pytest.raises(Exception, match="history"):
        windowed_exit_means(model, kin, 1.0, history=-1.0)


def test_goals_on_a_tiny_run(run, tmp_path, capsys):
    goals = _script()
    # residences wholly inside the windows, the chain as such a window sees it
    result = goals.run_goals([run], in_sample=[(0.5, 2.5)],
                             out_of_sample=[((0.5, 2.5), (2.0, 4.0))], damkoehler=(0.3, 1.0),
                             cells=(4, 10), lag=0.025, history=0.0)
    assert len(result["in_sample"]) == 4 and len(result["out_of_sample"]) == 4
    for row in result["in_sample"]:
        tau = row["tau"]
        if row["kind"] == "uniform":
            # Da = k tau_bar; in sample the baseline is the reference's own RTD, exactly
            assert row["rate_core"] == pytest.approx(row["damkoehler"] / tau, rel=1e-12)
            assert row["segregated_flow_error"] == pytest.approx(0.0, abs=1e-9)
        else:
            assert row["rate_wall"] == pytest.approx(0.1 * row["rate_core"], rel=1e-12)
            assert row["rate_core"] > row["damkoehler"] / tau > row["rate_wall"]
        # the chain (a Markov flow on these cells) sees what the paths see
        assert abs(row["chain_error"]) < 5.0
        assert 0 < row["reference"] < 1 and row["exits"] > 50
    # both kinds at one Da: the same baseline, different references
    uni, zones = (next(r for r in result["in_sample"] if r["kind"] == kind
                       and r["damkoehler"] == 1.0) for kind in ("uniform", "zones"))
    assert uni["segregated_flow"] == pytest.approx(zones["segregated_flow"], rel=1e-12)
    assert uni["reference"] != zones["reference"]
    # by default every exit in the judged window, followed back a window's length: more
    # exits, judged against the chain's exact exit mean per residence
    back = goals.run_goals([run], in_sample=[], out_of_sample=[((0.5, 2.5), (2.0, 4.0))],
                           damkoehler=(0.3, 1.0), cells=(4, 10), lag=0.025)
    inside = {(r["kind"], r["damkoehler"]): r for r in result["out_of_sample"]}
    for row in back["out_of_sample"]:
        assert row["exits"] > inside[row["kind"], row["damkoehler"]]["exits"]
        assert row["chain"] == pytest.approx(row["chain_windowed"], rel=1e-12)
        assert inside[row["kind"], row["damkoehler"]]["chain"] < row["chain"]
        assert row["chain"] < row["chain_unwindowed"]
        assert row["chain_exact_error"] == pytest.approx(
            100 * (row["chain_unwindowed"] / row["reference"] - 1), rel=1e-9)
        assert 0 <= row["exits_censored"] < 0.05 * row["exits"]
        # the generated flow is this chain: the difference is the reference's noise
        assert abs(row["chain"] - row["reference"]) < 3 * row["reference_se"]
    counts = result["counts"]
    assert counts["in_sample_within"]["zones"]["rows"] == 2
    assert counts["out_of_sample_no_worse"]["zones"]["1"]["cases"] == 1
    # the command line: tables and JSON
    out = tmp_path / "goals.json"
    assert goals.main([str(run), "--cells", "4x10", "--lag", "0.025", "--in-sample", "0.5:2.5",
                       "--out-of-sample", "0.5:2.5,2:4", "--damkoehler", "1",
                       "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "In sample" in text and "Out of sample" in text and "zones" in text
    data = json.loads(out.read_text())
    assert len(data["in_sample"]) == 2 and data["settings"]["damkoehler"] == [1.0]


def test_goals_skip_a_window_outside_the_run(run, capsys):
    goals = _script()
    assert goals.main([str(run), "--cells", "4x10", "--lag", "0.025", "--in-sample",
                       "10:15", "--out-of-sample", "10:15,15:20"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: no window could be judged") and err.count("\n") == 1
    # one window outside, one inside: the one judged, the other listed as skipped
    assert goals.main([str(run), "--cells", "4x10", "--lag", "0.025", "--in-sample", "0.5:2.5",
                       "--in-sample", "10:15", "--out-of-sample", "0.5:2.5,2:4",
                       "--damkoehler", "1"]) == 0
    out = capsys.readouterr().out
    assert "skipped: run, fit 10-15 s, judged 10-15 s:" in out
