"""Radial mixing by halves of the riser (the paper's Fig. 10-11).

At the start of the analysis window the particles are split into two *tracer groups* by
their position: the *left tracer group* holds the particles with x < W/2, the right tracer
group the rest (the figures draw them purple and green, as the paper does). The mixing
curve is the number of particles of the left tracer group that lie at x < W/2, divided by
the total number of particles, against time. It starts at the left group's share of all
particles and, when the bed is well mixed, approaches (left group's share) x (share of all
particles on the left).

For a model whose positions are drawn inside cells, x < W/2 is the same as a cell column
< m/2 when the number of columns m is even (with m odd the middle column straddles the axis
and mixing by halves is undefined; :func:`cfbmarkov.analysis.compare.compare_runs` refuses
it).

References
----------
docs/definitions.md, section "mixing".
"""

from __future__ import annotations

import numpy as np

from cfbmarkov.errors import InputError


def left_tracer_group(x, half_width: float) -> np.ndarray:
    """Members of the left tracer group in one frame.

    Parameters
    ----------
    x : array_like, shape (N,)
        Horizontal particle positions, m.
    half_width : float
        Half the riser width W/2, m.

    Returns
    -------
    numpy.ndarray of bool, shape (N,)
        True where x < W/2 (a particle exactly on the axis belongs to the right group).
    """
    return np.asarray(x) < half_width


def mixing_curve(x, half_width: float, left_group: np.ndarray | None = None) -> np.ndarray:
    """Mixing curve of a block of frames.

    Parameters
    ----------
    x : array_like, shape (T, N)
        Horizontal particle positions, m, frame by frame.
    half_width : float
        Half the riser width W/2, m.
    left_group : array_like of bool, shape (N,), optional
        The left tracer group; by default the particles with x < W/2 in the first frame.

    Returns
    -------
    numpy.ndarray, shape (T,)
        Fraction of all N particles that belong to the left tracer group and lie at
        x < W/2 (dimensionless).

    Raises
    ------
    InputError
        When ``x`` is not 2D, holds no particle, or ``left_group`` has the wrong shape.

    References
    ----------
    docs/definitions.md, section "mixing"; the paper's Fig. 11.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2:
        raise InputError(f"x must have shape (T, N), got {x.shape}")
    t, n = x.shape
    if n == 0:
        raise InputError("mixing curve of no particles")
    if left_group is None:
        if t == 0:
            return np.zeros(0)
        left_group = x[0] < half_width
    left_group = np.asarray(left_group, dtype=bool)
    if left_group.shape != (n,):
        raise InputError(f"left tracer group mask has shape {left_group.shape}, expected ({n},)")
    return np.count_nonzero(x[:, left_group] < half_width, axis=1) / n


def mixing_curve_of(traj, window: tuple[float, float], block: int = 64
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Mixing curve of a trajectory file over a window.

    Parameters
    ----------
    traj : cfbmarkov.trajectories.Trajectories
        An open trajectory file.
    window : (float, float)
        Analysis window (start, stop), s. The left tracer group is taken from the window's
        first frame.
    block : int, optional
        Frames read per block.

    Returns
    -------
    times : numpy.ndarray, shape (T,)
        Frame times, s.
    fraction : numpy.ndarray, shape (T,)
        The mixing curve of :func:`mixing_curve` (dimensionless).

    Raises
    ------
    InputError
        When the window is empty, leaves the file's frames or holds no frame.

    References
    ----------
    ``docs/definitions.md`` (Mixing);
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 10-11.
    """
    traj.require_supported("the mixing curve", three_d=True, absent=True,
                           open_boundary=True)     # the across coordinate only
    frames = traj.window(float(window[0]), float(window[1]))
    half = 0.5 * traj.width
    if traj.has_absences:
        return _mixing_of_present(traj, frames, half, block)
    left_group = None
    times, parts = [], []
    for t, positions, _ in traj.iter_frames(frames, block=block):
        x = positions[..., 0]
        if left_group is None:
            left_group = x[0] < half
        times.append(t)
        parts.append(mixing_curve(x, half, left_group))
    return np.concatenate(times).astype(np.float64), np.concatenate(parts)


def _mixing_of_present(traj, frames: slice, half: float, block: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The mixing curve where particles come and go (``docs/definitions.md``, Mixing in an
    open riser): the particles present at the window's first frame are the tracers; at each
    frame the fraction of those still present that belong to the left group and lie at
    x < W/2 (NaN once none is left)."""
    cohort = left = None
    times, parts = [], []
    for i in range(frames.start, frames.stop, block):
        rows = slice(i, min(i + block, frames.stop))
        x = traj.positions(rows)[..., 0]
        present = traj.present(rows)
        if cohort is None:
            cohort = present[0].copy()
            left = cohort & (np.where(cohort, x[0], np.inf) < half)
        still = present & cohort
        inside = still & left & (np.where(still, x, np.inf) < half)
        count = still.sum(axis=1)
        parts.append(np.divide(inside.sum(axis=1), count, out=np.full(count.size, np.nan),
                               where=count > 0))
        times.append(traj.times[rows])
    return np.concatenate(times).astype(np.float64), np.concatenate(parts)


__all__ = ["left_tracer_group", "mixing_curve", "mixing_curve_of"]
