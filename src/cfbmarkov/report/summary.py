"""The report's opening: its verdict, the operating conditions and the physics checks.

:func:`summary_blocks` writes, from the run's numbers, the verdict in one sentence (the
models against the persistence baseline by the one rule of Table 3, the paper's estimator
against the paper's largest E(RT) miss, the physics checks passed or failed, the next step),
then the comparison with the paper's Table 3, where the models beat the persistence baseline
and where not (and why), what was run and at what scale with the paper's citation, why the
windows and lags differ per case and how developed the flow is at the fitting window, and
what the scale cannot show;
:func:`conditions_blocks` the operating conditions of each case and the physics checks
(:func:`physics_checks`) stated as passed or failed against what a riser should show.

References
----------
Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Section 3 and Table 3;
docs/definitions.md, sections "riser", "residence time" and "Baseline and natural
variability".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cfbmarkov.analysis.reproduction import operating_point, wall_core_contrast
from cfbmarkov.config import ParticleConfig, RiserConfig
from cfbmarkov.report.document import Bullets, Heading, Para, Table, finite_or_none, link
from cfbmarkov.report.run_folder import Case
from cfbmarkov.report.sections import PAPER_TABLE3
from cfbmarkov.report.table3 import (BASELINE_RULE_SHORT, SAMPLING_ONLY, baseline_clause,
                                     baseline_judgement, baseline_outcomes, baseline_step,
                                     leaves_out_the_flow, reference_place)

CITATION = ("Y. Zhuang, Markov Chain Based Statistic Model for Predicting Particle Movement "
            "in Circulating Fluidized Bed (CFB) Risers, Processes 13(3), 614 (2025), "
            "doi:10.3390/pr13030614")
SUMMARY_HEADING = "Summary"
CONDITIONS_HEADING = "Operating conditions and physics checks"
#: the largest relative difference of the solids' mean vertical velocity between the fitting
#: and the predict window for which the flow counts as developed at the fitting window
DEVELOPED = 0.10
#: the estimator the paper used
PAPER_ESTIMATOR = "paper"


@dataclass
class PhysicsCheck:
    """One expectation on the CFD-DEM's physics and whether the run meets it.

    Attributes
    ----------
    name : str
        What is checked, e.g. "E(RT) falls as U rises".
    passed : bool or None
        Whether the run meets it; None when it cannot be judged (e.g. one finished case).
    evidence : str
        The numbers it was judged on.
    """

    name: str
    passed: bool | None
    evidence: str

    @property
    def verdict(self) -> str:
        """"passed", "failed" or "not judged"."""
        return {True: "passed", False: "failed", None: "not judged"}[self.passed]


def _u(case: Case) -> str:
    return f"{case.velocity:g}" if math.isfinite(case.velocity) else case.name


def physics_checks(done: list[Case], measures: dict) -> list[PhysicsCheck]:
    """The physics checks of the CFD-DEM, judged from the run's numbers.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.

    Returns
    -------
    list of PhysicsCheck
        "E(RT) falls as U rises" (the CFD-DEM's mean residence time from the net solids
        flux over the predict windows, falling from each velocity to the next: the paper's
        Fig. 8) and
        "core-annulus structure" (at every velocity the wall layers, the outer sixth of the
        riser on each side, hold more solids than the core:
        :func:`cfbmarkov.analysis.reproduction.wall_core_contrast`).
    """
    # E(RT) from each predict window's net solids flux (Little's law), which the window's
    # length does not censor: the mean of the residences held whole in windows of 1 and
    # 1.5 s leaves out the long ones, and rose from 3 to 4 m/s where the flux's fell
    means = [(c, getattr(measures[c.name], "flux_rt_mean", math.nan)) for c in done]
    finite = [(c, m) for c, m in means if math.isfinite(m) and m > 0]
    trend = ", ".join(f"{m:.3f} s at {_u(c)} m/s" for c, m in finite)
    basis = ("E(RT) from the net solids flux over each predict window (particle-time over "
             "net passes, which the window's length does not censor): ")
    if len(finite) < 2:
        fall = PhysicsCheck("E(RT) of the CFD-DEM falls as U rises", None,
                            f"fewer than two cases with a mean residence time from the net "
                            f"solids flux ({trend or 'none'})")
    else:
        rises = [f"{_u(a)} -> {_u(b)} m/s ({ma:.3f} -> {mb:.3f} s)"
                 for (a, ma), (b, mb) in zip(finite, finite[1:]) if mb >= ma]
        fall = PhysicsCheck("E(RT) of the CFD-DEM falls as U rises", not rises,
                            basis + trend + ("" if not rises else "; it does not fall from "
                                             + ", ".join(rises)))
    parts, dense_core = [], []
    for c in done:
        m = measures[c.name]
        wall, core, v_wall, v_core = wall_core_contrast(m.solids_fraction, m.solids_velocity)
        velocity = (f", vertical velocity wall/core {v_wall:+.2f}/{v_core:+.2f} m/s"
                    if math.isfinite(v_wall) and math.isfinite(v_core) else "")
        parts.append(f"{_u(c)} m/s: solids fraction wall/core {wall:.3g}/{core:.3g}{velocity}")
        if not (math.isfinite(wall) and math.isfinite(core) and wall > core):
            dense_core.append(f"{_u(c)} m/s")
    annulus = PhysicsCheck(
        "core-annulus structure (wall layers denser than the core)", not dense_core if done
        else None, "; ".join(parts) + (f"; the core is as dense or denser at "
                                       f"{', '.join(dense_core)}" if dense_core else ""))
    return [fall, annulus]


def _rows(cases: list[Case]):
    """(case, estimator, summary) of every finished comparison."""
    for c in cases:
        for e in c.finished:
            if e.summary is not None and not c.problems:
                yield c, e.name, e.summary


def _and(names: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _signed(values: list[tuple[str, float]], unit: str = " %") -> str:
    # whole percent, one decimal below 10 % (so that +0.46 % does not read "+0 %")
    return ", ".join(f"{v:+.0f}{unit} at {u} m/s" if abs(v) >= 10 else
                     f"{v:+.1f}{unit} at {u} m/s" for u, v in values)


def _paper_sentences(cases: list[Case]) -> list[str]:
    """The headline comparison with the paper's Table 3, from the paper estimator's rows."""
    rows = [(c, s) for c, name, s in _rows(cases) if name == PAPER_ESTIMATOR]
    if not rows:
        return ["No finished comparison of the paper's estimator: no comparison with the "
                "paper's Table 3 can be made."]
    pd_e = [(_u(c), v) for c, s in rows if (v := finite_or_none(s.get("pd_rt_mean"))) is not None]
    pd_sd = [(_u(c), v) for c, s in rows if (v := finite_or_none(s.get("pd_rt_sd"))) is not None]
    paper_e = [float(v[0]) for v in PAPER_TABLE3.values()]
    paper_sd = [float(v[1]) for v in PAPER_TABLE3.values()]
    out = []
    if pd_e:
        out.append(
            f"The paper's estimator misses the CFD-DEM's mean residence time E(RT) by "
            f"{_signed(pd_e)} (the paper: {min(paper_e):+.2f} to {max(paper_e):+.2f} %).")
    if pd_sd:
        narrower = [u for u, v in pd_sd if v < 0]
        out.append(
            f"Its spread SD(RT) differs by {_signed(pd_sd)}; it is narrower than the "
            f"CFD-DEM's in {len(narrower)} of {len(pd_sd)} cases (the paper: narrower at all "
            f"four velocities, by {-max(paper_sd):.0f} to {-min(paper_sd):.0f} %).")
    return out


def _paper_clause(cases: list[Case]) -> str | None:
    """The headline's comparison with the paper: in how many cases the paper's estimator
    misses E(RT) by no more than the paper's largest miss."""
    rows = [(c, v) for c, name, s in _rows(cases) if name == PAPER_ESTIMATOR
            and (v := finite_or_none(s.get("pd_rt_mean"))) is not None]
    if not rows:
        return None
    worst_paper = max(abs(float(v[0])) for v in PAPER_TABLE3.values())
    within = [_u(c) for c, v in rows if abs(v) <= worst_paper]
    if len(within) == len(rows):
        return (f"the paper's estimator is as close to the CFD-DEM's E(RT) as the paper's "
                f"(within its largest miss, {worst_paper:.2f} %) in "
                + ("its one case" if len(rows) == 1 else f"all {len(rows)} cases"))
    return (f"the paper's estimator is within the paper's largest E(RT) miss "
            f"({worst_paper:.2f} %) in {len(within)} of {len(rows)} cases"
            + (f" ({', '.join(within)} m/s)" if within else ""))


