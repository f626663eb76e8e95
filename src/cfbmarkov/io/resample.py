"""Resampling of particle tracks at irregular times onto a uniform time grid.

Positron emission particle tracking (PEPT) and similar methods give one location of a tracer
every few milliseconds at irregular times, with gaps where the tracer left the field of view.
:func:`resample_tracks` puts such rows onto the grid ``k * interval`` (the multiples of the
interval from the first at or after the earliest row to the last at or before the latest,
so that frame times are round numbers) with the *presence rule*: a grid time ``t`` is present for a
particle if and only if

- the particle has a sample at ``t`` (within ``1e-9 * interval``), or
- it has two consecutive samples ``ta < t < tb`` with ``tb - ta <= max_gap``.

Everywhere else (before its first sample, after its last, inside a gap longer than
``max_gap``) the particle is absent: NaN positions, ``present`` False, lap 0. Samples no
further apart than ``max_gap`` form a *stretch*; present positions are linear interpolations
inside a stretch. This is a pure kernel: no file I/O, no printing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cfbmarkov.errors import InputError

__all__ = ["ResampledTracks", "resample_tracks"]

#: relative tolerance (of the interval) within which a sample counts as lying on a grid time
_TOL = 1e-9


@dataclass(frozen=True)
class ResampledTracks:
    """Tracks on a uniform time grid.

    Attributes
    ----------
    times : numpy.ndarray
        [T] float64, s: ``k * interval`` for the whole numbers k with ``k * interval`` within
        the span of the rows (rounded to 1e-9 of the interval).
    ids : numpy.ndarray
        [N] int64, the sorted unique particle ids.
    positions : numpy.ndarray
        [T, N, D] float64, m; NaN where absent. With a periodic height the vertical column
        lies in [0, H).
    present : numpy.ndarray
        [T, N] bool, the presence rule of the module docstring.
    laps : numpy.ndarray
        [T, N] int32 lap counters (passes up through the top minus passes down through the
        bottom); 0 where absent and everywhere for an open riser.
    """

    times: np.ndarray
    ids: np.ndarray
    positions: np.ndarray
    present: np.ndarray
    laps: np.ndarray


def _positive(value, what: str) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a positive number of seconds, not {value!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{what} must be a positive finite number, not {value!r}")
    return value


#: a bridged step is a gap where it spans this many times the track's median sample spacing
GAP_SPACINGS = 4
#: the span (s) before and after a gap over which the speed around it is fitted, at least
#: (and at least :data:`SPEED_SAMPLES` spacings)
SPEED_SPAN = 0.05
#: samples on each side of a gap from which the speed around it is measured, at least
SPEED_SAMPLES = 10


def _side_speed(ts, height, stop, first, last) -> float | None:
    """The vertical speed (m/s) fitted by least squares to the samples ``first`` .. ``last``
    (inclusive) of one side of a gap, None where they are fewer than half of
    :data:`SPEED_SAMPLES` or span less than half the time asked for (``stop`` - the side's
    other end)."""
    t, y = ts[first:last + 1], height[first:last + 1]
    if t.size < SPEED_SAMPLES // 2 or t[-1] - t[0] < 0.5 * stop:
        return None
    return float(np.polyfit(t - t.mean(), y, 1)[0])


def _gap_outrun(ts, height, joined, limit):
    """The first bridged gap across which the particle's own speed carries it further than
    ``limit`` (m), and that speed: (index k of the gap's first sample, m/s), or None.

    A gap is a step joined in one stretch that spans :data:`GAP_SPACINGS` times the
    track's median joined spacing or more. Its minimal-image step cannot tell a move of
    0.8 H up from one of 0.2 H down; the tracer's speed can. It is fitted by least squares
    to the unwrapped ``height`` over :data:`SPEED_SPAN` s (at least :data:`SPEED_SAMPLES`
    spacings) of the stretch before the gap and after it (a few samples close together
    carry the location error, not the motion); where both sides give a speed, of one sign,
    the smaller one times the gap's duration must stay within ``limit``. A tracer that
    turns in the gap (speeds of opposite signs) or a side without enough samples is not
    judged."""
    dt = np.diff(ts)
    if not joined.any():
        return None
    typical = float(np.median(dt[joined]))
    span = max(SPEED_SPAN, SPEED_SAMPLES * typical)
    breaks = ~joined | (dt >= GAP_SPACINGS * typical)     # steps no stretch runs across
    gaps = np.flatnonzero(joined & (dt >= GAP_SPACINGS * typical))
    if not gaps.size:
        return None
    # each side: back (on) to span s or the stretch's end, whichever comes first
    piece = np.concatenate([[0], np.cumsum(breaks)])      # the stretch of each sample
    starts = np.searchsorted(piece, piece, side="left")
    ends = np.searchsorted(piece, piece, side="right") - 1
    lo = np.maximum(np.searchsorted(ts, ts[gaps] - span, side="left"), starts[gaps])
    hi = np.minimum(np.searchsorted(ts, ts[gaps + 1] + span, side="right") - 1,
                    ends[gaps + 1])
    # a first look from the sides' end points, then the fit where it may matter: the fit
    # differs from it by the location error over span s, far below half of it
    with np.errstate(divide="ignore", invalid="ignore"):
        rough_before = (height[gaps] - height[lo]) / (ts[gaps] - ts[lo])
        rough_after = (height[hi] - height[gaps + 1]) / (ts[hi] - ts[gaps + 1])
    rough = np.minimum(np.abs(rough_before), np.abs(rough_after))
    judged = ((rough_before * rough_after > 0) & (rough * dt[gaps] > 0.5 * limit))
    for g in np.flatnonzero(judged):
        k = int(gaps[g])
        before = _side_speed(ts, height, span, int(lo[g]), k)
        after = _side_speed(ts, height, span, k + 1, int(hi[g]))
        if before is None or after is None or before * after <= 0:
            continue
        speed = float(np.sign(before) * min(abs(before), abs(after)))
        if abs(speed * dt[k]) > limit:
            return k, speed
    return None


def resample_tracks(times, particles, positions, *, interval, max_gap=None, height=None,
                    vertical=1, max_step=0.25, label="tracks", open_height=None
                    ) -> ResampledTracks:
    """Resample rows ``(time, particle, position)`` onto the grid ``k * interval`` (the
    multiples of ``interval`` within the span of the rows).

    Present grid times (module docstring) get positions by linear interpolation between the
    two samples around them, ``x = xa + (t - ta) / (tb - ta) * (xb - xa)``; a sample on a grid
    time is copied exactly. With a periodic vertical axis (``height`` = H) the interpolation
    runs in the unwrapped height: between consecutive samples of one stretch the vertical step
    ``dy`` is taken by the minimal-image rule (``dy < -H/2``: passed up through the top, +H;
    ``dy > H/2``: passed down through the bottom, -H; Allen & Tildesley, *Computer Simulation
    of Liquids*, section 1.5.2). The stored height is the unwrapped one mod H and the lap is
    ``floor(unwrapped / H)``, counted from 0 at the particle's first sample. Across a gap
    (longer than ``max_gap``) no pass can be seen, so the next stretch's laps continue from
    the last lap of the previous stretch.

    Rows may come in any order (they are sorted by particle, then time, stably). The work is
    one loop over particles, each handled with vectorized numpy (``np.searchsorted``,
    ``np.cumsum``); there is no Python loop over rows or grid times, so 1e6 rows of one tracer
    take well under a second.

    Parameters
    ----------
    times : array_like
        [R] float, s, the time of each row.
    particles : array_like
        [R] int, the particle id of each row.
    positions : array_like
        [R, D] float, m, D = 2 or 3.
    interval : float
        s, the grid step (``--resample``); at most the span ``t_max - t_min`` of the data.
    max_gap : float, optional
        s, the longest time between two samples that is interpolated across
        (``--max-gap``); default ``interval``. It may be smaller than ``interval``.
    height : float, optional
        m, the period H of a periodic vertical axis (a circulating riser); None (default) for
        an open riser: no unwrapping, laps all 0.
    vertical : int, optional
        The column of ``positions`` that holds the height; default 1.
    max_step : float, optional
        The largest minimal-image vertical step between consecutive samples, as a fraction
        of H, that is trusted; default 0.25.
    label : str, optional
        The name of the data in error messages.
    open_height : float, optional
        m, an open riser's height: consecutive samples that lie half of it or more apart
        vertically are not joined (a particle that left through one face and came back
        through the other, e.g. a tracer in a circulating loop seen in an open view), so no
        height is interpolated across the riser between them.

    Returns
    -------
    ResampledTracks
        Times [T], ids [N], positions [T, N, D], present [T, N] and laps [T, N].

    Raises
    ------
    InputError
        If there are no rows, shapes disagree, a time or position is not finite, a particle
        has two rows at one time, ``interval``, ``max_gap``, ``height`` or ``max_step`` is
        not a positive finite number, ``interval`` is larger than the span of the data, a
        minimal-image vertical step exceeds ``max_step * H`` or a bridged gap is one across
        which the particle's speed before and after it carries it further than that (its
        passes there cannot be counted: a move of 0.8 H up reads as 0.2 H down), or no grid
        time is present for any particle.
    """
    interval = _positive(interval, "--resample (the resample step)")
    max_gap = interval if max_gap is None else _positive(max_gap, "--max-gap")
    max_step = _positive(max_step, "max_step")
    period = None if height is None else _positive(height, "the riser height")
    t = np.asarray(times, dtype=np.float64)
    pos = np.asarray(positions, dtype=np.float64)
    ids_in = np.asarray(particles)
    if t.ndim != 1 or t.size == 0:
        raise InputError(f"{label}: no rows to resample (--resample needs at least two times)")
    if ids_in.shape != t.shape or pos.ndim != 2 or len(pos) != len(t) or pos.shape[1] not in (2, 3):
        raise InputError(f"{label}: times {t.shape}, particles {ids_in.shape} and positions "
                         f"{pos.shape} do not agree as [R], [R] and [R, 2 or 3]")
    if not 0 <= vertical < pos.shape[1]:
        raise InputError(f"{label}: vertical column {vertical} is not one of the "
                         f"{pos.shape[1]} position columns")
    if not (np.issubdtype(ids_in.dtype, np.integer)
            or (np.all(np.isfinite(ids_in)) and np.all(ids_in == np.round(ids_in)))):
        raise InputError(f"{label}: particle ids must be whole numbers")
    pid = ids_in.astype(np.int64)
    for name, values in (("time", t), ("position", pos)):
        bad = np.flatnonzero(~np.isfinite(values.reshape(len(t), -1)).all(axis=1))
        if bad.size:
            raise InputError(f"{label}: {bad.size} row(s) have a non-finite {name}, the first "
                             f"of particle {pid[bad[0]]} at row {bad[0]}")
    start, span = float(t.min()), float(t.max() - t.min())
    if interval > span:
        raise InputError(f"{label}: --resample step {interval:g} s is larger than the span "
                         f"{span:g} s of the data")

    order = np.lexsort((t, pid))
    t, pid, pos = t[order], pid[order], pos[order]
    same = np.flatnonzero((pid[1:] == pid[:-1]) & (t[1:] == t[:-1]))
    if same.size:
        raise InputError(f"{label}: particle {pid[same[0]]} has two rows at t = {t[same[0]]:g} s")
    ids, first = np.unique(pid, return_index=True)
    bounds = np.append(first, len(t))

    from cfbmarkov.limits import check_memory

    frames = span / interval + 1
    check_memory(frames * ids.size * (8.0 * pos.shape[1] + 5), f"{label}: resampling "
                 f"{ids.size} particles onto {frames:.3g} frames", "use a larger --resample step")
    first_k = int(math.ceil(start / interval - _TOL))       # the grid: multiples of interval
    n_times = int(math.floor(float(t.max()) / interval + _TOL)) - first_k + 1
    decimals = 9 - int(math.floor(math.log10(interval)))   # below 1e-9 intervals: no round-off
    grid = np.round((first_k + np.arange(n_times)) * interval, decimals)
    out = np.full((n_times, len(ids), pos.shape[1]), np.nan)
    present = np.zeros((n_times, len(ids)), dtype=bool)
    laps = np.zeros((n_times, len(ids)), dtype=np.int32)
    tol = _TOL * interval
    for j, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        ts, xs = t[a:b], pos[a:b].copy()
        joined = np.diff(ts) <= max_gap + tol        # consecutive samples in one stretch
        if period is None and open_height is not None:  # left and came back: two stretches
            joined &= np.abs(np.diff(xs[:, vertical])) < 0.5 * float(open_height)
        lap = np.zeros(len(ts), dtype=np.int64)
        if period is not None:
            y = np.mod(xs[:, vertical], period)
            y[y >= period] = 0.0                     # np.mod(-tiny, H) can round to H
            xs[:, vertical] = y
            wrap = -np.round(np.diff(y) / period)    # +1: up through the top, -1: down
            step = np.diff(y) + wrap * period        # the minimal-image step, |step| <= H/2
            coarse = np.flatnonzero(joined & (np.abs(step) > max_step * period))
            if coarse.size:
                k = coarse[0]
                raise InputError(
                    f"{label}: particle {ids[j]} moves {step[k]:+.4g} m vertically between t = "
                    f"{ts[k]:.9g} and {ts[k + 1]:.9g} s, more than {max_step:g} x the height "
                    f"{period:g} m, so its passes through the top between the two samples "
                    f"cannot be counted; give --max-gap below {ts[k + 1] - ts[k]:.3g} s (the "
                    "particle is then absent between them, its passes there not counted), or "
                    "give unwrapped coordinates")
            lap[1:] = np.cumsum(np.where(joined, wrap, 0).astype(np.int64))
            fast = _gap_outrun(ts, y + period * lap, joined, max_step * period)
            if fast is not None:
                k, speed = fast
                raise InputError(
                    f"{label}: particle {ids[j]} moves at {speed:+.3g} m/s or faster "
                    f"vertically before and after its samples at t = {ts[k]:.9g} and "
                    f"{ts[k + 1]:.9g} s (its speed fitted on each side of the gap), so "
                    f"between them it can move {speed * (ts[k + 1] - ts[k]):+.3g} m, more "
                    f"than {max_step:g} x the height {period:g} m, while their heights differ "
                    f"by {step[k]:+.3g} m: its passes through the top there cannot be counted; "
                    f"give --max-gap below {ts[k + 1] - ts[k]:.3g} s (the particle is then "
                    "absent between them, its passes there not counted), or give unwrapped "
                    "coordinates")
        k0 = max(int(math.ceil(ts[0] / interval - _TOL)) - first_k, 0)
        k1 = min(int(math.floor(ts[-1] / interval + _TOL)) - first_k, n_times - 1)
        if k1 < k0:
            continue
        g = grid[k0:k1 + 1]
        i = np.minimum(np.searchsorted(ts, g - tol, side="left"), len(ts) - 1)
        exact = np.abs(ts[i] - g) <= tol
        ia = np.maximum(i - 1, 0)
        joined_at = np.append(joined, False)        # [n]: sample k and k + 1 in one stretch
        between = ~exact & (i >= 1) & joined_at[ia] & (ts[ia] < g) & (g < ts[i])
        here = exact | between
        ke, kb = np.flatnonzero(exact), np.flatnonzero(between)
        rows_b, rows_a = i[kb], ia[kb]
        w = ((g[kb] - ts[rows_a]) / (ts[rows_b] - ts[rows_a]))[:, None]
        values = np.full((len(g), pos.shape[1]), np.nan)
        values[ke] = xs[i[ke]]
        dx = xs[rows_b] - xs[rows_a]
        glap = np.zeros(len(g), dtype=np.int64)
        glap[ke] = lap[i[ke]]
        if period is not None:                       # interpolate in the unwrapped height
            dx[:, vertical] += (lap[rows_b] - lap[rows_a]) * period
        values[kb] = xs[rows_a] + w * dx
        if period is not None:
            shift = np.floor(values[kb, vertical] / period).astype(np.int64)
            height_in = values[kb, vertical] - shift * period
            low = height_in < 0                      # rounding can leave it a hair outside [0, H)
            height_in[low], shift[low] = height_in[low] + period, shift[low] - 1
            high = height_in >= period
            height_in[high], shift[high] = height_in[high] - period, shift[high] + 1
            values[kb, vertical] = height_in
            glap[kb] = lap[rows_a] + shift
        out[k0:k1 + 1, j][here] = values[here]
        present[k0:k1 + 1, j] = here
        laps[k0:k1 + 1, j] = np.where(here, glap, 0)
    if not present.any():   # every sample off the grid and no two within --max-gap around one
        raise InputError(f"{label}: no grid time is present for any particle with --max-gap "
                         f"{max_gap:g} s (the samples are further apart than that); give a larger "
                         f"--max-gap")
    return ResampledTracks(times=grid, ids=ids, positions=out, present=present, laps=laps)


#: rows of one time stamp may lie this many of their particle's median steps apart
SPREAD_STEPS = 3.0


def _check_spread(pos, pid, t, first, group, limit, height, vertical, label) -> None:
    """Refuse rows of one particle and time that lie farther from their group's first row
    than ``limit`` and than :data:`SPREAD_STEPS` times the particle's median step between
    consecutive distinct times (rows sorted by particle, then time)."""
    spread = np.linalg.norm(pos - pos[first[group]], axis=1)
    suspects = np.flatnonzero(spread > limit)
    if suspects.size == 0:
        return
    heads = pos[first]
    steps = heads[1:] - heads[:-1]
    if height is not None:
        steps[:, vertical] -= height * np.round(steps[:, vertical] / height)
    step = np.linalg.norm(steps, axis=1)
    same = pid[first][1:] == pid[first][:-1]
    for particle in np.unique(pid[suspects]):       # the few particles with a wide spread
        own = step[same & (pid[first][1:] == particle)]
        allowed = max(limit, SPREAD_STEPS * float(np.median(own)) if own.size else limit)
        rows = suspects[(pid[suspects] == particle) & (spread[suspects] > allowed)]
        if rows.size:
            k = int(rows[np.argmax(spread[rows])])
            raise InputError(
                f"{label}: two rows of particle {pid[k]} at t = {t[k]:g} s lie "
                f"{spread[k]:.3g} m apart (more than {allowed:.3g} m: {limit:.3g} m and "
                f"{SPREAD_STEPS:g} times its median step between samples), so they are "
                "not one sample of one track; check the id column (two tracers under one "
                "id?) or remove the wrong row")


def merge_same_times(times, particles, positions, *, height: float | None = None,
                     vertical: int = 1, spread_limit: float | None = None,
                     label: str = "the file"
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Merge the rows of a particle that share a time stamp into one, at their mean position.

    PEPT locations are printed at a fixed precision, so two locations of one tracer may carry
    the same time; they are one sample of the track.

    Parameters
    ----------
    times : array_like
        [R] float, s.
    particles : array_like
        [R] int, the particle id of each row.
    positions : array_like
        [R, D] float, m.
    height : float, optional
        m, the period H of a periodic vertical axis: heights are averaged by the minimal
        image about the group's first row, then wrapped into 0..H. None: plain means.
    vertical : int, optional
        The column of ``positions`` that holds the height.
    spread_limit : float, optional
        m: rows of one time that lie farther than this, and farther than
        :data:`SPREAD_STEPS` times the particle's median step between its samples of
        distinct times, from the group's first row are refused, not averaged (they are not
        one sample of one track: a tracer moves about a step within a time stamp's
        precision). None: no limit.
    label : str, optional
        Names the file in error messages.

    Returns
    -------
    times, particles, positions : numpy.ndarray
        The rows with each (particle, time) once, sorted by particle then time.
    merged : int
        The number of rows merged away (R minus the rows returned).

    Raises
    ------
    InputError
        If rows of one particle at one time lie farther apart than ``spread_limit``.
    """
    t = np.asarray(times, dtype=np.float64)
    pid = np.asarray(particles).astype(np.int64)
    pos = np.array(positions, dtype=np.float64)
    order = np.lexsort((t, pid))
    t, pid, pos = t[order], pid[order], pos[order]
    start = np.ones(t.size, dtype=bool)
    start[1:] = (pid[1:] != pid[:-1]) | (t[1:] != t[:-1])
    if start.all():
        return t, pid, pos, 0
    group = np.cumsum(start) - 1
    first = np.flatnonzero(start)
    if height is not None:
        offset = pos[:, vertical] - pos[first[group], vertical]
        pos[:, vertical] = pos[first[group], vertical] + offset - height * np.round(offset / height)
    if spread_limit is not None:
        _check_spread(pos, pid, t, first, group, spread_limit, height, vertical, label)
    sums = np.zeros((first.size, pos.shape[1]))
    np.add.at(sums, group, pos)
    mean = sums / np.bincount(group)[:, None]
    if height is not None:
        mean[:, vertical] = np.mod(mean[:, vertical], height)
    return t[first], pid[first], mean, int(t.size - first.size)
