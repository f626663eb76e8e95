"""LAMMPS beside our DEM on the same problem (optional: only where LAMMPS is installed).

``cfbmarkov bench`` runs the peer named in the issue, LAMMPS ``pair_style gran/hooke/history``
in 2D, on exactly the particles of its ``dem-throughput`` and ``dem-throughput-dense``
problems (same positions, velocities, spins, contact law, time step and neighbour skin),
and prints its rate and ours over it. LAMMPS is found as

* ``$CFBMARKOV_LAMMPS`` (the executable), else ``lmp``, ``lmp_serial`` or ``lmp_mpi`` beside
  the running Python or on the PATH (Debian's ``lammps`` package installs ``lmp``; so does
  the PyPI wheel, ``pip install cfbmarkov[peers]``, which brings ``mpich`` for its MPI);
* MPI ranks: ``$CFBMARKOV_LAMMPS_RANKS`` (default 2 where an ``mpirun``/``mpiexec`` sits
  beside the executable or on the PATH, else 1), launched by ``$CFBMARKOV_MPIRUN`` or that
  launcher.

The contact law is translated to LAMMPS's parameters: ``Kn = kn``, ``Kt = kt``, and the
damping ``gamma = eta / m_eff`` (LAMMPS multiplies its gamma by the reduced mass, ours is
``c sqrt(m_eff)``) at the particle-particle reduced mass m/2; the walls use the same gamma
(LAMMPS's convention, so their damping ratio differs from ours by sqrt(2), which does not
change the cost). Particles are spheres (``atom_style sphere`` in 2D gives the sphere mass,
and ``fix nve/sphere`` the sphere inertia), as ours. With more than one rank the domain
is split by ``balance`` so that each holds an equal share of the particles (without it the
settled bed, low in the tall riser, would sit on one rank). The rate is atoms x steps over the
"Loop time" LAMMPS reports for each timed ``run`` (median), after a warm-up run.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from cfbmarkov.simulate.dem.law import ContactLaw

_LOOP = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms")


def _g(value) -> str:
    """A number as LAMMPS reads it, exactly."""
    return f"{float(value):.17g}"


def find_lammps() -> str | None:
    """Path of the LAMMPS executable, or None."""
    env = os.environ.get("CFBMARKOV_LAMMPS")
    if env:
        return env if Path(env).exists() or shutil.which(env) else None
    here = Path(sys.executable).parent
    for name in ("lmp", "lmp_serial", "lmp_mpi"):
        if (here / name).exists():
            return str(here / name)
    for name in ("lmp", "lmp_serial", "lmp_mpi"):
        found = shutil.which(name)
        if found:
            return found
    return None


def mpi_launcher(executable: str) -> str | None:
    """``$CFBMARKOV_MPIRUN``, else an ``mpirun``/``mpiexec`` beside the executable or on the
    PATH (None where there is none)."""
    env = os.environ.get("CFBMARKOV_MPIRUN")
    if env:
        return env
    here = Path(executable).resolve().parent
    for name in ("mpirun", "mpiexec"):
        if (here / name).exists():
            return str(here / name)
    for name in ("mpirun", "mpiexec"):
        found = shutil.which(name)
        if found:
            return found
    return None


def lammps_parameters(law: ContactLaw, mass: float) -> tuple[float, float, float, float, float]:
    """(Kn, Kt, gamma_n, gamma_t, xmu) of ``gran/hooke/history`` for our law and particle
    mass (kg): gamma = eta(m_eff) / m_eff at m_eff = m / 2."""
    m_eff = 0.5 * mass
    return (law.kn, law.kt, law.normal_damping(m_eff) / m_eff,
            law.tangential_damping(m_eff) / m_eff, law.mu)


def write_problem(directory: Path, positions, velocities, angular_velocities, radius: float,
                  density: float, law: ContactLaw, width: float, height: float,
                  time_step: float, skin: float, gravity: float, floor: bool,
                  warmup: int, steps: int, repeat: int, final_dump: bool = False) -> Path:
    """The data file and input script of one problem; returns the input script's path.
    ``final_dump``: write the particles at the end to ``final.dump`` (id, x, y, vx, vy,
    omegaz, full precision)."""
    positions = np.asarray(positions, dtype=np.float64)
    velocities = np.asarray(velocities, dtype=np.float64)
    spins = (np.zeros(len(positions)) if angular_velocities is None
             else np.asarray(angular_velocities, dtype=np.float64).reshape(-1))
    n = len(positions)
    d = 2.0 * radius
    mass = density * math.pi * d**3 / 6.0
    kn, kt, gn, gt, mu = lammps_parameters(law, mass)
    top = height if not floor else max(height, float(positions[:, 1].max()) + 10 * d)
    lines = ["cfbmarkov benchmark problem", "", f"{n} atoms", "1 atom types", "",
             f"0 {_g(width)} xlo xhi", f"0 {_g(top)} ylo yhi",
             f"{_g(-radius)} {_g(radius)} zlo zhi", "", "Atoms # sphere", ""]
    ids = np.arange(1, n + 1)
    lines += [f"{i} 1 {_g(d)} {_g(density)} {_g(x)} {_g(y)} 0"
              for i, (x, y) in zip(ids, positions)]
    lines += ["", "Velocities", ""]
    lines += [f"{i} {_g(vx)} {_g(vy)} 0 0 0 {_g(w)}"
              for i, (vx, vy), w in zip(ids, velocities, spins)]
    directory = Path(directory)
    (directory / "problem.data").write_text("\n".join(lines) + "\n")
    gran = f"hooke/history {_g(kn)} {_g(kt)} {_g(gn)} {_g(gt)} {_g(mu)} 1"
    script = [
        "units si", "dimension 2", "atom_style sphere",
        f"boundary f {'f' if floor else 'p'} p", "comm_modify vel yes",
        "read_data problem.data",
        "balance 1.0 shift xy 20 1.0",      # the settled bed fills only the bottom
        f"pair_style gran/{gran}", "pair_coeff * *",
        f"neighbor {_g(skin)} bin", "neigh_modify delay 0 every 1 check yes",
        f"timestep {_g(time_step)}",
        "fix integrate all nve/sphere",
        "fix plane all enforce2d",
        f"fix side_walls all wall/gran {gran} xplane 0.0 {_g(width)}",
    ]
    if floor:
        script.append(f"fix floor all wall/gran {gran} yplane 0.0 NULL")
    if gravity:
        script.append(f"fix weight all gravity {_g(gravity)} vector 0 -1 0")
    script += ["thermo 0", f"run {int(warmup)}"]
    script += [f"run {int(steps)}"] * max(1, int(repeat))
    if final_dump:
        script.append("write_dump all custom final.dump id x y vx vy omegaz "
                      "modify sort id format float %.17g")
    path = directory / "in.problem"
    path.write_text("\n".join(script) + "\n")
    return path


def run_lammps(script: Path, executable: str, ranks: int = 1, timeout: float = 600.0
               ) -> list[tuple[float, int, int]]:
    """Run an input script; returns (loop seconds, steps, atoms) for every ``run``."""
    cmd = [executable, "-in", script.name, "-log", "log.lammps", "-screen", "none"]
    if ranks > 1:
        launcher = mpi_launcher(executable)
        if launcher is None:
            raise RuntimeError("no mpirun/mpiexec for more than one LAMMPS rank")
        cmd = [launcher, "-np", str(int(ranks))] + cmd
    done = subprocess.run(cmd, cwd=script.parent, capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "OMP_NUM_THREADS": "1"})
    log = script.parent / "log.lammps"
    text = log.read_text() if log.exists() else ""
    if done.returncode != 0:
        tail = (text or done.stderr or done.stdout).strip().splitlines()[-3:]
        raise RuntimeError(f"LAMMPS failed (exit {done.returncode}): {' / '.join(tail)}")
    return [(float(t), int(s), int(a)) for t, _, s, a in _LOOP.findall(text)]


def lammps_throughput(state: str = "dilute", n_particles: int = 27000, steps: int = 300,
                      repeat: int = 5, ranks: int | None = None, skin: float = 4e-4,
                      executable: str | None = None, warmup: int = 50) -> tuple[float, int]:
    """Median particle-steps/s of LAMMPS on our ``state`` problem (see
    :func:`cfbmarkov.simulate.dem.bench.make_system`), and the ranks it ran on."""
    from cfbmarkov.simulate.dem import bench

    executable = executable or find_lammps()
    if executable is None:
        raise RuntimeError("LAMMPS not found (set CFBMARKOV_LAMMPS or put lmp on the PATH)")
    if ranks is None:
        env = os.environ.get("CFBMARKOV_LAMMPS_RANKS")
        ranks = int(env) if env else (2 if mpi_launcher(executable) else 1)
    if state == "dilute":
        pos, vel = bench.dilute_state(n_particles)
        spins, gravity, floor = None, 0.0, False
    elif state == "dense":
        bed = bench.settled_bed(n_particles)
        pos, vel, spins = bed["positions"], bed["velocities"], bed["angular_velocities"]
        gravity, floor = 9.81, True
    else:
        raise ValueError(f"state must be 'dilute' or 'dense', got {state!r}")
    with tempfile.TemporaryDirectory(prefix="cfbmarkov-lammps-") as tmp:
        script = write_problem(Path(tmp), pos, vel, spins, bench.DIAMETER / 2, bench.DENSITY,
                               ContactLaw(), bench.WIDTH, bench.HEIGHT, bench.DT, skin,
                               gravity, floor, warmup, steps, repeat)
        runs = run_lammps(script, executable, ranks)
    timed = runs[1:]
    if not timed:
        raise RuntimeError("LAMMPS reported no timed run")
    return statistics.median(a * s / t for t, s, a in timed), ranks


def lammps_final_state(positions, velocities, angular_velocities, steps: int, *,
                       radius: float = 5e-4, density: float = 2600.0,
                       law: ContactLaw | None = None, width: float = 0.09,
                       height: float = 0.95, time_step: float = 5e-6, skin: float = 3e-4,
                       gravity: float = 0.0, floor: bool = False,
                       executable: str | None = None) -> dict[str, np.ndarray]:
    """Run ``steps`` LAMMPS steps of the given particles (one rank) and return their
    ``positions`` [N, 2], ``velocities`` [N, 2] and ``angular_velocities`` [N] at the end:
    the same problem a :class:`~cfbmarkov.simulate.dem.DEMSystem` is given, for a side-by-side
    check of the two engines."""
    executable = executable or find_lammps()
    if executable is None:
        raise RuntimeError("LAMMPS not found (set CFBMARKOV_LAMMPS or put lmp on the PATH)")
    with tempfile.TemporaryDirectory(prefix="cfbmarkov-lammps-") as tmp:
        script = write_problem(Path(tmp), positions, velocities, angular_velocities, radius,
                               density, law or ContactLaw(), width, height, time_step, skin,
                               gravity, floor, 0, steps, 1, final_dump=True)
        run_lammps(script, executable, 1)
        rows = np.loadtxt(Path(tmp) / "final.dump", skiprows=9, ndmin=2)
    rows = rows[np.argsort(rows[:, 0])]
    return {"positions": rows[:, 1:3], "velocities": rows[:, 3:5],
            "angular_velocities": rows[:, 5]}