def _baseline_sentences(cases: list[Case]) -> list[str]:
    """Where the models beat the persistence baseline and where not, and why, by the one rule
    of Table 3 (:func:`cfbmarkov.report.table3.baseline_judgement`); each velocity's
    baseline MD and halves' MD once."""
    beat, total = [], 0
    # per velocity: the baseline's MD, and the models not beating it grouped by reason
    why: dict[str, tuple[float, dict[str, list[str]]]] = {}
    for c, name, s in _rows(cases):
        j = baseline_judgement(s)
        if j is None:
            continue
        total += 1
        alone = (" (by the tie margin alone: the CFD-DEM's halves hold no residence)"
                 if j.by_tie_margin_alone else "")
        if j.outcome == "beats":
            beat.append(f"{name} at {_u(c)} m/s{alone}")
            continue
        md_own = finite_or_none((s.get("model_on_fitting_window") or {}).get("md_rtd"))
        if j.outcome == "tie":
            reason = f"a tie (within {100 * j.tie:g} %)"
        elif j.outcome == "not told apart":
            reason = (f"not told apart (gaps within the CFD-DEM's own variability, its halves "
                      f"differ by {j.md_halves:.3g})")
        elif md_own is not None and md_own < j.md_base:
            reason = ("worse: the flow changed between the windows (on its fitting window the "
                      f"model is {md_own:.3g} from the CFD-DEM, nearer than the baseline on "
                      "the predict window)")
        else:
            reason = ("worse: the model's own error" + (f" ({md_own:.3g} already on its "
                                                         "fitting window)"
                                                         if md_own is not None else ""))
        reason += alone
        reasons = why.setdefault(_u(c), (j.md_base, {}))[1]
        reasons.setdefault(reason, []).append(f"{name} {j.md:.4g}")
    if not total:
        return ["No comparison has a persistence baseline (the fitting window is not in the "
                "reference file): whether a model beats simply reusing the fitting window's "
                "RTD cannot be said."]
    # the count of each outcome is the verdict line's (:func:`headline`): here the pairs by
    # name, with the rule and the reasons
    out = ["The persistence baseline (the CFD-DEM's RTD of the fitting window reused as the "
           "prediction; distance MD) is beaten, by the rule of Table 3 "
           f"({BASELINE_RULE_SHORT}), by " + (_and(beat) if beat else "none of the models")
           + "."]
    if why:
        out.append("Not beating it, and why (each model's MD): " + " ".join(
            f"At {u} m/s, against the baseline's {base:.4g}: " + "; ".join(
                f"{_and(names)} {reason}" for reason, names in reasons.items()) + "."
            for u, (base, reasons) in why.items()))
    return out


