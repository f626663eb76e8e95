"""Reading a CSV file's header: columns, delimiter, decimal mark, units and axes (the rules
are in :mod:`cfbmarkov.io.csv`)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import TextIO

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.io._common import IdCodes

#: the source's axes, in the order of a region's ranges
AXES = ("x", "y", "z")
#: length and time units: the number a value is divided by to give m or s
LENGTH_UNITS = {"m": 1.0, "cm": 100.0, "mm": 1000.0, "um": 1e6}
TIME_UNITS = {"s": 1.0, "ms": 1000.0}
#: other spellings of those units in headers (TrackMate writes "micron")
UNIT_SPELLINGS = {"\u00b5m": "um", "\u03bcm": "um", "micron": "um", "microns": "um",
                  "micrometre": "um", "micrometer": "um", "micrometres": "um",
                  "micrometers": "um", "sec": "s", "second": "s", "seconds": "s",
                  "msec": "ms"}
#: units that count pixels or frames: no scale to metres or seconds is in the file
COUNTS = {"pixel": "pixels", "pixels": "pixels", "px": "pixels", "frame": "frames",
          "frames": "frames"}
#: characters of text parsed per call (about 70000 rows of six columns)
CHUNK_CHARS = 1 << 22
#: data rows read after the header to tell the delimiter and the decimal mark
SNIFF_ROWS = 5
_EXPECTED = ("expected t, x, y and optionally id, z, vx, vy, vz (or spreadsheet names such as "
             "'Time (s)', 'Particle ID', 'Position X (m)'); other columns are ignored")
_ALIASES = {"t": "t", "time": "t", "position t": "t"}
#: the columns that may hold the particle id, most specific first: a track's id
#: (TrackMate's TRACK_ID; its ID numbers detections), trackpy's ``particle``, pept's ``label``
#: (a trajectory's index, -1 for noise), then the plain id names
ID_COLUMNS = {"track id": 0, "trackid": 0, "track": 0, "particle": 1, "label": 2, "id": 3,
              "particle id": 3, "particleid": 3, "pid": 3, "tracer": 3, "tracer id": 3,
              "tracerid": 3, "trajectory": 3, "trajectory id": 3, "traj": 3}
#: ids that mark rows belonging to no particle, by the id column's kind: pept's noise label
#: -1; a TrackMate spot without a track has an empty TRACK_ID, read as -1
NOISE_IDS = {"label": -1, "track id": -1}
#: units written as words in some exports (TrackMate's '(sec)')
for _axis in AXES:
    _ALIASES.update({_axis: _axis, f"position {_axis}": _axis, f"pos {_axis}": _axis,
                     f"v{_axis}": f"v{_axis}", f"velocity {_axis}": f"v{_axis}",
                     f"vel {_axis}": f"v{_axis}", f"v {_axis}": f"v{_axis}"})
#: ParaView's CSV export names array components 'name:k' and the point coordinates 'Points:k'
for _k, _axis in enumerate(AXES):
    _ALIASES.update({f"points:{_k}": _axis, **{f"{v}:{_k}": f"v{_axis}" for v in
                                               ("v", "vel", "velocity")}})
_UNIT = re.compile(r"^(.*?)\s*[(\[]\s*([^)\]]*?)\s*[)\]]$")
_DELIMITERS = {";": "semicolon", "\t": "tab", "|": "vertical bar", ",": "comma",
               None: "whitespace"}


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
    dropped: str | None = None
    #: the id column as written, the other id-like columns not used, and the id marking
    #: rows of no particle (dropped and counted in ``noise_rows``)
    id_column: str | None = None
    id_others: list[str] = field(default_factory=list)
    noise_id: int | None = None
    noise_rows: int = 0
    #: rows placed on the riser, and those of them outside its region (absent there)
    placed_rows: int = 0
    outside_rows: int = 0
    #: lines above the header skipped as a title, and rows below it skipped as
    #: descriptions (TrackMate's names, short names and units rows)
    title_lines: list[str] = field(default_factory=list)
    description_rows: int = 0
    #: the exact ids behind the codes that the id column of parsed rows holds
    id_codes: IdCodes = field(default_factory=IdCodes, repr=False)

    def ids(self, rows: np.ndarray) -> np.ndarray:
        """The exact int64 particle ids of parsed rows (their id column holds codes)."""
        return self.id_codes.decode(rows[:, self.index("id")])

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
    def axes(self) -> tuple[str, ...]:
        """The stored axes: (across, vertical[, depth])."""
        return (self.across, self.vertical) + ((self.depth,) if self.depth else ())

    @property
    def velocity(self) -> tuple[str, ...] | None:
        """Velocity columns along the stored axes, or None where the file has none."""
        names = tuple(f"v{a}" for a in self.axes)
        return names if all(n in self.used for n in names) else None

    def shown(self) -> str:
        """The header as the file writes it (its names joined by its delimiter), for
        messages."""
        return (self.delimiter or " ").join(self.header)


def read_layout(fh: TextIO, label: str, *, length_unit: str | None = None,
                time_unit: str | None = None, vertical_axis: str | None = None,
                keep_depth: bool = True) -> CsvLayout:
    """Read the header (and a few data rows) of an open CSV file and tell how to read it.

    Parameters
    ----------
    fh : TextIO
        The file, at its start; left after the rows returned in ``pending``.
    label : str
        Names the file in error messages.
    length_unit, time_unit, vertical_axis : str, optional
        As for :func:`~cfbmarkov.io.csv.import_csv`.
    keep_depth : bool, optional
        Keep the depth axis of 3D positions (else it is dropped and recorded).

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
    header_text, header_line, pending, first_data_line, titles = _find_header(fh, label)
    described, pending = _description_rows(pending)
    first_data_line += len(described)
    data = [line for line in pending if line.split("#", 1)[0].strip()]
    delimiter = _delimiter(header_text, data[0] if data else None)
    decimal_comma = delimiter != "," and any("," in line.split("#", 1)[0] for line in data)
    header = [name.strip().strip('"').strip("'").strip()
              for name in _header_names(header_text, delimiter)]
    shown = (delimiter or " ").join(header)
    row_units = _units_row(described, delimiter, len(header))
    canonical: dict[str, int] = {}
    units: dict[str, str | None] = {}
    ignored = []
    id_kind, id_others = _id_column(header, shown, label)
    for k, name in enumerate(header):
        key, unit = _canonical(name)
        if unit is None:
            unit = row_units[k]
        if _id_key(name) is not None:
            key = "id" if id_kind is not None and k == id_kind[1] else None
            if key is None:
                ignored.append((k, f"{name} (not the particle id)"))
                continue
        if key is None:
            ignored.append((k, name or f"column {k + 1} (no name)"))
            continue
        if key in canonical:
            raise InputError(f"{label}: column {key!r} appears twice in the header {shown!r} "
                             f"({header[canonical[key]]!r} and {name!r})")
        canonical[key] = k
        units[key] = unit
    if "t" not in canonical:
        raise InputError(f"{label}: missing column 't' in the header {shown!r}"
                         f"{_no_time_advice(header, id_kind) or '; ' + _EXPECTED}")
    vertical, across, depth = _axes(canonical, vertical_axis, shown, label)
    for v in (f"v{across}", f"v{vertical}"):
        other = f"v{across}" if v == f"v{vertical}" else f"v{vertical}"
        if v in canonical and other not in canonical:
            raise InputError(f"{label}: the header {shown!r} has only one of v{across}, "
                             f"v{vertical} (velocity across and along the vertical axis "
                             f"{vertical}); give both or neither")
    dropped = None
    if depth is not None and not keep_depth:
        depth, dropped = None, depth
    keep = {"t", "id", across, vertical, f"v{across}", f"v{vertical}"}
    if depth is not None:
        keep |= {depth, f"v{depth}"}
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
                     first_data_line=first_data_line, unit_from=unit_from, pending=pending,
                     dropped=dropped, id_column=None if id_kind is None else header[id_kind[1]],
                     id_others=id_others,
                     noise_id=None if id_kind is None else NOISE_IDS.get(id_kind[0]),
                     title_lines=titles, description_rows=len(described))


