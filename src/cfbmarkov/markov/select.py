"""``--states auto``: choose the state space and lag from the fitting window alone.

Every candidate (state space x lag) is fitted on the fitting window [A, B] and judged by
what matters downstream, the residence-time distribution: its exact windowed RTD
(:func:`~cfbmarkov.markov.first_passage.exact_rtd`, no Monte Carlo noise), started from the entry
states observed in the window (the landing states of its passes; this spares the chain's
own stationary entry distribution, a sparse LU and an eigenvector per fit), against the
residence times observed over the same window, from frames at the lag
(``docs/definitions.md``, Residence time). The score is the Minkowski distance (Eq. 9,
k = 2) between the two RTD histograms, relative to that of the paper's state space,

    score = MD / MD(cells)

and the candidate with the lowest score wins. Its E(RT) and SD(RT) are recorded but do not
judge. This is the Chapman-Kolmogorov idea applied to the quantity the model is for: the
estimator fits one-lag transitions, never the RTD, so how far the chain's many-lag RTD is
from the data's is a test of the memory the state space misses, not a measure of how well
it was fitted (Prinz et al. 2011 run the CK test on the estimation data for the same
reason). With 10^5 to 10^7 transitions per window and at most a few thousand states the
estimation noise is small against the differences between the candidates.

Until session 18 the default was blocked cross-validation (``criterion="rtd"``, still
available): the window cut into ``folds`` (3) blocks of whole lags, each candidate fitted on
the other blocks and judged on the held-out block's RTD by

    score = |mean PD E(RT)| / u_E + |mean PD SD(RT)| / u_SD + mean MD / mean MD(cells)

with the units u the project's goals (2 %, 10 %) or the blocks' own variability where that
is larger. On sliding 5 s windows of the 3, 4, 6 and 8 m/s paper-scale runs
(``docs/method.md``, Choosing the state space and lag) the choice by the whole window's RTD
was the candidate with the lowest MD on the *next* window in 8, 3, 6 and 8 of 8 windows
each, the cross-validation's in 5, 4, 4 and 5, and lost less MD against the best candidate
in total (0.30 against 0.85 over the 32 windows): held-out blocks of 1.7 s see RTDs cut at 1.7 s, and the
bias terms of one block against the others followed the flow's surges more than the
models' errors. Neither is an oracle.

When the window holds fewer than ``MIN_RESIDENCES`` (30) complete residences (at low gas
velocity a residence can outlast the window), the RTD cannot judge, and the candidates are
judged instead by the Chapman-Kolmogorov test on held-out blocks: fitted on the other
blocks, each predicts where the particles of each coarse group (height thirds x core /
annulus) are found after t = 2, 4, ..., 20 base lags, from the occupancy of its states at
the start frames; the score is the mean absolute difference from the fractions observed in
the block, relative to that of the paper's cells.

Nothing outside the fitting window is used, so the choice can be checked on the prediction
window afterwards without fooling oneself. The window's frames are read once, every
candidate is discretised once and counted from memory, and the chosen model is formed from
those counts: the same model as fitting its state space on the window. The model records
every candidate's numbers and why it was chosen (``model.selection``, saved with it).
"""

from __future__ import annotations

import functools
import math
import operator
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from cfbmarkov.observed.metrics import minkowski_distance, percentage_difference
from cfbmarkov.observed.residence import net_flow_direction, residence_times, rtd_histogram
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.discrete import DiscreteTrajectories, read_frames
from cfbmarkov.markov.counting import count_transitions
from cfbmarkov.markov.estimate import estimator_from_name, fit_model
from cfbmarkov.markov.first_passage import rtd_of_split_chain
from cfbmarkov.markov.spaces import state_space_from_name
from cfbmarkov.trajectories import opened