def baseline_counts(cases: list[Case]) -> dict[str, int]:
    """How many velocity-model pairs have each outcome of the baseline rule.

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run.

    Returns
    -------
    dict of str to int
        Keys "beats", "loses", "tie", "not told apart"
        (:func:`cfbmarkov.analysis.baseline.judge_baseline`).
    """
    return baseline_outcomes(s for _, _, s in _rows(cases))


def _interval_sentence(cases: list[Case]) -> str | None:
    """How often the CFD-DEM's E(RT), and its SD(RT), lie inside the model's intervals."""
    inside, sd_inside, total, sd_total, level = [], [], 0, 0, None
    apart, sd_apart = [], []
    sampling_only = 0
    for c, name, s in _rows(cases):
        place = reference_place(s)
        if place is None:
            continue
        total += 1
        sampling_only += leaves_out_the_flow(s)
        level = 100 * float(s.get("level") or 0.9)
        {"inside": inside, "not told apart": apart}.get(place, []).append(
            f"{name} at {_u(c)} m/s")
        sd_place = reference_place(s, "rt_sd")
        if sd_place is not None:
            sd_total += 1
            {"inside": sd_inside, "not told apart": sd_apart}.get(sd_place, []).append(
                f"{name} at {_u(c)} m/s")
    if not total:
        return None

    def apart_text(which: list, figure: str) -> str:
        return (f" In {len(which)} more ({', '.join(which)}) its {figure} lies outside, but "
                "within its own sampling of the interval, which that interval leaves out: "
                "not told apart." if which else "")

    sd_text = (f" Its SD(RT) lies inside the model's SD(RT) interval in {len(sd_inside)} of "
               f"{sd_total}" + (f" ({', '.join(sd_inside)})." if sd_inside else ".")
               + apart_text(sd_apart, "SD(RT)")
               if sd_total else "")
    return (f"The CFD-DEM's E(RT) lies inside the model's {level:g} % interval in "
            f"{len(inside)} of {total} velocity-model pairs"
            + (f" ({', '.join(inside)})." if inside else ".") + apart_text(apart, "E(RT)")
            + sd_text
            + (f" {sampling_only} of the {total} intervals leave out the flow's variability "
               f"between windows (marked {SAMPLING_ONLY} in Table 3)." if sampling_only else "")
            + _too_narrow(total and len(inside) + len(apart) < 0.5 * total,
                          sd_total and len(sd_inside) + len(sd_apart) < 0.5 * sd_total))


