"""Reading LAMMPS / LIGGGHTS text dumps (``dump custom`` / ``dump atom``) frame by frame.

A dump is a sequence of frames::

    ITEM: UNITS            (optional, once; must be 'si')
    ITEM: TIME             (optional; simulated time, s)
    ITEM: TIMESTEP
    ITEM: NUMBER OF ATOMS
    ITEM: BOX BOUNDS [flags]   then one 'lo hi' line per dimension (2 or 3)
    ITEM: ATOMS id ... x y ... then one line per atom, columns in any order

Positions are read from unwrapped ``xu yu`` (or scaled ``xsu ysu``) where the dump has them,
else from ``x y`` (or scaled ``xs ys``), each with its z where present; velocities from
``vx vy (vz)``, image flags from ``ix iy (iz)``. A triclinic box whose tilt factors are all
zero is read as orthogonal; a tilted one is refused. Several files (one per timestep, as
LIGGGHTS writes them) are ordered by their first timestep (:func:`dump_files`). What the
frames mean for the riser is :mod:`cfbmarkov.io.lammps`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import glob
import itertools
import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from cfbmarkov._names import check_not_pipe
from cfbmarkov.errors import InputError
from cfbmarkov.io._common import check_source, exact_ids, open_text

#: position column families, in order of preference: unwrapped first (exact laps), then
#: wrapped (laps from image flags where present, else from the minimal-image rule)
POSITION_COLUMNS = (("xu", "yu", "zu"), ("xsu", "ysu", "zsu"), ("x", "y", "z"),
                    ("xs", "ys", "zs"))
VELOCITY_COLUMNS = ("vx", "vy", "vz")
IMAGE_COLUMNS = ("ix", "iy", "iz")
AXES = "xyz"
#: the most atoms a frame's ITEM: NUMBER OF ATOMS may announce
MAX_ATOMS = 2 ** 31 - 1


@dataclass(frozen=True)
class DumpFrame:
    """One frame of a dump as written.

    Attributes
    ----------
    timestep : int
        The frame's ``ITEM: TIMESTEP``.
    time : float or None
        Its ``ITEM: TIME``, s, when the dump has one.
    box : numpy.ndarray
        Box bounds [D, 2] (lo, hi per dimension, D = 2 or 3), m.
    boundary : tuple of str
        The BOX BOUNDS flags, e.g. ``('ff', 'pp', 'pp')``.
    columns : tuple of str
        The names on the ``ITEM: ATOMS`` line.
    atoms : numpy.ndarray
        The atom table [N, len(columns)], float64.
    line : int
        Line number of the frame's ``ITEM: ATOMS`` block, for messages.
    ids : numpy.ndarray of int64 or None
        The ``id`` column parsed exactly (ids of 2^53 and more from their text; the float
        table rounds them), None where there is no ``id`` column.
    """

    timestep: int
    time: float | None
    box: np.ndarray
    boundary: tuple[str, ...]
    columns: tuple[str, ...]
    atoms: np.ndarray
    line: int
    ids: np.ndarray | None = None

    def where(self, label: str) -> str:
        """``label`` with the frame's timestep and line, to start an error message."""
        return f"{label}: timestep {self.timestep} (line {self.line})"


@dataclass(frozen=True)
class AtomColumns:
    """Where an ``ITEM: ATOMS`` line puts the id, the positions, velocities and image flags.

    Attributes
    ----------
    id : int
        Column of the atom id.
    position : tuple of int
        Columns of the position family, x y (and z where present).
    position_names : tuple of str
        Their names, e.g. ``('xu', 'yu', 'zu')``, ``('x', 'y')``.
    velocity : tuple of (int or None) or None
        Columns of vx, vy, vz (None for a missing one), or None when the dump has none.
    image : tuple of (int or None) or None
        Columns of the image flags ix, iy, iz (None for a missing one), or None.
    """

    id: int
    position: tuple[int, ...]
    position_names: tuple[str, ...]
    velocity: tuple[int, ...] | None
    image: tuple[int, ...] | None

    @classmethod
    def find(cls, names: tuple[str, ...], where: str) -> AtomColumns:
        """The layout of the column ``names``: positions are the first family present
        among xu yu, xsu ysu, x y, xs ys (each with its z where present).

        Raises
        ------
        InputError
            Without an ``id`` column or any position pair (``where`` starts the message).
        """
        if "id" not in names:
            raise InputError(f"{where}: ITEM: ATOMS has no 'id' column ({' '.join(names)}), "
                             "so the frames' particles cannot be matched; write the dump "
                             "with id first (dump custom ... id type x y)")
        for family in POSITION_COLUMNS:
            if family[0] in names and family[1] in names:
                break
        else:
            raise InputError(f"{where}: ITEM: ATOMS has no position columns (xu yu, xsu ysu, "
                             f"x y or xs ys) among: {' '.join(names)}")
        present = family if family[2] in names else family[:2]

        def columns(group):         # per source axis; None where the column is missing
            found = tuple(names.index(n) if n in names else None for n in group)
            return found if any(c is not None for c in found) else None

        return cls(names.index("id"), tuple(names.index(n) for n in present), present,
                   columns(VELOCITY_COLUMNS), columns(IMAGE_COLUMNS))

    def velocity_columns(self, axes: tuple[int, ...]) -> tuple[int, ...] | None:
        """Columns of the velocity along the source ``axes`` (0, 1, 2 for x, y, z), or None
        where any is missing."""
        if self.velocity is None or any(self.velocity[k] is None for k in axes):
            return None
        return tuple(self.velocity[k] for k in axes)

    @property
    def scaled(self) -> bool:
        """Whether positions are fractions of the box (``xs``/``xsu`` columns)."""
        return self.position_names[0].startswith("xs")

    @property
    def unwrapped(self) -> bool:
        """Whether positions are unwrapped (``xu``/``xsu`` columns)."""
        return self.position_names[0].endswith("u")



