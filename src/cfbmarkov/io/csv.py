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
    without an id column is one tracer, stored as particle 0.

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
    frame by frame through :class:`~cfbmarkov.trajectories.TrajectoryWriter`, so memory
    stays at a few frames whatever its length. Otherwise (rows grouped by particle, say) the
    file is read again whole into memory (8 bytes per value of the used columns), its rows
    sorted by time then id, and written; the provenance says which (``row_order``). Every
    particle must be present in every frame and the frames evenly spaced: particles that
    enter or leave the view, and irregular frame times (PEPT), are refused with one line
    until the trajectory store has a presence mask and resampling exists.

A gzip-compressed file is recognised by its magic bytes; blank lines and other lines
starting with '#' are skipped; a UTF-8 byte-order mark and Windows line ends are accepted.
"""

from __future__ import annotations

import itertools
import os
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.io._common import (
    check_output,
    check_source,
    create_writer,
    frame_order,
    open_text,
    progress,
    reading,
    removing_new_folders,
    whole_ids,
)
from cfbmarkov.trajectories import POSITION_TOLERANCE
from cfbmarkov.trajectory_writer import TrajectoryWriter

#: the paper's riser (docs/definitions.md, Riser): width W and height H, m
DEFAULT_WIDTH = 0.09
DEFAULT_HEIGHT = 0.95
AXES = ("x", "y", "z")
#: length and time units: the number a value is divided by to give m or s
LENGTH_UNITS = {"m": 1.0, "cm": 100.0, "mm": 1000.0}
TIME_UNITS = {"s": 1.0, "ms": 1000.0}
#: characters of text parsed per call (about 70000 rows of six columns)
CHUNK_CHARS = 1 << 22
#: data rows read after the header to tell the delimiter and the decimal mark
SNIFF_ROWS = 5
_EXPECTED = ("expected t, x, y and optionally id, z, vx, vy, vz (or spreadsheet names such as "
             "'Time (s)', 'Particle ID', 'Position X (m)'); other columns are ignored")
_ALIASES = {"t": "t", "time": "t", "id": "id", "particle id": "id", "particleid": "id",
            "pid": "id"}
for _axis in AXES:
    _ALIASES.update({_axis: _axis, f"position {_axis}": _axis, f"pos {_axis}": _axis,
                     f"v{_axis}": f"v{_axis}", f"velocity {_axis}": f"v{_axis}",
                     f"vel {_axis}": f"v{_axis}", f"v {_axis}": f"v{_axis}"})
_UNIT = re.compile(r"^(.*?)\s*[(\[]\s*([^)\]]*?)\s*[)\]]$")
_DELIMITERS = {";": "semicolon", "\t": "tab", ",": "comma", None: "whitespace"}


class _Unsorted(Exception):
    """The times of the rows decrease somewhere: read the file whole and sort it."""


@dataclass
class CsvLayout:
    """How to read a CSV file: delimiter, decimal mark, used columns, units and axes.

    ``used`` lists the canonical names of the columns parsed, in file order; ``usecols``
    their positions in a row; ``divisors`` the number each is divided by for SI units.
    """

    header: list[str]
    delimiter: str | None
    decimal_comma: bool
    used: list[str]
    usecols: list[int]
    divisors: list[float]
    units: dict[str, str]
    ignored: list[str]
    vertical: str
    across: str
    depth: str | None
    header_line: int
    first_data_line: int
    unit_from: dict[str, str] = field(default_factory=dict)
    pending: list[str] = field(default_factory=list)

    def column(self, name: str) -> str:
        """The header name of canonical column ``name``, as written."""
        return self.header[self.usecols[self.used.index(name)]]

    def index(self, name: str) -> int:
        """Position of canonical column ``name`` in a parsed row."""
        return self.used.index(name)

    @property
    def has_id(self) -> bool:
        return "id" in self.used

    @property
    def velocity(self) -> tuple[str, str] | None:
        names = (f"v{self.across}", f"v{self.vertical}")
        return names if all(n in self.used for n in names) else None

    def shown(self) -> str:
        return (self.delimiter or " ").join(self.header)


# -- the CSV importer -------------------------------------------------------------------------
def import_csv(source: str | os.PathLike, output: str | os.PathLike, *,
               width: float | None = None, height: float | None = None,
               length_unit: str | None = None, time_unit: str | None = None,
               vertical_axis: str | None = None) -> Path:
    """Import a CSV file of particle positions (one row per particle and frame) as a
    trajectory file.

    The format (header names, delimiter, decimal comma, units, axes, row order) is described
    in the module docstring and docs/definitions.md, CSV import. The lap counter is derived
    from the positions by the minimal-image rule on the vertical axis (docs/definitions.md,
    Pass direction).

    Parameters
    ----------
    source : str or os.PathLike
        The CSV file, plain or gzip-compressed.
    output : str or os.PathLike
        The trajectory file (HDF5) to write; it appears only when complete.
    width, height : float, optional
        Riser width W and height H, m (whatever the file's unit); by default the paper's
        0.09 x 0.95 m riser. Positions must lie in 0..W across and 0..H vertically.
    length_unit : {"m", "cm", "mm"}, optional
        Unit of positions (and, over ``time_unit``, velocities) in columns whose header
        gives none; default m.
    time_unit : {"s", "ms"}, optional
        Unit of t where the header gives none; default s.
    vertical_axis : {"x", "y", "z"}, optional
        The file's vertical axis; required for a file with a z column (default y otherwise).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        On bad input (a malformed header or row, an unknown unit, a z column without
        ``vertical_axis``, a particle missing from a frame or entering later, unevenly
        spaced frames, a position outside the riser, ...); no file is left behind.
    """
    path = check_source(source)
    output = check_output(output, path)
    label = str(path)
    width = DEFAULT_WIDTH if width is None else float(width)
    height = DEFAULT_HEIGHT if height is None else float(height)
    check_units(length_unit, time_unit)
    if vertical_axis is not None and vertical_axis not in AXES:
        raise InputError(f"--vertical-axis {vertical_axis!r}: choose x, y or z")
    options = {"length_unit": length_unit, "time_unit": time_unit,
               "vertical_axis": vertical_axis}
    with removing_new_folders(output), reading(label):
        try:
            with open_text(path) as fh:
                layout = read_layout(fh, label, **options)
                blocks = _row_blocks(fh, layout, label, streaming=True)
                _write(output, path, layout, blocks, width, height, "as written")
            return output
        except _Unsorted:
            pass
        with open_text(path) as fh:     # rows out of time order: read whole, sort, write
            layout = read_layout(fh, label, **options)
            rows = list(_row_blocks(fh, layout, label, streaming=False))
        rows = np.concatenate(rows) if rows else np.empty((0, len(layout.used)))
        keys = (rows[:, layout.index("id")], rows[:, layout.index("t")]) if layout.has_id else (
            rows[:, layout.index("t")],)
        rows = rows[np.lexsort(keys)]
        _write(output, path, layout, iter([rows]), width, height,
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
        raise InputError(f"--length-unit {length_unit!r}: choose m, cm or mm")
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise InputError(f"--time-unit {time_unit!r}: choose s or ms")


def _write(output: Path, path: Path, layout: CsvLayout, blocks: Iterator[np.ndarray],
           width: float, height: float, row_order: str) -> None:
    """Split row blocks into frames and write them (the writer is discarded on an error)."""
    label = str(path)
    it = layout.index("t")
    frames = _frames(blocks, it)
    first = next(frames, None)
    if first is None:
        raise InputError(f"{label}: no data rows after the header")
    reference = (np.unique(whole_ids(first[0][:, layout.index("id")], label)) if layout.has_id
                 else np.zeros(1, dtype=np.int64))
    velocity = layout.velocity
    parameters = {
        "source_file": path.name, "format": "csv", "columns": layout.header,
        "delimiter": _DELIMITERS[layout.delimiter],
        "decimal_mark": "comma" if layout.decimal_comma else "point",
        "units": layout.units, "ignored_columns": layout.ignored,
        "vertical_axis": layout.vertical, "across_axis": layout.across,
        "depth_axis_dropped": layout.depth,
        "position_columns": [layout.across, layout.vertical],
        "velocity_columns": list(velocity) if velocity else [],
        "id_column": layout.has_id, "row_order": row_order,
        "width": width, "height": height,
    }
    with create_writer(output, reference, width=width, height=height, source="import:csv",
                       parameters=parameters, with_velocity=velocity is not None,
                       label=label) as writer:
        for rows, last in progress(itertools.chain([first], frames), label):
            _append_frame(writer, rows, layout, reference, label, last)


def _append_frame(writer: TrajectoryWriter, rows: np.ndarray, layout: CsvLayout,
                  reference: np.ndarray, label: str, last: bool) -> None:
    """Put one frame's rows into the reference id order and append it."""
    time = float(rows[0, layout.index("t")])
    where = f"{label}: frame at t = {time:g} s"
    if layout.has_id:
        ids = whole_ids(rows[:, layout.index("id")], where)
        try:
            order = frame_order(ids, reference, where,
                                "; the file ends there (truncated?)" if last else "")
        except InputError as exc:
            if np.unique(ids).size != ids.size:
                raise InputError(f"{exc} (two rows for one particle at one time)") from None
            raise InputError(f"{exc}; particles that enter or leave the view are not "
                             "supported yet") from None
        if order is not None:
            rows = rows[order]
    elif rows.shape[0] > 1:
        raise InputError(f"{where}: {rows.shape[0]} rows at this time, but the file has no id "
                         "column, so it is read as one tracer; add an id column for several "
                         "particles")
    position = rows[:, [layout.index(layout.across), layout.index(layout.vertical)]]
    _check_inside(position, writer, layout, reference, time, label)
    velocity = layout.velocity
    velocity = rows[:, [layout.index(v) for v in velocity]] if velocity else None
    writer.append(time, position, velocity)


