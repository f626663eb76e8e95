"""Reading VTK XML PolyData (``.vtp``), UnstructuredGrid (``.vtu``) and ParaView collections
(``.pvd``) as particle frames.

What MFiX-DEM (``RUN_DES_0000.vtp`` + ``RUN_DES.pvd``) and LAMMPS ``dump vtk`` or LIGGGHTS
``dump custom/vtk`` with a ``.vtp`` name write: a ``<VTKFile type="PolyData">`` whose
``<Points>`` are the particle centres and whose ``<PointData>`` holds the per-particle
arrays. What the same dumps with a ``.vtu`` name, Yade's ``VTKRecorder``, pyevtk's
``pointsToVTK`` and ``cfbmarkov export-vtk`` write: a ``<VTKFile type="UnstructuredGrid">``
of the same ``<Points>`` and ``<PointData>`` (its ``<Cells>``, a vertex per particle, are
not needed and not read). A ``.pvd`` lists the
files with their times (``<DataSet timestep=... file=...>``). Data arrays in ``format="ascii"``,
``"binary"`` (base64) or ``"appended"`` (raw or base64 ``<AppendedData>``), uncompressed or
zlib-compressed (``vtkZLibDataCompressor``), with UInt32 or UInt64 headers, are read; other
compressors are refused. The format: "VTK File Formats", XML section (Kitware), and
``vtkXMLDataParser.cxx`` for the binary headers.
"""

from __future__ import annotations

import base64
import binascii
import re
import xml.etree.ElementTree as ElementTree
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cfbmarkov._names import check_not_pipe
from cfbmarkov.errors import InputError

_TYPES = {"Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2", "Int32": "i4",
          "UInt32": "u4", "Int64": "i8", "UInt64": "u8", "Float32": "f4", "Float64": "f8"}
#: the time MFiX writes in a comment before the VTKFile element
_TIME_COMMENT = re.compile(rb"<!--\s*Time\s*=\s*([-+0-9.eEdD]+)\s*s?\s*-->")


#: the VTK XML data set types whose points are read as particles
PARTICLE_TYPES = ("PolyData", "UnstructuredGrid")


@dataclass
class PolyData:
    """The content of a ``.vtp`` or ``.vtu`` file that particle imports use.

    Attributes
    ----------
    points : numpy.ndarray of float64, shape (N, 3)
        The points (all pieces, in order).
    point_data : dict of str to numpy.ndarray
        Point arrays by name, shape (N,) or (N, k); integer arrays as int64.
    field_data : dict of str to numpy.ndarray
        Dataset-level arrays (e.g. ParaView's ``TimeValue``), flattened.
    comment_time : float or None
        The time of a ``<!-- Time = ... s -->`` comment (MFiX), s.
    """

    points: np.ndarray
    point_data: dict = field(default_factory=dict)
    field_data: dict = field(default_factory=dict)
    comment_time: float | None = None


