"""Helpers shared by the importers: opening (possibly gzipped) text, mapping read failures
to :class:`~cfbmarkov.errors.InputError`, putting a frame's rows into the reference id
order, progress bars, and cleaning up on failure."""

from __future__ import annotations

import contextlib
import decimal
import gzip
import os
import re
import shlex
import sys
import zlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from cfbmarkov._names import check_not_pipe
from cfbmarkov.errors import InputError
from cfbmarkov.trajectory_writer import TrajectoryWriter

GZIP_MAGIC = b"\x1f\x8b"


def check_source(source: str | os.PathLike) -> Path:
    """The input file as a Path.

    Parameters
    ----------
    source : str or os.PathLike
        The file to read.

    Returns
    -------
    pathlib.Path
        The same path.

    Raises
    ------
    InputError
        If it is missing, a folder, a pipe or device, or empty.
    """
    path = Path(source)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        from cfbmarkov.io.detect import folder_advice

        raise InputError(f"{path}: is a folder, not a file; {folder_advice(path)}")
    check_not_pipe(path)
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file (0 bytes): nothing to import; check the path, "
                         "or that the program writing it has finished")
    return path


def check_output(output: str | os.PathLike, source: Path) -> Path:
    """The output path.

    Parameters
    ----------
    output : str or os.PathLike
        The file to write.
    source : pathlib.Path
        The input file.

    Returns
    -------
    pathlib.Path
        The output path.

    Raises
    ------
    InputError
        If it is a folder or the input file itself.
    """
    path = Path(output)
    if path.is_dir():
        raise InputError(f"{path}: is a folder; give the name of the .h5 file to write")
    if path.exists() and path.resolve() == source.resolve():
        raise InputError(f"{path}: the output would overwrite the input file")
    return path


def open_text(path: Path) -> TextIO:
    """Open a text file for reading, decompressing it when it starts with the gzip magic bytes.

    Parameters
    ----------
    path : pathlib.Path
        The file: UTF-8 text with or without a byte-order mark, or UTF-16 with one (Excel's
        "Unicode Text"); plain or gzip-compressed.

    Returns
    -------
    TextIO
        The open text stream.

    Raises
    ------
    InputError
        If the file cannot be opened, or is a pipe.
    """
    check_not_pipe(path)
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
        if magic[:2] == GZIP_MAGIC:
            return gzip.open(path, "rt", encoding="utf-8-sig")
        return open(path, encoding=text_encoding(magic), newline=None)
    except OSError as exc:
        raise InputError(f"{path}: cannot open ({exc.strerror or exc})") from None


def check_text(source: str | os.PathLike) -> None:
    """Refuse a source that is missing, empty or not text (:func:`check_source`,
    :func:`not_text_message`), read from its first 8 KiB: where an option that does not
    apply to text is refused for a file told to be CSV by elimination, the file's own fault
    is named first.

    Parameters
    ----------
    source : str or os.PathLike
        The file (plain or gzip-compressed).

    Raises
    ------
    InputError
        As :func:`check_source`, or naming the file as not text.
    """
    path = check_source(source)
    try:
        with open_text(path) as fh:
            fh.read(8192)
    except (UnicodeDecodeError, EOFError, gzip.BadGzipFile, zlib.error):
        raise InputError(not_text_message(str(path))) from None
    with open(path, "rb") as fh:
        head = fh.read(2)
        if head != GZIP_MAGIC and head not in (b"\xff\xfe", b"\xfe\xff") \
                and b"\x00" in fh.read(8190):
            raise InputError(not_text_message(str(path)))


