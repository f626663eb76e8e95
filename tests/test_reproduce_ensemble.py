"""``cfbmarkov reproduce --ensemble N``: each case's CFD-DEM as N members, the models fitted
on the members pooled and compared on member 0, the folder's N kept, the report saying N."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.markov import MarkovModel
from cfbmarkov.simulate.ensemble import member_seeds
from cfbmarkov.trajectories import Trajectories
from tests.shared_builds import built_once, worker_copy

# the miniature reproduction's case (tests/test_reproduce.py)
TINY = """
[riser]
width = 0.03
height = 0.12
[particles]
number = 240
[numerics]
cfd_cells = [3, 12]
dem_cells = [10, 40]
[output]
end_time = 0.8
frame_interval = 0.01
[markov]
columns = 2
rows = 6
lag = 0.01
fit_window = [0.2, 0.5]
predict_window = [0.5, 0.8]
interval_resamples = 20
"""


def _argv(folder: Path) -> list[str]:
    return ["reproduce", "--scale", "quick", "--overrides", str(folder / "tiny.toml"),
            "--velocities", "8", "-o", str(folder / "run"), "--jobs", "1", "-q", "--models",
            "paper", "--ensemble", "2"]


def _build_ensemble(folder: Path) -> None:
    (folder / "tiny.toml").write_text(TINY)
    assert main(_argv(folder)) == 0


@pytest.fixture(scope="session")
def ensemble(tmp_path_factory):
    """(output folder, argv) of a miniature ``reproduce --ensemble 2``, built once per test
    run; this worker's own copy."""
    shared = built_once(tmp_path_factory, "reproduce-ensemble", _build_ensemble)
    folder = worker_copy(tmp_path_factory, shared, "reproduce-ensemble")
    return folder / "run", _argv(folder)


def test_members_are_written_and_the_report_says_n(ensemble):
    out, _ = ensemble
    case = out / "u8"
    assert (case / "cfd-dem-m0.h5").is_file() and (case / "cfd-dem-m1.h5").is_file()
    assert not (case / "cfd-dem.h5").exists()
    assert json.loads((case / "ensemble.json").read_text()) == {"members": 2}
    assert json.loads((out / "reproduce.json").read_text())["ensemble"] == 2
    seeds = member_seeds(json.loads((case / "case.json").read_text())["seed"], 2)
    for m in range(2):
        with Trajectories(case / f"cfd-dem-m{m}.h5") as t:
            assert t.parameters["seed"] == seeds[m]
    timings = json.loads((case / "timings.json").read_text())["cfd_dem"]
    assert timings["ensemble_members"] == 2 and timings["ensemble_device"] == "cpu"
    assert (case / "compare-paper" / "summary.json").is_file()
    assert "CFD-DEM runs per case: 2" in (out / "report.md").read_text()


def test_model_is_the_pooled_fit_of_the_members(ensemble, tmp_path):
    out, _ = ensemble
    case = out / "u8"
    model = MarkovModel.load(case / "model-paper.h5")
    members = [str(case / f"cfd-dem-m{m}.h5") for m in range(2)]
    common = ["--cells", "2x6", "--lag", "0.01", "--window", "0.2:0.5", "--estimator", "paper",
              "--states", "cells", "--no-adequacy", "--resamples", "0", "-q"]
    assert main(["fit", *members, *common, "-o", str(tmp_path / "pooled.h5")]) == 0
    assert main(["fit", members[0], *common, "-o", str(tmp_path / "one.h5")]) == 0
    pooled, one = (MarkovModel.load(tmp_path / f"{x}.h5") for x in ("pooled", "one"))
    assert np.array_equal(model.counts, pooled.counts)
    assert np.array_equal(model.transition_matrix, pooled.transition_matrix)
    assert model.counts.sum() > one.counts.sum()       # both members' transitions


def test_rerun_skips_and_another_n_is_refused(ensemble, capsys):
    out, argv = ensemble
    capsys.readouterr()
    assert main([a for a in argv if a != "-q"]) == 0
    printed = capsys.readouterr().out
    assert "cfd-dem skipped" in printed and "fit-paper skipped" in printed
    other = list(argv)
    other[other.index("--ensemble") + 1] = "3"
    assert main(other) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "2 CFD-DEM run(s) per case, not 3" in err[0]
    assert "--ensemble 2" in err[0]
    assert not (out / "u8" / "cfd-dem-m2.h5").exists()


def test_device_gpu_without_cuda_is_one_line(tmp_path):
    code = "from cfbmarkov.simulate.gpu import gpu_available; assert gpu_available()[0]"
    if subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 0:
        pytest.skip("a CUDA device is usable here")
    assert main(["reproduce", "--scale", "quick", "-o", str(tmp_path / "g"), "--ensemble", "2",
                 "--device", "gpu", "-q"]) == 2
    assert not (tmp_path / "g").exists()


GPU_STAGE = """
import sys
from pathlib import Path
from cfbmarkov.config import load_case
from cfbmarkov.reproduce_case import check_reference
from cfbmarkov.reproduce_ensemble import run_ensemble_cfd_dem
import cfbmarkov.simulate.gpu.riser as gpu_riser
gpu_riser.GPU_DEPOSIT_CHUNKS = 3  # not 256 mostly empty chunks, each a simulated thread
case, folder = load_case(sys.argv[1]), Path(sys.argv[2])
stage, paths = run_ensemble_cfd_dem(case, folder, 2, device="gpu", checkpoint_every=0.0002,
                                    progress=False, check=check_reference)
assert stage == "done" and [p.name for p in paths] == ["cfd-dem-m0.h5", "cfd-dem-m1.h5"]
assert all(p.is_file() for p in paths)
stage, _ = run_ensemble_cfd_dem(case, folder, 2, device="gpu", progress=False,
                                check=check_reference)
assert stage == "skipped", stage
print("ok")
"""

SIM_CASE = """
name = "tiny"
seed = 7
[riser]
width = 0.02
height = 0.04
[particles]
number = 10
[gas]
superficial_velocity = 4.0
[numerics]
cfd_cells = [2, 4]
[output]
end_time = 0.0002
frame_interval = 0.0001
[markov]
lag = 0.0001
fit_window = [0.0, 0.0001]
predict_window = [0.0001, 0.0002]
"""


def test_gpu_cfd_dem_stage_under_the_simulator(tmp_path):
    """The reproduction's CFD-DEM stage with ``device="gpu"`` (the CUDA simulator): the
    members written, then skipped on a rerun after their files are checked."""
    import os

    case = tmp_path / "tiny.toml"
    case.write_text(SIM_CASE)
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    env.setdefault("NUMBA_NUM_THREADS", "1")
    src = str(Path(__file__).resolve().parents[1] / "src")
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, "-c", GPU_STAGE, str(case), str(tmp_path / "u4")],
                          capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0 and "ok" in proc.stdout, proc.stderr[-3000:]