#: state spaces tried by default (names of :func:`state_space_from_name`)
DEFAULT_STATES = ("cells", "cells-direction", "cells-velocity", "cells-previous", "cells-regime")
#: (``cells-velocity-fine`` is not a default candidate either: at paper scale it fits one
#: sub-row, the states of ``cells-velocity``, and at the quick scale's 6 and 8 m/s, where its
#: sub-rows halve the later window's MD, the cross-validation on short blocks cannot tell it
#: from ``cells-previous``; it chose it only at the quick 4 m/s, where it did worse on the
#: later window and cost 14 s more of the demo (docs/method.md); ``states=`` can add it. A
#: candidate whose fitted states equal an earlier one's is listed, not judged twice.)
#: (``cells-direction-regime``, 912 states, is left out of the default candidates: it cost 0.4 s
#: of the 1.7 s choice at paper scale, and on the 6 m/s run it did worse than cells-direction,
#: +11.7 % / +36.4 % against +3.2 % / +6.4 % in PD E / SD; ``states=`` can add it)
#: lags tried, in multiples of the given lag. Only the given lag by default: a model at
#: twice the lag predicts residence times on a grid twice as coarse, every other bin of the
#: RTD histogram empty, which the Minkowski distance on lag-wide bins punishes (MD 0.34
#: instead of 0.12-0.14 on the 6 m/s run) whatever its mean and spread; pass (1, 2) to let
#: the cross-validation choose the lag too
DEFAULT_LAG_MULTIPLES = (1,)
#: the goals for a model's bias (%): the units of the score's PD terms on a steady flow
GOAL_PD_MEAN, GOAL_PD_SD = 2.0, 10.0
#: fewer residence times than this in a block: judge by the CK test instead of the RTD
MIN_RESIDENCES = 30
#: the CK criterion's times, in base lags
CK_LAG_MULTIPLES = np.arange(2, 21, 2)


@dataclass(frozen=True)
class CandidateScore:
    """How one candidate (state space x lag) fared in the cross-validation.

    Attributes
    ----------
    states : str
        Name of the state space (:func:`~cfbmarkov.markov.spaces.state_space_from_name`).
    lag : float
        The lag (s).
    n_states : int
        Number of states S.
    rt_mean, rt_sd : float
        The model's windowed E(RT) and SD(RT) (s), averaged over the blocks (NaN under
        the CK criterion).
    pd_rt_mean, pd_rt_sd : float
        Percentage differences (%) of E(RT) and SD(RT) from the held-out blocks, averaged
        with their signs.
    md_rtd : float
        Mean Minkowski distance (p = 2) between the model's and the held-out RTD
        histograms.
    score : float
        The criterion (lower is better; inf where the candidate failed).
    error : str
        Why the candidate could not be judged ("" if it could).
    ck_error : float
        Held-out Chapman-Kolmogorov error (the criterion when residences are too few).
    """

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
    # held-out Chapman-Kolmogorov error (the criterion when residences are too few)
    ck_error: float = math.nan

    def as_dict(self) -> dict[str, Any]:
        """The fields as a JSON-serialisable dict (non-finite numbers as None)."""
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in self.__dict__.items()}


def _exact_histogram(rtd, bin_width: float, n_bins: int) -> np.ndarray:
    index = np.floor(rtd.times / bin_width + 1e-6).astype(np.int64)
    keep = (index >= 0) & (index < n_bins)
    counts = np.bincount(index[keep], weights=rtd.probability[keep], minlength=n_bins)
    total = counts.sum()
    return counts / total if total > 0 else counts


