"""The baseline an engineer would use without the chain: the segregated-flow model
(``docs/kinetics-reference.md``, The segregated-flow baseline).

Every particle is a small batch reactor whose property depends on its residence time
alone; the exit value is averaged over the residence-time distribution (RTD),

    E[v_exit] = integral_0^inf v(t) E(t) dt,

(O. Levenspiel, Chemical Reaction Engineering, 3rd ed., Wiley (1999), Ch. 11, the
segregated-flow model). The rate law is the bed-averaged one: averaged over the fitting
window's state occupancy pi_s, the law k_s (v_inf,s - v) is k_bar (v_bar - v) with

    k_bar = sum_s pi_s k_s,    v_bar = sum_s pi_s k_s v_inf,s / k_bar

(v_bar the occupancy mean of v_inf,s where every k_s is zero), so that for the built-in
linear relaxations v(t) = v_bar + (v0 - v_bar) exp(-k_bar t). E(t) is the fitting window's
observed RTD (:func:`cfbmarkov.observed.residence.residence_times`), so the baseline uses
what the chain is fitted on and nothing of where in the riser a particle spends its time.
The bed's mean is the value averaged over the bed's age distribution,
I(a) = (1 - F(a)) / E(RT): with residence-time samples tau_i,

    mean over the bed = sum_i integral_0^tau_i v(a) da / sum_i tau_i,

or, sampled at the frames as the chain's exact bed mean and the reference's are (each
lag's start, the entry frame holding v0; ``lag`` given), with n_i = tau_i / lag,

    mean over the bed = sum_i sum_(j < n_i) v(j lag) / sum_i n_i,
    sum_(j < n) v(j lag) = n v_bar + (v0 - v_bar) (1 - e^(-k_bar n lag)) / (1 - e^(-k_bar lag)).

The continuous form lies above the sampled one by about k_bar lag / 2 of the relaxation
(1.95 % at k = 1.3 1/s, lag 0.1 s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfbmarkov.analysis.exit_statistics import ExitStatistics
from cfbmarkov.errors import InputError


@dataclass(frozen=True)
class SegregatedFlow(ExitStatistics):
    """One property by the segregated-flow model.

    Attributes
    ----------
    name : str
        The property.
    rate : float
        The bed-averaged rate k_bar (1/s).
    target : float
        The bed-averaged limit v_bar.
    initial : float
        The value at entry v0.
    residence_times : ndarray of float64, shape (K,)
        The RTD's samples (s).
    exit_values : ndarray of float64, shape (K,)
        v(tau) of each sample: the distribution at exit.
    bed_mean : float
        The mean over the bed's age distribution (NaN without a sample longer than 0).
    """

    name: str
    rate: float
    target: float
    initial: float
    residence_times: np.ndarray
    exit_values: np.ndarray
    bed_mean: float


def bed_averaged(rate, target, occupancy) -> tuple[float, float]:
    """The bed-averaged rate k_bar and limit v_bar of a linear relaxation (module docstring).

    Parameters
    ----------
    rate, target : array_like of float64, shape (S,)
        k_s (1/s) and v_inf,s per state.
    occupancy : array_like of float64, shape (S,)
        How often each state is occupied (particle-frames, or a distribution); normalised
        here.

    Returns
    -------
    (float, float)
        k_bar (1/s) and v_bar.

    Raises
    ------
    InputError
        When the shapes differ, the occupancy is negative or sums to zero, or a value is
        not finite.
    """
    rate = np.asarray(rate, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    pi = np.asarray(occupancy, dtype=np.float64)
    if not (rate.shape == target.shape == pi.shape) or rate.ndim != 1:
        raise InputError(f"rates {rate.shape}, limits {target.shape} and occupancy {pi.shape} "
                         "must be one value per state each")
    if not (np.isfinite(rate).all() and np.isfinite(target).all() and np.isfinite(pi).all()):
        raise InputError("bed-averaged kinetics: a rate, limit or occupancy is not finite")
    total = pi.sum()
    if pi.min() < 0 or not total > 0:
        raise InputError("bed-averaged kinetics: the occupancy must be >= 0 and not all zero")
    pi = pi / total
    k_bar = float(pi @ rate)
    v_bar = float(pi @ (rate * target)) / k_bar if k_bar > 0 else float(pi @ target)
    return k_bar, v_bar


def relaxation_value(times, rate: float, target: float, initial: float) -> np.ndarray:
    """v(t) = v_bar + (v0 - v_bar) exp(-k_bar t), the bed-averaged linear relaxation.

    Parameters
    ----------
    times : array_like of float64
        Times since entry (s).
    rate, target, initial : float
        k_bar (1/s), v_bar and v0.

    Returns
    -------
    ndarray of float64
        Shaped as ``times``.
    """
    times = np.asarray(times, dtype=np.float64)
    return target + (initial - target) * np.exp(-rate * times)


def segregated_flow(residence_times, rate, target, occupancy, initial: float, *,
                    name: str = "", lag: float | None = None) -> SegregatedFlow:
    """One property by the segregated-flow model over an observed RTD.

    Parameters
    ----------
    residence_times : array_like of float64, shape (K,)
        The fitting window's residence-time samples (s).
    rate, target : array_like of float64, shape (S,)
        k_s (1/s) and v_inf,s per state of the model's space.
    occupancy : array_like of float64, shape (S,)
        The fitting window's state occupancy (particle-frames per state).
    initial : float
        The value at entry v0.
    name : str, optional
        The property.
    lag : float, optional
        The model's lag (s): the bed's mean is sampled at each lag's start, as the chain's
        and the reference's are (module docstring); None: the continuous integral.

    Returns
    -------
    SegregatedFlow

    Raises
    ------
    InputError
        For bad rates or occupancy (:func:`bed_averaged`), negative or non-finite
        residence times or a non-finite start value.

    References
    ----------
    O. Levenspiel, Chemical Reaction Engineering, 3rd ed., Wiley (1999), Ch. 11.
    """
    tau = np.asarray(residence_times, dtype=np.float64).reshape(-1)
    if tau.size and (not np.isfinite(tau).all() or tau.min() < 0):
        raise InputError("segregated flow: residence times must be finite and >= 0")
    if not np.isfinite(initial):
        raise InputError(f"property {name}: its start value is not finite")
    k_bar, v_bar = bed_averaged(rate, target, occupancy)
    exits = relaxation_value(tau, k_bar, v_bar, float(initial))
    total = tau.sum()
    if total > 0 and lag is not None:
        n = np.maximum(np.rint(tau / lag), 1.0)         # lags of each residence
        if k_bar > 0:
            frames = n * v_bar + (initial - v_bar) * (np.expm1(-k_bar * n * lag)
                                                      / np.expm1(-k_bar * lag))
        else:
            frames = n * initial
        bed = float(frames.sum() / n.sum())
    elif total > 0:
        if k_bar > 0:
            integral = v_bar * tau + (initial - v_bar) * -np.expm1(-k_bar * tau) / k_bar
        else:
            integral = initial * tau
        bed = float(integral.sum() / total)
    else:
        bed = float("nan")
    return SegregatedFlow(name, k_bar, v_bar, float(initial), tau, exits, bed)


__all__ = ["SegregatedFlow", "bed_averaged", "relaxation_value", "segregated_flow"]
