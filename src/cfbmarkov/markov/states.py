"""State spaces: how a particle's position (and later its motion) becomes a Markov state.

A :class:`StateSpace` maps frames of a trajectory to integer states, knows which cell of the
riser each state lies in (for probability maps and for placing Monte Carlo particles), and
serialises itself to attributes so that a saved model can rebuild it. :class:`CellGrid` is
the paper's space: m columns x n rows of equal cells, state s = row*m + col
(``docs/definitions.md``, States and transitions).
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

    Every state lies in one cell of an underlying m x n cell grid (``cell_of_state``), so
    maps, placement and mixing by halves work for any state space. Subclasses that set a
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

    Notes
    -----
    See ``docs/definitions.md`` (States and transitions).

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

    @property
    @abstractmethod
    def n_states(self) -> int:
        """Number of states S."""

    @property
    def n_cells(self) -> int:
        """Number of cells m x n of the underlying grid."""
        return self.columns * self.rows

    @property
    @abstractmethod
    def cell_of_state(self) -> np.ndarray:
        """Cell index (row*m + col) of every state, int64 [S]."""

    @abstractmethod
    def discretize(self, positions: np.ndarray, velocities: np.ndarray | None = None,
                   lag_frames: int = 1, frame_interval: float | None = None) -> np.ndarray:
        """States of frames (a kernel on arrays; :func:`cfbmarkov.markov.discretize` is the
        way from a trajectory file).

        Parameters
        ----------
        positions : ndarray, shape (T, N, 2) or (N, 2)
            Positions (m) of consecutive frames; a space with memory reads the first
            ``memory_lags * lag_frames`` frames as history only.
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

        kind = attrs.pop("kind", None)
        if kind not in _REGISTRY:
            raise InputError(f"unknown state space kind {kind!r}")
        return _REGISTRY[kind](**attrs)

    def inlet_distribution(self) -> np.ndarray:
        """Eq. (8): a batch spread evenly over the bottom row of cells, as a state vector.

        Each of the m bottom cells gets 1/m, split evenly over the states that lie in it.

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
        bottom = cell < self.columns
        dist = np.zeros(self.n_states)
        # each bottom cell gets 1/m, split evenly over the states that lie in it
        per_cell = np.bincount(cell[bottom], minlength=self.columns)
        dist[bottom] = 1.0 / self.columns / per_cell[cell[bottom]]
        return dist

    def cell_maps(self, distributions: np.ndarray) -> np.ndarray:
        """Sum state vectors into cell maps.

        Parameters
        ----------
        distributions : array_like, shape (..., S)
            State vectors (probabilities or counts per state).

        Returns
        -------
        ndarray of float64, shape (..., rows, columns)
            The sum over the states of each cell; row 0 is the bottom of the riser.
        """
        distributions = np.asarray(distributions, dtype=np.float64)
        lead = distributions.shape[:-1]
        flat = distributions.reshape(-1, self.n_states)
        maps = np.zeros((flat.shape[0], self.n_cells))
        np.add.at(maps.T, self.cell_of_state, flat.T)
        return maps.reshape(*lead, self.rows, self.columns)

    def describe(self) -> str:
        """A one-line description, e.g. ``cells 6x38 (228 states)``."""
        return f"{self.kind} {self.columns}x{self.rows} ({self.n_states} states)"

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
    to 0..n-1."""
    v = coordinate * scale
    k = int(math.floor(v + EDGE_TOLERANCE * max(1.0, abs(v))))
    return min(max(k, 0), n - 1)


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


def cell_index(positions: np.ndarray, width: float, height: float, columns: int, rows: int
               ) -> np.ndarray:
    """Cell number row*m + col of positions; points on the far edges go inside.

    A position on a cell edge belongs to the cell above (right of) it, also where floating
    point puts it a round-off below the edge (0.29 m on 0.01 m rows is 28.999999999999996
    rows): values within ``EDGE_TOLERANCE`` cells below an edge count as on it.

    Parameters
    ----------
    positions : array_like, shape (..., 2)
        Positions (x, y) in m; points outside the domain are clipped into the nearest cell.
    width, height : float
        The riser W x H (m).
    columns, rows : int
        The cell grid m x n.

    Returns
    -------
    ndarray of int32, shape (...)
        The cell of each position.
    """
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    out = np.empty(positions.shape[:-1], dtype=np.int32)
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


