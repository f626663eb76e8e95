"""The verbs that analyse trajectory files and models: ``compare``, ``stationarity`` and
``maps``."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from cfbmarkov._names import one_line
from cfbmarkov.cli.options import (count, finite_float, level, minkowski_order, parse_cells,
                                   parse_times, parse_window, positive_float,
                                   relative_tolerance)
from cfbmarkov.errors import HistoryError, InputError


#: compare's bootstrap resamples where --resamples is not given
DEFAULT_RESAMPLES = 100


def _order_text(summary: dict) -> str:
    """`` (order P)`` after "MD" where the Minkowski order is not the default 2 (every MD
    the text prints is of that order), else nothing."""
    order = summary.get("md_order", 2)
    if order in (2, 2.0, "2"):
        return ""
    return f" (order {order:g})" if isinstance(order, (int, float)) else f" (order {order})"


def cmd_compare(args) -> int:
    """``cfbmarkov compare``: compare, then print the summary's figures and its file.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    import time

    from cfbmarkov.observed.metrics import percentage_text as pd_text
    from cfbmarkov.report.compare import compare

    started = time.perf_counter()
    from cfbmarkov.analysis.compare_inputs import check_not_same
    from cfbmarkov.trajectories import Trajectories

    with Trajectories(args.reference) as ref, Trajectories(args.prediction) as pred:
        check_not_same(ref, pred)
    # --resamples given: the intervals were asked for, and a fitting file not found refuses
    required = args.resamples is not None
    if required and 0 < args.resamples < 10:
        from cfbmarkov.cli.markov import _check_resamples

        _check_resamples(args.resamples)      # one line, as fit and rtd say it
    if args.resamples is None:
        args.resamples = DEFAULT_RESAMPLES
    if args.level is not None and not args.resamples and not args.kinetics:
        raise InputError(f"--level {args.level:g} sets the intervals' coverage, which "
                         "--resamples 0 leaves out (no interval is formed): leave out "
                         "--level or --resamples 0")
    args.level = 0.9 if args.level is None else args.level
    from cfbmarkov.cli.markov import _check_resamples

    _check_resamples(args.resamples, args.level)
    resampled = bool(args.resamples)
    if args.resamples:      # a refusal stays one line, before any other line
        from cfbmarkov.report.compare import check_fitting_file

        # a fitting file not found: no interval (a warning says so), nor resamples to announce
        resampled = check_fitting_file(args.reference, args.prediction, required)
    note = None
    if args.window is None:
        args.window, note = _default_window(args.reference, args.prediction)

    def checked() -> None:
        """The default window's note and the progress line, once the inputs are checked:
        a refusal stays one line."""
        if note is not None:
            print(note, file=sys.stderr, flush=True)
        if args.quiet:
            return
        a, b = args.window
        print(f"compare: {args.prediction} against {args.reference} over {a:g}-{b:g} s "
              f"(residence times, baselines, mixing"
              + (f", {args.resamples} bootstrap resamples for the intervals"
                 if resampled else "") + (", figures" if not args.no_figures else "")
              + ")", file=sys.stderr, flush=True)
    from cfbmarkov._console import heartbeat

    with heartbeat("" if args.quiet else "compare"):     # a line every 5 s of work
        summary = compare(args.reference, args.prediction, window=args.window,
                          output=args.output, bin_width=args.bin_width, md_order=args.md_order,
                          figures=not args.no_figures, basis=args.basis, level=args.level,
                          resamples=args.resamples, long_run_span=args.long_run_span,
                          kinetics=args.kinetics, intervals_required=required,
                          checked=checked)
    if not args.quiet:
        print(f"compare: done in {time.perf_counter() - started:.0f} s", file=sys.stderr,
              flush=True)
    for line in summary.get("warnings", []):
        print(f"warning: {one_line(line.strip())}", file=sys.stderr)
    print(f"E(RT) reference {summary['reference']['rt_mean']:.4g} s, model "
          f"{summary['model']['rt_mean']:.4g} s (PD {pd_text(summary['pd_rt_mean'])} %); "
          f"SD(RT) PD {pd_text(summary['pd_rt_sd'])} %; MD{_order_text(summary)} "
          f"{_number(summary['md_rtd'])}; "
          f"mixing RMS {_number(summary['mixing_rms'])}")
    exact_model = summary["model"].get("exact")
    if exact_model:
        print(f"  the model's exact E(RT) as a {exact_model['window_length']:g} s window sees "
              f"it: {exact_model['windowed_rt_mean']:.4g} s (PD "
              f"{pd_text(exact_model['pd_windowed_rt_mean'])} %; over all its residences "
              f"{exact_model['rt_mean']:.4g} s): what the prediction's residences estimate, "
              "up to its Monte Carlo noise")
    source = summary.get("bin_width_from", "given")
    counts = [summary[side].get("rt_count") for side in ("reference", "model")]
    print(f"  RTD bins {summary['bin_width']:g} s wide"
          + (" (--bin-width)" if source == "given" else f" ({source}; --bin-width to change)")
          + ("" if None in counts else
             f"; residences counted: reference {counts[0]}, model {counts[1]}"))
    baseline = summary.get("baseline")
    if baseline and baseline.get("md_rtd") is not None:
        import math

        halves = (summary.get("natural_variability") or {}).get("md_rtd")
        if summary["md_rtd"] is not None and math.isfinite(summary["md_rtd"]):
            print("  " + baseline_line(baseline, summary["md_rtd"], halves))
        else:       # no MD of the model's RTD (too few residences): nothing to judge
            print("  persistence baseline not judged: the model's MD is undefined in this "
                  "window")
    model = summary["model"]
    if model.get("rt_mean_interval"):
        (m0, m1), (s0, s1) = model["rt_mean_interval"], model["rt_sd_interval"]
        reference = summary["reference"]
        # rounded outwards, at the digits the verdict below prints the reference at
        dm = _digits(reference["rt_mean"], (m0, m1))
        ds = _digits(reference["rt_sd"], (s0, s1))
        with_flow = (summary.get("intervals") or {}).get("flow_sd") is not None
        own = ""
        if with_flow and "model_rt_mean_interval" in model:
            own = (f" (the model's own: E(RT) {_interval_text(model['model_rt_mean_interval'])}"
                   f" s, SD(RT) {_interval_text(model['model_rt_sd_interval'])} s)")
        kind = " with the flow's variability" if with_flow else ""
        print(f"  {100 * summary['level']:g} % intervals{kind}: E(RT) "
              f"{_interval_text((m0, m1), dm)} s, SD(RT) {_interval_text((s0, s1), ds)} s{own}")
        own_intervals = None
        if not with_flow and reference.get("rt_mean_interval"):
            own_intervals = (reference["rt_mean_interval"], reference["rt_sd_interval"])
        print("  " + interval_verdict(reference["rt_mean"], reference["rt_sd"],
                                      (m0, m1), (s0, s1), own_intervals, summary["level"]))
    exact = summary.get("exact_reference")
    if exact:
        print(f"  (residence times from frames at the model's lag on both sides; the reference's "
              f"exact pass events give E(RT) {exact['rt_mean']:.4g} s, PD "
              f"{pd_text(exact['pd_rt_mean'])} %, SD(RT) PD {pd_text(exact['pd_rt_sd'])} %)")
    long_run = summary.get("long_run")
    if long_run:
        (a, b), _ = long_run["windows"]
        print(f"  the reference's long run (its windows of {a:g}-{b:g} s but this one, pooled): PD E(RT) "
              f"{pd_text(long_run['pd_rt_mean'])} %, SD(RT) PD {pd_text(long_run['pd_rt_sd'])} "
              f"%, MD {_number(long_run['md_rtd'])} (what a perfect stationary model would "
              "predict)")
    _print_kinetics(summary.get("kinetics") or {}, summary.get("level") or args.level)
    print(Path(args.output) / "summary.json")
    return 0


