"""The report's sections of text and tables: the run, the unfinished cases, the paper's
Table 3 (quoted from the compare summaries), computing time and warnings. Each builder
returns document blocks (:mod:`cfbmarkov.report.document`).

References
----------
docs/definitions.md, sections "residence time" (PD, Minkowski distance, Eq. 9) and "mixing".
"""

from __future__ import annotations

import math

from cfbmarkov.observed.metrics import percentage_text
from cfbmarkov.report.document import (
    Bullets,
    Heading,
    Para,
    Table,
    duration_text,
    finite_or_none,
    number_text,
)
from cfbmarkov.report.run_folder import Case

#: the paper's Table 3 as printed: U (m/s) -> (PD of E(RT) %, PD of SD(RT) %, MD of RTD)
PAPER_TABLE3: dict[float, tuple[str, str, str]] = {
    3.0: ("11.89", "-50.55", "0.0185"),
    4.0: ("1.57", "-37.84", "0.238"),
    6.0: ("2.45", "-41.67", "0.380"),
    8.0: ("0.54", "-45.16", "0.328"),
}
#: the paper's §3.1: CFD-DEM of the 5 s predict window about 50 h, the MCM about 30 min
PAPER_CFD_DEM_S = 50 * 3600.0
PAPER_MCM_S = 30 * 60.0
PAPER_SPEEDUP = 100.0
#: RTD bin width (s) when no compare summary gives one
DEFAULT_BIN_WIDTH = 0.025


def shared_text(values: dict[str, str]) -> str:
    """One value when all cases agree, else 'case: value' for each.

    Parameters
    ----------
    values : dict of str to str
        A text per case name.

    Returns
    -------
    str
    """
    distinct = list(dict.fromkeys(values.values()))
    if len(distinct) == 1:
        return distinct[0]
    return "; ".join(f"{case}: {value}" for case, value in values.items())


def window_text(window) -> str:
    """A window (start, stop) in s as text.

    Parameters
    ----------
    window : sequence of two numbers
        (start, stop), s.

    Returns
    -------
    str
        E.g. "5–10 s".
    """
    return f"{float(window[0]):g}–{float(window[1]):g} s"


def header_blocks(meta: dict, cases: list[Case], estimators: list[str]) -> list:
    """The run: scale, cases, riser, windows, lag, cells, estimators, version.

    Parameters
    ----------
    meta : dict
        The run's ``reproduce.json``.
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.
    estimators : list of str
        The estimators of the run, in report order.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`; empty when there
        is nothing to say).
    """
    from cfbmarkov import __version__

    configured = [c for c in cases if c.config is not None]
    done = [c for c in cases if c.complete]
    pending = [c for c in cases if not c.complete]
    cfg = {c.name: c.config for c in configured}
    items = [
        f"Scale: {meta.get('scale', 'n/a')}",
        "Cases: " + ", ".join(f"{c.name} ({c.label})" for c in cases)
        + f" — {len(done)} finished" + (f", {len(pending)} not finished ("
                                         + ", ".join(c.name for c in pending) + ")"
                                         if pending else ""),
        "Riser: " + shared_text({n: f"{c.riser.width:g} m wide x {c.riser.height:g} m high"
                             for n, c in cfg.items()}),
        "Particles: " + shared_text({n: f"{c.particles.number}" for n, c in cfg.items()}),
        "Windows: " + shared_text({n: f"fit {window_text(c.markov.fit_window)}, predict "
                                  f"{window_text(c.markov.predict_window)}"
                               for n, c in cfg.items()}),
        "Lag: " + shared_text({n: f"{c.markov.lag:g} s" for n, c in cfg.items()}),
        "Cells: " + shared_text({n: f"{c.markov.columns} columns x {c.markov.rows} rows"
                             for n, c in cfg.items()}),
        "Estimators: " + (", ".join(estimators) or "none"),
        f"cfbmarkov version: {__version__}"
        + (f" (pipeline recorded {meta['version']})" if meta.get("version") not in (None, "")
           else ""),
    ]
    return [Heading(2, "Reproduction"), Bullets(items)]


