"""stationarity --sample-length says which figure misses, by how much, and the cure that
fits: a state space with memory where a figure stays off at every length, a longer run
where it still drifts with the length."""

import json

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.analysis.sample_length import SampleLength, _with_length, verdict_text
from cfbmarkov.cli import main


def _result(means, sds, long_mean=1.0, long_sd=1.0):
    lengths = np.array([0.5, 1.0, 2.0, 5.0, 10.0][:len(means)])
    return _with_length(SampleLength("run.h5", 5.0, 20.0, long_mean, long_sd, 1000, lengths,
                                     np.array(means, float), np.array(sds, float), 0.1,
                                     np.nan, "cells"))


def test_each_window_names_the_figure_it_misses():
    r = _result([1.0, 1.2, 1.0, 1.3], [1.0, 1.0, 0.5, 0.5])
    assert r.missed() == ["", "E(RT)", "SD(RT)", "both"]
    data = r.to_dict()
    assert [w["missed"] for w in data["windows"]] == [None, "E(RT)", "SD(RT)", "both"]
    assert data["windows"][2]["pd_rt_sd"] == pytest.approx(-50.0)


def test_a_figure_off_at_every_length_calls_for_memory_not_a_longer_run():
    r = _result([1.05, 1.02, 0.98, 1.01, 1.0], [0.44, 0.45, 0.43, 0.44, 0.44])
    assert set(r.steady_misses()) == {"SD(RT)"}
    line = verdict_text(r, "cells")
    assert "E(RT) settles (within 10 % from 0.5 s)" in line
    assert "SD(RT) stays -56 % off at every length" in line
    assert "state space with memory" in line and "--states auto" in line
    assert "longer run, or pool" not in line


def test_a_reducible_chain_off_at_every_length_calls_for_coarser_cells_not_memory():
    """A chain of several closed classes (particles in some cells never reaching others)
    whose E(RT) stays off at every length: neither a longer run nor memory joins the
    classes; the verdict names them and coarser cells, and --json carries their count."""
    from dataclasses import replace

    r = replace(_result([0.55, 0.54, 0.55, 0.54, 0.55], [1.0, 1.0, 1.0, 1.0, 1.0]),
                closed_classes=6)
    line = verdict_text(r, "cells")
    assert "neither a longer run nor memory cures that" in line
    assert "6 closed classes" in line and "coarser --cells" in line
    assert "--states auto" not in line
    assert r.to_dict()["closed_classes"] == 6
    assert "state space with memory" in verdict_text(replace(r, closed_classes=1), "cells")


def test_a_drifting_figure_calls_for_a_longer_run():
    r = _result([1.6, 1.4, 1.3, 1.2, 1.15], [1.0, 1.0, 1.0, 1.0, 1.0])
    assert r.steady_misses() == {}
    line = verdict_text(r, "cells")
    assert "the longest window's E(RT) +15 % off" in line
    assert "a longer run, or pool runs" in line
    assert line.endswith("; if it stays off as the windows grow, a state space with memory "
                         "(fit --states auto chooses one, e.g. --states cells-direction, "
                         "cells-previous or, for a flow that alternates between regimes, "
                         "cells-regime; try it here with --states)")
    both = verdict_text(_result([1.6, 1.4, 1.3, 1.2, 1.15],
                                          [0.44, 0.45, 0.43, 0.44, 0.44]), "cells")
    assert "for E(RT) a longer run" in both and "for SD(RT) a state space with memory" in both


def test_a_miss_under_one_percent_is_printed_with_its_digits():
    """With a tolerance under 1 %, a figure 0.06 % off is said to be so, not "+0 % off"."""
    from dataclasses import replace

    r = _result([1.2, 1.1, 1.05, 1.01, 1.0006], [1.0, 1.0, 1.0, 1.0, 1.0])
    line = verdict_text(_with_length(replace(r, tolerance=1e-4)), "cells")
    assert "the longest window's E(RT) +0.06 % off" in line, line


