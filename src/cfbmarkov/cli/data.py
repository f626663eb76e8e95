"""The verbs that bring data in and out: ``import`` (CSV, LAMMPS/LIGGGHTS dumps, VTK and
H5MD particle files) and ``export-vtk`` (ParaView files)."""

from __future__ import annotations

from cfbmarkov.boundary import BOUNDARIES
from cfbmarkov.cli.options import count, finite_float, parse_region, positive_float


def cmd_import(args) -> int:
    """``cfbmarkov import``: print the trajectory file written, alone, on stdout; on stderr
    one line on what was read and how the format was told, then what the import did beyond
    reading rows (id column chosen, rows dropped or merged, title rows skipped).

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    import sys

    from cfbmarkov.io import import_file, import_summary, resolve_format

    args.source = _one_source(args.source, args.format)
    _, detected = resolve_format(args.source, args.format)
    path = import_file(args.source, args.format, args.output, width=args.width,
                       height=args.height, time_step=args.time_step,
                       vertical_axis=args.vertical_axis, region=args.region,
                       length_unit=args.length_unit, time_unit=args.time_unit,
                       boundary=args.boundary, drop_depth=args.drop_depth,
                       resample=args.resample, max_gap=args.max_gap)
    from cfbmarkov.trajectories import Trajectories

    from cfbmarkov.io.plausibility import (gap_warnings, presence_warnings, return_warnings,
                                           shape_warnings, unit_warnings)

    with Trajectories(path) as written:     # what the import did beyond reading rows
        notes = list(written.parameters.get("import_notes", []))
        warnings = (shape_warnings(written) + unit_warnings(written)
                    + presence_warnings(written) + return_warnings(written)
                    + gap_warnings(written))
    print(path)
    print(f"cfbmarkov import: {import_summary(path, detected)}", file=sys.stderr)
    for note in notes:
        print(f"  {note}", file=sys.stderr)
    for line in warnings:
        print(f"warning: {line}", file=sys.stderr)
    return 0


def cmd_export_vtk(args) -> int:
    """``cfbmarkov export-vtk``: print the frames written and the file to open.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    from cfbmarkov.io.vtk import export_vtk_summary

    done = export_vtk_summary(args.run, args.output, start=args.start, stop=args.stop,
                              every=args.every, fields=not args.no_fields,
                              progress=not args.quiet)
    def frames(n: int, what: str) -> str:
        return f"{n} {what} frame{'' if n == 1 else 's'}"

    gas = f", {frames(done.n_gas_files, 'gas field')}" if done.n_gas_files else ""
    missing = f" ({done.n_gas_missing} frames without gas fields)" if done.n_gas_missing else ""
    also = f" (and {done.output / 'gas.pvd'})" if done.n_gas_files else ""
    print(f"{frames(done.n_particle_files, 'particle')}{gas}{missing}: open "
          f"{done.output / 'particles.pvd'}{also} in ParaView")
    return 0


def _one_source(sources: list[str], fmt: str | None = None) -> str | list[str]:
    """The source of ``import``: one file, folder or pattern, or several dump files (read
    in the order of their first timestep, whatever order the shell gave them); several
    files of another format are refused in one line giving the pattern quoted."""
    from cfbmarkov.errors import InputError
    from cfbmarkov.io import resolve_format
    from cfbmarkov.io.detect import pattern_of

    import glob
    from pathlib import Path

    if any(not str(source) for source in sources):      # Path("") is the current folder
        raise InputError("an empty file name (''): give the file, folder or quoted pattern "
                         "to import")
    files = []
    for source in sources:      # quoted patterns given with other sources: their files
        matched = ([] if Path(source).exists() or not glob.has_magic(source)
                   else sorted(glob.glob(source)))
        if len(sources) > 1 and glob.has_magic(source) and not Path(source).exists() \
                and not matched:
            raise InputError(f"{source}: no file matches this pattern")
        files += matched or [source]
    if len(sources) == 1:
        if files == sources:
            return sources[0]
    one_format = None
    if all(Path(p).is_file() for p in files):
        try:
            one_format = {resolve_format(p, fmt)[0] for p in files}
        except InputError:
            pass
    if len(sources) == 1:
        if one_format == {"csv"}:
            raise InputError(f"{sources[0]}: matches {len(files)} CSV files; import reads one "
                             "CSV file at a time, holding all its frames (patterns are for "
                             "dumps and VTK series; text files of one frame each, as OpenPTV's "
                             "res/ptv_is.*, are not read): the runs of one case, each in its "
                             "own file, are imported one by one and pooled by fit A.h5 B.h5 "
                             "...")
        return sources[0]
    if one_format == {"lammps"}:
        return files
    if one_format == {"csv"}:
        raise InputError(f"{len(sources)} CSV files given ({sources[0]}, ...): import reads "
                         "one CSV file at a time, holding all its frames (text files of one "
                         "frame each are not read): the runs of one case, each in its own "
                         "file, are imported one by one and pooled by fit A.h5 B.h5 ...")
    pattern = pattern_of(files)
    if sorted(glob.glob(pattern)) != sorted(str(Path(f)) for f in files):
        raise InputError(f"{len(sources)} sources given ({sources[0]}, ...): import reads one "
                         "file, folder or pattern, or several dump files; put the files of "
                         "one series in one folder and give the folder or a quoted pattern")
    raise InputError(f"{len(sources)} sources given ({sources[0]}, ...): import reads one "
                     "file, folder or pattern, or several dump files; quote a pattern so "
                     "that the shell leaves it to cfbmarkov, which orders the files by their "
                     f"time: '{pattern}'")


