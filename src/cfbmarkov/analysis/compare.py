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

from cfbmarkov._outputs import PREDICTION_SOURCE
from cfbmarkov._repr import compact_repr
from cfbmarkov.analysis.baseline import (WindowDifference, fitting_runs_of, fitting_window,
                                         model_on_fitting_window, pooled_window_difference,
                                         window_difference)
from cfbmarkov.analysis.compare_inputs import (check_bins, check_parameters, check_runs,
                                               common_span, default_bin_width, grid_parameter,
                                               model_flow_direction, starting_tracers)
from cfbmarkov.analysis.mixing import left_tracer_group, mixing_curve_of
from cfbmarkov.analysis.stationarity import long_run_baseline
from cfbmarkov.errors import InputError
from cfbmarkov.observed.clusters import cluster_index
from cfbmarkov.observed.metrics import (ROUNDOFF, minkowski_distance, mixing_rms,
                                        percentage_difference, rtd_span)
from cfbmarkov.observed.residence import (DEFAULT_FACE_ROWS, WHOLE_FRAMES, ResidenceTimes,
                                          net_flow_direction, residence_times, rtd_histogram)
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import TIME_TOLERANCE, time_text


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
    mixing_tracers : numpy.ndarray of int64, shape (T,), or None
        The tracers present at each frame of the mixing curve (an open riser's leave).
    """

    __repr__ = compact_repr   # arrays by their shape: a notebook's echo stays short

    traj: Trajectories
    frames: slice
    residence: ResidenceTimes
    rtd: np.ndarray
    mixing_times: np.ndarray
    mixing_fraction: np.ndarray
    left_group: np.ndarray
    mixing_tracers: np.ndarray | None = None

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
    bin_width_from : str
        Where the bin width comes from: ``given``, ``the model's lag``, or a file's frame
        interval (:func:`~cfbmarkov.analysis.compare_inputs.default_bin_width`).
    edges : numpy.ndarray, shape (B + 1,)
        RTD bin edges, s, from 0 to the window length.
    reference, model : ComparedRun
        The two sides.
    md_rtd : float
        Minkowski distance of the RTDs (NaN when either side has no sample in range).
    mixing_rms : float
        RMS difference of the mixing curves on the model's frames (fraction of all
        particles).
    mixing_frames : int
        The model's frames the mixing RMS compared (both curves defined; on an open riser,
        a tracer left on each side: :func:`mixing_weights`).
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
        as the prediction (a pooled model's: the RTD of its runs' windows pooled, where
        they can be read; None where the fitting window is unknown or outside the
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
        The direction residences are counted in: the model's (its fitting window's net
        solids flow, :attr:`MarkovModel.flow_direction
        <cfbmarkov.markov.model.MarkovModel.flow_direction>`) where the prediction records
        it, else down where the reference's net solids flow over the window is downward.
    cluster : dict or None
        The cluster index of each side's snapshots (mean and SD over the window's frames,
        :func:`cfbmarkov.observed.clusters.cluster_index`) and the grid it was counted on.
    """

    __repr__ = compact_repr

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
    mixing_frames: int = 0
    bin_width_from: str = "given"

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
            ``pd_rt_sd`` (%), ``md_rtd`` and ``md_order`` (``"inf"`` for the maximum norm),
            ``mixing_rms`` (fraction of all particles), the RTD bins (s), the source of the
            pass times, the mixing frames, the tracer-group check, the model's columns and
            the units. Undefined values are
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
            # strict JSON has no infinity: the maximum norm's order is written "inf"
            "md_order": float(self.md_order) if math.isfinite(self.md_order) else "inf",
            "mixing_rms": self.mixing_rms,
            "bin_width": float(self.bin_width),
            "bin_width_from": self.bin_width_from,
            "rtd_bins": {"from": 0.0, "to": float(self.edges[-1]),
                         "count": int(self.edges.size - 1)},
            "exact_events": {"reference": ref.exact, "model": mod.exact},
            "mixing_frames": int(self.mixing_frames),
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
            "units": {"time": "s", "pd": "%",
                      "flow_sd": "s (intervals.flow_sd: SD of E(RT) and SD(RT) between "
                                 "windows, not relative)",
                      "mixing_rms": ("fraction of the tracers still present"
                                     if self.reference.traj.boundary.is_open
                                     else "fraction of all particles")},
        }


#: the time bases of a comparison's residence times
BASES = ("frames", "events")


