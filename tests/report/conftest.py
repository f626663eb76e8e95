"""Fixtures of the reproduction-report tests: a small reproduction directory laid out as the
pipeline writes it (reproduce.json, and per case case.json, cfd-dem.h5, model-<est>.h5,
prediction-<est>.h5, compare-<est>/summary.json and figures, timings.json), built from the
synthetic core-annulus generator at two fake velocities, plus a third case whose comparison
has not run yet."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numba
import pytest

from cfbmarkov import synthetic
from cfbmarkov.config import CaseConfig
from cfbmarkov.markov import CellGrid, fit_model
from cfbmarkov.report.compare import compare
from tests.shared_builds import built_once

PARTICLES = 400
END = 6.0
FIT = (2.0, 4.0)
PREDICT = (4.0, 6.0)
COLUMNS, ROWS, LAG = 6, 12, 0.025
ESTIMATORS = ("paper", "mle")
#: fake superficial velocity (m/s) -> rise velocity of the synthetic core (m/s)
COMPLETE = {3.0: 1.4, 6.0: 2.6}
UNFINISHED = 8.0


def case_config(u: float) -> CaseConfig:
    return CaseConfig.model_validate({
        "name": f"u{u:g}", "seed": 1,
        "riser": {"width": 0.09, "height": 0.95},
        "particles": {"number": PARTICLES},
        "gas": {"superficial_velocity": u},
        "output": {"end_time": END, "frame_interval": LAG},
        "markov": {"columns": COLUMNS, "rows": ROWS, "lag": LAG, "fit_window": FIT,
                   "predict_window": PREDICT},
    })


def build_case(root: Path, u: float, rise: float, *, estimators=ESTIMATORS, compare_figures=True
               ) -> Path:
    """One finished case: CFD-DEM stand-in, models, predictions, comparisons, timings."""
    case = root / f"u{u:g}"
    case.mkdir(parents=True)
    (case / "case.json").write_text(case_config(u).model_dump_json(indent=2))
    flow = synthetic.RiserFlow(columns=COLUMNS, rows=ROWS, rise_velocity=rise)
    reference = synthetic.write_run(case / "cfd-dem.h5", flow, PARTICLES, END, seed=int(u))
    grid = CellGrid(COLUMNS, ROWS, flow.width, flow.height)
    timings = {"cfd_dem": {"wall_s": 3600.0 * u, "simulated_s": END, "particles": PARTICLES,
                           "predict_window_wall_s": 1200.0 * u,
                           "predict_window_estimated": u > 4}}
    for k, name in enumerate(estimators):
        model = fit_model(reference, grid, LAG, FIT, name)
        model.save(case / f"model-{name}.h5")
        prediction = model.predict(reference, start=PREDICT[0], duration=PREDICT[1] - PREDICT[0],
                                   seed=7, output=case / f"prediction-{name}.h5")
        # figures only where the report uses them (snapshots of compare-paper): faster
        compare(reference, prediction, window=PREDICT, output=case / f"compare-{name}",
                figures=compare_figures and name == "paper")
        timings[f"fit-{name}"] = {"wall_s": 2.0 + k}
        timings[f"predict-{name}"] = {"wall_s": 10.0 + k}
    (case / "timings.json").write_text(json.dumps(timings, indent=2))
    return case


@pytest.fixture(scope="session")
def reproduction_template(tmp_path_factory) -> Path:
    """u3 and u6 finished; u8 fitted and predicted (files copied from u6) but not compared,
    and without timings: built once per test run, shared by the workers (read only: tests
    copy it)."""
    return built_once(tmp_path_factory, "reproduction-template", _build_template)


def _build_template(root: Path) -> None:
    threads = numba.get_num_threads()
    # the Monte Carlo placement is a parallel kernel: on a busy machine, launching threads
    # for a few hundred particles costs more than it saves
    numba.set_num_threads(1)
    try:
        for u, rise in COMPLETE.items():
            build_case(root, u, rise)
    finally:
        numba.set_num_threads(threads)
    unfinished = root / f"u{UNFINISHED:g}"
    unfinished.mkdir()
    (unfinished / "case.json").write_text(case_config(UNFINISHED).model_dump_json(indent=2))
    for name in ("cfd-dem.h5", "model-paper.h5", "prediction-paper.h5"):
        shutil.copyfile(root / "u6" / name, unfinished / name)
    (root / "reproduce.json").write_text(json.dumps(
        {"scale": "quick", "cases": ["u6", "u8", "u3"], "version": "0.1.0"}))


@pytest.fixture
def reproduction(reproduction_template, tmp_path) -> Path:
    """A fresh copy of the template per test (tests may write into it or break it)."""
    root = tmp_path / "reproduction"
    shutil.copytree(reproduction_template, root)
    return root


@pytest.fixture(scope="session")
def report_of_template(reproduction_template, tmp_path_factory):
    """(directory, report.html path) of one report written on a copy of the template; the
    tests that only read the report share it."""
    from cfbmarkov.report.reproduction import write_report

    def build(folder: Path) -> None:
        shutil.copytree(reproduction_template, folder / "reproduction")
        write_report(folder / "reproduction")

    root = built_once(tmp_path_factory, "reported-template", build) / "reproduction"
    return root, root / "report.html"
