"""What a trajectory file holds, in lines for ``cfbmarkov info``: a wrong import must be
visible at a glance (``docs/definitions.md``, Boundary and presence)."""

from __future__ import annotations

import numpy as np

from cfbmarkov.trajectories import Trajectories


def describe(trajectories: Trajectories, block: int = 256) -> list[str]:
    """Lines that show at a glance what a trajectory file holds and how it was made:
    domain, axes and region, boundary, particles present per frame, passes through the
    periodic boundary (from the lap counters between consecutive frames where a particle is
    present), entries and exits (a particle absent in one frame and present in the next, or
    the reverse), where the laps came from and the particle properties a prediction
    stored (``/properties``). Frames are read block by block.

    Parameters
    ----------
    trajectories : Trajectories
        An open file.
    block : int
        Frames read at a time.

    Returns
    -------
    list of str
    """
    t = trajectories
    p = t.parameters
    d = t.dimensions
    size = f"{t.width:g} m across x {t.height:g} m high" + (
        f" x {t.depth:g} m deep (3D)" if d == 3 else " (2D)")
    boundary = ("periodic (what leaves the top re-enters the bottom)" if not t.boundary.is_open
                else "open (inlet at the bottom, outlet at the top; particles enter and leave)")
    lines = [repr(t), f"  domain: {size}; vertical boundary {boundary}"]
    axes = f"vertical {t.axes['vertical']}, across {t.axes['across']}" + (
        f", depth {t.axes['depth']}" if d == 3 else "")
    dropped = p.get("depth_axis_dropped")
    stored = ("across", "vertical", "depth")[:len(t.region_origin)]
    letters = [t.axes.get(name) or name for name in stored]
    # the source's coordinates named by the source's axis letters, in x, y, z order
    origin = ", ".join(f"{a} = {v:g}" for a, v in sorted(zip(letters, t.region_origin)))
    region = ""
    if "region" in p and len(p["region"]) == len(letters):
        region = "; riser region " + ", ".join(
            f"{a} {lo:g}:{hi:g}" for a, (lo, hi) in sorted(zip(letters, p["region"]))) + " m"
    lines.append(f"  axes from the source: {axes}"
                 + (f", depth axis {dropped} dropped (projection)" if dropped else "")
                 + f"; origin at {origin} m in the source's coordinates" + region)
    case = case_line(t)
    if case:
        lines.append(case)
    if "laps_from" in p:
        lines.append(f"  laps from: {p['laps_from']}")
    lines.extend(f"  import: {note}" for note in p.get("import_notes", []))
    counts = []
    up = down = entries = exits = 0
    previous = previous_present = None
    for i in range(0, t.n_frames, block):
        frames = slice(i, min(i + block, t.n_frames))
        laps = t.laps(frames).astype(np.int64)
        present = t.present(frames)
        counts.append(present.sum(axis=1))
        if previous is not None:
            laps = np.concatenate([previous[None], laps])
            present = np.concatenate([previous_present[None], present])
        step = np.where(present[1:] & present[:-1], np.diff(laps, axis=0), 0)
        up += int(step[step > 0].sum())
        down += int(-step[step < 0].sum())
        entries += int((present[1:] & ~present[:-1]).sum())
        exits += int((~present[1:] & present[:-1]).sum())
        previous, previous_present = laps[-1], present[-1]
    counts = np.concatenate(counts)
    every = " (every particle in every frame)" if not t.has_absences else ""
    lines.append(f"  particles present per frame: min {int(counts.min())}, max {int(counts.max())}"
                 f" of {t.n_particles}{every}")
    if not t.boundary.is_open and t.has_events:
        # the exact events hold the passes a particle undoes within one frame interval,
        # which the lap counters' frame-to-frame changes net out
        events = t.events()
        times = np.asarray(events.time)
        inside = (times > t.times[0]) & (times <= t.times[-1])
        direction = np.asarray(events.direction)[inside]
        lines.append(f"  passes through the periodic boundary: {int((direction > 0).sum())} "
                     f"up, {int((direction < 0).sum())} down (the exact pass events; "
                     f"{up} up, {down} down from the lap counters frame to frame, which net "
                     "out a pass undone within one frame interval)")
    elif not t.boundary.is_open:
        lines.append(f"  passes through the periodic boundary: {up} up, {down} down"
                     + (" (not counted across a particle's absence)" if t.has_absences else ""))
    lines.append(f"  tracks begun {entries}, ended {exits} (after the first frame, anywhere"
                 + ("; fit counts those within one cell of the inlet and the outlet as "
                    "entries and exits)" if t.boundary.is_open else ")"))
    if t.has_fields:
        lines.append(fields_line(t))
    for name in t.property_names:
        attrs = t.property_attrs(name)
        how = ", ".join(f"{key} {attrs[key]}" for key in ("law", "start") if key in attrs)
        lines.append(f"  particle property {name}" + (f" ({how})" if how else "")
                     + " per frame (cfbmarkov react --init; compare --kinetics reads it)")
    return lines


