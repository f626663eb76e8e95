"""The automatic choice on several runs of one case (``fit a.h5 b.h5 --states auto``): the
candidates judged on the pooled windows, as on one run of their concatenated flow.

Each run's window is cut into its ``folds`` blocks (:func:`~cfbmarkov.markov.select.blocks.
judged_blocks`); the blocks of all runs, in run order, are the blocks of the pooled sample
and each candidate is counted on each of them. The criterion is resolved on the pooled
residences (``window`` where all windows together hold at least ``MIN_RESIDENCES``), and
judges as on one run:

- ``window``: the candidate fitted on all the runs' counts, its exact RTD seen through
  each run's window against that window's observed RTD, one row per run (the score the
  mean of their MD);
- ``rtd`` and ``ck``: blocked cross-validation over all the runs' blocks (each held out in
  turn, fitted on all the others, of every run).

Residences are counted in the pooled windows' net solids flow direction (the sum of the
runs' net passes). A space fitted to its window (velocity bins, regime edges) is fitted on
the first run's window and applied as it is to the others (as
:func:`~cfbmarkov.markov.pooling.discretize_runs` does).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.counting import count_transitions
from cfbmarkov.markov.discrete import held_window
from cfbmarkov.markov.estimate import estimator_from_name
from cfbmarkov.markov.pooling import check_runs_distinct, check_runs_match, run_windows
from cfbmarkov.markov.select.blocks import MIN_RESIDENCES, JudgedBlocks, _open_riser_criterion
from cfbmarkov.markov.select.candidates import (JudgedCandidate, best_candidate,
                                                candidate_spaces, read_window_frames,
                                                score_candidates, visited_states)
from cfbmarkov.markov.select.criteria import criterion_for
from cfbmarkov.markov.select.record import kept_cells_record, selection_record
from cfbmarkov.markov.spaces import state_space_from_name
from cfbmarkov.observed.residence import ResidenceTimes, net_passes, residence_times


def pooled_blocks(runs, windows, lag: float, lag_multiples: Sequence[int], folds: int,
                  criterion: str, face_band: float | None = None
                  ) -> tuple[JudgedBlocks, list[int]]:
    """The judged blocks of several runs' windows as one sample.

    Parameters
    ----------
    runs : sequence of Trajectories
        Open runs of one case.
    windows : sequence of (float, float)
        One window per run (s).
    lag, lag_multiples, folds, criterion, face_band
        As :func:`~cfbmarkov.markov.select.blocks.judged_blocks`.

    Returns
    -------
    JudgedBlocks
        ``window`` the first run's, ``blocks`` every run's in run order, ``judged`` the
        runs' windows (``window`` criterion) or the blocks, ``whole`` the pooled residences.
    list of int
        The run of each judged stretch.

    Raises
    ------
    InputError
        As :func:`~cfbmarkov.markov.select.blocks.judged_blocks`, on the pooled residences.
    """
    step = lag * max(int(m) for m in lag_multiples)
    blocks, block_run = [], []
    for r, (run, (a, b)) in enumerate(zip(runs, windows)):
        n_steps = int(math.floor((b - a) / step + 1e-9))
        if n_steps < 2 * folds:
            raise InputError(f"auto: the fitting window {a:g}-{b:g} s of {run.path} is too "
                             f"short to split into {folds} blocks of whole lags")
        edges = [a + step * round(k * n_steps / folds) for k in range(folds + 1)]
        for k in range(folds):
            run.window(edges[k], edges[k + 1])
            blocks.append((float(edges[k]), float(edges[k + 1])))
            block_run.append(r)
    lag_frames = runs[0].lag_frames(lag)
    direction = "up" if sum(net_passes(run, w) for run, w in zip(runs, windows)) >= 0 \
        else "down"
    kwargs = {"use_events": False, "lag_frames": lag_frames, "direction": direction,
              "face_band": face_band}
    wholes = [residence_times(run, w, **kwargs) for run, w in zip(runs, windows)]
    whole = ResidenceTimes(np.concatenate([w.samples for w in wholes]), False,
                           tuple(windows[0]))
    criterion = _open_riser_criterion(runs[0].boundary.is_open, criterion)
    if criterion == "auto":
        criterion = "window" if whole.count >= MIN_RESIDENCES else "ck"
    if criterion == "window":
        if whole.count < MIN_RESIDENCES:
            raise InputError(f"auto: the fitting windows hold only {whole.count} residence "
                             "times, too few to judge by the RTD")
        judged, observed, judged_run = list(windows), wholes, list(range(len(runs)))
    else:
        judged, judged_run = blocks, block_run
        observed = [residence_times(runs[r], blk, **kwargs) for blk, r in zip(blocks, block_run)]
    fitting = JudgedBlocks(tuple(windows[0]), criterion, blocks, judged, observed, whole,
                           direction, lag_frames)
    if criterion == "rtd" and fitting.fewest < MIN_RESIDENCES:
        raise InputError(f"auto: a block holds only {fitting.fewest} residence times, too few "
                         "to judge by the RTD")
    return fitting, judged_run


def select_pooled(runs, *, windows, columns: int, rows: int, lag: float,
                  states: Sequence[str], lag_multiples: Sequence[int], estimator: str = "mle",
                  folds: int = 3, criterion: str = "auto", coherent: bool = False):
    """Choose the state space and lag on several runs' windows pooled, and fit the chosen
    one on all of them (the module docstring).

    Parameters
    ----------
    runs : sequence of Trajectories
        Open runs of one case (checked as :mod:`cfbmarkov.markov.pooling` checks them).
    windows : sequence of (float, float)
        One window for all runs, or one per run (s).
    columns, rows, lag, states, lag_multiples, estimator, folds, criterion, coherent
        As :func:`~cfbmarkov.markov.select.choice.select_model`.

    Returns
    -------
    MarkovModel
        Fitted on all the runs' windows (``source`` the runs, ``run_windows`` their
        windows), its ``selection`` the candidates' scores.

    Raises
    ------
    InputError
        For runs that cannot be pooled, windows too short for the blocks, too few
        residences for the criterion, or no candidate that can be fitted.
    """
    check_runs_match(runs)
    windows = run_windows(windows, len(runs))
    check_runs_distinct(runs, windows)
    # the frames each window holds, which the blocks and the chosen model are of
    windows = [held_window(run, w) for run, w in zip(runs, windows)]
    fitting, judged_run = pooled_blocks(runs, windows, lag, lag_multiples, folds, criterion,
                                        face_band=runs[0].height / rows)
    judge = criterion_for(fitting, lag)
    spaces = candidate_spaces(runs[0], states, lag_multiples, lag, columns, rows)
    frames = [read_window_frames(run, w, spaces) for run, w in zip(runs, windows)]
    block_run = [r for r, w in enumerate(windows) for _ in range(len(fitting.blocks)
                                                                 // len(windows))]
    judged, discrete_of = [], {}
    for (name, cand_lag), space in spaces.items():
        visited = None
        try:
            first = frames[0].discretize(space, runs[0].lag_frames(cand_lag))
            fitted = first.state_space
            data = [first] + [f.discretize(fitted, run.lag_frames(cand_lag))
                              for f, run in zip(frames[1:], runs[1:])]
            visited = visited_states(*data)     # in any run's window
            same = next((other for (other, t), ds in discrete_of.items()
                         if t == cand_lag and ds[0].state_space.n_states == fitted.n_states
                         and all(np.array_equal(d.states, e.states) for d, e in zip(ds, data))),
                        None)
            if same is not None:
                judged.append(JudgedCandidate(name, cand_lag, fitted.n_states, None,
                                              f"the same states as {same} on these windows",
                                              visited))
                continue
            discrete_of[(name, cand_lag)] = data
            est = estimator_from_name(estimator, fitted, cand_lag)
            parts = [count_transitions(data[r].block(*blk), frame_average=estimator == "paper",
                                       sparse=True)
                     for blk, r in zip(fitting.blocks, block_run)]
            table = [judge.judge(data[judged_run[k]], k, est, judge.training(parts, k),
                                 cand_lag) for k in range(len(fitting.judged))]
        except (InputError, CfbmarkovError) as exc:
            judged.append(JudgedCandidate(name, cand_lag, space.n_states, None, str(exc),
                                          visited))
            continue
        judged.append(JudgedCandidate(name, cand_lag, fitted.n_states, np.asarray(table), "",
                                      visited))
    scores = score_candidates(judged, judge, lag)
    usable = [c for c in scores if math.isfinite(c.score)]
    if not usable and judge.name == "ck":      # nothing judged: the paper's cells kept
        cells = state_space_from_name("cells", columns, rows, runs[0].width, runs[0].height)
        data = [f.discretize(cells, run.lag_frames(lag)) for f, run in zip(frames, runs)]
        return _fit_pooled(runs, windows, data, lag, estimator, coherent,
                           kept_cells_record(judge, estimator, scores, lag))
    if not usable:
        raise InputError("auto: no candidate state space could be fitted on the pooled "
                         "windows: " + "; ".join(f"{c.states} lag {c.lag:g}: {c.error}"
                                                 for c in scores))
    best = best_candidate(scores)
    record = selection_record(judge, estimator, best, scores, lag)
    record["reason"] += f"; judged on the windows of {len(runs)} runs pooled"
    return _fit_pooled(runs, windows, discrete_of[(best.states, best.lag)], best.lag,
                       estimator, coherent, record)


def _fit_pooled(runs, windows, data, lag: float, estimator: str, coherent: bool,
                record: dict):
    """The chosen candidate's model on all the runs' windows, with its selection record."""
    counts = count_transitions(data, frame_average=estimator == "paper")
    model = estimator_from_name(estimator, data[0].state_space, lag).fit_counts(
        counts, window=windows[0], source=[str(run.path) for run in runs], adopt=True,
        run_windows=windows)
    if coherent:
        from cfbmarkov.markov.coherence import calibrate_coherence

        if data[0].boundary.is_open:
            raise InputError("coherent moves (--coherent) are fitted for periodic risers "
                             "only yet; fit an open riser without it")
        model = model.with_coherence(calibrate_coherence(model, data))
    record["runs"] = [[str(run.path), list(w)] for run, w in zip(runs, windows)]
    return model.with_selection(record)


__all__ = ["pooled_blocks", "select_pooled"]
