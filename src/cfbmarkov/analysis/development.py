"""How developed the flow is: the solids' mean vertical velocity over consecutive windows of a
run from rest (``docs/definitions.md``, riser).

A riser started from rest takes time to reach its developed flow; a model fitted before then
learns a flow that the predict window no longer has. The solids' mean vertical velocity
(over the particles present and the window's frames) before the fitting window, over it and
over the predict window says how far the flow has settled when the model is fitted.
"""

from __future__ import annotations

import math

import numpy as np

#: the most frames read per window (evenly spaced); the mean of a window is steady long
#: before that
MAX_FRAMES = 200


def mean_vertical_velocity(traj, window: tuple[float, float],
                           max_frames: int = MAX_FRAMES) -> float:
    """The solids' mean vertical velocity over a window of a trajectory file.

    Parameters
    ----------
    traj : cfbmarkov.trajectories.Trajectories
        An open trajectory file with velocities.
    window : (float, float)
        (start, stop), s.
    max_frames : int, optional
        At most this many frames, evenly spaced over the window, are read.

    Returns
    -------
    float
        The mean over the frames read and the particles present of the vertical velocity
        (m/s, positive upward); NaN where the file has no velocities or the window no frame.
    """
    if not traj.has_velocity:
        return math.nan
    frames = traj.window(*window)
    n = frames.stop - frames.start
    if n <= 0:
        return math.nan
    total, count = 0.0, 0
    for k in np.unique(np.linspace(frames.start, frames.stop - 1,
                                   min(n, max(1, int(max_frames)))).astype(int)):
        v = traj.velocities(int(k))[:, 1]
        v = v[np.isfinite(v)]
        total += float(v.sum())
        count += v.size
    return total / count if count else math.nan


def development(traj, fit_window: tuple[float, float], predict_window: tuple[float, float]
                ) -> dict[str, float]:
    """The solids' mean vertical velocity before the fitting window, over it, and over the
    predict window.

    Parameters
    ----------
    traj : cfbmarkov.trajectories.Trajectories
        An open CFD-DEM file with velocities.
    fit_window, predict_window : (float, float)
        The case's windows, s.

    Returns
    -------
    dict
        ``start`` (the file's first frame time, s), and ``before``, ``fit``, ``predict``:
        the mean vertical velocity (m/s) from the first frame to the fitting window, over
        the fitting window and over the predict window (NaN where there is none).
    """
    first = float(traj.times[0])
    before = (mean_vertical_velocity(traj, (first, float(fit_window[0])))
              if fit_window[0] > first else math.nan)
    return {"start": first, "before": before,
            "fit": mean_vertical_velocity(traj, tuple(fit_window)),
            "predict": mean_vertical_velocity(traj, tuple(predict_window))}


__all__ = ["MAX_FRAMES", "development", "mean_vertical_velocity"]