def _number(value) -> str:
    """A figure at 4 significant digits; "n/d" where it is undefined (None or NaN)."""
    return "n/d" if value is None or not value == value else f"{value:.4g}"


def _default_window(reference: str, prediction: str) -> tuple[tuple[float, float], str]:
    """``compare`` without ``--window``: the span both files cover and the note that says
    so (printed once the inputs are checked); refused in one line naming both spans where
    they do not overlap, and before it where the files look swapped
    (:func:`~cfbmarkov.analysis.compare_inputs.check_order`)."""
    from cfbmarkov.analysis.compare_inputs import check_order, overlap_of
    from cfbmarkov.trajectories import Trajectories
    from cfbmarkov.trajectory_format import time_text

    with Trajectories(reference) as ref, Trajectories(prediction) as pred:
        check_order(ref, pred)
        (a, b), spans = overlap_of(ref, pred)
    return (a, b), (f"compare: no --window given: comparing over {time_text(a)}:"
                    f"{time_text(b)} s, the span both files cover ({spans})")


def _place(value: float, interval) -> str:
    """Where ``value`` lies against ``interval``: inside, below or above it."""
    lo, hi = interval
    return "inside" if lo <= value <= hi else "below" if value < lo else "above"


def _digits(value: float, interval) -> int:
    """Significant digits (4 or more) at which a value outside ``interval`` prints beyond
    the end it lies beyond, the value rounded to the nearest and the interval's ends
    outwards (:func:`~cfbmarkov.markov.uncertainty.outward_bounds`, as the interval is
    printed at these digits), so that "0.8855 lies above 0.8835-0.8855" or "0.8854 lies
    above 0.8801-0.8855" cannot be printed."""
    from cfbmarkov.markov.uncertainty import outward_bounds

    lo, hi = (float(v) for v in interval)
    digits = 4
    while digits < 12 and not lo <= value <= hi:
        lo_text, hi_text = outward_bounds(lo, hi, digits)
        shown = float(f"{value:.{digits}g}")
        if (value > hi and shown > float(hi_text)) or (value < lo and shown < float(lo_text)):
            break
        digits += 1
    return digits


def _interval_text(interval, digits: int = 4) -> str:
    """``lo-hi`` at ``digits`` significant digits rounded outwards."""
    from cfbmarkov.markov.uncertainty import outward_bounds

    return "-".join(outward_bounds(*(float(v) for v in interval), digits=digits))


