"""Markov chain models: state spaces, discrete trajectories, estimators, the fitted model,
Monte Carlo and the exact residence-time distribution.

The data flow one way: a trajectory file -> :func:`discretize` (states of one window, in
memory) -> an estimator's ``fit`` -> an immutable :class:`MarkovModel` that answers
questions (propagation, exact RTD, Monte Carlo, predictions written as trajectory files).
"""

# Each name is imported from its module on first use: a verb that loads a model and asks
# for its RTD does not pay for the estimators, the discretisation and their kernels.
_LAZY = {
    **dict.fromkeys(["ABSENT", "DiscreteTrajectories", "WindowFrames", "discretize",
                     "discretize_frame", "read_frames"], "cfbmarkov.markov.discrete"),
    **dict.fromkeys(["TransitionCounts", "count_transitions"], "cfbmarkov.markov.counting"),
    **dict.fromkeys(["ESTIMATORS", "MaximumLikelihoodEstimator", "PaperEstimator",
                     "TransitionEstimator", "estimator_from_name", "fit_model"],
                    "cfbmarkov.markov.estimate"),
    "MarkovModel": "cfbmarkov.markov.model",
    **dict.fromkeys(["ResidenceTimeDistribution", "exact_rtd"],
                    "cfbmarkov.markov.first_passage"),
    "cell_index": "cfbmarkov.markov.cells",
    **dict.fromkeys(["DirectionCells", "SecondOrderCells"], "cfbmarkov.markov.memory_states"),
    **dict.fromkeys(["DirectionRegimeCells", "RegimeCells"], "cfbmarkov.markov.regimes"),
    **dict.fromkeys(["STATE_SPACES", "state_space_from_attrs", "state_space_from_name"],
                    "cfbmarkov.markov.spaces"),
    **dict.fromkeys(["CellGrid", "StateSpace", "place_in_cells"], "cfbmarkov.markov.states"),
    **dict.fromkeys(["FineVelocityCells", "VelocityCells"], "cfbmarkov.markov.velocity_states"),
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'cfbmarkov.markov' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_LAZY])


__all__ = [
    "ABSENT", "CellGrid", "DirectionCells", "DirectionRegimeCells", "DiscreteTrajectories",
    "ESTIMATORS", "FineVelocityCells", "MarkovModel",
    "MaximumLikelihoodEstimator", "PaperEstimator", "RegimeCells", "ResidenceTimeDistribution",
    "STATE_SPACES", "SecondOrderCells", "StateSpace", "TransitionCounts", "TransitionEstimator",
    "VelocityCells", "WindowFrames", "cell_index", "count_transitions", "discretize",
    "discretize_frame", "estimator_from_name", "exact_rtd", "fit_model", "place_in_cells",
    "read_frames", "state_space_from_attrs", "state_space_from_name",
]
