"""``cfbmarkov import --format vtk|vtp|vtu|pvd|h5md``: particle files -> a trajectory file, and
the summary line the command prints about what was read."""

from __future__ import annotations

import os
from pathlib import Path

from cfbmarkov._console import plural
from cfbmarkov.errors import InputError
from cfbmarkov.io._common import check_output
from cfbmarkov.io.detect import first_file
from cfbmarkov.io.particle_frames import import_particle_series

#: the names of the formats in messages
NAMES = {"vtk": "legacy VTK", "vtp": "VTK XML PolyData", "vtu": "VTK XML UnstructuredGrid",
         "pvd": "ParaView collection (.pvd)",
         "h5md": "H5MD"}


def import_particles(source, fmt: str, output: str | os.PathLike, *,
                     width: float | None = None, height: float | None = None,
                     time_step: float | None = None, vertical_axis: str | None = None,
                     region=None, boundary: str | None = None, drop_depth: bool = False,
                     length_unit: str | None = None, time_unit: str | None = None,
                     resample: float | None = None, max_gap: float | None = None,
                     detected: str | None = None) -> Path:
    """Import VTK (``vtk``), VTK XML (``vtp``, ``vtu``, ``pvd``) or H5MD (``h5md``) particle
    files.

    Parameters
    ----------
    source : str, os.PathLike or list
        A file, a folder, a glob pattern or a list of files (:mod:`cfbmarkov.io.vtk_read`);
        an H5MD source is one file.
    fmt : {'vtk', 'vtp', 'vtu', 'pvd', 'h5md'}
        The format.
    output : str or os.PathLike
        The trajectory file to write.
    width, height, vertical_axis, region, boundary, drop_depth
        As for :func:`cfbmarkov.io.import_file`.
    time_step : float, optional
        VTK files without times (legacy, or XML without a ``.pvd``): the simulation time
        step (s) dating files by the step in their name.
    length_unit, time_unit, resample, max_gap
        Refused: these files are in SI units at simulation steps.
    detected : str, optional
        What showed the format, when it was detected (recorded).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        For an option that does not apply, or bad input (see
        :func:`cfbmarkov.io.particle_frames.import_particle_series`).
    """
    name = NAMES[fmt]
    if length_unit is not None or time_unit is not None:
        raise InputError(f"--length-unit and --time-unit apply to CSV files only; {name} files "
                         "are read in SI units (m, s)")
    if resample is not None or max_gap is not None:
        raise InputError(f"--resample and --max-gap apply to CSV files (tracks at irregular "
                         f"times); {name} files hold simulation frames")
    if time_step is not None and fmt == "pvd":
        raise InputError(f"--time-step applies to LAMMPS dumps, H5MD and VTK files without "
                         f"times; {name} files carry their times")
    check_output(output, first_file(source))
    if fmt == "h5md":
        from cfbmarkov.io.h5md import h5md_series

        if isinstance(source, (list, tuple)) or Path(os.fspath(source)).is_dir():
            raise InputError(f"{source}: give the H5MD file itself")
        series = h5md_series(source, time_step=time_step)
    elif fmt == "vtk":
        from cfbmarkov.io.vtk_read import vtk_series

        series = vtk_series(source, time_step)
    else:
        from cfbmarkov.io.vtk_read import vtp_series

        series = vtp_series(source, time_step)
    try:
        return import_particle_series(series, output, width=width, height=height,
                                      vertical_axis=vertical_axis, region=region,
                                      boundary=boundary, drop_depth=drop_depth,
                                      detected=detected)
    finally:
        series.close()


def import_summary(path: str | os.PathLike) -> str:
    """One line on what an import of particle files read (format and how it was told, frames,
    particles, where ids, times and the boundary came from).

    Parameters
    ----------
    path : str or os.PathLike
        A trajectory file written by :func:`import_particles`.

    Returns
    -------
    str
    """
    from cfbmarkov.trajectories import Trajectories

    with Trajectories(path) as t:
        p = t.parameters
        n_frames, n_particles = t.times.size, t.ids.size
    fmt = NAMES.get(p.get("format"), p.get("format"))
    told = (f"detected from the content: {p['format_detected_from']}"
            if p.get("format_detected_from") else "--format")
    velocity = p.get("velocity_from")
    velocity = f"velocities from {velocity}" if velocity else "no velocities"
    return (f"read {plural(n_frames, 'frame')} of {plural(n_particles, 'particle')} as {fmt} "
            f"({told}); {_axes_text(p)}; ids from {p.get('ids_from')}; times from "
            f"{p.get('time_from')}; "
            f"{velocity}; "
            f"{p.get('boundary_stored')} boundary from {p.get('boundary_from')}; laps from "
            f"{p.get('laps_from')}")


def _axes_text(parameters) -> str:
    """Which of the points' axes are across, vertical and depth (or dropped): ``positions
    x across, y vertical`` or ``positions x across, z vertical, y depth``."""
    axes = [f"{parameters.get('across_axis')} across",
            f"{parameters.get('vertical_axis')} vertical"]
    if parameters.get("depth_axis"):
        axes.append(f"{parameters['depth_axis']} depth")
    elif parameters.get("depth_axis_dropped"):
        axes.append(f"{parameters['depth_axis_dropped']} dropped (projected)")
    return "positions " + ", ".join(axes)
