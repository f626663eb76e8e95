"""Shared fixtures of the importer and trajectory-store tests: generated runs, CSV and dump
writers, the shared real-engine data and a command-line runner."""

from __future__ import annotations

import os

import gzip
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.cli import main

#: /work/shared/data from /work/main/tests/io; CI clones the repo with shared/ beside it
SHARED_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
WIDTH, HEIGHT = 0.09, 0.95


@dataclass
class Run:
    """A generated trajectory: times [T] (s), ids [N] (sorted), positions and velocities
    [T, N, 2] (m, m/s) inside 0..W x 0..H, and the lap counters [T, N] expected from the
    unwrapped heights (floor(y_unwrapped / H), counted from the first frame)."""

    times: np.ndarray
    ids: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    laps: np.ndarray
    unwrapped_y: np.ndarray
    width: float = WIDTH
    height: float = HEIGHT


def generate_run(n_particles: int = 6, n_frames: int = 16, *, t0: float = 0.5,
                 interval: float = 0.025, width: float = WIDTH, height: float = HEIGHT,
                 seed: int = 1) -> Run:
    """Random walks in a periodic-in-y box; particle index 0 (the smallest id) passes up
    through the top, then down through the bottom twice, so its laps go 0 -> +1 -> 0 -> -1."""
    rng = np.random.default_rng(seed)
    times = t0 + interval * np.arange(n_frames)
    ids = np.sort(rng.choice(np.arange(1, 10 * n_particles), n_particles, replace=False))
    # steps of at most 0.1 m on the paper's height, scaled with the height: within the
    # quarter of it that laps from wrapped heights allow
    steps = rng.uniform(-0.1, 0.1, (n_frames - 1, n_particles)) * (height / HEIGHT)
    y0 = rng.uniform(0.05, height - 0.05, n_particles)
    half = (n_frames - 1) // 3
    y0[0] = 0.92 * height
    top = y0[0] + 0.06 * height * half
    down = (top + 0.1 * height) / (n_frames - 1 - half)
    steps[:, 0] = np.r_[np.full(half, 0.06 * height), np.full(n_frames - 1 - half, -down)]
    unwrapped = y0 + np.vstack([np.zeros(n_particles), np.cumsum(steps, axis=0)])
    x = rng.uniform(0.001, width - 0.001, (n_frames, n_particles))
    positions = np.stack([x, np.mod(unwrapped, height)], axis=-1)
    velocities = rng.normal(0.0, 1.0, (n_frames, n_particles, 2))
    floors = np.floor(unwrapped / height).astype(np.int64)
    laps = floors - floors[0]
    assert laps[:, 0].max() == 1 and laps[-1, 0] <= -1, "particle 0 must cross top and bottom"
    return Run(times, ids, positions, velocities, laps, unwrapped, width, height)


def csv_rows(run: Run, columns=("t", "id", "x", "y", "vx", "vy"), *, shuffle: bool = True,
             seed: int = 2) -> str:
    """The run as CSV text with the given column order; rows of a frame in random order."""
    rng = np.random.default_rng(seed)
    fields = {"x": lambda k: run.positions[k, :, 0], "y": lambda k: run.positions[k, :, 1],
              "vx": lambda k: run.velocities[k, :, 0], "vy": lambda k: run.velocities[k, :, 1],
              "t": lambda k: np.full(run.ids.size, run.times[k]), "id": lambda k: run.ids}
    lines = [",".join(columns)]
    for k in range(run.times.size):
        order = rng.permutation(run.ids.size) if shuffle else np.arange(run.ids.size)
        for p in order:
            lines.append(",".join(_number(fields[c](k)[p]) for c in columns))
    return "\n".join(lines) + "\n"


def _number(value) -> str:
    value = value.item() if hasattr(value, "item") else value
    return str(value) if isinstance(value, int) else repr(float(value))


