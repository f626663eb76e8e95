"""ParaView export: a trajectory file -> VTK XML files and ``.pvd`` time series (via pyevtk).

``export_vtk(run, output)`` writes into the folder ``output``:

``particles_NNNNNN.vtu``
    One unstructured grid of vertices per exported frame. Points are (x, y, 0) m in the
    particle order of the file ((x, y, z) with z the depth in a 3D file). Point data:
    ``colour_group`` (int8; the tracer group of the mixing definition,
    :func:`cfbmarkov.analysis.mixing.left_tracer_group`: 1 = the left
    tracer group, the particles with x < W/2 in the *first exported frame*, 0 = the right
    tracer group, -1 = not in the first exported frame; the array keeps its name
    ``colour_group``, by which ParaView colours the particles), ``id`` (int64), ``lap``
    (int32) and,
    when the file stores velocities, ``speed`` (float64, m/s) and ``velocity`` (3 components,
    z = 0 in 2D, m/s). ``colour_group`` comes first so that ParaView colours by it when opened.
    Where particles come and go (an open riser, tracks), a frame's points are the particles
    present in it, so the point count varies from frame to frame.
``gas_NNNNNN.vtr``
    When the file has a ``/fields`` group (CFD-DEM runs) and ``fields=True``: one rectilinear
    grid per exported frame that has a gas frame at the same time, cell data
    ``void_fraction``, ``pressure`` (Pa) and ``gas_velocity`` (3 components, z = 0, m/s).
``particles.pvd``, ``gas.pvd``
    ParaView collections (open these), timestep = simulated time in s. ``gas.pvd`` is
    written only when at least one gas file is.

``NNNNNN`` is the frame's index in the trajectory file (not its rank in the export), so a
particle and a gas file of the same frame share the number, and a frame keeps its name
whatever window or stride is exported.

The gas grid is flat: node coordinates are the cell edges x = x0 + dx * arange(nx + 1),
y = y0 + dy * arange(ny + 1) and a single z node, z = [0]. VTK counts the cells of a
structured grid along the axes with more than one node only, so the grid holds nx x ny
2D cells (VTK_PIXEL) carrying the cell data, lying in the plane z = 0 of the particles
(ParaView draws points over coincident surfaces). A slab z = [0, dz] would instead hide
the particles behind its top face in the default 2D view (camera on +z) and give the
fields a thickness that the 2D model does not have.

Gas frames are matched to particle frames by time (relative tolerance 1e-9, on a 1 s
scale near t = 0). Exported frames with no gas frame get no gas file; their number is
reported in :class:`VtkExport` and by a warning, not raised.

The export is atomic: everything is written into a temporary sibling folder
``<output>.tmp-XXXX`` that is renamed to ``output`` when complete. A folder left by a
previous export (only these files in it), or an empty folder, is replaced only then; any
other existing folder is refused. On any error no partial output and no temporary folder
remain.
"""

from __future__ import annotations

import os
import re
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import h5py
import numpy as np

from cfbmarkov._atomic import atomic_folder
from cfbmarkov.analysis.mixing import left_tracer_group
from cfbmarkov.errors import CfbmarkovWarning, InputError
from cfbmarkov.trajectories import Trajectories, opened

#: relative tolerance (on max(|t|, 1 s)) for matching a gas frame to a particle frame
FIELD_TIME_TOLERANCE = 1e-9
PARTICLES = "particles"
GAS = "gas"
#: the names an export writes; a folder holding only these may be replaced by a new export
_EXPORT_NAME = re.compile(r"^(particles\.pvd|gas\.pvd|particles_\d{6,}\.vtu|gas_\d{6,}\.vtr)$")


@dataclass(frozen=True)
class VtkExport:
    """What :func:`export_vtk_summary` wrote.

    Attributes
    ----------
    output : pathlib.Path
        The output folder.
    times : numpy.ndarray, shape (F,)
        Times of the exported frames, s.
    frames : numpy.ndarray of int, shape (F,)
        Indices of the exported frames in the trajectory file.
    n_particle_files : int
        Particle files written (``particles_NNNNNN.vtu``).
    n_gas_files : int
        Gas files written (``gas_NNNNNN.vtr``).
    n_gas_missing : int
        Exported frames whose gas file was skipped (the file has fields, none at that time).
    """

    output: Path
    #: times (s) of the exported frames
    times: np.ndarray
    #: indices of the exported frames in the trajectory file
    frames: np.ndarray
    n_particle_files: int
    n_gas_files: int
    #: exported frames whose gas file was skipped (the file has fields, none at that time)
    n_gas_missing: int


