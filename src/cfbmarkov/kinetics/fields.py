"""Per-cell parameters of particle properties and the cell fields they may depend on.

A parameter of a rate law is given per cell of the model's grid in one of three ways
(``docs/definitions.md``, Properties along particle paths):

- :class:`Constant`: one value everywhere (``rate = 0.4``);
- :class:`ByCell`: a table with one row per cell, columns ``col,row[,depth],VALUE``
  (``rate_by_cell = "rates.csv"``);
- :class:`FromField`: a two-level function of one of the fitting window's time-averaged
  cell fields (:class:`CellFields`): the ``dense`` value where the cell is on the dense
  side of ``threshold``, else the ``dilute`` value (``rate_from = "solids_fraction"``).
  The dense side is a solids fraction >= threshold, a distance to the wall <= threshold
  (m), or a mean vertical velocity <= threshold (m/s: the falling wall layers).
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.limits import check_finite
from cfbmarkov._repr import compact_repr

#: the cell fields a parameter may be a function of, and the side that counts as dense
FIELDS = {"solids_fraction": "above", "wall_distance": "below", "vertical_velocity": "below"}


@dataclass(frozen=True)
class CellFields:
    """Time-averaged fields of the fitting window per cell of a grid.

    Attributes
    ----------
    solids_fraction : ndarray of float64, shape (C,)
        Mean solids volume fraction per cell (C = m x d x n cells, in the grid's cell order
        (row*d + k)*m + col).
    wall_distance : ndarray of float64, shape (C,)
        Distance (m) from the cell's centre to the nearest side wall.
    vertical_velocity : ndarray of float64, shape (C,)
        Mean vertical particle velocity (m/s) in the cell; NaN where no particle was seen.
    relative : bool, optional
        The solids fraction is each cell's mean count relative to the mean over the cells
        (1: the bed's mean), the file giving no particle diameter (default False).

    Raises
    ------
    InputError
        If the arrays are not all 1D of the same length.
    """

    __repr__ = compact_repr   # arrays by their shape: a notebook's echo stays short

    solids_fraction: np.ndarray
    wall_distance: np.ndarray
    vertical_velocity: np.ndarray
    relative: bool = False

    def __post_init__(self):
        n = None
        for name in FIELDS:
            value = np.array(getattr(self, name), dtype=np.float64)
            if value.ndim != 1 or (n is not None and value.size != n):
                raise InputError(f"cell field {name} must be one number per cell, like the "
                                 "others")
            n = value.size
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "relative", bool(self.relative))

    @property
    def n_cells(self) -> int:
        """Number of cells C."""
        return int(self.solids_fraction.size)

    def field(self, name: str) -> np.ndarray:
        """The field ``name`` (one of :data:`FIELDS`), float64 [C]."""
        return getattr(self, name)


class CellParameter(ABC):
    """A law parameter per cell of a grid."""

    @abstractmethod
    def per_cell(self, space, fields: CellFields | None) -> np.ndarray:
        """The parameter per cell of ``space``'s grid, float64 [C].

        Parameters
        ----------
        space : StateSpace
            The state space whose cell grid (columns, depth columns, rows) the values fit.
        fields : CellFields or None
            The fitting window's cell fields (needed by :class:`FromField` only).

        Raises
        ------
        InputError
            If a table does not fit the grid, or fields are needed but not given.
        """

    @abstractmethod
    def describe(self):
        """The source as JSON-serialisable text."""


@dataclass(frozen=True)
class Constant(CellParameter):
    """The same value in every cell."""

    value: float

    def __post_init__(self):
        try:
            check_finite(self.value, "value")
        except InputError:
            raise InputError(f"Constant({self.value!r}): a constant takes one finite number; "
                             "a value per cell is ByCell(table) or ByCell.from_grid(values)"
                             ) from None

    def per_cell(self, space, fields=None):
        return np.full(space.n_cells, float(self.value))

    def describe(self):
        return float(self.value)


@dataclass(frozen=True)
class ByCell(CellParameter):
    """A value per cell from a table.

    Attributes
    ----------
    table : ndarray of float64, shape (R, 3) or (R, 4)
        Rows col, row[, depth], value; every cell of the grid exactly once.
    source : str
        Where the table came from (a file name), for messages.
    key : str
        The key that named it (``rate_by_cell``), for messages.
    lines : ndarray of int64, shape (R,), optional
        The file line (from 1) of each row, for messages; None: the rows are numbered from 1.
    shape : tuple of int, optional
        The shape of the array :meth:`from_grid` read the table from, for messages (a
        transposed array is named as such); None for a table given as rows.

    Raises
    ------
    InputError
        If the table is a file name or not numbers, or a value is not finite (naming its
        row and cell).
    """

    table: np.ndarray
    source: str = "table"
    key: str = "value_by_cell"
    lines: np.ndarray | None = None
    shape: tuple | None = None

    def __post_init__(self):
        if isinstance(self.table, (str, bytes, os.PathLike)):
            raise InputError(f"ByCell({self.table!r}): a table of rows col, row[, depth], "
                             "value (an array), not a file name; a CSV file is read by "
                             "load_kinetics from a kinetics file's rate_by_cell = \"...\" "
                             "(or ByCell.from_grid(values) for an array of the grid's shape)")
        # the table and line numbers are the parameter's own: a later write to the caller's
        # array changes no answer of the frozen kinetics that holds it
        from cfbmarkov._frozen import read_only_copy

        try:
            table = read_only_copy(self.table, np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{self.source} ({self.key}): a table of numbers (rows col, "
                             "row[, depth], value) is needed") from None
        object.__setattr__(self, "table", table)
        if self.lines is not None:
            object.__setattr__(self, "lines", read_only_copy(self.lines))
        if table.ndim == 2 and table.shape[1] in (3, 4) and table.shape[0]:
            bad = ~np.isfinite(table[:, -1])
            if bad.any():    # named here, where the row is known, not later as "some cell"
                i = int(np.flatnonzero(bad)[0])
                line = (f"line {int(self.lines[i])}" if self.lines is not None
                        else f"data row {i + 1}")
                cell = ", ".join(f"{name} {table[i, c]:g}" for c, name in
                                 enumerate(("col", "row", "depth")[:table.shape[1] - 1]))
                raise InputError(f"{self.source} ({self.key}): {line} ({cell}) gives the "
                                 f"value {table[i, -1]:g}; give a finite number for every "
                                 "cell")

    @classmethod
    def from_grid(cls, values, source: str = "array", key: str = "value_by_cell") -> "ByCell":
        """A value per cell from an array laid out as the grid.

        Parameters
        ----------
        values : array_like of float, shape (rows, columns) or (rows, depth_columns, columns)
            ``values[row, col]`` (row 0 at the bottom), or ``values[row, depth, col]``.
        source, key : str, optional
            For messages.

        Returns
        -------
        ByCell

        Raises
        ------
        InputError
            If ``values`` is not two- or three-dimensional.
        """
        v = np.asarray(values, dtype=np.float64)
        if v.ndim == 2:
            rows, cols = np.meshgrid(np.arange(v.shape[0]), np.arange(v.shape[1]), indexing="ij")
            table = np.column_stack([cols.ravel(), rows.ravel(), v.ravel()])
        elif v.ndim == 3:
            rows, depth, cols = np.meshgrid(*(np.arange(n) for n in v.shape), indexing="ij")
            table = np.column_stack([cols.ravel(), rows.ravel(), depth.ravel(), v.ravel()])
        else:
            raise InputError(f"{source} ({key}): values of shape (rows, columns) or (rows, "
                             f"depth_columns, columns), not {v.shape}")
        return cls(table, source, key, shape=tuple(int(n) for n in v.shape))

    def per_cell(self, space, fields=None):
        if self.shape is not None:       # an array laid out as the grid: its shape says it
            m, d, n = space.columns, space.depth_columns, space.rows
            needed = (n, m) if d == 1 else (n, d, m)
            # a depth axis of one on a grid of one depth is the same layout
            if tuple(self.shape) not in (needed, (n, 1, m) if d == 1 else needed):
                layout = "(rows, columns)" if d == 1 else "(rows, depth_columns, columns)"
                flipped = (" (transposed: values[row, col], row 0 at the bottom)"
                           if tuple(self.shape) == needed[::-1] else "")
                raise InputError(f"{self.source} ({self.key}): values of shape "
                                 f"{tuple(self.shape)}{flipped}; the model's grid "
                                 f"{space.grid_text()} needs shape {layout} = {needed}")
        t = np.asarray(self.table, dtype=np.float64)
        if t.ndim != 2 or t.shape[1] not in (3, 4):
            raise InputError(f"{self.source} ({self.key}): a table of rows col, row[, depth], "
                             f"value, shape (R, 3) or (R, 4), not {t.shape}; a value per "
                             "cell in an array of the grid's shape is "
                             "ByCell.from_grid(values)")
        where = f"{self.source} ({self.key})"
        index = t[:, :t.shape[1] - 1]
        odd = ~(np.isfinite(index) & (index == np.round(index)))
        if odd.any():       # a cast would move 0.7 to column 0 and -0.5 to 0 silently
            r, c = (int(v) for v in np.argwhere(odd)[0])
            raise InputError(f"{where}: row {r} gives {('col', 'row', 'depth')[c]} "
                             f"{index[r, c]:g}: cells are numbered by whole numbers (col "
                             "from 0 at the left, row from 0 at the bottom)")
        cols = t[:, 0].astype(np.int64)
        rows = t[:, 1].astype(np.int64)
        depth = t[:, 2].astype(np.int64) if t.shape[1] == 4 else np.zeros(len(t), np.int64)
        m, d, n = space.columns, space.depth_columns, space.rows
        if t.shape[1] == 4 and d == 1 and np.any(depth != 0):
            i = int(np.flatnonzero(depth != 0)[0])
            line = (f"line {int(self.lines[i])}" if self.lines is not None
                    else f"data row {i + 1}")
            raise InputError(f"{where}: {line} gives depth {depth[i]}, but the grid "
                             f"{space.grid_text()} has the one depth 0: for values that "
                             "differ in depth fit the model on COLUMNSxDEPTHxROWS cells of a "
                             "3D run; else give col,row,VALUE (or depth 0 on every row)")
        if t.shape[1] == 3 and d > 1:
            raise InputError(f"{where}: the grid {space.grid_text()} has {d} depth columns; "
                             "give col,row,depth,VALUE")
        bad = (cols < 0) | (cols >= m) | (rows < 0) | (rows >= n) | (depth < 0) | (depth >= d)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            at = f"col {cols[i]}, row {rows[i]}" + (f", depth {depth[i]}" if d > 1 else "")
            ranges = f"col 0..{m - 1}, row 0..{n - 1}" + (f", depth 0..{d - 1}" if d > 1
                                                          else "")
            raise InputError(f"{where}: cell {at} is outside the grid {space.grid_text()} "
                             f"({ranges}); give one row per cell of the model's grid")
        cell = (rows * d + depth) * m + cols
        seen = np.bincount(cell, minlength=space.n_cells)
        if seen.max() > 1:
            i = int(np.flatnonzero(seen[cell] > 1)[0])        # the first repeated cell
            at = f"col {cols[i]}, row {rows[i]}" + (f", depth {depth[i]}" if d > 1 else "")
            repeated = np.flatnonzero(cell == cell[i])
            named = (f"lines {', '.join(str(int(self.lines[k])) for k in repeated)}"
                     if self.lines is not None else
                     f"data rows {', '.join(str(k + 1) for k in repeated)}")
            raise InputError(f"{where}: the table gives the cell {at} more than once ({named}); "
                             f"give each of the "
                             f"{space.n_cells} cells of the grid {space.grid_text()} exactly "
                             "once")
        if seen.min() < 1:
            missing = np.flatnonzero(seen == 0)
            m = space.columns
            named = "; ".join(f"col {c % m}, row {c // (m * d)}"
                              + (f", depth {(c // m) % d}" if d > 1 else "")
                              for c in missing[:3].tolist())
            more = f"; and {missing.size - 3} more" if missing.size > 3 else ""
            raise InputError(f"{where}: the table misses {missing.size} cell(s) of the grid "
                             f"{space.grid_text()} ({named}{more}); give each of its "
                             f"{space.n_cells} cells exactly once")
        out = np.empty(space.n_cells)
        out[cell] = t[:, -1]
        return out

    def describe(self):
        return {"by_cell": self.source}


@dataclass(frozen=True)
class FromField(CellParameter):
    """``dense`` on the dense side of ``threshold`` of a cell field, else ``dilute``
    (module docstring; a cell where the field is NaN, never visited, takes ``dilute``).
    """

    field: str
    dense: float
    dilute: float
    threshold: float
    key: str = "value_from"

    def __post_init__(self):
        """Refuse a field that is not one of :data:`FIELDS` and a value or threshold that is
        not a finite number (InputError): a NaN threshold would put every cell on the
        dilute side with nothing said."""
        if self.field not in FIELDS:
            raise InputError(f"FromField: {self.field!r} is not a cell field; use one of "
                             f"{', '.join(FIELDS)}")
        for name in ("dense", "dilute", "threshold"):
            object.__setattr__(self, name, check_finite(getattr(self, name),
                                                        f"FromField({self.field!r}) {name}"))

    def per_cell(self, space, fields=None):
        if fields is None:
            raise InputError(f"{self.key} = {self.field!r} needs the fitting window's cell "
                             "fields: give the trajectory file (CellFields)")
        value = fields.field(self.field)
        if value.size != space.n_cells:
            raise InputError(f"cell fields of {value.size} cells for a grid of "
                             f"{space.n_cells} ({space.grid_text()})")
        with np.errstate(invalid="ignore"):
            dense = (value >= self.threshold if FIELDS[self.field] == "above"
                     else value <= self.threshold)
        return np.where(dense, float(self.dense), float(self.dilute))

    def describe(self):
        return {"from": self.field, "dense": self.dense, "dilute": self.dilute,
                "threshold": self.threshold}


def wall_cells(space) -> np.ndarray:
    """Whether each cell of ``space``'s grid touches a side wall (its column is the first or
    the last across, or, on a grid with a depth, the first or last in depth: on one depth
    column every cell touches the front and back walls, as
    :func:`cfbmarkov.analysis.cell_fields.wall_distance` measures it), bool [C]."""
    c = np.arange(space.n_cells)
    m, d = space.columns, space.depth_columns
    col = c % m
    depth = (c // m) % d
    wall = (col == 0) | (col == m - 1)
    if getattr(space, "depth", None) is not None:
        wall |= (depth == 0) | (depth == d - 1)
    return wall
