"""Physics and agreement checks of the GPU DEM, on whatever ``numba.cuda`` runs here (a GPU,
or the CUDA simulator with ``NUMBA_ENABLE_CUDASIM=1``).

Each check returns a dict of measured values and ``ok``; the test suite runs them on tiny
systems under the simulator (tests/test_gpu.py) and ``benchmarks/gpu.py`` on a GPU.
``python -m cfbmarkov.simulate.gpu.checks`` prints them all as JSON.
"""

from __future__ import annotations

import json
import math
import sys
import warnings

import numpy as np

from cfbmarkov.simulate.coupling import place_without_overlap
from cfbmarkov.simulate.dem import ContactLaw, DEMSystem
from cfbmarkov.simulate.gpu.ensemble import GpuEnsembleDEM

D = 1e-3
RHO = 2500.0
LAW = ContactLaw(kn=1000.0, kt=285.7, en=0.9, et=0.5, mu=0.3)
DT = 5e-6


def _pair(a, b):
    """Largest absolute difference of two arrays (0 for empty ones)."""
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) if np.size(a) else 0.0


def _flow(n, width, height, seed, speed=1.0):
    rng = np.random.default_rng(seed)
    pos = place_without_overlap(n, D, width, height, seed)
    # all moved up (modulo H: no distance changes) so that the highest is 0.02 d below
    # the top, which it passes moving up
    pos[:, 1] = np.mod(pos[:, 1] + (height - 0.02 * D - pos[:, 1].max()), height)
    vel = rng.normal(0.0, speed, (n, 2))
    vel[np.argmax(pos[:, 1]), 1] = 2.0
    vel[np.argmin(pos[:, 1]), 1] = -2.0
    return pos, vel, rng.normal(0.0, 200.0, n)


def dem_vs_cpu(n=24, steps=80, width=6e-3, height=8e-3, seed=1, threads=None, tol=1e-12,
               speed=1.0):
    """A periodic flow with collisions, wall contacts and passes through the top and bottom:
    GPU and CPU positions, velocities, spins, laps and pass events after ``steps`` steps.

    Round-off: the flow amplifies any difference (collisions are chaotic), so the GPU is
    held against the flow's own amplification: a second CPU run whose x coordinates start
    one ulp apart (``cpu_one_ulp``, the largest position difference it reaches). ``ok``
    when the GPU's largest position difference is below ``max(tol, 100 * cpu_one_ulp)`` m
    and laps and pass events agree. ``speed``: the particles' velocity scale, m/s (the
    approach speed of a collision must stay below about 4 m/s, where its overlap reaches the
    blow-up limit)."""
    pos, vel, om = _flow(n, width, height, seed, speed)
    kw = dict(gravity=9.81, time_step=DT, skin=1e-4)
    cpu = DEMSystem(pos, vel, 0.5 * D, RHO, LAW, width, height, search_cells=None,
                    angular_velocities=om, **kw)
    ulp = DEMSystem(np.stack([np.nextafter(pos[:, 0], np.inf), pos[:, 1]], axis=1), vel,
                    0.5 * D, RHO, LAW, width, height, search_cells=None,
                    angular_velocities=om, **kw)
    gpu = GpuEnsembleDEM(pos[None], vel[None], 0.5 * D, RHO, LAW, width, height,
                         angular_velocities=om[None], threads=threads, **kw)
    cpu.step(steps)
    ulp.step(steps)
    gpu.step(steps)
    et_c, ep_c, ed_c = cpu.drain_pass_events()
    et_g, ep_g, ed_g = gpu.drain_pass_events(0)
    o = np.lexsort((ep_c, et_c))
    same_events = (et_c.size == et_g.size and np.array_equal(ep_c[o], ep_g)
                   and np.array_equal(ed_c[o], ed_g))
    out = {"particles": n, "steps": steps,
           "position": _pair(cpu.positions, gpu.positions[0]),
           "cpu_one_ulp": _pair(cpu.positions, ulp.positions),
           "velocity": _pair(cpu.velocities, gpu.velocities[0]),
           "spin": _pair(cpu.angular_velocities, gpu.angular_velocities[0]),
           "laps_equal": bool(np.array_equal(cpu.laps, gpu.laps[0])),
           "events": int(et_c.size), "events_equal": bool(same_events),
           "event_time": _pair(et_c[o], et_g) if same_events else None,
           "contacts": int(cpu.overlaps().size)}
    out["ok"] = (out["position"] < max(tol, 100.0 * out["cpu_one_ulp"]) and out["laps_equal"]
                 and same_events)
    return out


