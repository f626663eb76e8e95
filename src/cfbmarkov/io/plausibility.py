"""Warnings on an imported file whose sizes suggest a unit mistake: a riser kilometres
high, particles crowded into a sliver of the riser, frames microseconds apart. The import
itself stands (the sizes may be meant); the lines say what to check and how to fix it."""

from __future__ import annotations

import numpy as np

#: a riser's height (m) outside which the lengths are likely not in metres
HEIGHT_RANGE = (0.01, 100.0)
#: the share of the riser's height below which the particles' span suggests other units
SPAN_SHARE = 0.01
#: a frame interval (s) below which the times are likely not in seconds
SHORTEST_FRAME_INTERVAL = 1e-5
#: frames read to measure the particles' span (the first, the last and some between)
SAMPLED_FRAMES = 5
#: the particles' median speed (m/s) between frames outside which the times' or lengths'
#: unit is likely wrong (riser solids move at cm/s to tens of m/s)
SPEED_RANGE = (0.02, 100.0)
#: pairs of consecutive frames read to measure the particles' speed
SAMPLED_PAIRS = 10
#: the factors by which the moves' median speed may exceed the stored velocities' (moves
#: faster than the particles' own velocities cannot be), and fall short of it (frames far
#: apart in a flow that turns back show shorter moves), before the frames' times are taken
#: to be wrong
VELOCITY_MISMATCH = (5.0, 30.0)


def _sampled_frames(traj) -> np.ndarray:
    """The frames read to measure the particles' span: :data:`SAMPLED_FRAMES` of them,
    evenly from the first to the last."""
    return np.unique(np.linspace(0, traj.n_frames - 1, SAMPLED_FRAMES).round().astype(int))


def unit_warnings(traj) -> list[str]:
    """The unit warnings of an imported trajectory file.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    list of str
        One line each: a riser height outside :data:`HEIGHT_RANGE`, particles whose heights
        over a few frames (:data:`SAMPLED_FRAMES`, first to last) span less than
        :data:`SPAN_SHARE` of the riser's height, a median speed between frames outside
        :data:`SPEED_RANGE` (:func:`median_speed`), or frames less than
        :data:`SHORTEST_FRAME_INTERVAL` apart.
    """
    lines = []
    height, width = traj.height, traj.width
    low, high = HEIGHT_RANGE
    frames = _sampled_frames(traj)
    sampled = np.concatenate([traj.positions(int(k)) for k in frames])
    sampled = sampled[np.isfinite(sampled).all(axis=1)]
    heights = sampled[:, 1]
    if not low <= height <= high:
        # sizes typed in mm where they are in m: the particles fill a thousandth of them
        inside = (height > high and sampled.size
                  and np.all(np.abs(sampled[:, :2]) <= 1e-3 * np.array([width, height]) * 1.01))
        hint = (f"; given in mm? --width {width / 1000:g} --height {height / 1000:g} (m) "
                "would hold the particles" if inside else "")
        lines.append(f"the riser is {height:g} m high and {width:g} m wide: lengths are in "
                     "metres (CSV: --length-unit for the positions' unit; a dump is read "
                     "in SI units, so write it with LAMMPS's units si; --width and --height "
                     "in m, --region in the source's own units); check the units if that is "
                     f"not the riser{hint}")
    if heights.size > 1:
        span = float(heights.max() - heights.min())
        if span < SPAN_SHARE * height:
            lines.append(f"the particles' heights span {span:.3g} m of the riser's {height:g} m "
                         f"(in {frames.size} frames from the first to the last): the positions' "
                         "unit and the riser's may differ (CSV: --length-unit; a dump: "
                         "written in SI units, LAMMPS's units si; --width and "
                         "--height are in m, --region in the source's own units), or the "
                         "heights come from another axis than the vertical one (3D positions: "
                         "--vertical-axis names the vertical)")
    speed = median_speed(traj)
    stored = median_stored_speed(traj)
    if np.isfinite(speed) and np.isfinite(stored) and speed > 0 and stored > 0 and (
            speed / stored > VELOCITY_MISMATCH[0] or stored / speed > VELOCITY_MISMATCH[1]):
        lines.append(f"the file's velocities (median {stored:.3g} m/s) disagree with the "
                     f"particles' moves between frames (median {speed:.3g} m/s) by a factor "
                     f"{max(speed, stored) / min(speed, stored):.3g}: the frames' times are "
                     "likely wrong (dumps: --time-step in s, the simulation's time step; "
                     "CSV: --time-unit)")
    slow, fast = SPEED_RANGE
    if np.isfinite(speed) and 0 < speed < slow:
        lines.append(f"the particles move at a median {speed:.3g} m/s between frames: times "
                     "in milliseconds read as seconds (CSV: --time-unit ms; dumps: "
                     "--time-step in s), or lengths in metres read as millimetres (a "
                     "--length-unit mm too many)? check the times and lengths if the flow is "
                     "not this slow")
    elif speed > fast:
        lines.append(f"the particles move at a median {speed:.3g} m/s between frames: times "
                     "in seconds read as milliseconds, or lengths in mm read as m? (CSV: "
                     "--time-unit, --length-unit; dumps: --time-step in s, and SI units, "
                     "LAMMPS's units si); check the units if the flow is that fast")
    interval = traj.frame_interval
    if np.isfinite(interval) and 0 < interval < SHORTEST_FRAME_INTERVAL:
        lines.append(f"frames {interval:g} s apart: the times are read too small (CSV: a "
                     "file in seconds given --time-unit ms, drop it; dumps: --time-step in "
                     "s); check the times if that is not the sampling")
    return lines