def _check_inside(position: np.ndarray, writer: TrajectoryWriter, layout: CsvLayout,
                  ids: np.ndarray, time: float, label: str) -> None:
    """Refuse a particle outside 0..W x 0..H, naming the column and the value as written."""
    tol = POSITION_TOLERANCE
    limits = np.array([writer.width, writer.height])
    with np.errstate(invalid="ignore"):     # not finite: refused by the writer, by name
        outside = np.isfinite(position) & ((position < -tol) | (position > limits + tol))
    if not outside.any():
        return
    p, k = (int(v) for v in np.argwhere(outside)[0])
    axis = (layout.across, layout.vertical)[k]
    unit = layout.units[axis]
    written = position[p, k] * LENGTH_UNITS[unit]
    hint = ("; if the file is not in m, give --length-unit cm|mm" if layout.unit_from[axis] ==
            "default" else "")
    raise InputError(
        f"{label}: particle {int(ids[p])} at t = {time:g} s lies outside the domain "
        f"0..{writer.width:g} x 0..{writer.height:g} m: {layout.column(axis)!r} = {written:g} "
        f"{unit}; positions are measured from the riser's lower corner, {layout.across} across "
        f"and {layout.vertical} vertical (set the riser with --width and --height){hint}")


# -- the header ---------------------------------------------------------------------------------
def read_layout(fh: TextIO, label: str, *, length_unit: str | None = None,
                time_unit: str | None = None, vertical_axis: str | None = None) -> CsvLayout:
    """Read the header (and a few data rows) of an open CSV file and tell how to read it.

    Parameters
    ----------
    fh : TextIO
        The file, at its start; left after the rows returned in ``pending``.
    label : str
        Names the file in error messages.
    length_unit, time_unit, vertical_axis : str, optional
        As for :func:`import_csv`.

    Returns
    -------
    CsvLayout
        Delimiter, decimal mark, columns, units and axes; ``pending`` holds the data lines
        read ahead (from ``first_data_line`` on).

    Raises
    ------
    InputError
        For no header, a missing or repeated column, an unknown or contradicting unit, a z
        column without ``vertical_axis``, or a vertical axis the file does not have.
    """
    header_text, header_line, pending, first_data_line = _find_header(fh, label)
    data = [line for line in pending if line.split("#", 1)[0].strip()]
    delimiter = _delimiter(header_text, data[0] if data else None)
    decimal_comma = delimiter != "," and any("," in line.split("#", 1)[0] for line in data)
    header = [name.strip().strip('"').strip("'").strip() for name in _split(header_text,
                                                                               delimiter)]
    shown = (delimiter or " ").join(header)
    canonical: dict[str, int] = {}
    units: dict[str, str | None] = {}
    ignored = []
    for k, name in enumerate(header):
        key, unit = _canonical(name)
        if key is None:
            ignored.append((k, name or f"column {k + 1} (no name)"))
            continue
        if key in canonical:
            raise InputError(f"{label}: column {key!r} appears twice in the header {shown!r} "
                             f"({header[canonical[key]]!r} and {name!r})")
        canonical[key] = k
        units[key] = unit
    if "t" not in canonical:
        raise InputError(f"{label}: missing column 't' in the header {shown!r}; {_EXPECTED}")
    vertical, across, depth = _axes(canonical, vertical_axis, shown, label)
    for v in (f"v{across}", f"v{vertical}"):
        other = f"v{across}" if v == f"v{vertical}" else f"v{vertical}"
        if v in canonical and other not in canonical:
            raise InputError(f"{label}: the header {shown!r} has only one of v{across}, "
                             f"v{vertical} (velocity across and along the vertical axis "
                             f"{vertical}); give both or neither")
    keep = {"t", "id", across, vertical, f"v{across}", f"v{vertical}"}
    for key in set(canonical) - keep:
        k = canonical.pop(key)
        ignored.append((k, header[k] + " (depth axis)"))
        units.pop(key)
    used = sorted(canonical, key=canonical.get)
    si, divisors = _units(used, units, length_unit, time_unit, header, canonical, label)
    unit_from = {name: "header" if units[name] else "option" if (
        length_unit if name in AXES else time_unit) else "default" for name in used}
    return CsvLayout(header=header, delimiter=delimiter, decimal_comma=decimal_comma, used=used,
                     usecols=[canonical[n] for n in used], divisors=divisors, units=si,
                     ignored=[name for _, name in sorted(ignored)], vertical=vertical,
                     across=across, depth=depth, header_line=header_line,
                     first_data_line=first_data_line, unit_from=unit_from, pending=pending)


