"""The automatic choice run step by step (:func:`select_model`), and the models named in a
reproduction (:func:`parse_model_name`, :func:`fit_by_name`).

:func:`select_model` cuts the fitting window into its judged blocks
(:mod:`~cfbmarkov.markov.select.blocks`), judges and scores every candidate by the criterion
(:mod:`~cfbmarkov.markov.select.criteria`, :mod:`~cfbmarkov.markov.select.candidates`), forms
the best one from its counts and stores the selection record
(:mod:`~cfbmarkov.markov.select.record`) in it. The method is described in
:mod:`cfbmarkov.markov.select`.
"""

from __future__ import annotations

import math
import numbers
from typing import Sequence

from cfbmarkov.errors import InputError
from cfbmarkov.frame_times import window_pair
from cfbmarkov.markov.discrete import DiscreteTrajectories
from cfbmarkov.markov.counting import count_transitions
from cfbmarkov.markov.estimate import ESTIMATORS, estimator_from_name, fit_model
from cfbmarkov.markov.select.blocks import judged_blocks
from cfbmarkov.markov.select.candidates import (best_candidate, candidate_spaces,
                                                judge_candidates, read_window_frames,
                                                score_candidates)
from cfbmarkov.markov.select.criteria import criterion_for
from cfbmarkov.markov.select.record import kept_cells_record, selection_record
from cfbmarkov.markov.spaces import STATE_SPACES, state_space_from_name
from cfbmarkov.trajectories import opened

#: state spaces tried by default (names of
#: :func:`~cfbmarkov.markov.spaces.state_space_from_name`)
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


def select_model(data, *, window: tuple[float, float], columns: int, rows: int, lag: float,
                 states: Sequence[str] = DEFAULT_STATES,
                 lag_multiples: Sequence[int] = DEFAULT_LAG_MULTIPLES,
                 estimator: str = "mle", folds: int = 3, criterion: str = "auto",
                 coherent: bool = False):
    """Choose, fit on ``window`` and return the best model (see :mod:`cfbmarkov.markov.select`).

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
        blocked cross-validation (``rtd``), by the held-out Chapman-Kolmogorov error
        (``ck``), or ``auto``: ``window`` where the window holds at least
        :data:`cfbmarkov.markov.select.blocks.MIN_RESIDENCES` residences, else ``ck``.
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
    from cfbmarkov.limits import check_finite

    lag = check_finite(lag, "lag", "s", positive=True)
    if criterion not in ("auto", "rtd", "ck", "window"):
        raise InputError(f"auto: unknown criterion '{criterion}' (window, rtd, ck or auto)")
    if isinstance(folds, bool) or not isinstance(folds, numbers.Integral) or folds < 2:
        raise InputError(f"auto: folds={folds!r}; cross-validation needs a whole number of "
                         "at least 2, e.g. folds=3")
    folds = int(folds)
    if isinstance(data, (list, tuple)):
        raise InputError("select_model takes one run; several runs of one case are chosen "
                         "on pooled by select_pooled(runs, windows=..., ...) (what `fit A.h5 "
                         "B.h5 --states auto` does)")
    a, b = window_pair(window)
    with opened(data) as traj:
        # the frames the window holds: its blocks, and the RTD the candidates are judged
        # against, are of that length (as the chosen model's window is)
        a, b = traj.held(a, b)
        fitting = judged_blocks(traj, (a, b), lag, lag_multiples, folds, criterion,
                                face_band=traj.height / rows)
        judge = criterion_for(fitting, lag)
        spaces = candidate_spaces(traj, states, lag_multiples, lag, columns, rows)
        # the window's frames are read once; every candidate is discretised on them
        frames = read_window_frames(traj, (a, b), spaces)
        judged, discrete_of = judge_candidates(traj, frames, spaces, judge, estimator)
        scores = score_candidates(judged, judge, lag)
        usable = [c for c in scores if math.isfinite(c.score)]
        if not usable and judge.name == "ck":
            space = state_space_from_name("cells", columns, rows, traj.width, traj.height)
            model = fit_model(traj, space, lag, (a, b), estimator, coherent=coherent)
            return model.with_selection(kept_cells_record(judge, estimator, scores, lag))
        if not usable:
            raise InputError("auto: no candidate state space could be fitted: "
                             + "; ".join(f"{c.states} lag {c.lag:g}: {c.error}" for c in scores))
        best = best_candidate(scores)
        model = _fit_chosen(traj, discrete_of[(best.states, best.lag)], best.lag, estimator,
                            coherent)
    return model.with_selection(selection_record(judge, estimator, best, scores, lag))


def _fit_chosen(traj, chosen: DiscreteTrajectories, lag: float, estimator: str,
                coherent: bool):
    """The chosen candidate's model, formed from its states over the whole window."""
    counts = count_transitions(chosen, frame_average=estimator == "paper")
    model = estimator_from_name(estimator, chosen.state_space, lag).fit_counts(
        counts, window=chosen.window, source=traj.path, adopt=True)   # counted for it alone
    if coherent:
        from cfbmarkov.markov.coherence import calibrate_coherence

        if chosen.boundary.is_open:
            raise InputError("coherent moves (--coherent) are fitted for periodic risers "
                             "only yet; fit an open riser without it")
        model = model.with_coherence(calibrate_coherence(model, chosen))
    return model
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


def fit_pooled_by_name(name: str, runs: Sequence, *, window: tuple[float, float], columns: int,
                       rows: int, lag: float, coherent: bool = False):
    """Fit the model ``name`` on ``window`` of several runs of one case, their transitions
    pooled (:mod:`cfbmarkov.markov.pooling`), as :func:`fit_by_name` does on one run.

    ``auto`` chooses the state space and lag on all the runs' windows pooled and fits the
    chosen one on all of them (:func:`~cfbmarkov.markov.select.pooled.select_pooled`, as
    ``fit a.h5 b.h5 --states auto``).

    Parameters
    ----------
    name : str
        The model's name (``paper``, ``mle``, ``auto``, ``STATES[:ESTIMATOR]``).
    runs : sequence of Trajectories
        Open trajectory files of one case (e.g. an ensemble's members).
    window : tuple of float
        The fitting window (A, B) in s, the same in every run.
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
        As :func:`fit_by_name`, and for runs that cannot be pooled
        (:func:`~cfbmarkov.markov.pooling.check_runs_match`).
    """
    from cfbmarkov.markov.pooling import discretize_runs

    if not runs:
        raise InputError("no runs to fit")
    states, estimator = parse_model_name(name)
    first = runs[0]
    if states == "auto":
        from cfbmarkov.markov.select.pooled import select_pooled

        return select_pooled(runs, windows=[tuple(window)] * len(runs), columns=columns,
                             rows=rows, lag=lag, states=DEFAULT_STATES,
                             lag_multiples=DEFAULT_LAG_MULTIPLES, estimator=estimator,
                             coherent=coherent)
    space = state_space_from_name(states, columns, rows, first.width, first.height)
    discrete = discretize_runs(runs, space, lag, [tuple(window)])
    return estimator_from_name(estimator, space, lag, False, coherent).fit(discrete)


__all__ = ["DEFAULT_LAG_MULTIPLES", "DEFAULT_STATES", "fit_by_name", "fit_pooled_by_name",
           "parse_model_name", "select_model"]
