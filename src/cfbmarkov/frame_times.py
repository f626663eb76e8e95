"""Frame times of a trajectory file, and the rules that match a requested time, window or
lag to its frames (``docs/definitions.md``, File formats, Frame times).

Frames are evenly spaced within
:data:`~cfbmarkov.trajectory_format.FRAME_SPACING_TOLERANCE` of the frame interval; a
time matches a frame within half of that, whatever the time origin. Nothing here reads a
file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cfbmarkov.errors import InputError, LagError
from cfbmarkov.limits import MAX_LAGS
from cfbmarkov.trajectory_format import FRAME_SPACING_TOLERANCE, TIME_TOLERANCE, time_text


def window_pair(window) -> tuple[float, float]:
    """An analysis window given as two numbers, as two floats.

    Parameters
    ----------
    window : sequence of two real numbers
        (start, stop), s.

    Returns
    -------
    (float, float)
        (start, stop), s; whether they are finite, ordered and inside a file is for the
        file's frames to judge (:meth:`FrameTimes.window`).

    Raises
    ------
    InputError
        If ``window`` is text, None or anything but two real numbers (a text "15" would
        otherwise be read as the window 1:5).
    """
    import numbers

    from collections.abc import Sequence

    ok = (isinstance(window, (Sequence, np.ndarray)) and not isinstance(window, (str, bytes))
          and np.ndim(window) == 1 and len(window) == 2
          and all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in window))
    if not ok:
        raise InputError(f"window {window!r} is not (start, stop) in s: give two numbers, "
                         "e.g. window=(10.0, 15.0)")
    return float(window[0]), float(window[1])


class FrameTimes:
    """The frame times of a file, located by time, window or lag.

    :class:`~cfbmarkov.trajectories.Trajectories` is one.

    Parameters
    ----------
    path : str or os.PathLike
        The file, for messages.
    times : ndarray of float64, shape (T,)
        Frame times (s), finite, increasing and evenly spaced.
    frame_interval : float
        Time between frames (s); NaN for a file of one frame without a known interval.

    Attributes
    ----------
    path : pathlib.Path
        The file.
    times : ndarray of float64, shape (T,)
        Frame times (s), a read-only copy.
    frame_interval : float
        Time between frames (s), or NaN.
    """

    def __init__(self, path: str | os.PathLike, times: np.ndarray, frame_interval: float):
        self.path = Path(path)
        # read-only: every later answer (windows, frames, a fit's provenance) reads them
        self.times = np.array(times, dtype=np.float64)
        self.times.setflags(write=False)
        self.frame_interval = frame_interval

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.times.size)

    @property
    def time_tolerance(self) -> float:
        """How far (s) a frame may lie from a requested time and still be the frame at it.

        Half of :data:`~cfbmarkov.trajectory_format.FRAME_SPACING_TOLERANCE` of the frame
        interval: frame times rounded to q s lie within q/2 of the exact times, and the
        spacing check accepts q up to the spacing tolerance of an interval. It does not depend on the time origin. A file
        of one frame has no interval: then ``TIME_TOLERANCE * max(|t|, 1 s)`` (round-off).
        """
        if np.isfinite(self.frame_interval):
            return 0.5 * FRAME_SPACING_TOLERANCE * self.frame_interval
        return TIME_TOLERANCE * max(abs(float(self.times[-1])), 1.0)

    def _frames_text(self) -> str:
        if self.n_frames == 1:
            return f"{self.path} holds one frame, at t = {time_text(self.times[0])} s"
        return (f"frames span {time_text(self.times[0])} to {time_text(self.times[-1])} s every "
                f"{time_text(self.frame_interval)} s")

    def _outside_text(self, start: float, stop: float) -> str:
        """Why the window ``start:stop`` is refused where it leaves the data, with the part
        inside and a window of its length that fits."""
        first, last = float(self.times[0]), float(self.times[-1])
        data = f"{time_text(first)} to {time_text(last)} s"
        if stop <= first or start >= last:
            where = f"lies outside the data of {self.path} ({data})"
        else:
            where = (f"lies partly outside the data of {self.path} ({data}); only "
                     f"{self._short_time(max(start, first))}:"
                     f"{self._short_time(min(stop, last))} s lies "
                     "inside")
        length = stop - start
        short = self._short_time
        if length >= last - first:
            fits = f"{short(first)}:{short(last)} (all of it)"
        elif stop > last:
            fits = f"{short(last - length)}:{short(last)} (the same length)"
        else:
            fits = f"{short(first)}:{short(first + length)} (the same length)"
        return f"window {start:g}:{stop:g} s {where}: choose one within it, e.g. {fits}"

    def _short_time(self, value: float) -> str:
        """``value`` with the fewest decimals that keep it within half the
        :attr:`time_tolerance` of itself, so that a window suggested with it selects the
        same frames and is accepted (0.00046 for 0.000459185 with frames 5 ms apart)."""
        tol = 0.5 * self.time_tolerance
        for decimals in range(16):
            rounded = round(float(value), decimals)
            if abs(rounded - value) <= tol:
                return time_text(rounded)
        return time_text(value)

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
        # nearest frame to the time brought into the frames' span: far beyond it the
        # differences round alike (1e15 s named a frame at 19.95 s of a 0-20 s file)
        inside = min(max(time, float(self.times[0])), float(self.times[-1]))
        i = int(np.argmin(np.abs(self.times - inside)))
        if not abs(self.times[i] - time) <= self.time_tolerance:
            nearest = ("" if self.n_frames == 1
                       else f"; the nearest is at {time_text(self.times[i])} s")
            raise InputError(f"{self.path}: no frame at t = {time_text(time)} s "
                             f"({self._frames_text()}{nearest})")
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
            raise InputError(self._outside_text(start, stop))
        i0 = int(np.searchsorted(self.times, start - tol, side="left"))
        i1 = int(np.searchsorted(self.times, stop + tol, side="right"))
        if i1 - i0 < 1:
            every = (f" (frames every {self.frame_interval:g} s)"
                     if np.isfinite(self.frame_interval) else "")
            raise InputError(f"window {start:g}:{stop:g} s holds no frame of {self.path}"
                             f"{every}; give a window that holds at least one frame")
        return slice(i0, i1)

    def held(self, start: float, stop: float) -> tuple[float, float]:
        """The window as the frames it holds: an end that falls between frames moves to the
        first (last) frame inside; an end on a frame (within :attr:`time_tolerance`) is kept
        as given. What a model fitted on the window stores as its window.

        Parameters
        ----------
        start, stop : float
            The window (s).

        Returns
        -------
        (float, float)

        Raises
        ------
        InputError
            As :meth:`window`.
        """
        frames = self.window(start, stop)
        first, last = float(self.times[frames.start]), float(self.times[frames.stop - 1])
        tol = self.time_tolerance
        return (float(start) if abs(start - first) <= tol else first,
                float(stop) if abs(stop - last) <= tol else last)

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
            If the lag is not positive, or the file has no frame interval (one frame and no
            ``frame_interval`` attribute).
        LagError
            If the lag is not a whole multiple of the frame interval (an
            :class:`~cfbmarkov.errors.InputError`).
        """
        if not (np.isfinite(lag) and lag > 0):
            raise InputError(f"lag {lag:g} s must be a positive finite number")
        if not np.isfinite(self.frame_interval):
            raise InputError(f"{self.path} holds one frame: no frame interval, so no transition "
                             f"can be counted (lag {lag:g} s)")
        intervals = lag / self.frame_interval
        if not intervals < MAX_LAGS:    # inf beyond the floats: int() would overflow
            raise InputError(f"lag {lag:g} s is {intervals:.3g} frame intervals of "
                             f"{time_text(self.frame_interval)} s, far beyond the file's "
                             "span: give a lag of a few frame intervals")
        k = int(round(intervals))
        if k < 1 or not abs(lag - k * self.frame_interval) <= self.time_tolerance:
            interval = time_text(self.frame_interval)
            nearest = time_text(max(k, 1) * self.frame_interval)
            raise LagError(lag, interval, nearest, str(self.path))
        return k
