"""State spaces: how a particle's position (and later its motion) becomes a Markov state.

A :class:`StateSpace` maps frames of a trajectory to integer states, knows which cell of the
riser each state lies in (for probability maps and for placing Monte Carlo particles), and
serialises itself to attributes so that a saved model can rebuild it. :class:`CellGrid` is
the paper's space: m columns x n rows of equal cells, state s = row*m + col
(``docs/definitions.md``, States and transitions); with d > 1 depth columns (3D data) the
cell is s = (row*d + k)*m + col, k the depth column.
State spaces that carry more than the position subclass :class:`StateSpace` and register
under their ``kind``: :class:`DirectionCells` (cell x {rising, falling}),
:class:`VelocityCells` (cell x vertical-velocity bins) and :class:`SecondOrderCells` (cell x
offset of the previous cell: the second-order chain on cells, kind ``cells-previous``);
:func:`state_space_from_name` builds them by name.

Turning trajectory frames into states goes through :mod:`cfbmarkov.markov.discrete`, which
gives :meth:`StateSpace.discretize` the frames, the lag in frames and the frame interval.
"""

from __future__ import annotations

import json
import math
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numba as nb
import numpy as np

from cfbmarkov._random import uniform
from cfbmarkov.errors import InputError

_REGISTRY: dict[str, type["StateSpace"]] = {}