class DumpReader:
    """Iterate over the frames of a LAMMPS text dump, one :class:`DumpFrame` at a time.

    Parameters
    ----------
    fh : TextIO
        The open dump.
    label : str
        Name of the dump in error messages.

    Raises
    ------
    InputError
        While iterating, on a malformed or truncated frame.
    """

    def __init__(self, fh: TextIO, label: str):
        self._fh = fh
        self.label = label
        self.line = 0
        self.units: str | None = None
        self._pushed: str | None = None
        self._frame_line = 1        # the line where the frame being read begins

    def _keep_whole(self) -> str:
        """Advice for a file cut inside a frame (a run still writing it, a copy cut
        short): the command that keeps the whole frames before it; empty where none is."""
        if self._frame_line <= 1:
            return ""
        keep = self._frame_line - 1
        name = self.label
        command = (f"zcat {name} | head -n {keep} > whole.dump" if name.endswith(".gz") else
                   f"head -n {keep} {name} > whole.dump")
        return f"; the frames before line {self._frame_line} are whole: keep them with {command}"

    # -- lines -------------------------------------------------------------------------
    def _readline(self) -> str | None:
        if self._pushed is not None:
            line, self._pushed = self._pushed, None
        else:
            line = self._fh.readline()
            if not line:
                return None
        self.line += 1
        return line

    def _unread(self, line: str) -> None:
        self._pushed = line
        self.line -= 1

    def _value(self, item: str) -> str:
        line = self._readline()
        if line is None or not line.strip():
            raise InputError(f"{self.label}: line {self.line}: no value after 'ITEM: {item}' "
                             "(truncated?)")
        return line.strip()

    def _bounded(self, item: str, value: int, low: int, high: int) -> int:
        if not low <= value <= high:
            shown = str(value) if len(str(value)) <= 30 else f"of {len(str(value))} digits"
            raise InputError(f"{self.label}: line {self.line}: ITEM: {item} value {shown} is "
                             f"outside {low} .. {high}")
        return value

    def _number(self, item: str, kind: type):
        text = self._value(item)
        try:
            return kind(text)
        except ValueError:
            what = "a whole number" if kind is int else "a number"
            raise InputError(f"{self.label}: line {self.line}: ITEM: {item} value {text!r} is "
                             f"not {what}") from None

    # -- frames ------------------------------------------------------------------------
    def __iter__(self) -> Iterator[DumpFrame]:
        header: dict = {}
        after_atoms = False
        while (line := self._readline()) is not None:
            text = line.strip()
            if not text:
                continue
            if not text.startswith("ITEM:"):
                hint = ("more atom lines than NUMBER OF ATOMS?" if after_atoms
                        else "not a LAMMPS text dump?")
                raise InputError(f"{self.label}: line {self.line}: expected an 'ITEM:' line, "
                                 f"found {text[:40]!r} ({hint})")
            item = text[5:].strip()
            if not header:
                self._frame_line = self.line
            after_atoms = item.startswith("ATOMS")
            if after_atoms:
                yield self._atoms(item, header)
                header = {}
            else:
                self._header_item(item, header)
        if header:
            raise InputError(f"{self.label}: file ends inside the header of a frame at line "
                             f"{self.line} (truncated?){self._keep_whole()}")

    def _header_item(self, item: str, header: dict) -> None:
        if item == "TIMESTEP":
            header["timestep"] = self._bounded(item, self._number(item, int), 0, 2 ** 63 - 1)
        elif item == "TIME":
            time = self._number(item, float)
            if not np.isfinite(time):
                raise InputError(f"{self.label}: line {self.line}: ITEM: TIME value {time} is "
                                 "not a finite number")
            header["time"] = time
        elif item == "NUMBER OF ATOMS":
            header["atoms"] = self._bounded(item, self._number(item, int), 0, MAX_ATOMS)
        elif item.startswith("BOX BOUNDS"):
            header["box"], header["boundary"] = self._box(item)
        elif item == "UNITS":
            self._units(self._value(item))
        else:
            raise InputError(f"{self.label}: line {self.line}: unknown item 'ITEM: {item}' "
                             "(not a LAMMPS atom dump?)")

    def _units(self, units: str) -> None:
        if units.lower() != "si":
            raise InputError(f"{self.label}: line {self.line}: units are {units!r}, not SI; "
                             "write the dump with 'units si' (m, s)")
        self.units = units

    def _box(self, item: str) -> tuple[np.ndarray, tuple[str, ...]]:
        """Bounds [D, 2] (m) and boundary flags of an orthogonal box; a triclinic box
        (``xy xz yz`` and a tilt factor on each bounds line) is read as orthogonal where
        every tilt is zero, and refused otherwise."""
        words = item.split()[2:]
        tilted = any(tilt in words for tilt in ("xy", "xz", "yz"))
        flags = tuple(w for w in words if w not in ("xy", "xz", "yz"))
        where = f"{self.label}: line {self.line}"
        rows = []
        while (line := self._readline()) is not None and not line.lstrip().startswith("ITEM:"):
            rows.append(self._bounds(line, tilted))
            if flags and len(rows) == len(flags):
                break
        else:
            if line is not None:
                self._unread(line)
        if len(rows) < 2:
            raise InputError(f"{where}: ITEM: BOX BOUNDS needs a 'lo hi' line for x and for y "
                             f"(found {len(rows)}; truncated?)")
        return np.asarray(rows), flags

    def _bounds(self, line: str, tilted: bool = False) -> tuple[float, float]:
        fields = line.split()
        where = f"{self.label}: line {self.line}"
        if len(fields) == 3:
            try:
                tilt = float(fields[2])
            except ValueError:
                tilt = float("nan")
            if not tilted or tilt != 0.0:
                raise InputError(f"{where}: box bounds with a tilt factor {fields[2]}: a tilted "
                                 "(triclinic) box is not supported; the riser needs an "
                                 "orthogonal box")
            fields = fields[:2]
        try:
            lo, hi = (float(v) for v in fields)
        except ValueError:
            raise InputError(f"{where}: box bounds {line.strip()!r} are not two numbers 'lo hi'"
                             ) from None
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise InputError(f"{where}: box bounds {lo:g} {hi:g} do not make a box")
        return lo, hi

    def _atoms(self, item: str, header: dict) -> DumpFrame:
        where = f"{self.label}: line {self.line}"
        for key, name in (("timestep", "TIMESTEP"), ("atoms", "NUMBER OF ATOMS"),
                          ("box", "BOX BOUNDS")):
            if key not in header:
                raise InputError(f"{where}: ITEM: ATOMS without a preceding ITEM: {name}")
        columns = tuple(item.split()[1:])
        if not columns:
            raise InputError(f"{where}: ITEM: ATOMS names no columns")
        line = self.line
        atoms, ids = self._atom_table(header["atoms"], columns, header["timestep"])
        return DumpFrame(header["timestep"], header.get("time"), header["box"], header["boundary"],
                         columns, atoms, line, ids)

    def _atom_table(self, count: int, columns: tuple[str, ...], timestep: int) -> np.ndarray:
        """The next ``count`` atom lines as an array [count, columns], and their exact ids
        (None without an ``id`` column)."""
        first = self.line + 1
        lines = list(itertools.islice(self._fh, count))
        self.line += len(lines)
        if len(lines) < count:
            raise InputError(f"{self.label}: file ends inside the atoms of timestep {timestep}: "
                             f"{len(lines)} of {count} atom lines (truncated?)"
                             f"{self._keep_whole()}")
        if count == 0:
            return np.empty((0, len(columns))), (np.empty(0, np.int64) if "id" in columns else None)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # blank lines only
                atoms = np.loadtxt(lines, dtype=np.float64, ndmin=2, comments=None)
        except ValueError as exc:
            raise InputError(self._bad_atom_line(lines, first, columns, timestep, exc)) from None
        if atoms.shape != (count, len(columns)):
            raise InputError(f"{self.label}: line {first}: timestep {timestep} has atom lines of "
                             f"{atoms.shape[1] if atoms.size else 0} values for {count} atoms, "
                             f"ITEM: ATOMS names {len(columns)} columns")
        last = lines[-1]
        if not last.endswith("\n") and last.split() and last.split()[-1][-1] in ".eE+-":
            raise InputError(f"{self.label}: line {first + count - 1}: last value "
                             f"{last.split()[-1]!r} is incomplete: the file ends inside this "
                             f"line (truncated?){self._keep_whole()}")
        return atoms, self._exact_ids(atoms, lines, columns, first)

    def _exact_ids(self, atoms: np.ndarray, lines: list[str], columns: tuple[str, ...],
                   first: int) -> np.ndarray | None:
        """The ``id`` column, exact (from the text where 2^53 or more)."""
        if "id" not in columns:
            return None
        col = columns.index("id")
        return exact_ids(atoms[:, col], lambda: [line.split()[col] for line in lines if line.split()],
                         f"{self.label}: lines {first}-{first + len(lines) - 1}")

    def _bad_atom_line(self, lines: list[str], first: int, columns: tuple[str, ...],
                       timestep: int, exc: Exception) -> str:
        """Message naming the first atom line that numpy could not parse."""
        for k, line in enumerate(lines):
            fields = line.split()
            where = f"{self.label}: line {first + k}"
            if line.startswith("ITEM:"):
                return (f"{where}: {line.strip()!r} inside the atoms of timestep {timestep}: "
                        f"fewer atom lines ({k}) than NUMBER OF ATOMS ({len(lines)})")
            cut = "" if line.endswith("\n") else " (the file ends inside this line: truncated?)"
            if len(fields) != len(columns):
                return (f"{where}: {len(fields)} values, ITEM: ATOMS names {len(columns)} "
                        f"columns{cut}")
            for name, field in zip(columns, fields):
                try:
                    float(field)
                except ValueError:
                    return f"{where}: {field!r} in column {name!r} is not a number{cut}"
        return f"{self.label}: atoms of timestep {timestep}: {exc}"


