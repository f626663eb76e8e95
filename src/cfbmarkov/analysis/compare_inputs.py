"""The inputs of a comparison checked: the analysis window and parameters, the columns of
the model behind a prediction, and whether a prediction and a reference can be compared
(:func:`cfbmarkov.analysis.compare.compare_runs`).
"""

from __future__ import annotations

import contextlib
import json
import math

import numpy as np

from cfbmarkov._outputs import PREDICTION_SOURCE
from cfbmarkov.errors import InputError
from cfbmarkov.frame_times import window_pair
from cfbmarkov.limits import MAX_BINS
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import time_text


def check_window(window) -> tuple[float, float]:
    """An analysis window as two floats.

    Parameters
    ----------
    window : sequence of two numbers
        (start, stop), s.

    Returns
    -------
    (float, float)
        (start, stop), s.

    Raises
    ------
    InputError
        When the window is not two finite numbers with stop > start.
    """
    start, stop = window_pair(window)
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise InputError(f"window {start:g}:{stop:g} s is not finite")
    if not stop > start:
        raise InputError(f"window {start:g}:{stop:g} s is empty (the end must follow the start)")
    return start, stop


def check_parameters(window, bin_width: float | None, md_order: float) -> tuple[float, float]:
    """Check the parameters of a comparison.

    Parameters
    ----------
    window : sequence of two numbers
        Analysis window (start, stop), s.
    bin_width : float or None
        RTD bin width, s; None (taken from the files, :func:`default_bin_width`) passes.
    md_order : float
        Order k of the Minkowski distance (Eq. 9).

    Returns
    -------
    (float, float)
        The window as (start, stop), s.

    Raises
    ------
    InputError
        For an unusable window (:func:`check_window`), a Minkowski order that is not a
        number >= 1, or a bin width (s) that is not finite and positive or leaves fewer
        than two bins, or more than ``MAX_BINS``, over the window (:func:`check_bins`).
    """
    start, stop = check_window(window)
    from cfbmarkov.limits import check_finite

    if not (isinstance(md_order, float) and math.isinf(md_order)):
        check_finite(md_order, "Minkowski order")
    if bin_width is not None:
        bin_width = check_finite(bin_width, "bin width", "s")
    if not md_order >= 1:
        raise InputError(f"Minkowski order {md_order:g} must be a finite number >= 1 (or inf, "
                         "the largest difference): below 1 the sum is not a distance")
    if bin_width is None:
        return start, stop
    check_bins((start, stop), bin_width)
    return start, stop


def rtd_bin_count(window_length: float, bin_width: float) -> int:
    """Number of RTD bins over a window, as :func:`cfbmarkov.observed.residence.rtd_histogram`
    lays them (from 0 to the first multiple of the bin width at or above the length)."""
    return max(1, math.ceil(window_length / bin_width - 1e-6))


def check_bins(window: tuple[float, float], bin_width: float, source: str = "given") -> None:
    """Refuse an RTD bin width that leaves fewer than two bins over the window (the RTDs
    of both sides then fill the one bin, and their MD is 0 whatever the model), or more
    than ``MAX_BINS``.

    Parameters
    ----------
    window : (float, float)
        The analysis window (start, stop), s.
    bin_width : float
        RTD bin width, s.
    source : str, optional
        Where the width comes from: ``given`` (``--bin-width``) or a default
        (:func:`default_bin_width`); the refusal's advice follows it.

    Raises
    ------
    InputError
        One line naming the window and a workable width (or, for a default width, a
        window long enough for it).
    """
    start, stop = window
    length = stop - start
    if not (math.isfinite(bin_width) and bin_width > 0):
        raise InputError(f"RTD bin width {bin_width:g} s must be positive")
    if length / bin_width > MAX_BINS:
        raise InputError(f"RTD bin width {bin_width:g} s makes {length / bin_width:.3g} "
                         f"bins over the window, more than {MAX_BINS}; give a larger --bin-width")
    if rtd_bin_count(length, bin_width) >= 2:
        return
    if source == "given":
        raise InputError(f"--bin-width {bin_width:g} s leaves one RTD bin over the window "
                         f"{start:g}:{stop:g} s ({length:g} s long), and one bin gives an MD "
                         f"of 0 whatever the model: give --bin-width {length / 2:.3g} s or "
                         "less, or leave it out for the default width")
    raise InputError(f"window {start:g}:{stop:g} s ({length:g} s long) holds fewer than two "
                     f"RTD bins of {bin_width:g} s ({source}): compare over a window of "
                     f"{2 * bin_width:g} s or more")