# -- the gas-field group ----------------------------------------------------------------------
@dataclass(frozen=True)
class GasFields:
    """The optional ``/fields`` group of a trajectory file (read lazily, frame by frame).

    Node coordinates (cell edges) ``x_edges`` [nx+1] and ``y_edges`` [ny+1] in m; arrays
    ``void_fraction``, ``pressure`` [T, ny, nx] and ``gas_velocity`` [T, ny, nx, 2] stay
    h5py datasets (None when absent).
    """

    times: np.ndarray
    x_edges: np.ndarray
    y_edges: np.ndarray
    void_fraction: h5py.Dataset | None
    gas_velocity: h5py.Dataset | None
    pressure: h5py.Dataset | None

    @property
    def shape(self) -> tuple[int, int]:
        """(nx, ny) cells."""
        return self.x_edges.size - 1, self.y_edges.size - 1

    def match(self, times: np.ndarray) -> np.ndarray:
        """For each time, the index of the gas frame at that time, or -1 if there is none.

        Parameters
        ----------
        times : array_like, shape (F,)
            Particle frame times, s.

        Returns
        -------
        numpy.ndarray of int64, shape (F,)
            Index into :attr:`times` of the gas frame within the relative tolerance
            :data:`FIELD_TIME_TOLERANCE` (on max(|t|, 1 s)), else -1.
        """
        times = np.asarray(times, dtype=np.float64)
        last = self.times.size - 1
        if last < 0:
            return np.full(times.size, -1, dtype=np.int64)
        k = np.searchsorted(self.times, times)
        lower, upper = np.clip(k - 1, 0, last), np.clip(k, 0, last)
        nearest = np.where(np.abs(self.times[lower] - times) <= np.abs(self.times[upper] - times),
                           lower, upper)
        tol = FIELD_TIME_TOLERANCE * np.maximum(np.abs(times), 1.0)
        return np.where(np.abs(self.times[nearest] - times) <= tol, nearest, -1).astype(np.int64)


#: the field array of every particle file ``export-vtk`` writes: 1 where an axis (x, y, z)
#: is periodic; y is the riser's vertical (``import`` takes the riser's boundary from it)
PERIODIC_FIELD = "cfbmarkov_periodic"

def read_gas_fields(traj: Trajectories) -> GasFields | None:
    """The ``/fields`` group of a trajectory file, checked against the layout.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    GasFields or None
        The gas fields (datasets read lazily), None when the file has no ``/fields``.

    Raises
    ------
    InputError
        When the group is damaged: ``spacing``, ``origin`` or ``shape`` attributes missing,
        not numbers or not two entries each, a spacing that is not positive, a shape that
        is not whole numbers >= 1, no ``time`` dataset or times not finite and increasing,
        a field of the wrong shape, or none of ``void_fraction``, ``gas_velocity``,
        ``pressure``.

    References
    ----------
    ``docs/definitions.md`` (File formats, Trajectory files).
    """
    # Trajectories has no public accessor for groups outside /provenance; opening the path a
    # second time with h5py is unsafe (closing one handle closes the other's objects).
    f: h5py.File = traj._file
    if "fields" not in f:
        return None
    g = f["fields"]
    where = f"{traj.path}: damaged /fields group"
    try:
        spacing = np.asarray(g.attrs["spacing"], dtype=np.float64).reshape(-1)
        origin = np.asarray(g.attrs.get("origin", (0.0, 0.0)), dtype=np.float64).reshape(-1)
        shape = np.asarray(g.attrs["shape"]).reshape(-1)
    except KeyError as exc:
        raise InputError(f"{where} (no attribute {exc.args[0]!r})") from None
    except (TypeError, ValueError):
        raise InputError(f"{where} (attributes spacing, origin, shape are not numbers)") from None
    if spacing.size != 2 or origin.size != 2 or shape.size != 2:
        raise InputError(f"{where} (spacing, origin and shape must have two entries each)")
    if not (np.all(np.isfinite(spacing)) and np.all(spacing > 0) and np.all(np.isfinite(origin))):
        raise InputError(f"{where} (spacing {spacing.tolist()} m must be positive)")
    if not (np.all(shape == np.round(shape)) and np.all(shape >= 1)):
        raise InputError(f"{where} (shape {shape.tolist()} must be whole numbers >= 1)")
    nx, ny = int(shape[0]), int(shape[1])
    if "time" not in g or not isinstance(g["time"], h5py.Dataset):
        raise InputError(f"{where} (no 'time' dataset)")
    times = np.asarray(g["time"][()], dtype=np.float64).reshape(-1)
    if times.ndim != 1 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise InputError(f"{where} (times are not finite and increasing)")
    arrays = {}
    for name, tail in (("void_fraction", ()), ("gas_velocity", (2,)), ("pressure", ())):
        ds = g.get(name)
        if ds is not None:
            expected = (times.size, ny, nx) + tail
            if not isinstance(ds, h5py.Dataset) or ds.shape != expected:
                got = ds.shape if isinstance(ds, h5py.Dataset) else "a group"
                raise InputError(f"{where} ('{name}' has shape {got}, expected {expected} "
                                 f"for {times.size} times on {nx} x {ny} cells)")
        arrays[name] = ds
    if all(ds is None for ds in arrays.values()):
        raise InputError(f"{where} (none of void_fraction, gas_velocity, pressure)")
    return GasFields(times=times,
                     x_edges=origin[0] + spacing[0] * np.arange(nx + 1, dtype=np.float64),
                     y_edges=origin[1] + spacing[1] * np.arange(ny + 1, dtype=np.float64),
                     **arrays)


