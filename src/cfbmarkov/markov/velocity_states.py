"""State spaces of cells x bins of the vertical velocity (optionally with sub-rows): the
memory of how fast a particle moves, on the layout of the other product spaces
(:mod:`cfbmarkov.markov.memory_states`).

They register under their ``kind`` with :class:`~cfbmarkov.markov.states.StateSpace`, so
saved models rebuild them by name (``docs/method.md``, Velocity bins).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.markov.frame_quantities import FrameQuantities
from cfbmarkov.markov.memory_states import _CellProductSpace, _check_source


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
def _binned_sub_row_states(cells, y, vertical, scale, edges, columns, row_height, sub_rows,
                           out):
    """out = (cell*k + sub_row)*(B+1) + bin: as :func:`_binned_states`, with each row split
    into k = ``sub_rows`` equal sub-rows, sub_row = floor(k * (y / row height - row)) with
    the row of the cell, clipped to 0 .. k-1 (a position the cell index put in the row above
    by its edge tolerance is in that row's lowest sub-row)."""
    flat_c = cells.reshape(-1)
    flat_y = y.reshape(-1)
    flat_v = vertical.reshape(-1)
    flat_out = out.reshape(-1)
    n_bins = edges.size + 1
    for k in nb.prange(flat_out.size):
        v = flat_v[k] * scale
        b = 0
        while b < edges.size and edges[b] <= v:
            b += 1
        c = flat_c[k]
        sub = 0
        offset = flat_y[k] / row_height - c // columns
        if offset == offset:                      # not NaN (an absent particle: sub-row 0)
            sub = min(max(int(np.floor(sub_rows * offset)), 0), sub_rows - 1)
        flat_out[k] = (c * sub_rows + sub) * n_bins + b


#: velocity bins K of ``cells-velocity`` by name (edges at the fitting window's quantiles)
DEFAULT_VELOCITY_BINS = 8
#: the most velocity bins of a fitted space
MAX_VELOCITY_BINS = 32
#: the most velocities the quantile edges are taken from (every k-th of the window's)
QUANTILE_SAMPLES = 500_000
#: the most sub-rows per cell row of a fitted ``cells-velocity-fine`` space
MAX_SUB_ROWS = 8


class VelocityCells(_CellProductSpace):
    """Cells x bins of the vertical velocity, optionally with sub-rows:
    state = (cell*k + sub_row)*(B+1) + bin (k = 1: cell*(B+1) + bin).

    ``edges`` are the B interior bin edges (m/s, strictly increasing); bin b holds
    edges[b-1] <= v < edges[b] (bin 0: v < edges[0], bin B: v >= edges[-1]).
    ``source="displacement"`` (default): v = (wrapped vertical displacement over the
    previous lag) / lag, with the lag = ``lag_frames * frame_interval`` that
    :meth:`discretize` is given (the lag of the model being fitted, so the two cannot
    disagree); ``memory_lags = 1``. ``source="velocity"``: v = v_y of the frame
    (``needs_velocity``). The first frames (no previous frame) get v = 0.

    Made with ``edges=None`` (so by name, ``cells-velocity``), the space is *unfitted*: the
    estimators fit the edges on the fitting window's frames (:meth:`fit_to_frames`) as the
    quantiles k/K (k = 1 .. K - 1) of the window's vertical velocities, so that each of the
    K = ``bins`` bins holds about as many particle-frames whatever the flow (equal-frequency
    bins); the model keeps the fitted space. Fixed edges cannot fit every flow: at the
    paper's 4 m/s the solids fall at up to 4 m/s, and the edges -1, 0, 1, 3 m/s put all
    that falling motion into two bins, so the chain forgot how fast a particle was falling
    (``docs/method.md``, Velocity bins). ``VelocityCells(m, n)`` with no ``edges`` takes
    those fixed edges (the model files of that space read as they were written); the
    command line's ``cells-velocity`` is ``VelocityCells.with_defaults(m, n)`` (or
    ``edges=None``, or ``state_space_from_name("cells-velocity", m, n)``).

    With ``sub_rows`` k > 1 (:class:`FineVelocityCells`, ``cells-velocity-fine`` by name,
    fits k) each cell row is split into
    k equal sub-rows, sub_row = floor(k * (y / row height - row)), so the chain knows where
    in its cell a particle is. A chain on whole cells forgets it: a particle that moves a
    fraction f < 1 of a row per lag leaves its cell after a geometric number of lags (mean
    1/f), so a transit through n rows, steady in the flow, takes a random n/f lags in the
    chain: the dispersion of n tanks in series, which spreads the RTD (at the quick scale's
    lag of 0.002 s, f = 0.3-0.4 and SD(RT) twice the CFD-DEM's). Sub-rows no taller than
    the distance most particles move in a lag remove that artificial dispersion. Made with
    ``sub_rows=None`` the space fits k on the fitting window (:meth:`fit_to_frames`):
    k = ceil(row height / median |dy|) over the window's displacements in one lag, at most
    ``MAX_SUB_ROWS``, and 1 where the median particle moves a row or more per lag. The
    cells (``cell_of_state``) stay the grid's, so maps, placement and mixing are on the
    grid's cells; the Monte Carlo places a particle anywhere in its cell.

    Model files written before the lag lived in one place stored it here as ``lag``; it is
    accepted on loading and ignored (the model's own lag is the one used).

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n.
    width, height : float, optional
        The riser W x H (m); None (both, the default): the size of the file the space
        is used on.
    edges : sequence of float or None, optional
        The B interior bin edges of v_y (m/s), finite and strictly increasing; None:
        unfitted, the edges are the quantiles of the fitting window's velocities.
    source : {"displacement", "velocity"}, optional
        Where v_y comes from.
    lag : float, optional
        Accepted from old model files and ignored.
    bins : int, optional
        Number of bins K of an unfitted space (2 to 32; default ``DEFAULT_VELOCITY_BINS``);
        ignored where ``edges`` are given (K = B + 1).
    sub_rows : int or None, optional
        Sub-rows k per cell row (1 to ``MAX_SUB_ROWS``; default 1: whole cells); None: fitted
        on the fitting window (see above).

    Raises
    ------
    InputError
        For a bad grid, edges that are not numbers or not finite and strictly increasing,
        a number of bins outside 2-32, sub-rows outside 1-8, or an unknown ``source``.

    References
    ----------
    Equal-frequency (quantile) bins: J. Dougherty, R. Kohavi and M. Sahami, "Supervised and
    unsupervised discretization of continuous features", Proc. ICML 1995, 194-202.

    The dispersion of n tanks in series (variance of the residence time 1/n of the mean
    squared for n stirred tanks): O. Levenspiel, Chemical Reaction Engineering, 3rd ed.,
    Wiley (1999), ch. 14.
    """

    kind = "cells-velocity"
    #: sub-rows of a space made without ``sub_rows`` (left out of :meth:`to_attrs`)
    DEFAULT_SUB_ROWS: int | None = 1

    def __init__(self, columns: int, rows: int, width: float | None = None,
                 height: float | None = None,
                 edges=(-1.0, 0.0, 1.0, 3.0), source: str = "displacement",
                 lag: float | None = None, bins: int | None = None,
                 sub_rows: int | None = 1):
        super().__init__(columns, rows, width, height)
        del lag     # stored by older model files; the lag now comes with the frames
        if sub_rows is not None and not (isinstance(sub_rows, (int, np.integer))
                                         and 1 <= int(sub_rows) <= MAX_SUB_ROWS):
            raise InputError(f"{self.kind}: {sub_rows!r} sub-rows per row; choose 1 to "
                             f"{MAX_SUB_ROWS}")
        self.sub_rows = None if sub_rows is None else int(sub_rows)
        self.source = _check_source(self.kind, source)
        self.memory_lags = 1 if self.source == "displacement" else 0
        self.needs_velocity = self.source == "velocity"
        if edges is None:
            bins = DEFAULT_VELOCITY_BINS if bins is None else bins
            if not (isinstance(bins, (int, np.integer)) and 2 <= int(bins) <= MAX_VELOCITY_BINS):
                raise InputError(f"{self.kind}: {bins!r} velocity bins; choose 2 to "
                                 f"{MAX_VELOCITY_BINS}")
            self.edges, self.bins = None, int(bins)
            return
        try:
            edges = np.asarray(edges, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise InputError(f"{self.kind}: velocity bin edges {edges!r} are not numbers") from None
        if edges.size < 1 or not np.all(np.isfinite(edges)) or np.any(np.diff(edges) <= 0):
            raise InputError(f"{self.kind}: velocity bin edges must be one or more finite, "
                             f"strictly increasing values (m/s), got {edges.tolist()}")
        self.edges = tuple(float(e) for e in edges)
        self.bins = len(self.edges) + 1

    @classmethod
    def with_defaults(cls, columns: int, rows: int, width: float | None = None,
                      height: float | None = None) -> "VelocityCells":
        """This space unfitted (``edges=None``: the bin edges are fitted at the fitting
        window's quantiles; see :meth:`StateSpace.with_defaults
        <cfbmarkov.markov.states.StateSpace.with_defaults>`).

        Parameters
        ----------
        columns, rows : int
            The cell grid m x n.
        width, height : float, optional
            The riser W x H (m); None (both, the default): the size of the file the space
            is used on.

        Returns
        -------
        VelocityCells

        Raises
        ------
        InputError
            For a bad grid.
        """
        return cls(columns, rows, width, height, edges=None)

    @property
    def per_cell(self) -> int:
        """Sub-states per cell, k (B + 1): sub-rows times velocity bins (k counts as 1
        until it is fitted)."""
        return (self.sub_rows or 1) * self.bins

    @property
    def fitted(self) -> bool:
        """Whether the bin edges and the sub-rows are known (see :meth:`fit_to_frames`)."""
        return self.edges is not None and self.sub_rows is not None

    def fit_to_frames(self, positions: np.ndarray, lag_frames: int,
                      frame_interval: float | None, *,
                      memo: FrameQuantities | None = None) -> "VelocityCells":
        """This space with its bin edges and sub-rows fitted on frames (itself when already
        fitted). The edges are the quantiles k/K, k = 1 .. K - 1, of the vertical velocities
        of the particles present (of every k-th of them where there are more than
        ``QUANTILE_SAMPLES``; rounded to 1e-4 m/s; equal quantiles, as in a flow at rest,
        merge, so that fewer bins remain); the sub-rows, where asked for, are
        ceil(row height / median |dy|) over the same displacements (see the class).

        Parameters
        ----------
        positions : ndarray, shape (T, N, D)
            The fitting window's positions (m) with ``lag_frames`` frames of history first
            (``source="displacement"``), NaN where a particle is absent.
        lag_frames : int
            The lag in frames.
        frame_interval : float or None
            Time between frames (s).
        memo : FrameQuantities, optional
            The memo of what is derived from ``positions`` (see
            :meth:`StateSpace.discretize <cfbmarkov.markov.states.StateSpace.discretize>`).

        Returns
        -------
        VelocityCells

        Raises
        ------
        InputError
            If the frames hold no velocity (fewer frames than the lag plus one, or no
            particle present in two frames one lag apart), or the frame interval is missing.
        """
        if self.fitted:
            return self
        if self.source == "velocity":
            raise InputError(f"{self.kind}: bin edges and sub-rows from the velocities of "
                             "frames are fitted for source='displacement' only; give them")
        if frame_interval is None or not (np.isfinite(frame_interval) and frame_interval > 0):
            raise InputError(f"{self.kind}: velocities from displacements need the frame "
                             f"interval (s), got {frame_interval!r}")
        positions = np.asarray(positions, dtype=np.float64)
        lag_frames = int(lag_frames)
        if positions.ndim != 3 or positions.shape[0] <= lag_frames:
            raise InputError(f"{self.kind}: fitting the velocity bins needs at least "
                             f"{lag_frames + 1} frames")
        vertical = self._vertical(positions, None, lag_frames, "displacement",
                                  memo)[lag_frames:]
        moves = vertical[np.isfinite(vertical)]
        if moves.size == 0:
            raise InputError(f"{self.kind}: no particle is present one lag apart in the "
                             "fitting window, so no velocity bins can be fitted")
        # every k-th value, at most QUANTILE_SAMPLES of them: quantiles within about 0.1 % in
        # probability, at a tenth of the cost of the window's 5.4 million at paper scale
        sample = moves[::max(1, -(-moves.size // QUANTILE_SAMPLES))]
        edges = self.edges
        if edges is None:
            quantiles = np.quantile(sample / (lag_frames * float(frame_interval)),
                                    np.arange(1, self.bins) / self.bins)
            edges = tuple(float(e) for e in np.unique(np.round(quantiles, 4)))
        sub_rows = self.sub_rows
        if sub_rows is None:
            # sub-rows no taller than the median move in a lag (see the class docstring)
            median_move = float(np.median(np.abs(sample))) * self.rows / self.height
            sub_rows = (1 if not median_move > 0.0 or median_move >= 1.0
                        else min(MAX_SUB_ROWS, math.ceil(1.0 / median_move)))
        return type(self)(self.columns, self.rows, self.width, self.height, edges,
                          self.source, sub_rows=sub_rows)

    def accepts(self, other) -> bool:
        """Whether ``other`` is this space, or this unfitted space with edges fitted (see
        :meth:`StateSpace.accepts <cfbmarkov.markov.states.StateSpace.accepts>`)."""
        if self == other:
            return True
        if self.fitted or type(other) is not type(self) or not other.fitted:
            return False
        if self.edges is not None and self.edges != other.edges:
            return False
        if self.sub_rows is not None and self.sub_rows != other.sub_rows:
            return False
        mine, theirs = self.to_attrs(), other.to_attrs()
        return all(mine[k] == theirs.get(k) for k in mine
                   if k not in ("edges", "bins", "sub_rows"))

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
            Time between frames (s); required with ``source="displacement"`` (v = dy / lag).
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
            positions' shape, or (``source="displacement"``) ``lag_frames < 1`` or the
            frame interval is missing or not positive.
        """
        if not self.fitted:
            raise InputError(f"{self.kind}: the velocity bin edges or sub-rows are not fitted "
                             "yet (fit a model, whose state space has them, or give them)")
        cells = self._cells(positions, memo)
        vertical = self._vertical(positions, velocities, lag_frames, self.source, memo)
        scale = 1.0
        if self.source == "displacement":
            if frame_interval is None or not (np.isfinite(frame_interval) and frame_interval > 0):
                raise InputError(f"{self.kind}: velocities from displacements need the frame "
                                 f"interval (s), got {frame_interval!r}")
            scale = 1.0 / (int(lag_frames) * float(frame_interval))
        out = np.empty_like(cells)
        edges = np.asarray(self.edges, dtype=np.float64)
        if self.sub_rows == 1:
            _binned_states(cells, vertical, scale, edges, out)
            return out
        y = np.ascontiguousarray(np.asarray(positions, dtype=np.float64)[..., 1])
        _binned_sub_row_states(cells, y, vertical, scale, edges, self.columns,
                               self.height / self.rows, self.sub_rows, out)
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
        return self.sub_state(states) % self.bins

    def sub_row(self, states: np.ndarray) -> np.ndarray:
        """The sub-row (0..k-1, 0 at the bottom of the cell) of states.

        Parameters
        ----------
        states : array_like of int
            States of this space.

        Returns
        -------
        ndarray of int
            Same shape as ``states``.
        """
        return self.sub_state(states) // self.bins

    def to_attrs(self):
        """The grid, ``edges`` and ``source`` (see :meth:`StateSpace.to_attrs`)."""
        # sub_rows where it differs from the class's default, so that files without
        # sub-rows read back as before
        rows = ({} if self.sub_rows == type(self).DEFAULT_SUB_ROWS
                else {"sub_rows": self.sub_rows})
        if self.edges is None:
            return {**self._base_attrs(), "edges": None, "source": self.source,
                    "bins": self.bins, **rows}
        return {**self._base_attrs(), "edges": list(self.edges), "source": self.source, **rows}

    def describe(self) -> str:
        """A one-line description, with the bin edges (m/s) and their source."""
        rows = ("" if self.sub_rows == 1 else ", sub-rows fitted to the moves per lag"
                if self.sub_rows is None else f", {self.sub_rows} sub-rows per row")
        if self.edges is None:
            return (f"{self.kind} {self.columns}x{self.rows}x{self.per_cell} ({self.n_states} "
                    f"states, {self.bins} v_y bins at the fitting window's quantiles, from "
                    f"{self.source}{rows})")
        return (f"{self.kind} {self.columns}x{self.rows}x{self.per_cell} ({self.n_states} "
                f"states, v_y bins at {', '.join(f'{e:g}' for e in self.edges)} m/s from "
                f"{self.source}{rows})")

    def __repr__(self) -> str:
        edges = f"edges=None, bins={self.bins}" if self.edges is None else f"edges={self.edges}"
        return (f"{type(self).__name__}({self.columns}, {self.rows}, width={self.width}, "
                f"height={self.height}, {edges}, source={self.source!r}, "
                f"sub_rows={self.sub_rows})")


class FineVelocityCells(VelocityCells):
    """``cells-velocity-fine``: :class:`VelocityCells` whose rows are split into sub-rows
    fitted to the flow (``sub_rows=None``, the default: k = ceil(row height / median |dy|)
    on the fitting window, at most ``MAX_SUB_ROWS``, 1 where the median particle moves a
    row or more per lag), so that a chain at a lag short against the time to cross a row
    does not disperse the transit (see :class:`VelocityCells`). Where the fit gives one
    sub-row the states are those of ``cells-velocity``.

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n.
    width, height : float, optional
        The riser W x H (m); None (both, the default): the size of the file the space
        is used on.
    edges : sequence of float or None, optional
        As :class:`VelocityCells`; None (default): fitted.
    source : {"displacement", "velocity"}, optional
        Where v_y comes from.
    lag : float, optional
        Accepted from old model files and ignored.
    bins : int, optional
        Number of velocity bins of unfitted edges.
    sub_rows : int or None, optional
        Sub-rows per row (1 to ``MAX_SUB_ROWS``); None (default): fitted.

    Raises
    ------
    InputError
        As :class:`VelocityCells`.
    """

    kind = "cells-velocity-fine"
    DEFAULT_SUB_ROWS = None

    def __init__(self, columns: int, rows: int, width: float | None = None,
                 height: float | None = None,
                 edges=None, source: str = "displacement", lag: float | None = None,
                 bins: int | None = None, sub_rows: int | None = None):
        super().__init__(columns, rows, width, height, edges, source, lag, bins, sub_rows)