def compare_runs(ref, pred, window, *, bin_width: float | None = None,
                 md_order: float = 2.0, basis: str = "frames",
                 long_run_span: tuple[float, float] | None = None,
                 allow_empty: bool = False) -> RunComparison:
    """Compare a model's trajectories with a reference over a window.

    Parameters
    ----------
    ref, pred : Trajectories, str or os.PathLike
        Reference (e.g. CFD-DEM) and model (e.g. prediction) files, open or by path: the
        same riser and the same particle ids.
    window : (float, float)
        Analysis window (start, stop), s.
    bin_width : float, optional
        RTD bin width, s (bins from 0 to the window length); default the model's lag, as
        ``reproduce`` bins (:func:`~cfbmarkov.analysis.compare_inputs.default_bin_width`).
    md_order : float, optional
        Order k >= 1 of the Minkowski distance (``inf``: largest difference).
    basis : {"frames", "events"}, optional
        ``frames`` (default): like for like, both sides' residence times from frames at the
        model's lag (the prediction's frame interval), the reference's exact-event figures
        reported beside; ``events``: the reference's exact pass events (a reference
        without them is refused).
    long_run_span : (float, float), optional
        A span of the reference (s) whose other whole windows of the analysis window's
        length, pooled, stand beside the model as what a perfect stationary model would
        predict (:func:`cfbmarkov.analysis.stationarity.long_run_baseline`); default none.
    allow_empty : bool, optional
        Keep a side without a complete residence in the window (its E(RT), SD(RT), PD and
        MD NaN, with a warning) instead of refusing it; an open riser's reference without
        one is refused all the same. Default False: refused (what ``cfbmarkov compare``
        does; ``reproduce`` keeps them, its Table 3 says "no residences").

    Returns
    -------
    RunComparison

    Raises
    ------
    InputError
        For unusable parameters, a reference that is a Markov prediction against a run (the
        two swapped), a model with an odd column count (mixing by halves is undefined),
        different riser domains (size, 2D against 3D, or depth), different particle ids, a
        side without a complete residence in the window (unless ``allow_empty``), bins
        that put all the reference's residences in one bin (their MD could not tell RTDs
        apart), a long-run span outside the reference or without another whole window, or
        the ``events`` basis on a reference without exact pass events.

    References
    ----------
    docs/definitions.md, sections "residence time" and "mixing": PD = 100 (MCM - CFD-DEM) /
    CFD-DEM (Table 3), MD = (sum_j |e_j - f_j|^k)^(1/k) on the RTD probabilities per bin
    (Eq. 9), mixing curves of Fig. 11.
    The paper: Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614.
    """
    if not isinstance(ref, Trajectories) or not isinstance(pred, Trajectories):
        from cfbmarkov.trajectories import opened

        with opened(ref) as ref_run, opened(pred) as pred_run:
            return compare_runs(ref_run, pred_run, window, bin_width=bin_width,
                                md_order=md_order, basis=basis, long_run_span=long_run_span,
                                allow_empty=allow_empty)
    start, stop = check_parameters(window, bin_width, md_order)
    bin_width_from = "given"
    if bin_width is None:
        bin_width, bin_width_from = default_bin_width(ref, pred)
        check_bins((start, stop), bin_width, bin_width_from)
    ref_frames, pred_frames, columns = check_runs(ref, pred, start, stop)
    warnings: list[str] = []
    if ref.source == PREDICTION_SOURCE and pred.source == PREDICTION_SOURCE:
        warnings.append(f"the reference {ref.path} is itself a Markov prediction: the figures "
                        "compare two models, not a model against the flow; give a run (a "
                        "CFD-DEM run or an imported file) as the reference to judge a model")
    on = _residence_basis(ref, pred, (start, stop), basis, warnings)
    if bin_width_from == "given":
        _check_given_bins(ref, pred, bin_width, on, warnings)
    # residence times (an open riser: entries and exits within one cell of the faces), on
    # one time basis: frames at the model's lag, or the reference's exact events
    rt_ref = residence_times(ref, (start, stop), use_events=on.events,
                             face_band=reading_band(ref, on.band), lag_frames=on.lag_frames,
                             direction=on.direction)
    rt_mod = residence_times(pred, (start, stop), use_events=on.events,
                             face_band=reading_band(pred, on.band), direction=on.direction)
    for side, traj, rt in (("reference", ref, rt_ref), ("model", pred, rt_mod)):
        if rt.count == 0 and (not allow_empty or (side == "reference" and ref.boundary.is_open)):
            _refuse_empty(ref, pred, side, traj, (start, stop), on)
    if ref.boundary.is_open and not on.events and ref.source != PREDICTION_SOURCE:
        # tracks that end (begin) away from the faces at the model's lag are censored, not
        # residences: many of them (fast particles a lag's travel below the outlet) bias
        # the reference's RTD, as fit warns of its window
        from cfbmarkov.analysis.stationarity import face_band_warning
        from cfbmarkov.markov.open_flow import CENSORED_SHARE

        line = face_band_warning(ref, (start, stop), on.band, on.lag_frames,
                                 fix="their residences are left out (tracks that begin or end "
                                 "in mid-riser: out of view, or a section's faces), as fit "
                                 "leaves them out of its window; a model of taller cells "
                                 "keeps those that cross the faces farther than a cell from "
                                 "where they were last seen",
                                 limit=CENSORED_SHARE)
        if line:
            warnings.append(f"the reference: {line}")
    _check_bins_resolve(rt_ref, bin_width, bin_width_from, (start, stop))
    beside = _baselines(ref, pred, (start, stop), on, bin_width=bin_width, md_order=md_order,
                        long_run_span=long_run_span)
    warnings += [*beside.notes, *_fitting_window_warnings(ref, pred, (start, stop),
                                                          beside.baseline)]
    tracers = None
    if ref.boundary.is_open:
        tracers = starting_tracers(ref, pred, ref_frames.start, pred_frames.start)
        if tracers is not None:
            held = int(ref.present(ref_frames.start).sum())
            warnings.append(f"the prediction started {tracers.size} of the {held} particles "
                            f"present at {start:g} s in {ref.path} (the others entered within "
                            "its state space's memory and have no state yet; its newcomers "
                            "stand for them): the mixing curves follow those it started, on "
                            "both sides")
    edges, reference = _compared_run(ref, ref_frames, rt_ref, (start, stop), bin_width,
                                     tracers)
    _, model = _compared_run(pred, pred_frames, rt_mod, (start, stop), bin_width, tracers)
    comparison = _assemble(reference, model, edges, (start, stop), bin_width, md_order,
                           columns, warnings, on, beside)
    comparison.bin_width_from = bin_width_from
    return comparison