def _id_key(name: str) -> str | None:
    """The kind of id column ``name`` is (a key of :data:`ID_COLUMNS`), or None."""
    match = _UNIT.match(name)
    if match:
        name = match.group(1)
    key = " ".join(name.strip().strip('"').strip("'").replace("_", " ").lower().split())
    return key if key in ID_COLUMNS else None


def _no_time_advice(header: list[str], id_kind) -> str:
    """What to give a file that numbers its frames instead of timing them (trackpy's
    ``frame`` and ``particle``): a t column from the frame rate; empty for other files."""
    frame = next((name for name in header if name.strip().lower() in ("frame", "frame_no",
                                                                       "frame number")), None)
    if frame is None and any(name.strip() == "TimeStep" for name in header) and any(
            name.strip().startswith("Points:") for name in header):
        # ParaView's "Save Data" of a series with "Write Time Steps" but not "Add Time"
        return (": ParaView wrote the step index 'TimeStep' but no time: save the data again "
                "with \"Add Time\" ticked (a 'Time' column), or add a column t in s")
    if frame is None:
        return ""
    found = f"frame numbers in {frame!r}"
    if id_kind is not None:
        found += f" and particle ids in {header[id_kind[1]]!r}"
    pixels = (" (trackpy's x and y are in pixels: convert them to m, or to mm or cm with "
              "--length-unit)" if id_kind is not None and id_kind[0] == "particle" else "")
    return (f": it holds {found} but no times, and import takes no frame rate: add a column "
            f"t = {frame} / frame rate (s), e.g. in pandas df['t'] = df[{frame!r}] / fps, "
            f"and import that file{pixels}")