def interval_verdict(rt_mean: float, rt_sd: float, mean_interval, sd_interval,
                     reference_intervals=None, level: float = 0.9) -> str:
    """One line saying whether the reference's E(RT) and SD(RT) lie inside the model's
    intervals, and what that means.

    Parameters
    ----------
    rt_mean, rt_sd : float
        The reference's E(RT) and SD(RT), s.
    mean_interval, sd_interval : (float, float)
        The model's intervals of E(RT) and SD(RT), s.
    reference_intervals : ((float, float), (float, float)), optional
        The reference's own intervals of E(RT) and SD(RT) (its residences' sampling), given
        where the model's intervals leave the reference window's sampling out (no flow
        term): a figure outside the model's interval whose own interval overlaps it is not
        told apart from the model's, as :func:`kinetics_interval_line` judges an exit mean.
    level : float, optional
        The intervals' level, for the text.

    Returns
    -------
    str
        ``the reference's E(RT) 0.7446 s lies below the model's interval, SD(RT) ...``.
    """
    from cfbmarkov.analysis.kinetics_compare import exit_mean_agreement

    places = [_place(rt_mean, mean_interval), _place(rt_sd, sd_interval)]
    names = ("E(RT)", "SD(RT)")
    # outside the model's interval, inside the reference's own: compare --kinetics's rule
    owns = reference_intervals if reference_intervals is not None else (None, None)
    apart = [exit_mean_agreement(float(value), list(model), own) == "not told apart"
             for value, model, own in zip((rt_mean, rt_sd), (mean_interval, sd_interval),
                                          owns)]
    dm, ds = _digits(rt_mean, mean_interval), _digits(rt_sd, sd_interval)
    text = (f"the reference's E(RT) {rt_mean:.{dm}g} s lies {places[0]} the model's interval, "
            f"its SD(RT) {rt_sd:.{ds}g} s {places[1]}")
    if places == ["inside", "inside"]:
        lo, hi = (float(v) for v in mean_interval)
        centre = 0.5 * (lo + hi)
        if centre > 0 and (hi - lo) / centre > 1.0:
            # an interval wider than its centre holds almost any value: no test of the model
            return text + (f": inside, but the model's E(RT) interval is "
                           f"{100 * (hi - lo) / centre:.0f} % of its centre wide, so this "
                           "says little; its fitting sample cannot pin the chain down (its "
                           "verdict says why)")
        return text + (": the model's E(RT) and SD(RT) are consistent with the reference's "
                       "within their uncertainty")
    missed = " and ".join(n for n, p, a in zip(names, places, apart) if p != "inside" and not a)
    if any(apart):
        owns = "; ".join(f"{n} {_interval_text(own, d)} s" for n, own, a, d in
                         zip(names, reference_intervals, apart, (dm, ds)) if a)
        told = (f"the reference's own {100 * level:g} % interval ({owns}; its residences' "
                "sampling, which the model's interval leaves out here) overlaps it")
        if not missed:
            return text + f", but {told}: the two are not told apart"
        return (text + f": the model misses the reference's {missed} beyond its uncertainty; "
                f"its {' and '.join(n for n, a in zip(names, apart) if a)} is not told "
                f"apart: {told}")
    return text + f": the model misses the reference's {missed} beyond its uncertainty"


def baseline_line(baseline: dict, md_model: float, md_halves: float | None = None) -> str:
    """One line setting the persistence baseline's MD beside the model's, judged by the
    report's rule (:func:`cfbmarkov.analysis.baseline.judge_baseline`: a gap within 1 % of
    the baseline's MD is a tie, one within the reference's own variability, the MD of its
    window's halves, cannot be told apart).

    Parameters
    ----------
    baseline : dict
        The summary's ``baseline`` block (``windows``: the window whose observed RTD is the
        baseline's prediction, then the judged one; ``md_rtd``; ``pd_rt_mean``).
    md_model : float
        The model's MD of the RTD.
    md_halves : float, optional
        The MD of the reference window's halves (``natural_variability.md_rtd``).

    Returns
    -------
    str
        The line; where either MD is undefined (None or NaN: a side without residences),
        one saying the baseline is not judged.
    """
    from cfbmarkov.analysis.baseline import judge_baseline
    from cfbmarkov.observed.metrics import percentage_text as pd_text

    (a, b), _ = baseline["windows"]
    runs = int(baseline.get("runs") or 1)
    of = (f"{a:g}-{b:g} s" if runs == 1 else
          f"the model's fitting windows in its {runs} runs, pooled as it was fitted,")
    md = baseline["md_rtd"]
    if not all(v is not None and math.isfinite(v) for v in (md, md_model)):
        return (f"persistence baseline (the observed RTD of {of} taken as the "
                "prediction): not judged, an MD is undefined (a side without residences)")
    judged = judge_baseline(md_model, md, md_halves)
    verdict = {"beats": "the model is closer", "loses": "the baseline is closer",
               "tie": "a tie (within 1 %)"}.get(judged.outcome)
    if verdict is None:
        verdict = (f"not told apart (the gap is within the reference's own variability, "
                   f"its halves' MD {judged.md_halves:.4g})")
    elif judged.outcome != "tie" and judged.md_halves is None:
        verdict += (" (judged against no measure of the reference's own variability, "
                    "only beyond a 1 % tie: the reference window's halves give none, as "
                    "where a half holds no residence in the window's direction)")
    return (f"persistence baseline (the observed RTD of {of} taken as the "
            f"prediction): MD {md:.4g} against the model's {md_model:.4g}, PD E(RT) "
            f"{pd_text(baseline.get('pd_rt_mean'))} %: {verdict}")