def _fitting_window_warnings(ref: Trajectories, pred: Trajectories,
                             window: tuple[float, float],
                             baseline: WindowDifference | None) -> list[str]:
    """Lines about the model's fitting window(s) beside the compared one: a compared window
    that overlaps a fitting window on the run it was taken from (the reference holds that
    window's content, :func:`cfbmarkov.trajectory_identity.window_identity`; a pooled
    model's runs each), which judges the fit rather than a prediction; and a persistence
    baseline whose window (any of a pooled model's) is of another length than the compared
    one (a window sees residences up to its own length, so the two RTDs are not alike even
    for a steady flow)."""
    from cfbmarkov.trajectory_identity import same_window

    runs = fitting_runs_of(pred)
    fitted = fitting_window(pred)
    windows = [w for _, w in runs] if runs is not None else [fitted] if fitted else []
    if not windows:
        return []
    start, stop = window
    tol = max(ref.time_tolerance, pred.time_tolerance)
    lines = []
    group = pred.group("model")
    identity = group.attrs.get("source_identity") if group is not None else None
    if isinstance(identity, bytes):
        identity = identity.decode()
    identities = identity.split(";") if isinstance(identity, str) else []
    for k, (w, recorded) in enumerate(zip(windows, identities)):
        if not (w[0] < stop - tol and start < w[1] - tol and w[0] >= ref.times[0] - tol
                and w[1] <= ref.times[-1] + tol):
            continue
        with contextlib.suppress(InputError):
            if same_window(ref, w, recorded):
                run = "" if runs is None else f" (run {k + 1} of {len(runs)} pooled)"
                lines.append(f"the compared window {start:g}-{stop:g} s overlaps the model's "
                             f"fitting window {w[0]:g}-{w[1]:g} s of this run{run}: the "
                             "model was fitted on these frames, so the comparison judges its "
                             "fit, not a prediction; compare a window after the fitting "
                             "window")
                break
    length = stop - start
    other = [w for w in windows if abs((w[1] - w[0]) - length) > max(tol, 1e-6 * length)]
    if baseline is not None and other:
        if runs is None:
            said = f"window {other[0][0]:g}-{other[0][1]:g} s is {other[0][1] - other[0][0]:g} s"
        else:
            lengths = sorted({round(w[1] - w[0], 9) for w in windows})
            said = ("windows (one per pooled run) are "
                    + " and ".join(f"{x:g}" for x in lengths) + " s")
        lines.append(f"the persistence baseline's {said} long and the compared one "
                     f"{length:g} s: a window sees residences up to its own length, so the "
                     "baseline's RTD is not like for like, nor is the model's own error on its "
                     "fitting window (model_on_fitting_window, the prediction's residences "
                     "against that window's), which carries the lengths' difference too; "
                     "fit on "
                     f"{'a window' if runs is None else 'windows'} as long as the compared "
                     "one for a fair baseline")
    return lines