def flat_heights(traj) -> str | None:
    """Why an imported 3D file cannot be a riser run, where its particles all lie at one
    and the same height in every frame read (:data:`SAMPLED_FRAMES`, first to last) while
    they move along another axis: the axis taken as the vertical is one along which they
    never move (a 2D dump's z given as ``--vertical-axis z``), and no pass, residence or
    model can come of it. Unlike :func:`unit_warnings`' findings, which may be meant, this
    one is refused (a 2D file of flat heights keeps :func:`unit_warnings`' line).

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    str or None
        The line for the refusal; None where two or more particles are seen and their
        heights differ somewhere.
    """
    if traj.dimensions != 3:
        return None
    frames = _sampled_frames(traj)
    positions = np.stack([traj.positions(int(k)) for k in frames])
    seen = np.isfinite(positions).all(axis=2)
    if np.count_nonzero(seen.any(axis=0)) < 2:
        return None
    values = positions[seen]
    if values[:, 1].max() > values[:, 1].min() or np.ptp(values[:, 2]) == 0:
        return None
    axis = traj.parameters.get("vertical_axis") or "y"
    return (f"every particle lies at the height {values[0, 1]:g} m in every frame read (the "
            f"vertical axis {axis}): the particles never move along it, so it is not the "
            "riser's vertical; give the axis along which they rise and fall with "
            "--vertical-axis x|y|z (a 2D dump: leave --vertical-axis out, y is vertical)")


def median_speed(traj) -> float:
    """The particles' median speed (m/s) between consecutive frames, over
    :data:`SAMPLED_PAIRS` pairs spread through the file: |displacement| / frame interval
    of the particles present in both frames of a pair, leaving out moves of half the
    riser's height or more (a pass through a periodic boundary, or a particle leaving an
    open riser and a new one entering).

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    float
        NaN where no particle is present in both frames of any pair.
    """
    if traj.n_frames < 2:
        return float("nan")
    starts = np.unique(np.linspace(0, traj.n_frames - 2, SAMPLED_PAIRS).round().astype(int))
    speeds = []
    for k in starts:
        a, b = traj.positions(int(k)), traj.positions(int(k) + 1)
        dt = float(traj.times[k + 1] - traj.times[k])
        step = np.linalg.norm(b - a, axis=1)
        keep = np.isfinite(step) & (np.abs(b[:, 1] - a[:, 1]) < 0.5 * traj.height)
        if dt > 0 and keep.any():
            speeds.append(step[keep] / dt)
    if not speeds and traj.n_particles * traj.n_frames <= SPARSE_VALUES:
        speeds = _sparse_speeds(traj)
    return float(np.median(np.concatenate(speeds))) if speeds else float("nan")