def _natural_tolerances(observed) -> tuple[float, float]:
    """The units of the score's two bias terms (%): the goal, or the flow's own variability.

    Each block's observed E(RT) and SD(RT) are compared with those of the other blocks'
    residence times pooled (the persistence baseline inside the cross-validation); the RMS
    of those percentage differences over the blocks is how much the riser itself varies
    from one stretch of the window to the next. A candidate's bias smaller than that is not
    evidence for it, so the unit is the larger of the goal (2 % for E, 10 % for SD) and this
    natural variability.

    Parameters
    ----------
    observed : sequence of ResidenceTimes
        The held-out blocks' residence times, in block order.

    Returns
    -------
    (float, float)
        The units of |PD E(RT)| and |PD SD(RT)|, in %.
    """
    pd_mean, pd_sd = [], []
    for k, held_out in enumerate(observed):
        others = np.concatenate([o.samples for j, o in enumerate(observed) if j != k])
        if others.size < 2 or held_out.count < 2:
            continue
        pd_mean.append(percentage_difference(float(others.mean()), held_out.mean))
        pd_sd.append(percentage_difference(float(others.std(ddof=1)), held_out.sd,
                                           scale=held_out.mean))
    if not pd_mean:
        return GOAL_PD_MEAN, GOAL_PD_SD
    rms = lambda values: float(np.sqrt(np.mean(np.square(values))))  # noqa: E731
    return max(GOAL_PD_MEAN, rms(pd_mean)), max(GOAL_PD_SD, rms(pd_sd))


def _entry_distribution(counts, direction: str = "up") -> np.ndarray:
    """Where particles entered in the counted data: the landing states of up passes (of down
    passes where residences run downward)."""
    passes = counts.counts_up if direction == "up" else counts.counts_down
    return np.asarray(passes.sum(axis=0), dtype=np.float64).ravel()