def _refuse_empty(ref: Trajectories, pred: Trajectories, side: str, traj: Trajectories,
                  window: tuple[float, float], on: _Basis) -> None:
    """Refuse a side (``reference`` or ``model``, the file ``traj``) that holds no complete
    residence in the window, in one line saying what would give one: a model fitted where
    the flow runs as the reference's does (where the model's direction overrode it), else a
    longer window inside the span both files cover, or, where they overlap no longer than
    the window, a longer prediction."""
    start, stop = window
    first, last = common_span(ref, pred) or window
    tol = max(ref.time_tolerance, pred.time_tolerance)
    counted = f", counted {on.direction}ward" if on.direction == "down" else ""
    if on.direction != on.reference_flow:
        raise InputError(f"no residence begins and ends in {start:g}-{stop:g} s on the {side} "
                         f"side ({traj.path}), counted {on.direction}ward as the model counts, "
                         f"while the reference's net flow over the window runs "
                         f"{on.reference_flow}: compare with a model fitted where the flow runs "
                         f"{on.reference_flow}")
    if last - first > stop - start + tol:
        hint = (f"both files cover {time_text(first)} to {time_text(last)} s, e.g. --window "
                f"{time_text(first)}:{time_text(last)}")
    else:
        longer = ("predict a longer --duration" if pred.source == PREDICTION_SOURCE
                  else "give files that overlap longer")
        hint = f"both files cover only {time_text(first)} to {time_text(last)} s: {longer}"
    what = ("; in an open riser an entry through the inlet and the next exit through the "
            "outlet" if traj.boundary.is_open else "")
    raise InputError(f"no residence begins and ends in {start:g}-{stop:g} s on the {side} "
                     f"side ({traj.path}{what}{counted}): compare over a longer window ({hint})")


def _check_given_bins(ref: Trajectories, pred: Trajectories, bin_width: float, on,
                      warnings: list[str]) -> None:
    """Refuse a given RTD bin width narrower than the step of the residence times (on
    frames: the reference's frames at the model's lag, and the prediction's frames; on
    events: the prediction's frames), whose bins would only add empty ones and hide the
    few-bins warning; warn of one that is no whole number of that step (a comb)."""
    steps = [float(pred.frame_interval)]
    if not on.events:
        steps.append(float(ref.frame_interval) * on.lag_frames)
    steps = [x for x in steps if math.isfinite(x) and x > 0]
    if not steps:
        return
    step = max(steps)
    what = ("the model's lag and the reference's frames read at it" if not on.events
            else "the prediction's frames")
    if bin_width < step * (1.0 - 1e-9):
        raise InputError(f"--bin-width {bin_width:g} s is narrower than the residence times' "
                         f"step, {step:g} s ({what}): they are whole numbers of it, so "
                         "narrower bins only add empty ones (and hide the warning that the "
                         f"RTDs span few bins); give --bin-width {step:g} or more"
                         + (", or --basis events (the reference holds exact pass events)"
                            if ref.has_events and not on.events else ""))
    ratio = bin_width / step
    if abs(ratio - round(ratio)) > WHOLE_FRAMES:    # the rule a lag's whole frames keep
        low = math.floor(ratio) * step
        warnings.append(f"--bin-width {bin_width:g} s is no whole number of the residence "
                        f"times' step, {step:g} s ({what}): they fall {math.floor(ratio):d} "
                        f"or {math.ceil(ratio):d} to a bin, a comb in the binned RTDs and "
                        f"their MD; give a multiple of {step:g} s (e.g. {low:g} or "
                        f"{low + step:g})")


