"""The paper's Table 3 in the report: a compact table (one row per velocity and model, the
model's intervals in its cells, the paper's values beside them) and, linked from it, the
rest in detail (mixing, the persistence baseline, the CFD-DEM's own variability, the
model's own intervals) with a paragraph per prediction on how far to trust it, written from
its numbers. Each builder returns document blocks (:mod:`cfbmarkov.report.document`).

References
----------
Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Table 3 and Eq. 9;
docs/definitions.md, sections "residence time" (PD, Minkowski distance, Eq. 9), "Baseline and
natural variability" and "Intervals".
"""

from __future__ import annotations

import math

from cfbmarkov.analysis.baseline import BASELINE_TIE, OUTCOMES, BaselineJudgement, judge_baseline
from cfbmarkov.observed.metrics import percentage_text
from cfbmarkov.report.document import (Heading, Para, Table, finite_or_none, interval_text,
                                       link, number_text)
from cfbmarkov.report.run_folder import Case
from cfbmarkov.report.sections import DEFAULT_BIN_WIDTH, paper_row

TABLE3_HEADING = "Table 3: RTD of the CFD-DEM and the MCM"
DETAIL_HEADING = "Table 3 in detail"
#: a table cell where one side holds no complete residence (instead of "n/a")
NO_RESIDENCES = "no residences"
#: the compact table's columns
COMPACT_HEADER = ["U (m/s)", "Model", "E(RT) CFD-DEM (s)", "E(RT) MCM (s) [interval]",
                  "PD of E(RT) (%)", "SD(RT) CFD-DEM (s)", "SD(RT) MCM (s) [interval]",
                  "PD of SD(RT) (%)", "MD of RTD", "Against the baseline (its MD / halves' MD)",
                  "Paper: PD E (%) / PD SD (%) / MD"]
#: the detail table's columns
DETAIL_HEADER = ["U (m/s)", "Model", "Mixing RMS", "Baseline: PD E / PD SD / MD",
                 "CFD-DEM halves: PD E / PD SD / MD", "Model's own interval of E(RT) (s)",
                 "Model's own interval of SD(RT) (s)", "Intervals"]


def _difference_text(d) -> str:
    """'PD E / PD SD / MD' of a baseline or variability summary, or n/a."""
    if not d:
        return "n/a"
    return (f"{percentage_text(d.get('pd_rt_mean'), '.1f')} / "
            f"{percentage_text(d.get('pd_rt_sd'), '.1f')} / {number_text(d.get('md_rtd'), '.3g')}")


def _with_interval(value, interval) -> str:
    """'0.312 [0.276–0.349]': a value (s) and its interval, or the value alone; the interval
    with as many decimals as keep its ends apart."""
    text = number_text(value, ".3f")
    lo, hi = (finite_or_none(v) for v in (interval or [None, None])[:2])
    if lo is None or hi is None:
        return text
    return f"{text} [{interval_text(lo, hi)}]"


#: marks an interval of Table 3 that leaves out the flow's variability between windows
SAMPLING_ONLY = "†"


def _as_number(text: str) -> tuple:
    try:
        return (0, float(text))
    except ValueError:
        return (1, text)


def leaves_out_the_flow(summary: dict) -> bool:
    """Whether a compare summary's model intervals leave out the flow's variability between
    windows (its fitting window too short to show it): they then hold the fitting window's
    sampling and the Monte Carlo noise alone (``intervals.method``)."""
    method = (summary.get("intervals") or {}).get("method")
    return isinstance(method, str) and "flow's variability" not in method


def reference_place(summary: dict, figure: str = "rt_mean") -> str | None:
    """Where a compare summary's reference figure (``rt_mean`` or ``rt_sd``) stands against
    the model's interval of it, as `compare` judges it: ``inside``; ``not told apart``
    where it lies outside but the model's interval leaves out the flow's variability
    (:func:`leaves_out_the_flow`) and the reference's own interval (its residences'
    sampling, ``reference.<figure>_interval``) overlaps it; else ``outside``. None where
    either is missing.

    Parameters
    ----------
    summary : dict
        A comparison's ``summary.json``.
    figure : {"rt_mean", "rt_sd"}, optional

    Returns
    -------
    str or None
    """
    from cfbmarkov.analysis.kinetics_compare import exit_mean_agreement

    ref = summary.get("reference") or {}
    own = ref.get(f"{figure}_interval") if leaves_out_the_flow(summary) else None
    place = exit_mean_agreement(finite_or_none(ref.get(figure)),
                                (summary.get("model") or {}).get(f"{figure}_interval"), own)
    return "outside" if place == "missed" else place


