"""LAMMPS / LIGGGHTS text dump import, SI units (the dump format: :mod:`cfbmarkov.io.lammps_dump`).

The riser (:mod:`cfbmarkov.io.riser`): a 2D dump (no z, or all atoms at one z) has x across
and y vertical; a 3D dump (atoms spread over x, y and z) is refused unless its vertical axis
is given (``vertical_axis``), never guessed; it is then stored in 3D (across = the first
other axis, depth = the last), or projected on (across, vertical) with ``drop_depth``. The
riser's region in the dump's own coordinates is ``region`` (one range per axis), else
0..``width`` across and 0..``height`` vertically where those are given, else the box;
positions are measured from the region's lower corner, so a box wider than the riser
shifts nothing. A particle outside the region is absent from that frame. Without a region
the box must stay the same in every frame; with one, it may change (shrink-wrapped ``m``).

The vertical boundary is ``boundary``, by default the box flag of the vertical axis
(``p``: periodic; ``f``, ``s``, ``m``: open). On a periodic boundary, laps are exact where
the dump allows: floor(yu / H) from unwrapped coordinates, the image flag from wrapped ones;
otherwise they follow the minimal-image rule, and a particle that moves more than a quarter
of the height between frames is refused (coarse output of a fast particle), naming the
particle, the step and the fix. On an open boundary there are no laps: particles enter and
leave. Atoms inserted (new ids) or deleted between frames are present only in the frames
that hold them.

The time of a frame is ``ITEM: TIME`` when present, else timestep x ``time_step`` (s).
Frames are parsed and written one at a time, so memory stays at a few frames whatever the
length of the dump.
"""

from __future__ import annotations

import itertools
import os
from pathlib import Path

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.io._common import (
    check_output,
    create_writer,
    progress,
    reading,
    removing_new_folders,
    whole_ids,
)
from cfbmarkov.io.lammps_dump import AXES, AtomColumns, DumpFrame, _frames_of, dump_files
from cfbmarkov.io.riser import (FrameColumns, RiserFrame, box_text, region_notes, riser_frame,
                                riser_positions)
from cfbmarkov.trajectory_writer import IMPORT_MAX_STEP

#: relative change of the box bounds between frames that is taken as round-off
BOX_TOLERANCE = 1e-9


def import_lammps(source: str | os.PathLike, output: str | os.PathLike, *,
                  width: float | None = None, height: float | None = None,
                  time_step: float | None = None, vertical_axis: str | None = None,
                  region: tuple[tuple[float, float], ...] | None = None,
                  boundary: str | None = None, drop_depth: bool = False) -> Path:
    """Import a LAMMPS/LIGGGHTS text dump (optionally gzipped, SI units) as a trajectory file.

    Parameters
    ----------
    source : str, os.PathLike or sequence of them
        The dump (``dump custom`` or ``dump atom``), several files, or a glob pattern
        (:func:`~cfbmarkov.io.lammps_dump.dump_files`).
    output : str or os.PathLike
        The trajectory file (HDF5) to write; it appears only when complete.
    width, height : float, optional
        The riser is 0..width across and 0..height vertically in the dump's own
        coordinates (m); by default it is the dump's box.
    time_step : float, optional
        Simulation time step, s: the time of frames without ``ITEM: TIME`` is
        timestep x time_step.
    vertical_axis : {"x", "y", "z"}, optional
        The dump's vertical axis (gravity along minus it); required for a 3D dump.
        Default y for a 2D dump.
    region : sequence of (lo, hi), optional
        The riser in the dump's coordinates (m), one range per source axis x, y (, z); it
        overrides ``width``/``height`` and the box, and the box may then change between
        frames (shrink-wrapped boundaries).
    boundary : {"periodic", "open"}, optional
        The vertical boundary; default from the box flag of the vertical axis.
    drop_depth : bool, optional
        Store a 3D dump's positions projected on (across, vertical).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        On bad input (no frames, no time, a changing or triclinic box without a region, a
        3D dump without ``vertical_axis``, a region that holds no particle, laps that cannot
        be inferred, units other than SI, ...); no file is left behind.
    """
    paths = dump_files(source)
    output = Path(output)
    for path in paths:
        check_output(output, path)
    label = str(paths[0]) if len(paths) == 1 else f"{paths[0].parent}/ ({len(paths)} files)"
    with removing_new_folders(output), reading(label):
        units: list = []
        skipped = [0]
        frames = _frames_of(paths, units, skipped)
        first_label, first = next(frames, (label, None))
        if first is None:
            raise InputError(f"{label}: no frames with atoms (no 'ITEM: ATOMS' block)")
        where = first.where(first_label)
        layout = AtomColumns.find(first.columns, where)
        n_axes = min(len(layout.position), first.box.shape[0])
        spread, frames = _depth_spread(first, frames, layout, n_axes)
        riser = riser_frame(n_axes=n_axes, spread=spread, vertical_axis=vertical_axis,
                            flags=first.boundary, box=first.box[:n_axes], region=region,
                            width=width, height=height, boundary=boundary,
                            drop_depth=drop_depth, where=where, default_boundary="periodic")
        frame_time(first, time_step, first_label)  # refuse a dump without time before writing
        parameters = _provenance(paths[0], first, layout, units[0] if units else None,
                                 time_step, riser)
        if len(paths) > 1:
            parameters["source_files"] = [p.name for p in paths]
        parameters["frames_without_atoms_skipped"] = skipped[0]
        velocity = layout.velocity_columns(riser.axes)
        first_ids = np.unique(_frame_ids(first, layout, where))
        with create_writer(output, first_ids, max_step=IMPORT_MAX_STEP,
                           laps_advice="unwrapped coordinates (xu yu) or image flags (ix iy)",
                           source="import:lammps", parameters=parameters,
                           with_velocity=velocity is not None, label=label,
                           **riser.writer_options()) as writer:
            columns = FrameColumns(writer)
            flat_z = (float(positions_m(first, layout)[0, 2])
                      if n_axes == 3 and len(riser.axes) == 2 and riser.dropped is None else None)
            for frame_label, frame in progress(itertools.chain([(first_label, first)], frames),
                                               label):
                _append_frame(writer, columns, frame, first, layout, time_step, frame_label,
                              riser, flat_z)
            if not writer.any_present:
                raise InputError(f"{label}: the riser region {riser.region_text()} holds no "
                                 "particle in any frame; check --region (or --width/--height) "
                                 f"against the first frame's box, {box_text(first.box[:n_axes])}")
            notes = region_notes(riser, first.box[:n_axes], columns.rows, columns.outside,
                                 tuple(first.boundary))
            if first.time is not None and time_step is not None:
                notes.append(f"--time-step {time_step:g} s not used: the dump's ITEM: TIME "
                             "dates its frames (it also holds across a change of the time "
                             "step)")
            if notes:
                writer.update_parameters({"import_notes": notes})
    return output