def _find_header(fh: TextIO, label: str) -> tuple[str, int, list[str], int]:
    """The header text, its line number, the data lines read ahead and the first one's number.

    The header is the first non-blank line not starting with '#'; where that line is a row of
    numbers, the last '#' line before it that names columns (without the '#').
    """
    line_no, comment, comment_no = 0, None, 0
    while line := fh.readline():
        line_no += 1
        text = line.lstrip("\ufeff").strip()
        if not text:
            continue
        if text.startswith("#"):
            if _names_columns(text.lstrip("#")):
                comment, comment_no = text.lstrip("#").strip(), line_no
            continue
        if not _is_data(text):
            return text, line_no, _read_ahead(fh, []), line_no + 1
        if comment is not None:
            return comment, comment_no, _read_ahead(fh, [line]), line_no
        raise InputError(f"{label}: line {line_no} is not a header ({text!r}); {_EXPECTED}")
    raise InputError(f"{label}: empty file (no header line)")


def _read_ahead(fh: TextIO, lines: list[str]) -> list[str]:
    """Read lines until SNIFF_ROWS data rows (or the end) are in ``lines``."""
    while sum(1 for line in lines if line.split("#", 1)[0].strip()) < SNIFF_ROWS:
        line = fh.readline()
        if not line:
            break
        lines.append(line)
    return lines


