"""State spaces with memory: the cell of the paper's chain plus a sub-state that carries
some memory of the motion (direction, previous cell; the vertical-velocity bins are in
:mod:`cfbmarkov.markov.velocity_states`).

The paper's chain on cells forgets which way a particle was moving, so it spreads residence
times too little; these spaces keep the cell and add that memory (see ``docs/method.md``).
They register under their ``kind`` with :class:`~cfbmarkov.markov.states.StateSpace`, so
saved models rebuild them by name. ``_CellProductSpace`` is the layout they share (and the
velocity and regime spaces with them).
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.markov.frame_quantities import PARTICLE_BLOCK, FrameQuantities
from cfbmarkov.markov.states import CellGrid, StateSpace


# -- state spaces with memory --------------------------------------------------------------
#
# The paper's chain on cells forgets which way a particle was moving, so it spreads residence
# times too little (SD(RT) about -40...-50 %). The spaces below keep the cell and add a
# sub-state that carries some memory of the motion. They, and the velocity and regime
# spaces built on ``_CellProductSpace``, share one layout:
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
# Vertical displacements take the minimal image through a periodic boundary, wrapped into
# (-H/2, H/2] (a particle moves less than H/2 in one lag, docs/definitions.md, Pass direction);
# on an open riser (the memo's ``periodic`` False) they are the plain difference of heights.


@nb.njit(cache=True, parallel=True)
def _direction_states(cells, vertical, out):
    """out = 2*cell + (1 if vertical < 0 else 0): rising (including 0) or falling."""
    flat_c = cells.reshape(-1)
    flat_v = vertical.reshape(-1)
    flat_out = out.reshape(-1)
    for k in nb.prange(flat_out.size):
        flat_out[k] = 2 * flat_c[k] + (1 if flat_v[k] < 0.0 else 0)


@nb.njit(cache=True, parallel=True)
def _previous_cell_states(cells, lag_frames, columns, rows, reach, column_reach, periodic,
                          out):
    """out = cell*K + (dcol + Rc)*(2R + 1) + (drow + R), K = (2R+1)(2Rc+1), where drow and
    dcol are the row and column of the cell one lag earlier minus the current ones, drow by
    the minimal image on the rows of a ``periodic`` riser (wrapped into (-n/2, n/2]), both
    clipped to the reach; 0 where t < lag_frames."""
    n_frames, n = cells.shape
    span = 2 * reach + 1
    per_cell = span * (2 * column_reach + 1)
    blocks = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK
    for k in nb.prange(n_frames * blocks):
        t = k // blocks
        first = (k - t * blocks) * PARTICLE_BLOCK
        for p in range(first, min(n, first + PARTICLE_BLOCK)):
            c = cells[t, p]
            drow = 0
            dcol = 0
            if t >= lag_frames:
                prev = cells[t - lag_frames, p]
                row = c // columns
                prow = prev // columns
                drow = prow - row
                if periodic:
                    drow = drow % rows               # 0..n-1 (Python-style modulo in numba)
                    if 2 * drow > rows:
                        drow -= rows                 # into (-n/2, n/2]
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

    def _set_size(self, width: float, height: float) -> None:
        self._grid = self._grid.with_size(width, height)
        self.width, self.height = width, height

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

    def _cells(self, positions: np.ndarray, memo: FrameQuantities | None) -> np.ndarray:
        """The cell of every position on the grid (from ``memo`` where it holds them)."""
        self._require_size()
        return FrameQuantities.of(positions, memo).cells(self.columns, self.rows, self.width,
                                                         self.height)

    def _vertical(self, positions: np.ndarray, velocities, lag_frames: int, source: str,
                  memo: FrameQuantities | None) -> np.ndarray:
        """Vertical motion per frame [T, N]: wrapped dy over the previous lag (m) for
        ``source="displacement"`` (from ``memo`` where it holds it), v_y (m/s) for
        ``source="velocity"``."""
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
        return FrameQuantities.of(positions, memo).vertical_step(lag_frames, self.height)

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
    displacement over the previous lag (minimal image through a periodic boundary, the plain
    difference on an open riser), so the space needs one lag of history
    (``memory_lags = 1``) and no velocities; a particle that stayed at the same height
    (dy = 0, e.g. the first frames) counts as rising.
    ``source="velocity"``: the sign of v_y in the frame itself (``needs_velocity``; no
    history); v_y = 0 counts as rising.

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n.
    width, height : float, optional
        The riser W x H (m); None (both, the default): the size of the file the space
        is used on.
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

    def __init__(self, columns: int, rows: int, width: float | None = None,
                 height: float | None = None,
                 source: str = "displacement"):
        super().__init__(columns, rows, width, height)
        self.source = _check_source(self.kind, source)
        self.memory_lags = 1 if self.source == "displacement" else 0
        self.needs_velocity = self.source == "velocity"

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None, *,
                   memo=None):
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
        memo : FrameQuantities, optional
            The memo of what is derived from ``positions`` (see
            :meth:`StateSpace.discretize <cfbmarkov.markov.states.StateSpace.discretize>`).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If ``source="velocity"`` and the velocities are missing or do not match the
            positions' shape, or ``lag_frames < 1``.
        """
        cells = self._cells(positions, memo)
        vertical = self._vertical(positions, velocities, lag_frames, self.source, memo)
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
        return (f"DirectionCells({self.columns}, {self.rows}, width={self.width}, "
                f"height={self.height}, source={self.source!r})")


class SecondOrderCells(_CellProductSpace):
    """The second-order chain on cells, with the previous cell stored relative to the
    current one: state = cell*K + (dcol + Rc)*(2R + 1) + (drow + R), K = (2R+1)(2Rc+1).

    drow = (row one lag earlier) - (row now), by the minimal image on the rows of a periodic
    riser (the plain difference on an open one), clipped to [-R, R] (R = ``reach``);
    dcol = (column one lag earlier) - (column now), clipped to [-Rc, Rc]
    (Rc = ``column_reach``). ``memory_lags = 1``. The defaults (R = 3,
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
        The riser W x H (m); None (both, the default): the size of the file the space
        is used on.
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

    def __init__(self, columns: int, rows: int, width: float | None = None,
                 height: float | None = None,
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

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None, *,
                   memo=None):
        """States of frames (see :meth:`StateSpace.discretize`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, 2) or (N, 2)
            Positions (m); the first ``lag_frames`` frames are history.
        velocities, frame_interval
            Ignored.
        lag_frames : int
            The lag in frames (>= 1).
        memo : FrameQuantities, optional
            The memo of what is derived from ``positions`` (see
            :meth:`StateSpace.discretize <cfbmarkov.markov.states.StateSpace.discretize>`).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If ``lag_frames < 1``.
        """
        cells = self._cells(positions, memo)
        periodic = FrameQuantities.of(positions, memo).periodic
        lag_frames = int(lag_frames)
        if lag_frames < 1:
            raise InputError(f"lag of {lag_frames} frames: must be at least 1")
        if cells.ndim == 1:                   # a single frame: no previous frame
            cells = cells[None]
            out = np.empty_like(cells)
            _previous_cell_states(cells, lag_frames, self.columns, self.rows, self.reach,
                                  self.column_reach, periodic, out)
            return out[0]
        out = np.empty_like(cells)
        _previous_cell_states(cells, lag_frames, self.columns, self.rows, self.reach,
                              self.column_reach, periodic, out)
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
        return (f"SecondOrderCells({self.columns}, {self.rows}, width={self.width}, "
                f"height={self.height}, reach={self.reach}, "
                f"column_reach={self.column_reach})")
