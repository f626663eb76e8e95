"""Markov chain models: state spaces, discrete trajectories, estimators, the fitted model,
Monte Carlo and the exact residence-time distribution.

The data flow one way: a trajectory file -> :func:`discretize` (states of one window, in
memory) -> an estimator's ``fit`` -> an immutable :class:`MarkovModel` that answers
questions (propagation, exact RTD, Monte Carlo, predictions written as trajectory files).
"""

from cfbmarkov.markov.discrete import (
    ABSENT,
    DiscreteTrajectories,
    WindowFrames,
    discretize,
    discretize_frame,
    read_frames,
)
from cfbmarkov.markov.counting import TransitionCounts, count_transitions
from cfbmarkov.markov.estimate import (
    ESTIMATORS,
    MaximumLikelihoodEstimator,
    PaperEstimator,
    TransitionEstimator,
    estimator_from_name,
    fit_model,
)
from cfbmarkov.markov.model import MarkovModel
from cfbmarkov.markov.first_passage import ResidenceTimeDistribution, exact_rtd
from cfbmarkov.markov.cells import cell_index
from cfbmarkov.markov.memory_states import DirectionCells, SecondOrderCells
from cfbmarkov.markov.regimes import DirectionRegimeCells, RegimeCells
from cfbmarkov.markov.spaces import STATE_SPACES, state_space_from_attrs, state_space_from_name
from cfbmarkov.markov.states import CellGrid, StateSpace, place_in_cells
from cfbmarkov.markov.velocity_states import FineVelocityCells, VelocityCells

__all__ = [
    "ABSENT", "CellGrid", "DirectionCells", "DirectionRegimeCells", "DiscreteTrajectories",
    "ESTIMATORS", "FineVelocityCells", "MarkovModel",
    "MaximumLikelihoodEstimator", "PaperEstimator", "RegimeCells", "ResidenceTimeDistribution",
    "STATE_SPACES", "SecondOrderCells", "StateSpace", "TransitionCounts", "TransitionEstimator",
    "VelocityCells", "WindowFrames", "cell_index", "count_transitions", "discretize",
    "discretize_frame", "estimator_from_name", "exact_rtd", "fit_model", "place_in_cells",
    "read_frames", "state_space_from_attrs", "state_space_from_name",
]