class CellGrid(StateSpace):
    """The paper's states: m columns x n rows of equal cells over W x H (Fig. 1).

    State s = row*m + col, row 0 at the bottom (``docs/definitions.md``, Cells and state
    numbers).

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n (at least 1 x 1).
    width, height : float, optional
        The riser W x H (m); the paper's 0.09 x 0.95 m by default.

    Raises
    ------
    InputError
        If the grid has fewer than 1 x 1 cells or the domain is not of positive size.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Fig. 1 and Eq. 1).
    """

    kind = "cells"

    def __init__(self, columns: int, rows: int, width: float = 0.09, height: float = 0.95):
        if int(columns) < 1 or int(rows) < 1:
            raise InputError(f"a cell grid needs at least 1x1 cells, got {columns}x{rows}")
        if not (width > 0 and height > 0):
            raise InputError(f"domain {width:g} x {height:g} m must have positive size")
        self.columns, self.rows = int(columns), int(rows)
        self.width, self.height = float(width), float(height)

    @property
    def n_states(self) -> int:
        """Number of states S = m x n."""
        return self.columns * self.rows

    @property
    def cell_of_state(self) -> np.ndarray:
        """Cell of every state, int64 [S]: the state itself."""
        return np.arange(self.n_states, dtype=np.int64)

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None):
        """The cell of each position (see :meth:`StateSpace.discretize`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, 2) or (N, 2)
            Positions (m).
        velocities, lag_frames, frame_interval
            Ignored (the cells need neither motion nor history).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)
        """
        return cell_index(positions, self.width, self.height, self.columns, self.rows)

    def to_attrs(self):
        """``kind``, ``columns``, ``rows``, ``width`` and ``height`` (see
        :meth:`StateSpace.to_attrs`)."""
        return {"kind": self.kind, "columns": self.columns, "rows": self.rows,
                "width": self.width, "height": self.height}

    def __repr__(self) -> str:
        return f"CellGrid({self.columns}, {self.rows}, width={self.width:g}, height={self.height:g})"


def place_in_cells(cells: np.ndarray, space: StateSpace, seed: int, step: int) -> np.ndarray:
    """Positions drawn uniformly inside the given cells (``docs/definitions.md``, Monte Carlo).

    The draw depends only on (seed, particle index, step), so it is reproducible.

    Parameters
    ----------
    cells : array_like of int, shape (N,)
        The cell (row*m + col) of each particle.
    space : StateSpace
        Gives the grid and the riser's size.
    seed : int
        Seed of the counter-based generator (:func:`cfbmarkov._random.uniform`).
    step : int
        The step (lag) of the run, so that every step draws afresh.

    Returns
    -------
    ndarray of float64, shape (N, 2)
        Positions (x, y) in m.
    """
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    out = np.empty((cells.size, 2))
    _place_in_cells(cells, space.columns, space.width / space.columns,
                    space.height / space.rows, np.uint64(seed), np.uint64(step), out)
    return out


#: names accepted by :func:`state_space_from_name`
STATE_SPACES = ("cells", "cells-direction", "cells-velocity", "cells-previous")


def state_space_from_name(name: str, columns: int, rows: int, width: float = 0.09,
                          height: float = 0.95) -> StateSpace:
    """A state space by name with its defaults.

    Parameters
    ----------
    name : {"cells", "cells-direction", "cells-velocity", "cells-previous"}
        ``cells`` (the paper's), ``cells-direction`` (direction from the displacement),
        ``cells-velocity`` (v_y bins from the displacement over the model's lag),
        ``cells-previous`` (the second-order chain: previous cell within 3 rows).
    columns, rows : int
        The cell grid m x n.
    width, height : float
        The riser W x H (m).

    Returns
    -------
    StateSpace

    Raises
    ------
    InputError
        For an unknown name or a bad grid.

    Notes
    -----
    See ``docs/definitions.md`` (States and transitions).
    """
    from cfbmarkov.markov.memory_states import DirectionCells, SecondOrderCells, VelocityCells

    if name == "cells":
        return CellGrid(columns, rows, width, height)
    if name == "cells-direction":
        return DirectionCells(columns, rows, width, height)
    if name == "cells-velocity":
        return VelocityCells(columns, rows, width, height)
    if name == "cells-previous":
        return SecondOrderCells(columns, rows, width, height)
    raise InputError(f"unknown state space '{name}' (choose from {', '.join(STATE_SPACES)})")