def _check_bins_resolve(rt_ref: ResidenceTimes, bin_width: float, source: str,
                        window: tuple[float, float]) -> None:
    """Refuse bins so wide that the reference's residences (two or more, of different
    lengths beyond round-off) fall in one but for a stray few: its RTD then spans one bin
    (:func:`~cfbmarkov.observed.metrics.rtd_span`: from its 1 % to its 99 % quantile), and
    every RTD held in that bin is at an MD near 0 from the reference's, the model's and the
    baselines' alike."""
    from cfbmarkov.observed.metrics import rtd_span

    if rt_ref.count < 2:
        return
    samples = np.asarray(rt_ref.samples, dtype=np.float64)
    spread = float(samples.max() - samples.min())
    _, p = rtd_histogram(samples, bin_width, window_length=window[1] - window[0])
    if spread <= 1e-6 * float(samples.max()) or rtd_span(p) >= 2:
        return          # residences of one length (to round-off), or over two bins or more
    one = np.count_nonzero(p) < 2
    low, high = np.quantile(samples, [0.01, 0.99])
    width = spread / 2 if one or not high > low else (high - low) / 2
    leave = ", or leave it out for the default width" if source == "given" else ""
    held = "all" if one else "98 % or more of the"
    raise InputError(f"{held} {rt_ref.count} residences of the reference in {window[0]:g}-"
                     f"{window[1]:g} s ({samples.min():.3g} to {samples.max():.3g} s long) "
                     f"fall in one RTD bin of {bin_width:g} s, where an MD cannot tell RTDs "
                     f"apart: give --bin-width {width:.2g} s or less{leave}")


@dataclass(frozen=True)
class _Basis:
    """The residence times' basis of a comparison: exact events or frames every
    ``lag_frames``-th of the reference, the face band (m), the direction residences are
    counted in and the reference's own net flow over the window."""

    name: str
    events: bool
    lag_frames: int
    band: float
    direction: str
    reference_flow: str = "up"


def _residence_basis(ref: Trajectories, pred: Trajectories, window: tuple[float, float],
                     basis: str, warnings: list[str]) -> _Basis:
    """The residence times' basis of both sides: the reference's frames per model lag (a
    warning where the lag is not a whole number of them), the face band of one cell row
    and the direction residences are counted in: the model's (its fitting window's net
    solids flow, recorded in the prediction's ``/provenance/model``; a warning where the
    reference's net flow over the window runs the other way), else the reference's."""
    if basis not in BASES:
        raise InputError(f"comparison basis {basis!r}: choose frames or events")
    if basis == "events" and not ref.has_events:
        raise InputError(f"{ref.path} holds no exact pass events: --basis events needs a "
                         "reference that logged them (cfbmarkov simulate writes them); "
                         "compare on --basis frames")
    rows = grid_parameter(pred, "rows") or DEFAULT_FACE_ROWS
    band = ref.height / float(rows)
    lag_frames = 1
    if basis == "frames":
        ratio = pred.frame_interval / ref.frame_interval
        if round(ratio) >= 1 and abs(ratio - round(ratio)) <= WHOLE_FRAMES:
            lag_frames = int(round(ratio))
        else:
            warnings.append(f"the model's lag {pred.frame_interval:g} s is not a whole number "
                            f"of the reference's frames ({ref.frame_interval:g} s): its "
                            "residence times use every frame")
    direction = reference_flow = net_flow_direction(ref, window)
    model_direction = model_flow_direction(pred)
    if model_direction is not None and model_direction != direction:
        warnings.append(f"the model counts residences {model_direction}ward (its fitting "
                        f"window's net solids flow runs {model_direction}) but the "
                        f"reference's net flow over the window runs {direction}: both sides "
                        f"are counted {model_direction}ward, as the model")
        direction = model_direction
    elif direction == "down":
        warnings.append("the solids' net flow over the window is downward: residence times "
                        "run from entries through the top to exits through the bottom")
    return _Basis(basis, basis == "events", lag_frames, band, direction, reference_flow)


@dataclass(frozen=True)
class _Beside:
    """What stands beside the model: the reference's exact-event residence times and the
    persistence, long-run and natural-variability baselines (None where not formed)."""

    exact_reference: ResidenceTimes | None
    baseline: WindowDifference | None
    long_run: WindowDifference | None
    variability: WindowDifference | None
    notes: tuple[str, ...] = ()


def _found_runs(pred, ref, pooled):
    """A pooled model's runs and windows (:func:`~cfbmarkov.analysis.baseline.
    fitting_runs_of`) with each run's file found as the intervals find it (from this
    folder, beside the prediction, or the reference itself:
    :func:`~cfbmarkov.analysis.intervals.resolve_source`); as recorded where they cannot
    be found (the baseline then says which is missing), None for a model of one run."""
    if pooled is None:
        return None
    import os

    from cfbmarkov.analysis.intervals import resolve_source
    from cfbmarkov.markov import MarkovModel

    try:
        model = MarkovModel.from_trajectories(pred)
        if model is None:
            return pooled
        model._cache.setdefault("file", os.path.abspath(pred.path))
        found = resolve_source(model, [ref.path]).source
    except InputError:
        return pooled
    if not isinstance(found, (list, tuple)) or len(found) != len(pooled):
        return pooled
    return [(str(path), window) for path, (_, window) in zip(found, pooled)]