def _interval_text(interval) -> str:
    return interval_text(*(interval or [None, None])[:2])


#: the report's words for each outcome of :func:`cfbmarkov.analysis.baseline.judge_baseline`
#: the key of :func:`baseline_outcomes` counting the winners named without the reference's
#: own variability (by the tie margin alone)
BY_TIE_MARGIN_ALONE = "by the tie margin alone"
OUTCOME_WORDS = {"beats": "model better", "loses": "baseline better",
                 "tie": f"tie (within {100 * BASELINE_TIE:g} %)", "not told apart": "not told apart"}
#: the rule, as the report states it once in Table 3's note and in the summary
BASELINE_RULE = (f"a model beats the persistence baseline only where its MD is lower than the "
                 f"baseline's by more than {100 * BASELINE_TIE:g} % (the tie margin) and by "
                 "more than the CFD-DEM's own variability, the MD between the two halves of "
                 "its predict window (a smaller gap could be the reference's sampling noise: "
                 "docs/definitions.md, Baseline and natural variability); the baseline is "
                 "better where the model's MD is higher by as much; otherwise the two are a "
                 "tie or cannot be told apart")


#: the rule in a clause, where Table 3's note has it in full
BASELINE_RULE_SHORT = (f"an MD lower than the baseline's by more than {100 * BASELINE_TIE:g} % "
                       "and by more than the MD between the CFD-DEM's two halves of the "
                       "predict window")


def baseline_judgement(summary: dict) -> BaselineJudgement | None:
    """The model of a compare summary against its persistence baseline, by the one rule
    (:func:`cfbmarkov.analysis.baseline.judge_baseline`); None without both MDs.

    Parameters
    ----------
    summary : dict
        A compare summary (``md_rtd``, ``baseline``, ``natural_variability``).

    Returns
    -------
    BaselineJudgement or None
    """
    md = finite_or_none(summary.get("md_rtd"))
    md_base = finite_or_none((summary.get("baseline") or {}).get("md_rtd"))
    if md is None or md_base is None:
        return None
    halves = finite_or_none((summary.get("natural_variability") or {}).get("md_rtd"))
    return judge_baseline(md, md_base, halves)


def baseline_outcomes(summaries) -> dict[str, int]:
    """How many comparisons have each outcome of the baseline rule.

    Parameters
    ----------
    summaries : iterable of dict
        Compare summaries (:func:`baseline_judgement`; those without both MDs are left out).

    Returns
    -------
    dict of str to int
        Keys "beats", "loses", "tie", "not told apart"
        (:func:`cfbmarkov.analysis.baseline.judge_baseline`), and
        :data:`BY_TIE_MARGIN_ALONE`: how many of the "beats" and "loses" were judged
        without the reference's own variability.
    """
    counts = {k: 0 for k in (*OUTCOMES, BY_TIE_MARGIN_ALONE)}
    for summary in summaries:
        j = baseline_judgement(summary)
        if j is not None:
            counts[j.outcome] += 1
            counts[BY_TIE_MARGIN_ALONE] += j.by_tie_margin_alone
    return counts


def baseline_clause(counts: dict[str, int], unit: str = "velocity-model pair",
                    reference: str = "the CFD-DEM") -> str | None:
    """What the baseline rule says of the models, in words: the verdict's first clause.

    Parameters
    ----------
    counts : dict of str to int
        :func:`baseline_outcomes`.
    unit : str, optional
        What one comparison is, singular (the report: a velocity-model pair).
    reference : str, optional
        The reference, for its own variability.

    Returns
    -------
    str or None
        The clause; None where no comparison was judged.
    """
    total = sum(counts[k] for k in OUTCOMES)
    if not total:
        return None
    return _clause(counts, total, unit, reference) + _margin_alone(counts, reference)


def _margin_alone(counts: dict[str, int], reference: str) -> str:
    """The caveat on winners named by the tie margin alone (their number, and why)."""
    alone = counts.get(BY_TIE_MARGIN_ALONE, 0)
    if not alone:
        return ""
    judged = counts["beats"] + counts["loses"]
    which = "all of them" if alone == judged else f"{alone} of the {judged} with a winner"
    return (f" ({which} by the {100 * BASELINE_TIE:g} % tie margin alone: {reference}'s "
            "halves hold no residence, so its own variability is not known and a gap may be "
            "its sampling noise)")