def _id_column(header: list[str], shown: str, label: str):
    """((kind, index) of the particle id column, or None; the other id-like columns' names):
    the most specific of :data:`ID_COLUMNS` present."""
    found = [(ID_COLUMNS[key], k, key) for k, name in enumerate(header)
             if (key := _id_key(name)) is not None]
    if not found:
        return None, []
    found.sort()
    if len(found) > 1 and found[0][0] == found[1][0]:
        raise InputError(f"{label}: columns {header[found[0][1]]!r} and {header[found[1][1]]!r} "
                         f"of the header {shown!r} both name the particle id; keep one")
    rank, k, key = found[0]
    return (key, k), [header[j] for _, j, _ in found[1:]]


def _description_rows(pending: list[str]) -> tuple[list[str], list[str]]:
    """(rows right below the header that hold no number, the rest): TrackMate writes three,
    the columns' names, short names and units, before its first data row (whose text
    fields, such as its LABEL ``ID0``, make it no row of numbers, but it holds numbers)."""
    described = []
    while len(described) < 3 and pending and pending[0].strip() and \
            not pending[0].lstrip().startswith("#") and not any(
                _is_number(f.strip().strip('"')) for f in re.split(r"[;,|\s]", pending[0])
                if f.strip()):
        described.append(pending.pop(0))
    return described, pending


def _units_row(described: list[str], delimiter: str | None, n: int) -> list[str | None]:
    """Units per column from a description row that holds only units in parentheses
    (TrackMate's ``,,,(quality),(mm),(mm),(mm),(sec)``), else None for each."""
    for row in described:
        fields = [f.strip().strip('"') for f in _split(row, delimiter)]
        if len(fields) == n and any(fields) and all(
                not f or (f.startswith("(") and f.endswith(")")) for f in fields):
            units = [f[1:-1].strip() or None if f else None for f in fields]
            return units
    return [None] * n


def _find_header(fh: TextIO, label: str) -> tuple[str, int, list[str], int, list[str]]:
    """The header text, its line number, the data lines read ahead, the first one's number
    and the title lines skipped above the header.

    The header is the first non-blank line not starting with '#'; where that line is a row of
    numbers, the last '#' line before it that names columns (without the '#'). A first line
    that names no time column, followed by one that does, is a title (a spreadsheet's
    ``Riser PTV run 12, air at 25 °C``) and is skipped.
    """
    line_no, comment, comment_no = 0, None, 0
    titles: list[str] = []
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
            if not titles and not _names_time(text):
                following = fh.readline()
                if following.strip() and not _is_data(following) and _names_time(following):
                    titles.append(text.strip("\t ,;"))
                    line_no += 1
                    return following.strip(), line_no, _read_ahead(fh, []), line_no + 1, titles
                return text, line_no, _read_ahead(fh, [following] if following else []), \
                    line_no + 1, titles
            return text, line_no, _read_ahead(fh, []), line_no + 1, titles
        if comment is not None:
            return comment, comment_no, _read_ahead(fh, [line]), line_no, titles
        raise InputError(f"{label}: line {line_no} is not a header ({text!r}); {_EXPECTED}")
    raise InputError(f"{label}: empty file (no header line): nothing to import; check the "
                     "path, or that the export wrote the file")


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


