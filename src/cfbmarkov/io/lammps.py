"""LAMMPS / LIGGGHTS text dump import (``dump custom`` / ``dump atom``), SI units.

A dump is a sequence of frames::

    ITEM: UNITS            (optional, once; must be 'si')
    ITEM: TIME             (optional; simulated time, s)
    ITEM: TIMESTEP
    ITEM: NUMBER OF ATOMS
    ITEM: BOX BOUNDS [flags]   then one 'lo hi' line per dimension (2 or 3)
    ITEM: ATOMS id ... x y ... then one line per atom, columns in any order

Positions are read from ``x y``, unwrapped ``xu yu``, scaled ``xs ys`` or scaled unwrapped
``xsu ysu`` (the first pair present, in that order), velocities from ``vx vy`` when present.
Positions are measured from the box's lower corner (the domain starts at 0) and wrapped into
the box in every periodic direction: LAMMPS writes atoms slightly outside a periodic box
between re-neighbourings, and unwrapped coordinates far outside it. The box must stay the same
in every frame and be orthogonal (a triclinic box is refused).

The time of a frame is ``ITEM: TIME`` when present, else timestep x ``time_step`` (s). The
domain is the box unless ``width``/``height`` (m) override it. Frames are parsed and written
one at a time, so memory stays at a few frames whatever the length of the dump.
"""

from __future__ import annotations

import itertools
import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
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
from cfbmarkov.trajectory_writer import TrajectoryWriter

#: position column pairs, in order of preference
POSITION_COLUMNS = (("x", "y"), ("xu", "yu"), ("xs", "ys"), ("xsu", "ysu"))
VELOCITY_COLUMNS = ("vx", "vy")
#: relative change of the box bounds between frames that is taken as round-off
BOX_TOLERANCE = 1e-9


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
    """

    timestep: int
    time: float | None
    box: np.ndarray
    boundary: tuple[str, ...]
    columns: tuple[str, ...]
    atoms: np.ndarray
    line: int

    def where(self, label: str) -> str:
        """``label`` with the frame's timestep and line, to start an error message."""
        return f"{label}: timestep {self.timestep} (line {self.line})"


