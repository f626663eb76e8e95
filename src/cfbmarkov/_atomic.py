"""Atomic file output: write to a temporary name beside the target, then rename."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


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
        Added after ``.tmp`` to the temporary name (e.g. ``.h5`` for tools that look at it).

    Yields
    ------
    pathlib.Path
        The temporary path to write to.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp" + suffix,
                               dir=target.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def write_text_atomic(target: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``target`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    target : str or os.PathLike
        The file to write.
    text : str
        Its content.
    """
    with atomic_path(target) as tmp:
        tmp.write_text(text)
