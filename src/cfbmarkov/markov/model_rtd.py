"""The exact residence-time distributions of a fitted :class:`~cfbmarkov.markov.model.MarkovModel`
(:meth:`MarkovModel.rtd <cfbmarkov.markov.model.MarkovModel.rtd>`): a periodic riser's from
passes up through the top (or down through the bottom, for a net downflow), an open
riser's from the inlet to the outlet, each computed once and kept in the model's cache.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from cfbmarkov.errors import InputError
from cfbmarkov.limits import (MAX_STEPS, check_finite, check_memory, check_rtd,
                              memory_limit, rtd_memory)
from cfbmarkov.markov.first_passage import (ResidenceTimeDistribution, drift_residence_time,
                                            exact_rtd, split_by_pass, window_rtd)

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel


#: bytes per lag and state that the RTD as a window sees it holds (the landings and the
#: exits per lag on the lap-deficit levels; measured about 35-39, 2026-12-07)
WINDOW_BYTES = 48


def model_rtd(model: "MarkovModel", window: float | None = None,
              direction: str | None = None, occupancy=None) -> ResidenceTimeDistribution:
    """Exact residence-time distribution of ``model`` (no sampling noise), cached in it.

    Parameters
    ----------
    model : MarkovModel
        The fitted model.
    window : float, optional
        Length (s) of an analysis window: the RTD as seen in it (None: the intrinsic RTD).
        A length between two whole numbers of lags is taken as the nearest, which the
        result's ``window`` gives.
    direction : {"up", "down"}, optional
        A periodic riser's residences from passes up through the top or down through the
        bottom (the pass fractions swapped); default the model's ``flow_direction``.
    occupancy : array_like of float, shape (S,), optional
        With ``window``, for a periodic riser: where the window's particles start (weights
        per state); default :func:`window_start_occupancy`.

    Returns
    -------
    ResidenceTimeDistribution
        The intrinsic RTD in the model's direction carries the model's ``uncertainty``.

    Raises
    ------
    InputError
        If ``window`` is not a positive finite time of at most
        :data:`~cfbmarkov.limits.MAX_STEPS` lags or needs more memory than there is
        (:data:`WINDOW_BYTES` a lag and state), or ``direction`` is neither up nor down.
    CfbmarkovError
        If the model has no transition through the boundary in ``direction`` (no residence
        ends), or no residence fits in ``window``.

    Notes
    -----
    See :func:`~cfbmarkov.markov.first_passage.exact_rtd` and ``docs/definitions.md``
    (Residence time).
    """
    if window is not None:
        window = check_finite(window, "window length", "s", positive=True)
        if window / model.lag > MAX_STEPS:
            raise InputError(f"window length {window:g} s is {window / model.lag:.3g} lags "
                             f"of {model.lag:g} s, more than {MAX_STEPS}; give a window "
                             f"length of at most {MAX_STEPS * model.lag:g} s")
        lags = window / model.lag
        # the RTD is of whole lags: a length between two is taken as the nearest, and the
        # result says so (not the length given)
        if abs(lags - round(lags)) > 1e-9 * max(lags, 1.0) and round(lags) >= 1:
            window = round(lags) * model.lag
            lags = float(round(lags))
        chain = rtd_memory(model.n_states)       # the model's exact RTD, where it counts
        fits = max(memory_limit() - chain, 0.0) / (WINDOW_BYTES * model.n_states) * model.lag
        check_memory(WINDOW_BYTES * lags * model.n_states + chain,
                     f"the RTD as a {window:g} s window sees it ({lags:.0f} lags x "
                     f"{model.n_states} states)" + (" with the model's exact RTD" if chain
                                                     else ""),
                     f"give a window length of at most {fits:.3g} s" if fits >= model.lag
                     else "fit the model on fewer --cells, or a state space with fewer "
                          "states per cell")
    elif not any(str(key).startswith("rtd") for key in model._cache):
        check_rtd(model.n_states)   # none computed yet: the exact RTD's peak memory, first
    cache = model._cache
    if model.open_flow is not None:
        return _with_uncertainty(model, _open_rtd(model, window), window)
    if direction is None:
        direction = model.flow_direction
    if direction not in ("up", "down"):
        raise InputError(f"residence direction {direction!r}: up or down")
    own = direction == model.flow_direction     # the direction the uncertainty is of
    if window is not None:
        return _periodic_window_rtd(model, window, direction, occupancy)
    if direction == "down":
        rtd = _down_rtd(model, window)
        return _with_uncertainty(model, rtd, window) if own else rtd
    if "rtd" not in cache:
        cache["rtd"] = exact_rtd(model.transition_matrix, model.up_fraction,
                                 model.down_fraction, model.lag,
                                 entry_flux=net_entry_flux(model))
    intrinsic = cache["rtd"]
    return _with_uncertainty(model, intrinsic) if own else intrinsic


def net_entry_flux(model: "MarkovModel", direction: str = "up") -> np.ndarray | None:
    """Observed net entries per state of residences in ``direction``: landings of the
    passes that end them minus departures of the passes the other way (a particle that
    falls out and comes back starts no new residence); what the exact RTD weights a
    reducible chain's closed classes by (:func:`~cfbmarkov.markov.first_passage.exact_rtd`).

    Parameters
    ----------
    model : MarkovModel
        A periodic riser's model (its pass counts).
    direction : {"up", "down"}, optional
        Residences ended by passes up through the top, or down through the bottom.

    Returns
    -------
    ndarray of float64, shape (S,), or None
        None where the entries do not add up to an inflow.
    """
    ends, back = ((model.counts_up, model.counts_down) if direction == "up"
                  else (model.counts_down, model.counts_up))
    flux = (ends.sum(axis=0) - back.sum(axis=1)).astype(np.float64)
    return flux if flux.sum() > 0 else None


def _with_uncertainty(model: "MarkovModel", rtd: ResidenceTimeDistribution,
                      window: float | None = None) -> ResidenceTimeDistribution:
    """The intrinsic RTD with the model's uncertainty attached (a windowed one as it is)."""
    if window is not None or model.uncertainty is None:
        return rtd
    return dataclasses.replace(rtd, uncertainty=model.uncertainty)


