"""Ensembles (``simulate --ensemble N [--device cpu|gpu]``): member files and seeds, CPU
members equal to single runs of the member cases, the GPU path under the CUDA simulator
(members equal to the CPU's, resume bit for bit) and the one-line error without CUDA."""

import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.config import load_case
from cfbmarkov.errors import InputError
from cfbmarkov.simulate.ensemble import member_case, member_paths, member_seeds
from cfbmarkov.simulate.run import simulate
from cfbmarkov.trajectories import Trajectories

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                   "src")
TINY = """
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
end_time = 0.0005
frame_interval = 0.00025
"""


#: the GPU test's case: two frames of two gas steps each (the simulator runs every GPU
#: thread in Python, so its cost is threads x steps)
TINY_GPU = TINY.replace("end_time = 0.0005", "end_time = 0.0002").replace(
    "frame_interval = 0.00025", "frame_interval = 0.0001")


def _case(tmp_path, text=TINY):
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return path


def _env(**extra):
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("NUMBA_NUM_THREADS", "1")
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    env.update(extra)
    return env


def _arrays(path):
    with Trajectories(path) as t:
        return t.times, t.positions(), t.velocities(), t.laps()


def test_member_seeds_depend_on_the_member_only():
    a, b = member_seeds(7, 2), member_seeds(7, 5)
    assert a == b[:2] and len(set(b)) == 5 and member_seeds(8, 2) != a
    assert [p.name for p in member_paths("d/run.h5", 3)] == ["run-m0.h5", "run-m1.h5", "run-m2.h5"]


def test_cpu_ensemble_members_are_the_member_cases(tmp_path, capsys):
    case = _case(tmp_path)
    assert main(["simulate", str(case), "-o", str(tmp_path / "run.h5"), "--ensemble", "2",
                 "-q"]) == 0
    out = capsys.readouterr().out.split()
    assert out == [str(tmp_path / "run-m0.h5"), str(tmp_path / "run-m1.h5")]
    seeds = member_seeds(7, 2)
    single = simulate(member_case(load_case(case), seeds[1]), tmp_path / "single.h5",
                      progress=False)
    for a, b in zip(_arrays(tmp_path / "run-m1.h5"), _arrays(single)):
        assert np.array_equal(a, b)
    with h5py.File(tmp_path / "run-m0.h5") as f:
        assert json.loads(f.attrs["parameters"])["seed"] == seeds[0]
    assert not np.array_equal(_arrays(tmp_path / "run-m0.h5")[1], _arrays(single)[1])


def test_device_gpu_without_cuda_is_one_line(tmp_path):
    code = ("import sys; from cfbmarkov.simulate.gpu import gpu_available; "
            "sys.exit(0 if gpu_available()[0] else 3)")
    if subprocess.run([sys.executable, "-c", code], env=_env(), timeout=300).returncode == 0:
        import pytest
        pytest.skip("a CUDA device is usable here")
    proc = subprocess.run([sys.executable, "-m", "cfbmarkov", "simulate", str(_case(tmp_path)),
                           "-o", str(tmp_path / "g.h5"), "--ensemble", "2", "--device", "gpu",
                           "-q"], capture_output=True, text=True, env=_env(), timeout=300)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "--device cpu" in proc.stderr
    assert not list(tmp_path.glob("g*"))


