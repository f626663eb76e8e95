"""What the next block of frames written to a trajectory file must follow: the time of the
last frame and the spacing of the frames so far, and each particle's last height, lap
counter and presence, from which the laps of the next frames are counted
(``docs/definitions.md``, File formats, Frame times; Lap counter; Presence).

:class:`~cfbmarkov.trajectory_writer.TrajectoryWriter` keeps one :class:`FrameSeries` per
file; nothing here reads or writes a file.
"""

from __future__ import annotations

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.trajectory_format import (FRAME_SPACING_TOLERANCE, POSITION_TOLERANCE,
                                         lap_increments, time_text)

#: steps before a block that join its own in the median a block's steps are judged against
RECENT_STEPS = 64


class FrameSeries:
    """The state of a series of frames between the blocks written.

    Even spacing: every step between frames must lie within
    :data:`~cfbmarkov.trajectory_format.FRAME_SPACING_TOLERANCE` of the reference interval,
    the given ``frame_interval`` when known, else the median of each block's steps with the
    :data:`RECENT_STEPS` steps before it (the first step while fewer than three are known).

    Laps are 0 on an open riser; on a periodic one they are given or counted by the
    minimal-image rule between consecutive frames where a particle is present, carried over
    gaps.

    Parameters
    ----------
    label : str
        Names the file in messages.
    height : float
        Height H of the riser (m).
    open_riser : bool
        Whether the riser is open (laps are 0).
    max_step : float
        Where laps are counted from heights, the largest step a particle may make between
        frames, as a fraction of H.
    frame_interval : float, optional
        The reference frame interval (s); None to judge steps by their median.
    laps_advice : str, optional
        How the source can give laps itself (e.g. a LAMMPS dump's unwrapped coordinates),
        added to the refusal of a step too large; none: frames written more often only.

    Attributes
    ----------
    interval : float or None
        The reference frame interval (s), if known.
    last_time : float or None
        Time (s) of the last frame (written, or continued from); None before the first.
    continued_from : float or None
        Last time (s) of an earlier series this one continues, if any.
    last_y, last_lap, last_present : ndarray, shape (N,), or None
        Each particle's last height seen (m), its lap counter then, and whether it is
        present in the last frame; None before the first frame.
    """

    def __init__(self, label: str, height: float, open_riser: bool, max_step: float,
                 frame_interval: float | None = None, laps_advice: str | None = None):
        self.label = label
        self.laps_advice = laps_advice
        self.height = height
        self.open_riser = open_riser
        self.max_step = max_step
        self.interval = None if frame_interval is None else float(frame_interval)
        self.last_time: float | None = None
        self.continued_from: float | None = None
        self.recent_steps = np.zeros(0)
        self.last_y: np.ndarray | None = None
        self.last_lap: np.ndarray | None = None
        self.last_present: np.ndarray | None = None

    def continue_after(self, time: float, heights, laps, n: int,
                       frame_interval: float | None = None) -> None:
        """Follow the last frame of an earlier series.

        Parameters
        ----------
        time : float
            Its time (s).
        heights : array_like of float, shape (N,)
            Its heights y (m).
        laps : array_like of int, shape (N,)
            Its lap counters.
        n : int
            N, the number of particles (all present).
        frame_interval : float, optional
            The series' frame interval (s), if known.
        """
        self.last_time = self.continued_from = float(time)
        self.last_y = np.asarray(heights, dtype=np.float64).copy()
        self.last_lap = np.asarray(laps, dtype=np.int32).copy()
        self.last_present = np.ones(n, dtype=bool)
        if frame_interval is not None:
            self.interval = float(frame_interval)

    def add_particles(self, count: int) -> None:
        """Extend the per-particle state by ``count`` particles absent so far."""
        if self.last_y is not None:
            self.last_y = np.concatenate([self.last_y, np.full(count, np.nan)])
            self.last_lap = np.concatenate([self.last_lap, np.zeros(count, np.int32)])
            self.last_present = np.concatenate([self.last_present, np.zeros(count, bool)])

    def check_times(self, times: np.ndarray) -> None:
        """Refuse the times of a block that are not finite, do not increase after the last
        frame, or are unevenly spaced (:meth:`check_spacing`); remembers the recent steps.

        Parameters
        ----------
        times : ndarray of float64, shape (T,)
            The block's frame times (s).

        Raises
        ------
        InputError
            Naming the first time that breaks the rules.
        """
        if not np.all(np.isfinite(times)):
            raise InputError(f"{self.label}: frame time is not a finite number")
        allt = times if self.last_time is None else np.concatenate([[self.last_time], times])
        if allt.size < 2:
            return
        steps = np.diff(allt)
        if np.any(steps <= 0):
            k = int(np.argmax(steps <= 0))
            if steps[k] == 0:
                raise InputError(
                    f"{self.label}: the frame at t = {time_text(allt[k])} s comes twice (a "
                    "dump appended to after a restart repeats the restart's step; two files "
                    "that overlap): keep each frame once, e.g. import the files before and "
                    "after the restart as two files and pool them with fit A.h5 B.h5")
            raise InputError(
                f"{self.label}: time goes back from t = {time_text(allt[k])} to "
                f"{time_text(allt[k + 1])} s (frames out of order, or a run restarted from an "
                "earlier step and appended to the same file): keep the frames in time order, "
                "each once, e.g. cut the file where the restart begins")
        known = np.concatenate([self.recent_steps, steps])
        self.check_spacing(allt, known, known.size - steps.size)
        self.recent_steps = known[-RECENT_STEPS:]

    def check_spacing(self, times: np.ndarray, steps: np.ndarray, first: int = 0) -> None:
        """Refuse the first of ``steps[first:]`` (between ``times[i - first]`` and the
        next) more than FRAME_SPACING_TOLERANCE off the reference interval.

        Parameters
        ----------
        times : ndarray of float64, shape (K + 1,)
            Frame times (s) of the steps judged.
        steps : ndarray of float64, shape (S,)
            Steps (s), the last K of them between ``times``.
        first : int, optional
            Steps before this one only join the median.

        Raises
        ------
        InputError
            Naming the step, its times and the reference.
        """
        if self.interval is not None:
            reference, what = self.interval, "the frame interval"
        elif steps.size >= 3:
            reference, what = float(np.median(steps)), "the median step"
        else:
            reference, what = float(steps[0]), "the first step"
        bad = np.abs(steps[first:] - reference) > FRAME_SPACING_TOLERANCE * reference
        if np.any(bad):
            k = int(np.argmax(bad))
            # two steps only: which is wrong cannot be told (a stray row's time makes the
            # first one): both are named
            which = (" (which of the two is wrong cannot be told from two steps: a row with "
                     "a wrong time makes a first frame of its own)"
                     if what == "the first step" and first + k == 1 else "")
            step = float(steps[first + k])
            missing = int(round(step / reference)) - 1
            # a whole number of frames with no row: nobody in view (an open riser's track
            # file writes no row for an empty frame), or frames lost
            empty = (f" ({missing} frame(s) missing: a CSV track file of an open riser "
                     "writes no row while no particle is in view, and --resample DT reads "
                     "such frames as empty)"
                     if missing >= 1 and abs(step - (missing + 1) * reference)
                     <= FRAME_SPACING_TOLERANCE * reference else "")
            raise InputError(
                f"{self.label}: frames unevenly spaced: {time_text(steps[first + k])} s "
                f"between t = {time_text(times[k])} and {time_text(times[k + 1])} s, expected "
                f"{time_text(reference)} s ({what}, within {FRAME_SPACING_TOLERANCE:.0%})"
                f"{which}{empty}; for "
                "irregular frame times (CSV tracking data such as PEPT) resample them with "
                "--resample DT --max-gap G; a dump or VTK series that misses frames: import "
                "the frames before and after the gap as two files (fit A.h5 B.h5 pools them); "
                "one whose missing frames come later in the file, out of order: put its "
                "frames in time order")

    def laps(self, ids: np.ndarray, times: np.ndarray, positions: np.ndarray,
             present: np.ndarray, laps) -> np.ndarray:
        """The lap counters of a block: given, 0 for an open riser, or by the minimal-image
        rule between consecutive frames where a particle is present (carried over gaps);
        updates the last height, lap and presence of every particle.

        Parameters
        ----------
        ids : ndarray of int64, shape (N,)
            Particle ids, for messages.
        times : ndarray of float64, shape (T,)
            Frame times (s).
        positions : ndarray of float64, shape (T, N, D)
            Positions (m); NaN where absent.
        present : ndarray of bool, shape (T, N)
            Which particles are in each frame.
        laps : array_like of int, shape (T, N), or None
            Given lap counters, or None to count them.

        Returns
        -------
        ndarray of int32, shape (T, N)
            0 where a particle is absent.

        Raises
        ------
        InputError
            If (laps counted) a particle moved more than ``max_step`` of the height between
            frames.
        """
        t, n = present.shape
        if laps is not None:
            laps = _whole_laps(laps, t, n, present)
            laps = np.where(present, laps, 0)
            if not self.open_riser:
                self._check_given_laps(ids, times, positions[..., 1], laps, present)
            if self.last_y is None:
                self.last_y = np.full(n, np.nan)
                self.last_lap = np.zeros(n, np.int32)
            seen = present.any(axis=0)
            last = t - 1 - np.argmax(present[::-1], axis=0)
            cols = np.arange(n)
            self.last_y = np.where(seen, positions[last, cols, 1], self.last_y)
            self.last_lap = np.where(seen, laps[last, cols], self.last_lap).astype(np.int32)
            self.last_present = present[-1].copy()
            return laps
        if self.open_riser:
            return np.zeros((t, n), dtype=np.int32)
        out = np.zeros((t, n), dtype=np.int32)
        prev_y, prev_lap, prev_present = self.last_y, self.last_lap, self.last_present
        prev_t = self.last_time
        for k in range(t):
            y = positions[k, :, 1]
            if prev_y is None:
                lap = np.zeros(n, dtype=np.int32)
                prev_y = np.full(n, np.nan)
            else:
                both = present[k] & prev_present
                self._check_minimal_image(ids, prev_y, y, prev_t, times[k], both)
                with np.errstate(invalid="ignore"):
                    step = lap_increments(prev_y, y, self.height)
                lap = prev_lap + np.where(both, step, 0).astype(np.int32)
            out[k] = np.where(present[k], lap, 0)
            prev_y = np.where(present[k], y, prev_y)
            prev_lap, prev_present, prev_t = lap, present[k], times[k]
        self.last_y, self.last_lap, self.last_present = prev_y, prev_lap, prev_present
        return out

    def _check_given_laps(self, ids: np.ndarray, times: np.ndarray, y: np.ndarray,
                          laps: np.ndarray, present: np.ndarray) -> None:
        """Given laps (image flags, unwrapped coordinates, a source's own counter) may say
        that a particle moved more than the riser's height between two frames, which a
        trajectory file cannot hold (its laps must follow from the positions frame to frame:
        docs/definitions.md, What is checked): refuse it here, before anything is kept."""
        from cfbmarkov.trajectory_checks import first_lap_jump

        def refuse(y0, y1, lap0, lap1, t0, t1, p):
            moved = y1 - y0 + (int(lap1) - int(lap0)) * self.height
            raise InputError(
                f"{self.label}: particle {int(ids[p])} moves {moved:+.4g} m vertically "
                f"between t = {time_text(t0)} and {time_text(t1)} s (its laps {int(lap0)} -> "
                f"{int(lap1)}), more than the riser's height {self.height:g} m in one frame, "
                "which a trajectory file cannot hold: give frames closer together (an "
                "import: every dump, or export-vtk with a smaller --every; a simulation: a "
                "smaller output.frame_interval)")

        if self.last_y is not None and self.last_present is not None:   # across blocks
            k, p = first_lap_jump(np.vstack([self.last_y, y[0]]),
                                  np.vstack([self.last_lap, laps[0]]),
                                  np.vstack([self.last_present, present[0]]),
                                  float(self.height), POSITION_TOLERANCE)
            if k >= 0:
                refuse(self.last_y[p], y[0, p], self.last_lap[p], laps[0, p], self.last_time,
                       times[0], p)
        k, p = first_lap_jump(np.ascontiguousarray(y, dtype=np.float64),
                              np.ascontiguousarray(laps), np.ascontiguousarray(present),
                              float(self.height), POSITION_TOLERANCE)
        if k >= 0:
            refuse(y[k, p], y[k + 1, p], laps[k, p], laps[k + 1, p], times[k], times[k + 1], p)

    def _check_minimal_image(self, ids: np.ndarray, previous_y: np.ndarray, y: np.ndarray,
                             t0, t1, both: np.ndarray) -> None:
        """Laps from wrapped heights need small steps: refuse a particle that moved more
        than ``max_step`` of the height between two frames (by the minimal image; beyond
        half the height its pass through the periodic boundary, or not, cannot be told from
        the positions at all)."""
        step = np.where(both, np.abs(y - previous_y), 0.0)
        step = np.minimum(step, self.height - step)          # the minimal image
        worst = int(np.argmax(step)) if step.size else 0
        if step.size and step[worst] > self.max_step * self.height:
            raise InputError(
                f"{self.label}: particle {int(ids[worst])} moved {step[worst]:.4g} m "
                f"(more than {self.max_step:g} of the height {self.height:g} m) between t = {t0:g} "
                f"and {t1:g} s: the lap counter cannot be inferred from wrapped positions; "
                "write frames more often"
                + (f", or give {self.laps_advice}" if self.laps_advice else ""))