class StateSpace(ABC):
    """A discretisation of the riser into Markov states.

    Every state lies in one cell of an underlying m x n cell grid, or m x d x n with d depth
    columns (``cell_of_state``), so maps, placement and mixing by halves work for any state
    space. Subclasses that set a
    class attribute ``kind`` are registered under it, so that :meth:`from_attrs` can
    rebuild them from a saved model.

    Attributes
    ----------
    kind : str
        The name of the state space (``cells``, ``cells-direction``, ...), a class
        attribute.
    columns, rows : int
        The cell grid m x n.
    width, height : float
        The riser W x H (m) the grid covers.
    depth_columns : int
        Cells along the depth, d (1 for a 2D grid, a class default).
    depth : float or None
        The riser's depth (m) a 3D grid covers; None for a 2D grid, which uses only the
        (across, vertical) coordinates of 3D positions (a class default).

    Notes
    -----
    See ``docs/definitions.md`` (States and transitions; Cells and state numbers).

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 1, the state vector over the cells).
    """

    kind: ClassVar[str]
    #: how many earlier frames (in lags) :meth:`discretize` needs before the first state.
    #: A class default that a space may override per instance (callers read it on the
    #: instance, ``space.memory_lags``).
    memory_lags: int = 0
    #: whether :meth:`discretize` needs velocities (otherwise positions suffice); a class
    #: default that a space may override per instance, like :attr:`memory_lags`.
    needs_velocity: bool = False

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "kind" in cls.__dict__:
            _REGISTRY[cls.kind] = cls

    columns: int
    rows: int
    width: float
    height: float
    depth_columns: int = 1
    depth: float | None = None

    @property
    @abstractmethod
    def n_states(self) -> int:
        """Number of states S."""

    @property
    def is_3d(self) -> bool:
        """Whether the grid has a depth (it then needs 3D positions)."""
        return self.depth is not None

    @property
    def cells_per_row(self) -> int:
        """Cells in one row of the grid, m x d (cells 0 .. m*d - 1 are the bottom row)."""
        return self.columns * self.depth_columns

    @property
    def n_cells(self) -> int:
        """Number of cells m x d x n of the underlying grid (m x n in 2D)."""
        return self.columns * self.depth_columns * self.rows

    @property
    @abstractmethod
    def cell_of_state(self) -> np.ndarray:
        """Cell index ((row*d + k)*m + col; row*m + col in 2D) of every state, int64 [S]."""

    @abstractmethod
    def discretize(self, positions: np.ndarray, velocities: np.ndarray | None = None,
                   lag_frames: int = 1, frame_interval: float | None = None) -> np.ndarray:
        """States of frames (a kernel on arrays; :func:`cfbmarkov.markov.discretize` is the
        way from a trajectory file).

        Parameters
        ----------
        positions : ndarray, shape (T, N, D) or (N, D)
            Positions (m) of consecutive frames, D = 2 (across, vertical) or 3 (and depth);
            a 2D grid uses the first two coordinates of 3D positions, a 3D grid needs D = 3.
            A space with memory reads the first ``memory_lags * lag_frames`` frames as
            history only.
        velocities : ndarray, shape like ``positions``, optional
            Velocities (m/s), for spaces with ``needs_velocity``.
        lag_frames : int
            The lag in frames.
        frame_interval : float, optional
            Time between frames (s), for spaces that turn displacements into velocities.

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)
        """

    @abstractmethod
    def to_attrs(self) -> dict[str, Any]:
        """JSON-serialisable description; ``StateSpace.from_attrs`` rebuilds the space.

        Returns
        -------
        dict
            ``kind`` and the constructor's arguments.
        """

    @staticmethod
    def from_attrs(attrs: dict[str, Any] | str) -> "StateSpace":
        """Rebuild a state space from :meth:`to_attrs` (as a dict or as JSON text).

        Parameters
        ----------
        attrs : dict or str
            The description, e.g. a model file's ``state_space`` attribute.

        Returns
        -------
        StateSpace

        Raises
        ------
        InputError
            If the kind is unknown, or the arguments make no valid state space (e.g. a bad
            grid).
        """
        if isinstance(attrs, (str, bytes)):
            attrs = json.loads(attrs)
        attrs = dict(attrs)
        import cfbmarkov.markov.memory_states  # noqa: F401  (registers the memory spaces)
        import cfbmarkov.markov.regimes  # noqa: F401  (registers the regime space)

        kind = attrs.pop("kind", None)
        if kind not in _REGISTRY:
            raise InputError(f"unknown state space kind {kind!r}")
        return _REGISTRY[kind](**attrs)

    def fit_to_frames(self, positions: np.ndarray, lag_frames: int,
                      frame_interval: float | None) -> "StateSpace":
        """This space with what it learns from the fitting window fitted; itself for the
        spaces that learn nothing (all but the regime space,
        :class:`~cfbmarkov.markov.regimes.RegimeCells`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, D)
            The window's positions (m) with ``memory_lags * lag_frames`` frames of history
            first, NaN where a particle is absent.
        lag_frames : int
            The lag in frames.
        frame_interval : float or None
            Time between frames (s).

        Returns
        -------
        StateSpace
        """
        return self

    def accepts(self, other: "StateSpace") -> bool:
        """Whether discrete trajectories in ``other`` can be fitted by an estimator
        configured with this space: the same space, or (unfitted regime space) this space
        fitted on the data.

        Parameters
        ----------
        other : StateSpace
            The discrete trajectories' state space.

        Returns
        -------
        bool
        """
        return self == other

    def inlet_distribution(self) -> np.ndarray:
        """Eq. (8): a batch spread evenly over the bottom row of cells, as a state vector.

        Each of the m (m x d with depth columns) bottom cells gets an equal share, split
        evenly over the states that lie in it.

        Returns
        -------
        ndarray of float64, shape (S,)
            The initial state vector S(0); it sums to 1.

        References
        ----------
        Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
        Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
        doi:10.3390/pr13030614 (Eq. 8, batch injection).
        """
        cell = self.cell_of_state
        n_bottom = self.cells_per_row
        bottom = cell < n_bottom
        dist = np.zeros(self.n_states)
        # each bottom cell gets 1/(m d), split evenly over the states that lie in it
        per_cell = np.bincount(cell[bottom], minlength=n_bottom)
        dist[bottom] = 1.0 / n_bottom / per_cell[cell[bottom]]
        return dist

    def cell_maps(self, distributions: np.ndarray, *, by_depth: bool = False) -> np.ndarray:
        """Sum state vectors into cell maps.

        With depth columns (d > 1) the maps are summed over the depth: entry (row, col) is
        the probability (or count) in the whole depth of that cell column, so a map of a
        distribution still sums to its total (``docs/definitions.md``, Cells and state
        numbers). ``by_depth=True`` keeps the depth columns apart instead.

        Parameters
        ----------
        distributions : array_like, shape (..., S)
            State vectors (probabilities or counts per state).
        by_depth : bool, optional
            Return one map per depth column.

        Returns
        -------
        ndarray of float64, shape (..., rows, columns), or (..., d, rows, columns) with
        ``by_depth``
            The sum over the states of each cell; row 0 is the bottom of the riser.
        """
        distributions = np.asarray(distributions, dtype=np.float64)
        lead = distributions.shape[:-1]
        flat = distributions.reshape(-1, self.n_states)
        maps = np.zeros((flat.shape[0], self.n_cells))
        np.add.at(maps.T, self.cell_of_state, flat.T)
        if by_depth:
            maps = maps.reshape(-1, self.rows, self.depth_columns, self.columns)
            return np.moveaxis(maps, 2, 1).reshape(*lead, self.depth_columns, self.rows,
                                                   self.columns)
        if self.depth_columns > 1:
            maps = maps.reshape(-1, self.rows, self.depth_columns, self.columns).sum(axis=2)
        return maps.reshape(*lead, self.rows, self.columns)

    def grid_text(self) -> str:
        """The grid as ``--cells`` writes it: ``6x38``, or ``6x3x38`` with depth columns."""
        if self.is_3d:
            return f"{self.columns}x{self.depth_columns}x{self.rows}"
        return f"{self.columns}x{self.rows}"

    def describe(self) -> str:
        """A one-line description, e.g. ``cells 6x38 (228 states)`` or ``cells 6x3x38 (684
        states)``."""
        return f"{self.kind} {self.grid_text()} ({self.n_states} states)"

    def __eq__(self, other) -> bool:
        return isinstance(other, StateSpace) and self.to_attrs() == other.to_attrs()

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_attrs(), sort_keys=True))


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
        vertical).
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
        If positions are not 2D or 3D, or a depth is given for 2D positions.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim < 1 or positions.shape[-1] not in (2, 3):
        raise InputError(f"positions of shape {positions.shape} are neither 2D nor 3D")
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


