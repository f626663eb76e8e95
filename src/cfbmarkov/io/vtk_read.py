"""Importing VTK particle files: legacy ``.vtk`` series (LIGGGHTS ``dump custom/vtk``, LAMMPS
``dump vtk``) and VTK XML ``.vtp`` series with their ``.pvd`` (MFiX-DEM, LAMMPS, pyevtk).

One file holds one time step. A particle's id is its ``id`` point array (``ID``, ``Id``);
without one, particles are numbered by their point order (1..N), with a warning: that holds
only while the writer keeps its points in one order and no particle is inserted or deleted
(a file with another number of points is refused). The
velocity is the ``v``, ``vel`` or ``velocity`` vector (or ``vx vy vz`` scalars).

Times: a legacy series takes them from a ``TIME`` field array where the files carry one, else
from the step number in the file name (``dump5000.vtk``: step 5000) times ``time_step``; a
``.vtp`` series from the ``.pvd``, else from MFiX's ``<!-- Time = ... s -->`` comment or a
``TimeValue`` field array. The box of a LIGGGHTS series is its ``*_boundingBox.vtk`` files;
VTK XML files carry none (give ``--width``/``--height`` or ``--region``).
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.io._common import check_source
from cfbmarkov.io.particle_frames import ParticleFrame, ParticleSeries
from cfbmarkov.io.vtk_legacy import read_legacy
from cfbmarkov.io.vtk_xml import PARTICLE_SUFFIXES, particle_collection, read_pvd, read_vtp

_ID_NAMES = ("id", "ids", "particle_id", "particleid", "globalid")
#: image flags per axis (LAMMPS/LIGGGHTS ``ix iy iz``)
_IMAGE_NAMES = ("ix", "iy", "iz")
#: the passes along y that ``cfbmarkov export-vtk`` writes (its vertical axis)
_LAP_NAME = "lap"
_VELOCITY_NAMES = ("v", "vel", "velocity", "velocities")
_TIME_NAMES = ("time", "timevalue")
_DIGITS = re.compile(r"\d+")
BOUNDING_BOX = "_boundingBox"


def source_files(source, suffixes: tuple[str, ...]) -> list[Path]:
    """The files of ``source``: a file, a folder (its files with one of ``suffixes``), a
    glob pattern, or a list of paths.

    Raises
    ------
    InputError
        If nothing matches, or a file is missing or empty.
    """
    if isinstance(source, (list, tuple)):
        paths = [Path(p) for p in source]
    else:
        text = os.fspath(source)
        path = Path(text)
        if path.is_dir():
            paths = sorted(p for p in path.iterdir() if p.suffix.lower() in suffixes)
            if not paths:
                raise InputError(f"{path}: no {' or '.join(suffixes)} file in this folder")
        elif not path.exists() and any(c in text for c in "*?["):
            paths = [Path(p) for p in sorted(glob.glob(text))]
            if not paths:
                raise InputError(f"{text}: no file matches this pattern")
        else:
            paths = [path]
    for path in paths:
        check_source(path)
    return paths


def _label(paths: list[Path]) -> str:
    return str(paths[0]) if len(paths) == 1 else f"{paths[0].parent}/ ({len(paths)} files)"


def _step_position(paths: list[Path]) -> int:
    """Which number in the files' names is the step, counted from the end (-1: the last):
    in a series whose names all hold as many numbers, the only one that differs between
    them (``dump10000_v2.vtk``, ``dump20000_v2.vtk``: the first); else the last."""
    groups = [_DIGITS.findall(p.stem) for p in paths]
    if len(paths) > 1 and groups[0] and all(len(g) == len(groups[0]) for g in groups):
        varying = [k for k in range(len(groups[0])) if len({int(g[k]) for g in groups}) > 1]
        if len(varying) == 1:
            return varying[0] - len(groups[0])
    return -1


def _step_of(path: Path, position: int = -1) -> int | None:
    """The step number in ``path``'s name: its number at ``position`` (:func:`_step_position`)."""
    numbers = _DIGITS.findall(path.stem)
    return int(numbers[position]) if numbers else None


def _find(arrays: dict, names: tuple[str, ...]) -> str | None:
    for key in arrays:
        if key.lower() in names:
            return key
    return None


