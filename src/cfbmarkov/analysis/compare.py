"""A model's trajectories against a reference: the numbers of ``cfbmarkov compare``.

:func:`compare_runs` takes two open trajectory files and a window and computes, per side,
the residence-time samples (exact pass events where the file logged them), their RTD on
shared bins, the radial mixing curve and the left tracer group, and between the sides the
percentage differences of E(RT) and SD(RT) (the paper's Table 3), the Minkowski distance of
the RTDs (Eq. 9) and the RMS difference of the mixing curves. The result,
:class:`RunComparison`, turns into the ``summary.json`` of ``cfbmarkov compare`` with
:meth:`RunComparison.summary`; drawing and writing are left to
:mod:`cfbmarkov.report.compare`.

References
----------
docs/definitions.md, sections "residence time", "mixing" and "file formats" (summary.json).
"""

from __future__ import annotations

import contextlib
import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cfbmarkov.analysis.baseline import (WindowDifference, fitting_window,
                                         model_on_fitting_window, window_difference)
from cfbmarkov.observed.clusters import cluster_index
from cfbmarkov.observed.metrics import (ROUNDOFF, minkowski_distance, mixing_rms,
                                        percentage_difference, rtd_span)
from cfbmarkov.analysis.mixing import left_tracer_group, mixing_curve_of
from cfbmarkov.observed.residence import (DEFAULT_FACE_ROWS, ResidenceTimes, net_flow_direction,
                                    residence_times, rtd_histogram)
from cfbmarkov.analysis.stationarity import long_run_baseline
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories

#: snapshot offsets from the window start (s), as in the paper's Fig. 10
SNAPSHOT_OFFSETS = tuple(round(0.1 * k, 10) for k in range(8))


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
    try:
        start, stop = (float(v) for v in window)
    except (TypeError, ValueError):
        raise InputError(f"window {window!r} is not (start, stop) in seconds") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise InputError(f"window {start:g}:{stop:g} s is not finite")
    if not stop > start:
        raise InputError(f"window {start:g}:{stop:g} s is empty (the end must follow the start)")
    return start, stop


def check_parameters(window, bin_width: float, md_order: float) -> tuple[float, float]:
    """Check the parameters of a comparison.

    Parameters
    ----------
    window : sequence of two numbers
        Analysis window (start, stop), s.
    bin_width : float
        RTD bin width, s.
    md_order : float
        Order k of the Minkowski distance (Eq. 9).

    Returns
    -------
    (float, float)
        The window as (start, stop), s.

    Raises
    ------
    InputError
        For an unusable window (:func:`check_window`), a bin width (s) that is not finite
        and positive, or a Minkowski order that is not positive.
    """
    start, stop = check_window(window)
    if not (math.isfinite(bin_width) and bin_width > 0):
        raise InputError(f"RTD bin width {bin_width:g} s must be positive")
    from cfbmarkov.limits import MAX_BINS

    if (stop - start) / bin_width > MAX_BINS:
        raise InputError(f"RTD bin width {bin_width:g} s makes {(stop - start) / bin_width:.3g} "
                         f"bins over the window, more than {MAX_BINS}; give a larger --bin-width")
    if not md_order > 0:
        raise InputError(f"Minkowski order {md_order:g} must be positive")
    return start, stop


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
    columns = traj.parameters.get("columns") if isinstance(traj.parameters, dict) else None
    return None if columns is None else int(columns)


