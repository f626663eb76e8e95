"""The groups of a trajectory file being written: the particles and frames, created empty
and chunked one frame per chunk (an open riser's compactly, see :func:`create_frames`), and
the optional gas fields of CFD-DEM runs (``/fields``)
and exact pass events (``/events``), appended block by block (the layout is described in
:mod:`cfbmarkov.trajectories`).
"""

from __future__ import annotations

import json

import h5py
import numpy as np

from cfbmarkov._hdf5 import deflated_chunks
from cfbmarkov.errors import InputError

#: fewest particles per chunk of a frame (a file whose particles grow by insertion)
MIN_CHUNK_PARTICLES = 256
#: frames per chunk of a compact file (an open riser's)
COMPACT_FRAMES = 16


def frame_chunks(n: int, compact: bool, *tail: int, deflate: bool = True) -> dict:
    """The h5py options of a frame dataset (``/frames/position``, ``lap``, ``velocity``,
    ``present``) of ``n`` particles: one frame of every particle per chunk, or, with fewer
    than :data:`MIN_CHUNK_PARTICLES` particles (a PEPT tracer), as many frames of them as
    make about that many values, so that a chunk holds no padding (a one-tracer file of
    150 000 frames takes megabytes, not the 256-fold); or (``compact``)
    :data:`COMPACT_FRAMES` frames of :data:`MIN_CHUNK_PARTICLES` particles per chunk,
    deflated (``deflate``; a Markov prediction's, whose particles are present a short
    while each) or not (a run's: reading a deflated 2000-particle open window took 29 ms
    against 5 ms, most of an open fit), so that the particles absent from a block of frames
    take no space."""
    if not compact:
        if 0 < n < MIN_CHUNK_PARTICLES:
            return {"chunks": (MIN_CHUNK_PARTICLES // n, n, *tail)}
        return {"chunks": (1, max(n, MIN_CHUNK_PARTICLES), *tail)}
    if not deflate:
        return {"chunks": (COMPACT_FRAMES, MIN_CHUNK_PARTICLES, *tail)}
    return {"chunks": (COMPACT_FRAMES, MIN_CHUNK_PARTICLES, *tail), "compression": "gzip",
            "compression_opts": 1, "shuffle": True}


def write_frame_rows(ds: h5py.Dataset, i0: int, values: np.ndarray, compact: bool) -> None:
    """Write ``values`` (T frames) to the frame dataset ``ds`` from frame ``i0``.

    In a compact file, a block of :data:`MIN_CHUNK_PARTICLES` particles that holds only the
    dataset's fill value in these frames (NaN positions, lap 0, absent) is not written: its
    chunks stay unallocated and read back as that fill value, so an open riser's prediction,
    whose particles are present a short while each, stores only the particles present.
    A deflated compact dataset written from a chunk's first frame has its chunks deflated
    in threads and written as they are (:func:`_write_deflated_chunks`); the values read
    back are those HDF5's own filters would have stored.
    """
    i1 = i0 + values.shape[0]
    if not compact:
        ds[i0:i1] = values
        return
    if (ds.compression == "gzip" and ds.chunks is not None and i0 % ds.chunks[0] == 0
            and ds.dtype.isnative and ds.dtype.kind in "fib"):
        _write_deflated_chunks(ds, i0, np.asarray(values, dtype=ds.dtype))
        return
    fill = ds.fillvalue
    for j0 in range(0, values.shape[1], MIN_CHUNK_PARTICLES):
        block = values[:, j0:j0 + MIN_CHUNK_PARTICLES]
        if not _only_fill(block, fill):
            ds[i0:i1, j0:j0 + block.shape[1]] = block


def _only_fill(block: np.ndarray, fill) -> bool:
    """Whether ``block`` holds nothing but the fill value ``fill`` (NaN matching NaN)."""
    if isinstance(fill, float) and np.isnan(fill):
        return bool(np.isnan(block).all())
    return not (block != fill).any()


#: the fewest chunks a block deflates in threads: a one-tracer prediction's block of two
#: chunks took 1.5x as long in threads as in one (the hand-over costs more than the deflate)
THREADED_CHUNKS = 16


def _write_deflated_chunks(ds: h5py.Dataset, i0: int, values: np.ndarray) -> None:
    """Write ``values`` (T frames from frame ``i0``, a multiple of the chunks' frames) to the
    deflated dataset ``ds`` chunk by chunk, each deflated (in threads from
    :data:`THREADED_CHUNKS` chunks on: :func:`cfbmarkov._hdf5.deflated_chunks`) and written
    as it is (``write_direct_chunk``).

    A chunk holding only the fill value is not written (it reads back as that value); a
    chunk that reaches past the values (the last frames of a block, the last particles) is
    padded with the fill value, as HDF5 pads it. The bytes are those of the dataset's filter
    pipeline, byte shuffle (where set) then deflate at its level: any HDF5 reader reads them.
    Deterministic for any number of threads.
    """
    frames, particles = ds.chunks[0], ds.chunks[1]
    tail = values.shape[2:]
    fill = ds.fillvalue
    level = int(ds.compression_opts or 1)
    shuffle = bool(ds.shuffle) and values.dtype.itemsize > 1
    starts = [(f0, j0) for f0 in range(0, values.shape[0], frames)
              for j0 in range(0, values.shape[1], particles)
              if not _only_fill(values[f0:f0 + frames, j0:j0 + particles], fill)]

    def chunk_bytes(start: tuple[int, int]) -> bytes:
        f0, j0 = start
        part = values[f0:f0 + frames, j0:j0 + particles]
        if part.shape[:2] != (frames, particles):
            chunk = np.full((frames, particles, *tail), fill, dtype=values.dtype)
            chunk[:part.shape[0], :part.shape[1]] = part
        else:
            chunk = np.ascontiguousarray(part)
        raw = chunk.tobytes()
        if shuffle:      # HDF5's shuffle filter: the elements' first bytes, then their second ...
            raw = np.frombuffer(raw, np.uint8).reshape(-1, values.dtype.itemsize).T.tobytes()
        return raw

    # a few chunks (a prediction of a few particles): threads cost more than they save
    deflated = deflated_chunks(chunk_bytes, starts, level, len(starts) >= THREADED_CHUNKS)
    zeros = (0,) * len(tail)
    for (f0, j0), data in zip(starts, deflated):
        ds.id.write_direct_chunk((i0 + f0, j0, *zeros), data)


def create_frames(f: h5py.File, ids: np.ndarray, d: int, with_velocity: bool,
                  compact: bool = False, deflate: bool = True) -> int:
    """Create ``/particles/id`` and the empty, resizable frame datasets (time, position,
    lap and, with velocities, velocity; positions and velocities filled with NaN).

    A ``compact`` file (an open riser's: particles present a short while each) is chunked
    by blocks of frames and particles, deflated with ``deflate`` (:func:`frame_chunks`),
    and written by
    :func:`write_frame_rows`; the values read back are the same.

    Parameters
    ----------
    f : h5py.File
        The file being written.
    ids : ndarray of int64, shape (N,)
        Particle ids.
    d : int
        D, the coordinates per position (2 or 3).
    with_velocity : bool
        Whether the file stores velocities.
    compact : bool, optional
        Chunk by blocks of frames and particles, for particles absent from most frames.
    deflate : bool, optional
        With ``compact``, deflate the chunks (a prediction's; default True).

    Returns
    -------
    int
        Particles per chunk of a frame.
    """
    n = ids.size
    chunk = max(n, MIN_CHUNK_PARTICLES)
    f.create_dataset("particles/id", data=ids, maxshape=(None,), chunks=(max(n, 1024),))
    f.create_dataset("frames/time", shape=(0,), maxshape=(None,), dtype="f8", chunks=(4096,))
    f.create_dataset("frames/position", shape=(0, n, d), maxshape=(None, None, d), dtype="f8",
                     fillvalue=np.nan, **frame_chunks(n, compact, d, deflate=deflate))
    f.create_dataset("frames/lap", shape=(0, n), maxshape=(None, None), dtype="i4",
                     **frame_chunks(n, compact, deflate=deflate))
    if with_velocity:
        f.create_dataset("frames/velocity", shape=(0, n, d), maxshape=(None, None, d),
                         dtype="f8", fillvalue=np.nan,
                         **frame_chunks(n, compact, d, deflate=deflate))
    return chunk


def append_field_frames(f: h5py.File, label: str, times, spacing, fields: dict) -> None:
    """Append a block of gas-field frames on a cell-centred grid to ``/fields`` (one write
    per field); the first block creates the group.

    Parameters
    ----------
    f : h5py.File
        The file being written.
    label : str
        Names the file in messages.
    times : array_like, shape (T,)
        Times of the field frames (s).
    spacing : tuple of float
        (dx, dy) of the grid (m).
    fields : dict of str to array_like, shape (T, ny, nx) or (T, ny, nx, 2)
        Stored as float32: ``void_fraction`` (-), ``gas_velocity`` (m/s), ``pressure``
        (Pa). Every block must carry the same fields.

    Raises
    ------
    InputError
        If the fields are on different grids or do not hold T frames, or they are not the
        fields of earlier frames.
    """
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    g = f.require_group("fields")
    first = "time" not in g
    arrays = {name: np.asarray(value, dtype=np.float32) for name, value in fields.items()}
    if any(a.ndim < 3 or a.shape[0] != times.size for a in arrays.values()):
        raise InputError(f"{label}: gas fields must hold {times.size} frame(s) of a "
                         "2D grid each")
    if first:
        shapes = {a.shape[1:3] for a in arrays.values()}
        if len(shapes) != 1:
            raise InputError(f"{label}: gas fields of different grids {sorted(shapes)}")
        ny, nx = shapes.pop()
        g.attrs.update({"spacing": np.asarray(spacing, dtype=np.float64),
                        "origin": np.zeros(2), "shape": np.asarray([nx, ny]),
                        "units": json.dumps({"void_fraction": "-", "gas_velocity": "m/s",
                                             "pressure": "Pa"}),
                        "pressure": "the periodic part of the gas pressure, zero mean over "
                                    "the domain: the full pressure adds -G y, G (Pa/m) the "
                                    "driving gradient that carries the riser's weight, not "
                                    "stored"})
        g.create_dataset("time", shape=(0,), maxshape=(None,), dtype="f8", chunks=(1024,))
        for name, a in arrays.items():
            g.create_dataset(name, shape=(0, *a.shape[1:]), maxshape=(None, *a.shape[1:]),
                             dtype="f4", chunks=(1, *a.shape[1:]))
    elif set(arrays) != set(g) - {"time"}:
        raise InputError(f"{label}: gas fields {sorted(arrays)} differ from those of "
                         f"earlier frames {sorted(set(g) - {'time'})}")
    k = g["time"].shape[0]
    g["time"].resize(k + times.size, axis=0)
    g["time"][k:] = times
    for name, a in arrays.items():
        g[name].resize(k + times.size, axis=0)
        g[name][k:] = a


def append_events(f: h5py.File, times, particles, directions) -> None:
    """Append exact pass events, given in any order, to ``/events`` (each block sorted by
    time); the first block creates the group.

    Parameters
    ----------
    f : h5py.File
        The file being written.
    times : array_like of float, shape (E,)
        Times of the passes (s).
    particles : array_like of int, shape (E,)
        Particle indices (into ``/particles/id``).
    directions : array_like of int, shape (E,)
        +1 up through the top, -1 down through the bottom.
    """
    times = np.asarray(times, dtype=np.float64)
    order = np.argsort(times, kind="stable")
    g = f.require_group("events")
    g.attrs["exact"] = True
    for name, values, dtype in (("time", times, "f8"), ("particle", particles, "i4"),
                                ("direction", directions, "i1")):
        data = np.asarray(values)[order].astype(dtype)
        if name in g:
            old = g[name]
            old.resize(old.shape[0] + data.size, axis=0)
            old[-data.size:] = data
        else:
            g.create_dataset(name, data=data, maxshape=(None,), chunks=True)
