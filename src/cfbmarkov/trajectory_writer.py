"""Writing trajectory files: frame by frame (:class:`TrajectoryWriter`) or whole arrays
(:func:`write_trajectories`), in the layout that :mod:`cfbmarkov.trajectories` reads
(``docs/definitions.md``, Trajectory files).

Every frame is validated as it is written (finite, inside the domain, evenly spaced
increasing times), and the file appears under its name only when complete: it is written
under a temporary name beside it and renamed (:mod:`cfbmarkov._atomic`).

Even spacing is judged relative to the frame interval, independent of the time origin
(:class:`~cfbmarkov.trajectory_series.FrameSeries`; ``docs/definitions.md``, File formats,
Frame times).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from cfbmarkov import _interrupt
from cfbmarkov._atomic import (discard, is_write_failure, publish, temporary_path, write_error,
                               write_method)
from cfbmarkov._hdf5 import create_array_dataset, json_default
from cfbmarkov._outputs import PREDICTION_SOURCE
from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import InputError
from cfbmarkov.trajectory_checks import check_written_values
from cfbmarkov.trajectory_format import PassEvents, estimate_frame_interval
from cfbmarkov.trajectory_groups import (append_events, append_field_frames, create_frames,
                                         frame_chunks, write_frame_rows)
from cfbmarkov.trajectory_header import header_attrs
from cfbmarkov.trajectory_series import FrameSeries

#: laps from wrapped heights: the largest step between frames (fraction of H) that the
#: importers accept; beyond a quarter a coarse output of a fast particle is likely
IMPORT_MAX_STEP = 0.25


#: files whose writes failed: kept referenced so that they are never closed or freed
_FAILED_FILES: list = []


class TrajectoryWriter:
    """Write a trajectory file frame by frame; the file appears under its name only when closed.

    Every frame is validated (finite, inside the domain, times increasing and evenly spaced);
    the lap counter is derived from the positions by the minimal-image rule when not given.
    When used as a context manager that exits by an exception, or on an error writing to
    the file, the partial file is removed. A frame refused by its checks (an
    :class:`~cfbmarkov.errors.InputError` from :meth:`append_frames`, caught by the caller)
    is not written, and the frames before it are kept: :meth:`close` then publishes them.

    Even spacing: every step between frames must lie within
    :data:`~cfbmarkov.trajectory_format.FRAME_SPACING_TOLERANCE` (1 %) of the reference
    interval, ``frame_interval`` when given, else the median of the steps
    (:class:`~cfbmarkov.trajectory_series.FrameSeries`; of all steps when the file is
    closed). The stored ``frame_interval`` is then the least-squares slope of the times
    (:func:`~cfbmarkov.trajectory_format.estimate_frame_interval`).

    Particles may be absent from frames (inserted later, deleted at an outlet, out of a
    camera's view): give ``present`` to :meth:`append_frames`, and :meth:`add_particles` for
    ids that appear after the first frame. Absent positions and velocities are stored as NaN
    and absent laps as 0; the presence mask ``/frames/present`` is written only when some
    particle is absent from some frame. Laps are counted between consecutive frames in which
    a particle is present: no pass is seen across a gap, and the counter carries on from its
    last value when the particle reappears (``docs/definitions.md``, Presence). An open
    riser's frames are stored compactly (:func:`~cfbmarkov.trajectory_groups.create_frames`).

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
    boundary : Boundary or {"periodic", "open"}, optional
        The vertical boundary: ``periodic`` (what leaves the top re-enters at the bottom;
        laps counted) or ``open`` (inlet at the bottom, outlet at the top; laps are 0);
        stored as its name.
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
    laps_advice : str, optional
        How the source can give the laps itself, named in that refusal (a LAMMPS dump:
        "unwrapped coordinates (xu yu) or image flags (ix iy)"); none: frames written more
        often is the only fix named.

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
                 boundary: str | Boundary = "periodic", axes: dict[str, str] | None = None,
                 region_origin=None, laps_advice: str | None = None):
        self.path = Path(path)
        self.max_step = float(max_step)
        self._laps_advice = laps_advice
        self.ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if np.unique(self.ids).size != self.ids.size:
            raise InputError("particle ids are not unique")
        attrs = header_attrs(width=width, height=height, depth=depth, boundary=boundary,
                             axes=axes, region_origin=region_origin, source=source,
                             parameters=parameters, frame_interval=frame_interval)
        self.width, self.height = float(width), float(height)
        self.depth = None if depth is None else float(depth)
        self.dimensions = 2 if depth is None else 3
        self.boundary = boundary = Boundary.parse(boundary, "boundary")
        self.with_velocity = with_velocity
        self._label = label or str(self.path)
        self._tmp = temporary_path(self.path)
        self._closed = False
        try:
            self._file = h5py.File(self._tmp, "w")
        except (OSError, RuntimeError) as exc:
            discard(self._tmp)
            raise write_error(exc, self.path) from None
        except BaseException:           # Ctrl-C while the file opens: leave nothing behind
            discard(self._tmp)
            raise
        try:
            self._create(attrs, boundary, frame_interval)
        except BaseException:           # e.g. Ctrl-C while the datasets are created
            if not self._closed:
                self.abort()
            raise

    @write_method
    def _create(self, attrs: dict[str, Any], boundary: Boundary, frame_interval) -> None:
        f, d = self._file, self.dimensions
        f.attrs.update(attrs)
        self._compact = boundary.is_open   # particles present a short while each
        # a prediction's chunks deflated (its particles present a short while each); a
        # run's not, so that fitting on it reads as fast as on a periodic one's
        self._deflate = self._compact and attrs.get("source") == PREDICTION_SOURCE
        self._chunk = create_frames(f, self.ids, d, self.with_velocity, self._compact,
                                    self._deflate)
        self._n_frames = 0
        self._series = FrameSeries(self._label, self.height, boundary.is_open, self.max_step,
                                   frame_interval, self._laps_advice)
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
        series = self._series
        if series.last_time is None:
            return None
        return series.last_time, series.last_y, series.last_lap

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
        self._series.continue_after(time, heights, laps, self.ids.size, frame_interval)

    @write_method
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
        self._series.add_particles(new.size)

    def _mark_absent(self) -> None:
        """Create the presence mask on the first absence: every earlier entry present, except
        particles added since (fill value False)."""
        f = self._file
        if "frames/present" in f:
            return
        n = self.ids.size
        ds = f.create_dataset("frames/present", shape=(self._n_frames, n), maxshape=(None, None),
                              dtype="?", fillvalue=False,
                              **frame_chunks(n, self._compact, deflate=self._deflate))
        for i in range(0, self._n_frames, 1024):
            j = min(i + 1024, self._n_frames)
            write_frame_rows(ds, i, np.isfinite(f["frames/position"][i:j, :, 0]), self._compact)

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

    @write_method
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
            spaced, velocities are missing (or given to a file made without them), no frame
            is given, or (laps derived) a particle moved more than ``max_step`` of the
            height between frames.
        """
        _interrupt.check()            # a Ctrl-C swallowed by a finalizer stops here
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        positions = np.asarray(positions, dtype=np.float64)
        n, d = self.ids.size, self.dimensions
        t = times.size
        if positions.shape != (t, n, d):
            raise InputError(f"{self._label}: expected positions of shape ({t}, {n}, {d}), "
                             f"got {positions.shape}")
        if present is None:
            present = np.ones((t, n), dtype=bool)
        else:
            present = np.asarray(present, dtype=bool)
            if present.shape != (t, n):     # reshaped, (N, T) would pass as another layout
                raise InputError(f"{self._label}: expected present of shape ({t}, {n}) (frames, "
                                 f"particles), got {present.shape}")
        absent = not present.all()
        self._series.check_times(times)
        limits = [self.width, self.height] + ([] if self.depth is None else [self.depth])
        check_written_values(self._label, "position", positions, times, present, self.ids,
                             limits, domain=True)
        if t == 0:
            raise InputError(f"{self._label}: no frame to append (times and positions hold "
                             "0 frames); give at least one frame")
        if velocities is not None and not self.with_velocity:
            raise InputError(f"{self._label}: velocities given to a file made without them; "
                             "make it with with_velocity=True to store them")
        if self.with_velocity:
            if velocities is None:
                raise InputError(f"{self._label}: this file stores velocities; none were given")
            velocities = np.asarray(velocities, dtype=np.float64)
            if velocities.shape != (t, n, d):
                raise InputError(f"{self._label}: expected velocities of shape ({t}, {n}, {d})")
            check_written_values(self._label, "velocity", velocities, times, present,
                                 self.ids, limits)
        if absent:
            positions = np.where(present[..., None], positions, np.nan)
            if self.with_velocity:
                velocities = np.where(present[..., None], velocities, np.nan)
        laps = self._series.laps(self.ids, times, positions, present, laps)
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
        rows = {"position": positions, "lap": laps, "velocity": velocities, "present": present}
        for name in names[1:]:
            write_frame_rows(f[name], i0, np.asarray(rows[name.split("/")[1]]), self._compact)
        self._n_frames = i1
        self._series.last_time = float(times[-1])
        self._any_present = self._any_present or bool(present.any())

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

    @write_method
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
        append_field_frames(self._file, self._label, times, spacing, fields)

    @write_method
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
        append_events(self._file, times, particles, directions)

    @write_method
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

    @write_method
    def add_property(self, name: str, values: np.ndarray, attrs: dict[str, Any] | None = None
                     ) -> None:
        """Store a particle property ``/properties/<name>``, float64 [T, N] (NaN where a
        particle is absent), with its attributes (e.g. the law and start rule).

        Parameters
        ----------
        name : str
            The property's name.
        values : ndarray of float64, shape (T, N)
            One row per frame, in the order the frames are written.
        attrs : dict, optional
            Attributes of the dataset.
        """
        ds = self._file.require_group("properties").create_dataset(
            name, data=np.ascontiguousarray(values, dtype=np.float64))
        for key, value in (attrs or {}).items():
            ds.attrs[key] = value

    @write_method
    def update_parameters(self, values: dict[str, Any]) -> None:
        """Add ``values`` to the producer's parameters (what is known only once every row
        has been read: rows dropped, say).

        Parameters
        ----------
        values : dict
            Keys and JSON-serialisable values, replacing those of the same name.
        """
        parameters = json.loads(self._file.attrs["parameters"])
        parameters.update(values)
        self._file.attrs["parameters"] = json.dumps(parameters, default=json_default)

    @write_method
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
        if self._series.interval is not None:
            return      # every step was checked against it as it was written
        times = self._file["frames/time"][()]
        if self._series.continued_from is not None:
            times = np.concatenate([[self._series.continued_from], times])
        if times.size < 2:
            return      # one frame: no interval
        self._series.check_spacing(times, np.diff(times))
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
                       present=None, depth: float | None = None, boundary: str | Boundary = "periodic",
                       axes: dict[str, str] | None = None, region_origin=None,
                       force: bool = False) -> Path:
    """Write whole arrays as a trajectory file.

    An existing trajectory file or prediction at ``path`` is replaced; a file of another
    kind (a model, a text file) only with ``force``, as ``cfbmarkov import`` replaces one
    only with ``--force``.

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
    force : bool, optional
        Replace an existing file of another kind than a trajectory file.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InputError
        If ``positions`` is not (T, N, D) with D = 2 (3 with a depth), ``path`` holds a
        file of another kind and ``force`` is not given, or as :class:`TrajectoryWriter`.
    """
    from cfbmarkov._names import check_output_name
    from cfbmarkov._outputs import _check_kind

    check_output_name(path)             # a missing or empty name, before Path("") is "."
    _check_kind(Path(path), "trajectory", force)
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

