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

    With ``outflow`` the mass leaves where a residence ends, so the total mass is the
    fraction of a batch still in the riser: a particle that falls out of the bottom of a
    periodic riser (and comes back at the top) leaves only once it has risen through the
    top once more than it fell, as in the exact RTD (its lap-deficit levels); the first
    pass up through the top does not end it. A model whose residences run downward
    (``flow_direction`` "down", a net downflow) counts them as its RTD does: the mass
    leaves once it has fallen through the bottom once more than it rose. An open riser's
    model always propagates by its absorbing matrix Q = diag(1 - r) P: what leaves through
    the outlet is gone.

    Parameters
    ----------
    model : MarkovModel
    initial : array_like, shape (S,)
        The state vector S(0) (e.g. :meth:`StateSpace.inlet_distribution
        <cfbmarkov.markov.states.StateSpace.inlet_distribution>`).
    steps : int
        Number of lags to propagate.
    outflow : bool, optional
        Remove the mass whose residence ends (it passes up through the top once more
        than it fell out of the bottom; down through the bottom once more than it rose,
        for a model whose residences run downward).

    Returns
    -------
    ndarray of float64, shape (steps + 1, S)
        S(k lag) for k = 0 .. steps; row 0 is ``initial``.

    Raises
    ------
    InputError
        If ``initial`` does not have shape (S,) or holds a negative or non-finite entry, or
        ``steps`` is not a whole number >= 0, or the distributions would not fit in
        memory.

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
    check_memory(8.0 * (int(steps) + 1.0) * model.n_states,
                 f"the distribution over {model.n_states} states at {int(steps) + 1} lags",
                 "propagate fewer steps")
    if model.open_flow is not None:
        p = model.absorbing_matrix
    elif outflow:
        return _periodic_outflow(model, s0, int(steps))
    else:
        p = model.transition_matrix
    out = np.empty((int(steps) + 1, model.n_states))
    out[0] = s0
    for k in range(1, int(steps) + 1):   # one S x S product per lag, not per particle
        out[k] = out[k - 1] @ p
    return out


def _periodic_outflow(model: "MarkovModel", s0: np.ndarray, steps: int) -> np.ndarray:
    """:func:`propagate` with outflow on a periodic riser: on the lap-deficit levels of the
    exact RTD (docs/definitions.md, Exact RTD of a model), so that a particle that falls
    out of the bottom (and comes back at the top) leaves only when it has risen through the
    top once more than it fell, as a residence ends: the mass that passes up from level 0
    leaves; a pass down lowers the level, a pass up raises it. For a model whose residences
    run downward (``flow_direction`` "down") the same with the passes' directions swapped:
    the mass leaves when it has fallen through the bottom once more than it rose through
    the top. The levels are as deep as the model's exact RTD keeps (below its deepest, at
    most 1e-7 of the residences, the mass stays on the deepest level). Returns S(k lag)
    summed over the levels, (steps + 1, S)."""
    import warnings

    import scipy.sparse as sp

    from cfbmarkov.errors import CfbmarkovError
    from cfbmarkov.markov.first_passage import (MIN_DEFICIT_LEVELS, deficit_matrix,
                                                split_by_pass)

    try:
        with warnings.catch_warnings():          # the RTD's own warnings are not the maps'
            warnings.simplefilter("ignore")
            depth = int(model.rtd().deficit_levels)
    except CfbmarkovError:                       # no residence ends: none leaves either
        depth = MIN_DEFICIT_LEVELS
    up, down, stay = split_by_pass(sp.csr_matrix(model.transition_matrix), model.up_fraction,
                                   model.down_fraction)
    if model.flow_direction == "down":        # residences counted downward: the mirror image
        up, down = down, up
    levels = depth + 1
    q, _ = deficit_matrix(up, down, stay, levels)       # the exact RTD's chain on the levels
    deepest = sp.csr_matrix(([1.0], ([levels - 1], [levels - 1])), shape=(levels, levels))
    moves = (q + sp.kron(deepest, down)).T.tocsr()      # below the deepest level: kept there
    v = np.zeros(levels * model.n_states)               # index: level * S + state
    v[:model.n_states] = s0
    out = np.empty((steps + 1, model.n_states))
    out[0] = s0
    for k in range(1, steps + 1):                       # one sparse product a lag
        v = moves @ v
        out[k] = v.reshape(levels, model.n_states).sum(axis=0)
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
        Remove the mass whose residence ends (see :func:`propagate`). For a periodic
        riser's model whose residences run downward (``flow_direction`` "down") the batch
        is then fed over the top cells, where those residences start
        (:func:`inlet_batch`), and leaves through the bottom: the mirror image of Eq. (8)'s,
        whose mass left is the model's RTD survival as the batch's entries weight it.

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
    downward = outflow and model.open_flow is None and model.flow_direction == "down"
    history = propagate(model, inlet_batch(model, "down" if downward else "up"),
                        max(steps, default=0), outflow=outflow)
    return model.state_space.cell_maps(history[steps])