def _kinetics_sentence(done: list[Case]) -> str | None:
    """The properties along the paths (a run with a kinetics file) in one sentence: for
    each property, in how many comparisons the chain's exit mean is at least as close to
    the CFD-DEM's as the segregated-flow baseline's, as the section on them counts it
    (:func:`cfbmarkov.report.kinetics_section.verdict_sentence`); None without kinetics."""
    from cfbmarkov.report.kinetics_section import HEADING, collect_rows

    counts = []
    for name, rows in collect_rows(done).items():
        judged = [r for r in rows if r.chain_error is not None and r.baseline_error is not None]
        if judged:
            beats = sum(abs(r.chain_error) <= abs(r.baseline_error) for r in judged)
            counts.append(f"{name} in {beats} of {len(judged)}")
    if not counts:
        return None
    return ("Along the particle paths (the kinetics file), the chain's exit mean is at least "
            "as close to the CFD-DEM's as the segregated-flow baseline's (the property as a "
            "function of residence time alone) for " + "; ".join(counts)
            + f" comparisons ({link(HEADING.lower(), HEADING)}).")


def _too_narrow(mean_missed: bool, sd_missed: bool) -> str:
    """The remark on intervals that miss the CFD-DEM in most pairs, naming which figure's."""
    which = ("E(RT) and SD(RT)" if mean_missed and sd_missed else
             "E(RT)" if mean_missed else "SD(RT)" if sd_missed else "")
    if not which:
        return ""
    return (f" {which} intervals that miss it this often are too narrow to cover the models' "
            "structural error (they hold the Monte Carlo noise and the fitting window's "
            "sampling).")


