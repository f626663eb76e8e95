"""Reading the data rows of a CSV file (``docs/definitions.md``, CSV import): blocks of
rows parsed into numbers in SI units, each refusal naming its line, and the blocks split into
frames. The columns, units and delimiter come from the file's layout
(:mod:`cfbmarkov.io.csv_layout`).
"""

from __future__ import annotations

import csv
import re

import warnings
from collections.abc import Iterator
from typing import TextIO

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.io._common import exact_ids
from cfbmarkov.io.csv_layout import CHUNK_CHARS, CsvLayout, _split


class UnsortedRows(Exception):
    """The times of the rows decrease somewhere: read the file whole and sort it."""


def row_blocks(fh: TextIO, layout: CsvLayout, label: str, *, streaming: bool
                ) -> Iterator[np.ndarray]:
    """Parse the data rows in blocks of about CHUNK_CHARS characters.

    Parameters
    ----------
    fh : TextIO
        The file, positioned after the rows the layout read ahead (``layout.pending``).
    layout : CsvLayout
        The file's columns, units and delimiter.
    label : str
        Names the file in messages.
    streaming : bool
        Raise :class:`UnsortedRows` where the times decrease.

    Yields
    ------
    ndarray of float64, shape (R, C)
        Rows of the used columns, in SI units (m, s, m/s); ids encoded by the layout.

    Raises
    ------
    InputError
        Naming the line of a row that is not numbers, has too few values, a time that is
        not finite, an id that is not a whole number, or a last row cut short.
    UnsortedRows
        (``streaming``) where the times decrease.
    """
    it = layout.index("t")
    iid = layout.index("id") if layout.has_id else None
    line_no, last = layout.first_data_line, None
    lines = layout.pending
    shortest: dict = {}
    while lines or (lines := fh.readlines(CHUNK_CHARS)):
        if not lines[-1].endswith("\n"):          # the file's last line, unterminated
            _check_last_line(lines, line_no, layout, label, shortest)
        values = _parse_rows(lines, line_no, layout, label,
                             first=line_no == layout.first_data_line)
        _check_keys(values, it, iid, lines, line_no, label)
        if iid is not None:
            ids = _exact_block_ids(values[:, iid], lines, line_no, layout, label)
            if layout.noise_id is not None:
                noise = ids == layout.noise_id
                if noise.any():             # rows of no particle: dropped and counted
                    layout.noise_rows += int(noise.sum())
                    values, ids = values[~noise], ids[~noise]
            values[:, iid] = layout.id_codes.encode(ids)
        _note_last_field(lines, layout, shortest)
        if streaming and values.shape[0]:
            t = values[:, it]
            if (last is not None and t[0] < last) or np.any(t[1:] < t[:-1]):
                raise UnsortedRows
            last = t[-1]
        line_no += len(lines)
        lines = []
        if values.shape[0]:
            yield values


def _parse_rows(lines: list[str], line_no: int, layout: CsvLayout, label: str,
                first: bool = True) -> np.ndarray:
    """Rows of numbers from CSV lines (blank and '#' lines skipped); line_no numbers lines[0];
    ``first``: the file's first rows (where a column without a name shows in every row)."""
    text = [line.replace(",", ".") for line in lines] if layout.decimal_comma else lines
    if layout.delimiter is not None:      # a spreadsheet's ghost rows (only delimiters) are blank
        ghost = layout.delimiter + " \t\r\n"
        text = [line if line.strip(ghost) else "\n" for line in text]
    n = len(layout.header)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # a block of blank lines
            values = np.loadtxt(text, delimiter=layout.delimiter, dtype=np.float64, ndmin=2,
                                usecols=None if len(layout.usecols) == n else layout.usecols,
                                converters=_noise_converter(layout), quotechar='"')
    except ValueError as exc:
        raise InputError(_locate_bad_row(lines, line_no, layout, label, exc)) from None
    if len(layout.usecols) != n:          # np.loadtxt reads a longer row's first columns
        _check_row_lengths(text, line_no, layout, label, first)
    if values.size == 0:
        return np.empty((0, len(layout.used)))
    if values.shape[1] != len(layout.used):
        spreadsheet = _spreadsheet_error(lines, line_no, layout, label)
        if spreadsheet:
            raise InputError(spreadsheet)
        line = _data_line_numbers(lines, line_no)[0]
        raise InputError(f"{label}: line {line}: {values.shape[1]} values, the header names "
                         f"{n} columns")
    for k, divisor in enumerate(layout.divisors):
        if divisor != 1.0:
            values[:, k] /= divisor
    return values


