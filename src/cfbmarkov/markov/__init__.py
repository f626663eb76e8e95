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
from cfbmarkov.markov.states import (
    STATE_SPACES,
    CellGrid,
    DirectionCells,
    PreviousCellCells,
    StateSpace,
    VelocityCells,
    cell_index,
    place_in_cells,
    state_space_from_name,
)

__all__ = [
    "CellGrid", "DirectionCells", "ESTIMATORS", "MarkovModel", "MaximumLikelihoodEstimator",
    "PaperEstimator", "PreviousCellCells", "ResidenceTimeDistribution", "STATE_SPACES",
    "StateSpace", "TransitionCounts", "TransitionEstimator", "VelocityCells", "cell_index",
    "count_transitions", "discrete_trajectories", "estimator_from_name", "exact_rtd",
    "place_in_cells", "state_space_from_name",
]
