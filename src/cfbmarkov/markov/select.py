"""``--states auto``: choose the state space and lag from the fitting window alone.

Blocked cross-validation in time: the fitting window [A, B] is cut into ``folds`` (3)
blocks of whole lags; for each block, every candidate (state space x lag) is fitted on the
other blocks and judged by how well it predicts what matters downstream, the
residence-time distribution seen in a window of the block's length: the model's exact
windowed RTD (:func:`~cfbmarkov.markov.rtd.exact_rtd`, no Monte Carlo noise), started from
the entry states observed in the training blocks (the landing states of their up passes;
this spares the chain's own stationary entry distribution, a sparse LU and an eigenvector
per fit, most of the selection's time), against the residence times observed in the
held-out block (SPEC section 3). Averaged over the blocks,

    score = |mean PD E(RT)| / 2 % + |mean PD SD(RT)| / 10 % + mean MD / mean MD(cells)

i.e. the model's bias in units of the project's goal for it (2 % and 10 %) plus the
Minkowski distance relative to that of the paper's state space on the same data, so that
every term is about 1 at the edge of what is acceptable. The PDs are averaged with their
signs: how one block's RTD differs from another's (clusters come and go over seconds) is
noise that no stationary model can predict, what the state space can fix is the bias.
The candidate with the lowest score wins and is refitted on the whole window; the model
records every candidate's numbers and why it was chosen (``model.selection``, saved with
it). Every block is judged once, so a riser whose clusters come and go over seconds is
not judged on one unrepresentative stretch (a single held-out block at the end of the
window did exactly that on the project's 6 m/s run).

Nothing outside the fitting window is used, so the choice can be checked on the prediction
window afterwards without fooling oneself. The window's frames are read once, every
candidate is discretised once and counted block by block from memory, and the chosen model
is formed from those counts: the same model as fitting its state space on the window.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from cfbmarkov.analysis.metrics import minkowski_distance, percentage_difference
from cfbmarkov.analysis.rtd import residence_times, rtd_histogram
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.estimate import estimator_from_name
from cfbmarkov.markov.rtd import exact_rtd
from cfbmarkov.markov.states import state_space_from_name
from cfbmarkov.trajectories import Trajectories

#: state spaces tried by default (names of :func:`state_space_from_name`)
DEFAULT_STATES = ("cells", "cells-direction", "cells-velocity", "cells-previous")
#: lags tried, in multiples of the base lag
DEFAULT_LAG_MULTIPLES = (1, 2)
#: fewer residence times than this in the held-out part: keep the paper's cells
MIN_RESIDENCES = 30


@dataclass(frozen=True)
class CandidateScore:
    states: str
    lag: float
    n_states: int
    rt_mean: float
    rt_sd: float
    pd_rt_mean: float
    pd_rt_sd: float
    md_rtd: float
    score: float
    error: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in self.__dict__.items()}


def _exact_histogram(rtd, bin_width: float, n_bins: int) -> np.ndarray:
    index = np.floor(rtd.times / bin_width + 1e-6).astype(np.int64)
    keep = (index >= 0) & (index < n_bins)
    counts = np.bincount(index[keep], weights=rtd.probability[keep], minlength=n_bins)
    total = counts.sum()
    return counts / total if total > 0 else counts


def _with_history(traj, space, lag: float, window: tuple[float, float]) -> tuple[float, float]:
    """The window, its start moved past the history a state space with memory needs when
    the window begins at the file's first frames."""
    earliest = float(traj.times[0]) + space.memory_lags * lag
    return (max(window[0], earliest), window[1])


def _sum_counts(parts):
    from cfbmarkov.markov.estimate import TransitionCounts

    averages = [c.frame_average_sum for c in parts]
    return TransitionCounts(sum(c.counts for c in parts), sum(c.counts_up for c in parts),
                            sum(c.counts_down for c in parts),
                            None if any(a is None for a in averages) else sum(averages),
                            sum(c.occupied_frames for c in parts),
                            sum(c.frame_pairs for c in parts))


class _WindowFrames:
    """The frames of a fitting window (and the history before it that memory states need),
    read from the file once: every candidate is discretised on them once and counted on
    each block without going back to the file."""

    def __init__(self, traj, window: tuple[float, float], history_frames: int,
                 needs_velocity: bool):
        frames = traj.window(*window)
        self.start, self.stop, _ = frames.indices(traj.n_frames)
        self.first = max(0, self.start - history_frames)
        self.traj = traj
        self.positions = traj.positions(slice(self.first, self.stop))
        self.velocities = (traj.velocities(slice(self.first, self.stop))
                           if needs_velocity and traj.has_velocity else None)
        self.y = np.ascontiguousarray(self.positions[:, :, 1])

    def states(self, space, lag_frames: int) -> np.ndarray:
        if space.needs_velocity and self.velocities is None:
            raise InputError(f"state space {space.kind} needs velocities; {self.traj.path} "
                             "has none")
        return space.discretize(self.positions, self.velocities, lag_frames)

    def counts(self, space, states: np.ndarray, lag_frames: int, window: tuple[float, float],
               frame_average: bool = True):
        """Counts of ``window`` (a block, or the whole fitting window) from the states of
        :meth:`states`, the window's start moved past the history the space needs."""
        from cfbmarkov.markov.estimate import count_states

        start, stop, _ = self.traj.window(*window).indices(self.traj.n_frames)
        start = max(start, self.first + space.memory_lags * lag_frames)
        if stop - start <= lag_frames:
            raise InputError(f"window {window[0]:g}:{window[1]:g} s holds fewer than two "
                             f"frames one lag apart")
        rows = slice(start - self.first, stop - self.first)
        return count_states(states[rows], self.y[rows], lag_frames, self.traj.height,
                            space.n_states, frame_average)


