"""How long a whole ``cfbmarkov reproduce`` (and ``cfbmarkov demo``) has left.

Each case's worker prints its own CFD-DEM progress; the whole run's time left is estimated
by the parent from what the cases leave in their folders: the CFD-DEM's last checkpoint
(``cfd-dem.h5.parts/checkpoint.h5``: simulated time reached and wall time spent), the
finished CFD-DEM (``cfd-dem.h5``) and the wall times of the finished stages
(``timings.json``). Cases not started take the wall time per simulated second and particle
of those measured; the stages after the CFD-DEM (fits, predictions, comparisons) take the
mean of the finished cases'. The cases are then laid on the workers in order, each taking
the first free one (:func:`time_left`).
"""

from __future__ import annotations

import json
import math
import os
import time as _time
from dataclasses import dataclass
from pathlib import Path

from cfbmarkov._console import clock_text

#: seconds between two lines of the whole run's time left
EVERY = 30.0


@dataclass
class CaseState:
    """Where one case stands.

    Attributes
    ----------
    stage : {"waiting", "cfd-dem", "models", "done"}
        Not started, in its CFD-DEM, in its fits/predictions/comparisons, finished.
    simulated : float
        The simulated time it reaches, s.
    particles : int
        Its particles.
    reached : float
        Simulated time reached by its CFD-DEM at its last checkpoint, or at its end once
        finished, s (0 if none).
    wall : float
        Wall time its CFD-DEM had spent then, s.
    since : float
        Wall time since that checkpoint was written, s.
    models_wall : float or None
        Wall time of its stages after the CFD-DEM, s, once finished (else None).
    """

    stage: str
    simulated: float
    particles: int
    reached: float = 0.0
    wall: float = 0.0
    since: float = 0.0
    models_wall: float | None = None


def read_case(folder: str | os.PathLike, simulated: float, particles: int,
              finished: bool) -> CaseState:
    """Where the case in ``folder`` stands, from its files.

    Parameters
    ----------
    folder : str or os.PathLike
        The case's folder (``DIR/u6``).
    simulated : float
        The simulated time its CFD-DEM reaches, s.
    particles : int
        Its particles.
    finished : bool
        Whether its worker has returned.

    Returns
    -------
    CaseState
    """
    folder = Path(folder)
    timings = _read_json(folder / "timings.json")
    post = [v.get("wall_s") for k, v in timings.items()
            if k.split("-")[0] in ("fit", "predict", "compare") and isinstance(v, dict)]
    models_wall = (float(sum(post)) if finished and post
                   and all(isinstance(w, (int, float)) for w in post) else None)
    state = CaseState("done" if finished else "waiting", simulated, particles,
                      models_wall=models_wall)
    cfd = timings.get("cfd_dem")
    if isinstance(cfd, dict):           # a finished CFD-DEM: its pace, for the cases to come
        wall, reached = cfd.get("wall_s"), cfd.get("simulated_s")
        if (isinstance(wall, (int, float)) and isinstance(reached, (int, float))
                and math.isfinite(wall) and math.isfinite(reached) and reached > 0):
            state.reached, state.wall = float(reached), float(wall)
    if finished:
        return state
    if (folder / "cfd-dem.h5").exists():
        state.stage = "models"
        return state
    checkpoint = folder / "cfd-dem.h5.parts" / "checkpoint.h5"
    if not checkpoint.exists():
        state.stage = "cfd-dem" if folder.exists() else "waiting"
        return state
    state.stage = "cfd-dem"
    try:
        import h5py

        with h5py.File(checkpoint, "r") as f:
            history = f["wall_history"][()]
        if history.shape[0] >= 2 and history[-1, 0] > 0:
            state.reached, state.wall = float(history[-1, 0]), float(history[-1, 1])
            state.since = max(_time.time() - checkpoint.stat().st_mtime, 0.0)
    except (OSError, KeyError, ValueError):     # being replaced: the next look reads it
        pass
    return state


def _read_json(path: Path) -> dict:
    try:
        value = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return value if isinstance(value, dict) else {}


def time_left(cases: list[CaseState], jobs: int) -> tuple[float, bool] | None:
    """The whole run's wall time left.

    Parameters
    ----------
    cases : list of CaseState
        Every case, in the order the workers take them.
    jobs : int
        Cases run side by side.

    Returns
    -------
    (float, bool) or None
        The time left (s) and whether it includes the stages after the CFD-DEM (False
        before any case has finished them: the CFD-DEM's alone); None before any CFD-DEM
        has reached its first checkpoint.
    """
    measured = [c for c in cases if c.stage != "waiting" and c.reached > 0 and c.wall > 0]
    if not measured and any(c.stage in ("waiting", "cfd-dem") for c in cases):
        return None
    # wall time per simulated second and particle, from the CFD-DEMs measured
    unit = (sum(c.wall for c in measured) / sum(c.reached * c.particles for c in measured)
            if measured else 0.0)
    finished = [c.models_wall for c in cases if c.models_wall is not None]
    models = sum(finished) / len(finished) if finished else 0.0
    running, waiting = [], []
    for c in cases:
        if c.stage == "done":
            continue
        if c.stage == "models":
            running.append(models / 2)          # half of its stages done, on average
        elif c.stage == "cfd-dem":
            per_s = c.wall / c.reached if c.reached > 0 else unit * c.particles
            running.append(max((c.simulated - c.reached) * per_s - c.since, 0.0) + models)
        else:
            waiting.append(c.simulated * unit * c.particles + models)
    slots = [0.0] * max(jobs, 1)
    for work in running + waiting:      # each on the first free worker, in order
        slots.sort()
        slots[0] += work
    left = max(slots)
    return (left if math.isfinite(left) else math.nan), bool(finished)


def time_left_line(cases: list[CaseState], jobs: int, elapsed: float) -> str | None:
    """One line on the whole run: cases finished, time so far, time left.

    Parameters
    ----------
    cases : list of CaseState
        Every case.
    jobs : int
        Cases run side by side.
    elapsed : float
        Wall time of the run so far, s.

    Returns
    -------
    str or None
        ``whole run: 1 of 4 cases done, 2:10 so far, about 4:20 left``; None where nothing
        can be estimated yet.
    """
    estimate = time_left(cases, jobs)
    if estimate is None:
        return None
    left, with_models = estimate
    done = sum(c.stage == "done" for c in cases)
    tail = (" (then the report)" if with_models or done == len(cases)
            else " for the CFD-DEM alone (then the models and the report)")
    return (f"whole run: {done} of {len(cases)} case(s) done, {clock_text(elapsed)} so far, "
            f"about {clock_text(left)} left{tail}")


__all__ = ["EVERY", "CaseState", "read_case", "time_left", "time_left_line"]