@nb.njit(cache=True, parallel=True)
def _place_in_cells(cells, columns, cell_width, cell_height, seed, step, out):
    for p in nb.prange(cells.size):
        c = cells[p]
        row = c // columns
        col = c - row * columns
        out[p, 0] = (col + uniform(seed, 1, p, step)) * cell_width
        out[p, 1] = (row + uniform(seed, 2, p, step)) * cell_height


@nb.njit(cache=True, parallel=True)
def _place_in_cells_3d(cells, columns, depth_columns, cell_width, cell_height, cell_depth,
                       seed, step, out):
    """As :func:`_place_in_cells`, cells (row*d + k)*m + col, depth from stream 3 (with
    d = 1 and cell_depth = the riser's depth: uniform over the depth)."""
    for p in nb.prange(cells.size):
        c = cells[p]
        col = c % columns
        rest = c // columns
        row = rest // depth_columns
        lay = rest - row * depth_columns
        out[p, 0] = (col + uniform(seed, 1, p, step)) * cell_width
        out[p, 1] = (row + uniform(seed, 2, p, step)) * cell_height
        out[p, 2] = (lay + uniform(seed, 3, p, step)) * cell_depth


class CellGrid(StateSpace):
    """The paper's states: m columns x n rows of equal cells over W x H (Fig. 1), and
    optionally d depth columns over the riser's depth (3D data).

    State s = row*m + col, row 0 at the bottom; with a depth (a 3D grid, ``6x3x38`` on the
    command line) s = (row*d + k)*m + col, k = 0 .. d-1 the depth column from depth 0, so a
    row of cells is still one block of m*d states and the bottom row is 0 .. m*d - 1. A 2D
    grid (no depth) on 3D positions uses their (across, vertical) coordinates only: the
    projection. ``docs/definitions.md``, Cells and state numbers.

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n (at least 1 x 1).
    width, height : float, optional
        The riser W x H (m); the paper's 0.09 x 0.95 m by default.
    depth_columns : int, optional
        Cells along the depth, d (at least 1; more than 1 needs ``depth``).
    depth : float, optional
        The riser's depth (m): makes the grid 3D (it then needs 3D positions). None: a 2D
        grid, saved exactly as before depth columns existed.

    Raises
    ------
    InputError
        If the grid has fewer than 1 x 1 (x 1) cells, the domain is not of positive size,
        or depth columns are asked for without a depth.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Fig. 1 and Eq. 1).
    """

    kind = "cells"

    def __init__(self, columns: int, rows: int, width: float = 0.09, height: float = 0.95,
                 depth_columns: int = 1, depth: float | None = None):
        if int(columns) < 1 or int(rows) < 1 or int(depth_columns) < 1:
            grid = f"{columns}x{depth_columns}x{rows}" if depth is not None else f"{columns}x{rows}"
            raise InputError(f"a cell grid needs at least 1x1 cells, got {grid}")
        if int(depth_columns) > 1 and depth is None:
            raise InputError(f"{depth_columns} depth columns need the riser's depth")
        if not (width > 0 and height > 0) or (depth is not None and not depth > 0):
            size = f"{width:g} x {height:g}" + ("" if depth is None else f" x {depth:g}")
            raise InputError(f"domain {size} m must have positive size")
        self.columns, self.rows = int(columns), int(rows)
        self.width, self.height = float(width), float(height)
        self.depth_columns = int(depth_columns)
        self.depth = None if depth is None else float(depth)

    @property
    def n_states(self) -> int:
        """Number of states S = m x n (m x d x n with depth columns)."""
        return self.n_cells

    @property
    def cell_of_state(self) -> np.ndarray:
        """Cell of every state, int64 [S]: the state itself."""
        return np.arange(self.n_states, dtype=np.int64)

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None):
        """The cell of each position (see :meth:`StateSpace.discretize`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, D) or (N, D)
            Positions (m), D = 2 or 3; a 2D grid projects 3D positions on (across,
            vertical), a 3D grid needs D = 3.
        velocities, lag_frames, frame_interval
            Ignored (the cells need neither motion nor history).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If a 3D grid is given 2D positions.
        """
        return cell_index(positions, self.width, self.height, self.columns, self.rows,
                          self.depth, self.depth_columns)

    def to_attrs(self):
        """``kind``, ``columns``, ``rows``, ``width`` and ``height``, and for a 3D grid
        ``depth_columns`` and ``depth`` (see :meth:`StateSpace.to_attrs`)."""
        attrs = {"kind": self.kind, "columns": self.columns, "rows": self.rows,
                 "width": self.width, "height": self.height}
        if self.is_3d:
            attrs.update(depth_columns=self.depth_columns, depth=self.depth)
        return attrs

    def __repr__(self) -> str:
        if self.is_3d:
            return (f"CellGrid({self.columns}, {self.rows}, width={self.width:g}, "
                    f"height={self.height:g}, depth_columns={self.depth_columns}, "
                    f"depth={self.depth:g})")
        return f"CellGrid({self.columns}, {self.rows}, width={self.width:g}, height={self.height:g})"