def not_finished_blocks(cases: list[Case]) -> list:
    """The cases and estimators that have not completed every stage.

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`; empty when there
        is nothing to say).
    """
    pending = [c for c in cases if not c.complete or c.reasons]
    if not pending:
        return []
    items = []
    for c in pending:
        state = "not finished" if not c.complete else "partly finished; not finished"
        items.append(f"{c.name} ({c.label}): {state}: " + "; ".join(c.reasons))
    return [Heading(2, "Not finished"),
            Para("These cases or estimators have not completed every stage of the pipeline; "
                  "they are left out of the figures and shown as 'not finished' in the "
                  "tables."),
            Bullets(items)]


def paper_row(u: float) -> tuple[str, str, str]:
    """The paper's Table 3 values at a velocity, or dashes.

    Parameters
    ----------
    u : float
        Superficial gas velocity U, m/s.

    Returns
    -------
    (str, str, str)
        PD of E(RT) (%), PD of SD(RT) (%) and MD of the RTD as printed in the paper;
        ("—", "—", "—") where the paper has no case at U.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Table 3.
    """
    values = PAPER_TABLE3.get(round(u, 6)) if math.isfinite(u) else None
    return values if values is not None else ("—", "—", "—")


#: a table cell where one side holds no complete residence (instead of "n/a")
NO_RESIDENCES = "no residences"


def _difference_text(d) -> str:
    """'PD E / PD SD / MD' of a baseline or variability summary, or n/a."""
    if not d:
        return "n/a"
    return (f"{percentage_text(d.get('pd_rt_mean'), '.1f')} / "
            f"{percentage_text(d.get('pd_rt_sd'), '.1f')} / {number_text(d.get('md_rtd'), '.3g')}")