def default_bin_width(ref: Trajectories, pred: Trajectories) -> tuple[float, str]:
    """The RTD bin width of a comparison given none: the model's lag, as ``reproduce`` bins.

    Parameters
    ----------
    ref, pred : Trajectories
        The open reference and model files.

    Returns
    -------
    (float, str)
        The bin width (s) and where it comes from: the ``lag`` of the model attached to the
        prediction (``/provenance/model``), else the reference's frame interval, else the
        prediction's.

    Raises
    ------
    InputError
        When neither file has a frame interval (single frames) nor the prediction a model.
    """
    group = pred.group("model")
    if group is not None and "lag" in group.attrs:
        lag = float(np.asarray(group.attrs["lag"]))
        if math.isfinite(lag) and lag > 0:
            return lag, "the model's lag"
    for traj, what in ((ref, "the reference's frame interval"),
                       (pred, "the prediction's frame interval")):
        interval = float(traj.frame_interval)
        if math.isfinite(interval) and interval > 0:
            return interval, what
    raise InputError(f"neither {ref.path} nor {pred.path} has frames at a known interval: give "
                     "--bin-width (s)")


def model_columns(traj: Trajectories) -> int | None:
    """Number of cell columns of the model behind a prediction.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    int or None
        The ``columns`` attribute of ``/provenance/model`` (or of its ``state_space`` JSON),
        else ``parameters["columns"]`` of the file; None when the file has neither.
    """
    group = traj.group("model")
    if group is not None:
        if "columns" in group.attrs:
            return int(group.attrs["columns"])
        space = group.attrs.get("state_space")
        if space is not None:
            with contextlib.suppress(ValueError, TypeError, KeyError):
                return int(json.loads(space)["columns"])
    return grid_parameter(traj, "columns")


def grid_parameter(traj: Trajectories, name: str) -> int | None:
    """A whole-number grid parameter (``columns``, ``rows``) of a file's ``parameters``,
    else None: an imported file's ``columns`` are its source's column names, not a grid's
    width.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.
    name : str
        The parameter.

    Returns
    -------
    int or None
    """
    value = traj.parameters.get(name) if isinstance(traj.parameters, dict) else None
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value > 0:
        return int(value)
    return None


def model_flow_direction(traj: Trajectories) -> str | None:
    """The direction the model behind a prediction counts residences in.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    {"up", "down"} or None
        The ``flow_direction`` attribute of ``/provenance/model``; None where the file
        carries no model, or one whose file does not record it (or records something else).
    """
    group = traj.group("model")
    if group is None or "flow_direction" not in group.attrs:
        return None
    value = group.attrs["flow_direction"]
    value = value.decode(errors="replace") if isinstance(value, bytes) else str(value)
    return value if value in ("up", "down") else None


def common_span(ref: Trajectories, pred: Trajectories) -> tuple[float, float] | None:
    """The span of time both files cover.

    Parameters
    ----------
    ref, pred : Trajectories
        The open reference and model files.

    Returns
    -------
    (float, float) or None
        (first, last), s: from the later first frame to the earlier last one; None where
        the files share less than two frames' span (no window to compare over).
    """
    first = max(float(ref.times[0]), float(pred.times[0]))
    last = min(float(ref.times[-1]), float(pred.times[-1]))
    tol = max(ref.time_tolerance, pred.time_tolerance)
    return (first, last) if last - first > tol else None