def _baselines(ref: Trajectories, pred: Trajectories, window: tuple[float, float], on: _Basis,
               *, bin_width: float, md_order: float,
               long_run_span: tuple[float, float] | None) -> _Beside:
    """The reference's side of the baselines: its exact pass events (on the frames basis),
    its fitting window as the prediction (persistence), its long run over
    ``long_run_span`` and its first half against its second half."""
    start, stop = window
    exact_reference = None
    if not on.events and ref.has_events and not ref.boundary.is_open:
        exact_reference = residence_times(ref, (start, stop), use_events=True,
                                          direction=on.direction)
    basis_args = {"bin_width": bin_width, "md_order": md_order, "use_events": on.events,
                  "lag_frames": on.lag_frames, "face_band": on.band,
                  "window_length": stop - start, "direction": on.direction}
    baseline, unread = None, None
    fitted = fitting_window(pred)
    pooled = _found_runs(pred, ref, fitting_runs_of(pred))
    if pooled is not None:          # a pooled fit: its runs' windows pooled, as fitted
        try:
            baseline = pooled_window_difference(pooled, ref, (start, stop), **basis_args)
        except InputError as exc:
            unread = str(exc)
    inside = fitted is not None and fitted[0] >= ref.times[0] - ref.time_tolerance and (
        fitted[1] <= ref.times[-1] + ref.time_tolerance)
    unreadable = None
    if baseline is None and inside:
        try:
            baseline = window_difference(ref, fitted, (start, stop), **basis_args)
        except InputError as exc:                 # a window without residences, say
            unreadable = str(exc)
    notes = ()
    if unread is not None:
        instead = (f"the reference's own window {fitted[0]:g}-{fitted[1]:g} s instead (one "
                   "run's, not the model's pooled runs')" if baseline is not None else
                   "no persistence baseline")
        notes = (f"the persistence baseline could not pool the model's {len(pooled)} runs' "
                 f"fitting windows ({unread}): {instead}",)
    elif baseline is None and unreadable is not None:
        notes = (f"no persistence baseline: the reference's fitting window {fitted[0]:g}-"
                 f"{fitted[1]:g} s could not be read as one ({unreadable})",)
    elif baseline is None and fitted is not None and not inside:
        group = pred.group("model")
        source = group.attrs.get("source") if group is not None else None
        if isinstance(source, bytes):
            source = source.decode()
        with contextlib.suppress(ValueError, TypeError):
            source = json.loads(source)       # stored as JSON (a path, or a list of them)
        if isinstance(source, list):
            source = ", ".join(map(str, source))
        notes = (f"no persistence baseline: the model's fitting window {fitted[0]:g}-"
                 f"{fitted[1]:g} s does not lie in the reference's frames "
                 f"({float(ref.times[0]):g}-{float(ref.times[-1]):g} s)"
                 + (f", so the model was fitted on another run ({source})" if source else "")
                 + "; the baseline, the reference's RTD over the fitting window, needs that "
                 "window in the reference: compare against the run the model was fitted on "
                 "to have it",)
    long_run = None
    if long_run_span is not None:
        long_run = long_run_baseline(ref, (start, stop), span=long_run_span,
                                     option="--long-run-span", at_least=2,
                                     bin_width=bin_width, md_order=md_order,
                                     use_events=on.events, lag_frames=on.lag_frames,
                                     face_band=on.band, direction=on.direction)
    middle = 0.5 * (start + stop)
    variability = None
    with contextlib.suppress(InputError):
        variability = window_difference(ref, (start, middle), (middle, stop), **basis_args)
    return _Beside(exact_reference, baseline, long_run, variability, notes)


def _compared_run(traj: Trajectories, frames: slice, rt: ResidenceTimes,
                  window: tuple[float, float], bin_width: float, tracers=None
                  ) -> tuple[np.ndarray, ComparedRun]:
    """One side over the window: its RTD on bins of ``bin_width`` (and their edges), its
    mixing curve and its left tracer group (of an open riser: among the particles present
    at the window start, or the ids ``tracers`` among them)."""
    edges, rtd = rtd_histogram(rt.samples, bin_width, window_length=window[1] - window[0])
    times, fraction, present = mixing_curve_of(traj, window, tracers=tracers, counts=True)
    left = left_tracer_group(traj.positions(frames.start)[:, 0], 0.5 * traj.width)
    if traj.boundary.is_open:      # the tracers: the particles present at the window start
        left = left & traj.present(frames.start)
        if tracers is not None:
            left &= np.isin(traj.ids, tracers)
    return edges, ComparedRun(traj, frames, rt, rtd, times, fraction, left, present)


