"""Simulation benchmarks for ``cfbmarkov bench`` (particle-steps per second, medians).

- ``dem-throughput``: pure DEM, 27000 particles spread over the 0.09 x 0.95 m riser with
  random ~1 m/s velocities, no gravity (the peers' dilute problem; LAMMPS about 4e7 on
  2 MPI ranks here).
- ``dem-throughput-dense``: a settled bed of 27000 particles on a floor, gravity on (LAMMPS
  about 9e6 on one core). The bed is settled once and cached (see
  :func:`cfbmarkov.simulate.dem.bench.settled_bed`).
- ``cfd-dem-throughput``: the coupled CFD-DEM of the paper's case at U = 6 m/s in a
  fluidized state: the state after 0.5 s of simulated time from the initial placement,
  computed once and cached in ``~/.cache/cfbmarkov`` (or ``$CFBMARKOV_CACHE``).

Where LAMMPS is installed (:mod:`cfbmarkov.simulate.dem.lammps`), each DEM line is followed
by LAMMPS's rate on the same problem (``dem-throughput-lammps-Nranks``) and ours over it
(``dem-throughput-over-lammps``); the coupled figure is then also given over LAMMPS's dense
DEM rate (``cfd-dem-throughput-over-lammps-dense``).

DEM steps count as particle-steps (a gas step holds 10 DEM steps); times exclude numba
compilation. Both engines run with a 0.4 mm skin (the cases' default) and each with its own
search grid: ours the automatic one (cells of at least the cutoff, 64 x 678; the cases'
default, ``numerics.dem_cells = "auto"``), LAMMPS its default bins of half the cutoff.
"""

from __future__ import annotations

import statistics
import time
import warnings
from typing import Callable, Iterator

from cfbmarkov.simulate.dem.bench import _cache_dir, make_system


def _dem_rate(state: str, particles: int, repeat: int, steps: int = 300) -> float:
    system = make_system(state, particles, search_cells=None, skin=4e-4)
    system.step(50)
    rates = []
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        system.step(steps)
        rates.append(particles * steps / (time.perf_counter() - t0))
    return statistics.median(rates)


def fluidized_riser(particles: int = 27000, develop: float = 0.5):
    """The paper's U = 6 m/s case after ``develop`` s of simulated time (cached on disk).

    Parameters
    ----------
    particles : int, optional
        Number of particles (the case's 27000 by default).
    develop : float, optional
        Simulated time from the initial placement, s.

    Returns
    -------
    CoupledRiser
        The developed riser, read from ``$CFBMARKOV_CACHE`` or ``~/.cache/cfbmarkov`` when
        computed before.
    """
    from cfbmarkov.config import load_case
    from cfbmarkov.simulate.checkpoint import read_checkpoint, write_checkpoint
    from cfbmarkov.simulate.riser import CoupledRiser

    case = load_case("paper-u6")
    if particles != case.particles.number:
        case = case.model_copy(update={"particles": case.particles.model_copy(
            update={"number": particles})})
    path = _cache_dir() / f"fluidized-u6-{particles}-{develop:g}s.h5"
    if path.exists():
        try:
            return read_checkpoint(path, case)[0]
        except Exception:
            path.unlink()
    riser = CoupledRiser.initial(case)
    steps = int(round(develop / case.numerics.cfd_time_step))
    for _ in range(steps):
        riser.step()
    write_checkpoint(path, riser, 0, 0, 0.0)
    return riser


def _lammps_lines(name: str, state: str, ours: float, particles: int, repeat: int
                  ) -> Iterator[tuple[str, float, str]]:
    """LAMMPS on the same problem and our rate over it, where LAMMPS is installed."""
    import subprocess
    import sys

    from cfbmarkov.simulate.dem.lammps import find_lammps, lammps_throughput

    if find_lammps() is None:
        return
    try:
        rate, ranks = lammps_throughput(state, particles, repeat=repeat)
    except (RuntimeError, OSError, subprocess.SubprocessError) as exc:
        print(f"warning: LAMMPS beside {name} failed: {exc}", file=sys.stderr)
        return
    yield f"{name}-lammps-{ranks}rank{'s' if ranks > 1 else ''}", rate, "particle-steps/s"
    yield f"{name}-over-lammps", ours / rate, "x"


def simulation_benchmarks(repeat: int = 5, particles: int = 27000,
                          wanted: Callable[[str], bool] | None = None
                          ) -> Iterator[tuple[str, float, str]]:
    """The ``dem-*`` and ``cfd-dem-*`` figures (module docstring; docs/performance.md).

    Parameters
    ----------
    repeat : int, optional
        Timed runs per figure (the median is reported).
    particles : int, optional
        Number of particles.
    wanted : callable, optional
        ``wanted(name)`` says whether a figure is asked for (``cfbmarkov bench --only``);
        what no asked figure needs is not run. All figures when None.

    Yields
    ------
    tuple of (str, float, str)
        (name, value, unit): particle-steps/s, or ``'x'`` for the ratio over LAMMPS.
    """
    if wanted is None:
        def wanted(name: str) -> bool:
            return True
    # the coupled run's ratio needs LAMMPS's dense DEM figure
    over = wanted("cfd-dem-throughput-over-lammps-dense")
    lammps_dense = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # the paper's DEM step warning
        for name, state in (("dem-throughput", "dilute"), ("dem-throughput-dense", "dense")):
            if not (wanted(name) or (state == "dense" and over)):
                continue
            ours = _dem_rate(state, particles, repeat)
            if wanted(name):
                yield name, ours, "particle-steps/s"
            for line in _lammps_lines(name, state, ours, particles, repeat):
                if state == "dense" and line[2] == "particle-steps/s":
                    lammps_dense = line[1]
                if wanted(line[0]):
                    yield line
        if not (wanted("cfd-dem-throughput") or over):
            return
        riser = fluidized_riser(particles)
        gas_steps = 50
        riser.step()
        rates = []
        for _ in range(max(1, repeat)):
            t0 = time.perf_counter()
            for _ in range(gas_steps):
                riser.step()
            rates.append(particles * gas_steps * riser.dem_steps_per_cfd
                         / (time.perf_counter() - t0))
        if wanted("cfd-dem-throughput"):
            yield "cfd-dem-throughput", statistics.median(rates), "particle-steps/s"
        if lammps_dense and over:   # the coupled run against LAMMPS's pure dense DEM (issue 15)
            yield ("cfd-dem-throughput-over-lammps-dense", statistics.median(rates) / lammps_dense,
                   "x")