def spans_text(ref: Trajectories, pred: Trajectories) -> str:
    """'the reference R covers 0 to 20 s, the prediction P 15 to 25 s'."""
    def span(run):
        return f"{time_text(run.times[0])} to {time_text(run.times[-1])} s"

    return f"the reference {ref.path} covers {span(ref)}, the prediction {pred.path} {span(pred)}"


def overlap_of(ref: Trajectories, pred: Trajectories, lead: str = ""
               ) -> tuple[tuple[float, float], str]:
    """The span both files cover (:func:`common_span`) and the text naming both spans
    (:func:`spans_text`); refused where they do not overlap.

    Parameters
    ----------
    ref, pred : Trajectories
        The open reference and model files.
    lead : str, optional
        What the refusal begins with (the window asked for, say).

    Returns
    -------
    ((float, float), str)

    Raises
    ------
    InputError
        Where the files do not overlap: one line naming both spans.
    """
    both = common_span(ref, pred)
    spans = spans_text(ref, pred)
    if both is None:
        raise InputError(f"{lead}{spans}; they do not overlap, so no window holds both: "
                         "compare a prediction of the reference's span")
    return both, spans


def check_common_window(ref: Trajectories, pred: Trajectories, start: float,
                        stop: float) -> None:
    """Refuse a window that leaves the span both files cover, naming both spans and a
    window inside their overlap (or saying that they do not overlap).

    Parameters
    ----------
    ref, pred : Trajectories
        The open reference and model files.
    start, stop : float
        The analysis window, s.

    Raises
    ------
    InputError
        Where the window leaves the overlap of the two files' spans, or they do not overlap.
    """
    (first, last), spans = overlap_of(ref, pred, f"window {start:g}:{stop:g} s: ")
    tol = max(ref.time_tolerance, pred.time_tolerance)
    if start >= first - tol and stop <= last + tol:
        return
    if stop <= first or start >= last:
        where = "lies outside the span both files cover"
    else:
        where = (f"lies partly outside the span both files cover; only "
                 f"{time_text(max(start, first))}:{time_text(min(stop, last))} s lies inside")
    length = stop - start
    if length >= last - first - tol:
        fits = f"{time_text(first)}:{time_text(last)} (all of it)"
    elif stop > last:
        fits = f"{time_text(last - length)}:{time_text(last)} (the same length)"
    else:
        fits = f"{time_text(first)}:{time_text(first + length)} (the same length)"
    raise InputError(f"window {start:g}:{stop:g} s {where} ({spans}: both {time_text(first)} "
                     f"to {time_text(last)} s); choose one within it, e.g. {fits}")


