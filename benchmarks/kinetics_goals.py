"""The accuracy goals of kinetics along particle paths: the chain against the segregated-flow
baseline, both judged against the reference's own paths (``docs/kinetics-reference.md``,
The accuracy goals).

    python benchmarks/kinetics_goals.py RUN.h5 [RUN.h5 ...] [--in-sample 10:15]
        [--out-of-sample 10:15,15:20] [--out-of-sample 5:10,10:15] [--damkoehler 0.3,1,3]
        [--cells 6x38] [--lag 0.025] [--estimator paper] [--states cells] [--history S]
        [--json goals.json]

For each run (one per gas velocity) and each pair of windows (fit, judge) -- in sample the
judged window is the fitting window -- a model is fitted on the fitting window, and a
first-order reaction dX/dt = k_s (1 - X) (X = 0 at entry, reset at each entry) is given two
ways at each Damkoehler number Da:

- *uniform*: the same rate k in every cell;
- *zones*: ten times slower in the wall layers (the grid's outer columns,
  :func:`cfbmarkov.kinetics.wall_cells`) than in the core, as in the docs' worked example.

Da = k_bar tau_bar, with tau_bar the mean of the fitting window's observed residence times
(in the same direction, on the model's lag, counted by their exits as below) and k_bar the fitting window's
bed-averaged rate (the state occupancy's mean of k_s, the rate the segregated-flow baseline
uses): the uniform rate is k = Da / tau_bar, and the zone rates are scaled so that their
bed average is the same. The two kinds of rate therefore give the same segregated-flow
answer; the chain tells them apart.

Three exit means of X per residence, the residences counted in the direction of the
judged window's net solids flow (passes up through the top; down through the bottom where
the solids fall on average, as at low gas velocities), by their exits: every residence
that ends inside the window, its path followed back before the window (``--history``,
default the window's length): residences counted by their exits are a fair sample of the
flow's, where those wholly inside a window favour short ones:

- *reference*: X integrated along the run's own paths, on the model's states at its lag
  (:func:`cfbmarkov.analysis.kinetics_reference.reference_kinetics` with ``history``);
- *chain*: the fitted chain's exit mean as the reference observes it, each residence of n
  lags weighted by the number of its exits the judged window holds with the same history,
  min(M, M + H - n) for a window of M lags and a history of H lags
  (:func:`cfbmarkov.markov.kinetics_exact.windowed_exit_means` with ``history``): a window
  and its history cannot see residences longer than M + H lags, on either side; the exact
  exit mean per residence, the tail included
  (:func:`cfbmarkov.markov.kinetics_exact.exact_kinetics`, what ``react`` prints), is
  printed beside it as ``(exact)`` with its error in the JSON (``chain_exact_error``);
- *segregated flow*: the bed-averaged law over the fitting window's observed RTD, the
  residence times of the exits inside the fitting window followed back the same way
  (:func:`cfbmarkov.analysis.segregated_flow.segregated_flow`).

``--history 0`` gives the comparison of residences wholly inside the windows instead: the
reference and the baseline from those, the chain windowed.

Errors are relative to the reference, 100 (side - reference) / reference in %. Prints the
in-sample table (the goal: the chain within 2 %), the out-of-sample table (the goal: the
chain's error no larger than the baseline's in at least 6 of 8 zone cases) with the counts,
and writes everything as JSON with ``--json``. The reference's own standard error is given
beside each row: a goal finer than it cannot be judged on that window.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from cfbmarkov._json import jsonable
from cfbmarkov.analysis.kinetics_reference import reference_kinetics
from cfbmarkov.analysis.segregated_flow import segregated_flow
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.kinetics import ByCell, Constant, FirstOrder, Kinetics, Property, wall_cells
from cfbmarkov.markov import fit_model, state_space_from_name
from cfbmarkov.markov.discrete import discretize
from cfbmarkov.markov.estimate import default_estimator
from cfbmarkov.markov.kinetics_exact import exact_kinetics, windowed_exit_means
from cfbmarkov.markov.model_rtd import occupancy_at
from cfbmarkov.observed.residence import net_flow_direction, residence_times
from cfbmarkov.trajectories import Trajectories

#: the wall layers' rate relative to the core's in the zone-dependent case
WALL_FACTOR = 0.1
DAMKOEHLER = (0.3, 1.0, 3.0)
IN_SAMPLE = ((10.0, 15.0),)
OUT_OF_SAMPLE = (((10.0, 15.0), (15.0, 20.0)), ((5.0, 10.0), (10.0, 15.0)))
KINDS = ("uniform", "zones")
IN_SAMPLE_GOAL = 2.0          # %
#: above this share of a judged window's exits left out (begun before the history), the
#: tables warn
CENSORED_SHARE = 0.01


def exit_residence_times(traj, window, lag: float, direction: str, history: float):
    """Residence times (s) of the residences of a periodic run that end inside ``window``,
    each followed back at most ``history`` s before the window's start (cut at the file's
    first frame), on lap-counter records one lag apart in ``direction``; with ``history``
    0, those wholly inside the window (:func:`cfbmarkov.observed.residence.residence_times`).
    """
    if not history:
        return residence_times(traj, window, use_events=False,
                               lag_frames=traj.lag_frames(lag), direction=direction).samples
    first = max(float(traj.times[0]), window[0] - history)
    frames = traj.window(first, window[1])
    picked = slice(frames.start, frames.stop, traj.lag_frames(lag))
    times = np.asarray(traj.times[picked], dtype=np.float64)
    sign = 1 if direction == "up" else -1
    laps = sign * np.asarray(traj.laps(picked), dtype=np.int64)
    new = np.diff(np.maximum.accumulate(laps, axis=0), axis=0)        # [T - 1, N]
    particle, frame = np.nonzero(new.T)                                # by particle, frame
    repeat = new.T[particle, frame]
    particle, t = np.repeat(particle, repeat), np.repeat(times[frame + 1], repeat)
    same = particle[1:] == particle[:-1]
    entry, exit_ = t[:-1][same], t[1:][same]
    inside = exit_ > window[0] + 1e-9 * max(1.0, abs(window[0]))
    return exit_[inside] - entry[inside]


def fitting_window_facts(traj, model, direction: str = "up", history: float = 0.0) -> dict:
    """The fitting window's observed residence times (on the model's lag, in ``direction``,
    by their exits followed back ``history`` s: :func:`exit_residence_times`) and its state
    occupancy at the lag.

    Parameters
    ----------
    traj : Trajectories
        The fitting file.
    model : MarkovModel
        The model fitted on it (its state space, lag and window).
    direction : {"up", "down"}, optional
        Residences from passes up through the top, or down through the bottom (a net
        downflow).
    history : float, optional
        Seconds an exit's residence is followed back before the window (0: residences
        wholly inside the window).

    Returns
    -------
    dict
        ``residence_times`` (s, float64 [K]), ``tau`` (their mean, s), ``occupancy``
        (float64 [S], visits per state), ``direction``.

    Raises
    ------
    InputError
        Where the window holds no residence.
    """
    window = tuple(model.window)
    rt = exit_residence_times(traj, window, model.lag, direction, history)
    if rt.size < 2:
        raise InputError(f"{traj.path}: {rt.size} residences ({direction} passes) in the "
                         f"fitting window {window[0]:g}-{window[1]:g} s")
    discrete = discretize(traj, model.state_space, model.lag, window)
    states = discrete.states[::discrete.lag_frames]
    occupancy = np.bincount(states[states >= 0], minlength=model.n_states).astype(float)
    return {"residence_times": rt, "tau": float(rt.mean()), "occupancy": occupancy,
            "direction": direction, "history": float(history)}


def goal_kinetics(model, facts: dict, damkoehler) -> Kinetics:
    """The first-order reactions of the goals on ``model``'s grid: for each Da, ``uniform-Da``
    and ``zones-Da`` (module docstring).

    Parameters
    ----------
    model : MarkovModel
        The fitted model (its grid).
    facts : dict
        :func:`fitting_window_facts` of its fitting window.
    damkoehler : sequence of float
        The Damkoehler numbers (> 0).

    Returns
    -------
    Kinetics
        Properties named ``uniform-<i>`` and ``zones-<i>`` (i: the position of Da in
        ``damkoehler``), X = 0 at entry.
    """
    space = model.state_space
    cell = np.asarray(space.cell_of_state, dtype=np.int64)
    weight = np.where(wall_cells(space), WALL_FACTOR, 1.0)          # per cell
    occ = facts["occupancy"]
    mean_weight = float(np.sum(occ * weight[cell]) / occ.sum())
    c = np.arange(space.n_cells)
    m, d = space.columns, space.depth_columns
    cols, depth, rows = c % m, (c // m) % d, c // (m * d)
    props = []
    for i, da in enumerate(damkoehler):
        k_bar = float(da) / facts["tau"]
        table = np.column_stack([cols, rows, depth, k_bar / mean_weight * weight])
        props.append(Property(f"uniform-{i}", FirstOrder(), {"rate": Constant(k_bar)}))
        props.append(Property(f"zones-{i}", FirstOrder(),
                              {"rate": ByCell(table, "zones", "rate_by_cell")}))
    return Kinetics(tuple(props), "goals")


def _error(value: float, reference: float) -> float:
    if not (math.isfinite(value) and math.isfinite(reference)) or reference == 0:
        return float("nan")
    return 100.0 * (value - reference) / reference


def judge(traj, model, facts: dict, judge_window, damkoehler) -> list[dict]:
    """The three exit means and the errors of every reaction on one judged window.

    Parameters
    ----------
    traj : Trajectories
        The run (fitting and judged windows).
    model : MarkovModel
        Fitted on the fitting window.
    facts : dict
        :func:`fitting_window_facts`.
    judge_window : (float, float)
        The judged window (s).
    damkoehler : sequence of float

    Returns
    -------
    list of dict
        One per kind and Da: ``kind``, ``damkoehler``, ``rate_core`` and ``rate_wall``
        (1/s), ``reference`` (exit mean), ``reference_se``, ``exits``, ``chain`` (as the
        reference observes it: windowed with the history), ``chain_windowed`` (the same),
        ``chain_unwindowed`` (the exact exit mean), ``exits_censored``,
        ``segregated_flow``, ``chain_error``, ``chain_exact_error`` and
        ``segregated_flow_error`` (%), ``chain_no_worse`` (bool).
    """
    kinetics = goal_kinetics(model, facts, damkoehler)
    sk = kinetics.per_state(model.state_space)
    direction = facts["direction"]
    exact = exact_kinetics(model, sk, direction=direction)
    history = facts["history"]
    # the reference counts records from its first frame read: its particles' states there
    first = max(float(traj.times[0]), judge_window[0] - history)
    windowed = windowed_exit_means(model, sk, judge_window[1] - judge_window[0],
                                   direction=direction, history=judge_window[0] - first,
                                   occupancy=occupancy_at(model, traj, first))
    ref = reference_kinetics(traj, model, sk, tuple(judge_window), direction=direction,
                             history=history)
    wall = wall_cells(model.state_space)[np.asarray(model.state_space.cell_of_state)]
    out = []
    for i, name in enumerate(kinetics.names):
        kind, position = name.split("-", 1)
        da = damkoehler[int(position)]
        seg = segregated_flow(facts["residence_times"], sk.rate[i], sk.target[i],
                              facts["occupancy"], float(sk.initial[i]), name=name)
        r = ref[name]
        chain = windowed[name]
        ce, se = _error(chain, r.exit_mean), _error(seg.exit_mean, r.exit_mean)
        out.append({
            "kind": kind, "damkoehler": float(da),
            "rate_core": float(sk.rate[i][~wall].max()) if (~wall).any() else float("nan"),
            "rate_wall": float(sk.rate[i][wall].max()) if wall.any() else float("nan"),
            "reference": r.exit_mean, "reference_se": r.exit_se, "exits": int(r.exit_values.size),
            "chain": chain, "chain_unwindowed": exact[name].exit_mean,
            "chain_windowed": windowed[name], "exits_censored": r.exits_censored,
            "chain_exact_error": _error(exact[name].exit_mean, r.exit_mean),
            "segregated_flow": seg.exit_mean,
            "chain_error": ce, "segregated_flow_error": se,
            "chain_no_worse": bool(abs(ce) <= abs(se)) if math.isfinite(ce + se) else None})
    return out


def _label(traj) -> str:
    params = traj.parameters if isinstance(traj.parameters, dict) else {}
    u = (params.get("gas") or {}).get("superficial_velocity") if isinstance(
        params.get("gas"), dict) else None
    return f"U = {float(u):g} m/s" if u is not None else Path(traj.path).stem


def _grid(traj, cells, lag):
    markov = (traj.parameters or {}).get("markov") if isinstance(traj.parameters, dict) else None
    markov = markov if isinstance(markov, dict) else {}
    if cells is None:
        if "columns" not in markov or "rows" not in markov:
            raise InputError(f"{traj.path} names no grid in its parameters: give --cells CxR")
        cells = (int(markov["columns"]), int(markov["rows"]))
    if lag is None:
        if "lag" not in markov:
            raise InputError(f"{traj.path} names no lag in its parameters: give --lag SECONDS")
        lag = float(markov["lag"])
    return cells, lag


def run_goals(runs, *, in_sample=IN_SAMPLE, out_of_sample=OUT_OF_SAMPLE,
              damkoehler=DAMKOEHLER, cells=None, lag=None, estimator=None,
              states="cells", history=None, progress=None) -> dict:
    """The goals' numbers on every run.

    Parameters
    ----------
    runs : sequence of str or os.PathLike
        Trajectory files, one per velocity.
    in_sample : sequence of (float, float)
        Fitting windows judged on themselves.
    out_of_sample : sequence of ((float, float), (float, float))
        (fitting window, judged window) pairs.
    damkoehler : sequence of float
    cells : (int, int), optional
        Columns x rows of the cell grid (default: the run's ``markov`` parameters).
    lag : float, optional
        The lag (s; default: the run's ``markov`` parameters).
    estimator : str, optional
        ``paper`` or ``mle`` (default: paper for a periodic riser, mle for an open one).
    history : float, optional
        Seconds an exit's residence is followed back before its window (default: the
        window's length; 0: residences wholly inside the windows, the chain windowed).
    states : str, optional
        The state space's name (:func:`cfbmarkov.markov.state_space_from_name`) on the
        cell grid; default ``cells``, the paper's.
    progress : callable, optional
        Called with a line of text per fitted model.

    Returns
    -------
    dict
        ``{"in_sample": [...], "out_of_sample": [...], "settings": {...}}``: rows with the
        run, its label, the windows, the model's states and lag, tau_bar, the net flow
        direction, and :func:`judge`'s fields.
    """
    pairs = [("in", tuple(w), tuple(w)) for w in in_sample]
    pairs += [("out", tuple(f), tuple(j)) for f, j in out_of_sample]
    result = {"in_sample": [], "out_of_sample": [], "skipped": [],
              "settings": {"damkoehler": list(map(float, damkoehler)),
                           "wall_factor": WALL_FACTOR, "in_goal_percent": IN_SAMPLE_GOAL}}
    for path in runs:
        with Trajectories(path) as traj:
            (columns, rows), model_lag = _grid(traj, cells, lag)
            est = estimator or default_estimator(traj.boundary.is_open, states)
            space = state_space_from_name(states, columns, rows, traj.width, traj.height)
            fitted, facts_of = {}, {}
            for which, fit, judged in pairs:
                t0 = time.perf_counter()
                try:
                    if fit not in fitted:
                        fitted[fit] = fit_model(traj, space, model_lag, fit, est)
                    model = fitted[fit]
                    direction = net_flow_direction(traj, judged)
                    back = (fit[1] - fit[0]) if history is None else float(history)
                    if (fit, direction) not in facts_of:
                        facts_of[fit, direction] = fitting_window_facts(traj, model, direction,
                                                                        back)
                    rows_out = judge(traj, model, facts_of[fit, direction], judged, damkoehler)
                except CfbmarkovError as exc:
                    result["skipped"].append({"run": str(path), "label": _label(traj),
                                              "fit": list(fit), "judged": list(judged),
                                              "in_sample": which == "in",
                                              "reason": " ".join(str(exc).split())})
                    continue
                facts = facts_of[fit, direction]
                for row in rows_out:
                    row.update({"run": str(path), "label": _label(traj), "fit": list(fit),
                                "judged": list(judged), "tau": facts["tau"],
                                "direction": facts["direction"], "lag": model_lag,
                                "cells": [columns, rows], "estimator": est,
                                "states": states})
                result["in_sample" if which == "in" else "out_of_sample"] += rows_out
                if progress is not None:
                    progress(f"{_label(traj)}: fit {fit[0]:g}-{fit[1]:g} s, judged "
                             f"{judged[0]:g}-{judged[1]:g} s ({time.perf_counter() - t0:.1f} s)")
    result["counts"] = goal_counts(result)
    return result


def goal_counts(result: dict) -> dict:
    """How many rows meet each goal.

    Returns
    -------
    dict
        ``in_sample_within``: per kind, rows whose chain error is within
        :data:`IN_SAMPLE_GOAL` % (``within``; ``exact_within`` for the exact exit mean) of
        ``rows``; ``out_of_sample_no_worse``: per kind
        and Da, rows where the chain is no worse than the baseline, of ``cases``.
    """
    counts = {"in_sample_within": {}, "out_of_sample_no_worse": {}}
    for kind in KINDS:
        rows = [r for r in result["in_sample"] if r["kind"] == kind]
        counts["in_sample_within"][kind] = {
            "within": sum(abs(r["chain_error"]) <= IN_SAMPLE_GOAL for r in rows
                          if math.isfinite(r["chain_error"])),
            "exact_within": sum(abs(r["chain_exact_error"]) <= IN_SAMPLE_GOAL for r in rows
                                if math.isfinite(r["chain_exact_error"])),
            "rows": len(rows)}
        by_da = {}
        for r in result["out_of_sample"]:
            if r["kind"] == kind:
                entry = by_da.setdefault(f"{r['damkoehler']:g}", {"no_worse": 0, "cases": 0})
                entry["cases"] += 1
                entry["no_worse"] += bool(r["chain_no_worse"])
        counts["out_of_sample_no_worse"][kind] = by_da
    return counts


def _fmt(v, spec=".4f"):
    return "n/a" if v is None or not math.isfinite(v) else f"{v:{spec}}"


def tables(result: dict) -> str:
    """The in-sample and out-of-sample tables and the counts as text."""
    lines = []
    head = (f"{'run':<12} {'fit':>9} {'judged':>9} {'dir':<4} {'rate':<8} {'Da':>4} {'exits':>6} "
            f"{'reference':>10} {'ref SE %':>8} {'chain':>8} {'(exact)':>8} {'seg.flow':>8} "
            f"{'chain %':>8} {'exact %':>8} {'seg %':>8} {'ok':>3}")
    for key, title in (("in_sample", "In sample (fitted and judged on the same window; goal: "
                                     f"chain within {IN_SAMPLE_GOAL:g} %)"),
                       ("out_of_sample", "Out of sample (judged on the next window; goal: "
                                         "chain no worse than segregated flow)")):
        lines += [title, head]
        for r in result[key]:
            ok = (abs(r["chain_error"]) <= IN_SAMPLE_GOAL if key == "in_sample"
                  else r["chain_no_worse"])
            se = (100 * r["reference_se"] / r["reference"]
                  if r["reference"] and math.isfinite(r["reference_se"]) else float("nan"))
            lines.append(
                f"{r['label']:<12} {r['fit'][0]:>4g}-{r['fit'][1]:<4g} "
                f"{r['judged'][0]:>4g}-{r['judged'][1]:<4g} {r['direction']:<4} {r['kind']:<8} "
                f"{r['damkoehler']:>4g} {r['exits']:>6d} {_fmt(r['reference']):>10} "
                f"{_fmt(se, '.2f'):>8} {_fmt(r['chain']):>8} {_fmt(r['chain_unwindowed']):>8} "
                f"{_fmt(r['segregated_flow']):>8} "
                f"{_fmt(r['chain_error'], '+.2f'):>8} {_fmt(r['chain_exact_error'], '+.2f'):>8} "
                f"{_fmt(r['segregated_flow_error'], '+.2f'):>8}"
                f" {'yes' if ok else 'no':>3}")
        lines.append("")
    seen = set()
    for r in result["in_sample"] + result["out_of_sample"]:
        key = (r["label"], tuple(r["judged"]))
        total = r["exits"] + r.get("exits_censored", 0)
        if key in seen or not total or r.get("exits_censored", 0) <= CENSORED_SHARE * total:
            continue
        seen.add(key)
        lines.append(f"warning: {r['label']}, judged {r['judged'][0]:g}-{r['judged'][1]:g} s: "
                     f"{r['exits_censored']} of {total} exits began before the history "
                     "(or the file's start) and are left out, so the reference favours short "
                     "residences; judge a later window or give a longer --history")
    for r in result.get("skipped", []):
        lines.append(f"skipped: {r['label']}, fit {r['fit'][0]:g}-{r['fit'][1]:g} s, judged "
                     f"{r['judged'][0]:g}-{r['judged'][1]:g} s: {r['reason']}")
    lines.append("residences counted by their exits in the judged window, followed back before "
                 "it (with history 0: wholly inside it); chain: as the window and its "
                 "history observe it (no residence longer than both); (exact): per "
                 "residence of the chain, the tail included, as react prints it; "
                 "errors against the reference, %; dir: the judged window's net solids flow, "
                 "residences counted that way")
    counts = result["counts"]
    for kind, c in counts["in_sample_within"].items():
        lines.append(f"in sample, {kind}: chain within {IN_SAMPLE_GOAL:g} % in {c['within']} of "
                     f"{c['rows']} (the exact exit mean in {c['exact_within']})")
    for kind, by_da in counts["out_of_sample_no_worse"].items():
        for da, c in by_da.items():
            lines.append(f"out of sample, {kind}, Da {da}: chain no worse than segregated flow "
                         f"in {c['no_worse']} of {c['cases']}")
    return "\n".join(lines)


def _window(text: str) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not START:STOP (s)") from None
    if not (math.isfinite(a) and math.isfinite(b) and b > a):
        raise argparse.ArgumentTypeError(f"{text!r}: need finite START < STOP")
    return a, b


def _pair(text: str):
    parts = text.split(",")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{text!r} is not FIT_START:FIT_STOP,"
                                         "JUDGE_START:JUDGE_STOP")
    return _window(parts[0]), _window(parts[1])


def _numbers(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not numbers separated by commas") from None
    if not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: Damkoehler numbers are finite and > 0")
    return values


def _cells(text: str) -> tuple[int, int]:
    try:
        c, r = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not COLUMNSxROWS") from None
    if c < 1 or r < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: at least 1x1")
    return c, r


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="+", help="trajectory files, one per velocity")
    p.add_argument("--in-sample", type=_window, action="append", default=None,
                   metavar="A:B", help="fitting window judged on itself (default 10:15)")
    p.add_argument("--out-of-sample", type=_pair, action="append", default=None,
                   metavar="A:B,C:D", help="fitted on A:B, judged on C:D (default "
                                           "10:15,15:20 and 5:10,10:15)")
    p.add_argument("--damkoehler", type=_numbers, default=DAMKOEHLER,
                   help="Damkoehler numbers (default 0.3,1,3)")
    p.add_argument("--cells", type=_cells, default=None, help="COLUMNSxROWS (default: the "
                                                              "run's markov parameters)")
    p.add_argument("--lag", type=float, default=None, help="lag, s (default: the run's)")
    p.add_argument("--estimator", choices=("paper", "mle"), default=None)
    p.add_argument("--states", default="cells", help="state space on the grid (default cells, "
                                                     "the paper's; e.g. cells-velocity)")
    p.add_argument("--history", type=float, default=None,
                   help="seconds an exit's residence is followed back before its window "
                        "(default: the window's length; 0: residences wholly inside)")
    p.add_argument("--json", default=None, help="write the numbers here")
    args = p.parse_args(argv)
    try:
        result = run_goals(args.runs, in_sample=args.in_sample or IN_SAMPLE,
                           out_of_sample=args.out_of_sample or OUT_OF_SAMPLE,
                           damkoehler=args.damkoehler, cells=args.cells, lag=args.lag,
                           estimator=args.estimator, states=args.states,
                           history=args.history,
                           progress=lambda line: print(line, file=sys.stderr, flush=True))
    except CfbmarkovError as exc:
        print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    if not result["in_sample"] and not result["out_of_sample"]:
        first = result["skipped"][0]
        print(f"error: no window could be judged ({first['label']}, fit {first['fit'][0]:g}-"
              f"{first['fit'][1]:g} s: {first['reason']})", file=sys.stderr)
        return 2
    print(tables(result))
    if args.json:
        Path(args.json).write_text(json.dumps(jsonable(result), indent=1, allow_nan=False)
                                   + "\n")
        print(args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