def _print_kinetics(block: dict, level: float = 0.9) -> None:
    """Lines per property of ``compare --kinetics``: the exit means of the three sides, the
    model's interval and whether the reference lies inside it, the bed's means."""
    from cfbmarkov.observed.metrics import percentage_text as pd_text

    def value(v):
        return "n/d" if v is None or not v == v else f"{v:.4g}"

    for name, entry in block.items():
        ref, mod, seg = entry["reference"], entry["model"], entry.get("segregated_flow")
        exact = mod.get("exact")
        if entry.get("window_note"):
            a, b = entry["window"]
            print(f"{name} over {a:g}-{b:g} s: {entry['window_note']}")
        line = (f"{name} at the exit: reference {value(ref['exit_mean'])} "
                f"({ref['exit_count']} exits), model {value(mod['exit_mean'])} (PD "
                f"{pd_text(mod['pd_exit_mean'])} %, MD {value(mod['md_exit'])}")
        if exact and exact.get("pd_exit_mean") is None and exact.get("note"):
            line += f"; exact steady state {value(exact['exit_mean'])} ({exact['note']})"
        elif exact:
            line += f"; exact {value(exact['exit_mean'])}, PD {pd_text(exact['pd_exit_mean'])} %"
            if exact.get("windowed_exit_mean") is not None:
                line += (f"; exact as the window sees it {value(exact['windowed_exit_mean'])}, "
                         f"PD {pd_text(exact['pd_windowed_exit_mean'])} %")
        line += ")"
        if seg:
            line += (f", segregated flow {value(seg['exit_mean'])} (PD "
                     f"{pd_text(seg['pd_exit_mean'])} %, MD {value(seg['md_exit'])})")
        elif entry.get("segregated_flow_note"):
            line += f", segregated flow: {entry['segregated_flow_note']}"
        else:
            line += ", segregated flow n/d"
        print(line)
        verdict = kinetics_verdict(name, ref["exit_mean"], mod, level,
                                   ref.get("exit_mean_interval"))
        if verdict:
            print("  " + verdict)
        print(f"  {name} in the bed: mean over the window, reference "
              f"{value(ref['bed_mean'])}, model {value(mod['bed_mean'])}"
              + (f"; segregated flow {value(seg['bed_mean'])} (its steady state over the "
                 "age distribution, where the window's means carry its start from the first "
                 "frame's values)" if seg else ""))


def kinetics_verdict(name: str, reference_mean: float, model: dict, level: float,
                     reference_interval=None) -> str:
    """One line: the model's interval of a property's exit mean and whether the
    reference's exit mean lies inside it.

    Parameters
    ----------
    name : str
        The property.
    reference_mean : float
        The reference's exit mean.
    model : dict
        The property's ``model`` block of ``summary.json`` (``exit_mean_interval``,
        ``interval_method``, ``interval_not_formed``).
    level : float
        The intervals' coverage.
    reference_interval : (float, float), optional
        The reference's own interval of its exit mean (its exits' sampling); a model
        interval that misses the reference's value but overlaps this one is not told apart.

    Returns
    -------
    str
        Empty where the model has no interval or the reference no exit mean.
    """
    from cfbmarkov.analysis.kinetics_compare import exit_mean_agreement

    interval = model.get("exit_mean_interval")
    agreement = exit_mean_agreement(reference_mean, interval, reference_interval)
    if agreement is None:
        return ""
    lo, hi = interval
    method = model.get("interval_method") or "Monte Carlo noise only"
    sampled = method.startswith("block bootstrap")
    flow = model.get("flow_sd") if sampled else None
    kind = ("the fitting window's bootstrap and Monte Carlo noise" if sampled
            else "Monte Carlo noise only")
    kind += ("; the flow's variability left out" if flow is None else
             f", with the flow's variability between windows (E(RT)'s "
             f"{100 * flow['rt_mean_relative']:.3g} %, as a stretch of every residence)")
    place = _place(reference_mean, (lo, hi))
    d = _digits(reference_mean, (lo, hi))
    text = (f"{100 * level:g} % interval of the model's exit mean {_interval_text((lo, hi), d)} "
            f"({kind}): the reference's {reference_mean:.{d}g} lies {place} it")
    if not sampled and agreement != "not told apart":
        # the fitting sample's uncertainty, most of it, is not in this interval
        why = model.get("interval_not_formed") or "`--resamples 100` forms it"
        return text + (": within the Monte Carlo noise" if agreement == "inside" else
                       ": beyond the Monte Carlo noise") + (
            f"; the fitting sample's uncertainty, the larger part, is not in this interval "
            f"({why}), so no verdict is drawn from it")
    if agreement == "inside":
        return text + ": the model is consistent with the reference within its uncertainty"
    if agreement == "not told apart":
        return text + (f", but the reference's own {100 * level:g} % interval "
                       f"{_interval_text(tuple(reference_interval), d)} (its exits' sampling) "
                       "overlaps it: the two are not told apart")
    return text + f": the model misses the reference's {name} beyond its uncertainty"


#: windows with fewer residences than this get a note in ``cfbmarkov stationarity``
FEW_RESIDENCES = 100


