"""Reading legacy VTK files (``# vtk DataFile Version ...``) as particle frames.

What LIGGGHTS ``dump custom/vtk`` and LAMMPS ``dump vtk`` write with a ``.vtk`` name (one
file per time step): a POLYDATA (or UNSTRUCTURED_GRID) dataset whose POINTS are the particle
centres and whose POINT_DATA holds the per-particle arrays (``id``, ``type``, ``v``, ...) as
SCALARS, VECTORS or a FIELD; beside each, a ``*_boundingBox.vtk`` RECTILINEAR_GRID of two
coordinates per axis: the simulation box. ASCII and BINARY (big-endian, as the format
prescribes) files of format versions 2 to 5.1 are read; the cells (VERTICES, CELLS, ...) are
skipped. The format: *VTK User's Guide*, "VTK File Formats" (Kitware, 11th ed., 2010) and
``vtkDataReader.cxx`` for version 5.1's OFFSETS/CONNECTIVITY cells.
"""

from __future__ import annotations

import gzip
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cfbmarkov._names import check_not_pipe
from cfbmarkov.errors import InputError

MAGIC = b"# vtk DataFile"
#: legacy type names -> big-endian numpy types of their binary form
_TYPES = {"unsigned_char": ">u1", "char": ">i1", "unsigned_short": ">u2", "short": ">i2",
          "unsigned_int": ">u4", "int": ">i4", "unsigned_long": ">u8", "long": ">i8",
          "float": ">f4", "double": ">f8", "vtktypeint64": ">i8", "vtktypeuint64": ">u8",
          "vtkidtype": ">i8"}
#: cell blocks skipped (their first number is the cell count, the second the list size)
_CELLS = ("VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS", "CELLS")


@dataclass
class LegacyData:
    """The content of a legacy VTK file that particle imports use.

    Attributes
    ----------
    dataset : str
        The DATASET kind (``POLYDATA``, ``UNSTRUCTURED_GRID``, ``RECTILINEAR_GRID``, ...).
    points : numpy.ndarray of float64, shape (N, 3), or None
        The POINTS.
    point_data : dict of str to numpy.ndarray
        POINT_DATA arrays by name, shape (N,) or (N, k); integer arrays stay int64.
    field_data : dict of str to numpy.ndarray
        Dataset-level FIELD arrays (e.g. ``TIME``), flattened.
    coordinates : list of numpy.ndarray
        X, Y, Z_COORDINATES of a RECTILINEAR_GRID (empty otherwise).
    """

    dataset: str
    points: np.ndarray | None = None
    point_data: dict = field(default_factory=dict)
    field_data: dict = field(default_factory=dict)
    coordinates: list = field(default_factory=list)


class _Cursor:
    """Walks the bytes of a legacy file: keyword lines, then ASCII tokens or binary blocks."""

    def __init__(self, data: bytes, binary: bool, label: str):
        self.data, self.binary, self.label, self.pos = data, binary, label, 0

    def line(self) -> list[str] | None:
        """The next non-blank line's words (None at the end)."""
        data, n = self.data, len(self.data)
        while self.pos < n and data[self.pos:self.pos + 1].isspace():
            self.pos += 1
        if self.pos >= n:
            return None
        end = data.find(b"\n", self.pos)
        end = n if end < 0 else end
        words = data[self.pos:end].decode("ascii", errors="replace").split()
        self.pos = end + 1
        return words

    def peek(self) -> list[str] | None:
        """The next line's words without moving."""
        pos = self.pos
        words = self.line()
        self.pos = pos
        return words

    def values(self, count: int, vtk_type: str) -> np.ndarray:
        """``count`` values of ``vtk_type`` (integers as int64, reals as float64)."""
        kind = _TYPES.get(vtk_type.lower())
        if kind is None and self.pos >= len(self.data):   # its line is the file's last
            raise InputError(f"{self.label}: the file ends in the line that names the data "
                             f"type ({vtk_type!r}, no values after it): truncated")
        if kind is None:
            raise InputError(f"{self.label}: data type {vtk_type!r} is not read (integers, "
                             "float or double are)")
        if self.binary:
            size = np.dtype(kind).itemsize * count
            if self.pos + size > len(self.data):
                raise InputError(f"{self.label}: the file ends inside a binary block "
                                 "(truncated)")
            out = np.frombuffer(self.data, dtype=kind, count=count, offset=self.pos)
            self.pos += size
        else:
            words = self.data[self.pos:].split(None, count)
            if len(words) < count:
                raise InputError(f"{self.label}: the file ends before the {count} values of a "
                                 "block (truncated)")
            rest = words[count] if len(words) > count else b""
            self.pos = len(self.data) - len(rest)
            try:
                out = np.array(words[:count], dtype=np.int64 if kind[1] in "iu" else np.float64)
            except ValueError:
                raise InputError(f"{self.label}: a {vtk_type} block holds a value that is not a "
                                 "number") from None
        return out.astype(np.int64 if out.dtype.kind in "iu" else np.float64)


