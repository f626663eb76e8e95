"""State spaces: how a particle's position (and later its motion) becomes a Markov state.

A :class:`StateSpace` maps frames of a trajectory to integer states, knows which cell of the
riser each state lies in (for probability maps and for placing Monte Carlo particles), and
serialises itself to attributes so that a saved model can rebuild it. :class:`CellGrid` is
the paper's space: m columns x n rows of equal cells, state s = row*m + col (SPEC section 2).
State spaces that carry more than the position (direction of motion, velocity bins, the
previous cell) subclass :class:`StateSpace` and register under their ``kind``.
"""

from __future__ import annotations

import json
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
    maps, placement and mixing by halves work for any state space.
    """

    kind: ClassVar[str]
    #: how many earlier frames (in lags) :meth:`discretize` needs before the first state
    memory_lags: ClassVar[int] = 0
    #: whether :meth:`discretize` needs velocities (otherwise displacements suffice)
    needs_velocity: ClassVar[bool] = False

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
        return self.columns * self.rows

    @property
    @abstractmethod
    def cell_of_state(self) -> np.ndarray:
        """Cell index (row*m + col) of every state, int64 [S]."""

    @abstractmethod
    def discretize(self, positions: np.ndarray, velocities: np.ndarray | None = None,
                   lag_frames: int = 1) -> np.ndarray:
        """States int32 [T, N] of frames positions [T, N, 2] (m) (and velocities, m/s)."""

    @abstractmethod
    def to_attrs(self) -> dict[str, Any]:
        """JSON-serialisable description; ``StateSpace.from_attrs`` rebuilds the space."""

    @staticmethod
    def from_attrs(attrs: dict[str, Any] | str) -> "StateSpace":
        if isinstance(attrs, (str, bytes)):
            attrs = json.loads(attrs)
        attrs = dict(attrs)
        kind = attrs.pop("kind", None)
        if kind not in _REGISTRY:
            raise InputError(f"unknown state space kind {kind!r}")
        return _REGISTRY[kind](**attrs)

    def inlet_distribution(self) -> np.ndarray:
        """Eq. (8): a batch spread evenly over the bottom row of cells, as a state vector."""
        cell = self.cell_of_state
        bottom = cell < self.columns
        dist = np.zeros(self.n_states)
        # each bottom cell gets 1/m, split evenly over the states that lie in it
        per_cell = np.bincount(cell[bottom], minlength=self.columns)
        dist[bottom] = 1.0 / self.columns / per_cell[cell[bottom]]
        return dist

    def cell_maps(self, distributions: np.ndarray) -> np.ndarray:
        """Sum state vectors [..., S] into cell maps [..., rows, columns]."""
        distributions = np.asarray(distributions, dtype=np.float64)
        lead = distributions.shape[:-1]
        flat = distributions.reshape(-1, self.n_states)
        maps = np.zeros((flat.shape[0], self.n_cells))
        np.add.at(maps.T, self.cell_of_state, flat.T)
        return maps.reshape(*lead, self.rows, self.columns)

    def describe(self) -> str:
        return f"{self.kind} {self.columns}x{self.rows} ({self.n_states} states)"

    def __eq__(self, other) -> bool:
        return isinstance(other, StateSpace) and self.to_attrs() == other.to_attrs()

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_attrs(), sort_keys=True))


@nb.njit(cache=True, parallel=True)
def _cell_index(positions, width, height, columns, rows, out):
    flat_pos = positions.reshape(-1, 2)
    flat_out = out.reshape(-1)
    sx = columns / width
    sy = rows / height
    for k in nb.prange(flat_out.size):
        col = int(flat_pos[k, 0] * sx)
        row = int(flat_pos[k, 1] * sy)
        col = min(max(col, 0), columns - 1)
        row = min(max(row, 0), rows - 1)
        flat_out[k] = row * columns + col


def cell_index(positions: np.ndarray, width: float, height: float, columns: int, rows: int
               ) -> np.ndarray:
    """Cell number row*m + col of positions [..., 2] (m); points on the far edges go inside."""
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
    """The paper's states: m columns x n rows of equal cells over W x H (Fig. 1)."""

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
        return self.columns * self.rows

    @property
    def cell_of_state(self) -> np.ndarray:
        return np.arange(self.n_states, dtype=np.int64)

    def discretize(self, positions, velocities=None, lag_frames=1):
        return cell_index(positions, self.width, self.height, self.columns, self.rows)

    def to_attrs(self):
        return {"kind": self.kind, "columns": self.columns, "rows": self.rows,
                "width": self.width, "height": self.height}

    def __repr__(self) -> str:
        return f"CellGrid({self.columns}, {self.rows}, width={self.width:g}, height={self.height:g})"


def place_in_cells(cells: np.ndarray, space: StateSpace, seed: int, step: int) -> np.ndarray:
    """Positions [N, 2] (m) drawn uniformly inside the given cells (Monte Carlo, SPEC §2).

    The draw depends only on (seed, particle index, step), so it is reproducible.
    """
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    out = np.empty((cells.size, 2))
    _place_in_cells(cells, space.columns, space.width / space.columns,
                    space.height / space.rows, np.uint64(seed), np.uint64(step), out)
    return out