def _check_row_lengths(text: list[str], line_no: int, layout: CsvLayout, label: str,
                       first: bool = True) -> None:
    """Refuse rows with more values than the header names where their values would be read
    from the wrong columns: every one of the file's first rows longer (``first``: a column
    without a name in the header, as a row index written by R's ``write.table`` or pandas'
    ``to_csv(index_label=False)``), or a row longer where a used column lies after an unused
    one (a text value holding the delimiter, unquoted). Empty values after the named columns
    (a spreadsheet's ghost cells), and a longer row whose used columns all come before the
    unused ones (read right), are allowed."""
    n = len(layout.header)
    if layout.delimiter is None:
        longer = [k for k, line in enumerate(text) if len(line.split("#", 1)[0].split()) > n]
    else:
        longer = [k for k, line in enumerate(text) if line.count(layout.delimiter) >= n]
    if not longer:
        return
    bad = []
    for k in longer:
        fields = _fields(text[k].split("#", 1)[0].strip(), layout.delimiter)
        if len(fields) > n and any(field.strip() for field in fields[n:]):
            bad.append((k, len(fields)))
    if not bad:
        return
    rows = sum(1 for line in text if line.split("#", 1)[0].strip())
    k, count = bad[0]
    where = f"{label}: line {line_no + k}: {count} values, the header names {n} columns"
    if first and len(bad) == rows:
        raise InputError(f"{where} in every row, so each value would be read from the wrong "
                         "column; name every column in the header (a row index written "
                         "without a name: R's write.table, or pandas' to_csv with "
                         "index_label=False; save without the index, or give it a name)")
    if _shifted(layout):
        raise InputError(f"{where}: {_UNQUOTED.format(layout.delimiter or 'space')}")


_UNQUOTED = ("a value holds the delimiter {!r} unquoted, so the values after it would be read "
             "one column off; quote that value in the file (\"...\")")


def _shifted(layout: CsvLayout) -> bool:
    """Whether a used column lies after an unused one (a longer row shifts it)."""
    unused = sorted(set(range(len(layout.header))) - set(layout.usecols))
    return bool(unused) and max(layout.usecols) > unused[0]


def _fields(content: str, delimiter: str | None) -> list[str]:
    """The values of a row as np.loadtxt(quotechar='"') reads them: a quoted value is one,
    whatever delimiters or spaces it holds."""
    if '"' not in content:
        return _split(content, delimiter)
    if delimiter is None:
        return re.findall(r'"[^"]*"|[^\s"]+', content)
    return next(csv.reader([content], delimiter=delimiter))


def _noise_converter(layout: CsvLayout) -> dict | None:
    """An empty id field read as the noise id, where the id column has one (a TrackMate
    spot that belongs to no track has an empty TRACK_ID)."""
    if layout.noise_id is None or layout.delimiter is None:
        return None
    noise = float(layout.noise_id)
    return {layout.usecols[layout.index("id")]: lambda text: float(text) if text.strip()
            else noise}


def _locate_bad_row(lines: list[str], line_no: int, layout: CsvLayout, label: str,
                    exc: Exception) -> str:
    """Message naming the first line of a block that numpy could not parse."""
    spreadsheet = _spreadsheet_error(lines, line_no, layout, label)
    if spreadsheet:
        return spreadsheet
    n = len(layout.header)
    for k, line in enumerate(lines):
        content = line.split("#", 1)[0].strip()
        if not content:
            continue
        cut = "" if line.endswith("\n") else " (the file ends inside this row: truncated?)"
        fields = _fields(content, layout.delimiter)
        if len(fields) != n and (len(fields) < n or len(layout.usecols) == n):
            return (f"{label}: line {line_no + k}: {len(fields)} values, the header names "
                    f"{n} columns{cut}")
        if len(fields) > n and any(f.strip() for f in fields[n:]) and _shifted(layout):
            return (f"{label}: line {line_no + k}: {len(fields)} values, the header names "
                    f"{n} columns: {_UNQUOTED.format(layout.delimiter or 'space')}{cut}")
        for name, col in zip(layout.used, layout.usecols):
            value = fields[col].strip()
            number = value.replace(",", ".") if layout.decimal_comma else value
            if not value:
                return f"{label}: line {line_no + k}: column {name!r} is empty{cut}"
            if not _is_plain_number(number):
                mark = ("; the first rows use a decimal comma" if layout.decimal_comma else
                        "; a decimal comma needs a semicolon, tab or space delimiter"
                        if "," in value and layout.delimiter == "," else "")
                shown = layout.header[col].strip()
                column = repr(shown) if shown == name else f"{shown!r} (read as {name!r})"
                if name == "id":
                    mark += ("; the particle id must be a whole number (TrackMate: the spots "
                             "of tracks, with their TRACK_ID column)")
                return (f"{label}: line {line_no + k}: {value!r} in column {column} is "
                        f"not a number{mark}{cut}")
    return f"{label}: lines {line_no}-{line_no + len(lines) - 1}: {exc}"


#: a spreadsheet's error and missing-value cells (Excel, LibreOffice), which begin with the
#: comment mark '#'
SPREADSHEET_ERRORS = re.compile(r"#(N/A|VALUE!|DIV/0!|NUM!|REF!|NAME\?|NULL!|N/V)")