def _depth_spread(first: DumpFrame, frames, layout: AtomColumns, n_axes: int):
    """Whether positions vary along z (a 3D dump), and ``frames`` as they were. One atom
    cannot show it (a pour that inserts one atom at a time starts so): the frames after
    the first are read ahead, and put back, until one holds two atoms or z varies."""
    if n_axes < 3:
        return False, frames
    column = layout.position[2]
    z0 = first.atoms[0, column]
    spread = bool(np.any(first.atoms[:, column] != z0))
    ahead: list = []
    count = first.atoms.shape[0]
    while not spread and count < 2:
        following = next(frames, None)
        if following is None:
            break
        ahead.append(following)
        z = following[1].atoms[:, column]
        spread, count = bool(np.any(z != z0)), z.size
    return spread, itertools.chain(ahead, frames)


def _provenance(path: Path, first: DumpFrame, layout: AtomColumns, units: str | None,
                time_step: float | None, riser: RiserFrame) -> dict:
    periodic = not riser.boundary.is_open
    has_image = layout.image is not None and layout.image[riser.vertical] is not None
    laps_from = ("unwrapped coordinates" if layout.unwrapped and periodic
                 else "image flags" if has_image and periodic
                 else "minimal-image rule" if periodic else "none (open riser)")
    velocity = layout.velocity_columns(riser.axes)
    return {
        "source_file": path.name, "format": "lammps", "box": first.box.tolist(),
        "boundary": list(first.boundary), "origin_shift": riser.region[:, 0].tolist(),
        **riser.provenance(),
        "columns": list(first.columns),
        "position_columns": [layout.position_names[k] for k in riser.axes],
        "velocity_columns": [first.columns[c] for c in velocity] if velocity else [],
        "laps_from": laps_from,
        "units": units, "time_step": time_step, "first_timestep": first.timestep,
        "time_from": "ITEM: TIME" if first.time is not None else "timestep x time_step",
    }


def frame_time(frame: DumpFrame, time_step: float | None, label: str) -> float:
    """Time of a frame: ITEM: TIME, else timestep x ``time_step``.

    Parameters
    ----------
    frame : DumpFrame
        The frame.
    time_step : float or None
        Simulation time step, s.
    label : str
        Name of the dump in error messages.

    Returns
    -------
    float
        The time, s.

    Raises
    ------
    InputError
        When the frame has no ITEM: TIME and no ``time_step`` is given.
    """
    if frame.time is not None:
        return frame.time
    if time_step is None:
        raise InputError(f"{frame.where(label)}: the dump has no ITEM: TIME; give the "
                         "simulation time step with --time-step (s)")
    return frame.timestep * time_step