def select_model(data, *, window: tuple[float, float], columns: int, rows: int, lag: float,
                 states: Sequence[str] = DEFAULT_STATES,
                 lag_multiples: Sequence[int] = DEFAULT_LAG_MULTIPLES,
                 estimator: str = "mle", folds: int = 3, criterion: str = "auto",
                 coherent: bool = False):
    """Choose, fit on ``window`` and return the best model (see the module docstring).

    Parameters
    ----------
    data : str, os.PathLike or Trajectories
        The trajectory file, by path or open.
    window : tuple of float
        The fitting window (A, B) in s; nothing outside it is used.
    columns, rows : int
        The cell grid m x n of every candidate.
    lag : float
        The base lag (s), a whole multiple of the frame interval.
    states : sequence of str, optional
        Names of the candidate state spaces.
    lag_multiples : sequence of int, optional
        Candidate lags, in multiples of ``lag``.
    estimator : {"mle", "paper"}, optional
        The estimator of every candidate.
    folds : int, optional
        Number of blocks of the cross-validation (>= 2; the ``rtd`` and ``ck`` criteria).
    criterion : {"auto", "window", "rtd", "ck"}, optional
        Judge by the RTD over the whole fitting window (``window``), by the held-out RTD of
        blocked cross-validation (``rtd``, the default until session 18), by the held-out
        Chapman-Kolmogorov error (``ck``), or ``auto``: ``window`` where the window holds at
        least ``MIN_RESIDENCES`` residences, else ``ck``.
    coherent : bool, optional
        Also fit the chosen model's coherence (:mod:`cfbmarkov.markov.coherence`); it does
        not change the choice (the RTD and CK test are single-particle figures).

    Returns
    -------
    MarkovModel
        The chosen model, fitted on the whole window; its ``selection`` attribute holds
        the candidates' scores and the reason.

    Raises
    ------
    InputError
        For an unknown criterion, fewer than 2 folds, a window too short for the blocks,
        ``criterion="rtd"`` with too few residences in a block (``"window"``: in the
        window), a file, window or lag that does not fit, or when no candidate can be
        fitted.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 9, the Minkowski distance).

    J.-H. Prinz et al., "Markov models of molecular kinetics: generation and
    validation", J. Chem. Phys. 134, 174105 (2011) (the Chapman-Kolmogorov test).
    """
    if criterion not in ("auto", "rtd", "ck", "window"):
        raise InputError(f"auto: unknown criterion '{criterion}' (window, rtd, ck or auto)")
    if int(folds) < 2:
        raise InputError(f"auto: {folds} folds; cross-validation needs at least 2")
    folds = int(folds)
    a, b = (float(v) for v in window)
    with opened(data) as traj:
        step = lag * max(int(m) for m in lag_multiples)      # block edges on whole lags
        n_steps = int(math.floor((b - a) / step + 1e-9))
        if n_steps < 2 * folds:
            raise InputError(f"auto: the fitting window {a:g}-{b:g} s is too short to split "
                             f"into {folds} blocks of whole lags")
        edges = [a + step * round(k * n_steps / folds) for k in range(folds + 1)]
        blocks = [(float(edges[k]), float(edges[k + 1])) for k in range(folds)]
        # like for like: the held-out residence times from frames at the lag, the time
        # basis of the model's RTD (docs/definitions.md, Comparison basis)
        for block in blocks:
            traj.window(*block)         # a window outside the data is refused as such first
        lag_frames = traj.lag_frames(lag)
        # residences counted as the fitting window's net solids flow runs (docs/definitions.md,
        # Net downflow), as the comparison of the prediction will count them
        direction = net_flow_direction(traj, (a, b))
        whole = residence_times(traj, (a, b), use_events=False, lag_frames=lag_frames,
                                direction=direction)
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
                                        direction=direction) for block in blocks]
        fewest = min(o.count for o in observed)
        if criterion == "rtd" and fewest < MIN_RESIDENCES:
            raise InputError(f"auto: a block holds only {fewest} residence times, too few "
                             "to judge by the RTD")
        histograms = ([rtd_histogram(o.samples, lag, window_length=blk[1] - blk[0])[1]
                       for o, blk in zip(observed, judged)] if criterion != "ck" else [])
        ck_times = CK_LAG_MULTIPLES * lag
        spaces = {(name, lag * int(m)): state_space_from_name(
            name, columns, rows, traj.width, traj.height)
            for name in states for m in lag_multiples}
        history = max(sp_.memory_lags * traj.lag_frames(tau) for (_, tau), sp_ in spaces.items())
        # the window's frames are read once; every candidate is discretised on them
        frames = read_frames(traj, (a, b), history, short_history="skip",
                             velocities=traj.has_velocity and any(
                                 sp_.needs_velocity for sp_ in spaces.values()))
        raw = []
        discrete_of = {}
        for (name, tau), space in spaces.items():
            try:
                discrete = frames.discretize(space, traj.lag_frames(tau))
                space = discrete.state_space          # fitted to the window (bins, sub-rows)
                est = estimator_from_name(estimator, space, tau)
                same = next((other for (other, t), d in discrete_of.items()
                             if t == tau and d.state_space.n_states == space.n_states
                             and np.array_equal(d.states, discrete.states)), None)
                if same is not None:       # fitted to the states of an earlier candidate
                    raw.append((name, tau, discrete.state_space.n_states, None,
                                f"the same states as {same} on this window"))
                    continue
                discrete_of[(name, tau)] = discrete
                # sparse counts and chains: the work grows with the transitions, not S x S
                # (counted block by block also for the whole window: three block counts
                # took 0.07 s where one of the window took 0.10 s at paper scale)
                parts = [count_transitions(discrete.block(*block),
                                           frame_average=estimator == "paper", sparse=True)
                         for block in blocks]
                rows_ = []
                for k, block in enumerate(judged):
                    # fitted on the other blocks; its RTD from where particles entered there
                    # (with criterion="window": fitted and judged on the whole window)
                    training = functools.reduce(operator.add, parts if criterion == "window"
                                                else parts[:k] + parts[k + 1:])
                    up, down, stay = est.split_chain(training)
                    if criterion == "ck":
                        rows_.append((_held_out_ck_error(discrete.block(*block),
                                                         up + down + stay, ck_times),))
                        continue
                    entry = _entry_distribution(training, direction)
                    if direction == "down":     # the mirror image: in at the top, out below
                        up, down = down, up
                    steps = max(2, int(round((block[1] - block[0]) / tau)))
                    rtd = rtd_of_split_chain(up, down, stay, tau, max_steps=steps, entry=entry
                                             ).in_window(block[1] - block[0])
                    rows_.append((percentage_difference(rtd.mean, observed[k].mean),
                                  percentage_difference(rtd.sd, observed[k].sd,
                                                        scale=observed[k].mean),
                                  minkowski_distance(histograms[k], _exact_histogram(
                                      rtd, lag, histograms[k].size), 2.0),
                                  rtd.mean, rtd.sd))
            except (InputError, CfbmarkovError) as exc:
                raw.append((name, tau, space.n_states, None, str(exc)))
                continue
            raw.append((name, tau, space.n_states, np.asarray(rows_), ""))
        column = 0 if criterion == "ck" else 2
        cells_md = next((float(r[3][:, column].mean()) for r in raw
                         if r[0] == "cells" and r[1] == lag and r[3] is not None), math.nan)
        reference_md = cells_md if math.isfinite(cells_md) and cells_md > 0 else 1.0
        tolerance_mean, tolerance_sd = (_natural_tolerances(observed) if criterion == "rtd"
                                        else (GOAL_PD_MEAN, GOAL_PD_SD))
        if criterion == "window":
            tolerance_mean = tolerance_sd = math.nan
        final: list[CandidateScore] = []
        for name, tau, n_states, table, error in raw:
            if table is None or not np.all(np.isfinite(table[:, column])):
                final.append(CandidateScore(name, tau, n_states, math.nan, math.nan, math.nan,
                                            math.nan, math.nan, math.inf,
                                            error or "no held-out comparison"))
                continue
            if criterion == "ck":
                ck = float(table[:, 0].mean())
                final.append(CandidateScore(name, tau, n_states, math.nan, math.nan, math.nan,
                                            math.nan, math.nan, ck / reference_md, ck_error=ck))
                continue
            # the bias over the blocks: how the blocks' RTDs differ from one another (a
            # riser's clusters come and go) is noise no stationary model can predict.
            # On the window itself only the shape judges (module docstring)
            value = (table[:, 2].mean() / reference_md if criterion == "window" else
                     abs(table[:, 0].mean()) / tolerance_mean
                     + abs(table[:, 1].mean()) / tolerance_sd + table[:, 2].mean() / reference_md)
            final.append(CandidateScore(name, tau, n_states, float(table[:, 3].mean()),
                                        float(table[:, 4].mean()), float(table[:, 0].mean()),
                                        float(table[:, 1].mean()), float(table[:, 2].mean()),
                                        float(value)))
        usable = [c for c in final if math.isfinite(c.score)]
        if not usable and criterion == "ck":
            space = state_space_from_name("cells", columns, rows, traj.width, traj.height)
            model = fit_model(traj, space, lag, (a, b), estimator, coherent=coherent)
            return model.with_selection({
                "method": f"{folds}-fold blocked cross-validation",
                "blocks": [list(x) for x in blocks], "estimator": estimator,
                "chosen": {"states": "cells", "lag": lag},
                "reason": f"the blocks of the fitting window are too short to judge: a block "
                          f"holds only {fewest} residence times (fewer than {MIN_RESIDENCES}) "
                          f"and is shorter than the CK test's {ck_times.max():g} s, so the "
                          "paper's cells were kept",
                "candidates": [c.as_dict() for c in final]})
        if not usable:
            raise InputError("auto: no candidate state space could be fitted: "
                             + "; ".join(f"{c.states} lag {c.lag:g}: {c.error}" for c in final))
        best = min(usable, key=lambda c: c.score)
        chosen = discrete_of[(best.states, best.lag)]
        counts = count_transitions(chosen, frame_average=estimator == "paper")
        model = estimator_from_name(estimator, chosen.state_space, best.lag).fit_counts(
            counts, window=chosen.window, source=traj.path, adopt=True)   # counted for it alone
        if coherent:
            from cfbmarkov.markov.coherence import calibrate_coherence

            if chosen.boundary == "open":
                raise InputError("coherent moves (--coherent) are fitted for periodic risers "
                                 "only yet; fit an open riser without it")
            model = model.with_coherence(calibrate_coherence(model, chosen))
    cells = next((c for c in usable if c.states == "cells" and c.lag == lag), None)
    if criterion == "ck":
        why = (f"the fitting window holds only {whole.count} complete residences (fewer "
               f"than {MIN_RESIDENCES}), so the RTD could not judge; "
               if whole.count < MIN_RESIDENCES else "")
        reason = (f"{why}{best.states} "
                  f"at lag {best.lag:g} s had the lowest held-out Chapman-Kolmogorov error "
                  f"{best.ck_error:.4f} in {folds}-fold blocked cross-validation over "
                  f"{a:g}-{b:g} s")
        reason += (f" (cells: {cells.ck_error:.4f})" if cells is not None else "")
        method = f"{folds}-fold blocked cross-validation of the Chapman-Kolmogorov test"
    elif criterion == "window":
        reason = (f"{best.states} at lag {best.lag:g} s had the exact RTD closest to the one "
                  f"observed over the fitting window {a:g}-{b:g} s (MD {best.md_rtd:.3g}, PD "
                  f"E(RT) {best.pd_rt_mean:+.1f} %, SD(RT) {best.pd_rt_sd:+.1f} %")
        reason += (f"; cells: MD {cells.md_rtd:.3g}, {cells.pd_rt_mean:+.1f} %, "
                   f"{cells.pd_rt_sd:+.1f} %)" if cells is not None else ")")
        method = "the RTD over the fitting window"
    else:
        reason = (f"{best.states} at lag {best.lag:g} s had the lowest score {best.score:.3g} "
                  f"in {folds}-fold blocked cross-validation over {a:g}-{b:g} s (mean PD "
                  f"E(RT) {best.pd_rt_mean:+.1f} %, SD(RT) {best.pd_rt_sd:+.1f} %, MD "
                  f"{best.md_rtd:.3g}")
        reason += (f"; cells: {cells.pd_rt_mean:+.1f} %, {cells.pd_rt_sd:+.1f} %, MD "
                   f"{cells.md_rtd:.3g}, score {cells.score:.3g})" if cells is not None else ")")
        method = f"{folds}-fold blocked cross-validation of the RTD"
    if criterion != "ck" and direction == "down":
        reason += ("; residences counted downward, as the solids' net flow over the fitting "
                   "window runs")
    selection = {"method": method,
                 "blocks": [list(x) for x in judged],
                 "observed": [{"rt_mean": o.mean, "rt_sd": o.sd, "rt_count": o.count}
                              for o in observed],
                 "direction": direction,
                 "estimator": estimator, "chosen": {"states": best.states, "lag": best.lag},
                 "units": {"pd_rt_mean": tolerance_mean, "pd_rt_sd": tolerance_sd},
                 "reason": reason, "candidates": [c.as_dict() for c in final]}
    return model.with_selection(selection)


