"""Reading a reproduction run folder: U from case.json (whatever the folder is called), the
fallback to the case stored in cfd-dem.h5 for folders of older versions, and the error that
asks to rerun ``cfbmarkov reproduce``."""

from __future__ import annotations

import json
import math
import shutil

import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.report.run_folder import read_run_folder
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories


def test_velocity_and_paths_from_case_json(reproduction):
    folder = read_run_folder(reproduction)
    assert [c.name for c in folder.cases] == ["u3", "u6", "u8"]
    assert [c.velocity for c in folder.cases] == [3.0, 6.0, 8.0]
    assert folder.estimators == ["paper", "mle"]
    assert [c.name for c in folder.finished] == ["u3", "u6"]
    u3 = folder.cases[0]
    assert u3.reference == reproduction / "u3" / "cfd-dem.h5"
    assert [e.name for e in u3.finished] == ["paper", "mle"]
    assert u3.finished[0].model == reproduction / "u3" / "model-paper.h5"
    assert [float(t) for t in u3.config.markov.predict_window] == [4.0, 6.0]


def test_folder_name_does_not_encode_velocity(reproduction):
    (reproduction / "u6").rename(reproduction / "fast-case")
    (reproduction / "u3").rename(reproduction / "u99")          # a misleading name
    manifest = json.loads((reproduction / "reproduce.json").read_text())
    manifest["cases"] = ["fast-case", "u8", "u99"]
    (reproduction / "reproduce.json").write_text(json.dumps(manifest))
    folder = read_run_folder(reproduction)
    assert [(c.name, c.velocity) for c in folder.cases] == [("u99", 3.0), ("fast-case", 6.0),
                                                            ("u8", 8.0)]
    assert folder.cases[1].label == "U = 6 m/s"


def test_case_not_started_has_no_velocity(reproduction):
    manifest = json.loads((reproduction / "reproduce.json").read_text())
    manifest["cases"].append("u10")
    (reproduction / "reproduce.json").write_text(json.dumps(manifest))
    case = read_run_folder(reproduction).cases[-1]
    assert case.name == "u10" and math.isinf(case.velocity) and case.label == "u10"
    assert case.reasons == ["not started (no directory)"]


def test_old_folder_takes_the_case_stored_in_the_trajectories(reproduction):
    """A CFD-DEM run stores its case as the file's parameters; without case.json, U comes
    from there."""
    case_dir = reproduction / "u6"
    config = json.loads((case_dir / "case.json").read_text())
    (case_dir / "case.json").unlink()
    reference = case_dir / "cfd-dem.h5"
    with Trajectories(reference) as traj:
        times, positions = traj.times[()], traj.positions(slice(None))
        width, height = traj.width, traj.height
    reference.unlink()
    write_trajectories(reference, times, positions, width=width, height=height,
                       source="cfd-dem", parameters=config)
    case = {c.name: c for c in read_run_folder(reproduction).cases}["u6"]
    assert case.velocity == 6.0 and case.complete


def test_old_folder_without_any_case_asks_to_rerun(reproduction):
    (reproduction / "u8" / "case.json").unlink()
    (reproduction / "u8" / "cfd-dem.h5").unlink()
    with pytest.raises(InputError, match="rerun 'cfbmarkov reproduce") as info:
        read_run_folder(reproduction)
    assert "\n" not in str(info.value) and str(reproduction / "u8") in str(info.value)
    # the synthetic stand-in stores no case either
    shutil.copyfile(reproduction / "u6" / "cfd-dem.h5", reproduction / "u8" / "cfd-dem.h5")
    with pytest.raises(InputError, match="no case.json and no case stored in cfd-dem.h5"):
        read_run_folder(reproduction)
