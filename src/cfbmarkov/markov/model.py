"""The fitted Markov chain model: immutable, saved as HDF5, answering questions.

A :class:`MarkovModel` holds the transition matrix P (S x S), the pooled counts of the
fitting window, the counts of transitions that passed up through the top or down through
the bottom of the periodic riser, and its state space. It answers:

- :meth:`propagate` (Eq. 5-6), with or without the outflow of ended residences, and
  :meth:`batch_injection_maps` (Eq. 8, the paper's Fig. 4-7);
- :meth:`rtd`: the exact residence-time distribution (first passage of the lap counter);
- :meth:`monte_carlo` / :meth:`predict`: Monte Carlo of every particle (Eq. 7) with lap
  counters, :meth:`predict` writing a trajectory file like any other.

The file layout and its reading and writing are in :mod:`cfbmarkov.markov.model_file`.
"""

from __future__ import annotations

import copy
import os
import weakref
from dataclasses import InitVar, dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.kinetics.fields import CellFields
from cfbmarkov.limits import MAX_LAGS, check_finite, check_memory, check_seed
from cfbmarkov.markov import model_file, model_summary, propagation
from cfbmarkov.markov.adequacy import Adequacy
from cfbmarkov.markov.model_arrays import (SQUARE_ARRAYS, checked_arrays, checked_coherence,
                                          checked_flow_direction, checked_run_windows)
from cfbmarkov.markov.montecarlo import SparseChain, run_chain
from cfbmarkov.markov.open_flow import OpenFlow
from cfbmarkov.markov.regime_chain import (conditional_chain, regime_matrix, regime_path,
                                           start_regime, with_regime)
from cfbmarkov.markov.regimes import RegimeCells
from cfbmarkov.markov.states import StateSpace
from cfbmarkov.markov.uncertainty import ModelUncertainty

if TYPE_CHECKING:
    import h5py

    from cfbmarkov.markov.first_passage import ResidenceTimeDistribution



#: the model attached to each open prediction file, read once (:meth:`MarkovModel.from_trajectories`)
_ATTACHED: "weakref.WeakKeyDictionary[Any, tuple]" = weakref.WeakKeyDictionary()


def _read_only(method):
    """A cached property's array made read-only: the model is immutable, and what it returns
    is what later questions read."""
    def wrapped(self):
        value = method(self)
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
            value = value.view()   # a view of a read-only base cannot be made writeable
            value.setflags(write=False)
        return value

    wrapped.__doc__, wrapped.__name__ = method.__doc__, method.__name__
    return wrapped


def _whole_numbers(values, name: str) -> np.ndarray:
    """``values`` as a one-dimensional int64 array, refusing other shapes and fractions."""
    array = np.asarray(values)
    if array.ndim != 1:
        raise InputError(f"{name}: one value a particle, shape (N,), not {array.shape}")
    if array.dtype.kind == "f":
        if not (np.isfinite(array) & (array == np.round(array))).all():
            raise InputError(f"{name}: whole numbers, not fractions")
    elif array.dtype.kind not in "iu" and array.size:
        raise InputError(f"{name}: whole numbers, not {array.dtype}")
    return array.astype(np.int64)


