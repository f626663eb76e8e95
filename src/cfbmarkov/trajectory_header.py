"""What a trajectory file holds besides its frames: the format and version, particle ids
and frame times, the domain, the boundary, the axes, the producer and the frame interval;
checked when a file is written (:func:`header_attrs`) and read and checked when it is
opened (:func:`read_header`; ``docs/definitions.md``, File formats, What is checked).

No frame is read here; frames are checked as they are read (:mod:`cfbmarkov.trajectories`).
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from cfbmarkov._hdf5 import json_default, package_version
from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import InputError
from cfbmarkov.trajectory_format import (FORMAT, FRAME_SPACING_TOLERANCE, VERSION,
                                         estimate_frame_interval, time_text)


@dataclass(frozen=True)
class TrajectoryHeader:
    """The checked metadata of a trajectory file (the attributes of
    :class:`~cfbmarkov.trajectories.Trajectories` of the same names).

    Attributes
    ----------
    version : int
        The layout version (1 or 2).
    ids : ndarray of int64, shape (N,)
        Particle ids.
    times : ndarray of float64, shape (T,)
        Frame times (s), finite, increasing and evenly spaced.
    dimensions : int
        D, 2 or 3.
    width, height : float
        The riser W x H (m).
    depth : float or None
        The depth (m) in 3D; None in 2D.
    boundary : Boundary
        The vertical boundary.
    axes : dict of str to str
        The source's axis letter of each stored axis.
    region_origin : ndarray of float64, shape (D,)
        Source coordinates (m) of the stored origin.
    source : str
        What produced the file.
    parameters : dict
        The producer's parameters.
    frame_interval : float
        Time between frames (s); NaN for one frame without the attribute.
    """

    version: int
    ids: np.ndarray
    times: np.ndarray
    dimensions: int
    width: float
    height: float
    depth: float | None
    boundary: Boundary
    axes: dict[str, str]
    region_origin: np.ndarray
    source: str
    parameters: dict[str, Any]
    frame_interval: float


def header_attrs(*, width: float, height: float, depth: float | None,
                 boundary: str | Boundary, axes: dict[str, str] | None, region_origin,
                 source: str, parameters: dict[str, Any] | None,
                 frame_interval: float | None) -> dict[str, Any]:
    """The root attributes of a trajectory file about to be written, checked.

    Parameters
    ----------
    width, height : float
        The riser W x H (m), positive.
    depth : float or None
        The depth (m) of a 3D file; None in 2D.
    boundary : Boundary or {"periodic", "open"}
        The vertical boundary.
    axes : dict or None
        The source's axis letter of each stored axis (default x, y (, z)).
    region_origin : array_like of float, shape (D,), or None
        Source coordinates (m) of the stored origin (default zeros).
    source : str
        What produces the file.
    parameters : dict or None
        The producer's parameters (stored as JSON).
    frame_interval : float or None
        Time between frames (s); None: estimated when the file is closed (not stored here).

    Returns
    -------
    dict
        Attribute name -> value, with the creation time and the package's version.

    Raises
    ------
    InputError
        If the domain is not of positive size, the boundary is unknown, ``frame_interval``
        is not a positive number, or the origin has not D coordinates.
    """
    from cfbmarkov.limits import check_finite

    width = check_finite(width, "width", "m")
    height = check_finite(height, "height", "m")
    depth = None if depth is None else check_finite(depth, "depth", "m")
    if not (width > 0 and height > 0) or (depth is not None and not depth > 0):
        size = f"{width:g} x {height:g}" + ("" if depth is None else f" x {depth:g}")
        raise InputError(f"domain {size} m must have positive size")
    boundary = Boundary.parse(boundary, "boundary")
    if frame_interval is not None and not (np.isfinite(frame_interval) and frame_interval > 0):
        raise InputError(f"frame interval {frame_interval!r} s must be a positive number")
    d = 2 if depth is None else 3
    axes = dict(axes or {})
    origin = np.zeros(d) if region_origin is None else np.asarray(
        region_origin, dtype=np.float64).reshape(-1)
    if origin.size != d:
        raise InputError(f"region origin {origin.tolist()} needs {d} coordinates")
    attrs = {
        "format": FORMAT, "version": VERSION, "width": float(width), "height": float(height),
        "dimensions": d, "boundary": boundary.value, "across_axis": axes.get("across", "x"),
        "vertical_axis": axes.get("vertical", "y"),
        "depth_axis": axes.get("depth", "z") if d == 3 else "", "region_origin": origin,
        "length_unit": "m", "time_unit": "s", "source": source,
        "parameters": json.dumps(parameters or {}, default=json_default),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "cfbmarkov_version": package_version(),
    }
    if depth is not None:
        attrs["depth"] = float(depth)
    if frame_interval is not None:
        attrs["frame_interval"] = float(frame_interval)
    return attrs


def read_header(f: h5py.File, path: Path) -> TrajectoryHeader:
    """Read and check the metadata of an open trajectory file (no frame is read).

    Parameters
    ----------
    f : h5py.File
        The open file.
    path : pathlib.Path
        Its path, for messages.

    Returns
    -------
    TrajectoryHeader

    Raises
    ------
    InputError
        If the file is a model file, not a trajectory file, of a newer layout version,
        damaged (datasets missing, of mismatched shapes or types, attributes out of range,
        frame times not finite, not increasing or unevenly spaced) or holds no frames.
    KeyError, OSError, ValueError, TypeError
        Where h5py cannot read what the layout names (the caller reports a damaged file).
    """
    fmt = f.attrs.get("format")
    if isinstance(fmt, bytes):
        fmt = fmt.decode()
    if fmt != FORMAT:
        if fmt == "cfbmarkov.model":
            raise InputError(f"{path}: a cfbmarkov model file, not a trajectory file; give "
                             "a trajectory file (a run, an imported file or a prediction), "
                             "such as the one `cfbmarkov info MODEL` names as the source")
        raise InputError(f"{path}: not a cfbmarkov trajectory file "
                         + (f"(format attribute is {fmt!r})" if fmt else "(no 'format' attribute)"))
    version = _whole_attr(f.attrs.get("version", 1), "version", path)
    if version > VERSION:
        raise InputError(f"{path}: trajectory file of layout version {version}, written by a "
                         f"newer cfbmarkov (this one reads up to {VERSION}); upgrade cfbmarkov")
    for name in ("particles/id", "frames/time", "frames/position", "frames/lap"):
        if name not in f:
            raise InputError(f"{path}: damaged trajectory file (no '{name}' dataset)")
    ids = f["particles/id"][()]
    times = f["frames/time"][()]
    dimensions = _whole_attr(f.attrs.get("dimensions", 2), "dimensions", path)
    n, t, d = ids.size, times.size, dimensions
    if d not in (2, 3):
        raise InputError(f"{path}: damaged trajectory file (dimensions {d})")
    if f["frames/position"].shape != (t, n, d) or f["frames/lap"].shape != (t, n) or (
            "frames/present" in f and f["frames/present"].shape != (t, n)):
        raise InputError(f"{path}: damaged trajectory file (frame arrays do not match "
                         f"{t} times x {n} particles x {d} coordinates)")
    if t == 0:
        raise InputError(f"{path}: trajectory file holds no frames")
    _check_arrays(f, path, ids, times)
    width = _length_attr(f, path, "width")
    height = _length_attr(f, path, "height")
    depth = _length_attr(f, path, "depth") if d == 3 else None
    boundary = f.attrs.get("boundary", "periodic")
    boundary = boundary.decode() if isinstance(boundary, bytes) else str(boundary)
    try:
        boundary = Boundary(boundary)
    except ValueError:
        raise InputError(f"{path}: damaged trajectory file (boundary {boundary!r})") from None
    axes = {key: str(f.attrs.get(f"{key}_axis", default)) for key, default in
            (("across", "x"), ("vertical", "y"), ("depth", "z" if d == 3 else ""))}
    region_origin = np.asarray(f.attrs.get("region_origin", np.zeros(d)), dtype=np.float64)
    if region_origin.shape != (d,) or not np.all(np.isfinite(region_origin)):
        raise InputError(f"{path}: damaged trajectory file (region_origin "
                         f"{region_origin.tolist()} is not {d} finite numbers)")
    source = str(f.attrs.get("source", "unknown"))
    try:
        parameters: dict[str, Any] = json.loads(f.attrs.get("parameters", "{}"))
    except (ValueError, TypeError):
        raise InputError(f"{path}: damaged trajectory file (the 'parameters' attribute "
                         "is not JSON)") from None
    if "frame_interval" in f.attrs:
        frame_interval = _float_attr(f.attrs["frame_interval"])
        if not (np.isfinite(frame_interval) and frame_interval > 0):
            raise InputError(f"{path}: damaged trajectory file (frame_interval "
                             f"{_attribute_text(f.attrs['frame_interval'])} is not a positive "
                             "number of s)")
    else:
        frame_interval = estimate_frame_interval(times)
    _check_times(path, times, frame_interval)
    return TrajectoryHeader(version, ids, times, dimensions, width, height, depth, boundary,
                            axes, region_origin, source, parameters, frame_interval)


def _length_attr(f: h5py.File, path: Path, name: str) -> float:
    """A positive length attribute (m)."""
    if name not in f.attrs:
        raise InputError(f"{path}: damaged trajectory file (no '{name}' attribute)")
    value = _float_attr(f.attrs[name])
    if not (np.isfinite(value) and value > 0):
        shown = repr(f.attrs[name]) if np.isnan(value) else f"{value:g}"
        raise InputError(f"{path}: damaged trajectory file ({name} {shown} is not a "
                         "positive length in m)")
    return value


def _check_arrays(f: h5py.File, path: Path, ids: np.ndarray, times: np.ndarray) -> None:
    """Types of the datasets and unique ids (cheap: no frame is read)."""
    kinds = {"particles/id": "iu", "frames/time": "f", "frames/position": "f",
             "frames/lap": "iu", "frames/present": "b", "frames/velocity": "f"}
    for name, kind in kinds.items():
        if name in f and (not isinstance(f[name], h5py.Dataset) or f[name].dtype.kind not in kind):
            wanted = ("whole numbers" if kind == "iu" else "booleans" if kind == "b"
                      else "numbers")
            raise InputError(f"{path}: damaged trajectory file ('{name}' holds "
                             f"{getattr(f[name], 'dtype', 'a group')}, not {wanted})")
    if ids.ndim != 1 or times.ndim != 1:
        raise InputError(f"{path}: damaged trajectory file (ids or times are not 1-D)")
    if "frames/velocity" in f and f["frames/velocity"].shape != f["frames/position"].shape:
        raise InputError(f"{path}: damaged trajectory file (velocities of shape "
                         f"{f['frames/velocity'].shape}, positions {f['frames/position'].shape})")
    if np.unique(ids).size != ids.size:
        srt = np.sort(ids)
        raise InputError(f"{path}: damaged trajectory file (particle id "
                         f"{srt[1:][srt[1:] == srt[:-1]][0]} appears twice)")


def _check_times(path: Path, t: np.ndarray, fi: float) -> None:
    """Frame times finite, increasing and evenly spaced within twice
    FRAME_SPACING_TOLERANCE of the frame interval ``fi`` (the writer holds them to once;
    the margin covers a median interval when written against the slope when read)."""
    bad = ~np.isfinite(t)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(f"{path}: damaged trajectory file (frame {k} has time {t[k]}; "
                         "frame times must be finite)")
    if t.size < 2:
        return
    steps = np.diff(t)
    off = ~(np.abs(steps - fi) <= 2 * FRAME_SPACING_TOLERANCE * fi)
    if off.any() or not fi > 0:
        k = int(np.argmax(off))
        kind = ("do not increase" if not steps[k] > 0 else
                f"are not evenly spaced (step {time_text(steps[k])} s, frame interval "
                f"{time_text(fi)} s)")
        raise InputError(f"{path}: damaged trajectory file (frame times "
                         f"{time_text(t[k])} and {time_text(t[k + 1])} s {kind})")


def _float_attr(value) -> float:
    """An attribute as a float (NaN where it is not one number)."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return float("nan")
    return float(array) if array.size == 1 else float("nan")


def _whole_attr(value, name: str, path) -> int:
    """An attribute as a whole number, refused where it is not one."""
    number = _float_attr(value)
    if not (np.isfinite(number) and number == round(number)):
        raise InputError(f"{path}: damaged trajectory file ({name} {value!r} is not a whole number)")
    return int(number)


def _attribute_text(value) -> str:
    """An HDF5 attribute as a reader would write it (``nan``, ``0.025``, ``'text'``), not
    numpy's repr (``np.float64(nan)``)."""
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    if isinstance(value, str):
        return repr(value)
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "size", 1) == 1:
        value = item()
    return f"{value:g}" if isinstance(value, float) else str(value)