def _entry_distribution(counts) -> np.ndarray:
    """Where particles entered in the counted data: the landing states of up passes."""
    return counts.counts_up.sum(axis=0).astype(np.float64)


def select_model(data, *, window: tuple[float, float], columns: int, rows: int, lag: float,
                 states: Sequence[str] = DEFAULT_STATES,
                 lag_multiples: Sequence[int] = DEFAULT_LAG_MULTIPLES,
                 estimator: str = "mle", folds: int = 3):
    """Choose, fit on ``window`` and return the best model (see the module doc); its
    ``selection`` attribute holds the candidates' scores and the reason."""
    if int(folds) < 2:
        raise InputError(f"auto: {folds} folds; cross-validation needs at least 2")
    folds = int(folds)
    a, b = (float(v) for v in window)
    own = not isinstance(data, Trajectories)
    traj = Trajectories(data) if own else data
    try:
        step = lag * max(int(m) for m in lag_multiples)      # block edges on whole lags
        n_steps = int(math.floor((b - a) / step + 1e-9))
        if n_steps < 2 * folds:
            raise InputError(f"auto: the fitting window {a:g}-{b:g} s is too short to split "
                             f"into {folds} blocks of whole lags")
        edges = [a + step * round(k * n_steps / folds) for k in range(folds + 1)]
        blocks = [(float(edges[k]), float(edges[k + 1])) for k in range(folds)]
        observed = [residence_times(traj, block) for block in blocks]
        fewest = min(o.count for o in observed)
        if fewest < MIN_RESIDENCES:
            space = state_space_from_name("cells", columns, rows, traj.width, traj.height, lag)
            model = estimator_from_name(estimator, space, lag).fit(traj, window=(a, b))
            return model.with_selection({
                "method": f"{folds}-fold blocked cross-validation of the RTD",
                "blocks": [list(x) for x in blocks], "estimator": estimator,
                "chosen": {"states": "cells", "lag": lag},
                "reason": f"a block of the fitting window holds only {fewest} residence times "
                          f"(fewer than {MIN_RESIDENCES}): too few to choose, so the paper's "
                          "cells were kept",
                "candidates": []})
        histograms = [rtd_histogram(o.samples, lag, window_length=blk[1] - blk[0])[1]
                      for o, blk in zip(observed, blocks)]
        spaces = {(name, lag * int(m)): state_space_from_name(
            name, columns, rows, traj.width, traj.height, lag * int(m))
            for name in states for m in lag_multiples}
        history = max(sp_.memory_lags * traj.lag_frames(tau) for (_, tau), sp_ in spaces.items())
        cached = _WindowFrames(traj, (a, b), history,
                               any(sp_.needs_velocity for sp_ in spaces.values()))
        raw = []
        for (name, tau), space in spaces.items():
            est = estimator_from_name(estimator, space, tau)
            try:
                lag_frames = traj.lag_frames(tau)
                discrete = cached.states(space, lag_frames)
                parts = [cached.counts(space, discrete, lag_frames, block,
                                       frame_average=estimator == "paper") for block in blocks]
                rows_ = []
                for k, block in enumerate(blocks):
                    # fitted on the other blocks; its RTD from where particles entered there
                    training = _sum_counts(parts[:k] + parts[k + 1:])
                    matrix, fractions = est.chain(training)
                    up, down = fractions if fractions is not None else _pass_fractions(training)
                    steps = max(2, int(round((block[1] - block[0]) / tau)))
                    rtd = exact_rtd(matrix, up, down, tau, max_steps=steps,
                                    entry=_entry_distribution(training)
                                    ).in_window(block[1] - block[0])
                    rows_.append((percentage_difference(rtd.mean, observed[k].mean),
                                  percentage_difference(rtd.sd, observed[k].sd),
                                  minkowski_distance(histograms[k], _exact_histogram(
                                      rtd, lag, histograms[k].size), 2.0),
                                  rtd.mean, rtd.sd))
            except (InputError, CfbmarkovError) as exc:
                raw.append((name, tau, space.n_states, None, str(exc)))
                continue
            raw.append((name, tau, space.n_states, np.asarray(rows_), ""))
        cells_md = next((float(r[3][:, 2].mean()) for r in raw
                         if r[0] == "cells" and r[1] == lag and r[3] is not None), math.nan)
        reference_md = cells_md if math.isfinite(cells_md) and cells_md > 0 else 1.0
        final: list[CandidateScore] = []
        for name, tau, n_states, table, error in raw:
            if table is None:
                final.append(CandidateScore(name, tau, n_states, math.nan, math.nan, math.nan,
                                            math.nan, math.nan, math.inf, error))
                continue
            # the bias over the blocks: how the blocks' RTDs differ from one another (a
            # riser's clusters come and go) is noise no stationary model can predict
            value = (abs(table[:, 0].mean()) / 2.0 + abs(table[:, 1].mean()) / 10.0
                     + table[:, 2].mean() / reference_md)
            final.append(CandidateScore(name, tau, n_states, float(table[:, 3].mean()),
                                        float(table[:, 4].mean()), float(table[:, 0].mean()),
                                        float(table[:, 1].mean()), float(table[:, 2].mean()),
                                        float(value)))
        usable = [c for c in final if math.isfinite(c.score)]
        if not usable:
            raise InputError("auto: no candidate state space could be fitted: "
                             + "; ".join(f"{c.states} lag {c.lag:g}: {c.error}" for c in final))
        best = min(usable, key=lambda c: c.score)
        space = spaces[(best.states, best.lag)]
        lag_frames = traj.lag_frames(best.lag)
        counts = cached.counts(space, cached.states(space, lag_frames), lag_frames, (a, b))
        model = estimator_from_name(estimator, space, best.lag).fit_counts(
            counts, window=_with_history(traj, space, best.lag, (a, b)), source=traj.path)
    finally:
        if own:
            traj.close()
    cells = next((c for c in usable if c.states == "cells" and c.lag == lag), None)
    reason = (f"{best.states} at lag {best.lag:g} s had the lowest score {best.score:.3g} in "
              f"{folds}-fold blocked cross-validation over {a:g}-{b:g} s (mean PD E(RT) "
              f"{best.pd_rt_mean:+.1f} %, SD(RT) {best.pd_rt_sd:+.1f} %, MD {best.md_rtd:.3g}")
    reason += (f"; cells: {cells.pd_rt_mean:+.1f} %, {cells.pd_rt_sd:+.1f} %, MD "
               f"{cells.md_rtd:.3g}, score {cells.score:.3g})" if cells is not None else ")")
    selection = {"method": f"{folds}-fold blocked cross-validation of the RTD",
                 "blocks": [list(x) for x in blocks],
                 "observed": [{"rt_mean": o.mean, "rt_sd": o.sd, "rt_count": o.count}
                              for o in observed],
                 "estimator": estimator, "chosen": {"states": best.states, "lag": best.lag},
                 "reason": reason, "candidates": [c.as_dict() for c in final]}
    return model.with_selection(selection)