@dataclass(frozen=True, eq=False)
class MarkovModel:
    """A fitted Markov chain model of particle motion; immutable.

    Made by an estimator (:meth:`~cfbmarkov.markov.estimate.TransitionEstimator.fit`,
    :func:`~cfbmarkov.markov.fit_model`) or read by :meth:`load`. The arrays are stored
    as read-only copies; with the keyword ``adopt=True`` the model takes the given [S, S]
    arrays as its own instead (made read-only, not copied, where they already have the
    model's dtype and are C-contiguous; checked as any others): the caller must not keep
    writing them. What an estimator makes for one model alone is adopted.

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
    open_flow : OpenFlow or None
        An open riser's inlet and outlet (None for a periodic riser). Its chain is
        absorbing: each lag a particle in state i leaves through the outlet with probability
        ``open_flow.exit_probability[i]``, else moves by P; particles enter through the inlet
        (``docs/definitions.md``, Open risers).
    coherence : float
        rho in [0, 1]: in the Monte Carlo, the probability that a particle takes the draw
        shared by the particles leaving its state at that step (coherent moves, the cluster
        model; :mod:`cfbmarkov.markov.coherence`); 0: independent particles (the paper's).
    adequacy : Adequacy or None
        The verdict on the fitting sample (:mod:`cfbmarkov.markov.adequacy`); None where
        none was formed.
    uncertainty : ModelUncertainty or None
        Intervals of the exact E(RT), SD(RT) and RTD per bin from the fitting window
        (:func:`cfbmarkov.analysis.intervals.model_intervals`); None where not computed.
    source_identity : str or None
        The content identity of the fitting window of ``source``
        (:func:`cfbmarkov.trajectory_identity.window_identity`), recorded by ``fit``; a
        re-read of the window (a comparison's intervals) is refused where it differs; a
        pooled fit's: one identity per run, in ``source`` order, joined by ``;``. None: not
        recorded (a model made from counts).
    cell_fields : CellFields or None
        The fitting window's time-averaged cell fields (solids fraction, distance to the
        wall, mean vertical velocity; :class:`~cfbmarkov.kinetics.CellFields`), recorded by
        ``fit`` for kinetics whose rates depend on them; None: not recorded.
    run_windows : tuple of (float, float) or None
        A pooled fit's fitting window of each run of ``source``, in its order (``window``
        is the first); None for one run.
    flow_direction : {"up", "down"}
        The fitting window's net solids flow, the direction residences are counted in
        (None given: read off the pass counts by
        :func:`~cfbmarkov.markov.model_arrays.checked_flow_direction`;
        ``docs/definitions.md``, Flow direction of a model).

    Raises
    ------
    InputError
        If an array does not have shape (S, S) for the state space, P holds negative or
        non-finite entries, its rows do not sum to 1, the pass fractions have the wrong
        shape, an open riser's flow is not of S states, or the coherence is not in [0, 1].

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
    open_flow: OpenFlow | None = None
    coherence: float = 0.0
    adequacy: Adequacy | None = None
    uncertainty: ModelUncertainty | None = None
    source_identity: str | None = None
    cell_fields: CellFields | None = None
    run_windows: tuple[tuple[float, float], ...] | None = None
    flow_direction: str | None = None
    # results derived once (RTDs, ...): a model's own, never passed on by dataclasses.replace
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    adopt: InitVar[bool] = field(default=False, kw_only=True)

    def __setstate__(self, state: dict) -> None:
        """Unpickled or deep-copied: the arrays read-only again (pickle does not keep the
        flag), so that nothing derived and cached can go stale."""
        from cfbmarkov._frozen import freeze_arrays

        self.__dict__.update(state)
        freeze_arrays(state)

    def __post_init__(self, adopt: bool):
        from cfbmarkov._frozen import frozen_record

        # the selection record and a pooled fit's sources: read-only, not the caller's
        object.__setattr__(self, "selection", frozen_record(self.selection))
        object.__setattr__(self, "source", frozen_record(self.source))
        if not isinstance(self.state_space, StateSpace):
            raise InputError(f"model state_space {self.state_space!r} is a "
                             f"{type(self.state_space).__name__}, not a state space: give e.g. "
                             "CellGrid(6, 38, 0.09, 0.95) (cfbmarkov.markov)")
        s = self.state_space.n_states
        arrays, fractions = checked_arrays({name: getattr(self, name) for name in SQUARE_ARRAYS},
                                           self.pass_fractions, self.lag, self.state_space,
                                           adopt)
        for name, value in arrays.items():
            object.__setattr__(self, name, value)
        object.__setattr__(self, "pass_fractions", fractions)
        object.__setattr__(self, "coherence", checked_coherence(self.coherence))
        object.__setattr__(self, "flow_direction", checked_flow_direction(
            self.flow_direction, self.counts_up, self.counts_down, self.open_flow is not None))
        if not (isinstance(self.frame_pairs, (int, np.integer)) and self.frame_pairs >= 0):
            raise InputError(f"model frame_pairs {self.frame_pairs!r} must be a count >= 0")
        if self.window is not None and not (len(self.window) == 2 and all(
                np.isfinite(self.window)) and self.window[1] > self.window[0]):
            raise InputError(f"model window {self.window!r} is not two finite times (A < B)")
        if self.run_windows is not None:
            object.__setattr__(self, "run_windows", checked_run_windows(self.run_windows,
                                                                        self.source))
        if self.open_flow is not None and self.open_flow.n_states != s:
            raise InputError(f"model exit_probability must be {s} non-negative numbers")
        if self.cell_fields is not None and self.cell_fields.n_cells != self.state_space.n_cells:
            raise InputError(f"model cell fields of {self.cell_fields.n_cells} cells for a grid "
                             f"of {self.state_space.n_cells}")

    @property
    def boundary(self) -> Boundary:
        """The riser's vertical boundary: ``Boundary.OPEN`` where the model has an
        :attr:`open_flow`, else ``Boundary.PERIODIC``."""
        return Boundary.PERIODIC if self.open_flow is None else Boundary.OPEN

    @cached_property
    @_read_only
    def absorbing_matrix(self) -> np.ndarray:
        """Q = diag(1 - r) P, the sub-stochastic matrix of an open riser's chain (the
        transitions among the states; r leaves through the outlet), float64 [S, S]
        (:meth:`OpenFlow.absorbing_matrix <cfbmarkov.markov.open_flow.OpenFlow.absorbing_matrix>`).

        Raises
        ------
        InputError
            For a periodic riser's model (no outlet).
        """
        if self.open_flow is None:
            raise InputError("a periodic riser's model has no outlet (no absorbing matrix)")
        return self.open_flow.absorbing_matrix(self.transition_matrix)

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
    @_read_only
    def unvisited_states(self) -> np.ndarray:
        """States with no outgoing transition in the window, int64 [U].

        They stay in place (P_ii = 1) or move as the other states of their cell
        (``docs/definitions.md``, Unvisited states).
        """
        if self.n_transitions == 0:      # a model given by its matrix, not fitted
            return np.zeros(0, np.int64)
        left = self.counts.sum(axis=1)
        if self.open_flow is not None:   # leaving through the outlet is leaving too
            left = left + self.open_flow.exit_counts
        return np.flatnonzero(left == 0)

    @cached_property
    @_read_only
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
        from cfbmarkov.markov.connectivity import states_reaching

        traps = [i for i in self.entered_never_left if self.transition_matrix[i, i] == 1.0]
        occupancy = self.counts.sum(axis=1).astype(np.float64)
        if not traps or occupancy.sum() == 0:
            return 0.0
        return float(occupancy[states_reaching(self.transition_matrix, traps)].sum()
                     / occupancy.sum())

    @cached_property
    def closed_classes(self) -> tuple[np.ndarray, ...]:
        """Closed classes of P with two or more states, largest first (read-only): more than
        one means a reducible chain (particles in one never reach the other's states)."""
        from cfbmarkov.markov.connectivity import closed_classes

        classes = tuple(closed_classes(self.transition_matrix, min_size=2))
        for members in classes:
            members.setflags(write=False)
        return classes

    @cached_property
    @_read_only
    def up_fraction(self) -> np.ndarray:
        """Fraction of the i -> j transitions that passed up through the top, float64 [S, S]."""
        if self.pass_fractions is not None:
            return self.pass_fractions[0]
        c = self.counts.astype(np.float64)
        return np.divide(self.counts_up, c, out=np.zeros_like(c), where=c > 0)

    @cached_property
    @_read_only
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
    @_read_only
    def regime_chain(self) -> np.ndarray | None:
        """The regime chain G (R x R) of a regime model, read off its counts
        (:func:`~cfbmarkov.markov.regime_chain.regime_matrix`; from P itself for a model without
        counts); None for other state spaces."""
        if not isinstance(self.state_space, RegimeCells):
            return None
        weights = self.counts if self.n_transitions else self.transition_matrix
        return regime_matrix(weights, self.state_space)

    @cached_property
    def _conditional_chain(self) -> SparseChain:
        return conditional_chain(self.transition_matrix, self.up_fraction, self.down_fraction,
                                 self.state_space)

    @cached_property
    @_read_only
    def stationary_distribution(self) -> np.ndarray:
        """The long-run distribution over the states, float64 [S], summing to 1.

        A periodic riser's: pi P = pi; for a reducible chain, the particle-frames observed
        in the fitting window (uniform for a model given by its matrix) carried into the
        closed classes (:func:`~cfbmarkov.markov.connectivity.stationary_distribution`).
        An open riser's: where the particles of a steady riser are, fed at its inflow,
        e (I - Q)^-1 normalised (e the entry distribution, Q the absorbing matrix; the
        expected lags a particle spends in each state, Kemeny & Snell, Ch. III), not the
        stationary vector of P, which leaves out the exits and piles the particles up at
        the top.

        Raises
        ------
        CfbmarkovError
            For an open riser's chain whose entering particles reach a state they never
            leave (a trap: no steady state; fit with ``connected=True``). States the
            entries never reach (unvisited cells) hold 0.
        """
        if self.open_flow is not None:
            import warnings

            from scipy.sparse import csc_matrix, identity
            from scipy.sparse.linalg import spsolve

            from cfbmarkov.markov.connectivity import states_reaching

            q = csc_matrix(self.absorbing_matrix)
            entry = self.open_flow.entry_distribution
            # the states the entries reach (unvisited cells keep P_ii = 1 and are never
            # reached: they hold no particle)
            reached = np.flatnonzero(states_reaching(q.T, np.flatnonzero(entry > 0)))
            block = q[reached][:, reached]
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")          # scipy's MatrixRankWarning
                try:
                    lags = np.atleast_1d(spsolve(
                        (identity(reached.size, format="csc") - block).T.tocsc(),
                        entry[reached]))
                except RuntimeError:                     # singular: a trap
                    lags = np.full(reached.size, np.nan)
            if not (np.all(np.isfinite(lags)) and lags.min() >= -1e-9 and lags.sum() > 0):
                raise CfbmarkovError(
                    "an open riser's chain in which the entering particles reach a state "
                    "they never leave (a trap) has no steady state: its particles pile up "
                    "there; fit with connected=True (fit --connected) or on a longer window")
            full = np.zeros(self.n_states)
            full[reached] = np.clip(lags, 0.0, None)
            return full / full.sum()
        from cfbmarkov.markov.connectivity import stationary_distribution

        return stationary_distribution(self.transition_matrix,
                                       self.counts.sum(axis=1).astype(np.float64))

    # -- propagation (Eq. 5, 6, 8) -----------------------------------------------------
    def propagate(self, initial, steps: int, outflow: bool = False) -> np.ndarray:
        """State vectors from ``initial`` by S(t + lag) = S(t) P, lag by lag (Eq. 5-6); an
        open riser's by its absorbing matrix (:func:`cfbmarkov.markov.propagation.propagate`).

        Parameters
        ----------
        initial : array_like of float, shape (S,)
            S(0), non-negative.
        steps : int
            Number of lags to propagate, >= 0.
        outflow : bool, optional
            Remove the mass whose residence ends: it passes up through the top once more
            than it fell out of the bottom, or, for a model whose residences run downward
            (``flow_direction`` "down"), down through the bottom once more than it rose.

        Returns
        -------
        ndarray of float64, shape (steps + 1, S)
            S(k lag) for k = 0 .. steps; row 0 is ``initial``.

        Raises
        ------
        InputError
            For an ``initial`` of another shape, negative or not finite, or ``steps`` not a
            whole number >= 0.
        """
        return propagation.propagate(self, initial, steps, outflow)

    def steps_for(self, time: float, name: str = "time") -> int:
        """Number of lags in ``time``.

        Parameters
        ----------
        time : float
            A time (s), a whole multiple of the lag.
        name : str, optional
            What the time is, for messages (``duration``).

        Returns
        -------
        int
            ``time / lag``, >= 0.

        Raises
        ------
        InputError
            If ``time`` is negative or not a whole multiple of the lag.
        """
        time = check_finite(time, name, "s")
        if time < 0:
            raise InputError(f"{name} {time:g} s is negative: a time after the start, >= 0")
        lags = time / self.lag
        if not lags < MAX_LAGS:         # inf beyond the floats: int() would overflow
            raise InputError(f"{name} {time:g} s is {lags:.3g} lags of {self.lag:g} s, beyond "
                             f"any run ({MAX_LAGS:.0e} lags at most): give a shorter {name}")
        k = int(round(lags))
        if k < 0 or abs(k * self.lag - time) > 1e-6 * max(self.lag, abs(time)):
            below = max(int(np.floor(time / self.lag + 1e-9)), 0) * self.lag
            nearest = f"{below:g} or {below + self.lag:g} s" if below > 0 else \
                f"{self.lag:g} s"
            raise InputError(f"{name} {time:g} s is not a whole multiple of the model's lag "
                             f"{self.lag:g} s (e.g. {nearest})")
        return k

    def batch_injection_maps(self, times: Sequence[float], outflow: bool = False) -> np.ndarray:
        """Eq. (8): where a batch fed evenly over the inlet cells at t = 0 is at ``times``
        (:func:`cfbmarkov.markov.propagation.batch_injection_maps`).

        Parameters
        ----------
        times : sequence of float
            Times (s) after the injection, whole multiples of the lag.
        outflow : bool, optional
            Remove the mass whose residence ends (:meth:`propagate`); for a model whose
            residences run downward the batch is then fed over the top cells and leaves
            through the bottom.

        Returns
        -------
        ndarray of float64, shape (len(times), rows, columns)
            Probability per cell at each time; row 0 is the bottom (the paper's Fig. 4-7).
        """
        return propagation.batch_injection_maps(self, times, outflow)

    # -- residence times (cfbmarkov.markov.model_rtd) ---------------------------------
    def rtd(self, window: float | None = None, direction: str | None = None,
            occupancy=None, *, window_length: float | None = None
            ) -> "ResidenceTimeDistribution":
        """Exact residence-time distribution (no sampling noise), cached.

        Parameters
        ----------
        window : float, optional
            Length (s) of an analysis window: the RTD as seen in it, the quantity a
            sample-based RTD estimates (None: the intrinsic RTD); taken as the nearest
            whole number of lags (a window's frame pairs one lag apart), the length the
            result's ``window`` gives.
        direction : {"up", "down"}, optional
            A periodic riser's residences from passes up through the top or, for a net
            downflow, down through the bottom (the pass fractions swapped;
            ``docs/definitions.md``, Net downflow); default :attr:`flow_direction`.
        occupancy : array_like of float, shape (S,), optional
            With ``window``, a periodic riser's: where the window's particles start
            (weights per state; default the fitting window's particle-frames per state).
            The window counts records of the lap counter from its first frame, as its
            samples do (:func:`~cfbmarkov.markov.first_passage.window_rtd`).
        window_length : float, optional
            The same as ``window``, under the name the other functions give a window's
            length (give one of the two).

        Returns
        -------
        ResidenceTimeDistribution
            The intrinsic RTD in the model's direction carries the model's
            :attr:`uncertainty` (its ``uncertainty``; None where the model has none).

        Raises
        ------
        CfbmarkovError
            If the model has no transition through the boundary in ``direction`` (no
            residence ends), or no residence fits in ``window``; InputError for a
            ``direction`` that is neither up nor down, ``occupancy`` without ``window``,
            ``window`` and ``window_length`` both given, or a window given as a (start,
            stop) pair or other sequence instead of a length.

        Warns
        -----
        UnresolvedWarning
            Once per model and direction, where the intrinsic RTD leaves more than 1 % of
            its residences unresolved (e.g. ``direction="down"`` on a net upflow): its
            E(RT) and SD(RT) then describe the others
            (:func:`~cfbmarkov.markov.model_summary.unresolved_warning`).

        Notes
        -----
        See :func:`~cfbmarkov.markov.first_passage.exact_rtd` and ``docs/definitions.md`` (Residence
        time).

        References
        ----------
        J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton
        (1960) (Ch. III, absorbing chains).
        """
        from cfbmarkov.markov.model_rtd import model_rtd

        if window_length is not None:
            if window is not None:
                raise InputError("rtd(): give the window's length once, as window_length= "
                                 "(window= is the same argument)")
            window = window_length
        if isinstance(window, (tuple, list, np.ndarray)) and np.ndim(window) >= 1:
            if np.size(window) == 2:
                raise InputError(f"rtd(): window {window!r} is a (start, stop) pair; the RTD "
                                 "seen in a window takes its length: "
                                 "window_length=stop - start")
            raise InputError(f"rtd(): window {window!r} is not a length (s): give one "
                             "number, e.g. window_length=5.0")
        if occupancy is not None and window is None:
            raise InputError("occupancy= says where a window's particles start: give the "
                             "window's length with it (rtd(window=..., occupancy=...)); the "
                             "intrinsic RTD starts from the entry distribution")
        rtd = model_rtd(self, window, direction, occupancy)
        key = ("unresolved-warned", direction or self.flow_direction)
        if window is None and key not in self._cache:
            from cfbmarkov.markov.model_summary import unresolved_warning

            self._cache[key] = line = unresolved_warning(rtd, key[1], self.flow_direction)
            if line is not None:
                import warnings

                from cfbmarkov.errors import UnresolvedWarning

                warnings.warn(line, UnresolvedWarning, stacklevel=2)
        return rtd

    # -- Monte Carlo -------------------------------------------------------------------
    def monte_carlo(self, initial_states, n_steps: int, seed: int = 0, initial_laps=None,
                    progress=None) -> tuple[np.ndarray, np.ndarray]:
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
        progress : callable, optional
            ``progress(steps)`` is called with the lags run so far after each piece of the
            run (pieces of about 2e7 particle-steps, between which a Ctrl-C is taken; the
            draws do not depend on the pieces).

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
            If the initial states are not whole numbers in one dimension, one lies outside
            the state space, ``n_steps`` is not a non-negative whole number,
            ``initial_laps`` is not N whole numbers, or the run's states and laps would not
            fit in memory.

        References
        ----------
        Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
        Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
        doi:10.3390/pr13030614 (Eq. 7, the cumulative rule).
        """
        seed = check_seed(seed)
        initial_states = _whole_numbers(initial_states, "initial_states")
        if initial_states.size and (initial_states.min() < 0 or initial_states.max() >= self.n_states):
            low, high = int(initial_states.min()), int(initial_states.max())
            absent = (" (-1 marks a particle absent from the frame initial_states read: "
                      "run the present ones, states[states >= 0])" if low == -1 else "")
            raise InputError(f"initial states outside the model's state space 0 .. "
                             f"{self.n_states - 1}: from {low} to {high}{absent}")
        if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 0:
            raise InputError(f"n_steps {n_steps!r}: the number of lags to run, a whole number "
                             ">= 0")
        # states and laps (int32 each) of every particle at every lag; an open riser's
        # newcomers add their columns
        newcomers = (0.0 if self.open_flow is None
                     else float(self.open_flow.inflow_per_lag) * int(n_steps))
        check_memory(8.0 * (int(n_steps) + 1.0) * (initial_states.size + newcomers),
                     f"a Monte Carlo of {initial_states.size} particles over {int(n_steps)} "
                     "lags", "run fewer particles or lags")
        if initial_laps is not None:
            initial_laps = _whole_numbers(initial_laps, "initial_laps")
            if initial_laps.shape != initial_states.shape:
                raise InputError(f"initial_laps holds {initial_laps.size} laps for "
                                 f"{initial_states.size} particles: one a particle")
            limit = np.iinfo(np.int32).max      # the lap counter of trajectory files
            if initial_laps.size and np.abs(initial_laps).max() >= limit:
                raise InputError(f"initial_laps: a lap beyond +-{limit} (the lap counter is "
                                 "a 32-bit integer)")
        chain, offset, retag = self._chain, None, None
        if self.regime_chain is not None:
            # one regime path for every particle, each moving by the chain conditioned on it
            space = self.state_space
            path = regime_path(self.regime_chain, start_regime(initial_states, space), n_steps,
                               seed)
            chain, offset = self._conditional_chain, path * self.n_states

            def retag(states, steps):
                return with_regime(states, path[steps], space)
        if self.open_flow is not None:
            states = self.open_flow.monte_carlo(chain, initial_states, n_steps, seed, offset,
                                                retag, self.coherence, progress)
            return states, np.zeros_like(states)
        return run_chain(chain, initial_states, n_steps, seed, initial_laps, offset,
                         self.coherence, progress)

    def initial_states(self, trajectories, start: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The particles' states, positions and laps in the frame at ``start``
        (:func:`cfbmarkov.markov.prediction.initial_states`: what a prediction starts from).

        Parameters
        ----------
        trajectories : str, os.PathLike or Trajectories
            The file whose frame at ``start`` gives them.
        start : float
            The frame's time (s).

        Returns
        -------
        states : ndarray of int, shape (N,)
            -1 for a particle absent from the frame (an open riser's, a tracer out of view).
        positions : ndarray of float64, shape (N, 2) or (N, 3)
            m.
        laps : ndarray of int, shape (N,)
        """
        from cfbmarkov.markov import prediction

        return prediction.initial_states(self, trajectories, start)

    def predict(self, trajectories, start: float, duration: float, seed: int = 0,
                output: str | os.PathLike | None = None, progress: bool | str = False,
                kinetics=None, force: bool = False):
        """Monte Carlo prediction (Eq. 7) from the particles' states in the frame at
        ``start``, written as a trajectory file when ``output`` is given
        (:func:`cfbmarkov.markov.prediction.predict`, which details each parameter).

        Parameters
        ----------
        trajectories : str, os.PathLike or Trajectories
            The file whose frame at ``start`` gives the initial states.
        start, duration : float
            Start time and length of the prediction (s); ``duration`` a whole number of lags.
        seed : int, optional
            Seed of the Monte Carlo: the same prediction for any thread count.
        output : str or os.PathLike, optional
            Write the prediction as a trajectory file.
        progress : bool or {"bar", "lines"}, optional
            Show progress on stderr.
        kinetics : Kinetics or StateKinetics, optional
            Particle properties carried along the paths, stored per frame.
        force : bool, optional
            Replace an existing ``output`` that is a run or a model file.

        Returns
        -------
        pathlib.Path or tuple
            The output path, or (times [K+1] s, states [K+1, N], laps [K+1, N]) without one
            (and the properties [P, K+1, N] as a fourth item with ``kinetics``).

        Raises
        ------
        InputError
            For a file that does not fit the model or lacks the frame at ``start``, a
            ``duration`` that is not a whole number of lags, kinetics of another state
            space, or an output that cannot be written.
        """
        from cfbmarkov.markov import prediction

        return prediction.predict(self, trajectories, start, duration, seed, output, progress,
                                  kinetics, force)

    def _derived(self, **changes) -> "MarkovModel":
        """This model with fields that change neither the chain nor anything derived from
        it (the coherence, the selection record) replaced by values the caller has checked.
        The copy shares this model's validated read-only arrays (not checked again) and what
        it has already derived (sampling chain, pass fractions, exact RTDs, ...), not
        recomputed: calibrating the coherence runs the same chain with many values of it."""
        from cfbmarkov._frozen import frozen_record

        model = copy.copy(self)         # the fields and the cached properties, shared
        object.__setattr__(model, "_cache", dict(self._cache))
        for name, value in changes.items():
            if name in ("selection", "source"):     # read-only, as __post_init__ makes them
                value = frozen_record(value)
            object.__setattr__(model, name, value)
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
        return self._derived(coherence=checked_coherence(coherence))

    def with_selection(self, selection: dict) -> "MarkovModel":
        """The same model recording how its state space and lag were chosen (``selection``:
        a JSON-serialisable record of candidates, scores and reason)."""
        return self._derived(selection=dict(selection))

    def with_source_identity(self, identity: str | None) -> "MarkovModel":
        """The same model recording the content identity of its fitting window
        (:func:`cfbmarkov.trajectory_identity.window_identity` of ``source`` and ``window``)."""
        return self._derived(source_identity=identity)

    def with_adequacy(self, adequacy: Adequacy | None) -> "MarkovModel":
        """The same model, holding the verdict on its fitting sample
        (:func:`cfbmarkov.analysis.adequacy.assess_adequacy`; None: none)."""
        return self._derived(adequacy=adequacy)

    def with_uncertainty(self, uncertainty: ModelUncertainty | None) -> "MarkovModel":
        """The same model (chain and derived quantities shared) carrying the intervals of
        its residence-time figures, a :class:`~cfbmarkov.markov.uncertainty.ModelUncertainty`
        from :func:`cfbmarkov.analysis.intervals.model_intervals` (None: none); InputError
        for anything else."""
        if uncertainty is not None and not isinstance(uncertainty, ModelUncertainty):
            raise InputError(f"model uncertainty must be a ModelUncertainty, not "
                             f"{type(uncertainty).__name__}")
        return self._derived(uncertainty=uncertainty)

    def with_cell_fields(self, fields: CellFields | None) -> "MarkovModel":
        """The same model holding its fitting window's cell fields (None: none); InputError
        where they are not one value per cell of its grid."""
        if fields is not None and fields.n_cells != self.state_space.n_cells:
            raise InputError(f"cell fields of {fields.n_cells} cells for a model grid of "
                             f"{self.state_space.n_cells}")
        return self._derived(cell_fields=fields)

    # -- description -------------------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        """Estimator, lag (s), window (s), state space, source and selection (and the flow
        direction where it is down).

        Returns
        -------
        dict
            JSON-serialisable; a copy the caller may change.
        """
        from cfbmarkov._frozen import thawed_record

        out = {"estimator": self.estimator, "lag": self.lag,
               "window": list(self.window) if self.window else None,
               "state_space": self.state_space.to_attrs(),
               "source": thawed_record(self.source)}
        if self.coherence:
            out["coherence"] = self.coherence
        if self.flow_direction == "down":
            out["flow_direction"] = "down"
        if self.selection:
            out["selection"] = thawed_record(self.selection)
        return out

    def warnings(self) -> list[str]:
        """Lines about states entered but never left (traps), for an open riser about many
        tracks that ended or began away from the faces, and the fitting sample's verdict
        (:attr:`adequacy`), for ``fit``, ``predict`` and ``info``
        (:func:`~cfbmarkov.markov.model_summary.model_warnings`).

        Returns
        -------
        list of str
            One line each, as ``fit`` prints them after ``warning:`` (no indentation).
        """
        return [line.strip() for line in model_summary.model_warnings(self)]

    def summary(self, warnings: bool = True) -> str:
        """A few lines of text: state space, lag, fitting data, passes, unvisited states
        and the exact E(RT) and SD(RT) (:func:`~cfbmarkov.markov.model_summary.model_summary`).

        Parameters
        ----------
        warnings : bool, optional
            Include the model's warnings (:meth:`warnings`).

        Returns
        -------
        str
        """
        return model_summary.model_summary(self, warnings)

    def __repr__(self) -> str:
        window = (f", window={self.window[0]:g}-{self.window[1]:g} s" if self.window
                  else "")
        extra = (f", coherence={self.coherence:.3g}" if self.coherence else "") + (
            ", open riser" if self.open_flow is not None else "") + (
            f", runs={len(self.run_windows)}" if self.run_windows else "")
        return (f"MarkovModel({self.state_space.describe()}, lag={self.lag:g} s, "
                f"estimator={self.estimator!r}{window}, transitions={self.n_transitions}"
                f"{extra})")

    # -- persistence (the file layout lives in cfbmarkov.markov.model_file) --------------
    def save(self, path: str | os.PathLike, force: bool = False) -> Path:
        """Write the model as an HDF5 file at ``path``, atomically, and return the path
        (:func:`~cfbmarkov.markov.model_file.write_model`).

        An existing model file at ``path`` is replaced; a file of another kind (a
        trajectory file, an image) only with ``force=True``, as ``cfbmarkov fit -o``
        with ``--force``.

        Parameters
        ----------
        path : str or os.PathLike
            The model file to write (HDF5, ``.h5``); its folder is created if missing.
        force : bool, optional
            Replace a file of another kind at ``path`` (default False: refused).

        Returns
        -------
        pathlib.Path
            The path written.

        Raises
        ------
        InputError
            If ``path`` holds a file of another kind and ``force`` is False, or the file
            cannot be put in place.
        """
        from cfbmarkov._outputs import claim_output

        with claim_output(path, "save", "model", force=force):
            return model_file.write_model(self, path)

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
        return model_file.read_model_group(group, cls, label)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "MarkovModel":
        """Read a model file written by :meth:`save` (or by ``cfbmarkov fit``)
        (:func:`~cfbmarkov.markov.model_file.read_model`).

        Parameters
        ----------
        path : str or os.PathLike
            The model file (HDF5).

        Returns
        -------
        MarkovModel
            The model as saved: its arrays read-only, with its interval, verdict, cell
            fields and selection record where the file holds them.

        Raises
        ------
        InputError
            If the file is missing, empty, not HDF5, not a model file (a trajectory file,
            say), or damaged.
        """
        return model_file.read_model(path, cls)

    @classmethod
    def from_trajectories(cls, trajectories) -> "MarkovModel | None":
        """The model attached to a prediction file, or None where it has none. An open
        :class:`~cfbmarkov.trajectories.Trajectories` is read once: the verbs that ask it
        several times (``compare``: intervals, verdict, exact RTD, maps, kinetics) share
        one model and its cached RTD.

        Parameters
        ----------
        trajectories : Trajectories or str or os.PathLike
            The prediction file, open or by its path (then opened, read and closed).

        Raises
        ------
        InputError
            If the attached group is not a valid model, or the file is not a trajectory
            file.
        """
        if isinstance(trajectories, (str, os.PathLike)):
            from cfbmarkov.trajectories import Trajectories

            with Trajectories(trajectories) as opened:
                return cls.from_trajectories(opened)
        from cfbmarkov.trajectories import Trajectories

        if not isinstance(trajectories, Trajectories):
            raise InputError(f"MarkovModel.from_trajectories({trajectories!r}): give a "
                             "prediction file's path or its open Trajectories")
        found = _ATTACHED.get(trajectories)
        if found is not None and found[0] is cls:
            return found[1]
        group = trajectories.group("model")
        model = None if group is None else cls.from_group(group, str(trajectories.path))
        _ATTACHED[trajectories] = (cls, model)
        return model
