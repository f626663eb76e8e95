"""File names: inputs that are not files (pipes, devices), and the names of the helper files
and folders built from an output's name (lock, temporaries, checkpoint folder).

A file name may be up to :data:`NAME_MAX` bytes long (the limit of Linux and macOS file
systems). The helpers add a prefix and a suffix to the output's name (``.NAME.lock``,
``.NAME.XXXXXXXX.tmp.png``, ``NAME.tmp-XXXXXXXX``, ``NAME.parts``); where that would pass
the limit, they are built from :func:`helper_stem`, the name cut short with a hash of the
whole name, so that every legal output name can be written.
"""

from __future__ import annotations

import hashlib
import os
import stat
from pathlib import Path

from cfbmarkov.errors import InputError

#: the longest file name, bytes (one path component)
NAME_MAX = 255
#: the most bytes a helper adds to the stem it is built from
#: (``.`` + stem + ``.XXXXXXXX.tmp`` + a suffix of up to 6 bytes, e.g. ``.json``)
HELPER_ROOM = 20


def helper_stem(name: str) -> str:
    """The stem of the helper names of an output named ``name``: ``name`` itself where
    every helper built from it stays within :data:`NAME_MAX` bytes, else its start cut on a
    character boundary, ``~`` and 16 hexadecimal digits of the SHA-256 of the whole name
    (distinct names keep distinct helpers).

    Parameters
    ----------
    name : str
        The output's file name (no folder).

    Returns
    -------
    str
        A stem of at most ``NAME_MAX - HELPER_ROOM`` bytes.
    """
    raw = os.fsencode(name)
    room = NAME_MAX - HELPER_ROOM
    if len(raw) <= room:
        return name
    digest = hashlib.sha256(raw).hexdigest()[:16]
    keep = raw[:room - len(digest) - 1].decode("utf-8", errors="ignore")
    while len(os.fsencode(keep)) > room - len(digest) - 1:   # surrogate-escaped names
        keep = keep[:-1]
    return f"{keep}~{digest}"


def named_output(output: str | os.PathLike) -> Path:
    """``output`` as a path whose last part is a name; ``.``, ``..``, ``./``, ``dir/..`` and
    the root folder are refused: a verb's output is replaced whole when it is complete, and
    the current folder (or one above it) cannot be.

    Parameters
    ----------
    output : str or os.PathLike

    Returns
    -------
    pathlib.Path

    Raises
    ------
    InputError
        For a name that is no name (``.``, ``..``, a path ending in them, the root folder).
    """
    path = Path(output)
    text = os.fspath(output).rstrip("/")
    if path.name in ("", ".", "..") or text in ("", ".", "..") or text.endswith(("/..", "/.")):
        from cfbmarkov.errors import InputError

        raise InputError(f"output {os.fspath(output)!r} names no file or folder of its own (a "
                         "verb replaces its output whole when it is complete, which the "
                         "current folder, a folder above it or the root cannot be); give a "
                         "new one by name (e.g. -o model.h5, or -o results for a folder)")
    return path


def parts_folder(output: str | os.PathLike) -> Path:
    """The checkpoint folder of a run written to ``output``: ``OUTPUT.parts`` beside it
    (built from :func:`helper_stem` for a name near the length limit)."""
    output = named_output(output)
    return output.with_name(helper_stem(output.name) + ".parts")


def check_output_name(path: str | os.PathLike) -> None:
    """Refuse an output name longer than the file system allows, in one line.

    Raises
    ------
    InputError
        If ``path`` is empty, or a component of it is longer than :data:`NAME_MAX` bytes.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(f"{path!r} is no file name: give the output's path as a str or "
                         "pathlib.Path")
    if not os.fspath(path):        # Path("") is "." (the current folder)
        raise InputError("an empty output name (-o ''): give the file or folder to write")
    for part in Path(path).parts:
        if len(os.fsencode(part)) > NAME_MAX:
            raise InputError(f"{shown(path)}: a file name of {len(os.fsencode(part))} bytes, "
                             f"longer than the file system's limit of {NAME_MAX}; give a "
                             "shorter name")


def shown(path: str | os.PathLike) -> str:
    """A path as one line: as given, or in quotes with escapes (``repr``) where it holds a
    line break or another control character."""
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if any(ord(c) < 32 or ord(c) == 127 for c in text):
        return repr(text)
    return text


def one_line(text: str) -> str:
    """``text`` on one line: line breaks and other control characters (in a file name, or
    in a library's message) written as escapes (``\\n``), a tab as a space.

    Parameters
    ----------
    text : str
        A message.

    Returns
    -------
    str
    """
    text = text.rstrip("\n").replace("\t", " ")
    if not any(ord(c) < 32 or ord(c) == 127 for c in text):
        return text
    return "".join(c if ord(c) >= 32 and ord(c) != 127 else repr(c)[1:-1] for c in text)


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message (h5py's and HDF5's run over several), or
    the exception's type where it has none."""
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    lines = text.strip().splitlines()
    return lines[0].strip() if lines else type(exc).__name__


def check_not_pipe(path: str | os.PathLike) -> None:
    """Refuse, in one line, an input that is a pipe, a socket or a device (a FIFO,
    ``/dev/stdin`` from a pipe, a shell's ``<(...)``): the readers read their files more than
    once (the format's detection, then the data) and seek in them.

    Raises
    ------
    InputError
        Naming the kind and the fix (save it to a file first).
    """
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return
    if stat.S_ISFIFO(mode):
        kind = "a pipe"
    elif stat.S_ISSOCK(mode):
        kind = "a socket"
    elif stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        kind = "a device"
    else:
        return
    raise InputError(f"{shown(path)}: is {kind}, not a file (it is read more than once): save "
                     "it to a file first and give that file")


__all__ = ["HELPER_ROOM", "NAME_MAX", "check_not_pipe", "check_output_name", "first_line",
           "helper_stem", "one_line", "parts_folder", "shown"]
