"""The exact residence-time distributions of a fitted :class:`~cfbmarkov.markov.model.MarkovModel`
(:meth:`MarkovModel.rtd <cfbmarkov.markov.model.MarkovModel.rtd>`): a periodic riser's from
passes up through the top (or down through the bottom, for a net downflow), an open
riser's from the inlet to the outlet, each computed once and kept in the model's cache.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.limits import MAX_STEPS, check_finite
from cfbmarkov.markov.first_passage import ResidenceTimeDistribution, exact_rtd

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel


def model_rtd(model: "MarkovModel", window: float | None = None,
              direction: str | None = None) -> ResidenceTimeDistribution:
    """Exact residence-time distribution of ``model`` (no sampling noise), cached in it.

    Parameters
    ----------
    model : MarkovModel
        The fitted model.
    window : float, optional
        Length (s) of an analysis window: the RTD as seen in it (None: the intrinsic RTD).
    direction : {"up", "down"}, optional
        A periodic riser's residences from passes up through the top or down through the
        bottom (the pass fractions swapped); default the model's ``flow_direction``.

    Returns
    -------
    ResidenceTimeDistribution
        The intrinsic RTD in the model's direction carries the model's ``uncertainty``.

    Raises
    ------
    InputError
        If ``window`` is not a positive finite time of at most
        :data:`~cfbmarkov.limits.MAX_STEPS` lags, or ``direction`` is neither up nor down.
    CfbmarkovError
        If the model has no transition through the boundary in ``direction`` (no residence
        ends), or no residence fits in ``window``.

    Notes
    -----
    See :func:`~cfbmarkov.markov.first_passage.exact_rtd` and ``docs/definitions.md``
    (Residence time).
    """
    if window is not None:
        window = check_finite(window, "--window-length", "s", positive=True)
        if window / model.lag > MAX_STEPS:
            raise InputError(f"--window-length {window:g} s is {window / model.lag:.3g} lags "
                             f"of {model.lag:g} s, more than {MAX_STEPS}")
    cache = model._cache
    if model.open_flow is not None:
        return _with_uncertainty(model, _open_rtd(model, window), window)
    if direction is None:
        direction = model.flow_direction
    if direction not in ("up", "down"):
        raise InputError(f"residence direction {direction!r}: up or down")
    own = direction == model.flow_direction     # the direction the uncertainty is of
    if direction == "down":
        rtd = _down_rtd(model, window)
        return _with_uncertainty(model, rtd, window) if own else rtd
    if window is not None and "rtd" not in cache:
        # a window of n lags sees residence times below n lags only: propagate no further
        steps = max(2, int(round(window / model.lag)))
        key = ("rtd-steps", steps)
        if key not in cache:
            cache[key] = exact_rtd(model.transition_matrix, model.up_fraction,
                                   model.down_fraction, model.lag, max_steps=steps,
                                   entry_flux=net_entry_flux(model))
        return cache[key].in_window(window)
    if "rtd" not in cache:
        cache["rtd"] = exact_rtd(model.transition_matrix, model.up_fraction,
                                 model.down_fraction, model.lag,
                                 entry_flux=net_entry_flux(model))
    intrinsic = cache["rtd"]
    if window is not None:
        return intrinsic.in_window(window)
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


def _down_rtd(model: "MarkovModel", window: float | None) -> ResidenceTimeDistribution:
    """Residences of a net downflow: entries through the top, exits through the bottom."""
    if "rtd-down" not in model._cache:
        model._cache["rtd-down"] = exact_rtd(model.transition_matrix, model.down_fraction,
                                             model.up_fraction, model.lag,
                                             entry_flux=net_entry_flux(model, "down"))
    intrinsic = model._cache["rtd-down"]
    return intrinsic if window is None else intrinsic.in_window(window)


def _open_rtd(model: "MarkovModel", window: float | None) -> ResidenceTimeDistribution:
    """First passage to the outside from the entry distribution (fundamental matrix of the
    absorbing chain): f(k) = e Q^(k-1) r."""
    if "open-rtd" not in model._cache:
        model._cache["open-rtd"] = model.open_flow.rtd(model.absorbing_matrix, model.lag)
    intrinsic = model._cache["open-rtd"]
    return intrinsic if window is None else intrinsic.in_window(window)


__all__ = ["model_rtd"]