# -- the export ---------------------------------------------------------------------------------
def export_vtk(run: str | os.PathLike | Trajectories, output: str | os.PathLike, *,
               start: float | None = None, stop: float | None = None, every: int = 1,
               fields: bool = True, progress: bool = False) -> Path:
    """Export frames of a trajectory file as VTK files for ParaView (see the module docstring).

    Parameters
    ----------
    run : str, os.PathLike or Trajectories
        A trajectory file path or an open :class:`~cfbmarkov.trajectories.Trajectories`
        (left open).
    output : str or os.PathLike
        The output folder (new, empty, or holding only a previous export).
    start, stop : float, optional
        Export the frames with start <= t <= stop, s (default: all).
    every : int, optional
        Export every ``every``-th of those frames (>= 1).
    fields : bool, optional
        Write the gas fields when the file has them.
    progress : bool, optional
        Show a progress bar on stderr, where it is a terminal.

    Returns
    -------
    pathlib.Path
        The output folder.

    Raises
    ------
    InputError
        When pyevtk is missing, ``every`` is not a whole number >= 1, ``start``/``stop`` are
        not finite numbers or select no frame of the file, ``output`` is a file (or the
        input) or a folder holding other files, the ``/fields`` group is damaged, or the
        output cannot be created or written. No output is left behind.
    """
    return export_vtk_summary(run, output, start=start, stop=stop, every=every, fields=fields,
                              progress=progress).output


def export_vtk_summary(run: str | os.PathLike | Trajectories, output: str | os.PathLike, *,
                       start: float | None = None, stop: float | None = None, every: int = 1,
                       fields: bool = True, progress: bool = False) -> VtkExport:
    """:func:`export_vtk`, returning what was written (files, frames, gas frames missing).

    Parameters
    ----------
    run : str, os.PathLike or Trajectories
        A trajectory file path or an open :class:`~cfbmarkov.trajectories.Trajectories`
        (left open).
    output : str or os.PathLike
        The output folder (new, empty, or holding only a previous export).
    start, stop : float, optional
        Export the frames with start <= t <= stop, s (default: all).
    every : int, optional
        Export every ``every``-th of those frames (>= 1).
    fields : bool, optional
        Write the gas fields when the file has them.
    progress : bool, optional
        Show a progress bar on stderr, where it is a terminal.

    Returns
    -------
    VtkExport
        The output folder, the exported frames and their times, and the files written.

    Raises
    ------
    InputError
        When pyevtk is missing, ``every`` is not a whole number >= 1, ``start``/``stop`` are
        not finite numbers or select no frame of the file, ``output`` is a file (or the
        input) or a folder holding other files, the ``/fields`` group is damaged, or the
        output cannot be created or written. No output is left behind.
    """
    hl = _pyevtk()
    every = _check_every(every)
    output = Path(output)
    with opened(run) as traj:
        traj.require_supported("VTK export", three_d=True, absent=True, open_boundary=True)
        frames = _select_frames(traj, start, stop, every)
        _check_output(output, traj.path)
        gas = read_gas_fields(traj) if fields else None
        times = traj.times[frames]
        gas_index = gas.match(times) if gas is not None else np.full(frames.size, -1)
        with atomic_folder(output) as tmp:
            n_gas = _write(hl, traj, gas, frames, gas_index, tmp, progress)
    missing = int(np.count_nonzero(gas_index < 0)) if gas is not None else 0
    if missing:
        warnings.warn(f"{missing} of {frames.size} exported frames have no gas field at their "
                      f"time; their gas files were skipped", CfbmarkovWarning, stacklevel=2)
    return VtkExport(output=output, times=times, frames=frames, n_particle_files=int(frames.size),
                     n_gas_files=n_gas, n_gas_missing=missing)


