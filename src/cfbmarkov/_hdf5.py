"""HDF5 helpers shared by the file readers and writers: opening a file for reading with a
one-line message on failure, compressed array datasets, JSON attributes."""

from __future__ import annotations

import errno
import os
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import h5py
import numpy as np

try:                    # ISA-L's deflate: the same zlib format, about five times faster
    from isal import isal_zlib
except ImportError:     # pragma: no cover - isal is a dependency; zlib where it is missing
    isal_zlib = None

from cfbmarkov._names import check_not_pipe, first_line
from cfbmarkov._version import __version__
from cfbmarkov.errors import InputError

#: elements an [S, S]-like array must have before :func:`create_array_dataset` compresses it
COMPRESS_MIN_SIZE = 4096


def deflate_bytes(raw: bytes, level: int = 1) -> bytes:
    """``raw`` deflated in the zlib format (RFC 1950), which HDF5's deflate filter reads
    and writes, at compression level ``level``: by ISA-L (``isal``, levels 0-3; about five
    times zlib's speed at level 1, a few per cent larger) where it is installed, by zlib
    otherwise. Releases the GIL, so that threads deflate chunks in parallel; the same
    bytes for the same input.

    Parameters
    ----------
    raw : bytes
        The data (a chunk's bytes, filtered as the dataset's pipeline says before deflate).
    level : int, optional
        Compression level, as HDF5's ``compression_opts`` of gzip (default 1).

    Returns
    -------
    bytes
    """
    if isal_zlib is not None and level <= 3:
        return isal_zlib.compress(raw, level)
    return zlib.compress(raw, level)


def deflated_chunks(chunk_bytes, starts: list, level: int = 1,
                    threaded: bool = True) -> list[bytes]:
    """``chunk_bytes(start)`` of each of ``starts`` deflated at ``level``
    (:func:`deflate_bytes`), in order: in up to four threads where ``threaded`` and the
    machine has more than one core (the deflate releases the GIL), else in this one. The
    same bytes either way."""
    def deflate(start):
        return deflate_bytes(chunk_bytes(start), level)

    workers = min(4, os.cpu_count() or 1)
    if threaded and workers > 1 and len(starts) > 1:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            return list(pool.map(deflate, starts))
    return [deflate(start) for start in starts]


def create_array_dataset(group: h5py.Group, name: str, value) -> h5py.Dataset:
    """Write ``value`` as dataset ``name`` of ``group``, compressed where it pays.

    An array of two or more dimensions with at least :data:`COMPRESS_MIN_SIZE` elements
    (the [S, S] matrices of a model) is stored chunked in blocks of whole rows of about
    1 MiB and compressed with gzip (deflate) at level 1, the chunks deflated in parallel
    threads and written as they are (``write_direct_chunk``); anything else is stored plain.
    Deflate is built into every HDF5 library, so any reader still reads the dataset as a
    plain dense array. Level 1 without the shuffle filter: on the sparse matrices of a
    model it gave the smallest file and the fastest load of the settings tried (shuffle
    and higher levels gave larger or slower files).

    Parameters
    ----------
    group : h5py.Group
        Where to create the dataset.
    name : str
        The dataset's name.
    value : array_like
        Its data (stored with its own dtype and shape).

    Returns
    -------
    h5py.Dataset
    """
    value = np.asarray(value)
    if value.ndim < 2 or value.size < COMPRESS_MIN_SIZE:
        return group.create_dataset(name, data=value)
    row = int(np.prod(value.shape[1:])) * value.dtype.itemsize
    rows = int(min(value.shape[0], max(1, (1 << 20) // max(row, 1))))
    if not value.dtype.isnative:        # HDF5 converts the bytes itself
        return group.create_dataset(name, data=value, chunks=(rows, *value.shape[1:]),
                                    compression="gzip", compression_opts=1)
    dataset = group.create_dataset(name, shape=value.shape, dtype=value.dtype,
                                   chunks=(rows, *value.shape[1:]), compression="gzip",
                                   compression_opts=1)
    # the chunks deflated in threads (deflate_bytes releases the GIL), then written as they are:
    # the same zlib stream HDF5's deflate filter writes, in a fraction of the time
    starts = range(0, value.shape[0], rows)

    def chunk_bytes(start: int) -> bytes:
        chunk = value[start:start + rows]
        if chunk.shape[0] < rows:                      # the last chunk, padded as HDF5 does
            chunk = np.concatenate([chunk, np.zeros((rows - chunk.shape[0],
                                                     *value.shape[1:]), value.dtype)])
        return np.ascontiguousarray(chunk).tobytes()

    starts = list(starts)
    for start, deflated in zip(starts, deflated_chunks(chunk_bytes, starts)):
        dataset.id.write_direct_chunk((start,) + (0,) * (value.ndim - 1), deflated)
    return dataset



def json_default(obj):
    """``json.dumps`` default: numpy arrays and scalars, paths."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.integer, np.floating)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


def package_version() -> str:
    """The installed cfbmarkov version."""
    return __version__


def open_h5(path: str | os.PathLike, mode: str = "r") -> h5py.File:
    """Open an HDF5 file, refusing in one line what cannot be opened.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    mode : str, optional
        The h5py mode (default ``"r"``).

    Returns
    -------
    h5py.File

    Raises
    ------
    InputError
        If the file is missing, empty, not readable (permission denied), locked by a
        program writing it, not HDF5 (truncated, or another format), or damaged (its root
        group cannot be read).
    """
    if str(path) == "":
        raise InputError("an empty file name (''): give the path of a cfbmarkov trajectory or "
                         "model file (.h5)")
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(f"{path!r} is no file name: give the path of a cfbmarkov trajectory "
                         "or model file (.h5) as a str or pathlib.Path")
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    check_not_pipe(path)
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")
    try:
        handle = h5py.File(path, mode)
    except OSError as exc:
        text = str(exc).lower()
        if isinstance(exc, PermissionError) or "permission denied" in text or \
                getattr(exc, "errno", None) in (errno.EACCES, errno.EPERM):
            raise InputError(f"{path}: cannot read (permission denied)") from None
        if "unable to lock file" in text:
            raise InputError(f"{path}: locked by another program that is writing it (HDF5 "
                             "file lock); wait for it to end") from None
        if Path(path).is_dir():
            raise InputError(f"{path}: is a folder, not a file; give a cfbmarkov trajectory "
                             "or model file (.h5) in it") from None
        raise InputError(f"{path}: not a readable HDF5 file: truncated (copy it or write it "
                         "again: fit again for a model) or of another format (particle data: "
                         "cfbmarkov import it first)") from None
    try:                                # a damaged root group fails only when it is read
        handle.attrs.get("format")
        list(handle.keys())
    except Exception as exc:            # noqa: BLE001 - whatever a damaged file raises
        handle.close()
        raise InputError(f"{path}: damaged HDF5 file, cannot be read ({first_line(exc)})"
                         ) from None
    return handle
