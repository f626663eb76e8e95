"""Residence times from lap counters or exact pass events (docs/definitions.md, section
"residence time").

Every particle carries a lap counter L (+1 per pass up through the top, -1 per pass down
through the bottom). Inside an analysis window [A, B], L is counted from its value at A;
every upward pass that lifts L above the running maximum since A is an exit through the
outlet and, at the same moment, an entry through the inlet (a *record*). A residence-time
sample is the time between two consecutive records of the same particle. Falling back out
of the bottom therefore stays inside the same residence, and the time before a particle's
first record in the window is never a sample (its entry is unknown).

From frames, the moment of a pass is the time of the first frame after it: every frame in
which L exceeds the running maximum records that frame's time, once per new level (a jump
by 2 in one frame records the time twice, a zero-length residence). Where a simulation
logged exact pass events, :func:`residence_times_from_events` uses their times instead.

The kernels are pure functions on arrays (numba); :func:`residence_times` reads a
:class:`~cfbmarkov.trajectories.Trajectories` file in blocks of frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.frame_times import window_pair

#: frames read per block by :func:`residence_times` (27000 particles: ~28 MB of int32 laps)
_BLOCK_FRAMES = 256


# -- kernels -------------------------------------------------------------------------------
@nb.njit(cache=True, inline="always")
def _records(p, level, t, running_max, last_record, out, n_out):
    """Particle ``p`` at lap ``level`` at time ``t``: one record per new level reached, a
    sample (the time since its previous record) for each but its first; returns the new
    number of samples in ``out``."""
    while level > running_max[p]:
        running_max[p] += 1
        if not np.isnan(last_record[p]):
            out[n_out] = t - last_record[p]
            n_out += 1
        last_record[p] = t
    return n_out


@nb.njit(cache=True)
def _scan_laps(times, laps, running_max, last_record, out):
    """Advance the record state over a block of frames; write samples into ``out``.

    ``running_max`` [N] (int64) and ``last_record`` [N] (float64, NaN before the first
    record) are updated in place. Returns the number of samples written.
    """
    n_frames, n_particles = laps.shape
    n_out = 0
    for k in range(n_frames):
        t = times[k]
        for p in range(n_particles):
            level = np.int64(laps[k, p])
            n_out = _records(p, level, t, running_max, last_record, out, n_out)
    return n_out


@nb.njit(cache=True)
def _scan_laps_present(times, laps, seen, running_max, last_record, started, out):
    """:func:`_scan_laps` over frames where particles may be absent: a frame where
    ``seen[k, p]`` is false (the particle absent there or in a frame since the previous one)
    ends the particle's record chain, and the next frame where it is seen starts a new one
    from its counter there, as a window's first frame does. ``started`` [N] (bool) says
    whether a chain is running; it, ``running_max`` and ``last_record`` carry over between
    blocks. Returns the number of samples written."""
    n_frames, n_particles = laps.shape
    n_out = 0
    for k in range(n_frames):
        t = times[k]
        for p in range(n_particles):
            if not seen[k, p]:
                started[p] = False
                last_record[p] = np.nan
                continue
            level = np.int64(laps[k, p])
            if not started[p]:
                started[p] = True
                running_max[p] = level
                continue
            n_out = _records(p, level, t, running_max, last_record, out, n_out)
    return n_out


@nb.njit(cache=True)
def _scan_open(times, present, vertical, last_vertical, band, height, was_present,
               last_height, entered, out):
    """Advance the residences of an open riser over a block of frames; write samples into
    ``out`` and return how many.

    Per particle: ``was_present`` [N] (int8: 1 present, 0 absent, -1 before the window's
    first frame), ``last_height`` [N] (its height when last present) and ``entered`` [N]
    (time of the entry of its current residence, -inf in one begun before the window, NaN
    outside one) carry over between blocks. An entry is a frame where the particle is
    present, was absent in the frame before and lies within ``band`` of the inlet where it
    was first seen (``vertical``: height <= band); an exit is a frame where it is absent,
    was present before and was within ``band`` of the outlet where it was last seen
    (``last_vertical`` of the frame before: height >= H - band). Frames a lag apart take
    those heights from the frames between (:func:`lag_face_heights`). A residence runs from an entry to the next
    exit; other absences (back out through the inlet, out of view) do not end it, also for
    a particle inside at the window's first frame, whose entry is unknown (no sample).
    """
    n_frames, n_particles = present.shape
    n_out = 0
    for k in range(n_frames):
        t = times[k]
        for p in range(n_particles):
            now = present[k, p]
            before = was_present[p]
            if now and before == -1:
                entered[p] = -np.inf        # inside at the start: its entry unknown
            elif now and before == 0 and vertical[k, p] <= band and np.isnan(entered[p]):
                entered[p] = t
            elif not now and before == 1 and last_height[p] >= height - band:
                if np.isfinite(entered[p]):
                    out[n_out] = t - entered[p]
                    n_out += 1
                entered[p] = np.nan
            if now:
                last_height[p] = last_vertical[k, p]
            was_present[p] = 1 if now else 0
    return n_out


@nb.njit(cache=True)
def _face_tracks(present, vertical, last_vertical, band, height, was_present, last_height,
                 counts):
    """Count an open riser's tracks that begin or end, and those of them within ``band`` of
    the inlet or the outlet, over a block of frames (Numba kernel): ``counts`` [5] +=
    (begun, begun at the inlet, ended, ended at the outlet, returns: begun at the inlet by
    a particle seen before that did not end at the outlet then, whose residence goes on).
    ``was_present`` (int8, -1 before the first frame) and ``last_height`` carry over
    between blocks."""
    n_frames, n_particles = present.shape
    for k in range(n_frames):
        for p in range(n_particles):
            now = present[k, p]
            before = was_present[p]
            if now and before == 0:
                counts[0] += 1
                if vertical[k, p] <= band:
                    counts[1] += 1
                    if last_height[p] < height - band:      # False for NaN: never seen
                        counts[4] += 1
            elif not now and before == 1:
                counts[2] += 1
                if last_height[p] >= height - band:
                    counts[3] += 1
            if now:
                last_height[p] = last_vertical[k, p]
            was_present[p] = 1 if now else 0


def lag_face_heights(vertical: np.ndarray, lag_frames: int, rows) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """Where a particle is first and last seen around each of the lag's frames: the
    heights an open riser's faces are judged by when it is read a lag apart.

    Parameters
    ----------
    vertical : ndarray of float64, shape (F, N)
        Heights on every frame (m), NaN where a particle is absent.
    lag_frames : int
        The lag, in frames.
    rows : slice or ndarray of int
        The lag's frames g among the F.

    Returns
    -------
    first_seen, last_seen : ndarray of float64, shape (T, N)
        Per lag frame g: the height at the first frame the particle is present in
        (g - lag, g] (an entry at g is judged there) and at the last frame it is present in
        [g, g + lag) (an exit at g + lag is judged there); NaN where it is present in none.
        A gap shorter than a lag between two lag frames does not end a presence.
    """
    vertical = np.asarray(vertical, dtype=np.float64)
    frames = np.arange(vertical.shape[0])[rows]
    first = np.full((frames.size, vertical.shape[1]), np.nan)
    last = np.full_like(first, np.nan)
    for back in range(int(lag_frames) - 1, -1, -1):      # the earliest present wins
        f = frames - back
        ok = f >= 0
        seen = np.where(ok[:, None], vertical[np.clip(f, 0, None)], np.nan)
        take = np.isnan(first) & np.isfinite(seen)
        first[take] = seen[take]
    for ahead in range(int(lag_frames) - 1, -1, -1):     # the latest present wins
        f = frames + ahead
        ok = f < vertical.shape[0]
        seen = np.where(ok[:, None], vertical[np.clip(f, None, vertical.shape[0] - 1)],
                        np.nan)
        take = np.isnan(last) & np.isfinite(seen)
        last[take] = seen[take]
    return first, last


def open_face_tracks(traj, window: tuple[float, float], band: float,
                     lag_frames: int = 1) -> tuple[int, int, int, int]:
    """How many of an open riser's tracks begin or end in a window, and how many of them
    within ``band`` of the inlet or the outlet: those the residence times count as entries
    and exits (:func:`residence_times`), the others being censored.

    Parameters
    ----------
    traj : cfbmarkov.trajectories.Trajectories
        An open trajectory file of an open riser.
    window : (float, float)
        The window (s).
    band : float
        How close to a face a track must begin or end to have crossed it, m.
    lag_frames : int, optional
        Every ``lag_frames``-th frame, as the residence times read them, with the faces
        judged where a particle is first and last seen on the frames between.

    Returns
    -------
    (int, int, int, int)
        Tracks begun after the window's first frame, those begun within ``band`` of the
        inlet, tracks ended before its last frame, those ended within ``band`` of the outlet.
        A particle that comes back through the inlet after it fell out (or left the view)
        goes on with its track, as its residence does: neither its fall nor its return is
        counted.
    """
    frames = traj.window(*window_pair(window))
    n = traj.n_particles
    was, last = np.full(n, -1, np.int8), np.full(n, np.nan)
    counts = np.zeros(5, np.int64)
    for block, present, first_seen, last_seen in _lag_blocks(traj, frames.start, frames.stop,
                                                            int(lag_frames)):
        _face_tracks(present, first_seen, last_seen, float(band), float(traj.height), was,
                     last, counts)
    returns = int(counts[4])
    return (int(counts[0]) - returns, int(counts[1]) - returns, int(counts[2]) - returns,
            int(counts[3]))


def _lag_blocks(traj, i0: int, i1: int, lag_frames: int):
    """The frames i0, i0 + lag, ... before i1 in blocks: (slice, presence [T, N], heights
    where first seen, heights where last seen), the heights from every frame around each
    (:func:`lag_face_heights`, within the frames i0 .. i1 - 1)."""
    span = _BLOCK_FRAMES * lag_frames
    for k in range(i0, i1, span):
        block = slice(k, min(k + span, i1), lag_frames)
        lo, hi = max(k - lag_frames + 1, i0), min(block.stop + lag_frames - 1, i1)
        heights = traj.positions(slice(lo, hi))[..., 1]
        present = np.ascontiguousarray(traj.present(block))
        first_seen, last_seen = lag_face_heights(
            np.where(np.ascontiguousarray(traj.present(slice(lo, hi))), heights, np.nan),
            lag_frames, np.arange(block.start, block.stop, lag_frames) - lo)
        yield block, present, np.nan_to_num(first_seen), np.nan_to_num(last_seen)


def open_residence_times(times, present, vertical, band: float, height: float) -> np.ndarray:
    """Residence-time samples of an open riser from frames (``docs/definitions.md``,
    Residence time in an open riser).

    Parameters
    ----------
    times : array_like of float, shape (T,)
        Frame times (s) of the analysis window.
    present : array_like of bool, shape (T, N)
        Which particles are in each frame.
    vertical : array_like of float, shape (T, N)
        Heights (m); ignored where absent.
    band : float
        How close to a face (m) a particle must appear or vanish to have crossed it.
    height : float
        The riser's height H (m).

    Returns
    -------
    numpy.ndarray of float64
        The time from each entry through the inlet to the next exit through the outlet,
        both inside the window (s): the first frame present to the first frame absent.
    """
    present = np.ascontiguousarray(present, dtype=np.bool_)
    n = present.shape[1]
    out = np.empty(present.size)
    vertical = np.ascontiguousarray(vertical, dtype=np.float64)
    k = _scan_open(np.ascontiguousarray(times, dtype=np.float64), present, vertical, vertical,
                   float(band), float(height),
                   np.full(n, -1, np.int8), np.full(n, np.nan), np.full(n, np.nan), out)
    return out[:k].copy()


def _new_levels_bound(laps: np.ndarray, running_max: np.ndarray) -> int:
    """Upper bound on the records in a block: new levels reached per particle, summed."""
    if laps.shape[0] == 0:
        return 0
    return int(np.maximum(laps.max(axis=0).astype(np.int64) - running_max, 0).sum())


def residence_times_from_laps(times, laps) -> np.ndarray:
    """Residence-time samples (s) from frames.

    The window is the span of the given frames: L is counted from its value in the first
    frame, and each frame time at which L exceeds its running maximum is a record (twice if
    L jumped by 2). Samples are the differences between consecutive records of the same
    particle, in the order in which they complete (by frame, then particle index).

    Parameters
    ----------
    times : array_like, shape (T,)
        Frame times, s.
    laps : array_like of int, shape (T, N)
        Lap counter L of each particle in each frame.

    Returns
    -------
    numpy.ndarray, shape (K,)
        Residence-time samples, s (empty for T = 0).

    Raises
    ------
    InputError
        When ``laps`` is not of shape (T, N) with T the number of ``times``, or its dtype
        is not an integer type.

    References
    ----------
    ``docs/definitions.md`` (Residence time, Residence-time samples).
    """
    times = np.ascontiguousarray(times, dtype=np.float64)
    laps = np.asarray(laps)
    if laps.ndim != 2 or times.ndim != 1 or laps.shape[0] != times.shape[0]:
        raise InputError(f"laps must have shape (T, N) with T = {times.shape[0]} frame times, "
                         f"got {laps.shape}")
    if not np.issubdtype(laps.dtype, np.integer):
        raise InputError(f"lap counters must be integers, got {laps.dtype}")
    if laps.shape[0] == 0:
        return np.zeros(0)
    laps = np.ascontiguousarray(laps)
    running_max = laps[0].astype(np.int64)
    last_record = np.full(laps.shape[1], np.nan)
    out = np.empty(_new_levels_bound(laps, running_max))
    n = _scan_laps(times, laps, running_max, last_record, out)
    return out[:n]


@nb.njit(cache=True)
def _scan_events(lap_at_start, event_time, event_particle, event_direction, start, stop, out):
    n_particles = lap_at_start.size
    level = np.empty(n_particles, np.int64)
    running_max = np.empty(n_particles, np.int64)
    last_record = np.empty(n_particles)
    for p in range(n_particles):
        level[p] = lap_at_start[p]
        running_max[p] = lap_at_start[p]
        last_record[p] = np.nan
    n_out = 0
    for e in range(event_time.size):
        t = event_time[e]
        if t <= start:
            continue
        if t > stop:
            break                                # events are sorted by time
        p = event_particle[e]
        level[p] += event_direction[e]
        if level[p] > running_max[p]:
            running_max[p] = level[p]
            if not np.isnan(last_record[p]):
                out[n_out] = t - last_record[p]
                n_out += 1
            last_record[p] = t
    return n_out


def residence_times_from_events(lap_at_start, event_time, event_particle, event_direction,
                                start: float, stop: float) -> np.ndarray:
    """Residence-time samples (s) from exact pass events.

    The events, sorted by time, are applied for ``start < t <= stop``. Each event that lifts
    a particle's counter above its running maximum since ``start`` is a record; samples are
    the differences of consecutive records of the same particle, in order of completion.

    Parameters
    ----------
    lap_at_start : array_like of int, shape (N,)
        Each particle's lap counter L at ``start``.
    event_time : array_like, shape (E,)
        Event times, s, sorted (non-decreasing).
    event_particle : array_like of int, shape (E,)
        Particle index (0 .. N - 1) of each event.
    event_direction : array_like of int, shape (E,)
        +1 for a pass up through the top, -1 for a pass down through the bottom.
    start, stop : float
        The window, s (``stop > start``).

    Returns
    -------
    numpy.ndarray, shape (K,)
        Residence-time samples, s.

    Raises
    ------
    InputError
        When the event arrays differ in length, the window is empty (``stop <= start``),
        the events are not sorted by time, a particle index lies outside 0 .. N - 1, or a
        direction is not +1 or -1.

    References
    ----------
    ``docs/definitions.md`` (Residence time, Residence-time samples).
    """
    lap_at_start = np.ascontiguousarray(lap_at_start, dtype=np.int64).reshape(-1)
    event_time = np.ascontiguousarray(event_time, dtype=np.float64).reshape(-1)
    event_particle = np.ascontiguousarray(event_particle, dtype=np.int64).reshape(-1)
    event_direction = np.ascontiguousarray(event_direction, dtype=np.int64).reshape(-1)
    e = event_time.size
    if event_particle.size != e or event_direction.size != e:
        raise InputError(f"pass events disagree in length: {e} times, {event_particle.size} "
                         f"particles, {event_direction.size} directions")
    if not stop > start:
        raise InputError(f"window {start:g}:{stop:g} s is empty (the end must follow the start)")
    if e:
        if np.any(np.diff(event_time) < 0):
            raise InputError("pass events are not sorted by time")
        if event_particle.min() < 0 or event_particle.max() >= lap_at_start.size:
            raise InputError(f"pass event refers to a particle index outside 0..{lap_at_start.size - 1}")
        if np.any((event_direction != 1) & (event_direction != -1)):
            raise InputError("pass event direction is not +1 or -1")
    n_up = int(np.count_nonzero(event_direction > 0))
    out = np.empty(n_up)
    n = _scan_events(lap_at_start, event_time, event_particle, event_direction,
                     float(start), float(stop), out)
    return out[:n]


# -- wrapper -------------------------------------------------------------------------------
@dataclass(frozen=True)
class ResidenceTimes:
    """Residence-time samples (s) of one trajectory file in one window.

    Attributes
    ----------
    samples : numpy.ndarray, shape (K,)
        Residence-time samples, s.
    exact : bool
        True when exact pass events were used, False when frame times were.
    window : (float, float)
        The analysis window (start, stop), s.
    """

    samples: np.ndarray
    #: True when exact pass events were used, False when frame times were
    exact: bool
    window: tuple[float, float]

    @property
    def count(self) -> int:
        """Number of samples."""
        return int(self.samples.size)

    @property
    def mean(self) -> float:
        """E(RT), s (NaN without samples)."""
        return float(self.samples.mean()) if self.samples.size else float("nan")

    @property
    def sd(self) -> float:
        """SD(RT), s, with ddof = 1 (NaN with fewer than two samples)."""
        return float(self.samples.std(ddof=1)) if self.samples.size > 1 else float("nan")

    def __repr__(self) -> str:
        return (f"ResidenceTimes({self.count} samples, mean {self.mean:.4g} s, sd {self.sd:.4g} s, "
                f"window {self.window[0]:g}:{self.window[1]:g} s, "
                f"{'exact events' if self.exact else 'frame times'})")


#: rows of the paper's cell grid: an open riser's face band defaults to H / 38 (one cell)
#: how far (in frames) a model's lag may lie from a whole number of a reference's frames and
#: be taken as that many: the time tolerance of a frame (half of
#: :data:`~cfbmarkov.trajectory_format.FRAME_SPACING_TOLERANCE`, as
#: ``Trajectories.lag_frames`` holds a lag to), not a share of the lag (1 % of 100 frames
#: would take 100.5 as 101)
WHOLE_FRAMES = 0.005

DEFAULT_FACE_ROWS = 38


def net_passes(traj, window: tuple[float, float]) -> int:
    """Net passes through the periodic boundary in a window: the lap counters' change from
    its first to its last frame, summed over the particles (negative: net downflow). A
    particle absent from some frames counts from its first to its last frame present in
    the window (passes while absent are not seen).

    Parameters
    ----------
    traj : Trajectories
        An open periodic trajectory file.
    window : (float, float)
        The window (s).

    Returns
    -------
    int
    """
    frames = traj.window(*window_pair(window))
    if not traj.has_absences:
        first = traj.laps(frames.start).astype(np.int64)
        last = traj.laps(frames.stop - 1).astype(np.int64)
        return int((last - first).sum())
    # with absences: from each particle's first to its last frame present in the window
    # (a counter carries on across an absence; an absent frame's stored lap means nothing)
    n = traj.n_particles
    first, last, seen = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, bool)
    for k in range(frames.start, frames.stop, _BLOCK_FRAMES):
        block = slice(k, min(k + _BLOCK_FRAMES, frames.stop))
        laps, here = traj.laps(block).astype(np.int64), np.asarray(traj.present(block))
        some = np.flatnonzero(here.any(axis=0))
        new = some[~seen[some]]
        first[new] = laps[here[:, new].argmax(axis=0), new]
        last[some] = laps[here.shape[0] - 1 - here[::-1, some].argmax(axis=0), some]
        seen[some] = True
    return int((last - first)[seen].sum())


def _tracked_flux(traj, window: tuple[float, float]) -> tuple[float, int]:
    """Particle-time and net passes over the window's frame steps at which the particle is
    present at both ends (a file with absences: what is seen while tracked, never a lap
    change across an absence)."""
    frames = traj.window(*window_pair(window))
    times = np.asarray(traj.times[frames], dtype=np.float64)
    particle_time, passes = 0.0, 0
    for k in range(frames.start, frames.stop - 1, _BLOCK_FRAMES):
        block = slice(k, min(k + _BLOCK_FRAMES + 1, frames.stop))      # one frame shared
        laps, here = traj.laps(block).astype(np.int64), np.asarray(traj.present(block))
        both = here[1:] & here[:-1]
        steps = np.diff(times[block.start - frames.start:block.stop - frames.start])
        particle_time += float(steps @ both.sum(axis=1))
        passes += int(np.diff(laps, axis=0)[both].sum())
    return particle_time, passes


def net_flow_direction(traj, window: tuple[float, float]) -> str:
    """The direction residences are counted in over a window: "down" where a periodic
    riser's net solids flow over it is downward (:func:`net_passes` < 0), else "up"
    (docs/definitions.md, Net downflow).

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file (an open riser: always "up").
    window : (float, float)
        The window (s).

    Returns
    -------
    {"up", "down"}
    """
    return "down" if not traj.boundary.is_open and net_passes(traj, window) < 0 else "up"


def flux_residence_time(traj, window: tuple[float, float], direction: str | None = None) -> float:
    """The mean residence time of a periodic riser's flow over a window from its net solids
    flux, free of the window's censoring: N (t_last - t_first) / the net passes in
    ``direction`` (``docs/definitions.md``, Long-run E(RT)).

    Every particle is always in the riser, and each residence ends with one net pass, so by
    Little's law (mean number in the system = throughput x mean time in it) the mean
    residence time is the particle-time over the passes that end residences. In a
    stationary flow the expected net lap change of a particle over a time T is T / E(RT)
    exactly (renewal-reward, whatever the RTD's shape), so the estimate is unbiased in its
    denominator however long the residences are against the window, unlike the mean of the
    residences observed wholly inside it, which leaves out those longer than the window and
    under-counts those close to its length (on a paper-scale riser at 4 m/s over 5-20 s:
    2.26 s from the flux, 0.99 s from the 246 510 residences inside). It is the observed
    counterpart of a chain's :func:`~cfbmarkov.markov.first_passage.drift_residence_time`.

    In a file with absent particles (a tracer out of the field of view, a particle outside
    the walls that is never present) both sides count the frame steps at which a particle is
    present at both ends only: the particle-time and the passes seen while it is tracked,
    never a lap change across an absence (what happens while it is away is not seen); a
    particle never present counts for nothing. The chain fitted on such a file counts its
    transitions so too.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file of a periodic riser.
    window : (float, float)
        The window (s).
    direction : {"up", "down"}, optional
        The direction residences are counted in; default the window's net flow direction
        (:func:`net_flow_direction`).

    Returns
    -------
    float
        E(RT) (s); ``inf`` where the window has no net pass in ``direction`` (the flow's
        long-run residence is then not finite over it).

    Raises
    ------
    InputError
        For an open riser (no lap counters), a bad direction, or a window as
        :meth:`~cfbmarkov.trajectories.Trajectories.window` refuses.

    References
    ----------
    J. D. C. Little, "A proof for the queuing formula L = lambda W", Oper. Res. 9, 383
    (1961); for the periodic riser, A. Wald, "On cumulative sums of random variables", Ann.
    Math. Stat. 15, 283 (1944), as in the chain's drift_residence_time.
    """
    particle_time, passes = residence_flux(traj, window, direction)
    return particle_time / passes if passes > 0 else float("inf")


def residence_flux(traj, window: tuple[float, float],
                   direction: str | None = None) -> tuple[float, int]:
    """The two sides of :func:`flux_residence_time`: the particle-time of a periodic riser
    over a window and its net passes in ``direction`` (several runs' are added before
    dividing).

    Parameters
    ----------
    traj, window, direction
        As :func:`flux_residence_time`.

    Returns
    -------
    particle_time : float
        N (t_last - t_first), particle s (with absences: the time of the frame steps with
        the particle present at both ends, summed over the particles).
    passes : int
        Net passes in ``direction`` (negative where the flow runs the other way).

    Raises
    ------
    InputError
        As :func:`flux_residence_time`.
    """
    if traj.boundary.is_open:
        raise InputError(f"{traj.path}: the flux residence time reads a periodic riser's lap "
                         "counters (an open riser has none)")
    if direction is not None and direction not in ("up", "down"):
        raise InputError(f"residence direction {direction!r}: up or down")
    if traj.has_absences:
        particle_time, passes = _tracked_flux(traj, window)
    else:
        frames = traj.window(*window_pair(window))
        length = float(traj.times[frames.stop - 1]) - float(traj.times[frames.start])
        particle_time, passes = traj.n_particles * length, net_passes(traj, window)
    direction = net_flow_direction(traj, window) if direction is None else direction
    return particle_time, int((1 if direction == "up" else -1) * passes)


def residence_times(traj, window: tuple[float, float], use_events: bool = True,
                    face_band: float | None = None, lag_frames: int = 1,
                    direction: str = "up", split_at_absences: bool = False) -> ResidenceTimes:
    """Residence-time samples of a trajectory file in a window.

    Uses the file's exact pass events when it has them and ``use_events`` is true (counted
    from the lap counter at the window's start, the first frame's less the passes between
    the start and that frame, events with start < t <= stop);
    otherwise the lap counters frame by frame, read in blocks.

    Parameters
    ----------
    traj : cfbmarkov.trajectories.Trajectories
        An open trajectory file.
    window : (float, float)
        Analysis window (start, stop), s.
    use_events : bool, optional
        Use the file's exact pass events (``/events``) when it has them.
    face_band : float, optional
        Open riser: how close to a face (m) a particle must appear or vanish to have
        crossed it (a model's cell height; default H / 38, the paper's rows).
    lag_frames : int, optional
        From frames: use every ``lag_frames``-th frame of the window from its first (a model's
        lag when the file's frames are finer), so that both sides of a comparison see
        passes on the same time basis (``docs/definitions.md``, Comparison basis). An open
        riser's faces are judged where the particle is first and last seen on the frames
        between the lag's, as the model counts them (:func:`lag_face_heights`).
    direction : {"up", "down"}, optional
        Periodic riser: residences from passes up through the top (the solids' net flow
        upward, the default) or, where the net flow is downward, down through the bottom
        (entries through the top, exits through the bottom; ``docs/definitions.md``, Net
        downflow).
    split_at_absences : bool, optional
        Periodic riser with particles absent from some frames: count each particle's
        residences within each stretch of frames where it is present, a stretch standing
        for a window of its own (a pass while absent is not seen, so a residence across an
        absence is not a sample; ``docs/definitions.md``, Residence times across
        absences). Default False: such a file is refused, unless every particle is present
        throughout the window or absent throughout
        (:meth:`~cfbmarkov.trajectories.Trajectories.absent_throughout`: the absent ones
        are left out, the others counted as in a file without absences). Without absences
        it changes nothing.

    Returns
    -------
    ResidenceTimes
        The samples (s), whether exact events were used, and the window. For an open
        riser: from entries through the inlet to exits through the outlet, from frames
        (:func:`open_residence_times`).

    Raises
    ------
    InputError
        When the window is empty, lies outside the file's frames or holds no frame
        (:meth:`~cfbmarkov.trajectories.Trajectories.window`), the file's pass events are
        damaged (unsorted, unequal lengths, bad particle index or direction), or a periodic
        riser has particles absent from part of the window and ``split_at_absences`` is
        false.

    References
    ----------
    ``docs/definitions.md`` (Residence time, Residence-time samples).
    """
    split = bool(split_at_absences) and traj.has_absences and not traj.boundary.is_open
    if traj.has_absences and not (traj.boundary.is_open or split) and \
            traj.absent_throughout(traj.window(*window_pair(window))) is not None:
        split = True      # each particle present throughout the window or absent throughout
    if traj.has_absences and not (traj.boundary.is_open or split):
        raise InputError(f"{traj.path}: residences on a periodic riser cannot be observed "
                         "across particles' absences (a pass while absent is not seen): "
                         "`fit` with the states given (--states cells) fits the model, its "
                         "verdict and interval counting residences within each particle's "
                         "stretches of presence; a window or span of the file in which "
                         "every particle is present throughout (or absent throughout) is "
                         "read as it is; import with --boundary open only where particles "
                         "enter and leave through the riser's faces (not where a tracer "
                         "is out of view)")
    traj.require_supported("residence times", three_d=True,
                           absent=traj.boundary.is_open or split, open_boundary=True)
    start, stop = window_pair(window)
    frames = traj.window(start, stop)
    i0, i1 = frames.start, frames.stop
    lag_frames = int(lag_frames)
    if lag_frames < 1:
        raise InputError(f"a lag of {lag_frames} frames: it must be at least 1")
    if direction not in ("up", "down"):
        raise InputError(f"residence direction {direction!r}: up or down")
    sign = 1 if direction == "up" else -1
    span = _BLOCK_FRAMES * lag_frames
    if traj.boundary.is_open:
        # the lag's frames, the faces judged where a particle is first and last seen on
        # every frame between them (judged on the lag's frames alone, a lag of 3 frames
        # lost 68 % of a known chain's residences, the short ones first)
        band = traj.height / DEFAULT_FACE_ROWS if face_band is None else float(face_band)
        n = traj.n_particles
        was, last, entered, chunks = np.full(n, -1, np.int8), np.full(n, np.nan), np.full(n, np.nan), []
        for block, present, first_seen, last_seen in _lag_blocks(traj, i0, i1, lag_frames):
            out = np.empty(present.size)
            m = _scan_open(np.ascontiguousarray(traj.times[block], dtype=np.float64), present,
                           first_seen, last_seen, band, traj.height, was, last, entered, out)
            chunks.append(out[:m])
        return ResidenceTimes(np.concatenate(chunks) if chunks else np.zeros(0), False,
                              (start, stop))
    if split:
        samples = _split_residences(traj, i0, i1, lag_frames, sign)
        _check_resolved(traj, samples, lag_frames)
        return ResidenceTimes(samples, False, (start, stop))
    if use_events and traj.has_events and lag_frames == 1:
        events = traj.events()
        t_first = float(traj.times[i0])
        if not stop > t_first:                   # a window of a single frame
            return ResidenceTimes(np.zeros(0), True, (start, stop))
        try:
            # the counters at the window's start: the first frame's, less the passes made
            # between the start and that frame (a window may start between frames)
            laps = traj.laps(i0).astype(np.int64)
            between = (events.time > start) & (events.time <= t_first)
            if between.any():
                np.subtract.at(laps, events.particle[between].astype(np.int64),
                               events.direction[between].astype(np.int64))
            first = min(start, t_first)
            samples = residence_times_from_events(sign * laps, events.time, events.particle,
                                                  sign * events.direction.astype(np.int64),
                                                  first, stop)
        except InputError as exc:
            raise InputError(f"{traj.path}: damaged pass events ({exc})") from None
        return ResidenceTimes(samples, True, (start, stop))
    running_max = None
    last_record = np.full(traj.n_particles, np.nan)
    chunks = []
    for k in range(i0, i1, span):
        block = slice(k, min(k + span, i1), lag_frames)
        laps = np.ascontiguousarray(traj.laps(block) if sign == 1 else -traj.laps(block))
        if running_max is None:
            running_max = laps[0].astype(np.int64)
        out = np.empty(_new_levels_bound(laps, running_max))
        n = _scan_laps(np.ascontiguousarray(traj.times[block], dtype=np.float64), laps,
                       running_max, last_record, out)
        chunks.append(out[:n])
    samples = np.concatenate(chunks) if chunks else np.zeros(0)
    _check_resolved(traj, samples, lag_frames)
    return ResidenceTimes(samples, False, (start, stop))


def _check_resolved(traj, samples: np.ndarray, lag_frames: int) -> None:
    """Refuse residences from frames one lag apart where a lap counter stepped by two or
    more within a lag (a residence shorter than the lag, recorded as zero) for more than
    :data:`~cfbmarkov.observed.lag_resolution.TOLERANCE` of them."""
    from cfbmarkov.observed.lag_resolution import TOLERANCE, short_residences

    short = short_residences(samples)
    if short > TOLERANCE * samples.size:
        raise InputError(f"{traj.path}: at a lag of {lag_frames * traj.frame_interval:g} s, "
                         f"{short} of {samples.size} residences are shorter than the lag (a "
                         "particle passed the periodic boundary twice or more between frames "
                         "one lag apart), so the residence times cannot be told; give a "
                         f"shorter lag (--lag; the file's frames are {traj.frame_interval:g} s "
                         "apart)")


def _split_residences(traj, i0: int, i1: int, lag_frames: int, sign: int) -> np.ndarray:
    """Residence-time samples of frames ``i0:i1:lag_frames`` of a periodic riser with
    absences, each particle's record chain cut where it is absent in a used frame or in a
    frame between two used ones (:func:`_scan_laps_present`)."""
    n = traj.n_particles
    running_max, last_record = np.zeros(n, np.int64), np.full(n, np.nan)
    started, chunks = np.zeros(n, np.bool_), []
    span = _BLOCK_FRAMES * lag_frames
    for k in range(i0, i1, span):
        end = min(k + span, i1)
        used = np.arange(k, end, lag_frames)
        lo = max(i0, k - lag_frames + 1)          # the frames since the previous used one
        absent = np.zeros((end - lo + 1, n), np.int64)
        np.cumsum(~traj.present(slice(lo, end)), axis=0, out=absent[1:])
        first = np.maximum(used - lag_frames + 1, i0) - lo
        seen = np.ascontiguousarray(absent[used - lo + 1] - absent[first] == 0)
        laps = sign * traj.laps(slice(k, end, lag_frames)).astype(np.int64)
        previous = np.where(started, running_max, laps[0])
        bound = int(np.maximum(np.diff(laps, axis=0, prepend=previous[None]), 0).sum())
        out = np.empty(bound)
        m = _scan_laps_present(np.ascontiguousarray(traj.times[k:end:lag_frames],
                                                    dtype=np.float64),
                               np.ascontiguousarray(laps), seen, running_max, last_record,
                               started, out)
        chunks.append(out[:m])
    return np.concatenate(chunks) if chunks else np.zeros(0)


def rtd_histogram(samples, bin_width: float = 0.025, *, window_length: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Residence-time distribution (RTD) as probability per bin.

    Bins are ``bin_width`` wide from 0 up to the window length (the last edge is the first
    multiple of the bin width at or above it), half-open [a, b). Samples lying within 1e-6
    bin widths below an edge count as on it, so frame-based samples that are whole multiples
    of the bin width fall in the same bin whatever their round-off. A sample exactly at the
    window length falls in the last bin; samples outside the bins are dropped.

    Parameters
    ----------
    samples : array_like
        Residence-time samples, s (flattened).
    bin_width : float, optional
        Bin width, s.
    window_length : float
        Length of the analysis window, s (keyword only).

    Returns
    -------
    edges : numpy.ndarray, shape (B + 1,)
        Bin edges, s, from 0.
    probability : numpy.ndarray, shape (B,)
        Probability per bin (-), summing to 1 over the samples in range (all zero when
        there are none).

    Raises
    ------
    InputError
        When ``bin_width`` or ``window_length`` is not finite and positive, or a sample is
        negative or not finite.

    References
    ----------
    ``docs/definitions.md`` (Residence time, Residence-time distribution); the paper's
    Figs. 8-9.
    """
    samples = np.asarray(samples, dtype=np.float64).reshape(-1)
    if not (np.isfinite(bin_width) and bin_width > 0):
        raise InputError(f"RTD bin width {bin_width:g} s must be positive")
    if not (np.isfinite(window_length) and window_length > 0):
        raise InputError(f"window length {window_length:g} s must be positive")
    bad = ~(np.isfinite(samples) & (samples >= 0))
    if bad.any():
        raise InputError(f"{int(bad.sum())} of {samples.size} residence times are not "
                         f"finite numbers >= 0 (e.g. {samples[bad][0]:g} s); give the "
                         "residence times in s")
    n_bins = max(1, int(np.ceil(window_length / bin_width - 1e-6)))
    edges = bin_width * np.arange(n_bins + 1)
    index = np.floor(samples / bin_width + 1e-6).astype(np.int64)
    # a sample exactly at the window length belongs to the last bin
    index[(index == n_bins) & (samples <= window_length * (1 + 1e-9))] = n_bins - 1
    index = index[(index >= 0) & (index < n_bins)]
    counts = np.bincount(index, minlength=n_bins).astype(np.float64)
    total = counts.sum()
    return edges, (counts / total if total > 0 else counts)


__all__ = ["WHOLE_FRAMES", "ResidenceTimes", "flux_residence_time", "lag_face_heights",
           "net_flow_direction", "open_face_tracks", "residence_times",
           "residence_times_from_events", "residence_times_from_laps", "rtd_histogram"]