def _write(hl, traj: Trajectories, gas: GasFields | None, frames: np.ndarray,
           gas_index: np.ndarray, folder: Path, progress: bool) -> int:
    """Write the files of the export into ``folder``; returns the number of gas files."""
    from pyevtk.vtk import VtkGroup

    n = traj.n_particles
    zeros = np.zeros(n, dtype=np.float64)
    ids = np.ascontiguousarray(traj.ids, dtype=np.int64)
    tracer_group = None
    particle_files: list[tuple[str, float]] = []
    gas_files: list[tuple[str, float]] = []
    for frame, g in _progress(zip(frames.tolist(), gas_index.tolist()), frames.size, progress):
        t = float(traj.times[frame])
        position = traj.positions(frame)
        x = np.ascontiguousarray(position[:, 0], dtype=np.float64)
        y = np.ascontiguousarray(position[:, 1], dtype=np.float64)
        z = np.ascontiguousarray(position[:, 2], dtype=np.float64) if position.shape[1] == 3 else zeros
        keep = traj.present(frame) if traj.has_absences else None
        if tracer_group is None:
            tracer_group = left_tracer_group(x, 0.5 * traj.width).astype(np.int8)
            if keep is not None:         # absent from the first frame: no tracer group
                tracer_group[~keep] = -1
        point_data = {"colour_group": tracer_group, "id": ids,
                "lap": np.ascontiguousarray(traj.laps(frame), dtype=np.int32)}
        for prop in traj.property_names:      # particle properties (kinetics)
            point_data[prop] = np.ascontiguousarray(traj.property_values(prop, frame),
                                                    dtype=np.float64)
        velocity = traj.velocities(frame)
        if velocity is not None:
            vx = np.ascontiguousarray(velocity[:, 0], dtype=np.float64)
            vy = np.ascontiguousarray(velocity[:, 1], dtype=np.float64)
            if velocity.shape[1] == 3:
                vz = np.ascontiguousarray(velocity[:, 2], dtype=np.float64)
                point_data["speed"] = np.sqrt(vx * vx + vy * vy + vz * vz)
            else:
                vz = zeros
                point_data["speed"] = np.hypot(vx, vy)
            point_data["velocity"] = (vx, vy, vz)
        if keep is not None:             # only the particles in the frame are points
            x, y, z = (np.ascontiguousarray(a[keep]) for a in (x, y, z))
            point_data = {key: (tuple(np.ascontiguousarray(c[keep]) for c in value)
                                if isinstance(value, tuple) else np.ascontiguousarray(value[keep]))
                          for key, value in point_data.items()}
        name = f"{PARTICLES}_{frame:06d}"
        if x.size:
            # the vertical boundary, for an import of the export: periodic per axis
            periodic = np.array([0, 0 if traj.boundary.is_open else 1, 0], dtype=np.int32)
            hl.pointsToVTK(str(folder / name), x, y, z, data=point_data,
                           fieldData={PERIODIC_FIELD: periodic})
        else:                            # every particle absent (an open riser emptied)
            _write_no_points(folder / (name + ".vtu"), point_data,
                             np.array([0, 0 if traj.boundary.is_open else 1, 0]))
        particle_files.append((name + ".vtu", t))
        if gas is not None and g >= 0:
            name = f"{GAS}_{frame:06d}"
            _write_gas(hl, gas, g, folder / name)
            gas_files.append((name + ".vtr", t))
    for stem, files in ((PARTICLES, particle_files), (GAS, gas_files)):
        if files:
            group = VtkGroup(str(folder / stem))
            for name, t in files:
                # the frame's time to 12 digits: 10.075, not 10.075000000000001
                group.addFile(filepath=str(folder / name), sim_time=float(f"{t:.12g}"))
            group.save()
    return len(gas_files)