def _append_frame(writer, columns: FrameColumns, frame: DumpFrame, first: DumpFrame,
                  layout: AtomColumns, time_step: float | None, label: str,
                  riser: RiserFrame, flat_z: float | None = None) -> None:
    """Map one frame onto the riser and append it (new ids become new particles). A dump
    taken as 2D because its first frames held every atom at one z (``flat_z``) is refused
    where atoms leave that z: it is 3D (an inlet face at one height inserts so)."""
    where = frame.where(label)
    if riser.from_box:
        _check_same_box(frame, first, where)
    if frame.columns != first.columns:
        layout = _same_layout(frame, layout, where)
    time = frame_time(frame, time_step, label)
    atoms = frame.atoms
    ids = _frame_ids(frame, layout, where)
    raw = positions_m(frame, layout)
    bad = ~np.isfinite(raw).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(f"{where}: position of particle {int(ids[k])} at t = {time:g} s is not "
                         "a finite number (the simulation had diverged by this frame: keep only "
                         "the frames written before it)")
    if flat_z is not None and np.any(raw[:, 2] != flat_z):
        k = int(np.argmax(raw[:, 2] != flat_z))
        raise InputError(
            f"{where}: particle {int(ids[k])} at z = {raw[k, 2]:g} m, while every atom of the "
            f"first frame lay at z = {flat_z:g} m: a 3D dump; say which axis is vertical with "
            "--vertical-axis x|y|z (or --drop-depth with it for a projection)")
    image = None
    if layout.image is not None and layout.image[riser.vertical] is not None:
        image = atoms[:, layout.image[riser.vertical]]
    positions, inside, laps = riser_positions(raw, riser, image=image, unwrapped=layout.unwrapped)
    vcols = layout.velocity_columns(riser.axes)
    velocity = atoms[:, list(vcols)] if writer.with_velocity and vcols else None
    full, vel, lap, present = columns.frame(ids, positions, inside, velocity, laps,
                                            f"{where}, t = {time:g} s")
    writer.append(time, full, vel, lap, present)


def positions_m(frame: DumpFrame, layout: AtomColumns) -> np.ndarray:
    """Positions of a frame's atoms in the dump's coordinates, m.

    Parameters
    ----------
    frame : DumpFrame
        The frame.
    layout : AtomColumns
        Its column layout.

    Returns
    -------
    numpy.ndarray
        [N, D] positions; scaled columns (``xs``, ``xsu``) are mapped through the box,
        x = lo + s (hi - lo) (LAMMPS ``dump`` doc), so a 2D dump's ``zs = 0.5`` is z = 0
        in the default -0.5..0.5 z box.
    """
    raw = frame.atoms[:, list(layout.position)]
    if layout.scaled:
        lo = frame.box[:raw.shape[1], 0]
        raw = lo + raw * (frame.box[:raw.shape[1], 1] - lo)
    return raw


def _check_same_box(frame: DumpFrame, first: DumpFrame, where: str) -> None:
    scale = float(np.abs(first.box).max()) or 1.0
    if frame.box.shape != first.box.shape or np.abs(frame.box - first.box).max() > BOX_TOLERANCE * scale:
        changed = [k for k in range(min(len(frame.box), len(first.box)))
                   if np.abs(frame.box[k] - first.box[k]).max() > BOX_TOLERANCE * scale]
        axis = "xyz"[changed[0]] if changed else "x"
        k = changed[0] if changed else 0
        raise InputError(f"{where}: the box changes along {axis} ({first.box[k][0]:.4g}.."
                         f"{first.box[k][1]:.4g} m in the first frame, {frame.box[k][0]:.4g}.."
                         f"{frame.box[k][1]:.4g} m here); a deforming or shrink-wrapped box "
                         "can be imported with the riser's region given (--region "
                         "XMIN:XMAX,YMIN:YMAX[,ZMIN:ZMAX])")


def _same_layout(frame: DumpFrame, layout: AtomColumns, where: str) -> AtomColumns:
    """The column layout of a frame whose ATOMS line differs from the first frame's."""
    new = AtomColumns.find(frame.columns, where)
    if new.position_names != layout.position_names or (new.velocity is None) != (
            layout.velocity is None) or (new.image is None) != (layout.image is None):
        raise InputError(f"{where}: ITEM: ATOMS columns change ({' '.join(frame.columns)}); "
                         "every frame must carry the same position and velocity columns")
    return new


__all__ = ["AXES", "BOX_TOLERANCE", "dump_files", "frame_time", "import_lammps"]


def _frame_ids(frame, layout, where: str) -> np.ndarray:
    """The frame's particle ids, exact (the reader parses ids of 2^53 and more from text)."""
    if frame.ids is not None and layout.id == frame.columns.index("id"):
        return frame.ids
    return whole_ids(frame.atoms[:, layout.id], where)