@dataclass
class ComparedRun:
    """One side of a comparison (the reference or the model) over the window.

    Attributes
    ----------
    traj : Trajectories
        The file (left open by the caller).
    frames : slice
        Frames of the window in the file.
    residence : ResidenceTimes
        Residence-time samples, s.
    rtd : numpy.ndarray, shape (B,)
        RTD as probability per bin (bins of :attr:`RunComparison.edges`).
    mixing_times, mixing_fraction : numpy.ndarray, shape (T,)
        The mixing curve: frame times (s) and the fraction of all particles that belong to
        the left tracer group and lie at x < W/2.
    left_group : numpy.ndarray of bool, shape (N,)
        The left tracer group (x < W/2 in the window's first frame), in the file's order.
    """

    traj: Trajectories
    frames: slice
    residence: ResidenceTimes
    rtd: np.ndarray
    mixing_times: np.ndarray
    mixing_fraction: np.ndarray
    left_group: np.ndarray

    @property
    def left_group_fraction(self) -> float:
        """The left tracer group's share of all particles at the window start (-)."""
        return float(self.mixing_fraction[0])

    def summary(self) -> dict[str, Any]:
        """This side's part of summary.json.

        Returns
        -------
        dict
            ``rt_mean`` and ``rt_sd`` (s), ``rt_count``, ``exact_events``, ``path``,
            ``source``, ``n_particles``, ``frames``, ``frame_interval`` (s),
            ``purple_fraction`` and ``left_group_fraction`` (the left tracer group's share,
            -), in the key order written.

        References
        ----------
        ``docs/definitions.md`` (File formats, Comparison summary).
        """
        rt, traj = self.residence, self.traj
        return {"rt_mean": rt.mean, "rt_sd": rt.sd, "rt_count": rt.count,
                "exact_events": rt.exact, "path": str(traj.path), "source": traj.source,
                "n_particles": traj.n_particles, "frames": self.frames.stop - self.frames.start,
                "frame_interval": traj.frame_interval,
                # the left tracer group's share; "purple_fraction" is its former name
                "purple_fraction": self.left_group_fraction,
                "left_group_fraction": self.left_group_fraction}