def _is_data(text: str) -> bool:
    """Whether a line is a row of numbers (any delimiter, either decimal mark)."""
    fields = [f for f in re.split(r"[;,\s]+", text) if f]
    return bool(fields) and all(_is_number(f) for f in fields)


def _names_columns(text: str) -> bool:
    """Whether a '#' line names columns: t and at least two known position columns."""
    keys = {_canonical(name)[0] for name in _split(text, _delimiter(text, None))}
    return "t" in keys and len(keys & set(AXES)) >= 2


def _delimiter(header: str, data: str | None) -> str | None:
    """The delimiter: the first of ';', tab, ',' in the header under which the first data row
    has as many fields as the header (None: whitespace)."""
    candidates = [d for d in (";", "\t", ",") if d in header] + [None]
    if data is None:
        return candidates[0]
    data = data.split("#", 1)[0]
    for delimiter in candidates + [d for d in (";", "\t", ",", None) if d not in candidates]:
        n = len(_split(header, delimiter))
        if n >= 2 and len(_split(data, delimiter)) == n:
            return delimiter
    return candidates[0]     # the rows are then refused line by line


def _split(text: str, delimiter: str | None) -> list[str]:
    return text.split() if delimiter is None else text.strip("\r\n").split(delimiter)


def _canonical(name: str) -> tuple[str | None, str | None]:
    """(canonical column name or None, unit written in the header or None)."""
    unit = None
    match = _UNIT.match(name)
    if match:
        name, unit = match.group(1), match.group(2).strip() or None
    key = " ".join(name.strip().strip('"').strip("'").replace("_", " ").lower().split())
    return _ALIASES.get(key), unit