def mixing_weights(reference: ComparedRun, model: ComparedRun) -> np.ndarray | None:
    """The weight of each of the model's frames in the mixing RMS: None (equal weights)
    where every tracer stays (a periodic riser); on an open riser, where tracers leave and
    each curve is a fraction of those still present, the smaller of the two sides' tracer
    counts at that frame (the reference's at its frame nearest in time), so that the last
    frames, whose few tracers make the curves' noise, weigh as little as they tell
    (inverse-variance weighting of a fraction of n tracers; ``docs/definitions.md``,
    Mixing RMS).

    Parameters
    ----------
    reference, model : ComparedRun
        The two sides, with their ``mixing_tracers``.

    Returns
    -------
    ndarray of float64, shape (T,), or None
    """
    if reference.mixing_tracers is None or model.mixing_tracers is None:
        return None
    ref_count = np.asarray(reference.mixing_tracers, dtype=np.float64)
    mod_count = np.asarray(model.mixing_tracers, dtype=np.float64)
    if (np.all(ref_count == ref_count[0]) and np.all(mod_count == mod_count[0])
            and not (reference.traj.boundary.is_open or model.traj.boundary.is_open)):
        return None
    t_ref = np.asarray(reference.mixing_times, dtype=np.float64)
    nearest = np.clip(np.searchsorted(t_ref, model.mixing_times), 0, t_ref.size - 1)
    before = np.clip(nearest - 1, 0, t_ref.size - 1)
    closer = np.where(np.abs(t_ref[before] - model.mixing_times)
                      < np.abs(t_ref[nearest] - model.mixing_times), before, nearest)
    return np.minimum(mod_count, ref_count[closer])


def reading_band(traj, band: float | None) -> float | None:
    """The face band an open riser's file is read with: ``band`` (one cell of the model),
    or for a Markov prediction the whole height: its Monte Carlo has no other way in or
    out than the inlet and the outlet, so every appearance is an entry and every
    disappearance an exit (its newcomers are shown in their first state's cell, rows above
    the inlet's at a lag of many frames).

    Parameters
    ----------
    traj : Trajectories
        An open file (reference or prediction).
    band : float or None
        The band for a file of data (m).

    Returns
    -------
    float or None
    """
    if traj.boundary.is_open and traj.source == PREDICTION_SOURCE:
        return float(traj.height)
    return band


#: RTDs spanning fewer bins than this (1st to 99th percentile) are warned of as coarse
COARSE_SPAN = 10