@dataclass
class RunComparison:
    """The numbers of a comparison of a model's trajectories with a reference.

    Attributes
    ----------
    window : (float, float)
        Analysis window (start, stop), s.
    bin_width : float
        RTD bin width, s.
    md_order : float
        Order k of the Minkowski distance.
    edges : numpy.ndarray, shape (B + 1,)
        RTD bin edges, s, from 0 to the window length.
    reference, model : ComparedRun
        The two sides.
    md_rtd : float
        Minkowski distance of the RTDs (NaN when either side has no sample in range).
    mixing_rms : float
        RMS difference of the mixing curves on the model's frames (fraction of all
        particles).
    same_tracer_groups : bool
        Whether both files put the same particles (by id) in the left tracer group.
    model_columns : int or None
        Cell columns of the model behind the prediction, when known.
    warnings : list of str
        Warnings of the computation (figures may add more).
    basis : str
        ``frames``: both sides' residence times from frames at the model's lag (the
        reference's frames taken every ``lag_frames``-th); ``events``: the reference's exact
        pass events where it has them (``docs/definitions.md``, Comparison basis).
    lag_frames : int
        Reference frames per model lag used on the ``frames`` basis.
    exact_reference : ResidenceTimes or None
        The reference's residence times from its exact pass events, reported beside the
        ``frames`` basis (None where it has none, or on the ``events`` basis).
    baseline : WindowDifference or None
        The persistence baseline: the reference's RTD in the model's fitting window taken
        as the prediction (None where the fitting window is unknown or outside the
        reference).
    natural_variability : WindowDifference or None
        The reference's first half of the window against its second half.
    on_fitting_window : WindowDifference or None
        The prediction's RTD against the reference's in the model's fitting window, the
        model's own error (:func:`cfbmarkov.analysis.baseline.model_on_fitting_window`);
        None where there is no baseline.
    long_run : WindowDifference or None
        The reference's RTD pooled over the other whole windows of a span, as the prediction
        of the window (:func:`cfbmarkov.analysis.stationarity.long_run_baseline`): what a
        perfect stationary model would predict. None unless a span was given.
    intervals : PredictionIntervals or None
        The prediction's intervals, set by the report where they can be formed
        (:mod:`cfbmarkov.analysis.intervals`).
    direction : {"up", "down"}
        The direction residences are counted in: down where the reference's net solids
        flow over the window is downward.
    cluster : dict or None
        The cluster index of each side's snapshots (mean and SD over the window's frames,
        :func:`cfbmarkov.observed.clusters.cluster_index`) and the grid it was counted on.
    """

    window: tuple[float, float]
    bin_width: float
    md_order: float
    edges: np.ndarray
    reference: ComparedRun
    model: ComparedRun
    md_rtd: float
    mixing_rms: float
    same_tracer_groups: bool
    model_columns: int | None
    warnings: list[str] = field(default_factory=list)
    basis: str = "events"
    lag_frames: int = 1
    exact_reference: ResidenceTimes | None = None
    baseline: WindowDifference | None = None
    natural_variability: WindowDifference | None = None
    on_fitting_window: WindowDifference | None = None
    long_run: WindowDifference | None = None
    intervals: Any = None
    direction: str = "up"
    cluster: dict | None = None

    @property
    def pd_rt_mean(self) -> float:
        """PD of E(RT), % (model against reference)."""
        return percentage_difference(self.model.residence.mean, self.reference.residence.mean)

    @property
    def pd_rt_sd(self) -> float:
        """PD of SD(RT), % (model against reference)."""
        return percentage_difference(self.model.residence.sd, self.reference.residence.sd,
                                     scale=self.reference.residence.mean)

    def summary(self) -> dict[str, Any]:
        """The summary as a dict, in the key order of summary.json.

        ``purple_fraction`` (per side) and ``same_purple_particles`` are the former names of
        ``left_group_fraction`` and ``same_tracer_groups`` and hold the same values.

        Returns
        -------
        dict
            Window (s), both sides (:meth:`ComparedRun.summary`), ``pd_rt_mean`` and
            ``pd_rt_sd`` (%), ``md_rtd`` and ``md_order``, ``mixing_rms`` (fraction of all
            particles), the RTD bins (s), the source of the pass times, the mixing frames,
            the tracer-group check, the model's columns and the units. Undefined values are
            NaN; the ``figures`` and ``warnings`` keys are added by the writer.

        References
        ----------
        ``docs/definitions.md`` (File formats, Comparison summary); the paper's Table 3.
        """
        ref, mod = self.reference.residence, self.model.residence
        start, stop = self.window
        return {
            "window": [start, stop],
            "reference": self.reference.summary(),
            "model": self.model.summary(),
            "pd_rt_mean": self.pd_rt_mean,
            "pd_rt_sd": self.pd_rt_sd,
            "md_rtd": self.md_rtd,
            "md_order": float(self.md_order),
            "mixing_rms": self.mixing_rms,
            "bin_width": float(self.bin_width),
            "rtd_bins": {"from": 0.0, "to": float(self.edges[-1]),
                         "count": int(self.edges.size - 1)},
            "exact_events": {"reference": ref.exact, "model": mod.exact},
            "mixing_frames": int(self.model.mixing_times.size),
            "same_purple_particles": bool(self.same_tracer_groups),
            "same_tracer_groups": bool(self.same_tracer_groups),
            "model_columns": self.model_columns,
            "basis": self.basis,
            "direction": self.direction,
            "cluster_index": self.cluster,
            "rtd_bins_spanned": {"reference": rtd_span(self.reference.rtd),
                                 "model": rtd_span(self.model.rtd)},
            "reference_frame_stride": int(self.lag_frames),
            "exact_reference": None if self.exact_reference is None else {
                "rt_mean": self.exact_reference.mean, "rt_sd": self.exact_reference.sd,
                "rt_count": self.exact_reference.count,
                "pd_rt_mean": percentage_difference(mod.mean, self.exact_reference.mean),
                "pd_rt_sd": percentage_difference(mod.sd, self.exact_reference.sd,
                                                  scale=self.exact_reference.mean)},
            "baseline": None if self.baseline is None else self.baseline.summary(),
            "natural_variability": (None if self.natural_variability is None
                                    else self.natural_variability.summary()),
            "model_on_fitting_window": (None if self.on_fitting_window is None
                                        else self.on_fitting_window.summary()),
            "long_run": None if self.long_run is None else self.long_run.summary(),
            "units": {"time": "s", "pd": "%", "mixing_rms": "fraction of all particles"},
        }