def cmd_stationarity(args) -> int:
    """``cfbmarkov stationarity``: the sliding windows (and the judged window) as a table, or
    as JSON with ``--json``.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    import json

    import numpy as np

    from cfbmarkov.analysis.stationarity import check_stationarity
    from cfbmarkov.observed.metrics import percentage_text as pd_text

    _check_stationarity_options(args)
    from cfbmarkov.trajectories import Trajectories

    for path in args.file:           # windows need frames, before any other word on them
        with Trajectories(path) as run:
            if run.n_frames < 2:
                raise InputError(f"{path} holds one frame: no frame interval, so no window "
                                 "of residences or transitions can be judged; import more "
                                 "frames of the run")
    if args.sample_length:
        return _sample_length(args)
    if len(args.file) > 1:
        raise InputError(f"{len(args.file)} runs: the sliding windows are of one run (several "
                         "runs pool only with --sample-length)")
    args.file = args.file[0]
    face_band = None
    if args.cells is not None:          # an open riser's face band: one cell of the rows
        from cfbmarkov.trajectories import Trajectories

        with Trajectories(args.file) as run:
            face_band = run.height / args.cells[-1]
    check = check_stationarity(args.file, window_length=args.window_length, step=args.step,
                               span=args.span, lag=args.lag, basis=args.basis,
                               judge=args.judge, face_band=face_band)
    for line in check.warnings:
        print(f"warning: {one_line(line)}", file=sys.stderr)
    if args.json:
        print(json.dumps(check.to_dict(), indent=1, allow_nan=False))
        return 0

    def value(v, spec=".4g"):
        return format(v, spec) if v is not None and np.isfinite(v) else "n/d"

    stats, bin_width = check.statistics, check.rtd_bin_width
    length = stats.window_length
    basis_text = ("exact pass events" if check.exact_events else f"frames every {bin_width:g} s")
    print(f"{args.file}: {stats.starts.size} windows of {length:g} s, {stats.step:g} s apart, "
          f"residence times from {basis_text}")
    flux = stats.flux_rt_mean
    print(f"{'window (s)':>13}  {'direction':>9}  {'E(RT) (s)':>9}  {'SD(RT) (s)':>10}  "
          f"{'residences':>10}" + ("" if flux is None else f"  {'flux E(RT) (s)':>14}"))
    for k, (a, m, sd, n, d) in enumerate(zip(stats.starts, stats.rt_mean, stats.rt_sd,
                                             stats.rt_count, stats.direction)):
        span_text = f"{a:g}-{a + length:g}"
        print(f"{span_text:>13}  {d:>9}  {value(m):>9}  {value(sd):>10}  {n:10d}"
              + ("" if flux is None else f"  {value(flux[k]):>14}"))
    print(f"E(RT) {value(stats.average_rt_mean)} s on average, relative SD "
          f"{value(100 * stats.relative_sd_rt_mean, '.1f')} %; SD(RT) "
          f"{value(stats.average_rt_sd)} s, relative SD "
          f"{value(100 * stats.relative_sd_rt_sd, '.1f')} % (the scatter of one {length:g} s "
          "window's residences about the run's average: a stationary prediction of a given "
          "window carries about as much)")
    if flux is not None:
        finite = flux[np.isfinite(flux)]
        if finite.size:
            print(f"flux E(RT) from {value(finite.min())} to {value(finite.max())} s (median "
                  f"{value(float(np.median(finite)))} s, relative SD "
                  f"{value(100 * stats.relative_sd_flux_rt_mean, '.1f')} %): the throughput a "
                  f"chain fitted on one {length:g} s window carries, so its E(RT) scatters "
                  "about as much from window to window")
        print(f"(E(RT), SD(RT): of the residences wholly inside each window, which leaves out "
              f"those longer than {length:g} s; flux E(RT): the window's particle-time over its "
              "net passes, the flow's mean residence time without that cut; "
              "docs/definitions.md, Long-run E(RT))")
    few = int(np.sum(stats.rt_count < FEW_RESIDENCES))
    if few:
        print(f"note: {few} of {stats.starts.size} windows hold fewer than {FEW_RESIDENCES} "
              "residences: their E(RT) and SD(RT), and the scatter, carry sampling noise (a "
              "longer --window-length)")
    if check.judged is not None:
        judged = check.judged
        j0, j1 = judged.window
        observed = judged.long_run.observed
        lr = judged.long_run.summary()
        pe = None if judged.persistence is None else judged.persistence.summary()
        print(f"judged window {j0:g}-{j1:g} s: E(RT) {value(observed.mean)} s, SD(RT) "
              f"{value(observed.sd)} s, {observed.count} residences")
        s0, s1 = lr["windows"][0]
        print(f"  the run's long run (its {j1 - j0:g} s windows of {s0:g}-{s1:g} s but this one, "
              f"pooled; what a perfect stationary model would predict): PD E(RT) "
              f"{pd_text(lr['pd_rt_mean'], '+.1f')} %, PD SD(RT) "
              f"{pd_text(lr['pd_rt_sd'], '+.1f')} %, MD {value(lr['md_rtd'], '.3f')}")
        others = int(round((s1 - s0) / (j1 - j0))) - 1    # the long run's windows
        if pe is not None and others == 1:
            print(f"  persistence (the {j0 - (j1 - j0):g}-{j0:g} s window): the long run's "
                  "one window, so the same figures (a longer span gives the long run more)")
        elif pe is not None:
            print(f"  persistence (the {j0 - (j1 - j0):g}-{j0:g} s window): PD E(RT) "
                  f"{pd_text(pe['pd_rt_mean'], '+.1f')} %, PD SD(RT) "
                  f"{pd_text(pe['pd_rt_sd'], '+.1f')} %, MD {value(pe['md_rtd'], '.3f')}")
        else:
            print(f"  persistence: no whole {j1 - j0:g} s window before {j0:g} s in the span")
    return 0


#: stationarity's options of each mode: the sliding windows' and --sample-length's
_SLIDING_ONLY = ("window_length", "step")
_SAMPLE_LENGTH_ONLY = ("start", "tolerance", "states", "estimator")
_STATIONARITY_DEFAULTS = {"window_length": 5.0, "step": 1.0, "tolerance": 0.1,
                          "states": "cells"}


def _option_names(names: list[str]) -> tuple[str, str]:
    """The options' command-line names joined, and the pronoun for them."""
    return (", ".join("--" + name.replace("_", "-") for name in names),
            "it" if len(names) == 1 else "them")


