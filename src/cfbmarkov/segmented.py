"""Crash-safe output of long runs: a trajectory file written as a series of segments.

HDF5 files are not safe against a kill in the middle of a write, so a long CFD-DEM run
writes its frames to complete segment files, closed at every checkpoint, and merges them
into one trajectory file at the end (see :class:`SegmentedTrajectoryWriter`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from cfbmarkov._names import parts_folder
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import TrajectoryWriter


class SegmentedTrajectoryWriter:
    """Crash-safe output for long runs: frames go to a series of complete segment files.

    HDF5 files are not safe against a kill in the middle of a write, so a long run writes
    its frames to ``<output>.parts/segment-NNNNN.h5``, each closed (renamed into place
    atomically) at a checkpoint. :meth:`finish` merges the segments into ``output`` (again
    atomically) and removes the folder. After a crash, :meth:`resume` keeps exactly the first
    ``n_segments`` segments named by the last checkpoint and discards the rest, so the run
    continues from a consistent state.

    Parameters
    ----------
    output : str or os.PathLike
        The final trajectory file.
    ids : array_like of int, shape (N,)
        Particle ids.
    width, height : float
        The riser W x H (m).
    source : str
        What produces the file.
    parameters : dict, optional
        The producer's parameters.
    with_velocity : bool, optional
        Store velocities.
    frame_interval : float, optional
        Time between frames (s).
    n_segments : int, optional
        Complete segments already written (see :meth:`resume`).
    run_id : str, optional
        The run's identity, stored in every segment (``/provenance/segment`` attribute
        ``run_id``) and checked by :meth:`resume`: a segment of another run is refused.

    Attributes
    ----------
    output : pathlib.Path
        The final trajectory file.
    parts : pathlib.Path
        The folder of the segments, ``<output>.parts``.
    n_segments : int
        Number of complete segments.
    """

    def __init__(self, output: str | os.PathLike, ids, *, width: float, height: float,
                 source: str, parameters: dict[str, Any] | None = None,
                 with_velocity: bool = False, frame_interval: float | None = None,
                 n_segments: int = 0, run_id: str | None = None):
        self.output = Path(output)
        self.run_id = run_id
        self.parts = parts_folder(self.output)
        self.parts.mkdir(parents=True, exist_ok=True)
        self._options = dict(ids=np.asarray(ids, dtype=np.int64), width=width, height=height,
                             source=source, parameters=parameters,
                             with_velocity=with_velocity, frame_interval=frame_interval)
        self.n_segments = int(n_segments)
        self._current: TrajectoryWriter | None = None
        self._last: tuple[float, np.ndarray, np.ndarray] | None = None

    @classmethod
    def resume(cls, output: str | os.PathLike, n_segments: int, **options) -> "SegmentedTrajectoryWriter":
        """Continue after a crash: keep segments 0..n_segments-1, remove any later ones.

        Parameters
        ----------
        output : str or os.PathLike
            The final trajectory file.
        n_segments : int
            Complete segments recorded by the last checkpoint.
        **options
            The other constructor arguments (ids, width, height, source, ...).

        Returns
        -------
        SegmentedTrajectoryWriter
            Continues the series after the last kept segment.

        Raises
        ------
        InputError
            If one of the kept segments is missing or cannot be read, or (where ``run_id``
            is given) belongs to another run.
        """
        writer = cls(output, n_segments=n_segments, **options)
        for path in writer.parts.glob("segment-*.h5"):
            if int(path.stem.split("-")[1]) >= n_segments:
                path.unlink()
        for path in writer.parts.glob(".segment-*"):
            path.unlink()
        missing = [p for p in writer.segment_paths() if not p.exists()]
        if missing:
            raise InputError(f"cannot resume {output}: segment {missing[0].name} is missing")
        if writer.run_id is not None:
            for path in writer.segment_paths():
                found = segment_run_id(path)
                if found != writer.run_id:
                    raise InputError(
                        f"cannot resume {output}: {path} is not a segment of this run (its "
                        f"run identity is {found or 'missing'}, the checkpoint's "
                        f"{writer.run_id}); put the run's own segment back, or delete "
                        f"{writer.parts} to start again")
        if n_segments:
            with Trajectories(writer.segment_paths()[-1]) as last:
                writer._last = (float(last.times[-1]), last.positions(-1)[:, 1].copy(), last.laps(-1))
        return writer

    def segment_paths(self) -> list[Path]:
        """Paths of the complete segments, in order."""
        return [self.parts / f"segment-{k:05d}.h5" for k in range(self.n_segments)]

    def _writer(self) -> TrajectoryWriter:
        if self._current is None:
            o = self._options
            self._current = TrajectoryWriter(
                self.parts / f"segment-{self.n_segments:05d}.h5", o["ids"], width=o["width"],
                height=o["height"], source=o["source"], parameters=o["parameters"],
                with_velocity=o["with_velocity"], frame_interval=o["frame_interval"],
                label=str(self.output))
            if self.run_id is not None:
                self._current.attach("segment", {}, {"run_id": self.run_id,
                                                     "index": self.n_segments})
            if self._last is not None:     # continue validation and laps across segments
                self._current.continue_after(*self._last, frame_interval=o["frame_interval"])
        return self._current

    def append(self, time: float, position, velocity=None, lap=None) -> None:
        """Append one frame to the current segment.

        See :meth:`cfbmarkov.trajectory_writer.TrajectoryWriter.append` for the arguments and
        the errors.
        """
        self._writer().append(time, position, velocity, lap)

    def add_events(self, times, particles, directions) -> None:
        """Store exact pass events in the current segment (nothing if there are none).

        See :meth:`cfbmarkov.trajectory_writer.TrajectoryWriter.add_events`.
        """
        if len(times):
            self._writer().add_events(times, particles, directions)

    def append_fields(self, time: float, spacing, **fields) -> None:
        """Append one frame of gas fields to the current segment.

        See :meth:`cfbmarkov.trajectory_writer.TrajectoryWriter.append_fields`.
        """
        self._writer().append_fields(time, spacing, **fields)

    def append_frames(self, times, positions, velocities=None, laps=None) -> None:
        """Append a block of frames to the current segment.

        See :meth:`cfbmarkov.trajectory_writer.TrajectoryWriter.append_frames`.
        """
        self._writer().append_frames(times, positions, velocities, laps)

    def append_field_frames(self, times, spacing, **fields) -> None:
        """Append a block of gas-field frames to the current segment.

        See :meth:`cfbmarkov.trajectory_writer.TrajectoryWriter.append_field_frames`.
        """
        self._writer().append_field_frames(times, spacing, **fields)

    def close_segment(self) -> int:
        """Close the current segment (if it holds frames; an empty one is discarded).

        Returns
        -------
        int
            The number of complete segments, the figure a checkpoint must record.

        Raises
        ------
        InputError
            If the segment cannot be put in place.
        """
        w = self._current
        if w is not None:
            if w.n_frames == 0:
                w.abort()
            else:
                self._last = w.last_frame
                w.close()
                self.n_segments += 1
            self._current = None
        return self.n_segments

    def abort(self) -> None:
        """Discard the current, unfinished segment (complete segments stay).

        Temporary files of the next segment are removed too, even one whose writer never
        finished opening (an interrupt can arrive at any point of its creation).
        """
        try:
            if self._current is not None:
                self._current.abort()
                self._current = None
        finally:
            for path in self.parts.glob(f".segment-{self.n_segments:05d}.h5.*.tmp"):
                path.unlink(missing_ok=True)

    def finish(self, attach: dict[str, tuple[dict, dict]] | None = None) -> Path:
        """Merge the segments into the output file and remove the parts folder.

        Parameters
        ----------
        attach : dict of str to (dict, dict), optional
            Provenance groups to attach: name to (datasets, attributes).

        Returns
        -------
        pathlib.Path
            The output file.

        Raises
        ------
        InputError
            If no frame was written, or the output cannot be written.
        """
        self.close_segment()
        paths = self.segment_paths()
        if not paths:
            raise InputError(f"{self.output}: no frames were written")
        o = self._options
        with TrajectoryWriter(self.output, o["ids"], width=o["width"], height=o["height"],
                              source=o["source"], parameters=o["parameters"],
                              with_velocity=o["with_velocity"],
                              frame_interval=o["frame_interval"]) as merged:
            for path in paths:
                with Trajectories(path) as seg:
                    for i in range(0, seg.n_frames, 64):
                        frames = slice(i, min(i + 64, seg.n_frames))
                        merged.append_frames(seg.times[frames], seg.positions(frames),
                                             seg.velocities(frames), seg.laps(frames))
                    events = seg.events()
                    if events is not None and len(events):
                        merged.add_events(events.time, events.particle, events.direction)
                    if seg.has_fields:
                        spacing = seg.field_spacing
                        field_times = seg.field_times
                        for i in range(0, field_times.size, 256):
                            block = slice(i, min(i + 256, field_times.size))
                            merged.append_field_frames(
                                field_times[block], spacing,
                                **{name: seg.field(name, block) for name in seg.field_names})
            for name, (datasets, attrs) in (attach or {}).items():
                merged.attach(name, datasets, attrs)
        # the output is in place: remove the checkpoint first (a kill from here on leaves
        # segments without a checkpoint, which a rerun or --resume clears), then the rest
        (self.parts / "checkpoint.h5").unlink(missing_ok=True)
        for path in paths:
            path.unlink(missing_ok=True)
        for path in self.parts.iterdir():
            path.unlink(missing_ok=True)
        self.parts.rmdir()
        return self.output


def segment_run_id(path: Path) -> str | None:
    """The run identity stored in a segment (None where it holds none).

    Raises
    ------
    InputError
        If the segment cannot be read.
    """
    import h5py

    from cfbmarkov._names import first_line

    try:
        with h5py.File(path, "r") as f:
            group = f.get("provenance/segment")
            value = None if group is None else group.attrs.get("run_id")
    except (OSError, KeyError, RuntimeError, ValueError) as exc:
        raise InputError(f"{path}: unreadable segment ({first_line(exc)}); delete the "
                         "folder to start again") from None
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    return None if value is None else str(value)