def _axes(canonical: dict[str, int], vertical_axis: str | None, shown: str,
          label: str) -> tuple[str, str, str | None]:
    """(vertical, across, depth) axis names; refuses a z column without a vertical axis."""
    present = [a for a in AXES if a in canonical]
    if vertical_axis is None:
        if "z" in present:
            raise InputError(
                f"{label}: the header {shown!r} has a z column (3D positions): say which axis "
                "is vertical with --vertical-axis x|y|z (nothing is guessed; a 2D file would "
                "take y, LIGGGHTS and EDEM usually put gravity along -z)")
        vertical_axis = "y"
    if vertical_axis not in AXES:
        raise InputError(f"--vertical-axis {vertical_axis!r}: choose x, y or z")
    if vertical_axis not in present:
        if vertical_axis == "y" and "z" not in present:
            raise InputError(f"{label}: missing column 'y' in the header {shown!r}; {_EXPECTED}")
        raise InputError(f"{label}: --vertical-axis {vertical_axis} but the header {shown!r} has "
                         f"no {vertical_axis} column")
    others = [a for a in present if a != vertical_axis]
    if not others:
        missing = "x" if vertical_axis != "x" else "y"
        raise InputError(f"{label}: missing column {missing!r} in the header {shown!r} (no "
                         f"position across the riser); {_EXPECTED}")
    return vertical_axis, others[0], others[1] if len(others) > 1 else None


def _units(used: list[str], units: dict[str, str | None], length_unit: str | None,
           time_unit: str | None, header: list[str], canonical: dict[str, int],
           label: str) -> tuple[dict[str, str], list[float]]:
    """Each used column's unit (as recorded) and divisor to SI; refuses unknown or
    contradicting units."""
    recorded, divisors = {}, []
    for name in used:
        written = units[name]
        if name == "id":
            divisors.append(1.0)
            continue
        column = header[canonical[name]]
        if name == "t":
            unit = _unit(written, TIME_UNITS, time_unit, "--time-unit", column, label)
            divisor = TIME_UNITS[unit]
        elif name in AXES:
            unit = _unit(written, LENGTH_UNITS, length_unit, "--length-unit", column, label)
            divisor = LENGTH_UNITS[unit]
        else:
            length, time = length_unit or "m", time_unit or "s"
            if written is not None:
                parts = written.replace(" ", "").split("/")
                if len(parts) != 2 or parts[0] not in LENGTH_UNITS or parts[1] not in TIME_UNITS:
                    raise InputError(f"{label}: column {column!r}: unit {written!r} is not "
                                     "known; velocities in m/s, cm/s or mm/s (or per ms)")
                length, time = parts
            unit = f"{length}/{time}"
            divisor = LENGTH_UNITS[length] / TIME_UNITS[time]
        recorded[name] = unit
        divisors.append(divisor)
    return recorded, divisors


def _unit(written: str | None, known: dict[str, float], option: str | None, flag: str,
          column: str, label: str) -> str:
    if written is None:
        return option or next(iter(known))
    if written not in known:
        raise InputError(f"{label}: column {column!r}: unit {written!r} is not known; "
                         f"{flag} takes {', '.join(known)}")
    if option is not None and option != written:
        raise InputError(f"{label}: column {column!r} is in {written} but {flag} {option} was "
                         f"given; drop {flag} or correct the header")
    return written


def _is_number(text: str) -> bool:
    try:
        float(text.replace(",", "."))
    except ValueError:
        return False
    return True


# -- the rows -----------------------------------------------------------------------------------
def _row_blocks(fh: TextIO, layout: CsvLayout, label: str, *, streaming: bool
                ) -> Iterator[np.ndarray]:
    """Parse the data rows in blocks of about CHUNK_CHARS characters: arrays [rows, used
    columns] in SI units. ``streaming``: raise _Unsorted where the times decrease."""
    it = layout.index("t")
    iid = layout.index("id") if layout.has_id else None
    line_no, last = layout.first_data_line, None
    lines = layout.pending
    while lines or (lines := fh.readlines(CHUNK_CHARS)):
        values = _parse_rows(lines, line_no, layout, label)
        _check_keys(values, it, iid, lines, line_no, label)
        if streaming and values.shape[0]:
            t = values[:, it]
            if (last is not None and t[0] < last) or np.any(t[1:] < t[:-1]):
                raise _Unsorted
            last = t[-1]
        line_no += len(lines)
        lines = []
        if values.shape[0]:
            yield values


