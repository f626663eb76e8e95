"""Estimators of the transition matrix (paper Eq. 2-4; ``docs/definitions.md``, States and
transitions).

An estimator is configured with a state space and a lag, then ``fit(discrete)`` on
discrete trajectories (:mod:`cfbmarkov.markov.discrete`) returns an immutable
:class:`~cfbmarkov.markov.model.MarkovModel`:

- :class:`PaperEstimator` (``paper``): the plain average over the frames t_c of the
  row-normalised per-frame matrices P'(t_c), Eq. (2)-(4), a row of P'(t_c) being all zero
  when its cell is empty at t_c. Such a plain average has row sums equal to the fraction of
  frames in which the cell was occupied; each row is divided by its sum so that P is
  stochastic, which equals averaging P' over the frames in which the cell was occupied.
- :class:`MaximumLikelihoodEstimator` (``mle``): pooled counts C_ij / sum_j C_ij, the
  maximum-likelihood non-reversible estimate.

Both form P from the counts of :func:`~cfbmarkov.markov.counting.count_transitions` (every
pair of frames (t, t + lag) in the window, with the direction of each transition through the
periodic boundary). A state with no outgoing transition in the window keeps its
particles in place (P_ii = 1) when it is the only state of its cell (cells); in a state
space with memory it moves as the other states of its cell did (their pooled counts). The
model lists such states.
"""

from __future__ import annotations

import os

import numpy as np
import scipy.sparse as sp

from cfbmarkov._console import plural
from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import InputError
from cfbmarkov.limits import check_fit
from cfbmarkov.markov.coherence import calibrate_coherence
from cfbmarkov.markov.connectivity import largest_connected_set, restrict_to_set
from cfbmarkov.markov.counting import TransitionCounts, count_transitions
from cfbmarkov.markov.discrete import (as_discrete_list, check_arguments,
                                       check_distinct_windows, discretize)
from cfbmarkov.markov.first_passage import split_by_pass
from cfbmarkov.markov.model import MarkovModel
from cfbmarkov.markov.open_flow import OpenFlow
from cfbmarkov.markov.states import StateSpace


def open_chain(counts: TransitionCounts, lag_sequences: int = 1) -> OpenFlow:
    """The open riser's part of a model from its counts (pooled, maximum likelihood).

    Each state i leaves to the outside with probability r_i = X_i / (sum_j C_ij + X_i)
    (X: exits through the outlet); otherwise it moves by the row-stochastic P (the
    transition matrix given that it stays), so the sub-stochastic matrix of the open chain
    is Q = diag(1 - r) P. Entries through the inlet give the entry distribution
    e_j = N_j / sum N and the inflow, entries per lag. Tracks that vanish or appear away
    from the faces are censored: neither transitions nor exits nor entries.

    Parameters
    ----------
    counts : TransitionCounts
        Counts of an open riser (``faces`` not None).
    lag_sequences : int, optional
        The lag in frames: the sequences of frames one lag apart the counts were summed
        over (:attr:`OpenFlow.lag_sequences`).

    Returns
    -------
    OpenFlow
        ``exit_probability`` [S], ``exit_counts`` [S], ``entry_counts`` [S],
        ``inflow_per_lag``, ``censored_tracks`` (vanished less those that came back,
        appeared), ``returned_entries`` and ``returned_time``.

    Raises
    ------
    InputError
        If no particle entered through the inlet.

    References
    ----------
    J. G. Kemeny and J. L. Snell, Finite Markov Chains (1960), Ch. III (absorbing chains).
    """
    faces = counts.faces
    stayed = counts.counts.sum(axis=1).astype(np.float64)
    total = stayed + faces.exits
    exit_probability = np.divide(faces.exits, total, out=np.zeros(total.size), where=total > 0)
    return OpenFlow(exit_probability=exit_probability, exit_counts=faces.exits.copy(),
                    entry_counts=faces.entries.copy(),
                    inflow_per_lag=float(faces.entries.sum()) / max(counts.frame_pairs, 1),
                    # a fall out through the inlet that came back is no censored end
                    censored_tracks=(max(int(faces.vanished.sum() - faces.returns.sum()), 0),
                                     int(faces.appeared.sum())),
                    returned_entries=int(faces.returns.sum()),
                    returned_time=float(faces.returned_time.sum()),
                    lag_sequences=int(lag_sequences))


