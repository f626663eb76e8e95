"""Coarse groups of cells for the Chapman-Kolmogorov test and the automatic choice:
height bands, core and annulus, their intersections (pure functions of the cell grid).

Every state belongs to the group of its cell, so the groups work for any state space.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.markov.states import StateSpace


# -- coarse groups of cells ------------------------------------------------------------------
def _band_names(n: int) -> list[str] | None:
    return {1: ["all"], 2: ["bottom", "top"], 3: ["bottom", "middle", "top"],
            4: ["bottom", "lower middle", "upper middle", "top"]}.get(n)


def height_bands(state_space: StateSpace, n_bands: int = 3) -> dict[str, np.ndarray]:
    """Partition of the cells into ``n_bands`` horizontal bands of whole rows.

    The bands are as equal as possible, bottom first, named bottom/middle/top for 3 bands
    (bottom/top for 2, four names for 4, ``rows a-b`` otherwise).

    Parameters
    ----------
    state_space : StateSpace
        Gives the cell grid.
    n_bands : int, optional
        Number of bands, 1 .. rows.

    Returns
    -------
    dict of str to ndarray of int64
        The cells (row*m + col; (row*d + k)*m + col with depth columns) of each band.

    Raises
    ------
    InputError
        If ``n_bands`` is not between 1 and the number of rows.
    """
    rows, m = state_space.rows, state_space.cells_per_row     # m*d cells per row in 3D
    n_bands = int(n_bands)
    if not 1 <= n_bands <= rows:
        raise InputError(f"{n_bands} height bands do not fit {rows} rows of cells")
    names = _band_names(n_bands)
    out = {}
    for b, band in enumerate(np.array_split(np.arange(rows), n_bands)):
        name = names[b] if names else f"rows {band[0]}-{band[-1]}"
        out[name] = (band[:, None] * m + np.arange(m)[None, :]).ravel().astype(np.int64)
    return out


def core_annulus(state_space: StateSpace, wall_columns: int = 1) -> dict[str, np.ndarray]:
    """Partition of the cells into the core and the annulus next to the walls.

    Parameters
    ----------
    state_space : StateSpace
        Gives the cell grid.
    wall_columns : int, optional
        Columns on each side, next to the walls at x = 0 and x = W, that form the annulus.

    Returns
    -------
    dict of str to ndarray of int64
        ``core`` and ``annulus``: their cells (row*m + col; (row*d + k)*m + col with
        depth columns, every depth column alike).

    Raises
    ------
    InputError
        If ``wall_columns < 1`` or the annulus leaves no core column.
    """
    m = state_space.columns
    wall_columns = int(wall_columns)
    if wall_columns < 1 or 2 * wall_columns >= m:
        raise InputError(f"{wall_columns} wall column(s) per side leave no core in {m} columns")
    col = np.arange(state_space.n_cells) % m      # also (row*d + k)*m + col in 3D
    wall = (col < wall_columns) | (col >= m - wall_columns)
    return {"core": np.flatnonzero(~wall).astype(np.int64),
            "annulus": np.flatnonzero(wall).astype(np.int64)}


def product_groups(first: Mapping[str, Sequence[int]], second: Mapping[str, Sequence[int]]
                   ) -> dict[str, np.ndarray]:
    """Intersections of two partitions, e.g. height bands x core/annulus ("bottom core", ...).

    Parameters
    ----------
    first, second : mapping of str to sequence of int
        Two partitions of the cells.

    Returns
    -------
    dict of str to ndarray of int64
        ``"<first name> <second name>"`` to the cells of both; empty intersections are
        left out.
    """
    out = {}
    for a, ca in first.items():
        for b, cb in second.items():
            both = np.intersect1d(np.asarray(ca, np.int64), np.asarray(cb, np.int64))
            if both.size:
                out[f"{a} {b}"] = both
    return out


def group_labels(state_space: StateSpace, groups: Mapping[str, Sequence[int]]
                 ) -> tuple[list[str], np.ndarray]:
    """Names and the group of every cell.

    Parameters
    ----------
    state_space : StateSpace
        Gives the cells.
    groups : mapping of str to sequence of int
        Name to cells (row*m + col); must be a partition of the cells.

    Returns
    -------
    names : list of str
        The group names, in the mapping's order.
    labels : ndarray of int64, shape (n_cells,)
        Index into ``names`` of every cell.

    Raises
    ------
    InputError
        If ``groups`` is not a non-empty mapping, a group is empty, names cells outside
        the grid or overlaps another, or a cell is left unassigned.
    """
    if not isinstance(groups, Mapping) or len(groups) < 1:
        raise InputError("groups must be a non-empty mapping name -> cell indices")
    n_cells = state_space.n_cells
    label = np.full(n_cells, -1, np.int64)
    names = [str(n) for n in groups]
    for g, cells in enumerate(groups.values()):
        cells = np.asarray(cells, dtype=np.int64).ravel()
        if cells.size == 0:
            raise InputError(f"group '{names[g]}' holds no cell")
        if cells.min() < 0 or cells.max() >= n_cells:
            raise InputError(f"group '{names[g]}' names cells outside 0..{n_cells - 1}")
        if np.any(label[cells] >= 0):
            raise InputError(f"group '{names[g]}' overlaps another group")
        label[cells] = g
    if np.any(label < 0):
        raise InputError(f"groups leave {int(np.sum(label < 0))} cell(s) unassigned")
    return names, label


__all__ = ["core_annulus", "group_labels", "height_bands", "product_groups"]
