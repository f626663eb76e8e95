"""The report's sections of text and tables: the run, the unfinished cases, the paper's
Table 3 values, computing time and warnings (Table 3 itself: :mod:`cfbmarkov.report.table3`). Each builder
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
    """The run: scale, cases, cells, estimators, version (the riser, particles, windows and
    lag of each case are in the operating conditions,
    :func:`cfbmarkov.report.summary.conditions_blocks`).

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
    description = _without_brackets(meta.get("description") or "")
    items = [
        f"Scale: {meta.get('scale', 'n/a')}" + (f", {description}" if description else ""),
        "Cases: " + ", ".join(f"{c.name} ({c.label})" for c in cases)
        + f" — {len(done)} finished" + (f", {len(pending)} not finished ("
                                         + ", ".join(c.name for c in pending) + ")"
                                         if pending else ""),
        "Cells: " + shared_text({n: f"{c.markov.columns} columns x {c.markov.rows} rows"
                             for n, c in cfg.items()}),
        "Estimators: " + (", ".join(estimators) or "none"),
        f"cfbmarkov version: {__version__}"
        + (f" (pipeline recorded {meta['version']})" if meta.get("version") not in (None, "")
           else ""),
    ]
    return [Heading(2, "Reproduction"), Bullets(items)]


def _without_brackets(text: str) -> str:
    """``text`` less its bracketed asides (a scale's settings, which the operating
    conditions give case by case)."""
    depth, out = 0, []
    for ch in text:
        depth += ch == "("
        if not depth:
            out.append(ch)
        depth -= ch == ")" and depth > 0
    return " ".join("".join(out).split())


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
    """The warnings of the compare summaries and the report's own notes, each once.

    A warning that several comparisons give in the same words is listed once, followed by
    the comparisons that gave it.

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
    given: dict[str, list[str]] = {}
    compared = 0
    for c in cases:
        for e in c.finished:
            compared += 1
            for w in dict.fromkeys(e.summary.get("warnings") or []):
                given.setdefault(w, []).append(f"{c.name} / {e.name}")
    items = [f"{w} ({'every comparison' if len(where) == compared > 1 else ', '.join(where)})"
             for w, where in given.items()]
    items += [f"report: {n}" for n in dict.fromkeys(notes)]
    return [Heading(2, "Warnings"),
            Bullets(items) if items else Para("No warnings from the comparisons.")]

__all__ = ["DEFAULT_BIN_WIDTH", "PAPER_TABLE3", "computing_blocks", "header_blocks",
           "not_finished_blocks", "paper_row", "shared_text", "warning_blocks",
           "window_text"]