def _check_stationarity_options(args) -> None:
    """Refuse an option of the other mode (it would be ignored without a word), then fill
    in the defaults."""
    if args.sample_length:
        given = [name for name in _SLIDING_ONLY if getattr(args, name) is not None]
        if args.basis != "frames":
            given.append("basis")
        if given:
            names, it = _option_names(given)
            raise InputError(f"{names}: of the sliding windows, not of --sample-length (whose "
                             f"windows grow from --start); leave {it} out, or run without "
                             "--sample-length")
    else:
        given = [name for name in _SAMPLE_LENGTH_ONLY if getattr(args, name) is not None]
        if given:
            names, it = _option_names(given)
            raise InputError(f"{names}: of --sample-length only (the sliding windows fit no "
                             f"model); add --sample-length, or leave {it} out")
    for name, value in _STATIONARITY_DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    if args.sample_length and args.cells is None:
        args.cells = (6, 38)


def _sample_length(args) -> int:
    """``stationarity --sample-length``: models on growing windows against the long run."""
    import json

    import numpy as np

    from cfbmarkov.analysis.sample_length import missed_text, sample_length, verdict_text
    from cfbmarkov.markov import state_space_from_name
    from cfbmarkov.trajectories import Trajectories

    if args.judge is not None:
        raise InputError("--judge compares one window with the run's long run in the sliding "
                         "windows' table; --sample-length fits models on growing windows "
                         "instead: give one of them")
    columns, rows = args.cells[0], args.cells[-1]
    depth = args.cells[1] if len(args.cells) == 3 else None
    with Trajectories(args.file[0]) as run:
        space = state_space_from_name(args.states, columns, rows, run.width, run.height,
                                      depth, run.depth)
    start = args.start
    if args.span is not None and start is None:
        start = args.span[0]
    elif args.span is not None and not args.span[0] <= start < args.span[1]:
        raise InputError(f"--start {start:g} s lies outside --span {args.span[0]:g}:"
                         f"{args.span[1]:g} s: give a start inside the span, or one of them")
    def measure(start):
        return sample_length(args.file if len(args.file) > 1 else args.file[0], space,
                             lag=args.lag or 0.025, start=start,
                             estimator=args.estimator, tolerance=args.tolerance,
                             stop=None if args.span is None else args.span[1])

    try:
        result = measure(start)
    except HistoryError as exc:
        if start is not None or exc.earliest is None:
            raise
        # no start named: the windows start where the state space has its history
        print(f"note: the windows start at {exc.earliest:g} s, the first frame with the "
              f"history that {args.states} needs (--start sets another)", file=sys.stderr)
        result = measure(exc.earliest)
    from cfbmarkov.analysis.stationarity import face_band_warning

    warned = []
    for path in args.file:              # an open riser's tracks left out of the long run
        with Trajectories(path) as run:
            end = min(result.span_end, float(run.times[-1]))
            line = face_band_warning(run, (result.start, end), run.height / rows,
                                     run.lag_frames(args.lag or 0.025))
        if line is not None:
            warned.append(line if len(args.file) == 1 else f"{path}: {line}")
            print(f"warning: {one_line(warned[-1])}", file=sys.stderr)
    if args.json:
        print(json.dumps(result.to_dict() | {"verdict": verdict_text(result, args.states),
                                             "warnings": warned},
                         indent=1, allow_nan=False))
        return 0

    def value(v):
        return format(v, ".4g") if np.isfinite(v) else "n/d"

    span = (f"{result.start:g}-{result.span_end:g} s" if len(args.file) == 1 else
            f"from {result.start:g} s to each run's last frame (at most {result.span_end:g} s)")
    if np.isfinite(result.censored_share):
        print(f"{result.file}: models ({result.description}) on windows from {result.start:g} s "
              f"against the long run {span}: E(RT) {value(result.long_run_mean)} s from its "
              f"net solids flux; its {result.long_run_count} complete residences: mean "
              f"{value(result.long_run_observed_mean)} s, SD(RT) {value(result.long_run_sd)} s")
        cut = (f"{100 * result.censored_share:.0f} % of the span's particle-time lies "
               "outside its complete residences")
        shortfall = 100 * result.observed_shortfall
        if result.sd_judged:
            print(f"  (SD(RT) judged: the complete residences' mean lies {shortfall:.0f} % "
                  f"below the flux's E(RT), within the tolerance; {cut}; "
                  "docs/definitions.md, Sample length)")
        else:
            print(f"  (SD(RT) not judged: their mean lies {shortfall:.0f} % below the flux's "
                  f"E(RT), more than the tolerance, and {cut}: the span cuts the long "
                  "residences off and their SD(RT) is too low; a longer run judges it; "
                  "docs/definitions.md, Sample length)")
    else:
        print(f"{result.file}: models ({result.description}) on windows from {result.start:g} s "
              f"against the long run {span} (E(RT) {value(result.long_run_mean)} s, SD(RT) "
              f"{value(result.long_run_sd)} s, {result.long_run_count} residences)")
    tol = 100 * result.tolerance
    print(f"{'length (s)':>10}  {'E(RT) (s)':>9}  {'SD(RT) (s)':>10}  within {tol:g} %")
    pd_mean, pd_sd = result.deviations()
    shares = (result.outlasting_share if result.outlasting_share is not None
              else [math.nan] * len(result.lengths))
    for n, m, sd, miss, a, b, o in zip(result.lengths, result.rt_mean, result.rt_sd,
                                       result.missed(), pd_mean, pd_sd, shares):
        print(f"{n:>10g}  {value(m):>9}  {value(sd):>10}  {missed_text(miss, a, b, o)}")
    if result.fit_failure:
        print(f"  (no model: {one_line(result.fit_failure)})")
    print("sample length: " + verdict_text(result, args.states))
    return 0


