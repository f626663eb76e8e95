"""Cell numbers of positions on a grid of equal cells (Numba kernels).

A grid of m columns x n rows over a riser of W x H numbers its cells row*m + col, row 0 at
the bottom; with d depth columns over the riser's depth the cell is (row*d + k)*m + col
(``docs/definitions.md``, Cells and state numbers). :func:`cell_index` is the one rule
that puts a position in a cell, used by every state space.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError

#: a position within this relative distance (in cells) below a cell edge counts as on the
#: edge, so in the cell above it: 0.29 m on a grid of 0.01 m rows is 28.999999999999996
#: rows by floating point, and lands in row 29 as written (about 1e-11 m on the paper's grid)
EDGE_TOLERANCE = 1e-9


@nb.njit(cache=True, inline="always")
def _index_along(coordinate, scale, n):
    """floor(coordinate * scale), a value a round-off below an edge taken as on it, clipped
    to 0..n-1 (0 for NaN: an absent particle, whose state the caller masks)."""
    v = coordinate * scale
    if v != v:
        return 0
    k = int(math.floor(v + EDGE_TOLERANCE * max(1.0, abs(v))))
    return min(max(k, 0), n - 1)


@nb.njit(cache=True, parallel=True)
def _cell_index_3d(positions, width, height, depth, columns, rows, depth_columns, out):
    flat_pos = positions.reshape(-1, 3)
    flat_out = out.reshape(-1)
    sx = columns / width
    sy = rows / height
    sz = depth_columns / depth
    for k in nb.prange(flat_out.size):
        col = _index_along(flat_pos[k, 0], sx, columns)
        row = _index_along(flat_pos[k, 1], sy, rows)
        lay = _index_along(flat_pos[k, 2], sz, depth_columns)
        flat_out[k] = (row * depth_columns + lay) * columns + col


@nb.njit(cache=True, parallel=True)
def _cell_index(positions, width, height, columns, rows, out):
    flat_pos = positions.reshape(-1, 2)
    flat_out = out.reshape(-1)
    sx = columns / width
    sy = rows / height
    for k in nb.prange(flat_out.size):
        col = _index_along(flat_pos[k, 0], sx, columns)
        row = _index_along(flat_pos[k, 1], sy, rows)
        flat_out[k] = row * columns + col


def cell_index(positions: np.ndarray, width: float, height: float, columns: int, rows: int,
               depth: float | None = None, depth_columns: int = 1) -> np.ndarray:
    """Cell number row*m + col of positions (``(row*d + k)*m + col`` with a depth); points
    on the far edges go inside.

    A position on a cell edge belongs to the cell above (right of) it, also where floating
    point puts it a round-off below the edge (0.29 m on 0.01 m rows is 28.999999999999996
    rows): values within ``EDGE_TOLERANCE`` cells below an edge count as on it.

    Parameters
    ----------
    positions : array_like, shape (..., 2) or (..., 3)
        Positions (across, vertical[, depth]) in m; points outside the domain are clipped
        into the nearest cell. Without ``depth``, 3D positions are projected on (across,
        vertical). A NaN position (an absent particle) gets no meaningful cell: the caller
        masks absent particles.
    width, height : float
        The riser W x H (m).
    columns, rows : int
        The cell grid m x n.
    depth : float, optional
        The riser's depth (m): cells also along the depth (needs 3D positions).
    depth_columns : int, optional
        Cells along the depth, d.

    Returns
    -------
    ndarray of int32, shape (...)
        The cell of each position.

    Raises
    ------
    InputError
        If positions are not 2D or 3D, a depth is given for 2D positions, the grid's counts
        are not whole numbers >= 1 or its sizes not positive.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim < 1 or positions.shape[-1] not in (2, 3):
        raise InputError(f"positions of shape {positions.shape} are neither 2D nor 3D")
    for name, value in (("columns", columns), ("rows", rows), ("depth_columns", depth_columns)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InputError(f"cell_index: {name} {value!r} must be a whole number >= 1")
    for name, value in (("width", width), ("height", height)) + (
            (("depth", depth),) if depth is not None else ()):
        if not (isinstance(value, (int, float, np.number)) and np.isfinite(value) and value > 0):
            raise InputError(f"cell_index: {name} {value!r} m must be a positive finite number")
    out = np.empty(positions.shape[:-1], dtype=np.int32)
    if depth is not None:
        if positions.shape[-1] != 3:
            raise InputError(f"a grid with {depth_columns} depth column(s) needs 3D positions, "
                             "got 2D ones")
        _cell_index_3d(np.ascontiguousarray(positions), float(width), float(height),
                       float(depth), int(columns), int(rows), int(depth_columns), out)
        return out
    positions = np.ascontiguousarray(positions[..., :2])
    _cell_index(positions, float(width), float(height), int(columns), int(rows), out)
    return out


__all__ = ["EDGE_TOLERANCE", "cell_index"]
