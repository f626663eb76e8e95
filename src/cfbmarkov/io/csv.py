"""CSV import (docs/definitions.md, CSV import): one row per particle and frame.

Header
    The first non-blank line that is not a comment names the columns; where the first such
    line is already a data row, the last line starting with ``#`` just before it is the
    header (the ``pept`` library writes ``# t x y z error``). Names are matched without case,
    surrounding quotes, ``_`` or repeated spaces, and a unit may follow in parentheses or
    brackets (spreadsheet exports such as EDEM's: ``Time (s)``, ``Particle ID``,
    ``Position X (m)``, ``Velocity Y (m/s)``):

    ========  =====================================================  ==============
    column    names                                                  required
    ========  =====================================================  ==============
    t         ``t``, ``time``                                         yes
    id        ``id``, ``particle id``, ``particleid``, ``pid``        no: one tracer
    x, y, z   ``x``, ``position x``, ``pos x`` (and y, z)             x, y
    vx ...    ``vx``, ``velocity x``, ``vel x``, ``v x`` (and y, z)   no
    ========  =====================================================  ==============

    Other columns are ignored and listed in the provenance (``ignored_columns``). A file
    without an id column is one tracer, stored as particle 0. Where several columns may
    hold the id, the most specific is used: ``TRACK_ID`` (TrackMate; its ``ID`` numbers
    detections), then ``particle`` (trackpy), ``label`` (pept), then the plain id names;
    rows of ``label`` -1 (noise) or with an empty ``TRACK_ID`` are dropped and counted
    (``import_notes``). A title line above the header (one that names no time column)
    and up to three rows without numbers below it (TrackMate's names, short names and
    units, ``(mm)``, ``(sec)``) are skipped.

Delimiter and decimal mark
    Comma, semicolon, tab or whitespace, told from the header line and checked against the
    first data line (the first of ``;``, tab, ``,`` found in the header where the first data
    row splits into as many fields, else whitespace). Where the delimiter is not a comma and
    the first data rows hold a comma, the comma is the decimal mark (European spreadsheet
    export: ``0,025;1;0,020;0,100``).

Units
    Positions in m, cm or mm and times in s or ms: from the column's unit in the header,
    else from ``length_unit`` / ``time_unit`` (``--length-unit``, ``--time-unit``), else m and
    s; velocities in (length unit)/(time unit) unless the header says otherwise. A header
    unit that contradicts the option given is refused. Values are converted to SI (divided
    by 100 or 1000) and the units are recorded in the provenance.

Axes
    A file without z has x across and y vertical. A file with a z column is refused unless
    ``vertical_axis`` (``--vertical-axis x|y|z``) says which axis is vertical, never
    guessed; across is then the first other axis (x, else y), and the remaining (depth)
    axis is dropped and recorded (``depth_axis_dropped``).

Rows
    Rows may come in any order. A file whose times never decrease (the rows of each frame
    together, frames in time order, the usual case) is read in blocks of rows and written
    frame by frame through :class:`~cfbmarkov.trajectory_writer.TrajectoryWriter`, so memory
    stays at a few frames whatever its length. Otherwise (rows grouped by particle, say) the
    file is read again whole into memory (8 bytes per value of the used columns), its rows
    sorted by time then id, and written; the provenance says which (``row_order``). Every
    particle must be present in every frame and the frames evenly spaced: particles that
    enter or leave the view, and irregular frame times (PEPT), are refused with one line
    until the trajectory store has a presence mask and resampling exists.

A gzip-compressed file is recognised by its magic bytes; blank lines, rows of only
delimiters and other lines starting with '#' are skipped; UTF-8 with or without a
byte-order mark, UTF-16 with one, and Windows line ends are accepted.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from cfbmarkov.boundary import Boundary
from cfbmarkov._console import plural
from cfbmarkov.errors import InputError
from cfbmarkov.io._common import (
    check_output,
    check_source,
    create_writer,
    open_text,
    progress,
    reading,
    removing_new_folders,
)
from cfbmarkov.io.csv_layout import (
    AXES,
    LENGTH_UNITS,
    TIME_UNITS,
    _DELIMITERS,
    CsvLayout,
    read_layout,
)
from cfbmarkov.io.csv_rows import UnsortedRows, frame_rows, row_blocks
from cfbmarkov.io.resample import merge_same_times, resample_tracks
from cfbmarkov.io.riser import FrameColumns, RiserFrame
from cfbmarkov.trajectory_writer import IMPORT_MAX_STEP, TrajectoryWriter


#: rows of one tracer at one time (printed at a fixed precision) are averaged into one
#: sample only where they lie within this fraction of the riser's width of each other
SAME_TIME_SPREAD = 0.05


def import_csv(source: str | os.PathLike, output: str | os.PathLike, *,
               width: float | None = None, height: float | None = None,
               length_unit: str | None = None, time_unit: str | None = None,
               vertical_axis: str | None = None, region=None, boundary: str | None = None,
               drop_depth: bool = False, resample: float | None = None,
               max_gap: float | None = None) -> Path:
    """Import a CSV file of particle positions (one row per particle and frame) as a
    trajectory file.

    The format (header names, delimiter, decimal comma, units, axes, row order) is described
    in the module docstring and docs/definitions.md, CSV import. The lap counter is derived
    from the positions by the minimal-image rule on a periodic vertical axis
    (docs/definitions.md, Pass direction).

    Parameters
    ----------
    source : str or os.PathLike
        The CSV file, plain or gzip-compressed.
    output : str or os.PathLike
        The trajectory file (HDF5) to write; it appears only when complete.
    width, height : float, optional
        Riser width W and height H, m (whatever the file's unit); the riser is 0..W across
        and 0..H vertically. A CSV file does not give the riser's size: give both, or
        ``region``; without them the import is refused with the data's extent.
    length_unit : {"m", "cm", "mm"}, optional
        Unit of positions (and, over ``time_unit``, velocities) in columns whose header
        gives none; default m.
    time_unit : {"s", "ms"}, optional
        Unit of t where the header gives none; default s.
    vertical_axis : {"x", "y", "z"}, optional
        The file's vertical axis; required for a file with a z column (default y otherwise).
    region : sequence of (lo, hi), optional
        The riser in the file's coordinates and length unit, one range per axis x, y (, z);
        required for 3D positions (a z column) unless ``drop_depth``.
    boundary : {"periodic", "open"}, optional
        The vertical boundary (default periodic).
    drop_depth : bool, optional
        Store 3D positions projected on (across, vertical).
    resample : float, optional
        Interpolate tracks with irregular times (PEPT) onto frames this far apart (s), with
        :func:`~cfbmarkov.io.resample.resample_tracks`; velocities are then not stored.
    max_gap : float, optional
        With ``resample``: a particle is absent between two of its samples further apart
        than this (s); default ``resample``.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        On bad input (a malformed header or row, an unknown unit, a z column without
        ``vertical_axis``, unevenly spaced frames without ``resample``, neither the riser's
        size nor a region (the message names the data's extent), a region that holds no
        particle, ...); no file is left behind.
    """
    path = check_source(source)
    output = check_output(output, path)
    label = str(path)
    check_units(length_unit, time_unit)
    if vertical_axis is not None and vertical_axis not in AXES:
        raise InputError(f"--vertical-axis {vertical_axis!r}: choose x, y or z")
    boundary = Boundary.PERIODIC if boundary is None else Boundary.parse(boundary, "--boundary")
    if max_gap is not None and resample is None:
        raise InputError("--max-gap applies with --resample only")
    options = {"length_unit": length_unit, "time_unit": time_unit,
               "vertical_axis": vertical_axis, "keep_depth": not drop_depth}
    geometry = {"width": width, "height": height, "region": region,
                "boundary": boundary}
    with removing_new_folders(output), reading(label):
        if resample is None:
            try:
                with open_text(path) as fh:
                    layout = read_layout(fh, label, **options)
                    _check_depth_option(layout, label, drop_depth)
                    if _unsized(layout, geometry):
                        _refuse_unsized(row_blocks(fh, layout, label, streaming=False),
                                        layout, label, geometry)
                    riser = csv_riser(layout, label, **geometry)
                    blocks = row_blocks(fh, layout, label, streaming=True)
                    _write(output, path, layout, riser, blocks, "as written")
                return output
            except UnsortedRows:
                pass
        with open_text(path) as fh:     # read whole: rows out of time order, or resampling
            layout = read_layout(fh, label, **options)
            _check_depth_option(layout, label, drop_depth)
            rows = list(row_blocks(fh, layout, label, streaming=False))
            if _unsized(layout, geometry):
                _refuse_unsized(rows, layout, label, geometry)
            riser = csv_riser(layout, label, **geometry)
        rows = np.concatenate(rows) if rows else np.empty((0, len(layout.used)))
        if resample is not None:
            if not layout.has_id:
                _refuse_an_unnamed_tracer_column(path, label, options, layout, riser, rows)
            _write_resampled(output, path, layout, riser, rows, resample, max_gap)
            return output
        keys = (layout.ids(rows), rows[:, layout.index("t")]) if layout.has_id else (
            rows[:, layout.index("t")],)
        rows = rows[np.lexsort(keys)]
        _write(output, path, layout, riser, iter([rows]),
               "sorted by time and id (rows out of time order; the whole file read into memory)")
    return output


def check_units(length_unit: str | None, time_unit: str | None) -> None:
    """Refuse a length or time unit that CSV import does not know.

    Parameters
    ----------
    length_unit : str or None
        ``m``, ``cm`` or ``mm`` (or None).
    time_unit : str or None
        ``s`` or ``ms`` (or None).

    Raises
    ------
    InputError
        Naming the option and the units it takes.
    """
    if length_unit is not None and length_unit not in LENGTH_UNITS:
        raise InputError(f"--length-unit {length_unit!r}: choose m, cm, mm or um")
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise InputError(f"--time-unit {time_unit!r}: choose s or ms")


def _unsized(layout: CsvLayout, geometry: dict) -> bool:
    """Whether a 2D CSV import has neither the riser's width and height nor a region."""
    return (geometry["region"] is None and layout.depth is None
            and (geometry["width"] is None or geometry["height"] is None))


def _refuse_unsized(blocks, layout: CsvLayout, label: str, geometry: dict) -> None:
    """Refuse a CSV import without the riser's size, naming the data's extent (m) and the
    option missing where one of --width and --height was given."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for rows in blocks:
        raw = _source_positions(rows, layout)
        lo = np.fmin(lo, np.where(np.isfinite(raw), raw, np.inf).min(axis=0, initial=np.inf))
        hi = np.fmax(hi, np.where(np.isfinite(raw), raw, -np.inf).max(axis=0, initial=-np.inf))
    spans = [f"{axis} {lo[AXES.index(axis)]:.4g}..{hi[AXES.index(axis)]:.4g} m"
             for axis in (layout.across, layout.vertical)
             if np.isfinite(lo[AXES.index(axis)])]
    extent = f"; the data span {', '.join(spans)}" if spans else ""
    given = [name for name in ("width", "height") if geometry.get(name) is not None]
    missing = ("--height H" if given == ["width"] else "--width W" if given == ["height"]
               else "--width W and --height H")
    told = f" (--{given[0]} is given)" if len(given) == 1 else ""
    raise InputError(f"{label}: a CSV file does not give the riser's size: give {missing}"
                     f"{told} (m; the riser is 0..W across, {layout.across}, and 0..H "
                     f"vertically, {layout.vertical}) or --region{extent}")


def csv_riser(layout: CsvLayout, label: str, *, width: float | None, height: float | None,
              region, boundary: Boundary) -> RiserFrame:
    """The riser of a CSV file: axes from the layout; region from ``region`` (in the file's
    length unit, converted to m), else 0..W x 0..H.

    Parameters
    ----------
    layout : CsvLayout
        The file's columns and axes.
    label : str
        Names the file in error messages.
    width, height : float or None
        The riser (m) when no region is given.
    region : sequence of (lo, hi) or None
        One range per axis x, y (, z), in the file's length unit.
    boundary : Boundary
        The vertical boundary.

    Returns
    -------
    RiserFrame
        ``from_box`` is False: a position outside the given riser is absent.

    Raises
    ------
    InputError
        For 3D positions without a region, a region without the riser's axes, or 2D
        positions with neither a region nor both ``width`` and ``height``.
    """
    axes = [AXES.index(layout.across), AXES.index(layout.vertical)]
    if layout.depth is not None:
        axes.append(AXES.index(layout.depth))
    if region is not None:
        ranges = np.asarray(region, dtype=np.float64)
        if ranges.shape[0] > 2 and layout.depth is None and layout.dropped is None:
            raise InputError(f"{label}: --region gives a z range, but the file's positions are "
                             f"2D ({layout.across} across, {layout.vertical} vertical), which "
                             "would leave it unused: give two ranges, --region "
                             "XMIN:XMAX,YMIN:YMAX")
        if max(axes) >= ranges.shape[0]:
            raise InputError(f"--region gives {ranges.shape[0]} ranges but the riser uses the "
                             f"{AXES[max(axes)]} axis: give x, y and z ranges")
        divisor = LENGTH_UNITS[layout.units[layout.vertical]]
        bounds = ranges[axes] / divisor
        given = True
    elif layout.depth is not None:
        raise InputError(f"{label}: 3D positions ({layout.across} across, {layout.vertical} "
                         f"vertical, {layout.depth} depth): give the riser with --region "
                         "XMIN:XMAX,YMIN:YMAX,ZMIN:ZMAX in the file's units, or --drop-depth")
    elif width is None or height is None:
        raise InputError(f"{label}: a CSV file does not give the riser's size: give --width W "
                         "and --height H (m) or --region")
    else:
        bounds = np.array([(0.0, float(width)), (0.0, float(height))])
        given = True
    periodic = (False, not boundary.is_open) + ((False,) if len(axes) == 3 else ())
    return RiserFrame(tuple(axes), bounds, not given, periodic, boundary)


def _parameters(path: Path, layout: CsvLayout, riser: RiserFrame, row_order: str) -> dict:
    velocity = layout.velocity
    return {
        "source_file": path.name, "format": "csv", "columns": layout.header,
        "delimiter": _DELIMITERS[layout.delimiter],
        "decimal_mark": "comma" if layout.decimal_comma else "point",
        "units": layout.units, "ignored_columns": layout.ignored,
        **riser.provenance(),
        "depth_axis_dropped": layout.dropped,
        "position_columns": list(layout.axes),
        "velocity_columns": list(velocity) if velocity else [],
        "id_column": layout.id_column if layout.has_id else None,
        "id_columns_not_used": layout.id_others, "row_order": row_order,
        "title_lines_skipped": layout.title_lines,
        "description_rows_skipped": layout.description_rows,
        "width": riser.width, "height": riser.height,
    }


def _check_depth_option(layout: CsvLayout, label: str, drop_depth: bool) -> None:
    """Refuse ``--drop-depth`` on a file of 2D positions (it would be ignored)."""
    if drop_depth and layout.dropped is None:
        raise InputError(f"{label}: --drop-depth drops a z column, but the file's positions "
                         f"are 2D ({layout.across} across, {layout.vertical} vertical): leave "
                         "--drop-depth out")


def _no_rows(label: str, layout: CsvLayout) -> str:
    """The message of a file with no particle's row: none after the header, or every one
    marked as belonging to no particle (pept's label -1, an empty TrackMate TRACK_ID)."""
    if layout.noise_rows:
        if "track" in str(layout.id_column).lower():
            what, fix = "an empty", "track the spots first (TrackMate: export the spots of tracks)"
        else:
            what, fix = f"{layout.noise_id} (noise) in", "label the tracers' points first"
        return (f"{label}: all {layout.noise_rows} data rows have {what} "
                f"{layout.id_column!r}: they belong to no particle, nothing to import; {fix}")
    return (f"{label}: no data rows after the header: nothing to import; check that the "
            "export wrote its rows (a run or an export still writing, or stopped)")


def _write(output: Path, path: Path, layout: CsvLayout, riser: RiserFrame,
           blocks: Iterator[np.ndarray], row_order: str) -> None:
    """Split row blocks into frames and write them (the writer is discarded on an error)."""
    label = str(path)
    it = layout.index("t")
    frames = frame_rows(blocks, it)
    first = next(frames, None)
    if first is None:
        raise InputError(_no_rows(label, layout))
    reference = (np.unique(layout.ids(first[0])) if layout.has_id
                 else np.zeros(1, dtype=np.int64))
    parameters = _parameters(path, layout, riser, row_order)
    periodic = not riser.boundary.is_open
    parameters["laps_from"] = "minimal-image rule" if periodic else "none (open riser)"
    with create_writer(output, reference, source="import:csv", parameters=parameters,
                       with_velocity=layout.velocity is not None, label=label,
                       max_step=IMPORT_MAX_STEP, **riser.writer_options()) as writer:
        columns = FrameColumns(writer)
        followed = _FollowedIds()
        for rows, _last in progress(itertools.chain([first], frames), label):
            _append_frame(writer, columns, rows, layout, riser, label)
            if layout.has_id:
                followed.add(layout.ids(rows))
        _check_some_present(writer, riser, label)
        followed.check(layout, label)
        writer.update_parameters(read_notes(layout))


#: a column of whole numbers is taken to number the tracers where the samples, read as one
#: tracer, move this many times faster (median) than the samples of each of its values
TRACER_SPEED_RATIO = 3.0


def _refuse_an_unnamed_tracer_column(path: Path, label: str, options: dict,
                                     layout: CsvLayout, riser: RiserFrame,
                                     rows: np.ndarray) -> None:
    """Refuse a file without an id column whose unused column of a few whole numbers numbers
    its tracers (PEPT's multi-tracer output under a name that is not id, tracer, label or
    track): read as one tracer, the track would jump between the tracers' places, which
    resampling smooths into a plausible path. The column is read again and the samples'
    median speed compared with that within each of its values (:data:`TRACER_SPEED_RATIO`)."""
    import dataclasses

    skipped = set(layout.usecols)
    extra = [k for k, name in enumerate(layout.header) if k not in skipped
             and any(ignored.startswith(name) for ignored in _unused_columns(layout))]
    if not extra or rows.shape[0] < 4:
        return
    wide = dataclasses.replace(
        layout, used=layout.used + [f"column {k}" for k in extra],
        usecols=layout.usecols + extra, divisors=layout.divisors + [1.0] * len(extra))
    try:
        with open_text(path) as fh:
            fresh = read_layout(fh, label, **options)
            wide.pending = fresh.pending
            table = np.concatenate(list(row_blocks(fh, wide, label, streaming=False)))
    except (InputError, ValueError):
        return                      # text, or rows too short: not a tracer number
    if table.shape[0] != rows.shape[0]:
        return
    t = table[:, layout.index("t")]
    xy = table[:, [layout.index(layout.across), layout.index(layout.vertical)]]
    period = None if riser.boundary.is_open else riser.height

    def median_speed(order, same=None):
        dt = np.diff(t[order])
        d = np.diff(xy[order], axis=0)
        if period:
            d[:, 1] -= period * np.round(d[:, 1] / period)
        ok = dt > 0 if same is None else (dt > 0) & same
        return float(np.median(np.hypot(d[ok, 0], d[ok, 1]) / dt[ok])) if ok.any() else None

    overall = median_speed(np.argsort(t, kind="stable"))
    for j, k in enumerate(extra):
        v = table[:, len(layout.used) + j]
        values = np.unique(v)
        if (not np.all(np.isfinite(v)) or np.any(v != np.round(v)) or values.size < 2
                or values.size > max(2, rows.shape[0] // 20)):
            continue
        order = np.lexsort((t, v))
        within = median_speed(order, np.diff(v[order]) == 0)
        if overall is None or within is None or overall <= TRACER_SPEED_RATIO * within:
            continue
        name = layout.header[k]
        raise InputError(
            f"{label}: column {name!r} seems to number the tracers ({values.size} whole "
            f"values): read as one tracer, the samples jump between their places (median "
            f"{overall:.3g} m/s from one sample to the next), while those of each value move "
            f"at a median {within:.3g} m/s; name the column id, tracer, label or track to "
            "import each tracer apart (or leave the column out where the file holds one "
            "tracer)")


def _unused_columns(layout: CsvLayout) -> list[str]:
    """The file's columns that the import reads nothing from (the depth axis left out)."""
    return [name for name in layout.ignored if not name.endswith("(depth axis)")]


def read_notes(layout: CsvLayout, merged: int = 0, time_note: str = "") -> dict:
    """What the import did beyond reading rows, for the provenance and the import's summary
    (``import_notes``, shown by ``cfbmarkov import`` and ``cfbmarkov info``).

    Parameters
    ----------
    layout : CsvLayout
        The file's layout, after every row was read (its ``noise_rows`` counted).
    merged : int, optional
        Rows merged with another row of the same particle at the same time (resampling).
    time_note : str, optional
        Why rows may share a time (:func:`time_resolution_note`), added to the merge's note.

    Returns
    -------
    dict
        ``noise_rows_dropped``, ``rows_merged`` and ``import_notes`` (a list of str).
    """
    notes = []
    if layout.title_lines:
        notes.append(f"title line above the header skipped: {layout.title_lines[0]!r}")
    if layout.description_rows:
        notes.append(f"{layout.description_rows} description rows below the header skipped "
                     "(names, units)")
    if layout.has_id and layout.id_others:
        notes.append(f"particle ids from column {layout.id_column!r}; not from "
                     + ", ".join(repr(n) for n in layout.id_others))
    elif layout.has_id and layout.noise_id is not None:
        notes.append(f"particle ids from column {layout.id_column!r}")
    unused = _unused_columns(layout)
    if not layout.has_id and unused:
        notes.append("no id column, so the file is read as one tracer; not used: "
                     + ", ".join(repr(n) for n in unused) + " (a column that numbers the "
                     "tracers must be named id, tracer, label or track)")
    if layout.noise_rows:
        notes.append(f"{plural(layout.noise_rows, 'row')} with {layout.id_column} "
                     f"{layout.noise_id} or empty (noise, or no track) dropped")
    if merged:
        notes.append(f"{plural(merged, 'row')} at the same time as another row of their "
                     f"particle merged (positions averaged) before resampling{time_note}")
    if layout.outside_rows:
        share = 100 * layout.outside_rows / max(layout.placed_rows, 1)
        notes.append(f"{layout.outside_rows} of {layout.placed_rows} rows ({share:.3g} %) lie "
                     "outside the riser's region and are absent there; if that is not the "
                     "particles leaving the view, check --width, --region and where the "
                     "positions' origin lies")
    return {"noise_rows_dropped": layout.noise_rows, "rows_merged": merged,
            "import_notes": notes}


class _FollowedIds:
    """Whether some particle id of a CSV file occurs in two frames or more: where none does
    (over two frames or more), the id column numbers detections, not particles, and nothing
    could be followed from frame to frame (TrackMate's ``ID`` without its ``TRACK_ID``)."""

    def __init__(self):
        self.frames, self.repeated = 0, False
        self.ids = np.zeros(0, dtype=np.int64)

    def add(self, ids: np.ndarray) -> None:
        self.frames += 1
        if not self.repeated:
            ids = np.unique(ids)
            self.repeated = bool(np.isin(ids, self.ids, assume_unique=True).any())
            self.ids = np.union1d(self.ids, ids)

    def check(self, layout: CsvLayout, label: str) -> None:
        if self.frames >= 2 and not self.repeated:
            raise InputError(
                f"{label}: each of the {self.ids.size} ids in column {layout.id_column!r} "
                f"occurs in one frame only (over {self.frames} frames): the column numbers "
                "detections, not particles, so no particle can be followed; give the file "
                "with the column that names each track (TrackMate: TRACK_ID; trackpy: "
                "particle; pept: label), or link the detections into tracks first")


def _check_some_present(writer: TrajectoryWriter, riser: RiserFrame, label: str) -> None:
    if not writer.any_present:
        raise InputError(f"{label}: the riser region {riser.region_text()} holds no particle "
                         "in any frame; check --region and --length-unit")


def _append_frame(writer: TrajectoryWriter, columns: FrameColumns, rows: np.ndarray,
                  layout: CsvLayout, riser: RiserFrame, label: str) -> None:
    """Map one frame's rows onto the riser and append it (particles not in the frame, or
    outside a given region, are absent)."""
    time = float(rows[0, layout.index("t")])
    where = f"{label}: frame at t = {time:g} s"
    if layout.has_id:
        ids = layout.ids(rows)
    elif rows.shape[0] > 1:
        unused = _unused_columns(layout)
        named = (f" (not used: {', '.join(repr(n) for n in unused)})" if unused else "")
        coarse = time_resolution_note(rows[:, layout.index("t")])
        raise InputError(f"{where}: {rows.shape[0]} rows at this time, but the file has no id "
                         f"column{named}, so it is read as one tracer; name the column that "
                         "numbers the particles id (or tracer, label, track), or add one"
                         + (f"{coarse.replace('; the times', '; or the times', 1)}"
                            if coarse else ""))
    else:
        ids = np.zeros(1, dtype=np.int64)
    positions, inside = _riser_positions(rows, layout, riser, ids, label)
    velocity = layout.velocity
    velocity = rows[:, [layout.index(v) for v in velocity]] if velocity else None
    try:
        full, vel, _, present = columns.frame(ids, positions, inside, velocity, None, where)
    except InputError as exc:     # a particle twice at one time: why, where times are large
        coarse = time_resolution_note(rows[:, layout.index("t")])
        if not coarse or "more than once" not in str(exc):
            raise
        raise InputError(f"{exc}{coarse}") from None
    writer.append(time, full, vel, None, present)


#: the time step (s) a double must hold at a file's times, below which rows stamped apart
#: may read as one time: times since an epoch (1.7e9 s is held to 2.4e-7 s)
TIME_RESOLUTION = 1e-9


def time_resolution_note(times) -> str:
    """``"; the times lie near ... s"``: why rows stamped apart may read as one time (a
    double holds times as large as the file's to more than :data:`TIME_RESOLUTION`, e.g.
    seconds since 1970), and the fix; ``""`` where it holds them finer."""
    times = np.asarray(times, dtype=np.float64)
    finite = times[np.isfinite(times)]
    if not finite.size:
        return ""
    largest = float(np.abs(finite).max())
    step = float(np.spacing(largest))
    if step <= TIME_RESOLUTION:
        return ""
    return (f"; the times lie near {largest:.6g} s, where a double holds them only to "
            f"{step:.2g} s, so rows stamped closer than that read as one time: give the times "
            "from the run's start (subtract the first time from the column)")


def _riser_positions(rows: np.ndarray, layout: CsvLayout, riser: RiserFrame, ids: np.ndarray,
                     label: str) -> tuple[np.ndarray, np.ndarray]:
    """Stored positions [M, D] (m, from the region's lower corner) and which rows lie in the
    region. Refused: a position that is not finite; outside the default riser (no region
    given: a wrong unit is likelier); a height outside a periodic riser (it has no outside
    vertically)."""
    t = rows[:, layout.index("t")]
    raw = _source_positions(rows, layout)[:, list(riser.axes)]
    bad = ~np.isfinite(raw).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(f"{label}: position of particle {int(ids[k])} at t = {t[k]:g} s is not "
                         f"a finite number ({raw[k].tolist()}; a particle out of view is left "
                         "out of its frame: drop the rows that hold such values)")
    relative = raw - riser.region[:, 0]
    extent = riser.region[:, 1] - riser.region[:, 0]
    tol = 1e-9
    within = (relative >= -tol) & (relative <= extent + tol)
    inside = within.all(axis=1)
    strict = ~within[:, 1] if not riser.boundary.is_open else np.zeros(len(rows), bool)
    if riser.from_box:
        strict = ~inside
    if strict.any():
        k = int(np.argmax(strict))
        _refuse_outside(rows[k:k + 1], layout, riser, ids[k:k + 1], float(t[k]), label)
    layout.placed_rows += int(inside.size)
    layout.outside_rows += int(inside.size - np.count_nonzero(inside))
    return np.clip(relative, 0.0, extent), inside


def _source_positions(rows: np.ndarray, layout: CsvLayout) -> np.ndarray:
    """[M, 3] source positions x, y, z (m) of a block of rows (NaN for a missing axis)."""
    raw = np.full((rows.shape[0], 3), np.nan)
    for k, axis in enumerate(AXES):
        if axis in layout.used:
            raw[:, k] = rows[:, layout.index(axis)]
    return raw


def _refuse_outside(row: np.ndarray, layout: CsvLayout, riser: RiserFrame, ids: np.ndarray,
                    time: float, label: str) -> None:
    """Refuse a row outside the riser, naming the column and the value as written."""
    p = 0
    raw = _source_positions(row, layout)[0]
    k = next(k for k, a in enumerate(riser.axes)
             if not riser.region[k, 0] - 1e-9 <= raw[a] <= riser.region[k, 1] + 1e-9)
    axis = AXES[riser.axes[k]]
    unit = layout.units[axis]
    written = raw[riser.axes[k]] * LENGTH_UNITS[unit]
    hint = ("; if the file is not in m, give --length-unit cm|mm" if layout.unit_from[axis] ==
            "default" else "" if unit == "m" else
            f"; --region is read in the file's unit ({unit}), --width and --height in m")
    depth = "" if riser.depth_extent is None else f" x 0..{riser.depth_extent:g}"
    if k == 1 and not riser.from_box:
        # a periodic riser holds every particle (they pass through its top and bottom):
        # no region keeps heights out
        fix = ("a periodic riser holds every particle, so its vertical range must cover "
               "every height: give a taller --height or --region's vertical range, or "
               "--boundary open if particles leave through the top and bottom")
    else:
        fix = ("set the riser with --width and --height, or give --region to keep only the "
               "particles inside it")
    raise InputError(
        f"{label}: particle {int(ids[p])} at t = {time:g} s lies outside the domain "
        f"0..{riser.width:g} x 0..{riser.height:g}{depth} m: {layout.column(axis)!r} = "
        f"{written:g} {unit}; positions are measured from the riser's lower corner, "
        f"{layout.across} across and {layout.vertical} vertical ({fix}){hint}")


def _write_resampled(output: Path, path: Path, layout: CsvLayout, riser: RiserFrame,
                     rows: np.ndarray, interval: float, max_gap: float | None) -> None:
    """Resample every track onto frames ``interval`` apart and write them."""
    label = str(path)
    if rows.shape[0] == 0:
        raise InputError(_no_rows(label, layout))
    ids = (layout.ids(rows) if layout.has_id
           else np.zeros(rows.shape[0], dtype=np.int64))
    order = np.argsort(rows[:, layout.index("t")], kind="stable")
    rows, ids = rows[order], ids[order]
    relative, inside = _riser_positions(rows, layout, riser, ids, label)
    extent = riser.region[:, 1] - riser.region[:, 0]
    periodic = not riser.boundary.is_open
    keep = inside
    if not keep.any():
        raise InputError(f"{label}: the riser region {riser.region_text()} holds no "
                         "particle in any row; check --region and --length-unit")
    times, ids, relative, merged = merge_same_times(
        rows[keep, layout.index("t")], ids[keep], relative[keep],
        height=riser.height if periodic else None, vertical=1,
        spread_limit=SAME_TIME_SPREAD * riser.width, label=label)
    coarse = time_resolution_note(times) if merged else ""   # why rows may share a time
    try:
        tracks = resample_tracks(times, ids, relative,
                                 interval=interval, max_gap=max_gap,
                                 height=riser.height if periodic else None, vertical=1,
                                 label=label, open_height=None if periodic else riser.height)
    except InputError as error:
        unused = _unused_columns(layout)
        if layout.has_id or not unused:
            raise
        # several tracers under a column of another name jump between each other's places
        raise InputError(f"{error} (the file has no id column and is read as one tracer; "
                         f"not used: {', '.join(repr(n) for n in unused)}: if one of them "
                         "numbers the tracers, name it id)") from None
    positions = np.clip(tracks.positions, 0.0, extent)
    parameters = _parameters(path, layout, riser, "resampled")
    parameters.update({"resample": interval, "max_gap": interval if max_gap is None else max_gap,
                       "max_gap_from": "--max-gap" if max_gap is not None else "default",
                       # the samples after rows of one time stamp were merged into one
                       "velocity_columns": [], "samples": int(times.size),
                       "laps_from": ("minimal-image rule between samples" if periodic
                                     else "none (open riser)")})
    with create_writer(output, tracks.ids, source="import:csv", parameters=parameters,
                       label=label, frame_interval=interval, **riser.writer_options()) as writer:
        writer.append_frames(tracks.times, positions, None, tracks.laps, tracks.present)
        _check_some_present(writer, riser, label)
        writer.update_parameters(read_notes(layout, merged, coarse))
