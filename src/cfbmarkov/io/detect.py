"""Telling an import source's format from its content (``cfbmarkov import`` without
``--format``, or ``--format auto``), and refusing a source given the wrong format.

The first bytes decide: HDF5's signature with an ``/h5md`` group (H5MD), ``# vtk
DataFile`` (legacy VTK), ``<VTKFile type="PolyData">`` (VTK XML PolyData),
``type="UnstructuredGrid"`` (VTK XML UnstructuredGrid) or ``type="Collection"`` (a ParaView
``.pvd``), ``ITEM: TIMESTEP`` (a LAMMPS/LIGGGHTS dump); other text is read as CSV. A folder
or a glob pattern is judged by its first file (a folder's ``.pvd`` of particle files
first).
"""

from __future__ import annotations

import glob
import gzip
import os
import re
from pathlib import Path

from cfbmarkov._names import check_not_pipe
from cfbmarkov.errors import InputError

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
#: the formats read from particle files, and what the content shows for each
DESCRIPTIONS = {"h5md": "H5MD (an HDF5 file with an /h5md group)",
                "vtk": "legacy VTK ('# vtk DataFile' first line)",
                "vtp": "VTK XML PolyData ('<VTKFile type=\"PolyData\">')",
                "vtu": "VTK XML UnstructuredGrid ('<VTKFile type=\"UnstructuredGrid\">')",
                "pvd": "a ParaView collection ('<VTKFile type=\"Collection\">')",
                "lammps": "a LAMMPS/LIGGGHTS dump (an 'ITEM:' first line)",
                "csv": "text that is no dump or VTK file (read as CSV)"}
_VTK_TYPE = re.compile(rb"<VTKFile[^>]*\btype\s*=\s*[\"'](\w+)[\"']")


def pattern_of(paths) -> str:
    """A glob pattern that matches the files ``paths`` of one folder: their names' common
    start and end around a ``*`` (the digits of a step number left to the ``*``), e.g.
    ``post/dump*.liggghts`` for ``post/dump0.liggghts``, ``post/dump2000.liggghts``."""
    names = [os.path.basename(os.fspath(p)) for p in paths]
    head = os.path.commonprefix(names).rstrip("0123456789")
    tail = os.path.commonprefix([n[len(head):][::-1] for n in names])[::-1]
    return os.path.join(os.path.dirname(os.fspath(paths[0])), f"{head}*{tail.lstrip('0123456789')}")


def folder_advice(path: Path) -> str:
    """What to give instead of a folder: a quoted pattern of the LAMMPS/LIGGGHTS dumps it
    holds (files whose first line starts ``ITEM:``), else a file or a pattern."""
    dumps = []
    for file in sorted(p for p in path.iterdir() if p.is_file()):
        try:
            with open(file, "rb") as fh:
                if fh.read(5) == b"ITEM:":
                    dumps.append(file)
        except OSError:
            continue
    if dumps:
        return (f"it holds {len(dumps)} LAMMPS/LIGGGHTS dump(s): import them with the quoted "
                f"pattern '{pattern_of(dumps)}'")
    return "give the file, or a quoted pattern such as 'post/dump*.vtk'"


def first_file(source) -> Path:
    """The file whose content stands for ``source`` (a file, folder, pattern or list)."""
    if isinstance(source, (list, tuple)):
        if not source:
            raise InputError("no source file given")
        return Path(source[0])
    text = os.fspath(source)
    path = Path(text)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.is_file())
        from cfbmarkov.io.vtk_xml import particle_collection

        collection = particle_collection(path)
        if collection is not None:
            return collection
        for suffix in (".vtp", ".vtu", ".vtk", ".h5", ".hdf5"):
            chosen = [p for p in files if p.suffix.lower() == suffix]
            if chosen:
                return chosen[0]
        raise InputError(f"{path}: a folder without .pvd, .vtp, .vtu, .vtk or .h5 files; "
                         f"{folder_advice(path)}")
    if not path.exists() and any(c in text for c in "*?["):
        matches = sorted(glob.glob(text))
        if not matches:
            raise InputError(f"{text}: no file matches this pattern")
        return Path(matches[0])
    return path