def _whole_laps(laps, t: int, n: int, present: np.ndarray) -> np.ndarray:
    """Given lap counters as int32 [T, N], refused where a present particle's counter is not
    a finite whole number within int32 (a fractional counter cast to int32 would be another
    count, silently)."""
    from cfbmarkov.errors import InputError

    try:
        given = np.asarray(laps)
        if given.dtype == bool or given.dtype.kind not in "iuf":
            raise TypeError(given.dtype)
        if given.shape != (t, n):       # reshaped, (N, T) would pass as another layout
            raise ValueError(given.shape)
    except (TypeError, ValueError):
        raise InputError(f"laps: whole numbers of shape ({t}, {n}), one per frame and "
                         f"particle (frames, particles), got {np.shape(laps)}") from None
    if given.dtype.kind == "f":
        shown = given[present]
        bad = ~np.isfinite(shown) | (shown != np.round(shown))
        if bad.any():
            raise InputError(f"laps: {float(shown[bad][0]):g} is not a whole number; a lap counter "
                             "counts passes through the periodic boundary (give integers)")
    info = np.iinfo(np.int32)
    if given.size and (given[present].min(initial=0) < info.min
                       or given[present].max(initial=0) > info.max):
        raise InputError("laps: a counter beyond the 32-bit range")
    return given.astype(np.int32)

