"""The open riser's flow through a Markov chain model: where particles enter, how likely they
leave through the outlet from each state, and how many enter per lag
(``docs/definitions.md``, Open risers).

An open riser's chain is absorbing: each lag a particle in state i leaves through the
outlet with probability r_i, else moves by the row-stochastic P, so the chain among the
states is Q = diag(1 - r) P; particles enter through the inlet into state j with
probability e_j, the observed entries normalised. An :class:`OpenFlow` holds these and
answers what depends on them: the exact residence-time distribution, the Monte Carlo with
inflow and outflow, the fields of a model file and the lines of a model's summary. A
periodic riser's model has none.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import InputError
from cfbmarkov.markov.montecarlo import SparseChain
from cfbmarkov.markov.open_montecarlo import run_open_chain
from cfbmarkov._repr import compact_repr

if TYPE_CHECKING:
    from cfbmarkov.markov.first_passage import ResidenceTimeDistribution

#: share of an open riser's tracks ending (beginning) away from the outlet (inlet) above
#: which :meth:`OpenFlow.warnings` says so
CENSORED_SHARE = 0.05
#: relative difference of the entries through the inlet and the exits through the outlet
#: above which :meth:`OpenFlow.warnings` says the inflow does not balance the outflow
IMBALANCE_SHARE = 0.25
#: the [S] datasets of an open riser's model file
OPEN_DATASETS = ("exit_probability", "exit_counts", "entry_counts")


@dataclass(frozen=True, eq=False)
class OpenFlow:
    """The inlet and outlet of an open riser's model; immutable.

    Made by the estimator from the counts of an open riser
    (:func:`~cfbmarkov.markov.estimate.open_chain`) or read from a model file
    (:meth:`from_group`). The arrays are stored as read-only copies.

    Attributes
    ----------
    exit_probability : ndarray of float64, shape (S,)
        r_i, the probability that a particle in state i leaves through the outlet within
        one lag.
    exit_counts, entry_counts : ndarray of int64, shape (S,)
        Exits from / entries into each state observed in the fitting window.
    inflow_per_lag : float
        Mean number of particles entering through the inlet per lag.
    censored_tracks : tuple of int
        (vanished, appeared): tracks that ended or began more than one cell from the outlet
        or inlet face, left out as censored.
    returned_entries : int
        Returns through the inlet in the fitting window, not among ``entry_counts``:
        particles that came back within a residence (they fell back out through the inlet,
        or left the view, and did not leave through the outlet since); their residences go
        on (0 in a model file written without the count).
    returned_time : float
        The residence time (s) that no transition of the chain counts around the returns:
        from a returning particle's last state before its fall to its first after it,
        summed.
    lag_sequences : int
        The sequences of frames one lag apart the counts were summed over: the lag in
        frames (every frame starts a transition), so that an exit, entry, return or
        censored track every sequence sees is counted that many times; one sequence's
        counts, on average, are the counts over it (:meth:`observed`). 1 in a model file
        written without it.

    Raises
    ------
    InputError
        If an array is missing, is not S non-negative finite numbers (S the length of
        ``exit_probability``), an exit probability exceeds 1, no particle entered, or the
        inflow is negative or not finite.

    References
    ----------
    J. G. Kemeny and J. L. Snell, Finite Markov Chains, Van Nostrand, Princeton (1960),
    Ch. III (absorbing chains).
    """

    __repr__ = compact_repr   # arrays by their shape: a notebook's echo stays short

    exit_probability: np.ndarray
    exit_counts: np.ndarray
    entry_counts: np.ndarray
    inflow_per_lag: float = 0.0
    censored_tracks: tuple[int, int] = (0, 0)
    returned_entries: int = 0
    returned_time: float = 0.0
    lag_sequences: int = 1

    def __post_init__(self):
        s = int(np.size(self.exit_probability))
        for name, dtype in (("exit_probability", np.float64), ("exit_counts", np.int64),
                            ("entry_counts", np.int64)):
            value = getattr(self, name)
            if value is None:
                raise InputError(f"an open riser's model needs {name}")
            value = np.array(value, dtype=dtype)
            if (value.shape != (s,) or not value.size or not np.all(np.isfinite(value))
                    or value.min() < 0):
                raise InputError(f"model {name} must be {s} non-negative numbers")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.exit_probability.max() > 1.0:
            raise InputError("model exit probabilities exceed 1")
        if (isinstance(self.lag_sequences, bool)
                or not isinstance(self.lag_sequences, (int, np.integer))
                or self.lag_sequences < 1):
            raise InputError(f"model lag_sequences {self.lag_sequences!r} must be a whole "
                             "number >= 1")
        if self.entry_counts.sum() == 0:
            began = self.observed(self.censored_tracks[1])
            away = (f"; {began} tracks began in it more than one cell from the inlet, "
                    "censored: where particles are inserted or come into view above the "
                    "inlet's cell, taller --cells (or a shorter lag) count them as entries"
                    if began else "")
            raise InputError("an open riser's model without any entry through the inlet: the "
                             "fitting window saw no particle enter (its entry distribution is "
                             f"empty){away}; fit on a window in which particles enter through "
                             "the bottom, or import a riser that recycles its particles with "
                             "--boundary periodic")
        if not (np.isfinite(self.inflow_per_lag) and self.inflow_per_lag >= 0):
            raise InputError(f"model inflow {self.inflow_per_lag!r} per lag must be >= 0")
        if not (isinstance(self.returned_entries, (int, np.integer))
                and self.returned_entries >= 0):
            raise InputError(f"model returned_entries {self.returned_entries!r} must be a "
                             "count >= 0")
        if not (np.isfinite(self.returned_time) and self.returned_time >= 0):
            raise InputError(f"model returned_time {self.returned_time!r} s must be >= 0")

    def observed(self, count) -> int:
        """A count summed over the :attr:`lag_sequences` as one sequence of frames a lag
        apart sees it, on average (the count over the sequences, rounded): each exit,
        entry, return or censored track once where every sequence sees it.

        Parameters
        ----------
        count : int or float
            A count of the model's (e.g. ``exit_counts.sum()``).

        Returns
        -------
        int
        """
        return int(round(float(count) / int(self.lag_sequences)))

    @property
    def n_states(self) -> int:
        """Number of states S."""
        return int(self.exit_probability.size)

    @property
    def entry_distribution(self) -> np.ndarray:
        """Where particles enter: the observed entries per state, normalised, float64 [S]."""
        return self.entry_counts / self.entry_counts.sum()

    def absorbing_matrix(self, transition_matrix: np.ndarray) -> np.ndarray:
        """Q = diag(1 - r) P, the sub-stochastic matrix among the states.

        Parameters
        ----------
        transition_matrix : ndarray of float64, shape (S, S)
            P, the row-stochastic transitions of the particles that stay.

        Returns
        -------
        ndarray of float64, shape (S, S)
        """
        return (1.0 - self.exit_probability)[:, None] * transition_matrix

    def rtd(self, absorbing: np.ndarray, lag: float) -> "ResidenceTimeDistribution":
        """Exact residence-time distribution: first passage to the outside from the entry
        distribution, f(k) = e Q^(k-1) r (:func:`~cfbmarkov.markov.first_passage.open_rtd`).

        Parameters
        ----------
        absorbing : ndarray of float64, shape (S, S)
            Q, from :meth:`absorbing_matrix`.
        lag : float
            The lag (s).

        Returns
        -------
        ResidenceTimeDistribution

        Raises
        ------
        TrappedResidences
            If no particle that enters can ever leave.
        """
        from cfbmarkov.markov.first_passage import open_rtd

        return open_rtd(absorbing, self.exit_probability, self.entry_distribution, lag)

    def monte_carlo(self, chain: SparseChain, initial_states: np.ndarray, n_steps: int,
                    seed: int, row_offset=None, retag=None, coherence: float = 0.0,
                    progress=None) -> np.ndarray:
        """States of a Monte Carlo run with outflow and inflow
        (:func:`~cfbmarkov.markov.open_montecarlo.run_open_chain`).

        Parameters
        ----------
        chain : SparseChain
            P, the transitions of particles that stay.
        initial_states : ndarray of int, shape (N0,)
            States of the particles present at the start.
        n_steps : int
            Lags to run.
        seed : int
            Seed of the counter-based generator.
        row_offset : array_like of int, shape (n_steps + 1,), optional
            Row offset of each step in ``chain`` (a regime model's common path times S).
        retag : callable, optional
            ``retag(states, steps)``: the newcomers' states given their drawn states and
            entry steps.
        coherence : float, optional
            Probability that a particle takes its row's common draw.
        progress : callable, optional
            ``progress(steps)``, called with the lags run so far after each piece of the
            run.

        Returns
        -------
        ndarray of int32, shape (n_steps + 1, N0 + M)
            -1 where absent; the M newcomers (Poisson, ``inflow_per_lag`` per lag, states
            from the entry distribution) follow the N0 initial particles in order of entry.
        """
        states, _ = run_open_chain(chain, self.exit_probability, self.entry_distribution,
                                   self.inflow_per_lag, initial_states, n_steps, seed,
                                   row_offset, retag, coherence, progress)
        return states

    # -- the model file ----------------------------------------------------------------
    def file_fields(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """What a model file stores of the open riser: the datasets ``exit_probability``
        [S] float64, ``exit_counts`` and ``entry_counts`` [S] int64, and the attributes
        ``boundary = "open"``, ``inflow_per_lag``, ``censored_tracks`` (vanished,
        appeared; int64), ``returned_entries``, ``returned_time`` and ``lag_sequences``.

        Returns
        -------
        datasets : dict of str to ndarray
        attrs : dict of str to value
        """
        attrs = {"boundary": Boundary.OPEN.value, "inflow_per_lag": float(self.inflow_per_lag),
                 "censored_tracks": np.asarray(self.censored_tracks, dtype=np.int64),
                 "returned_entries": int(self.returned_entries),
                 "returned_time": float(self.returned_time),
                 "lag_sequences": int(self.lag_sequences)}
        return {name: getattr(self, name) for name in OPEN_DATASETS}, attrs

    @classmethod
    def from_group(cls, group) -> "OpenFlow":
        """The open riser's fields of a model group written with :meth:`file_fields`.

        Parameters
        ----------
        group : h5py.Group or h5py.File
            A model group whose ``boundary`` attribute is ``open``.

        Returns
        -------
        OpenFlow

        Raises
        ------
        KeyError
            If a dataset or the ``inflow_per_lag`` attribute is missing.
        InputError
            If the fields are invalid.
        """
        censored = group.attrs.get("censored_tracks", (0, 0))
        return cls(inflow_per_lag=float(group.attrs["inflow_per_lag"]),
                   censored_tracks=(int(censored[0]), int(censored[1])),
                   returned_entries=int(group.attrs.get("returned_entries", 0)),
                   returned_time=float(group.attrs.get("returned_time", 0.0)),
                   lag_sequences=int(group.attrs.get("lag_sequences", 1)),
                   **{name: group[name][()] for name in OPEN_DATASETS})

    # -- description -------------------------------------------------------------------
    def summary_line(self) -> str:
        """The line of a model's summary on the open riser's exits, entries and censored
        tracks.

        Returns
        -------
        str
        """
        seen = self.observed
        return (f"  open riser: {seen(self.exit_counts.sum())} exits through the outlet, "
                f"{seen(self.entry_counts.sum())} entries through the inlet "
                f"({self.inflow_per_lag:.4g} per lag) into "
                f"{int(np.count_nonzero(self.entry_counts))} states"
                + (f", {seen(self.returned_entries)} returns through it (back after a fall "
                   "out or out of view: no entry)" if self.returned_entries else "")
                + "; tracks censored (ended or began away from the faces): "
                f"{seen(self.censored_tracks[0])}, {seen(self.censored_tracks[1])}"
                + (f" (one sequence of frames a lag apart, on average: the model's "
                   f"counts, of every pair of frames, are {self.lag_sequences} times these)"
                   if self.lag_sequences > 1 else ""))

    def warnings(self) -> list[str]:
        """Lines about many tracks that ended or began away from the faces (more than
        :data:`CENSORED_SHARE` of those that ended or began), and about entries through the
        inlet that do not balance the exits through the outlet (a difference beyond
        :data:`IMBALANCE_SHARE` of the larger and beyond three standard deviations of the
        two counts' Poisson noise): the window's flow was not steady; and about returns
        through the inlet beyond :data:`CENSORED_SHARE` of the entries, with the time out of
        view the chain leaves out of their residences. (Whether the model's
        Monte Carlo then drains or fills the riser, its hold-up against the data's, is
        :func:`~cfbmarkov.markov.model_summary.hold_up_warning`'s line.)

        Returns
        -------
        list of str
        """
        lines = []
        # one sequence's counts (the lag's sequences of frames summed count an event once
        # a sequence): the Poisson noise is that of one sequence's events
        entries, exits = self.observed(self.entry_counts.sum()), self.observed(
            self.exit_counts.sum())
        if abs(entries - exits) > max(IMBALANCE_SHARE * max(entries, exits),
                                      3.0 * np.sqrt(entries + exits)):
            lines.append(
                f"  the fitting window saw {entries} entries through the inlet and {exits} "
                "exits through the outlet: its inflow does not balance its outflow (the "
                f"riser {'drains' if exits > entries else 'fills'} over the window, or "
                "solids leave or enter elsewhere), and the model's inflow "
                f"({self.inflow_per_lag:.4g} a lag) is that window's; the answers per "
                "residence (the RTD, exit means) are not affected, its Monte Carlo's hold-up "
                "may be. Fit on a window of steady flow, or import the riser from its "
                "inlet to its outlet where solids leave or enter elsewhere")
        returned = self.observed(self.returned_entries)
        if returned > CENSORED_SHARE * entries:
            lines.append(
                f"  {returned} returns through the inlet against {entries} entries: particles "
                "that fell back out through it (or left the view) and came back within the "
                "fitting window; the chain goes on with their residences across the fall, as "
                "a residence observed does (docs/definitions.md, Open risers), but it has no "
                "state below the inlet or out of view, and its transitions leave out the time "
                "from a particle's last state before the fall to its first after it, "
                f"{self.returned_time / max(float(self.entry_counts.sum()), 1.0):.3g} s a "
                "residence on average: the "
                "flow's E(RT) may be that much longer than the chain's. Import the riser from "
                "farther below the inlet, so that the falls stay inside it")
        for what, censored, counted, face in (
                ("ended", self.observed(self.censored_tracks[0]), exits, "outlet"),
                ("began", self.observed(self.censored_tracks[1]), entries, "inlet")):
            if censored > CENSORED_SHARE * (censored + counted):
                lines.append(
                    f"  {censored} tracks {what} more than one cell from the {face} "
                    f"({100 * censored / (censored + counted):.0f} % of those that {what} "
                    f"near it or not) and were left out as censored: they "
                    f"{'left' if what == 'ended' else 'came into'} the view elsewhere, through "
                    f"the {'inlet' if face == 'outlet' else 'outlet'} face ("
                    + ("solids falling back out through a section's bottom" if what == "ended"
                       else "solids falling into a section through its top")
                    + ", which the open model counts as no exit or entry: import the riser "
                      "from its "
                    "inlet to its outlet), a side or a gap in the tracking; if they crossed "
                    f"the {face} farther than a cell per lag, use taller cells or a shorter lag")
        return lines
