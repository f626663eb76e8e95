"""The judged blocks of the fitting window: where each candidate is judged, and the
residence times observed there.

The fitting window [A, B] is cut into ``folds`` blocks of whole lags (of the longest
candidate lag). The ``window`` criterion judges on the whole window, the others on each
block held out in turn. The residence times are those observed from frames at the base lag,
counted in the direction of the window's net solids flow (``docs/definitions.md``,
Comparison basis and Net downflow), as the comparison of a prediction counts them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from cfbmarkov.errors import InputError
from cfbmarkov.observed.residence import ResidenceTimes, net_flow_direction, residence_times

#: fewer residence times than this in a block: judge by the CK test instead of the RTD
MIN_RESIDENCES = 30


@dataclass(frozen=True)
class JudgedBlocks:
    """The fitting window cut into blocks, and what was observed where candidates are judged.

    Attributes
    ----------
    window : tuple of float
        The fitting window (A, B), s.
    criterion : {"window", "rtd", "ck"}
        The criterion that judges (``auto`` resolved).
    blocks : list of tuple of float
        The ``folds`` blocks (start, stop) of whole lags, s, in time order.
    judged : list of tuple of float
        The stretches judged: ``[window]`` for the ``window`` criterion, else ``blocks``.
    observed : list of ResidenceTimes
        The residence times observed in each judged stretch.
    whole : ResidenceTimes
        The residence times observed over the whole window.
    direction : {"up", "down"}
        The direction in which residences are counted (the window's net solids flow).
    lag_frames : int
        The base lag in frames.
    """

    window: tuple[float, float]
    criterion: str
    blocks: list[tuple[float, float]]
    judged: list[tuple[float, float]]
    observed: list[ResidenceTimes]
    whole: ResidenceTimes
    direction: str
    lag_frames: int

    @property
    def folds(self) -> int:
        """Number of blocks."""
        return len(self.blocks)

    @property
    def fewest(self) -> int:
        """The fewest residence times observed in a judged stretch."""
        return min(o.count for o in self.observed)


def _open_riser_criterion(is_open: bool, criterion: str) -> str:
    """An open riser's criterion: the Chapman-Kolmogorov test (``auto``), the RTD criteria
    refused in one line: their chain's RTD is the periodic riser's (passes up through the
    top), not the absorbing chain of an open one."""
    if not is_open:
        return criterion
    if criterion in ("window", "rtd"):
        raise InputError(f"auto: the {criterion} criterion judges a periodic riser's RTD; an "
                         "open riser's candidates are judged by the Chapman-Kolmogorov test "
                         "(criterion ck, or auto)")
    return "ck"


def judged_blocks(traj, window: tuple[float, float], lag: float, lag_multiples: Sequence[int],
                  folds: int, criterion: str, face_band: float | None = None) -> JudgedBlocks:
    """Cut the fitting window into blocks and observe the residence times to judge by.

    Parameters
    ----------
    traj : Trajectories
        The open trajectory file.
    window : tuple of float
        The fitting window (A, B), s.
    lag : float
        The base lag, s.
    lag_multiples : sequence of int
        Candidate lags in multiples of ``lag``; block edges fall on whole multiples of the
        longest.
    folds : int
        Number of blocks (>= 2).
    criterion : {"auto", "window", "rtd", "ck"}
        The criterion asked for; ``auto`` becomes ``window`` where the window holds at least
        :data:`MIN_RESIDENCES` residences, else ``ck``; on an open riser always ``ck``.
    face_band : float, optional
        An open riser's face band (m): one cell row of the candidates' grid, where a
        vanishing particle has left (:func:`cfbmarkov.observed.residence.residence_times`).

    Returns
    -------
    JudgedBlocks

    Raises
    ------
    InputError
        For a window too short for the blocks, a block or lag that does not fit the file,
        ``criterion="window"`` with fewer than :data:`MIN_RESIDENCES` residences in the
        window, or ``criterion="rtd"`` with fewer in a block.
    """
    a, b = window
    step = lag * max(int(m) for m in lag_multiples)      # block edges on whole lags
    n_steps = int(math.floor((b - a) / step + 1e-9))
    if n_steps < 2 * folds:
        raise InputError(f"auto: the fitting window {a:g}-{b:g} s is too short to split "
                         f"into {folds} blocks of whole lags")
    edges = [a + step * round(k * n_steps / folds) for k in range(folds + 1)]
    blocks = [(float(edges[k]), float(edges[k + 1])) for k in range(folds)]
    # like for like: the held-out residence times from frames at the lag, the time
    # basis of the model's RTD (docs/definitions.md, Comparison basis)
    traj.window(a, b)               # a window outside the data is refused as such first,
    for block in blocks:            # named as given
        traj.window(*block)
    lag_frames = traj.lag_frames(lag)
    # residences counted as the fitting window's net solids flow runs (docs/definitions.md,
    # Net downflow), as the comparison of the prediction will count them
    direction = net_flow_direction(traj, (a, b))
    whole = residence_times(traj, (a, b), use_events=False, lag_frames=lag_frames,
                            direction=direction, face_band=face_band)
    criterion = _open_riser_criterion(traj.boundary.is_open, criterion)
    if criterion == "auto":
        criterion = "window" if whole.count >= MIN_RESIDENCES else "ck"
    if criterion == "window":          # one "block": the whole window, in sample
        if whole.count < MIN_RESIDENCES:
            raise InputError(f"auto: the fitting window holds only {whole.count} "
                             "residence times, too few to judge by the RTD")
        judged, observed = [(a, b)], [whole]
    else:
        judged = blocks
        observed = [residence_times(traj, block, use_events=False, lag_frames=lag_frames,
                                    direction=direction, face_band=face_band)
                    for block in blocks]
    fitting = JudgedBlocks((a, b), criterion, blocks, judged, observed, whole, direction,
                           lag_frames)
    if criterion == "rtd" and fitting.fewest < MIN_RESIDENCES:
        raise InputError(f"auto: a block holds only {fitting.fewest} residence times, too few "
                         "to judge by the RTD")
    return fitting
