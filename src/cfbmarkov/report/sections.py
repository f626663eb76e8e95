"""The report's sections of text and tables: the run, the unfinished cases, the paper's
Table 3 values, computing time and warnings (Table 3 itself: :mod:`cfbmarkov.report.table3`). Each builder
returns document blocks (:mod:`cfbmarkov.report.document`).

References
----------
docs/definitions.md, sections "residence time" (PD, Minkowski distance, Eq. 9) and "mixing".
"""

from __future__ import annotations

import math

from cfbmarkov.report.document import (
    Bullets,
    Heading,
    Para,
    Table,
    duration_text,
    finite_or_none,
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


def ensemble_text(meta: dict) -> str:
    """The header's line on the CFD-DEM runs per case (``reproduce --ensemble N``).

    Parameters
    ----------
    meta : dict
        The run's ``reproduce.json``.

    Returns
    -------
    str
        One line naming N (1 where the manifest does not say).
    """
    n = meta.get("ensemble", 1)
    n = n if isinstance(n, int) and n >= 1 else 1
    if n == 1:
        return "CFD-DEM runs per case: 1"
    return (f"CFD-DEM runs per case: {n} (an ensemble, on the {meta.get('device', 'cpu')}; "
            f"each model fitted on the {n} runs' fitting windows pooled and compared on "
            "member 0's prediction window, cfd-dem-m0.h5)")


def command_text(meta: dict, cases: list[Case], root) -> str:
    """The ``cfbmarkov reproduce`` command that makes this run folder again, from its
    ``reproduce.json`` and its cases.

    Parameters
    ----------
    meta : dict
        The run's ``reproduce.json``.
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run (their velocities U).
    root : path-like
        The run folder.

    Returns
    -------
    str
        One shell line; the changes of ``--overrides`` follow it as TOML-like text (the
        file itself is not kept).
    """
    import math
    import shlex
    from pathlib import Path

    words = ["cfbmarkov", "reproduce", "--scale", str(meta.get("scale", "quick"))]
    velocities = [c.velocity for c in cases if math.isfinite(c.velocity)]
    if velocities and len(velocities) == len(cases):
        words += ["--velocities", ",".join(f"{u:g}" for u in velocities)]
    models = [m for m in meta.get("models") or [] if isinstance(m, str)]
    if models:
        words += ["--models", ",".join(models)]
    kinetics = meta.get("kinetics")
    if isinstance(kinetics, dict) and isinstance(kinetics.get("file"), str):
        words += ["--kinetics", kinetics["file"]]
    ensemble = meta.get("ensemble", 1)
    if isinstance(ensemble, int) and ensemble > 1:
        words += ["--ensemble", str(ensemble)]
    if meta.get("device", "cpu") not in ("cpu", None):
        words += ["--device", str(meta["device"])]
    overrides = meta.get("overrides")
    if overrides:
        words += ["--overrides", "OVERRIDES.toml"]
    words += ["-o", Path(root).name]         # the folder as named from its parent
    text = " ".join(shlex.quote(w) for w in words)
    if overrides:
        import json

        text += f" (OVERRIDES.toml holding {json.dumps(overrides, sort_keys=True)})"
    return text


def header_blocks(meta: dict, cases: list[Case], estimators: list[str], root=None) -> list:
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
    root : path-like, optional
        The run folder: the command that makes it again (:func:`command_text`) is listed.

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
        ensemble_text(meta),
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
    if root is not None:
        items.append("Made by: " + command_text(meta, cases, root))
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
    header = ["U (m/s)", "CFD-DEM run: simulated / wall / CPU",
              "CFD-DEM predict window: wall / CPU", "CFD-DEM particle-steps/s (wall)",
              "Estimator", "MCM fit: wall / CPU", "MCM predict: wall / CPU",
              "MCM fit + predict: wall / CPU", "CFD-DEM / MCM: CPU (wall)"]
    rows, ratios, wall_ratios, loads = [], [], [], []
    for c in cases:
        if not c.complete:
            continue
        t = c.timings
        cfd = t.get("cfd_dem") if isinstance(t.get("cfd_dem"), dict) else {}
        window_wall = finite_or_none(cfd.get("predict_window_wall_s"))
        wall, simulated = finite_or_none(cfd.get("wall_s")), finite_or_none(cfd.get("simulated_s"))
        cpu = finite_or_none(cfd.get("cpu_s"))
        start, stop = (float(v) for v in c.config.markov.predict_window)
        # the run's CPU time pro rata over the predict window: CPU time, unlike wall time,
        # does not grow with the machine's load
        window_cpu = (cpu * (stop - start) / simulated if cpu is not None and simulated
                      else None)
        window_text = _pair(window_wall, window_cpu)
        if window_wall is not None and cfd.get("predict_window_estimated"):
            window_text += " (wall estimated)"
        run_text = (f"{simulated:g} s / {_pair(wall, cpu)}" if simulated is not None else "n/a")
        if wall and cpu is not None:
            loads.append((f"{c.velocity:g}", cpu / wall))
        particles = finite_or_none(cfd.get("particles"))
        rate = "n/a"
        if particles and simulated and wall and wall > 0:
            steps = simulated / float(c.config.numerics.dem_time_step)
            rate = f"{particles * steps / wall:.3g}"
        for e in c.finished:
            fit_wall, fit_cpu = _stage(t, f"fit-{e.name}")
            pred_wall, pred_cpu = _stage(t, f"predict-{e.name}")
            total = _sum(fit_wall, pred_wall)
            total_cpu = _sum(fit_cpu, pred_cpu)
            ratio = window_cpu / total_cpu if window_cpu is not None and total_cpu else None
            wall_ratio = window_wall / total if window_wall is not None and total else None
            if ratio is not None:
                ratios.append(ratio)
            if wall_ratio is not None:
                wall_ratios.append(wall_ratio)
            rows.append([f"{c.velocity:g}", run_text, window_text, rate, e.name,
                         _pair(fit_wall, fit_cpu), _pair(pred_wall, pred_cpu),
                         _pair(total, total_cpu),
                         f"{_ratio_text(ratio)} ({_ratio_text(wall_ratio)})"])
    rows.append(["paper (3–8)", f"5 s / about {duration_text(PAPER_CFD_DEM_S)} (27000 "
                 "particles)", "—", "—", "MCM", "—", "—", f"about {duration_text(PAPER_MCM_S)}",
                 f"about {PAPER_SPEEDUP:g}"])
    notes = ["Wall and CPU times as recorded in each case's timings.json ('n/a' where not "
             "recorded). CPU time is the process's own (all its threads), which the machine's "
             "other work does not lengthen; wall time grows with the load. The CFD-DEM's CPU "
             "time over the predict window is the run's, pro rata; its wall time comes from "
             "the run's checkpoint history ('wall estimated': pro rata from a shorter run), "
             "so it differs from the run's share where the load changed during the run.",
             "Particle-steps/s = particles x (simulated time / DEM time step) / wall time of the "
             "CFD-DEM run.",
             "The first fit and predict in a worker process also load (or, without Numba's "
             "cache, compile) the Markov kernels, a one-time cost of seconds; 'auto' fits and "
             "judges several state spaces before it keeps one.",
             "A fit here is the paper's: counting and estimating the chain. The model's "
             "interval (its block bootstrap) and the verdict on its fitting sample, which "
             "`cfbmarkov fit` adds and the paper has no counterpart of, are made after it "
             "and not timed; the ratios compare the paper's steps alone."]
    if loads:
        low = min(loads, key=lambda x: x[1])
        notes.append("The CFD-DEM's CPU time over its wall time: " + ", ".join(
            f"{v:.2f} at {u} m/s" for u, v in loads)
            + (f"; below 1 the process waited for the processor (at {low[0]} m/s it ran "
               f"{100 * low[1]:.0f} % of the time): the machine was loaded, and its wall "
               "times overstate the tool's." if low[1] < 0.8 else "."))
    blocks = [Heading(2, "Computing time (paper §3.1)"), Table(header, rows, notes)]
    if ratios:
        blocks.append(Para(
            f"Over the predict window the MCM (fit + predict) takes {_ratio_text(min(ratios))} to "
            f"{_ratio_text(max(ratios))} times less CPU time than the CFD-DEM (the CFD-DEM's "
            f"CPU time pro rata over the window, against the fit's and the prediction's; on "
            f"wall time {_ratio_text(min(wall_ratios))} to {_ratio_text(max(wall_ratios))} "
            f"times, which the machine's "
            f"load moves). The paper: about {PAPER_SPEEDUP:g} times, 50 h against 30 min, wall "
            "time of its own runs."))
    elif wall_ratios:
        blocks.append(Para(
            f"Over the predict window the MCM (fit + predict) is {_ratio_text(min(wall_ratios))} "
            f"to {_ratio_text(max(wall_ratios))} times faster than the CFD-DEM on wall time "
            f"(no CPU times "
            f"recorded, so the machine's load is in these figures; paper: about "
            f"{PAPER_SPEEDUP:g} times, 50 h against 30 min)."))
    else:
        blocks.append(Para("No speed-up can be given: the wall times of the CFD-DEM over the "
                            "predict window or of the MCM were not recorded."))
    return blocks


def _ratio_text(value) -> str:
    """A speed-up as text: three significant digits below 1000, whole numbers above (not
    1e+03), "n/a" where not finite."""
    v = finite_or_none(value)
    if v is None:
        return "n/a"
    return f"{v:.0f}" if abs(v) >= 999.5 else f"{v:.3g}"


def _stage(timings: dict, key: str) -> tuple[float | None, float | None]:
    """(wall, CPU) seconds of one stage of timings.json, None where not recorded."""
    entry = timings.get(key)
    if not isinstance(entry, dict):
        return None, None
    return finite_or_none(entry.get("wall_s")), finite_or_none(entry.get("cpu_s"))


def _sum(a: float | None, b: float | None) -> float | None:
    return a + b if a is not None and b is not None else None


def _pair(wall: float | None, cpu: float | None) -> str:
    """'3.08 min / 31.2 s': a wall time and a CPU time; the wall time alone without a CPU
    time."""
    return duration_text(wall) if cpu is None else f"{duration_text(wall)} / {duration_text(cpu)}"


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

__all__ = ["DEFAULT_BIN_WIDTH", "PAPER_TABLE3", "command_text", "computing_blocks", "header_blocks",
           "not_finished_blocks", "paper_row", "shared_text", "warning_blocks",
           "window_text"]
