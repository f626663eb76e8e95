"""A compact ``repr`` for result dataclasses that hold arrays: each array shown by its
shape and dtype, numbers to six digits, so that a notebook cell's echo stays a line or two
(the arrays themselves are attributes)."""

from __future__ import annotations

import dataclasses

import numpy as np

#: longest text of one non-array field in the repr
_LONGEST = 60


def compact_repr(obj) -> str:
    """``Type(name=value, ...)`` of a dataclass instance, arrays as ``<array SHAPE DTYPE>``.

    Parameters
    ----------
    obj : dataclass instance

    Returns
    -------
    str
    """
    parts = [f"{f.name}={_short(getattr(obj, f.name), nested=True)}"
             for f in dataclasses.fields(obj) if f.repr]
    return f"{type(obj).__name__}({', '.join(parts)})"


def _short(value, nested: bool = False) -> str:
    """One field's text (a tuple's or list's items in turn, one level deep)."""
    if isinstance(value, np.ndarray):
        return f"<array {'x'.join(map(str, value.shape)) or 'scalar'} {value.dtype}>"
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.6g}"
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return f"<{type(value).__name__}>"
    if nested and isinstance(value, (tuple, list)):
        items = ", ".join(_short(v) for v in value)
        text = f"({items}{',' if len(value) == 1 else ''})" if isinstance(value, tuple) \
            else f"[{items}]"
    else:
        text = repr(value)
    return text if len(text) <= _LONGEST else text[:_LONGEST - 3] + "..."
