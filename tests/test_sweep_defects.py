"""The fault and bad-input sweep's defects, each kind: a model's source identified by its
content, option values that cannot be honoured refused, sizes bounded before allocating,
case values validated, folder outputs published whole, output names checked with their
temporary and lock names. Each ends in one line on stderr and exit code 2, or in the
right output."""

import json
import os
import shutil

import pytest

from cfbmarkov import synthetic
from cfbmarkov.cli import main
from cfbmarkov.markov import MarkovModel

FLOW = synthetic.RiserFlow(columns=3, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    """A small run (60 particles x 3 s), a model fitted on it and a prediction from it."""
    folder = tmp_path_factory.mktemp("good")
    run = synthetic.write_run(folder / "run.h5", FLOW, 60, 3.0, seed=4)
    model = folder / "model.h5"
    here = os.getcwd()
    os.chdir(folder)                    # the model names its source by a relative path
    try:
        assert main(["fit", "run.h5", "--cells", "4x8", "--window", "0:2.5", "--resamples",
                     "0", "-o", "model.h5"]) == 0
    finally:
        os.chdir(here)
    pred = folder / "pred.h5"
    assert main(["predict", str(model), "--init", str(run), "--start", "0.5", "--duration",
                 "2", "-q", "-o", str(pred)]) == 0
    return run, model, pred


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


# -- a model's source identified by content ------------------------------------------------
def test_fit_records_the_content_identity_of_its_window(good):
    _, model, pred = good
    identity = MarkovModel.load(model).source_identity
    assert identity and identity.startswith("window-sha256-1:")


def test_compare_refuses_intervals_from_a_replaced_source(good, tmp_path, capsys, monkeypatch):
    run, model, pred = good
    monkeypatch.chdir(run.parent)
    out = tmp_path / "cmp"
    assert main(["compare", "run.h5", "pred.h5", "--window", "0.5:2.5", "--no-figures",
                 "--resamples", "10", "-o", str(out)]) == 0
    assert "rt_mean_interval" in json.loads((out / "summary.json").read_text())["model"]
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(pred, other / "pred.h5")                 # the prediction, beside another run
    synthetic.write_run(other / "run.h5", FLOW, 60, 3.0, seed=5)
    monkeypatch.chdir(other)
    err = one_line_error(capsys, ["compare", "run.h5", "pred.h5", "--window", "0.5:2.5",
                                  "--no-figures", "--resamples", "10", "-q", "-o", tmp_path / "c2"],
                         tmp_path / "c2")
    assert "not the data the model was fitted on" in err