def presence_warnings(traj) -> list[str]:
    """A warning where some particles of an imported file lie in no frame inside the
    riser: the region (``--region``, ``--width``, ``--height``) leaves out part of the
    riser, or the source's origin is not the riser's corner.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    list of str
    """
    if not traj.has_absences or traj.n_particles == 0:
        return []
    seen = np.zeros(traj.n_particles, dtype=bool)
    for start in range(0, traj.n_frames, 256):       # blocks of frames: bounded memory
        seen |= traj.present(slice(start, start + 256)).any(axis=0)
    never = int(np.count_nonzero(~seen))
    if not never:
        return []
    verb = "lies" if never == 1 else "lie"
    return [f"{never} of the {traj.n_particles} particles {verb} outside the riser's region in "
            "every frame: the region leaves out part of the riser, or its origin is not the "
            "riser's corner; check --region (or --width/--height, from 0 in the source's "
            "coordinates) against the riser's walls"]


def shape_warnings(traj) -> list[str]:
    """A warning where the imported riser is wider (or deeper) than it is high: a riser is
    tall, so the vertical axis is most likely wrong (``--vertical-axis``; a 2D source's
    default is y).

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    list of str
    """
    p = traj.parameters
    depth = getattr(traj, "depth", None) or 0.0
    if traj.height >= max(traj.width, depth):
        return []
    axis = p.get("vertical_axis") or "y"
    sides = f"{traj.width:g} m across" + (f", {depth:g} m deep" if depth else "")
    return [f"the riser is {sides} and {traj.height:g} m high (vertical axis {axis}): a riser "
            "is taller than it is wide, so the vertical axis is most likely wrong; give the "
            "axis along which the particles rise and fall with --vertical-axis x|y|z"]


def gap_warnings(traj) -> list[str]:
    """A warning where a resampled import's tracers are absent between samples further apart
    than the default ``--max-gap`` (the resample step) and present again after: on
    irregularly sampled tracks (PEPT) each such gap breaks a residence, which a larger
    ``--max-gap`` would bridge where the tracer stayed in the riser.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    list of str
    """
    p = traj.parameters
    if not p.get("resample") or p.get("max_gap_from") != "default" or not traj.has_absences:
        return []
    seen = np.zeros(traj.n_particles, dtype=bool)
    previous = np.zeros(traj.n_particles, dtype=bool)
    gaps = 0
    for start in range(0, traj.n_frames, 4096):        # blocks of frames: bounded memory
        present = traj.present(slice(start, start + 4096))
        rows = np.vstack([previous[None, :], present])
        back = ~rows[:-1] & rows[1:]                   # absent, then present again
        gaps += int(np.count_nonzero(back & np.logical_or.accumulate(
            np.vstack([seen[None, :], rows[1:-1]]), axis=0)))
        seen |= present.any(axis=0)
        previous = present[-1]
    if not gaps:
        return []
    step = float(p["resample"])
    return [f"the tracers are absent {gaps} time(s) between two of their samples further "
            f"apart than --max-gap, by default the resample step {step:g} s, and each such "
            "gap breaks a residence; where the tracers stayed in view between samples, "
            f"give a larger --max-gap (such as {4 * step:g}); a gap over which a tracer moves "
            "more than a quarter of the riser's height cannot be bridged and is refused, "
            "naming the largest --max-gap that leaves it out"]


