"""Propagation of a fitted model's state vector (paper Eq. 5-6) and the batch-injection maps
(Eq. 8, the paper's Fig. 4-7): S(t + lag) = S(t) P, one S x S product per lag.

References
----------
Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025), doi:10.3390/pr13030614.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.limits import MAX_STEPS, check_memory

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel


def propagate(model: "MarkovModel", initial, steps: int, outflow: bool = False) -> np.ndarray:
    """State vectors from ``initial`` by S(t + lag) = S(t) P, lag by lag.

    With ``outflow`` the transitions up through the top are taken out, so the total
    mass is the fraction still in the riser (a batch leaving through the outlet). An
    open riser's model always propagates by its absorbing matrix Q = diag(1 - r) P:
    what leaves through the outlet is gone.

    Parameters
    ----------
    model : MarkovModel
    initial : array_like, shape (S,)
        The state vector S(0) (e.g. :meth:`StateSpace.inlet_distribution
        <cfbmarkov.markov.states.StateSpace.inlet_distribution>`).
    steps : int
        Number of lags to propagate.
    outflow : bool, optional
        Remove the mass that passes up through the top.

    Returns
    -------
    ndarray of float64, shape (steps + 1, S)
        S(k lag) for k = 0 .. steps; row 0 is ``initial``.

    Raises
    ------
    InputError
        If ``initial`` does not have shape (S,) or holds a negative or non-finite entry, or
        ``steps`` is not a whole number >= 0.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 5-6).
    """
    try:
        if np.asarray(initial).dtype.kind not in "biuf":    # text or objects
            raise TypeError
        s0 = np.asarray(initial, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"initial distribution {initial!r}: probabilities per state, "
                         f"({model.n_states},) numbers") from None
    if s0.shape != (model.n_states,):
        raise InputError(f"initial distribution has shape {s0.shape}, expected ({model.n_states},)")
    if not (np.isfinite(s0).all() and (s0 >= 0).all()):
        raise InputError("initial distribution: finite, non-negative probabilities (or "
                         "masses) per state")
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
        raise InputError(f"steps {steps!r}: the number of lags to propagate, a whole number "
                         ">= 0")
    if model.open_flow is not None:
        p = model.absorbing_matrix
    elif outflow:
        p = model.transition_matrix * (1.0 - model.up_fraction)
    else:
        p = model.transition_matrix
    out = np.empty((int(steps) + 1, model.n_states))
    out[0] = s0
    for k in range(1, int(steps) + 1):   # one S x S product per lag, not per particle
        out[k] = out[k - 1] @ p
    return out


def batch_injection_maps(model: "MarkovModel", times: Sequence[float], outflow: bool = False
                         ) -> np.ndarray:
    """Eq. (8): where a batch fed evenly over the inlet cells at t = 0 is at ``times``.

    Parameters
    ----------
    model : MarkovModel
    times : sequence of float
        Times (s) after the injection, whole multiples of the lag.
    outflow : bool, optional
        Remove the mass that leaves up through the top (see :func:`propagate`).

    Returns
    -------
    ndarray of float64, shape (len(times), rows, columns)
        Probability per cell at each time; row 0 is the bottom (the paper's Fig. 4-7).

    Raises
    ------
    InputError
        If a time is negative or not a whole multiple of the lag.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 5-6 and Eq. 8).
    """
    if isinstance(times, (str, bytes)) or np.ndim(times) != 1 or not len(times):
        raise InputError(f"times {times!r}: a sequence of one or more times after the "
                         "injection (s), e.g. [0.05, 0.1]")
    steps = [model.steps_for(t) for t in times]
    last = max(steps, default=0)
    if last > MAX_STEPS:
        raise InputError(f"time {max(times):g} s is {last} lags of {model.lag:g} s, more than "
                         f"{MAX_STEPS} to propagate; give earlier --times")
    check_memory(8.0 * (last + 1) * model.n_states, f"maps up to {max(times):g} s "
                 f"({last} lags x {model.n_states} states)", "give earlier --times")
    history = propagate(model, model.state_space.inlet_distribution(), max(steps, default=0),
                       outflow=outflow)
    return model.state_space.cell_maps(history[steps])
