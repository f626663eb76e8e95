"""CSV import (docs/definitions.md, CSV import): rows ``t,id,x,y`` with optional ``vx,vy``, in SI units.

One row per particle and frame: time t (s), particle id, position x, y (m) and, when the
header names them, velocity vx, vy (m/s). Columns may come in any order. The rows of one
frame share the same t and come together; every particle id appears exactly once in every
frame, in any order; frames are stored in the order of the first frame's sorted ids.

The file is read in blocks of rows and written frame by frame through
:class:`~cfbmarkov.trajectories.TrajectoryWriter`, so memory stays at a few frames whatever
the length of the input. A gzip-compressed file is recognised by its magic bytes. Blank
lines and lines starting with '#' are skipped; a UTF-8 byte-order mark and Windows line ends are
accepted.

"""

from __future__ import annotations

import itertools
import os
import warnings
from collections.abc import Iterator
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

#: the paper's riser (docs/definitions.md, Riser): width W and height H, m
DEFAULT_WIDTH = 0.09
DEFAULT_HEIGHT = 0.95
REQUIRED_COLUMNS = ("t", "id", "x", "y")
VELOCITY_COLUMNS = ("vx", "vy")
#: characters of text parsed per call (about 70000 rows of six columns)
CHUNK_CHARS = 1 << 22
_EXPECTED = "expected t, id, x, y and optionally vx, vy"


# -- the CSV importer -------------------------------------------------------------------------
def import_csv(source: str | os.PathLike, output: str | os.PathLike, *,
               width: float | None = None, height: float | None = None) -> Path:
    """Import a CSV file of ``t,id,x,y[,vx,vy]`` rows (SI units) as a trajectory file.

    The lap counter is derived from the positions by the minimal-image rule on y
    (docs/definitions.md, Pass direction).

    Parameters
    ----------
    source : str or os.PathLike
        The CSV file, plain or gzip-compressed; format in docs/definitions.md, CSV import.
    output : str or os.PathLike
        The trajectory file (HDF5) to write; it appears only when complete.
    width, height : float, optional
        Domain width W and height H, m; by default the paper's 0.09 x 0.95 m riser.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        On bad input (a malformed header or row, times that do not increase, a particle
        missing from a frame, a position outside the domain, ...); no file is left behind.
    """
    path = check_source(source)
    output = check_output(output, path)
    label = str(path)
    width = DEFAULT_WIDTH if width is None else float(width)
    height = DEFAULT_HEIGHT if height is None else float(height)
    with removing_new_folders(output), reading(label), open_text(path) as fh:
        header, first_line = _read_header(fh, label)
        columns = _column_index(header, first_line - 1, label)
        frames = _frames(_row_blocks(fh, header, first_line, label), columns["t"])
        first = next(frames, None)
        if first is None:
            raise InputError(f"{label}: no data rows after the header")
        reference = np.unique(whole_ids(first[0][:, columns["id"]], label))
        parameters = {"source_file": path.name, "format": "csv", "columns": header,
                      "width": width, "height": height}
        with create_writer(output, reference, width=width, height=height, source="import:csv",
                           parameters=parameters, with_velocity="vx" in columns,
                           label=label) as writer:
            previous = None
            for rows, last in progress(itertools.chain([first], frames), label):
                previous = _append_frame(writer, rows, columns, reference, label, last, previous)
    return output


def _append_frame(writer: TrajectoryWriter, rows: np.ndarray, columns: dict[str, int],
                  reference: np.ndarray, label: str, last: bool, previous: float | None
                  ) -> float:
    """Put one frame's rows into the reference id order and append it; returns its time (s)."""
    time = float(rows[0, columns["t"]])
    where = f"{label}: frame at t = {time:g} s"
    if previous is not None and not time > previous:
        raise InputError(f"{label}: time does not increase at t = {time:g} s (after "
                         f"{previous:g} s); the rows of a frame must come together and the "
                         "frames in time order")
    ids = whole_ids(rows[:, columns["id"]], where)
    order = frame_order(ids, reference, where, "; the file ends there (truncated?)" if last else "")
    if order is not None:
        rows = rows[order]
    position = rows[:, [columns["x"], columns["y"]]]
    velocity = rows[:, [columns["vx"], columns["vy"]]] if "vx" in columns else None
    writer.append(time, position, velocity)
    return time


def _read_header(fh: TextIO, label: str) -> tuple[list[str], int]:
    """Column names of the first non-blank line, and the number of the line after it."""
    line_no = 0
    while line := fh.readline():
        line_no += 1
        text = line.lstrip("\ufeff").strip()
        if text and not text.startswith("#"):
            return [name.strip().lower() for name in text.split(",")], line_no + 1
    raise InputError(f"{label}: empty file (no header line)")


