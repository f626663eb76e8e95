"""Radial mixing by halves (SPEC section 4, the paper's Fig. 10-11).

At the start of the analysis window the particles with x < W/2 are "purple", the rest
"green". The mixing curve is the number of purple particles with x < W/2 divided by the
total number of particles, against time. It starts at the purple fraction of the first
frame and, when the bed is well mixed, approaches (purple fraction) x (fraction on the
left). For a model whose positions are drawn inside cells, x < W/2 is the same as a cell
column < m/2 when the number of columns m is even (with m odd the middle column straddles
the axis and mixing by halves is undefined; :func:`cfbmarkov.report.compare.compare`
refuses it).
"""

from __future__ import annotations

import numpy as np

from cfbmarkov.errors import InputError


def purple_mask(x, half_width: float) -> np.ndarray:
    """Purple particles of one frame: x < W/2 (``x`` [N] in m)."""
    return np.asarray(x) < half_width


def mixing_curve(x, half_width: float, purple: np.ndarray | None = None) -> np.ndarray:
    """Mixing curve of frames ``x`` [T, N] (m): fraction [T] of all particles that are purple
    (x < ``half_width`` in the first frame, unless ``purple`` [N] is given) and lie at
    x < ``half_width``."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2:
        raise InputError(f"x must have shape (T, N), got {x.shape}")
    t, n = x.shape
    if n == 0:
        raise InputError("mixing curve of no particles")
    if purple is None:
        if t == 0:
            return np.zeros(0)
        purple = x[0] < half_width
    purple = np.asarray(purple, dtype=bool)
    if purple.shape != (n,):
        raise InputError(f"purple mask has shape {purple.shape}, expected ({n},)")
    return np.count_nonzero(x[:, purple] < half_width, axis=1) / n


def mixing_curve_of(traj, window: tuple[float, float], block: int = 64
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(times [T] s, fraction [T]) of ``traj`` over the frames of ``window`` = (start, stop) s,
    purple taken from the window's first frame; frames are read in blocks."""
    frames = traj.window(float(window[0]), float(window[1]))
    half = 0.5 * traj.width
    purple = None
    times, parts = [], []
    for t, positions, _ in traj.iter_frames(frames, block=block):
        x = positions[..., 0]
        if purple is None:
            purple = x[0] < half
        times.append(t)
        parts.append(mixing_curve(x, half, purple))
    return np.concatenate(times).astype(np.float64), np.concatenate(parts)


__all__ = ["mixing_curve", "mixing_curve_of", "purple_mask"]
