"""The candidates (state space x lag): fitted on the fitting window, judged and scored.

The window's frames are read once (:func:`read_window_frames`); every candidate is
discretised on them, counted block by block from memory and judged on each judged block by
the criterion (:func:`judge_candidates`); :func:`score_candidates` turns each candidate's
rows into its score, relative to the paper's cells.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple, Sequence

import numpy as np

from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.discrete import DiscreteTrajectories, WindowFrames, read_frames
from cfbmarkov.markov.counting import count_transitions
from cfbmarkov.markov.estimate import estimator_from_name
from cfbmarkov.markov.select.criteria import Criterion
from cfbmarkov.markov.select.record import CandidateScore
from cfbmarkov.markov.spaces import state_space_from_name
from cfbmarkov.markov.states import StateSpace


class JudgedCandidate(NamedTuple):
    """One candidate's numbers on the judged blocks.

    Attributes
    ----------
    states : str
        Name of the state space.
    lag : float
        The candidate's lag, s.
    n_states : int
        Number of states S (fitted to the window where it could be).
    table : ndarray of float64, shape (K, C), or None
        One row per judged block (:meth:`Criterion.judge`); None where the candidate was
        not judged.
    error : str
        Why it was not judged ("" if it was).
    visited : int or None
        States occupied in some frame of the window; None where it was not discretised.
    """

    states: str
    lag: float
    n_states: int
    table: np.ndarray | None
    error: str
    visited: int | None = None


def candidate_spaces(traj, states: Sequence[str], lag_multiples: Sequence[int], lag: float,
                     columns: int, rows: int) -> dict[tuple[str, float], StateSpace]:
    """Every candidate's state space, by (name, lag in s), names first.

    Parameters
    ----------
    traj : Trajectories
        The open trajectory file (its width and height).
    states : sequence of str, or str
        Names of the state spaces (one name: that one alone).
    lag_multiples : sequence of int
        Candidate lags, in multiples of ``lag``.
    lag : float
        The base lag, s.
    columns, rows : int
        The cell grid m x n.

    Returns
    -------
    dict

    Raises
    ------
    InputError
        For an unknown state space name or a grid that does not fit.
    """
    if isinstance(states, str):         # one name, not its letters
        states = [states]
    return {(name, lag * int(m)): state_space_from_name(
        name, columns, rows, traj.width, traj.height)
        for name in states for m in lag_multiples}


def read_window_frames(traj, window: tuple[float, float],
                       spaces: dict[tuple[str, float], StateSpace]) -> WindowFrames:
    """The fitting window's frames, read once for every candidate: with the history the
    longest memory needs, and velocities where a candidate needs them.

    Parameters
    ----------
    traj : Trajectories
        The open trajectory file.
    window : tuple of float
        The fitting window (A, B), s.
    spaces : dict
        The candidates (:func:`candidate_spaces`).

    Returns
    -------
    WindowFrames
    """
    history = max(space.memory_lags * traj.lag_frames(lag) for (_, lag), space in spaces.items())
    return read_frames(traj, window, history, short_history="skip",
                       velocities=traj.has_velocity and any(
                           space.needs_velocity for space in spaces.values()))


def judge_candidates(traj, frames: WindowFrames, spaces: dict[tuple[str, float], StateSpace],
                     criterion: Criterion, estimator: str
                     ) -> tuple[list[JudgedCandidate], dict[tuple[str, float],
                                                            DiscreteTrajectories]]:
    """Discretise, count and judge every candidate on the judged blocks.

    A candidate whose fitted states equal an earlier one's (at the same lag) is listed, not
    judged again; one that cannot be fitted or judged is listed with the error.

    Parameters
    ----------
    traj : Trajectories
        The open trajectory file.
    frames : WindowFrames
        The fitting window's frames (:func:`read_window_frames`).
    spaces : dict
        The candidates (:func:`candidate_spaces`).
    criterion : Criterion
        The criterion, with the judged blocks.
    estimator : {"mle", "paper"}
        The estimator of every candidate.

    Returns
    -------
    judged : list of JudgedCandidate
        Every candidate, in the order of ``spaces``.
    discrete_of : dict
        The judged candidates' states over the window, by (name, lag).
    """
    fitting = criterion.fitting
    judged, discrete_of = [], {}
    for (name, lag), space in spaces.items():
        visited = None
        try:
            discrete = frames.discretize(space, traj.lag_frames(lag))
            space = discrete.state_space          # fitted to the window (bins, sub-rows)
            visited = visited_states(discrete)
            est = estimator_from_name(estimator, space, lag)
            same = next((other for (other, t), d in discrete_of.items()
                         if t == lag and d.state_space.n_states == space.n_states
                         and np.array_equal(d.states, discrete.states)), None)
            if same is not None:       # fitted to the states of an earlier candidate
                judged.append(JudgedCandidate(name, lag, discrete.state_space.n_states, None,
                                              f"the same states as {same} on this window",
                                              visited))
                continue
            discrete_of[(name, lag)] = discrete
            # sparse counts and chains: the work grows with the transitions, not S x S
            # (counted block by block also for the whole window: three block counts
            # took 0.07 s where one of the window took 0.10 s at paper scale)
            parts = [count_transitions(discrete.block(*block),
                                       frame_average=estimator == "paper", sparse=True)
                     for block in fitting.blocks]
            rows = [criterion.judge(discrete, k, est, criterion.training(parts, k), lag)
                    for k in range(len(fitting.judged))]
        except (InputError, CfbmarkovError) as exc:
            judged.append(JudgedCandidate(name, lag, space.n_states, None, str(exc), visited))
            continue
        judged.append(JudgedCandidate(name, lag, space.n_states, np.asarray(rows), "", visited))
    return judged, discrete_of


def visited_states(*discrete: DiscreteTrajectories) -> int:
    """How many states are occupied in some frame of any of ``discrete`` (several runs on
    one state space: the union; absent particles aside).

    Parameters
    ----------
    *discrete : DiscreteTrajectories
        One or more runs' states on the same state space (at least one).

    Returns
    -------
    int
        The states occupied in any frame of any run, at most the state space's S.
    """
    occupied = np.zeros(discrete[0].state_space.n_states, dtype=bool)
    for d in discrete:
        states = d.states.ravel()
        occupied[states[states >= 0]] = True
    return int(np.count_nonzero(occupied))


def score_candidates(judged: list[JudgedCandidate], criterion: Criterion, lag: float
                     ) -> list[CandidateScore]:
    """Every candidate's score, relative to the paper's cells at the base lag.

    Parameters
    ----------
    judged : list of JudgedCandidate
        The candidates (:func:`judge_candidates`).
    criterion : Criterion
        The criterion that judged them.
    lag : float
        The base lag, s.

    Returns
    -------
    list of CandidateScore
        In the order of ``judged``; score inf (and the error) where a candidate was not
        judged or a block could not judge it.
    """
    column = criterion.column
    cells = next((float(c.table[:, column].mean()) for c in judged
                  if c.states == "cells" and c.lag == lag and c.table is not None), math.nan)
    reference = cells if math.isfinite(cells) and cells > 0 else 1.0
    scores = []
    for c in judged:
        if c.table is None or not np.all(np.isfinite(c.table[:, column])):
            scores.append(CandidateScore(c.states, c.lag, c.n_states, math.nan, math.nan,
                                         math.nan, math.nan, math.nan, math.inf,
                                         c.error or "no held-out comparison",
                                         visited=c.visited))
            continue
        scores.append(dataclasses.replace(
            criterion.score(c.states, c.lag, c.n_states, c.table, reference),
            visited=c.visited))
    return scores


def best_candidate(scores: list[CandidateScore]) -> CandidateScore | None:
    """The candidate to choose: the lowest score among those judged, leaving out a state
    space that more than :data:`~cfbmarkov.markov.selection_table.UNVISITED_LIMIT` of whose
    states the window never visits (its chain rests on the few states seen, and the chosen
    model would warn that its space is too fine), unless every judged candidate is such.

    Parameters
    ----------
    scores : list of CandidateScore
        Every candidate (:func:`score_candidates`).

    Returns
    -------
    CandidateScore or None
        None where no candidate was judged.
    """
    from cfbmarkov.markov.selection_table import UNVISITED_LIMIT, too_sparse

    usable = [c for c in scores if math.isfinite(c.score)]
    filled = [c for c in usable if not too_sparse(c, UNVISITED_LIMIT)]
    return min(filled or usable, key=lambda c: c.score, default=None)