#: the time bases of a comparison's residence times
BASES = ("frames", "events")


def compare_runs(ref: Trajectories, pred: Trajectories, window, *, bin_width: float = 0.025,
                 md_order: float = 2.0, basis: str = "frames",
                 long_run_span: tuple[float, float] | None = None) -> RunComparison:
    """Compare a model's trajectories with a reference over a window.

    Parameters
    ----------
    ref, pred : Trajectories
        Open reference (e.g. CFD-DEM) and model (e.g. prediction) files: the same riser
        and the same particle ids.
    window : (float, float)
        Analysis window (start, stop), s.
    bin_width : float, optional
        RTD bin width, s (bins from 0 to the window length).
    md_order : float, optional
        Order k > 0 of the Minkowski distance (``inf``: largest difference).
    basis : {"frames", "events"}, optional
        ``frames`` (default): like for like, both sides' residence times from frames at the
        model's lag (the prediction's frame interval), the reference's exact-event figures
        reported beside; ``events``: the reference's exact pass events where it has them.
    long_run_span : (float, float), optional
        A span of the reference (s) whose other whole windows of the analysis window's
        length, pooled, stand beside the model as what a perfect stationary model would
        predict (:func:`cfbmarkov.analysis.stationarity.long_run_baseline`); default none.

    Returns
    -------
    RunComparison

    Raises
    ------
    InputError
        For unusable parameters, a model with an odd column count (mixing by halves is
        undefined), different riser domains (size, 2D against 3D, or depth), different
        particle ids, or a long-run span outside the reference or without another whole
        window.

    References
    ----------
    docs/definitions.md, sections "residence time" and "mixing": PD = 100 (MCM - CFD-DEM) /
    CFD-DEM (Table 3), MD = (sum_j |e_j - f_j|^k)^(1/k) on the RTD probabilities per bin
    (Eq. 9), mixing curves of Fig. 11.
    The paper: Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614.
    """
    start, stop = check_parameters(window, bin_width, md_order)
    for run in (ref, pred):
        run.require_supported("comparing runs", three_d=True, absent=run.boundary == "open",
                              open_boundary=True)
    if ref.boundary != pred.boundary:
        raise InputError(f"{ref.path} is a{'n open' if ref.boundary == 'open' else ' periodic'} "
                         f"riser and {pred.path} a{'n open' if pred.boundary == 'open' else ' periodic'}"
                         " one: compare runs of the same kind")
    warnings: list[str] = []
    ref_frames = ref.window(start, stop)
    pred_frames = pred.window(start, stop)
    columns = model_columns(pred)
    if columns is not None and columns % 2:
        raise InputError(f"{pred.path}: the model's state space has an odd column count "
                         f"({columns}): mixing by halves (x < W/2) is undefined")
    if not (np.isclose(ref.width, pred.width) and np.isclose(ref.height, pred.height)):
        raise InputError(f"domains differ: {ref.path} is {ref.width:g} x {ref.height:g} m, "
                         f"{pred.path} is {pred.width:g} x {pred.height:g} m")
    if ref.dimensions != pred.dimensions or (ref.depth is not None
                                             and not np.isclose(ref.depth, pred.depth)):
        raise InputError(f"domains differ: {ref.path} is {ref.dimensions}D"
                         + (f" ({ref.depth:g} m deep)" if ref.depth is not None else "")
                         + f", {pred.path} is {pred.dimensions}D"
                         + (f" ({pred.depth:g} m deep)" if pred.depth is not None else ""))
    if ref.boundary == "open":
        _check_same_start(ref, pred, ref_frames.start, pred_frames.start)
    elif ref.n_particles != pred.n_particles or not np.array_equal(np.sort(ref.ids),
                                                                    np.sort(pred.ids)):
        raise InputError(f"{ref.path} ({ref.n_particles} particles) and {pred.path} "
                         f"({pred.n_particles}) do not hold the same particle ids; mixing "
                         "needs the same particles on both sides")

    # residence times (an open riser: entries and exits within one cell of the faces), on
    # one time basis: frames at the model's lag, or the reference's exact events
    if basis not in BASES:
        raise InputError(f"comparison basis {basis!r}: choose frames or events")
    rows = pred.parameters.get("rows") or DEFAULT_FACE_ROWS
    band = ref.height / float(rows)
    lag_frames = 1
    if basis == "frames":
        ratio = pred.frame_interval / ref.frame_interval
        if round(ratio) >= 1 and abs(ratio - round(ratio)) <= 0.01 * ratio:
            lag_frames = int(round(ratio))
        else:
            warnings.append(f"the model's lag {pred.frame_interval:g} s is not a whole number "
                            f"of the reference's frames ({ref.frame_interval:g} s): its "
                            "residence times use every frame")
    events = basis == "events"
    direction = net_flow_direction(ref, (start, stop))
    if direction == "down":
        warnings.append("the solids' net flow over the window is downward: residence times "
                        "run from entries through the top to exits through the bottom")
    rt_ref = residence_times(ref, (start, stop), use_events=events, face_band=band,
                             lag_frames=lag_frames, direction=direction)
    rt_mod = residence_times(pred, (start, stop), use_events=events, face_band=band,
                             direction=direction)
    exact_reference = None
    if not events and ref.has_events and ref.boundary == "periodic":
        exact_reference = residence_times(ref, (start, stop), use_events=True,
                                          direction=direction)
    basis_args = {"bin_width": bin_width, "md_order": md_order, "use_events": events,
                  "lag_frames": lag_frames, "face_band": band, "window_length": stop - start,
                  "direction": direction}
    baseline = None
    fitted = fitting_window(pred)
    if fitted is not None and fitted[0] >= ref.times[0] - ref.time_tolerance and (
            fitted[1] <= ref.times[-1] + ref.time_tolerance):
        with contextlib.suppress(InputError):     # a window without frames: no baseline
            baseline = window_difference(ref, fitted, (start, stop), **basis_args)
    long_run = None
    if long_run_span is not None:
        long_run = long_run_baseline(ref, (start, stop), span=long_run_span,
                                     bin_width=bin_width, md_order=md_order,
                                     use_events=events, lag_frames=lag_frames, face_band=band,
                                     direction=direction)
    middle = 0.5 * (start + stop)
    variability = None
    with contextlib.suppress(InputError):
        variability = window_difference(ref, (start, middle), (middle, stop), **basis_args)
    if ref.boundary == "open" and rt_ref.count == 0:
        raise InputError(f"window {start:g}:{stop:g} s of {ref.path} holds no complete residence "
                         "(an entry through the inlet and the next exit through the outlet "
                         "inside the window): compare over a longer window")
    length = stop - start
    edges, p_ref = rtd_histogram(rt_ref.samples, bin_width, window_length=length)
    _, p_mod = rtd_histogram(rt_mod.samples, bin_width, window_length=length)
    for name, rt in (("reference", rt_ref), ("model", rt_mod)):
        if rt.count < 2:
            warnings.append(f"{name}: {rt.count} residence-time sample(s) in the window; "
                            "E(RT), SD(RT) or the RTD are undefined (a longer window helps)")
    if p_ref.sum() > 0 and p_mod.sum() > 0:
        md = minkowski_distance(p_ref, p_mod, md_order)
    else:
        md = float("nan")
    on_fit = None
    if baseline is not None:
        on_fit = model_on_fitting_window(rt_mod, p_mod, baseline, bin_width=bin_width,
                                         md_order=md_order, window_length=length)
    for what, value in (("E(RT)", rt_ref.mean), ("SD(RT)", rt_ref.sd)):
        if rt_ref.count >= 2 and abs(value) <= ROUNDOFF * abs(rt_ref.mean):
            warnings.append(f"the reference {what} is zero to round-off ({value:.3g} s): its "
                            "percentage difference is undefined (null; n/d in tables)")
    if rt_ref.exact != rt_mod.exact:
        warnings.append("residence times use exact pass events on one side and frame times "
                        "on the other")

    # mixing
    t_ref, f_ref = mixing_curve_of(ref, (start, stop))
    t_mod, f_mod = mixing_curve_of(pred, (start, stop))
    rms = mixing_rms(t_ref, f_ref, t_mod, f_mod)
    if not np.isfinite(rms):
        ends = [f"{name} at {times[~np.isfinite(curve)][0]:g} s"
                for name, times, curve in (("reference", t_ref, f_ref), ("model", t_mod, f_mod))
                if not np.isfinite(curve).all()]
        warnings.append("the mixing curve is undefined where no tracer (a particle present at "
                        f"the window start) is left ({', '.join(ends)}): the mixing RMS is "
                        "undefined (null); a window that ends before that gives one")
    left_ref = left_tracer_group(ref.positions(ref_frames.start)[:, 0], 0.5 * ref.width)
    left_mod = left_tracer_group(pred.positions(pred_frames.start)[:, 0], 0.5 * pred.width)
    if ref.boundary == "open":      # the tracers: the particles present at the window start
        left_ref = left_ref & ref.present(ref_frames.start)
        left_mod = left_mod & pred.present(pred_frames.start)
        same = bool(np.array_equal(np.sort(ref.ids[left_ref]), np.sort(pred.ids[left_mod])))
    else:
        same = bool(np.array_equal(left_ref[np.argsort(ref.ids)], left_mod[np.argsort(pred.ids)]))
    if not same:
        warnings.append("the two files' first frames of the window disagree on which "
                        "particles are in the left tracer group (x < W/2): the prediction did "
                        "not start from the reference's state at the window start")
    return RunComparison(
        window=(start, stop), bin_width=float(bin_width), md_order=float(md_order), edges=edges,
        reference=ComparedRun(ref, ref_frames, rt_ref, p_ref, t_ref, f_ref, left_ref),
        model=ComparedRun(pred, pred_frames, rt_mod, p_mod, t_mod, f_mod, left_mod),
        md_rtd=md, mixing_rms=rms, same_tracer_groups=same, model_columns=columns,
        warnings=warnings, basis=basis, lag_frames=lag_frames, exact_reference=exact_reference,
        baseline=baseline, natural_variability=variability, on_fitting_window=on_fit,
        long_run=long_run, direction=direction,
        cluster=_clusters(ref, pred, ref_frames, pred_frames, columns))


