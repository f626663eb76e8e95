"""The fitted Markov chain model: immutable, saved as HDF5, answering questions.

A :class:`MarkovModel` holds the transition matrix P (S x S), the pooled counts of the
fitting window, the counts of transitions that passed up through the top or down through
the bottom of the periodic riser, and its state space. It answers:

- :meth:`propagate` (Eq. 5-6), with or without outflow through the top, and
  :meth:`batch_injection_maps` (Eq. 8, the paper's Fig. 4-7);
- :meth:`rtd`: the exact residence-time distribution (first passage of the lap counter);
- :meth:`monte_carlo` / :meth:`predict`: Monte Carlo of every particle (Eq. 7) with lap
  counters, :meth:`predict` writing a trajectory file like any other.

The file layout and its reading and writing are in :mod:`cfbmarkov.markov.model_file`.
"""

from __future__ import annotations

import dataclasses

import os
import weakref
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Sequence

import h5py
import numpy as np
from threadpoolctl import threadpool_limits

from cfbmarkov.errors import InputError
from cfbmarkov.markov.connectivity import (closed_classes, long_run_distribution,
                                           states_reaching)
from cfbmarkov.markov.discrete import discretize_frame
from cfbmarkov.markov.montecarlo import SparseChain, run_chain
from cfbmarkov.markov.first_passage import ResidenceTimeDistribution, exact_rtd
from cfbmarkov.markov.states import StateSpace

#: the ``format`` attribute of a model file
MODEL_FORMAT = "cfbmarkov.model"
_DATASETS = ("transition_matrix", "counts", "counts_up", "counts_down")
#: the read-only arrays that a model's validation made, by id: a model derived from another
#: (``with_selection``, ``with_coherence``) takes them as they are instead of copying and
#: checking [S, S] arrays again
_VALIDATED: "weakref.WeakValueDictionary[int, np.ndarray]" = weakref.WeakValueDictionary()


def _validated(value) -> bool:
    return _VALIDATED.get(id(value)) is value


#: arrays an estimator made for the model it is forming and hands over (nobody else holds
#: them): the model's validation checks them and keeps them instead of copying
_HANDED_OVER: "weakref.WeakValueDictionary[int, np.ndarray]" = weakref.WeakValueDictionary()


def hand_over(*arrays: np.ndarray) -> None:
    """Give arrays to the next model made from them: it checks them and keeps them (made
    read-only) instead of copying them. Only for arrays no one else holds or writes.

    Parameters
    ----------
    *arrays : ndarray
        The arrays (None is skipped).
    """
    for value in arrays:
        if isinstance(value, np.ndarray):
            _HANDED_OVER[id(value)] = value


def _take(value, dtype) -> np.ndarray:
    """The model's own read-only array of ``value``: the array itself where it was handed
    over with this dtype (and is contiguous), else a copy."""
    if (_HANDED_OVER.get(id(value)) is value and value.dtype == dtype
            and value.flags.c_contiguous):
        del _HANDED_OVER[id(value)]
        return value
    return np.array(value, dtype=dtype)


def _mark_validated(value: np.ndarray) -> np.ndarray:
    value.setflags(write=False)
    _VALIDATED[id(value)] = value
    return value
#: share of an open riser's tracks ending (beginning) away from the outlet (inlet) above
#: which :meth:`MarkovModel.warnings` says so
CENSORED_SHARE = 0.05


