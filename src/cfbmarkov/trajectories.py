"""The trajectory store: one HDF5 layout for CFD-DEM runs, imported data and predictions.

Layout, version 2 (H5MD-like, every array in SI units)::

    /                       attrs: format, version (2), width, height, depth (3D only),
                                   dimensions (D = 2 or 3), boundary ("periodic" | "open"),
                                   across_axis, vertical_axis, depth_axis (the source's axis
                                   letters), region_origin [D] (source coordinates of the
                                   stored origin, m), length_unit, time_unit, frame_interval,
                                   source, parameters (JSON), created, cfbmarkov_version
    /particles/id           [N]      int64    particle ids (the column order of every frame)
    /frames/time            [T]      float64  s
    /frames/position        [T,N,D]  float64  m: across, vertical (height) [, depth], from
                                              the region's origin; NaN where absent;
                                              chunked one frame per chunk
    /frames/velocity        [T,N,D]  float64  m/s (optional); NaN where absent
    /frames/lap             [T,N]    int32    lap counter: +1 per pass up through the top,
                                              -1 per pass down through the bottom (0 where
                                              absent; all 0 for an open riser)
    /frames/present         [T,N]    bool     which particles are in each frame (only in a
                                              file where some particle is absent somewhere)
    /events/time            [E]      float64  exact pass events (optional)
    /events/particle        [E]      int32    index into /particles/id
    /events/direction       [E]      int8     +1 up through the top, -1 down through the bottom
    /provenance/<name>/...  groups a producer attaches (e.g. the model behind a prediction)

Version-1 files (2D, periodic, every particle in every frame, none of the new attributes)
read as version 2 with those defaults.

Files are written by :mod:`cfbmarkov.trajectory_writer`, under a temporary name and renamed
when complete, so a reader never sees a half-written file. Frames are read one at a time or
by window without loading the whole file (:meth:`Trajectories.positions` with a slice).

Frames are evenly spaced within :data:`FRAME_SPACING_TOLERANCE` (1 %) of the frame interval,
whatever the time origin, so times printed to a few decimals are accepted. A file of one
frame has no ``frame_interval`` unless its producer gave one; then :meth:`Trajectories.lag_frames`
refuses it (``docs/definitions.md``, File formats, Frame times).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import h5py
import numba as nb
import numpy as np

from cfbmarkov.boundary import BOUNDARIES, Boundary
from cfbmarkov.errors import InputError

#: the ``format`` attribute of a trajectory file
FORMAT = "cfbmarkov.trajectories"
#: the layout's version (the ``version`` attribute); version 1 files still read
VERSION = 2
#: the vertical boundaries a riser may have
#: relative tolerance (on max(|t|, 1 s)) for matching a requested time to the frame of a
#: file that holds one frame, and so has no frame interval to scale a tolerance
TIME_TOLERANCE = 1e-6
#: relative tolerance on frame spacing: every step between frames lies within this fraction
#: of the file's frame interval (``docs/definitions.md``, File formats, Frame times); a
#: requested time or lag matches a frame within half of it, in frame intervals
FRAME_SPACING_TOLERANCE = 0.01
#: positions may lie this far outside the domain (m) before they are refused (round-off)
POSITION_TOLERANCE = 1e-9


@dataclass(frozen=True)
class PassEvents:
    """Exact passes through the periodic boundary, sorted by time.

    Attributes
    ----------
    time : ndarray of float64, shape (E,)
        Times of the passes (s).
    particle : ndarray of int32, shape (E,)
        Index of the particle (into the file's ids).
    direction : ndarray of int8, shape (E,)
        +1 up through the top, -1 down through the bottom.
    """

    time: np.ndarray
    particle: np.ndarray
    direction: np.ndarray

    def __len__(self) -> int:
        return int(self.time.size)


def lap_increments(previous_y: np.ndarray, y: np.ndarray, height: float) -> np.ndarray:
    """Boundary passes between two frames by the minimal-image rule on y
    (``docs/definitions.md``, Pass direction).

    Parameters
    ----------
    previous_y, y : ndarray of float64, shape (N,) (or any matching shape)
        Heights (m) in the earlier and the later frame.
    height : float
        Height H of the riser (m).

    Returns
    -------
    ndarray of int32
        +1 where a particle passed up through the top (y dropped by more than H/2), -1
        where it passed down through the bottom, 0 elsewhere.
    """
    dy = y - previous_y
    return (dy < -0.5 * height).astype(np.int32) - (dy > 0.5 * height).astype(np.int32)


def estimate_frame_interval(times) -> float:
    """The frame interval of evenly spaced frame times: the least-squares slope of t_k
    against k.

    With times rounded to q s (printed to a few decimals) the slope is off by about
    q / T^1.5 s, far less than a single step (off by up to q) or the median step; it does
    not depend on the time origin.

    Parameters
    ----------
    times : array_like of float, shape (T,)
        Frame times (s), increasing.

    Returns
    -------
    float
        The interval (s); NaN for fewer than two times.
    """
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    n = times.size
    if n < 2:
        return float("nan")
    k = np.arange(n, dtype=np.float64) - 0.5 * (n - 1)
    return float(np.dot(k, times - times[0]) / np.dot(k, k))


def _open_h5(path: str | os.PathLike, mode: str = "r") -> h5py.File:
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")
    try:
        return h5py.File(path, mode)
    except OSError as exc:
        text = str(exc).lower()
        if isinstance(exc, PermissionError) or "permission denied" in text or \
                getattr(exc, "errno", None) in (errno.EACCES, errno.EPERM):
            raise InputError(f"{path}: cannot read (permission denied)") from None
        if "unable to lock file" in text:
            raise InputError(f"{path}: locked by another program that is writing it (HDF5 "
                             "file lock); wait for it to end") from None
        raise InputError(f"{path}: not a readable HDF5 file (truncated, or another format)") from None


@nb.njit(cache=True)
def _frame_problem(pos, lap, present, extent, tol, height, open_riser):
    """The first problem of a block of frames, in one pass without temporaries: (code,
    frame, particle) with code 0 none, 1 a present position not finite, 2 outside the
    domain (beyond ``tol``), 3 a non-zero lap on an open riser, 4 (periodic) between
    consecutive present frames |dy + dL H| > H + 2 tol (laps inconsistent with positions).
    Codes 1-2 are found before 3-4 for the same frame and particle (docs/definitions.md,
    File formats, What is checked)."""
    n_frames, n_particles, d = pos.shape
    for k in range(n_frames):
        for p in range(n_particles):
            if not present[k, p]:
                continue
            for c in range(d):
                v = pos[k, p, c]
                if not np.isfinite(v):
                    return 1, k, p
                if v < -tol or v > extent[c] + tol:
                    return 2, k, p
            if open_riser:
                if lap[k, p] != 0:
                    return 3, k, p
            elif k > 0 and present[k - 1, p]:
                moved = pos[k, p, 1] - pos[k - 1, p, 1] + (lap[k, p] - lap[k - 1, p]) * height
                if not abs(moved) <= height + 2 * tol:
                    return 4, k - 1, p
    return 0, 0, 0


@contextlib.contextmanager
def opened(source: "str | os.PathLike | Trajectories") -> Iterator["Trajectories"]:
    """An open :class:`Trajectories` for ``source``, a path or an already open file.

    A file opened here is closed on leaving the block; an open file given by the caller
    stays open. This is the one place where "a path or an open file" is decided.

    Parameters
    ----------
    source : str, os.PathLike or Trajectories
        A path, or an open file.

    Yields
    ------
    Trajectories

    Raises
    ------
    InputError
        If a path does not name a readable trajectory file.
    """
    if isinstance(source, Trajectories):
        yield source
        return
    with Trajectories(source) as traj:
        yield traj


class Trajectories:
    """Read access to a trajectory file. Open with ``Trajectories(path)`` or as a context manager.

    Small metadata (times, ids, domain) is loaded on open; frames are read on demand.

    Parameters
    ----------
    path : str or os.PathLike
        The trajectory file.

    Attributes
    ----------
    path : pathlib.Path
        The file.
    ids : ndarray of int64, shape (N,)
        Particle ids, the column order of every frame.
    times : ndarray of float64, shape (T,)
        Frame times (s).
    width, height : float
        The riser W x H (m).
    depth : float or None
        The riser's depth (m) of a 3D file; None in 2D.
    dimensions : int
        D, the coordinates per position: 2 (across, vertical) or 3 (across, vertical, depth).
    boundary : Boundary
        The vertical boundary (a str: ``"periodic"`` or ``"open"``).
    axes : dict of str to str
        The source's axis letter of each stored axis (keys ``across``, ``vertical``,
        ``depth``; ``depth`` is empty in 2D).
    region_origin : ndarray of float64, shape (D,)
        Source coordinates (m) of the stored origin, in the stored axis order.
    version : int
        The file's layout version (1 or 2).
    frame_interval : float
        Time between frames (s): the file's ``frame_interval`` attribute or, for a file
        without one, :func:`estimate_frame_interval` of its times; NaN for a file of one
        frame without the attribute (then :meth:`lag_frames` raises).
    source : str
        What produced the file.
    parameters : dict
        The producer's parameters.

    Raises
    ------
    InputError
        If the file is missing, empty, not HDF5, a model file, not a trajectory file,
        damaged (datasets missing or of mismatched shapes) or holds no frames.

    Notes
    -----
    See ``docs/definitions.md`` (File formats, Trajectory files).
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._file = _open_h5(self.path)
        try:
            self._validate()
        except InputError:
            self._file.close()
            raise
        except (KeyError, OSError, ValueError, TypeError) as exc:
            self._file.close()
            raise InputError(f"{self.path}: damaged trajectory file ({exc})") from None

    # -- opening and validation -------------------------------------------------------
    def _validate(self) -> None:
        f = self._file
        fmt = f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode()
        if fmt != FORMAT:
            if fmt == "cfbmarkov.model":
                raise InputError(f"{self.path}: a cfbmarkov model file, not a trajectory file")
            raise InputError(f"{self.path}: not a cfbmarkov trajectory file "
                             + (f"(format attribute is {fmt!r})" if fmt else "(no 'format' attribute)"))
        version = _whole_attr(f.attrs.get("version", 1), "version", self.path)
        if version > VERSION:
            raise InputError(f"{self.path}: trajectory file of layout version {version}, written by a "
                             f"newer cfbmarkov (this one reads up to {VERSION}); upgrade cfbmarkov")
        self.version = version
        for name in ("particles/id", "frames/time", "frames/position", "frames/lap"):
            if name not in f:
                raise InputError(f"{self.path}: damaged trajectory file (no '{name}' dataset)")
        self.ids = f["particles/id"][()]
        self.times = f["frames/time"][()]
        self.dimensions = _whole_attr(f.attrs.get("dimensions", 2), "dimensions", self.path)
        n, t, d = self.ids.size, self.times.size, self.dimensions
        if d not in (2, 3):
            raise InputError(f"{self.path}: damaged trajectory file (dimensions {d})")
        if f["frames/position"].shape != (t, n, d) or f["frames/lap"].shape != (t, n) or (
                "frames/present" in f and f["frames/present"].shape != (t, n)):
            raise InputError(f"{self.path}: damaged trajectory file (frame arrays do not match "
                             f"{t} times x {n} particles x {d} coordinates)")
        if t == 0:
            raise InputError(f"{self.path}: trajectory file holds no frames")
        self._check_arrays()
        self.width = self._length_attr("width")
        self.height = self._length_attr("height")
        self.depth = self._length_attr("depth") if d == 3 else None
        boundary = f.attrs.get("boundary", "periodic")
        boundary = boundary.decode() if isinstance(boundary, bytes) else str(boundary)
        if boundary not in BOUNDARIES:
            raise InputError(f"{self.path}: damaged trajectory file (boundary {boundary!r})")
        self.boundary = Boundary(boundary)
        self.axes = {key: str(f.attrs.get(f"{key}_axis", default)) for key, default in
                     (("across", "x"), ("vertical", "y"), ("depth", "z" if d == 3 else ""))}
        self.region_origin = np.asarray(f.attrs.get("region_origin", np.zeros(d)), dtype=np.float64)
        if self.region_origin.shape != (d,) or not np.all(np.isfinite(self.region_origin)):
            raise InputError(f"{self.path}: damaged trajectory file (region_origin "
                             f"{self.region_origin.tolist()} is not {d} finite numbers)")
        self.source = str(f.attrs.get("source", "unknown"))
        try:
            self.parameters: dict[str, Any] = json.loads(f.attrs.get("parameters", "{}"))
        except (ValueError, TypeError):
            raise InputError(f"{self.path}: damaged trajectory file (the 'parameters' attribute "
                             "is not JSON)") from None
        if "frame_interval" in f.attrs:
            self.frame_interval = _float_attr(f.attrs["frame_interval"])
            if not (np.isfinite(self.frame_interval) and self.frame_interval > 0):
                raise InputError(f"{self.path}: damaged trajectory file (frame_interval "
                                 f"{f.attrs['frame_interval']!r} is not a positive number of s)")
        else:
            self.frame_interval = estimate_frame_interval(self.times)
        self._check_times()
        #: frames whose positions and laps have passed the per-frame checks
        self._checked = np.zeros(t, dtype=bool)

    def _length_attr(self, name: str) -> float:
        if name not in self._file.attrs:
            raise InputError(f"{self.path}: damaged trajectory file (no '{name}' attribute)")
        value = _float_attr(self._file.attrs[name])
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"{self.path}: damaged trajectory file ({name} "
                             f"{self._file.attrs[name]!r} is not a positive length in m)")
        return value

    def _check_arrays(self) -> None:
        """Types of the datasets and unique ids (cheap: no frame is read)."""
        f = self._file
        kinds = {"particles/id": "iu", "frames/time": "f", "frames/position": "f",
                 "frames/lap": "iu", "frames/present": "b", "frames/velocity": "f"}
        for name, kind in kinds.items():
            if name in f and (not isinstance(f[name], h5py.Dataset) or f[name].dtype.kind not in kind):
                wanted = ("whole numbers" if kind == "iu" else "booleans" if kind == "b"
                          else "numbers")
                raise InputError(f"{self.path}: damaged trajectory file ('{name}' holds "
                                 f"{getattr(f[name], 'dtype', 'a group')}, not {wanted})")
        if self.ids.ndim != 1 or self.times.ndim != 1:
            raise InputError(f"{self.path}: damaged trajectory file (ids or times are not 1-D)")
        if "frames/velocity" in f and f["frames/velocity"].shape != f["frames/position"].shape:
            raise InputError(f"{self.path}: damaged trajectory file (velocities of shape "
                             f"{f['frames/velocity'].shape}, positions {f['frames/position'].shape})")
        if np.unique(self.ids).size != self.ids.size:
            srt = np.sort(self.ids)
            raise InputError(f"{self.path}: damaged trajectory file (particle id "
                             f"{srt[1:][srt[1:] == srt[:-1]][0]} appears twice)")

    def _check_times(self) -> None:
        """Frame times finite, increasing and evenly spaced within twice
        FRAME_SPACING_TOLERANCE of the frame interval (the writer holds them to once; the
        margin covers a median interval when written against the slope when read)."""
        t = self.times
        bad = ~np.isfinite(t)
        if bad.any():
            k = int(np.argmax(bad))
            raise InputError(f"{self.path}: damaged trajectory file (frame {k} has time {t[k]}; "
                             "frame times must be finite)")
        if t.size < 2:
            return
        steps = np.diff(t)
        fi = self.frame_interval
        off = ~(np.abs(steps - fi) <= 2 * FRAME_SPACING_TOLERANCE * fi)
        if off.any() or not fi > 0:
            k = int(np.argmax(off))
            kind = ("do not increase" if not steps[k] > 0 else
                    f"are not evenly spaced (step {_t(steps[k])} s, frame interval {_t(fi)} s)")
            raise InputError(f"{self.path}: damaged trajectory file (frame times "
                             f"{_t(t[k])} and {_t(t[k + 1])} s {kind})")

    def _check_frames(self, i0: int, i1: int, positions: np.ndarray | None = None,
                      laps: np.ndarray | None = None) -> None:
        """Per-frame checks of frames i0 .. i1 - 1, each frame once (docs/definitions.md,
        File formats, What is checked): positions finite and inside the domain (within
        POSITION_TOLERANCE) where present; on a periodic riser, between consecutive frames
        where a particle is present, the unwrapped displacement y1 - y0 + (L1 - L0) H is at
        most H (no lap jump of more than 1, none against the motion); on an open riser laps
        are 0 where present. ``positions`` / ``laps`` are those frames when already read."""
        if i1 <= i0 or self._checked[i0:i1].all():
            return
        f = self._file
        lo = i0 - 1 if i0 > 0 else i0
        pos = f["frames/position"][i0:i1] if positions is None else positions
        lap = f["frames/lap"][i0:i1] if laps is None else laps
        if lo < i0:
            pos = np.concatenate([f["frames/position"][lo:i0], pos])
            lap = np.concatenate([f["frames/lap"][lo:i0], lap])
        present = self.present(slice(lo, i1))
        extent = np.array([self.width, self.height] + ([self.depth] if self.dimensions == 3 else []))
        tol = POSITION_TOLERANCE
        code, k, n = _frame_problem(np.ascontiguousarray(pos, dtype=np.float64),
                                    np.ascontiguousarray(lap, dtype=np.int64),
                                    np.ascontiguousarray(present, dtype=np.bool_), extent, tol,
                                    self.height, self.boundary == "open")
        if code == 1 or code == 2:
            what = ("is not a finite number" if code == 1 else "lies outside the domain 0.."
                    + " x 0..".join(f"{v:g}" for v in extent) + " m")
            raise InputError(f"{self.path}: damaged trajectory file (position "
                             f"{pos[k, n].tolist()} of particle {self.ids[n]} at t = "
                             f"{_t(self.times[lo + k])} s {what})")
        if code == 3:
            raise InputError(f"{self.path}: damaged trajectory file (an open riser, but particle "
                             f"{self.ids[n]} has lap {lap[k, n]} at t = {_t(self.times[lo + k])} s)")
        if code == 4:
            raise InputError(
                f"{self.path}: damaged trajectory file (lap counter of particle {self.ids[n]} "
                f"goes from {lap[k, n]} to {lap[k + 1, n]} between t = {_t(self.times[lo + k])} "
                f"and {_t(self.times[lo + k + 1])} s while its height goes from "
                f"{pos[k, n, 1]:.6g} to {pos[k + 1, n, 1]:.6g} m: laps inconsistent with the "
                "positions)")
        self._checked[i0:i1] = True

    def _check_read(self, frames, data: np.ndarray, name: str) -> None:
        """Run the per-frame checks on what positions() or laps() just read."""
        if isinstance(frames, (int, np.integer)):
            i = int(frames) + (self.n_frames if frames < 0 else 0)
            if 0 <= i < self.n_frames:
                self._check_frames(i, i + 1, **{name: data[None]})
            return
        if isinstance(frames, slice):
            start, stop, step = frames.indices(self.n_frames)
            if step == 1:
                self._check_frames(start, stop, **{name: data})
                return
            index = np.arange(start, stop, step)
        else:
            index = np.asarray(frames).reshape(-1)      # a list or array of frames
            index = np.where(index < 0, index + self.n_frames, index)
        for i in np.unique(index).tolist():             # frame by frame, not the span
            self._check_frames(i, i + 1)

    def close(self) -> None:
        """Close the file."""
        self._file.close()

    def __enter__(self) -> "Trajectories":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        span = f"{self.times[0]:g}..{self.times[-1]:g} s"
        every = (f", every {self.frame_interval:g} s" if np.isfinite(self.frame_interval) else "")
        return (f"Trajectories({str(self.path)!r}: {self.n_particles} particles x {self.n_frames} "
                f"frames, {span}{every}, source={self.source!r})")

    # -- metadata --------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.times.size)

    @property
    def n_particles(self) -> int:
        """Number of particles N."""
        return int(self.ids.size)

    @property
    def has_velocity(self) -> bool:
        """Whether the file stores velocities."""
        return "frames/velocity" in self._file

    @property
    def has_absences(self) -> bool:
        """Whether some particle is absent from some frame (the file has a presence mask)."""
        return "frames/present" in self._file

    def unsupported(self, *, three_d: bool = False, absent: bool = False,
                    open_boundary: bool = False) -> list[str]:
        """What in this file a consumer cannot use: 3D positions, particles absent from
        frames, an open vertical boundary (empty for the paper's periodic 2D data).

        Parameters
        ----------
        three_d, absent, open_boundary : bool, optional
            What the consumer can use (then it is not listed).

        Returns
        -------
        list of str
        """
        reasons = []
        if self.dimensions == 3 and not three_d:
            reasons.append("3D positions")
        if self.has_absences and not absent:
            reasons.append("particles absent from some frames")
        if self.boundary == "open" and not open_boundary:
            reasons.append("an open riser (particles enter and leave)")
        return reasons

    def require_supported(self, purpose: str, *, three_d: bool = False, absent: bool = False,
                          open_boundary: bool = False) -> None:
        """Refuse, in one line, a file that holds what the consumer cannot use yet
        (:meth:`unsupported`).

        Parameters
        ----------
        purpose : str
            What was asked (e.g. ``"fitting a Markov model"``), for the message.
        three_d, absent, open_boundary : bool, optional
            What the consumer can use.

        Raises
        ------
        InputError
            Naming the file, the purpose and what it cannot use yet.
        """
        reasons = self.unsupported(three_d=three_d, absent=absent, open_boundary=open_boundary)
        if reasons:
            hint = (" (a 3D dump imported with --drop-depth gives 2D positions)"
                    if self.dimensions == 3 and not three_d else "")
            raise InputError(f"{self.path}: {purpose} cannot use {' and '.join(reasons)} yet{hint}")

    @property
    def has_events(self) -> bool:
        """Whether the file stores exact pass events."""
        return "events/time" in self._file

    @property
    def attrs(self) -> dict[str, Any]:
        """The root attributes of the file (bytes decoded to str)."""
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in self._file.attrs.items()}

    # -- locating frames -------------------------------------------------------------
    @property
    def time_tolerance(self) -> float:
        """How far (s) a frame may lie from a requested time and still be the frame at it.

        Half of :data:`FRAME_SPACING_TOLERANCE` of the frame interval: frame times rounded
        to q s lie within q/2 of the exact times, and the spacing check accepts q up to
        the spacing tolerance of an interval. It does not depend on the time origin. A file
        of one frame has no interval: then ``TIME_TOLERANCE * max(|t|, 1 s)`` (round-off).
        """
        if np.isfinite(self.frame_interval):
            return 0.5 * FRAME_SPACING_TOLERANCE * self.frame_interval
        return TIME_TOLERANCE * max(abs(float(self.times[-1])), 1.0)

    def _frames_text(self) -> str:
        if self.n_frames == 1:
            return f"{self.path} holds one frame, at t = {_t(self.times[0])} s"
        return (f"frames span {_t(self.times[0])} to {_t(self.times[-1])} s every "
                f"{_t(self.frame_interval)} s")

    def frame_index(self, time: float) -> int:
        """Index of the frame at ``time``.

        Parameters
        ----------
        time : float
            A frame time (s), matched within :attr:`time_tolerance`.

        Returns
        -------
        int

        Raises
        ------
        InputError
            If no frame lies at ``time``.
        """
        if not np.isfinite(time):
            raise InputError(f"time {time:g} s is not a finite number")
        i = int(np.argmin(np.abs(self.times - time)))
        if not abs(self.times[i] - time) <= self.time_tolerance:
            raise InputError(f"{self.path}: no frame at t = {_t(time)} s ({self._frames_text()})")
        return i

    def window(self, start: float, stop: float) -> slice:
        """Frames with start <= t <= stop, as a slice.

        Parameters
        ----------
        start, stop : float
            The window (s), matched to frames within :attr:`time_tolerance`.

        Returns
        -------
        slice

        Raises
        ------
        InputError
            If the window is empty, leaves the data, or holds no frame.
        """
        if not (np.isfinite(start) and np.isfinite(stop)):
            raise InputError(f"window {start:g}:{stop:g} s is not finite")
        if not stop > start:
            raise InputError(f"window {start:g}:{stop:g} s is empty (the end must follow the start)")
        tol = self.time_tolerance
        if start < self.times[0] - tol or stop > self.times[-1] + tol:
            raise InputError(
                f"window {start:g}:{stop:g} s lies outside the data of {self.path} "
                f"({_t(self.times[0])} to {_t(self.times[-1])} s)")
        i0 = int(np.searchsorted(self.times, start - tol, side="left"))
        i1 = int(np.searchsorted(self.times, stop + tol, side="right"))
        if i1 - i0 < 1:
            raise InputError(f"window {start:g}:{stop:g} s holds no frame of {self.path}")
        return slice(i0, i1)

    def lag_frames(self, lag: float) -> int:
        """The lag as a whole number of frame intervals.

        Parameters
        ----------
        lag : float
            The lag (s), matched to a whole number of frame intervals within
            :attr:`time_tolerance`.

        Returns
        -------
        int
            ``lag / frame_interval`` rounded (>= 1).

        Raises
        ------
        InputError
            If the lag is not positive, the file has no frame interval (one frame and no
            ``frame_interval`` attribute), or the lag is not a whole multiple of the frame
            interval.
        """
        if not (np.isfinite(lag) and lag > 0):
            raise InputError(f"lag {lag:g} s must be a positive finite number")
        if not np.isfinite(self.frame_interval):
            raise InputError(f"{self.path} holds one frame: no frame interval, so no transition "
                             f"can be counted (lag {lag:g} s)")
        k = int(round(lag / self.frame_interval))
        if k < 1 or not abs(lag - k * self.frame_interval) <= self.time_tolerance:
            raise InputError(f"lag {lag:g} s is not a whole multiple of the frame interval "
                             f"{_t(self.frame_interval)} s of {self.path}")
        return k

    # -- reading frames --------------------------------------------------------------
    def positions(self, frames: int | slice = slice(None)) -> np.ndarray:
        """Positions of one frame or a range of frames.

        Parameters
        ----------
        frames : int or slice, optional
            A frame index, or a slice of frames (default: all).

        Returns
        -------
        ndarray of float64, shape (N, D) or (T, N, D)
            Positions (m): across, vertical [, depth]; NaN where a particle is absent.

        Raises
        ------
        InputError
            If a frame read fails the per-frame checks (a present position not finite or
            outside the domain, laps inconsistent with the positions; see
            :meth:`_check_frames`).
        """
        data = self._file["frames/position"][frames]
        self._check_read(frames, data, "positions")
        return data

    def present(self, frames: int | slice = slice(None)) -> np.ndarray:
        """Which particles are in one frame or a range of frames.

        Parameters
        ----------
        frames : int or slice, optional
            A frame index, or a slice of frames (default: all).

        Returns
        -------
        ndarray of bool, shape (N,) or (T, N)
            All True in a file without absences.
        """
        if self.has_absences:
            return self._file["frames/present"][frames]
        if isinstance(frames, slice):
            return np.ones((len(range(*frames.indices(self.n_frames))), self.n_particles), bool)
        return np.ones(self.n_particles, dtype=bool)

    def velocities(self, frames: int | slice = slice(None)) -> np.ndarray | None:
        """Velocities like :meth:`positions`, or None when the source had none.

        Parameters
        ----------
        frames : int or slice, optional
            A frame index, or a slice of frames (default: all).

        Returns
        -------
        ndarray of float64, shape (N, D) or (T, N, D), or None
            Velocities (m/s); NaN where a particle is absent.

        Raises
        ------
        InputError
            If a present particle's velocity is not a finite number (a damaged file).
        """
        if not self.has_velocity:
            return None
        values = self._file["frames/velocity"][frames]
        with np.errstate(invalid="ignore"):
            bad = self.present(frames) & ~np.isfinite(values).all(axis=-1)
        if bad.any():
            where = np.unravel_index(int(np.argmax(bad)), bad.shape)
            n = int(where[-1])
            raise InputError(f"{self.path}: damaged trajectory file (velocity of particle "
                             f"{self.ids[n]} is not a finite number)")
        return values

    def laps(self, frames: int | slice = slice(None)) -> np.ndarray:
        """Lap counters of one frame or a range of frames.

        Parameters
        ----------
        frames : int or slice, optional
            A frame index, or a slice of frames (default: all).

        Returns
        -------
        ndarray of int32, shape (N,) or (T, N)

        Raises
        ------
        InputError
            If a frame read fails the per-frame checks (as :meth:`positions`).
        """
        data = self._file["frames/lap"][frames]
        self._check_read(frames, data, "laps")
        return data

    def iter_frames(self, frames: slice = slice(None), block: int = 64
                    ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Read frames block by block.

        Parameters
        ----------
        frames : slice, optional
            A contiguous range of frames (default: all).
        block : int, optional
            Most frames per block.

        Yields
        ------
        times : ndarray of float64, shape (B,)
            Times (s).
        positions : ndarray of float64, shape (B, N, D)
            Positions (m).
        laps : ndarray of int32, shape (B, N)
            Lap counters.

        Raises
        ------
        ValueError
            If ``frames`` has a step other than 1.
        """
        start, stop, step = frames.indices(self.n_frames)
        if step != 1:
            raise ValueError("iter_frames takes a contiguous slice")
        for i in range(start, stop, block):
            j = min(i + block, stop)
            yield self.times[i:j], self.positions(slice(i, j)), self.laps(slice(i, j))

    def events(self) -> PassEvents | None:
        """Exact pass events, sorted by time, or None when the source logged none.

        Returns
        -------
        PassEvents or None
        """
        if not self.has_events:
            return None
        g = self._file["events"]
        events = PassEvents(g["time"][()], g["particle"][()], g["direction"][()])
        e = events.time.shape
        if (events.particle.shape != e or events.direction.shape != e or len(e) != 1
                or not np.all(np.isfinite(events.time))
                or (e[0] and (events.particle.min() < 0 or events.particle.max() >= self.n_particles
                              or not np.all(np.abs(events.direction) == 1)))):
            raise InputError(f"{self.path}: damaged trajectory file (pass events: times, "
                             "particles and directions must be equally long, times finite, "
                             "particles indices of /particles/id and directions +1 or -1)")
        return events

    # -- gas fields (CFD-DEM runs) ---------------------------------------------------------
    @property
    def has_fields(self) -> bool:
        """Whether the file holds gas fields (``/fields``, written by CFD-DEM runs)."""
        return "fields" in self._file and "time" in self._file["fields"]

    @property
    def field_names(self) -> list[str]:
        """Names of the gas fields (sorted; empty without fields)."""
        return sorted(set(self._file["fields"]) - {"time"}) if self.has_fields else []

    @property
    def field_times(self) -> np.ndarray:
        """Times (s) of the gas-field frames."""
        return self._file["fields/time"][()] if self.has_fields else np.empty(0)

    @property
    def field_spacing(self) -> tuple[float, float]:
        """(dx, dy) of the cell-centred gas grid, m; cell (j, i) is centred at
        ((i + 1/2) dx, (j + 1/2) dy)."""
        dx, dy = self._file["fields"].attrs["spacing"]
        return float(dx), float(dy)

    def field(self, name: str, frames: int | slice = slice(None)) -> np.ndarray:
        """Gas field ``name`` at one or more field frames.

        Parameters
        ----------
        name : str
            ``void_fraction`` (-), ``gas_velocity`` (m/s) or ``pressure`` (Pa), as stored.
        frames : int or slice, optional
            Field frame index or slice (default: all).

        Returns
        -------
        ndarray of float32, shape (ny, nx) or (ny, nx, 2) per frame
            With a leading frame axis for a slice.

        Raises
        ------
        InputError
            If the file holds no field ``name``.
        """
        if name not in self.field_names:
            raise InputError(f"{self.path}: no gas field '{name}' (has: "
                             f"{', '.join(self.field_names) or 'none'})")
        return self._file["fields"][name][frames]

    def group(self, name: str) -> h5py.Group | None:
        """A provenance group attached by the producer, or None.

        Parameters
        ----------
        name : str
            The group's name under ``/provenance`` (e.g. ``'model'``).

        Returns
        -------
        h5py.Group or None
        """
        key = f"provenance/{name}"
        return self._file[key] if key in self._file else None


def _float_attr(value) -> float:
    """An attribute as a float (NaN where it is not one number)."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return float("nan")
    return float(array) if array.size == 1 else float("nan")


def _whole_attr(value, name: str, path) -> int:
    number = _float_attr(value)
    if not (np.isfinite(number) and number == round(number)):
        raise InputError(f"{path}: damaged trajectory file ({name} {value!r} is not a whole number)")
    return int(number)


def _t(value: float) -> str:
    """A time for a message: up to 10 significant digits (10.00833, not 10.0083)."""
    return f"{float(value):.10g}"
