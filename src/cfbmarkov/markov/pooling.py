"""Several runs of one case as one sample: their windows discretised alike and their
transitions counted together (``docs/definitions.md``, Pooled fits).

A model fitted on several runs pools their transition counts (:class:`TransitionCounts`
add; :func:`~cfbmarkov.markov.counting.count_transitions` sums over a list of windows):
its P is that of all their transitions, as if the windows were one longer sample of the
same flow. Runs pool only where they describe one riser at one time basis:
:func:`check_runs_match` refuses runs that differ in dimensions, width, height, depth,
boundary or frame interval, and runs whose files record different case parameters (the
physical settings of a simulated case, :data:`CASE_SECTIONS`, e.g.
``gas.superficial_velocity``), naming the first difference; :func:`check_runs_distinct`
refuses a run pooled with itself.
"""

from __future__ import annotations

import math
import os
from typing import Sequence

import numpy as np

from cfbmarkov._outputs import PREDICTION_SOURCE
from cfbmarkov.errors import InputError
from cfbmarkov.markov.discrete import DiscreteTrajectories, discretize
from cfbmarkov.markov.states import StateSpace
from cfbmarkov.trajectory_identity import window_identity

#: what two runs must share to be pooled, as (attribute, what the message calls it)
_SHARED = (("dimensions", "dimensions"), ("width", "width (m)"), ("height", "height (m)"),
           ("depth", "depth (m)"), ("boundary", "boundary"),
           ("frame_interval", "frame interval (s)"))


#: the sections of a file's ``parameters`` (a simulated case's settings) that define its flow:
#: runs whose files both record a setting of these and differ in it are of different cases.
#: Files that record none (imports, synthetic flows) are not compared on them.
CASE_SECTIONS = ("riser", "particles", "gas", "contact")


def case_parameters(parameters) -> dict[str, object]:
    """The case-defining settings recorded in a trajectory file's ``parameters``.

    Parameters
    ----------
    parameters : dict
        The file's ``parameters`` (a case's settings as nested sections, or a producer's
        own keys).

    Returns
    -------
    dict
        ``{"section.name": value}`` for every setting under :data:`CASE_SECTIONS` (empty
        for a file that records none).
    """
    out: dict[str, object] = {}

    def flat(d, prefix):
        for key, value in d.items():
            if isinstance(value, dict):
                flat(value, f"{prefix}{key}.")
            else:
                out[f"{prefix}{key}"] = value

    for section in CASE_SECTIONS:
        value = (parameters or {}).get(section) if isinstance(parameters, dict) else None
        if isinstance(value, dict):
            flat(value, f"{section}.")
    return out


def _same(a, b, tolerance: float = 1e-9) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=tolerance, abs_tol=0.0)
    return a == b


def _text(value) -> str:
    return format(value, "g") if isinstance(value, float) else str(getattr(value, "value", value))


def check_runs_match(runs: Sequence) -> None:
    """Refuse runs that do not describe one riser at one time basis.

    Parameters
    ----------
    runs : sequence of Trajectories
        Open trajectory files.

    Raises
    ------
    InputError
        At the first run that differs from the first in dimensions, width, height, depth,
        boundary or frame interval (relative tolerance 1e-9), or in a case parameter both
        files record (:func:`case_parameters`), naming the setting and both values.
    """
    first = runs[0]
    first_case = case_parameters(getattr(first, "parameters", None))
    for run in runs[1:]:
        for name, words in _SHARED:
            a, b = getattr(first, name), getattr(run, name)
            if not _same(a, b):
                raise InputError(f"runs of different {words} cannot be pooled: {first.path} "
                                 f"has {_text(a)}, {run.path} has {_text(b)} (fit runs of "
                                 "one case, at one frame interval)")
        case = case_parameters(getattr(run, "parameters", None))
        for key in sorted(set(first_case) & set(case)):
            a, b = first_case[key], case[key]
            if not _same(float(a) if isinstance(a, int) and not isinstance(a, bool) else a,
                         float(b) if isinstance(b, int) and not isinstance(b, bool) else b):
                raise InputError(f"runs of different cases cannot be pooled: {first.path} has "
                                 f"{key} = {_text(a)}, {run.path} has {key} = {_text(b)} "
                                 "(pool runs of one case; fit each case on its own)")