def case_line(trajectories: Trajectories) -> str | None:
    """The case a CFD-DEM run was simulated from, in one line for ``cfbmarkov info``: its
    name and seed, the superficial gas velocity, the particles, the steps and the end time
    it runs to (the file's own span is in the line above), or None for another source.

    Parameters
    ----------
    trajectories : Trajectories
        An open file.

    Returns
    -------
    str or None
    """
    p = trajectories.parameters
    if trajectories.source != "cfd-dem" or not isinstance(p.get("particles"), dict):
        return None
    parts = []
    gas, particles = p.get("gas", {}), p["particles"]
    numerics, output = p.get("numerics", {}), p.get("output", {})
    if "superficial_velocity" in gas:
        parts.append(f"superficial gas velocity {gas['superficial_velocity']:g} m/s")
    if {"number", "diameter", "density"} <= particles.keys():
        parts.append(f"{particles['number']} particles of {1e3 * particles['diameter']:g} mm, "
                     f"{particles['density']:g} kg/m3")
    steps = [f"{label} {numerics[key]:g} s" for label, key in (("DEM step", "dem_time_step"),
                                                               ("CFD step", "cfd_time_step"))
             if isinstance(numerics.get(key), (int, float))]
    if steps:
        parts.append(", ".join(steps))
    if isinstance(output.get("end_time"), (int, float)):
        end = float(output["end_time"])
        last = float(trajectories.times[-1]) if trajectories.n_frames else end
        parts.append(f"end time {end:g} s" + (f" (this file ends at {last:g} s)"
                                                if last < end - 1e-9 else ""))
    name = p.get("name")
    head = "  case" + (f" {name}" if name else "") + (
        f" (seed {p['seed']})" if "seed" in p else "")
    return head + (": " + "; ".join(parts) if parts else "")


def fields_line(t) -> str:
    """The gas fields a CFD-DEM file stores, and what its ``pressure`` is: the periodic
    part, with the weight per unit volume that the driving gradient G carries, (1 - eps)
    (rho_p - rho_g) g + rho_g g from the fields' mean void fraction (an estimate of G, which
    the file does not store)."""
    names = ", ".join(t.field_names)
    shape = t.field(t.field_names[0], 0).shape
    line = (f"  gas fields: {names} on {shape[1]} x {shape[0]} cells at "
            f"{len(t.field_times)} times")
    if "pressure" not in t.field_names:
        return line
    p = t.parameters
    weight = ""
    try:
        eps = float(np.mean(t.field("void_fraction", slice(None))))
        rho_p, rho_g = float(p["particles"]["density"]), float(p["gas"]["density"])
        g = float(p["riser"]["gravity"])
        weight = (f", about {(1.0 - eps) * (rho_p - rho_g) * g + rho_g * g:.4g} Pa/m here "
                  f"(the weight per volume at the mean void fraction {eps:.4g})")
    except (KeyError, TypeError, ValueError):
        pass
    return (line + "; pressure is its periodic part (zero mean): the full pressure adds "
            f"-G y, with G the driving gradient that carries the riser's weight{weight}")
