"""The rules of the trajectory file format that its reader and writer share: the format's
name and version, the tolerances on positions and frame times, the lap counter's
minimal-image rule, the frame interval of evenly spaced times and the exact pass events
(``docs/definitions.md``, File formats, Trajectory files; the layout is described in
:mod:`cfbmarkov.trajectories`).

Nothing here reads or writes a file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the ``format`` attribute of a trajectory file
FORMAT = "cfbmarkov.trajectories"
#: the layout's version (the ``version`` attribute); version 1 files still read
VERSION = 2
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


def time_text(value: float) -> str:
    """A time for a message: up to 10 significant digits (10.00833, not 10.0083).

    Parameters
    ----------
    value : float
        A time (s).

    Returns
    -------
    str
    """
    return f"{float(value):.10g}"