def _held_out_ck_error(block: DiscreteTrajectories, matrix: np.ndarray, times: np.ndarray
                       ) -> float:
    """Mean |P_model(A -> B, t) - P_observed(A -> B, t)| over the coarse groups (height
    thirds x core/annulus) and ``times`` (s) in the held-out ``block``. Every time uses the
    same start frames (those at least the longest time before the block's end), and the
    model starts from the occupancy of its states in each group there (as :func:`ck_test`);
    NaN when the block is shorter than the longest time."""
    import scipy.sparse as sp

    from cfbmarkov.markov.diagnostics import (core_annulus, group_labels, height_bands,
                                              product_groups)

    space, lag, lag_frames = block.state_space, block.lag, block.lag_frames
    block_states = block.states
    steps = np.rint(np.asarray(times, dtype=np.float64) / lag).astype(np.int64)
    if steps.min() < 1 or np.any(np.abs(steps * lag - times) > 1e-9):
        return math.nan                     # the times are not whole multiples of this lag
    n_start = block_states.shape[0] - int(steps.max()) * lag_frames
    if n_start <= 0:
        return math.nan
    _, cell_label = group_labels(space, product_groups(height_bands(space, 3),
                                                       core_annulus(space)))
    state_group = cell_label[space.cell_of_state]
    g, s = int(state_group.max()) + 1, space.n_states
    labels = state_group[block_states]
    member = np.zeros((s, g))
    member[np.arange(s), state_group] = 1.0
    occupancy = np.bincount(block_states[:n_start].ravel(), minlength=s).astype(np.float64)
    start_distribution = occupancy[:, None] * member                       # [S, G]
    mass = start_distribution.sum(axis=0, keepdims=True)
    x = np.divide(start_distribution, mass, out=np.zeros_like(start_distribution),
                  where=mass > 0)
    transposed = sp.csr_matrix(matrix.T)
    errors, done = [], 0
    for k in np.sort(steps):
        for _ in range(int(k) - done):
            x = transposed @ x                         # each group's distribution, k lags on
        done = int(k)
        shift = int(k) * lag_frames
        pairs = np.bincount((labels[:n_start] * g + labels[shift:shift + n_start]).ravel(),
                            minlength=g * g).reshape(g, g).astype(np.float64)
        n_a = pairs.sum(axis=1)
        ok = n_a > 0
        predicted = (member.T @ x).T                   # [G from, G to]
        errors.append(np.abs(predicted[ok] - pairs[ok] / n_a[ok, None]).mean())
    return float(np.mean(errors))


