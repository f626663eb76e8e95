"""The GPU check: throughput of the GPU DEM against particle count, DEM alone and coupled,
the CPU path beside it, and the physics checks on the GPU itself.

    python benchmarks/gpu.py [--quick] [--json OUT.json] [--steps N] [--threads T]

Full run (a CUDA GPU; about 10 minutes on one): particle-steps/s of the DEM alone for one
paper riser (27 000 particles, dilute benchmark state of ``cfbmarkov bench``), an ensemble
of 10 of them, one riser of 270 000 and one of 2.7 million particles (the riser made taller
at the same area fraction), each also as the launches of a coupled run go (10 DEM steps a
call); the coupled riser (paper case) for 1 and 10 members, with the coupling on the device
and on the host; the CPU engine on the same
27 000-particle state and the CPU coupled riser, with numba's threads; then the checks of
:mod:`cfbmarkov.simulate.gpu.checks` (round-off agreement with the CPU over the first 1000
steps of 2000 particles, restitution, bed weight, independent members, checkpoint round
trip, coupled agreement). Prints a table and writes JSON (default ``gpu-check.json``).

``--quick``: tiny sizes, a few steps: runs in a minute under the CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``), to prove the script works where there is no GPU. Its rates
mean nothing.

Exit status: 0 when every check passed, 1 when one failed, 2 when no CUDA device is usable.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings

import numba
import numpy as np

from cfbmarkov.config import CaseConfig
from cfbmarkov.simulate.dem import ContactLaw, DEMSystem
from cfbmarkov.simulate.dem.bench import DENSITY, DIAMETER, DT, HEIGHT, WIDTH
from cfbmarkov.simulate.dem.bench import _random_sequential_addition
from cfbmarkov.simulate.gpu import checks, gpu_available, simulator
from cfbmarkov.simulate.riser import CoupledRiser

PAPER = 27000


def _state(n, seed=0):
    """The dilute benchmark state of ``cfbmarkov bench`` for n particles: the riser's height
    scaled by n / 27000 (area fraction 0.25)."""
    height = HEIGHT * max(1.0, n / PAPER)
    pos = _random_sequential_addition(n, WIDTH, height, DIAMETER, seed)
    if pos[-1, 0] < 0:
        raise SystemExit(f"{n} particles do not fit in the riser")
    rng = np.random.default_rng(seed)
    return pos, rng.normal(0.0, math.sqrt(0.5), (n, 2)), height


def _law():
    return ContactLaw.from_config(CaseConfig().contact, DIAMETER, DENSITY)


def dem_rate_gpu(members, n, steps, per_call, threads, blocks=1):
    """GPU particle-steps/s: ``steps`` steps in calls of ``per_call`` steps, ``blocks`` thread
    blocks per member."""
    from cfbmarkov.simulate.gpu.ensemble import GpuEnsembleDEM
    states = [_state(n, seed) for seed in range(members)]
    height = states[0][2]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dem = GpuEnsembleDEM(np.stack([s[0] for s in states]), np.stack([s[1] for s in states]),
                             0.5 * DIAMETER, DENSITY, _law(), WIDTH, height, gravity=0.0,
                             time_step=DT, skin=3e-4, threads=threads,
                             blocks_per_member=blocks)
    dem.step(per_call)  # compilation, first list build
    t = time.perf_counter()
    done = 0
    while done < steps:
        dem.step(per_call)
        done += per_call
    return members * n * done / (time.perf_counter() - t)


def dem_rate_cpu(n, steps):
    pos, vel, height = _state(n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dem = DEMSystem(pos, vel, 0.5 * DIAMETER, DENSITY, _law(), WIDTH, height, gravity=0.0,
                        time_step=DT, search_cells=None, skin=3e-4)
    dem.step(10)
    t = time.perf_counter()
    dem.step(steps)
    return n * steps / (time.perf_counter() - t)


def _case(quick):
    if quick:
        return CaseConfig.model_validate({
            "seed": 5, "riser": {"width": 0.02, "height": 0.04}, "particles": {"number": 30},
            "gas": {"superficial_velocity": 4.0}, "numerics": {"cfd_cells": [2, 4]}})
    return CaseConfig()


def coupled_rate(members, gas_steps, quick, threads, device, blocks=1, coupling="device"):
    """Coupled particle-steps/s (DEM steps x particles) over ``gas_steps`` gas steps
    (``coupling``: the GPU riser's, device or host)."""
    case = _case(quick)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if device == "gpu":
            from cfbmarkov.simulate.gpu.riser import GpuEnsembleRiser
            riser = GpuEnsembleRiser.initial(case, range(case.seed, case.seed + members),
                                             threads=threads, blocks_per_member=blocks,
                                             coupling=coupling)
        else:
            riser = CoupledRiser.initial(case)
    riser.step()
    riser.host_gas_seconds = 0.0
    t = time.perf_counter()
    for _ in range(gas_steps):
        riser.step()
    wall = time.perf_counter() - t
    rate = members * case.particles.number * gas_steps * riser.dem_steps_per_cfd / wall
    extra = {}
    if device == "gpu":
        extra["bytes_per_gas_step"] = riser.bytes_per_gas_step
        if coupling == "device":  # the share of the wall time in the host's gas solves
            extra["host_gas_fraction"] = riser.host_gas_seconds / wall
    return rate, extra


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny sizes (the CUDA simulator)")
    ap.add_argument("--json", default="gpu-check.json", help="JSON output file")
    ap.add_argument("--steps", type=int, default=None, help="timed DEM steps per size")
    ap.add_argument("--threads", type=int, default=None, help="GPU threads per member")
    args = ap.parse_args(argv)
    ok, reason = gpu_available()
    if not ok:
        print(f"benchmarks/gpu.py: {reason}; run it on a machine with an NVIDIA GPU, or with "
              f"NUMBA_ENABLE_CUDASIM=1 --quick to check the script", file=sys.stderr)
        return 2
    from cfbmarkov.simulate.gpu._cuda import cuda
    quick = args.quick
    steps = args.steps or (20 if quick else 1000)
    sizes = [(1, 40), (2, 40)] if quick else [(1, PAPER), (10, PAPER), (1, 10 * PAPER),
                                              (1, 100 * PAPER)]
    device = "CUDA simulator" if simulator() else cuda.get_current_device().name
    if isinstance(device, bytes):
        device = device.decode()
    report = {"device": str(device), "numba_threads": numba.get_num_threads(), "quick": quick,
              "dem": [], "coupled": [], "checks": {}}
    rows = []
    # the grid-synchronised kernel: one block of `threads` per SM in all (always resident)
    sms = 1 if quick else cuda.get_current_device().MULTIPROCESSOR_COUNT
    for members, n in sizes:
        grid = max(1, sms // members)
        for per_call, blocks in dict.fromkeys(((steps, 1), (10, 1), (steps, grid), (10, grid))):
            try:
                rate = dem_rate_gpu(members, n, steps, per_call, args.threads, blocks)
            except Exception as exc:  # e.g. out of device memory at 2.7 million
                rate = None
                print(f"  {members} x {n}, {per_call} steps a call, {blocks} blocks a member: "
                      f"{type(exc).__name__}: {exc}", file=sys.stderr)
            report["dem"].append({"device": "gpu", "members": members, "particles": n,
                                  "steps_per_call": per_call, "blocks_per_member": blocks,
                                  "particle_steps_per_s": rate})
            rows.append((f"DEM gpu {members} x {n}", f"{per_call} st/call {blocks} bl/memb",
                         rate))
    cpu_n = 40 if quick else PAPER
    rate = dem_rate_cpu(cpu_n, steps if quick else 300)
    report["dem"].append({"device": "cpu", "members": 1, "particles": cpu_n,
                          "particle_steps_per_s": rate})
    rows.append((f"DEM cpu 1 x {cpu_n}", f"{numba.get_num_threads()} threads", rate))
    gas_steps = 2 if quick else 50
    for members in ((1, 2) if quick else (1, 10)):
        runs = [(b, "device") for b in dict.fromkeys((1, max(1, sms // members)))]
        for blocks, coupling in runs + [(1, "host")]:
            try:
                rate, extra = coupled_rate(members, gas_steps, quick, args.threads, "gpu", blocks,
                                           coupling)
            except Exception as exc:
                rate, extra = None, {}
                print(f"  coupled, {members} members, {blocks} blocks a member, {coupling} "
                      f"coupling: {type(exc).__name__}: {exc}", file=sys.stderr)
            report["coupled"].append({"device": "gpu", "members": members, **extra,
                                      "blocks_per_member": blocks, "coupling": coupling,
                                      "particle_steps_per_s": rate})
            gas = extra.get("host_gas_fraction")
            rows.append((f"coupled gpu {members} member(s)", f"{blocks} bl/memb, {coupling} "
                         f"coupling, {extra.get('bytes_per_gas_step', '?')} B/gas st"
                         + ("" if gas is None else f", host gas {100 * gas:.0f} %"), rate))
    rate, _ = coupled_rate(1, gas_steps, quick, None, "cpu")
    report["coupled"].append({"device": "cpu", "members": 1, "particle_steps_per_s": rate})
    rows.append(("coupled cpu 1 member", f"{numba.get_num_threads()} threads", rate))
    kw = {"threads": args.threads}
    report["checks"]["dem_vs_cpu"] = (checks.dem_vs_cpu(**kw) if quick else
                                      checks.dem_vs_cpu(n=2000, steps=1000, width=0.03,
                                                        height=0.2, speed=0.5, **kw))
    for name in ("restitution", "bed_weight", "members_independent", "state_roundtrip",
                 "coupled_vs_cpu"):
        report["checks"][name] = checks.CHECKS[name](**kw)
    print(f"GPU check on {report['device']} ({'quick' if quick else 'full'}; "
          f"CPU with {report['numba_threads']} threads)")
    print(f"{'run':34s} {'':58s} {'particle-steps/s':>16s}")
    for name, how, rate in rows:
        print(f"{name:34s} {how:58s} {('%.3g' % rate) if rate else 'failed':>16s}")
    for name, r in report["checks"].items():
        print(f"check {name}: {'ok' if r['ok'] else 'FAILED'} "
              + json.dumps({k: v for k, v in r.items() if k != 'ok'}))
    with open(args.json, "w") as f:
        json.dump(report, f, indent=1)
    print(f"written {args.json}")
    return 0 if all(r["ok"] for r in report["checks"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