def _clusters(ref, pred, ref_frames: slice, pred_frames: slice, columns: int | None) -> dict:
    """Both sides' cluster index on the model's grid (else the paper's 6 x 38)."""
    rows = pred.parameters.get("rows") if isinstance(pred.parameters, dict) else None
    columns, rows = (columns or 6), int(rows or DEFAULT_FACE_ROWS)
    r_mean, r_sd = cluster_index(ref, ref_frames, columns, rows)
    m_mean, m_sd = cluster_index(pred, pred_frames, columns, rows)
    return {"grid": [columns, rows], "reference": {"mean": r_mean, "sd": r_sd},
            "model": {"mean": m_mean, "sd": m_sd}}


def _check_same_start(ref: Trajectories, pred: Trajectories, i_ref: int, i_pred: int) -> None:
    """Open risers: the particles present at the window's first frame must be the same on
    both sides (the prediction started from the reference's state); newcomers may differ."""
    a = np.sort(ref.ids[ref.present(i_ref)])
    b = np.sort(pred.ids[pred.present(i_pred)])
    if not np.array_equal(a, b):
        raise InputError(f"{ref.path} ({a.size} particles present at the window start) and "
                         f"{pred.path} ({b.size}) do not start from the same particles; mixing "
                         "needs the same tracers on both sides")