GPU_RUN = """
import sys
from pathlib import Path
from cfbmarkov.config import load_case
from cfbmarkov.simulate.ensemble import simulate_ensemble
import cfbmarkov.simulate.gpu.riser as gpu_riser
# 3 deposit chunks of 3 or 4 particles, not the default 256 chunks (mostly empty for 10
# particles, each an idle simulated thread): the same kernels, uneven chunks, a summation
# order other than the CPU's 8 chunks
gpu_riser.GPU_DEPOSIT_CHUNKS = 3
case = load_case(sys.argv[1])
kw = dict(checkpoint_every=0.0001, progress=False, threads=4)
simulate_ensemble(case, sys.argv[2], 2, device="gpu", **kw)
simulate_ensemble(case, sys.argv[3], 2, device="gpu", stop_after_frames=2, **kw)
assert (Path(sys.argv[3] + ".parts") / "gpu-checkpoint.h5").exists()
simulate_ensemble(case, sys.argv[3], 2, device="gpu", resume=True, **kw)
from cfbmarkov.errors import InputError
from cfbmarkov.simulate.gpu.riser import GpuEnsembleRiser
try:  # the grid-synchronised kernel needs a GPU
    GpuEnsembleRiser.initial(case, [1], blocks_per_member=2)
except InputError as exc:
    assert "simulator" in str(exc)
else:
    raise AssertionError("blocks_per_member=2 accepted under the simulator")
import numpy as np
from cfbmarkov.errors import CfbmarkovError
from cfbmarkov.simulate.dem import ContactLaw, SimulationBlowUp
from cfbmarkov.simulate.gpu.ensemble import GpuEnsembleDEM
law = ContactLaw(kn=1000.0, kt=285.7, en=0.9, et=0.5, mu=0.3)
pos = np.array([[[2e-3, 4e-3], [3.05e-3, 4e-3]], [[2e-3, 4e-3], [3.05e-3, 4e-3]]])
vel = np.zeros((2, 2, 2))
vel[1, :, 0] = [30.0, -30.0]   # member 1 collides far too fast for the step
kw = dict(gravity=0.0, time_step=5e-6, skin=1e-4, threads=2)
try:
    GpuEnsembleDEM(pos, vel, 5e-4, 2500.0, law, 8e-3, 8e-3, **kw).step(20)
except SimulationBlowUp as exc:
    assert "member 1" in str(exc) and "overlaps" in str(exc), str(exc)
else:
    raise AssertionError("no blow-up")
try:
    GpuEnsembleDEM(pos, np.zeros((2, 2, 2)), 5e-4, 2500.0, law, 8e-3, 8e-3,
                   max_neighbours=0, **kw).step(1)
except CfbmarkovError as exc:
    assert "neighbours" in str(exc) and "smaller skin" in str(exc), str(exc)
else:
    raise AssertionError("no list overflow")
# bytes moved per gas step, counted on the simulator's copies: as bytes_per_gas_step says
from numba.cuda.simulator.cudadrv import devicearray as da
moved = [0]
to_dev, to_host = da.FakeCUDAArray.copy_to_device, da.FakeCUDAArray.copy_to_host
def counted_to_dev(self, ary, *a, **k):
    moved[0] += np.asarray(ary).nbytes
    return to_dev(self, ary, *a, **k)
def counted_to_host(self, *a, **k):
    out = to_host(self, *a, **k)
    moved[0] += out.nbytes
    return out
da.FakeCUDAArray.copy_to_device, da.FakeCUDAArray.copy_to_host = counted_to_dev, counted_to_host
# device coupling: grid-sized fields only (2 x 4 cells: eps, fv, kv, v 8 values each, fu,
# ku, u 12 each), whatever the particles; host coupling: 48 bytes a particle
riser = GpuEnsembleRiser.initial(case, [1, 2], threads=2)
riser.step()
moved[0] = 0
riser.step()
assert moved[0] == riser.bytes_per_gas_step == 2 * 8 * (4 * 8 + 3 * 12) + 2 * 7 * 8, moved[0]
riser = GpuEnsembleRiser.initial(case, [1, 2], threads=2, coupling="host")
riser.step()
moved[0] = 0
riser.step()
assert moved[0] == riser.bytes_per_gas_step == 2 * 10 * 48 + 2 * 7 * 8, moved[0]
"""


def test_gpu_ensemble_under_the_simulator(tmp_path):
    """Members on the (simulated) GPU equal the CPU members to round-off, and a run stopped
    after its first checkpoint and resumed equals the uninterrupted one bit for bit."""
    case = _case(tmp_path, TINY_GPU)
    proc = subprocess.run([sys.executable, "-c", GPU_RUN, str(case), str(tmp_path / "g.h5"),
                           str(tmp_path / "r.h5")], capture_output=True, text=True,
                          env=_env(NUMBA_ENABLE_CUDASIM="1"), timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert main(["simulate", str(case), "-o", str(tmp_path / "c.h5"), "--ensemble", "2",
                 "-q"]) == 0
    for m in range(2):
        g, c, r = (_arrays(tmp_path / f"{x}-m{m}.h5") for x in "gcr")
        assert np.array_equal(g[0], c[0]) and np.array_equal(g[3], c[3])
        assert np.abs(g[1] - c[1]).max() < 1e-12
        for a, b in zip(g, r):
            assert np.array_equal(a, b)
    assert not (tmp_path / "r.h5.parts").exists()


def test_cpu_ensemble_resumes_the_unfinished_members(tmp_path):
    """Member 0 finished, member 1 stopped after its first checkpoint: ``resume`` keeps
    member 0 as it is and continues member 1 to the file an uninterrupted run writes."""
    from cfbmarkov.simulate.ensemble import simulate_ensemble

    case = load_case(_case(tmp_path))
    full = simulate_ensemble(case, tmp_path / "full.h5", 2, checkpoint_every=0.00025,
                             progress=False)
    seeds = member_seeds(case.seed, 2)
    part = member_paths(tmp_path / "part.h5", 2)
    simulate(member_case(case, seeds[0]), part[0], checkpoint_every=0.00025, progress=False)
    stamp = part[0].stat().st_mtime_ns
    simulate(member_case(case, seeds[1]), part[1], checkpoint_every=0.00025, progress=False,
             stop_after_frames=2)
    assert (part[1].with_name(part[1].name + ".parts") / "checkpoint.h5").exists()
    simulate_ensemble(case, tmp_path / "part.h5", 2, checkpoint_every=0.00025, resume=True,
                      progress=False)
    assert part[0].stat().st_mtime_ns == stamp
    # a resume with no member and no checkpoint (a mistyped -o) starts nothing
    with pytest.raises(InputError, match=r"nothing to resume: none of the 2 members of "):
        simulate_ensemble(case, tmp_path / "typo.h5", 2, resume=True, progress=False)
    assert not list(tmp_path.glob("typo*"))
    for a, b in zip(full, part):
        for x, y in zip(_arrays(a), _arrays(b)):
            assert np.array_equal(x, y)