def check_runs(ref: Trajectories, pred: Trajectories, start: float, stop: float
               ) -> tuple[slice, slice, int | None]:
    """Check that two files can be compared over a window.

    Parameters
    ----------
    ref, pred : Trajectories
        The open reference and model files.
    start, stop : float
        The analysis window, s.

    Returns
    -------
    ref_frames, pred_frames : slice
        The window's frames in each file.
    columns : int or None
        The columns of the model behind the prediction (:func:`model_columns`).

    Raises
    ------
    InputError
        For a file whose content comparing does not support, a reference that is a Markov
        prediction against a prediction that is not (the two look swapped,
        :func:`check_order`), an open riser against a periodic one, a window outside the
        span both files cover (:func:`check_common_window`) or without frames, a model
        with an odd column count (mixing by halves is undefined), different domains (size,
        2D against 3D, or depth), or different particles (an open riser: different
        particles present at the window start).
    """
    for run in (ref, pred):
        # a periodic run's particles absent throughout the window are not part of its flow
        # there; one present in part of it would hide passes
        whole = (run.has_absences and not run.boundary.is_open
                 and _absent_throughout(run, start, stop) is not None)
        run.require_supported("comparing runs", three_d=True,
                              absent=run.boundary.is_open or whole, open_boundary=True)
    check_order(ref, pred)
    if ref.boundary != pred.boundary:
        raise InputError(f"{ref.path} is a{'n open' if ref.boundary.is_open else ' periodic'} "
                         f"riser and {pred.path} a{'n open' if pred.boundary.is_open else ' periodic'}"
                         " one: compare runs of the same kind")
    check_common_window(ref, pred, start, stop)
    ref_frames = ref.window(start, stop)
    pred_frames = pred.window(start, stop)
    columns = model_columns(pred)
    if columns is not None and columns % 2:
        raise InputError(f"{pred.path}: the model's state space has an odd column count "
                         f"({columns}): mixing by halves (x < W/2) is undefined, as the middle "
                         "column's cells straddle W/2; compare a prediction of a model fitted "
                         f"with an even count (--cells {columns + 1}xROWS)")
    if not (np.isclose(ref.width, pred.width) and np.isclose(ref.height, pred.height)):
        raise InputError(f"domains differ: {ref.path} is {ref.width:g} x {ref.height:g} m, "
                         f"{pred.path} is {pred.width:g} x {pred.height:g} m")
    if ref.dimensions != pred.dimensions or (ref.depth is not None
                                             and not np.isclose(ref.depth, pred.depth)):
        raise InputError(f"domains differ: {ref.path} is {ref.dimensions}D"
                         + (f" ({ref.depth:g} m deep)" if ref.depth is not None else "")
                         + f", {pred.path} is {pred.dimensions}D"
                         + (f" ({pred.depth:g} m deep)" if pred.depth is not None else ""))
    if ref.boundary.is_open:
        _check_same_start(ref, pred, ref_frames.start, pred_frames.start)
    elif not np.array_equal(np.sort(_window_ids(ref, start, stop)),
                            np.sort(_window_ids(pred, start, stop))):
        started = (pred.parameters.get("initial_frames")
                   if isinstance(pred.parameters, dict) else None)
        hint = (f" ({pred.path} was predicted from {started}: give that as the reference)"
                if isinstance(started, str) and started else "")
        raise InputError(f"{ref.path} ({_window_ids(ref, start, stop).size} particles) and "
                         f"{pred.path} ({_window_ids(pred, start, stop).size}) do not hold "
                         f"the same particle ids; mixing needs the same particles on both "
                         f"sides{hint}")
    return ref_frames, pred_frames, columns


def _absent_throughout(run: Trajectories, start: float, stop: float) -> np.ndarray | None:
    """:meth:`~cfbmarkov.trajectories.Trajectories.absent_throughout` over a window (s);
    None also where the window holds no frame (refused later, by the window's check)."""
    try:
        return run.absent_throughout(run.window(start, stop))
    except InputError:
        return None


def _window_ids(run: Trajectories, start: float, stop: float) -> np.ndarray:
    """The ids of a periodic run's particles in a window: those not absent throughout it."""
    absent = _absent_throughout(run, start, stop) if run.has_absences else None
    return run.ids if absent is None else run.ids[~absent]


def check_order(ref: Trajectories, pred: Trajectories) -> None:
    """Refuse a Markov prediction given as the reference beside a prediction that is not
    one (a run): the two look swapped, and every percentage difference would change sign.
    Two predictions (one model against another) pass.

    Parameters
    ----------
    ref, pred : Trajectories
        The open reference and model files, as given.

    Raises
    ------
    InputError
        One line naming both files and the order to give them in.
    """
    if ref.source == PREDICTION_SOURCE and pred.source != PREDICTION_SOURCE:
        raise InputError(f"the reference {ref.path} is a Markov prediction and the prediction "
                         f"{pred.path} is not (its source is {pred.source!r}): the two look "
                         f"swapped; give the run first, then the prediction (cfbmarkov compare "
                         f"{pred.path} {ref.path} ...)")


