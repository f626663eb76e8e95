"""The import path shared by the particle-file readers (VTK, VTK XML, H5MD): a series of
frames of particle positions -> a trajectory file, through the riser mapping of
:mod:`cfbmarkov.io.riser` exactly as LAMMPS dumps go (:mod:`cfbmarkov.io.lammps`).

A source whose positions vary along x, y and z is 3D and needs its vertical axis
(``vertical_axis``); one whose particles all lie at one z is 2D (x across, y vertical), and
is refused at the first frame where a particle leaves that z. The region is ``region``, else
0..``width`` x 0..``height``, else the box the files carry; a source without a box needs one
of them. The vertical boundary is ``boundary``, else the box's periodicity flags, else
periodic (the files say nothing: stated in the summary). Laps come from image flags where
the source has them, else from the minimal-image rule.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.io._common import create_writer, progress, removing_new_folders
from cfbmarkov.io.riser import (AXES, FrameColumns, box_text, region_notes, riser_frame,
                                riser_positions)
from cfbmarkov.trajectory_format import POSITION_TOLERANCE
from cfbmarkov.trajectory_writer import IMPORT_MAX_STEP

#: relative change of the box between frames taken as round-off
BOX_TOLERANCE = 1e-9


@dataclass
class ParticleFrame:
    """One frame of a particle file.

    Attributes
    ----------
    time : float
        Time, s.
    ids : numpy.ndarray of int64, shape (N,)
        Particle ids.
    positions : numpy.ndarray of float64, shape (N, 3)
        Positions x, y, z (m).
    velocities : numpy.ndarray of float64, shape (N, 3), or None
        Velocities (m/s).
    image : numpy.ndarray of int64, shape (N, 3), or None
        Periodic image flags per axis.
    box : numpy.ndarray of float64, shape (3, 2), or None
        The simulation box [lo, hi] per axis (m), where the files give it.
    where : str
        Names the frame in error messages.
    """

    time: float
    ids: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None
    image: np.ndarray | None = None
    box: np.ndarray | None = None
    where: str = ""


#: where each format can give the laps itself (named where the minimal-image rule refuses)
LAPS_ADVICE = {"h5md": "image flags (the image element of the H5MD particles group)",
               "vtk": "image flags (point arrays ix iy iz)",
               "vtp": "image flags (point arrays ix iy iz)",
               "vtu": "image flags (point arrays ix iy iz)"}


@dataclass
class ParticleSeries:
    """The frames of a particle source and what the reader found out about it.

    Attributes
    ----------
    label : str
        Names the source in messages.
    fmt : str
        The format (``vtk``, ``vtp``, ``h5md``).
    frames : iterator of ParticleFrame
        The frames in time order (read lazily).
    flags : tuple of str
        Periodicity per axis (``'periodic'``/``'p'`` for periodic), empty where unknown.
    source_file : str
        The file name recorded.
    provenance : dict
        What the reader recorded (JSON-ready): ``ids_from``, ``time_from``,
        ``velocity_from``, ``box_from``, file names, ...
    box_origin_unknown : bool
        The box is known by its edges only (H5MD): positions outside 0..edge on the box's
        own region are refused rather than wrapped.
    late_provenance : callable
        Returns what the reader learnt from the first frame (e.g. ``ids_from``).
    close : callable
        Releases the source (an open HDF5 file).
    flags_from : str
        Where ``flags`` came from, for the summary (default the box's flags).
    """

    label: str
    fmt: str
    frames: Iterator[ParticleFrame]
    flags: tuple = ()
    source_file: str = ""
    provenance: dict = field(default_factory=dict)
    box_origin_unknown: bool = False
    late_provenance: Callable[[], dict] = dict
    close: Callable[[], None] = lambda: None
    flags_from: str = "the box's flags"


def import_particle_series(series: ParticleSeries, output: str | os.PathLike, *,
                           width: float | None = None, height: float | None = None,
                           vertical_axis: str | None = None,
                           region: tuple[tuple[float, float], ...] | None = None,
                           boundary: str | None = None, drop_depth: bool = False,
                           detected: str | None = None) -> Path:
    """Write the frames of ``series`` as the trajectory file ``output``.

    Parameters
    ----------
    series : ParticleSeries
        The source's frames.
    output : str or os.PathLike
        The trajectory file (HDF5); it appears only when complete.
    width, height : float, optional
        The riser is 0..width across and 0..height vertically in the source's coordinates
        (m); default the box the files carry.
    vertical_axis : {"x", "y", "z"}, optional
        Required for a 3D source; default y for a 2D one.
    region : sequence of (lo, hi), optional
        The riser in the source's coordinates (m), one range per axis x, y (, z).
    boundary : {"periodic", "open"}, optional
        The vertical boundary; default from the box's flags, else periodic.
    drop_depth : bool, optional
        Store a 3D source projected on (across, vertical).
    detected : str, optional
        How the format was detected from the content (recorded).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        On bad input (no frames, a 3D source without its vertical axis, no box and no
        region, a changing box without a region, a region holding no particle, ...); no file
        is left behind.
    """
    output = Path(output)
    label = series.label
    with removing_new_folders(output):
        frames = iter(series.frames)
        first = next(frames, None)
        if first is None:
            raise InputError(f"{label}: no frames with particles")
        spread, frames = _depth_spread(first, frames)
        box = None if first.box is None else first.box[:3]
        if box is None and region is None and (width is None or height is None):
            raise InputError(f"{label}: the files carry no box; give the riser with --width and "
                             "--height (from 0 in the files' coordinates) or --region")
        riser = riser_frame(n_axes=3, spread=spread, vertical_axis=vertical_axis,
                            flags=tuple(series.flags), box=box, region=region, width=width,
                            height=height, boundary=boundary, drop_depth=drop_depth,
                            where=first.where, default_boundary="periodic")
        velocity = first.velocities is not None
        image = first.image is not None and not riser.boundary.is_open
        late = dict(series.late_provenance())
        image_from = late.pop("image_from", None)
        if (first.image is not None and image_from and "passes along y" in image_from
                and riser.vertical != 1):
            raise InputError(f"{first.where}: the laps are {image_from}, but the vertical axis "
                             f"is {'xyz'[riser.vertical]}; give --vertical-axis y, the export's "
                             "vertical (or leave it out where the export is 2D)")
        parameters = {
            "source_file": series.source_file, "format": series.fmt,
            "format_detected_from": detected, "box": None if box is None else box.tolist(),
            "boundary": list(series.flags),
            "boundary_from": ("--boundary" if boundary is not None else
                              series.flags_from if series.flags else
                              "default (the files carry no periodicity)"),
            "origin_shift": riser.region[:, 0].tolist(), **riser.provenance(),
            "laps_from": ((image_from or "image flags") if image else "minimal-image rule"
                          if not riser.boundary.is_open else "none (open riser)"),
            **series.provenance, **late,
        }
        first_ids = np.unique(first.ids)
        flat_z = (float(first.positions[0, 2]) if not spread and first.positions.shape[0]
                  else None)
        with create_writer(output, first_ids, max_step=IMPORT_MAX_STEP,
                           laps_advice=LAPS_ADVICE.get(series.fmt),
                           source=f"import:{series.fmt}", parameters=parameters,
                           with_velocity=velocity, label=label,
                           **riser.writer_options()) as writer:
            columns = FrameColumns(writer)
            v = riser.vertical
            period_from_box = bool(riser.periodic[1] and box is not None and v < len(box)
                                   and np.all(np.isfinite(box[v])) and box[v][1] > box[v][0])
            for frame in progress(itertools.chain([first], frames), label):
                _append(writer, columns, frame, first, riser, flat_z, image,
                        series.box_origin_unknown and riser.from_box, period_from_box)
            if not writer.any_present:
                raise InputError(f"{label}: the riser region {riser.region_text()} holds no "
                                 "particle in any frame; check --region (or --width/--height)"
                                 + ("" if box is None or series.box_origin_unknown
                                    else f" against the box, {box_text(box)}"))
            # a box whose origin the format does not give (H5MD: its edges only) says
            # nothing of where the particles may lie: no note on a region beyond it
            notes = region_notes(riser, None if series.box_origin_unknown else box,
                                 columns.rows, columns.outside, tuple(series.flags))
            if notes:
                writer.update_parameters({"import_notes": notes})
    return output


def _depth_spread(first: ParticleFrame, frames):
    """Whether positions vary along z, reading frames ahead (and putting them back) while
    fewer than two particles have been seen."""
    z0 = first.positions[0, 2] if first.positions.shape[0] else None
    spread = z0 is not None and bool(np.any(first.positions[:, 2] != z0))
    ahead, count = [], first.positions.shape[0]
    while not spread and count < 2:
        following = next(frames, None)
        if following is None:
            break
        ahead.append(following)
        z = following.positions[:, 2]
        if z0 is None and z.size:
            z0 = z[0]
        spread, count = bool(np.any(z != z0)), count + z.size
    return spread, itertools.chain(ahead, frames)


def _append(writer, columns: FrameColumns, frame: ParticleFrame, first: ParticleFrame, riser,
            flat_z: float | None, use_image: bool, check_origin: bool,
            period_from_box: bool) -> None:
    where = frame.where
    if riser.from_box and frame.box is not None and first.box is not None:
        scale = float(np.abs(first.box).max()) or 1.0
        if np.abs(frame.box - first.box).max() > BOX_TOLERANCE * scale:
            k = int(np.argmax(np.abs(frame.box - first.box).max(axis=1)))
            raise InputError(f"{where}: the box changes along {'xyz'[k]} ({first.box[k][0]:.4g}"
                             f"..{first.box[k][1]:.4g} m in the first frame, "
                             f"{frame.box[k][0]:.4g}..{frame.box[k][1]:.4g} m here); give the "
                             "riser's region with --region XMIN:XMAX,YMIN:YMAX[,ZMIN:ZMAX]")
    raw = frame.positions
    bad = ~np.isfinite(raw).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(f"{where}: position {raw[k].tolist()} of particle "
                         f"{int(frame.ids[k])} at t = {frame.time:g} s is not a finite number; "
                         "the writer left a particle without a position: repair this file, or "
                         "import the files before it")
    if flat_z is not None and np.any(raw[:, 2] != flat_z):
        k = int(np.argmax(raw[:, 2] != flat_z))
        raise InputError(
            f"{where}: particle {int(frame.ids[k])} at z = {raw[k, 2]:g} m, while every "
            f"particle of the first frame lay at z = {flat_z:g} m: 3D positions; say which axis "
            "is vertical with --vertical-axis x|y|z (or --drop-depth with it for a projection)")
    if check_origin:
        _check_inside_box(raw, frame, riser)
    _check_periodic_height(raw, frame, riser, period_from_box)
    image = frame.image[:, riser.vertical] if use_image and frame.image is not None else None
    positions, inside, laps = riser_positions(raw, riser, image=image)
    vel = None
    if writer.with_velocity:
        if frame.velocities is None:
            raise InputError(f"{where}: no velocity array, while the first frame has one")
        vel = frame.velocities[:, list(riser.axes)]
    full, v, lap, present = columns.frame(frame.ids, positions, inside, vel, laps,
                                          f"{where}, t = {frame.time:g} s")
    writer.append(frame.time, full, v, lap, present)


def _check_periodic_height(raw: np.ndarray, frame: ParticleFrame, riser,
                           period_from_box: bool) -> None:
    """A periodic riser whose period is the given region's, not a periodic box's (a file
    with no box, or ``export-vtk``'s, which says periodic and gives no box): every height
    must lie in the region. Particles above or below it would be wrapped into it by a period
    that is the user's guess (a --height shorter than the riser), moved silently."""
    if riser.boundary.is_open or riser.from_box or period_from_box:
        return                  # a periodic box's wrap (the region must equal its period)
    lo, hi = riser.region[1]
    y = raw[:, riser.vertical]
    tol = POSITION_TOLERANCE + 1e-9 * max(abs(lo), abs(hi))
    outside = (y < lo - tol) | (y > hi + tol)
    if outside.any():
        k = int(np.argmax(outside))
        axis = AXES[riser.vertical]
        raise InputError(
            f"{frame.where}: particle {int(frame.ids[k])} at t = {frame.time:g} s lies at "
            f"{axis} = {y[k]:g} m, outside the riser's vertical range {lo:g}..{hi:g} m: a "
            "periodic riser holds every particle, so its vertical range must cover every "
            "height (the files carry no periodic box to wrap by); give a taller --height or "
            f"--region's {axis} range, or --boundary open if particles leave through the top "
            "and bottom")


def _check_inside_box(raw: np.ndarray, frame: ParticleFrame, riser) -> None:
    """A box known by its edges only: positions must lie in 0..edge (else the origin is not
    0 and wrapping would move them)."""
    lo, hi = riser.region[:, 0], riser.region[:, 1]
    pos = raw[:, list(riser.axes)]
    tol = POSITION_TOLERANCE + 1e-9 * float(np.abs(hi).max())
    outside = np.any((pos < lo - tol) | (pos > hi + tol), axis=1)
    if outside.any():
        k = int(np.argmax(outside))
        axes = ", ".join(f"{AXES[a]} {v:g}" for a, v in zip(riser.axes, pos[k]))
        raise InputError(f"{frame.where}: particle {int(frame.ids[k])} at {axes} m lies outside "
                         f"the box 0..edges {hi.tolist()} m: the file gives the box's edges, not "
                         "its origin; give the riser's region with --region")