@dataclass(frozen=True, eq=False)
class MarkovModel:
    """A fitted Markov chain model of particle motion; immutable.

    Made by an estimator (:meth:`~cfbmarkov.markov.estimate.TransitionEstimator.fit`,
    :func:`~cfbmarkov.markov.fit_model`) or read by :meth:`load`. The arrays are stored
    as read-only copies.

    Attributes
    ----------
    transition_matrix : ndarray of float64, shape (S, S)
        The row-stochastic transition matrix P over one lag.
    counts : ndarray of int64, shape (S, S)
        Pooled transition counts C_ij of the fitting window.
    counts_up, counts_down : ndarray of int64, shape (S, S)
        The transitions among them that passed up through the top / down through the
        bottom of the periodic riser.
    state_space : StateSpace
        The states.
    lag : float
        The lag tau (s).
    estimator : str
        Name of the estimator (``paper`` or ``mle``).
    window : tuple of float or None
        The fitting window (A, B) in s (None: every frame).
    source : str or list of str
        The trajectory file(s) it was fitted on.
    frame_pairs : int
        Number of frame pairs (t, t + lag) counted.
    pass_fractions : tuple of two ndarrays of shape (S, S), or None
        (up, down) fractions of each i -> j transition that pass the boundary; None: taken
        from the counts.
    selection : dict or None
        How the state space and lag were chosen (``--states auto``), JSON-serialisable.
    connected : bool
        Fitted on the largest strongly connected set (transitions leaving it removed).
    boundary : {"periodic", "open"}
        The riser's vertical boundary. An open riser's chain is absorbing: each lag a
        particle in state i leaves through the outlet with probability ``exit_probability[i]``,
        else moves by P; particles enter through the inlet (``docs/definitions.md``, Open
        risers).
    exit_probability : ndarray of float64, shape (S,), or None
        r_i (open riser; None for a periodic one).
    exit_counts, entry_counts : ndarray of int64, shape (S,), or None
        Exits from / entries into each state observed in the fitting window (open riser).
    inflow_per_lag : float
        Mean number of particles entering through the inlet per lag (open riser).
    censored_tracks : tuple of int
        (vanished, appeared): tracks of an open riser that ended or began more than one cell
        from the outlet or inlet face, left out as censored.
    coherence : float
        rho in [0, 1]: in the Monte Carlo, the probability that a particle takes the draw
        shared by the particles leaving its state at that step (coherent moves, the cluster
        model; :mod:`cfbmarkov.markov.coherence`); 0: independent particles (the paper's).

    Raises
    ------
    InputError
        If an array does not have shape (S, S) for the state space, P holds negative or
        non-finite entries, its rows do not sum to 1, the pass fractions have the wrong
        shape, or an open riser's exit probabilities are not probabilities, its counts are
        negative or it has no entry, or the coherence is not in [0, 1].

    Notes
    -----
    See ``docs/definitions.md`` (Estimators; Propagation; File formats, Model files).

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 1-8).
    """

    transition_matrix: np.ndarray
    counts: np.ndarray
    counts_up: np.ndarray
    counts_down: np.ndarray
    state_space: StateSpace
    lag: float
    estimator: str = "mle"
    window: tuple[float, float] | None = None
    source: Any = ""
    frame_pairs: int = 0
    # (up, down) fractions of each i -> j transition passing the boundary; from counts if None
    pass_fractions: tuple[np.ndarray, np.ndarray] | None = None
    # how the state space and lag were chosen (``--states auto``), JSON-serialisable
    selection: dict | None = None
    connected: bool = False
    boundary: str = "periodic"
    exit_probability: np.ndarray | None = None
    exit_counts: np.ndarray | None = None
    entry_counts: np.ndarray | None = None
    inflow_per_lag: float = 0.0
    censored_tracks: tuple[int, int] = (0, 0)
    coherence: float = 0.0
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        s = self.state_space.n_states
        trusted = {name for name in _DATASETS if _validated(getattr(self, name))}
        for name in _DATASETS:
            if name in trusted:
                if getattr(self, name).shape != (s, s):
                    raise InputError(f"model {name} has shape {getattr(self, name).shape}, "
                                     f"expected ({s}, {s}) for {self.state_space.describe()}")
                continue
            given = np.asarray(getattr(self, name))
            if name != "transition_matrix" and given.dtype.kind not in "iub" and not (
                    np.all(np.isfinite(given)) and np.all(given == np.round(given))):
                raise InputError(f"model {name} holds values that are not whole counts")
            value = _take(getattr(self, name), np.float64 if name == "transition_matrix"
                          else np.int64)
            if value.shape != (s, s):
                raise InputError(f"model {name} has shape {value.shape}, expected ({s}, {s}) "
                                 f"for {self.state_space.describe()}")
            object.__setattr__(self, name, _mark_validated(value))
        if not (isinstance(self.lag, (int, float, np.number)) and np.isfinite(self.lag)
                and self.lag > 0):
            raise InputError(f"model lag {self.lag!r} s must be a positive finite number")
        p = self.transition_matrix
        if "transition_matrix" in trusted:
            pass                            # checked when it was validated
        elif not np.all(np.isfinite(p)) or (p.size and p.min() < 0):
            raise InputError("transition matrix holds negative or non-finite entries")
        rows = p.sum(axis=1) if "transition_matrix" not in trusted else np.ones(s)
        if not np.allclose(rows, 1.0, atol=1e-9):
            k = int(np.argmax(np.abs(rows - 1.0)))
            raise InputError(f"transition matrix rows do not sum to 1 (row {k} sums to {rows[k]:.6g})")
        for name in ("counts", "counts_up", "counts_down"):
            value = getattr(self, name)
            if name not in trusted and value.size and value.min() < 0:
                raise InputError(f"model {name} holds negative counts")
        if self.pass_fractions is not None and not all(
                _validated(f) for f in self.pass_fractions):
            if len(self.pass_fractions) != 2:
                raise InputError("pass fractions must be (up, down)")
            fractions = tuple(_take(f, np.float64) for f in self.pass_fractions)
            if any(f.shape != (s, s) for f in fractions):
                raise InputError(f"pass fractions must have shape ({s}, {s})")
            up, down = fractions
            if not (np.all(np.isfinite(up)) and np.all(np.isfinite(down))) or (up.size and (
                    min(up.min(), down.min()) < 0 or (up + down).max() > 1.0 + 1e-9)):
                worst = float(max(np.nanmax(np.abs(up)), np.nanmax(np.abs(down)))) if up.size else 0
                raise InputError("pass fractions must lie in [0, 1] with up + down <= 1 for each "
                                 f"transition (largest {worst:.6g})")
            object.__setattr__(self, "pass_fractions", tuple(_mark_validated(f)
                                                             for f in fractions))
        if not (isinstance(self.coherence, (int, float, np.number))
                and 0.0 <= float(self.coherence) <= 1.0):
            raise InputError(f"model coherence {self.coherence!r} must lie in [0, 1]")
        object.__setattr__(self, "coherence", float(self.coherence))
        if not (isinstance(self.frame_pairs, (int, np.integer)) and self.frame_pairs >= 0):
            raise InputError(f"model frame_pairs {self.frame_pairs!r} must be a count >= 0")
        if self.window is not None and not (len(self.window) == 2 and all(
                np.isfinite(self.window)) and self.window[1] > self.window[0]):
            raise InputError(f"model window {self.window!r} is not two finite times (A < B)")
        self._check_open(s)

    def _check_open(self, s: int) -> None:
        if self.boundary not in ("periodic", "open"):
            raise InputError(f"model boundary {self.boundary!r}: periodic or open")
        if self.boundary == "periodic":
            return
        for name, dtype in (("exit_probability", np.float64), ("exit_counts", np.int64),
                            ("entry_counts", np.int64)):
            value = getattr(self, name)
            if value is None:
                raise InputError(f"an open riser's model needs {name}")
            value = np.array(value, dtype=dtype)
            if value.shape != (s,) or not np.all(np.isfinite(value)) or value.min() < 0:
                raise InputError(f"model {name} must be {s} non-negative numbers")
            object.__setattr__(self, name, _mark_validated(value))
        if self.exit_probability.max() > 1.0:
            raise InputError("model exit probabilities exceed 1")
        if self.entry_counts.sum() == 0:
            raise InputError("an open riser's model without any entry through the inlet: the "
                             "fitting window saw no particle enter (its entry distribution is "
                             "empty)")
        if not (np.isfinite(self.inflow_per_lag) and self.inflow_per_lag >= 0):
            raise InputError(f"model inflow {self.inflow_per_lag!r} per lag must be >= 0")

    @property
    def entry_distribution(self) -> np.ndarray | None:
        """Where particles enter an open riser: the observed entries per state, normalised,
        float64 [S] (None for a periodic riser)."""
        if self.entry_counts is None:
            return None
        return self.entry_counts / self.entry_counts.sum()

    @cached_property
    def absorbing_matrix(self) -> np.ndarray:
        """Q = diag(1 - r) P, the sub-stochastic matrix of an open riser's chain (the
        transitions among the states; r leaves through the outlet), float64 [S, S].

        Raises
        ------
        InputError
            For a periodic riser's model (no outlet).
        """
        if self.exit_probability is None:
            raise InputError("a periodic riser's model has no outlet (no absorbing matrix)")
        return (1.0 - self.exit_probability)[:, None] * self.transition_matrix

    # -- derived quantities ------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """Number of states S."""
        return self.state_space.n_states

    @property
    def n_transitions(self) -> int:
        """Number of transitions counted in the fitting window (0 for a model given by its
        matrix)."""
        return int(self.counts.sum())

    @cached_property
    def unvisited_states(self) -> np.ndarray:
        """States with no outgoing transition in the window, int64 [U].

        They stay in place (P_ii = 1) or move as the other states of their cell
        (``docs/definitions.md``, Unvisited states).
        """
        if self.n_transitions == 0:      # a model given by its matrix, not fitted
            return np.zeros(0, np.int64)
        left = self.counts.sum(axis=1)
        if self.exit_counts is not None:   # leaving through the outlet is leaving too
            left = left + self.exit_counts
        return np.flatnonzero(left == 0)

    @cached_property
    def entered_never_left(self) -> np.ndarray:
        """States entered in the fitting window but never left (e.g. first entered in its
        last frame), int64 [E]: a subset of :attr:`unvisited_states` that is not "never
        visited"."""
        entered = self.counts.sum(axis=0) > 0
        return self.unvisited_states[entered[self.unvisited_states]]

    @cached_property
    def trap_share(self) -> float:
        """Share of the fitting window's particle-frames in states from which the chain can
        reach a state entered but never left that keeps its particles (P_ii = 1)."""
        traps = [i for i in self.entered_never_left if self.transition_matrix[i, i] == 1.0]
        occupancy = self.counts.sum(axis=1).astype(np.float64)
        if not traps or occupancy.sum() == 0:
            return 0.0
        return float(occupancy[states_reaching(self.transition_matrix, traps)].sum()
                     / occupancy.sum())

    @cached_property
    def closed_classes(self) -> list[np.ndarray]:
        """Closed classes of P with two or more states, largest first: more than one means a
        reducible chain (particles in one never reach the other's states)."""
        return closed_classes(self.transition_matrix, min_size=2)

    @property
    def _entry_flux(self) -> np.ndarray | None:
        # net entries through the inlet per state: landings of up passes minus departures of
        # down passes (a particle that falls out and comes back starts no new residence)
        flux = (self.counts_up.sum(axis=0) - self.counts_down.sum(axis=1)).astype(np.float64)
        return flux if flux.sum() > 0 else None

    @cached_property
    def up_fraction(self) -> np.ndarray:
        """Fraction of the i -> j transitions that passed up through the top, float64 [S, S]."""
        if self.pass_fractions is not None:
            return self.pass_fractions[0]
        c = self.counts.astype(np.float64)
        return np.divide(self.counts_up, c, out=np.zeros_like(c), where=c > 0)

    @cached_property
    def down_fraction(self) -> np.ndarray:
        """Fraction of the i -> j transitions that passed down through the bottom, float64
        [S, S]."""
        if self.pass_fractions is not None:
            return self.pass_fractions[1]
        c = self.counts.astype(np.float64)
        return np.divide(self.counts_down, c, out=np.zeros_like(c), where=c > 0)

    @cached_property
    def _chain(self) -> SparseChain:
        return SparseChain.from_matrix(self.transition_matrix, self.up_fraction, self.down_fraction)

    @cached_property
    def regime_chain(self) -> np.ndarray | None:
        """The regime chain G (R x R) of a regime model, read off its counts
        (:func:`~cfbmarkov.markov.regimes.regime_matrix`; from P itself for a model without
        counts); None for other state spaces."""
        from cfbmarkov.markov.regimes import RegimeCells, regime_matrix

        if not isinstance(self.state_space, RegimeCells):
            return None
        weights = self.counts if self.n_transitions else self.transition_matrix
        return regime_matrix(weights, self.state_space)

    @cached_property
    def _conditional_chain(self) -> SparseChain:
        from cfbmarkov.markov.regimes import conditional_chain

        return conditional_chain(self.transition_matrix, self.up_fraction, self.down_fraction,
                                 self.state_space)

    @cached_property
    def stationary_distribution(self) -> np.ndarray:
        """The long-run distribution over the states, float64 [S], summing to 1 (pi P = pi).

        One closed class: the left eigenvector of P for eigenvalue 1. A reducible chain
        (several closed classes, traps P_ii = 1 included) has no unique one: the particle-
        frames observed in the fitting window (uniform for a model given by its matrix) are
        carried into the closed classes by their absorption probabilities, and each class
        holds its own stationary distribution with that mass
        (:func:`~cfbmarkov.markov.connectivity.long_run_distribution`).

        References
        ----------
        J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton
        (1960) (Ch. III absorbing chains, IV-V regular and ergodic chains).
        """
        classes = closed_classes(self.transition_matrix)
        if len(classes) > 1:
            occupancy = self.counts.sum(axis=1).astype(np.float64)
            return long_run_distribution(self.transition_matrix, classes, occupancy)
        with threadpool_limits(1):          # BLAS threads only contend on a dense eig here
            values, vectors = np.linalg.eig(self.transition_matrix.T)
        lead = int(np.argmin(np.abs(values - 1.0)))
        pi = np.abs(vectors[:, lead].real)
        return pi / pi.sum()

    # -- propagation (Eq. 5, 6, 8) -----------------------------------------------------
    def propagate(self, initial, steps: int, outflow: bool = False) -> np.ndarray:
        """State vectors from ``initial`` by S(t + lag) = S(t) P, lag by lag.

        With ``outflow`` the transitions up through the top are taken out, so the total
        mass is the fraction still in the riser (a batch leaving through the outlet). An
        open riser's model always propagates by its absorbing matrix Q = diag(1 - r) P:
        what leaves through the outlet is gone.

        Parameters
        ----------
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
            If ``initial`` does not have shape (S,).

        References
        ----------
        Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
        Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
        doi:10.3390/pr13030614 (Eq. 5-6).
        """
        s0 = np.asarray(initial, dtype=np.float64)
        if s0.shape != (self.n_states,):
            raise InputError(f"initial distribution has shape {s0.shape}, expected ({self.n_states},)")
        p = self.transition_matrix * (1.0 - self.up_fraction) if outflow else self.transition_matrix
        if self.boundary == "open":
            p = self.absorbing_matrix
        out = np.empty((int(steps) + 1, self.n_states))
        out[0] = s0
        for k in range(1, int(steps) + 1):   # one S x S product per lag, not per particle
            out[k] = out[k - 1] @ p
        return out

    def steps_for(self, time: float) -> int:
        """Number of lags in ``time``.

        Parameters
        ----------
        time : float
            A time (s), a whole multiple of the lag.

        Returns
        -------
        int
            ``time / lag``, >= 0.

        Raises
        ------
        InputError
            If ``time`` is negative or not a whole multiple of the lag.
        """
        if not np.isfinite(time):
            raise InputError(f"time {time:g} s is not a finite number")
        k = int(round(time / self.lag))
        if k < 0 or abs(k * self.lag - time) > 1e-6 * max(self.lag, abs(time)):
            raise InputError(f"time {time:g} s is not a whole multiple of the lag {self.lag:g} s")
        return k

    def batch_injection_maps(self, times: Sequence[float], outflow: bool = False) -> np.ndarray:
        """Eq. (8): where a batch fed evenly over the inlet cells at t = 0 is at ``times``.

        Parameters
        ----------
        times : sequence of float
            Times (s) after the injection, whole multiples of the lag.
        outflow : bool, optional
            Remove the mass that leaves up through the top (see :meth:`propagate`).

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
        from cfbmarkov.limits import MAX_STEPS, check_memory

        steps = [self.steps_for(t) for t in times]
        last = max(steps, default=0)
        if last > MAX_STEPS:
            raise InputError(f"time {max(times):g} s is {last} lags of {self.lag:g} s, more than "
                             f"{MAX_STEPS} to propagate; give earlier --times")
        check_memory(8.0 * (last + 1) * self.n_states, f"maps up to {max(times):g} s "
                     f"({last} lags x {self.n_states} states)", "give earlier --times")
        history = self.propagate(self.state_space.inlet_distribution(), max(steps, default=0),
                                 outflow=outflow)
        return self.state_space.cell_maps(history[steps])

    # -- residence times ---------------------------------------------------------------
    def rtd(self, window: float | None = None, direction: str = "up") -> ResidenceTimeDistribution:
        """Exact residence-time distribution (no sampling noise), cached.

        Parameters
        ----------
        window : float, optional
            Length (s) of an analysis window: the RTD as seen in it, the quantity a
            sample-based RTD estimates (None: the intrinsic RTD).
        direction : {"up", "down"}, optional
            A periodic riser's residences from passes up through the top (default) or, for
            a net downflow, down through the bottom (the pass fractions swapped;
            ``docs/definitions.md``, Net downflow).

        Returns
        -------
        ResidenceTimeDistribution

        Raises
        ------
        CfbmarkovError
            If the model has no transition up through the top (no residence ends), or no
            residence fits in ``window``.

        Notes
        -----
        See :func:`~cfbmarkov.markov.first_passage.exact_rtd` and ``docs/definitions.md`` (Residence
        time).

        References
        ----------
        J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton
        (1960) (Ch. III, absorbing chains).
        """
        if window is not None:
            from cfbmarkov.limits import MAX_STEPS, check_finite

            window = check_finite(window, "--window-length", "s", positive=True)
            if window / self.lag > MAX_STEPS:
                raise InputError(f"--window-length {window:g} s is {window / self.lag:.3g} lags "
                                 f"of {self.lag:g} s, more than {MAX_STEPS}")
        if self.boundary == "open":
            return self._open_rtd(window)
        if direction not in ("up", "down"):
            raise InputError(f"residence direction {direction!r}: up or down")
        if direction == "down":
            return self._down_rtd(window)
        if window is not None and "rtd" not in self._cache:
            # a window of n lags sees residence times below n lags only: propagate no further
            steps = max(2, int(round(window / self.lag)))
            key = ("rtd-steps", steps)
            if key not in self._cache:
                self._cache[key] = exact_rtd(self.transition_matrix, self.up_fraction,
                                             self.down_fraction, self.lag, max_steps=steps,
                                             entry_flux=self._entry_flux)
            return self._cache[key].in_window(window)
        if "rtd" not in self._cache:
            self._cache["rtd"] = exact_rtd(self.transition_matrix, self.up_fraction,
                                           self.down_fraction, self.lag,
                                           entry_flux=self._entry_flux)
        intrinsic = self._cache["rtd"]
        return intrinsic if window is None else intrinsic.in_window(window)

    def _down_rtd(self, window: float | None) -> ResidenceTimeDistribution:
        """Residences of a net downflow: entries through the top, exits through the bottom."""
        if "rtd-down" not in self._cache:
            flux = (self.counts_down.sum(axis=0) - self.counts_up.sum(axis=1)).astype(np.float64)
            self._cache["rtd-down"] = exact_rtd(self.transition_matrix, self.down_fraction,
                                                self.up_fraction, self.lag,
                                                entry_flux=flux if flux.sum() > 0 else None)
        intrinsic = self._cache["rtd-down"]
        return intrinsic if window is None else intrinsic.in_window(window)

    def _open_rtd(self, window: float | None) -> ResidenceTimeDistribution:
        """First passage to the outside from the entry distribution (fundamental matrix of
        the absorbing chain): f(k) = e Q^(k-1) r."""
        from cfbmarkov.markov.first_passage import open_rtd

        if "open-rtd" not in self._cache:
            self._cache["open-rtd"] = open_rtd(self.absorbing_matrix, self.exit_probability,
                                               self.entry_distribution, self.lag)
        intrinsic = self._cache["open-rtd"]
        return intrinsic if window is None else intrinsic.in_window(window)

    # -- Monte Carlo -------------------------------------------------------------------
    def monte_carlo(self, initial_states, n_steps: int, seed: int = 0, initial_laps=None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Monte Carlo of the chain (paper Eq. 7): every particle draws its next state from
        its row of P, lag by lag, and carries a lap counter.

        Parameters
        ----------
        initial_states : array_like of int, shape (N,)
            States at the start.
        n_steps : int
            Number of lags to run.
        seed : int
            Seed of the counter-based generator: the run depends only on (seed, particle,
            step), whatever the thread count.
        initial_laps : array_like of int, shape (N,), optional
            Lap counters at the start (0 when None).

        Returns
        -------
        states, laps : ndarray of int32, shape (n_steps + 1, N)
            For an open riser N = N0 + M: the initial particles, then the M that entered
            through the inlet during the run (Poisson, ``inflow_per_lag`` per lag, states
            from the entry distribution), in order of entry; -1 where absent (not yet
            entered, or left through the outlet with the state's exit probability); laps 0
            (:mod:`cfbmarkov.markov.open_montecarlo`).

        Raises
        ------
        InputError
            If an initial state lies outside the state space.

        References
        ----------
        Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
        Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
        doi:10.3390/pr13030614 (Eq. 7, the cumulative rule).
        """
        from cfbmarkov.limits import check_seed

        seed = check_seed(seed)
        initial_states = np.asarray(initial_states)
        if initial_states.size and (initial_states.min() < 0 or initial_states.max() >= self.n_states):
            raise InputError("initial states outside the model's state space")
        chain, offset, retag = self._chain, None, None
        if self.regime_chain is not None:
            # one regime path for every particle, each moving by the chain conditioned on it
            from cfbmarkov.markov.regimes import regime_path, start_regime, with_regime

            space = self.state_space
            path = regime_path(self.regime_chain, start_regime(initial_states, space), n_steps,
                               seed)
            chain, offset = self._conditional_chain, path * self.n_states

            def retag(states, steps):
                return with_regime(states, path[steps], space)
        if self.boundary == "open":
            from cfbmarkov.markov.open_montecarlo import run_open_chain

            states, _ = run_open_chain(chain, self.exit_probability,
                                       self.entry_distribution, self.inflow_per_lag,
                                       initial_states, n_steps, seed, offset, retag,
                                       self.coherence)
            return states, np.zeros_like(states)
        return run_chain(chain, initial_states, n_steps, seed, initial_laps, offset,
                         self.coherence)

    def initial_states(self, trajectories, start: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """States, positions and laps of the particles in the frame at ``start``.

        The frame is discretised with the history the state space needs.

        Parameters
        ----------
        trajectories : str, os.PathLike or Trajectories
            A trajectory file, by path or open.
        start : float
            Time of the frame (s).

        Returns
        -------
        states : ndarray of int32, shape (N,)
        positions : ndarray of float64, shape (N, 2)
            Positions (m).
        laps : ndarray of int32, shape (N,)

        Raises
        ------
        InputError
            If the file does not fit the model's domain, has no frame at ``start``, lacks
            the history before it, or the lag is not a whole number of its frames.
        """
        frame = discretize_frame(trajectories, self.state_space, self.lag, start)
        return frame.states[-1], frame.positions[-1], frame.laps[-1]

    def predict(self, trajectories, start: float, duration: float, seed: int = 0,
                output: str | os.PathLike | None = None, progress: bool = False):
        """Monte Carlo prediction (Eq. 7) from the particles' states in the frame at
        ``start`` (s) for ``duration`` (s), written as a trajectory file when ``output`` is
        given; see :func:`cfbmarkov.markov.prediction.predict` for the parameters, the
        returned values and the errors raised."""
        from cfbmarkov.markov.prediction import predict

        return predict(self, trajectories, start, duration, seed, output, progress)

    def _derived(self, **changes) -> "MarkovModel":
        """This model with fields that change neither the chain nor anything derived from
        it (the coherence, the selection record) replaced; what it has already derived
        (sampling chain, pass fractions, exact RTDs, ...) is carried over, not recomputed:
        calibrating the coherence runs the same chain with many values of it."""
        model = dataclasses.replace(self, _cache=dict(self._cache), **changes)
        for name, attribute in vars(type(self)).items():
            if isinstance(attribute, cached_property) and name in self.__dict__:
                model.__dict__[name] = self.__dict__[name]
        return model

    def with_coherence(self, coherence: float) -> "MarkovModel":
        """The same model with coherent moves of the given coherence.

        Parameters
        ----------
        coherence : float
            rho in [0, 1] (:mod:`cfbmarkov.markov.coherence`).

        Returns
        -------
        MarkovModel

        Raises
        ------
        InputError
            If ``coherence`` is not in [0, 1].
        """
        return self._derived(coherence=coherence)

    def with_selection(self, selection: dict) -> "MarkovModel":
        """The same model, recording how its state space and lag were chosen.

        Parameters
        ----------
        selection : dict
            JSON-serialisable record (candidates, scores, reason).

        Returns
        -------
        MarkovModel
            A copy with ``selection`` set.
        """
        return self._derived(selection=dict(selection))

    # -- description -------------------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        """Estimator, lag (s), window (s), state space, source and selection.

        Returns
        -------
        dict
            JSON-serialisable.
        """
        out = {"estimator": self.estimator, "lag": self.lag,
               "window": list(self.window) if self.window else None,
               "state_space": self.state_space.to_attrs(), "source": self.source}
        if self.coherence:
            out["coherence"] = self.coherence
        if self.selection:
            out["selection"] = self.selection
        return out

    def warnings(self) -> list[str]:
        """Lines about states entered but never left (traps) and, for an open riser, about
        many tracks that ended or began away from the faces, for ``fit`` and ``info``."""
        lines = []
        if self.boundary == "open":
            for what, censored, counted, face in (
                    ("ended", self.censored_tracks[0], int(self.exit_counts.sum()), "outlet"),
                    ("began", self.censored_tracks[1], int(self.entry_counts.sum()), "inlet")):
                if censored > CENSORED_SHARE * (censored + counted):
                    lines.append(
                        f"  {censored} tracks {what} more than one cell from the {face} "
                        f"({100 * censored / (censored + counted):.0f} % of those that {what} "
                        f"near it or not) and were left out as censored; if particles cross the "
                        "face farther than a cell per lag, use taller cells or a shorter lag")
        trapped = self.entered_never_left
        if not trapped.size or self.trap_share == 0.0:
            return lines
        return lines + [f"  states entered but never left: {trapped.size} ({_short_list(trapped)}): "
                f"they keep their particles (P_ii = 1) or move as their cell; "
                f"{100 * self.trap_share:.1f} % of the particle-frames are in states that "
                "can reach a trap (fit --connected leaves them out)"]

    def summary(self) -> str:
        """A few lines of text: state space, lag, fitting data, passes, unvisited states
        and the exact E(RT) and SD(RT).

        Returns
        -------
        str
        """
        lines = [
            f"Markov chain model: {self.state_space.describe()}, lag {self.lag:g} s, "
            f"estimator '{self.estimator}'",
            f"  fitted on {self.source} window "
            f"{'all' if self.window is None else f'{self.window[0]:g}:{self.window[1]:g} s'}: "
            f"{self.n_transitions} transitions over {self.frame_pairs} frame pairs",
            f"  passes through the periodic boundary: {int(self.counts_up.sum())} up, "
            f"{int(self.counts_down.sum())} down" if self.boundary == "periodic" else
            f"  open riser: {int(self.exit_counts.sum())} exits through the outlet, "
            f"{int(self.entry_counts.sum())} entries through the inlet "
            f"({self.inflow_per_lag:.4g} per lag) into "
            f"{int(np.count_nonzero(self.entry_counts))} states; tracks censored (ended or "
            f"began away from the faces): {self.censored_tracks[0]}, {self.censored_tracks[1]}",
        ]
        never = np.setdiff1d(self.unvisited_states, self.entered_never_left)
        lines.append(f"  states never visited: {never.size}"
                     + (f" ({_short_list(never)})" if never.size else ""))
        lines.extend(self.warnings())
        if self.entered_never_left.size and self.trap_share == 0.0:
            lines.append(f"  states entered but never left: {self.entered_never_left.size} "
                         f"({_short_list(self.entered_never_left)}): no state leads to them")
        if self.connected:
            lines.append("  fitted on the largest strongly connected set of the counts")
        if self.regime_chain is not None:
            g = self.regime_chain
            stay = ", ".join(f"{g[r, r]:.3f}" for r in range(g.shape[0]))
            lines.append(f"  regime chain: stays per lag {stay} (mean durations "
                         + ", ".join(f"{self.lag / max(1.0 - g[r, r], 1e-12):.3g}"
                                     for r in range(g.shape[0])) + " s)")
        if self.coherence:
            lines.append(f"  coherent moves (the cluster model): coherence {self.coherence:.3f} "
                         "(share of a state's particles that move together each lag)")
        classes = self.closed_classes
        if len(classes) > 1:
            lines.append(f"  closed classes: {len(classes)} (sizes "
                         f"{', '.join(str(c.size) for c in classes[:6])}"
                         f"{', ...' if len(classes) > 6 else ''}): a reducible chain; the "
                         "exact RTD weights each class by its observed entry flux")
        if self.selection:
            lines.append(f"  chosen automatically: {self.selection.get('reason', '')}")
        try:
            r = self.rtd()
            lines.append(f"  exact residence time: E(RT) = {r.mean:.4g} s, SD(RT) = {r.sd:.4g} s")
        except Exception as exc:  # a model without exits still has a summary
            lines.append(f"  exact residence time: none ({exc})")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"MarkovModel({self.state_space.describe()}, lag={self.lag:g} s, "
                f"estimator={self.estimator!r}, transitions={self.n_transitions})")

    # -- persistence (the file layout lives in cfbmarkov.markov.model_file) --------------
    def save(self, path: str | os.PathLike) -> Path:
        """Write the model as an HDF5 file at ``path``, atomically, and return the path
        (:func:`~cfbmarkov.markov.model_file.write_model`; InputError if it cannot be put
        in place)."""
        from cfbmarkov.markov.model_file import write_model

        return write_model(self, path)

    @classmethod
    def from_group(cls, group: h5py.Group | h5py.File, label: str = "") -> "MarkovModel":
        """Rebuild a model from an HDF5 group written by :meth:`save` (or attached to a
        prediction as ``/provenance/model``); see
        :func:`~cfbmarkov.markov.model_file.read_model_group`.

        Raises
        ------
        InputError
            If the group is not a cfbmarkov model, or is damaged or invalid.
        """
        from cfbmarkov.markov.model_file import read_model_group

        return read_model_group(group, label)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "MarkovModel":
        """Read a model file written by :meth:`save`
        (:func:`~cfbmarkov.markov.model_file.read_model`; InputError if the file is
        missing, empty, not HDF5, not a model file, or damaged)."""
        from cfbmarkov.markov.model_file import read_model

        return read_model(path)

    @classmethod
    def from_trajectories(cls, trajectories) -> "MarkovModel | None":
        """The model attached to a prediction file (an open
        :class:`~cfbmarkov.trajectories.Trajectories`), or None where it has none.

        Raises
        ------
        InputError
            If the attached group is not a valid model.
        """
        group = trajectories.group("model")
        return None if group is None else cls.from_group(group, str(trajectories.path))


def _short_list(values: np.ndarray, limit: int = 12) -> str:
    text = ", ".join(str(v) for v in values[:limit])
    return text + (", ..." if values.size > limit else "")