def _assemble(reference: ComparedRun, model: ComparedRun, edges: np.ndarray,
              window: tuple[float, float], bin_width: float, md_order: float,
              columns: int | None, warnings: list[str], on: _Basis, beside: _Beside
              ) -> RunComparison:
    """The comparison of the two sides: MD of the RTDs, the model on its fitting window,
    mixing RMS, the tracer-group check, the cluster index and the warnings about them."""
    rt_ref, rt_mod = reference.residence, model.residence
    p_ref, p_mod = reference.rtd, model.rtd
    for name, rt in (("reference", rt_ref), ("model", rt_mod)):
        if rt.count < 2:
            warnings.append(f"{name}: {rt.count} residence-time sample(s) in the window; "
                            "E(RT), SD(RT) or the RTD are undefined (a longer window helps)")
    if p_ref.sum() > 0 and p_mod.sum() > 0:
        md = minkowski_distance(p_ref, p_mod, md_order)
        spans = {name: rtd_span(p) for name, p in (("reference", p_ref), ("model", p_mod))}
        if min(spans.values()) < COARSE_SPAN:
            warnings.append(
                f"the RTDs span only {spans['reference']} (reference) and {spans['model']} "
                f"(model) bins of {bin_width:g} s from their 1st to their 99th percentile: "
                f"below about {COARSE_SPAN}, MD and SD(RT) say little about the RTD's shape "
                "(a residence one bin off moves them much); a lag or --bin-width shorter "
                "against the residence times resolves them, where the frames allow")
    else:
        md = float("nan")
    on_fit = None
    if beside.baseline is not None:
        on_fit = model_on_fitting_window(rt_mod, p_mod, beside.baseline, bin_width=bin_width,
                                         md_order=md_order, window_length=window[1] - window[0])
    for what, value in (("E(RT)", rt_ref.mean), ("SD(RT)", rt_ref.sd)):
        if rt_ref.count >= 2 and abs(value) <= ROUNDOFF * abs(rt_ref.mean):
            warnings.append(f"the reference {what} is zero to round-off ({value:.3g} s): its "
                            "percentage difference is undefined (null; n/d in tables)")
    if rt_ref.exact != rt_mod.exact:
        warnings.append("residence times use exact pass events on one side and frame times "
                        "on the other")
    t_ref, f_ref = reference.mixing_times, reference.mixing_fraction
    t_mod, f_mod = model.mixing_times, model.mixing_fraction
    rms, compared = mixing_rms(t_ref, f_ref, t_mod, f_mod, mixing_weights(reference, model),
                               frames=True)
    if not np.isfinite(rms):
        ends = [f"{name} at {times[~np.isfinite(curve)][0]:g} s"
                for name, times, curve in (("reference", t_ref, f_ref), ("model", t_mod, f_mod))
                if not np.isfinite(curve).all()]
        warnings.append("the mixing curve is undefined where no tracer (a particle present at "
                        f"the window start) is left ({', '.join(ends)}): the mixing RMS is "
                        "undefined (null); a window that ends before that gives one")
    def flat(curve):     # where the tracers are there to say (an open riser's leave: NaN)
        known = curve[np.isfinite(curve)]
        return known.size > 0 and np.ptp(known) == 0

    if np.isfinite(rms) and flat(f_ref) and flat(f_mod):
        warnings.append(f"the mixing curves stay flat in both files (the tracers make no "
                        f"net crossing of the mid-plane x = W/2 over the window): the mixing "
                        f"RMS {rms:g} tests nothing; a longer window, or a flow whose "
                        "particles move across, gives it a meaning")
    ref, pred = reference.traj, model.traj
    left_ref, left_mod = reference.left_group, model.left_group
    if ref.boundary.is_open:
        same = bool(np.array_equal(np.sort(ref.ids[left_ref]), np.sort(pred.ids[left_mod])))
    else:
        same = bool(np.array_equal(left_ref[np.argsort(ref.ids)], left_mod[np.argsort(pred.ids)]))
    if not same:
        first = float(pred.times[model.frames.start])
        first_ref = float(ref.times[reference.frames.start])
        start = float(pred.times[0])
        if abs(first - first_ref) > TIME_TOLERANCE * max(abs(first), 1.0):
            # the two files' frames lie on other grids: their tracer groups are taken apart
            warnings.append(f"the window's first frames differ: the reference's at "
                            f"{first_ref:g} s, the prediction's at {first:g} s (its frames are "
                            f"{float(pred.frame_interval):g} s apart from {start:g} s), so "
                            "their tracer groups (x < W/2) and mixing curves start at "
                            "different times and disagree; start the window on a frame of "
                            f"both (--window {first:g}:... or {start:g}:...)")
        elif abs(first - start) > TIME_TOLERANCE * max(abs(start), 1.0):
            # the prediction carries the reference's state at its own start, not later
            warnings.append(f"the two files' first frames of the window (t = {first:g} s) "
                            "disagree on which particles are in the left tracer group (x < "
                            f"W/2): the window starts after the prediction's first frame "
                            f"({start:g} s), where it carries the reference's state, and the "
                            "particles have moved apart since; start the window there "
                            f"(--window {start:g}:...) for the mixing curves to start alike")
        else:
            warnings.append("the two files' first frames of the window disagree on which "
                            "particles are in the left tracer group (x < W/2): the prediction "
                            "did not start from the reference's state at the window start")
    return RunComparison(
        window=window, bin_width=float(bin_width), md_order=float(md_order), edges=edges,
        reference=reference, model=model,
        md_rtd=md, mixing_rms=rms, mixing_frames=compared, same_tracer_groups=same,
        model_columns=columns,
        warnings=warnings, basis=on.name, lag_frames=on.lag_frames,
        exact_reference=beside.exact_reference, baseline=beside.baseline,
        natural_variability=beside.variability, on_fitting_window=on_fit,
        long_run=beside.long_run, direction=on.direction,
        cluster=_clusters(ref, pred, reference.frames, model.frames, columns))


def _clusters(ref, pred, ref_frames: slice, pred_frames: slice, columns: int | None) -> dict:
    """Both sides' cluster index on the model's grid (else the paper's 6 x 38)."""
    columns, rows = (columns or 6), grid_parameter(pred, "rows") or DEFAULT_FACE_ROWS
    r_mean, r_sd = cluster_index(ref, ref_frames, columns, rows)
    m_mean, m_sd = cluster_index(pred, pred_frames, columns, rows)
    return {"grid": [columns, rows], "reference": {"mean": r_mean, "sd": r_sd},
            "model": {"mean": m_mean, "sd": m_sd}}


__all__ = ["BASES", "ComparedRun", "RunComparison", "compare_runs"]
