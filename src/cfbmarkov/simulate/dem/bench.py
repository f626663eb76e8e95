"""Throughput benchmark of the DEM engine on the paper's riser (particle-steps per second).

``dem_throughput("dilute")``: N particles (default 27000, d = 1 mm, paper's contact law and
step 5e-6 s) placed at random without overlap (random sequential addition) over the
0.09 x 0.95 m riser (area fraction 0.25), random Gaussian velocities of 1 m/s RMS speed, no
gravity, y periodic.

``dem_throughput("dense")``: the same particles as a bed settled under gravity on a floor
(``bottom_wall=True``; without gas nothing else could carry it). Settling starts from a loose
jittered square lattice (spacing 1.1 d) and runs with a strongly damped law (en = et = 0.3)
until the kinetic energy is small; the settled state is cached (``np.savez``) in
``$CFBMARKOV_CACHE`` or ``~/.cache/cfbmarkov`` (``tempfile.gettempdir()`` when that is not
writable), keyed by particle number, seed and format, so later runs start at once. The timed
run then uses the paper's law (en = 0.97), gravity on.

Timing: ``warmup`` steps first (compilation, first list builds), then ``steps`` steps timed
with ``time.perf_counter``; the result is N * steps / seconds. Threads: whatever numba is
set to (``numba.set_num_threads``). ``search_cells`` defaults to the automatic grid (cells of
at least the search cutoff: 69 x 730 here), as the cases use it (LAMMPS, the peer, bins by
half its cutoff of its own accord); ``skin`` to 0.3 mm, the skin the peer runs with.

Measured on the 2-core development machine (medians of 5 x 300 steps, other jobs running
now and then), particle-steps/s:

=====================  ==========  ==========  ==========  ==========
configuration          dilute 1T   dilute 2T   dense 1T    dense 2T
=====================  ==========  ==========  ==========  ==========
30 x 351, skin 0.3 mm  3.8e7       7.2e7-8.0e7 1.9e7       3.9e7-4.0e7
auto grid, 0.3 mm      4.1e7       9.1e7       2.0e7       4.1e7
30 x 351, skin 0.4 mm  3.9e7       8.7e7       1.9e7       4.0e7
=====================  ==========  ==========  ==========  ==========

In the dilute case about a third of the time goes into list rebuilds (every ~8 steps: the
fastest of 27000 particles, ~3.5 m/s, covers skin/2 in 8-9 steps); the auto grid
(``search_cells=None``: 69 x 730 cells of 1.3 mm) or a 0.4 mm skin make them cheaper/rarer.

Run ``python -m cfbmarkov.simulate.dem.bench [dilute|dense]`` for a table of 1 and all threads.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from numba import njit

import cfbmarkov  # noqa: F401  (sets the OpenMP threading layer before numba compiles)
from cfbmarkov.simulate.dem.law import ContactLaw
from cfbmarkov.simulate.dem.system import DEMSystem

WIDTH, HEIGHT = 0.09, 0.95
DIAMETER, DENSITY = 1e-3, 2600.0
DT = 5e-6
CACHE_FORMAT = 2


def _quiet_system(*args, **kwargs) -> DEMSystem:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the paper's step gives ~5.2 steps per contact
        return DEMSystem(*args, **kwargs)


@njit(cache=True)
def _random_sequential_addition(n, width, height, d, seed):
    """n non-overlapping discs of diameter d placed uniformly at random one after the other
    (y periodic), a random hard-disc gas; -1 rows if they did not fit."""
    np.random.seed(seed)
    ncx = int(width / d)
    ncy = int(height / d)
    cw = width / ncx
    ch = height / ncy
    head = -np.ones(ncx * ncy, np.int64)
    nxt = -np.ones(n, np.int64)
    pos = -np.ones((n, 2))
    placed = 0
    tries = 0
    while placed < n and tries < 1000 * n:
        tries += 1
        x = d / 2 + np.random.random() * (width - d)
        y = np.random.random() * height
        ix = min(int(x / cw), ncx - 1)
        iy = min(int(y / ch), ncy - 1)
        ok = True
        for dyc in range(-1, 2):
            row = (iy + dyc) % ncy
            for dxc in range(-1, 2):
                col = ix + dxc
                if col < 0 or col >= ncx:
                    continue
                j = head[row * ncx + col]
                while j >= 0:
                    dx = pos[j, 0] - x
                    dy = pos[j, 1] - y
                    dy -= height * np.round(dy / height)
                    if dx * dx + dy * dy < d * d:
                        ok = False
                        break
                    j = nxt[j]
                if not ok:
                    break
            if not ok:
                break
        if ok:
            pos[placed, 0] = x
            pos[placed, 1] = y
            c = iy * ncx + ix
            nxt[placed] = head[c]
            head[c] = placed
            placed += 1
    return pos


def dilute_state(n_particles=27000, seed=0):
    """Positions (random sequential addition: a random hard-disc gas, area fraction 0.25 for
    27000 particles) and velocities (Gaussian, 1 m/s RMS speed) of the dilute benchmark."""
    pos = _random_sequential_addition(n_particles, WIDTH, HEIGHT, DIAMETER, seed)
    if pos[-1, 0] < 0:
        raise ValueError(f"{n_particles} particles do not fit dilutely in the riser")
    rng = np.random.default_rng(seed)
    vel = rng.normal(0.0, math.sqrt(0.5), (n_particles, 2))
    return pos, vel


def _cache_dir() -> Path:
    env = os.environ.get("CFBMARKOV_CACHE")
    for cand in ([Path(env)] if env else []) + [Path.home() / ".cache" / "cfbmarkov",
                                                Path(tempfile.gettempdir()) / "cfbmarkov-cache"]:
        try:
            cand.mkdir(parents=True, exist_ok=True)
            if os.access(cand, os.W_OK):
                return cand
        except OSError:
            continue
    raise OSError("no writable cache directory")


def settled_bed(n_particles=27000, seed=0, verbose=False) -> dict:
    """Positions, velocities, angular velocities of a bed settled on a floor (cached)."""
    path = _cache_dir() / f"dem-settled-bed-n{n_particles}-s{seed}-v{CACHE_FORMAT}.npz"
    if path.exists():
        with np.load(path) as f:
            return {k: f[k] for k in f.files}
    rng = np.random.default_rng(seed)
    sp = 1.1 * DIAMETER
    ncol = int(WIDTH / sp)
    nrow = math.ceil(n_particles / ncol)
    if (nrow + 1) * sp > HEIGHT:
        raise ValueError(f"{n_particles} particles do not fit in the riser as a loose lattice")
    ix, iy = np.meshgrid(np.arange(ncol), np.arange(nrow))
    x0 = (WIDTH - ncol * sp) / 2 + (ix.ravel()[:n_particles] + 0.5) * sp
    y0 = (iy.ravel()[:n_particles] + 0.5) * sp
    jit = 0.04 * DIAMETER
    pos = np.column_stack([x0 + rng.uniform(-jit, jit, n_particles),
                           y0 + rng.uniform(-jit, jit, n_particles)])
    vel = rng.normal(0.0, 0.05, (n_particles, 2))
    law = ContactLaw(en=0.3, et=0.3, mu=0.1)
    sysm = _quiet_system(pos, vel, DIAMETER / 2, DENSITY, law, WIDTH, HEIGHT, gravity=9.81,
                         time_step=DT, search_cells=(30, 351), skin=3e-4, bottom_wall=True)
    m = sysm.mass[0]
    t0 = time.perf_counter()
    for block in range(400):
        sysm.step(500)
        ke = sysm.kinetic_energy() / (n_particles * m)  # per unit mass, m^2/s^2
        if verbose:
            print(f"settling t = {sysm.time:.3f} s, ke/m = {ke:.3e}, "
                  f"{time.perf_counter() - t0:.1f} s wall")
        if block >= 60 and ke < 1e-6:
            break
    out = {"positions": sysm.positions, "velocities": sysm.velocities,
           "angular_velocities": sysm.angular_velocities}
    tmp = path.with_suffix(f".tmp{os.getpid()}.npz")
    np.savez(tmp, **out)
    os.replace(tmp, path)
    return out


def make_system(state="dilute", n_particles=27000, seed=0, search_cells=None,
                skin=3e-4) -> DEMSystem:
    law = ContactLaw()  # paper's Table 2 values
    if state == "dilute":
        pos, vel = dilute_state(n_particles, seed)
        return _quiet_system(pos, vel, DIAMETER / 2, DENSITY, law, WIDTH, HEIGHT, gravity=0.0,
                             time_step=DT, search_cells=search_cells, skin=skin)
    if state == "dense":
        bed = settled_bed(n_particles, seed)
        return _quiet_system(bed["positions"], bed["velocities"], DIAMETER / 2, DENSITY, law,
                             WIDTH, HEIGHT, gravity=9.81, time_step=DT,
                             search_cells=search_cells, skin=skin,
                             angular_velocities=bed["angular_velocities"], bottom_wall=True)
    raise ValueError(f"state must be 'dilute' or 'dense', got {state!r}")


def dem_throughput(state="dilute", n_particles=27000, steps=400, seed=0, warmup=50,
                   repeats=1, search_cells=None, skin=3e-4) -> float:
    """Particle-steps per second of ``steps`` DEM steps after ``warmup`` steps (the best of
    ``repeats`` timed blocks run one after the other)."""
    sysm = make_system(state, n_particles, seed, search_cells, skin)
    sysm.step(warmup)
    best = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        sysm.step(steps)
        wall = time.perf_counter() - t0
        best = max(best, n_particles * steps / wall)
    return best


if __name__ == "__main__":  # pragma: no cover
    import sys

    import numba

    which = sys.argv[1:] or ["dilute", "dense"]
    for threads in sorted({1, numba.config.NUMBA_NUM_THREADS}):
        numba.set_num_threads(threads)
        for st in which:
            runs = [dem_throughput(st, steps=300) for _ in range(5)]
            print(f"{st:7s} threads={threads}: median {np.median(runs):.3g} particle-steps/s "
                  f"(min {min(runs):.3g}, max {max(runs):.3g})")
