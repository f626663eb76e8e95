"""A model names its fitting file as it was given at fit time, relative to that folder:
the intervals find it from another folder (beside the model file, or the file a verb was
given) and never take another file of that name."""

import shutil

import pytest

from cfbmarkov import synthetic
from cfbmarkov.analysis.intervals import SourceChanged, model_intervals, resolve_source
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.markov import MarkovModel

FLOW = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A model fitted in ``fit/`` on ``synth/run.h5`` (a relative path), saved there."""
    import os

    home = tmp_path_factory.mktemp("fit")
    (home / "synth").mkdir()
    synthetic.write_run(home / "synth" / "run.h5", FLOW, 300, 6.0, seed=2)
    cwd = os.getcwd()
    os.chdir(home)
    try:
        assert main(["fit", "synth/run.h5", "--cells", "4x16", "--window", "1:5",
                     "--resamples", "20", "-q", "-o", "model.h5"]) == 0
    finally:
        os.chdir(cwd)
    return home


def test_from_another_folder_the_fitting_file_is_found_beside_the_model(fitted, tmp_path,
                                                                        monkeypatch):
    monkeypatch.chdir(tmp_path)
    model = MarkovModel.load(fitted / "model.h5")
    assert model.source == "synth/run.h5"
    found = resolve_source(model)
    assert found.source == str(fitted / "synth" / "run.h5")
    here = model_intervals(model, resamples=20)
    monkeypatch.chdir(fitted)
    there = model_intervals(MarkovModel.load("model.h5"), resamples=20)
    assert here.rt_mean_interval == there.rt_mean_interval


def test_another_file_of_that_name_is_never_taken(fitted, tmp_path, monkeypatch):
    """A folder with its own synth/run.h5 (other data): the one beside the model is taken;
    with none beside the model, refused in one line naming the files tried."""
    (tmp_path / "synth").mkdir()
    synthetic.write_run(tmp_path / "synth" / "run.h5", FLOW, 200, 6.0, seed=9)
    monkeypatch.chdir(tmp_path)
    model = MarkovModel.load(fitted / "model.h5")
    assert resolve_source(model).source == str(fitted / "synth" / "run.h5")
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    shutil.copy(fitted / "model.h5", moved / "model.h5")
    alone = MarkovModel.load(moved / "model.h5")
    with pytest.raises(SourceChanged, match="are not the data the model was fitted on"):
        resolve_source(alone)
    assert main(["rtd", str(moved / "model.h5"), "--resamples", "20"]) == 2
    # the right file given as a candidate (compare's reference) is taken
    assert resolve_source(alone, [fitted / "synth" / "run.h5"]).source == str(
        fitted / "synth" / "run.h5")
    shutil.rmtree(tmp_path / "synth")
    with pytest.raises(InputError, match="no file of that name was found"):
        resolve_source(alone)