def place_in_cells(cells: np.ndarray, space: StateSpace, seed: int, step: int,
                   depth: float | None = None) -> np.ndarray:
    """Positions drawn uniformly inside the given cells (``docs/definitions.md``, Monte Carlo).

    The draw depends only on (seed, particle index, step), so it is reproducible. A 3D grid
    gives 3D positions inside its cells; a 2D grid gives 2D positions, or with ``depth`` 3D
    positions whose depth is drawn uniformly over 0 .. ``depth`` (a 2D cell spans the whole
    depth). The across and vertical coordinates are the same draws in all cases.

    Parameters
    ----------
    cells : array_like of int, shape (N,)
        The cell (row*m + col, or (row*d + k)*m + col with depth columns) of each particle.
    space : StateSpace
        Gives the grid and the riser's size.
    seed : int
        Seed of the counter-based generator (:func:`cfbmarkov._random.uniform`).
    step : int
        The step (lag) of the run, so that every step draws afresh.
    depth : float, optional
        The riser's depth (m), for 3D positions from a 2D grid; ignored by a 3D grid (it
        has its own depth).

    Returns
    -------
    ndarray of float64, shape (N, 2) or (N, 3)
        Positions (across, vertical[, depth]) in m.
    """
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    if space.is_3d or depth is not None:
        d = space.depth_columns if space.is_3d else 1
        out = np.empty((cells.size, 3))
        _place_in_cells_3d(cells, space.columns, d, space.width / space.columns,
                           space.height / space.rows,
                           (space.depth if space.is_3d else float(depth)) / d,
                           np.uint64(seed), np.uint64(step), out)
        return out
    out = np.empty((cells.size, 2))
    _place_in_cells(cells, space.columns, space.width / space.columns,
                    space.height / space.rows, np.uint64(seed), np.uint64(step), out)
    return out


