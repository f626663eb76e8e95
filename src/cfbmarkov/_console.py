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


#: the exit code of a verb whose standard output was closed by its reader (``cfbmarkov
#: info model.h5 | head -1``): 128 + SIGPIPE, what a shell reports for a program that a
#: closed pipe stopped
CLOSED_PIPE = 141


def stdout_closed() -> bool:
    """Whether the reader of standard output has gone: a pipe or socket whose other end is
    closed (``| head -1`` after its line). False where standard output is a file, a
    terminal or an object without a file descriptor (a test's capture).

    Returns
    -------
    bool
    """
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return False
    try:
        import select

        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        events = poller.poll(0)
    except (AttributeError, OSError, ValueError):   # no poll (Windows): assume a pipe
        return True
    return any(mask & (select.POLLERR | select.POLLHUP) for _, mask in events)


def quit_closed_stdout() -> int:
    """Stop quietly after the reader of standard output has gone: what is still buffered
    for it goes to the null device (Python's advice on SIGPIPE, so that the flush at exit
    raises nothing), and the exit code is :data:`CLOSED_PIPE`.

    Returns
    -------
    int
        :data:`CLOSED_PIPE`.
    """
    import os

    with contextlib.suppress(AttributeError, OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    return CLOSED_PIPE


def _show(previous):
    def show(message, category, filename, lineno, file=None, line=None):
        if isinstance(category, type) and issubclass(category, CfbmarkovWarning):
            write_line(getattr(category, "prefix", NOTE) + " ".join(str(message).split()),
                       file)
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


#: seconds between the lines of :func:`heartbeat`
HEARTBEAT_EVERY = 5.0


@contextlib.contextmanager
def heartbeat(text: str, write=None, every: float | None = None) -> Iterator[None]:
    """Within the block, one line ``TEXT: still working, M:SS so far`` every ``every``
    seconds of work, from a background thread, so that a long step without progress of its
    own still shows it is alive in a log file.

    Parameters
    ----------
    text : str
        What the block does (``compare: pred.h5 against ref.h5``).
    write : callable, optional
        Called with each line (default :func:`write_line` to the current ``sys.stderr``);
        None as ``write`` and a falsy ``text`` alike mean no lines.
    every : float, optional
        Seconds between lines (default :data:`HEARTBEAT_EVERY`).
    """
    import threading
    import time

    if not text:
        yield
        return
    write = write_line if write is None else write
    every = HEARTBEAT_EVERY if every is None else every
    stop = threading.Event()
    started = time.perf_counter()

    def beat() -> None:
        while not stop.wait(every):
            write(f"{text}: still working, {clock_text(time.perf_counter() - started)} so far")

    thread = threading.Thread(target=beat, name="cfbmarkov-heartbeat", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


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
        return "bar" if draws_bars() else "lines"
    raise InputError(f"progress {progress!r}: choose True, False, 'bar' or 'lines'")


def draws_bars() -> bool:
    """Whether stderr is a terminal a progress bar can be drawn on: a tty that reports a
    width (a pseudo-terminal of 0 columns, as ``script`` and some container shells open,
    cuts a bar to nothing: whole lines show there)."""
    import os

    try:
        if not sys.stderr.isatty():
            return False
        return os.get_terminal_size(sys.stderr.fileno()).columns > 0
    except (AttributeError, ValueError, OSError):   # no stderr, a closed one, no size
        return False


__all__ = ["HEARTBEAT_EVERY", "NOTE", "clock_text", "draws_bars", "heartbeat",
           "install_one_line_notes",
           "one_line_notes", "progress_mode",
           "write_line"]


def plural(count: int, noun: str) -> str:
    """``count`` and ``noun``, with an ``s`` unless the count is 1 (``1 particle``,
    ``300 particles``); for nouns whose plural adds ``s``."""
    return f"{count} {noun}" + ("" if count == 1 else "s")