def window_start_occupancy(model: "MarkovModel", direction: str | None = None) -> np.ndarray:
    """Where a window's particles start, for the RTD it sees of a periodic riser's chain:
    the fitting window's particle-frames per state (the counts' row sums), or for a model
    given by its matrix alone the chain's stationary distribution (every state from which
    the boundary can be reached, alike, where that distribution lies in traps).

    Parameters
    ----------
    model : MarkovModel
    direction : {"up", "down"}, optional
        The boundary whose passes end a residence; default the model's ``flow_direction``.

    Returns
    -------
    ndarray of float64, shape (S,)
    """
    occupancy = np.asarray(model.counts.sum(axis=1), dtype=np.float64)
    if occupancy.sum() > 0:
        return occupancy
    stationary = np.asarray(model.stationary_distribution, dtype=np.float64)
    # a chain with traps holds its long run there, where no record can happen: then every
    # state from which the boundary can be reached, alike
    from cfbmarkov.markov.connectivity import states_reaching

    direction = model.flow_direction if direction is None else direction
    ends = model.up_fraction if direction == "up" else model.down_fraction
    exits = np.flatnonzero((np.asarray(model.transition_matrix) * ends).sum(axis=1) > 0)
    reaching = np.zeros(model.n_states, bool)
    reaching[states_reaching(model.transition_matrix, exits)] = True
    if stationary[reaching].sum() > 1e-9:
        return stationary
    return reaching.astype(np.float64)


def occupancy_at(model: "MarkovModel", source, time: float) -> np.ndarray | None:
    """The particles per state of ``model`` in the frame of ``source`` at ``time``: where a
    window that starts there finds them (the start of :func:`window_rtd
    <cfbmarkov.markov.first_passage.window_rtd>` and of the windowed exit means).

    Parameters
    ----------
    model : MarkovModel
    source : str, os.PathLike or Trajectories
        A run or a prediction.
    time : float
        The frame's time (s).

    Returns
    -------
    ndarray of float64, shape (S,), or None
        None for an open riser, or where the frame holds no particle in a state (the
        model's default start, :func:`window_start_occupancy`, then applies).
    """
    from cfbmarkov.errors import CfbmarkovError

    if model.open_flow is not None:
        return None
    try:
        states = np.asarray(model.initial_states(source, float(time))[0])
    except (CfbmarkovError, ValueError):
        return None
    states = states[(states >= 0) & (states < model.n_states)]
    if states.size == 0:
        return None
    return np.bincount(states, minlength=model.n_states).astype(np.float64)


def _periodic_window_rtd(model: "MarkovModel", window: float, direction: str,
                         occupancy) -> ResidenceTimeDistribution:
    """A periodic riser's RTD as a window sees it, its records counted from the window's
    first frame (:func:`~cfbmarkov.markov.first_passage.window_rtd`), cached for the
    default start."""
    cache = model._cache
    steps = int(round(window / model.lag))
    key = ("rtd-window", direction, steps)
    if occupancy is None and key in cache:
        cached = cache[key]     # the same whole lags; the window as this call gave it
        return (cached if cached.window == window
                else dataclasses.replace(cached, window=window))
    # its unresolved mass and depth: the intrinsic RTD's (computed once, cached)
    intrinsic = model_rtd(model, None, direction)
    ends, back = ((model.up_fraction, model.down_fraction) if direction == "up"
                  else (model.down_fraction, model.up_fraction))
    p_up, p_down, p_stay = split_by_pass(sp.csr_matrix(model.transition_matrix), ends, back)
    start = window_start_occupancy(model, direction) if occupancy is None else occupancy
    start = np.asarray(start, dtype=np.float64)
    if start.shape != (model.n_states,) or not np.all(np.isfinite(start)) or start.min() < 0 \
            or not start.sum() > 0:
        raise InputError(f"occupancy: non-negative finite weights of shape ({model.n_states},) "
                         "with some mass (where the window's particles start)")
    rtd = window_rtd(p_up, p_down, p_stay, model.lag, window, start, intrinsic.deficit_levels,
                     intrinsic)
    if occupancy is None:
        cache[key] = rtd
    return rtd


