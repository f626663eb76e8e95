"""Importers: CSV files, LAMMPS/LIGGGHTS text dumps, VTK particle files (legacy ``.vtk``,
XML ``.vtp``, ``.vtu`` and ``.pvd``) and H5MD files -> trajectory files (HDF5).

Each reads their input a frame at a time and write through
:class:`~cfbmarkov.trajectory_writer.TrajectoryWriter`, which validates every frame and derives the
lap counter; bad input raises :class:`~cfbmarkov.errors.InputError` and leaves no output file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from cfbmarkov._console import plural
from cfbmarkov.errors import InputError
from cfbmarkov.io.csv import import_csv
from cfbmarkov.io.lammps import import_lammps

FORMATS = ("csv", "lammps", "vtk", "vtp", "vtu", "pvd", "h5md")
#: the formats read by :mod:`cfbmarkov.io.particle_frames` (no CSV options apply)
PARTICLE_FORMATS = ("vtk", "vtp", "vtu", "pvd", "h5md")


def resolve_format(source, fmt: str | None) -> tuple[str, str | None]:
    """The format to read ``source`` with, and what showed it when it was detected.

    Parameters
    ----------
    source : str, os.PathLike or list
        The source.
    fmt : str or None
        A format of :data:`FORMATS`, or None / ``'auto'`` to detect it from the content.

    Returns
    -------
    (str, str or None)
        The format, and the description of what the content showed (None when given).

    Raises
    ------
    InputError
        For an unknown format, a particle file (VTK, H5MD) given as CSV or LAMMPS, or a
        source whose format cannot be told (see :func:`cfbmarkov.io.detect.detect_format`).
    """
    from cfbmarkov.io.detect import check_given_format, detect_format

    if fmt is None or str(fmt).lower() == "auto":
        return detect_format(source)
    fmt = str(fmt).lower()
    if fmt not in FORMATS:
        raise InputError(f"unknown import format {fmt!r}; choose one of {', '.join(FORMATS)} "
                         "or auto")
    check_given_format(source, fmt)
    return fmt, None


def import_file(source: str | os.PathLike, fmt: str, output: str | os.PathLike, *,
                width: float | None = None, height: float | None = None,
                time_step: float | None = None, vertical_axis: str | None = None,
                region: tuple[tuple[float, float], ...] | None = None,
                length_unit: str | None = None, time_unit: str | None = None,
                boundary: str | None = None, drop_depth: bool = False,
                resample: float | None = None, max_gap: float | None = None) -> Path:
    """Import ``source`` in format ``fmt`` (or the format its content shows) as the
    trajectory file ``output``.

    Parameters
    ----------
    source : str or os.PathLike
        The file to import (optionally gzip-compressed).
    fmt : {'csv', 'lammps', 'vtk', 'vtp', 'vtu', 'pvd', 'h5md', 'auto'} or None
        Its format (case-insensitive); None or 'auto': detected from the content
        (:func:`resolve_format`), and recorded in the file's parameters.
    output : str or os.PathLike
        The trajectory file (HDF5) to write.
    width, height : float, optional
        The domain, m (LAMMPS default: the dump's box; a CSV file needs both, or ``region``,
        and is refused without them, the message naming the data's extent).
    time_step : float, optional
        Simulation time step, s, that dates LAMMPS frames carrying no ``ITEM: TIME`` and
        legacy VTK files carrying no ``TIME`` array (by the step in their name); a CSV
        file carries its times in column t and takes no time step.
    vertical_axis : {"x", "y", "z"}, optional
        The source's vertical axis; required for a 3D dump and for a CSV file with a z
        column (default y otherwise).
    region : sequence of (lo, hi), optional
        The riser in the source's coordinates and length unit, one range per axis x, y (, z);
        particles outside it are absent.
    boundary : {"periodic", "open"}, optional
        The vertical boundary (default: the dump's box flag on the vertical axis; periodic
        for CSV).
    drop_depth : bool, optional
        Store 3D positions projected on (across, vertical).
    resample : float, optional
        CSV: interpolate tracks with irregular times onto frames this far apart (s).
    max_gap : float, optional
        With ``resample``: a particle is absent between samples further apart (s); default
        the resample step (``cfbmarkov import`` warns where that leaves tracers absent
        between their samples).
    length_unit : {"m", "cm", "mm"}, optional
        Unit of a CSV file's positions (and, over ``time_unit``, velocities) where its header
        gives none; default m (CSV only).
    time_unit : {"s", "ms"}, optional
        Unit of a CSV file's times where its header gives none; default s (CSV only).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        For an unknown format, a non-positive size, time step, resample step or gap, a
        region given with a width or height, ``drop_depth`` on 2D positions, a time step
        given with a CSV file, a length or time unit or resampling given with a dump,
        a 3D file whose particles all lie at one height in every frame (the vertical axis
        is not the riser's: :func:`~cfbmarkov.io.plausibility.flat_heights`; the file
        written is removed), or bad input (see
        :func:`import_csv` and :func:`import_lammps`).
    """
    path = _import_file(source, fmt, output, width=width, height=height, time_step=time_step,
                        vertical_axis=vertical_axis, region=region, length_unit=length_unit,
                        time_unit=time_unit, boundary=boundary, drop_depth=drop_depth,
                        resample=resample, max_gap=max_gap)
    from cfbmarkov.io.plausibility import flat_heights
    from cfbmarkov.trajectories import Trajectories

    with Trajectories(path) as written:
        refused = flat_heights(written)
    if refused is not None:              # nothing of it is kept
        Path(path).unlink(missing_ok=True)
        raise InputError(f"{source}: {refused}")
    return path


def _import_file(source, fmt, output, *, width, height, time_step, vertical_axis, region,
                 length_unit, time_unit, boundary, drop_depth, resample, max_gap) -> Path:
    """:func:`import_file` before the written file is checked."""
    fmt, detected = resolve_format(source, fmt)
    for name, value in (("--width", width), ("--height", height), ("--time-step", time_step),
                        ("--resample", resample), ("--max-gap", max_gap)):
        if value is not None and not (np.isfinite(float(value)) and float(value) > 0):
            raise InputError(f"{name} {value} must be a positive number")
    if region is not None and (width is not None or height is not None):
        given = " and ".join(name for name, value in (("--width", width), ("--height", height))
                             if value is not None)
        raise InputError(f"--region sets the riser's size and place, so {given} would be "
                         f"ignored; give --region alone, or {given} without it")
    if fmt == "csv":
        if time_step is not None:
            if detected is not None:      # CSV by elimination: an empty or binary file's
                from cfbmarkov.io._common import check_text     # own fault named first

                check_text(source)
            raise InputError("--time-step dates the steps of LAMMPS dumps, H5MD and VTK "
                             "series; a CSV file gives its times in column t (leave out "
                             "--time-step)")
        return import_csv(source, output, width=width, height=height, length_unit=length_unit,
                          time_unit=time_unit, vertical_axis=vertical_axis, region=region,
                          boundary=boundary, drop_depth=drop_depth, resample=resample,
                          max_gap=max_gap)
    if fmt in PARTICLE_FORMATS:
        from cfbmarkov.io.particle_import import import_particles

        return import_particles(source, fmt, output, width=width, height=height,
                                time_step=time_step, vertical_axis=vertical_axis, region=region,
                                boundary=boundary, drop_depth=drop_depth,
                                length_unit=length_unit, time_unit=time_unit,
                                resample=resample, max_gap=max_gap, detected=detected)
    if length_unit is not None or time_unit is not None:
        raise InputError("--length-unit and --time-unit apply to CSV files only; a LAMMPS dump "
                         "must be in SI units (ITEM: UNITS si)")
    if resample is not None or max_gap is not None:
        raise InputError("--resample and --max-gap apply to CSV files (tracks at irregular "
                         "times); a LAMMPS dump is written every so many timesteps")
    return import_lammps(source, output, width=width, height=height, time_step=time_step,
                         vertical_axis=vertical_axis, region=region, boundary=boundary,
                         drop_depth=drop_depth)


_FORMAT_NAMES = {"csv": "CSV", "lammps": "LAMMPS/LIGGGHTS text dump"}


def import_summary(path: str | os.PathLike, detected: str | None = None) -> str:
    """One line on what an import read: the format and how it was told, frames, particles,
    and where positions, ids, times, velocities, the boundary and laps came from.

    Parameters
    ----------
    path : str or os.PathLike
        A trajectory file written by :func:`import_file`.
    detected : str, optional
        What the content showed where the format was detected (the second item of
        :func:`resolve_format`); None where it was given. Files of the particle formats
        record it themselves.

    Returns
    -------
    str
        For example ``read 20 frames of 3 particles as CSV (--format); positions from x, y
        (mm); ids from column 'TRACK_ID'; times in s; no velocities; periodic
        boundary; laps from minimal-image rule``.
    """
    from cfbmarkov.trajectories import Trajectories

    with Trajectories(path) as t:
        p = dict(t.parameters)
        n_frames, n_particles = t.times.size, t.ids.size
    fmt = p.get("format")
    if fmt in PARTICLE_FORMATS:
        from cfbmarkov.io.particle_import import import_summary as particle_summary

        return particle_summary(path)
    told = f"detected from the content: {detected}" if detected else "--format"
    units = p.get("units") if isinstance(p.get("units"), dict) else {}   # CSV: per column
    columns = list(p.get("position_columns") or [])
    positions = ", ".join(columns)
    length = [units.get(a) for a in columns if units.get(a)]
    if len(set(length)) == 1:
        positions += f" ({length[0]})"
    elif length:                       # each column in its own unit
        positions = ", ".join(f"{a} ({units[a]})" if units.get(a) else a for a in columns)
    parts = [f"read {plural(n_frames, 'frame')} of {plural(n_particles, 'particle')} as "
             f"{_FORMAT_NAMES.get(fmt, fmt)} ({told})", f"positions from {positions}"]
    if fmt == "csv":
        column = p.get("id_column")
        parts.append(f"ids from column {column!r}" if column else "one tracer (no id column)")
        parts.append(f"times in {units.get('t', 's')}")
    else:
        parts.append(f"times from {p.get('time_from')}")
    velocities = ", ".join(p.get("velocity_columns") or [])
    parts.append(f"velocities from {velocities}" if velocities else "no velocities")
    if p.get("resample"):
        parts.append(f"resampled every {p['resample']:g} s from {p.get('samples')} samples")
    parts.append(f"{p.get('boundary_stored')} boundary")
    parts.append(f"laps from {p.get('laps_from')}")
    return "; ".join(parts)


__all__ = ["FORMATS", "PARTICLE_FORMATS", "import_csv", "import_file", "import_lammps",
           "import_summary", "resolve_format"]