#: relative difference between a given lag and the frames it spans (lag frames x frame
#: interval) beyond which a model takes the frames' lag (:meth:`TransitionEstimator.fit`):
#: below a lag typed short (0.008333 s for one 1/120 s frame is 4e-5 short, and a
#: prediction's 4 s were then no whole number of its lags), above the round-off of frame
#: times printed to 5 decimals over a few hundred frames (3e-8); where a file's few frames
#: leave its interval less certain than this, the frames' lag is taken, as exact as the
#: file's own times
LAG_ROUND_OFF = 1e-6


class TransitionEstimator:
    """Base estimator: configure with a state space and a lag (s), then :meth:`fit`.

    Parameters
    ----------
    state_space : StateSpace
        The states of the models it fits.
    lag : float, optional
        The lag tau (s), positive.
    connected : bool, optional
        Remove the transitions that leave the largest strongly connected set of the counts
        (and renormalise those rows), as deeptime and PyEMMA do by default: a state first
        entered in the window's last frame then traps no particle. Off by default (the
        paper's chain keeps every observed transition).
    coherent : bool, optional
        Also fit the coherence of the particles' moves (the cluster model,
        :mod:`cfbmarkov.markov.coherence`), for a periodic riser: calibrated so that the
        model's Monte Carlo snapshots show the window's cluster index
        (:func:`~cfbmarkov.markov.coherence.calibrate_coherence`); off by default
        (independent particles, the paper's).

    Attributes
    ----------
    name : str
        The estimator's name (``paper``, ``mle``), recorded in its models; a class
        attribute.

    Raises
    ------
    InputError
        If ``lag`` is not positive.

    Notes
    -----
    See ``docs/definitions.md`` (Estimators; Unvisited states).
    """

    name: str = ""

    def __init__(self, state_space: StateSpace, lag: float = 0.025, connected: bool = False,
                 coherent: bool = False):
        check_arguments(state_space, lag)
        if not (np.isfinite(lag) and lag > 0):
            raise InputError(f"lag {lag:g} s must be a positive finite number")
        check_fit(state_space)          # refuse before counting: the dense [S, S] arrays
        self.state_space = state_space
        self.lag = float(lag)
        self.connected = bool(connected)
        self.coherent = bool(coherent)

    def __repr__(self) -> str:
        extra = (", connected=True" if self.connected else "") + (
            ", coherent=True" if self.coherent else "")
        return f"{type(self).__name__}({self.state_space!r}, lag={self.lag:g}{extra})"

    def transition_matrix(self, counts: TransitionCounts) -> np.ndarray:
        """The estimate of P from the counts, before unvisited states are filled.

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered by :func:`~cfbmarkov.markov.counting.count_transitions`.

        Returns
        -------
        ndarray of float64, shape (S, S)
            Rows of states never left are all zero.

        Raises
        ------
        NotImplementedError
            In the base class: the subclasses implement it.
        """
        raise NotImplementedError

    def fit(self, data, *, check_passes: bool = True) -> MarkovModel:
        """Fit on discrete trajectories: a new immutable model out, the estimator unchanged
        (deeptime's ``fit`` returns the estimator and hands the model by ``fetch_model()``;
        here ``fit`` returns the model itself).

        Parameters
        ----------
        data : DiscreteTrajectories or sequence of them
            Made by :func:`cfbmarkov.markov.discretize` with this estimator's state space
            and lag (or use :func:`cfbmarkov.markov.fit_model` to fit from a file).
        check_passes : bool, optional
            Refuse a lag at which the heights one lag apart misread the periodic boundary's
            passes (``DiscreteTrajectories.pass_reading``; default). False for a transition
            matrix whose passes are not used (implied timescales).

        Returns
        -------
        MarkovModel
            Its ``lag`` is the one the transitions span, lag frames x frame interval: a lag
            given within the files' time tolerance of it (half a percent of a frame) but
            further from it than round-off (:data:`LAG_ROUND_OFF`; 0.0083 or 0.008333 s for
            one frame of 1/120 s) is replaced by it.

        Raises
        ------
        InputError
            If ``data`` is not discrete trajectories, or was made with another state space
            or lag, or holds no transition, or (``check_passes``) its lag misreads the
            passes (:meth:`cfbmarkov.observed.lag_resolution.PassReading.check`).
        """
        # the settings as they are now: an attribute set after construction is checked too
        check_arguments(self.state_space, self.lag)
        windows = as_discrete_list(data)
        check_distinct_windows(windows)
        if check_passes:
            for window in windows:
                if window.pass_reading is not None:
                    window.pass_reading.check()
        fitted = windows[0].state_space
        if not self.state_space.sized and fitted.sized:
            # a space made without a size: the discretisation gave it the file's
            sized = self.state_space.with_size(fitted.width, fitted.height)
            return type(self)(sized, self.lag, self.connected, self.coherent).fit(
                windows, check_passes=check_passes)
        if fitted != self.state_space and self.state_space.accepts(fitted):
            # an unfitted regime space: the discretisation fitted its edges on the window
            return type(self)(fitted, self.lag, self.connected, self.coherent).fit(
                windows, check_passes=check_passes)
        for window in windows:
            if window.state_space != self.state_space:
                theirs = window.state_space.describe_against(self.state_space)
                ours = self.state_space.describe()
                raise InputError(f"discrete trajectories are in {theirs}, the estimator's "
                                 f"state space is {ours}: discretise on the estimator's "
                                 "state space")
            if not window.matches_lag(self.lag):
                raise InputError(f"discrete trajectories have a lag of {window.lag:g} s "
                                 f"({plural(window.lag_frames, 'frame')}), the estimator's is "
                                 f"{self.lag:g} s")
        if abs(windows[0].lag - self.lag) > LAG_ROUND_OFF * windows[0].lag:
            # a lag typed near a whole number of frames (0.0083 s for one 1/120 s frame):
            # the model's is what the transitions span, or every time it gives is off
            return type(self)(self.state_space, windows[0].lag, self.connected,
                              self.coherent).fit(windows, check_passes=check_passes)
        open_riser = Boundary(windows[0].boundary).is_open
        if self.name == "paper" and open_riser:
            raise InputError("the paper's estimator (Eq. 2-4) averages per-frame matrices of a "
                             "closed (periodic) riser; fit an open riser with --estimator mle (in "
                             "Python MaximumLikelihoodEstimator)")
        if self.coherent and open_riser:
            raise InputError("coherent moves (--coherent) are fitted for periodic risers only "
                             "yet; fit an open riser without it")
        counts = count_transitions(windows, frame_average=self.name == "paper")
        check_some_transitions(counts, self.lag)
        sources = [w.source for w in windows]
        pooled = len(windows) > 1 and all(w.window is not None for w in windows)
        model = self.fit_counts(counts, window=windows[0].window,     # counted for it alone
                                source=sources[0] if len(sources) == 1 else sources, adopt=True,
                                run_windows=[w.window for w in windows] if pooled else None,
                                lag_sequences=int(windows[0].lag_frames))
        if self.coherent:
            model = model.with_coherence(calibrate_coherence(model, windows))
        return model

    def chain(self, counts: TransitionCounts
              ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """The stochastic matrix and pass fractions that :meth:`fit_counts` puts in a model.

        A state never left in the counts moves as the other states of its cell did (their
        pooled counts); where its whole cell was never left it stays in place (P_ii = 1).

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered by :func:`~cfbmarkov.markov.counting.count_transitions`.

        Returns
        -------
        matrix : ndarray of float64, shape (S, S)
            The row-stochastic transition matrix P.
        fractions : tuple of two ndarrays of shape (S, S), or None
            (up, down) fractions of each i -> j transition that passed the boundary, where
            states were filled from their cell; None: the counts give them.
        """
        matrix = self.transition_matrix(counts)
        unvisited = np.flatnonzero(counts.counts.sum(axis=1) == 0)
        fractions = _fill_from_cells(matrix, counts, self.state_space, unvisited)
        stuck = unvisited[matrix[unvisited].sum(axis=1) == 0]
        matrix[stuck, :] = 0.0
        matrix[stuck, stuck] = 1.0
        if self.connected:      # deeptime's default: no transition leaves the largest set
            matrix = restrict_to_set(matrix, largest_connected_set(counts.counts))
        return matrix, fractions

    def split_chain(self, counts: TransitionCounts) -> tuple[sp.csr_matrix, sp.csr_matrix,
                                                              sp.csr_matrix]:
        """The chain that :meth:`chain` forms, split by pass direction, without any dense
        [S, S] array: P_up, P_down and P_stay with P = P_up + P_down + P_stay (what
        :func:`cfbmarkov.markov.first_passage.rtd_of_split_chain` takes).

        A transition's share of P is split as its counts were (P_ij C^up_ij / C_ij, ...); a
        state never left takes its cell's pooled counts, and stays in place where its whole
        cell was never left, as in :meth:`chain`.

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered by :func:`~cfbmarkov.markov.counting.count_transitions`, sparse (``sparse=True``) or dense.

        Returns
        -------
        tuple of three scipy.sparse.csr_matrix, shape (S, S)
            P_up, P_down, P_stay. Equal to :func:`cfbmarkov.markov.first_passage.split_by_pass` of
            :meth:`chain`'s matrix and fractions up to rounding (tested).
        """
        if self.connected:      # the largest connected set: through the dense chain
            dense = counts.dense()
            matrix, fractions = self.chain(dense)
            up, down = fractions if fractions is not None else pass_fractions(dense)
            return split_by_pass(matrix, up, down)
        c = sp.csr_matrix(counts.counts, dtype=np.float64)
        moves = {"up": sp.csr_matrix(counts.counts_up, dtype=np.float64),
                 "down": sp.csr_matrix(counts.counts_down, dtype=np.float64)}
        moves["stay"] = c - moves["up"] - moves["down"]
        weights = self._sparse_weights(counts, c)
        totals = np.asarray(weights.sum(axis=1)).ravel()
        scale = np.divide(1.0, totals, out=np.zeros_like(totals), where=totals > 0)
        matrix = sp.diags(scale) @ weights
        inverse = c.copy()
        inverse.data = 1.0 / inverse.data
        share = matrix.multiply(inverse)                  # P_ij / C_ij on the counted pairs
        parts = {name: sp.csr_matrix(share.multiply(values)) for name, values in moves.items()}
        # states never left: their cell's pooled counts, or in place
        space = self.state_space
        n = space.n_states
        unvisited = np.flatnonzero(np.asarray(c.sum(axis=1)).ravel() == 0)
        cell = np.asarray(space.cell_of_state)
        fill = np.zeros(0, np.int64)
        if unvisited.size and np.unique(cell).size != cell.size:
            needed = np.unique(cell[unvisited])
            slot = -np.ones(space.n_cells, np.int64)
            slot[needed] = np.arange(needed.size)
            members = np.flatnonzero(slot[cell] >= 0)
            indicator = sp.csr_matrix((np.ones(members.size), (slot[cell[members]], members)),
                                      shape=(needed.size, n))
            pooled_totals = np.asarray((indicator @ c).sum(axis=1)).ravel()
            fill = unvisited[pooled_totals[slot[cell[unvisited]]] > 0]
            chosen = sp.csr_matrix((1.0 / pooled_totals[slot[cell[fill]]],
                                    (fill, slot[cell[fill]])), shape=(n, needed.size))
            for name, values in moves.items():
                parts[name] = (parts[name] + chosen @ (indicator @ values)).tocsr()
        stuck = np.setdiff1d(unvisited, fill)
        if stuck.size:
            parts["stay"] = (parts["stay"] + sp.csr_matrix(
                (np.ones(stuck.size), (stuck, stuck)), shape=(n, n))).tocsr()
        for part in parts.values():
            part.eliminate_zeros()
        return parts["up"], parts["down"], parts["stay"]

    def _sparse_weights(self, counts: TransitionCounts, pooled: sp.csr_matrix) -> sp.csr_matrix:
        """The rows that :meth:`transition_matrix` normalises, as a sparse matrix (the pooled
        counts; the paper's estimator overrides it)."""
        return pooled

    def fit_counts(self, counts: TransitionCounts, window=None, source="", *,
                   adopt: bool = False, run_windows=None,
                   lag_sequences: int = 1) -> MarkovModel:
        """Form the model from counts already gathered (e.g. by cross-validation).

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered with this estimator's state space and lag.
        window : tuple of float, optional
            The fitting window (A, B) in s, recorded in the model.
        source : str, os.PathLike or list, optional
            Where the data came from, recorded in the model.
        adopt : bool, optional
            The model takes the counts' [S, S] arrays as its own: made read-only, not
            copied; the caller must not keep writing them (nor count into them again).
            Without it the model holds copies.
        run_windows : sequence of (float, float), optional
            A pooled fit's window (s) of each run of ``source`` (a list), recorded in the
            model.
        lag_sequences : int, optional
            An open riser's lag in frames, the sequences of frames its counts were summed
            over (:attr:`~cfbmarkov.markov.open_flow.OpenFlow.lag_sequences`).

        Returns
        -------
        MarkovModel

        Raises
        ------
        InputError
            If the counts do not fit the state space, or (paper estimator) were gathered
            without the per-frame matrices.
        """
        matrix, fractions = self.chain(counts)      # made here for this model alone
        square = {"counts": counts.counts, "counts_up": counts.counts_up,
                  "counts_down": counts.counts_down}
        if not adopt:       # the model's own copies
            square = {name: np.array(value) for name, value in square.items()}
        open_flow = (open_chain(counts, lag_sequences) if counts.faces is not None
                     else None)
        return MarkovModel(
            transition_matrix=matrix, **square, state_space=self.state_space, lag=self.lag,
            estimator=self.name, window=tuple(window) if window is not None else None,
            source=os.fspath(source) if isinstance(source, (str, os.PathLike)) else list(source),
            frame_pairs=counts.frame_pairs, pass_fractions=fractions, connected=self.connected,
            open_flow=open_flow, run_windows=run_windows, adopt=True)


def _fill_from_cells(matrix: np.ndarray, counts: TransitionCounts, space: StateSpace,
                     unvisited: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """In a state space with several states per cell, a state never left in the window
    (e.g. a rare velocity class) moves as the other states of its cell did: its row of P
    and its pass fractions are those of the cell's pooled counts. Fills ``matrix`` in place
    and returns the pass fractions (None when nothing was filled; then the counts give
    them). States whose whole cell was never left stay in place (P_ii = 1) as for cells."""
    cell = np.asarray(space.cell_of_state)
    if unvisited.size == 0 or np.unique(cell).size == cell.size:
        return None
    # pool the rows of the cells that need it: a sparse (cells x states) indicator times
    # the counts (np.add.at over a dense S x S array was most of an auto fit's time)
    needed = np.unique(cell[unvisited])
    slot = -np.ones(space.n_cells, np.int64)
    slot[needed] = np.arange(needed.size)
    members = np.flatnonzero(slot[cell] >= 0)
    indicator = sp.csr_matrix((np.ones(members.size), (slot[cell[members]], members)),
                              shape=(needed.size, cell.size))
    pooled = indicator @ counts.counts.astype(np.float64)
    totals = pooled.sum(axis=1)
    c = counts.counts.astype(np.float64)
    up = np.divide(counts.counts_up, c, out=np.zeros_like(c), where=c > 0)
    down = np.divide(counts.counts_down, c, out=np.zeros_like(c), where=c > 0)
    fill = unvisited[totals[slot[cell[unvisited]]] > 0]
    if fill.size == 0:
        return None
    rows = pooled[slot[cell[fill]]]
    matrix[fill] = rows / rows.sum(axis=1)[:, None]
    pooled_up = indicator @ counts.counts_up.astype(np.float64)
    pooled_down = indicator @ counts.counts_down.astype(np.float64)
    up[fill] = np.divide(pooled_up[slot[cell[fill]]], rows, out=np.zeros_like(rows),
                         where=rows > 0)
    down[fill] = np.divide(pooled_down[slot[cell[fill]]], rows, out=np.zeros_like(rows),
                           where=rows > 0)
    return up, down


class MaximumLikelihoodEstimator(TransitionEstimator):
    """``mle``: P_ij = C_ij / sum_j C_ij from the pooled counts.

    The maximum-likelihood estimate of a non-reversible chain. Parameters as for
    :class:`TransitionEstimator`.

    References
    ----------
    J.-H. Prinz et al., "Markov models of molecular kinetics: generation and
    validation", J. Chem. Phys. 134, 174105 (2011) (the non-reversible maximum-likelihood estimate).
    """

    name = "mle"

    def transition_matrix(self, counts):
        """P_ij = C_ij / sum_j C_ij (rows of states never left: zero).

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered by :func:`~cfbmarkov.markov.counting.count_transitions`.

        Returns
        -------
        ndarray of float64, shape (S, S)
        """
        c = counts.counts.astype(np.float64)
        rows = c.sum(axis=1, keepdims=True)
        return np.divide(c, rows, out=np.zeros_like(c), where=rows > 0)


class PaperEstimator(TransitionEstimator):
    """``paper``: average of the per-frame row-normalised matrices P'(t_c), Eq. (2)-(4).

    Parameters as for :class:`TransitionEstimator`. The plain average has row sums equal to
    the fraction of frames in which a state was occupied; each row is divided by its sum,
    which equals averaging P' over the frames in which the state was occupied.

    Notes
    -----
    The estimator is the paper's for its cells. On a state space with memory its
    frame-averaged rows can carry the chain away from the window's own flux (docs/method.md,
    Estimators): :class:`MaximumLikelihoodEstimator` is the one to fit such spaces with (the
    command line's default there, which warns where ``--estimator paper`` is asked for;
    this class does not warn).

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 2-4).
    """

    name = "paper"

    def transition_matrix(self, counts):
        """The average of the per-frame matrices P'(t), rows renormalised.

        Parameters
        ----------
        counts : TransitionCounts
            Counts gathered with ``frame_average=True``.

        Returns
        -------
        ndarray of float64, shape (S, S)

        Raises
        ------
        InputError
            If the counts were gathered without the per-frame matrices.
        """
        if counts.frame_average_sum is None:
            raise InputError("the paper's estimator needs the per-frame matrices; these counts "
                             "were gathered without them")
        if counts.frame_pairs == 0:
            return np.zeros_like(counts.frame_average_sum)
        plain_average = counts.frame_average_sum / counts.frame_pairs   # Eq. (4)
        rows = plain_average.sum(axis=1, keepdims=True)
        return np.divide(plain_average, rows, out=np.zeros_like(plain_average), where=rows > 0)


    def _sparse_weights(self, counts, pooled):
        if counts.frame_average_sum is None:
            raise InputError("the paper's estimator needs the per-frame matrices; these counts "
                             "were gathered without them")
        return sp.csr_matrix(counts.frame_average_sum, dtype=np.float64)


def pass_fractions(counts: TransitionCounts) -> tuple[np.ndarray, np.ndarray]:
    """The fractions of each i -> j transition that passed up through the top and down
    through the bottom, C^up_ij / C_ij and C^down_ij / C_ij (0 where C_ij = 0).

    Parameters
    ----------
    counts : TransitionCounts
        Dense counts.

    Returns
    -------
    (ndarray, ndarray) of float64, shape (S, S)
    """
    c = counts.counts.astype(np.float64)
    return (np.divide(counts.counts_up, c, out=np.zeros_like(c), where=c > 0),
            np.divide(counts.counts_down, c, out=np.zeros_like(c), where=c > 0))


ESTIMATORS: dict[str, type[TransitionEstimator]] = {
    "paper": PaperEstimator, "mle": MaximumLikelihoodEstimator}


def default_estimator(open_boundary: bool, states: str) -> str:
    """The estimator the command line fits with where none is named.

    The paper's (Eq. 2-4) for the paper's cells on a periodic riser, as the paper fits;
    maximum likelihood (``mle``) otherwise: on an open riser, where only it is defined, and
    on a state space with memory or ``auto``, whose chains the paper's frame-averaged rows
    carry away from the window's own flux (``docs/method.md``, Estimators; the reproduction's
    models ``auto`` and ``STATES`` fit with ``mle`` too, :func:`~cfbmarkov.markov.select.
    choice.parse_model_name`).

    Parameters
    ----------
    open_boundary : bool
        Whether the riser is open (inlet and outlet) rather than periodic.
    states : str
        The state space's name (``cells``, ``cells-velocity``, ..., or ``auto``).

    Returns
    -------
    {"paper", "mle"}
    """
    return "paper" if states == "cells" and not open_boundary else "mle"


def estimator_from_name(name: str, state_space: StateSpace, lag: float = 0.025,
                        connected: bool = False, coherent: bool = False
                        ) -> TransitionEstimator:
    """An estimator by name.

    Parameters
    ----------
    name : {"paper", "mle"}
        A key of ``ESTIMATORS``.
    state_space : StateSpace
        The states of the models it fits.
    lag : float, optional
        The lag (s).
    connected : bool, optional
        Restrict to the largest strongly connected set (see :class:`TransitionEstimator`).
    coherent : bool, optional
        Also fit the coherence of the moves (see :class:`TransitionEstimator`).

    Returns
    -------
    TransitionEstimator

    Raises
    ------
    InputError
        For an unknown name or a lag that is not positive.
    """
    try:
        return ESTIMATORS[name](state_space, lag, connected, coherent)
    except KeyError:
        raise InputError(f"unknown estimator '{name}' (choose from {', '.join(ESTIMATORS)})") from None


def fit_model(source, state_space: StateSpace, lag: float,
              window: tuple[float, float] | None = None, estimator: str = "mle",
              connected: bool = False, coherent: bool = False) -> MarkovModel:
    """Fit a model on a trajectory file: :func:`~cfbmarkov.markov.discretize`, then the
    estimator's ``fit`` (the one convenience wrapper that takes a file).

    Parameters
    ----------
    source : str, os.PathLike or Trajectories
        The trajectory file (path or open).
    state_space : StateSpace
        The states.
    lag : float
        The lag (s), a whole multiple of the file's frame interval.
    window : tuple of float, optional
        The fitting window (A, B) in s; None: every frame.
    estimator : {"paper", "mle"}, optional
        Paper Eq. 2-4, or the pooled maximum-likelihood estimate (default ``"mle"``; the
        command line's default differs, :func:`default_estimator`).
    connected : bool, optional
        Restrict to the largest strongly connected set (see :class:`TransitionEstimator`;
        default False).
    coherent : bool, optional
        Also fit the coherence of the moves (see :class:`TransitionEstimator`).

    Returns
    -------
    MarkovModel

    Raises
    ------
    InputError
        On an unreadable file, a window outside the data, a lag that is not a whole number
        of frames, a state space that does not fit the file, or an unknown estimator.

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 2-4, the paper estimator).
    """
    fitter = estimator_from_name(estimator, state_space, lag, connected, coherent)
    return fitter.fit(discretize(source, state_space, lag, window))


def check_some_transitions(counts: TransitionCounts, lag: float) -> None:
    """Refuse counts from which no row of the transition matrix can be estimated.

    Parameters
    ----------
    counts : TransitionCounts
        The counts of the data to fit.
    lag : float
        The lag, s (for the message).

    Raises
    ------
    InputError
        When no transition was counted: no particle is present at both ends of any frame
        pair (one-frame tracks, a lag longer than every track, or too few frames).
    """
    if counts.n_transitions > 0:
        return
    if counts.frame_pairs == 0:
        why = f"the data hold no pair of frames {lag:g} s apart"
    else:
        why = (f"no particle is present at both ends of any of the {counts.frame_pairs} frame "
               f"pairs {lag:g} s apart")
    raise InputError(f"no transitions to fit: {why}; check the import (particle ids: each "
                     "track one id, 'cfbmarkov info' shows particles per frame), or give a "
                     "shorter --lag or a longer --window")
