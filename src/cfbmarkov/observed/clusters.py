"""A cluster measure of particle snapshots (``docs/definitions.md``, Cluster index).

The *index of dispersion* of the particle counts over the cells of a grid, var(n_c) /
mean(n_c), per frame: 1 for particles placed independently and uniformly (Poisson counts),
above 1 where they gather in clusters and leave voids, below 1 for an ordered packing. The
mean over the window's frames says how clustered the flow is; its SD over the frames how
much that changes (surges and collapses). A Markov model that moves each particle
independently gives about 1 whatever the flow: the figure shows what a model without a
cluster (regime) state cannot reproduce (the paper's conclusion).

References
----------
D. R. Cox and V. Isham, Point Processes, Chapman & Hall (1980), §6.2 (index of dispersion).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, parallel=True)
def _dispersion_kernel(states, cell_of_state, n_cells, index):
    """index[t] = var(n_c) / mean(n_c) of frame t's cell counts (Numba kernel, frames in
    parallel). ``states`` [T, N] (negative: absent), ``cell_of_state`` [S] maps a state to
    its cell. The sums of n_c and n_c^2 are integers, so
    var / mean = (C sum n_c^2 - (sum n_c)^2) / (C sum n_c) is exact up to one rounding
    (C: number of cells); NaN for an empty frame."""
    n_frames, n_particles = states.shape
    for t in nb.prange(n_frames):
        counts = np.zeros(n_cells, np.int64)
        for p in range(n_particles):
            s = states[t, p]
            if s >= 0:
                counts[cell_of_state[s]] += 1
        total = 0
        squares = 0
        for c in range(n_cells):
            total += counts[c]
            squares += counts[c] * counts[c]
        if total == 0:
            index[t] = np.nan
        else:
            index[t] = (n_cells * squares - total * total) / (n_cells * total)


def snapshot_cluster_index(cells: np.ndarray, n_cells: int,
                           cell_of_state: np.ndarray | None = None) -> np.ndarray:
    """The index of dispersion of the cell counts of each snapshot.

    Parameters
    ----------
    cells : ndarray of int, shape (T, N)
        Cell of particle p in frame t (negative: absent, not counted); with
        ``cell_of_state``, its state instead.
    n_cells : int
        Number of cells.
    cell_of_state : ndarray of int, shape (S,), optional
        The cell of each state (a state space's ``cell_of_state``) where ``cells`` holds
        states: the same as passing ``cell_of_state[cells]`` without forming it.

    Returns
    -------
    ndarray of float64, shape (T,)
        var(n_c) / mean(n_c) over the cells of each frame (-; var with divisor C, the
        number of cells), NaN for an empty frame: the measure of :func:`cluster_index`,
        from cells (e.g. a model's states mapped to their cells).

    Raises
    ------
    ValueError
        For a cell (or state) out of range.
    """
    cells = np.ascontiguousarray(cells)
    if cells.ndim != 2:
        raise ValueError(f"cells must be (T, N), not of shape {cells.shape}")
    if cell_of_state is None:
        cell_of_state = np.arange(n_cells, dtype=np.int64)
    cell_of_state = np.ascontiguousarray(cell_of_state, dtype=np.int64)
    if cells.size and (cells.max() >= cell_of_state.size
                       or (cell_of_state.size and (cell_of_state.min() < 0
                                                   or cell_of_state.max() >= n_cells))):
        raise ValueError("a cell or state lies outside the grid")
    index = np.empty(cells.shape[0], np.float64)
    _dispersion_kernel(cells, cell_of_state, int(n_cells), index)
    return index


#: values within this many cells below a cell edge count as on it, the rule of the model's
#: states (:data:`cfbmarkov.markov.cells.EDGE_TOLERANCE`): 0.29 m on 0.01 m rows is row 29,
#: not 28.999999999999996
EDGE_TOLERANCE = 1e-9


def _cell_floor(v: np.ndarray) -> np.ndarray:
    """The cell of each value in cells, an edge (to round-off) belonging to the cell above."""
    return np.floor(v + EDGE_TOLERANCE * np.maximum(1.0, np.abs(v)))


def cluster_index(traj, frames: slice, columns: int, rows: int, block: int = 64
                  ) -> tuple[float, float]:
    """Mean and SD over frames of the index of dispersion of the cell counts.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.
    frames : slice
        The window's frames.
    columns, rows : int
        The grid over (across, vertical), e.g. the model's cells.
    block : int, optional
        Frames read at a time.

    Returns
    -------
    (float, float)
        Mean and SD (ddof = 1; NaN for one frame) of var(n_c) / mean(n_c) over the frames
        (-); absent particles are not counted.
    """
    values = []
    n_cells = columns * rows
    for i in range(frames.start, frames.stop, block):
        rows_ = slice(i, min(i + block, frames.stop))
        pos = traj.positions(rows_)[..., :2]
        present = traj.present(rows_) & np.isfinite(pos).all(axis=-1)
        with np.errstate(invalid="ignore"):
            col = np.clip(_cell_floor(np.nan_to_num(pos[..., 0]) / traj.width * columns), 0,
                          columns - 1).astype(np.int64)
            row = np.clip(_cell_floor(np.nan_to_num(pos[..., 1]) / traj.height * rows), 0,
                          rows - 1).astype(np.int64)
        values.append(snapshot_cluster_index(np.where(present, row * columns + col, -1),
                                             n_cells))
    v = np.concatenate(values) if values else np.zeros(0)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else float("nan")
