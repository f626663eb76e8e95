"""State spaces: how a particle's position (and later its motion) becomes a Markov state.

A :class:`StateSpace` maps frames of a trajectory to integer states, knows which cell of the
riser each state lies in (for probability maps and for placing Monte Carlo particles), and
serialises itself to attributes so that a saved model can rebuild it. :class:`CellGrid` is
the paper's space: m columns x n rows of equal cells, state s = row*m + col
(``docs/definitions.md``, States and transitions); with d > 1 depth columns (3D data) the
cell is s = (row*d + k)*m + col, k the depth column.
State spaces that carry more than the position subclass :class:`StateSpace` and register
themselves under their ``kind`` (:meth:`StateSpace.registered_kinds`):
:class:`~cfbmarkov.markov.memory_states.DirectionCells` (cell x {rising, falling}),
:class:`~cfbmarkov.markov.velocity_states.VelocityCells` (cell x vertical-velocity bins),
:class:`~cfbmarkov.markov.memory_states.SecondOrderCells` (cell x offset of the previous
cell: the second-order chain on cells, kind ``cells-previous``) and the regime spaces of
:mod:`cfbmarkov.markov.regimes`; :mod:`cfbmarkov.markov.spaces` builds them by name or from
a saved description.

Turning trajectory frames into states goes through :mod:`cfbmarkov.markov.discrete`, which
gives :meth:`StateSpace.discretize` the frames, the lag in frames, the frame interval and
the memo of what the spaces derive from those frames
(:class:`~cfbmarkov.markov.frame_quantities.FrameQuantities`).
"""

from __future__ import annotations

import copy
import functools
import json
from abc import ABC, abstractmethod
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numba as nb
import numpy as np

from cfbmarkov._random import uniform
from cfbmarkov.errors import InputError
from cfbmarkov.markov.cells import cell_index
from cfbmarkov.markov.frame_quantities import FrameQuantities

#: random-number streams of a particle's place within its cell: across, up, and in depth
#: (the depth's own stream: stream 3 draws the pass direction of the same particle and step,
#: :mod:`cfbmarkov.markov.montecarlo`, and a shared draw tied the depth to the pass)
STREAM_X, STREAM_Y, STREAM_DEPTH = 1, 2, 10

#: every subclass of :class:`StateSpace` that sets ``kind``, by kind (filled as they are
#: defined)
_REGISTRY: dict[str, type["StateSpace"]] = {}