def check_runs_distinct(runs: Sequence, windows: Sequence[tuple[float, float]]) -> None:
    """Refuse to pool a run with itself: a window pooled twice counts its transitions
    twice and narrows the interval as if it were independent flow.

    Parameters
    ----------
    runs : sequence of Trajectories
        Open trajectory files, one per window.
    windows : sequence of (float, float)
        The fitting window (s) of each run.

    Raises
    ------
    InputError
        Where two windows have the same content
        (:func:`~cfbmarkov.trajectory_identity.window_identity`: a run given twice, or a
        copy of it), two windows are of one run (one file, or two files that hold the same
        frame, :func:`same_run_frame`: a copy or a link; overlapping: counted twice; apart:
        not independent runs), two windows of two files hold the same frames under two
        clocks (:func:`same_window_frames`: a copy with its times shifted), or one of
        several files is a Markov chain's prediction.
    """
    if len(runs) > 1:
        for run in runs:
            if getattr(run, "source", None) == PREDICTION_SOURCE:
                raise InputError(f"{run.path} is a Markov chain's prediction, not a run: pooled "
                                 "with other files it would be counted as independent flow, "
                                 "while it only repeats the chain it was drawn from (pool "
                                 "CFD-DEM runs or measurements; fit a prediction on its own)")
    seen: dict[str, str] = {}
    for k, (run, window) in enumerate(zip(runs, windows)):
        identity = window_identity(run, window)
        where = f"{run.path} {window[0]:g}-{window[1]:g} s"
        if identity in seen:
            raise InputError(f"{seen[identity]} and {where} hold the same data: pooling a run "
                             "with itself counts its transitions twice, as if it were twice "
                             "the data (pool independent runs of one case)")
        seen[identity] = where
        for other, w in zip(runs[:k], windows[:k]):
            one_file = os.path.realpath(other.path) == os.path.realpath(run.path)
            common = None if one_file else same_run_frame(other, run)
            if not one_file and common is None:
                shifted = (same_window_frames(other, w, run, window)
                           or same_index_frames(other, run))
                if shifted is not None:
                    raise InputError(
                        f"{other.path} {w[0]:g}-{w[1]:g} s and {where} hold the same "
                        f"particles at the same positions at {shifted[0]:.10g} s and "
                        f"{shifted[1]:.10g} s: one run under two clocks (a copy whose "
                        "times were shifted, or exported twice); "
                        "pooled it would count its transitions twice, as if it were twice "
                        "the data (pool independent runs of one case)")
                continue
            what = (f"of {run.path}" if one_file else
                    f"of {other.path} and {run.path}, which hold one run (their frames at "
                    f"t = {common:.10g} s hold the same particles at the same positions: a "
                    "copy or a link of one file, or of a part of it, or its particles "
                    "reordered, or its coordinates rounded)")
            if w[0] < window[1] and window[0] < w[1]:
                raise InputError(f"the windows {w[0]:g}-{w[1]:g} s and {window[0]:g}-"
                                 f"{window[1]:g} s {what} overlap: their common frames "
                                 "would be counted twice ("
                                 + (f"fit one window spanning both, {min(w[0], window[0]):g}:"
                                    f"{max(w[1], window[1]):g}" if one_file else
                                    "fit one of the files alone")
                                 + ", or pool independent runs of the case)")
            raise InputError(f"the windows {w[0]:g}-{w[1]:g} s and {window[0]:g}-"
                             f"{window[1]:g} s are both {what}; pooled as runs they "
                             "would be taken as independent flow and narrow the interval by "
                             "sqrt(2), while windows of one run share its slow changes; fit "
                             f"one window of it ({min(w[0], window[0]):g}:"
                             f"{max(w[1], window[1]):g}), or pool independent runs of the case")