def text_encoding(start: bytes) -> str:
    """The encoding of a text file from its first bytes: UTF-16 where a UTF-16 byte-order
    mark starts it, else UTF-8 (a UTF-8 byte-order mark skipped).

    Parameters
    ----------
    start : bytes
        The file's first (up to 4) bytes.

    Returns
    -------
    str
        A Python codec name: ``'utf-16'`` or ``'utf-8-sig'``.
    """
    if start[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "utf-16"
    return "utf-8-sig"


def not_text_message(label: str) -> str:
    """The message for a file that is not UTF-8 text: the first line holding a byte that
    is not UTF-8, the byte, what it reads as in Windows cp1252, and the fix.

    Parameters
    ----------
    label : str
        The file's name (a path where the file can be read again to find the line).

    Returns
    -------
    str
        One line.
    """
    try:
        with open(label, "rb") as fh:
            if fh.read(2) == GZIP_MAGIC:
                fh = gzip.open(label, "rb")
            else:
                fh.seek(0)
            head = fh.read(8192)
            fh.seek(0)
            if b"\x00" in head:      # binary data (HDF5, NetCDF, ...), not text in any encoding
                return (f"{label}: not a text file (it holds binary data, bytes that are not "
                        "UTF-8 or UTF-16 text)")
            for number, raw in enumerate(fh, start=1):
                try:
                    raw.decode("utf-8")
                except UnicodeDecodeError as exc:
                    byte = raw[exc.start]
                    shown = bytes([byte]).decode("cp1252", errors="replace")
                    spreadsheet = str(label).lower().removesuffix(".gz").endswith(
                        (".csv", ".tsv", ".txt"))
                    quoted = shlex.quote(str(label))
                    convert = (f"gunzip -c {quoted} | iconv -f cp1252 -t utf-8 | gzip > "
                               "NEW.gz" if str(label).lower().endswith(".gz") else
                               f"iconv -f cp1252 -t utf-8 {quoted} > NEW")
                    how = ("save it as UTF-8 (Excel: 'CSV UTF-8') or as 'Unicode Text'"
                           if spreadsheet else
                           f"convert it to UTF-8 ({convert}), or remove the stray byte")
                    return (f"{label}: line {number}: byte 0x{byte:02x} is not UTF-8 text (in "
                            f"Windows cp1252 it is {shown!r}): the file is not UTF-8 or "
                            f"UTF-16; {how}")
    except (OSError, EOFError, gzip.BadGzipFile, zlib.error):
        pass
    return (f"{label}: not a text file (it holds bytes that are not UTF-8 or UTF-16 text); "
            "save it as UTF-8")


@contextlib.contextmanager
def reading(label: str):
    """Context manager: turn low-level read failures into InputError.

    Parameters
    ----------
    label : str
        Names the file (and position) in the message.

    Returns
    -------
    contextlib.AbstractContextManager
        A context manager that yields None.

    Raises
    ------
    InputError
        When the body raises EOFError (a cut compressed stream), a gzip or zlib error
        (damaged gzip data) or UnicodeDecodeError (not a text file).
    """
    try:
        yield
    except EOFError:
        raise InputError(f"{label}: file is truncated (the compressed stream ends early)") from None
    except (gzip.BadGzipFile, zlib.error) as exc:
        raise InputError(f"{label}: damaged gzip data ({exc})") from None
    except UnicodeDecodeError:
        raise InputError(not_text_message(label)) from None


@contextlib.contextmanager
def removing_new_folders(output: Path):
    """Context manager: on an error, remove the folders above ``output`` that the import created.

    Parameters
    ----------
    output : pathlib.Path
        The file being written; its missing parent folders are noted on entry and removed
        (deepest first, only if empty) when the body raises. The error is re-raised.

    Returns
    -------
    contextlib.AbstractContextManager
        A context manager that yields None.
    """
    new = [p for p in output.resolve().parents if not p.exists()]
    try:
        yield
    except BaseException:
        for folder in new:  # deepest first
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


def create_writer(output: Path, ids: np.ndarray, **options: Any) -> TrajectoryWriter:
    """A TrajectoryWriter on ``output``.

    Parameters
    ----------
    output : pathlib.Path
        The trajectory file to write.
    ids : numpy.ndarray
        [N] particle ids.
    **options
        Passed on to :class:`~cfbmarkov.trajectory_writer.TrajectoryWriter`.

    Returns
    -------
    TrajectoryWriter
        The open writer.

    Raises
    ------
    InputError
        If the file cannot be created.
    """
    try:
        return TrajectoryWriter(output, ids, **options)
    except OSError as exc:
        raise InputError(f"{output}: cannot write ({exc.strerror or exc})") from None


def frame_order(ids: np.ndarray, reference: np.ndarray, where: str,
                hint: str = "") -> np.ndarray | None:
    """Row order that puts a frame's particle ids onto ``reference`` (sorted ids).

    Parameters
    ----------
    ids : numpy.ndarray
        [N] the frame's ids, in row order.
    reference : numpy.ndarray
        [N] the sorted ids of the first frame.
    where : str
        Which frame, to start an error message.
    hint : str, optional
        Ends the message when the frame has fewer rows than the reference.

    Returns
    -------
    numpy.ndarray or None
        The row order, or None when the rows are already in that order.

    Raises
    ------
    InputError
        Naming the first repeated, missing or unknown id.
    """
    if ids.size == reference.size and np.array_equal(ids, reference):
        return None
    order = np.argsort(ids, kind="stable")
    ordered = ids[order]
    if ids.size == reference.size and np.array_equal(ordered, reference):
        return order
    raise InputError(_id_mismatch(ordered, reference, where)
                     + (hint if ids.size < reference.size else ""))


def _id_mismatch(ordered: np.ndarray, reference: np.ndarray, where: str) -> str:
    repeated = ordered[1:][ordered[1:] == ordered[:-1]]
    if repeated.size:
        return f"{where}: particle id {repeated[0]} appears more than once"
    missing = np.setdiff1d(reference, ordered, assume_unique=True)
    extra = np.setdiff1d(ordered, reference, assume_unique=True)
    if extra.size:
        instead = f" (and id {missing[0]} is missing)" if missing.size else ""
        return f"{where}: particle id {extra[0]} is not in the first frame{instead}"
    more = f" and {missing.size - 1} more" if missing.size > 1 else ""
    return (f"{where}: particle id {missing[0]}{more} missing ({ordered.size} of "
            f"{reference.size} particles of the first frame present)")


def whole_ids(values: np.ndarray, where: str) -> np.ndarray:
    """Particle ids parsed as floats, as int64.

    Parameters
    ----------
    values : numpy.ndarray
        The ids as floats.
    where : str
        Which frame or line, to start an error message.

    Returns
    -------
    numpy.ndarray
        The ids, int64.

    Raises
    ------
    InputError
        If one is not a finite whole number.
    """
    finite = np.isfinite(values)
    ids = np.where(finite, values, 0.0).astype(np.int64)
    bad = ~finite | (ids != values)
    if bad.any():
        raise InputError(f"{where}: particle id {values[np.argmax(bad)]:g} is not a whole number")
    return ids


#: float64 holds every whole number below 2^53 in magnitude exactly; ids from there on are
#: parsed from their text
EXACT_FLOAT_INTEGER = 2.0 ** 53
_INTEGER_TEXT = re.compile(r"[+-]?[0-9]+\Z")


def id_from_text(text: str, where: str) -> int:
    """A particle id parsed exactly from its text (``9007199254740993``, ``1.0e3``).

    Raises
    ------
    InputError
        If it is not a whole number or lies outside int64.
    """
    token = text.strip()
    try:
        if _INTEGER_TEXT.match(token):
            value = int(token)
        else:
            number = decimal.Decimal(token)
            if not number.is_finite() or number != number.to_integral_value():
                raise ValueError
            if number.adjusted() > 19:
                raise OverflowError
            value = int(number)
    except OverflowError:
        value = 2 ** 64
    except (ValueError, decimal.InvalidOperation):
        raise InputError(f"{where}: particle id {token[:40]!r} is not a whole number") from None
    if not -2 ** 63 <= value < 2 ** 63:
        raise InputError(f"{where}: particle id {token[:40]} lies outside the 64-bit integers")
    return value


def exact_ids(values: np.ndarray, texts, where: str) -> np.ndarray:
    """Particle ids, exact: from the floats where they hold the id exactly (magnitude below
    2^53), else from the text (2^53 + 1 stays 2^53 + 1).

    Parameters
    ----------
    values : numpy.ndarray
        The ids as parsed to float64.
    texts : callable
        Returns the ids' texts, in the same order (called only when some id is that large).
    where : str
        Starts an error message.

    Returns
    -------
    numpy.ndarray of int64

    Raises
    ------
    InputError
        If an id is not a whole number or lies outside int64.
    """
    values = np.asarray(values, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        small = np.isfinite(values) & (np.abs(values) < EXACT_FLOAT_INTEGER)
    if small.all():
        return whole_ids(values, where)
    tokens = texts()
    ids = whole_ids(np.where(small, values, 0.0), where)
    for k in np.flatnonzero(~small):
        ids[k] = id_from_text(tokens[k], where)
    return ids


class IdCodes:
    """Exact int64 particle ids carried through float64 row arrays as small codes (the
    order of first appearance), so that no id is rounded."""

    def __init__(self):
        self._code: dict[int, int] = {}
        self._ids: list[int] = []

    def encode(self, ids: np.ndarray) -> np.ndarray:
        """Codes (float64) of int64 ``ids``."""
        unique, inverse = np.unique(ids, return_inverse=True)
        codes = np.empty(unique.size, dtype=np.float64)
        for k, value in enumerate(unique.tolist()):
            code = self._code.get(value)
            if code is None:
                code = self._code[value] = len(self._ids)
                self._ids.append(value)
            codes[k] = code
        return codes[inverse.reshape(-1)]

    def decode(self, codes: np.ndarray) -> np.ndarray:
        """The int64 ids of ``codes``."""
        table = np.asarray(self._ids, dtype=np.int64)
        return table[np.asarray(codes).astype(np.int64)]


def progress(frames: Iterable, label: str) -> Iterable:
    """Wrap an iterator of frames in a tqdm bar on stderr, shown only on a terminal.

    Parameters
    ----------
    frames : Iterable
        The frames.
    label : str
        The input file's name, shown in the bar.

    Returns
    -------
    Iterable
        ``frames``, wrapped when stderr is a terminal.
    """
    from cfbmarkov._console import draws_bars

    if not draws_bars():
        return frames
    from tqdm import tqdm

    return tqdm(frames, desc=f"import {Path(label).name}", unit="frame", file=sys.stderr,
                delay=1.0, leave=False)