# -- the importer -----------------------------------------------------------------------------
def dump_files(source) -> list[Path]:
    """The dump file(s) of ``source``, ordered by their first timestep.

    Parameters
    ----------
    source : str, os.PathLike or sequence of them
        A file, several files, or a glob pattern such as ``'post/dump*.liggghts'`` (one
        file per timestep, as LIGGGHTS writes them).

    Returns
    -------
    list of pathlib.Path
        Ordered by the first ``ITEM: TIMESTEP`` of each file, not by name
        (``dump800`` before ``dump7200``).

    Raises
    ------
    InputError
        If a file is missing, a folder or empty, a pattern matches no file, or two files
        start at the same timestep.
    """
    if isinstance(source, (list, tuple)):
        paths = [Path(p) for p in source]
    else:
        text = os.fspath(source)
        if not Path(text).exists() and any(c in text for c in "*?["):
            paths = [Path(p) for p in sorted(glob.glob(text))]
            if not paths:
                raise InputError(f"{text}: no file matches this pattern")
        else:
            paths = [Path(text)]
    if not paths:
        raise InputError("no dump file given")
    if len(paths) == 1:
        return [check_source(paths[0])]
    for path in paths:
        if not path.exists() or path.is_dir():
            check_source(path)
        check_not_pipe(path)
    kept = [p for p in paths if p.stat().st_size > 0]      # empty files are skipped
    if not kept:
        raise InputError(f"{paths[0].parent}: all {len(paths)} dump files are empty")
    starts = [(_first_step(p), p) for p in kept]
    # by time where every file dates its frames (ITEM: TIME carries on across a
    # reset_timestep), else by timestep
    timed = all(start[1] is not None for start, _ in starts)
    ordered = sorted(starts, key=lambda item: ((item[0][1], item[0][0]) if timed
                                               else (item[0][0], item[1].name)))
    for (before, a), (after, b) in zip(ordered[:-1], ordered[1:]):
        if before[0] == after[0] < 2 ** 62 and before[1] == after[1] and not _pieces(a, b):
            when = (f"timestep {before[0]}" if before[1] is None else
                    f"timestep {before[0]}, t = {before[1]:g} s")
            raise InputError(f"{a} and {b} both start at {when} with the same atoms: the same "
                             "frames given twice (a copy, or a restarted run's dump beside "
                             "the first): leave one of them out")
    return [p for _, p in ordered]