def snapshot_frames(ref: Trajectories, pred: Trajectories, start: float, stop: float
                    ) -> list[tuple[float, int, int]]:
    """Frames of the snapshots (the paper's Fig. 10).

    Parameters
    ----------
    ref, pred : Trajectories
        The two open files.
    start, stop : float
        The analysis window, s.

    Returns
    -------
    list of (float, int, int)
        (time s, frame index in ``ref``, frame index in ``pred``) at start + 0, 0.1, ...
        0.7 s inside the window, where both files have a frame.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 10.
    """
    chosen = []
    for offset in SNAPSHOT_OFFSETS:
        t = start + offset
        if t > stop + 1e-9 * max(1.0, abs(stop)):
            break
        try:
            chosen.append((t, ref.frame_index(t), pred.frame_index(t)))
        except InputError:
            continue
    return chosen


def map_times(reference_mean: float, lag: float) -> list[float]:
    """Times of the batch-injection maps of a comparison.

    Parameters
    ----------
    reference_mean : float
        E(RT) of the reference, s.
    lag : float
        The model's lag, s.

    Returns
    -------
    list of float
        About E(RT)/4, E(RT)/2 and 3 E(RT)/4 in whole lags (the paper's choice of 0.05-0.15 s
        or 0.25-0.75 s), s; 2, 4 and 6 lags when these do not give three distinct times.
    """
    if math.isfinite(reference_mean) and reference_mean > 0:
        steps = sorted({max(1, round(f * reference_mean / lag)) for f in (0.25, 0.5, 0.75)})
        if len(steps) == 3:
            return [k * lag for k in steps]
    return [k * lag for k in (2, 4, 6)]