def _cannot_show(meta: dict, done: list[Case], checks: list[PhysicsCheck]) -> list[str]:
    """What the scale of the run cannot show of what the paper shows, from its settings and
    its checks."""
    if meta.get("scale") == "paper" or not done:
        return []
    paper_riser, paper_particles = RiserConfig(), ParticleConfig()
    out = []
    risers = {(c.config.riser.width, c.config.riser.height, c.config.particles.number)
              for c in done}
    w, h, n = sorted(risers)[0]
    if len(risers) == 1 and h < paper_riser.height:
        out.append(f"The paper's residence times in seconds: the riser is {w:g} m x {h:g} m "
                   f"with {n} particles (the paper's {paper_riser.width:g} m x "
                   f"{paper_riser.height:g} m with {paper_particles.number}), so a particle "
                   "crosses it sooner; compare the percentage differences, not the seconds.")
    elif len(risers) == 1 and n != paper_particles.number:
        out.append(f"The paper's flow in full: {n} particles instead of the paper's "
                   f"{paper_particles.number} in a {w:g} m x {h:g} m riser; compare the "
                   "percentage differences, not the flow itself.")
    windows = {c.name: (tuple(c.config.markov.predict_window), c.config.markov.lag)
               for c in done}
    if len(set(windows.values())) > 1:
        # which windows and lags: the operating conditions' table, linked
        differ = " and ".join(k for k, n in (("predict windows", {w for w, _ in
                                                                   windows.values()}),
                                              ("lags", {t for _, t in windows.values()}))
                              if len(n) > 1)
        out.append(f"A trend with U alone: the cases differ in more than U (their {differ}, "
                   f"{link('operating conditions', CONDITIONS_HEADING)}), so a trend across "
                   "them mixes U with the time since the start and the lag.")
    for check in checks:
        if check.passed is False:
            out.append(f"The check \"{check.name}\", which the paper's riser passes; this "
                       f"run's CFD-DEM fails it ({link('the numbers', CONDITIONS_HEADING)}).")
    return out


def _run_text(done: list[Case]) -> str:
    """' (the CFD-DEM run from rest 0-4.5 s at 3, 4 m/s, 0-3 s at 6, 8 m/s)': how long the
    finished cases ran, from their settings (their riser, particles, windows and lag are in
    the operating conditions)."""
    if not done:
        return ""
    runs: dict[str, list[str]] = {}
    for c in done:
        end = float(c.config.output.end_time)
        runs.setdefault(f"0-{end:g} s", []).append(_u(c))
    text = ", ".join(f"{span} at {', '.join(us)} m/s" for span, us in runs.items())
    return f"the CFD-DEM run from rest {text}"


def windows_text(done: list[Case], measures: dict) -> str | None:
    """Why the cases' windows and lags differ, and how developed the flow is at the fitting
    window, from the case data.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        Their recomputed numbers (``reference.rt.mean``, ``development``).

    Returns
    -------
    str or None
        None without a finished case.
    """
    if not done:
        return None
    settings = {(tuple(c.config.markov.fit_window), tuple(c.config.markov.predict_window),
                 c.config.markov.lag) for c in done}
    out = []
    if len(settings) > 1:
        spans = []
        for c in done:
            mean = finite_or_none(measures[c.name].reference.rt.mean)
            if mean is not None:
                spans.append(f"{mean / c.config.markov.lag:.0f} lags at {_u(c)} m/s")
        out.append("The windows and lags differ per case ("
                   + link("operating conditions", CONDITIONS_HEADING) + "): a riser started "
                   "from rest takes a time that depends on U to develop its flow, and the "
                   "windows lie after it; the faster the solids, the shorter their residence "
                   "times, so the lag and the RTD bins shrink with U to keep a mean residence "
                   "time many lags long"
                   + (f" (the CFD-DEM's E(RT) is {', '.join(spans)})." if spans else "."))
    flows, changing = [], []
    for c in done:
        d = getattr(measures[c.name], "development", None) or {}
        before, fit, predict = (finite_or_none(d.get(k)) for k in ("before", "fit", "predict"))
        if fit is None or predict is None:
            continue
        values = " / ".join("n/a" if v is None else f"{v:+.2f}" for v in (before, fit, predict))
        off = abs(fit - predict) / abs(predict) if abs(predict) > 1e-9 else math.nan
        flows.append(f"{_u(c)} m/s {values} m/s"
                     + (f" ({100 * off:.0f} %)" if math.isfinite(off) else ""))
        if not off <= DEVELOPED:
            changing.append(f"{_u(c)} m/s")
    if flows:
        out.append("How developed the flow is at the fitting window: the CFD-DEM's mean "
                   "vertical solids velocity before the fitting window / over it / over the "
                   "predict window (the fitting window's difference from the predict "
                   "window's): " + "; ".join(flows) + ". "
                   + (f"The flow was still changing when the model was fitted (more than "
                      f"{100 * DEVELOPED:.0f} %) at {', '.join(changing)}." if changing else
                      f"At every velocity the fitting window's lies within "
                      f"{100 * DEVELOPED:.0f} % of the predict window's."))
    return " ".join(out) or None