class StateSpace(ABC):
    """A discretisation of the riser into Markov states.

    Every state lies in one cell of an underlying m x n cell grid, or m x d x n with d depth
    columns (``cell_of_state``), so maps, placement and mixing by halves work for any state
    space. Subclasses that set a class attribute ``kind`` register themselves under it
    (:meth:`registered_kinds`), so that
    :func:`~cfbmarkov.markov.spaces.state_space_from_attrs` can rebuild them from a saved
    model and :func:`~cfbmarkov.markov.spaces.state_space_from_name` can build them by name.

    Attributes
    ----------
    kind : str
        The name of the state space (``cells``, ``cells-direction``, ...), a class
        attribute.
    columns, rows : int
        The cell grid m x n.
    width, height : float or None
        The riser W x H (m) the grid covers; None for a space made without a size, which
        takes the size of the trajectory file it is first discretised on (:meth:`with_size`).
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
    #: whether the constructor takes ``depth_columns`` and ``depth`` after the riser's
    #: size (a 3D grid); only such spaces are built by name with depth columns
    has_depth_columns: ClassVar[bool] = False

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "kind" in cls.__dict__:
            _REGISTRY[cls.kind] = cls
        init = cls.__dict__.get("__init__")
        if init is not None:
            # a space is immutable once made, as a fitted model that holds it is: its
            # states cannot change under the model (a caller's grid changed after the fit
            # made the model's arrays another size than its states)
            @functools.wraps(init)
            def frozen_init(self, *args, _init=init, _cls=cls, **kw):
                _init(self, *args, **kw)
                if type(self).__init__ is _cls.__init__:     # the outermost __init__ done
                    object.__setattr__(self, "_frozen", True)

            cls.__init__ = frozen_init

    def __setattr__(self, name: str, value) -> None:
        if self.__dict__.get("_frozen", False):
            raise AttributeError(f"{type(self).__name__} is immutable: cannot set {name!r}; make "
                                 "a new state space (e.g. CellGrid(6, 38, width, height))")
        object.__setattr__(self, name, value)

    @staticmethod
    def registered_kinds() -> Mapping[str, type["StateSpace"]]:
        """The state-space classes defined so far, by ``kind``.

        Returns
        -------
        Mapping of str to type
            A read-only view: every subclass that sets ``kind`` is in it once its module is
            imported (:mod:`cfbmarkov.markov.spaces` imports them all).
        """
        return MappingProxyType(_REGISTRY)

    @classmethod
    def with_defaults(cls, columns: int, rows: int, width: float | None = None,
                      height: float | None = None) -> "StateSpace":
        """This kind of space on a grid with its other parameters at their defaults (what
        :func:`~cfbmarkov.markov.spaces.state_space_from_name` builds).

        Parameters
        ----------
        columns, rows : int
            The cell grid m x n.
        width, height : float, optional
            The riser W x H (m); None: the size of the file the space is used on.

        Returns
        -------
        StateSpace

        Raises
        ------
        InputError
            For a bad grid.
        """
        return cls(columns, rows, width, height)

    @property
    def sized(self) -> bool:
        """Whether the space has the riser's size (else it takes a file's, :meth:`with_size`)."""
        return self.width is not None and self.height is not None

    def with_size(self, width: float, height: float) -> "StateSpace":
        """This space on a riser of ``width`` x ``height`` (m): how a space made without a
        size takes the size of the trajectory file it is discretised on.

        Parameters
        ----------
        width, height : float
            The riser W x H (m).

        Returns
        -------
        StateSpace
            A copy with the size set (everything else shared).

        Raises
        ------
        InputError
            If the size is not positive.
        """
        if not (width > 0 and height > 0):
            raise InputError(f"domain {width:g} x {height:g} m must have positive size")
        new = copy.copy(self)
        object.__setattr__(new, "_frozen", False)       # the copy is made here, then frozen
        new._set_size(float(width), float(height))
        object.__setattr__(new, "_frozen", True)
        return new

    def _set_size(self, width: float, height: float) -> None:
        self.width, self.height = width, height

    def _require_size(self) -> None:
        """Refuse to discretise arrays with a space made without a size."""
        if not self.sized:
            raise InputError(f"state space {self.kind} {self.grid_text()} has no riser size: "
                             "give width and height, or discretise a trajectory file (whose "
                             "size it takes)")

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
                   lag_frames: int = 1, frame_interval: float | None = None, *,
                   memo: FrameQuantities | None = None) -> np.ndarray:
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
        memo : FrameQuantities, optional
            What is derived from ``positions`` (this very array) and shared by the spaces
            discretised on it (cells, vertical displacements); None, or a memo of other
            positions: computed here. It also carries the riser's boundary: without one,
            a space with memory reads vertical moves by the periodic riser's minimal image;
            for an open riser give ``FrameQuantities(positions, periodic=False)``
            (:func:`cfbmarkov.markov.discretize` does so from the file).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)
        """

    @abstractmethod
    def to_attrs(self) -> dict[str, Any]:
        """JSON-serialisable description;
        :func:`~cfbmarkov.markov.spaces.state_space_from_attrs` rebuilds the space.

        Returns
        -------
        dict
            ``kind`` and the constructor's arguments.
        """

    def fit_to_frames(self, positions: np.ndarray, lag_frames: int,
                      frame_interval: float | None, *,
                      memo: FrameQuantities | None = None) -> "StateSpace":
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
        memo : FrameQuantities, optional
            As in :meth:`discretize`.

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

    def describe_against(self, other: "StateSpace") -> str:
        """:meth:`describe`, with what differs from ``other`` where both describe alike
        (the same cells on a riser of another size: ``cells 6x38 (228 states) (height 2.0
        against 0.95, width 0.2 against 0.09)``), for a refusal that names the difference."""
        text = self.describe()
        if text != other.describe() or self == other:
            return text
        a, b = self.to_attrs(), other.to_attrs()
        differ = [f"{k} {a.get(k)!r} against {b.get(k)!r}"
                  for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        return f"{text} ({', '.join(differ)})"

    def __eq__(self, other) -> bool:
        return isinstance(other, StateSpace) and self.to_attrs() == other.to_attrs()

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_attrs(), sort_keys=True))