@dataclass(frozen=True)
class AtomColumns:
    """Where an ``ITEM: ATOMS`` line puts the id, the position pair and the velocity pair.

    Attributes
    ----------
    id : int
        Column of the atom id.
    position : tuple of int
        Columns of the position pair.
    position_names : tuple of str
        Their names: ``('x', 'y')``, ``('xu', 'yu')``, ``('xs', 'ys')`` or ``('xsu', 'ysu')``.
    velocity : tuple of int or None
        Columns of ``vx``, ``vy``, or None when the dump has no velocities.
    """

    id: int
    position: tuple[int, int]
    position_names: tuple[str, str]
    velocity: tuple[int, int] | None

    @classmethod
    def find(cls, names: tuple[str, ...], where: str) -> AtomColumns:
        """The layout of the column ``names``; positions are the first pair present among
        x y, xu yu, xs ys, xsu ysu.

        Raises
        ------
        InputError
            Without an ``id`` column or any position pair (``where`` starts the message).
        """
        if "id" not in names:
            raise InputError(f"{where}: ITEM: ATOMS has no 'id' column ({' '.join(names)})")
        for pair in POSITION_COLUMNS:
            if pair[0] in names and pair[1] in names:
                break
        else:
            raise InputError(f"{where}: ITEM: ATOMS has no position columns (x y, xu yu, xs ys "
                             f"or xsu ysu) among: {' '.join(names)}")
        velocity = None
        if all(v in names for v in VELOCITY_COLUMNS):
            velocity = (names.index("vx"), names.index("vy"))
        return cls(names.index("id"), (names.index(pair[0]), names.index(pair[1])), pair,
                   velocity)

    @property
    def scaled(self) -> bool:
        """Whether positions are fractions of the box (``xs``/``xsu`` columns)."""
        return self.position_names[0].startswith("xs")


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
            after_atoms = item.startswith("ATOMS")
            if after_atoms:
                yield self._atoms(item, header)
                header = {}
            else:
                self._header_item(item, header)
        if header:
            raise InputError(f"{self.label}: file ends inside the header of a frame at line "
                             f"{self.line} (truncated?)")

    def _header_item(self, item: str, header: dict) -> None:
        if item == "TIMESTEP":
            header["timestep"] = self._number(item, int)
        elif item == "TIME":
            header["time"] = self._number(item, float)
        elif item == "NUMBER OF ATOMS":
            header["atoms"] = self._number(item, int)
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
        """Bounds [D, 2] (m) and boundary flags of an orthogonal box."""
        flags = tuple(item.split()[2:])
        where = f"{self.label}: line {self.line}"
        if any(tilt in flags for tilt in ("xy", "xz", "yz")):
            raise InputError(f"{where}: triclinic box ({item}) is not supported; the riser "
                             "needs an orthogonal box")
        rows = []
        while (line := self._readline()) is not None and not line.lstrip().startswith("ITEM:"):
            rows.append(self._bounds(line))
            if flags and len(rows) == len(flags):
                break
        else:
            if line is not None:
                self._unread(line)
        if len(rows) < 2:
            raise InputError(f"{where}: ITEM: BOX BOUNDS needs a 'lo hi' line for x and for y "
                             f"(found {len(rows)}; truncated?)")
        return np.asarray(rows), flags

    def _bounds(self, line: str) -> tuple[float, float]:
        fields = line.split()
        where = f"{self.label}: line {self.line}"
        if len(fields) == 3:
            raise InputError(f"{where}: box bounds with a tilt factor: triclinic box is not "
                             "supported; the riser needs an orthogonal box")
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
        atoms = self._atom_table(header["atoms"], columns, header["timestep"])
        return DumpFrame(header["timestep"], header.get("time"), header["box"], header["boundary"],
                         columns, atoms, line)

    def _atom_table(self, count: int, columns: tuple[str, ...], timestep: int) -> np.ndarray:
        """The next ``count`` atom lines as an array [count, columns]."""
        first = self.line + 1
        lines = list(itertools.islice(self._fh, count))
        self.line += len(lines)
        if len(lines) < count:
            raise InputError(f"{self.label}: file ends inside the atoms of timestep {timestep}: "
                             f"{len(lines)} of {count} atom lines (truncated?)")
        if count == 0:
            return np.empty((0, len(columns)))
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
        return atoms

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
def import_lammps(source: str | os.PathLike, output: str | os.PathLike, *,
                  width: float | None = None, height: float | None = None,
                  time_step: float | None = None) -> Path:
    """Import a LAMMPS/LIGGGHTS text dump (optionally gzipped, SI units) as a trajectory file.

    Parameters
    ----------
    source : str or os.PathLike
        The dump (``dump custom`` or ``dump atom``; format in the module docstring).
    output : str or os.PathLike
        The trajectory file (HDF5) to write; it appears only when complete.
    width, height : float, optional
        Override the domain, m, which is by default the dump's box with its lower corner
        moved to 0.
    time_step : float, optional
        Simulation time step, s: the time of frames without ``ITEM: TIME`` is
        timestep x time_step.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        On bad input (no frames, no time, a changing or triclinic box, particles missing
        from a frame, units other than SI, ...); no file is left behind.
    """
    path = check_source(source)
    output = check_output(output, path)
    label = str(path)
    with removing_new_folders(output), reading(label), open_text(path) as fh:
        reader = DumpReader(fh, label)
        frames = iter(reader)
        first = next(frames, None)
        if first is None:
            raise InputError(f"{label}: no frames (no 'ITEM: ATOMS' block)")
        layout = AtomColumns.find(first.columns, first.where(label))
        reference = np.unique(whole_ids(first.atoms[:, layout.id], first.where(label)))
        if reference.size == 0:
            raise InputError(f"{first.where(label)}: the first frame holds no atoms")
        domain = (float(np.ptp(first.box[0])) if width is None else float(width),
                  float(np.ptp(first.box[1])) if height is None else float(height))
        frame_time(first, time_step, label)  # refuse a dump without time before writing
        parameters = _provenance(path, first, layout, reader.units, time_step)
        with create_writer(output, reference, width=domain[0], height=domain[1],
                           source="import:lammps", parameters=parameters,
                           with_velocity=layout.velocity is not None, label=label) as writer:
            for frame in progress(itertools.chain([first], frames), label):
                _append_frame(writer, frame, first, layout, reference, time_step, label)
    return output


def _provenance(path: Path, first: DumpFrame, layout: AtomColumns, units: str | None,
                time_step: float | None) -> dict:
    return {
        "source_file": path.name, "format": "lammps", "box": first.box.tolist(),
        "boundary": list(first.boundary), "origin_shift": first.box[:2, 0].tolist(),
        "columns": list(first.columns), "position_columns": list(layout.position_names),
        "velocity_columns": list(VELOCITY_COLUMNS) if layout.velocity else [],
        "units": units, "time_step": time_step, "first_timestep": first.timestep,
        "time_from": "ITEM: TIME" if first.time is not None else "timestep x time_step",
    }