def restitution(threads=None, tol=0.02):
    """Head-on impacts without gravity or friction: two particles approaching at 1 m/s, and a
    particle hitting the left wall at 0.5 m/s. The rebound-to-approach speed ratio of a
    linear spring-dashpot contact is ``en`` (here 0.9; the step resolves the contact in
    about 16 steps). ``ok`` when both are within ``tol`` of ``en`` and GPU and CPU agree to
    1e-12."""
    law = ContactLaw(kn=LAW.kn, kt=LAW.kt, en=LAW.en, et=LAW.et, mu=0.0)
    w, h = 8e-3, 8e-3
    pos = np.array([[[3.0e-3, 4e-3], [4.05e-3, 4e-3]], [[0.55e-3, 4e-3], [6.0e-3, 6e-3]]])
    vel = np.array([[[0.5, 0.0], [-0.5, 0.0]], [[-0.5, 0.0], [0.0, 0.0]]])
    kw = dict(gravity=0.0, time_step=DT, skin=1e-4)
    gpu = GpuEnsembleDEM(pos, vel, 0.5 * D, RHO, law, w, h, threads=threads, **kw)
    gpu.step(60)
    v = gpu.velocities
    e_pair = (v[0, 1, 0] - v[0, 0, 0]) / 1.0
    e_wall = v[1, 0, 0] / 0.5
    cpu = [DEMSystem(pos[k], vel[k], 0.5 * D, RHO, law, w, h, search_cells=None, **kw)
           for k in range(2)]
    for c in cpu:
        c.step(60)
    diff = max(_pair(cpu[k].velocities, v[k]) for k in range(2))
    return {"pair": float(e_pair), "wall": float(e_wall), "en": law.en, "cpu_difference": diff,
            "ok": abs(e_pair - law.en) < tol and abs(e_wall - law.en) < tol and diff < 1e-12}


def bed_weight(threads=None, steps=200, tol=0.01):
    """A hexagonal bed of 4 + 3 particles at rest on the floor, in a box exactly 4 diameters
    wide:
    after ``steps`` steps the floor carries the bed's weight (the sum of kn * overlap over
    the floor contacts, which the dashpot no longer changes once the bed is still). ``ok``
    when within ``tol`` of m g N."""
    law = ContactLaw(kn=LAW.kn, kt=LAW.kt, en=0.3, et=0.3, mu=0.3)
    r = 0.5 * D
    pos = np.array([[(2 * c + 1 + (k % 2)) * r, r + k * math.sqrt(3.0) * r]
                    for k in range(2) for c in range(4 - (k % 2))])
    n = pos.shape[0]
    gpu = GpuEnsembleDEM(pos[None], np.zeros((1, n, 2)), r, RHO, law, 4 * D, 10 * D,
                         gravity=9.81, time_step=DT, skin=1e-4, bottom_wall=True,
                         threads=threads)
    gpu.step(steps)
    y = gpu.positions[0, :, 1]
    floor = float(np.sum(law.kn * np.maximum(r - y, 0.0)))
    mass = RHO * math.pi * D**3 / 6
    weight = n * mass * 9.81
    return {"particles": n, "floor_force": floor, "weight": weight,
            "ok": abs(floor / weight - 1.0) < tol}


def members_independent(n=12, steps=40, threads=None):
    """Two members of different seeds side by side, and member 1 alone: member 1's positions
    and velocities must be the same bits either way (``ok``)."""
    w, h = 6e-3, 8e-3
    a, b = _flow(n, w, h, 2), _flow(n, w, h, 3)
    kw = dict(gravity=9.81, time_step=DT, skin=1e-4, threads=threads)
    both = GpuEnsembleDEM(np.stack([a[0], b[0]]), np.stack([a[1], b[1]]), 0.5 * D, RHO, LAW,
                          w, h, angular_velocities=np.stack([a[2], b[2]]), **kw)
    alone = GpuEnsembleDEM(b[0][None], b[1][None], 0.5 * D, RHO, LAW, w, h,
                           angular_velocities=b[2][None], **kw)
    both.step(steps)
    alone.step(steps)
    same = (np.array_equal(both.positions[1], alone.positions[0])
            and np.array_equal(both.velocities[1], alone.velocities[0]))
    differ = not np.array_equal(both.positions[0], both.positions[1])
    return {"identical": bool(same), "members_differ": bool(differ), "ok": bool(same and differ)}


