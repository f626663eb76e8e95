"""Command line: ``cfbmarkov VERB ...``; every verb is a thin layer over the Python API.

Errors in the input (files, options) are reported as one line on stderr with exit code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
from pathlib import Path

from cfbmarkov.errors import CfbmarkovError, InputError


# -- option parsers ------------------------------------------------------------------------
def parse_window(text: str) -> tuple[float, float]:
    """Parse a time window: ``'10:15'`` -> (10.0, 15.0).

    Parameters
    ----------
    text : str
        ``START:STOP`` in seconds.

    Returns
    -------
    tuple of float
        (start, stop), s.

    Raises
    ------
    argparse.ArgumentTypeError
        When ``text`` is not two finite numbers or the window is empty.
    """
    try:
        a, b = text.split(":")
        start, stop = float(a), float(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"window '{text}' is not START:STOP in seconds") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise argparse.ArgumentTypeError(f"window '{text}' is not two finite times")
    if not stop > start:
        raise argparse.ArgumentTypeError(f"window '{text}' is empty: STOP must exceed START")
    return start, stop


def parse_region(text: str) -> tuple[tuple[float, float], ...]:
    """Parse a region: ``'-0.001:0.091,0:0.95'`` -> ((-0.001, 0.091), (0.0, 0.95)).

    Parameters
    ----------
    text : str
        Two or three ``LO:HI`` ranges (m), for x, y (, z), separated by commas.

    Returns
    -------
    tuple of (float, float)

    Raises
    ------
    argparse.ArgumentTypeError
        When a range is not two finite numbers with HI > LO, or there are not 2 or 3.
    """
    try:
        ranges = tuple(tuple(float(v) for v in part.split(":")) for part in text.split(","))
    except ValueError:
        ranges = ()
    if not 2 <= len(ranges) <= 3 or any(
            len(r) != 2 or not all(map(math.isfinite, r)) or not r[1] > r[0] for r in ranges):
        raise argparse.ArgumentTypeError(
            f"region '{text}' is not XMIN:XMAX,YMIN:YMAX[,ZMIN:ZMAX] in m (finite, MAX > MIN)")
    return ranges


def parse_cells(text: str) -> tuple[int, int] | tuple[int, int, int]:
    """Parse a cell grid: ``'6x38'`` -> (6 columns, 38 rows); ``'6x3x38'`` -> (6 columns,
    3 depth columns, 38 rows), a 3D grid for 3D data (``docs/definitions.md``, Cells and
    state numbers).

    Parameters
    ----------
    text : str
        ``COLUMNSxROWS`` or ``COLUMNSxDEPTHxROWS``.

    Returns
    -------
    tuple of int
        (columns m, rows n), or (columns m, depth columns d, rows n).

    Raises
    ------
    argparse.ArgumentTypeError
        When ``text`` is not two or three whole numbers of at least 1.
    """
    try:
        values = tuple(int(v) for v in text.lower().split("x"))
    except ValueError:
        values = ()
    if len(values) not in (2, 3):
        raise argparse.ArgumentTypeError(
            f"cells '{text}' is not COLUMNSxROWS or COLUMNSxDEPTHxROWS (for example 6x38 or "
            "6x3x38)")
    if min(values) < 1:
        axes = "column and one row" if len(values) == 2 else "column, depth column and row"
        raise argparse.ArgumentTypeError(f"cells '{text}' needs at least one {axes}")
    return values


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None


def _finite_float(text: str) -> float:
    """A finite number (a time, s)."""
    value = _number(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"'{text}' is not a finite number")
    return value


def _positive_float(text: str) -> float:
    """A finite number > 0."""
    value = _finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be positive")
    return value


def _level(text: str) -> float:
    """A coverage level strictly between 0 and 1 (NaN refused)."""
    value = _number(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"'{text}' must lie between 0 and 1")
    return value


def _minkowski_order(text: str) -> float:
    """A Minkowski order k > 0; ``inf`` (the largest difference) is allowed, NaN is not."""
    value = _number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be positive (or inf)")
    return value


def _whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None


def _seed(text: str) -> int:
    """A seed of the counter-based generator: a whole number in 0 .. 2^64 - 1."""
    from cfbmarkov.limits import MAX_SEED

    value = _whole(text)
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"'{text}' must lie in 0 .. 2^64 - 1")
    return value


def _count(low: int, high: int):
    """An argparse type: a whole number in low .. high."""
    def parse(text: str) -> int:
        value = _whole(text)
        if value < low:
            raise argparse.ArgumentTypeError(f"'{text}' must be at least {low}")
        if value > high:
            raise argparse.ArgumentTypeError(f"'{text}' must be at most {high}")
        return value
    parse.__name__ = "count"
    return parse


#: the most particles a synthetic demo, a case or a benchmark may be given
MAX_PARTICLES = 10_000_000
#: the most worker processes
MAX_JOBS = 1024


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit code 2
        self.exit(2, f"{self.prog}: error: {message}\n")


# -- verbs -----------------------------------------------------------------------------------
def _cmd_import(args) -> int:
    from cfbmarkov.io import import_file

    path = import_file(args.source, args.format, args.output, width=args.width,
                       height=args.height, time_step=args.time_step,
                       vertical_axis=args.vertical_axis, region=args.region,
                       length_unit=args.length_unit, time_unit=args.time_unit,
                       boundary=args.boundary, drop_depth=args.drop_depth,
                       resample=args.resample, max_gap=args.max_gap)
    print(path)
    return 0


def _cmd_fit(args) -> int:
    from cfbmarkov.markov import fit_model, state_space_from_name
    from cfbmarkov.markov.select import select_model
    from cfbmarkov.trajectories import Trajectories

    from cfbmarkov.markov.first_passage import TrappedResidences

    columns, rows = args.cells[0], args.cells[-1]
    depth_columns = args.cells[1] if len(args.cells) == 3 else None
    with Trajectories(args.run) as run:
        if args.estimator is None:
            args.estimator = "mle" if run.boundary == "open" else "paper"
        if depth_columns is not None and run.dimensions != 3:
            raise InputError(f"{args.run} is 2D: cells {'x'.join(map(str, args.cells))} with "
                             "depth columns need 3D data (use COLUMNSxROWS)")
        if args.states == "auto" and depth_columns is not None:
            raise InputError("--states auto has no depth columns yet: use COLUMNSxROWS cells")
        if args.states == "auto":
            model = select_model(run, window=args.window, columns=columns, rows=rows,
                                 lag=args.lag, estimator=args.estimator,
                                 coherent=args.coherent)
            if args.connected:     # the chosen space, refitted on its largest connected set
                model = fit_model(run, model.state_space, model.lag, args.window,
                                  args.estimator, connected=True, coherent=args.coherent
                                  ).with_selection(model.selection)
        else:
            space = state_space_from_name(args.states, columns, rows, run.width, run.height,
                                          depth_columns, run.depth)
            model = fit_model(run, space, args.lag, args.window, args.estimator,
                              connected=args.connected, coherent=args.coherent)
    try:
        model.rtd()
    except TrappedResidences as exc:
        raise InputError(f"{args.run}: {exc}") from None
    except CfbmarkovError:
        pass                       # no circulation at all: a model without residence times
    for line in model.warnings():
        print(f"warning: {line.strip()}", file=sys.stderr)
    model.save(args.output)
    print(model.summary())
    print(args.output)
    return 0


def _cmd_predict(args) -> int:
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.trajectories import Trajectories

    model = MarkovModel.load(args.model)
    with Trajectories(args.init) as run:
        model.predict(run, start=args.start, duration=args.duration, seed=args.seed,
                      output=args.output, progress=not args.quiet)
    print(args.output)
    return 0


def _cmd_compare(args) -> int:
    from cfbmarkov.report.compare import compare

    summary = compare(args.reference, args.prediction, window=args.window, output=args.output,
                      bin_width=args.bin_width, md_order=args.md_order, figures=not args.no_figures,
                      basis=args.basis, level=args.level, resamples=args.resamples,
                      long_run_span=args.long_run_span)
    from cfbmarkov.observed.metrics import percentage_text as pd_text

    for line in summary.get("warnings", []):
        print(f"warning: {line.strip()}", file=sys.stderr)
    print(f"E(RT) reference {summary['reference']['rt_mean']:.4g} s, model "
          f"{summary['model']['rt_mean']:.4g} s (PD {pd_text(summary['pd_rt_mean'])} %); "
          f"SD(RT) PD {pd_text(summary['pd_rt_sd'])} %; MD {summary['md_rtd']:.4g}; "
          f"mixing RMS {summary['mixing_rms']:.4g}")
    model = summary["model"]
    if "rt_mean_interval" in model:
        (m0, m1), (s0, s1) = model["rt_mean_interval"], model["rt_sd_interval"]
        with_flow = (summary.get("intervals") or {}).get("flow_sd") is not None
        own = ""
        if with_flow and "model_rt_mean_interval" in model:
            (o0, o1), (p0, p1) = model["model_rt_mean_interval"], model["model_rt_sd_interval"]
            own = f" (the model's own: E(RT) {o0:.4g}-{o1:.4g} s, SD(RT) {p0:.4g}-{p1:.4g} s)"
        kind = " with the flow's variability" if with_flow else ""
        print(f"  {100 * summary['level']:g} % intervals{kind}: E(RT) {m0:.4g}-{m1:.4g} s, "
              f"SD(RT) {s0:.4g}-{s1:.4g} s{own}")
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
              f"%, MD {long_run['md_rtd']:.4g} (what a perfect stationary model would predict)")
    print(Path(args.output) / "summary.json")
    return 0


def _cmd_stationarity(args) -> int:
    import json

    import numpy as np

    from cfbmarkov.analysis.baseline import window_difference
    from cfbmarkov.observed.metrics import percentage_text as pd_text
    from cfbmarkov.observed.residence import net_flow_direction
    from cfbmarkov.analysis.stationarity import long_run_baseline, window_statistics
    from cfbmarkov.report.compare import _jsonable
    from cfbmarkov.trajectories import Trajectories

    events = args.basis == "events"
    with Trajectories(args.file) as traj:
        if events and not (traj.has_events and traj.boundary == "periodic"):
            raise InputError(f"{args.file} holds no exact pass events: residence times from "
                             "frames need no --basis events")
        lag_frames = traj.lag_frames(args.lag) if args.lag is not None else 1
        bin_width = args.lag if args.lag is not None else traj.frame_interval
        basis = {"use_events": events, "lag_frames": 1 if events else lag_frames}
        span = args.span or (float(traj.times[0]), float(traj.times[-1]))
        stats = window_statistics(traj, window_length=args.window_length, step=args.step,
                                  span=args.span, **basis)
        summary = {"file": str(args.file), "span": list(span),
                   "basis": "events" if events else "frames", "rtd_bin_width": bin_width,
                   **stats.summary()}
        judged = None
        if args.judge is not None:
            j0, j1 = args.judge
            length = j1 - j0
            tol = traj.time_tolerance
            if j0 < span[0] - tol or j1 > span[1] + tol:
                raise InputError(f"--judge {j0:g}:{j1:g} s lies outside the span "
                                 f"{span[0]:g}:{span[1]:g} s")
            direction = net_flow_direction(traj, args.judge)
            long_run = long_run_baseline(traj, args.judge, span=args.span, bin_width=bin_width,
                                         direction=direction, **basis)
            judged = {"window": [j0, j1], "direction": direction,
                      "rt_mean": long_run.observed.mean, "rt_sd": long_run.observed.sd,
                      "rt_count": long_run.observed.count, "long_run": long_run.summary(),
                      "persistence": None}
            if j0 - length >= span[0] - tol:
                persistence = window_difference(
                    traj, (j0 - length, j0), (j0, j1), bin_width=bin_width, md_order=2.0,
                    face_band=None, window_length=length, direction=direction, **basis)
                judged["persistence"] = persistence.summary()
            summary["judged"] = judged
    if args.json:
        print(json.dumps(_jsonable(summary), indent=1, allow_nan=False))
        return 0

    def value(v, spec=".4g"):
        return format(v, spec) if v is not None and np.isfinite(v) else "n/d"

    length = stats.window_length
    basis_text = ("exact pass events" if events else f"frames every {bin_width:g} s")
    print(f"{args.file}: {stats.starts.size} windows of {length:g} s, {stats.step:g} s apart, "
          f"residence times from {basis_text}")
    print(f"{'window (s)':>13}  {'direction':>9}  {'E(RT) (s)':>9}  {'SD(RT) (s)':>10}  "
          f"{'residences':>10}")
    for a, m, sd, n, d in zip(stats.starts, stats.rt_mean, stats.rt_sd, stats.rt_count,
                              stats.direction):
        span_text = f"{a:g}-{a + length:g}"
        print(f"{span_text:>13}  {d:>9}  {value(m):>9}  {value(sd):>10}  {n:10d}")
    print(f"E(RT) {value(stats.average_rt_mean)} s on average, relative SD "
          f"{value(100 * stats.relative_sd_rt_mean, '.1f')} %; SD(RT) "
          f"{value(stats.average_rt_sd)} s, relative SD "
          f"{value(100 * stats.relative_sd_rt_sd, '.1f')} % (the scatter of one {length:g} s "
          "window about the run's average: a stationary prediction of a given window carries "
          "about as much)")
    few = int(np.sum(stats.rt_count < FEW_RESIDENCES))
    if few:
        print(f"note: {few} of {stats.starts.size} windows hold fewer than {FEW_RESIDENCES} "
              "residences: their E(RT) and SD(RT), and the scatter, carry sampling noise (a "
              "longer --window-length)")
    if judged is not None:
        lr, pe = judged["long_run"], judged["persistence"]
        print(f"judged window {j0:g}-{j1:g} s: E(RT) {value(judged['rt_mean'])} s, SD(RT) "
              f"{value(judged['rt_sd'])} s, {judged['rt_count']} residences")
        s0, s1 = lr["windows"][0]
        print(f"  the run's long run (its {j1 - j0:g} s windows of {s0:g}-{s1:g} s but this one, "
              f"pooled; what a perfect stationary model would predict): PD E(RT) "
              f"{pd_text(lr['pd_rt_mean'], '+.1f')} %, PD SD(RT) "
              f"{pd_text(lr['pd_rt_sd'], '+.1f')} %, MD {value(lr['md_rtd'], '.3f')}")
        if pe is not None:
            print(f"  persistence (the {j0 - (j1 - j0):g}-{j0:g} s window): PD E(RT) "
                  f"{pd_text(pe['pd_rt_mean'], '+.1f')} %, PD SD(RT) "
                  f"{pd_text(pe['pd_rt_sd'], '+.1f')} %, MD {value(pe['md_rtd'], '.3f')}")
        else:
            print(f"  persistence: no whole {j1 - j0:g} s window before {j0:g} s in the span")
    return 0


#: windows with fewer residences than this get a note in ``cfbmarkov stationarity``
FEW_RESIDENCES = 100


def _cmd_rtd(args) -> int:
    from cfbmarkov.markov import MarkovModel

    model = MarkovModel.load(args.model)
    rtd = model.rtd(window=args.window_length)
    print(f"E(RT) = {rtd.mean:.6g} s, SD(RT) = {rtd.sd:.6g} s "
          f"({'window ' + format(args.window_length, 'g') + ' s' if args.window_length else 'intrinsic'}, "
          f"unresolved mass {rtd.unresolved:.2g})")
    return 0


def _cmd_maps(args) -> int:
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.report.figures import plot_probability_maps

    model = MarkovModel.load(args.model)
    maps = model.batch_injection_maps(args.times, outflow=args.outflow)
    space = model.state_space
    title = (f"Batch fed over the inlet at t = 0 ({space.describe()}"
             + (", summed over the depth" if space.depth_columns > 1 else "") + f", lag {model.lag:g} s"
             + (", outflow through the top removed)" if args.outflow else ")"))
    plot_probability_maps(maps, args.times, space.width, space.height, args.output, title=title)
    for t, m in zip(args.times, maps):
        print(f"t = {t:g} s: fraction in riser {m.sum():.4f}")
    print(args.output)
    return 0


def _parse_times(text: str) -> list[float]:
    try:
        times = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"times '{text}' are not comma-separated seconds") from None
    if not all(map(math.isfinite, times)):
        raise argparse.ArgumentTypeError(f"times '{text}' must be finite numbers of seconds")
    if not times or min(times) < 0:
        raise argparse.ArgumentTypeError(f"times '{text}' must be one or more values >= 0 s")
    return times


def _cmd_info(args) -> int:
    import h5py

    from cfbmarkov._hdf5 import open_h5

    with open_h5(args.file) as f:
        fmt = f.attrs.get("format")
    if isinstance(fmt, bytes):
        fmt = fmt.decode()
    if fmt == "cfbmarkov.model":
        from cfbmarkov.markov import MarkovModel

        print(MarkovModel.load(args.file).summary())
    else:
        from cfbmarkov.trajectories import Trajectories
        from cfbmarkov.trajectory_info import describe

        with Trajectories(args.file) as t:
            print("\n".join(describe(t)))
    del h5py
    return 0


def _parse_velocities(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"velocities '{text}' are not comma-separated numbers "
                                         "in m/s") from None
    if not values or any(not (v > 0 and math.isfinite(v)) for v in values):
        raise argparse.ArgumentTypeError(f"velocities '{text}' must be positive numbers in m/s")
    return values


def _parse_names(text: str) -> list[str]:
    names = [v.strip() for v in text.split(",") if v.strip()]
    if not names:
        raise argparse.ArgumentTypeError("no names given")
    return names


def _cmd_reproduce(args) -> int:
    from cfbmarkov.reproduce import load_overrides, reproduce

    overrides = load_overrides(args.overrides) if args.overrides else None
    report = reproduce(args.output, args.scale, args.velocities, overrides=overrides,
                       models=args.models, scheduler=args.scheduler, jobs=args.jobs,
                       progress=not args.quiet, log=lambda line: print(line, flush=True))
    print(report)
    return 0


def _cmd_demo(args) -> int:
    if args.synthetic:
        from cfbmarkov.demo import run_demo

        out = run_demo(args.output, particles=args.particles, seed=args.seed)
        print(out)
        return 0
    from cfbmarkov.reproduce import reproduce

    report = reproduce(args.output, "quick", jobs=args.jobs, progress=not args.quiet,
                       log=lambda line: print(line, flush=True))
    print(f"report: {report}")
    return 0


def _cmd_export_vtk(args) -> int:
    from cfbmarkov.io.vtk import export_vtk_summary

    done = export_vtk_summary(args.run, args.output, start=args.start, stop=args.stop,
                              every=args.every, fields=not args.no_fields,
                              progress=not args.quiet)
    gas = f", {done.n_gas_files} gas field frames" if done.n_gas_files else ""
    missing = f" ({done.n_gas_missing} frames without gas fields)" if done.n_gas_missing else ""
    print(f"{done.n_particle_files} particle frames{gas}{missing}: open "
          f"{done.output / 'particles.pvd'} in ParaView")
    return 0


def _cmd_simulate(args) -> int:
    from cfbmarkov.config import load_case
    from cfbmarkov.simulate.run import simulate

    case = load_case(args.case)
    if args.particles is not None:
        case = case.model_copy(update={"particles": case.particles.model_copy(
            update={"number": args.particles})})
    out = simulate(case, args.output, until=args.until, checkpoint_every=args.checkpoint_every,
                   resume=args.resume, progress=not args.quiet)
    print(out)
    return 0


def _cmd_cases(args) -> int:
    from cfbmarkov.config import case_names, load_case

    for name in case_names():
        c = load_case(name)
        print(f"{name}: U = {c.gas.superficial_velocity:g} m/s, {c.particles.number} particles, "
              f"{c.riser.width:g} x {c.riser.height:g} m, 0-{c.output.end_time:g} s")
    return 0


def _cmd_bench(args) -> int:
    from cfbmarkov.bench import run_benchmarks

    for name, value, unit in run_benchmarks(only=args.only, repeat=args.repeat,
                                            particles=args.particles):
        print(f"{name}: {value:.4g} {unit}", flush=True)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``cfbmarkov`` with all its verbs.

    Returns
    -------
    argparse.ArgumentParser
        A parser whose usage errors exit with code 2; each verb sets ``func``.
    """
    from cfbmarkov import __version__

    p = _Parser(prog="cfbmarkov", description="Markov chain models of particle motion in CFB risers.")
    p.add_argument("--version", action="version", version=f"cfbmarkov {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("import", help="import CSV or LAMMPS/LIGGGHTS dumps as a trajectory file")
    s.add_argument("source", help="input file (.csv, dump, optionally .gz)")
    s.add_argument("--format", required=True, choices=["csv", "lammps"])
    s.add_argument("-o", "--output", required=True, help="output trajectory file (.h5)")
    s.add_argument("--width", type=_positive_float, default=None,
                   help="riser width W, m: the riser is 0..W across in the source's own "
                        "coordinates (default: the dump's box, else 0.09)")
    s.add_argument("--height", type=_positive_float, default=None,
                   help="riser height H, m: 0..H vertically in the source's coordinates "
                        "(default: the dump's box, else 0.95)")
    s.add_argument("--time-step", type=_positive_float, default=None,
                   help="LAMMPS time step, s, for dumps without ITEM: TIME")
    s.add_argument("--vertical-axis", choices=["x", "y", "z"], default=None,
                   help="the source's vertical axis (gravity along minus it); required for a "
                        "3D dump or a CSV file with a z column")
    s.add_argument("--drop-depth", action="store_true",
                   help="store 3D positions projected on (across, vertical)")
    s.add_argument("--region", type=parse_region, default=None,
                   help="the riser in the source's coordinates and units: "
                        "XMIN:XMAX,YMIN:YMAX[,ZMIN:ZMAX]; particles outside it are absent")
    s.add_argument("--boundary", choices=["periodic", "open"], default=None,
                   help="the vertical boundary (default: the dump's box flag on the vertical "
                        "axis; periodic for CSV)")
    s.add_argument("--resample", type=_positive_float, default=None, metavar="DT",
                   help="CSV: interpolate tracks at irregular times (PEPT) onto frames DT s apart")
    s.add_argument("--max-gap", type=_positive_float, default=None, metavar="G",
                   help="with --resample: a particle is absent between samples more than G s "
                        "apart (default DT)")
    s.add_argument("--length-unit", choices=["m", "cm", "mm"], default=None,
                   help="CSV: unit of positions (and, per --time-unit, velocities) in columns "
                        "whose header names none (default m)")
    s.add_argument("--time-unit", choices=["s", "ms"], default=None,
                   help="CSV: unit of t where the header names none (default s)")
    s.set_defaults(func=_cmd_import)

    s = sub.add_parser("fit", help="fit a Markov chain model on a window of a trajectory file")
    s.add_argument("run", help="trajectory file")
    s.add_argument("--cells", type=parse_cells, default=(6, 38),
                   help="COLUMNSxROWS, or COLUMNSxDEPTHxROWS for 3D data (depth columns; "
                        "COLUMNSxROWS projects 3D data on across x vertical) (default 6x38)")
    s.add_argument("--lag", type=_positive_float, default=0.025, help="lag, s (default 0.025)")
    s.add_argument("--window", type=parse_window, default=(10.0, 15.0),
                   help="fitting window START:STOP, s (default 10:15)")
    s.add_argument("--estimator", choices=["paper", "mle"], default=None,
                   help="paper (Eq. 2-4; the default for a periodic riser) or mle (pooled "
                        "counts; the default, and the only choice, for an open riser)")
    s.add_argument("--states", choices=["cells", "cells-direction", "cells-velocity",
                                        "cells-velocity-fine", "cells-previous",
                                        "cells-regime", "cells-direction-regime", "auto"],
                   default="cells",
                   help="state space: the paper's cells, cells x direction of motion, cells x "
                        "vertical-velocity bins, and with sub-rows fitted to the moves per lag "
                        "(fine), cells x previous-cell offset (second order), "
                        "cells x 2 regimes of the solids flux (the regime model; with "
                        "direction: x direction too), or auto: the one whose RTD is closest to "
                        "the window's own (default cells)")
    s.add_argument("--connected", action="store_true",
                   help="fit on the largest strongly connected set of the counts (transitions "
                        "out of it removed, as deeptime and PyEMMA do): states entered but "
                        "never left then trap no particle")
    s.add_argument("--coherent", action="store_true",
                   help="the cluster model: also fit how often particles that share a state "
                        "move together (coherence, calibrated so that the model's snapshots "
                        "show the window's cluster index), so that predictions keep clusters; "
                        "the RTD and maps are unchanged (periodic risers)")
    s.add_argument("-o", "--output", required=True, help="model file (.h5)")
    s.set_defaults(func=_cmd_fit)

    s = sub.add_parser("predict", help="Monte Carlo prediction from a run's state at a start time")
    s.add_argument("model")
    s.add_argument("--init", required=True, help="trajectory file giving the initial state")
    s.add_argument("--start", type=_finite_float, required=True, help="initial frame time, s")
    s.add_argument("--duration", type=_positive_float, required=True, help="simulated time, s")
    s.add_argument("--seed", type=_seed, default=0, help="0 .. 2^64 - 1 (default 0)")
    s.add_argument("-o", "--output", required=True, help="prediction trajectory file (.h5)")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_predict)

    s = sub.add_parser("compare", help="compare two trajectory files: RTD, mixing of the two "
                       "tracer groups, figures")
    s.add_argument("reference", help="reference trajectory file (e.g. CFD-DEM)")
    s.add_argument("prediction", help="model trajectory file (e.g. a prediction)")
    s.add_argument("--window", type=parse_window, required=True, help="analysis window START:STOP, s")
    s.add_argument("-o", "--output", required=True, help="output directory")
    s.add_argument("--bin-width", type=_positive_float, default=0.025, help="RTD bin width, s")
    s.add_argument("--md-order", type=_minkowski_order, default=2.0,
                   help="Minkowski order k > 0 (inf: the largest difference)")
    s.add_argument("--no-figures", action="store_true", help="write summary.json only")
    s.add_argument("--level", type=_level, default=0.9,
                   help="coverage of the prediction's intervals (default 0.9)")
    s.add_argument("--resamples", type=_count(0, 100000), default=100,
                   help="bootstrap resamples of the model's fitting window for the intervals "
                        "(0: no intervals; default 100)")
    s.add_argument("--basis", choices=["frames", "events"], default="frames",
                   help="residence times of both sides from frames at the model's lag (like "
                        "for like, the default; the reference's exact-event figures are shown "
                        "beside), or the reference's exact pass events")
    s.add_argument("--long-run-span", type=parse_window, default=None,
                   help="START:STOP, s: also give the reference's RTD pooled over this span's "
                        "other whole windows (what a perfect stationary model would predict; "
                        "e.g. 5:20)")
    s.set_defaults(func=_cmd_compare)

    s = sub.add_parser("rtd", help="exact residence-time distribution of a model")
    s.add_argument("model")
    s.add_argument("--window-length", type=_positive_float, default=None,
                   help="observation window, s: the RTD as seen in such a window")
    s.set_defaults(func=_cmd_rtd)

    s = sub.add_parser("stationarity",
                       help="how much a run's RTD changes from window to window (sliding "
                            "windows), and the run's long run against one window")
    s.add_argument("file", help="trajectory file")
    s.add_argument("--window-length", type=_positive_float, default=5.0,
                   help="window length, s (default 5)")
    s.add_argument("--step", type=_positive_float, default=1.0,
                   help="time between window starts, s (default 1)")
    s.add_argument("--span", type=parse_window, default=None,
                   help="START:STOP, s, the part of the file used (default all; leave out a "
                        "start-up from rest)")
    s.add_argument("--lag", type=_positive_float, default=None,
                   help="frames every LAG s (a model's lag; default every frame); also the "
                        "RTD bins of the MD")
    s.add_argument("--basis", choices=["frames", "events"], default="frames",
                   help="residence times from frames (every --lag, the default) or from the "
                        "file's exact pass events (as in compare)")
    s.add_argument("--judge", type=parse_window, default=None,
                   help="START:STOP, s: also compare this window with the run's long run "
                        "(the span's other whole windows of its length, pooled) and with the "
                        "window before it (persistence)")
    s.add_argument("--json", action="store_true", help="print JSON instead of a table")
    s.set_defaults(func=_cmd_stationarity)

    s = sub.add_parser("maps", help="batch-injection probability maps (Eq. 8, Fig. 4-7)")
    s.add_argument("model")
    s.add_argument("--times", type=_parse_times, default=[0.05, 0.1, 0.15],
                   help="comma-separated times after injection, s (default 0.05,0.1,0.15)")
    s.add_argument("--outflow", action="store_true",
                   help="remove what passes up through the top (fraction still in the riser)")
    s.add_argument("-o", "--output", required=True, help="PNG file")
    s.set_defaults(func=_cmd_maps)

    s = sub.add_parser("info", help="describe a trajectory or model file")
    s.add_argument("file")
    s.set_defaults(func=_cmd_info)

    s = sub.add_parser("simulate", help="CFD-DEM of the periodic riser (a TOML case or a shipped name)")
    s.add_argument("case", help="case file (.toml) or shipped case name (see 'cfbmarkov cases')")
    s.add_argument("-o", "--output", required=True, help="trajectory file (.h5)")
    s.add_argument("--until", type=_positive_float, default=None, help="end time, s (default: the case's)")
    s.add_argument("--checkpoint-every", type=_positive_float, default=1.0,
                   help="simulated seconds between checkpoints (default 1)")
    s.add_argument("--resume", action="store_true", help="continue an interrupted run")
    s.add_argument("--particles", type=_count(1, MAX_PARTICLES), default=None,
                   help="override the number of particles")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_simulate)

    s = sub.add_parser("cases", help="list the shipped cases")
    s.set_defaults(func=_cmd_cases)

    s = sub.add_parser("reproduce", help="the paper end to end at U = 3, 4, 6, 8 m/s: CFD-DEM, "
                       "Markov models, predictions, comparison, report")
    s.add_argument("--scale", choices=["paper", "quick"], default="quick",
                   help="paper: the paper's riser and 0-20 s (hours); quick: a reduced riser "
                        "(minutes); default quick")
    s.add_argument("-o", "--output", required=True, help="output directory (rerun to resume)")
    s.add_argument("--velocities", type=_parse_velocities, default=[3.0, 4.0, 6.0, 8.0],
                   help="comma-separated superficial gas velocities U, m/s (default 3,4,6,8)")
    s.add_argument("--models", type=_parse_names, default=["paper", "mle", "auto"],
                   help="comma-separated models: paper, mle (the paper's cells with that "
                        "estimator), auto (state space and lag chosen on the fitting window), "
                        "or STATES[:ESTIMATOR] (default paper,mle,auto)")
    s.add_argument("--overrides", default=None,
                   help="TOML file of changes applied to every case (same tables as a case file)")
    s.add_argument("--jobs", type=_count(1, MAX_JOBS), default=None,
                   help="local worker processes (default: min(cases, cores))")
    s.add_argument("--scheduler", default=None,
                   help="address of a Dask distributed scheduler (tcp://host:8786) to run the "
                        "cases on; the workers must see the output directory")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=_cmd_reproduce)

    s = sub.add_parser("demo", help="the main job on a fresh machine: 'reproduce --scale quick' "
                       "(about 4 min on 2 quiet cores), ending with the path of its report")
    s.add_argument("-o", "--output", default="cfbmarkov-demo", help="output directory")
    s.add_argument("--jobs", type=_count(1, MAX_JOBS), default=None,
                   help="local worker processes")
    s.add_argument("--synthetic", action="store_true",
                   help="instead, the Markov part alone on synthetic core-annulus trajectories "
                        "(30 s)")
    s.add_argument("--particles", type=_count(1, MAX_PARTICLES), default=6000,
                   help="with --synthetic: particles")
    s.add_argument("--seed", type=_seed, default=1, help="with --synthetic: seed")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=_cmd_demo)

    s = sub.add_parser("export-vtk", help="ParaView files: particle frames (with their tracer "
                       "group, colour_group) and gas fields with .pvd time series")
    s.add_argument("run", help="trajectory file")
    s.add_argument("-o", "--output", required=True, help="output directory")
    s.add_argument("--start", type=_finite_float, default=None, help="first time, s")
    s.add_argument("--stop", type=_finite_float, default=None, help="last time, s")
    s.add_argument("--every", type=_count(1, 2 ** 31 - 1), default=1,
                   help="export every k-th frame")
    s.add_argument("--no-fields", action="store_true", help="particles only")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_export_vtk)

    s = sub.add_parser("bench", help="benchmarks; one line per figure as 'name: value unit'")
    s.add_argument("--only", action="append", default=None, help="run only this benchmark")
    s.add_argument("--repeat", type=_count(1, 1000), default=5,
                   help="repetitions (median reported)")
    s.add_argument("--particles", type=_count(1, MAX_PARTICLES), default=27000)
    s.set_defaults(func=_cmd_bench)
    for name, verb in sub.choices.items():
        if name in OUTPUTS:
            verb.add_argument("--force", action="store_true",
                              help="replace an existing output of another kind (a file of "
                                   "another format, a FIFO, an empty folder, ...)")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run ``cfbmarkov`` with ``argv`` (default: the process's arguments).

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name.

    Returns
    -------
    int
        The exit code: 0 on success, 2 on a usage error or a
        :class:`~cfbmarkov.errors.CfbmarkovError` (reported as one line on stderr), 130 when
        interrupted.
    """
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:      # usage errors (2), --help and --version (0)
            return int(exc.code or 0)
    except KeyboardInterrupt:
        print("cfbmarkov: interrupted", file=sys.stderr)
        return 130
    from cfbmarkov._console import one_line_notes

    with one_line_notes():             # cfbmarkov's warnings: one line, "note: ..."
        code = _run(args)
    from cfbmarkov import _atomic

    if _atomic.HDF5_WRITE_FAILED:      # HDF5 may crash at exit after a failed write
        from cfbmarkov._outputs import release_all

        release_all()
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code)
    return code


#: the output each writing verb claims: kind, and the arguments naming its inputs
OUTPUTS = {"import": ("trajectory", ("source",)), "fit": ("model", ("run",)),
           "predict": ("trajectory", ("model", "init")),
           "compare": ("folder", ("reference", "prediction")), "maps": ("png", ("model",)),
           "simulate": ("trajectory", ("case",)), "reproduce": ("folder", ("overrides",)),
           "demo": ("folder", ()), "export-vtk": ("folder", ("run",))}


def _run(args) -> int:
    """Run the verb of ``args`` with its output claimed; errors become one line."""
    from cfbmarkov import _interrupt

    try:
        with _interrupt.installed():
            return _run_claimed(args)
    except CfbmarkovError as exc:
        print(f"cfbmarkov {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"cfbmarkov {args.command}: interrupted{_resumable(args)}", file=sys.stderr)
        return 130
    except OSError as exc:             # a write that failed outside the writers' mapping
        from cfbmarkov._atomic import write_error

        name = exc.filename or getattr(args, "output", "")
        print(f"cfbmarkov {args.command}: error: {write_error(exc, name)}", file=sys.stderr)
        return 2


def _run_claimed(args) -> int:
    """The verb with its output claimed; a Ctrl-C swallowed on the way is raised at the end."""
    from cfbmarkov import _interrupt

    try:
        if args.command in OUTPUTS:
            from cfbmarkov._outputs import claim_output

            kind, inputs = OUTPUTS[args.command]
            with claim_output(args.output, args.command, kind,
                              [getattr(args, name, None) for name in inputs],
                              force=getattr(args, "force", False)):
                return int(args.func(args) or 0)
        return int(args.func(args) or 0)
    finally:
        _interrupt.check()


def _resumable(args) -> str:
    """What an interrupted verb can be resumed with."""
    if args.command == "simulate":
        checkpoint = Path(str(args.output) + ".parts") / "checkpoint.h5"
        if checkpoint.exists():
            return "; the run can be resumed with --resume (from its last checkpoint)"
    if args.command in ("reproduce", "demo") and not getattr(args, "synthetic", False):
        return "; rerun the same command to resume"
    return ""


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())


__all__ = ["main", "build_parser", "parse_cells", "parse_window", "InputError"]
