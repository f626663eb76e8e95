"""What the command line and its worker processes print on stderr besides errors: cfbmarkov's
warnings as one line each (``note: MESSAGE``), and whole lines of progress.

Every line goes out in one ``write`` and is flushed at once, so that the lines of worker
processes sharing one stderr (``cfbmarkov reproduce``, ``cfbmarkov demo``) never interleave
within a line.
"""

from __future__ import annotations

import contextlib
import math
import sys
import warnings
from typing import Iterator

from cfbmarkov._names import one_line
from cfbmarkov.errors import CfbmarkovWarning, InputError

#: what starts the line of a :class:`~cfbmarkov.errors.CfbmarkovWarning` on the command line
NOTE = "note: "


def write_line(text: str, stream=None) -> None:
    """Write ``text`` and a newline to ``stream`` (default: the current ``sys.stderr``) in
    one call, and flush it.

    Parameters
    ----------
    text : str
        One line (without its newline); a line break inside it (a file name's) is written
        as an escape.
    stream : file-like, optional
        Where to write.
    """
    stream = sys.stderr if stream is None else stream
    with contextlib.suppress(OSError, ValueError):     # a closed or broken stderr
        stream.write(one_line(text) + "\n")
        stream.flush()


def _show(previous):
    def show(message, category, filename, lineno, file=None, line=None):
        if isinstance(category, type) and issubclass(category, CfbmarkovWarning):
            write_line(NOTE + " ".join(str(message).split()), file)
        else:
            previous(message, category, filename, lineno, file, line)
    show.cfbmarkov_notes = True
    return show


def install_one_line_notes() -> None:
    """From now on, print this process's cfbmarkov warnings as one line ``note: MESSAGE``
    (other warnings keep Python's format). For worker processes, whose warnings cannot reach
    the caller's filters."""
    if not getattr(warnings.showwarning, "cfbmarkov_notes", False):
        warnings.showwarning = _show(warnings.showwarning)


@contextlib.contextmanager
def one_line_notes() -> Iterator[None]:
    """Within the block, print cfbmarkov's warnings as one line ``note: MESSAGE`` on stderr,
    without the warning's category, file and source line; other warnings keep Python's
    format. The warning filters are those in force (a warning already shown from the same
    place with the same text is not shown again; ``-W error`` still raises).
    """
    with warnings.catch_warnings():
        warnings.showwarning = _show(warnings.showwarning)
        yield


def clock_text(seconds: float) -> str:
    """A duration as ``H:MM:SS`` or ``M:SS`` (``?`` where it is not finite).

    Parameters
    ----------
    seconds : float
        The duration (s); negative counts as 0.

    Returns
    -------
    str
    """
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(max(seconds, 0.0)))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def progress_mode(progress) -> str | None:
    """How to show progress on stderr: ``"bar"`` (a bar redrawn in place, for a terminal),
    ``"lines"`` (whole lines, readable in a log file) or None (quiet).

    Parameters
    ----------
    progress : bool, None or {"bar", "lines"}
        True: a bar where stderr is a terminal, lines where it is not (a file, a pipe);
        False or None: quiet; ``"bar"`` or ``"lines"``: that.

    Returns
    -------
    str or None

    Raises
    ------
    InputError
        For any other value.
    """
    if progress is None or progress is False:
        return None
    if progress in ("bar", "lines"):
        return progress
    if progress is True:
        try:
            return "bar" if sys.stderr.isatty() else "lines"
        except (AttributeError, ValueError):        # no stderr, or a closed one
            return "lines"
    raise InputError(f"progress {progress!r}: choose True, False, 'bar' or 'lines'")


__all__ = ["NOTE", "clock_text", "install_one_line_notes", "one_line_notes", "progress_mode",
           "write_line"]
