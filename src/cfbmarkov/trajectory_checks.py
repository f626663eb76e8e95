"""The per-frame checks of trajectory files, on blocks of frames in memory: the reader's
(positions finite and inside the domain where present, laps consistent with the positions,
pass events well formed)
and the writer's (present values finite, present positions inside the domain)
(``docs/definitions.md``, File formats, What is checked).

Numba kernels find the first problem in one pass without temporaries; the functions around
them raise it as an :class:`~cfbmarkov.errors.InputError` naming the file, the particle and
the time. Nothing here reads or writes a file.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.trajectory_format import POSITION_TOLERANCE, PassEvents, time_text


@nb.njit(cache=True, inline="always")
def _laps_off(y0, y1, lap0, lap1, height, tol):
    """Whether a particle's laps and heights in two consecutive frames where it is present
    say it moved more than the riser's height: |dy + dL H| > H + 2 tol."""
    return not abs(y1 - y0 + (lap1 - lap0) * height) <= height + 2 * tol


@nb.njit(cache=True)
def first_lap_jump(y, lap, present, height, tol):
    """The first (frame, particle) of a block (heights ``y`` [T, N], laps, presence) whose
    laps and heights in frames k and k + 1 say it moved more than the riser's height
    (:func:`_laps_off`), or (-1, -1): the writer's check of given laps (Numba kernel, one
    pass, no temporaries)."""
    n_frames, n_particles = y.shape
    for k in range(n_frames - 1):
        for p in range(n_particles):
            if present[k, p] and present[k + 1, p] and _laps_off(
                    y[k, p], y[k + 1, p], lap[k, p], lap[k + 1, p], height, tol):
                return k, p
    return -1, -1


@nb.njit(cache=True)
def _frame_problem(pos, lap, present, extent, tol, height, open_riser):
    """The first problem of a block of frames, in one pass without temporaries: (code,
    frame, particle) with code 0 none, 1 a present position not finite, 2 outside the
    domain (beyond ``tol``), 3 a non-zero lap on an open riser, 4 (periodic) between
    consecutive present frames |dy + dL H| > H + 2 tol (laps inconsistent with positions).
    Codes 1-2 are found before 3-4 for the same frame and particle (docs/definitions.md,
    File formats, What is checked)."""
    n_frames, n_particles, d = pos.shape
    for k in range(n_frames):
        for p in range(n_particles):
            if not present[k, p]:
                continue
            for c in range(d):
                v = pos[k, p, c]
                if not np.isfinite(v):
                    return 1, k, p
                if v < -tol or v > extent[c] + tol:
                    return 2, k, p
            if open_riser:
                if lap[k, p] != 0:
                    return 3, k, p
            elif k > 0 and present[k - 1, p]:
                if _laps_off(pos[k - 1, p, 1], pos[k, p, 1], lap[k - 1, p], lap[k, p], height,
                             tol):
                    return 4, k - 1, p
    return 0, 0, 0


@nb.njit(cache=True)
def _values_problem(values, present, extent, tol, domain):
    """The first problem of a block of per-particle values, in one pass without
    temporaries: (code, frame, particle), code 0 none, 1 a present value not finite, 2
    (``domain``) a present position outside [-tol, extent + tol] on some axis. A particle's
    non-finite value is reported before its being outside."""
    n_frames, n_particles, d = values.shape
    for k in range(n_frames):
        for p in range(n_particles):
            if not present[k, p]:
                continue
            for c in range(d):
                if not np.isfinite(values[k, p, c]):
                    return 1, k, p
            if domain:
                for c in range(d):
                    v = values[k, p, c]
                    if v < -tol or v > extent[c] + tol:
                        return 2, k, p
    return 0, 0, 0