def _first_ids(path: Path) -> np.ndarray | None:
    """The atom ids of a dump's first frame (None where it has no id column or cannot be
    read: the reader says what is wrong later)."""
    try:
        with open_text(path) as fh:
            frame = next(iter(DumpReader(fh, str(path))), None)
    except (InputError, OSError, UnicodeDecodeError, ValueError):
        return None
    return None if frame is None else frame.ids


def _pieces(a: Path, b: Path) -> bool:
    """Whether two dumps that start at one timestep are pieces of one dump, each holding
    other atoms (a LAMMPS dump named with %, one file per processor): their first frames'
    ids are disjoint, and the files differ."""
    first, second = _first_ids(a), _first_ids(b)
    if first is None or second is None:
        return False
    if first.size == 0 and second.size == 0:        # a copy of a frame without atoms?
        return a.stat().st_size != b.stat().st_size or a.read_bytes() != b.read_bytes()
    return not np.intersect1d(first, second).size


def piece_groups(paths: list[Path]) -> list[list[Path]]:
    """The ordered dumps of :func:`dump_files` grouped into the files that hold one stretch
    of frames: one file each, or the pieces of one dump written per processor (files that
    start at one timestep, ``dump ... dump.%.txt`` in LAMMPS), whose frames are joined.

    Parameters
    ----------
    paths : list of pathlib.Path
        As :func:`dump_files` orders them.

    Returns
    -------
    list of list of pathlib.Path
    """
    groups: list[list[Path]] = []
    last = None
    for path in paths:
        start = _first_step(path)
        if groups and start == last and start[0] < 2 ** 62:
            groups[-1].append(path)
        else:
            groups.append([path])
        last = start
    return groups