def frame_time(frame: DumpFrame, time_step: float | None, label: str) -> float:
    """Time of a frame: ITEM: TIME, else timestep x ``time_step``.

    Parameters
    ----------
    frame : DumpFrame
        The frame.
    time_step : float or None
        Simulation time step, s.
    label : str
        Name of the dump in error messages.

    Returns
    -------
    float
        The time, s.

    Raises
    ------
    InputError
        When the frame has no ITEM: TIME and no ``time_step`` is given.
    """
    if frame.time is not None:
        return frame.time
    if time_step is None:
        raise InputError(f"{frame.where(label)}: the dump has no ITEM: TIME; give the "
                         "simulation time step with --time-step (s)")
    return frame.timestep * time_step


def periodic_axes(boundary: tuple[str, ...]) -> tuple[bool, bool]:
    """Whether x and y are periodic.

    Parameters
    ----------
    boundary : tuple of str
        BOX BOUNDS flags such as ``('ff', 'pp', 'pp')``.

    Returns
    -------
    tuple of bool
        (x periodic, y periodic); both False with fewer than two flags.
    """
    if len(boundary) < 2:
        return False, False
    return boundary[0].startswith("p"), boundary[1].startswith("p")


def box_positions(raw: np.ndarray, scaled: bool, box: np.ndarray,
                  periodic: tuple[bool, bool]) -> np.ndarray:
    """Positions from the box's lower corner, wrapped into the box where periodic.

    Parameters
    ----------
    raw : numpy.ndarray
        [N, 2] x, y in m, or fractions of the box when ``scaled``.
    scaled : bool
        Whether ``raw`` holds fractions of the box.
    box : numpy.ndarray
        Box bounds [D, 2], m.
    periodic : tuple of bool
        Whether x and y are periodic (:func:`periodic_axes`).

    Returns
    -------
    numpy.ndarray
        [N, 2] positions, m, measured from the box's lower corner.
    """
    lo, length = box[:2, 0], box[:2, 1] - box[:2, 0]
    offset = raw * length if scaled else raw - lo
    for axis in (0, 1):
        if periodic[axis]:
            wrapped = np.mod(offset[:, axis], length[axis])
            wrapped[wrapped >= length[axis]] = 0.0  # round-off of a tiny negative offset
            offset[:, axis] = wrapped
    return offset


def _append_frame(writer: TrajectoryWriter, frame: DumpFrame, first: DumpFrame,
                  layout: AtomColumns, reference: np.ndarray, time_step: float | None,
                  label: str) -> None:
    """Check one frame against the first, order its atoms by id and append it."""
    where = frame.where(label)
    _check_same_box(frame, first, where)
    if frame.columns != first.columns:
        layout = _same_layout(frame, layout, where)
    time = frame_time(frame, time_step, label)
    ids = whole_ids(frame.atoms[:, layout.id], where)
    order = frame_order(ids, reference, f"{where}, t = {time:g} s")
    atoms = frame.atoms if order is None else frame.atoms[order]
    position = box_positions(atoms[:, list(layout.position)], layout.scaled, first.box,
                             periodic_axes(first.boundary))
    velocity = atoms[:, list(layout.velocity)] if layout.velocity else None
    writer.append(time, position, velocity)


def _check_same_box(frame: DumpFrame, first: DumpFrame, where: str) -> None:
    scale = float(np.abs(first.box[:2]).max()) or 1.0
    if frame.box.shape[0] < 2 or np.abs(frame.box[:2] - first.box[:2]).max() > BOX_TOLERANCE * scale:
        raise InputError(f"{where}: the box changes ({frame.box[:2].tolist()} instead of "
                         f"{first.box[:2].tolist()}); a deforming or shrink-wrapped box cannot "
                         "be imported")


def _same_layout(frame: DumpFrame, layout: AtomColumns, where: str) -> AtomColumns:
    """The column layout of a frame whose ATOMS line differs from the first frame's."""
    new = AtomColumns.find(frame.columns, where)
    if new.position_names != layout.position_names or (new.velocity is None) != (
            layout.velocity is None):
        raise InputError(f"{where}: ITEM: ATOMS columns change ({' '.join(frame.columns)}); "
                         "every frame must carry the same position and velocity columns")
    return new
