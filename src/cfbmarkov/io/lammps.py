"""LAMMPS / LIGGGHTS text dump import (``dump custom`` / ``dump atom``), SI units.

A dump is a sequence of frames::

    ITEM: UNITS            (optional, once; must be 'si')
    ITEM: TIME             (optional; simulated time, s)
    ITEM: TIMESTEP
    ITEM: NUMBER OF ATOMS
    ITEM: BOX BOUNDS [flags]   then one 'lo hi' line per dimension (2 or 3)
    ITEM: ATOMS id ... x y ... then one line per atom, columns in any order

Positions are read from unwrapped ``xu yu`` (or scaled ``xsu ysu``) where the dump has them,
else from ``x y`` (or scaled ``xs ys``), each with its z where present; velocities from
``vx vy (vz)``, image flags from ``ix iy (iz)``.

The riser: a 2D dump (no z, or all atoms at one z) has x across and y vertical; a 3D dump
(atoms spread over x, y and z) is refused unless its vertical axis is given
(``vertical_axis``), never guessed; it is then projected on (across, vertical), across being
the first other axis, and the depth axis dropped (recorded in the provenance). The riser's
region in the dump's own coordinates is ``region`` (one range per axis), else 0..``width``
across and 0..``height`` vertically where those are given, else the box; positions are
measured from the region's lower corner, so a box wider than the riser shifts nothing, and
a particle outside the region is refused with its coordinate as the dump writes it. Without
a region the box must stay the same in every frame; with one, it may change (shrink-wrapped
``m`` boundaries).

Laps on a periodic vertical axis are exact where the dump allows: floor(yu / H) from
unwrapped coordinates, the image flag iy from wrapped ones; otherwise they follow the
minimal-image rule, and a particle that moves more than a quarter of the height between
frames is refused (coarse output of a fast particle), naming the particle, the step and
the fix. A triclinic box is refused.

Several files (a list, or a glob such as ``'post/dump*.liggghts'``, one file per timestep
as LIGGGHTS writes them) are read in the order of their first timestep, not of their
names; empty files, and frames before the first that holds atoms, are skipped. A triclinic
box whose tilt factors are all zero is read as orthogonal.

The time of a frame is ``ITEM: TIME`` when present, else timestep x ``time_step`` (s).
Frames are parsed and written one at a time, so memory stays at a few frames whatever the
length of the dump.
"""

from __future__ import annotations

import glob
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
from cfbmarkov.trajectory_writer import IMPORT_MAX_STEP, TrajectoryWriter

#: position column families, in order of preference: unwrapped first (exact laps), then
#: wrapped (laps from image flags where present, else from the minimal-image rule)
POSITION_COLUMNS = (("xu", "yu", "zu"), ("xsu", "ysu", "zsu"), ("x", "y", "z"),
                    ("xs", "ys", "zs"))
VELOCITY_COLUMNS = ("vx", "vy", "vz")
IMAGE_COLUMNS = ("ix", "iy", "iz")
AXES = "xyz"
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
            raise InputError(f"{where}: ITEM: ATOMS has no 'id' column ({' '.join(names)})")
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

    def velocity_columns(self, across: int, vertical: int) -> tuple[int, int] | None:
        """Columns of the across and vertical velocity, or None where either is missing."""
        if self.velocity is None or None in (self.velocity[across], self.velocity[vertical]):
            return None
        return self.velocity[across], self.velocity[vertical]

    @property
    def scaled(self) -> bool:
        """Whether positions are fractions of the box (``xs``/``xsu`` columns)."""
        return self.position_names[0].startswith("xs")

    @property
    def unwrapped(self) -> bool:
        """Whether positions are unwrapped (``xu``/``xsu`` columns)."""
        return self.position_names[0].endswith("u")


