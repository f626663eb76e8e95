"""compare --kinetics never takes a number it cannot vouch for: stored values of another
definition, a carried property's steady state against a window, a state space with memory
read from a prediction's first frame."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest

from cfbmarkov.synthetic import RiserFlow, write_run

FLOW = RiserFlow(columns=6, rows=10, lag=0.02, persistence=False, rise_velocity=2.0,
                 fall_velocity=-2.0)


def _toml(tmp_path, name, body):
    path = tmp_path / f"{name}.toml"
    path.write_text(f'[[property]]\nname = "X"\n{body}\n')
    return path


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    """A run, a cells model and a cells-velocity model fitted on 0-4 s (the velocity one
    from 0.02 s: its first frame is history), predictions from 4 s with the first-order
    property X (rate 1) stored, and one of the velocity model without properties."""
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.markov import CellGrid, fit_model
    from cfbmarkov.markov.spaces import state_space_from_name

    tmp = tmp_path_factory.mktemp("stored")
    run = write_run(tmp / "run.h5", FLOW, 250, 8.0, seed=3)
    kin = load_kinetics(_toml(tmp, "first", 'law = "first-order"\nrate = 1.0'))
    cells = fit_model(run, CellGrid(FLOW.columns, FLOW.rows), FLOW.lag, (0.0, 4.0), "mle")
    velocity = fit_model(run, state_space_from_name("cells-velocity", FLOW.columns, FLOW.rows),
                         FLOW.lag, (0.02, 4.0), "mle")
    out = {"run": run, "tmp": tmp}
    out["pred"] = cells.predict(run, start=4.0, duration=4.0, seed=5, output=tmp / "p.h5",
                                kinetics=kin.per_state(cells.state_space))
    out["pred_v"] = velocity.predict(run, start=4.0, duration=4.0, seed=5,
                                     output=tmp / "pv.h5",
                                     kinetics=kin.per_state(velocity.state_space))
    out["plain_v"] = velocity.predict(run, start=4.0, duration=4.0, seed=5,
                                      output=tmp / "plain_v.h5")
    return out


def _compare(runs, pred, kinetics, out, window=(4.0, 8.0)):
    from cfbmarkov.report.compare import compare

    return compare(runs["run"], pred, window=window, output=out, figures=False, resamples=0,
                   kinetics=kinetics)


# -- the fingerprint -----------------------------------------------------------------------

def _state_kinetics(tmp_path, body, name="k"):
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.markov import CellGrid

    return load_kinetics(_toml(tmp_path, name, body)).per_state(
        CellGrid(FLOW.columns, FLOW.rows).with_size(0.1, 1.0))


def test_fingerprint_tells_definitions_apart_and_ignores_the_last_bits(tmp_path):
    from dataclasses import replace

    from cfbmarkov.kinetics.fingerprint import property_fingerprint

    base = _state_kinetics(tmp_path, 'law = "first-order"\nrate = 1.0', "a")
    same = property_fingerprint(base, 0, 0.02)
    assert same.startswith("sha256:") and len(same) == 7 + 64
    assert property_fingerprint(_state_kinetics(tmp_path, 'law = "first-order"\nrate = 1.0',
                                                "b"), 0, 0.02) == same
    others = [_state_kinetics(tmp_path, 'law = "first-order"\nrate = 1.1', "c"),
              _state_kinetics(tmp_path, 'law = "deactivation"\nrate = 1.0\ninitial = 0.0', "d"),
              _state_kinetics(tmp_path, 'law = "first-order"\nrate = 1.0\nstart = "carried"',
                              "e"),
              _state_kinetics(tmp_path, 'law = "first-order"\nrate = 1.0\ninitial = 0.5', "f")]
    for other in others:
        assert property_fingerprint(other, 0, 0.02) != same
    assert property_fingerprint(base, 0, 0.04) != same
    assert property_fingerprint(base, 0, 0.02, "down") != same
    # one state's rate changed by 1e-9: another definition; by one ulp: the same
    rate = np.array(base.rate)
    rate[0, 7] *= 1 + 1e-9
    assert property_fingerprint(replace(base, rate=rate), 0, 0.02) != same
    rate = np.array(base.rate)
    rate[0, 7] = np.nextafter(rate[0, 7], 2.0)
    assert property_fingerprint(replace(base, rate=rate), 0, 0.02) == same


def test_custom_laws_of_one_name_and_other_bodies_have_other_fingerprints():
    """The fingerprint hashes a custom rate function's definition, not only its name."""
    import importlib.util
    from pathlib import Path

    from cfbmarkov.kinetics import Constant, Custom, Kinetics, Property
    from cfbmarkov.kinetics.fingerprint import property_fingerprint
    from cfbmarkov.markov import CellGrid

    spec = importlib.util.spec_from_file_location(
        "rate_functions", Path(__file__).parents[1] / "kinetics" / "rate_functions.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.FIRST.__name__ == module.SECOND.__name__ == "rate"
    space = CellGrid(FLOW.columns, FLOW.rows).with_size(0.1, 1.0)

    def fingerprint(function):
        law = Custom(function, parameters=("k",))
        kinetics = Kinetics((Property("X", law, {"k": Constant(1.0)}),))
        return property_fingerprint(kinetics.per_state(space), 0, 0.02)

    assert fingerprint(module.FIRST) == fingerprint(module.FIRST)
    assert fingerprint(module.FIRST) != fingerprint(module.SECOND)


def test_prediction_stores_the_fingerprint(runs):
    with h5py.File(runs["pred"], "r") as f:
        attrs = dict(f["properties/X"].attrs)
    assert str(attrs["fingerprint"]).startswith("sha256:")
    assert attrs["fingerprint_method"] == "cfbmarkov-kinetics-2"
    assert attrs["entries"] == "up"


# -- 1. stored values of another definition ------------------------------------------------

def test_stored_values_of_the_same_kinetics_are_used(runs, tmp_path):
    kin = _toml(tmp_path, "same", 'law = "first-order"\nrate = 1.0')
    got = _compare(runs, runs["pred"], kin, tmp_path / "same")
    model = got["kinetics"]["X"]["model"]
    assert model["values_from"] == "stored" and "values_note" not in model
    assert not any("stored" in w for w in got["warnings"])


@pytest.mark.parametrize("body, differs", [
    ('law = "first-order"\nrate = 1.1', "rates or targets"),
    ('law = "deactivation"\nrate = 1.0\ninitial = 0.0', "law first-order stored, deactivation"),
])
def test_stored_values_of_another_definition_are_not_the_model(runs, tmp_path, body,
                                                                differs):
    kin = _toml(tmp_path, "other", body)
    got = _compare(runs, runs["pred"], kin, tmp_path / "other")
    model = got["kinetics"]["X"]["model"]
    assert model["values_from"] == "paths"
    assert "another definition of X" in model["values_note"] and differs in model["values_note"]
    assert sum("another definition of X" in w for w in got["warnings"]) == 1
    # the model side is that of the compare's kinetics: as if the prediction stored none
    with h5py.File(runs["pred"], "r") as f, \
            h5py.File(shutil.copy(runs["pred"], tmp_path / "bare.h5"), "a") as g:
        assert "properties" in f
        del g["properties"]
    bare = _compare(runs, tmp_path / "bare.h5", kin, tmp_path / "bare")["kinetics"]["X"]
    assert model["exit_mean"] == pytest.approx(bare["model"]["exit_mean"], rel=1e-12)


def test_stored_values_without_a_fingerprint_are_not_trusted(runs, tmp_path):
    old = shutil.copy(runs["pred"], tmp_path / "old.h5")
    with h5py.File(old, "a") as f:
        del f["properties/X"].attrs["fingerprint"]
        del f["properties/X"].attrs["fingerprint_method"]
    kin = _toml(tmp_path, "same", 'law = "first-order"\nrate = 1.0')
    got = _compare(runs, old, kin, tmp_path / "old")
    model = got["kinetics"]["X"]["model"]
    assert model["values_from"] == "paths" and "without the fingerprint" in model["values_note"]
    assert any("without the fingerprint" in w for w in got["warnings"])


def test_stored_values_of_an_older_recipe_or_another_direction_are_not_the_model(runs,
                                                                                tmp_path):
    """Values stored by the recipe that did not record the residence direction (a net
    downflow's Monte Carlo then reset its entry properties at the wrong passes), or stored
    for the other direction, are integrated along the prediction's paths instead."""
    kin = _toml(tmp_path, "same", 'law = "first-order"\nrate = 1.0')
    for label, attrs, said in [
            ("older", {"fingerprint_method": "cfbmarkov-kinetics-1"}, "older recipe"),
            ("down", {"entries": "down"}, "entries counted down stored, up here")]:
        copy = shutil.copy(runs["pred"], tmp_path / f"{label}.h5")
        with h5py.File(copy, "a") as f:
            stored = f["properties/X"].attrs
            if label == "older":
                del stored["entries"]
            stored["fingerprint"] = "sha256:" + "0" * 64
            for key, value in attrs.items():
                stored[key] = value
        model = _compare(runs, copy, kin, tmp_path / label)["kinetics"]["X"]["model"]
        assert model["values_from"] == "paths" and said in model["values_note"]


# -- 2. a carried property -----------------------------------------------------------------

def test_carried_property_has_no_steady_state_pd_nor_segregated_flow(runs, tmp_path, capsys):
    from cfbmarkov.cli import main

    kin = _toml(tmp_path, "carried", 'law = "deactivation"\nrate = 0.5\nstart = "carried"')
    code = main(["compare", str(runs["run"]), str(runs["pred"]), "--window", "4:8", "-o",
                 str(tmp_path / "c"), "--resamples", "0", "--no-figures", "--kinetics",
                 str(kin), "-q"])
    assert code == 0
    printed = capsys.readouterr().out
    line = next(x for x in printed.splitlines() if x.startswith("X at the exit"))
    assert "exact steady state 0 (" in line and "not comparable with a 4 s window" in line
    assert "PD -100" not in line
    assert "segregated flow: not defined for a carried property" in line
    block = json.loads((tmp_path / "c" / "summary.json").read_text())["kinetics"]["X"]
    assert block["model"]["exact"]["pd_exit_mean"] is None
    assert "steady state" in block["model"]["exact"]["note"]
    assert block["segregated_flow"] is None
    assert "carried" in block["segregated_flow_note"]
    # an entry property keeps both
    kin = _toml(tmp_path, "entry", 'law = "deactivation"\nrate = 0.5')
    entry = _compare(runs, runs["pred"], kin, tmp_path / "e")["kinetics"]["X"]
    assert entry["model"]["exact"]["pd_exit_mean"] is not None
    assert entry["segregated_flow"] is not None and "segregated_flow_note" not in entry


# -- 3. a state space with memory from a prediction's first frame --------------------------

def test_velocity_states_compare_from_the_predictions_start(runs, tmp_path, capsys):
    from cfbmarkov.cli import main

    kin = _toml(tmp_path, "same", 'law = "first-order"\nrate = 1.0')
    code = main(["compare", str(runs["run"]), str(runs["pred_v"]), "--window", "4:8", "-o",
                 str(tmp_path / "v"), "--resamples", "0", "--no-figures", "--kinetics",
                 str(kin), "-q"])
    assert code == 0
    out, err = capsys.readouterr()
    assert "X over 4.02-8 s: starts 1 lag(s) after the window's start" in out
    assert "comparison starts 1 lag(s) later" in err
    block = json.loads((tmp_path / "v" / "summary.json").read_text())["kinetics"]["X"]
    assert block["window"] == pytest.approx([4.02, 8.0])
    # the stored values have run a lag ahead of the reference's: the paths from 4.02 s
    assert block["model"]["values_from"] == "paths"
    assert "has run since its first frame at 4 s" in block["model"]["values_note"]
    assert block["reference"]["exit_count"] > 50
    # a prediction without properties (predict) and the plain comparison
    got = _compare(runs, runs["plain_v"], kin, tmp_path / "plain")
    assert got["kinetics"]["X"]["model"]["values_from"] == "paths"
    assert got["kinetics"]["X"]["window"] == pytest.approx([4.02, 8.0])
    assert np.isfinite(_compare(runs, runs["plain_v"], None, tmp_path / "nokin")["md_rtd"])


def test_velocity_states_window_too_short_names_the_fix(runs, tmp_path, capsys):
    from cfbmarkov.cli import main

    kin = _toml(tmp_path, "same", 'law = "first-order"\nrate = 1.0')
    code = main(["compare", str(runs["run"]), str(runs["pred_v"]), "--window", "4:4.02",
                 "-o", str(tmp_path / "short"), "--resamples", "0", "--no-figures",
                 "--kinetics", str(kin), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    # one lag of 0.02 s: one RTD bin, refused before the kinetics' own check of the window
    assert "compare over a window of 0.04 s or more" in err[0]
    assert not (tmp_path / "short").exists()


def test_missing_history_at_a_files_start_names_the_window(runs):
    from cfbmarkov.errors import InputError
    from cfbmarkov.markov import fit_model
    from cfbmarkov.markov.spaces import state_space_from_name

    with pytest.raises(InputError, match=r"--window 0\.02:4\)"):
        fit_model(runs["run"], state_space_from_name("cells-velocity", FLOW.columns, FLOW.rows),
                  FLOW.lag, (0.0, 4.0), "mle")


# -- 4. the interval and its verdict on the console ----------------------------------------

def test_console_prints_the_models_interval_and_verdict(runs, tmp_path, capsys):
    from cfbmarkov.cli import main

    kin = _toml(tmp_path, "same", 'law = "first-order"\nrate = 1.0')
    code = main(["compare", str(runs["run"]), str(runs["pred"]), "--window", "4:8", "-o",
                 str(tmp_path / "i"), "--resamples", "0", "--no-figures", "--kinetics",
                 str(kin), "-q"])
    assert code == 0
    lines = capsys.readouterr().out.splitlines()
    verdict = next(x for x in lines if "interval of the model's exit mean" in x)
    block = json.loads((tmp_path / "i" / "summary.json").read_text())["kinetics"]["X"]
    lo, hi = block["model"]["exit_mean_interval"]
    assert f"{lo:.4g}-{hi:.4g}" in verdict and "the flow's variability left out" in verdict
    inside = lo <= block["reference"]["exit_mean"] <= hi
    # --resamples 0: the Monte Carlo noise alone, which draws no verdict
    assert ("within the Monte Carlo noise" in verdict) == inside
    assert "so no verdict is drawn from it" in verdict and "misses" not in verdict


def test_a_carried_property_stored_from_before_a_later_start_is_not_used(runs, tmp_path):
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.trajectories import Trajectories

    kin = _toml(tmp_path, "carried", 'law = "deactivation"\nrate = 0.5\nstart = "carried"')
    with Trajectories(runs["pred_v"]) as traj:
        model = MarkovModel.from_trajectories(traj)
    pred = model.predict(runs["run"], start=4.0, duration=4.0, seed=5,
                         output=tmp_path / "pvc.h5",
                         kinetics=load_kinetics(kin).per_state(model.state_space))
    block = _compare(runs, pred, kin, tmp_path / "pvc")["kinetics"]["X"]
    assert block["window"] == pytest.approx([4.02, 8.0])
    assert block["model"]["values_from"] == "paths"
    assert "has run since its first frame at 4 s" in block["model"]["values_note"]


def test_stored_values_are_not_used_where_the_window_starts_after_the_prediction(runs,
                                                                                 tmp_path):
    """A prediction from 4 s that stores X, compared over 6-8 s: its values at 6 s carry
    what happened since 4 s, while the reference's start every particle at the window's
    start; the model side integrates X along the prediction's paths from 6 s, the same
    answer as the same paths predicted without stored values (before: the stored values,
    a model side that started ahead of the reference)."""
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.trajectories import Trajectories

    kin = _toml(tmp_path, "same", 'law = "first-order"\nrate = 1.0')
    later = _compare(runs, runs["pred"], kin, tmp_path / "late", window=(6.0, 8.0))
    block = later["kinetics"]["X"]["model"]
    assert block["values_from"] == "paths"
    assert "has run since its first frame at 4 s" in block["values_note"]
    with Trajectories(runs["pred"]) as traj:
        model = MarkovModel.from_trajectories(traj)
    plain = model.predict(runs["run"], start=4.0, duration=4.0, seed=5,
                          output=tmp_path / "plain.h5")
    same = _compare(runs, plain, kin, tmp_path / "plain", window=(6.0, 8.0))
    assert block["exit_mean"] == same["kinetics"]["X"]["model"]["exit_mean"]
    assert block["bed_mean"] == same["kinetics"]["X"]["model"]["bed_mean"]


@pytest.mark.parametrize("stored_by_prediction", [True, False])
def test_a_reference_start_begins_both_sides_at_the_references_values(runs, tmp_path,
                                                                      stored_by_prediction):
    """A prediction started from a file that stores X (another prediction's, of another
    rate) with start = "reference" takes the stored values; the comparison's reference side
    started from X integrated along the file's paths from its first frame instead, and its
    model side, where it integrates, from the entry value: the two sides began apart (0.3515
    against 0.2932 in a trial). Both now start from the file's stored values: the bed means
    of the first frame agree, whether the model side reads its stored values or integrates
    along its paths (a prediction without kinetics)."""
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.trajectories import Trajectories

    kin = _toml(tmp_path, "ref", 'law = "first-order"\nrate = 0.5\nstart = "reference"')
    with Trajectories(runs["pred"]) as traj:
        model = MarkovModel.from_trajectories(traj)
        stored = traj.property_values("X", int(np.argmin(np.abs(traj.times - 5.0))))
    per_state = load_kinetics(kin).per_state(model.state_space)
    pred = model.predict(runs["pred"], start=5.0, duration=2.0, seed=7,
                         output=tmp_path / "pr.h5",
                         kinetics=per_state if stored_by_prediction else None)
    from cfbmarkov.report.compare import compare

    got = compare(runs["pred"], pred, window=(5.0, 7.0), output=tmp_path / "c", figures=False,
                  resamples=0, kinetics=kin)["kinetics"]["X"]
    assert got["model"]["values_from"] == ("stored" if stored_by_prediction else "paths")
    first_ref = got["reference"]["bed_mean_over_time"]["mean"][0]
    first_model = got["model"]["bed_mean_over_time"]["mean"][0]
    assert first_ref == pytest.approx(float(np.nanmean(stored)), rel=1e-12)
    assert first_model == pytest.approx(first_ref, rel=1e-12)


def test_a_reference_start_from_values_of_another_law_is_refused(runs, tmp_path):
    """The reference stores X as a first-order conversion (0 to 1); a heat exchange named X
    that starts from the reference would start at temperatures of 0-1 K: refused, as a
    prediction from that file refuses it."""
    from cfbmarkov.errors import InputError
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.report.compare import compare
    from cfbmarkov.trajectories import Trajectories

    kin = _toml(tmp_path, "heat", 'law = "heat-exchange"\ncoefficient = 1.0\n'
                'temperature = 800.0\ninitial = 300.0\nstart = "reference"')
    with Trajectories(runs["pred"]) as traj:
        model = MarkovModel.from_trajectories(traj)
    plain = model.predict(runs["pred"], start=5.0, duration=2.0, seed=7,
                          output=tmp_path / "plain.h5")
    with pytest.raises(InputError, match=r"stores X of law first-order, not heat-exchange"):
        compare(runs["pred"], plain, window=(5.0, 7.0), output=tmp_path / "heat",
                figures=False, resamples=0, kinetics=kin)
    assert not (tmp_path / "heat").exists()
