"""Importers: CSV files and LAMMPS/LIGGGHTS text dumps -> trajectory files (HDF5).

Both read their input a frame at a time and write through
:class:`~cfbmarkov.trajectories.TrajectoryWriter`, which validates every frame and derives the
lap counter; bad input raises :class:`~cfbmarkov.errors.InputError` and leaves no output file.
"""

from __future__ import annotations

import os
from pathlib import Path

from cfbmarkov.errors import InputError
from cfbmarkov.io.csv import import_csv
from cfbmarkov.io.lammps import import_lammps

FORMATS = ("csv", "lammps")


def import_file(source: str | os.PathLike, fmt: str, output: str | os.PathLike, *,
                width: float | None = None, height: float | None = None,
                time_step: float | None = None, vertical_axis: str | None = None,
                region: tuple[tuple[float, float], ...] | None = None) -> Path:
    """Import ``source`` in format ``fmt`` ('csv' or 'lammps') as the trajectory file ``output``.

    Parameters
    ----------
    source : str or os.PathLike
        The file to import (optionally gzip-compressed).
    fmt : {'csv', 'lammps'}
        Its format (case-insensitive).
    output : str or os.PathLike
        The trajectory file (HDF5) to write.
    width, height : float, optional
        The domain, m (CSV default: the paper's 0.09 x 0.95 m riser; LAMMPS default: the
        dump's box).
    time_step : float, optional
        Simulation time step, s, that dates LAMMPS frames carrying no ``ITEM: TIME``; a CSV
        file carries its times in column t and takes no time step.
    vertical_axis : {"x", "y", "z"}, optional
        The source's vertical axis (LAMMPS dumps; required for a 3D dump).
    region : sequence of (lo, hi), optional
        The riser in the source's coordinates, one range per axis x, y (, z) (LAMMPS dumps).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        For an unknown format, a non-positive size or time step, a time step given with a
        CSV file, or bad input (see :func:`import_csv` and :func:`import_lammps`).
    """
    fmt = str(fmt).lower()
    if fmt not in FORMATS:
        raise InputError(f"unknown import format {fmt!r}; choose one of {', '.join(FORMATS)}")
    for name, value in (("width", width), ("height", height), ("time step", time_step)):
        if value is not None and not float(value) > 0:
            raise InputError(f"{name} {value} must be a positive number")
    if fmt == "csv":
        if time_step is not None:
            raise InputError("--time-step applies to LAMMPS dumps only; a CSV file gives its "
                             "times in column t")
        if vertical_axis not in (None, "y") or region is not None:
            raise InputError("--vertical-axis and --region apply to LAMMPS dumps only so far; "
                             "a CSV file gives x across and y up, measured from the riser's "
                             "lower-left corner")
        return import_csv(source, output, width=width, height=height)
    return import_lammps(source, output, width=width, height=height, time_step=time_step,
                         vertical_axis=vertical_axis, region=region)


__all__ = ["FORMATS", "import_csv", "import_file", "import_lammps"]