def _names_time(text: str) -> bool:
    """Whether a line names a time column under any delimiter."""
    return any(_canonical(name)[0] == "t" for name in re.split(r"[;,\t]|\s{2,}| ", text.strip()))


def _names_columns(text: str) -> bool:
    """Whether a '#' line names columns: t and at least two known position columns."""
    keys = {_canonical(name)[0] for name in _header_names(text, _delimiter(text, None))}
    return "t" in keys and len(keys & set(AXES)) >= 2


def _delimiter(header: str, data: str | None) -> str | None:
    """The delimiter: the first of ';', tab, '|', ',' in the header under which the first
    data row has as many fields as the header (None: whitespace)."""
    candidates = [d for d in (";", "\t", "|", ",") if d in header] + [None]
    if data is None:
        return candidates[0]
    data = data.split("#", 1)[0]
    for delimiter in candidates + [d for d in (";", "\t", "|", ",", None)
                                   if d not in candidates]:
        n = len(_header_names(header, delimiter))
        if n >= 2 and len(_split(data, delimiter)) == n:
            return delimiter
    return candidates[0]     # the rows are then refused line by line


def _split(text: str, delimiter: str | None) -> list[str]:
    return text.split() if delimiter is None else text.strip("\r\n").split(delimiter)


def _header_names(text: str, delimiter: str | None) -> list[str]:
    """The names of a header line; under whitespace, a unit in brackets written apart from
    its name (``x (mm)``, ``v [m / s]``) stays with the name before it."""
    fields = _split(text, delimiter)
    if delimiter is not None:
        return fields
    names: list[str] = []
    open_unit = False
    for token in fields:
        # a bracket after a name without a unit is that name's unit; after a unit, a
        # column of its own (``y (mm) (error)``)
        if names and (open_unit or (token[:1] in "([" and not _is_number(token)
                                    and not names[-1].endswith((")", "]")))):
            names[-1] += " " + token
            open_unit = not token.endswith((")", "]"))
        else:
            names.append(token)
            open_unit = False
    return names


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
                "take y, LIGGGHTS and EDEM usually put gravity along -z); a 2D export whose z "
                "is all 0 (TrackMate, PTV): --vertical-axis y --drop-depth")
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
                parts = [_spelled(part) for part in written.replace(" ", "").split("/")]
                if len(parts) != 2 or parts[0] not in LENGTH_UNITS or parts[1] not in TIME_UNITS:
                    raise InputError(f"{label}: column {column!r}: unit {written!r} is not "
                                     "known; velocities in m/s, cm/s, mm/s or um/s (or per ms)")
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
    shown, written = written, _spelled(written)
    if written in COUNTS:
        scale = ("the pixel size (m per pixel)" if COUNTS[written] == "pixels"
                 else "the frame rate (frames per second)")
        raise InputError(f"{label}: column {column!r} is in {shown} (a count of "
                         f"{COUNTS[written]}, with no scale in the file): convert it with "
                         f"{scale} to one of {', '.join(known)} and name that unit in the "
                         "header")
    if written not in known:
        raise InputError(f"{label}: column {column!r}: unit {shown!r} is not known; convert "
                         f"the column to one of {', '.join(known)} and name that unit in the "
                         f"header ({flag} sets the unit of columns that name none)")
    if option is not None and option != written:
        raise InputError(f"{label}: column {column!r} is in {written} but {flag} {option} was "
                         f"given; drop {flag} or correct the header")
    return written


def _spelled(unit: str) -> str:
    """A unit as :data:`LENGTH_UNITS` and :data:`TIME_UNITS` name it (µm, micron: um)."""
    return UNIT_SPELLINGS.get(unit.strip().lower(), unit.strip())


def _is_number(text: str) -> bool:
    try:
        float(text.replace(",", "."))
    except ValueError:
        return False
    return True
