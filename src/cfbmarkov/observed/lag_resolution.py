"""Whether a lag resolves a periodic riser's passes (``docs/definitions.md``, Lag and
fitting window).

The transitions of a model and the residences observed on frames one lag apart tell a pass
through the periodic boundary from the heights at the two ends of a lag (the minimal-image
rule: a height that drops or rises by more than H/2 passed the top or the bottom) or from
the lap counters there. Both fail where a particle moves half the riser's height or more
within one lag: the minimal image then takes a pass up for a move down, and the lap
counters step by two, so that a residence shorter than the lag is recorded as zero. The
kernel here compares, move by move, the pass the minimal image reads with the change of the
file's lap counters (counted frame by frame, or from unwrapped coordinates, which hold
every pass even where frames lie far apart); :func:`check_lag_resolves_passes` refuses a
lag at which they disagree for more than :data:`TOLERANCE` of the passes, naming a lag at
which they would not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError

#: the share of the passes (file's laps) that may be read wrong before a lag is refused: a
#: count error well below the sampling noise of any window's passes
TOLERANCE = 1e-3


@nb.njit(cache=True)
def _misread_passes(vertical, laps, lag_frames, height):
    """The moves over one lag whose pass the minimal image reads wrong (Numba kernel).

    ``vertical`` float64 [T, N] heights in the period (NaN: absent), ``laps`` int [T, N]
    lap counters. For particle p from frame t to t + lag the file's pass is the change of
    its laps, and the minimal image's is +1 where the height drops by more than H / 2, -1
    where it rises by more, else 0. A move over frames where the particle was absent is
    left out: a pass made while it was away is in no lap counter (a file's laps carry on
    across an absence), so its laps cannot say how the move should read. Returns the number
    of moves where they differ, the number of moves (present at both ends and between),
    the number of moves with a pass (laps changed) and
    the largest |move| (m), the unwrapped height change vertical[t + lag] - vertical[t]
    + H (laps[t + lag] - laps[t])."""
    n_frames, n_particles = vertical.shape
    half = 0.5 * height
    misread = 0
    moves = 0
    passes = 0
    largest = 0.0
    for t in range(n_frames - lag_frames):
        for p in range(n_particles):
            a = vertical[t, p]
            b = vertical[t + lag_frames, p]
            if np.isnan(a) or np.isnan(b):
                continue
            seen = True         # a pass while absent is not in the laps: no reading
            for u in range(t + 1, t + lag_frames):
                if np.isnan(vertical[u, p]):
                    seen = False
                    break
            if not seen:
                continue
            laps_change = laps[t + lag_frames, p] - laps[t, p]
            dy = b - a
            image = 1 if dy < -half else (-1 if dy > half else 0)
            moves += 1
            if laps_change != 0:
                passes += 1
            if image != laps_change:
                misread += 1
            move = abs(dy + height * laps_change)
            if move > largest:
                largest = move
    return misread, moves, passes, largest


@dataclass(frozen=True)
class PassReading:
    """How the heights one lag apart read a window's passes through the periodic boundary,
    against the file's lap counters (:func:`read_passes`).

    Attributes
    ----------
    misread : int
        Moves over one lag whose pass the minimal image reads otherwise than the laps.
    moves : int
        Moves over one lag with the particle present at both ends and between.
    passes : int
        Moves with a pass (the laps changed).
    largest : float
        The largest unwrapped height change over one lag (m).
    lag_frames : int
        The lag, in frames.
    frame_interval : float
        Time between frames (s).
    height : float
        The riser's height H (m).
    source : str
        The file, for the message.
    """

    misread: int
    moves: int
    passes: int
    largest: float
    lag_frames: int
    frame_interval: float
    height: float
    source: str = ""

    @property
    def resolved(self) -> bool:
        """Whether the misread moves stay within :data:`TOLERANCE` of the passes."""
        return self.misread <= TOLERANCE * self.passes

    def check(self) -> None:
        """Refuse the lag where the passes are not resolved.

        Raises
        ------
        InputError
            One line: the misread passes, the largest move, and the longest lag (a whole
            number of frames) at which the largest move, scaled with the lag, stays below
            H / 2; where not even one frame does, the frame interval that would.
        """
        if self.resolved:
            return
        dt, half = self.frame_interval, 0.5 * self.height
        # the largest move grows about as the lag: the longest lag that keeps it below H / 2
        frames = math.ceil(self.lag_frames * half / self.largest) - 1
        fix = (f"give a lag of at most {frames * dt:g} s (--lag)" if frames >= 1 else
               f"the file's frames, {dt:g} s apart, are too far apart for this flow (laps "
               "from unwrapped coordinates count the passes, the states cannot): write "
               f"frames at most {dt * half / self.largest:.2g} s apart")
        where = f"{self.source}: " if self.source else ""
        raise InputError(f"{where}at a lag of {self.lag_frames * dt:g} s the heights one lag "
                         f"apart read {self.misread} passes through the periodic boundary "
                         f"wrong (missed, or seen where there is none) against the "
                         f"{self.passes} that the file's laps count, in "
                         f"{self.moves} particle moves: particles move half the riser's "
                         f"height ({half:g} m) or more within the lag, up to "
                         f"{self.largest:.3g} m; {fix} (or, where the frames are close, the "
                         "file's laps contradict its positions: laps written as zeros, or for "
                         "another height; write the laps the passes make, or none to have "
                         "them derived)")


def read_passes(vertical, laps, lag_frames: int, height: float, frame_interval: float,
                source: str = "") -> PassReading:
    """How the heights one lag apart read the passes that the file's laps count.

    Parameters
    ----------
    vertical : ndarray of float64, shape (T, N)
        Heights (m) in the periodic riser, NaN where a particle is absent.
    laps : ndarray of int, shape (T, N)
        The file's lap counters at the same frames.
    lag_frames : int
        The lag, in frames (at least 1).
    height : float
        The riser's height H (m), the period.
    frame_interval : float
        Time between frames (s).
    source : str, optional
        The file, for the message.

    Returns
    -------
    PassReading
    """
    vertical = np.ascontiguousarray(vertical, dtype=np.float64)
    laps = np.ascontiguousarray(laps, dtype=np.int64)
    lag_frames = int(lag_frames)
    counts = ((0, 0, 0, 0.0) if lag_frames < 1 or vertical.shape[0] <= lag_frames else
              _misread_passes(vertical, laps, lag_frames, float(height)))
    return PassReading(int(counts[0]), int(counts[1]), int(counts[2]), float(counts[3]),
                       lag_frames, float(frame_interval), float(height), source)


def check_lag_resolves_passes(vertical, laps, lag_frames: int, height: float,
                              frame_interval: float, source: str = "") -> None:
    """Refuse a lag at which the heights one lag apart misread the periodic boundary's
    passes (a particle moving half the riser's height or more within it) for more than
    :data:`TOLERANCE` of them: :func:`read_passes`, then :meth:`PassReading.check`.

    Parameters
    ----------
    vertical, laps, lag_frames, height, frame_interval, source
        As :func:`read_passes`.

    Raises
    ------
    InputError
        See :meth:`PassReading.check`.
    """
    read_passes(vertical, laps, lag_frames, height, frame_interval, source).check()


def short_residences(samples) -> int:
    """The residence-time samples of zero length: a particle whose lap counter stepped by
    two or more between two frames one lag apart (a residence shorter than the lag,
    recorded as zero), int."""
    return int(np.count_nonzero(np.asarray(samples) <= 0.0))


__all__ = ["TOLERANCE", "PassReading", "check_lag_resolves_passes", "read_passes",
           "short_residences"]
