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

import numpy as np


def snapshot_cluster_index(cells: np.ndarray, n_cells: int) -> np.ndarray:
    """The index of dispersion of the cell counts of each snapshot.

    Parameters
    ----------
    cells : ndarray of int, shape (T, N)
        Cell of particle p in frame t (negative: absent, not counted).
    n_cells : int
        Number of cells.

    Returns
    -------
    ndarray of float64, shape (T,)
        var(n_c) / mean(n_c) over the cells of each frame (-), NaN for an empty frame: the
        measure of :func:`cluster_index`, from cells (e.g. a model's states mapped to
        their cells).
    """
    cells = np.asarray(cells)
    n_frames = cells.shape[0]
    keep = cells >= 0
    index = cells + n_cells * np.arange(n_frames)[:, None]
    counts = np.bincount(index[keep], minlength=n_cells * n_frames).reshape(
        n_frames, n_cells).astype(np.float64)
    mean = counts.mean(axis=1)
    return np.divide(counts.var(axis=1), mean, out=np.full(n_frames, np.nan), where=mean > 0)


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
            col = np.clip(np.floor(np.nan_to_num(pos[..., 0]) / traj.width * columns), 0,
                          columns - 1).astype(np.int64)
            row = np.clip(np.floor(np.nan_to_num(pos[..., 1]) / traj.height * rows), 0,
                          rows - 1).astype(np.int64)
        values.append(snapshot_cluster_index(np.where(present, row * columns + col, -1),
                                             n_cells))
    v = np.concatenate(values) if values else np.zeros(0)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else float("nan")