@dataclass
class ModelMaps:
    """The model behind a prediction, as the figures of the paper's Fig. 3-7 need it.

    Attributes
    ----------
    transition_matrix : numpy.ndarray, shape (S, S)
        P_ij, the probability to go from state i to state j in one lag.
    columns, rows : int
        Cells across and along the riser.
    lag : float
        Lag, s.
    times : list of float
        Times of the batch-injection maps, s (:func:`map_times`).
    maps : numpy.ndarray, shape (len(times), rows, columns)
        Probability per cell of a batch fed evenly over the inlet at t = 0 (Eq. 8).
    """

    transition_matrix: np.ndarray
    columns: int
    rows: int
    lag: float
    times: list[float]
    maps: np.ndarray


def model_maps(pred: Trajectories, reference_mean: float, warnings: list[str]
               ) -> ModelMaps | None:
    """The transition matrix and batch-injection maps of the model carried by a prediction.

    Parameters
    ----------
    pred : Trajectories
        An open prediction file.
    reference_mean : float
        E(RT) of the reference, s (chooses the map times).
    warnings : list of str
        Receives a line when the model cannot be used.

    Returns
    -------
    ModelMaps or None
        None when the file carries no model (``/provenance/model``) or it cannot be used.
    """
    group = pred.group("model")
    if group is None:
        return None
    try:
        from cfbmarkov.markov import MarkovModel
    except ImportError as exc:
        warnings.append(f"model figures skipped: cfbmarkov.markov cannot be imported ({exc})")
        return None
    try:
        model = MarkovModel.from_group(group)
        P = np.asarray(model.transition_matrix, dtype=np.float64)
        columns, rows = int(model.state_space.columns), int(model.state_space.rows)
        lag = float(getattr(model, "lag", pred.frame_interval))
        times = map_times(reference_mean, lag)
        maps = np.asarray(model.batch_injection_maps(times), dtype=np.float64)
    except (InputError, AttributeError, KeyError, TypeError, ValueError) as exc:
        warnings.append(f"model figures skipped: the model of {pred.path} cannot be used "
                        f"({type(exc).__name__}: {exc})")
        return None
    return ModelMaps(P, columns, rows, lag, times, maps)


__all__ = ["ComparedRun", "ModelMaps", "RunComparison", "SNAPSHOT_OFFSETS", "check_parameters",
           "check_window", "compare_runs", "map_times", "model_columns", "model_maps",
           "snapshot_frames"]
