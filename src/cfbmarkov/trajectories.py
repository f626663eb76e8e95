"""The trajectory store: one HDF5 layout for CFD-DEM runs, imported data and predictions.

Layout (H5MD-like, every array in SI units)::

    /                       attrs: format, version, width, height, length_unit, time_unit,
                                   frame_interval, source, parameters (JSON), created,
                                   cfbmarkov_version
    /particles/id           [N]      int64    particle ids (the column order of every frame)
    /frames/time            [T]      float64  s
    /frames/position        [T,N,2]  float64  m, chunked one frame per chunk
    /frames/velocity        [T,N,2]  float64  m/s (optional)
    /frames/lap             [T,N]    int32    lap counter: +1 per pass up through the top,
                                              -1 per pass down through the bottom
    /events/time            [E]      float64  exact pass events (optional)
    /events/particle        [E]      int32    index into /particles/id
    /events/direction       [E]      int8     +1 up through the top, -1 down through the bottom
    /provenance/<name>/...  groups a producer attaches (e.g. the model behind a prediction)

Every file is written under a temporary name and renamed when complete, so a reader never
sees a half-written file. Frames are read one at a time or by window without loading the
whole file (:meth:`Trajectories.positions` with a slice).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import h5py
import numpy as np

from cfbmarkov._atomic import discard, publish, temporary_path
from cfbmarkov.errors import InputError

#: the ``format`` attribute of a trajectory file
FORMAT = "cfbmarkov.trajectories"
#: the layout's version (the ``version`` attribute)
VERSION = 1
#: relative tolerance on frame spacing and on matching a requested time to a frame
TIME_TOLERANCE = 1e-6
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


def _open_h5(path: str | os.PathLike, mode: str = "r") -> h5py.File:
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")
    try:
        return h5py.File(path, mode)
    except OSError:
        raise InputError(f"{path}: not a readable HDF5 file (truncated, or another format)") from None


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
    frame_interval : float
        Time between frames (s).
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
        for name in ("particles/id", "frames/time", "frames/position", "frames/lap"):
            if name not in f:
                raise InputError(f"{self.path}: damaged trajectory file (no '{name}' dataset)")
        self.ids = f["particles/id"][()]
        self.times = f["frames/time"][()]
        n, t = self.ids.size, self.times.size
        if f["frames/position"].shape != (t, n, 2) or f["frames/lap"].shape != (t, n):
            raise InputError(f"{self.path}: damaged trajectory file (frame arrays do not match "
                             f"{t} times x {n} particles)")
        if t == 0:
            raise InputError(f"{self.path}: trajectory file holds no frames")
        self.width = float(f.attrs["width"])
        self.height = float(f.attrs["height"])
        self.source = str(f.attrs.get("source", "unknown"))
        self.parameters: dict[str, Any] = json.loads(f.attrs.get("parameters", "{}"))
        self.frame_interval = float(f.attrs.get("frame_interval", np.nan))
        if not np.isfinite(self.frame_interval) and t > 1:
            self.frame_interval = float(self.times[1] - self.times[0])

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
    def has_events(self) -> bool:
        """Whether the file stores exact pass events."""
        return "events/time" in self._file

    @property
    def attrs(self) -> dict[str, Any]:
        """The root attributes of the file (bytes decoded to str)."""
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in self._file.attrs.items()}

    # -- locating frames -------------------------------------------------------------
    def _tolerance(self) -> float:
        interval = self.frame_interval if np.isfinite(self.frame_interval) else 1.0
        return max(TIME_TOLERANCE * max(abs(self.times[-1]), 1.0), 1e-3 * interval)

    def frame_index(self, time: float) -> int:
        """Index of the frame at ``time``.

        Parameters
        ----------
        time : float
            A frame time (s), matched within a small tolerance.

        Returns
        -------
        int

        Raises
        ------
        InputError
            If no frame lies at ``time``.
        """
        i = int(np.argmin(np.abs(self.times - time)))
        if abs(self.times[i] - time) > self._tolerance():
            raise InputError(
                f"{self.path}: no frame at t = {time:g} s (frames span {self.times[0]:g} to "
                f"{self.times[-1]:g} s every {self.frame_interval:g} s)")
        return i

    def window(self, start: float, stop: float) -> slice:
        """Frames with start <= t <= stop, as a slice.

        Parameters
        ----------
        start, stop : float
            The window (s), matched to frames within a small tolerance.

        Returns
        -------
        slice

        Raises
        ------
        InputError
            If the window is empty, leaves the data, or holds no frame.
        """
        if not stop > start:
            raise InputError(f"window {start:g}:{stop:g} s is empty (the end must follow the start)")
        tol = self._tolerance()
        if start < self.times[0] - tol or stop > self.times[-1] + tol:
            raise InputError(
                f"window {start:g}:{stop:g} s lies outside the data of {self.path} "
                f"({self.times[0]:g} to {self.times[-1]:g} s)")
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
            The lag (s).

        Returns
        -------
        int
            ``lag / frame_interval`` (>= 1).

        Raises
        ------
        InputError
            If the lag is not positive or not a whole multiple of the frame interval.
        """
        if not lag > 0:
            raise InputError(f"lag {lag:g} s must be positive")
        ratio = lag / self.frame_interval
        k = int(round(ratio))
        if k < 1 or abs(ratio - k) > 1e-6 * max(ratio, 1.0):
            raise InputError(f"lag {lag:g} s is not a whole multiple of the frame interval "
                             f"{self.frame_interval:g} s of {self.path}")
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
        ndarray of float64, shape (N, 2) or (T, N, 2)
            Positions (m).
        """
        return self._file["frames/position"][frames]

    def velocities(self, frames: int | slice = slice(None)) -> np.ndarray | None:
        """Velocities like :meth:`positions`, or None when the source had none.

        Parameters
        ----------
        frames : int or slice, optional
            A frame index, or a slice of frames (default: all).

        Returns
        -------
        ndarray of float64, shape (N, 2) or (T, N, 2), or None
            Velocities (m/s).
        """
        if not self.has_velocity:
            return None
        return self._file["frames/velocity"][frames]

    def laps(self, frames: int | slice = slice(None)) -> np.ndarray:
        """Lap counters of one frame or a range of frames.

        Parameters
        ----------
        frames : int or slice, optional
            A frame index, or a slice of frames (default: all).

        Returns
        -------
        ndarray of int32, shape (N,) or (T, N)
        """
        return self._file["frames/lap"][frames]

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
        positions : ndarray of float64, shape (B, N, 2)
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
        return PassEvents(g["time"][()], g["particle"][()], g["direction"][()])

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


class TrajectoryWriter:
    """Write a trajectory file frame by frame; the file appears under its name only when closed.

    Every frame is validated (finite, inside the domain, times increasing and evenly spaced);
    the lap counter is derived from the positions by the minimal-image rule when not given.
    On an error, or when used as a context manager that exits by an exception, the partial
    file is removed.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write; its folder is created if needed.
    ids : array_like of int, shape (N,)
        Unique particle ids, the column order of every frame.
    width, height : float
        The riser W x H (m), positive.
    source : str
        What produces the file (e.g. ``cfd-dem``, ``markov-prediction``).
    parameters : dict, optional
        The producer's parameters, stored as JSON.
    with_velocity : bool, optional
        Store velocities (then every frame must carry them).
    frame_interval : float, optional
        Time between frames (s); by default taken from the first two frames.
    label : str, optional
        Names the file in error messages (default: ``path``).

    Raises
    ------
    InputError
        If there is no particle id, the ids are not unique, or the domain is not of
        positive size.

    Notes
    -----
    See ``docs/definitions.md`` (File formats, Trajectory files; Lap counter).
    """

    def __init__(self, path: str | os.PathLike, ids, *, width: float, height: float,
                 source: str, parameters: dict[str, Any] | None = None,
                 with_velocity: bool = False, frame_interval: float | None = None,
                 label: str | None = None):
        self.path = Path(path)
        self.ids = np.asarray(ids, dtype=np.int64)
        if self.ids.ndim != 1 or self.ids.size == 0:
            raise InputError("a trajectory needs at least one particle id")
        if np.unique(self.ids).size != self.ids.size:
            raise InputError("particle ids are not unique")
        if not (width > 0 and height > 0):
            raise InputError(f"domain {width:g} x {height:g} m must have positive size")
        self.width, self.height = float(width), float(height)
        self.with_velocity = with_velocity
        self._label = label or str(self.path)
        self._tmp = temporary_path(self.path)
        n = self.ids.size
        self._file = h5py.File(self._tmp, "w")
        f = self._file
        f.attrs.update({
            "format": FORMAT, "version": VERSION, "width": self.width, "height": self.height,
            "length_unit": "m", "time_unit": "s", "source": source,
            "parameters": json.dumps(parameters or {}, default=_json_default),
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "cfbmarkov_version": _version(),
        })
        if frame_interval is not None:
            f.attrs["frame_interval"] = float(frame_interval)
        f.create_dataset("particles/id", data=self.ids)
        f.create_dataset("frames/time", shape=(0,), maxshape=(None,), dtype="f8", chunks=(4096,))
        f.create_dataset("frames/position", shape=(0, n, 2), maxshape=(None, n, 2), dtype="f8",
                         chunks=(1, n, 2))
        f.create_dataset("frames/lap", shape=(0, n), maxshape=(None, n), dtype="i4", chunks=(1, n))
        if with_velocity:
            f.create_dataset("frames/velocity", shape=(0, n, 2), maxshape=(None, n, 2),
                             dtype="f8", chunks=(1, n, 2))
        self._n_frames = 0
        self._first_time = self._last_time = None
        self._interval = frame_interval
        self._last_y: np.ndarray | None = None
        self._last_lap: np.ndarray | None = None
        self._closed = False

    # -- context manager ---------------------------------------------------------------
    def __enter__(self) -> "TrajectoryWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    @property
    def n_frames(self) -> int:
        """Number of frames written so far."""
        return self._n_frames

    @property
    def last_frame(self) -> tuple[float, np.ndarray, np.ndarray] | None:
        """(time in s, heights y [N] in m, laps [N]) of the last frame written, or None."""
        if self._last_time is None:
            return None
        return self._last_time, self._last_y, self._last_lap

    def continue_after(self, time: float, heights: np.ndarray, laps: np.ndarray,
                       frame_interval: float | None = None) -> None:
        """Continue a series written by another writer whose last frame was ``time`` (s)
        with heights ``heights`` [N] (m) and lap counters ``laps`` [N]: the next frame must
        follow it at the frame interval, and its laps count on from ``laps``.

        Parameters
        ----------
        time : float
            Time of the last frame of the earlier series (s).
        heights : array_like of float, shape (N,)
            Heights y of that frame (m).
        laps : array_like of int, shape (N,)
            Lap counters of that frame.
        frame_interval : float, optional
            The series' frame interval (s), if known.

        Raises
        ------
        InputError
            If frames were already written by this writer.
        """
        if self._n_frames:
            raise InputError(f"{self._label}: cannot continue a series after writing frames")
        self._last_time = float(time)
        self._last_y = np.asarray(heights, dtype=np.float64).copy()
        self._last_lap = np.asarray(laps, dtype=np.int32).copy()
        if frame_interval is not None:
            self._interval = float(frame_interval)

    # -- validation --------------------------------------------------------------------
    def _check_times(self, times: np.ndarray) -> None:
        if not np.all(np.isfinite(times)):
            raise InputError(f"{self._label}: frame time is not a finite number")
        allt = times if self._last_time is None else np.concatenate([[self._last_time], times])
        if allt.size < 2:
            return
        steps = np.diff(allt)
        if np.any(steps <= 0):
            k = int(np.argmax(steps <= 0))
            raise InputError(f"{self._label}: time does not increase at t = {allt[k + 1]:g} s "
                             f"(after {allt[k]:g} s)")
        interval = self._interval if self._interval is not None else steps[0]
        tol = max(TIME_TOLERANCE * max(abs(allt[-1]), 1.0), 1e-4 * interval)
        bad = np.abs(steps - interval) > tol
        if np.any(bad):
            k = int(np.argmax(bad))
            raise InputError(f"{self._label}: frames unevenly spaced: {steps[k]:g} s between "
                             f"t = {allt[k]:g} and {allt[k + 1]:g} s, expected {interval:g} s")
        if self._interval is None:
            self._interval = float(interval)
            self._file.attrs["frame_interval"] = self._interval

    def _check_array(self, name: str, values: np.ndarray, times: np.ndarray) -> None:
        finite = np.isfinite(values)
        if not finite.all():
            t_idx, p_idx = np.argwhere(~finite.all(axis=-1))[0]
            raise InputError(f"{self._label}: {name} of particle {self.ids[p_idx]} at t = "
                             f"{times[t_idx]:g} s is not a finite number")

    def _check_domain(self, positions: np.ndarray, times: np.ndarray) -> None:
        tol = POSITION_TOLERANCE
        x, y = positions[..., 0], positions[..., 1]
        outside = (x < -tol) | (x > self.width + tol) | (y < -tol) | (y > self.height + tol)
        if outside.any():
            t_idx, p_idx = np.argwhere(outside)[0]
            raise InputError(
                f"{self._label}: particle {self.ids[p_idx]} at t = {times[t_idx]:g} s lies outside "
                f"the domain 0..{self.width:g} x 0..{self.height:g} m at ({x[t_idx, p_idx]:g}, "
                f"{y[t_idx, p_idx]:g})")

    # -- writing -----------------------------------------------------------------------
    def append(self, time: float, position, velocity=None, lap=None) -> None:
        """Append one frame.

        Parameters
        ----------
        time : float
            Frame time (s).
        position : array_like, shape (N, 2)
            Positions (m).
        velocity : array_like, shape (N, 2), optional
            Velocities (m/s); required when the file stores velocities.
        lap : array_like of int, shape (N,), optional
            Lap counters (derived by the minimal-image rule when None).

        Raises
        ------
        InputError
            As :meth:`append_frames`.
        """
        self.append_frames(np.asarray([time], dtype=float), np.asarray(position)[None],
                           None if velocity is None else np.asarray(velocity)[None],
                           None if lap is None else np.asarray(lap)[None])

    def append_frames(self, times, positions, velocities=None, laps=None) -> None:
        """Append a block of frames.

        Parameters
        ----------
        times : array_like, shape (T,)
            Frame times (s), increasing, evenly spaced, following the last frame.
        positions : array_like, shape (T, N, 2)
            Positions (m), inside the domain.
        velocities : array_like, shape (T, N, 2), optional
            Velocities (m/s); required when the file stores velocities.
        laps : array_like of int, shape (T, N), optional
            Lap counters (derived by the minimal-image rule when None).

        Raises
        ------
        InputError
            If an array has the wrong shape, a value is not finite, a position lies
            outside the domain, the times do not increase or are unevenly spaced, or
            velocities are missing.
        """
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        positions = np.asarray(positions, dtype=np.float64)
        n = self.ids.size
        t = times.size
        if positions.shape != (t, n, 2):
            raise InputError(f"{self._label}: expected positions of shape ({t}, {n}, 2), "
                             f"got {positions.shape}")
        self._check_times(times)
        self._check_array("position", positions, times)
        self._check_domain(positions, times)
        if self.with_velocity:
            if velocities is None:
                raise InputError(f"{self._label}: this file stores velocities; none were given")
            velocities = np.asarray(velocities, dtype=np.float64)
            if velocities.shape != (t, n, 2):
                raise InputError(f"{self._label}: expected velocities of shape ({t}, {n}, 2)")
            self._check_array("velocity", velocities, times)
        if laps is None:
            laps = np.empty((t, n), dtype=np.int32)
            prev_y, prev_lap = self._last_y, self._last_lap
            for k in range(t):
                y = positions[k, :, 1]
                laps[k] = 0 if prev_y is None else prev_lap + lap_increments(prev_y, y, self.height)
                prev_y, prev_lap = y, laps[k]
        else:
            laps = np.asarray(laps, dtype=np.int32).reshape(t, n)
        f = self._file
        i0, i1 = self._n_frames, self._n_frames + t
        for name in ("frames/time", "frames/position", "frames/lap") + (
                ("frames/velocity",) if self.with_velocity else ()):
            f[name].resize(i1, axis=0)
        f["frames/time"][i0:i1] = times
        f["frames/position"][i0:i1] = positions
        f["frames/lap"][i0:i1] = laps
        if self.with_velocity:
            f["frames/velocity"][i0:i1] = velocities
        self._n_frames = i1
        self._last_time = float(times[-1])
        self._last_y = positions[-1, :, 1].copy()
        self._last_lap = laps[-1].copy()

    def append_fields(self, time: float, spacing, **fields) -> None:
        """Append one frame of gas fields on a cell-centred grid to ``/fields``.

        Parameters
        ----------
        time : float
            Time of the field frame (s).
        spacing : tuple of float
            (dx, dy) of the grid (m).
        **fields : array_like, shape (ny, nx) or (ny, nx, 2)
            Stored as float32: ``void_fraction`` (-), ``gas_velocity`` (m/s),
            ``pressure`` (Pa). Every frame must carry the same fields.

        Raises
        ------
        InputError
            If the fields of the first frame are on different grids, or a later frame
            carries other fields.
        """
        g = self._file.require_group("fields")
        first = "time" not in g
        arrays = {name: np.asarray(value, dtype=np.float32) for name, value in fields.items()}
        if first:
            shapes = {a.shape[:2] for a in arrays.values()}
            if len(shapes) != 1:
                raise InputError(f"{self._label}: gas fields of different grids {sorted(shapes)}")
            ny, nx = shapes.pop()
            g.attrs.update({"spacing": np.asarray(spacing, dtype=np.float64),
                            "origin": np.zeros(2), "shape": np.asarray([nx, ny]),
                            "units": json.dumps({"void_fraction": "-", "gas_velocity": "m/s",
                                                 "pressure": "Pa"})})
            g.create_dataset("time", shape=(0,), maxshape=(None,), dtype="f8", chunks=(1024,))
            for name, a in arrays.items():
                g.create_dataset(name, shape=(0, *a.shape), maxshape=(None, *a.shape),
                                 dtype="f4", chunks=(1, *a.shape))
        elif set(arrays) != set(g) - {"time"}:
            raise InputError(f"{self._label}: gas fields {sorted(arrays)} differ from those of "
                             f"earlier frames {sorted(set(g) - {'time'})}")
        k = g["time"].shape[0]
        g["time"].resize(k + 1, axis=0)
        g["time"][k] = float(time)
        for name, a in arrays.items():
            g[name].resize(k + 1, axis=0)
            g[name][k] = a

    def add_events(self, times, particles, directions) -> None:
        """Store exact pass events, in any order.

        Parameters
        ----------
        times : array_like of float, shape (E,)
            Times of the passes (s).
        particles : array_like of int, shape (E,)
            Particle indices (into ``ids``).
        directions : array_like of int, shape (E,)
            +1 up through the top, -1 down through the bottom.
        """
        times = np.asarray(times, dtype=np.float64)
        order = np.argsort(times, kind="stable")
        g = self._file.require_group("events")
        g.attrs["exact"] = True
        for name, values, dtype in (("time", times, "f8"), ("particle", particles, "i4"),
                                    ("direction", directions, "i1")):
            data = np.asarray(values)[order].astype(dtype)
            if name in g:
                old = g[name]
                old.resize(old.shape[0] + data.size, axis=0)
                old[-data.size:] = data
            else:
                g.create_dataset(name, data=data, maxshape=(None,), chunks=True)

    def attach(self, name: str, datasets: dict[str, np.ndarray], attrs: dict[str, Any] | None = None
               ) -> None:
        """Attach a provenance group ``/provenance/<name>``.

        Parameters
        ----------
        name : str
            The group's name.
        datasets : dict of str to ndarray
            Datasets of the group.
        attrs : dict, optional
            Attributes of the group.
        """
        g = self._file.create_group(f"provenance/{name}")
        for key, value in datasets.items():
            g.create_dataset(key, data=value)
        for key, value in (attrs or {}).items():
            g.attrs[key] = value

    def close(self) -> Path:
        """Finish the file and move it to its final name (nothing if already closed).

        Returns
        -------
        pathlib.Path
            The final path.

        Raises
        ------
        InputError
            If no frame was written (the partial file is discarded) or the rename fails.
        """
        if self._closed:
            return self.path
        if self._n_frames == 0:
            self.abort()
            raise InputError(f"{self._label}: no frames to write")
        self._file.close()
        try:
            publish(self._tmp, self.path)
        finally:
            self._closed = True
        return self.path

    def abort(self) -> None:
        """Discard the partial file."""
        if self._closed:
            return
        try:
            self._file.close()
        finally:
            discard(self._tmp)
            self._closed = True


def write_trajectories(path: str | os.PathLike, times, positions, *, width: float, height: float,
                       ids=None, velocities=None, laps=None, source: str = "arrays",
                       parameters: dict[str, Any] | None = None, events: PassEvents | None = None
                       ) -> Path:
    """Write whole arrays as a trajectory file.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    times : array_like, shape (T,)
        Frame times (s), increasing and evenly spaced.
    positions : array_like, shape (T, N, 2)
        Positions (m).
    width, height : float
        The riser W x H (m).
    ids : array_like of int, shape (N,), optional
        Particle ids (0 .. N-1 by default).
    velocities : array_like, shape (T, N, 2), optional
        Velocities (m/s).
    laps : array_like of int, shape (T, N), optional
        Lap counters (derived by the minimal-image rule when None).
    source : str, optional
        What produced the data.
    parameters : dict, optional
        The producer's parameters.
    events : PassEvents, optional
        Exact pass events.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InputError
        If ``positions`` is not (T, N, 2), or as :class:`TrajectoryWriter`.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[-1] != 2:
        raise InputError(f"positions must have shape (T, N, 2), got {positions.shape}")
    ids = np.arange(positions.shape[1]) if ids is None else ids
    with TrajectoryWriter(path, ids, width=width, height=height, source=source,
                          parameters=parameters, with_velocity=velocities is not None) as w:
        w.append_frames(times, positions, velocities, laps)
        if events is not None:
            w.add_events(events.time, events.particle, events.direction)
    return Path(path)


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.integer, np.floating)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


def _version() -> str:
    from cfbmarkov import __version__

    return __version__