#: most maps one ``maps`` figure draws (one panel each)
MAX_MAP_PANELS = 36


def cmd_maps(args) -> int:
    """``cfbmarkov maps``: draw the batch-injection maps; print the fractions and the file.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.report.figures import plot_probability_maps

    if len(args.times) > MAX_MAP_PANELS:
        raise InputError(f"--times gives {len(args.times)} times: one figure draws at most "
                         f"{MAX_MAP_PANELS} maps; give fewer times (or several figures)")
    model = MarkovModel.load(args.model)
    from cfbmarkov.markov.propagation import fed_inlet_cells

    downward = args.outflow and model.open_flow is None and model.flow_direction == "down"
    fed = fed_inlet_cells(model, "down" if downward else "up")    # its refusal first
    if args.outflow and model.open_flow is not None:
        print("note: an open riser's maps always take out what leaves through its outlet; "
              "--outflow changes nothing here", file=sys.stderr)
    if downward:
        print("note: the model's residences run downward (its fitting window's net solids "
              "flow runs down, as rtd counts them): with --outflow the batch is fed over the "
              "top cells and leaves through the bottom; without --outflow it is Eq. (8)'s "
              "batch over the bottom cells", file=sys.stderr)
    maps = model.batch_injection_maps(args.times, outflow=args.outflow)
    space = model.state_space
    from cfbmarkov.markov.model_summary import (cells_text, maps_left_out_warning,
                                                monte_carlo_warnings)
    import numpy as np

    if not fed.all():
        first = space.n_cells - space.cells_per_row if downward else 0
        left_out = first + np.flatnonzero(~fed)
        print(f"note: the batch is fed over {int(fed.sum())} of the {fed.size} "
              f"{'top' if downward else 'bottom'} cells: {cells_text(space, left_out)} "
              f"{'was' if left_out.size == 1 else 'were'} never left in the fitting window "
              "(never visited, or entered last), where the chain would keep a share in place "
              "at every time (Eq. (8) spreads it over the cells particles pass through)",
              file=sys.stderr)
    for line in monte_carlo_warnings(model):
        print(f"warning: the model: {one_line(line)}", file=sys.stderr)
    # with --outflow the fraction in riser of what the chain keeps levels off; without it a
    # periodic riser keeps the whole batch, whatever its classes
    left_out = (maps_left_out_warning(model, args.times, True, "down" if downward else "up")
                if args.outflow else None)
    if left_out is not None:
        print(f"warning: the model: {left_out}", file=sys.stderr)
    title = (f"Batch fed over the {'top cells' if downward else 'inlet'} at t = 0 "
             f"({space.describe()}"
             + (", summed over the depth" if space.depth_columns > 1 else "") + f", lag {model.lag:g} s"
             + (", what has left taken out)" if args.outflow or model.open_flow is not None
                else ")"))
    plot_probability_maps(maps, args.times, space.width, space.height, args.output, title=title)
    for t, m in zip(args.times, maps):
        print(f"t = {t:g} s: fraction in riser {m.sum():.4f}")
    print(args.output)
    return 0


def add_compare(sub) -> None:
    """Add the ``compare`` verb (a prediction against a reference) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("compare", help="compare two trajectory files: RTD, mixing of the two "
                       "tracer groups, figures")
    s.add_argument("reference", help="reference trajectory file (e.g. CFD-DEM)")
    s.add_argument("prediction", help="model trajectory file (e.g. a prediction)")
    s.add_argument("--window", type=parse_window, default=None,
                   help="analysis window START:STOP, s (default: the span both files cover, "
                        "said on stderr; a window outside it is refused naming both spans)")
    s.add_argument("-o", "--output", required=True, help="output directory")
    s.add_argument("--bin-width", type=positive_float, default=None,
                   help="RTD bin width, s (default: the lag of the model behind the prediction, "
                        "else the reference's frame interval; printed); refused where it "
                        "leaves fewer than two bins over the window or over the reference's "
                        "residences")
    s.add_argument("--md-order", type=minkowski_order, default=2.0,
                   help="Minkowski order k >= 1 of the MD (Eq. 9; inf: the largest difference; "
                        "default 2)")
    s.add_argument("--no-figures", action="store_true", help="write summary.json only")
    s.add_argument("--level", type=level, default=None,
                   help="coverage of the prediction's intervals (default 0.9; refused with "
                        "--resamples 0 unless --kinetics, whose Monte Carlo and reference "
                        "intervals take it)")
    s.add_argument("--resamples", type=count(0, 100000), default=None,
                   help="bootstrap resamples of the model's fitting window for the intervals "
                        f"(0: no intervals; default {DEFAULT_RESAMPLES}, left out with a "
                        "warning where the model's fitting file is not found; given, such a "
                        "comparison is refused)")
    s.add_argument("--basis", choices=["frames", "events"], default="frames",
                   help="frames: residence times of both sides from frames at the model's "
                        "lag, like for like (the reference's exact-event figures are shown "
                        "beside); events: the reference's exact pass events (default frames)")
    s.add_argument("--long-run-span", type=parse_window, default=None,
                   help="START:STOP, s: also give the reference's RTD pooled over this span's "
                        "other whole windows (what a perfect stationary model would predict; "
                        "e.g. 5:20; default none)")
    s.add_argument("--kinetics", default=None, metavar="FILE",
                   help="a kinetics file (TOML, linear laws): also each property at the exit "
                        "and in the bed for the reference (integrated along its paths), the "
                        "model and the segregated-flow baseline (summary.json 'kinetics', "
                        "figures kinetics-NAME.png)")
    s.add_argument("-q", "--quiet", action="store_true",
                   help="no progress lines on stderr")
    s.set_defaults(func=cmd_compare)