def _first_step(path: Path) -> tuple[int, float | None]:
    """(first ITEM: TIMESTEP, its ITEM: TIME or None) of a dump, to order files; files that
    do not say come last (the reader then reports what is wrong)."""
    time = None
    try:
        with open_text(path) as fh:
            for _ in range(50):
                line = fh.readline()
                if not line:
                    break
                if line.strip() == "ITEM: TIME":
                    time = float(fh.readline().split()[0])
                elif line.strip() == "ITEM: TIMESTEP":
                    return int(fh.readline().split()[0]), time
    except (OSError, ValueError, IndexError, UnicodeDecodeError):
        pass
    return 2 ** 62, None


def _frames_of(paths: list[Path], units: list, skipped: list) -> Iterator[tuple[str, DumpFrame]]:
    """(label, frame) of every frame, file after file (the pieces of a dump written per
    processor joined frame by frame, :func:`piece_groups`), from the first frame that holds
    atoms; the frames before it (the empty first file of a LIGGGHTS run, say) are counted
    in ``skipped[0]``."""
    started = False
    for group in piece_groups(paths):
        label = str(group[0]) if len(group) == 1 else f"{group[0]} (+{len(group) - 1} pieces)"
        with contextlib.ExitStack() as stack:
            readers = [DumpReader(stack.enter_context(open_text(path)), str(path))
                       for path in group]
            for frame in _joined(readers, label):
                for reader in readers:
                    if not units and reader.units:
                        units.append(reader.units)
                if not started and frame.atoms.shape[0] == 0:
                    skipped[0] += 1         # before any atom exists: nothing to store
                    continue
                started = True
                yield label, frame


def _joined(readers: list, label: str) -> Iterator[DumpFrame]:
    """The frames of one dump, or of its pieces joined: each piece's frame of a timestep
    holds other atoms of the same box; the pieces must hold the same timesteps."""
    if len(readers) == 1:
        yield from readers[0]
        return
    iterators = [iter(reader) for reader in readers]
    while True:
        frames = [next(it, None) for it in iterators]
        if all(f is None for f in frames):
            return
        if any(f is None for f in frames) or len({f.timestep for f in frames}) > 1:
            steps = ", ".join("end" if f is None else str(f.timestep) for f in frames)
            raise InputError(f"{label}: the pieces of one dump (files starting at one "
                             f"timestep) hold other timesteps here ({steps}): give pieces "
                             "written by one run, each with every frame")
        first = frames[0]
        if any(f.columns != first.columns or not np.array_equal(f.box, first.box)
               for f in frames[1:]):
            raise InputError(f"{label}: the pieces of timestep {first.timestep} differ in "
                             "their columns or box: give pieces of one dump")
        ids = (None if any(f.ids is None for f in frames)
               else np.concatenate([f.ids for f in frames]))
        yield dataclasses.replace(first, atoms=np.vstack([f.atoms for f in frames]), ids=ids)