def check_not_same(ref: Trajectories, pred: Trajectories) -> None:
    """Refuse one file given as both the reference and the prediction (also through a link,
    or a copy of a run): every figure would say the model is perfect. The command line's
    check; in Python a run compared with itself is a sanity check and passes.

    Parameters
    ----------
    ref, pred : Trajectories
        The open reference and model files, as given.

    Raises
    ------
    InputError
        One line naming both files and what to give instead.
    """
    import os

    try:
        same = os.path.samefile(ref.path, pred.path)
    except OSError:
        same = False
    if same or (ref.source != PREDICTION_SOURCE and pred.source != PREDICTION_SOURCE
                and _same_content(ref, pred)):
        raise InputError(f"the reference {ref.path} and the prediction {pred.path} hold the "
                         "same trajectories: a file compared with itself gives MD 0 whatever "
                         "the model; give the run and a prediction of it (cfbmarkov predict "
                         "... -o PRED)")


def _same_content(ref: Trajectories, pred: Trajectories) -> bool:
    """Whether two runs (neither a prediction) hold the same data: the same content
    identity over their whole span (a copy of one file)."""
    from cfbmarkov.trajectory_identity import window_identity

    if (ref.n_frames != pred.n_frames or ref.n_particles != pred.n_particles
            or not np.array_equal(ref.times, pred.times)):
        return False
    span = (float(ref.times[0]), float(ref.times[-1]))
    try:
        return window_identity(ref, span, 1) == window_identity(pred, span, 1)   # cheap: 3 frames
    except Exception:       # noqa: BLE001 - unreadable: the comparison itself says why
        return False


def _check_same_start(ref: Trajectories, pred: Trajectories, i_ref: int, i_pred: int) -> None:
    """Open risers: the particles present at the window's first frame must be the same on
    both sides (the prediction started from the reference's state); newcomers may differ
    (:func:`starting_tracers`)."""
    starting_tracers(ref, pred, i_ref, i_pred)


def starting_tracers(ref: Trajectories, pred: Trajectories, i_ref: int, i_pred: int
                     ) -> np.ndarray | None:
    """Open risers: the tracers of the mixing curves, the particles present at the window's
    first frame on both sides.

    A prediction starts from the reference's frame, so both sides hold the same particles
    there; a model with memory leaves out those that entered within its memory before that
    frame (they have no state yet; its newcomers of the next lags stand for them), and the
    tracers are then the particles the prediction started.

    Parameters
    ----------
    ref, pred : Trajectories
        Open files of an open riser.
    i_ref, i_pred : int
        The window's first frame in each.

    Returns
    -------
    ndarray of int64 or None
        The tracers' ids where the prediction started fewer particles than the reference
        holds; None where both hold the same.

    Raises
    ------
    InputError
        Where the prediction's particles at its start are not all the reference's.
    """
    a = np.sort(ref.ids[ref.present(i_ref)])
    b = np.sort(pred.ids[pred.present(i_pred)])
    if np.array_equal(a, b):
        return None
    if b.size and b.size < a.size and np.isin(b, a).all():
        return b
    first = float(pred.times[0]) if pred.n_frames else float("nan")
    started = (pred.parameters.get("initial_frames")
               if isinstance(pred.parameters, dict) else None)
    at_start = i_pred == 0
    if at_start:       # the prediction's own first frame: it started from another file
        fix = (f"{pred.path} was predicted from {started}: give that as the reference"
               if isinstance(started, str) and started else
               f"give the run {pred.path} was predicted from as the reference")
    else:
        fix = (f"start the window at the prediction's first frame ({first:g} s), where it "
               "holds the reference's particles")
    raise InputError(f"{ref.path} ({a.size} particles present at the window start) and "
                     f"{pred.path} ({b.size}) do not start from the same particles; mixing "
                     f"needs the same tracers on both sides: {fix}")


__all__ = ["check_bins", "check_common_window", "check_order", "check_parameters",
           "check_runs", "check_window", "common_span", "default_bin_width", "model_columns",
           "rtd_bin_count", "spans_text", "starting_tracers"]