#: the VTK XML type names of the point-data arrays' dtypes
_VTK_TYPES = {"f8": "Float64", "f4": "Float32", "i8": "Int64", "i4": "Int32", "i1": "Int8",
              "u1": "UInt8"}


def _write_no_points(path: Path, point_data: dict, periodic: np.ndarray) -> None:
    """A frame without particles as pyevtk writes a frame of points (an UnstructuredGrid,
    raw appended data with UInt64 byte counts), with no point and every array of
    ``point_data`` empty: pyevtk refuses a piece without points, and a ParaView series
    needs a file for every time. It carries the periodicity per axis (``periodic``, the
    :data:`PERIODIC_FIELD` field array) as the files with points do, so that an import of
    an export whose first frame is empty knows the boundary."""
    arrays = [("points", 3, "Float64")]
    arrays += [("connectivity", 1, "Int32"), ("offsets", 1, "Int32"), ("types", 1, "UInt8")]
    for key, value in point_data.items():
        first = value[0] if isinstance(value, tuple) else value
        arrays.append((key, 3 if isinstance(value, tuple) else 1,
                       _VTK_TYPES[np.dtype(first.dtype).str[1:]]))

    def entry(k: int) -> str:
        name, components, kind = arrays[k]
        return (f'<DataArray Name="{name}" NumberOfComponents="{components}" type="{kind}" '
                f'format="appended" offset="{8 * k}"/>\n')

    flags = np.asarray(periodic, dtype="<i4")       # appended after the empty arrays
    text = ('<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="1.0" '
            'byte_order="LittleEndian" header_type="UInt64">\n<UnstructuredGrid>\n'
            '<Piece NumberOfPoints="0" NumberOfCells="0">\n<Points>\n' + entry(0)
            + '</Points>\n<Cells>\n' + entry(1) + entry(2) + entry(3) + '</Cells>\n'
            + '<PointData>\n' + "".join(entry(k) for k in range(4, len(arrays)))
            + '</PointData>\n<FieldData>\n'     # as pyevtk writes it, inside the piece
            + f'<DataArray Name="{PERIODIC_FIELD}" NumberOfComponents="1" type="Int32" '
            + f'format="appended" offset="{8 * len(arrays)}"/>\n</FieldData>\n'
            + '</Piece>\n</UnstructuredGrid>\n<AppendedData encoding="raw">\n_')
    path.write_bytes(text.encode() + bytes(8 * len(arrays))
                     + np.uint64(flags.nbytes).astype("<u8").tobytes() + flags.tobytes()
                     + b"\n</AppendedData>\n</VTKFile>\n")


def _write_gas(hl, gas: GasFields, index: int, path: Path) -> None:
    """One gas frame as a flat rectilinear grid with cell data (see the module docstring)."""
    cells: dict = {}

    def cell_array(values: np.ndarray) -> np.ndarray:
        # [ny, nx] (row j = y) -> [nx, ny, 1], written in Fortran order: x runs fastest, as
        # VTK numbers the cells
        return np.asfortranarray(np.asarray(values).T[:, :, None])

    def checked(name: str, values) -> np.ndarray:
        # a damaged field is refused, not drawn (a NaN or a void fraction of 7 was exported)
        values = np.asarray(values)
        bad = ~np.isfinite(values) if name != "void_fraction" else ~(
            (values >= 0.0) & (values <= 1.0))
        if bad.any():
            what = ("not a finite number" if name != "void_fraction"
                    else "not a fraction between 0 and 1")
            raise InputError(f"damaged /fields group: {name} at t = {gas.times[index]:g} s "
                             f"holds {int(bad.sum())} value(s) {what}; write the file again "
                             "from its source, or export --no-fields")
        return values

    if gas.void_fraction is not None:
        cells["void_fraction"] = cell_array(checked("void_fraction",
                                                    gas.void_fraction[index]))
    if gas.pressure is not None:
        cells["pressure"] = cell_array(checked("pressure", gas.pressure[index]))
    if gas.gas_velocity is not None:
        u = checked("gas_velocity", gas.gas_velocity[index])
        ux, uy = cell_array(u[..., 0]), cell_array(u[..., 1])
        cells["gas_velocity"] = (ux, uy, np.zeros_like(ux, order="F"))
    hl.gridToVTK(str(path), gas.x_edges, gas.y_edges, np.zeros(1, dtype=np.float64),
                 cellData=cells)


