"""TOML files as users give them: read as UTF-8 text (an editor's BOM too), a file that is
not text or holds nothing named in one line."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

from cfbmarkov.errors import InputError


def binary_kind(path: str | os.PathLike) -> str:
    """What a file that is not UTF-8 text seems to be, in words.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    str
        ``an HDF5 file: a model or trajectory file?``, ``text in UTF-16``, ``text in another
        encoding than UTF-8``, ``a binary file`` or ``unreadable``.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return "unreadable"
    if head[:8] == b"\x89HDF\r\n\x1a\n":
        return "an HDF5 file: a model or trajectory file?"
    if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "text in UTF-16"
    if b"\x00" not in head:
        return "text in another encoding than UTF-8"
    return "a binary file"


#: the fix named after a TOML syntax error (its line and column are in the parser's text)
SYNTAX_FIX = ("correct the file there: each setting `key = value` on its own line, text in "
              "double quotes, a key once in each table")


def read_toml(path: str | os.PathLike, what: str, example: str) -> dict:
    """The tables of a TOML file that must hold something.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        What the file is, for messages (``"case file"``).
    example : str
        What it should be, for messages (``"a TOML file of [riser], [gas], ... tables"``).

    Returns
    -------
    dict

    Raises
    ------
    InputError
        One line naming the file: unreadable, not UTF-8 text, not valid TOML, or empty.
    """
    name = os.fspath(path)
    try:
        text = Path(path).read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise InputError(f"cannot read {what} {name}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        kind = binary_kind(path)
        if kind.startswith("text"):
            raise InputError(f"{what} {name} is {kind}; save it as UTF-8 ({example})") from None
        raise InputError(f"{what} {name} is not text ({kind}): give {example}") from None
    text = text.replace("\r\n", "\n").replace("\r", "\n")    # as text mode reads line ends
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{name}: not valid TOML: {exc}; {SYNTAX_FIX}") from None
    if not data:
        raise InputError(f"{what} {name} is empty (it sets nothing): give {example}")
    return data


__all__ = ["SYNTAX_FIX", "binary_kind", "read_toml"]