def _clause(counts: dict[str, int], total: int, unit: str, reference: str) -> str:
    hidden = counts["not told apart"] + counts["tie"]
    every = (f"all {total} {unit}s" if total > 2 else f"both {unit}s" if total == 2
             else f"the one {unit}")
    if counts["beats"] == total:
        return f"the models beat the persistence baseline in {every}"
    if counts["loses"] == total:
        return ("reusing the fitting window's RTD (the persistence baseline) predicts "
                f"better than the models in {every}")
    if counts["beats"] == 0:
        return (f"no model is shown to predict the RTD better than reusing the fitting "
                f"window's (0 of {total} {unit}s beat the persistence baseline; {hidden} are "
                f"tied with it or within {reference}'s own variability"
                + (f", {counts['loses']} worse)" if counts["loses"] else ")"))
    return f"the models beat the persistence baseline in {counts['beats']} of {total} {unit}s"


def baseline_step(counts: dict[str, int], reference: str = "the CFD-DEM") -> str:
    """The next step the baseline rule's outcomes call for (:func:`baseline_outcomes`)."""
    total = sum(counts[k] for k in OUTCOMES)
    hidden = counts["not told apart"] + counts["tie"]
    if total and 2 * hidden > total:
        return (f"longer predict windows (more residences), so that {reference}'s own "
                "variability no longer hides the difference from the baseline")
    if total and 2 * counts["loses"] > total:
        return ("a state space with memory (fit --states auto) or a longer fitting window, "
                "since reusing the fitting window's RTD predicts better")
    return "use the models over windows like these, with their intervals"


def _baseline_cell(summary: dict) -> str:
    """'model better (0.1240 / 0.0300)': the outcome of the rule, the baseline's and the halves'
    MD, at the precision of the model's MD column."""
    base = summary.get("baseline") or {}
    if base.get("rt_count") == 0:
        return NO_RESIDENCES
    j = baseline_judgement(summary)
    if j is None:
        return "n/a"
    halves = "n/a" if j.md_halves is None else f"{j.md_halves:.4g}"
    alone = ", by the tie margin alone" if j.by_tie_margin_alone else ""
    return f"{OUTCOME_WORDS[j.outcome]}{alone} ({j.md_base:.4g} / {halves})"


def _count(value) -> str:
    return "n/a" if value is None else f"{int(value)}"


def _sizes_text(sizes: dict[str, dict]) -> str:
    """Per case: the RTD bin width, the residences counted on each side and the bins their
    RTD spans, e.g. '3 m/s 0.01 s: CFD-DEM 7740 (43), paper 6280 (64), mle 6111 (62)'."""
    def one(n, b) -> str:
        return _count(n) + ("" if b is None else f" ({_count(b)})")

    parts = []
    for u, size in sizes.items():
        width = "n/a" if size["width"] is None else f"{size['width']:g} s"
        models = ", ".join(f"{name} {one(n, b)}" for name, n, b in size["models"])
        parts.append(f"{u} m/s {width}: CFD-DEM {one(size['reference'], size['spanned'])}, "
                     f"{models}")
    return "; ".join(parts)


