"""Particle properties along a Monte Carlo run (kernels; ``docs/definitions.md``,
Properties along particle paths).

The states of a run ([T, N], -1 where a particle is absent) and its lap counters fix every
particle's path; the properties follow it lag by lag: over the lag from frame k-1 to k a
particle in state s maps its value by v' = a_s v + b_s (a linear law, exact) or by
``substeps`` RK4 steps of its custom rate function with the state held. Where a particle
enters (an open riser's newcomer at its first frame; in a periodic riser, for
``start = entry``, the frame after the pass up through the top that lifts its lap counter
above every value it had; for a model of a net downflow, whose residences run from one pass
down through the bottom to the next, the frame after the pass down that takes the counter
below every value it had) the value resets to the entry value. Each particle's values
depend only on its own path, so the result is the same for any number of threads.
"""

from __future__ import annotations

from functools import partial

import numba as nb
import numpy as np

from cfbmarkov.markov import montecarlo


@nb.njit(cache=True, parallel=True)
def linear_properties(states, laps, a, b, reset, initial, entry_value, periodic, entry_lags,
                      first, last, top, out):
    """The values of the linear properties of every particle at the frames ``first`` ..
    ``last`` (Numba, parallel over particles).

    Parameters
    ----------
    states, laps : ndarray of int32, shape (T, N)
        The run (-1: absent).
    a, b : ndarray of float64, shape (P, S)
        The affine maps of one lag.
    reset : ndarray of bool, shape (P,)
        Whether each property resets on a periodic riser's pass up through the top.
    initial : ndarray of float64, shape (P, N)
        Values at frame 0.
    entry_value : ndarray of float64, shape (P,)
        The value a particle takes where it enters.
    periodic : bool
        A periodic riser (passes from the lap counters) or an open one (entries at the
        first frame a newcomer is present).
    entry_lags : int
        Lags from an open riser's inlet to a newcomer's first state (a state space with
        memory, :func:`~cfbmarkov.markov.model_rtd.entry_delay`): its entry value is
        carried over them with its first state's map, as the exact answers take it.
    first, last : int
        The frames filled (0 <= first <= last < T); for ``first`` > 0 the frame
        ``first - 1`` is read as filled, so that a run is made in pieces
        (:func:`run_properties`) with the same values as in one.
    top : ndarray of int64, shape (N,)
        Each particle's highest lap counter so far: set at frame 0, read and updated after.
    out : ndarray of float64, shape (P, T, N)
        Frames ``first`` .. ``last`` filled in place; NaN where a particle is absent.
    """
    n_props = a.shape[0]
    n = states.shape[1]
    block = 256                 # particles side by side: each frame's row is read in order
    for c in nb.prange((n + block - 1) // block):
        lo = c * block
        hi = min(lo + block, n)
        if first == 0:
            for p in range(lo, hi):
                top[p] = laps[0, p]
                for q in range(n_props):
                    out[q, 0, p] = initial[q, p] if states[0, p] >= 0 else np.nan
        for k in range(max(first, 1), last + 1):
            for p in range(lo, hi):
                s_prev = states[k - 1, p]
                s = states[k, p]
                passed = False
                if periodic and laps[k, p] > top[p]:
                    top[p] = laps[k, p]
                    passed = True
                for q in range(n_props):
                    if s < 0:
                        v = np.nan
                    elif s_prev < 0:
                        v = entry_value[q]
                        for _ in range(entry_lags):    # inlet to first state: its law
                            v = a[q, s] * v + b[q, s]
                    elif passed and reset[q]:
                        v = entry_value[q]
                    else:
                        v = a[q, s_prev] * out[q, k - 1, p] + b[q, s_prev]
                    out[q, k, p] = v


@nb.njit(cache=True)
def _rk4_lag(function, v, row, others, lag, substeps):
    """One lag of ``substeps`` classical RK4 steps of dv/dt = function(v, row, others)."""
    h = lag / substeps
    for _ in range(substeps):
        k1 = function(v, row, others)
        k2 = function(v + 0.5 * h * k1, row, others)
        k3 = function(v + 0.5 * h * k2, row, others)
        k4 = function(v + h * k3, row, others)
        v = v + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return v


@nb.njit(cache=False, parallel=True)
def custom_property(function, states, laps, parameters, lag, substeps, reset, initial,
                    entry_value, periodic, entry_lags, index, first, last, top, values):
    """The values of a custom-law property at the frames ``first`` .. ``last`` (Numba,
    parallel over particles): each lag ``substeps`` classical RK4 steps of
    dv/dt = function(v, parameters[s], values at the lag's start), the state s held.

    Parameters
    ----------
    function : numba dispatcher
        ``function(v, row, others) -> dv/dt``.
    states, laps : ndarray of int32, shape (T, N)
    parameters : ndarray of float64, shape (S, q)
        The law's parameters per state.
    lag : float
        The lag (s).
    substeps : int
        RK4 steps per lag.
    reset : bool
        Reset on a periodic riser's pass up through the top.
    initial : ndarray of float64, shape (N,)
        Values at frame 0.
    entry_value : float
        The value where a particle enters.
    periodic : bool
    entry_lags : int
        As in :func:`linear_properties` (the law integrated over them in the first state,
        the properties not yet computed for that frame NaN).
    index : int
        The property's position q in ``values``.
    first, last : int
        The frames filled, as in :func:`linear_properties`.
    top : ndarray of int64, shape (N,)
        Each particle's highest lap counter so far (set at frame 0, updated after).
    values : ndarray of float64, shape (P, T, N)
        All properties; row ``index`` is filled in place at those frames (the earlier rows
        are read).
    """
    n_props = values.shape[0]
    n = states.shape[1]
    for p in nb.prange(n):
        others = np.empty(n_props)
        if first == 0:
            s = states[0, p]
            v = initial[p] if s >= 0 else np.nan
            values[index, 0, p] = v
            top[p] = laps[0, p]
        else:
            s = states[first - 1, p]
            v = values[index, first - 1, p]
        for k in range(max(first, 1), last + 1):
            s_prev = s
            s = states[k, p]
            if s < 0:
                v = np.nan
            elif s_prev < 0:
                v = entry_value
                if entry_lags > 0:      # inlet to first state: its law, the others held
                    for q in range(n_props):
                        others[q] = values[q, k, p] if q < index else np.nan
                    others[index] = v
                    row = parameters[s]
                    for _ in range(entry_lags):
                        v = _rk4_lag(function, v, row, others, lag, substeps)
            else:
                for q in range(n_props):
                    others[q] = values[q, k - 1, p]
                row = parameters[s_prev]
                v = _rk4_lag(function, v, row, others, lag, substeps)
                if periodic and laps[k, p] > top[p]:
                    top[p] = laps[k, p]
                    if reset:
                        v = entry_value
            values[index, k, p] = v


def run_properties(state_kinetics, lag: float, states: np.ndarray, laps: np.ndarray,
                   periodic: bool, initial: np.ndarray | None = None,
                   direction: str = "up", progress=None, entry_lags: int = 0) -> np.ndarray:
    """Every property of every particle at every frame of a Monte Carlo run.

    Parameters
    ----------
    state_kinetics : StateKinetics
        The kinetics on the model's states.
    lag : float
        The lag (s).
    states, laps : ndarray of int32, shape (T, N)
        The run (-1 where absent).
    periodic : bool
        A periodic riser (resets at passes up through the top for ``start = entry``) or
        an open one (resets where a newcomer enters).
    initial : ndarray of float64, shape (P, N), optional
        Values at frame 0 (default: every property's entry value).
    direction : {"up", "down"}, optional
        The model's residence direction (``MarkovModel.flow_direction``): a periodic
        riser's ``entry`` properties reset at passes up through the top to a new lap
        maximum, or for "down" at passes down through the bottom to a new lap minimum, as
        the chain's exact answers count residences.
    progress : callable, optional
        ``progress(done, total)`` is called after each piece of the work, in lags: one
        pass over the run for the linear properties together and one for each custom law
        (pieces of about :data:`~cfbmarkov.markov.montecarlo.PIECE_PARTICLE_STEPS`
        particle-steps, RK4 substeps counted, between which a Ctrl-C is taken; the values
        do not depend on the pieces).
    entry_lags : int, optional
        An open riser's lags from the inlet to a newcomer's first state
        (:func:`~cfbmarkov.markov.model_rtd.entry_delay`; 0 for the cells).

    Returns
    -------
    ndarray of float64, shape (P, T, N)
        NaN where a particle is absent.

    Raises
    ------
    ValueError
        If ``direction`` is neither "up" nor "down".
    """
    if direction not in ("up", "down"):
        raise ValueError(f"direction {direction!r}: up or down")
    sk = state_kinetics
    n_props = sk.n_properties
    states = np.ascontiguousarray(states, dtype=np.int32)
    laps = np.ascontiguousarray(laps, dtype=np.int32)
    if direction == "down":     # a new lap minimum is a new maximum of the negated counter
        laps = np.negative(laps)
    n = states.shape[1]
    if initial is None:
        initial = np.repeat(sk.initial[:, None], n, axis=1)
    initial = np.ascontiguousarray(initial, dtype=np.float64)
    reset = np.array([st != "carried" for st in sk.starts])
    values = np.empty((n_props,) + states.shape)
    linear = np.flatnonzero(sk.linear)
    custom = np.flatnonzero(~sk.linear)
    last_frame = states.shape[0] - 1
    passes = (1 if linear.size else 0) + custom.size
    top = np.empty(n, np.int64)
    done = 0

    def in_pieces(cost, run):
        """run(first, last) over the frames in pieces of about PIECE_PARTICLE_STEPS
        particle-steps of ``cost`` each."""
        nonlocal done
        piece = max(1, int(montecarlo.PIECE_PARTICLE_STEPS // max(n * cost, 1)))
        for first in range(0, last_frame + 1, piece):
            last = min(last_frame, first + piece - 1)
            run(first, last)
            if progress is not None:
                progress(done + last, passes * last_frame)
        done += last_frame

    if linear.size:
        a, b = sk.over(lag)
        # all linear (the usual case): straight into the result, no copy
        part = values if linear.size == n_props else np.empty((linear.size,) + states.shape)
        maps = (np.ascontiguousarray(a[linear]), np.ascontiguousarray(b[linear]),
                reset[linear], np.ascontiguousarray(initial[linear]), sk.initial[linear],
                bool(periodic), int(entry_lags))
        in_pieces(linear.size, lambda first, last: linear_properties(
            states, laps, *maps, first, last, top, part))
        if part is not values:
            values[linear] = part
    values[custom] = np.nan        # a custom law that reads one not yet computed reads NaN
    for q in custom:
        law = sk.laws[q]
        _check_custom_start(sk, int(q), states)
        arguments = (law.function, states, laps,
                     np.ascontiguousarray(sk.parameters[q], dtype=np.float64), float(lag),
                     int(law.substeps), bool(reset[q]), initial[q], float(sk.initial[q]),
                     bool(periodic), int(entry_lags), int(q))
        in_pieces(4 * int(law.substeps), partial(_custom_piece, arguments, top, values))
        if not _warn_not_finite(sk.names[q], values[q], states >= 0):
            _warn_too_few_substeps(sk, int(q), float(lag), states, values)
    return values


#: the relative difference over one lag between RK4 with ``substeps`` and with twice as
#: many, above which a custom law's sub-steps are said to be too few
SUBSTEP_TOLERANCE = 1e-3
#: particle-lags a custom law's sub-steps are checked on (every k-th of those held)
SUBSTEP_SAMPLES = 4096


@nb.njit(cache=True)
def _step_doubling(function, start, rows, others, lag, substeps):
    """The largest difference, over the particle-lags given, between one lag of RK4 with
    ``substeps`` steps and with twice as many, relative to the largest value met (the
    property's scale, so that a value near 0, at a kink or a depletion, does not magnify
    a small difference) (Numba kernel); inf where either is not finite from a finite
    start."""
    worst = 0.0
    scale = 1e-300
    for i in range(start.size):
        v = start[i]
        if not np.isfinite(v):
            continue
        coarse = _rk4_lag(function, v, rows[i], others[i], lag, substeps)
        fine = _rk4_lag(function, v, rows[i], others[i], lag, 2 * substeps)
        if not (np.isfinite(coarse) and np.isfinite(fine)):
            return np.inf
        scale = max(scale, abs(fine), abs(v))
        worst = max(worst, abs(coarse - fine))
    return worst / scale


def _warn_too_few_substeps(sk, q: int, lag: float, states: np.ndarray,
                           values: np.ndarray) -> None:
    """Warn where a custom law's RK4 sub-steps are too few for its rates: on up to
    :data:`SUBSTEP_SAMPLES` particle-lags of the run spread over it (a particle present at
    both ends, its value, state and the other properties at the lag's start as the run
    held them), one lag with ``substeps`` steps and one with twice as many differ by more
    than :data:`SUBSTEP_TOLERANCE` of the largest value met. An unstable step (k lag /
    substeps beyond about 2.8 for a rate k) grows the values by orders of magnitude per
    lag while they stay finite for many lags; the step-doubling difference shows it from the first lag
    (E. Hairer, S. P. Norsett and G. Wanner, Solving Ordinary Differential Equations I,
    Springer 1993, Ch. II.4: step-size control by step doubling)."""
    import warnings

    from cfbmarkov.errors import CfbmarkovWarning

    law = sk.laws[q]
    n = states.shape[1]
    lags = (states.shape[0] - 1) * n
    if lags <= 0:
        return
    # candidates drawn at random over the run (seeded: the same warning for any thread
    # count; a stride would fall on few particles where it shares factors with N), then
    # those held; no index array over every particle-frame
    draws = min(lags, 8 * SUBSTEP_SAMPLES)
    candidates = np.sort(np.random.default_rng(0).choice(lags, size=draws, replace=False))
    frames, particles = np.divmod(candidates, n)
    held = (states[frames, particles] >= 0) & (states[frames + 1, particles] >= 0)
    frames, particles = frames[held], particles[held]
    if not frames.size:
        return
    every = -(-frames.size // SUBSTEP_SAMPLES)
    frames, particles = frames[::every], particles[::every]
    parameters = np.ascontiguousarray(sk.parameters[q], dtype=np.float64)
    rows = np.ascontiguousarray(parameters[states[frames, particles]])
    others = np.ascontiguousarray(values[:, frames, particles].T)
    start = np.ascontiguousarray(values[q, frames, particles])
    worst = _step_doubling(law.function, start, rows, others, float(lag), int(law.substeps))
    if worst > SUBSTEP_TOLERANCE:
        said = (f"by up to {worst:.3g} times its largest value" if worst >= 1.0 else
                f"by up to {100 * worst:.3g} % of its largest value" if np.isfinite(worst)
                else "so much that one of them is not finite")
        warnings.warn(f"property {sk.names[q]}: over one lag its RK4 integration with "
                      f"{law.substeps} sub-steps and with {2 * law.substeps} differ {said} "
                      f"on {frames.size} particle-lags of the run: the sub-steps are "
                      "too few for its rates (RK4 is unstable beyond a rate times the "
                      "sub-step of about 2.8, and inaccurate well before), so its values "
                      "may be far off while finite; give more (Custom(..., substeps=...))",
                      CfbmarkovWarning, stacklevel=3)


def _custom_piece(arguments, top, values, first, last) -> None:
    """:func:`custom_property` over the frames ``first`` .. ``last``."""
    custom_property(*arguments, first, last, top, values)


def _check_custom_start(sk, q: int, states: np.ndarray) -> None:
    """Evaluate a custom law's rate function once, in Python, at its start value in the
    first occupied state, with the properties computed before it at their start values and
    the others NaN (as the Monte Carlo fills them): a function that raises there, or gives
    no finite rate, is refused naming the property before the run (inside the compiled run
    the error would be a bare SystemError)."""
    from cfbmarkov.errors import InputError

    law = sk.laws[q]
    occupied = states[states >= 0]
    if not occupied.size:
        return
    s = int(occupied[0])
    others = np.full(sk.n_properties, np.nan)
    filled = [i for i in range(sk.n_properties) if sk.linear[i] or i < q]
    others[filled] = sk.initial[filled]
    row = np.asarray(sk.parameters[q], dtype=np.float64)[s]
    function = getattr(law.function, "py_func", law.function)
    readable = ", ".join(sk.names[i] for i in filled if i != q) or "none"
    try:
        rate = float(function(float(sk.initial[q]), row, others))
    except Exception as exc:     # the user's code: any error it raises is named
        raise InputError(f"property {sk.names[q]}: its rate function raised "
                         f"{type(exc).__name__} ({exc}) at its start value "
                         f"{sk.initial[q]:g} in state {s}, with the properties it can read "
                         f"filled ({readable}; the others NaN): a coupled law reads only the "
                         "linear properties and those declared before it, so declare the "
                         "properties it reads first") from None
    if not np.isfinite(rate):
        raise InputError(f"property {sk.names[q]}: its rate function gives {rate} at its "
                         f"start value {sk.initial[q]:g} in state {s}, with the properties "
                         f"it can read filled ({readable}; the others NaN): declare the "
                         "properties it reads before it, and give it a finite rate there")


def _warn_not_finite(name: str, values: np.ndarray, present: np.ndarray) -> bool:
    """Warn where a custom law's values are not finite for particles present (a rate
    function that diverges): they are stored, and every figure from them is NaN. Returns
    whether it warned."""
    import warnings

    from cfbmarkov.errors import CfbmarkovWarning

    bad = int(np.count_nonzero(present & ~np.isfinite(values)))
    if bad:
        warnings.warn(f"property {name} is not finite for {bad} of "
                      f"{int(np.count_nonzero(present))} particle-frames present: its rate "
                      "function diverges (a rate growing with the value) or the RK4 "
                      "sub-steps are too few for it (Custom(..., substeps=...))",
                      CfbmarkovWarning, stacklevel=3)
    return bool(bad)


@nb.njit(cache=True)
def _exit_values(states, laps, values, a, b, periodic, fresh_only, out, out_time, out_entry):
    n_frames, n = states.shape
    count = 0
    for p in range(n):
        top = laps[0, p]
        fresh = False
        entered = 0
        for k in range(1, n_frames):
            s_prev = states[k - 1, p]
            s = states[k, p]
            if s_prev < 0:
                fresh = s >= 0
                entered = k
                continue
            left = (s < 0) if not periodic else (laps[k, p] > top)
            if periodic and laps[k, p] > top:
                top = laps[k, p]
            if left:
                if fresh or not fresh_only:
                    out[count] = a[s_prev] * values[k - 1, p] + b[s_prev]
                    out_time[count] = k
                    out_entry[count] = entered
                    count += 1
                fresh = True
                entered = k
    return count


def exit_values(states: np.ndarray, laps: np.ndarray, values: np.ndarray, a: np.ndarray,
                b: np.ndarray, periodic: bool, fresh_only: bool = True
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The value of a linear property at every exit of a run (the lag's map applied to the
    value at the last frame before it).

    Parameters
    ----------
    states, laps : ndarray of int32, shape (T, N)
    values : ndarray of float64, shape (T, N)
        The property (:func:`run_properties`, one row of it).
    a, b : ndarray of float64, shape (S,)
        Its affine maps of one lag.
    periodic : bool
        Exits are passes up through the top to a new lap maximum (else leaving an open
        riser).
    fresh_only : bool, optional
        Only residences that began in the run (an entry seen), the ones whose start value
        is the entry value.

    Returns
    -------
    values : ndarray of float64, shape (E,)
    frames : ndarray of int64, shape (E,)
        The frame of each exit (the first after it).
    entries : ndarray of int64, shape (E,)
        The frame its residence began (0 for one under way at the start). A run of K lags
        sees only residences that end in it: to average over residences without favouring
        the short ones, keep those that began early enough to have ended.
    """
    states = np.ascontiguousarray(states, dtype=np.int32)
    out = np.empty(states.size)
    frames = np.empty(states.size, np.int64)
    entries = np.empty(states.size, np.int64)
    count = _exit_values(states, np.ascontiguousarray(laps, dtype=np.int32),
                         np.ascontiguousarray(values, dtype=np.float64),
                         np.ascontiguousarray(a, dtype=np.float64),
                         np.ascontiguousarray(b, dtype=np.float64), bool(periodic),
                         bool(fresh_only), out, frames, entries)
    return out[:count].copy(), frames[:count].copy(), entries[:count].copy()
