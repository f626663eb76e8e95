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

Frames are evenly spaced within
:data:`~cfbmarkov.trajectory_format.FRAME_SPACING_TOLERANCE` (1 %) of the frame interval,
whatever the time origin, so times printed to a few decimals are accepted. A file of one
frame has no ``frame_interval`` unless its producer gave one; then :meth:`Trajectories.lag_frames`
refuses it (``docs/definitions.md``, File formats, Frame times).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any, Iterator

import h5py
import numpy as np

from cfbmarkov._hdf5 import open_h5
from cfbmarkov.errors import InputError
from cfbmarkov.trajectory_checks import check_pass_events, check_stored_frames
from cfbmarkov.frame_times import FrameTimes
from cfbmarkov.trajectory_format import PassEvents
from cfbmarkov.trajectory_header import read_header


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


class Trajectories(FrameTimes):
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
        without one, :func:`~cfbmarkov.trajectory_format.estimate_frame_interval` of its
        times; NaN for a file of one frame without the attribute (then :meth:`lag_frames`
        raises).
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
        if isinstance(path, Trajectories):     # another handle on the same file
            path = path.path
        if not isinstance(path, (str, os.PathLike)):
            raise InputError(f"expected a trajectory file (its path, or an open Trajectories), "
                             f"got a {type(path).__name__}"
                             + ("; a model is no trajectories: give a run's file"
                                if type(path).__name__ == "MarkovModel" else ""))
        if not os.fspath(path):     # Path("") is "." (the current folder)
            open_h5("")             # refused in one line: an empty file name
        self.path = Path(path)
        self._h5 = open_h5(self.path)
        try:
            header = read_header(self._h5, self.path)
        except InputError:
            self._h5.close()
            raise
        except (KeyError, OSError, ValueError, TypeError) as exc:
            self._h5.close()
            raise InputError(f"{self.path}: damaged trajectory file ({exc})") from None
        self.version = header.version
        self.ids = np.array(header.ids, dtype=np.int64)
        self.ids.setflags(write=False)      # read-only, as the times: answers read them
        self.dimensions = header.dimensions
        self.width, self.height, self.depth = header.width, header.height, header.depth
        self.boundary = header.boundary
        self.axes = header.axes
        self.region_origin = header.region_origin
        self.source = header.source
        self.parameters: dict[str, Any] = header.parameters
        super().__init__(self.path, header.times, header.frame_interval)
        #: frames whose positions and laps have passed the per-frame checks
        self._checked = np.zeros(self.n_frames, dtype=bool)

    # -- per-frame checks -------------------------------------------------------------
    def _check_frames(self, i0: int, i1: int, positions: np.ndarray | None = None,
                      laps: np.ndarray | None = None) -> None:
        """Per-frame checks of frames i0 .. i1 - 1, each frame once, with the frame before
        (:func:`~cfbmarkov.trajectory_checks.check_stored_frames`). ``positions`` /
        ``laps`` are those frames when already read."""
        if i1 <= i0 or self._checked[i0:i1].all():
            return
        f = self._file
        pos = f["frames/position"][i0:i1] if positions is None else positions
        lap = f["frames/lap"][i0:i1] if laps is None else laps
        present = self.present(slice(i0, i1))
        extent = np.array([self.width, self.height] + ([self.depth] if self.dimensions == 3 else []))
        if i0 > 0:      # the step from the frame before, first: the first problem in order
            check_stored_frames(self.path, self.ids, self.times[i0 - 1:i0 + 1],
                                np.concatenate([f["frames/position"][i0 - 1:i0], pos[:1]]),
                                np.concatenate([f["frames/lap"][i0 - 1:i0], lap[:1]]),
                                self.present(slice(i0 - 1, i0 + 1)), extent, self.height,
                                self.boundary.is_open)
        check_stored_frames(self.path, self.ids, self.times[i0:i1], pos, lap, present, extent,
                            self.height, self.boundary.is_open)
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

    @property
    def _file(self):
        """The open HDF5 file; refused in one line once closed (h5py's own error is a
        KeyError about an invalid identifier)."""
        if not self._h5.id.valid:
            raise InputError(f"{self.path}: the trajectory file is closed (read after its "
                             "`with` block or close()); open it again: Trajectories(path)")
        return self._h5

    def __reduce__(self):
        """Pickled by its path (an h5py file cannot be): unpickled, e.g. in a worker
        process, it is the same file opened again."""
        return (type(self), (os.path.abspath(self.path),))

    @property
    def closed(self) -> bool:
        """Whether the file has been closed."""
        return not self._h5.id.valid

    def close(self) -> None:
        """Close the file."""
        self._h5.close()

    def __enter__(self) -> "Trajectories":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        span = f"{self.times[0]:g}..{self.times[-1]:g} s"
        every = (f", every {self.frame_interval:g} s" if np.isfinite(self.frame_interval) else "")
        return (f"Trajectories({str(self.path)!r}: {self.n_particles} "
                f"particle{'' if self.n_particles == 1 else 's'} x {self.n_frames} "
                f"frame{'' if self.n_frames == 1 else 's'}, {span}{every}, "
                f"source={self.source!r}"
                + (", closed" if self.closed else "") + ")")

    # -- metadata --------------------------------------------------------------------
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
        if self.boundary.is_open and not open_boundary:
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
                    if self.dimensions == 3 and not three_d else
                    ": a periodic riser's passes cannot be followed across a particle's gap; "
                    "import the tracks again with --boundary open where particles enter and "
                    "leave through the riser's faces (each gap an exit and an entry; not "
                    "where a tracer is out of view)"
                    if self.has_absences and not absent and not self.boundary.is_open else "")
            raise InputError(f"{self.path}: {purpose} cannot use {' and '.join(reasons)} yet{hint}")

    @property
    def has_events(self) -> bool:
        """Whether the file stores exact pass events."""
        return "events/time" in self._file

    @property
    def attrs(self) -> dict[str, Any]:
        """The root attributes of the file (bytes decoded to str)."""
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in self._file.attrs.items()}

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

    def absent_throughout(self, frames: slice) -> np.ndarray | None:
        """The particles absent from every one of ``frames``, where every other particle
        is present in all of them; None where some particle is present in part of them.

        Such absences hide no pass: a particle outside the riser's region in every frame (a
        dump's atom beyond the walls) is simply not part of the flow there, and residences,
        mixing and comparisons over ``frames`` follow the others as in a file without
        absences (``docs/definitions.md``, Residence times across absences).

        Parameters
        ----------
        frames : slice
            A range of frames (step 1).

        Returns
        -------
        ndarray of bool, shape (N,), or None
            True for each particle absent throughout (all False in a file without
            absences).
        """
        ever = np.zeros(self.n_particles, dtype=bool)
        always = np.ones(self.n_particles, dtype=bool)
        if self.has_absences:
            start, stop, _ = frames.indices(self.n_frames)
            for k in range(start, stop, 256):           # blocks of frames: bounded memory
                present = self.present(slice(k, min(k + 256, stop)))
                ever |= present.any(axis=0)
                always &= present.all(axis=0)
        return ~ever if np.array_equal(ever, always) else None

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

        Raises
        ------
        InputError
            If the events are damaged (:func:`~cfbmarkov.trajectory_checks.check_pass_events`).
        """
        if not self.has_events:
            return None
        g = self._file["events"]
        events = PassEvents(g["time"][()], g["particle"][()], g["direction"][()])
        check_pass_events(self.path, events, self.n_particles)
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

    @property
    def property_names(self) -> list[str]:
        """Names of the particle properties stored under ``/properties`` (a prediction
        with kinetics; ``docs/definitions.md``, Properties along particle paths)."""
        return sorted(self._file["properties"]) if "properties" in self._file else []

    def property_values(self, name: str, frames: int | slice = slice(None)) -> np.ndarray:
        """A particle property at frames, float64 [N] or [T, N] (NaN where absent).

        Raises
        ------
        InputError
            If the file has no property of that name.
        """
        if name not in self.property_names:
            raise InputError(f"{self.path}: no particle property '{name}' (has: "
                             f"{', '.join(self.property_names) or 'none'})")
        return self._file["properties"][name][frames]

    def property_attrs(self, name: str) -> dict:
        """The attributes stored with ``/properties/NAME`` (a prediction's: ``law``,
        ``start``, ``initial``, ``fingerprint``, ``fingerprint_method``; a file written
        before fingerprints holds none of the last two).

        Raises
        ------
        InputError
            If the file has no property of that name.
        """
        if name not in self.property_names:
            raise InputError(f"{self.path}: no particle property '{name}' (has: "
                             f"{', '.join(self.property_names) or 'none'})")
        return {k: (v.decode() if isinstance(v, bytes) else v)
                for k, v in self._file["properties"][name].attrs.items()}

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