def _velocity(arrays: dict, n: int, where: str) -> tuple[np.ndarray | None, str | None]:
    name = _find(arrays, _VELOCITY_NAMES)
    if name is not None:
        v = np.asarray(arrays[name], dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise InputError(f"{where}: velocity array {name!r} has shape {v.shape}; expected "
                             f"{n} x 3")
        return v, name
    parts = [_find(arrays, (c,)) for c in ("vx", "vy", "vz")]
    if all(parts):
        return np.column_stack([arrays[p] for p in parts]).astype(np.float64), " ".join(parts)
    return None, None


def _ids(arrays: dict, n: int, where: str) -> tuple[np.ndarray, str | None]:
    name = _find(arrays, _ID_NAMES)
    if name is None:
        return np.arange(1, n + 1, dtype=np.int64), None
    values = np.asarray(arrays[name])
    if values.ndim != 1:
        raise InputError(f"{where}: id array {name!r} has {values.shape[1]} components")
    if values.dtype.kind == "f":
        whole = np.isfinite(values) & (values == np.round(values))
        if not whole.all():
            raise InputError(f"{where}: particle id {values[np.argmax(~whole)]:g} in array "
                             f"{name!r} is not a whole number")
    return values.astype(np.int64), name


def _whole(values, name: str, where: str) -> np.ndarray:
    values = np.asarray(values)
    if values.ndim != 1:
        raise InputError(f"{where}: point array {name!r} has {values.shape[1]} components; "
                         "expected one")
    if values.dtype.kind == "f" and not (np.isfinite(values)
                                         & (values == np.round(values))).all():
        raise InputError(f"{where}: point array {name!r} holds a value that is not a whole "
                         "number; image flags and laps are integers")
    return values.astype(np.int64)


def _image(arrays: dict, n: int, where: str) -> tuple[np.ndarray | None, str | None]:
    """Image flags [n, 3] from ``ix iy iz`` point arrays, or from the ``lap`` array of
    ``cfbmarkov export-vtk`` (passes along y, the others zero); with what gave them."""
    names = [_find(arrays, (c,)) for c in _IMAGE_NAMES]
    if all(names):
        image = np.column_stack([_whole(arrays[k], k, where) for k in names])
        return image, "image flags (point arrays " + ", ".join(repr(k) for k in names) + ")"
    lap = _find(arrays, (_LAP_NAME,))
    if lap is not None:
        image = np.zeros((n, 3), np.int64)
        image[:, 1] = _whole(arrays[lap], lap, where)
        return image, f"point array {lap!r} (passes along y, as cfbmarkov export-vtk writes)"
    return None, None


def _array_text(name: str | None) -> str:
    """An array's name quoted, or ``none`` where a file has no such array (messages)."""
    return repr(name) if name is not None else "none"


class _Frames:
    """Builds ParticleFrames from point arrays, checking that the id, velocity and image
    arrays stay the same from file to file; records where ids, velocities and laps come
    from."""

    def __init__(self):
        self.ids_from: str | None = ""
        self.velocity_from: str | None = ""
        self.image_from: str | None = ""
        self.n_first: int | None = None

    def frame(self, time: float, points: np.ndarray, arrays: dict, box, where: str):
        n = points.shape[0]
        ids, ids_from = _ids(arrays, n, where)
        velocity, velocity_from = _velocity(arrays, n, where)
        image, image_from = _image(arrays, n, where)
        if self.n_first is None:
            self.n_first, self.ids_from, self.velocity_from = n, ids_from, velocity_from
            self.image_from = image_from
            if ids_from is None and n > 1:
                import warnings

                from cfbmarkov.errors import CfbmarkovWarning

                warnings.warn(f"{where}: no 'id' point array: particle k is taken to be the "
                              "k-th point of every file, which holds only where the writer "
                              "keeps its points in one order (LAMMPS sorts its atoms in "
                              "memory, atom_modify sort, and a dump vtk follows that order); "
                              "where it may not, write the ids (dump custom/vtk ... id), or "
                              "the tracks are mixed", CfbmarkovWarning, stacklevel=2)
        elif ids_from != self.ids_from:
            raise InputError(f"{where}: id array {_array_text(ids_from)} here, "
                             f"{_array_text(self.ids_from)} in the first file; every file must "
                             "carry the same arrays")
        elif self.ids_from is None and n != self.n_first:
            raise InputError(f"{where}: {n} points where the first file has {self.n_first}, and "
                             "no 'id' point array tells which particle is which; write the "
                             "particle ids (e.g. LIGGGHTS dump custom/vtk ... id)")
        if (velocity_from is None) != (self.velocity_from is None):
            raise InputError(f"{where}: velocity array {_array_text(velocity_from)} here, "
                             f"{_array_text(self.velocity_from)} in the first file; every file "
                             "must carry the same arrays")
        if image_from != self.image_from:
            raise InputError(f"{where}: laps from {image_from or 'no array'}, the first file's "
                             f"from {self.image_from or 'no array'}; every file must carry the "
                             "same arrays")
        return ParticleFrame(time=float(time), ids=ids, positions=points, velocities=velocity,
                             image=image, box=box, where=where)

    def provenance(self) -> dict:
        return {"ids_from": (f"point array {self.ids_from!r}" if self.ids_from
                             else "point order (no id array): particle k is the k-th point"),
                "velocity_from": (f"point array {self.velocity_from!r}" if self.velocity_from
                                  else None),
                "image_from": self.image_from}


def vtk_series(source, time_step: float | None = None) -> ParticleSeries:
    """The frames of a legacy VTK series (one ``.vtk`` file per time step).

    Parameters
    ----------
    source : str, os.PathLike or list
        A file, a folder, a glob pattern (``'post/dump*.vtk'``) or a list of files;
        ``*_boundingBox.vtk`` files among them give the box and are not particle frames.
    time_step : float, optional
        Simulation time step, s: a file without a ``TIME`` field array is at the step number
        of its name times it.

    Returns
    -------
    ParticleSeries
        Frames in time order, read one file at a time.

    Raises
    ------
    InputError
        If no particle file is found, a time cannot be known (no ``TIME`` array, no step in
        the name, or no ``time_step``), two files have one time, or a file is not read.
    """
    paths = source_files(source, (".vtk",))
    boxes = {p.name.replace(BOUNDING_BOX, ""): p for p in paths if BOUNDING_BOX in p.stem}
    particles = [p for p in paths if BOUNDING_BOX not in p.stem]
    for path in particles:
        if (path.parent / (path.stem + BOUNDING_BOX + path.suffix)).exists():
            boxes.setdefault(path.name, path.parent / (path.stem + BOUNDING_BOX + path.suffix))
    if not particles:
        raise InputError(f"{_label(paths)}: only bounding-box files, no particle file")
    label = _label(particles)
    first = read_legacy(particles[0])
    position = _step_position(particles)
    first_time = _legacy_time(first, particles[0], time_step, position)
    if len(particles) > 1:
        stamped = []
        for path in particles:
            step = _step_of(path, position)
            if step is None and first_time[1] != "TIME":
                raise InputError(f"{path}: no step number in the file name and no TIME array: "
                                 "the files cannot be put in time order")
            stamped.append((step if step is not None else 0, path.name, path))
        particles = [p for *_, p in sorted(stamped)]
    builder = _Frames()
    provenance = {"time_from": ("the TIME field array" if first_time[1] == "TIME" else
                                "the step in the file name x --time-step"),
                  "time_step": time_step, "box_from": "*_boundingBox.vtk" if boxes else None}
    if len(particles) > 1:
        provenance["source_files"] = [p.name for p in particles]

    def frames() -> Iterator[ParticleFrame]:
        seen: dict[float, str] = {}
        for k, path in enumerate(particles):
            data = first if k == 0 else read_legacy(path)
            if data.dataset not in ("POLYDATA", "UNSTRUCTURED_GRID"):
                raise InputError(f"{path}: DATASET {data.dataset} is not particle data "
                                 "(POLYDATA or UNSTRUCTURED_GRID with POINTS)")
            if data.points is None:
                raise InputError(f"{path}: no POINTS")
            time = _legacy_time(data, path, time_step, position)[0]
            if time in seen:
                raise InputError(f"{path}: time {time:g} s again (as in {seen[time]}); one file "
                                 "per time step")
            seen[time] = path.name
            arrays = dict(data.point_data)
            box = _bounding_box(boxes.get(path.name))
            yield builder.frame(time, data.points, arrays, box, str(path))

    series = ParticleSeries(label=label, fmt="vtk", frames=_sorted_by_time(frames(), label),
                            source_file=particles[0].name, provenance=provenance,
                            late_provenance=builder.provenance)
    return series


def _legacy_time(data, path: Path, time_step: float | None,
                 position: int = -1) -> tuple[float, str]:
    name = _find(data.field_data, _TIME_NAMES)
    if name is not None and np.asarray(data.field_data[name]).size:
        time = float(np.asarray(data.field_data[name]).ravel()[0])
        if not np.isfinite(time):
            raise InputError(f"{path}: the TIME array holds {time}")
        return time, "TIME"
    step = _step_of(path, position)
    if step is None:
        raise InputError(f"{path}: no TIME field array and no step number in the file name: "
                         "the frame's time is unknown")
    if time_step is None:
        raise InputError(f"{path}: the files carry no time (no TIME array); give the simulation "
                         f"time step with --time-step (s): {path.name} is step {step}")
    return step * time_step, "step"


def _bounding_box(path: Path | None) -> np.ndarray | None:
    if path is None:
        return None
    data = read_legacy(path)
    if data.dataset != "RECTILINEAR_GRID" or len(data.coordinates) != 3:
        raise InputError(f"{path}: a bounding-box file should be a RECTILINEAR_GRID with X, Y "
                         "and Z coordinates")
    return np.array([(c.min(), c.max()) for c in data.coordinates], dtype=np.float64)


def _sorted_by_time(frames: Iterator[ParticleFrame], label: str) -> Iterator[ParticleFrame]:
    """The frames, refused where a time does not increase (files out of order)."""
    last = None
    for frame in frames:
        if last is not None and frame.time == last:
            raise InputError(f"{frame.where}: the same time {frame.time:g} s as the file "
                             f"before (in {label}): the files are pieces of one frame "
                             "(written in parallel, as MFiX's RISER_DES_*_p*.vtp) or copies; "
                             "import the .pvd that lists the pieces of each frame")
        if last is not None and frame.time < last:
            raise InputError(f"{frame.where}: time {frame.time:g} s does not follow "
                             f"{last:g} s of the file before (in {label})")
        last = frame.time
        yield frame


def vtp_series(source, time_step: float | None = None) -> ParticleSeries:
    """The frames of a VTK XML particle series: a ``.pvd`` collection, or ``.vtp``
    (PolyData) or ``.vtu`` (UnstructuredGrid) files of the particle centres.

    Parameters
    ----------
    source : str, os.PathLike or list
        A ``.pvd`` file (times from it), a folder (its ``.pvd`` of particle files,
        :func:`~cfbmarkov.io.vtk_xml.particle_collection`, else its ``.vtp`` and ``.vtu``
        files), a ``.vtp`` or ``.vtu`` file, a glob pattern or a list of such files (times
        from MFiX's ``<!-- Time = ... s -->`` comment or a ``TimeValue`` field array, else
        from the step number in the file name times ``time_step``).
    time_step : float, optional
        The simulation time step (s) that dates files without a time by the step in their
        name (pyevtk's, Yade's and LIGGGHTS' series without a ``.pvd``).

    Returns
    -------
    ParticleSeries

    Raises
    ------
    InputError
        If a time is unknown or repeated, or a file is not read.
    """
    path = Path(os.fspath(source)) if not isinstance(source, (list, tuple)) else None
    if path is not None and path.is_dir():
        path = particle_collection(path) or path
    if path is not None and path.suffix.lower() == ".pvd":
        check_source(path)
        listing = read_pvd(path)
        for _, files in listing:
            for file in files:
                if not file.exists():
                    raise InputError(f"{path}: lists {file.name}, which does not exist beside it")
        entries = [(time, files) for time, files in listing]
        time_from, label, first_name = "the .pvd collection", str(path), path.name
        names = [f.name for _, files in entries for f in files]
    else:
        files = source_files(source, PARTICLE_SUFFIXES)
        entries = [(None, [f]) for f in files]
        time_from, label, first_name = ("each file's '<!-- Time = ... s -->' comment or "
                                          "TimeValue array" + (
                                              "" if time_step is None else
                                              f", else its step number x --time-step "
                                              f"{time_step:g} s")), _label(files), files[0].name
        names = [f.name for f in files]
    position = _step_position([files[0] for _, files in entries])
    listed = sorted({t for t, _ in entries if t is not None})
    spacing = float(np.diff(listed).min()) if len(listed) > 1 else None
    builder = _Frames()
    provenance = {"time_from": time_from, "box_from": None, "source_files": names}

    def frames() -> Iterator[ParticleFrame]:
        read = []
        for time, files in entries:
            datas = [read_vtp(f) for f in files]
            points = np.concatenate([d.points for d in datas])
            if points.ndim != 2 or points.shape[1] != 3:
                raise InputError(f"{files[0]}: points with {points.shape[-1]} components; "
                                 "expected 3")
            arrays = {k: np.concatenate([d.point_data[k] for d in datas])
                      for k in datas[0].point_data}
            if time is None:
                time = _vtp_time(datas[0], files[0], time_step, position)
            elif datas[0].comment_time is not None:
                _check_listed_time(time, datas[0].comment_time, spacing, files[0], label)
            read.append((time, points, arrays, files[0]))
            if entries[0][0] is not None:                  # a .pvd: already in time order
                yield builder.frame(time, points, arrays, None, str(files[0]))
                read.clear()
        read.sort(key=lambda r: r[0])
        for time, points, arrays, file in read:
            yield builder.frame(time, points, arrays, None, str(file))

    first_file = entries[0][1][0]
    fmt = "vtu" if first_file.suffix.lower() == ".vtu" else "vtp"
    flags = _export_flags(first_file)
    series = ParticleSeries(label=label, fmt=fmt, frames=_sorted_by_time(frames(), label),
                            source_file=first_name, provenance=provenance,
                            late_provenance=builder.provenance, flags=flags,
                            flags_from="the export's cfbmarkov_periodic field")
    return series


def _check_listed_time(listed: float, written: float, spacing: float | None, file: Path,
                       label: str) -> None:
    """Refuse a .pvd whose time for ``file`` contradicts the file's own
    ``<!-- Time = ... s -->`` comment (MFiX writes both): the frames would be put in
    another order, the particles stepping back and forth."""
    tolerance = 0.25 * spacing if spacing else 1e-6 * max(1.0, abs(listed))
    if abs(written - listed) > tolerance:
        raise InputError(f"{label}: lists {file.name} at t = {listed:g} s, while the file "
                         f"says Time = {written:g} s in its header comment; correct the "
                         ".pvd's timestep, or import the files themselves (their comments "
                         "give the times)")


def _export_flags(path: Path) -> tuple[str, ...]:
    """The periodicity per axis that ``cfbmarkov export-vtk`` records in each particle file
    (its ``cfbmarkov_periodic`` field array: ``p`` periodic, ``f`` a wall or open); empty
    for other writers' files."""
    from cfbmarkov.io.vtk import PERIODIC_FIELD

    try:
        field_data = read_vtp(path).field_data
    except InputError:
        return ()                  # the frames' reading says what is wrong with it
    values = field_data.get(PERIODIC_FIELD)
    if values is None or np.size(values) != 3:
        return ()
    return tuple("p" if int(v) else "f" for v in np.ravel(values))


def _vtp_time(data, path: Path, time_step: float | None = None, position: int = -1) -> float:
    if data.comment_time is not None:
        return data.comment_time
    name = _find(data.field_data, _TIME_NAMES)
    if name is not None and data.field_data[name].size:
        return float(data.field_data[name][0])
    step = _step_of(path, position)
    if time_step is not None and step is not None:
        return step * time_step
    from cfbmarkov.io.vtk import PERIODIC_FIELD

    if PERIODIC_FIELD in data.field_data:       # written by cfbmarkov export-vtk
        raise InputError(f"{path}: no time in the file; import the .pvd that cfbmarkov "
                         "export-vtk wrote beside it (it lists each frame's time), or give "
                         "the time between its files with --time-step (s): export-vtk numbers "
                         "the files it writes 0, 1, 2, ..., so their times then start at 0")
    raise InputError(f"{path}: no time in the file (no '<!-- Time = ... s -->' comment, no "
                     "TimeValue field array); import the .pvd that lists it"
                     + (f", or give the simulation time step with --time-step (s): "
                        f"{path.name} is step {step}" if step is not None else ""))