def table3_blocks(cases: list[Case], estimators: list[str]) -> list:
    """The paper's Table 3 from the compare summaries, beside the paper's values.

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.
    estimators : list of str
        The estimators of the run, in report order.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`; empty when there
        is nothing to say).

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Table 3 and Eq. 9;
    ``docs/definitions.md`` (Metrics).
    """
    header = ["U (m/s)", "Estimator", "E(RT) CFD-DEM (s)", "E(RT) MCM (s)", "PD of E(RT) (%)",
              "SD(RT) CFD-DEM (s)", "SD(RT) MCM (s)", "PD of SD(RT) (%)", "MD of RTD",
              "Mixing RMS", "Baseline: PD E / PD SD / MD", "CFD-DEM halves: PD E / PD SD / MD",
              "Paper: PD of E(RT) (%)", "Paper: PD of SD(RT) (%)", "Paper: MD of RTD"]
    rows, pd_sd, pd_mean, orders, widths, exact = [], [], [], set(), set(), {}
    exact_pd: list[str] = []
    downward: set[str] = set()
    for c in cases:
        paper = paper_row(c.velocity)
        u = f"{c.velocity:g}" if math.isfinite(c.velocity) else c.name
        for e in c.estimators if c.estimators else [None]:
            s = e.summary if e is not None and not c.problems else None
            if s is None:
                rows.append([u, e.name if e else "—"] + ["not finished"] * 10 + list(paper))
                continue
            ref, mod = s["reference"], s["model"]
            row = [u, e.name, number_text(ref.get("rt_mean"), ".3f"),
                   number_text(mod.get("rt_mean"), ".3f"),
                   percentage_text(s.get("pd_rt_mean"), ".2f"),
                   number_text(ref.get("rt_sd"), ".3f"), number_text(mod.get("rt_sd"), ".3f"),
                   percentage_text(s.get("pd_rt_sd"), ".2f"),
                   number_text(s.get("md_rtd"), ".3g"), number_text(s.get("mixing_rms"), ".3g"),
                   _difference_text(s.get("baseline")),
                   _difference_text(s.get("natural_variability"))] + list(paper)
            # a side without a complete residence in the net flow's direction: say so
            for side, columns in ((ref, (2, 5)), (mod, (3, 6))):
                if side.get("rt_count") == 0:
                    for k in (*columns, 4, 7, 8):
                        row[k] = NO_RESIDENCES
            for k, summary in ((10, s.get("baseline")), (11, s.get("natural_variability"))):
                if summary and summary.get("rt_count") == 0:
                    row[k] = NO_RESIDENCES
            rows.append(row)
            if (v := finite_or_none(s.get("pd_rt_sd"))) is not None:
                pd_sd.append(v)
            if (v := finite_or_none(s.get("pd_rt_mean"))) is not None:
                pd_mean.append(v)
            if (v := finite_or_none(s.get("md_order"))) is not None:
                orders.add(v)
            if (v := finite_or_none(s.get("bin_width"))) is not None:
                widths.add(v)
            if s.get("direction") == "down":
                downward.add(u)
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
    order_text = ", ".join(f"{k:g}" for k in sorted(orders)) or "n/a"
    width_text = ", ".join(f"{w:g}" for w in sorted(widths)) or f"{DEFAULT_BIN_WIDTH:g}"
    notes = [
        "PD = 100 (MCM − CFD-DEM) / CFD-DEM, in % (docs/definitions.md, residence time); "
        "E(RT) and SD(RT) over the predict window, SD with ddof = 1. The paper's columns quote "
        "its Table 3; '—' where the paper has no case at this U.",
        "The paper reports MD under a '%' heading. Our MD is Eq. 9 of order k = "
        f"{order_text} (md_order of the compare summaries) on the RTD probabilities per "
        f"{width_text} s bin (bins from 0 to the window length), a dimensionless distance; "
        "compare its size with the paper's only loosely.",
        "Mixing RMS: root-mean-square difference of the MCM and CFD-DEM mixing curves on the "
        "model's frames, as a fraction of all particles (no paper value).",
        "Baseline: the CFD-DEM's own RTD in the fitting window taken as the prediction "
        "(persistence); a model is only worth its name where it beats it. CFD-DEM halves: "
        "the first half of the predict window against the second, the CFD-DEM's natural "
        "variability at that scale (docs/definitions.md, Baseline and natural variability).",
    ]
    if any(row[4] == "n/d" or row[7] == "n/d" for row in rows):
        notes.append("n/d: the percentage difference is undefined because the CFD-DEM value "
                     "is zero to round-off (e.g. SD(RT) of residence times that are all "
                     "equal), or missing.")
    if exact:
        notes.append("Residence-time basis: " + "; ".join(
            f"{k} ({', '.join(sorted(v))})" for k, v in exact.items())
            + "; MCM predictions: frame times (docs/definitions.md, Comparison basis)."
            + (" With the CFD-DEM's residence times from its exact pass events instead, the "
               "PD of E(RT) / SD(RT) (%) would be: " + "; ".join(exact_pd) + "."
               if exact_pd else ""))
    if any(NO_RESIDENCES in row for row in rows):
        notes.append(f"{NO_RESIDENCES}: that side holds no complete residence in the window, "
                     "counted in the direction of the CFD-DEM's net solids flow (a model "
                     "fitted where the solids rose predicts almost no residence when they "
                     "fall); no mean, spread or distance can be formed.")
    if downward:
        notes.append(f"At U = {', '.join(sorted(downward))} m/s the solids' net flow over the "
                     "predict window is downward: residence times run from entries through the "
                     "top to exits through the bottom (docs/definitions.md, Net downflow).")
    blocks = [Heading(2, "Table 3: RTD of the CFD-DEM and the MCM"), Table(header, rows, notes)]
    if pd_mean:
        under = sum(v < 0 for v in pd_sd)
        blocks.append(Para(
            f"PD of E(RT) ranges from {min(pd_mean):.2f} to {max(pd_mean):.2f} % (paper: 0.54 to "
            f"11.89 %); the MCM's SD(RT) is smaller than the CFD-DEM's in {under} of "
            f"{len(pd_sd)} comparisons (paper: all four, by 38 to 51 %)."))
    blocks.extend(trust_blocks(cases))
    return blocks


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
    if md_base is not None:
        verdict = ("beats" if md < md_base else "does not beat")
        parts.append(f"its RTD is {md:.3g} from the CFD-DEM's (MD), where the persistence "
                     f"baseline is {md_base:.3g}: the model {verdict} simply reusing the "
                     "fitting window's RTD.")
    else:
        parts.append(f"its RTD is {md:.3g} from the CFD-DEM's (MD); no persistence baseline "
                     "(the fitting window is not in the reference file).")
    if md_own is not None and md_base is not None:
        windows = own.get("windows") or [[], []]
        fit = "-".join(f"{t:g}" for t in windows[1]) if len(windows[1]) == 2 else "fitting"
        pd_own = [finite_or_none(own.get(k)) for k in ("pd_rt_mean", "pd_rt_sd")]
        pds = (f" (PD of E(RT) {pd_own[0]:+.1f} %, of SD(RT) {pd_own[1]:+.1f} %)"
               if None not in pd_own else "")
        share = ("smaller than" if md_own < md_base else "at least")
        parts.append(f"On its own fitting window ({fit} s) the model is {md_own:.3g} from the "
                     f"CFD-DEM's RTD{pds}, {share} the flow's change between the windows "
                     f"({md_base:.3g})"
                     + (": the flow's change, more than the model, limits this prediction."
                        if md_own < md_base else ": the model's own error dominates."))
    if md_halves is not None:
        scale = ("within" if md <= md_halves else f"{md / md_halves:.1f} times")
        flow_limits = md_own is not None and md_base is not None and md_own < md_base
        parts.append(f"The CFD-DEM's two halves of the window differ by {md_halves:.3g}: the "
                     f"model's error is {scale} the reference's own variability"
                     + ("." if md <= md_halves else
                        "; the rest is the flow's change since the fitting window." if flow_limits
                        else "; the difference is the model's."))
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
    cluster = summary.get("cluster_index") or {}
    c_ref = finite_or_none((cluster.get("reference") or {}).get("mean"))
    c_mod = finite_or_none((cluster.get("model") or {}).get("mean"))
    if c_ref is not None and c_mod is not None:
        parts.append(f"Cluster index of the snapshots (1: independent particles): CFD-DEM "
                     f"{c_ref:.3g}, model {c_mod:.3g}.")
    model = summary.get("model") or {}
    ref = summary.get("reference") or {}
    interval = model.get("rt_mean_interval")
    if interval and finite_or_none(ref.get("rt_mean")) is not None:
        inside = interval[0] <= ref["rt_mean"] <= interval[1]
        level = 100 * float(summary.get("level", 0.9))
        own = model.get("model_rt_mean_interval")
        # one precision for the value and its interval (ms): "0.400 s lies outside
        # 0.229-0.398 s", not "0.4 s"
        parts.append(f"The CFD-DEM's E(RT) {ref['rt_mean']:.3f} s lies "
                     f"{'inside' if inside else 'outside'} the model's {level:g} % interval "
                     f"{interval[0]:.3f}-{interval[1]:.3f} s"
                     + (f" (with the flow's variability between windows; the model's own "
                        f"value: {own[0]:.3f}-{own[1]:.3f} s)." if own else "."))
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