def inlet_batch(model: "MarkovModel", direction: str = "up") -> np.ndarray:
    """The batch of Eq. (8) as a state vector: 1/m in each of the m bottom cells (m d with
    depth columns; the cells the fitting window never visited left out and m counting the
    others, :func:`fed_inlet_cells`), each cell's share split over its states (a state space with memory has
    several a cell) as the fitting window's particles entered them through the inlet (the
    landings of their passes up through the top, ``counts_up``), so that a batch fed over
    the inlet enters rising as particles do; on an open riser as they entered through its
    inlet face (``open_flow.entry_counts``); evenly where a cell saw no entry.

    With ``direction`` "down" the mirror image: 1/m in each of the m top cells, split as
    particles entered them through the bottom (the landings of their passes down through
    the bottom, ``counts_down``), where a downward residence starts.

    Parameters
    ----------
    model : MarkovModel
    direction : {"up", "down"}, optional
        Fed over the bottom cells (Eq. 8) or over the top cells.

    Returns
    -------
    ndarray of float64, shape (S,)
        S(0), summing to 1 (:meth:`StateSpace.inlet_distribution
        <cfbmarkov.markov.states.StateSpace.inlet_distribution>` where each bottom cell
        holds one state and every bottom cell is fed).
    """
    space = model.state_space
    top = direction == "down" and model.open_flow is None
    cell = space.cell_of_state
    per_row = space.cells_per_row
    first = space.n_cells - per_row if top else 0
    row = cell >= first if top else cell < per_row          # the cells fed
    place = cell - first                                    # their place in the row
    fed = fed_inlet_cells(model, direction)
    row &= fed[np.clip(place, 0, per_row - 1)]
    cells_fed = max(int(fed.sum()), 1)
    states_per_cell = np.bincount(place[row], minlength=per_row)
    batch = np.zeros(model.n_states)
    batch[row] = 1.0 / cells_fed / states_per_cell[place[row]]   # even (Eq. 8 at the bottom)
    if states_per_cell.max(initial=0) <= 1:
        return batch                             # one state a cell: nothing to split
    if model.open_flow is not None:              # the entries through the inlet, per state
        landings = np.asarray(model.open_flow.entry_counts, dtype=np.float64) * row
    else:
        counts = getattr(model, "counts_down" if top else "counts_up", None)
        if counts is None:
            return batch
        landings = np.asarray(counts.sum(axis=0), dtype=np.float64).ravel() * row
    per_cell = np.bincount(place[row], weights=landings[row], minlength=per_row)
    seen = np.flatnonzero(row)
    seen = seen[per_cell[place[seen]] > 0]
    batch[seen] = (1.0 / cells_fed) * landings[seen] / per_cell[place[seen]]
    return batch


def fed_inlet_cells(model: "MarkovModel", direction: str = "up") -> np.ndarray:
    """Which cells of the row :func:`inlet_batch` feeds take a share of the batch: those
    whose particles the chain moves on. A cell none of whose states was left in the
    fitting window, each never visited or entered but never left, and keeping its
    particles (P_ii = 1: no row in the chain beyond that convention), would keep a share
    fed there at every time; it is left out and the batch spread over the others.

    Parameters
    ----------
    model : MarkovModel
    direction : {"up", "down"}, optional
        The bottom row (up) or, for a periodic riser's downward residences, the top row.

    Returns
    -------
    ndarray of bool, shape (cells_per_row,)
        Per cell of the row, across then depth (as :attr:`StateSpace.cells_per_row`
        counts them): fed or not.

    Raises
    ------
    InputError
        Where no cell of the row is left: the whole batch would stay in place at every
        time (an open riser's state space with memory, whose entries are counted into
        the states a lag above the inlet, can leave its bottom row unvisited).
    """
    space = model.state_space
    per_row = space.cells_per_row
    first = space.n_cells - per_row if direction == "down" and model.open_flow is None else 0
    unvisited = np.asarray(model.unvisited_states, dtype=np.int64)
    keeps = unvisited[np.diagonal(model.transition_matrix)[unvisited] == 1.0]
    moving = np.ones(space.n_cells, bool)
    if keeps.size:
        moving = np.zeros(space.n_cells, bool)
        others = np.setdiff1d(np.arange(model.n_states), keeps)
        moving[space.cell_of_state[others]] = True
    fed = moving[first:first + per_row]
    if not fed.any():
        from cfbmarkov.markov.model_rtd import entry_delay

        row = "top" if first else "bottom"
        why = (": an open riser's state space with memory counts its entries into the "
               "states a lag above the inlet; fit with --states cells for the maps"
               if model.open_flow is not None and entry_delay(model) > 0 else
               "; fit on a window in which particles pass through it")
        raise InputError(f"no cell of the chain's {row} row was left in the fitting window "
                         "(each never visited, or entered but never left): a batch fed "
                         f"over it would stay in place at every time{why}")
    return fed
