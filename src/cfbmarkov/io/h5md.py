"""Importing H5MD files (LAMMPS ``dump h5md``): the HDF5 layout for particle trajectories.

The layout (H5MD 1.0, https://nongnu.org/h5md/h5md.html): a ``/h5md`` group, and per
particle group ``/particles/<group>/`` the time-dependent elements ``position``,
``velocity``, ``image``, ``id`` (each with ``step``, ``time`` and ``value`` of shape
[frames, particles(, dimension)]) and a ``box`` with the attributes ``dimension`` and
``boundary`` (``periodic`` or ``none`` per axis) and its ``edges`` (fixed or time-dependent).

A particle's id is the ``id`` element where the file has one; LAMMPS writes none and orders
the particles by atom id, so particle k is id k + 1 (recorded as such). H5MD gives the box's
edges, not its origin: taken from 0, and a position outside 0..edge is refused with the
advice to give the region. Laps come from the ``image`` flags where present.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.io._common import check_source
from cfbmarkov.io.particle_frames import ParticleFrame, ParticleSeries

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


def h5md_series(source: str | os.PathLike, group: str | None = None,
                time_step: float | None = None) -> ParticleSeries:
    """The frames of an H5MD file.

    Parameters
    ----------
    source : str or os.PathLike
        The ``.h5`` file.
    group : str, optional
        The particle group under ``/particles`` (default: the only one; LAMMPS names it
        after the dump's group, usually ``all``).
    time_step : float, optional
        The simulation time step (s), for a file whose time-dependent elements hold their
        ``step`` but no ``time`` (H5MD makes ``time`` optional): frame k is at step_k x
        time_step. Refused for a file that holds its times.

    Returns
    -------
    ParticleSeries
        Frames read one at a time (the file stays open until the last is read).

    Raises
    ------
    InputError
        If the file is not HDF5 or not H5MD, the group is missing or ambiguous, it has no
        ``position``, its elements disagree in their times or particle counts, a time is
        not finite, or the times are missing without ``time_step`` (or present with it).
    """
    path = check_source(Path(source))
    label = str(path)
    with open(path, "rb") as fh:
        if fh.read(8) != HDF5_MAGIC:
            raise InputError(f"{label}: not an HDF5 file, so not H5MD")
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        cut = "truncated" in str(exc).lower()
        raise InputError(f"{label}: cannot read as HDF5 ("
                         + ("the file is truncated: it ends before the size its header gives; "
                            "copy or write it again" if cut else " ".join(str(exc).split()))
                         + ")") from None
    try:
        with _damaged(label):
            return _series(handle, label, path, group, time_step)
    except BaseException:
        handle.close()
        raise


@contextlib.contextmanager
def _damaged(label: str):
    """HDF5 read failures (a damaged or cut file) as one-line InputErrors."""
    try:
        yield
    except InputError:
        raise                       # the reader's own finding, already one line
    except (OSError, KeyError, RuntimeError, ValueError, TypeError, IndexError) as exc:
        text = " ".join(str(exc).split())[:160]
        raise InputError(f"{label}: damaged HDF5 data ({text})") from None


def _series(f: h5py.File, label: str, path: Path, group: str | None,
            time_step: float | None = None) -> ParticleSeries:
    if "h5md" not in f or "particles" not in f:
        raise InputError(f"{label}: an HDF5 file without the H5MD groups /h5md and /particles "
                         "(not H5MD; a cfbmarkov trajectory file needs no import)")
    groups = sorted(f["particles"])
    if group is None:
        if len(groups) != 1:
            raise InputError(f"{label}: /particles holds the groups {groups}; one is read: "
                             "copy /h5md and the group of the particles to follow into a "
                             "file of their own (h5copy, or h5py's Group.copy) and import "
                             "that")
        group = groups[0]
    if group not in f["particles"]:
        raise InputError(f"{label}: no particle group /particles/{group} (groups: {groups})")
    g = f["particles"][group]
    where = f"{label}:/particles/{group}"
    if "position" not in g:
        raise InputError(f"{where}: no 'position' element")
    position = _element(g["position"], f"{where}/position", time_step=time_step)
    n_frames, n_particles, dimension = position["value"].shape
    if dimension not in (2, 3):
        raise InputError(f"{where}/position: {dimension} components; expected 2 or 3")
    times = position["time"]
    others = {}
    for name in ("velocity", "image", "id"):
        if name in g:
            element = _element(g[name], f"{where}/{name}", fixed_ok=name == "id",
                               time_step=time_step)
            if "time" in element and not np.array_equal(element["time"], times):
                raise InputError(f"{where}/{name}: its times differ from the positions'; every "
                                 "element must be written at the same steps")
            others[name] = element["value"]
    if not np.all(np.isfinite(times)):
        raise InputError(f"{where}/position/time: holds a time that is not finite")
    box, flags = _box(g, where, dimension, times, time_step)
    provenance = {"h5md_group": group,
                  "time_from": ("position/time" if time_step is None else
                                f"position/step x --time-step {time_step:g} s"),
                  "ids_from": "id element" if "id" in others
                  else "particle order (no id element): particle k is id k + 1, as LAMMPS "
                       "orders atoms",
                  "velocity_from": "velocity element" if "velocity" in others else None,
                  "box_from": "box/edges (origin taken at 0)" if box is not None else None,
                  "creator": _creator(f), "time_step": time_step}

    def frames() -> Iterator[ParticleFrame]:
        for k in range(n_frames):
            with _damaged(label):
                frame = _frame(k)
            yield frame

    def _frame(k: int) -> ParticleFrame:
        at = f"{where} frame {k} (step {int(position['step'][k])})"
        pos = _three(np.asarray(position["value"][k], dtype=np.float64))
        ids = (_frame_ids(others["id"], k, at) if "id" in others
               else np.arange(1, n_particles + 1, dtype=np.int64))
        keep = ids >= 0 if "id" in others else slice(None)   # -1 fills unused slots
        vel = (_three(np.asarray(others["velocity"][k], dtype=np.float64))[keep]
               if "velocity" in others else None)
        img = (_three(np.asarray(others["image"][k], dtype=np.int64))[keep]
               if "image" in others else None)
        return ParticleFrame(time=float(times[k]), ids=ids[keep], positions=pos[keep],
                            velocities=vel, image=img,
                            box=None if box is None else box[k], where=at)

    return ParticleSeries(label=label, fmt="h5md", frames=frames(), flags=flags,
                          source_file=path.name, provenance=provenance,
                          box_origin_unknown=box is not None, close=f.close)


def _element(node, where: str, fixed_ok: bool = False, time_step: float | None = None
             ) -> dict:
    """step, time and value of a time-dependent element (or a fixed dataset's value); the
    times from its steps where it has none and ``time_step`` is given."""
    if isinstance(node, h5py.Dataset):
        if not fixed_ok:
            raise InputError(f"{where}: a fixed dataset; expected a time-dependent group with "
                             "step, time and value")
        return {"value": node[()][None, ...]}
    if "value" not in node:
        raise InputError(f"{where}: no 'value' dataset")
    out = {"value": node["value"]}
    if "step" in node:
        out["step"] = np.asarray(node["step"][()]).reshape(-1)
    if "time" in node:
        out["time"] = np.asarray(node["time"][()], dtype=np.float64).reshape(-1)
    if "time" in out and time_step is not None:
        raise InputError(f"{where}: the file holds its times ('time' dataset); leave "
                         "--time-step out")
    if "time" not in out:
        if "step" not in out:
            raise InputError(f"{where}: neither a 'time' nor a 'step' dataset: no frame can "
                             "be dated")
        if time_step is None:
            raise InputError(f"{where}: no 'time' dataset, only the steps: give the "
                             "simulation time step with --time-step (s)")
        out["time"] = out["step"].astype(np.float64) * float(time_step)
    if "step" not in out:
        out["step"] = np.arange(out["time"].size)
    if out["time"].size != out["value"].shape[0] or out["step"].size != out["value"].shape[0]:
        raise InputError(f"{where}: {out['time'].size} times for {out['value'].shape[0]} values")
    return out


def _box(g, where: str, dimension: int, times: np.ndarray, time_step: float | None = None):
    """Per-frame box [lo, hi] of each axis (origin 0, 3 axes), and the boundary flags."""
    if "box" not in g:
        return None, ()
    box = g["box"]
    flags = tuple(v.decode() if isinstance(v, bytes) else str(v)
                  for v in np.asarray(box.attrs.get("boundary", [])).reshape(-1))
    if "edges" not in box:
        return None, flags
    edges = box["edges"]
    if isinstance(edges, h5py.Group):
        element = _element(edges, f"{where}/box/edges",
                           time_step=None if "time" in edges else time_step)
        values = np.asarray(element["value"][()], dtype=np.float64)
        if element["time"].size != times.size or not np.allclose(element["time"], times):
            raise InputError(f"{where}/box/edges: its times differ from the positions'")
    else:
        values = np.broadcast_to(np.asarray(edges[()], dtype=np.float64), (times.size, dimension))
    if values.ndim == 3:                         # edge vectors of a triclinic box
        off = values - values * np.eye(dimension)
        if np.any(off != 0):
            raise InputError(f"{where}/box/edges: a triclinic box; give the riser with --region")
        values = np.einsum("tii->ti", values)
    hi = np.zeros((times.size, 3))
    hi[:, :dimension] = values
    if dimension == 2:
        hi[:, 2] = 1.0
    return np.stack([np.zeros_like(hi), hi], axis=2), flags


def _three(values: np.ndarray) -> np.ndarray:
    """(N, 2) -> (N, 3) with z = 0."""
    if values.ndim == 2 and values.shape[1] == 2:
        return np.column_stack([values, np.zeros(values.shape[0], dtype=values.dtype)])
    return values


def _frame_ids(values, k: int, where: str) -> np.ndarray:
    row = np.asarray(values[min(k, values.shape[0] - 1)])
    if row.dtype.kind == "f":
        if not np.all(np.isfinite(row) & (row == np.round(row))):
            raise InputError(f"{where}: an id is not a whole number")
    return row.astype(np.int64).reshape(-1)


def _creator(f: h5py.File) -> str | None:
    node = f["h5md"].get("creator")
    if node is None:
        return None
    name = node.attrs.get("name", "")
    version = node.attrs.get("version", "")
    text = " ".join(v.decode() if isinstance(v, bytes) else str(v) for v in (name, version))
    return text.strip() or None