def table3_blocks(cases: list[Case], estimators: list[str]) -> list:
    """The paper's Table 3, compact: one row per velocity and model, intervals in the cells.

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.
    estimators : list of str
        The estimators of the run, in report order.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`); the rest of each
        comparison is in :func:`table3_detail_blocks`, linked from here.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Table 3 and Eq. 9;
    ``docs/definitions.md`` (Metrics).
    """
    rows, orders, widths, levels = [], set(), set(), set()
    downward: set[str] = set()
    sampling_only: set[str] = set()
    sizes: dict[str, dict] = {}
    for c in cases:
        values = paper_row(c.velocity)
        paper = " / ".join(values) if values != ("—", "—", "—") else "—"
        u = f"{c.velocity:g}" if math.isfinite(c.velocity) else c.name
        for e in c.estimators if c.estimators else [None]:
            s = e.summary if e is not None and not c.problems else None
            if s is None:
                rows.append([u, e.name if e else "—"] + ["not finished"] * 8 + [paper])
                continue
            ref, mod = s["reference"], s["model"]
            mark = SAMPLING_ONLY if leaves_out_the_flow(s) else ""
            mean_cell = _with_interval(mod.get("rt_mean"), mod.get("rt_mean_interval"))
            sd_cell = _with_interval(mod.get("rt_sd"), mod.get("rt_sd_interval"))
            if mark:
                sampling_only.add(u)
                mean_cell += mark if mod.get("rt_mean_interval") else ""
                sd_cell += mark if mod.get("rt_sd_interval") else ""
            row = [u, e.name, number_text(ref.get("rt_mean"), ".3f"), mean_cell,
                   percentage_text(s.get("pd_rt_mean"), ".2f"),
                   number_text(ref.get("rt_sd"), ".3f"), sd_cell,
                   percentage_text(s.get("pd_rt_sd"), ".2f"),
                   number_text(s.get("md_rtd"), ".4g"), _baseline_cell(s), paper]
            # a side without a complete residence in the net flow's direction: say so
            for side, columns in ((ref, (2, 5)), (mod, (3, 6))):
                if side.get("rt_count") == 0:
                    for k in (*columns, 4, 7, 8):
                        row[k] = NO_RESIDENCES
            rows.append(row)
            order = s.get("md_order")
            if (v := math.inf if order == "inf" else finite_or_none(order)) is not None:
                orders.add(v)
            if (v := finite_or_none(s.get("bin_width"))) is not None:
                widths.add(v)
            if mod.get("rt_mean_interval"):
                levels.add(100 * float(s.get("level") or 0.9))
            if s.get("direction") == "down":
                downward.add(u)
            size = sizes.setdefault(u, {"width": finite_or_none(s.get("bin_width")),
                                        "spanned": (s.get("rtd_bins_spanned") or {}).get(
                                            "reference"),
                                        "reference": ref.get("rt_count"), "models": []})
            size["models"].append((e.name, mod.get("rt_count"),
                                   (s.get("rtd_bins_spanned") or {}).get("model")))
    order_text = ", ".join(f"{k:g}" for k in sorted(orders)) or "n/a"
    width_text = ", ".join(f"{w:g}" for w in sorted(widths)) or f"{DEFAULT_BIN_WIDTH:g}"
    level_text = ", ".join(f"{v:g}" for v in sorted(levels)) or "n/a"
    notes = [
        "PD = 100 (MCM − CFD-DEM) / CFD-DEM, in % (docs/definitions.md, residence time); "
        "E(RT) and SD(RT) over the predict window, SD with ddof = 1: of the residences that "
        "begin and end inside it (a particle's time from one pass through the boundary to the "
        "next), on both sides alike, so that residences longer than the window are left out "
        "of both and the figures are of the window, not of the flow's long run (the "
        "physics checks take E(RT) from the net solids flux instead). [interval]: the MCM's "
        f"{level_text} % interval (docs/definitions.md, Intervals). The paper's column quotes "
        "its Table 3; '—' where the paper has no case at this U.",
        "The paper reports MD under a '%' heading. Our MD is Eq. 9 of order k = "
        f"{order_text} (md_order of the compare summaries) on the RTD probabilities per "
        + (f"{width_text} s bin (" if len(widths) <= 1 else "bin of the case's width (next "
           "note; ")
        + "bins from 0 to the window length), a dimensionless distance; "
        "compare its size with the paper's only loosely.",
        "Against the baseline: the persistence baseline is the CFD-DEM's RTD of the fitting "
        f"window reused as the prediction; {BASELINE_RULE}. In brackets: the baseline's MD "
        "and the halves' MD. Mixing, the CFD-DEM's own variability, the model's own intervals and the "
        f"residence-time basis: {link(DETAIL_HEADING, DETAIL_HEADING)}.",
    ]
    if sampling_only:
        notes.insert(1, f"{SAMPLING_ONLY}: the interval leaves out the flow's variability "
                        "between windows, the fitting window being too short to show it (at "
                        f"U = {', '.join(sorted(sampling_only, key=_as_number))} m/s): it "
                        "holds the fitting window's sampling and the Monte Carlo noise alone, "
                        "and the flow's long run may lie outside it; the others include it.")
    sizes_text = _sizes_text(sizes)
    if sizes_text:
        notes.insert(2, "RTD bins and residences per case (the bin width; the residences "
                        "counted in the predict window, with the number of bins their RTD "
                        f"spans in brackets): {sizes_text}.")
    if any(row[4] == "n/d" or row[7] == "n/d" for row in rows):
        notes.append("n/d: the percentage difference is undefined because the CFD-DEM value "
                     "is zero to round-off (e.g. SD(RT) of residence times that are all "
                     "equal), or missing.")
    if any(NO_RESIDENCES in row for row in rows):
        notes.append(f"{NO_RESIDENCES}: that side holds no complete residence in the window, "
                     "counted in the direction of the CFD-DEM's net solids flow (a model "
                     "fitted where the solids rose predicts almost no residence when they "
                     "fall); no mean, spread or distance can be formed.")
    if downward:
        notes.append(f"At U = {', '.join(sorted(downward))} m/s the solids' net flow over the "
                     "predict window is downward: residence times run from entries through the "
                     "top to exits through the bottom (docs/definitions.md, Net downflow).")
    blocks = [Heading(2, TABLE3_HEADING), Table(COMPACT_HEADER, rows, notes)]
    return blocks