def dump_text(run: Run, *, columns=("id", "type", "x", "y", "z", "vx", "vy", "vz"),
              box=((0.0, WIDTH), (0.0, HEIGHT), (-0.0005, 0.0005)), boundary="ff pp pp",
              with_time: bool = True, units: str | None = "si", time_step: float = 5e-6,
              shuffle: bool = True, trailing_space: bool = False, seed: int = 3) -> str:
    """The run as a LAMMPS dump (box lower corner at ``box[d][0]``).

    Columns x y hold positions + box origin, xs ys fractions of the box, xu yu the unwrapped
    heights (+ origin); velocities vx vy; other columns are filled with zeros or ones.
    """
    rng = np.random.default_rng(seed)
    lo = np.array([box[0][0], box[1][0]])
    length = np.array([box[0][1] - box[0][0], box[1][1] - box[1][0]])
    out = [f"ITEM: UNITS\n{units}\n"] if units else []
    for k, t in enumerate(run.times):
        unwrapped = np.stack([run.positions[k, :, 0], run.unwrapped_y[k]], axis=-1)
        table = {"id": run.ids.astype(float), "type": np.ones(run.ids.size),
                 "x": run.positions[k, :, 0] + lo[0], "y": run.positions[k, :, 1] + lo[1],
                 "xs": run.positions[k, :, 0] / length[0], "ys": run.positions[k, :, 1] / length[1],
                 "xu": unwrapped[:, 0] + lo[0], "yu": unwrapped[:, 1] + lo[1],
                 "vx": run.velocities[k, :, 0], "vy": run.velocities[k, :, 1]}
        order = rng.permutation(run.ids.size) if shuffle else np.arange(run.ids.size)
        if with_time:
            out.append(f"ITEM: TIME\n{_number(t)}\n")
        out.append(f"ITEM: TIMESTEP\n{round(t / time_step)}\nITEM: NUMBER OF ATOMS\n"
                   f"{run.ids.size}\nITEM: BOX BOUNDS {boundary}\n")
        out.extend(f"{a!r} {b!r}\n" for a, b in box)
        out.append(f"ITEM: ATOMS {' '.join(columns)}\n")
        end = " \n" if trailing_space else "\n"
        for p in order:
            values = (table.get(c, np.zeros(run.ids.size))[p] for c in columns)
            out.append(" ".join(_number(int(v) if c == "id" else v)
                                for c, v in zip(columns, values)) + end)
    return "".join(out)


def write_text(path: Path, text: str, gz: bool = False) -> Path:
    """Write text, gzip-compressed when ``gz``."""
    if gz:
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    return path


@pytest.fixture
def run() -> Run:
    return generate_run()


@pytest.fixture
def make_run():
    return generate_run


@pytest.fixture
def make_csv():
    return csv_rows


@pytest.fixture
def make_dump():
    return dump_text


@pytest.fixture
def save():
    return write_text


@pytest.fixture
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        if os.environ.get("CI"):      # CI always has ../shared beside the clone: fail there
            pytest.fail(f"shared data folder {SHARED_DATA} is absent")
        pytest.skip(f"shared data folder {SHARED_DATA} is absent")
    return SHARED_DATA


@pytest.fixture
def cli(capsys):
    """Run ``cfbmarkov ARGS...`` in-process: returns (exit code, stdout, stderr)."""

    def call(*args) -> tuple[int, str, str]:
        code = main([str(a) for a in args])
        captured = capsys.readouterr()
        return code, captured.out, captured.err

    return call


@pytest.fixture
def assert_clean_failure(cli):
    """Run a command that must fail: exit code 2, one stderr line, no traceback, no output
    file and no temporary file left in the output folder."""

    def check(*args, output: Path, match: str | None = None) -> str:
        folder_existed = output.parent.exists()
        code, out, err = cli(*args)
        assert code == 2, (code, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1, err
        assert "Traceback" not in err
        if match is not None:
            import re

            assert re.search(match, lines[0]), (match, lines[0])
        assert not output.exists()
        folder = output.parent
        if folder_existed:
            assert sorted(folder.iterdir()) == [], list(folder.iterdir())
        else:
            assert not folder.exists(), "the failed import left the folder it created"
        return lines[0]

    return check
