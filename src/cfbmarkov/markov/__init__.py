"""Markov chain models: state spaces, estimators, the fitted model, Monte Carlo, exact RTD."""

from cfbmarkov.markov.estimate import (
    ESTIMATORS,
    MaximumLikelihoodEstimator,
    PaperEstimator,
    TransitionCounts,
    TransitionEstimator,
    count_transitions,
    discrete_trajectories,
    estimator_from_name,
)
from cfbmarkov.markov.model import MarkovModel
from cfbmarkov.markov.rtd import ResidenceTimeDistribution, exact_rtd
from cfbmarkov.markov.states import CellGrid, StateSpace, cell_index, place_in_cells

__all__ = [
    "CellGrid", "ESTIMATORS", "MarkovModel", "MaximumLikelihoodEstimator", "PaperEstimator",
    "ResidenceTimeDistribution", "StateSpace", "TransitionCounts", "TransitionEstimator",
    "cell_index", "count_transitions", "discrete_trajectories", "estimator_from_name",
    "exact_rtd", "place_in_cells",
]
