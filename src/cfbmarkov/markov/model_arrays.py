"""The checks of a Markov chain model's fields, and its own read-only arrays.

:func:`checked_arrays` turns the arrays given to a
:class:`~cfbmarkov.markov.model.MarkovModel` (P, the counts, the pass fractions) into the
model's own: read-only copies, or the given arrays themselves where the model adopts them
(made read-only, not copied). Each is checked as it is taken: shapes for the state space,
whole non-negative counts, a row-stochastic P, pass fractions in [0, 1].
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.markov.states import StateSpace

#: the model's [S, S] arrays (model files store them as datasets of the same names)
SQUARE_ARRAYS = ("transition_matrix", "counts", "counts_up", "counts_down")


def owned_array(value, dtype, adopt: bool) -> np.ndarray:
    """A model's read-only array of ``value``.

    Parameters
    ----------
    value : array_like
    dtype : numpy dtype
        The model's dtype for it.
    adopt : bool
        Take ``value`` itself where it is an ndarray of ``dtype`` and C-contiguous (it is
        made read-only; the caller must not keep writing it); else (and without ``adopt``)
        a copy.

    Returns
    -------
    ndarray
        Read-only.
    """
    if (adopt and isinstance(value, np.ndarray) and value.dtype == dtype
            and value.flags.c_contiguous):
        owned = value
    else:
        owned = np.array(value, dtype=dtype)
    owned.setflags(write=False)
    view = owned.view()      # a view of a read-only base cannot be made writeable again
    view.setflags(write=False)
    return view


def checked_coherence(value) -> float:
    """The coherence rho as a float.

    Parameters
    ----------
    value : float

    Returns
    -------
    float

    Raises
    ------
    InputError
        If ``value`` is not a number in [0, 1].
    """
    if not (isinstance(value, (int, float, np.number)) and 0.0 <= float(value) <= 1.0):
        raise InputError(f"model coherence {value!r} must lie in [0, 1]")
    return float(value)


def checked_flow_direction(value, counts_up: np.ndarray, counts_down: np.ndarray,
                           open_riser: bool) -> str:
    """The direction a model counts residences in: ``value`` checked, or where it is None
    the fitting window's net solids flow read off its pass counts ("down" where a periodic
    riser's transitions passed down through the bottom more often than up through the top;
    "up" otherwise and for an open riser).

    Parameters
    ----------
    value : {"up", "down"} or None
        The recorded direction (None: from the counts).
    counts_up, counts_down : ndarray of int64, shape (S, S)
        The transitions that passed up through the top / down through the bottom.
    open_riser : bool
        An open riser's model (always "up": from the inlet to the outlet).

    Returns
    -------
    {"up", "down"}

    Raises
    ------
    InputError
        If ``value`` is neither None, "up" nor "down", or "down" for an open riser.
    """
    if value is None:
        if open_riser:
            return "up"
        return "down" if int(counts_down.sum()) > int(counts_up.sum()) else "up"
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    if value not in ("up", "down") or (open_riser and value == "down"):
        raise InputError(f"model flow direction {value!r}: up or down (an open riser: up)")
    return str(value)


def checked_run_windows(windows, source) -> tuple[tuple[float, float], ...]:
    """A pooled fit's windows, one per run of ``source``, as a tuple of float pairs.

    Parameters
    ----------
    windows : sequence of (float, float)
        The fitting window (s) of each run.
    source : list of str
        The runs.

    Returns
    -------
    tuple of (float, float)

    Raises
    ------
    InputError
        If ``source`` is not a list of as many runs, or a window is not two finite times
        A < B.
    """
    try:
        pairs = tuple((float(a), float(b)) for a, b in windows)
    except (TypeError, ValueError):
        raise InputError(f"model run_windows {windows!r} are not pairs of times") from None
    if not isinstance(source, (list, tuple)) or len(source) != len(pairs):
        raise InputError(f"model run_windows: {len(pairs)} windows for source {source!r} "
                         "(one per run of a pooled fit)")
    if not all(np.isfinite(w).all() and w[1] > w[0] for w in pairs):
        raise InputError(f"model run_windows {windows!r} are not finite times (A < B)")
    return pairs


def checked_arrays(square: dict[str, Any], pass_fractions, lag, state_space: StateSpace,
                   adopt: bool) -> tuple[dict[str, np.ndarray], tuple | None]:
    """A model's own P, counts and pass fractions, checked.

    Parameters
    ----------
    square : dict of str to array_like
        ``transition_matrix`` (float64 [S, S]) and ``counts``, ``counts_up``,
        ``counts_down`` (whole numbers [S, S]).
    pass_fractions : (array_like, array_like) or None
        (up, down) fractions [S, S] of each transition passing the boundary.
    lag : float
        The lag (s).
    state_space : StateSpace
        The states (S).
    adopt : bool
        Take the given arrays themselves (see :func:`owned_array`).

    Returns
    -------
    arrays : dict of str to ndarray
        The four [S, S] arrays, float64 and int64, read-only.
    pass_fractions : tuple of two ndarrays of float64, shape (S, S), or None

    Raises
    ------
    InputError
        If an array does not have shape (S, S), the counts are not whole or are negative,
        the pass counts of a transition exceed its count (where ``pass_fractions`` is None
        and the fractions are the counts' shares), the lag is not positive and finite, P
        holds negative or non-finite entries or its rows do not sum to 1, or the pass
        fractions are not (up, down) of shape (S, S) in
        [0, 1] with up + down <= 1.
    """
    s = state_space.n_states
    arrays = {}
    for name in SQUARE_ARRAYS:
        given = np.asarray(square[name])
        if name != "transition_matrix" and given.dtype.kind not in "iub" and not (
                np.all(np.isfinite(given)) and np.all(given == np.round(given))):
            raise InputError(f"model {name} holds values that are not whole counts")
        value = owned_array(square[name], np.float64 if name == "transition_matrix"
                            else np.int64, adopt)
        if value.shape != (s, s):
            raise InputError(f"model {name} has shape {value.shape}, expected ({s}, {s}) "
                             f"for {state_space.describe()}")
        arrays[name] = value
    if not (isinstance(lag, (int, float, np.number)) and np.isfinite(lag) and lag > 0):
        raise InputError(f"model lag {lag!r} s must be a positive finite number")
    p = arrays["transition_matrix"]
    check_stochastic(p, p.sum(axis=1))
    for name in ("counts", "counts_up", "counts_down"):
        value = arrays[name]
        if value.size and value.min() < 0:
            raise InputError(f"model {name} holds negative counts")
    passes = arrays["counts_up"] + arrays["counts_down"]
    # where the pass fractions are not given they are the pass counts' shares of the counts
    if pass_fractions is None and passes.size and np.any(passes > arrays["counts"]):
        i, j = np.unravel_index(int(np.argmax(passes - arrays["counts"])), passes.shape)
        raise InputError(f"model counts_up + counts_down exceed counts ({int(passes[i, j])} "
                         f"passes of the {int(arrays['counts'][i, j])} transitions {i} -> {j}): "
                         "a pass through the top or the bottom is one of the transitions "
                         "counted")
    if pass_fractions is None:
        return arrays, None
    if len(pass_fractions) != 2:
        raise InputError("pass fractions must be (up, down)")
    fractions = tuple(owned_array(f, np.float64, adopt) for f in pass_fractions)
    if any(f.shape != (s, s) for f in fractions):
        raise InputError(f"pass fractions must have shape ({s}, {s})")
    check_pass_fractions(*fractions)
    return arrays, fractions


def check_stochastic(values: np.ndarray, row_sums: np.ndarray) -> None:
    """Refuse a transition matrix (its entries, dense or a sparse matrix's non-zeros, and
    its row sums) with a negative or non-finite entry or a row not summing to 1 within
    1e-9 (as documented).

    Raises
    ------
    InputError
        Naming the rule broken (and the first row off).
    """
    if not np.all(np.isfinite(values)) or (values.size and values.min() < 0):
        raise InputError("transition matrix holds negative or non-finite entries")
    if not np.allclose(row_sums, 1.0, rtol=0.0, atol=1e-9):
        k = int(np.argmax(np.abs(row_sums - 1.0)))
        raise InputError(f"transition matrix rows do not sum to 1 (row {k} sums to "
                         f"{row_sums[k]:.6g})")


def check_pass_fractions(up: np.ndarray, down: np.ndarray) -> None:
    """Refuse pass fractions (of every transition, or of P's non-zeros) outside [0, 1] or
    with up + down > 1.

    Raises
    ------
    InputError
        Naming the largest value.
    """
    if not (np.all(np.isfinite(up)) and np.all(np.isfinite(down))) or (up.size and (
            min(up.min(), down.min()) < 0 or (up + down).max() > 1.0 + 1e-9)):
        worst = float(max(np.nanmax(np.abs(up)), np.nanmax(np.abs(down)))) if up.size else 0
        raise InputError("pass fractions must lie in [0, 1] with up + down <= 1 for each "
                         f"transition (largest {worst:.6g})")