def table3_detail_blocks(cases: list[Case]) -> list:
    """The rest of each Table 3 comparison, and how far to trust each prediction.

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.

    Returns
    -------
    list
        Document blocks (empty without a finished comparison).
    """
    rows, exact, exact_pd = [], {}, []
    for c in cases:
        u = f"{c.velocity:g}" if math.isfinite(c.velocity) else c.name
        for e in c.estimators or []:
            s = e.summary if not c.problems else None
            if s is None:
                continue
            mod = s.get("model") or {}
            method = (s.get("intervals") or {}).get("method", "none")
            rows.append([u, e.name, number_text(s.get("mixing_rms"), ".3g"),
                         _difference_text(s.get("baseline")),
                         _difference_text(s.get("natural_variability")),
                         _interval_text(mod.get("model_rt_mean_interval")),
                         _interval_text(mod.get("model_rt_sd_interval")), method])
            for k, summary in ((3, s.get("baseline")), (4, s.get("natural_variability"))):
                if summary and summary.get("rt_count") == 0:
                    rows[-1][k] = NO_RESIDENCES
            ex = s.get("exact_events") or {}
            if s.get("basis") == "frames":
                lag_frames = s.get("reference_frame_stride") or 1
                key = ("like for like: both sides from frames at the model's lag (CFD-DEM "
                       f"frames every {lag_frames})")
                exact.setdefault(key, set()).add(c.name)
                er = s.get("exact_reference")
                if er and (finite_or_none(er.get("pd_rt_mean")) is not None
                           or finite_or_none(er.get("pd_rt_sd")) is not None):
                    exact_pd.append(f"{u} m/s {e.name} {percentage_text(er.get('pd_rt_mean'), '.1f')}"
                                    f" / {percentage_text(er.get('pd_rt_sd'), '.1f')}")
            else:
                exact.setdefault("CFD-DEM: exact pass events" if ex.get("reference")
                                 else "CFD-DEM: frame times", set()).add(c.name)
    if not rows:
        return []
    notes = [
        "Mixing RMS: root-mean-square difference of the MCM and CFD-DEM mixing curves on the "
        "model's frames, as a fraction of all particles (no paper value).",
        "Baseline: the CFD-DEM's own RTD in the fitting window taken as the prediction "
        "(persistence); a model is only worth its name where it beats it. CFD-DEM halves: "
        "the first half of the predict window against the second, the CFD-DEM's natural "
        "variability at that scale (docs/definitions.md, Baseline and natural variability).",
        "Model's own interval: from the model alone (block bootstrap of its fitting window and "
        "Monte Carlo noise); the interval in Table 3 adds the flow's variability between "
        "windows where the fitting window is long enough to show it (column Intervals).",
    ]
    if exact:
        notes.append("Residence-time basis: " + "; ".join(
            f"{k} ({', '.join(sorted(v))})" for k, v in exact.items())
            + "; MCM predictions: frame times (docs/definitions.md, Comparison basis)."
            + (" With the CFD-DEM's residence times from its exact pass events instead, the "
               "PD of E(RT) / SD(RT) (%) would be: " + "; ".join(exact_pd) + "."
               if exact_pd else ""))
    return ([Heading(2, DETAIL_HEADING),
             Para(f"The rest of each comparison of {link('Table 3', TABLE3_HEADING)}.")]
            + [Table(DETAIL_HEADER, rows, notes)] + trust_blocks(cases))