@nb.njit(cache=True, parallel=True)
def _place_in_cells(cells, columns, depth_columns, cell_width, cell_height, cell_depth, seed,
                    step, out):
    """Positions uniform in the cells ``cells`` [T, N] ((row*d + k)*m + col; d = 1 without
    depth columns) of steps step .. step + T - 1 into ``out`` [T, N, D]: across from
    stream 1, vertical from stream 2 and, where D = 3, depth from stream 3 (with d = 1 and
    cell_depth the riser's depth: uniform over the depth); NaN where a cell is negative (a
    particle absent)."""
    n = cells.shape[1]
    dims = out.shape[2]
    for i in nb.prange(cells.size):
        t = i // n
        p = i - t * n
        k = step + np.uint64(t)
        c = cells[t, p]
        if c < 0:
            for a in range(dims):
                out[t, p, a] = np.nan
            continue
        col = c % columns
        rest = c // columns
        row = rest // depth_columns
        out[t, p, 0] = (col + uniform(seed, STREAM_X, p, k)) * cell_width
        out[t, p, 1] = (row + uniform(seed, STREAM_Y, p, k)) * cell_height
        if dims == 3:
            out[t, p, 2] = ((rest - row * depth_columns + uniform(seed, STREAM_DEPTH, p, k))
                            * cell_depth)


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
        The riser W x H (m); None (the default, both): the size of the trajectory file the
        grid is first discretised on (:meth:`StateSpace.with_size`). Give both or neither.
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
    has_depth_columns = True

    def __init__(self, columns: int, rows: int, width: float | None = None,
                 height: float | None = None, depth_columns: int = 1,
                 depth: float | None = None):
        counts = []
        for name, value in (("columns", columns), ("rows", rows),
                            ("depth_columns", depth_columns)):
            if isinstance(value, np.ndarray) and value.ndim == 0:
                value = value.item()                    # np.array(6)
            if isinstance(value, (bool, np.bool_)) or not isinstance(
                    value, (int, np.integer, float, np.floating)) or not np.isfinite(
                    value) or value != int(value):
                raise InputError(f"cell grid {name} {value!r}: a whole number of cells (e.g. "
                                 "CellGrid(6, 38, width, height))")
            counts.append(int(value))
        columns, rows, depth_columns = counts
        if int(columns) < 1 or int(rows) < 1 or int(depth_columns) < 1:
            grid = f"{columns}x{depth_columns}x{rows}" if depth is not None else f"{columns}x{rows}"
            raise InputError(f"a cell grid needs at least 1x1 cells, got {grid}")
        if int(depth_columns) > 1 and depth is None:
            raise InputError(f"{depth_columns} depth columns need the riser's depth")
        if (width is None) != (height is None):
            raise InputError("give the riser's width and height, or neither (the size of the "
                             "file the grid is used on)")
        from cfbmarkov.limits import check_finite

        width = None if width is None else check_finite(width, "cell grid width", "m")
        height = None if height is None else check_finite(height, "cell grid height", "m")
        depth = None if depth is None else check_finite(depth, "cell grid depth", "m")
        if width is not None and not (width > 0 and height > 0) or (
                depth is not None and not depth > 0):
            size = (f"{width:g} x {height:g}" if width is not None else "?") + (
                "" if depth is None else f" x {depth:g}")
            raise InputError(f"domain {size} m must have positive size")
        self.columns, self.rows = int(columns), int(rows)
        self.width = None if width is None else float(width)
        self.height = None if height is None else float(height)
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

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None, *,
                   memo=None):
        """The cell of each position (see :meth:`StateSpace.discretize`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, D) or (N, D)
            Positions (m), D = 2 or 3; a 2D grid projects 3D positions on (across,
            vertical), a 3D grid needs D = 3.
        velocities, lag_frames, frame_interval
            Ignored (the cells need neither motion nor history).
        memo : FrameQuantities, optional
            Ignored (the grid computes its cells, with depth columns, itself).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If a 3D grid is given 2D positions, or the grid has no size.
        """
        self._require_size()
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
        size = (f", width={self.width:g}, height={self.height:g}" if self.sized else "")
        if self.is_3d:
            return (f"CellGrid({self.columns}, {self.rows}{size}, "
                    f"depth_columns={self.depth_columns}, depth={self.depth:g})")
        return f"CellGrid({self.columns}, {self.rows}{size})"


