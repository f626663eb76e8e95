"""``cfbmarkov compare``: a model's trajectories against a reference (the paper's §3), drawn
and written.

Both sides are trajectory files (or open :class:`~cfbmarkov.trajectories.Trajectories`).
The numbers come from :func:`cfbmarkov.analysis.compare.compare_runs`: per side the
residence-time samples, their RTD on shared bins and the Minkowski distance of the two RTDs
(Eq. 9), the percentage differences of E(RT) and SD(RT) (Table 3), and the radial mixing
curves of the two tracer groups (Fig. 11) with the RMS of their difference. This module
writes the folder ``output`` whole (filled as a temporary sibling folder, renamed onto it
when complete): ``summary.json`` and, with ``figures``, the PNGs of Fig. 8-11 and, when the
prediction carries its model (``/provenance/model``), those of Fig. 3-7 too.

References
----------
docs/definitions.md, sections "residence time", "mixing" and "file formats".
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from cfbmarkov._atomic import atomic_folder
from cfbmarkov._outputs import refuse_foreign
from cfbmarkov._json import jsonable
from cfbmarkov.analysis.compare import RunComparison, compare_runs
from cfbmarkov.analysis.compare_inputs import check_parameters, model_columns
from cfbmarkov.analysis.figure_inputs import model_maps, snapshot_frames
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories, opened

SUMMARY = "summary.json"


def _open(source, stack: contextlib.ExitStack) -> Trajectories:
    return stack.enter_context(opened(source))


def _tracers(model, comparison: RunComparison, warnings: list[str]):
    """The particles' states at the window start in the model's state space and the left
    tracer group, for the mixing band: from the reference's frame (the frame a prediction
    starts from, with the history a state space with memory needs), else the prediction's
    first frame. None (with a warning) where neither can be discretised, the model's
    columns are odd or the prediction's frames are not whole lags apart."""
    from cfbmarkov.analysis.mixing import model_mixing_curve

    times = comparison.model.mixing_times
    lags = (times - times[0]) / model.lag
    if times.size == 0 or np.abs(lags - np.rint(lags)).max(initial=0.0) > 1e-3:
        warnings.append("no mixing interval: the prediction's frames are not whole lags of "
                        f"its model ({model.lag:g} s) apart")
        return None
    reasons = []
    for side in (comparison.reference, comparison.model):
        try:
            states, _, _ = model.initial_states(side.traj, float(side.traj.times[side.frames.start]))
            if states.shape != side.left_group.shape:
                raise InputError("the particle counts differ")
            model_mixing_curve(model, states, side.left_group, 0)     # checks the tracers
        except InputError as exc:
            reasons.append(f"{side.traj.path}: {exc}")
            continue
        return states, side.left_group
    warnings.append(f"no mixing interval: the tracers' states at {comparison.window[0]:g} s "
                    f"cannot be formed ({'; '.join(reasons)})")
    return None


def _intervals(pred, comparison: RunComparison, level: float, resamples: int,
               warnings: list[str], required: bool = False):
    """The prediction's intervals, or None (with a warning saying why) where they cannot be
    formed: no model attached, its fitting data unreadable or (unless ``required``) not
    found, too few residences. The mixing curve's band is left out (a warning says why)
    where the tracers' states cannot be formed (:func:`_tracers`)."""
    if not resamples:
        return None
    from cfbmarkov.analysis.intervals import SourceChanged, SourceMissing, prediction_intervals
    from cfbmarkov.markov import MarkovModel

    try:
        model = MarkovModel.from_trajectories(pred)
        if model is None:
            warnings.append("no intervals: the prediction carries no model")
            return None
        start, stop = comparison.window
        tracers = _tracers(model, comparison, warnings)
        mixing = None if tracers is None else (comparison.model.mixing_times,
                                               comparison.model.mixing_fraction)
        # the fitting file: as recorded, beside the prediction, or the reference itself
        model._cache.setdefault("file", os.path.abspath(pred.path))
        return prediction_intervals(model, comparison.model.residence.samples, comparison.edges,
                                    stop - start, level=level, resamples=resamples,
                                    direction=comparison.direction, mixing=mixing,
                                    tracers=tracers,
                                    candidates=[comparison.reference.traj.path],
                                    occupancy=_window_start(model, pred, comparison, start))
    except SourceChanged:
        raise
    except InputError as exc:
        if required and isinstance(exc, SourceMissing):
            raise           # the intervals were asked for: refused, not left out
        warnings.append(f"no intervals: {exc}")
        return None