def _baseline_sentence(j: BaselineJudgement) -> str:
    """The model against the persistence baseline, by the one rule, in a sentence; the MDs
    themselves are in Table 3's row (the model's, the baseline's and the halves'), not
    repeated."""
    gap = abs(j.gap)
    halves = ", more than the halves differ" if j.md_halves is not None else ""
    if j.outcome == "beats":
        body = ("the model beats simply reusing the fitting window's RTD (the persistence "
                f"baseline): its MD is lower by {gap:.2g}{halves}.")
    elif j.outcome == "loses":
        body = ("simply reusing the fitting window's RTD beats the model (the persistence "
                f"baseline's MD is lower by {gap:.2g}{halves}).")
    elif j.outcome == "tie":
        body = ("the model and simply reusing the fitting window's RTD (the persistence "
                f"baseline) are a tie: their MDs differ by less than {100 * j.tie:g} %.")
    else:
        body = ("the model's MD and the persistence baseline's differ by "
                f"{gap:.2g}, within the CFD-DEM's own variability: the window cannot tell the "
                "model from simply reusing the fitting window's RTD.")
    if j.md_halves is None:
        body += " (No halves' variability is known: the tie margin alone judges.)"
    return "by the baseline rule (Table 3), " + body


def _cluster_clause(c_ref: float, c_mod: float) -> str:
    """What the cluster indices say: the share of the CFD-DEM's clustering the model keeps."""
    if not c_ref > 1.0:
        return ""
    share = (c_mod - 1.0) / (c_ref - 1.0)
    if share < 0.5:
        return (f": the model keeps {100 * max(share, 0.0):.0f} % of the CFD-DEM's clustering "
                "above 1 (a chain whose particles move independently keeps none; coherent "
                "moves keep some)")
    if share <= 1.25:
        return f": the model keeps {100 * share:.0f} % of the CFD-DEM's clustering above 1"
    return f": the model clusters more than the CFD-DEM ({100 * share:.0f} % of its clustering above 1)"


