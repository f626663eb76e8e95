"""A model names its fitting file as it was given at fit time, relative to that folder:
the intervals find it from another folder (beside the model file, or the file a verb was
given) and never take another file of that name."""

import json
import shutil

import pytest

from cfbmarkov import synthetic
from cfbmarkov.analysis.intervals import SourceChanged, model_intervals, resolve_source
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.markov import MarkovModel

FLOW = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)


@pytest.fixture(scope="session")
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


def test_the_files_name_beside_the_model_is_taken_only_with_its_identity(fitted, tmp_path,
                                                                        monkeypatch):
    """The model names synth/run.h5; in a folder holding the model and run.h5 side by side
    (no synth/ in it), that run.h5 is taken where it is the fitting file, and refused where
    it is another file of that name."""
    flat = tmp_path / "flat"
    flat.mkdir()
    shutil.copy(fitted / "model.h5", flat / "model.h5")
    shutil.copy(fitted / "synth" / "run.h5", flat / "run.h5")
    monkeypatch.chdir(flat)
    model = MarkovModel.load("model.h5")
    assert model.source == "synth/run.h5"
    assert resolve_source(model).source == str(flat / "run.h5")
    assert main(["rtd", "model.h5", "--resamples", "20"]) == 0
    synthetic.write_run(flat / "run.h5", FLOW, 200, 6.0, seed=9)
    with pytest.raises(SourceChanged, match=f"tried \\({flat / 'run.h5'}\\)"):
        resolve_source(MarkovModel.load("model.h5"))


def test_an_interval_asked_for_without_its_fitting_file_is_refused(fitted, tmp_path, capsys,
                                                                   monkeypatch):
    """rtd --resamples N asks for an interval: with the fitting file nowhere to be found it
    is exit 2 and one line (the stored figures are printed without --resamples). A model
    recording no identity whose file is missing is refused the same way."""
    from cfbmarkov.analysis.intervals import SourceMissing

    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(fitted / "model.h5", alone / "model.h5")
    monkeypatch.chdir(alone)
    capsys.readouterr()
    assert main(["rtd", "model.h5", "--resamples", "20"]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert captured.out == "" and len(err) == 1
    assert err[0].startswith("cfbmarkov rtd: error: synth/run.h5 (the model's fitting file")
    assert "put the file beside the model file" in err[0]
    assert main(["rtd", "model.h5"]) == 0           # the stored interval, no file needed
    assert "90 % interval" in capsys.readouterr().out
    unrecorded = MarkovModel.load("model.h5").with_source_identity(None)
    with pytest.raises(SourceMissing, match="records no identity"):
        resolve_source(unrecorded)
    with pytest.raises(SourceMissing, match="no such file from this folder"):
        model_intervals(unrecorded, resamples=20)


def test_compare_refuses_intervals_asked_for_without_the_fitting_file(fitted, tmp_path,
                                                                      capsys, monkeypatch):
    """compare against another run than the fitting file, the fitting file nowhere: with
    --resamples given, exit 2 in one line and no output; by default the comparison is
    written without intervals and a warning says why."""
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(fitted / "model.h5", alone / "model.h5")
    monkeypatch.chdir(alone)
    synthetic.write_run(alone / "other.h5", FLOW, 300, 6.0, seed=4)   # synth/run.h5 absent
    assert main(["predict", "model.h5", "--init", "other.h5", "--start", "1", "--duration",
                 "5", "-o", "pred.h5", "-q"]) == 0
    capsys.readouterr()
    argv = ["compare", "other.h5", "pred.h5", "--window", "1:6", "--no-figures", "-q"]
    assert main([*argv, "--resamples", "20", "-o", "c"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "synth/run.h5 (the model's fitting file" in err[0]
    assert not (alone / "c").exists()
    assert main([*argv, "-o", "c"]) == 0
    err = capsys.readouterr().err
    assert "warning: no intervals: synth/run.h5 (the model's fitting file" in err
    # the progress line does not announce the resamples that are not drawn
    assert main([*argv[:-1], "-o", "c2"]) == 0
    err = capsys.readouterr().err
    assert "compare: pred.h5 against other.h5" in err and "bootstrap resamples" not in err
    summary = json.loads((alone / "c" / "summary.json").read_text())
    assert summary["model"]["rt_mean_interval"] is None and summary["level"] is None