def reference_sampling_intervals(samples, level: float):
    """The reference's own intervals of E(RT) and SD(RT): its window's residences' sampling
    alone, as though independent (mean +- z SD / sqrt(n), SD +- z SD sqrt((kurtosis - 1) /
    (4 n)), the delta method on the variance, which holds for the skewed, long-tailed
    RTDs of a riser where SD / sqrt(2 (n - 1)) holds only for normal samples; Kendall &
    Stuart, Vol. 1, 10.7; ``docs/definitions.md``, Intervals). `compare` judges with them
    where the model's intervals leave the reference window's sampling out (no flow term):
    a reference figure outside the model's interval whose own interval overlaps it is not
    told apart from the model's.

    Parameters
    ----------
    samples : ndarray of float64, shape (K,)
        The reference's residence times in the window (s).
    level : float
        Coverage, in (0, 1).

    Returns
    -------
    ((float, float), (float, float)) or None
        The intervals of E(RT) and SD(RT) (s, lower ends cut at 0); None for fewer than 2
        residences.
    """
    from scipy.special import ndtri

    from cfbmarkov.analysis.bootstrap import _sd_noise

    samples = np.asarray(samples, dtype=np.float64)
    n = samples.size
    if n < 2:
        return None
    z = float(ndtri(0.5 * (1.0 + level)))
    mean, sd = float(samples.mean()), float(samples.std(ddof=1))
    h_mean, h_sd = z * sd / np.sqrt(n), z * sd * np.sqrt(_sd_noise(samples))
    return ([max(mean - h_mean, 0.0), mean + h_mean], [max(sd - h_sd, 0.0), sd + h_sd])


def check_fitting_file(reference, prediction, required: bool = False) -> bool:
    """Refuse, before any work, a comparison whose intervals cannot use the model the
    prediction carries: its fitting file replaced since the fit or, where ``required``, not
    found (:func:`cfbmarkov.analysis.intervals.resolve_source`, with ``reference`` as a
    candidate). A prediction without a model passes.

    Parameters
    ----------
    reference, prediction : str or os.PathLike
        The comparison's trajectory files.
    required : bool, optional
        The intervals were asked for: a fitting file not found is refused too.

    Returns
    -------
    bool
        False where the model's fitting file was not found (the comparison then forms no
        model interval, and says so), else True.

    Raises
    ------
    InputError
        :class:`~cfbmarkov.analysis.intervals.SourceChanged`, or
        :class:`~cfbmarkov.analysis.intervals.SourceMissing` where ``required``.
    """
    from cfbmarkov.analysis.intervals import SourceMissing, resolve_source
    from cfbmarkov.markov import MarkovModel

    with opened(prediction) as pred:
        model = MarkovModel.from_trajectories(pred)
        if model is None:
            return True
        model._cache.setdefault("file", os.path.abspath(pred.path))
    try:
        resolve_source(model, [reference])
    except SourceMissing:
        if required:
            raise
        return False
    return True


def _carried_model(pred):
    """The model a prediction carries (None where it carries none, or one that cannot be
    read)."""
    from cfbmarkov.markov import MarkovModel

    try:
        return MarkovModel.from_trajectories(pred)
    except InputError:
        return None