#: names accepted by :func:`state_space_from_name`
STATE_SPACES = ("cells", "cells-direction", "cells-velocity", "cells-velocity-fine",
                "cells-previous", "cells-regime", "cells-direction-regime")


def state_space_from_name(name: str, columns: int, rows: int, width: float = 0.09,
                          height: float = 0.95, depth_columns: int | None = None,
                          depth: float | None = None) -> StateSpace:
    """A state space by name with its defaults.

    Parameters
    ----------
    name : {"cells", "cells-direction", "cells-velocity", "cells-velocity-fine", \
            "cells-previous", "cells-regime", "cells-direction-regime"}
        ``cells`` (the paper's), ``cells-direction`` (direction from the displacement),
        ``cells-velocity`` (8 v_y bins from the displacement over the model's lag, edges at
        the quantiles of the fitting window's velocities), ``cells-velocity-fine`` (and each
        row split into sub-rows no taller than the median move in a lag, fitted on the
        fitting window),
        ``cells-previous`` (the second-order chain: previous cell within 3 rows),
        ``cells-regime`` (cells x 2 regimes of the solids flux, edges fitted on the fitting
        window), ``cells-direction-regime`` (and the direction).
    columns, rows : int
        The cell grid m x n.
    width, height : float
        The riser W x H (m).
    depth_columns : int, optional
        Cells along the depth, d: a 3D grid (needs ``depth``; only ``cells`` has depth
        columns yet). None: a 2D grid, which projects 3D positions.
    depth : float, optional
        The riser's depth (m), for a 3D grid.

    Returns
    -------
    StateSpace

    Raises
    ------
    InputError
        For an unknown name, a bad grid, depth columns without a depth, or depth columns
        for a state space with memory.

    Notes
    -----
    See ``docs/definitions.md`` (States and transitions).
    """
    from cfbmarkov.markov.memory_states import (DirectionCells, FineVelocityCells,
                                                SecondOrderCells, VelocityCells)

    if depth_columns is not None:
        if name not in STATE_SPACES:
            raise InputError(f"unknown state space '{name}' (choose from {', '.join(STATE_SPACES)})")
        if name != "cells":
            raise InputError(f"state space {name} has no depth columns yet: use --states cells "
                             "with COLUMNSxDEPTHxROWS, or COLUMNSxROWS (the projection)")
        if depth is None:
            raise InputError(f"{depth_columns} depth column(s) need 3D data (the riser's depth)")
        return CellGrid(columns, rows, width, height, depth_columns, depth)
    if name == "cells":
        return CellGrid(columns, rows, width, height)
    if name == "cells-direction":
        return DirectionCells(columns, rows, width, height)
    if name == "cells-velocity":
        return VelocityCells(columns, rows, width, height, edges=None)
    if name == "cells-velocity-fine":
        return FineVelocityCells(columns, rows, width, height)
    if name == "cells-previous":
        return SecondOrderCells(columns, rows, width, height)
    if name in ("cells-regime", "cells-direction-regime"):
        from cfbmarkov.markov.regimes import DirectionRegimeCells, RegimeCells

        return (DirectionRegimeCells if name == "cells-direction-regime" else RegimeCells)(
            columns, rows, width, height)
    raise InputError(f"unknown state space '{name}' (choose from {', '.join(STATE_SPACES)})")