def detect_format(source) -> tuple[str, str]:
    """The format of ``source`` from its content.

    Parameters
    ----------
    source : str, os.PathLike or list
        A file, folder, glob pattern or list of files.

    Returns
    -------
    (str, str)
        The format (a key of :data:`DESCRIPTIONS`) and what showed it.

    Raises
    ------
    InputError
        If the file is missing, unreadable or a pipe, or is HDF5 without the H5MD groups, or VTK XML
        of a type that holds no particles.
    """
    path = first_file(source)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a file; {folder_advice(path)}")
    check_not_pipe(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
        if head[:2] == b"\x1f\x8b":
            with gzip.open(path, "rb") as fh:
                head = fh.read(4096)
    except (OSError, EOFError) as exc:
        raise InputError(f"{path}: cannot read ({getattr(exc, 'strerror', None) or exc})"
                         ) from None
    if head.startswith(HDF5_MAGIC):
        import h5py

        try:
            with h5py.File(path, "r") as f:
                h5md = "h5md" in f and "particles" in f
                ours = "frames" in f
                fmt = f.attrs.get("format")
                fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
        except (OSError, KeyError, RuntimeError, ValueError) as exc:
            text = " ".join(str(exc).split())[:160]
            cut = "truncated" in text.lower()
            raise InputError(f"{path}: cannot read as HDF5 ("
                             + ("the file is truncated: it ends before the size its header "
                                "gives, as a copy or a run stopped while writing leaves it; "
                                "copy or write it again" if cut else text) + ")") from None
        if not h5md:
            hint = ("; it is a cfbmarkov trajectory file already: use it as it is" if ours
                    else "; it is a cfbmarkov model file (from fit): import reads particle "
                    "data (dumps, CSV, VTK, H5MD)" if fmt == "cfbmarkov.model" else "")
            raise InputError(f"{path}: an HDF5 file without the H5MD groups /h5md and "
                             f"/particles: no importer reads it{hint}")
        return "h5md", DESCRIPTIONS["h5md"]
    stripped = head.lstrip(b"\xef\xbb\xbf").lstrip()
    if stripped.startswith(b"# vtk DataFile"):
        return "vtk", DESCRIPTIONS["vtk"]
    match = _VTK_TYPE.search(head)
    if match:
        kind = match.group(1).decode()
        if kind == "PolyData":
            return "vtp", DESCRIPTIONS["vtp"]
        if kind == "UnstructuredGrid":
            return "vtu", DESCRIPTIONS["vtu"]
        if kind == "Collection":
            return "pvd", DESCRIPTIONS["pvd"]
        raise InputError(f"{path}: VTK XML of type {kind}; particle files are PolyData (.vtp) "
                         "or UnstructuredGrid (.vtu) of the particle centres, or a .pvd "
                         "collection of them")
    if stripped.startswith(b"ITEM: TIMESTEP") or stripped.startswith(b"ITEM:"):
        return "lammps", DESCRIPTIONS["lammps"]
    _refuse_unread_text(path, stripped)
    return "csv", DESCRIPTIONS["csv"]


_TECPLOT = re.compile(rb"^(title|variables)\s*=|^zone(\s+|\s*,\s*)[a-z]+\s*=")
_TECPLOT_VARIABLES = re.compile(rb"\nvariables\s*=")


class UnreadFormat(InputError):
    """A text format no importer reads (XML other than VTK, Tecplot ASCII)."""


def _refuse_unread_text(path, head: bytes) -> None:
    """Refuse, naming the format and what to export instead, text formats no importer
    reads (their first line would otherwise be read as a CSV header): XML other than VTK
    (TrackMate's XML tracks) and Tecplot ASCII (MFiX, Fluent)."""
    lower = head[:4096].lower()
    if lower.startswith(b"<"):
        what = ("TrackMate XML tracks" if b"<trackmate" in lower or b"<tracks" in lower
                else "XML that is no VTK file")
        raise UnreadFormat(f"{path}: {what}: not read; export the tracks as CSV (TrackMate: "
                         "the spots table, with TRACK_ID, POSITION_T, POSITION_X, POSITION_Y; "
                         "docs/how-to/pept-ptv.md) or as VTK PolyData (.vtp)")
    commands = _lammps_commands(lower)
    if len(commands) >= 3:
        # the file name as written (the search on the original text, not the lower-case)
        dump = re.search(rb"^\s*dump\s+\S+\s+\S+\s+\S+\s+\S+\s+(\S+)", head[:4096],
                         re.M | re.I)
        writes = (f" (here: {dump.group(1).decode(errors='replace')})" if dump else "")
        raise UnreadFormat(f"{path}: LAMMPS commands ({', '.join(commands[:4])}): an input "
                           "script or its log, not a dump: import the file its dump command "
                           f"writes{writes}, a dump of atom or custom style")
    first = lower.split(b"\n", 1)[0].strip()
    # Tecplot's keywords take "=" (TITLE = "...", VARIABLES = "X" "Y", ZONE T="..."): a
    # CSV header that merely begins with a column named zone or title is no such file
    if _TECPLOT.match(first) or _TECPLOT_VARIABLES.search(lower[:1024]):
        raise UnreadFormat(f"{path}: Tecplot ASCII (TITLE/VARIABLES/ZONE lines): not read; "
                         "export the particles as CSV with columns t, id, x, y (or VTK "
                         "PolyData, .vtp; MFiX writes those with its VTK output)")


#: commands of a LAMMPS/LIGGGHTS input script that no CSV header or data line starts with
_LAMMPS_COMMANDS = (b"units", b"atom_style", b"dimension", b"boundary", b"region",
                    b"create_box", b"create_atoms", b"lattice", b"pair_style", b"pair_coeff",
                    b"fix", b"dump", b"run", b"timestep", b"neighbor", b"neigh_modify",
                    b"thermo", b"variable", b"read_data", b"comm_modify")


def _lammps_commands(text: bytes) -> list[str]:
    """The LAMMPS commands the lines of ``text`` start with (a word, then a space), in the
    order first seen; a CSV's first line never does."""
    seen: list[str] = []
    for line in text.split(b"\n")[:200]:
        words = line.split(None, 1)
        if len(words) == 2 and words[0] in _LAMMPS_COMMANDS:
            word = words[0].decode()
            if word not in seen:
                seen.append(word)
    return seen


def _tabular(path) -> bool:
    """Whether a text file's first line reads as a table's (a comma, semicolon or tab in it):
    a CSV file rather than an empty, binary or damaged one, whose reader says what is
    wrong."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    if head[:2] == b"\x1f\x8b" or b"\x00" in head:
        return False
    first = head.lstrip(b"\xef\xbb\xbf").lstrip().split(b"\n", 1)[0]
    return any(mark in first for mark in (b",", b";", b"\t"))


def check_given_format(source, fmt: str) -> None:
    """Refuse a source whose content is plainly of another format than ``fmt``: a particle
    file (VTK, H5MD) given as ``csv`` or ``lammps``, a LAMMPS dump given as ``csv``, a CSV
    file (text whose first line is no ``ITEM:``) given as ``lammps``, or a text file given
    as a particle format, or a text format no importer reads (TrackMate XML, Tecplot);
    the message names the content's format.

    Raises
    ------
    InputError
        On such a mismatch.
    """
    try:
        found, shown = detect_format(source)
    except UnreadFormat:
        if fmt in ("csv", "lammps"):  # a text reader would misread its first line
            raise
        return
    except InputError:
        return                       # the reader of fmt reports what is wrong
    particle = ("h5md", "vtk", "vtp", "vtu", "pvd")
    # a dump's 'ITEM:' first line is never a CSV file's, and a dump has no other (blank
    # lines aside): text of one given as the other is refused, naming it
    same = found == fmt or {found, fmt} <= {"vtp", "vtu", "pvd"} or (
        found not in particle and fmt not in particle and (found, fmt) != ("lammps", "csv")
        and not ((found, fmt) == ("csv", "lammps") and _tabular(first_file(source))))
    if not same:
        raise InputError(f"{first_file(source)}: the content is {shown}, not {fmt}; import it "
                         f"with --format {found} (or without --format)")