def median_stored_speed(traj) -> float:
    """The median speed (m/s) of the non-zero velocities stored in the file, at the frames
    that :func:`median_speed` samples; NaN where the file stores none."""
    if not traj.has_velocity or traj.n_frames < 2:
        return float("nan")
    starts = np.unique(np.linspace(0, traj.n_frames - 2, SAMPLED_PAIRS).round().astype(int))
    speeds = [np.linalg.norm(traj.velocities(int(k)), axis=1) for k in starts]
    speeds = np.concatenate(speeds)
    speeds = speeds[np.isfinite(speeds) & (speeds > 0)]    # zeros: velocities not written
    return float(np.median(speeds)) if speeds.size else float("nan")


#: the most particle-frames read whole where no particle is present in two consecutive
#: frames (a tracer resampled with gaps longer than its samples' spacing)
SPARSE_VALUES = 5_000_000


def _sparse_speeds(traj) -> list[np.ndarray]:
    """Speeds between each particle's consecutive observations, however far apart, with
    heights unwrapped by the laps on a periodic riser (an open riser's moves of half its
    height or more left out)."""
    positions, present = traj.positions(), traj.present()
    laps = None if traj.boundary.is_open else traj.laps()
    speeds = []
    for j in range(traj.n_particles):
        seen = np.flatnonzero(present[:, j] & np.isfinite(positions[:, j, 1]))
        if seen.size < 2:
            continue
        track = positions[seen, j].copy()
        if laps is not None:
            track[:, 1] += traj.height * laps[seen, j]
        step = np.linalg.norm(np.diff(track, axis=0), axis=1)
        dt = np.diff(traj.times[seen])
        keep = dt > 0
        if laps is None:
            keep &= np.abs(np.diff(track[:, 1])) < 0.5 * traj.height
        speeds.append(step[keep] / dt[keep])
    return speeds


#: frames read at once where every frame is scanned (bounded memory)
FRAME_BLOCK = 256


def return_warnings(traj) -> list[str]:
    """A warning where particles of an open riser move half its height or more between
    consecutive frames in which they are present: particles taken from the outlet back to
    the inlet (or the other way) keeping their ids, which an open riser reads as one move
    inside it, not as an exit and an entry.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file; a periodic riser gets no warning (its laps count such
        moves as passes through the boundary).

    Returns
    -------
    list of str
        At most one line: how many such moves, the first one (particle id, heights, times),
        and the fixes (``--boundary periodic`` for a riser that recycles its particles, or
        the frames' times).
    """
    if not traj.boundary.is_open or traj.n_frames < 2 or traj.n_particles == 0:
        return []
    count, first = 0, None
    half = 0.5 * traj.height
    for start in range(0, traj.n_frames - 1, FRAME_BLOCK):
        stop = min(start + FRAME_BLOCK + 1, traj.n_frames)
        heights = traj.positions(slice(start, stop))[:, :, 1]
        present = traj.present(slice(start, stop))
        both = present[1:] & present[:-1]
        with np.errstate(invalid="ignore"):
            jump = both & (np.abs(np.diff(heights, axis=0)) >= half)
        if not jump.any():
            continue
        count += int(np.count_nonzero(jump))
        if first is None:
            k, j = (int(v[0]) for v in np.nonzero(jump))
            first = (int(traj.ids[j]), float(heights[k, j]), float(heights[k + 1, j]),
                     float(traj.times[start + k]), float(traj.times[start + k + 1]))
    if not count:
        return []
    pid, y0, y1, t0, t1 = first
    return [f"{count} move(s) of half the riser's height or more between consecutive frames "
            f"(particle {pid}: {y0:.3g} -> {y1:.3g} m between {t0:g} and {t1:g} s): particles "
            "taken from the outlet back to the inlet with their ids? this open riser reads "
            "each as a move inside it, not as an exit and an entry; import with --boundary "
            "periodic if the riser recycles its particles, or give them new ids on re-entry"]


__all__ = ["flat_heights", "median_speed", "median_stored_speed", "presence_warnings", "return_warnings",
           "unit_warnings"]