def computing_blocks(cases: list[Case]) -> list:
    """Computing times of the CFD-DEM and the MCM (the paper's §3.1).

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`; empty when there
        is nothing to say).

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Section 3.1.
    """
    header = ["U (m/s)", "CFD-DEM, predict window (wall)", "CFD-DEM run (wall / simulated)",
              "CFD-DEM particle-steps/s", "Estimator", "MCM fit (wall)", "MCM predict (wall)",
              "MCM fit + predict", "CFD-DEM / MCM"]
    rows, ratios = [], []
    for c in cases:
        if not c.complete:
            continue
        t = c.timings
        cfd = t.get("cfd_dem") if isinstance(t.get("cfd_dem"), dict) else {}
        window_wall = finite_or_none(cfd.get("predict_window_wall_s"))
        window_text = duration_text(window_wall)
        if window_wall is not None and cfd.get("predict_window_estimated"):
            window_text += " (estimated)"
        wall, simulated = finite_or_none(cfd.get("wall_s")), finite_or_none(cfd.get("simulated_s"))
        run_text = (f"{duration_text(wall)} / {simulated:g} s" if wall is not None
                    and simulated is not None else "n/a")
        particles = finite_or_none(cfd.get("particles"))
        rate = "n/a"
        if particles and simulated and wall and wall > 0:
            steps = simulated / float(c.config.numerics.dem_time_step)
            rate = f"{particles * steps / wall:.3g}"
        for e in c.finished:
            fit = finite_or_none((t.get(f"fit-{e.name}") or {}).get("wall_s")
                          if isinstance(t.get(f"fit-{e.name}"), dict) else None)
            pred = finite_or_none((t.get(f"predict-{e.name}") or {}).get("wall_s")
                           if isinstance(t.get(f"predict-{e.name}"), dict) else None)
            total = fit + pred if fit is not None and pred is not None else None
            ratio = window_wall / total if window_wall is not None and total else None
            if ratio is not None:
                ratios.append(ratio)
            rows.append([f"{c.velocity:g}", window_text, run_text, rate, e.name, duration_text(fit),
                         duration_text(pred), duration_text(total), number_text(ratio, ".3g")])
    rows.append(["paper (3–8)", f"about {duration_text(PAPER_CFD_DEM_S)} (5 s, 27000 particles)",
                 "—", "—", "MCM", "—", "—", f"about {duration_text(PAPER_MCM_S)}",
                 f"about {PAPER_SPEEDUP:g}"])
    notes = ["Wall times as recorded in each case's timings.json ('n/a' where not recorded); "
             "'estimated' marks a CFD-DEM time for the predict window extrapolated from a "
             "shorter run.",
             "Particle-steps/s = particles x (simulated time / DEM time step) / wall time of the "
             "CFD-DEM run."]
    blocks = [Heading(2, "Computing time (paper §3.1)"), Table(header, rows, notes)]
    if ratios:
        blocks.append(Para(
            f"Over the predict window the MCM (fit + predict) is {min(ratios):.3g} to "
            f"{max(ratios):.3g} times faster than the CFD-DEM (paper: about "
            f"{PAPER_SPEEDUP:g} times, 50 h against 30 min)."))
    else:
        blocks.append(Para("No speed-up can be given: the wall times of the CFD-DEM over the "
                            "predict window or of the MCM were not recorded."))
    return blocks


def warning_blocks(cases: list[Case], notes: list[str]) -> list:
    """The warnings of the compare summaries and the report's own notes.

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.
    notes : list of str
        The report's own notes.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`; empty when there
        is nothing to say).
    """
    items = []
    for c in cases:
        for e in c.finished:
            for w in e.summary.get("warnings") or []:
                items.append(f"{c.name} / {e.name}: {w}")
    items += [f"report: {n}" for n in notes]
    return [Heading(2, "Warnings"),
            Bullets(items) if items else Para("No warnings from the comparisons.")]


__all__ = ["DEFAULT_BIN_WIDTH", "PAPER_TABLE3", "computing_blocks", "header_blocks",
           "not_finished_blocks", "paper_row", "shared_text", "table3_blocks", "warning_blocks",
           "window_text"]