def _spreadsheet_error(lines: list[str], line_no: int, layout: CsvLayout, label: str
                       ) -> str | None:
    """The message for the first row holding a spreadsheet's error cell (``#N/A``), which
    the '#' of comments would otherwise cut short; None where no row does."""
    for k, line in enumerate(lines):
        found = SPREADSHEET_ERRORS.search(line)
        if found is None or not line.split("#", 1)[0].strip():
            continue
        fields = _split(line.strip(), layout.delimiter)
        column = next((layout.header[c].strip() for c, f in enumerate(fields)
                       if c < len(layout.header) and found.group(0) in f), None)
        where = f" in column {column!r}" if column else ""
        return (f"{label}: line {line_no + k}: {found.group(0)!r}{where} is a spreadsheet's "
                "error or missing value, not a number; remove the row, or fill the value "
                "before exporting")
    return None


def _is_plain_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _data_line_numbers(lines: list[str], line_no: int) -> list[int]:
    """Line numbers of the rows that np.loadtxt returned for a block (blank lines skipped)."""
    return [line_no + k for k, line in enumerate(lines) if line.split("#", 1)[0].strip()]


def _check_keys(values: np.ndarray, it: int, iid: int | None, lines: list[str], line_no: int,
                label: str) -> None:
    """Refuse a time that is not finite or an id that is not a whole number, by line."""
    t = values[:, it]
    bad_t = ~np.isfinite(t)
    if iid is None:
        bad_id = np.zeros(t.shape, dtype=bool)
        ids = t
    else:
        ids = values[:, iid]
        with np.errstate(invalid="ignore"):     # large ids are checked from their text
            bad_id = (~np.isfinite(ids) | (ids != np.round(ids))) & ~(np.abs(ids) >= 2.0 ** 53)
    if not (bad_t.any() or bad_id.any()):
        return
    rows = _data_line_numbers(lines, line_no)
    if bad_t.any():
        k = int(np.argmax(bad_t))
        raise InputError(f"{label}: line {rows[k]}: time t = {t[k]:g} is not a finite number")
    k = int(np.argmax(bad_id))
    raise InputError(f"{label}: line {rows[k]}: particle id {ids[k]:g} is not a whole number")


def _exact_block_ids(values: np.ndarray, lines: list[str], line_no: int, layout: CsvLayout,
                     label: str) -> np.ndarray:
    """The ids of a block of rows, exact (from the text where 2^53 or more)."""
    def texts() -> list[str]:
        col = layout.usecols[layout.index("id")]
        rows = [line.split("#", 1)[0].strip() for line in lines]
        return [_split(row, layout.delimiter)[col] for row in rows if row]

    return exact_ids(values, texts, f"{label}: lines {line_no}-{line_no + len(lines) - 1}")


def _note_last_field(lines: list[str], layout: CsvLayout, shortest: dict) -> None:
    """Remember the shortest text of the last field over the last rows read (for
    :func:`_check_last_line`)."""
    n = len(layout.header)
    lengths = []
    for line in lines[-64:]:
        content = line.split("#", 1)[0].strip()
        if content:
            fields = _split(content, layout.delimiter)
            if len(fields) == n:
                lengths.append(len(fields[-1].strip()))
    if lengths:
        shortest["last"] = min(lengths)


def _check_last_line(lines: list[str], line_no: int, layout: CsvLayout, label: str,
                     shortest: dict) -> None:
    """Refuse a file cut inside its last row: the last line has no final newline and
    fewer fields than the header, or a last value that cannot be complete (empty, ending in
    '.', 'e', '+' or '-'), or one shorter than that column's value in every one of the
    (up to 64) rows before it (``0.12345`` cut to ``0``)."""
    _note_last_field(lines[:-1], layout, shortest)
    content = lines[-1].split("#", 1)[0].strip()
    if not content:
        return
    where = f"{label}: line {line_no + len(lines) - 1}"
    fields = _split(content, layout.delimiter)
    n = len(layout.header)
    tail = ("(the file ends inside this row: truncated?; if the row is complete, end the "
            "file with a newline)")
    if len(fields) < n:
        raise InputError(f"{where}: {len(fields)} values, the header names {n} columns "
                         "(the file ends inside this row: truncated?)")
    value = fields[n - 1].strip()
    if not value or value[-1] in ".eE+-,":
        raise InputError(f"{where}: last value {value!r} is incomplete {tail}")
    if len(value) < shortest.get("last", 0):
        raise InputError(f"{where}: last value {value!r} is shorter than in every row before "
                         f"it {tail}")


def frame_rows(blocks: Iterator[np.ndarray], it: int) -> Iterator[tuple[np.ndarray, bool]]:
    """Split row blocks, sorted by time, into frames (runs of equal t).

    Parameters
    ----------
    blocks : iterator of ndarray, shape (R, C)
        Row blocks (:func:`row_blocks`).
    it : int
        The time column.

    Yields
    ------
    rows : ndarray, shape (R, C)
        The rows of one frame.
    is_last : bool
        Whether it is the last frame.
    """
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