def headline(meta: dict, cases: list[Case], checks: list[PhysicsCheck]) -> str:
    """The report's verdict in one line, with the next step, written from the numbers.

    Parameters
    ----------
    meta : dict
        The run's ``reproduce.json`` (its ``scale``).
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run.
    checks : list of PhysicsCheck
        The physics checks (:func:`physics_checks`).

    Returns
    -------
    str
        "Verdict at the ... scale: ..." naming how many velocity-model pairs beat the
        persistence baseline by the report's one rule
        (:func:`cfbmarkov.analysis.baseline.judge_baseline`), in how many cases the paper's
        estimator misses E(RT) by no more than the paper's largest miss, each physics check
        passed or failed (its numbers linked, not repeated), and the next step.
    """
    scale = meta.get("scale", "n/a")
    counts = baseline_counts(cases)
    parts = []
    clause = baseline_clause(counts)
    if clause:
        parts.append(clause)
    paper = _paper_clause(cases)
    if paper:
        parts.append(paper)
    failed = [c.name for c in checks if c.passed is False]
    if checks:
        # passed or failed, each; their numbers once, in the physics checks, linked
        parts.append(f"physics checks of the CFD-DEM ({link('evidence', CONDITIONS_HEADING)}): "
                     + "; ".join(f"{c.name}: {c.verdict.upper()}" for c in checks))
    text = "Verdict at the " + scale + " scale: " + ("; ".join(parts) or "nothing finished to "
                                                     "judge") + "."
    if failed and scale != "paper":
        step = ("the numbers test the pipeline, not the method: judge the method on the "
                "paper's scale (cfbmarkov reproduce --scale paper, hours), where the paper's "
                "flow shows what these checks expect")
    elif failed:
        step = ("check the CFD-DEM's settings against the paper's before reading the models' "
                "errors as the method's")
    else:
        step = baseline_step(counts)
    return text + " Next step: " + step + "."


def summary_blocks(meta: dict, cases: list[Case], done: list[Case], measures: dict,
                   estimators: list[str], checks: list[PhysicsCheck]) -> list:
    """The report's opening section: the verdict (:func:`headline`), its details, what was
    run, why the windows differ (:func:`windows_text`), what the scale cannot show. Each
    number is said once: the physics checks' evidence and each case's windows and lag are
    left to :func:`conditions_blocks`, linked.

    Parameters
    ----------
    meta : dict
        The run's ``reproduce.json``.
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.
    estimators : list of str
        The estimators of the run, in report order.
    checks : list of PhysicsCheck
        The physics checks (:func:`physics_checks`).

    Returns
    -------
    list
        Document blocks (:mod:`cfbmarkov.report.document`).
    """
    scale = meta.get("scale", "n/a")
    velocities = ", ".join(_u(c) for c in cases)
    run = _run_text(done)
    ran = (f"What was run: {CITATION}, Section 3, at the {scale} scale"
           + (f", {run}" if run else "") + f" (each case's riser, particles, windows and lag: "
           f"{link('operating conditions', CONDITIONS_HEADING)}). Cases at U = {velocities} "
           f"m/s, {len(done)} of {len(cases)} finished; models: {', '.join(estimators) or 'none'}"
           ", each fitted on the CFD-DEM's fitting window and compared with the CFD-DEM on "
           "the predict window that follows.")
    verdict = _paper_sentences(cases) + _baseline_sentences(cases)
    interval = _interval_sentence(cases)
    if interval:
        verdict.append(interval)
    reactions = _kinetics_sentence(done)
    if reactions:
        verdict.append(reactions)
    blocks = [Heading(2, SUMMARY_HEADING), Para(headline(meta, cases, checks), css="verdict"),
              Bullets(verdict), Para(ran)]
    windows = windows_text(done, measures)
    if windows:
        blocks.append(Para(windows))
    limits = _cannot_show(meta, done, checks)
    if limits:
        blocks += [Heading(3, f"What the {scale} scale cannot show"), Bullets(limits)]
    return blocks


