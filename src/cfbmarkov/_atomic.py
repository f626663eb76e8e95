"""Atomic file output: write to a temporary name beside the target, then rename.

Every writer of the package (trajectory files, models, reports, figures) goes through
:func:`temporary_path` and :func:`publish`, or the context manager :func:`atomic_path` that
pairs them, so that a failed or interrupted writer never leaves a half-written output
under the final name.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from cfbmarkov.errors import InputError


def temporary_path(target: str | os.PathLike, suffix: str = "") -> Path:
    """Create an empty temporary file beside ``target`` and return its path.

    Parameters
    ----------
    target : str or os.PathLike
        The final output path; its folder is created if missing.
    suffix : str
        Appended after ``.tmp`` (e.g. ``".png"`` for writers that look at the extension).

    Returns
    -------
    pathlib.Path
        A hidden file ``.<name>.<random>.tmp<suffix>`` in the target's folder (same file
        system, so the final rename is atomic).
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp" + suffix,
                               dir=target.parent)
    os.close(fd)
    return Path(tmp)


def publish(tmp: str | os.PathLike, target: str | os.PathLike) -> Path:
    """Move the finished temporary file ``tmp`` onto ``target`` (atomic rename).

    Parameters
    ----------
    tmp : str or os.PathLike
        The finished temporary file (from :func:`temporary_path`).
    target : str or os.PathLike
        The final name; an existing file of that name is replaced.

    Returns
    -------
    pathlib.Path
        ``target``.

    Raises
    ------
    InputError
        If the rename fails (the temporary file is removed first).
    """
    try:
        os.replace(tmp, target)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise InputError(f"{target}: cannot write ({exc.strerror or exc})") from None
    return Path(target)


def discard(tmp: str | os.PathLike) -> None:
    """Remove a temporary file if it is still there.

    Parameters
    ----------
    tmp : str or os.PathLike
        The temporary file; nothing happens if it no longer exists.
    """
    Path(tmp).unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike, suffix: str = ""):
    """Yield a temporary path beside ``target``; rename it onto ``target`` on success.

    On any exception the temporary file is removed and ``target`` is left untouched, so a
    failed or interrupted writer never leaves a half-written output file.

    Parameters
    ----------
    target : str or os.PathLike
        The file to write; its folder is created if needed.
    suffix : str, optional
        Added after ``.tmp`` to the temporary name (e.g. ``.png`` for tools that look at it).

    Yields
    ------
    pathlib.Path
        The temporary path to write to.

    Raises
    ------
    InputError
        If the final rename fails.
    """
    tmp = temporary_path(target, suffix)
    try:
        yield tmp
    except BaseException:
        discard(tmp)
        raise
    publish(tmp, target)


def write_text_atomic(target: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``target`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    target : str or os.PathLike
        The file to write.
    text : str
        Its content.

    Raises
    ------
    InputError
        If the final rename fails (the target is then left untouched).
    """
    with atomic_path(target) as tmp:
        tmp.write_text(text)