def _down_rtd(model: "MarkovModel", window: float | None) -> ResidenceTimeDistribution:
    """Residences of a net downflow: entries through the top, exits through the bottom."""
    if "rtd-down" not in model._cache:
        model._cache["rtd-down"] = exact_rtd(model.transition_matrix, model.down_fraction,
                                             model.up_fraction, model.lag,
                                             entry_flux=net_entry_flux(model, "down"))
    intrinsic = model._cache["rtd-down"]
    return intrinsic if window is None else intrinsic.in_window(window)


def entry_delay(model: "MarkovModel") -> int:
    """Lags between an open riser's particle first seen at the inlet and its first state:
    a state space with memory from displacements (``memory_lags``, one lag of history)
    gives a particle its first state a lag after it is first seen, and its entry is counted
    into that state (``counting._open_kernel``); 0 for the cells."""
    return int(getattr(model.state_space, "memory_lags", 0) or 0)


def _open_rtd(model: "MarkovModel", window: float | None) -> ResidenceTimeDistribution:
    """First passage to the outside from the entry distribution (fundamental matrix of the
    absorbing chain): f(k) = e Q^(k-1-d) r, d = :func:`entry_delay` lags from the inlet to
    the first state (a residence runs from the inlet, as the data's do)."""
    if "open-rtd" not in model._cache:
        chain = model.open_flow.rtd(model.absorbing_matrix, model.lag)
        delay = entry_delay(model)
        if delay:
            chain = dataclasses.replace(chain, probability=np.concatenate(
                [np.zeros(delay), np.asarray(chain.probability, dtype=np.float64)]))
        model._cache["open-rtd"] = chain
    intrinsic = model._cache["open-rtd"]
    return intrinsic if window is None else intrinsic.in_window(window)


__all__ = ["drift_rt_mean", "entry_delay", "model_rtd"]


def drift_rt_mean(model: "MarkovModel", direction: str | None = None) -> float | None:
    """A periodic riser's exact E(RT) from its chain's net lap drift, without the RTD.

    lag / (pi (P_end - P_back) 1), pi the chain's stationary distribution, P_end the part
    of P through the boundary that ends a residence in ``direction`` and P_back the other
    (:func:`~cfbmarkov.markov.first_passage.drift_residence_time`): equal to the mean of
    the exact RTD (:meth:`MarkovModel.rtd`) where its residences run in one closed class, at the
    cost of one sparse LU of [S, S] whatever the depth its residences fall to. Used where
    only E(RT) is needed of many models (the sample verdict's parts of a window).

    Parameters
    ----------
    model : MarkovModel
    direction : {"up", "down"}, optional
        Default the model's ``flow_direction``.

    Returns
    -------
    float or None
        E(RT) in s; None for an open riser, a chain whose residences start in several
        closed classes (the exact RTD then weights them by the observed entries) or in
        transient states (some fall into traps), or one whose laps do not advance in
        ``direction``.

    References
    ----------
    A. Wald, "On cumulative sums of random variables", Ann. Math. Statist. 15, 283 (1944).
    """
    if model.open_flow is not None:
        return None
    direction = model.flow_direction if direction is None else direction
    p_up, p_down, p_stay = split_by_pass(sp.csr_matrix(model.transition_matrix),
                                         model.up_fraction, model.down_fraction)
    if direction == "down":
        p_up, p_down = p_down, p_up
    return drift_residence_time(p_up, p_down, (p_up + p_down + p_stay).tocsr(), model.lag)


def rtd_at_depth(model: "MarkovModel", direction: str | None, deficit_levels: int
                 ) -> ResidenceTimeDistribution:
    """A periodic riser's intrinsic exact RTD on a given number of lap deficits (not
    cached; :meth:`MarkovModel.rtd` keeps as many as its residences need), or an open
    riser's exact RTD.

    Parameters
    ----------
    model : MarkovModel
    direction : {"up", "down"} or None
        Default the model's ``flow_direction``.
    deficit_levels : int
        K (:func:`~cfbmarkov.markov.first_passage.exact_rtd`).

    Returns
    -------
    ResidenceTimeDistribution

    Raises
    ------
    CfbmarkovError
        If no residence ends in ``direction``.
    """
    if model.open_flow is not None:
        return model.rtd()
    direction = model.flow_direction if direction is None else direction
    ends, back = ((model.up_fraction, model.down_fraction) if direction == "up"
                  else (model.down_fraction, model.up_fraction))
    return exact_rtd(model.transition_matrix, ends, back, model.lag, int(deficit_levels),
                     entry_flux=net_entry_flux(model, direction))