def add_import(sub) -> None:
    """Add the ``import`` verb (a trajectory file from CSV or a dump) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("import", help="import CSV, LAMMPS/LIGGGHTS dumps, VTK (.vtk, .vtp, "
                       ".vtu, .pvd) or H5MD particle files as a trajectory file")
    s.add_argument("source", nargs="+",
                   help="input file (.csv, dump, optionally .gz; .vtk, .vtp, .vtu, .pvd, .h5), a "
                        "folder of VTK files, a quoted pattern such as 'post/dump*.vtk', or "
                        "several dump files (read in timestep order)")
    s.add_argument("--format", default="auto",
                   choices=["auto", "csv", "lammps", "vtk", "vtp", "vtu", "pvd", "h5md"],
                   help="the source's format (default auto: told from the content, and said "
                        "so on stderr); csv: docs/how-to/csv.md, lammps: LAMMPS/LIGGGHTS text "
                        "dumps, vtk/vtp/vtu/pvd/h5md: docs/how-to/particle-files.md")
    s.add_argument("-o", "--output", required=True, help="output trajectory file (.h5)")
    s.add_argument("--width", type=positive_float, default=None,
                   help="riser width W, m: the riser is 0..W across in the source's own "
                        "coordinates (default: the dump's box; a CSV file needs it, or "
                        "--region)")
    s.add_argument("--height", type=positive_float, default=None,
                   help="riser height H, m: 0..H vertically in the source's coordinates "
                        "(default: the dump's box; a CSV file needs it, or --region)")
    s.add_argument("--time-step", type=positive_float, default=None,
                   help="simulation time step, s, for LAMMPS dumps without ITEM: TIME, "
                        "H5MD files with steps but no times, and VTK files without times "
                        "(dated by the step in their name)")
    s.add_argument("--vertical-axis", choices=["x", "y", "z"], default=None,
                   help="the source's vertical axis (gravity along minus it); required for a "
                        "3D dump or a CSV file with a z column")
    s.add_argument("--drop-depth", action="store_true",
                   help="store 3D positions projected on (across, vertical)")
    s.add_argument("--region", type=parse_region, default=None,
                   help="the riser in the source's coordinates and units: "
                        "XMIN:XMAX,YMIN:YMAX[,ZMIN:ZMAX]; particles outside it are absent")
    s.add_argument("--boundary", choices=list(BOUNDARIES), default=None,
                   help="the vertical boundary (default: the dump's box flag on the vertical "
                        "axis; periodic for CSV)")
    s.add_argument("--resample", type=positive_float, default=None, metavar="DT",
                   help="CSV: interpolate tracks at irregular times (PEPT) onto frames at the "
                        "multiples of DT s")
    s.add_argument("--max-gap", type=positive_float, default=None, metavar="G",
                   help="with --resample: a particle is absent between samples more than G s "
                        "apart (default DT)")
    s.add_argument("--length-unit", choices=["m", "cm", "mm", "um"], default=None,
                   help="CSV: unit of positions (and, per --time-unit, velocities) in columns "
                        "whose header names none (default m)")
    s.add_argument("--time-unit", choices=["s", "ms"], default=None,
                   help="CSV: unit of t where the header names none (default s)")
    s.set_defaults(func=cmd_import)


def add_export_vtk(sub) -> None:
    """Add the ``export-vtk`` verb (ParaView files of a trajectory file) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("export-vtk", help="ParaView files: particle frames (with their tracer "
                       "group, colour_group) and gas fields with .pvd time series")
    s.add_argument("run", help="trajectory file")
    s.add_argument("-o", "--output", required=True, help="output directory")
    s.add_argument("--start", type=finite_float, default=None, help="first time, s")
    s.add_argument("--stop", type=finite_float, default=None, help="last time, s")
    s.add_argument("--every", type=count(1, 2 ** 31 - 1), default=1,
                   help="export every k-th frame (default 1)")
    s.add_argument("--no-fields", action="store_true", help="particles only")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_export_vtk)
