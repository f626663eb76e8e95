"""What state spaces derive from one array of frames, computed once and shared.

The candidates of ``--states auto`` are discretised on the same frames of one window; most
of them need the frames' cells on the grid and the particles' vertical displacement over a
lag. A :class:`FrameQuantities` is the memo of those arrays for one array of positions: the
window's frames (:class:`~cfbmarkov.markov.discrete.WindowFrames`) own one per array they
hand out and pass it to :meth:`StateSpace.discretize
<cfbmarkov.markov.states.StateSpace.discretize>` and :meth:`StateSpace.fit_to_frames
<cfbmarkov.markov.states.StateSpace.fit_to_frames>`, so each [T, N] array is computed (and
costs its page faults) once instead of once per space. The arrays are never written.

Vertical displacements take the minimal image through a periodic boundary, wrapped into
(-H/2, H/2] (a particle moves less than H/2 in one lag, ``docs/definitions.md``, Pass
direction); on an open riser, which joins no top to its bottom, they are the plain
difference of heights.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from cfbmarkov.markov.cells import cell_index

#: particles per work item of the [T, N] kernels (a division per item, not per element)
PARTICLE_BLOCK = 1024


@nb.njit(cache=True, parallel=True)
def _wrapped_step(y, lag_frames, height, periodic, out):
    """out[t, p] = y[t, p] - y[t - lag_frames, p], wrapped into (-H/2, H/2] where
    ``periodic``; 0 where t < lag_frames (no previous frame)."""
    n_frames, n = y.shape
    half = 0.5 * height if periodic else np.inf
    blocks = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK    # frames x particle blocks
    for k in nb.prange(n_frames * blocks):
        t = k // blocks
        first = (k - t * blocks) * PARTICLE_BLOCK
        for p in range(first, min(n, first + PARTICLE_BLOCK)):
            if t < lag_frames:
                out[t, p] = 0.0
            else:
                d = y[t, p] - y[t - lag_frames, p]
                if d > half:
                    d -= height
                elif d <= -half:
                    d += height
                out[t, p] = d


class FrameQuantities:
    """The memo of what state spaces derive from one array of positions.

    Each quantity is computed on first request and kept for the memo's lifetime; the
    arrays returned are shared, never to be written.

    Parameters
    ----------
    positions : ndarray of float64, shape (T, N, D) or (N, D)
        The frames' positions (m), D = 2 or 3; the memo holds this very object.
    periodic : bool, optional
        Whether the riser's top joins its bottom (a periodic riser, the default), so that
        vertical displacements take the minimal image; False for an open riser.

    Attributes
    ----------
    positions : ndarray
        The positions the quantities are derived from.
    periodic : bool
        As given.
    """

    def __init__(self, positions: np.ndarray, periodic: bool = True):
        self.positions = positions
        self.periodic = bool(periodic)
        self._arrays: dict[tuple, np.ndarray] = {}

    @classmethod
    def of(cls, positions: np.ndarray, memo: FrameQuantities | None) -> FrameQuantities:
        """``memo`` where it was made for ``positions`` (this very object), else a new memo
        of them (a memo of other positions, even a view or a copy, is not used) on the
        boundary of ``memo`` (periodic where None).

        Parameters
        ----------
        positions : ndarray, shape (T, N, D) or (N, D)
            Positions (m).
        memo : FrameQuantities or None
            A memo that may hold the quantities of ``positions``.

        Returns
        -------
        FrameQuantities
        """
        if memo is not None and memo.positions is positions:
            return memo
        return cls(positions, periodic=True if memo is None else memo.periodic)

    @property
    def derived(self) -> tuple[tuple, ...]:
        """The quantities computed so far: ``("cells", columns, rows, width, height)`` and
        ``("displacement", lag_frames, height)`` keys."""
        return tuple(self._arrays)

    def cells(self, columns: int, rows: int, width: float, height: float) -> np.ndarray:
        """The cell of every position on a 2D grid (:func:`~cfbmarkov.markov.cells.cell_index`;
        3D positions are projected on (across, vertical)).

        Parameters
        ----------
        columns, rows : int
            The cell grid m x n.
        width, height : float
            The riser W x H (m).

        Returns
        -------
        ndarray of int32, shape (T, N) or (N,)

        Raises
        ------
        InputError
            If the positions are neither 2D nor 3D.
        """
        key = ("cells", columns, rows, width, height)
        if key not in self._arrays:
            self._arrays[key] = cell_index(self.positions, width, height, columns, rows)
        return self._arrays[key]

    def vertical_step(self, lag_frames: int, height: float) -> np.ndarray:
        """The vertical displacement of every particle over the previous lag, by the minimal
        image through the periodic boundary (wrapped into (-H/2, H/2]) on a periodic riser,
        the plain difference on an open one; 0 in the first ``lag_frames`` frames (no
        previous frame) and for a single frame.

        Parameters
        ----------
        lag_frames : int
            The lag in frames (>= 1).
        height : float
            The riser's height H (m), the period of a periodic riser.

        Returns
        -------
        ndarray of float64, shape (T, N) or (N,)
            dy (m); NaN where a particle is absent at either end.
        """
        key = ("displacement", lag_frames, height)
        if key not in self._arrays:
            y = np.ascontiguousarray(np.asarray(self.positions, dtype=np.float64)[..., 1])
            if y.ndim == 1:      # a single frame has no previous frame
                self._arrays[key] = np.zeros_like(y)
            else:
                out = np.empty_like(y)
                _wrapped_step(y, lag_frames, height, self.periodic, out)
                self._arrays[key] = out
        return self._arrays[key]


__all__ = ["PARTICLE_BLOCK", "FrameQuantities"]