@dataclass(frozen=True)
class RiserFrame:
    """How the dump's coordinates map onto the riser: which source axis is vertical and
    which is across, and the region (in the source's coordinates) that is the riser.

    Attributes
    ----------
    across, vertical : int
        Source axis (0, 1, 2 for x, y, z) of the riser's x and y.
    region : numpy.ndarray
        [[across lo, hi], [vertical lo, hi]] in m, source coordinates.
    from_box : bool
        Whether the region is the dump's box (then the box must not change).
    periodic : tuple of bool
        Whether the across and the vertical axis are periodic in the dump.
    depth : int or None
        The source axis dropped (a 3D dump projected on across x vertical).
    """

    across: int
    vertical: int
    region: np.ndarray
    from_box: bool
    periodic: tuple[bool, bool]
    depth: int | None

    @property
    def width(self) -> float:
        return float(self.region[0, 1] - self.region[0, 0])

    @property
    def height(self) -> float:
        return float(self.region[1, 1] - self.region[1, 0])


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
                  time_step: float | None = None, vertical_axis: str | None = None,
                  region: tuple[tuple[float, float], ...] | None = None) -> Path:
    """Import a LAMMPS/LIGGGHTS text dump (optionally gzipped, SI units) as a trajectory file.

    Parameters
    ----------
    source : str, os.PathLike or sequence of them
        The dump (``dump custom`` or ``dump atom``; format in the module docstring), several
        files, or a glob pattern (:func:`dump_files`).
    output : str or os.PathLike
        The trajectory file (HDF5) to write; it appears only when complete.
    width, height : float, optional
        The riser is 0..width across and 0..height vertically in the dump's own
        coordinates (m); by default it is the dump's box. A box wider than the riser does
        not shift the positions.
    time_step : float, optional
        Simulation time step, s: the time of frames without ``ITEM: TIME`` is
        timestep x time_step.
    vertical_axis : {"x", "y", "z"}, optional
        The dump's vertical axis (gravity along minus it); required for a 3D dump (atoms
        spread over x, y and z), which is then projected on (across, vertical), across
        being the first other axis. Default y for a 2D dump.
    region : sequence of (lo, hi), optional
        The riser in the dump's coordinates (m), one range per source axis x, y (, z); it
        overrides ``width``/``height`` and the box, and the box may then change between
        frames (shrink-wrapped boundaries).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        On bad input (no frames, no time, a changing or triclinic box without a region, a
        3D dump without ``vertical_axis``, a particle outside the riser, particles missing
        from a frame, laps that cannot be inferred, units other than SI, ...); no file is
        left behind.
    """
    paths = dump_files(source)
    output = Path(output)
    for path in paths:
        check_output(output, path)
    label = str(paths[0]) if len(paths) == 1 else f"{paths[0].parent}/ ({len(paths)} files)"
    with removing_new_folders(output), reading(label):
        units: list = []
        skipped = [0]
        frames = _frames_of(paths, units, skipped)
        first_label, first = next(frames, (label, None))
        if first is None:
            raise InputError(f"{label}: no frames with atoms (no 'ITEM: ATOMS' block)")
        layout = AtomColumns.find(first.columns, first.where(first_label))
        reference = np.unique(whole_ids(first.atoms[:, layout.id], first.where(first_label)))
        riser = riser_frame(first, layout, first_label, width=width, height=height,
                            vertical_axis=vertical_axis, region=region)
        frame_time(first, time_step, first_label)  # refuse a dump without time before writing
        parameters = _provenance(paths[0], first, layout, units[0] if units else None,
                                 time_step, riser)
        if len(paths) > 1:
            parameters["source_files"] = [p.name for p in paths]
        parameters["frames_without_atoms_skipped"] = skipped[0]
        with create_writer(output, reference, max_step=IMPORT_MAX_STEP, width=riser.width,
                           height=riser.height,
                           source="import:lammps", parameters=parameters,
                           with_velocity=layout.velocity_columns(riser.across, riser.vertical)
                           is not None, label=label) as writer:
            for frame_label, frame in progress(itertools.chain([(first_label, first)], frames),
                                               label):
                _append_frame(writer, frame, first, layout, reference, time_step, frame_label,
                              riser)
    return output


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
        If a file is missing, a folder or empty, or a pattern matches no file.
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
    kept = [p for p in paths if p.stat().st_size > 0]      # empty files are skipped
    if not kept:
        raise InputError(f"{paths[0].parent}: all {len(paths)} dump files are empty")
    return sorted(kept, key=_first_timestep)


def _first_timestep(path: Path) -> tuple[int, str]:
    """(first ITEM: TIMESTEP, name) of a dump, to order files; files that do not say come
    last (the reader then reports what is wrong)."""
    try:
        with open_text(path) as fh:
            for _ in range(50):
                line = fh.readline()
                if not line:
                    break
                if line.strip() == "ITEM: TIMESTEP":
                    return int(fh.readline().split()[0]), path.name
    except (OSError, ValueError, IndexError, UnicodeDecodeError):
        pass
    return 2 ** 62, path.name


