"""``compare``'s refusals: one line, before any output, naming its own options; a
prediction given as the reference of a run is refused as the two swapped."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
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


def prediction(path, run):
    return write_trajectories(path, run.times, run.positions, width=WIDTH, height=HEIGHT,
                              source="markov-prediction", parameters={"columns": 6, "rows": 38})


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