def _model_exact(pred, comparison: RunComparison) -> dict | None:
    """The exact E(RT) and SD(RT) of the chain a prediction carries, over all its
    residences and as a window of the comparison's length sees them (the quantity the
    prediction's residences estimate, up to Monte Carlo noise); None where the prediction
    carries no model or its RTD cannot be formed.

    References
    ----------
    ``docs/definitions.md`` (RTD as a window sees it): the window counts the records of the
    lap counter from its first frame, the particles starting where the prediction's are
    (:func:`~cfbmarkov.markov.first_passage.window_rtd`).
    """
    from cfbmarkov.errors import CfbmarkovError
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.observed.metrics import percentage_difference

    try:
        model = MarkovModel.from_trajectories(pred)
        if model is None:
            return None
        # the frames the comparison counts residences on: a window given between frames
        # (15.01:19.99 s) holds those from 15.025 to 19.975 s, 4.95 s
        times = np.asarray(pred.times)
        tol = pred.time_tolerance
        inside = times[(times >= comparison.window[0] - tol)
                       & (times <= comparison.window[1] + tol)]
        first, length = ((float(inside[0]), float(inside[-1] - inside[0])) if inside.size
                         else (float(comparison.window[0]),
                               float(comparison.window[1] - comparison.window[0])))
        full = model.rtd(direction=comparison.direction)
        seen = model.rtd(window=length, direction=comparison.direction,
                         occupancy=_window_start(model, pred, comparison, first))
    except CfbmarkovError:
        return None
    reference = comparison.reference.residence
    return {"rt_mean": full.mean, "rt_sd": full.sd, "window_length": length,
            "windowed_rt_mean": seen.mean, "windowed_rt_sd": seen.sd,
            "pd_windowed_rt_mean": float(percentage_difference(seen.mean, reference.mean)),
            "pd_windowed_rt_sd": float(percentage_difference(seen.sd, reference.sd))}


def _window_start(model, pred, comparison: RunComparison, start: float):
    """Where the particles are at the compared window's start, per state of the model: the
    prediction's, or the reference's where the prediction's first frame lacks the history a
    state space with memory needs (a prediction starts from the reference's particles)."""
    from cfbmarkov.markov.model_rtd import occupancy_at

    found = occupancy_at(model, pred, start)
    return found if found is not None else occupancy_at(model, comparison.reference.traj,
                                                        start)


def _draw(comparison: RunComparison, out: Path, warnings: list[str]) -> list[str]:
    """Draw the figures of a comparison into ``out``; returns the file names written."""
    from cfbmarkov.report import figures as fg

    ref, mod = comparison.reference, comparison.model
    rt_ref, rt_mod = ref.residence, mod.residence
    start, stop = comparison.window
    labels = (f"{ref.traj.source} (reference)", f"{mod.traj.source} (model)")
    written: list[str] = []
    fg.plot_rtd(comparison.edges, ref.rtd, mod.rtd,
                {"mean": rt_ref.mean, "sd": rt_ref.sd, "count": rt_ref.count},
                {"mean": rt_mod.mean, "sd": rt_mod.sd, "count": rt_mod.count},
                out / "rtd.png", labels=labels,
                band=None if getattr(comparison, "intervals", None) is None
                else (comparison.intervals.rtd, comparison.intervals.level),
                title=f"Residence-time distribution, window {start:g}-{stop:g} s "
                      f"(bins {comparison.bin_width:g} s; MD = {comparison.md_rtd:.3g}, order "
                      f"{comparison.md_order:g})")
    written.append("rtd.png")
    snaps = snapshot_frames(ref.traj, mod.traj, start, stop)
    if snaps:
        fg.plot_snapshots(np.stack([ref.traj.positions(i) for _, i, _ in snaps]),
                          np.stack([mod.traj.positions(j) for _, _, j in snaps]),
                          ref.left_group, mod.left_group, [t for t, _, _ in snaps],
                          ref.traj.width, ref.traj.height, out / "snapshots.png", labels=labels)
        written.append("snapshots.png")
    else:
        warnings.append("snapshots skipped: no frame at the window start + 0, 0.1, ... "
                        "0.7 s on both sides")
    intervals = getattr(comparison, "intervals", None)
    fg.plot_mixing(ref.mixing_times, ref.mixing_fraction, mod.mixing_times, mod.mixing_fraction,
                   out / "mixing.png", labels=labels,
                   band=None if intervals is None or intervals.mixing is None
                   else (intervals.mixing_times, intervals.mixing, intervals.level),
                   well_mixed=ref.left_group_fraction ** 2,
                   open_riser=ref.traj.boundary.is_open,
                   title=f"Radial mixing from {start:g} s (RMS difference "
                         f"{comparison.mixing_rms:.3g})")
    written.append("mixing.png")
    maps = model_maps(mod.traj, rt_ref.mean, warnings)
    if maps is not None:
        fg.plot_transition_matrix(maps.transition_matrix, maps.columns, maps.rows,
                                  out / "transition_matrix.png", states=maps.states or None,
                                  row_of_state=maps.row_of_state)
        fg.plot_probability_maps(maps.maps, maps.times, mod.traj.width, mod.traj.height,
                                 out / "probability_maps.png",
                                 title=f"Batch fed over the inlet at t = 0\nmodel: "
                                       f"{maps.states or f'{maps.columns} x {maps.rows} cells'}"
                                       + (", summed over the depth" if maps.depth_columns > 1
                                          else "") + f", lag {maps.lag:g} s")
        written += ["transition_matrix.png", "probability_maps.png"]
    return written