def add_stationarity(sub) -> None:
    """Add the ``stationarity`` verb (a run's window-to-window scatter) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("stationarity",
                       help="how much a run's RTD changes from window to window (sliding "
                            "windows), and the run's long run against one window")
    s.add_argument("file", nargs="+",
                   help="trajectory file; with --sample-length, several runs of one case "
                        "(their windows' counts pooled, their long runs pooled)")
    s.add_argument("--window-length", type=positive_float, default=None,
                   help="window length, s (default 5)")
    s.add_argument("--step", type=positive_float, default=None,
                   help="time between window starts, s (default 1)")
    s.add_argument("--span", type=parse_window, default=None,
                   help="START:STOP, s, the part of the file used (default all; leave out a "
                        "start-up from rest)")
    s.add_argument("--lag", type=positive_float, default=None,
                   help="frames every LAG s (a model's lag; default every frame, and 0.025 s "
                        "with --sample-length); also the RTD bins of the MD")
    s.add_argument("--basis", choices=["frames", "events"], default="frames",
                   help="residence times from frames (every --lag) or from the file's exact "
                        "pass events (as in compare); default frames")
    s.add_argument("--judge", type=parse_window, default=None,
                   help="START:STOP, s: also compare this window with the run's long run "
                        "(the span's other whole windows of its length, pooled) and with the "
                        "window before it (persistence)")
    s.add_argument("--sample-length", action="store_true",
                   help="how long a fitting window must be: fit models (--states, --cells, "
                        "--lag, --estimator as in fit) on windows of 0.5, 1, 2, 5, 10, ... s "
                        "from --start, and give the length from which their E(RT) and SD(RT) "
                        "stay within --tolerance of the run's long run from --start on (its "
                        "E(RT) from its net solids flux, its SD(RT) from its residences, "
                        "pooled, judged where the run is long enough for them)")
    s.add_argument("--start", type=finite_float, default=None,
                   help="with --sample-length: where the windows start, s (default the "
                        "start of --span, else the first frame; leave out a start-up from "
                        "rest); --span's end also ends the long run")
    s.add_argument("--tolerance", type=relative_tolerance, default=None,
                   help="with --sample-length: relative tolerance, a fraction (default 0.1, "
                        "10 %%)")
    s.add_argument("--states", choices=["cells", "cells-direction", "cells-velocity",
                                        "cells-velocity-fine", "cells-previous",
                                        "cells-regime", "cells-direction-regime"],
                   default=None, help="with --sample-length: the models' states (default cells)")
    s.add_argument("--cells", type=parse_cells, default=None,
                   help="COLUMNSxROWS: with --sample-length the models' cells (default "
                        "6x38); on an open riser also the face band of the residences, one "
                        "cell height H/ROWS (default H/38): a particle first seen within it "
                        "of the inlet entered, last seen within it of the outlet left")
    s.add_argument("--estimator", choices=["paper", "mle"], default=None,
                   help="with --sample-length: as in fit (default paper for the cells, mle on "
                        "an open riser or for a state space with memory)")
    s.add_argument("--json", action="store_true", help="print JSON instead of a table")
    s.set_defaults(func=cmd_stationarity)


def add_maps(sub) -> None:
    """Add the ``maps`` verb (batch-injection maps) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("maps", help="batch-injection probability maps (Eq. 8, Fig. 4-7)")
    s.add_argument("model", help="model file (.h5, from cfbmarkov fit)")
    s.add_argument("--times", type=parse_times, default=[0.05, 0.1, 0.15],
                   help="comma-separated times after injection, s (default 0.05,0.1,0.15)")
    s.add_argument("--outflow", action="store_true",
                   help="remove what leaves as a residence ends (fraction still in the "
                        "riser; a model whose residences run downward feeds the batch over "
                        "the top cells and takes out what leaves through the bottom)")
    s.add_argument("-o", "--output", required=True, help="PNG file")
    s.set_defaults(func=cmd_maps)