def state_roundtrip(n=12, steps=20, threads=None):
    """An ensemble saved by ``state()`` after ``steps`` steps and rebuilt by ``from_state()``
    continues with the same bits as the original (``ok``), pass events included."""
    w, h = 6e-3, 8e-3
    a = _flow(n, w, h, 4)
    kw = dict(gravity=9.81, time_step=DT, skin=1e-4, threads=threads)
    one = GpuEnsembleDEM(a[0][None], a[1][None], 0.5 * D, RHO, LAW, w, h,
                         angular_velocities=a[2][None], **kw)
    one.step(steps)
    two = GpuEnsembleDEM.from_state(one.state(), threads=threads)
    one.step(steps)
    two.step(steps)
    same = (np.array_equal(one.positions, two.positions)
            and np.array_equal(one.velocities, two.velocities)
            and np.array_equal(one.laps, two.laps))
    e1, e2 = one.drain_pass_events(0), two.drain_pass_events(0)
    same_events = all(np.array_equal(x, y) for x, y in zip(e1, e2))
    return {"identical": bool(same), "events": int(e1[0].size),
            "events_identical": bool(same_events), "ok": bool(same and same_events)}


def coupled_vs_cpu(gas_steps=5, threads=None, tol=1e-12):
    """Two small coupled risers (30 particles, 2 x 4 gas cells, seeds 5 and 6) as one GPU
    ensemble against :class:`~cfbmarkov.simulate.riser.CoupledRiser` of each seed after
    ``gas_steps`` gas steps (positions and gas velocities, the largest difference over both
    members; ``ok`` below ``tol`` and 1e-9 m/s), for the device coupling with its default
    chunks (``position``, ``gas_velocity``), with the CPU's 8 chunks (``*_cpu_chunks``: the
    CPU's sums term for term) and for the host coupling (``*_host``)."""
    from cfbmarkov.config import CaseConfig
    from cfbmarkov.simulate.cfd.coupling import DEPOSIT_CHUNKS
    from cfbmarkov.simulate.gpu.riser import GpuEnsembleRiser
    from cfbmarkov.simulate.riser import CoupledRiser
    case = CaseConfig.model_validate({
        "seed": 5, "riser": {"width": 0.02, "height": 0.04}, "particles": {"number": 30},
        "gas": {"superficial_velocity": 4.0}, "numerics": {"cfd_cells": [2, 4]}})
    seeds = [5, 6]
    variants = {"": {}, "_cpu_chunks": {"deposit_chunks": DEPOSIT_CHUNKS},
                "_host": {"coupling": "host"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cpus = [CoupledRiser.initial(case.model_copy(update={"seed": s})) for s in seeds]
        gpus = {k: GpuEnsembleRiser.initial(case, seeds, threads=threads, **kw)
                for k, kw in variants.items()}
    for _ in range(gas_steps):
        for r in cpus + list(gpus.values()):
            r.step()
    out = {"gas_steps": gas_steps}
    for k, gpu in gpus.items():
        out["position" + k] = max(_pair(c.dem.positions, gpu.dem.positions[m])
                                  for m, c in enumerate(cpus))
        out["gas_velocity" + k] = max(max(_pair(c.gas.u, gpu.gases[m].u),
                                          _pair(c.gas.v, gpu.gases[m].v))
                                      for m, c in enumerate(cpus))
        out["bytes_per_gas_step" + k] = gpu.bytes_per_gas_step
    out["members_differ"] = _pair(gpus[""].dem.positions[0], gpus[""].dem.positions[1]) > 0
    out["ok"] = (all(out["position" + k] < tol and out["gas_velocity" + k] < 1e-9
                     for k in variants) and out["members_differ"])
    return out


CHECKS = {"dem_vs_cpu": dem_vs_cpu, "restitution": restitution, "bed_weight": bed_weight,
          "members_independent": members_independent, "state_roundtrip": state_roundtrip,
          "coupled_vs_cpu": coupled_vs_cpu}


def main(argv=None) -> int:
    """Run the checks named in ``argv`` (all by default) and print their results as JSON."""
    args = list(argv if argv is not None else sys.argv[1:])
    threads = None
    if args[:1] == ["--threads"]:
        threads, args = int(args[1]), args[2:]
    out = {name: CHECKS[name](threads=threads) for name in (args or list(CHECKS))}
    print(json.dumps(out))
    return 0 if all(r["ok"] for r in out.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
