"""The GPU backend (cfbmarkov.simulate.gpu) under the CUDA simulator: tiny systems, against
the CPU engine.

``NUMBA_ENABLE_CUDASIM`` is read when ``numba.cuda`` is first imported, so the checks
(:mod:`cfbmarkov.simulate.gpu.checks`) run in one subprocess with it set; this process and
the rest of the suite never import ``numba.cuda``.
"""

import json
import os
import subprocess
import sys

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")


def _env(**extra):
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("NUMBA_NUM_THREADS", "1")
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    env.update(extra)
    return env


@pytest.fixture(scope="session")
def checks():
    proc = subprocess.run([sys.executable, "-m", "cfbmarkov.simulate.gpu.checks", "--threads", "4"],
                          capture_output=True, text=True, env=_env(NUMBA_ENABLE_CUDASIM="1"),
                          timeout=600)
    assert proc.stdout.strip(), proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_dem_agrees_with_cpu_to_round_off(checks):
    r = checks["dem_vs_cpu"]
    assert r["contacts"] > 0 and r["events"] > 0  # the check exercises contacts and passes
    assert r["position"] < 1e-12 and r["position"] <= 100 * r["cpu_one_ulp"]
    assert r["velocity"] < 1e-9
    assert r["laps_equal"] and r["events_equal"] and r["event_time"] < 1e-15


def test_head_on_impacts_rebound_with_the_restitution_coefficient(checks):
    r = checks["restitution"]
    assert abs(r["pair"] - r["en"]) < 0.02
    assert abs(r["wall"] - r["en"]) < 0.02
    assert r["cpu_difference"] < 1e-12


def test_settled_bed_weighs_on_the_floor(checks):
    r = checks["bed_weight"]
    assert abs(r["floor_force"] / r["weight"] - 1.0) < 0.01


def test_members_are_independent(checks):
    r = checks["members_independent"]
    assert r["identical"] and r["members_differ"]


def test_state_continues_bit_for_bit(checks):
    r = checks["state_roundtrip"]
    assert r["events"] > 0  # a pass event is pending in the saved state
    assert r["identical"] and r["events_identical"]


def test_coupled_riser_agrees_with_cpu(checks):
    r = checks["coupled_vs_cpu"]
    assert r["members_differ"]
    # the device coupling (256 chunks): the CPU's to round-off
    assert r["position"] < 1e-12 and r["gas_velocity"] < 1e-9
    # with the CPU's 8 chunks the simulator adds the same terms in the same order
    assert r["position_cpu_chunks"] == 0.0 and r["gas_velocity_cpu_chunks"] == 0.0
    assert r["position_host"] < 1e-12 and r["gas_velocity_host"] < 1e-9
    # two members, 2 x 4 cells: grid-sized fields only (device), 48 bytes a particle (host)
    assert r["bytes_per_gas_step"] == 2 * (8 * (4 * 8 + 3 * 12) + 7 * 8)
    assert r["bytes_per_gas_step_host"] == 2 * (30 * 48 + 7 * 8)


def test_package_imports_without_numba_cuda():
    code = ("import sys, cfbmarkov.simulate.gpu, cfbmarkov.cli; "
            "assert 'numba.cuda' not in sys.modules, 'numba.cuda imported'")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=_env(), timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_coupling_kernels_compile_for_a_gpu_where_libnvvm_is_present():
    """numba-cuda types and lowers the coupling kernels, the CPU's scalar functions called
    as device functions included, to PTX for sm_90 (libNVVM only, no GPU needed)."""
    code = ("import json; from cfbmarkov.simulate.gpu.coupling import compile_ptx; "
            "print(json.dumps(compile_ptx((9, 0))))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=_env(), timeout=600)
    if proc.returncode != 0 and ("NVVM" in proc.stderr or "nvvm" in proc.stderr):
        pytest.skip("no libNVVM here: " + proc.stderr.strip().splitlines()[-1][:200])
    assert proc.returncode == 0, proc.stderr[-3000:]
    sizes = json.loads(proc.stdout.strip().splitlines()[-1])
    assert set(sizes) == {"solid_chunks", "void_fraction", "drag_at_old_gas", "drag_chunks",
                          "face_sums", "drag_at_new_gas"}
    assert all(v > 1000 for v in sizes.values())