def _frames_of(paths: list[Path], units: list, skipped: list) -> Iterator[tuple[str, DumpFrame]]:
    """(label, frame) of every frame, file after file, from the first frame that holds
    atoms; the frames before it (the empty first file of a LIGGGHTS run, say) are counted
    in ``skipped[0]``."""
    started = False
    for path in paths:
        label = str(path)
        with open_text(path) as fh:
            reader = DumpReader(fh, label)
            for frame in reader:
                if not units and reader.units:
                    units.append(reader.units)
                if not started and frame.atoms.shape[0] == 0:
                    skipped[0] += 1         # before any atom exists: nothing to store
                    continue
                started = True
                yield label, frame


def _extents(box: np.ndarray) -> str:
    return ", ".join(f"{AXES[k]} {lo:g}..{hi:g}" for k, (lo, hi) in enumerate(box))


def riser_frame(first: DumpFrame, layout: AtomColumns, label: str, *,
                width: float | None = None, height: float | None = None,
                vertical_axis: str | None = None,
                region: tuple[tuple[float, float], ...] | None = None) -> RiserFrame:
    """The riser's axes and region in the dump's coordinates (see :func:`import_lammps`).

    Raises
    ------
    InputError
        For a 3D dump without ``vertical_axis`` (the message lists the box and the axis a
        guess would take), an axis the dump does not have, or a region that does not fit.
    """
    where = first.where(label)
    n_axes = min(len(layout.position), first.box.shape[0])
    spread = (n_axes == 3 and float(np.ptp(first.atoms[:, layout.position[2]])) > 0.0)
    if vertical_axis is None:
        if spread:
            longest = AXES[int(np.argmax(np.diff(first.box[:3], axis=1)))]
            raise InputError(
                f"{where}: a 3D dump (box {_extents(first.box[:3])} m, atoms spread over "
                f"x, y and z): say which axis is vertical with --vertical-axis x|y|z (a guess "
                f"would take the longest, {longest}; LIGGGHTS puts gravity along -z)")
        vertical_axis = "y"
    if vertical_axis not in AXES:
        raise InputError(f"--vertical-axis {vertical_axis!r}: choose x, y or z")
    vertical = AXES.index(vertical_axis)
    if vertical >= n_axes:
        raise InputError(f"{where}: --vertical-axis {vertical_axis} but the dump has no "
                         f"{vertical_axis} positions ({' '.join(layout.position_names)})")
    others = [k for k in range(3 if spread else 2) if k != vertical and k < n_axes]
    across = others[0]
    depth = others[1] if len(others) > 1 else None
    flags = first.boundary
    periodic = tuple(len(flags) > k and flags[k].startswith("p") for k in (across, vertical))
    if region is not None:
        ranges = [tuple(float(v) for v in r) for r in region]
        if len(ranges) < 2 or len(ranges) > 3:
            raise InputError(f"--region needs 2 or 3 ranges (x, y[, z]), got {len(ranges)}")
        if any(not (np.isfinite(lo) and np.isfinite(hi) and hi > lo) for lo, hi in ranges):
            raise InputError(f"--region {ranges}: every range must be LO:HI with HI > LO")
        if max(across, vertical) >= len(ranges):
            raise InputError(f"--region gives {len(ranges)} ranges but the vertical axis is "
                             f"{AXES[vertical]}: give x, y and z ranges")
        bounds = np.array([ranges[across], ranges[vertical]])
        from_box = False
    else:
        box = first.box
        bounds = np.array([(0.0, float(width)) if width is not None else box[across],
                           (0.0, float(height)) if height is not None else box[vertical]],
                          dtype=np.float64)
        from_box = width is None and height is None
    return RiserFrame(across, vertical, bounds, from_box, periodic, depth)


