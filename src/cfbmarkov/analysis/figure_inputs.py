"""What a comparison's figures show beside its numbers: the frames of the snapshots (the
paper's Fig. 10) and the transition matrix and batch-injection maps of the model behind a
prediction (Fig. 3-7), drawn by :mod:`cfbmarkov.report.compare`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories

#: snapshot offsets from the window start (s), as in the paper's Fig. 10
SNAPSHOT_OFFSETS = tuple(round(0.1 * k, 10) for k in range(8))


def snapshot_frames(ref: Trajectories, pred: Trajectories, start: float, stop: float
                    ) -> list[tuple[float, int, int]]:
    """Frames of the snapshots (the paper's Fig. 10).

    Parameters
    ----------
    ref, pred : Trajectories
        The two open files.
    start, stop : float
        The analysis window, s.

    Returns
    -------
    list of (float, int, int)
        (time s, frame index in ``ref``, frame index in ``pred``) at start + 0, 0.1, ...
        0.7 s inside the window, where both files have a frame.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 10.
    """
    chosen = []
    for offset in SNAPSHOT_OFFSETS:
        t = start + offset
        if t > stop + 1e-9 * max(1.0, abs(stop)):
            break
        try:
            chosen.append((t, ref.frame_index(t), pred.frame_index(t)))
        except InputError:
            continue
    return chosen


def map_times(reference_mean: float, lag: float) -> list[float]:
    """Times of the batch-injection maps of a comparison.

    Parameters
    ----------
    reference_mean : float
        E(RT) of the reference, s.
    lag : float
        The model's lag, s.

    Returns
    -------
    list of float
        About E(RT)/4, E(RT)/2 and 3 E(RT)/4 in whole lags (the paper's choice of 0.05-0.15 s
        or 0.25-0.75 s), s; 2, 4 and 6 lags when these do not give three distinct times.
    """
    if math.isfinite(reference_mean) and reference_mean > 0:
        steps = sorted({max(1, round(f * reference_mean / lag)) for f in (0.25, 0.5, 0.75)})
        if len(steps) == 3:
            return [k * lag for k in steps]
    return [k * lag for k in (2, 4, 6)]


@dataclass
class ModelMaps:
    """The model behind a prediction, as the figures of the paper's Fig. 3-7 need it.

    Attributes
    ----------
    transition_matrix : numpy.ndarray, shape (S, S)
        P_ij, the probability to go from state i to state j in one lag.
    columns, rows : int
        Cells across and along the riser.
    lag : float
        Lag, s.
    times : list of float
        Times of the batch-injection maps, s (:func:`map_times`).
    maps : numpy.ndarray, shape (len(times), rows, columns)
        Probability per cell of a batch fed evenly over the inlet at t = 0 (Eq. 8); on a
        grid with several depth columns summed over the depth (``depth_columns``).
    states : str
        The state space's description, e.g. ``cells 6x38 (228 states)``.
    row_of_state : numpy.ndarray of int, shape (S,)
        The riser row (0 = bottom) of each state's cell.
    depth_columns : int
        The grid's depth columns, which ``maps`` sums over (1 on a 2D grid).
    """

    transition_matrix: np.ndarray
    columns: int
    rows: int
    lag: float
    times: list[float]
    maps: np.ndarray
    states: str = ""
    row_of_state: np.ndarray | None = None
    depth_columns: int = 1


def model_maps(pred: Trajectories, reference_mean: float, warnings: list[str]
               ) -> ModelMaps | None:
    """The transition matrix and batch-injection maps of the model carried by a prediction.

    Parameters
    ----------
    pred : Trajectories
        An open prediction file.
    reference_mean : float
        E(RT) of the reference, s (chooses the map times).
    warnings : list of str
        Receives a line when the model cannot be used.

    Returns
    -------
    ModelMaps or None
        None when the file carries no model (``/provenance/model``) or it cannot be used.
    """
    group = pred.group("model")
    if group is None:
        return None
    try:
        from cfbmarkov.markov import MarkovModel
    except ImportError as exc:
        warnings.append(f"model figures skipped: cfbmarkov.markov cannot be imported ({exc})")
        return None
    try:
        model = MarkovModel.from_trajectories(pred)
        P = np.asarray(model.transition_matrix, dtype=np.float64)
        columns, rows = int(model.state_space.columns), int(model.state_space.rows)
        lag = float(getattr(model, "lag", pred.frame_interval))
        times = map_times(reference_mean, lag)
        maps = np.asarray(model.batch_injection_maps(times), dtype=np.float64)
        space = model.state_space
        states = space.describe()
        row_of_state = np.asarray(space.cell_of_state) // space.cells_per_row
    except (InputError, AttributeError, KeyError, TypeError, ValueError) as exc:
        warnings.append(f"model figures skipped: the model of {pred.path} cannot be used "
                        f"({type(exc).__name__}: {exc})")
        return None
    return ModelMaps(P, columns, rows, lag, times, maps, states, row_of_state,
                     int(space.depth_columns))


__all__ = ["ModelMaps", "SNAPSHOT_OFFSETS", "map_times", "model_maps", "snapshot_frames"]