def read_vtp(path: Path) -> PolyData:
    """Read the points and point arrays of a VTK XML PolyData or UnstructuredGrid file.

    Parameters
    ----------
    path : pathlib.Path
        The ``.vtp`` or ``.vtu`` file.

    Returns
    -------
    PolyData

    Raises
    ------
    InputError
        If it is neither XML PolyData nor UnstructuredGrid, is damaged or truncated, or uses
        an encoding, compressor or data type that is not read (named in the message).
    """
    label = str(path)
    try:
        check_not_pipe(path)
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{label}: cannot read ({exc.strerror or exc})") from None
    appended = b""
    start = data.find(b"<AppendedData")
    if start >= 0:
        open_end = data.find(b">", start)
        close = data.rfind(b"</AppendedData>")
        if open_end < 0 or close < 0:
            raise InputError(f"{label}: <AppendedData> is not closed (truncated file)")
        body = data[open_end + 1:close]
        underscore = body.find(b"_")
        appended = body[underscore + 1:] if underscore >= 0 else b""
        data = data[:open_end + 1] + data[close:]
    root = _parse(data, label)
    kind = root.get("type")
    if root.tag != "VTKFile" or kind not in PARTICLE_TYPES:
        raise InputError(f"{label}: not VTK XML PolyData or UnstructuredGrid (VTKFile type="
                         f"{kind!r}); particle files are PolyData (.vtp) or UnstructuredGrid "
                         "(.vtu) of the particle centres")
    decoder = _Decoder(root, appended, label)
    pieces = root.findall(f"./{kind}/Piece")
    if not pieces:
        raise InputError(f"{label}: no <Piece> in <{kind}>")
    points, arrays = [], []
    for piece in pieces:
        n = _count(piece, "NumberOfPoints", "0", label)
        array = piece.find("./Points/DataArray")
        if array is None:
            if n:
                raise InputError(f"{label}: a piece of {n} points has no <Points> array")
            pts = np.zeros((0, 3))
        else:
            values = decoder.array(array, n)
            # a piece of no points (a frame before the first injection) has no values to
            # infer the components from
            pts = (values.reshape(n, -1) if n else np.zeros((0, 3))).astype(np.float64)
        points.append(pts)
        arrays.append({a.get("Name", ""): decoder.array(a, n)
                       for a in piece.findall("./PointData/DataArray")})
    names = set(arrays[0])
    if any(set(a) != names for a in arrays):
        raise InputError(f"{label}: the pieces carry different point arrays")
    point_data = {k: np.concatenate([a[k] for a in arrays]) for k in arrays[0]}
    # the data set's field arrays (ParaView's TimeValue), and those pyevtk writes in its
    # piece (cfbmarkov export-vtk's periodicity)
    field_data = {a.get("Name", ""): decoder.array(a, None).ravel()
                  for a in root.findall(f"./{kind}/Piece/FieldData/DataArray")
                  + root.findall(f"./{kind}/FieldData/DataArray")}
    match = _TIME_COMMENT.search(data[:start] if start >= 0 else data)
    comment_time = float(match.group(1).replace(b"d", b"e").replace(b"D", b"e")) if match else None
    return PolyData(np.concatenate(points), point_data, field_data, comment_time)


def read_pvd(path: Path) -> list[tuple[float, list[Path]]]:
    """The (time, files) of a ParaView collection, in time order.

    Parameters
    ----------
    path : pathlib.Path
        The ``.pvd`` file.

    Returns
    -------
    list of (float, list of pathlib.Path)
        Each time (s) and the files (pieces) of that time, relative paths taken from the
        ``.pvd``'s folder.

    Raises
    ------
    InputError
        If it is not a collection, a data set lacks its time or file, or a time is not a
        finite number.
    """
    label = str(path)
    try:
        check_not_pipe(path)
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{label}: cannot read ({exc.strerror or exc})") from None
    root = _parse(data, label)
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        raise InputError(f"{label}: not a ParaView collection (VTKFile type="
                         f"{root.get('type')!r}, expected 'Collection')")
    times: dict[float, list[Path]] = {}
    for k, item in enumerate(root.findall("./Collection/DataSet")):
        stamp, name = item.get("timestep"), item.get("file")
        if stamp is None or name is None:
            raise InputError(f"{label}: DataSet {k + 1} lacks its 'timestep' or 'file'")
        try:
            time = float(stamp)
        except ValueError:
            raise InputError(f"{label}: DataSet {k + 1}: timestep {stamp!r} is not a number"
                             ) from None
        if not np.isfinite(time):
            raise InputError(f"{label}: DataSet {k + 1}: timestep {stamp!r} is not finite")
        times.setdefault(time, []).append(path.parent / name)
    if not times:
        raise InputError(f"{label}: the collection lists no data set")
    return sorted(times.items())


def _count(node, attribute: str, default: str, label: str) -> int:
    """A non-negative whole-number attribute."""
    text = node.get(attribute, default)
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise InputError(f"{label}: {attribute}={text!r} is not a count")
    return value


def _parse(data: bytes, label: str):
    if not data or data.isspace():
        raise InputError(f"{label}: empty file (no XML in it): nothing to import; check "
                         "that the program writing it has finished")
    try:
        return ElementTree.fromstring(data)
    except ElementTree.ParseError as exc:
        raise InputError(f"{label}: damaged XML ({exc})") from None