def check_stored_frames(path, ids: np.ndarray, times: np.ndarray, pos: np.ndarray,
                        lap: np.ndarray, present: np.ndarray, extent: np.ndarray,
                        height: float, open_riser: bool) -> None:
    """Refuse the first problem of a block of frames read from a trajectory file.

    Positions must be finite and inside the domain (within
    :data:`~cfbmarkov.trajectory_format.POSITION_TOLERANCE`) where present; on a periodic
    riser, between consecutive frames where a particle is present, the unwrapped
    displacement y1 - y0 + (L1 - L0) H is at most H (no lap jump of more than 1, none
    against the motion); on an open riser laps are 0 where present.

    Parameters
    ----------
    path : str or os.PathLike
        The file, for the message.
    ids : ndarray of int64, shape (N,)
        The file's particle ids.
    times : ndarray of float64, shape (B,)
        Times (s) of the frames of the block.
    pos : ndarray of float64, shape (B, N, D)
        Positions (m).
    lap : ndarray of int, shape (B, N)
        Lap counters.
    present : ndarray of bool, shape (B, N)
        Which particles are in each frame.
    extent : ndarray of float64, shape (D,)
        The domain's size (m) along each stored axis.
    height : float
        Height H of the riser (m).
    open_riser : bool
        Whether the riser is open (laps must be 0).

    Raises
    ------
    InputError
        Naming the file, the particle, the time and what is wrong.
    """
    lap = np.ascontiguousarray(lap)
    if lap.dtype.kind not in "iu":      # the file's own integers as they are: no copy
        lap = lap.astype(np.int64)
    code, k, n = _frame_problem(np.ascontiguousarray(pos, dtype=np.float64), lap,
                                np.ascontiguousarray(present, dtype=np.bool_), extent,
                                POSITION_TOLERANCE, height, open_riser)
    if code == 1 or code == 2:
        what = ("is not a finite number" if code == 1 else "lies outside the domain 0.."
                + " x 0..".join(f"{v:g}" for v in extent) + " m")
        raise InputError(f"{path}: damaged trajectory file (position "
                         f"{pos[k, n].tolist()} of particle {ids[n]} at t = "
                         f"{time_text(times[k])} s {what})")
    if code == 3:
        raise InputError(f"{path}: damaged trajectory file (an open riser, but particle "
                         f"{ids[n]} has lap {lap[k, n]} at t = {time_text(times[k])} s)")
    if code == 4:
        raise InputError(
            f"{path}: damaged trajectory file (lap counter of particle {ids[n]} "
            f"goes from {lap[k, n]} to {lap[k + 1, n]} between t = {time_text(times[k])} "
            f"and {time_text(times[k + 1])} s while its height goes from "
            f"{pos[k, n, 1]:.6g} to {pos[k + 1, n, 1]:.6g} m: laps inconsistent with the "
            "positions)")


def check_written_values(label: str, name: str, values: np.ndarray, times: np.ndarray,
                         present: np.ndarray, ids: np.ndarray, limits: list[float],
                         domain: bool = False) -> None:
    """Refuse a present value that is not finite, or (``domain``) a present position
    outside the domain by more than
    :data:`~cfbmarkov.trajectory_format.POSITION_TOLERANCE`; one pass, the first problem
    in frame, then particle order.

    Parameters
    ----------
    label : str
        Names the file being written, for the message.
    name : str
        What the values are (``"position"``, ``"velocity"``).
    values : ndarray of float64, shape (T, N, D)
        Positions (m) or velocities (m/s) of a block of frames.
    times : ndarray of float64, shape (T,)
        Their times (s).
    present : ndarray of bool, shape (T, N)
        Which particles are in each frame.
    ids : ndarray of int64, shape (N,)
        Particle ids.
    limits : list of float, length D
        The domain's size (m) along each stored axis.
    domain : bool, optional
        Whether the values are positions to hold to the domain.

    Raises
    ------
    InputError
        Naming the particle and the time.
    """
    code, t_idx, p_idx = _values_problem(np.ascontiguousarray(values), present,
                                         np.asarray(limits, dtype=np.float64),
                                         POSITION_TOLERANCE, domain)
    if code == 1:
        hint = (" (a particle out of view is left out of its frame: present False)"
                if name == "position" else "")
        raise InputError(f"{label}: {name} of particle {ids[p_idx]} at t = "
                         f"{times[t_idx]:g} s is not a finite number{hint}")
    if code == 2:
        where = ", ".join(f"{v:g}" for v in values[t_idx, p_idx])
        size = " x ".join(f"0..{v:g}" for v in limits)
        raise InputError(
            f"{label}: particle {ids[p_idx]} at t = {times[t_idx]:g} s lies outside "
            f"the domain {size} m at ({where})")


def check_pass_events(path, events: PassEvents, n_particles: int) -> None:
    """Refuse damaged pass events read from a trajectory file.

    Parameters
    ----------
    path : str or os.PathLike
        The file, for the message.
    events : PassEvents
        The events as stored.
    n_particles : int
        N, the number of the file's particles.

    Raises
    ------
    InputError
        Unless times, particles and directions are equally long and 1-D, the times
        finite, the particles indices 0 .. N-1 and the directions +1 or -1.
    """
    e = events.time.shape
    if (events.particle.shape != e or events.direction.shape != e or len(e) != 1
            or not np.all(np.isfinite(events.time))
            or (e[0] and (events.particle.min() < 0 or events.particle.max() >= n_particles
                          or not np.all(np.abs(events.direction) == 1)))):
        raise InputError(f"{path}: damaged trajectory file (pass events: times, "
                         "particles and directions must be equally long, times finite, "
                         "particles indices of /particles/id and directions +1 or -1)")