# -- arguments ----------------------------------------------------------------------------------
def _pyevtk():
    try:
        from pyevtk import hl
    except ImportError:
        raise InputError("the VTK export needs the package pyevtk "
                         "(pip install pyevtk)") from None
    return hl


def _check_every(every) -> int:
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise InputError(f"every {every!r} must be a whole number >= 1 (export every n-th frame)")
    return int(every)


def _select_frames(traj: Trajectories, start: float | None, stop: float | None,
                   every: int) -> np.ndarray:
    """Indices of the frames with start <= t <= stop, every ``every``-th from the first."""
    for name, value in (("start", start), ("stop", stop)):
        if value is not None and not np.isfinite(_as_float(name, value)):
            raise InputError(f"{name} time {value} s is not a finite number")
    t0 = float(traj.times[0]) if start is None else float(start)
    t1 = float(traj.times[-1]) if stop is None else float(stop)
    if t0 > t1 and (start is None or stop is None):   # one bound given, beyond the data
        given = f"--start {t0:g} s" if start is not None else f"--stop {t1:g} s"
        side = "after its end" if start is not None else "before its start"
        raise InputError(f"{given} lies outside the data of {traj.path}, {side} "
                         f"({traj.times[0]:g} to {traj.times[-1]:g} s)")
    if t0 == t1:
        window = slice(traj.frame_index(t0), traj.frame_index(t0) + 1)
    else:
        window = traj.window(t0, t1)
    frames = np.arange(window.start, window.stop, every, dtype=np.int64)
    if frames.size == 0:  # pragma: no cover - window() refuses empty windows
        raise InputError(f"window {t0:g}:{t1:g} s holds no frame of {traj.path}")
    return frames


def _as_float(name: str, value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} time {value!r} is not a number") from None


def _check_output(output: Path, source: Path) -> None:
    if output.exists() and not output.is_dir():
        if output.resolve() == source.resolve():
            raise InputError(f"{output}: the output would overwrite the input file")
        raise InputError(f"{output}: exists and is a file; give a folder for the VTK export")
    if output.is_dir():
        from cfbmarkov._outputs import refuse_foreign

        refuse_foreign(output, lambda p: bool(_EXPORT_NAME.match(p.name)) and p.is_file(),
                       "a VTK export", "replace it (give a new or empty folder)")


def _progress(items: Iterable, total: int, enabled: bool) -> Iterable:
    """``items`` in a bar on stderr where ``enabled`` and stderr is a terminal that can draw
    one; elsewhere (a log, a pipe) whole lines: at the start, every
    :data:`~cfbmarkov._console.HEARTBEAT_EVERY` s, and at the end."""
    from cfbmarkov._console import draws_bars

    if not enabled:
        return items
    if not draws_bars():
        return _progress_lines(items, total)
    from tqdm import tqdm

    return tqdm(items, total=total, desc="export vtk", unit="frame", file=sys.stderr, leave=False)


def _progress_lines(items: Iterable, total: int) -> Iterable:
    import time

    from cfbmarkov._console import HEARTBEAT_EVERY, clock_text, write_line

    started = last = time.perf_counter()
    write_line(f"export vtk: {total} frames")
    done = 0
    for item in items:
        yield item
        done += 1
        now = time.perf_counter()
        if now - last >= HEARTBEAT_EVERY and done < total:
            write_line(f"export vtk: {done}/{total} frames, {clock_text(now - started)} so far")
            last = now
    write_line(f"export vtk: {done} frames in {clock_text(time.perf_counter() - started)}")


__all__ = ["GasFields", "VtkExport", "export_vtk", "export_vtk_summary", "read_gas_fields"]