def _check_interval_options(level, resamples) -> None:
    """Refuse what the command line refuses: resamples that are not a whole number, 0 or
    at least 10 (with enough for the level's tails), a level that is not a number in
    (0, 1). Without this a Python call had its intervals dropped with one line in the
    summary's warnings."""
    import numbers

    from cfbmarkov.analysis.bootstrap import check_interval_options

    if isinstance(resamples, bool) or not isinstance(resamples, numbers.Integral) \
            or resamples < 0:
        raise InputError(f"resamples {resamples!r}: a whole number, 0 (no intervals) or at "
                         "least 10")
    if resamples:
        check_interval_options(level, resamples)
    elif isinstance(level, (bool, str, bytes)) or not isinstance(level, numbers.Real) \
            or not 0.0 < float(level) < 1.0:
        raise InputError(f"interval level {level!r} must be a number strictly between 0 "
                         "and 1")


def compare(reference, prediction, *, window, output, bin_width: float | None = None,
            basis: str = "frames",
            level: float = 0.9, resamples: int = 100,
            md_order: float = 2.0, figures: bool = True,
            long_run_span: tuple[float, float] | None = None, kinetics=None,
            intervals_required: bool = False, allow_empty: bool = False,
            checked=None) -> dict[str, Any]:
    """Compare ``prediction`` (the model) with ``reference`` on a window; write the results.

    Parameters
    ----------
    reference, prediction : str, os.PathLike or Trajectories
        Trajectory files (e.g. CFD-DEM and a Markov chain prediction) of the same riser and
        particles.
    window : (float, float)
        Analysis window (start, stop), s.
    output : str or os.PathLike
        Output directory (created).
    bin_width : float, optional
        RTD bin width, s; default: the lag of the model attached to the prediction, else the
        reference's frame interval, else the prediction's
        (:func:`~cfbmarkov.analysis.compare_inputs.default_bin_width`); the summary's
        ``bin_width`` and ``bin_width_from`` say which.
    md_order : float, optional
        Order k of the Minkowski distance (Eq. 9).
    basis : {"frames", "events"}, optional
        The residence times' time basis (:func:`cfbmarkov.analysis.compare.compare_runs`):
        frames at the model's lag on both sides (default), or the reference's exact events.
    level : float, optional
        Coverage of the prediction's intervals (``docs/definitions.md``, Intervals).
    resamples : int, optional
        Bootstrap resamples of the model's fitting window for the intervals (0: none).
    intervals_required : bool, optional
        Refuse the comparison where the model's fitting file cannot be found
        (:class:`~cfbmarkov.analysis.intervals.SourceMissing`; nothing is written) instead
        of leaving the intervals out with a warning (default). The command line sets it
        where ``--resamples`` is given.
    long_run_span : (float, float), optional
        A span of the reference (s) whose other whole windows, pooled, give the summary's
        ``long_run`` block (what a perfect stationary model would predict; docs/definitions.md,
        Stationarity); default none (``long_run`` null).
    kinetics : str, os.PathLike or Kinetics, optional
        A kinetics file (or loaded kinetics): the summary's ``kinetics`` block, each
        property at the exit and in the bed for the reference, the model and the
        segregated-flow baseline (:func:`cfbmarkov.analysis.kinetics_compare.compare_kinetics`),
        and with ``figures`` the ``kinetics-NAME.png`` of each.
    figures : bool, optional
        Draw ``rtd.png``, ``snapshots.png``, ``mixing.png`` and, when the prediction carries
        its model, ``transition_matrix.png`` (a heat map) and ``probability_maps.png``.
    allow_empty : bool, optional
        Write a side without a complete residence in the window (its E(RT), SD(RT), PD and
        MD null, with a warning) instead of refusing it (default False: refused before
        anything is written; :func:`cfbmarkov.analysis.compare.compare_runs`).
    checked : callable, optional
        Called without arguments once both files and the parameters are checked and the
        residences counted, before the intervals, kinetics and figures (the command line's
        progress line: a refusal comes before it).

    Returns
    -------
    dict
        The summary (:meth:`cfbmarkov.analysis.compare.RunComparison.summary` plus
        ``figures`` and ``warnings``), undefined values as NaN; ``output/summary.json`` holds
        the same with null for them.

    Raises
    ------
    InputError
        For unusable parameters (a level outside (0, 1), resamples other than 0 or at
        least 10, as the command line refuses them) or files
        (:func:`cfbmarkov.analysis.compare.compare_runs`:
        among them a side without a complete residence in the window, bins too wide to tell
        RTDs apart, a prediction given as the reference of a run), an ``output`` that
        exists and is not a directory, a model's fitting file replaced since the fit
        (:class:`~cfbmarkov.analysis.intervals.SourceChanged`) or, with
        ``intervals_required``, not found; raised before ``output`` is written or replaced.

    References
    ----------
    docs/definitions.md, section "file formats" (summary.json keys);
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Table 3, Eq. 9 and Figs. 3-11.
    """
    check_parameters(window, bin_width, md_order)
    _check_interval_options(level, resamples)
    out = Path(output)
    if out.exists() and not out.is_dir():
        raise InputError(f"output {out} exists and is not a directory")
    _check_replaceable(out)     # before any work or line: a refusal stays one line
    if kinetics is not None and not hasattr(kinetics, "properties"):
        from cfbmarkov.kinetics import load_kinetics

        kinetics = load_kinetics(kinetics)      # a bad file: one line, before any work
    with contextlib.ExitStack() as stack:
        ref = _open(reference, stack)
        pred = _open(prediction, stack)
        if kinetics is not None:     # a refusal before the progress line: one line
            from cfbmarkov.analysis.kinetics_compare import check_kinetics_inputs

            check_kinetics_inputs(pred, kinetics)
        comparison = compare_runs(ref, pred, window, bin_width=bin_width, md_order=md_order,
                                  basis=basis, long_run_span=long_run_span,
                                  allow_empty=allow_empty)
        if checked is not None:
            checked()
        summary = comparison.summary()
        warnings = list(comparison.warnings)
        intervals = _intervals(pred, comparison, level, resamples, warnings,
                               required=intervals_required)
        carried = _carried_model(pred)
        adequacy = None if carried is None else carried.adequacy  # its fitting sample's verdict
        exact_model = _model_exact(pred, comparison)
        if exact_model is not None:
            summary["model"]["exact"] = exact_model
        if adequacy is not None:        # the verdict on the model's fitting sample, repeated
            summary["adequacy"] = adequacy.to_dict()
            warnings += [f"the model's fitting sample: {line}" for line in adequacy.warnings]
            from cfbmarkov.markov.model_summary import on_window_warning

            missed = on_window_warning(carried)
            if missed:                  # the chain misses its own fitting window
                warnings.append(f"the model: {missed}")
        if intervals is None:       # the keys scripts read, null: no interval was formed
            summary["level"] = None
            for key in ("rt_mean_interval", "rt_sd_interval", "rtd_interval"):
                summary["model"][key] = None
        else:
            summary["level"] = intervals.level
            summary["model"]["rt_mean_interval"] = list(intervals.rt_mean)
            summary["model"]["rt_sd_interval"] = list(intervals.rt_sd)
            summary["model"]["rtd_interval"] = intervals.rtd.tolist()
            if intervals.mixing is not None:
                summary["model"]["mixing_interval"] = {
                    "times": intervals.mixing_times.tolist(),
                    "lower": intervals.mixing[0].tolist(), "upper": intervals.mixing[1].tolist()}
            summary["model"]["model_rt_mean_interval"] = list(intervals.model_rt_mean)
            summary["model"]["model_rt_sd_interval"] = list(intervals.model_rt_sd)
            own = reference_sampling_intervals(comparison.reference.residence.samples,
                                               intervals.level)
            if own is not None:
                summary["reference"]["rt_mean_interval"], \
                    summary["reference"]["rt_sd_interval"] = own
            if intervals.flow is None:
                warnings.append("the intervals leave out the flow's variability between "
                                "windows: the fitting window is too short to show it (it "
                                "must hold two blocks, each three mean residence times long "
                                "and holding two residences or more); they are the model's "
                                "own")
            summary["intervals"] = {
                "resamples": intervals.resamples, "blocks": intervals.blocks,
                "bootstrap_widening": intervals.bootstrap_widening,
                "method": ("block bootstrap of the fitting window, Monte Carlo noise"
                           + (" and the flow's variability between windows"
                              if intervals.flow is not None else "") + ", in quadrature"),
                "flow_sd": None if intervals.flow is None else {
                    "rt_mean": intervals.flow[0], "rt_sd": intervals.flow[1],
                    "degrees_of_freedom": intervals.flow_degrees_of_freedom}}
        comparison.intervals = intervals
        kinetic = None
        if kinetics is not None:
            from cfbmarkov.analysis.kinetics_compare import compare_kinetics

            kinetic = compare_kinetics(ref, pred, comparison, kinetics, level=level,
                                       resamples=resamples, warnings=warnings)
            summary["kinetics"] = kinetic["summary"]
            from cfbmarkov.kinetics.fingerprint import kinetics_digest

            summary["kinetics_source"] = {"file": kinetics.source or None,
                                          "digest": kinetics_digest(kinetics)}
        _check_replaceable(out)
        with atomic_folder(out) as folder:    # published whole: figures and summary, or none
            summary["figures"] = _draw(comparison, folder, warnings) if figures else []
            if figures and kinetic is not None:
                from cfbmarkov.report.kinetics import plot_kinetics

                for name, drawn in kinetic["figures"].items():
                    file = f"kinetics-{name}.png"
                    plot_kinetics(drawn, name, folder / file, window=comparison.window)
                    summary["figures"].append(file)
            summary["warnings"] = warnings
            (folder / SUMMARY).write_text(json.dumps(jsonable(summary), indent=2,
                                                     allow_nan=False) + "\n")
    return summary


def is_comparison_file(entry: Path) -> bool:
    """Whether ``entry`` of a comparison's folder is one of its files (its summary or a
    PNG figure)."""
    return entry.is_file() and (entry.name == SUMMARY or entry.suffix == ".png")


def _check_replaceable(out: Path) -> None:
    """Refuse to replace a folder holding anything but a comparison's files (its summary
    and PNG figures): the new comparison replaces the folder whole."""
    refuse_foreign(out, is_comparison_file, "a comparison",
                   "replace it (give a new or empty folder)")


__all__ = ["SUMMARY", "check_fitting_file", "compare", "is_comparison_file", "model_columns"]