def _provenance(path: Path, first: DumpFrame, layout: AtomColumns, units: str | None,
                time_step: float | None, riser: RiserFrame) -> dict:
    has_image = layout.image is not None and layout.image[riser.vertical] is not None
    laps_from = ("unwrapped coordinates" if layout.unwrapped and riser.periodic[1]
                 else "image flags" if has_image and riser.periodic[1]
                 else "minimal-image rule" if riser.periodic[1] else "none (not periodic)")
    return {
        "source_file": path.name, "format": "lammps", "box": first.box.tolist(),
        "boundary": list(first.boundary), "origin_shift": riser.region[:, 0].tolist(),
        "region": riser.region.tolist(), "vertical_axis": AXES[riser.vertical],
        "across_axis": AXES[riser.across],
        "depth_axis_dropped": None if riser.depth is None else AXES[riser.depth],
        "columns": list(first.columns),
        "position_columns": [layout.position_names[riser.across],
                             layout.position_names[riser.vertical]],
        "velocity_columns": ([VELOCITY_COLUMNS[riser.across], VELOCITY_COLUMNS[riser.vertical]]
                             if layout.velocity_columns(riser.across, riser.vertical)
                             else []),
        "laps_from": laps_from,
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


def riser_positions(frame: DumpFrame, atoms: np.ndarray, layout: AtomColumns,
                    riser: RiserFrame) -> tuple[np.ndarray, np.ndarray | None]:
    """Riser positions [N, 2] (m, from the region's lower corner) and exact laps [N] (None
    where they must come from the minimal-image rule) of one frame's (ordered) atoms.

    Unwrapped coordinates on a periodic vertical axis give laps = floor(y / H) and the
    wrapped height; image flags give laps = the vertical image flag (plus any wrap of an atom
    written just outside the box); wrapped coordinates are wrapped into the riser. Across,
    a periodic axis is wrapped.
    """
    raw = atoms[:, list(layout.position)]
    if layout.scaled:
        lo = frame.box[:raw.shape[1], 0]
        raw = lo + raw * (frame.box[:raw.shape[1], 1] - lo)
    a = raw[:, riser.across] - riser.region[0, 0]
    v = raw[:, riser.vertical] - riser.region[1, 0]
    width, height = riser.width, riser.height
    laps = None
    if riser.periodic[1]:
        k = np.floor(v / height)
        v = v - k * height
        v[v >= height] = 0.0          # round-off of a tiny negative height
        if layout.unwrapped:
            laps = k.astype(np.int64)
        elif layout.image is not None and layout.image[riser.vertical] is not None:
            laps = atoms[:, layout.image[riser.vertical]].astype(np.int64) + k.astype(np.int64)
    if riser.periodic[0]:
        a = np.mod(a, width)
        a[a >= width] = 0.0
    return np.stack([a, v], axis=1), laps


def _check_inside(position: np.ndarray, atoms: np.ndarray, layout: AtomColumns,
                  riser: RiserFrame, ids: np.ndarray, where: str) -> None:
    """Refuse a particle outside the riser, naming its coordinate as the dump writes it."""
    tol = 1e-9
    outside = ((position[:, 0] < -tol) | (position[:, 0] > riser.width + tol)
               | (position[:, 1] < -tol) | (position[:, 1] > riser.height + tol))
    if outside.any():
        p = int(np.argmax(outside))
        axis = riser.across if not (-tol <= position[p, 0] <= riser.width + tol) else riser.vertical
        k = 0 if axis == riser.across else 1
        value = atoms[p, layout.position[axis]]
        raise InputError(
            f"{where}: particle {int(ids[p])} at {layout.position_names[axis]} = {value:g} lies "
            f"outside the riser {riser.region[k, 0]:g}..{riser.region[k, 1]:g} m "
            f"({AXES[axis]}); give the riser's region with --region, or (until particles may "
            "leave it) cut the dump to particles inside")


def _append_frame(writer: TrajectoryWriter, frame: DumpFrame, first: DumpFrame,
                  layout: AtomColumns, reference: np.ndarray, time_step: float | None,
                  label: str, riser: RiserFrame) -> None:
    """Check one frame against the first, order its atoms by id and append it."""
    where = frame.where(label)
    if riser.from_box:
        _check_same_box(frame, first, where)
    if frame.columns != first.columns:
        layout = _same_layout(frame, layout, where)
    time = frame_time(frame, time_step, label)
    ids = whole_ids(frame.atoms[:, layout.id], where)
    try:
        order = frame_order(ids, reference, f"{where}, t = {time:g} s")
    except InputError as exc:
        if np.unique(ids).size != ids.size:
            raise
        raise InputError(f"{exc}; atoms inserted or deleted between frames (an open riser, "
                         "insert/stream, an outlet) are not supported yet") from None
    atoms = frame.atoms if order is None else frame.atoms[order]
    position, laps = riser_positions(frame, atoms, layout, riser)
    _check_inside(position, atoms, layout, riser, reference, f"{where}, t = {time:g} s")
    columns = layout.velocity_columns(riser.across, riser.vertical)
    velocity = atoms[:, list(columns)] if writer.with_velocity and columns else None
    writer.append(time, position, velocity, laps)


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
            layout.velocity is None) or (new.image is None) != (layout.image is None):
        raise InputError(f"{where}: ITEM: ATOMS columns change ({' '.join(frame.columns)}); "
                         "every frame must carry the same position and velocity columns")
    return new
