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
from cfbmarkov.errors import InputError
from cfbmarkov.markov import MarkovModel

FLOW = synthetic.RiserFlow(columns=3, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)


@pytest.fixture(scope="session")
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
    assert identity and identity.startswith("window-sha256-2:")


def test_the_identity_sees_a_value_changed_in_any_frame_and_reads_the_earlier_rule(good,
                                                                                  tmp_path):
    """One coordinate changed in a frame between the window's first, middle and last (which
    the earlier rule alone read) changes the identity; an identity recorded by the earlier
    rule is still compared by it."""
    import h5py

    from cfbmarkov.trajectories import Trajectories
    from cfbmarkov.trajectory_identity import same_window, window_identity

    run, model, _ = good
    copy = tmp_path / "copy.h5"
    shutil.copy(run, copy)
    window = MarkovModel.load(model).window
    with Trajectories(copy) as t:
        frames = t.window(*window)
        v1, v2 = window_identity(t, window, 1), window_identity(t, window)
        assert same_window(t, window, v1) and same_window(t, window, v2)
    k = frames.start + (frames.stop - frames.start) // 4          # none of the three
    with h5py.File(copy, "r+") as f:
        f["frames/position"][k, 3, 0] += 1e-9
    with Trajectories(copy) as t:
        assert window_identity(t, window, 1) == v1                # the earlier rule misses it
        assert not same_window(t, window, v2) and same_window(t, window, v1)


def test_the_identity_does_not_depend_on_the_blocks_read(good, monkeypatch):
    """The folds of every frame are digested whole, stream by stream: reading the window in
    blocks of another size gives the same identity (a recorded one stays valid)."""
    import cfbmarkov.trajectory_identity as identity
    from cfbmarkov.trajectories import Trajectories

    run, model, _ = good
    window = MarkovModel.load(model).window
    with Trajectories(run) as t:
        whole = identity.window_identity(t, window)
        for values in (1, 7 * t.n_particles * t.dimensions, 10 ** 9):
            monkeypatch.setattr(identity, "_BLOCK_VALUES", values)
            assert identity.window_identity(t, window) == whole
    with pytest.raises(InputError, match="unknown rule .*newer cfbmarkov"):
        identity.identity_version("window-sha256-9:00")


def test_a_model_recorded_by_the_earlier_identity_rule_is_assessed_on_its_data(good):
    """assess_fit forms the identity by the rule the model recorded it with: a model of the
    earlier rule (three frames) passes on its own unchanged data."""
    import dataclasses

    from cfbmarkov.analysis.fit_checks import assess_fit
    from cfbmarkov.trajectories import Trajectories
    from cfbmarkov.trajectory_identity import window_identity

    run, model_path, _ = good
    model = MarkovModel.load(model_path)
    with Trajectories(run) as t:
        v1 = window_identity(t, model.window, 1)
    older = dataclasses.replace(model, source=str(run), source_identity=v1)
    assessed = assess_fit(older, resamples=0)
    assert assessed.source_identity == v1


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


# -- tracebacks and unbounded work, each now one line ------------------------------------
def test_fit_coherent_on_one_cell_is_refused(good, tmp_path, capsys):
    run, _, _ = good
    err = one_line_error(capsys, ["fit", run, "--cells", "1x1", "--coherent", "--window",
                                  "0:2.5", "-o", tmp_path / "m.h5"], tmp_path / "m.h5")
    assert "at least 2 cells" in err


def test_fit_open_riser_with_states_auto(tmp_path, capsys):
    run = synthetic.write_open_run(tmp_path / "open.h5", FLOW, 60, 6.0, seed=4)
    out = tmp_path / "m.h5"
    assert main(["fit", str(run), "--states", "auto", "--window", "0.5:6", "--resamples", "0",
                 "-q", "-o", str(out)]) == 0
    assert MarkovModel.load(out).boundary.is_open


CASE_VALUES = {"riser.height": "[riser]\nheight = 1e300\n",
               "particles.density": "[particles]\ndensity = 1e-300\n",
               "gas.superficial_velocity": "[gas]\nsuperficial_velocity = inf\n",
               "particles.number": "[particles]\nnumber = 10000000000\n",
               "seed": "seed = 18446744073709551616\n",
               "numerics.cfd_cells.0": "[numerics]\ncfd_cells = [0, 5]\n"}


@pytest.mark.parametrize("field", CASE_VALUES)
def test_case_values_out_of_range_are_refused(field, tmp_path, capsys):
    case = tmp_path / "case.toml"
    case.write_text(CASE_VALUES[field])
    err = one_line_error(capsys, ["simulate", case, "-o", tmp_path / "s.h5"], tmp_path / "s.h5")
    assert f"'{field}'" in err