def read_legacy(path: Path) -> LegacyData:
    """Read a legacy VTK file (optionally gzipped).

    Parameters
    ----------
    path : pathlib.Path
        The file.

    Returns
    -------
    LegacyData

    Raises
    ------
    InputError
        If the file is not legacy VTK, is truncated, holds a value that is not a number, or
        uses a data type or dataset feature that is not read (named in the message).
    """
    try:
        check_not_pipe(path)
        data = path.read_bytes()
        if data[:2] == b"\x1f\x8b":
            data = gzip.decompress(data)
    except (OSError, EOFError) as exc:
        raise InputError(f"{path}: cannot read ({getattr(exc, 'strerror', None) or exc})") from None
    label = str(path)
    if not data.startswith(MAGIC):
        raise InputError(f"{label}: not a legacy VTK file (no '# vtk DataFile' first line)")
    lines = data.split(b"\n", 3)
    if len(lines) < 4:
        raise InputError(f"{label}: the header ends early (truncated)")
    mode = lines[2].strip().upper()
    if mode not in (b"ASCII", b"BINARY"):
        raise InputError(f"{label}: third line {lines[2][:20]!r} should say ASCII or BINARY")
    cursor = _Cursor(lines[3], mode == b"BINARY", label)
    head = cursor.line()
    if not head or head[0].upper() != "DATASET" or len(head) < 2:
        raise InputError(f"{label}: expected a 'DATASET' line after the header")
    out = LegacyData(dataset=head[1].upper())
    target = out.field_data
    n_points = None
    while (words := cursor.line()) is not None:
        key = words[0].upper()
        if key == "POINTS":
            n_points = _int(words, 1, label)
            out.points = cursor.values(3 * n_points, _word(words, 2, label)).reshape(n_points, 3)
            out.points = out.points.astype(np.float64)
        elif key in _CELLS:
            _skip_cells(cursor, words, label)
        elif key in ("CELL_TYPES", "DIMENSIONS", "SPACING", "ORIGIN"):
            if key == "CELL_TYPES":
                cursor.values(_int(words, 1, label), "int")
        elif key.endswith("_COORDINATES"):
            out.coordinates.append(cursor.values(_int(words, 1, label), _word(words, 2, label)
                                                 ).astype(np.float64))
        elif key == "POINT_DATA":
            target = out.point_data
        elif key == "CELL_DATA":
            target = {}
        elif key == "FIELD":
            for _ in range(_int(words, 2, label)):
                spec = cursor.line()
                if spec is None or len(spec) < 4:
                    raise InputError(f"{label}: a FIELD array line ends early (truncated)")
                ncomp, ntuples = _int(spec, 1, label), _int(spec, 2, label)
                values = cursor.values(ncomp * ntuples, spec[3])
                target[spec[0]] = values.reshape(ntuples, ncomp) if ncomp > 1 else values
        elif key in ("SCALARS", "VECTORS", "NORMALS", "COLOR_SCALARS", "TENSORS"):
            count = n_points if target is out.point_data else None
            if count is None:
                raise InputError(f"{label}: {key} outside POINT_DATA is not read")
            name = _word(words, 1, label)
            if key == "SCALARS":
                ncomp = _int(words, 3, label) if len(words) > 3 else 1
                lookup = cursor.peek()
                if lookup and lookup[0].upper() == "LOOKUP_TABLE":
                    cursor.line()
                values = cursor.values(ncomp * count, _word(words, 2, label))
            elif key == "COLOR_SCALARS":
                ncomp = _int(words, 2, label)
                values = (cursor.values(ncomp * count, "unsigned_char") if cursor.binary
                          else cursor.values(ncomp * count, "float"))
            else:
                ncomp = 9 if key == "TENSORS" else 3
                values = cursor.values(ncomp * count, _word(words, 2, label))
            target[name] = values.reshape(count, ncomp) if ncomp > 1 else values
        elif key == "LOOKUP_TABLE":
            cursor.values(4 * _int(words, 2, label), "float")
        elif key == "METADATA":
            _skip_metadata(cursor)
        else:
            raise InputError(f"{label}: keyword {words[0]!r} is not read (POINTS, cells and "
                             "POINT_DATA/FIELD arrays are)")
    return out


def _skip_cells(cursor: _Cursor, words: list[str], label: str) -> None:
    """Skip a cell block: n rows of (count, ids...) of ``size`` numbers in all, or in version
    5.1 an OFFSETS and a CONNECTIVITY array."""
    n, size = _int(words, 1, label), _int(words, 2, label)
    nxt = cursor.peek()
    if nxt and nxt[0].upper() == "OFFSETS":
        cursor.line()
        cursor.values(n, nxt[1] if len(nxt) > 1 else "vtktypeint64")
        conn = cursor.line()
        if not conn or conn[0].upper() != "CONNECTIVITY":
            raise InputError(f"{label}: OFFSETS without CONNECTIVITY in a cell block")
        cursor.values(size, conn[1] if len(conn) > 1 else "vtktypeint64")
    else:
        cursor.values(size, "int")


def _skip_metadata(cursor: _Cursor) -> None:
    """Skip a METADATA block (up to its blank line)."""
    data = cursor.data
    end = data.find(b"\n\n", cursor.pos)
    cursor.pos = len(data) if end < 0 else end + 2


def _word(words: list[str], k: int, label: str) -> str:
    if len(words) <= k:
        raise InputError(f"{label}: line {' '.join(words)!r} ends early")
    return words[k]


def _int(words: list[str], k: int, label: str) -> int:
    word = _word(words, k, label)
    try:
        value = int(word)
    except ValueError:
        raise InputError(f"{label}: line {' '.join(words)!r}: {word!r} is not a count") from None
    if value < 0:
        raise InputError(f"{label}: line {' '.join(words)!r}: negative count")
    return value
