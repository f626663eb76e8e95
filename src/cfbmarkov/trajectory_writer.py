"""Writing trajectory files: frame by frame (:class:`TrajectoryWriter`) or whole arrays
(:func:`write_trajectories`), in the layout that :mod:`cfbmarkov.trajectories` reads
(``docs/definitions.md``, Trajectory files).

Every frame is validated as it is written (finite, inside the domain, evenly spaced
increasing times), and the file appears under its name only when complete: it is written
under a temporary name beside it and renamed (:mod:`cfbmarkov._atomic`).

Even spacing is judged relative to the frame interval, independent of the time origin:
every step between frames must lie within :data:`~cfbmarkov.trajectories.FRAME_SPACING_TOLERANCE`
(1 %) of the reference interval, the caller's ``frame_interval`` when given, else the
median step (``docs/definitions.md``, File formats, Frame times). 1 % accepts times printed
to 5 decimals at frame rates up to 1 kHz: rounding to q s moves a step by at most q
(1e-5 s, 1 % of 1 ms) and still refuses a missing frame (100 %) or a step a few per cent
off.
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import os
from pathlib import Path
from typing import Any

import h5py
import numba as nb
import numpy as np

from cfbmarkov import _interrupt
from cfbmarkov._atomic import (discard, is_write_failure, late_write_failure, publish,
                               temporary_path, write_error)
from cfbmarkov._hdf5 import create_array_dataset, json_default, package_version
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import (BOUNDARIES, FORMAT, FRAME_SPACING_TOLERANCE, POSITION_TOLERANCE,
                                    VERSION, PassEvents, _t, estimate_frame_interval, lap_increments)

#: steps before a block that join its own in the median a block's steps are judged against
RECENT_STEPS = 64
#: laps from wrapped heights: the largest step between frames (fraction of H) that the
#: importers accept; beyond a quarter a coarse output of a fast particle is likely
IMPORT_MAX_STEP = 0.25
#: fewest particles per chunk of a frame (a file whose particles grow by insertion)
MIN_CHUNK_PARTICLES = 256


#: files whose writes failed: kept referenced so that they are never closed or freed
_FAILED_FILES: list = []


def _writes(method):
    """Method decorator: a failed write (no space left, file too large, ...) discards the
    partial file and becomes one InputError naming the output and the cause."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            result = method(self, *args, **kwargs)
            late = late_write_failure()
        except (OSError, RuntimeError) as exc:
            if not is_write_failure(exc):
                raise
            late = exc
        if late is not None:
            self._fail()
            raise write_error(late, self.path) from None
        return result
    return wrapper