def test_simulate_more_particles_than_fit_is_refused(tmp_path, capsys):
    err = one_line_error(capsys, ["simulate", "paper-u6", "--particles", "10000000", "--until",
                                  "0.05", "-o", tmp_path / "s.h5"], tmp_path / "s.h5")
    assert "do not fit" in err and "--particles" in err
    assert list(tmp_path.iterdir()) == []


def test_demo_checks_memory_before_allocating(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("CFBMARKOV_MEMORY_LIMIT", "1000000000")
    err = one_line_error(capsys, ["demo", "--synthetic", "--particles", "10000000", "-q",
                                  "-o", tmp_path / "d"], tmp_path / "d")
    assert "of memory" in err and "--particles" in err


def test_synthetic_run_takes_the_largest_seed():
    times, cells, positions, laps = synthetic.sample_run(FLOW, 5, 3, seed=2 ** 64 - 1)
    assert positions.shape == (3, 5, 2)


def test_numba_threads_that_are_not_a_number(good, tmp_path, capsys, monkeypatch):
    run, _, _ = good
    monkeypatch.setenv("NUMBA_NUM_THREADS", "abc")
    err = one_line_error(capsys, ["fit", run, "--cells", "4x8", "--window", "0:2.5",
                                  "-o", tmp_path / "m.h5"], tmp_path / "m.h5")
    assert "NUMBA_NUM_THREADS" in err


def test_stationarity_steps_are_bounded(good, capsys):
    run, _, _ = good
    err = one_line_error(capsys, ["stationarity", run, "--window-length", "1", "--step", "1e-9"])
    assert "shorter than the frame interval" in err


def test_maps_times_are_bounded(good, tmp_path, capsys):
    _, model, _ = good
    times = ",".join(f"{0.025 * k:g}" for k in range(1, 401))
    err = one_line_error(capsys, ["maps", model, "--times", times, "-o", tmp_path / "m.png"],
                         tmp_path / "m.png")
    assert "at most 36" in err


# -- an option value that cannot be honoured is an error ------------------------------------
def test_compare_events_basis_without_events_is_refused(good, tmp_path, capsys):
    run, _, pred = good
    err = one_line_error(capsys, ["compare", run, pred, "--window", "0.5:2.5", "--basis",
                                  "events", "--resamples", "0", "--no-figures", "-q",
                                  "-o", tmp_path / "c"], tmp_path / "c")
    assert "no exact pass events" in err and "--basis frames" in err


@pytest.mark.parametrize("order", ["1e-300", "0.5"])
def test_compare_md_order_below_one_is_refused(good, tmp_path, capsys, order):
    run, _, pred = good
    err = one_line_error(capsys, ["compare", run, pred, "--window", "0.5:2.5", "--md-order",
                                  order, "-o", tmp_path / "c"], tmp_path / "c")
    assert "must be a finite number >= 1" in err


# -- output size estimated before writing --------------------------------------------------
def test_predict_refuses_an_output_larger_than_the_free_disk(good, tmp_path, capsys,
                                                             monkeypatch):
    import cfbmarkov.limits

    run, model, _ = good
    monkeypatch.setattr(cfbmarkov.limits, "free_disk", lambda folder: 1e5)
    err = one_line_error(capsys, ["predict", model, "--init", run, "--start", "0.5",
                                  "--duration", "2", "-q", "-o", tmp_path / "p.h5"],
                         tmp_path / "p.h5")
    assert "on disk" in err and "--duration" in err
    assert list(tmp_path.iterdir()) == []


# -- folder outputs published whole ---------------------------------------------------------
def test_compare_interrupted_while_drawing_leaves_no_folder(good, tmp_path, capsys,
                                                            monkeypatch):
    import importlib

    report = importlib.import_module("cfbmarkov.report.compare")
    run, _, pred = good

    def draw(comparison, out, warnings):
        (out / "rtd.png").write_bytes(b"half a figure")
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "_draw", draw)
    out = tmp_path / "cmp"
    assert main(["compare", str(run), str(pred), "--window", "0.5:2.5", "--resamples", "0",
                 "-q", "-o", str(out)]) == 130
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == []


def test_compare_replaces_a_previous_comparison_whole(good, tmp_path):
    run, _, pred = good
    out = tmp_path / "cmp"
    out.mkdir()
    (out / "old.png").write_bytes(b"a figure of an earlier comparison")
    assert main(["compare", str(run), str(pred), "--window", "0.5:2.5", "--resamples", "0",
                 "--no-figures", "-q", "-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]
    (out / "notes.txt").write_text("mine")
    assert main(["compare", str(run), str(pred), "--window", "0.5:2.5", "--resamples", "0",
                 "--no-figures", "-q", "-o", str(out)]) == 2
    assert (out / "notes.txt").read_text() == "mine"