def same_window_frames(a, window_a: tuple[float, float], b,
                       window_b: tuple[float, float]) -> tuple[float, float] | None:
    """The times of two windows' frames as far into each (the last frame of the shorter
    window's length) where both hold the same particles at the same positions: one run
    under two clocks (a copy with its times shifted), which :func:`same_run_frame`, reading
    one time in both files, does not see. Independent runs, even members started from one
    state, differ there (a chaotic flow never meets again).

    Parameters
    ----------
    a, b : Trajectories
        Open trajectory files.
    window_a, window_b : (float, float)
        Their windows (s).

    Returns
    -------
    (float, float) or None
        The two frames' times (s) where they hold one run's particles
        (:func:`shared_positions`), else None.
    """
    frames_a, frames_b = a.window(*window_a), b.window(*window_b)
    span = min(frames_a.stop - frames_a.start, frames_b.stop - frames_b.start) - 1
    if span < 0:
        return None
    i, j = frames_a.start + span, frames_b.start + span
    if not shared_positions(a, i, b, j):
        return None
    return float(a.times[i]), float(b.times[j])


def same_index_frames(a, b) -> tuple[float, float] | None:
    """The times of two files' frames of one index (the middle and the last both hold)
    where both hold the same particles at the same positions under different times: a
    copy exported under another clock, whatever windows are taken of it
    (:func:`same_window_frames` compares the frames as far into each window, which windows
    offset from each other's pass by). The first frames are not compared: independent runs
    started from one state (an ensemble's members) share them.

    Parameters
    ----------
    a, b : Trajectories
        Open trajectory files.

    Returns
    -------
    (float, float) or None
        The two frames' times (s), else None.
    """
    last = min(a.n_frames, b.n_frames) - 1
    for i in sorted({last // 2, last} - {0}) if last >= 1 else ():
        if a.times[i] != b.times[i] and shared_positions(a, i, b, i):
            return float(a.times[i]), float(b.times[i])
    return None


#: the common frames :func:`same_run_frame` reads at a time, looking back for the latest
#: with a particle in view
SAME_RUN_FRAMES = 64


def same_run_frame(a, b) -> float | None:
    """The time of a frame two files share with the same content: a sign that they hold one
    run (a copy, a link, or a run and a part of it) rather than two.

    Two runs of a case are told apart by their particles' positions at one time both files
    hold: the latest such time (runs started from one state part at once, a chaotic flow
    never meets again), compared whatever the particles' ids and order
    (:func:`shared_positions`: a reordered, renumbered or partial copy is one run too).

    Parameters
    ----------
    a, b : Trajectories
        Open trajectory files.

    Returns
    -------
    float or None
        That frame's time (s) where both files hold one run's particles
        (:func:`shared_positions`); None where the files share no frame time with a
        particle in view, or differ at the latest such frame.
    """
    times_a, times_b = np.asarray(a.times), np.asarray(b.times)
    common = np.intersect1d(times_a, times_b)
    if common.size == 0:
        return None
    rows_a = np.searchsorted(times_a, common)
    rows_b = np.searchsorted(times_b, common)
    # the latest common frame with a particle in view (a tracer out of view for long, the
    # usual PEPT track, leaves many empty ones), looked for a block of frames at a time
    found = None
    for stop in range(common.size, 0, -SAME_RUN_FRAMES):
        rows = rows_a[max(stop - SAME_RUN_FRAMES, 0):stop]
        seen = np.asarray(a.present(slice(int(rows[0]), int(rows[-1]) + 1)))
        in_view = seen[rows - rows[0]].any(axis=1)
        if in_view.any():
            found = stop - rows.size + int(np.flatnonzero(in_view)[-1])
            break
    if found is None:
        return None
    i, j = int(rows_a[found]), int(rows_b[found])
    return float(common[found]) if shared_positions(a, i, b, j) else None


#: the share of the particles in view (of the file with fewer) at the same coordinates in
#: both files beyond which two frames are taken for one run's
SHARED_POSITIONS = 0.5

#: the relative resolution below which two coordinates are the same written again
#: (2^-20, a little coarser than float32's 2^-24)
FLOAT32_RESOLUTION = 2.0 ** -20

#: the most decimals (of m) to which a file's coordinates are told to be written: a copy
#: written again to k decimals (k <= 9)
MOST_DECIMALS = 9


def shared_positions(a, i: int, b, j: int) -> bool:
    """Whether frame ``i`` of ``a`` and frame ``j`` of ``b`` hold one run's particles: more
    than :data:`SHARED_POSITIONS` of the particles in view of the frame with fewer sit at
    the same coordinates in the other, whatever their ids and order: bit for bit, or within
    half the step to which a frame's coordinates were written (:func:`rounding_step`: a copy
    written again, rounded) and at least :data:`FLOAT32_RESOLUTION` of the largest
    coordinate (a copy written to 10 significant digits, or as float32), in every
    coordinate.

    A copy, a link, a copy with its particles reordered or renumbered, a part of a run
    (some of its particles), or a copy with its coordinates rounded shares them all; two
    independent runs share none (a chaotic flow's particles never meet the same
    coordinates again), and coordinates rounded to a coarse grid (PEPT to 1 mm) share a
    few per cent by chance.

    Parameters
    ----------
    a, b : Trajectories
        Open trajectory files.
    i, j : int
        Frame indices of ``a`` and ``b``.

    Returns
    -------
    bool
    """
    first = np.asarray(a.positions(i))[np.asarray(a.present(i), dtype=bool)]
    second = np.asarray(b.positions(j))[np.asarray(b.present(j), dtype=bool)]
    if first.shape[1:] != second.shape[1:]:
        return False
    fewer = min(len(first), len(second))
    if fewer == 0:
        return False
    rows = [np.ascontiguousarray(x, dtype=np.float64) for x in (first, second)]
    if _share_found(rows) > SHARED_POSITIONS * fewer:
        return True
    steps = [s for s in (rounding_step(x) for x in rows) if s is not None]
    from scipy.spatial import cKDTree

    # within half the coarser step in every coordinate (how far rounding moves a value),
    # and at least a float32's resolution of the coordinates (a copy written to 10
    # significant digits, or as float32: 1 um on a 1 m riser, which independent runs'
    # particles come within for some 1e-4 of them even packed as 70 um grains)
    scale = max(float(np.nanmax(np.abs(x))) if x.size else 0.0 for x in rows)
    reach = max(0.5 * max(steps, default=0.0) * (1.0 + 1e-6), FLOAT32_RESOLUTION * scale)
    if not reach > 0.0:
        return False
    small, large = sorted(rows, key=len)
    distance, _ = cKDTree(large).query(small, p=np.inf, distance_upper_bound=reach)
    return int(np.isfinite(distance).sum()) > SHARED_POSITIONS * fewer


def _share_found(rows: list[np.ndarray]) -> int:
    """How many rows of the first array (positions, [n, D]) the second holds, bit for bit."""
    as_bytes = [np.ascontiguousarray(x).view(np.dtype((np.void, x.dtype.itemsize
                                                       * x.shape[1]))).ravel() for x in rows]
    return int(np.isin(as_bytes[0], as_bytes[1]).sum())


def rounding_step(positions: np.ndarray) -> float | None:
    """The largest step (m) by which the coordinates of ``positions`` were rounded when
    written: 10^-k for k fixed decimals (``%.4f``: 1e-4), or for s significant digits
    (``%.6g``) the step of the largest coordinate's magnitude, 10^(floor(log10 max|x|) + 1 - s);
    None where the coordinates are of full precision (more than :data:`MOST_DECIMALS`
    decimals). Nine in ten coordinates must keep to the rule.

    Parameters
    ----------
    positions : ndarray of float64, shape (n, D)

    Returns
    -------
    float or None
    """
    values = positions[np.isfinite(positions)]
    if values.size == 0:
        return None
    decimals = np.full(values.shape, MOST_DECIMALS + 1)
    for k in range(MOST_DECIMALS, -1, -1):
        scaled = values * 10.0 ** k
        # a decimal read back as the nearest double: within a few units of its last place
        on = np.abs(scaled - np.rint(scaled)) <= 1e-6 + 4e-16 * np.abs(scaled)
        decimals[on] = k
    written = decimals <= MOST_DECIMALS
    if written.mean() < KEPT_TO_RULE:
        return None
    # the two rules' steps, of nine in ten coordinates: the coarser is how far a value
    # may have moved (fixed decimals give the same step both ways)
    fixed = float(np.quantile(decimals[written], KEPT_TO_RULE, method="higher"))
    nonzero = written & (values != 0.0)
    if not nonzero.any():
        return 10.0 ** -fixed
    magnitude = np.floor(np.log10(np.abs(values[nonzero])))
    digits = decimals[nonzero] + magnitude + 1
    significant = float(np.quantile(digits, KEPT_TO_RULE, method="higher"))
    top = float(np.floor(np.log10(np.max(np.abs(values)))))
    return max(10.0 ** -fixed, 10.0 ** (top + 1 - significant))


#: the share of a file's coordinates that must keep to one rounding rule
#: (:func:`rounding_step`)
KEPT_TO_RULE = 0.9


def run_windows(windows: Sequence[tuple[float, float]], n_runs: int
                ) -> list[tuple[float, float]]:
    """One fitting window per run: one window for all, or one each.

    Parameters
    ----------
    windows : sequence of (float, float)
        One window (s), or ``n_runs`` of them.
    n_runs : int
        Number of runs.

    Returns
    -------
    list of (float, float)
        ``n_runs`` windows.

    Raises
    ------
    InputError
        If neither one nor ``n_runs`` windows are given.
    """
    windows = [tuple(map(float, w)) for w in windows]
    if len(windows) == 1:
        return windows * n_runs
    if len(windows) != n_runs:
        raise InputError(f"{len(windows)} windows for {n_runs} runs: give one window for all "
                         "runs or one per run (--window 10:15,12:17,...)")
    return windows


def discretize_runs(runs: Sequence, state_space: StateSpace, lag: float,
                    windows: Sequence[tuple[float, float]]) -> list[DiscreteTrajectories]:
    """The fitting windows of several runs, checked to match and discretised alike.

    Parameters
    ----------
    runs : sequence of Trajectories
        Open trajectory files of one case.
    state_space : StateSpace
        The states (the same for every run).
    lag : float
        The lag (s).
    windows : sequence of (float, float)
        One window for all runs, or one per run (s).

    Returns
    -------
    list of DiscreteTrajectories
        One per run, in order, all in one state space (a space that fits itself to its
        window, e.g. ``cells-velocity`` or ``cells-regime``, fitted on the first run's);
        an estimator's ``fit`` pools them.

    Raises
    ------
    InputError
        If the runs differ (:func:`check_runs_match`), the windows do not match the runs
        (:func:`run_windows`), a run is pooled with itself (:func:`check_runs_distinct`),
        or a window cannot be discretised
        (:func:`~cfbmarkov.markov.discretize`).
    """
    check_runs_match(runs)
    windows = run_windows(windows, len(runs))
    check_runs_distinct(runs, windows)
    first = discretize(runs[0], state_space, lag, windows[0])
    # a space that fits itself to its window (velocity bins, regime edges) is fitted on the
    # first run's and applied as it is to the others, so that their states are the same
    fitted = first.state_space
    return [first] + [discretize(run, fitted, lag, window)
                      for run, window in zip(runs[1:], windows[1:])]
