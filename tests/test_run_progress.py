"""The whole run's time left of ``cfbmarkov reproduce`` and ``cfbmarkov demo``, from what the
cases leave in their folders."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from cfbmarkov.run_progress import CaseState, read_case, time_left, time_left_line


def test_nothing_measured_yet_gives_no_estimate():
    cases = [CaseState("cfd-dem", 2.0, 100), CaseState("waiting", 2.0, 100)]
    assert time_left(cases, 2) is None
    assert time_left_line(cases, 2, 10.0) is None


def test_waiting_cases_queue_behind_the_running_ones():
    # two workers: each running case has 1 s of 2 s simulated left at 30 s per simulated s;
    # the waiting one (2 s at the same rate) starts on the first free worker
    running = CaseState("cfd-dem", 2.0, 100, reached=1.0, wall=30.0)
    cases = [running, CaseState("cfd-dem", 2.0, 100, reached=1.0, wall=30.0),
             CaseState("waiting", 2.0, 100), CaseState("done", 2.0, 100, models_wall=10.0)]
    left, with_models = time_left(cases, 2)
    assert with_models
    assert left == pytest.approx(30.0 + 10.0 + 60.0 + 10.0)
    # one worker: everything in a row
    left, _ = time_left(cases, 1)
    assert left == pytest.approx(40.0 + 40.0 + 70.0)
    line = time_left_line(cases, 2, 65.0)
    assert line == "whole run: 1 of 4 case(s) done, 1:05 so far, about 1:50 left (then the report)"


def test_before_any_case_finishes_the_line_says_cfd_dem_alone():
    cases = [CaseState("cfd-dem", 2.0, 100, reached=0.5, wall=10.0, since=4.0),
             CaseState("waiting", 4.0, 200)]
    left, with_models = time_left(cases, 1)
    assert not with_models
    assert left == pytest.approx(1.5 * 20.0 - 4.0 + 4.0 * 200 * 0.2)
    assert "for the CFD-DEM alone" in time_left_line(cases, 1, 1.0)


def test_read_case_from_its_files(tmp_path):
    assert read_case(tmp_path / "u3", 2.0, 10, False).stage == "waiting"
    folder = tmp_path / "u4"
    (folder / "cfd-dem.h5.parts").mkdir(parents=True)
    with h5py.File(folder / "cfd-dem.h5.parts" / "checkpoint.h5", "w") as f:
        f["wall_history"] = np.array([[0.0, 0.0], [0.5, 12.0]])
    state = read_case(folder, 2.0, 10, False)
    assert (state.stage, state.reached, state.wall) == ("cfd-dem", 0.5, 12.0)
    (folder / "cfd-dem.h5").write_bytes(b"")
    assert read_case(folder, 2.0, 10, False).stage == "models"
    (folder / "timings.json").write_text(json.dumps(
        {"cfd_dem": {"wall_s": 100.0}, "fit-paper": {"wall_s": 1.0},
         "predict-paper": {"wall_s": 2.0}, "compare-paper": {"wall_s": 3.5}}))
    done = read_case(folder, 2.0, 10, True)
    assert done.stage == "done" and done.models_wall == pytest.approx(6.5)


def test_a_finished_cfd_dem_paces_the_cases_to_come(tmp_path):
    """Between two cases (the first finished, the next not started) the estimate holds."""
    folder = tmp_path / "u3"
    folder.mkdir()
    (folder / "timings.json").write_text(json.dumps(
        {"cfd_dem": {"wall_s": 40.0, "simulated_s": 2.0}, "fit-paper": {"wall_s": 4.0}}))
    cases = [read_case(folder, 2.0, 100, True), read_case(tmp_path / "u4", 1.0, 200, False)]
    assert cases[0].stage == "done" and cases[1].stage == "waiting"
    left, with_models = time_left(cases, 2)
    assert with_models and left == pytest.approx(1.0 * 200 * (40.0 / 200.0) + 4.0)