def _column_index(header: list[str], line_no: int, label: str) -> dict[str, int]:
    """Map each known column name to its position; an InputError for a bad header."""
    shown = ",".join(header)
    if all(_is_number(name) for name in header):
        raise InputError(f"{label}: line {line_no} is not a header ({shown!r}); {_EXPECTED}")
    for name in REQUIRED_COLUMNS:
        if name not in header:
            raise InputError(f"{label}: missing column {name!r} in the header {shown!r}; "
                             f"{_EXPECTED}")
    for k, name in enumerate(header):
        if name not in REQUIRED_COLUMNS + VELOCITY_COLUMNS:
            what = f"column {k + 1} has no name" if not name else f"unknown column {name!r}"
            raise InputError(f"{label}: {what} in the header {shown!r}; {_EXPECTED}")
        if header.count(name) > 1:
            raise InputError(f"{label}: column {name!r} appears twice in the header {shown!r}")
    if ("vx" in header) != ("vy" in header):
        raise InputError(f"{label}: the header {shown!r} has only one of vx, vy; give both or "
                         "neither")
    return {name: k for k, name in enumerate(header)}


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _row_blocks(fh: TextIO, header: list[str], line_no: int, label: str
                ) -> Iterator[np.ndarray]:
    """Parse the data rows in blocks of about CHUNK_CHARS characters: arrays [rows, columns]."""
    it, iid = header.index("t"), header.index("id")
    while lines := fh.readlines(CHUNK_CHARS):
        values = _parse_rows(lines, line_no, header, label)
        _check_keys(values, it, iid, lines, line_no, label)
        line_no += len(lines)
        if values.shape[0]:
            yield values


def _parse_rows(lines: list[str], line_no: int, header: list[str], label: str) -> np.ndarray:
    """Rows of numbers from CSV lines (blank and '#' lines skipped); line_no numbers lines[0]."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # a block of blank lines
            values = np.loadtxt(lines, delimiter=",", dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise InputError(_locate_bad_row(lines, line_no, header, label, exc)) from None
    if values.size == 0:
        return np.empty((0, len(header)))
    if values.shape[1] != len(header):
        line = _data_line_numbers(lines, line_no)[0]
        raise InputError(f"{label}: line {line}: {values.shape[1]} values, the header names "
                         f"{len(header)} columns")
    return values


def _locate_bad_row(lines: list[str], line_no: int, header: list[str], label: str,
                    exc: Exception) -> str:
    """Message naming the first line of a block that numpy could not parse."""
    for k, line in enumerate(lines):
        content = line.split("#", 1)[0].strip()
        if not content:
            continue
        cut = "" if line.endswith("\n") else " (the file ends inside this row: truncated?)"
        fields = content.split(",")
        if len(fields) != len(header):
            return (f"{label}: line {line_no + k}: {len(fields)} values, the header names "
                    f"{len(header)} columns{cut}")
        for name, field in zip(header, fields):
            if not field.strip():
                return f"{label}: line {line_no + k}: column {name!r} is empty{cut}"
            if not _is_number(field):
                return (f"{label}: line {line_no + k}: {field.strip()!r} in column {name!r} is "
                        f"not a number{cut}")
    return f"{label}: lines {line_no}-{line_no + len(lines) - 1}: {exc}"


def _data_line_numbers(lines: list[str], line_no: int) -> list[int]:
    """Line numbers of the rows that np.loadtxt returned for a block (blank lines skipped)."""
    return [line_no + k for k, line in enumerate(lines) if line.split("#", 1)[0].strip()]


def _check_keys(values: np.ndarray, it: int, iid: int, lines: list[str], line_no: int,
                label: str) -> None:
    """Refuse a time that is not finite or an id that is not a whole number, by line."""
    t, ids = values[:, it], values[:, iid]
    bad_t = ~np.isfinite(t)
    bad_id = ~np.isfinite(ids) | (ids != np.round(ids))
    if not (bad_t.any() or bad_id.any()):
        return
    rows = _data_line_numbers(lines, line_no)
    if bad_t.any():
        k = int(np.argmax(bad_t))
        raise InputError(f"{label}: line {rows[k]}: time t = {t[k]:g} is not a finite number")
    k = int(np.argmax(bad_id))
    raise InputError(f"{label}: line {rows[k]}: particle id {ids[k]:g} is not a whole number")


def _frames(blocks: Iterator[np.ndarray], it: int) -> Iterator[tuple[np.ndarray, bool]]:
    """Split row blocks into frames (runs of equal t): yield (rows, is_last_frame)."""
    pending: list[np.ndarray] = []
    for values in blocks:
        t = values[:, it]
        cuts = np.flatnonzero(t[1:] != t[:-1]) + 1
        if cuts.size == 0 and (not pending or pending[-1][0, it] == t[0]):
            pending.append(values)
            continue
        if pending and pending[-1][0, it] != t[0]:
            cuts = np.concatenate([[0], cuts])
        start = 0
        for cut in cuts:
            pending.append(values[start:cut])
            rows = np.concatenate(pending) if len(pending) > 1 else pending[0]
            if rows.shape[0]:
                yield rows, False
            pending, start = [], cut
        pending = [values[start:]]
    if pending:
        yield (np.concatenate(pending) if len(pending) > 1 else pending[0]), True