def _pass_fractions(counts) -> tuple[np.ndarray, np.ndarray]:
    c = counts.counts.astype(np.float64)
    return (np.divide(counts.counts_up, c, out=np.zeros_like(c), where=c > 0),
            np.divide(counts.counts_down, c, out=np.zeros_like(c), where=c > 0))


def parse_model_name(name: str) -> tuple[str, str]:
    """A model's name in a reproduction -> (state space, estimator): ``paper`` and ``mle``
    are the paper's cells with that estimator, ``auto`` is :func:`select_model`, and
    ``STATES`` or ``STATES:ESTIMATOR`` names a state space (estimator ``mle`` by default)."""
    from cfbmarkov.markov.estimate import ESTIMATORS
    from cfbmarkov.markov.states import STATE_SPACES

    if name in ESTIMATORS:
        return "cells", name
    if name == "auto":
        return "auto", "mle"
    states, _, estimator = name.partition(":")
    estimator = estimator or "mle"
    if states not in STATE_SPACES or estimator not in ESTIMATORS:
        raise InputError(f"unknown model '{name}': use paper, mle, auto, or STATES[:ESTIMATOR] "
                         f"with STATES in {', '.join(STATE_SPACES)} and ESTIMATOR in "
                         f"{', '.join(ESTIMATORS)}")
    return states, estimator


def fit_by_name(name: str, data, *, window: tuple[float, float], columns: int, rows: int,
                lag: float):
    """Fit the model ``name`` (see :func:`parse_model_name`) on ``window`` of ``data``."""
    states, estimator = parse_model_name(name)
    if states == "auto":
        return select_model(data, window=window, columns=columns, rows=rows, lag=lag,
                            estimator=estimator)
    own = not isinstance(data, Trajectories)
    traj = Trajectories(data) if own else data
    try:
        space = state_space_from_name(states, columns, rows, traj.width, traj.height, lag)
        return estimator_from_name(estimator, space, lag).fit(traj, window=window)
    finally:
        if own:
            traj.close()


__all__ = ["DEFAULT_LAG_MULTIPLES", "DEFAULT_STATES", "CandidateScore", "fit_by_name",
           "parse_model_name", "select_model"]