def test_cli_on_a_flow_with_hidden_direction(tmp_path, capsys):
    run = tmp_path / "run.h5"
    synthetic.write_run(run, synthetic.RiserFlow(), 300, 12.0, seed=1)
    assert main(["stationarity", str(run), "--sample-length", "--start", "1"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.strip().startswith(("2 ", "10 "))]
    assert rows and all("no: SD(RT) -" in line for line in rows), out
    short = next(line for line in out.splitlines() if line.strip().startswith("0.5 "))
    # with the figures it misses by: such a window may lie far off
    pd_mean = float(short.split("(fit warns; E(RT) ")[1].split(" %")[0])
    assert "of its model's residences outlast the window (fit warns; E(RT) " in short
    assert ", SD(RT) " in short and abs(pd_mean) < 1000
    assert "docs/definitions.md, Sample length" in out
    last = out.strip().splitlines()[-1]
    assert "SD(RT) stays" in last and "state space with memory" in last, last
    assert main(["stationarity", str(run), "--sample-length", "--start", "1", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert "SD(RT)" in data["steady_misses"]


def test_a_run_too_short_names_the_fix_that_exists(tmp_path, capsys):
    """A run shorter than the shortest window from its first frame needs a longer run (no
    earlier start exists); from a later start, an earlier one; a start outside the frames
    that several runs all hold names them as such."""
    short = synthetic.write_run(tmp_path / "short.h5", synthetic.RiserFlow(), 100, 0.4, seed=1)
    other = synthetic.write_run(tmp_path / "other.h5", synthetic.RiserFlow(), 100, 0.8, seed=2)
    assert main(["stationarity", str(short), "--sample-length"]) == 2
    err = capsys.readouterr().err
    assert ("no window of 0.5 s or more is shorter than that span, the long run each window "
            "is judged against; a run longer than 0.5 s") in err
    assert main(["stationarity", str(other), "--sample-length", "--start", "0.4"]) == 2
    assert "judged against; an earlier --start" in capsys.readouterr().err
    assert main(["stationarity", str(short), str(other), "--sample-length", "--start",
                 "0.6"]) == 2
    assert (f"start 0.6 s lies outside the frames all of {short}, {other} hold (0 to 0.4 s)"
            in capsys.readouterr().err)


def test_a_length_only_the_longest_window_meets_is_not_confirmed():
    r = _result([1.6, 1.4, 1.3, 1.2, 1.05], [1.0, 1.0, 1.0, 1.0, 1.0])
    assert r.sample_length == 10.0
    line = verdict_text(r, "cells")
    assert line.startswith("10 s at most") and "no longer window confirms it" in line
    assert r.at_most and r.to_dict()["sample_length_at_most"] is True
    confirmed = _result([1.6, 1.4, 1.3, 1.05, 1.0], [1.0] * 5)
    assert verdict_text(confirmed, "cells").startswith("5 s (from it on")
    assert not confirmed.at_most and confirmed.to_dict()["sample_length_at_most"] is False


def test_no_window_spans_the_whole_long_run(tmp_path, capsys):
    """From 10 s on a run ending at 20 s the long run is 10 s long: the 10 s window would
    be that long run judged against itself, so the windows stop at 5 s; a run from 18 s
    (a 2 s long run) has windows of 0.5 and 1 s only."""
    run = tmp_path / "run.h5"
    synthetic.write_run(run, synthetic.RiserFlow(), 300, 20.0, seed=1)
    assert main(["stationarity", str(run), "--sample-length", "--start", "10", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["span_end"] == pytest.approx(20.0)
    assert [w["length"] for w in data["windows"]] == [0.5, 1.0, 2.0, 5.0]
    assert main(["stationarity", str(run), "--sample-length", "--start", "18", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [w["length"] for w in data["windows"]] == [0.5, 1.0]
    assert data["sample_length"] != 2.0


def test_a_figure_within_only_at_the_longest_window_is_said_so():
    r = _result([1.6, 1.4, 1.3, 1.2, 1.05], [0.44, 0.45, 0.43, 0.44, 0.44])
    line = verdict_text(r, "cells")
    assert "E(RT) lies within 10 % at the longest window (10 s) only" in line
    assert "settles" not in line


def test_a_window_whose_fit_failed_says_why(tmp_path, capsys, monkeypatch):
    """A window whose model fails prints 'no model'; the fit's own refusal is said once
    under the table (and in --json's fit_failure), where it only said that the fit failed."""
    from cfbmarkov.analysis import sample_length as module
    from cfbmarkov.errors import CfbmarkovError

    run = synthetic.write_run(tmp_path / "r.h5", synthetic.RiserFlow(), 100, 8.0, seed=1)

    class Refusing:
        def fit(self, windows):
            raise CfbmarkovError("no pass in the window: a lag of at most 0.01 s (--lag)")

    monkeypatch.setattr(module, "estimator_from_name", lambda *a, **k: Refusing())
    assert main(["stationarity", str(run), "--sample-length", "--start", "1"]) == 0
    out = capsys.readouterr().out
    assert "no: no model (the window's fit failed)" in out
    assert out.count("(no model: no pass in the window: a lag of at most 0.01 s (--lag))") == 1
    # the verdict sends to that refusal, not to a longer run (which cures no failing fit)
    verdict = out.split("sample length: ")[1]
    assert verdict.startswith("not judged: the longest window") and "its fit was refused" in verdict
    assert "a longer run, or pool runs" not in verdict
    assert main(["stationarity", str(run), "--sample-length", "--start", "1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["fit_failure"].startswith("no pass in the window")
    assert summary["verdict"].startswith("not judged: the longest window")