def _parse_rows(lines: list[str], line_no: int, layout: CsvLayout, label: str) -> np.ndarray:
    """Rows of numbers from CSV lines (blank and '#' lines skipped); line_no numbers lines[0]."""
    text = [line.replace(",", ".") for line in lines] if layout.decimal_comma else lines
    n = len(layout.header)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # a block of blank lines
            values = np.loadtxt(text, delimiter=layout.delimiter, dtype=np.float64, ndmin=2,
                                usecols=None if len(layout.usecols) == n else layout.usecols)
    except ValueError as exc:
        raise InputError(_locate_bad_row(lines, line_no, layout, label, exc)) from None
    if values.size == 0:
        return np.empty((0, len(layout.used)))
    if values.shape[1] != len(layout.used):
        line = _data_line_numbers(lines, line_no)[0]
        raise InputError(f"{label}: line {line}: {values.shape[1]} values, the header names "
                         f"{n} columns")
    for k, divisor in enumerate(layout.divisors):
        if divisor != 1.0:
            values[:, k] /= divisor
    return values


def _locate_bad_row(lines: list[str], line_no: int, layout: CsvLayout, label: str,
                    exc: Exception) -> str:
    """Message naming the first line of a block that numpy could not parse."""
    n = len(layout.header)
    for k, line in enumerate(lines):
        content = line.split("#", 1)[0].strip()
        if not content:
            continue
        cut = "" if line.endswith("\n") else " (the file ends inside this row: truncated?)"
        fields = _split(content, layout.delimiter)
        if len(fields) != n and (len(fields) < n or len(layout.usecols) == n):
            return (f"{label}: line {line_no + k}: {len(fields)} values, the header names "
                    f"{n} columns{cut}")
        for name, col in zip(layout.used, layout.usecols):
            value = fields[col].strip()
            number = value.replace(",", ".") if layout.decimal_comma else value
            if not value:
                return f"{label}: line {line_no + k}: column {name!r} is empty{cut}"
            if not _is_plain_number(number):
                mark = ("; the first rows use a decimal comma" if layout.decimal_comma else
                        "; a decimal comma needs a semicolon, tab or space delimiter"
                        if "," in value and layout.delimiter == "," else "")
                return (f"{label}: line {line_no + k}: {value!r} in column {name!r} is "
                        f"not a number{mark}{cut}")
    return f"{label}: lines {line_no}-{line_no + len(lines) - 1}: {exc}"


def _is_plain_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _data_line_numbers(lines: list[str], line_no: int) -> list[int]:
    """Line numbers of the rows that np.loadtxt returned for a block (blank lines skipped)."""
    return [line_no + k for k, line in enumerate(lines) if line.split("#", 1)[0].strip()]


def _check_keys(values: np.ndarray, it: int, iid: int | None, lines: list[str], line_no: int,
                label: str) -> None:
    """Refuse a time that is not finite or an id that is not a whole number, by line."""
    t = values[:, it]
    bad_t = ~np.isfinite(t)
    if iid is None:
        bad_id = np.zeros(t.shape, dtype=bool)
        ids = t
    else:
        ids = values[:, iid]
        bad_id = ~np.isfinite(ids) | (ids != np.round(ids))
    if not (bad_t.any() or bad_id.any()):
        return
    rows = _data_line_numbers(lines, line_no)
    if bad_t.any():
        k = int(np.argmax(bad_t))
        raise InputError(f"{label}: line {rows[k]}: time t = {t[k]:g} is not a finite number")
    k = int(np.argmax(bad_id))
    raise InputError(f"{label}: line {rows[k]}: particle id {ids[k]:g} is not a whole number")


def _frames(blocks: Iterator[np.ndarray], it: int) -> Iterator[tuple[np.ndarray, bool]]:
    """Split row blocks into frames (runs of equal t): yield (rows, is_last_frame)."""
    pending: list[np.ndarray] = []
    for values in blocks:
        t = values[:, it]
        cuts = np.flatnonzero(t[1:] != t[:-1]) + 1
        if cuts.size == 0 and (not pending or pending[-1][0, it] == t[0]):
            pending.append(values)
            continue
        if pending and pending[-1][0, it] != t[0]:
            cuts = np.concatenate([[0], cuts])
        start = 0
        for cut in cuts:
            pending.append(values[start:cut])
            rows = np.concatenate(pending) if len(pending) > 1 else pending[0]
            if rows.shape[0]:
                yield rows, False
            pending, start = [], cut
        pending = [values[start:]]
    if pending:
        yield (np.concatenate(pending) if len(pending) > 1 else pending[0]), True