def trust_text(u: str, estimator: str, summary: dict) -> str:
    """One paragraph: how far to trust this prediction, written from its numbers (the model
    against the persistence baseline, its own error on its fitting window, the CFD-DEM's own
    variability, what a perfect stationary model would predict (the run's long run) where
    the summary has it, and its interval).

    Parameters
    ----------
    u : str
        The case's velocity as written in the table.
    estimator : str
        The model's name.
    summary : dict
        The compare summary.

    Returns
    -------
    str
    """
    md = finite_or_none(summary.get("md_rtd"))
    base = summary.get("baseline") or {}
    halves = summary.get("natural_variability") or {}
    md_base, md_halves = finite_or_none(base.get("md_rtd")), finite_or_none(halves.get("md_rtd"))
    own = summary.get("model_on_fitting_window") or {}
    md_own = finite_or_none(own.get("md_rtd"))
    parts = [f"U = {u} m/s, {estimator}:"]
    if md is None:
        return " ".join(parts + ["no RTD to judge (too few residences in the window)."])
    j = baseline_judgement(summary)
    if j is not None:
        parts.append(_baseline_sentence(j))
    else:
        parts.append(f"its RTD is {md:.4g} from the CFD-DEM's (MD); no persistence baseline "
                     "(the fitting window is not in the reference file).")
    # the model's error within the reference's own variability: its split into the model's
    # own part and the flow's change cannot be told, so none is claimed
    within = md_halves is not None and md <= md_halves
    if md_own is not None and md_base is not None:
        windows = own.get("windows") or [[], []]
        fit = "-".join(f"{t:g}" for t in windows[1]) if len(windows[1]) == 2 else "fitting"
        pd_own = [finite_or_none(own.get(k)) for k in ("pd_rt_mean", "pd_rt_sd")]
        pds = (f" (PD of E(RT) {pd_own[0]:+.1f} %, of SD(RT) {pd_own[1]:+.1f} %)"
               if None not in pd_own else "")
        # the MDs (the model's, the baseline's, the halves') are in Table 3's row: said in
        # words here, not repeated
        text = (f"On its own fitting window ({fit} s) the model is {md_own:.3g} from the "
                f"CFD-DEM's RTD{pds}")
        if within:
            text += (". Its MD on the predict window is within the CFD-DEM's own variability "
                     "(the MD between the two halves of the window, Table 3): the window "
                     "cannot tell how much of it is the model's own error and how much the "
                     "flow's change.")
        else:
            text += (f", {'smaller than' if md_own < md_base else 'at least'} the flow's "
                     "change between the windows (the baseline's MD)"
                     + (": the flow's change, more than the model, limits this prediction."
                        if md_own < md_base else ": the model's own error dominates."))
        parts.append(text)
    if md_halves is not None and not within:
        flow_limits = md_own is not None and md_base is not None and md_own < md_base
        parts.append(f"The model's error is {md / md_halves:.1f} times the reference's own "
                     "variability (the MD between the CFD-DEM's two halves of the window, "
                     "Table 3)"
                     + ("; the rest is the flow's change since the fitting window." if flow_limits
                        else "; the difference is the model's."))
    elif md_halves is not None and (md_own is None or md_base is None):
        parts.append("The model's error is within the reference's own variability (the MD "
                     "between the CFD-DEM's two halves of the window, Table 3).")
    long_run = summary.get("long_run") or {}
    md_long = finite_or_none(long_run.get("md_rtd"))
    if md_long is not None:
        (a, b), _ = long_run["windows"]
        pd_long = [finite_or_none(long_run.get(k)) for k in ("pd_rt_mean", "pd_rt_sd")]
        pds = (f" (PD of E(RT) {pd_long[0]:+.1f} %, of SD(RT) {pd_long[1]:+.1f} %)"
               if None not in pd_long else "")
        parts.append(f"What a perfect stationary model would predict, the CFD-DEM's own RTD over the "
                     f"run's other windows of {a:g}-{b:g} s pooled, is {md_long:.3g} from it"
                     f"{pds}: the flow's scatter about its long run, which no state space "
                     "removes; the model is "
                     + ("closer than that." if md < md_long else
                        f"{md / md_long:.1f} times as far."))
    else:
        parts.append("What a perfect stationary model would predict (the CFD-DEM's RTD pooled "
                     "over the run's other windows) is not given: besides the fitting window "
                     "the run holds no other whole window of the predict window's length "
                     "after its first window length (the start-up from rest), and one window "
                     "alone would be the persistence baseline again.")
    cluster = summary.get("cluster_index") or {}
    c_ref = finite_or_none((cluster.get("reference") or {}).get("mean"))
    c_mod = finite_or_none((cluster.get("model") or {}).get("mean"))
    if c_ref is not None and c_mod is not None:
        parts.append(f"Cluster index of the snapshots (1: particles placed independently, "
                     f"higher: clusters and voids; the nearer the CFD-DEM's, the better): "
                     f"CFD-DEM {c_ref:.3g}, model {c_mod:.3g}"
                     + _cluster_clause(c_ref, c_mod) + ".")
    place = reference_place(summary)
    if place is not None:
        level = 100 * float(summary.get("level") or 0.9)
        # the value and the interval are in Table 3's row, the model's own interval in the
        # detail table: said in words here, not repeated
        parts.append(f"The CFD-DEM's E(RT) lies {'outside' if place != 'inside' else place} "
                     f"the model's {level:g} % interval (Table 3)"
                     + (", but within its own sampling of it (the interval leaves that out "
                        "here): not told apart" if place == "not told apart" else "") + ".")
    verdict = (summary.get("adequacy") or {}).get("warnings") or []
    if verdict:
        parts.append("The model's fitting sample was warned about when it was fitted: "
                     + "; ".join(line.rstrip(".") for line in verdict) + ".")
    return " ".join(parts)


def trust_blocks(cases: list[Case]) -> list:
    """"How far to trust this prediction": one paragraph per velocity and estimator.

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run.

    Returns
    -------
    list
        Document blocks (empty without summaries).
    """
    texts = []
    for c in cases:
        u = f"{c.velocity:g}" if math.isfinite(c.velocity) else c.name
        for e in c.estimators or []:
            if e.summary is not None and not c.problems:
                texts.append(trust_text(u, e.name, e.summary))
    if not texts:
        return []
    return [Heading(3, "How far to trust these predictions")] + [Para(t) for t in texts]


__all__ = ["BY_TIE_MARGIN_ALONE", "COMPACT_HEADER", "DETAIL_HEADER", "DETAIL_HEADING", "NO_RESIDENCES",
           "SAMPLING_ONLY", "TABLE3_HEADING", "baseline_clause", "baseline_judgement", "baseline_outcomes",
           "baseline_step", "leaves_out_the_flow", "table3_blocks", "table3_detail_blocks", "trust_blocks",
           "trust_text"]
