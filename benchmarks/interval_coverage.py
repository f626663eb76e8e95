"""The coverage study: do the intervals `fit` prints hold the flow's long-run E(RT)?

    python benchmarks/interval_coverage.py RUN.h5 [RUN.h5 ...] [--lengths 0.5,1,2,5] [--starts 6]
                                  [--settle 10] [--cells 4x12] [--lag 0.01] [--auto] [--estimator mle]
                                  [--resamples 100] [--level 0.9] [--pool] [-o coverage.json]

For each run and each window length L, six fitting windows (``--starts``) start at times
spread evenly from the settling time (``--settle``) to the run's last frame minus L. On
each window a model is fitted as ``cfbmarkov fit`` does (the cells and lag given, or those
of the ``case.json`` beside the run, written by ``reproduce``; the estimator ``fit``
takes by default, or ``--estimator``), with its interval (:func:`cfbmarkov.analysis.intervals.model_intervals`)
and the verdict on its sample (:func:`cfbmarkov.analysis.adequacy.assess_adequacy`);
``--auto`` also fits ``--states auto`` (:func:`cfbmarkov.markov.select.select_model`).

The model's E(RT) and interval are those of residences counted in the direction of the
span's net solids flow (``model.rtd(None, direction)``, ``model_intervals(direction=...)``;
``docs/definitions.md``, Net downflow), the direction the long run is counted in; ``fit``
prints the upward one, which differs from it where the net flow runs down (the verdict's
E(RT) limit then comes from the default tolerance instead of the interval).

The reference is the run's **long-run E(RT) outside the window**, in two forms:

- *residences*: every residence of the run after the settling time (from the lap counters
  at the model's lag, counted in the net solids flow direction of the whole span, from one
  record of a new lap level to the next, as :func:`cfbmarkov.observed.residence.residence_times`
  counts them over the span) whose interval [entry, exit] does not overlap the fitting
  window, pooled: the rest of the run's residences, none cut by the window's edges. The
  span censors them: residences longer than the rest of the run are missing and those
  close to its length under-counted, so where the residences are long against the run this
  mean lies below the flow's E(RT);
- *flux*: the particle-time of the rest of the run (settling time to the window, window to
  the last frame) over its net passes in that direction (Little's law,
  :func:`cfbmarkov.observed.residence.flux_residence_time`), which no length censors.

Printed per window length (and model), against each reference: fits; coverage, the share
of intervals holding the long-run value; the median relative width of the interval, (upper
- lower) / the fitted E(RT); the median relative error |E(RT) - long run| / long run; the
fits more than 50 % off the long run and how many of them printed a verdict warning (any
line of the sample's verdict; ``warned`` counts them). The JSON (``-o``) holds every fit.
``--rescore STUDY.json`` forms the references again for the fits of an earlier study's JSON
(the runs given as in that study) and prints its table without fitting again. ``--pool``
takes the runs as independent runs of one case: each window, the same in every run, is
fitted on all of them pooled (``fit A.h5 B.h5 ... --window A:B``), and the long run is all
their rests pooled (:func:`pooled_study`).
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
from cfbmarkov.analysis.adequacy import assess_adequacy
from cfbmarkov.analysis.intervals import model_intervals
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.estimate import default_estimator
from cfbmarkov.markov import fit_model
from cfbmarkov.markov.states import CellGrid
from cfbmarkov.observed.residence import net_flow_direction, net_passes, residence_flux
from cfbmarkov.trajectories import Trajectories

#: a fit this far from the long run (relative) must warn
OFF = 0.5


def residence_intervals(traj, span: tuple[float, float], lag: float,
                        direction: str | None = None) -> np.ndarray:
    """Every residence of a periodic run in ``span``: (entry, exit) times, float [K, 2].

    From the lap counters of every ``lag_frames``-th frame of the span from its first, in
    ``direction`` (default the span's net solids flow direction): a record is a frame at which a particle's lap
    counter first exceeds its running maximum (twice, at the same time, if it jumped by
    two), and a residence runs from one record of a particle to its next; the samples are
    those of :func:`cfbmarkov.observed.residence.residence_times` over the span, with
    their times.
    """
    if traj.boundary.is_open:
        raise InputError(f"{traj.path}: the coverage study reads a periodic riser's lap "
                         "counters (an open riser has none)")
    frames = traj.window(*span)
    step = traj.lag_frames(lag)
    picked = slice(frames.start, frames.stop, step)
    times = np.asarray(traj.times[picked], dtype=np.float64)
    direction = net_flow_direction(traj, span) if direction is None else direction
    sign = 1 if direction == "up" else -1
    laps = sign * np.asarray(traj.laps(picked), dtype=np.int64)
    top = np.maximum.accumulate(laps, axis=0)
    new = np.diff(top, axis=0)                            # new levels per frame, [T - 1, N]
    particle, frame = np.nonzero(new.T)                   # by particle, then by frame
    repeat = new.T[particle, frame]
    particle = np.repeat(particle, repeat)
    t = np.repeat(times[frame + 1], repeat)
    same = particle[1:] == particle[:-1]
    return np.column_stack([t[:-1][same], t[1:][same]])


def long_run_outside(residences: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    """The residence times (s) of ``residences`` ([K, 2] entry and exit) whose interval
    does not overlap ``window``."""
    a, b = window
    keep = (residences[:, 1] <= a + 1e-9) | (residences[:, 0] >= b - 1e-9)
    return residences[keep, 1] - residences[keep, 0]


def flux_outside(trajs, window: tuple[float, float], span: tuple[float, float],
                 direction: str) -> float | None:
    """The flux long run outside ``window``: the particle-time of the parts of ``span``
    before and after it over their net passes in ``direction``, summed over ``trajs`` (one
    open run, or several of one case; s; None where they have none)."""
    particle_time, passes = 0.0, 0
    for traj in (trajs if isinstance(trajs, (list, tuple)) else [trajs]):
        for lo, hi in ((span[0], window[0]), (window[1], span[1])):
            if hi - lo >= float(traj.frame_interval) - 1e-9:
                part = residence_flux(traj, (lo, hi), direction)
                particle_time += part[0]
                passes += part[1]
    return particle_time / passes if passes > 0 else None


def _case_markov(path: Path) -> dict:
    case = path.parent / "case.json"
    if case.is_file():
        return json.loads(case.read_text()).get("markov", {})
    return {}


def fit_one(path: Path, traj, window, *, columns: int, rows: int, lag: float, auto: bool,
            level: float, resamples: int, direction: str = "up",
            estimator: str | None = None) -> dict:
    """One fit as ``cfbmarkov fit`` makes it: E(RT) and its interval in ``direction`` (the
    residences' direction of the long run it is compared with) and the verdict's lines;
    ``estimator`` None: ``fit``'s default (``paper`` for the cells on a periodic riser,
    ``mle`` open or with ``auto``)."""
    if estimator is None:
        estimator = default_estimator(traj.boundary.is_open, "auto" if auto else "cells")
    if auto:
        from cfbmarkov.markov.select import select_model

        model = select_model(traj, window=window, columns=columns, rows=rows, lag=lag,
                             estimator=estimator)
    else:
        space = CellGrid(columns, rows, traj.width, traj.height)
        model = fit_model(traj, space, lag, window, estimator)
    out = {"window": list(window), "states": model.state_space.describe()}
    try:
        rtd = model.rtd(None, direction)
    except CfbmarkovError as exc:
        return out | {"error": str(exc)}
    out["rt_mean"] = float(rtd.mean)
    out["direction"] = direction
    interval = None
    try:
        u = model_intervals(model, level=level, resamples=resamples, direction=direction)
        interval = u.rt_mean_interval
        out["rt_mean_interval"] = list(interval)
    except CfbmarkovError as exc:
        out["interval_error"] = str(exc)
    verdict = assess_adequacy(model, [path], [window],
                              interval=interval if direction == "up" else None)
    out["warnings"] = list(verdict.warnings)
    out["window_rt_mean"] = verdict.window_rt_mean
    return out


def _record(fit: dict, fits: list, progress, reference: np.ndarray, flux, t0: float,
            **keys) -> None:
    """Complete a fit's record (its ``keys``, both long runs, the seconds since ``t0``),
    keep it in ``fits`` and show it."""
    fit.update(**keys, long_run=float(reference.mean()) if reference.size else None,
               long_run_count=int(reference.size), long_run_flux=flux,
               seconds=time.perf_counter() - t0)
    fits.append(fit)
    if progress:
        progress(fit)


def pooled_study(runs, *, lengths, starts: int, settle: float, cells, lag, level: float,
                 resamples: int, estimator: str | None = None, progress=None) -> dict:
    """``--pool``: the runs are of one case, and each window (the same in every run, from
    the settling time to the shortest run's end) is fitted on all of them pooled, as
    ``fit A.h5 B.h5 ... --window A:B`` does, with its interval and verdict; the long run
    is every run's rest pooled (their residences outside the window, and their
    particle-time over their net passes there), counted in the pooled span's net flow
    direction."""
    import contextlib

    from cfbmarkov.markov.estimate import estimator_from_name
    from cfbmarkov.markov.pooling import discretize_runs

    paths = [Path(name) for name in runs]
    case = _case_markov(paths[0])
    columns, rows = cells or (case.get("columns", 6), case.get("rows", 38))
    run_lag = lag or case.get("lag", 0.025)
    fits = []
    with contextlib.ExitStack() as stack:
        trajs = [stack.enter_context(Trajectories(p)) for p in paths]
        if any(t.boundary.is_open for t in trajs):
            raise InputError("--pool reads periodic risers' lap counters (an open riser has "
                             "none)")
        a0 = max(max(float(t.times[0]) for t in trajs), settle)
        last = min(float(t.times[-1]) for t in trajs)
        direction = "up" if sum(net_passes(t, (a0, last)) for t in trajs) >= 0 else "down"
        residences = [residence_intervals(t, (a0, last), run_lag, direction) for t in trajs]
        space = CellGrid(columns, rows, trajs[0].width, trajs[0].height)
        if estimator is None:
            estimator = "paper"
        fitter = estimator_from_name(estimator, space, run_lag)
        for length in lengths:
            if a0 + length > last + 1e-9:
                continue
            for start in np.linspace(a0, last - length, starts):
                window = (round(float(start), 6), round(float(start) + length, 6))
                reference = np.concatenate([long_run_outside(r, window) for r in residences])
                flux = flux_outside(trajs, window, (a0, last), direction)
                t0 = time.perf_counter()
                fit = {"window": list(window)}
                try:
                    model = fitter.fit(discretize_runs(trajs, space, run_lag, [window]))
                    fit["states"] = model.state_space.describe()
                    fit["rt_mean"] = float(model.rtd(None, direction).mean)
                    fit["direction"] = direction
                    interval = None
                    try:
                        u = model_intervals(model, level=level, resamples=resamples,
                                            direction=direction)
                        interval = u.rt_mean_interval
                        fit["rt_mean_interval"] = list(interval)
                    except CfbmarkovError as exc:
                        fit["interval_error"] = str(exc)
                    verdict = assess_adequacy(model, trajs, [window] * len(trajs),
                                              interval=interval if direction == "up" else None)
                    fit["warnings"] = list(verdict.warnings)
                    fit["window_rt_mean"] = verdict.window_rt_mean
                except CfbmarkovError as exc:     # kept, and left out of the table
                    fit["error"] = str(exc)
                _record(fit, fits, progress, reference, flux, t0,
                        run=", ".join(str(p) for p in paths), model=f"pool{len(paths)}",
                        length=float(length))
    return {"level": level, "resamples": resamples, "settle": settle, "estimator": estimator,
            "lag": lag, "lengths": list(lengths), "starts": starts, "off": OFF,
            "pooled": [str(p) for p in paths], "table": table(fits), "fits": fits}


#: the references: the fits' key of each and its suffix in the table's keys
REFERENCES = (("long_run", ""), ("long_run_flux", "_flux"))


def table(fits: list[dict]) -> list[dict]:
    """Per (model, window length) and per reference (``REFERENCES``; keys with its
    suffix): fits, coverage, median relative width and error, the fits more than ``OFF``
    off and how many of them warned."""
    rows = []
    for key in sorted({(f["model"], f["length"]) for f in fits}):
        failed = sum("error" in f for f in fits if (f["model"], f["length"]) == key)
        row = {"model": key[0], "length": key[1], "failed": failed}
        for reference, suffix in REFERENCES:
            group = [f for f in fits if (f["model"], f["length"]) == key and "rt_mean" in f
                     and f.get(reference) is not None]
            with_interval = [f for f in group if "rt_mean_interval" in f]
            held = [f["rt_mean_interval"][0] <= f[reference] <= f["rt_mean_interval"][1]
                    for f in with_interval]
            widths = [(f["rt_mean_interval"][1] - f["rt_mean_interval"][0]) / f["rt_mean"]
                      for f in with_interval]
            errors = [abs(f["rt_mean"] / f[reference] - 1.0) for f in group]
            off = [f for f in group if abs(f["rt_mean"] / f[reference] - 1.0) > OFF]
            row |= {f"fits{suffix}": len(group), f"intervals{suffix}": len(with_interval),
                    f"coverage{suffix}": float(np.mean(held)) if held else math.nan,
                    f"median_relative_width{suffix}":
                        float(np.median(widths)) if widths else math.nan,
                    f"median_relative_error{suffix}":
                        float(np.median(errors)) if errors else math.nan,
                    f"off{suffix}": len(off),
                    f"off_warned{suffix}": sum(bool(f["warnings"]) for f in off),
                    f"warned{suffix}": sum(bool(f["warnings"]) for f in group)}
        rows.append(row)
    return rows


def rescore(study_json: dict, runs, lag: float | None = None) -> dict:
    """An earlier study's fits with both references formed again from ``runs`` (matched to
    the fits by file name; the lag ``lag``, else the study's, else the run's case.json's,
    else 0.025 s), and its table."""
    if study_json.get("pooled"):
        raise InputError("--rescore forms the references of a study of single runs; a --pool "
                         "study's are formed as it runs: run it again with --pool")
    paths = {Path(name).name: Path(name) for name in runs}
    fits = study_json["fits"]
    for name in sorted({Path(f["run"]).name for f in fits}):
        if name not in paths:
            raise InputError(f"the study's fits name {name}: give it among the runs")
        path = paths[name]
        case = _case_markov(path)
        with Trajectories(path) as traj:
            first, last = float(traj.times[0]), float(traj.times[-1])
            a0 = max(first, float(study_json["settle"]))
            run_lag = float(lag or study_json.get("lag") or case.get("lag", 0.025))
            direction = net_flow_direction(traj, (a0, last))
            residences = residence_intervals(traj, (a0, last), run_lag)
            for f in fits:
                if Path(f["run"]).name != name:
                    continue
                window = tuple(f["window"])
                reference = long_run_outside(residences, window)
                f["long_run"] = float(reference.mean()) if reference.size else None
                f["long_run_count"] = int(reference.size)
                f["long_run_flux"] = flux_outside(traj, window, (a0, last), direction)
    return study_json | {"table": table(fits), "fits": fits}


def study(runs, *, lengths, starts: int, settle: float, cells, lag, auto: bool, level: float,
          resamples: int, estimator: str | None = None, progress=None) -> dict:
    """Every fit of the study and its table (the module docstring)."""
    fits = []
    for name in runs:
        path = Path(name)
        case = _case_markov(path)
        columns, rows = cells or (case.get("columns", 6), case.get("rows", 38))
        run_lag = lag or case.get("lag", 0.025)
        with Trajectories(path) as traj:
            first, last = float(traj.times[0]), float(traj.times[-1])
            a0 = max(first, settle)
            residences = residence_intervals(traj, (a0, last), run_lag)
            direction = net_flow_direction(traj, (a0, last))
            for length in lengths:
                if a0 + length > last + 1e-9:
                    continue
                for start in np.linspace(a0, last - length, starts):
                    window = (round(float(start), 6), round(float(start) + length, 6))
                    reference = long_run_outside(residences, window)
                    flux = flux_outside(traj, window, (a0, last), direction)
                    for model in (("cells", "auto") if auto else ("cells",)):
                        t0 = time.perf_counter()
                        try:
                            fit = fit_one(path, traj, window, columns=columns, rows=rows,
                                          lag=run_lag, auto=model == "auto", level=level,
                                          resamples=resamples, direction=direction,
                                          estimator=estimator)
                        except CfbmarkovError as exc:     # kept, and left out of the table
                            fit = {"window": list(window), "error": str(exc)}
                        _record(fit, fits, progress, reference, flux, t0, run=str(path),
                                model=model, length=float(length))
    return {"level": level, "resamples": resamples, "settle": settle, "estimator": estimator,
            "lag": lag, "lengths": list(lengths),
            "starts": starts, "off": OFF, "table": table(fits), "fits": fits}


def _print_table(result: dict) -> None:
    pct = f"{100 * result['level']:g}"
    for reference, suffix in REFERENCES:
        print(f"long run from the {'net flux' if suffix else 'residences'} outside the window:")
        print(f"{'model':<6} {'L (s)':>6} {'fits':>5} {'coverage':>9} {'width':>7} "
              f"{'error':>7} {'>50% off':>9} {'warned':>7} {'any warning':>12}")
        for r in result["table"]:
            if f"fits{suffix}" not in r:       # a study before the flux reference
                continue
            print(f"{r['model']:<6} {r['length']:>6g} {r[f'fits{suffix}']:>5d} "
                  f"{r[f'coverage{suffix}']:>9.2f} {r[f'median_relative_width{suffix}']:>7.2f} "
                  f"{r[f'median_relative_error{suffix}']:>7.2f} {r[f'off{suffix}']:>9d} "
                  f"{r[f'off_warned{suffix}']:>7d} {r[f'warned{suffix}']:>12d}"
                  + (f" ({r['failed']} failed)" if r["failed"] else ""))
    print(f"coverage: share of {pct} % intervals holding the long-run E(RT) outside the "
          "window; width: median (upper - lower) / fitted E(RT); error: median |fit / long "
          "run - 1|; warned: of the fits > 50 % off, those with a verdict warning; any "
          "warning: fits with a verdict warning")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="trajectory files (long runs)")
    p.add_argument("--lengths", default="0.5,1,2,5", help="window lengths, s (0.5,1,2,5)")
    p.add_argument("--starts", type=int, default=6, help="start times per length (6)")
    p.add_argument("--settle", type=float, default=10.0,
                   help="settling time, s: windows and long run start after it (10)")
    p.add_argument("--cells", default=None,
                   help="COLUMNSxROWS (default: case.json beside the run, else 6x38)")
    p.add_argument("--lag", type=float, default=None,
                   help="lag, s (default: case.json beside the run, else 0.025)")
    p.add_argument("--auto", action="store_true", help="also fit --states auto")
    p.add_argument("--estimator", choices=("paper", "mle"), default=None,
                   help="estimator (default: fit's, paper for the cells on a periodic "
                        "riser, mle with --auto)")
    p.add_argument("--level", type=float, default=0.9, help="interval level (0.9)")
    p.add_argument("--resamples", type=int, default=100, help="bootstrap resamples (100)")
    p.add_argument("-o", "--output", default="coverage.json", help="JSON of every fit")
    p.add_argument("-q", "--quiet", action="store_true", help="no line per fit on stderr")
    p.add_argument("--pool", action="store_true",
                   help="the runs are of one case: fit every window on all of them pooled "
                        "(fit A.h5 B.h5 ...), the long run their rests pooled")
    p.add_argument("--rescore", default=None, metavar="STUDY.json",
                   help="form the references again for an earlier study's fits (its runs "
                        "given) and print its table, without fitting; -o writes it")
    args = p.parse_args(argv)
    if args.rescore:
        try:
            result = rescore(json.loads(Path(args.rescore).read_text()), args.runs, args.lag)
        except CfbmarkovError as exc:
            print(f"coverage: {exc}", file=sys.stderr)
            return 2
        except (OSError, ValueError, KeyError) as exc:
            print(f"coverage: {args.rescore} is not a study's JSON ({exc})", file=sys.stderr)
            return 2
        return _write(result, args.output)
    if args.pool and args.auto:
        print("coverage: --pool fits the paper's cells (--cells) on the runs pooled; --auto "
              "is of single runs", file=sys.stderr)
        return 2
    try:
        lengths = [float(v) for v in args.lengths.split(",")]
        cells = tuple(int(v) for v in args.cells.lower().split("x")) if args.cells else None
        if any(not v > 0 for v in lengths) or args.starts < 1 or (cells and len(cells) != 2):
            raise ValueError
    except ValueError:
        print("coverage: --lengths must be positive numbers (0.5,1,2,5), --starts at least 1 "
              "and --cells COLUMNSxROWS", file=sys.stderr)
        return 2

    def progress(fit):
        if not args.quiet:
            if "error" in fit:
                print(f"{Path(fit['run']).name} {fit['model']} {fit['window'][0]:g}-"
                      f"{fit['window'][1]:g} s: no fit ({fit['error']})", file=sys.stderr)
                return
            lo, hi = fit.get("rt_mean_interval", (math.nan, math.nan))
            ref = math.nan if fit["long_run"] is None else fit["long_run"]
            flux = math.nan if fit["long_run_flux"] is None else fit["long_run_flux"]
            print(f"{Path(fit['run']).parent.name}/{Path(fit['run']).name} {fit['model']} "
                  f"{fit['window'][0]:g}-{fit['window'][1]:g} s: E(RT) "
                  f"{fit.get('rt_mean', math.nan):.3g} s [{lo:.3g}, {hi:.3g}], long run "
                  f"{ref:.3g} s (flux {flux:.3g} s), {len(fit.get('warnings', []))} warning(s), "
                  f"{fit['seconds']:.1f} s", file=sys.stderr, flush=True)

    try:
        if args.pool:
            result = pooled_study(args.runs, lengths=lengths, starts=args.starts,
                                  settle=args.settle, cells=cells, lag=args.lag,
                                  level=args.level, resamples=args.resamples,
                                  estimator=args.estimator, progress=progress)
        else:
            result = study(args.runs, lengths=lengths, starts=args.starts, settle=args.settle,
                           cells=cells, lag=args.lag, auto=args.auto, level=args.level,
                           resamples=args.resamples, estimator=args.estimator,
                           progress=progress)
    except CfbmarkovError as exc:
        print(f"coverage: {exc}", file=sys.stderr)
        return 2
    return _write(result, args.output)


def _write(result: dict, output: str) -> int:
    """Write the study's JSON, print its table and the file's name; 0."""
    Path(output).write_text(json.dumps(jsonable(result), indent=1, allow_nan=False))
    _print_table(result)
    print(output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