class TrajectoryWriter:
    """Write a trajectory file frame by frame; the file appears under its name only when closed.

    Every frame is validated (finite, inside the domain, times increasing and evenly spaced);
    the lap counter is derived from the positions by the minimal-image rule when not given.
    On an error, or when used as a context manager that exits by an exception, the partial
    file is removed.

    Even spacing: every step between frames must lie within
    :data:`~cfbmarkov.trajectories.FRAME_SPACING_TOLERANCE` (1 %) of the reference
    interval, whatever the time origin. The reference is ``frame_interval`` when given;
    otherwise the median of the steps: of each block with the steps just before it as it is
    written (the first step while fewer than three are known), and of all steps when the
    file is closed. The stored ``frame_interval`` is then the least-squares slope of the
    times (:func:`~cfbmarkov.trajectories.estimate_frame_interval`), exact to far below one
    rounding step for times printed to a few decimals.

    Particles may be absent from frames (inserted later, deleted at an outlet, out of a
    camera's view): give ``present`` to :meth:`append_frames`, and :meth:`add_particles` for
    ids that appear after the first frame. Absent positions and velocities are stored as NaN
    and absent laps as 0; the presence mask ``/frames/present`` is written only when some
    particle is absent from some frame. Laps are counted between consecutive frames in which
    a particle is present: no pass is seen across a gap, and the counter carries on from its
    last value when the particle reappears (``docs/definitions.md``, Presence).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write; its folder is created if needed.
    ids : array_like of int, shape (N,)
        Unique particle ids, the column order of every frame (N may be 0 when every
        particle is added later by :meth:`add_particles`).
    width, height : float
        The riser W x H (m), positive.
    depth : float, optional
        The riser's depth (m) for 3D positions (across, vertical, depth); 2D when None.
    boundary : {"periodic", "open"}, optional
        The vertical boundary: ``periodic`` (what leaves the top re-enters at the bottom;
        laps counted) or ``open`` (inlet at the bottom, outlet at the top; laps are 0).
    axes : dict, optional
        The source's axis letter of each stored axis, keys ``across``, ``vertical`` and (3D)
        ``depth``; default x, y (, z).
    region_origin : array_like of float, shape (D,), optional
        Source coordinates (m) of the stored origin, in the stored axis order (across,
        vertical[, depth]); default zeros.
    source : str
        What produces the file (e.g. ``cfd-dem``, ``markov-prediction``).
    parameters : dict, optional
        The producer's parameters, stored as JSON.
    with_velocity : bool, optional
        Store velocities (then every frame must carry them).
    frame_interval : float, optional
        Time between frames (s), the reference for the spacing check and stored as is; by
        default estimated from the times when the file is closed.
    label : str, optional
        Names the file in error messages (default: ``path``).
    max_step : float, optional
        Where laps are derived from the heights (none given), the largest step a particle
        may make between frames, as a fraction of the height H (default 0.5: beyond it the
        minimal-image rule cannot work; the importers use ``IMPORT_MAX_STEP`` = 0.25); a
        larger step is refused, naming the particle and the times.

    Raises
    ------
    InputError
        If the ids are not unique, the domain is not of positive size, the boundary is
        unknown, or ``frame_interval`` is not a positive number.

    Notes
    -----
    See ``docs/definitions.md`` (File formats, Trajectory files; Lap counter).
    """

    def __init__(self, path: str | os.PathLike, ids, *, width: float, height: float,
                 source: str, parameters: dict[str, Any] | None = None,
                 with_velocity: bool = False, frame_interval: float | None = None,
                 label: str | None = None, max_step: float = 0.5, depth: float | None = None,
                 boundary: str = "periodic", axes: dict[str, str] | None = None,
                 region_origin=None):
        self.path = Path(path)
        self.max_step = float(max_step)
        self.ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if np.unique(self.ids).size != self.ids.size:
            raise InputError("particle ids are not unique")
        if not (width > 0 and height > 0) or (depth is not None and not depth > 0):
            size = f"{width:g} x {height:g}" + ("" if depth is None else f" x {depth:g}")
            raise InputError(f"domain {size} m must have positive size")
        if boundary not in BOUNDARIES:
            raise InputError(f"boundary {boundary!r}: choose periodic or open")
        if frame_interval is not None and not (np.isfinite(frame_interval) and frame_interval > 0):
            raise InputError(f"frame interval {frame_interval!r} s must be a positive number")
        self.width, self.height = float(width), float(height)
        self.depth = None if depth is None else float(depth)
        self.dimensions = 2 if depth is None else 3
        self.boundary = boundary
        self.with_velocity = with_velocity
        self._label = label or str(self.path)
        axes = dict(axes or {})
        axes = {"across": axes.get("across", "x"), "vertical": axes.get("vertical", "y"),
                "depth": axes.get("depth", "z") if self.dimensions == 3 else ""}
        origin = np.zeros(self.dimensions) if region_origin is None else np.asarray(
            region_origin, dtype=np.float64).reshape(-1)
        if origin.size != self.dimensions:
            raise InputError(f"region origin {origin.tolist()} needs {self.dimensions} coordinates")
        self._tmp = temporary_path(self.path)
        self._closed = False
        n, d = self.ids.size, self.dimensions
        try:
            self._file = h5py.File(self._tmp, "w")
        except (OSError, RuntimeError) as exc:
            discard(self._tmp)
            raise write_error(exc, self.path) from None
        except BaseException:           # Ctrl-C while the file opens: leave nothing behind
            discard(self._tmp)
            raise
        try:
            self._create(n, d, source, parameters, origin, axes, boundary, frame_interval)
        except BaseException:           # e.g. Ctrl-C while the datasets are created
            if not self._closed:
                self.abort()
            raise

    @_writes
    def _create(self, n, d, source, parameters, origin, axes, boundary, frame_interval) -> None:
        f = self._file
        f.attrs.update({
            "format": FORMAT, "version": VERSION, "width": self.width, "height": self.height,
            "dimensions": d, "boundary": boundary, "across_axis": axes["across"],
            "vertical_axis": axes["vertical"], "depth_axis": axes["depth"],
            "region_origin": origin,
            "length_unit": "m", "time_unit": "s", "source": source,
            "parameters": json.dumps(parameters or {}, default=json_default),
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "cfbmarkov_version": package_version(),
        })
        if self.depth is not None:
            f.attrs["depth"] = self.depth
        if frame_interval is not None:
            f.attrs["frame_interval"] = float(frame_interval)
        chunk = max(n, MIN_CHUNK_PARTICLES)
        f.create_dataset("particles/id", data=self.ids, maxshape=(None,), chunks=(max(n, 1024),))
        f.create_dataset("frames/time", shape=(0,), maxshape=(None,), dtype="f8", chunks=(4096,))
        f.create_dataset("frames/position", shape=(0, n, d), maxshape=(None, None, d), dtype="f8",
                         chunks=(1, chunk, d), fillvalue=np.nan)
        f.create_dataset("frames/lap", shape=(0, n), maxshape=(None, None), dtype="i4",
                         chunks=(1, chunk))
        if self.with_velocity:
            f.create_dataset("frames/velocity", shape=(0, n, d), maxshape=(None, None, d),
                             dtype="f8", chunks=(1, chunk, d), fillvalue=np.nan)
        self._chunk = chunk
        self._n_frames = 0
        self._last_time: float | None = None
        self._continued_from: float | None = None   # last time of the series continued
        self._interval = None if frame_interval is None else float(frame_interval)
        self._recent_steps = np.zeros(0)
        self._last_y: np.ndarray | None = None       # last height seen of each particle
        self._last_lap: np.ndarray | None = None     # its lap counter then
        self._last_present: np.ndarray | None = None  # present in the last frame written
        self._any_present = False

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
    def any_present(self) -> bool:
        """Whether some particle was present in some frame written so far."""
        return self._any_present

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
        self._last_time = self._continued_from = float(time)
        self._last_y = np.asarray(heights, dtype=np.float64).copy()
        self._last_lap = np.asarray(laps, dtype=np.int32).copy()
        self._last_present = np.ones(self.ids.size, dtype=bool)
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
            raise InputError(f"{self._label}: time does not increase at t = {_t(allt[k + 1])} s "
                             f"(after {_t(allt[k])} s)")
        known = np.concatenate([self._recent_steps, steps])
        self._check_spacing(allt, known, known.size - steps.size)
        self._recent_steps = known[-RECENT_STEPS:]

    def _check_spacing(self, times: np.ndarray, steps: np.ndarray, first: int = 0) -> None:
        """Refuse the first of ``steps[first:]`` (between ``times[i - first]`` and the
        next) more than FRAME_SPACING_TOLERANCE off the reference interval."""
        if self._interval is not None:
            reference, what = self._interval, "the frame interval"
        elif steps.size >= 3:
            reference, what = float(np.median(steps)), "the median step"
        else:
            reference, what = float(steps[0]), "the first step"
        bad = np.abs(steps[first:] - reference) > FRAME_SPACING_TOLERANCE * reference
        if np.any(bad):
            k = int(np.argmax(bad))
            raise InputError(
                f"{self._label}: frames unevenly spaced: {_t(steps[first + k])} s between "
                f"t = {_t(times[k])} and {_t(times[k + 1])} s, expected {_t(reference)} s "
                f"({what}, within {FRAME_SPACING_TOLERANCE:.0%}); for irregular frame times "
                "(tracking data such as PEPT, or missing frames) resample them with --resample "
                "DT --max-gap G")

    def _check_array(self, name: str, values: np.ndarray, times: np.ndarray,
                     present: np.ndarray, domain: bool = False) -> None:
        """Refuse a present value that is not finite, or (``domain``) a present position
        outside the domain by more than ``POSITION_TOLERANCE``; one pass
        (:func:`_values_problem`), the first problem in frame, then particle order."""
        limits = [self.width, self.height] + ([] if self.depth is None else [self.depth])
        code, t_idx, p_idx = _values_problem(np.ascontiguousarray(values), present,
                                             np.asarray(limits, dtype=np.float64),
                                             POSITION_TOLERANCE, domain)
        if code == 1:
            raise InputError(f"{self._label}: {name} of particle {self.ids[p_idx]} at t = "
                             f"{times[t_idx]:g} s is not a finite number")
        if code == 2:
            where = ", ".join(f"{v:g}" for v in values[t_idx, p_idx])
            size = " x ".join(f"0..{v:g}" for v in limits)
            raise InputError(
                f"{self._label}: particle {self.ids[p_idx]} at t = {times[t_idx]:g} s lies outside "
                f"the domain {size} m at ({where})")

    def _check_minimal_image(self, previous_y: np.ndarray, y: np.ndarray, t0, t1,
                             both: np.ndarray) -> None:
        """Laps from wrapped heights need small steps: refuse a particle that moved more
        than ``max_step`` of the height between two frames (by the minimal image; beyond
        half the height its pass through the periodic boundary, or not, cannot be told from
        the positions at all)."""
        step = np.where(both, np.abs(y - previous_y), 0.0)
        step = np.minimum(step, self.height - step)          # the minimal image
        worst = int(np.argmax(step)) if step.size else 0
        if step.size and step[worst] > self.max_step * self.height:
            raise InputError(
                f"{self._label}: particle {int(self.ids[worst])} moved {step[worst]:.4g} m "
                f"(more than {self.max_step:g} of the height {self.height:g} m) between t = {t0:g} "
                f"and {t1:g} s: the lap counter cannot be inferred from wrapped positions; "
                "write frames more often, or give unwrapped coordinates (xu yu) or image "
                "flags (ix iy)")

    # -- writing -----------------------------------------------------------------------
    @_writes
    def add_particles(self, ids) -> None:
        """Add particles that appear after the first frame (inserted, entering the view):
        new columns, absent from every frame written so far.

        Parameters
        ----------
        ids : array_like of int, shape (M,)
            New ids, none already in the file.

        Raises
        ------
        InputError
            If an id is already in the file or given twice.
        """
        new = np.asarray(ids, dtype=np.int64).reshape(-1)
        if new.size == 0:
            return
        if np.unique(new).size != new.size or np.isin(new, self.ids).any():
            raise InputError(f"{self._label}: particle ids added twice")
        n0, n1 = self.ids.size, self.ids.size + new.size
        f = self._file
        f["particles/id"].resize(n1, axis=0)
        f["particles/id"][n0:] = new
        names = ["frames/position", "frames/lap"] + (["frames/velocity"] if self.with_velocity else [])
        if "frames/present" in f:
            names.append("frames/present")
        for name in names:
            f[name].resize(n1, axis=1)
        self.ids = np.concatenate([self.ids, new])
        if self._n_frames:
            self._mark_absent()       # the new particles are absent from the frames so far
        if self._last_y is not None:
            self._last_y = np.concatenate([self._last_y, np.full(new.size, np.nan)])
            self._last_lap = np.concatenate([self._last_lap, np.zeros(new.size, np.int32)])
            self._last_present = np.concatenate([self._last_present, np.zeros(new.size, bool)])

    def _mark_absent(self) -> None:
        """Create the presence mask on the first absence: every earlier entry present, except
        particles added since (fill value False)."""
        f = self._file
        if "frames/present" in f:
            return
        n = self.ids.size
        ds = f.create_dataset("frames/present", shape=(self._n_frames, n), maxshape=(None, None),
                              dtype="?", chunks=(1, self._chunk), fillvalue=False)
        for i in range(0, self._n_frames, 1024):
            j = min(i + 1024, self._n_frames)
            ds[i:j] = np.isfinite(f["frames/position"][i:j, :, 0])

    def append(self, time: float, position, velocity=None, lap=None, present=None) -> None:
        """Append one frame.

        Parameters
        ----------
        time : float
            Frame time (s).
        position : array_like, shape (N, D)
            Positions (m); D = 2, or 3 with a depth.
        velocity : array_like, shape (N, D), optional
            Velocities (m/s); required when the file stores velocities.
        lap : array_like of int, shape (N,), optional
            Lap counters (derived by the minimal-image rule when None).
        present : array_like of bool, shape (N,), optional
            Which particles are in the frame (default: all).

        Raises
        ------
        InputError
            As :meth:`append_frames`.
        """
        self.append_frames(np.asarray([time], dtype=float), np.asarray(position)[None],
                           None if velocity is None else np.asarray(velocity)[None],
                           None if lap is None else np.asarray(lap)[None],
                           None if present is None else np.asarray(present)[None])

    @_writes
    def append_frames(self, times, positions, velocities=None, laps=None, present=None) -> None:
        """Append a block of frames.

        Parameters
        ----------
        times : array_like, shape (T,)
            Frame times (s), increasing, evenly spaced, following the last frame.
        positions : array_like, shape (T, N, D)
            Positions (m), inside the domain where present (anything, NaN included, where
            absent); D = 2, or 3 with a depth.
        velocities : array_like, shape (T, N, D), optional
            Velocities (m/s); required when the file stores velocities.
        laps : array_like of int, shape (T, N), optional
            Lap counters (derived by the minimal-image rule when None; 0 for an open riser).
        present : array_like of bool, shape (T, N), optional
            Which particles are in each frame (default: all).

        Raises
        ------
        InputError
            If an array has the wrong shape, a present value is not finite, a present
            position lies outside the domain, the times do not increase or are unevenly
            spaced, velocities are missing, or (laps derived) a particle moved more than
            ``max_step`` of the height between frames.
        """
        _interrupt.check()            # a Ctrl-C swallowed by a finalizer stops here
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        positions = np.asarray(positions, dtype=np.float64)
        n, d = self.ids.size, self.dimensions
        t = times.size
        if positions.shape != (t, n, d):
            raise InputError(f"{self._label}: expected positions of shape ({t}, {n}, {d}), "
                             f"got {positions.shape}")
        present = np.ones((t, n), dtype=bool) if present is None else np.asarray(
            present, dtype=bool).reshape(t, n)
        absent = not present.all()
        self._check_times(times)
        self._check_array("position", positions, times, present, domain=True)
        if self.with_velocity:
            if velocities is None:
                raise InputError(f"{self._label}: this file stores velocities; none were given")
            velocities = np.asarray(velocities, dtype=np.float64)
            if velocities.shape != (t, n, d):
                raise InputError(f"{self._label}: expected velocities of shape ({t}, {n}, {d})")
            self._check_array("velocity", velocities, times, present)
        if absent:
            positions = np.where(present[..., None], positions, np.nan)
            if self.with_velocity:
                velocities = np.where(present[..., None], velocities, np.nan)
        laps = self._laps(times, positions, present, laps)
        f = self._file
        if absent:
            self._mark_absent()
        i0, i1 = self._n_frames, self._n_frames + t
        names = ["frames/time", "frames/position", "frames/lap"] + (
            ["frames/velocity"] if self.with_velocity else [])
        if "frames/present" in f:
            names.append("frames/present")
        for name in names:
            f[name].resize(i1, axis=0)
        f["frames/time"][i0:i1] = times
        f["frames/position"][i0:i1] = positions
        f["frames/lap"][i0:i1] = laps
        if self.with_velocity:
            f["frames/velocity"][i0:i1] = velocities
        if "frames/present" in f:
            f["frames/present"][i0:i1] = present
        self._n_frames = i1
        self._last_time = float(times[-1])
        self._any_present = self._any_present or bool(present.any())

    def _laps(self, times, positions, present, laps) -> np.ndarray:
        """The lap counters of a block: given, 0 for an open riser, or by the minimal-image
        rule between consecutive frames where a particle is present (carried over gaps);
        updates the last height, lap and presence of every particle."""
        t, n = present.shape
        if laps is not None:
            laps = np.where(present, np.asarray(laps, dtype=np.int32).reshape(t, n), 0)
            if self._last_y is None:
                self._last_y = np.full(n, np.nan)
                self._last_lap = np.zeros(n, np.int32)
            seen = present.any(axis=0)
            last = t - 1 - np.argmax(present[::-1], axis=0)
            cols = np.arange(n)
            self._last_y = np.where(seen, positions[last, cols, 1], self._last_y)
            self._last_lap = np.where(seen, laps[last, cols], self._last_lap).astype(np.int32)
            self._last_present = present[-1].copy()
            return laps
        if self.boundary == "open":
            return np.zeros((t, n), dtype=np.int32)
        out = np.zeros((t, n), dtype=np.int32)
        prev_y, prev_lap, prev_present = self._last_y, self._last_lap, self._last_present
        prev_t = self._last_time
        for k in range(t):
            y = positions[k, :, 1]
            if prev_y is None:
                lap = np.zeros(n, dtype=np.int32)
                prev_y = np.full(n, np.nan)
            else:
                both = present[k] & prev_present
                self._check_minimal_image(prev_y, y, prev_t, times[k], both)
                with np.errstate(invalid="ignore"):
                    step = lap_increments(prev_y, y, self.height)
                lap = prev_lap + np.where(both, step, 0).astype(np.int32)
            out[k] = np.where(present[k], lap, 0)
            prev_y = np.where(present[k], y, prev_y)
            prev_lap, prev_present, prev_t = lap, present[k], times[k]
        self._last_y, self._last_lap, self._last_present = prev_y, prev_lap, prev_present
        return out

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
        self.append_field_frames([time], spacing,
                                 **{name: np.asarray(value)[None] for name, value in fields.items()})

    @_writes
    def append_field_frames(self, times, spacing, **fields) -> None:
        """Append a block of gas-field frames to ``/fields`` (one write per field).

        Parameters
        ----------
        times : array_like, shape (T,)
            Times of the field frames (s).
        spacing : tuple of float
            (dx, dy) of the grid (m).
        **fields : array_like, shape (T, ny, nx) or (T, ny, nx, 2)
            As in :meth:`append_fields`, with a leading frame axis.

        Raises
        ------
        InputError
            If the fields are on different grids or do not hold T frames, or they are not
            the fields of earlier frames.
        """
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        g = self._file.require_group("fields")
        first = "time" not in g
        arrays = {name: np.asarray(value, dtype=np.float32) for name, value in fields.items()}
        if any(a.ndim < 3 or a.shape[0] != times.size for a in arrays.values()):
            raise InputError(f"{self._label}: gas fields must hold {times.size} frame(s) of a "
                             "2D grid each")
        if first:
            shapes = {a.shape[1:3] for a in arrays.values()}
            if len(shapes) != 1:
                raise InputError(f"{self._label}: gas fields of different grids {sorted(shapes)}")
            ny, nx = shapes.pop()
            g.attrs.update({"spacing": np.asarray(spacing, dtype=np.float64),
                            "origin": np.zeros(2), "shape": np.asarray([nx, ny]),
                            "units": json.dumps({"void_fraction": "-", "gas_velocity": "m/s",
                                                 "pressure": "Pa"})})
            g.create_dataset("time", shape=(0,), maxshape=(None,), dtype="f8", chunks=(1024,))
            for name, a in arrays.items():
                g.create_dataset(name, shape=(0, *a.shape[1:]), maxshape=(None, *a.shape[1:]),
                                 dtype="f4", chunks=(1, *a.shape[1:]))
        elif set(arrays) != set(g) - {"time"}:
            raise InputError(f"{self._label}: gas fields {sorted(arrays)} differ from those of "
                             f"earlier frames {sorted(set(g) - {'time'})}")
        k = g["time"].shape[0]
        g["time"].resize(k + times.size, axis=0)
        g["time"][k:] = times
        for name, a in arrays.items():
            g[name].resize(k + times.size, axis=0)
            g[name][k:] = a

    @_writes
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

    @_writes
    def attach(self, name: str, datasets: dict[str, np.ndarray], attrs: dict[str, Any] | None = None
               ) -> None:
        """Attach a provenance group ``/provenance/<name>``.

        Parameters
        ----------
        name : str
            The group's name.
        datasets : dict of str to ndarray
            Datasets of the group, written by :func:`create_array_dataset` (arrays of two or
            more dimensions compressed).
        attrs : dict, optional
            Attributes of the group.
        """
        g = self._file.create_group(f"provenance/{name}")
        for key, value in datasets.items():
            create_array_dataset(g, key, value)
        for key, value in (attrs or {}).items():
            g.attrs[key] = value

    @_writes
    def close(self) -> Path:
        """Finish the file and move it to its final name (nothing if already closed).

        Returns
        -------
        pathlib.Path
            The final path.

        Raises
        ------
        InputError
            If no frame or no particle was written (the partial file is discarded) or the
            rename fails.
        """
        if self._closed:
            return self.path
        if self._n_frames == 0 or self.ids.size == 0:
            self.abort()
            raise InputError(f"{self._label}: no " + ("frames" if self._n_frames == 0 else
                                                      "particle in any frame") + " to write")
        try:
            self._finish_times()
        except BaseException:
            self.abort()
            raise
        try:
            self._file.close()
        except BaseException:
            self._closed = True     # never close twice: HDF5 may crash after a failed close
            discard(self._tmp)
            raise
        try:
            publish(self._tmp, self.path)
        finally:
            self._closed = True
        return self.path

    def _finish_times(self) -> None:
        """Check the spacing of all frames against their median step and store the frame
        interval estimated from them (when the caller gave none)."""
        if self._interval is not None:
            return      # every step was checked against it as it was written
        times = self._file["frames/time"][()]
        if self._continued_from is not None:
            times = np.concatenate([[self._continued_from], times])
        if times.size < 2:
            return      # one frame: no interval
        self._check_spacing(times, np.diff(times))
        self._file.attrs["frame_interval"] = estimate_frame_interval(times)

    def abort(self) -> None:
        """Discard the partial file."""
        if self._closed:
            return
        try:
            self._file.close()
        except (OSError, RuntimeError) as exc:
            if not is_write_failure(exc):
                raise
        finally:
            discard(self._tmp)
            self._closed = True

    def _fail(self) -> None:
        """After a failed write: discard the file without closing it (HDF5 may crash when
        it closes a file whose writes failed; the command line then ends with os._exit)."""
        if self._closed:
            return
        self._closed = True
        _FAILED_FILES.append(self._file)    # never freed, never closed
        discard(self._tmp)


