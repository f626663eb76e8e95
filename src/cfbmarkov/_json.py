"""Values made ready for :func:`json.dumps` with ``allow_nan=False``.

Summaries hold numpy scalars and NaN where a figure is undefined; JSON files and
``--json`` output carry Python numbers and ``null`` instead.
"""

from __future__ import annotations

import math

import numpy as np


def jsonable(value):
    """``value`` with numpy scalars as Python numbers and non-finite floats as None.

    Parameters
    ----------
    value : object
        A dict, list or tuple (converted recursively; tuples become lists), a bool, number
        or any other value (returned as it is).

    Returns
    -------
    object
        The same structure, ready for ``json.dumps(..., allow_nan=False)``.
    """
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


__all__ = ["jsonable"]
