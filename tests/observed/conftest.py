"""Fixtures of the observed-quantity and analysis tests: small generated riser runs written as
trajectory files (paths in tmp_path), and a generator of such runs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from cfbmarkov.trajectory_format import PassEvents
from cfbmarkov.trajectory_writer import write_trajectories

WIDTH, HEIGHT = 0.09, 0.95


@dataclass
class Run:
    times: np.ndarray          # [T] s
    positions: np.ndarray      # [T, N, 2] m, inside 0..W x 0..H
    unwrapped_y: np.ndarray    # [T, N] m


def generate_run(n_particles: int = 80, t0: float = 0.0, t1: float = 3.0, dt: float = 0.025,
                 seed: int = 0, rise: float = 1.6, spread: float = 0.02,
                 lateral: float = 0.004, initial: np.ndarray | None = None) -> Run:
    """Particles rising at about ``rise`` m/s with a random walk on top (``spread`` m per frame
    vertically, ``lateral`` m sideways, reflected at the walls), periodic in y; ``initial``
    [N, 2] (m) fixes the first frame."""
    rng = np.random.default_rng(seed)
    n_frames = round((t1 - t0) / dt) + 1
    times = t0 + dt * np.arange(n_frames)
    speeds = rise * rng.uniform(0.6, 1.4, n_particles)
    dy = speeds * dt + rng.normal(0.0, spread, (n_frames - 1, n_particles))
    x0, y0 = rng.uniform(0.0, WIDTH, n_particles), rng.uniform(0.0, HEIGHT, n_particles)
    if initial is not None:
        x0, y0 = initial[:, 0].copy(), initial[:, 1].copy()
    y = y0 + np.vstack([np.zeros(n_particles),
                                                           np.cumsum(dy, axis=0)])
    x = x0 + np.vstack(
        [np.zeros(n_particles), np.cumsum(rng.normal(0.0, lateral, (n_frames - 1, n_particles)),
                                          axis=0)])
    x = np.abs(np.mod(x, 2 * WIDTH))                 # reflect at both walls
    x = np.where(x > WIDTH, 2 * WIDTH - x, x)
    positions = np.stack([x, np.mod(y, HEIGHT)], axis=-1)
    return Run(times, positions, y)


@pytest.fixture
def make_run():
    return generate_run


@pytest.fixture
def write_run():
    """write_run(path, run, **kwargs): the run as a trajectory file (laps from positions)."""

    def _write(path, run: Run, **kwargs):
        return write_trajectories(path, run.times, run.positions, width=WIDTH, height=HEIGHT,
                                  **kwargs)

    return _write


@pytest.fixture
def pair(tmp_path):
    """(reference, prediction) files over 0-3 s with the same 80 particle ids; the prediction
    starts from the reference's frame at 0.5 s and says it came from a 6-column model."""
    ref = generate_run(seed=1)
    pred = generate_run(seed=2, rise=1.3, t0=0.5, initial=ref.positions[20])
    ref_path = write_trajectories(tmp_path / "reference.h5", ref.times, ref.positions,
                                  width=WIDTH, height=HEIGHT, source="cfd-dem")
    pred_path = write_trajectories(tmp_path / "prediction.h5", pred.times, pred.positions,
                                   width=WIDTH, height=HEIGHT, source="markov-prediction",
                                   parameters={"columns": 6, "rows": 38})
    return ref_path, pred_path


@pytest.fixture
def events_of():
    """events_of(run): exact pass events of a run from its unwrapped heights, at the times
    where linear interpolation between frames crosses a multiple of H."""

    def _events(run: Run) -> PassEvents:
        t, y = run.times, run.unwrapped_y
        times, particles, directions = [], [], []
        for p in range(y.shape[1]):
            level = np.floor(y[:, p] / HEIGHT)
            for k in np.flatnonzero(np.diff(level) != 0):
                step = int(level[k + 1] - level[k])
                for n in range(abs(step)):
                    boundary = (level[k] + (n + 1 if step > 0 else -n)) * HEIGHT
                    frac = (boundary - y[k, p]) / (y[k + 1, p] - y[k, p])
                    times.append(t[k] + frac * (t[k + 1] - t[k]))
                    particles.append(p)
                    directions.append(1 if step > 0 else -1)
        return PassEvents(np.array(times), np.array(particles), np.array(directions))

    return _events