def write_trajectories(path: str | os.PathLike, times, positions, *, width: float, height: float,
                       ids=None, velocities=None, laps=None, source: str = "arrays",
                       parameters: dict[str, Any] | None = None, events: PassEvents | None = None,
                       present=None, depth: float | None = None, boundary: str = "periodic",
                       axes: dict[str, str] | None = None, region_origin=None) -> Path:
    """Write whole arrays as a trajectory file.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    times : array_like, shape (T,)
        Frame times (s), increasing and evenly spaced.
    positions : array_like, shape (T, N, D)
        Positions (m); D = 2, or 3 with ``depth``.
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
    present : array_like of bool, shape (T, N), optional
        Which particles are in each frame (default: all).
    depth, boundary, axes, region_origin : optional
        As :class:`TrajectoryWriter`.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InputError
        If ``positions`` is not (T, N, D) with D = 2 (3 with a depth), or as
        :class:`TrajectoryWriter`.
    """
    positions = np.asarray(positions, dtype=np.float64)
    d = 2 if depth is None else 3
    if positions.ndim != 3 or positions.shape[-1] != d:
        raise InputError(f"positions must have shape (T, N, {d}), got {positions.shape}")
    ids = np.arange(positions.shape[1]) if ids is None else ids
    with TrajectoryWriter(path, ids, width=width, height=height, source=source,
                          parameters=parameters, with_velocity=velocities is not None, depth=depth,
                          boundary=boundary, axes=axes, region_origin=region_origin) as w:
        w.append_frames(times, positions, velocities, laps, present)
        if events is not None:
            w.add_events(events.time, events.particle, events.direction)
    return Path(path)


@nb.njit(cache=True)
def _values_problem(values, present, extent, tol, domain):
    """The first problem of a block of per-particle values, in one pass without
    temporaries: (code, frame, particle), code 0 none, 1 a present value not finite, 2
    (``domain``) a present position outside [-tol, extent + tol] on some axis. A particle's
    non-finite value is reported before its being outside."""
    n_frames, n_particles, d = values.shape
    for k in range(n_frames):
        for p in range(n_particles):
            if not present[k, p]:
                continue
            for c in range(d):
                if not np.isfinite(values[k, p, c]):
                    return 1, k, p
            if domain:
                for c in range(d):
                    v = values[k, p, c]
                    if v < -tol or v > extent[c] + tol:
                        return 2, k, p
    return 0, 0, 0