def place_in_cells(cells: np.ndarray, space: StateSpace, seed: int, step: int,
                   depth: float | None = None) -> np.ndarray:
    """Positions drawn uniformly inside the given cells (``docs/definitions.md``, Monte Carlo).

    The draw depends only on (seed, particle index, step), so it is reproducible: a block of
    T steps gives the positions T calls one step each would. A 3D grid gives 3D positions
    inside its cells; a 2D grid gives 2D positions, or with ``depth`` 3D positions whose
    depth is drawn uniformly over 0 .. ``depth`` (a 2D cell spans the whole depth). The
    across and vertical coordinates are the same draws in all cases.

    Parameters
    ----------
    cells : array_like of int, shape (N,) or (T, N)
        The cell (row*m + col, or (row*d + k)*m + col with depth columns) of each particle,
        at one step or at T consecutive steps; negative for a particle absent (its position
        NaN).
    space : StateSpace
        Gives the grid and the riser's size.
    seed : int
        Seed of the counter-based generator (:func:`cfbmarkov._random.uniform`).
    step : int
        The step (lag) of the run, so that every step draws afresh; with T steps of cells,
        the first one's.
    depth : float, optional
        The riser's depth (m), for 3D positions from a 2D grid; ignored by a 3D grid (it
        has its own depth).

    Returns
    -------
    ndarray of float64, shape (N, 2) or (N, 3), or (T, N, 2) or (T, N, 3)
        Positions (across, vertical[, depth]) in m.

    Raises
    ------
    InputError
        If a cell lies beyond the grid (a state given for a cell, say).
    """
    cells = np.asarray(cells, dtype=np.int64)
    if cells.size and cells.max() >= space.n_cells:
        raise InputError(f"place_in_cells: cell {int(cells.max())} outside the grid's "
                         f"{space.n_cells} cells (0 .. {space.n_cells - 1}; negative: absent)")
    one_step = cells.ndim == 1
    cells = np.ascontiguousarray(cells.reshape(1, -1) if one_step else cells)
    three = space.is_3d or depth is not None
    d = space.depth_columns if space.is_3d else 1
    out = np.empty((*cells.shape, 3 if three else 2))
    cell_depth = ((space.depth if space.is_3d else float(depth)) / d) if three else 0.0
    _place_in_cells(cells, space.columns, d, space.width / space.columns,
                    space.height / space.rows, cell_depth, np.uint64(seed), np.uint64(step),
                    out)
    return out[0] if one_step else out