class _Decoder:
    """Decodes the DataArrays of one file (its byte order, header type and compressor)."""

    def __init__(self, root, appended: bytes, label: str):
        self.label = label
        self.order = "<" if root.get("byte_order", "LittleEndian") == "LittleEndian" else ">"
        header = root.get("header_type", "UInt32")
        if header not in ("UInt32", "UInt64"):
            raise InputError(f"{label}: header_type {header!r} is not read (UInt32 or UInt64)")
        self.header = np.dtype(self.order + _TYPES[header])
        compressor = root.get("compressor")
        if compressor not in (None, "", "vtkZLibDataCompressor"):
            raise InputError(f"{label}: compressor {compressor!r} is not read; write the files "
                             "uncompressed or with zlib (vtkZLibDataCompressor)")
        self.compressed = bool(compressor)
        self.appended = appended
        appended_node = root.find("./AppendedData")
        self.appended_base64 = (appended_node is not None
                                and appended_node.get("encoding", "raw") == "base64")

    def array(self, node, n_tuples: int | None) -> np.ndarray:
        """The values of a DataArray: shape (n,) or (n, components); int64 or float64."""
        name = node.get("Name") or "(no Name)"
        kind = node.get("type")
        if kind not in _TYPES:
            raise InputError(f"{self.label}: array {name!r}: type {kind!r} is not read "
                             f"({', '.join(_TYPES)} are)")
        dtype = np.dtype(self.order + _TYPES[kind])
        encoding = node.get("format", "ascii")
        if encoding == "ascii":
            try:
                values = np.array((node.text or "").split(),
                                  dtype=np.int64 if dtype.kind in "iu" else np.float64)
            except ValueError:
                raise InputError(f"{self.label}: array {name!r} holds a value that is not a "
                                 "number") from None
        elif encoding == "binary":
            values = self._values(self._inline(node.text or "", name), dtype, name)
        elif encoding == "appended":
            offset = _count(node, "offset", "0", self.label)
            values = self._values(self._appended(offset, name), dtype, name)
        else:
            raise InputError(f"{self.label}: array {name!r}: format {encoding!r} is not read "
                             "(ascii, binary or appended)")
        ncomp = max(_count(node, "NumberOfComponents", "1", self.label), 1)
        if n_tuples is not None and values.size != ncomp * n_tuples:
            raise InputError(f"{self.label}: array {name!r} holds {values.size} values, expected "
                             f"{ncomp} x {n_tuples} (damaged or truncated file)")
        values = values.astype(np.int64 if values.dtype.kind in "iu" else np.float64)
        return values.reshape(-1, ncomp) if ncomp > 1 else values

    def _first(self, raw: bytes, name: str) -> int:
        """The first header word of ``raw``."""
        if len(raw) < self.header.itemsize:
            raise InputError(f"{self.label}: array {name!r}: its header is cut short (damaged "
                             "file)")
        return int(np.frombuffer(raw[:self.header.itemsize], self.header)[0])

    def _values(self, raw: bytes, dtype: np.dtype, name: str) -> np.ndarray:
        if len(raw) % dtype.itemsize:
            raise InputError(f"{self.label}: array {name!r}: {len(raw)} bytes is no whole number "
                             f"of {dtype.itemsize}-byte values (damaged file)")
        return np.frombuffer(raw, dtype=dtype)

    def _b64(self, text: bytes | str, name: str) -> bytes:
        try:
            return base64.b64decode(text, validate=False)
        except (binascii.Error, ValueError):
            raise InputError(f"{self.label}: array {name!r}: damaged base64 data") from None

    def _inline(self, text: str, name: str) -> bytes:
        """Data of an inline binary array: the header and the data are base64 encoded
        separately (VTK) or together (some writers)."""
        text = "".join(text.split())
        size = self.header.itemsize
        if not self.compressed:
            head_chars = 4 * -(-size // 3)
            if text[head_chars - 1:head_chars] == "=":        # encoded separately
                nbytes = self._first(self._b64(text[:head_chars], name), name)
                return self._exact(self._b64(text[head_chars:], name), nbytes, name)
            raw = self._b64(text, name)
            nbytes = self._first(raw, name)
            return self._exact(raw[size:], nbytes, name)
        first = self._b64(text[:4 * -(-3 * size // 3)], name)
        nblocks = self._first(first, name)
        head_bytes = (3 + nblocks) * size
        head_chars = 4 * -(-head_bytes // 3)
        head = self._b64(text[:head_chars], name)
        if text[head_chars - 1:head_chars] == "=" or head_bytes % 3 == 0:
            body = self._b64(text[head_chars:], name)
        else:
            joint = self._b64(text, name)
            head, body = joint[:head_bytes], joint[head_bytes:]
        return self._inflate(head, body, name)

    def _appended(self, offset: int, name: str) -> bytes:
        data = self.appended
        size = self.header.itemsize
        if self.appended_base64:
            return self._inline(data[offset:].split(b"<")[0].decode("ascii", "replace"), name)
        if offset + size > len(data):
            raise InputError(f"{self.label}: array {name!r}: offset past the appended data "
                             "(truncated file)")
        if not self.compressed:
            nbytes = int(np.frombuffer(data, self.header, count=1, offset=offset)[0])
            return self._exact(data[offset + size:offset + size + nbytes], nbytes, name)
        nblocks = int(np.frombuffer(data, self.header, count=1, offset=offset)[0])
        head_bytes = (3 + nblocks) * size
        head = data[offset:offset + head_bytes]
        return self._inflate(head, data[offset + head_bytes:], name)

    def _inflate(self, head: bytes, body: bytes, name: str) -> bytes:
        """Decompress zlib blocks: header [nblocks, block size, last size, sizes...]."""
        usable = len(head) - len(head) % self.header.itemsize
        words = np.frombuffer(head[:usable], self.header)
        if words.size < 3 or words.size < 3 + int(words[0]):
            raise InputError(f"{self.label}: array {name!r}: damaged compression header")
        sizes = words[3:3 + int(words[0])].astype(np.int64)
        if int(sizes.sum()) > len(body):
            raise InputError(f"{self.label}: array {name!r}: compressed data cut short "
                             "(truncated file)")
        out, pos = [], 0
        try:
            for size in sizes:
                out.append(zlib.decompress(body[pos:pos + int(size)]))
                pos += int(size)
        except zlib.error as exc:
            raise InputError(f"{self.label}: array {name!r}: damaged zlib data ({exc})") from None
        return b"".join(out)

    def _exact(self, raw: bytes, nbytes: int, name: str) -> bytes:
        if len(raw) < nbytes:
            raise InputError(f"{self.label}: array {name!r}: {len(raw)} bytes of {nbytes} "
                             "(truncated file)")
        return raw[:nbytes]


#: the file names of particle data sets in a collection
PARTICLE_SUFFIXES = (".vtp", ".vtu")


def particle_collection(folder: Path) -> Path | None:
    """The ``.pvd`` of a folder whose data sets are particle files, or None where it has no
    ``.pvd``.

    A folder written by ``cfbmarkov export-vtk`` (or ParaView) may hold several collections,
    for example ``particles.pvd`` (``.vtu`` files) beside ``gas.pvd`` (``.vtr`` grids): the
    one listing ``.vtp`` or ``.vtu`` files is taken; a lone ``.pvd`` is taken as it is (its
    reader says what is wrong with it).

    Parameters
    ----------
    folder : pathlib.Path

    Returns
    -------
    pathlib.Path or None

    Raises
    ------
    InputError
        If several collections list particle files, or several list none of them.
    """
    pvds = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".pvd" and p.is_file())
    if len(pvds) <= 1:
        return pvds[0] if pvds else None
    particle = []
    for pvd in pvds:
        try:
            listing = read_pvd(pvd)
        except InputError:
            continue
        if all(f.suffix.lower() in PARTICLE_SUFFIXES for _, files in listing for f in files):
            particle.append(pvd)
    if len(particle) == 1:
        return particle[0]
    names = ", ".join(p.name for p in (particle or pvds))
    raise InputError(f"{folder}: {len(particle or pvds)} collections ({names}) "
                     + ("list particle files (.vtp, .vtu)" if particle else
                        "and none lists particle files (.vtp, .vtu)")
                     + "; import the one of the particles by its name")
