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
    """Cell number row*m + col of positions; points on the far edges go inside.

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


# -- state spaces with memory (issue 5) ----------------------------------------------------
#
# The paper's chain on cells forgets which way a particle was moving, so it spreads residence
# times too little (SD(RT) about -40...-50 %). The spaces below keep the cell and add a
# sub-state that carries some memory of the motion. They all share one layout:
#
#     state = cell * K + sub,   cell = row*m + col (CellGrid's numbering), 0 <= sub < K,
#
# so ``cell_of_state = state // K`` and everything that works on cells (maps, Monte Carlo
# placement, mixing by halves, the inlet distribution of Eq. 8) works unchanged.
#
# Spaces whose sub-state comes from the displacement over the previous lag have
# ``memory_lags = 1``: ``discretize`` is then given frames that start one lag (``lag_frames``
# frames) before the first frame whose state is wanted (:mod:`cfbmarkov.markov.discrete`
# reads them and drops them again), returns states for every frame, and the state of frame t
# uses the frames t - lag_frames and t. The first ``lag_frames`` frames have no previous
# frame; they get the sub-state of a zero displacement (any valid state: callers drop them).
# Vertical displacements take the minimal image through the periodic boundary, wrapped into
# (-H/2, H/2] (a particle moves less than H/2 in one lag, docs/definitions.md, Pass direction).


@nb.njit(cache=True, parallel=True)
def _wrapped_step(y, lag_frames, height, out):
    """out[t, p] = y[t, p] - y[t - lag_frames, p] wrapped into (-H/2, H/2]; 0 where
    t < lag_frames (no previous frame)."""
    n_frames, n = y.shape
    half = 0.5 * height
    for k in nb.prange(n_frames * n):
        t = k // n
        p = k - t * n
        if t < lag_frames:
            out[t, p] = 0.0
        else:
            d = y[t, p] - y[t - lag_frames, p]
            if d > half:
                d -= height
            elif d <= -half:
                d += height
            out[t, p] = d


@nb.njit(cache=True, parallel=True)
def _direction_states(cells, vertical, out):
    """out = 2*cell + (1 if vertical < 0 else 0): rising (including 0) or falling."""
    flat_c = cells.reshape(-1)
    flat_v = vertical.reshape(-1)
    flat_out = out.reshape(-1)
    for k in nb.prange(flat_out.size):
        flat_out[k] = 2 * flat_c[k] + (1 if flat_v[k] < 0.0 else 0)


@nb.njit(cache=True, parallel=True)
def _binned_states(cells, vertical, scale, edges, out):
    """out = cell*(B+1) + bin, bin = number of edges <= vertical*scale (B = len(edges))."""
    flat_c = cells.reshape(-1)
    flat_v = vertical.reshape(-1)
    flat_out = out.reshape(-1)
    n_bins = edges.size + 1
    for k in nb.prange(flat_out.size):
        v = flat_v[k] * scale
        b = 0
        while b < edges.size and edges[b] <= v:
            b += 1
        flat_out[k] = flat_c[k] * n_bins + b


@nb.njit(cache=True, parallel=True)
def _previous_cell_states(cells, lag_frames, columns, rows, reach, column_reach, out):
    """out = cell*K + (dcol + Rc)*(2R + 1) + (drow + R), K = (2R+1)(2Rc+1), where drow and
    dcol are the row and column of the cell one lag earlier minus the current ones, drow by
    the minimal image on the periodic rows (wrapped into (-n/2, n/2]), both clipped to the
    reach; 0 where t < lag_frames."""
    n_frames, n = cells.shape
    span = 2 * reach + 1
    per_cell = span * (2 * column_reach + 1)
    for k in nb.prange(n_frames * n):
        t = k // n
        p = k - t * n
        c = cells[t, p]
        drow = 0
        dcol = 0
        if t >= lag_frames:
            prev = cells[t - lag_frames, p]
            row = c // columns
            prow = prev // columns
            drow = (prow - row) % rows          # 0..n-1 (Python-style modulo in numba)
            if 2 * drow > rows:
                drow -= rows                     # into (-n/2, n/2]
            dcol = (prev - prow * columns) - (c - row * columns)
            drow = min(max(drow, -reach), reach)
            dcol = min(max(dcol, -column_reach), column_reach)
        out[t, p] = c * per_cell + (dcol + column_reach) * span + (drow + reach)


class _CellProductSpace(StateSpace):
    """Cells x K sub-states: state = cell*K + sub (see the section comment above)."""

    def __init__(self, columns: int, rows: int, width: float, height: float):
        self._grid = CellGrid(columns, rows, width, height)      # validates the grid
        self.columns, self.rows = self._grid.columns, self._grid.rows
        self.width, self.height = self._grid.width, self._grid.height

    #: sub-states per cell, K
    per_cell: int

    @property
    def n_states(self) -> int:
        return self.n_cells * self.per_cell

    @property
    def cell_of_state(self) -> np.ndarray:
        return np.arange(self.n_states, dtype=np.int64) // self.per_cell

    def sub_state(self, states: np.ndarray) -> np.ndarray:
        """The sub-state (0..K-1) of states.

        Parameters
        ----------
        states : array_like of int
            States of this space.

        Returns
        -------
        ndarray of int
            ``states % K``, same shape.
        """
        return np.asarray(states) % self.per_cell

    def _cells(self, positions: np.ndarray) -> np.ndarray:
        return cell_index(positions, self.width, self.height, self.columns, self.rows)

    def _vertical(self, positions: np.ndarray, velocities, lag_frames: int, source: str
                  ) -> np.ndarray:
        """Vertical motion per frame [T, N]: wrapped dy over the previous lag (m) for
        ``source="displacement"``, v_y (m/s) for ``source="velocity"``."""
        if source == "velocity":
            if velocities is None:
                raise InputError(f"state space {self.kind} with source='velocity' needs "
                                 "velocities; the trajectories have none")
            velocities = np.asarray(velocities, dtype=np.float64)
            if velocities.shape != np.shape(positions):
                raise InputError(f"velocities have shape {velocities.shape}, positions "
                                 f"{np.shape(positions)}")
            return np.ascontiguousarray(velocities[..., 1])
        lag_frames = int(lag_frames)
        if lag_frames < 1:
            raise InputError(f"lag of {lag_frames} frames: must be at least 1")
        y = np.ascontiguousarray(np.asarray(positions, dtype=np.float64)[..., 1])
        if y.ndim == 1:      # a single frame has no previous frame
            return np.zeros_like(y)
        out = np.empty_like(y)
        _wrapped_step(y, lag_frames, self.height, out)
        return out

    def _base_attrs(self) -> dict[str, Any]:
        return {"kind": self.kind, "columns": self.columns, "rows": self.rows,
                "width": self.width, "height": self.height}


_SOURCES = ("displacement", "velocity")


def _check_source(kind: str, source: str) -> str:
    if source not in _SOURCES:
        raise InputError(f"{kind}: unknown source {source!r} (choose from {', '.join(_SOURCES)})")
    return str(source)


class DirectionCells(_CellProductSpace):
    """Cells x {rising, falling}: state = 2*cell + (1 if falling else 0).

    ``source="displacement"`` (default): the direction is the sign of the vertical
    displacement over the previous lag (minimal image through the periodic boundary), so the
    space needs one lag of history (``memory_lags = 1``) and no velocities; a particle that
    stayed at the same height (dy = 0, e.g. the first frames) counts as rising.
    ``source="velocity"``: the sign of v_y in the frame itself (``needs_velocity``; no
    history); v_y = 0 counts as rising.

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n.
    width, height : float, optional
        The riser W x H (m).
    source : {"displacement", "velocity"}, optional
        Where the direction comes from.

    Attributes
    ----------
    RISING, FALLING : int
        The two sub-states (0 and 1).

    Raises
    ------
    InputError
        For a bad grid or an unknown ``source``.

    Notes
    -----
    See ``docs/definitions.md`` (Pass direction) for the minimal-image rule.
    """

    kind = "cells-direction"
    per_cell = 2
    RISING, FALLING = 0, 1

    def __init__(self, columns: int, rows: int, width: float = 0.09, height: float = 0.95,
                 source: str = "displacement"):
        super().__init__(columns, rows, width, height)
        self.source = _check_source(self.kind, source)
        self.memory_lags = 1 if self.source == "displacement" else 0
        self.needs_velocity = self.source == "velocity"

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None):
        """States of frames (see :meth:`StateSpace.discretize`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, 2) or (N, 2)
            Positions (m); with ``memory_lags = 1`` the first ``lag_frames`` frames are
            history.
        velocities : ndarray, shape like ``positions``, optional
            Velocities (m/s), needed with ``source="velocity"``.
        lag_frames : int
            The lag in frames (>= 1).
        frame_interval : float, optional
            Time between frames (s); not used.

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If ``source="velocity"`` and the velocities are missing or do not match the
            positions' shape, or ``lag_frames < 1``.
        """
        cells = self._cells(positions)
        vertical = self._vertical(positions, velocities, lag_frames, self.source)
        out = np.empty_like(cells)
        _direction_states(cells, vertical, out)
        return out

    def falling(self, states: np.ndarray) -> np.ndarray:
        """True where a state is a falling one.

        Parameters
        ----------
        states : array_like of int
            States of this space.

        Returns
        -------
        ndarray of bool
            Same shape as ``states``.
        """
        return self.sub_state(states) == self.FALLING

    def to_attrs(self):
        """The grid and ``source`` (see :meth:`StateSpace.to_attrs`)."""
        return {**self._base_attrs(), "source": self.source}

    def describe(self) -> str:
        """A one-line description, with the source of the direction."""
        return (f"{self.kind} {self.columns}x{self.rows}x2 ({self.n_states} states, direction "
                f"from {self.source})")

    def __repr__(self) -> str:
        return (f"DirectionCells({self.columns}, {self.rows}, width={self.width:g}, "
                f"height={self.height:g}, source={self.source!r})")


class VelocityCells(_CellProductSpace):
    """Cells x bins of the vertical velocity: state = cell*(B+1) + bin.

    ``edges`` are the B interior bin edges (m/s, strictly increasing); bin b holds
    edges[b-1] <= v < edges[b] (bin 0: v < edges[0], bin B: v >= edges[-1]).
    ``source="displacement"`` (default): v = (wrapped vertical displacement over the
    previous lag) / lag, with the lag = ``lag_frames * frame_interval`` that
    :meth:`discretize` is given (the lag of the model being fitted, so the two cannot
    disagree); ``memory_lags = 1``. ``source="velocity"``: v = v_y of the frame
    (``needs_velocity``). The first frames (no previous frame) get v = 0.

    Model files written before the lag lived in one place stored it here as ``lag``; it is
    accepted on loading and ignored (the model's own lag is the one used).

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n.
    width, height : float, optional
        The riser W x H (m).
    edges : sequence of float, optional
        The B interior bin edges of v_y (m/s), finite and strictly increasing.
    source : {"displacement", "velocity"}, optional
        Where v_y comes from.
    lag : float, optional
        Accepted from old model files and ignored.

    Raises
    ------
    InputError
        For a bad grid, edges that are not numbers or not finite and strictly increasing,
        or an unknown ``source``.
    """

    kind = "cells-velocity"

    def __init__(self, columns: int, rows: int, width: float = 0.09, height: float = 0.95,
                 edges=(-1.0, 0.0, 1.0, 3.0), source: str = "displacement",
                 lag: float | None = None):
        super().__init__(columns, rows, width, height)
        try:
            edges = np.asarray(edges, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise InputError(f"{self.kind}: velocity bin edges {edges!r} are not numbers") from None
        if edges.size < 1 or not np.all(np.isfinite(edges)) or np.any(np.diff(edges) <= 0):
            raise InputError(f"{self.kind}: velocity bin edges must be one or more finite, "
                             f"strictly increasing values (m/s), got {edges.tolist()}")
        del lag     # stored by older model files; the lag now comes with the frames
        self.edges = tuple(float(e) for e in edges)
        self.source = _check_source(self.kind, source)
        self.memory_lags = 1 if self.source == "displacement" else 0
        self.needs_velocity = self.source == "velocity"

    @property
    def per_cell(self) -> int:
        """Sub-states per cell, K = B + 1 velocity bins."""
        return len(self.edges) + 1

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None):
        """States of frames (see :meth:`StateSpace.discretize`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, 2) or (N, 2)
            Positions (m); with ``memory_lags = 1`` the first ``lag_frames`` frames are
            history.
        velocities : ndarray, shape like ``positions``, optional
            Velocities (m/s), needed with ``source="velocity"``.
        lag_frames : int
            The lag in frames (>= 1).
        frame_interval : float, optional
            Time between frames (s); required with ``source="displacement"`` (v = dy / lag).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If ``source="velocity"`` and the velocities are missing or do not match the
            positions' shape, or (``source="displacement"``) ``lag_frames < 1`` or the
            frame interval is missing or not positive.
        """
        cells = self._cells(positions)
        vertical = self._vertical(positions, velocities, lag_frames, self.source)
        scale = 1.0
        if self.source == "displacement":
            if frame_interval is None or not (np.isfinite(frame_interval) and frame_interval > 0):
                raise InputError(f"{self.kind}: velocities from displacements need the frame "
                                 f"interval (s), got {frame_interval!r}")
            scale = 1.0 / (int(lag_frames) * float(frame_interval))
        out = np.empty_like(cells)
        _binned_states(cells, vertical, scale, np.asarray(self.edges, dtype=np.float64), out)
        return out

    def velocity_bin(self, states: np.ndarray) -> np.ndarray:
        """The velocity bin (0..B) of states.

        Parameters
        ----------
        states : array_like of int
            States of this space.

        Returns
        -------
        ndarray of int
            Same shape as ``states``.
        """
        return self.sub_state(states)

    def to_attrs(self):
        """The grid, ``edges`` and ``source`` (see :meth:`StateSpace.to_attrs`)."""
        return {**self._base_attrs(), "edges": list(self.edges), "source": self.source}

    def describe(self) -> str:
        """A one-line description, with the bin edges (m/s) and their source."""
        return (f"{self.kind} {self.columns}x{self.rows}x{self.per_cell} ({self.n_states} "
                f"states, v_y bins at {', '.join(f'{e:g}' for e in self.edges)} m/s from "
                f"{self.source})")

    def __repr__(self) -> str:
        return (f"VelocityCells({self.columns}, {self.rows}, width={self.width:g}, "
                f"height={self.height:g}, edges={self.edges}, source={self.source!r})")


class SecondOrderCells(_CellProductSpace):
    """The second-order chain on cells, with the previous cell stored relative to the
    current one: state = cell*K + (dcol + Rc)*(2R + 1) + (drow + R), K = (2R+1)(2Rc+1).

    drow = (row one lag earlier) - (row now), by the minimal image on the periodic rows,
    clipped to [-R, R] (R = ``reach``); dcol = (column one lag earlier) - (column now),
    clipped to [-Rc, Rc] (Rc = ``column_reach``). ``memory_lags = 1``. The defaults (R = 3,
    Rc = 0) give 7 sub-states per cell, 1596 states on 6 x 38.

    What clipping loses: a particle that moved more than R rows in one lag (faster than
    R*cell height/lag: 0.075 m / 0.025 s = 3 m/s for the paper's grid and R = 3) is
    remembered only as "came from R or more rows below/above"; with Rc = 0 the column it
    came from is forgotten (only vertical memory is kept). Within the reach the chain is
    the exact second-order chain on cells. The first frames (no previous frame) get
    drow = dcol = 0.

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n.
    width, height : float, optional
        The riser W x H (m).
    reach : int, optional
        R, the row offsets kept (whole number >= 0).
    column_reach : int, optional
        Rc, the column offsets kept (whole number >= 0).

    Raises
    ------
    InputError
        For a bad grid, or ``reach`` or ``column_reach`` not whole numbers >= 0.
    """

    kind = "cells-previous"

    def __init__(self, columns: int, rows: int, width: float = 0.09, height: float = 0.95,
                 reach: int = 3, column_reach: int = 0):
        super().__init__(columns, rows, width, height)
        if int(reach) != reach or int(column_reach) != column_reach \
                or reach < 0 or column_reach < 0:
            raise InputError(f"{self.kind}: reach {reach!r} and column_reach {column_reach!r} "
                             "must be whole numbers >= 0")
        self.reach, self.column_reach = int(reach), int(column_reach)
        self.memory_lags = 1

    @property
    def per_cell(self) -> int:
        """Sub-states per cell, K = (2R + 1)(2Rc + 1)."""
        return (2 * self.reach + 1) * (2 * self.column_reach + 1)

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None):
        """States of frames (see :meth:`StateSpace.discretize`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, 2) or (N, 2)
            Positions (m); the first ``lag_frames`` frames are history.
        velocities, frame_interval
            Ignored.
        lag_frames : int
            The lag in frames (>= 1).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If ``lag_frames < 1``.
        """
        cells = self._cells(positions)
        lag_frames = int(lag_frames)
        if lag_frames < 1:
            raise InputError(f"lag of {lag_frames} frames: must be at least 1")
        if cells.ndim == 1:                   # a single frame: no previous frame
            cells = cells[None]
            out = np.empty_like(cells)
            _previous_cell_states(cells, lag_frames, self.columns, self.rows, self.reach,
                                  self.column_reach, out)
            return out[0]
        out = np.empty_like(cells)
        _previous_cell_states(cells, lag_frames, self.columns, self.rows, self.reach,
                              self.column_reach, out)
        return out

    def offsets(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(drow, dcol) of states: previous minus current, as clipped.

        Parameters
        ----------
        states : array_like of int
            States of this space.

        Returns
        -------
        drow, dcol : ndarray of int
            Row and column offsets, same shape as ``states``.
        """
        sub = self.sub_state(states)
        span = 2 * self.reach + 1
        return sub % span - self.reach, sub // span - self.column_reach

    def to_attrs(self):
        """The grid, ``reach`` and ``column_reach`` (see :meth:`StateSpace.to_attrs`)."""
        return {**self._base_attrs(), "reach": self.reach, "column_reach": self.column_reach}

    def describe(self) -> str:
        """A one-line description, with the reach of the memory."""
        return (f"{self.kind} {self.columns}x{self.rows}x{self.per_cell} ({self.n_states} "
                f"states, previous cell within {self.reach} row(s), {self.column_reach} "
                "column(s))")

    def __repr__(self) -> str:
        return (f"SecondOrderCells({self.columns}, {self.rows}, width={self.width:g}, "
                f"height={self.height:g}, reach={self.reach}, "
                f"column_reach={self.column_reach})")


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
    if name == "cells":
        return CellGrid(columns, rows, width, height)
    if name == "cells-direction":
        return DirectionCells(columns, rows, width, height)
    if name == "cells-velocity":
        return VelocityCells(columns, rows, width, height)
    if name == "cells-previous":
        return SecondOrderCells(columns, rows, width, height)
    raise InputError(f"unknown state space '{name}' (choose from {', '.join(STATE_SPACES)})")