def parse_model_name(name: str) -> tuple[str, str]:
    """A model's name in a reproduction, as (state space, estimator).

    ``paper`` and ``mle`` are the paper's cells with that estimator, ``auto`` is
    :func:`select_model`, and ``STATES`` or ``STATES:ESTIMATOR`` names a state space
    (estimator ``mle`` by default).

    Parameters
    ----------
    name : str
        The model's name.

    Returns
    -------
    states : str
        A name of :data:`~cfbmarkov.markov.spaces.STATE_SPACES`, or ``auto``.
    estimator : str
        ``paper`` or ``mle``.

    Raises
    ------
    InputError
        For an unknown state space or estimator.
    """
    from cfbmarkov.markov.estimate import ESTIMATORS
    from cfbmarkov.markov.spaces import STATE_SPACES

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
                lag: float, coherent: bool = False):
    """Fit the model ``name`` (see :func:`parse_model_name`) on ``window`` of ``data``.

    Parameters
    ----------
    name : str
        The model's name (``paper``, ``mle``, ``auto``, ``STATES[:ESTIMATOR]``).
    data : str, os.PathLike or Trajectories
        The trajectory file, by path or open.
    window : tuple of float
        The fitting window (A, B) in s.
    columns, rows : int
        The cell grid m x n.
    lag : float
        The lag (s), a whole multiple of the frame interval.
    coherent : bool, optional
        Also fit the coherence of the moves (:mod:`cfbmarkov.markov.coherence`).

    Returns
    -------
    MarkovModel

    Raises
    ------
    InputError
        For an unknown name, or a file, window or lag that does not fit (and as
        :func:`select_model` for ``auto``).
    """
    states, estimator = parse_model_name(name)
    if states == "auto":
        return select_model(data, window=window, columns=columns, rows=rows, lag=lag,
                            estimator=estimator, coherent=coherent)
    with opened(data) as traj:
        space = state_space_from_name(states, columns, rows, traj.width, traj.height)
        return fit_model(traj, space, lag, window, estimator, coherent=coherent)


__all__ = ["DEFAULT_LAG_MULTIPLES", "DEFAULT_STATES", "CandidateScore", "fit_by_name",
           "parse_model_name", "select_model"]