def conditions_blocks(done: list[Case], measures: dict, checks: list[PhysicsCheck]) -> list:
    """The operating conditions of each finished case and the physics checks.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.
    checks : list of PhysicsCheck
        The physics checks (:func:`physics_checks`).

    Returns
    -------
    list
        Document blocks (:mod:`cfbmarkov.report.document`).
    """
    header = ["U (m/s)", "Particles", "Riser W x H (m)", "Solids hold-up, set / CFD-DEM (%)",
              "Solids flux G_s (kg/m²s)", "Fit / predict window (s)", "Lag (s)"]
    rows = []
    for c in done:
        point = operating_point(c.config, measures[c.name])
        m = c.config.markov
        flux = "n/a" if not math.isfinite(point.solids_flux) else f"{point.solids_flux:+.3g}"
        rows.append([_u(c), f"{point.particles} x {1000 * point.diameter:g} mm, "
                            f"{point.density:g} kg/m³",
                     f"{c.config.riser.width:g} x {c.config.riser.height:g}",
                     f"{100 * point.hold_up:.3g} / {100 * point.measured_hold_up:.3g}", flux,
                     f"{m.fit_window[0]:g}-{m.fit_window[1]:g} / "
                     f"{m.predict_window[0]:g}-{m.predict_window[1]:g}", f"{m.lag:g}"])
    notes = ["Hold-up: solids volume over the riser's, pseudo-2D (one particle diameter "
             "thick); set from the particles, and as the CFD-DEM holds it over the predict "
             "window. G_s: the CFD-DEM's net vertical solids mass flux over the predict window "
             "and the cross-section, positive upward (rho_p times the mean of solids fraction "
             "x vertical velocity across the riser)."]
    advisory = _time_step_text(done)
    if advisory:
        notes.append(advisory)
    items = [f"{c.name}: {c.verdict.upper()} ({c.evidence})." for c in checks]
    return [Heading(2, CONDITIONS_HEADING), Table(header, rows, notes),
            Heading(3, "Physics checks"), Bullets(items)]


def _time_step_text(done: list[Case]) -> str | None:
    """The DEM time step's resolution of a contact, once for the run, when it is below the
    recommended 10 steps."""
    from cfbmarkov.simulate.dem.law import ContactLaw, contact_resolution

    from cfbmarkov.config import ContactConfig, NumericsConfig

    def steps(contact, particles, time_step) -> tuple[float, str]:
        law = ContactLaw.from_config(contact, particles.diameter, particles.density)
        return contact_resolution(law, law.mass, time_step)

    texts: dict[str, list[str]] = {}
    for c in done:
        worst, message = steps(c.config.contact, c.config.particles,
                               c.config.numerics.dem_time_step)
        if worst < 10:
            texts.setdefault(message, []).append(c.name)
    if not texts:
        return None
    paper, _ = steps(ContactConfig(), ParticleConfig(), NumericsConfig().dem_time_step)
    return ("; ".join(m + ("" if len(names) == len(done) else f" ({', '.join(names)})")
                      for m, names in texts.items())
            + (" in every case" if all(len(n) == len(done) for n in texts.values()) else "")
            + f": fewer than the 10 steps recommended, as the paper's own settings give "
            f"({paper:.2f} steps); a property of the run's scale, said once here.")


__all__ = ["CITATION", "CONDITIONS_HEADING", "PhysicsCheck", "SUMMARY_HEADING",
           "baseline_counts", "conditions_blocks", "headline",
           "windows_text", "physics_checks", "summary_blocks"]
