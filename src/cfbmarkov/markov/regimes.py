"""The regime (cluster) model: states that carry a global flow regime shared by all particles.

The chains on cells, with or without memory, are stationary: every lag, every particle moves
by the same matrix whatever the rest of the riser does. A riser is not like that: its solids
inventory surges and collapses, clusters form and fall, and while the whole bed falls every
particle is more likely to fall. The paper names the cure ("an extra cluster model", Sect. 4);
this module is it.

Every frame gets a *regime*: the frame's value of a global feature of the solids, binned into
R regimes. The features (``docs/method.md``, The regime model):

- ``flux``: the solids' mean vertical velocity over the previous lag, (1/N) sum_p dy_p / tau
  (m/s), proportional to the net vertical solids flux through the riser (dy the minimal-image
  displacement through a periodic boundary, over the particles present at both frames);
- ``height``: the height of the solids' centre of mass in the frame (m).

The bin edges are fitted on the fitting window (:meth:`RegimeCells.fit_to_frames`): a
one-dimensional k-means (Lloyd's algorithm) on the frames' feature values, with edges midway
between neighbouring centres, so two regimes of very different frequency are still split where
their values separate. A particle's state is (cell, regime[, direction]),

    state = cell * K + regime * D + direction,   K = R * D,   D = 2 with direction, else 1,

the layout of the other product spaces (``cell_of_state = state // K``), so everything that
works on cells works unchanged, and the pooled maximum-likelihood chain on these states is a
Markov chain on the product space whose exact RTD (:func:`~cfbmarkov.markov.first_passage.exact_rtd`) is
the single-particle RTD over the regimes' own randomness.

The Monte Carlo differs (:mod:`cfbmarkov.markov.regime_chain`): all particles share one
regime path. The regime chain G (R x R) is
read off the counts (each frame's particles move from its regime to the next frame's), a path
rho_0, rho_1, ... is drawn from it once per run, and at step k every particle moves by the
chain *conditioned* on the regime moving from rho_(k-1) to rho_k:

    M_(r r')[(c, r, d), (c', r', d')] = P[(c, r, d), (c', r', d')]
                                        / sum_(c'', d'') P[(c, r, d), (c'', r', d'')],

so that the single-particle marginal is the product chain again, while surges and collapses
move the whole cloud together (they appear in the snapshots and in the fluctuations of the
mixing curve). Where a state never saw the regime move to r' its row moves as all its
observed transitions, with the regime set to r'.

References
----------
Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in Circulating
Fluidized Bed Risers", Processes 13(3), 614 (2025), doi:10.3390/pr13030614 (Sect. 4: the model
cannot reproduce clusters; an extra cluster model should add their instantaneous effect).

S. P. Lloyd, "Least squares quantization in PCM", IEEE Trans. Inf. Theory 28(2), 129-137
(1982) (k-means).
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.markov.frame_quantities import PARTICLE_BLOCK, FrameQuantities
from cfbmarkov.markov.memory_states import _CellProductSpace

#: the global features a regime can be read from
FEATURES = ("flux", "height")


@nb.njit(cache=True)
def _frame_means(values, first, out):
    """out[t] = mean over the finite values[t, :] for t >= first, NaN where none (or t <
    first)."""
    n_frames, n = values.shape
    for t in range(n_frames):
        total = 0.0
        count = 0
        if t >= first:
            for p in range(n):
                v = values[t, p]
                if v == v:
                    total += v
                    count += 1
        out[t] = total / count if count > 0 else np.nan


@nb.njit(cache=True, parallel=True)
def _regime_states(cells, vertical, regime, per_cell, with_direction, out):
    """out[t, p] = cells[t, p] * K + regime[t] * D + (1 if falling else 0 with direction)."""
    n_frames, n = cells.shape
    d = 2 if with_direction else 1
    blocks = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK
    for k in nb.prange(n_frames * blocks):
        t = k // blocks
        first = (k - t * blocks) * PARTICLE_BLOCK
        for p in range(first, min(n, first + PARTICLE_BLOCK)):
            s = cells[t, p] * per_cell + regime[t] * d
            if with_direction and vertical[t, p] < 0.0:
                s += 1
            out[t, p] = s


def regime_edges(features: np.ndarray, regimes: int) -> tuple[float, ...]:
    """Bin edges that split frames' feature values into ``regimes`` groups (1D k-means).

    Parameters
    ----------
    features : ndarray of float64, shape (T,)
        The feature value of each frame; NaN values are ignored.
    regimes : int
        Number of regimes R (>= 2).

    Returns
    -------
    tuple of float
        The R - 1 interior edges, strictly increasing: midway between neighbouring
        k-means centres.

    Raises
    ------
    InputError
        If fewer than 2 R frames have a value, or the values do not separate into R
        distinct groups (e.g. a constant feature).

    References
    ----------
    S. P. Lloyd, "Least squares quantization in PCM", IEEE Trans. Inf. Theory 28(2),
    129-137 (1982).
    """
    values = np.asarray(features, dtype=np.float64)
    values = np.sort(values[np.isfinite(values)])
    regimes = int(regimes)
    if values.size < 2 * regimes:
        raise InputError(f"regimes: only {values.size} frames with a feature value, too few "
                         f"to split into {regimes} regimes")
    spread = float(values[-1] - values[0])
    if not spread > 0:
        raise InputError("regimes: the feature is the same in every frame of the fitting "
                         "window (no regimes to tell apart); use a state space without "
                         "regimes")
    centres = np.quantile(values, (np.arange(regimes) + 0.5) / regimes)
    for _ in range(200):       # Lloyd's iterations on sorted 1D values (R groups, a few ms)
        edges = 0.5 * (centres[1:] + centres[:-1])
        cut = np.searchsorted(values, edges, side="left")
        bounds = np.concatenate([[0], cut, [values.size]])
        new = np.array([values[a:b].mean() if b > a else centres[k]
                        for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:]))])
        if np.all(np.abs(new - centres) <= 1e-12 * spread):
            break
        centres = new
    edges = 0.5 * (centres[1:] + centres[:-1])
    if np.any(np.diff(centres) <= 1e-9 * spread):
        raise InputError(f"regimes: the feature does not separate into {regimes} distinct "
                         "groups in the fitting window; use fewer regimes")
    return tuple(float(e) for e in edges)


class RegimeCells(_CellProductSpace):
    """Cells x regimes (x direction): states carrying the riser's global flow regime.

    ``state = cell * K + regime * D + direction`` with K = R D, D = 2 when ``direction``
    (falling = 1, from the sign of the displacement over the previous lag, as
    :class:`~cfbmarkov.markov.memory_states.DirectionCells`) else 1. The regime of a frame is
    the bin of its feature among ``edges`` (regime r holds edges[r-1] <= f < edges[r]); a
    frame without a value (no particle present in it and the previous one) is regime 0. The
    space needs one lag of history (``memory_lags = 1``) for the flux and the direction.

    Made without ``edges`` (e.g. by name, ``cells-regime``), the space is *unfitted*: the
    estimators fit the edges on the fitting window's frames (:meth:`fit_to_frames`) and the
    model keeps the fitted space, so that predictions and later windows use the same edges.
    See the module docstring and ``docs/method.md`` (The regime model).

    Parameters
    ----------
    columns, rows : int
        The cell grid m x n.
    width, height : float, optional
        The riser W x H (m); None (both, the default): the size of the file the space
        is used on.
    regimes : int, optional
        Number of regimes R (2 to 8).
    edges : sequence of float, optional
        The R - 1 interior edges of the feature (m/s for ``flux``, m for ``height``),
        finite and strictly increasing; None: unfitted.
    feature : {"flux", "height"}, optional
        The global feature the regime is read from.

    Raises
    ------
    InputError
        For a bad grid, a number of regimes outside 2-8, edges that are not R - 1 finite
        strictly increasing numbers, or an unknown feature.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Sect. 4, the cluster model the paper calls for).
    """

    kind = "cells-regime"
    memory_lags = 1
    #: whether the states carry the direction (:class:`DirectionRegimeCells`)
    direction = False

    def __init__(self, columns: int, rows: int, width: float | None = None,
                 height: float | None = None,
                 regimes: int = 2, edges=None, feature: str = "flux"):
        super().__init__(columns, rows, width, height)
        if not (isinstance(regimes, (int, np.integer)) and 2 <= int(regimes) <= 8):
            raise InputError(f"{self.kind}: {regimes!r} regimes; choose 2 to 8")
        if feature not in FEATURES:
            raise InputError(f"{self.kind}: unknown feature {feature!r} (choose from "
                             f"{', '.join(FEATURES)})")
        self.regimes = int(regimes)
        self.feature = str(feature)
        if edges is not None:
            try:
                edges = np.asarray(edges, dtype=np.float64).ravel()
            except (TypeError, ValueError):
                raise InputError(f"{self.kind}: regime edges {edges!r} are not numbers") from None
            if (edges.size != self.regimes - 1 or not np.all(np.isfinite(edges))
                    or np.any(np.diff(edges) <= 0)):
                raise InputError(f"{self.kind}: {self.regimes} regimes need {self.regimes - 1} "
                                 f"finite, strictly increasing edges, got {edges.tolist()}")
            edges = tuple(float(e) for e in edges)
        self.edges = edges

    @property
    def per_cell(self) -> int:
        """Sub-states per cell, K = R (x 2 with direction)."""
        return self.regimes * (2 if self.direction else 1)

    @property
    def fitted(self) -> bool:
        """Whether the regime edges are known (see :meth:`fit_to_frames`)."""
        return self.edges is not None

    def frame_features(self, positions: np.ndarray, lag_frames: int,
                       frame_interval: float | None, *,
                       memo: FrameQuantities | None = None) -> np.ndarray:
        """The global feature of every frame.

        Parameters
        ----------
        positions : ndarray, shape (T, N, D)
            Positions (m), NaN where a particle is absent; the first ``lag_frames`` frames
            are history (no flux there).
        lag_frames : int
            The lag in frames (>= 1).
        frame_interval : float or None
            Time between frames (s), needed for ``flux``.
        memo : FrameQuantities, optional
            What is derived from ``positions``, shared (:mod:`~cfbmarkov.markov.frame_quantities`).

        Returns
        -------
        ndarray of float64, shape (T,)
            m/s (``flux``) or m (``height``); NaN where no particle is present (and, for
            the flux, in the first ``lag_frames`` frames).

        Raises
        ------
        InputError
            For the flux without a positive frame interval, or ``lag_frames < 1``.
        """
        positions = np.asarray(positions, dtype=np.float64)
        if positions.ndim == 2:
            positions = positions[None]
        out = np.empty(positions.shape[0])
        if self.feature == "height":
            _frame_means(np.ascontiguousarray(positions[..., 1]), 0, out)
            return out
        if frame_interval is None or not (np.isfinite(frame_interval) and frame_interval > 0):
            raise InputError(f"{self.kind}: the solids flux needs the frame interval (s), got "
                             f"{frame_interval!r}")
        lag_frames = int(lag_frames)
        vertical = self._vertical(positions, None, lag_frames, "displacement", memo)
        _frame_means(vertical, lag_frames, out)
        return out / (lag_frames * float(frame_interval))

    def fit_to_frames(self, positions: np.ndarray, lag_frames: int,
                      frame_interval: float | None, *,
                      memo: FrameQuantities | None = None) -> "RegimeCells":
        """This space with its regime edges fitted on frames (itself when already fitted).

        Parameters
        ----------
        positions : ndarray, shape (T, N, D)
            The fitting window's positions (m) with ``lag_frames`` frames of history first.
        lag_frames : int
            The lag in frames.
        frame_interval : float or None
            Time between frames (s).
        memo : FrameQuantities, optional
            As in :meth:`frame_features`.

        Returns
        -------
        RegimeCells

        Raises
        ------
        InputError
            As :func:`regime_edges` (too few frames, no distinct regimes).
        """
        if self.fitted:
            return self
        features = self.frame_features(positions, lag_frames, frame_interval, memo=memo)
        return type(self)(self.columns, self.rows, self.width, self.height, self.regimes,
                          regime_edges(features, self.regimes), self.feature)

    def accepts(self, other) -> bool:
        """Whether ``other`` is this space, or this unfitted space with edges fitted (see
        :meth:`StateSpace.accepts <cfbmarkov.markov.states.StateSpace.accepts>`)."""
        if self == other:
            return True
        mine, theirs = self.to_attrs(), dict(getattr(other, "to_attrs", dict)())
        return not self.fitted and theirs.pop("edges", None) is not None and (
            {k: v for k, v in mine.items() if k != "edges"} == theirs)

    def frame_regimes(self, positions: np.ndarray, lag_frames: int,
                      frame_interval: float | None, *,
                      memo: FrameQuantities | None = None) -> np.ndarray:
        """The regime (0 .. R-1) of every frame.

        Parameters
        ----------
        positions, lag_frames, frame_interval, memo
            As :meth:`frame_features`.

        Returns
        -------
        ndarray of int32, shape (T,)

        Raises
        ------
        InputError
            If the space is not fitted (as :meth:`frame_features` otherwise).
        """
        if not self.fitted:
            raise InputError(f"{self.kind}: the regime edges are not fitted yet (fit a model, "
                             "which fits them on its window)")
        features = self.frame_features(positions, lag_frames, frame_interval, memo=memo)
        regime = np.searchsorted(np.asarray(self.edges), features, side="right")
        regime[~np.isfinite(features)] = 0
        return regime.astype(np.int32)

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None, *,
                   memo=None):
        """States of frames (see :meth:`StateSpace.discretize
        <cfbmarkov.markov.states.StateSpace.discretize>`).

        Parameters
        ----------
        positions : ndarray, shape (T, N, D) or (N, D)
            Positions (m); the first ``lag_frames`` frames are history.
        velocities : ignored
            The regime and direction come from displacements.
        lag_frames : int
            The lag in frames (>= 1).
        frame_interval : float, optional
            Time between frames (s), needed for the flux.
        memo : FrameQuantities, optional
            As in :meth:`frame_features`.

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If the space is not fitted, the frame interval is missing (flux) or
            ``lag_frames < 1``.
        """
        single = np.ndim(positions) == 2
        frames = np.asarray(positions)[None] if single else np.asarray(positions)
        cells = self._cells(frames, memo)
        regime = self.frame_regimes(frames, lag_frames, frame_interval, memo=memo)
        vertical = (self._vertical(frames, None, lag_frames, "displacement", memo)
                    if self.direction else np.zeros((1, 1)))
        out = np.empty_like(cells)
        _regime_states(cells, vertical, regime, self.per_cell, self.direction, out)
        return out[0] if single else out

    def regime_of(self, states: np.ndarray) -> np.ndarray:
        """The regime (0 .. R-1) of states.

        Parameters
        ----------
        states : array_like of int
            States of this space.

        Returns
        -------
        ndarray of int
            Same shape as ``states``.
        """
        return self.sub_state(states) // (2 if self.direction else 1)

    def to_attrs(self) -> dict[str, Any]:
        """The grid, ``regimes``, ``edges`` and ``feature`` (see
        :meth:`StateSpace.to_attrs <cfbmarkov.markov.states.StateSpace.to_attrs>`)."""
        return {**self._base_attrs(), "regimes": self.regimes,
                "edges": None if self.edges is None else list(self.edges),
                "feature": self.feature}

    def describe(self) -> str:
        """A one-line description, with the regimes' feature and edges."""
        unit = "m/s" if self.feature == "flux" else "m"
        where = ("edges not fitted" if self.edges is None else
                 f"at {', '.join(f'{e:.4g}' for e in self.edges)} {unit}")
        what = "solids flux" if self.feature == "flux" else "solids centre-of-mass height"
        return (f"{self.kind} {self.columns}x{self.rows}x{self.per_cell} ({self.n_states} "
                f"states: {self.regimes} regimes of the {what} {where}"
                f"{', with direction' if self.direction else ''})")

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.columns}, {self.rows}, width={self.width}, "
                f"height={self.height}, regimes={self.regimes}, edges={self.edges}, "
                f"feature={self.feature!r})")


class DirectionRegimeCells(RegimeCells):
    """Cells x regimes x {rising, falling}: :class:`RegimeCells` whose states also carry the
    particle's direction over the previous lag (falling = 1), K = 2 R sub-states per cell.

    Parameters and errors as :class:`RegimeCells`.
    """

    kind = "cells-direction-regime"
    direction = True


__all__ = ["FEATURES", "DirectionRegimeCells", "RegimeCells", "regime_edges"]
