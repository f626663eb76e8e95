"""The verbs of Markov models: ``fit``, ``predict``, ``rtd`` and ``info``."""

from __future__ import annotations

import contextlib
import math
import sys

from cfbmarkov._names import one_line
from cfbmarkov.cli.options import (count, finite_float, level, parse_cells, parse_windows,
                                   positive_float, seed)
from cfbmarkov.errors import CfbmarkovError, InputError, SampleWarning


@contextlib.contextmanager
def _stage(args, short: str, text: str | None):
    """A stage of a verb: a line ``VERB: TEXT`` on stderr at its start (none where ``text``
    is None: a stage that may still refuse its input, in one line) and a line every 5 s of
    work after it (:func:`cfbmarkov._console.heartbeat`); nothing with ``-q``."""
    from cfbmarkov._console import heartbeat, write_line

    if getattr(args, "quiet", False):
        yield
        return
    if text is not None:
        write_line(f"{args.command}: {text}")
    with heartbeat(f"{args.command} ({short})"):
        yield


def cmd_fit(args) -> int:
    """``cfbmarkov fit``: fit, save and summarise a model; print its file.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    if args.level is not None and not args.resamples:
        raise InputError(f"--level {args.level:g} sets the interval's coverage, which "
                         "--resamples 0 leaves out (the model then carries no interval): "
                         "leave out --level or --resamples 0")
    args.level = 0.9 if args.level is None else args.level
    _check_resamples(args.resamples, args.level)
    if args.window is None:       # the paper's window; a refusal of it says it is the default
        args.window = [DEFAULT_WINDOW]
        try:
            return _fit(args)
        except InputError as exc:
            if "window 10:15 s" not in str(exc):
                raise
            raise InputError(f"{exc} (no --window was given: 10:15 s is its default, the "
                             "paper's fitting window)") from None
    return _fit(args)


#: ``fit``'s window where none is given: the paper's fitting window (s)
DEFAULT_WINDOW = (10.0, 15.0)


def _fit(args) -> int:
    """``fit`` with its window given."""
    from cfbmarkov.markov import fit_model, state_space_from_name
    from cfbmarkov.markov.select import select_model
    from cfbmarkov.trajectories import Trajectories

    columns, rows = args.cells[0], args.cells[-1]
    depth_columns = args.cells[1] if len(args.cells) == 3 else None
    if len(args.run) > 1:       # several runs of one case, pooled
        return _fit_pooled(args, columns, rows, depth_columns)
    args.run, args.window = args.run[0], _one_window(args.window)
    with Trajectories(args.run) as run:
        _choose_estimator(args, run.boundary.is_open)
        if depth_columns is not None and run.dimensions != 3:
            raise InputError(f"{args.run} is 2D: cells {'x'.join(map(str, args.cells))} with "
                             "depth columns need 3D data (use COLUMNSxROWS)")
        if args.states == "auto" and depth_columns is not None:
            raise InputError("--states auto has no depth columns yet: use COLUMNSxROWS cells")
        if args.states == "auto":
            run.lag_frames(args.lag)        # a refusal stays one line, before any progress
            run.window(*args.window)
            with _stage(args, "choosing the state space",
                        f"judging the candidate state spaces on {args.run}, "
                        f"{args.window[0]:g}-{args.window[1]:g} s (each fitted and judged "
                        + ("by the Chapman-Kolmogorov test, an open riser's criterion)"
                           if run.boundary.is_open else
                           "by its RTD against the window's, or by the Chapman-Kolmogorov test "
                           "where the window holds too few residences)")):
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
            with _stage(args, "counting", None):    # a refusal stays one line: no start line
                model = fit_model(run, space, args.lag, args.window, args.estimator,
                                  connected=args.connected, coherent=args.coherent)
        _refuse_an_open_riser_read_as_periodic(run, model, args.run, args.window)
        notes = _between_frames(run, args.window)
        held_from = float(run.times[run.window(*args.window).start])   # its first frame
        if (model.window is not None
                and model.window[0] > held_from + run.time_tolerance):
            # a space with memory needs the frames before the window's first: at the
            # file's start, auto judges and fits from where that history begins
            notes.append(f"the window starts at {model.window[0]:g} s, the first frame with "
                         f"the history that {model.state_space.kind} needs (the file starts "
                         f"at {float(run.times[0]):g} s): the model is fitted on "
                         f"{model.window[0]:g}:{model.window[1]:g} s")
    # the window the model was fitted on (a space with memory may start it a lag late):
    # its verdict and throughput are of those frames
    fitted = tuple(model.window) if model.window is not None else args.window
    return _finish_fit(args, model, [args.run], [fitted], notes)


def _refuse_an_open_riser_read_as_periodic(run, model, path, window) -> None:
    """Refuse, before the model is written, a periodic riser's model that no particle's
    pass through the top or the bottom fed, on a file whose particles come and go in the
    window: an open riser imported without ``--boundary open`` (its model has no residence
    time, and the advice of a longer window would not help)."""
    if run.boundary.is_open or not run.has_absences or model.open_flow is not None:
        return
    passes = sum(abs(getattr(model, name)).sum() for name in ("counts_up", "counts_down")
                 if getattr(model, name, None) is not None)
    if passes:
        return
    frames = run.window(*window)
    present = run.present(frames)
    began = int((present[1:] & ~present[:-1]).sum())
    ended = int((~present[1:] & present[:-1]).sum())
    if began + ended == 0:
        return
    raise InputError(f"{path} is read as a periodic riser, but in {window[0]:g}-{window[1]:g} s "
                     f"its particles come and go ({began} tracks begin, {ended} end) and none "
                     "passes through the top or the bottom, so its model would have no "
                     "residence time: an open riser, whose particles enter at the inlet and "
                     "leave at the outlet, is imported with --boundary open; a periodic one "
                     "needs a window long enough for passes (a longer --window)")


def _between_frames(run, window) -> list[str]:
    """A note where a fitting window's ends fall between the run's frames: the frames it
    holds, which the model is fitted on and stores as its window)."""
    frames = run.window(*window)
    first, last = float(run.times[frames.start]), float(run.times[frames.stop - 1])
    tol = run.time_tolerance
    if abs(first - window[0]) <= tol and abs(last - window[1]) <= tol:
        return []
    return [f"the window {window[0]:g}:{window[1]:g} s falls between the frames of "
            f"{run.path} (every {run.frame_interval:g} s): the model is fitted on those it "
            f"holds, {first:g} to {last:g} s"]


def _choose_estimator(args, open_boundary: bool) -> None:
    """``args.estimator`` where none was given (:func:`~cfbmarkov.markov.estimate.
    default_estimator`), and a ``warning:`` line where the paper's estimator is asked for on
    a state space with memory."""
    from cfbmarkov.markov.estimate import default_estimator

    if args.estimator is None:
        args.estimator = default_estimator(open_boundary, args.states)
    elif args.estimator == "paper" and args.states != "cells":
        print(f"warning: the paper's estimator (Eq. 2-4) is the paper's for its cells; on "
              f"--states {args.states} its frame-averaged rows can carry the chain away from "
              "the window's own flux (docs/method.md, Estimators): --estimator mle, the "
              "default there, keeps it", file=sys.stderr)


def _finish_fit(args, model, runs, windows, notes=()) -> int:
    """The end of ``fit``: the exact RTD, the sample's verdict, warnings, save, summary;
    ``notes`` printed as ``note:`` lines once the model is saved."""
    import warnings

    from cfbmarkov.analysis.fit_checks import IntervalWarning, assess_fit

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", IntervalWarning)
        model = assess_fit(model, runs, windows, level=args.level, resamples=args.resamples,
                           verdict=args.adequacy,
                           stage=lambda short, text: _stage(args, short, text))
    for caught_warning in caught:
        if issubclass(caught_warning.category, IntervalWarning):
            print(f"warning: {one_line(str(caught_warning.message))}", file=sys.stderr)
        elif issubclass(caught_warning.category, SampleWarning):
            continue                   # the verdict's lines: printed below, after the save
        else:
            warnings.warn_explicit(caught_warning.message, caught_warning.category,
                                   caught_warning.filename, caught_warning.lineno)
    model.save(args.output)
    for line in notes:
        print(f"note: {line}", file=sys.stderr)
    for line in model.warnings():      # after the save: a failed fit prints one line
        print(f"warning: {one_line(line.strip())}", file=sys.stderr)
    try:
        model.rtd()
    except CfbmarkovError as exc:      # saved (its maps and predictions stand), but said
        print(f"warning: the model has no residence time ({one_line(str(exc))}): `rtd`, "
              "`react` and the exact figures of `compare` refuse it; fit on a longer window "
              "or one where particles pass through the top", file=sys.stderr)
    print(model.summary(warnings=False))   # each warning once, on stderr
    if getattr(args, "coherent", False) and not model.coherence:
        print("  coherent moves: calibrated to a coherence of 0 on the fitting window (its "
              "particles move together no more than the chain's own moves make them): the "
              "model is the plain chain")
    print(args.output)
    return 0


def _one_window(windows) -> tuple[float, float]:
    """The one fitting window of a single run (several: refused in one line)."""
    if len(windows) != 1:
        raise InputError(f"{len(windows)} windows for one run: give one window (START:STOP)")
    return windows[0]


def _fit_pooled(args, columns: int, rows: int, depth_columns: int | None) -> int:
    """``fit`` on several runs of one case: their windows' counts pooled
    (:mod:`cfbmarkov.markov.pooling`)."""
    import contextlib

    from cfbmarkov.markov import state_space_from_name
    from cfbmarkov.markov.estimate import estimator_from_name
    from cfbmarkov.markov.pooling import discretize_runs, run_windows
    from cfbmarkov.trajectories import Trajectories

    if args.states == "auto" and depth_columns is not None:
        raise InputError("--states auto has no depth columns yet: use COLUMNSxROWS cells")
    windows = run_windows(args.window, len(args.run))
    with contextlib.ExitStack() as stack:
        runs = [stack.enter_context(Trajectories(path)) for path in args.run]
        first = runs[0]
        _choose_estimator(args, first.boundary.is_open)
        if depth_columns is not None and first.dimensions != 3:
            raise InputError(f"{first.path} is 2D: cells {'x'.join(map(str, args.cells))} "
                             "with depth columns need 3D data (use COLUMNSxROWS)")
        if args.states == "auto":       # chosen on the pooled windows
            from cfbmarkov.markov.select import DEFAULT_LAG_MULTIPLES, DEFAULT_STATES
            from cfbmarkov.markov.select import select_pooled

            if not args.quiet:
                print(f"fit: judging the candidate state spaces on {len(runs)} runs' windows "
                      "pooled (each fitted and judged by its RTD against the windows', or "
                      "by the Chapman-Kolmogorov test where they hold too few residences)",
                      file=sys.stderr, flush=True)
            model = select_pooled(runs, windows=windows, columns=columns, rows=rows,
                                  lag=args.lag, states=DEFAULT_STATES,
                                  lag_multiples=DEFAULT_LAG_MULTIPLES,
                                  estimator=args.estimator, coherent=args.coherent)
            if not args.connected:
                return _finish_fit(args, model, list(args.run), windows)
            space, selection, lag = model.state_space, model.selection, model.lag
        else:
            space = state_space_from_name(args.states, columns, rows, first.width,
                                          first.height, depth_columns, first.depth)
            selection, lag = None, args.lag
        with _stage(args, "counting", None):    # a refusal stays one line: no start line
            discrete = discretize_runs(runs, space, lag, windows)
            model = estimator_from_name(args.estimator, space, lag, args.connected,
                                        args.coherent).fit(discrete)
        if selection is not None:      # the chosen space, refitted on its connected set
            model = model.with_selection(selection)
    return _finish_fit(args, model, list(args.run), windows)


def resamples_for(level: float) -> int:
    """The resamples to suggest for an interval at ``level``: 100, or as many as its tails
    need (:func:`~cfbmarkov.analysis.bootstrap.check_interval_options`)."""
    return max(100, math.ceil(1.0 / (1.0 - float(level)) - 1e-9))


def _check_resamples(resamples: int, level: float | None = None) -> None:
    """Refuse 1-9 resamples in one line (0: no interval), and resamples too few for the
    level's tails (:func:`~cfbmarkov.analysis.bootstrap.check_interval_options`)."""
    if 0 < resamples < 10:
        raise InputError(f"--resamples {resamples}: an interval needs at least 10 bootstrap "
                         "resamples (0 leaves it out)")
    if resamples and level is not None:
        from cfbmarkov.analysis.bootstrap import check_interval_options

        check_interval_options(level, resamples,
                               fix=f"give --resamples {math.ceil(1 / (1 - level) - 1e-9)} "
                                   "or more, or a lower --level")


def _with_interval(model, level: float, resamples: int):
    """``model`` carrying its interval at ``level`` from ``resamples`` bootstrap resamples,
    or as it is with a ``warning:`` line on stderr saying why none could be formed from its
    fitting data; refused where that data cannot be found (the interval was asked for)."""
    from cfbmarkov.analysis.intervals import SourceChanged, SourceMissing, model_intervals

    try:
        return model.with_uncertainty(model_intervals(model, level=level, resamples=resamples))
    except (SourceChanged, SourceMissing):
        raise           # another file of the fitting file's name, or none: refused
    except CfbmarkovError as exc:
        print(f"warning: no interval for the model's E(RT) and SD(RT): {exc}", file=sys.stderr)
        return model


def cmd_predict(args) -> int:
    """``cfbmarkov predict``: a Monte Carlo prediction; print its file.

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
    from cfbmarkov.trajectories import Trajectories

    import warnings

    model = MarkovModel.load(args.model)
    with Trajectories(args.init) as run, warnings.catch_warnings():
        warnings.simplefilter("ignore", SampleWarning)     # printed below, after the file
        model.predict(run, start=args.start, duration=args.duration, seed=args.seed,
                      output=args.output, progress=not args.quiet)
    for line in model.adequacy.warnings if model.adequacy is not None else ():
        print(f"warning: the model's fitting sample: {one_line(line)}", file=sys.stderr)
    from cfbmarkov.markov.model_summary import on_window_warning

    missed = on_window_warning(model)
    if missed:
        print(f"warning: the model: {one_line(missed)}", file=sys.stderr)
    from cfbmarkov.markov.model_summary import monte_carlo_warnings

    for line in monte_carlo_warnings(model):
        print(f"warning: the model: {one_line(line)}", file=sys.stderr)
    print(args.output)
    return 0


def cmd_rtd(args) -> int:
    """``cfbmarkov rtd``: print a model's E(RT) and SD(RT).

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

    from cfbmarkov._json import jsonable
    from cfbmarkov.markov import MarkovModel

    _check_resamples(args.resamples, args.level)
    if args.resamples and args.window_length:
        raise InputError(f"--resamples forms the interval of the model's intrinsic RTD, not of "
                         f"its RTD as a {args.window_length:g} s window sees it: leave out "
                         "--window-length (or --resamples; `compare RUN PREDICTION` gives a "
                         "window's intervals against a run)")
    if args.level is not None and args.window_length:
        raise InputError(f"--level sets the interval of the model's intrinsic RTD; its RTD as "
                         f"a {args.window_length:g} s window sees it has none: leave out "
                         "--window-length (or --level; `compare RUN PREDICTION` gives a "
                         "window's intervals against a run)")
    model = MarkovModel.load(args.model)
    if args.window_length:
        # a whole number of lags, as the window's frame pairs are (not rounded silently)
        model.steps_for(args.window_length, "--window-length")
    stored = model.uncertainty          # the interval the fitting sample's verdict was made with
    if args.resamples:
        from cfbmarkov.analysis.intervals import resolve_source

        # its fitting file found (or the refusal, one line) before the progress line
        model = resolve_source(model.with_uncertainty(None))
        level_ = args.level if args.level is not None else 0.9
        pooled = "s" if isinstance(model.source, (list, tuple)) else ""
        with _stage(args, "interval", f"the model's {100 * level_:g} % interval: "
                    f"{args.resamples} bootstrap resamples of the fitting window{pooled}"):
            model = _with_interval(model, level_, args.resamples)
    elif (args.level is not None and model.uncertainty is not None
          and abs(model.uncertainty.level - args.level) > 1e-12):
        n = resamples_for(args.level)
        raise InputError(f"{args.model} holds a {model.uncertainty.percent} % interval, not "
                         f"{100 * args.level:g} %: add --resamples {n} to form it from {n} "
                         "bootstrap resamples of the model's fitting window")
    elif args.level is not None and model.uncertainty is None:
        n = resamples_for(args.level)
        raise InputError(f"{args.model} holds no interval (fitted with --resamples 0, or in "
                         f"Python): add --resamples {n} to form a {100 * args.level:g} % one "
                         f"from {n} bootstrap resamples of the model's fitting window")
    # a line every 5 s of work where the exact RTD takes long (a long tail, a long window)
    with _stage(args, "exact RTD", None):
        rtd = model.rtd(window=args.window_length)
    band = rtd.uncertainty              # the intrinsic RTD's only
    adequacy = getattr(model, "adequacy", None)
    warnings = [str(line) for line in getattr(adequacy, "warnings", ()) or ()]
    formed = model.uncertainty
    if (warnings and args.resamples and stored is not None
            and (formed is None or formed.level != stored.level
                 or tuple(formed.rt_mean_interval) != tuple(stored.rt_mean_interval))):
        # the verdict quotes and judges by the interval fit stored, not the one formed here
        # (said where they differ: the same resamples form the same interval)
        from cfbmarkov.markov.uncertainty import outward_bounds

        lo, hi = outward_bounds(*map(float, stored.rt_mean_interval), digits=4)
        warnings.append(f"the fitting sample's verdict above was made by fit with the model's "
                        f"stored {100 * stored.level:g} % E(RT) interval {lo}-{hi} s, not with "
                        "the interval formed here")
    from cfbmarkov.markov.model_summary import (fitting_run_count, left_out_classes_warning,
                                                on_window_warning,
                                                one_sided_interval_warnings,
                                                unresolved_warning)

    missed = None if adequacy is None else on_window_warning(model, adequacy)
    if missed:                          # the chain misses its own fitting window
        warnings.append(missed)
    unresolved = unresolved_warning(rtd)
    if unresolved is not None:
        warnings.append(unresolved)
    if band is not None:
        warnings += band.warnings(fitting_run_count(model))
    left_out = left_out_classes_warning(model)
    if left_out is not None:
        warnings.append(left_out)
    if band is not None and args.window_length is None:
        warnings += one_sided_interval_warnings(model, rtd, band)
    if args.resamples and band is not None and band.flow_sd is None:
        # an interval formed here, on a window too short for the flow's term: the verdict's
        # line, as fit gives it
        from cfbmarkov.analysis.adequacy import flow_term_line

        windows = model.run_windows or ((model.window,) if model.window else ())
        if windows:
            line = flow_term_line(min(b - a for a, b in windows), rtd.mean, len(windows))
            if not any(line.split(":")[0] in w for w in warnings):
                warnings.append(line)
    if args.json:
        out = {"rt_mean": rtd.mean, "rt_sd": rtd.sd, "direction": model.flow_direction,
               "window_length": args.window_length, "unresolved": rtd.unresolved,
               "level": None if band is None else band.level,
               "rt_mean_interval": None if band is None else list(band.rt_mean_interval),
               "rt_sd_interval": None if band is None else list(band.rt_sd_interval),
               "rtd_interval": None if band is None else {
                   "edges": band.rtd_edges.tolist(), "lower": band.rtd_interval[0].tolist(),
                   "upper": band.rtd_interval[1].tolist()},
               "rtd": {"lag": rtd.lag, "times": rtd.times.tolist(),
                       "probability": rtd.probability.tolist()},
               "warnings": warnings}
        print(json.dumps(jsonable(out), indent=1, allow_nan=False))
        return 0
    for line in warnings:
        print(f"warning: {one_line(line.strip())}", file=sys.stderr)
    kind = ('window ' + format(args.window_length, 'g') + ' s' if args.window_length
            else 'intrinsic')
    figures = (band.describe(rtd.mean, rtd.sd) if band is not None
               else f"E(RT) = {rtd.mean:.4f} s, SD(RT) = {rtd.sd:.4f} s")
    print(f"{figures} ({kind}, unresolved mass {rtd.unresolved:.2g}"
          + (": the share of the residences begun in the window that outlast it)"
             if args.window_length else ")"))
    if model.flow_direction == "down":
        from cfbmarkov.markov.model_summary import DOWNWARD_LINE

        print(f"  {DOWNWARD_LINE}")
    if band is None and model.uncertainty is not None:
        print(f"  the model's {model.uncertainty.percent} % interval is of the intrinsic RTD: "
              "leave out --window-length to see it")
    elif model.uncertainty is None and not args.window_length:
        print("  no interval: the model carries none (fitted with --resamples 0, or in "
              "Python); `rtd MODEL --resamples 100` or a fit without --resamples 0 gives one")
    return 0


def cmd_info(args) -> int:
    """``cfbmarkov info``: describe a model or trajectory file.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    import h5py

    from cfbmarkov._hdf5 import open_h5

    with open_h5(args.file) as f:
        fmt = f.attrs.get("format")
    if isinstance(fmt, bytes):
        fmt = fmt.decode(errors="replace")
    if fmt is not None and fmt not in ("cfbmarkov.model", "cfbmarkov.trajectories"):
        raise InputError(f"{args.file}: neither a cfbmarkov trajectory nor model file (its "
                         f"format attribute is {fmt!r}); import particle data first "
                         "(cfbmarkov import), or give a model that cfbmarkov fit wrote")
    if fmt == "cfbmarkov.model":
        from cfbmarkov.markov import MarkovModel

        print(MarkovModel.load(args.file).summary())
    else:
        from cfbmarkov.trajectories import Trajectories
        from cfbmarkov.trajectory_info import describe

        with Trajectories(args.file) as t:
            print("\n".join(describe(t)))
        from cfbmarkov._names import parts_folder

        waiting = parts_folder(args.file) / "checkpoint.h5"
        if waiting.is_file():
            print(f"note: {waiting.parent} holds an interrupted simulate run to this file; "
                  "until it is resumed (simulate --resume) or deleted, this file is the "
                  "earlier run", file=sys.stderr)
    del h5py
    return 0


def add_fit(sub) -> None:
    """Add the ``fit`` verb (fit a model) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("fit", help="fit a Markov chain model on a window of a trajectory file")
    s.add_argument("run", nargs="+",
                   help="trajectory file; several runs of one case (same riser and frame "
                        "interval) pool their transitions into one model")
    s.add_argument("--cells", type=parse_cells, default=(6, 38),
                   help="COLUMNSxROWS, or COLUMNSxDEPTHxROWS for 3D data (depth columns; "
                        "COLUMNSxROWS projects 3D data on across x vertical) (default 6x38)")
    s.add_argument("--lag", type=positive_float, default=0.025, help="lag, s (default 0.025)")
    s.add_argument("--window", type=parse_windows, default=None,
                   help="fitting window START:STOP, s (default 10:15); with several runs one "
                        "window for all or one per run, comma-separated (10:15,12:17)")
    s.add_argument("--estimator", choices=["paper", "mle"], default=None,
                   help="paper (Eq. 2-4; the default for the paper's cells on a periodic "
                        "riser) or mle (pooled counts; the default for a state space with "
                        "memory or auto, and the only choice for an open riser)")
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
    s.add_argument("--no-adequacy", dest="adequacy", action="store_false",
                   help="leave out the verdict on the fitting sample (the window's halves and "
                        "quarters refitted and compared, the net flow per part, the residences "
                        "longer than the window)")
    s.add_argument("--level", type=level, default=None,
                   help="coverage of the interval of the model's E(RT), SD(RT) and RTD "
                        "(default 0.9; refused with --resamples 0)")
    s.add_argument("--resamples", type=count(0, 100000), default=100,
                   help="bootstrap resamples of the fitting window for the model's interval "
                        "(0: no interval; default 100)")
    s.add_argument("-o", "--output", required=True, help="model file (.h5)")
    s.add_argument("-q", "--quiet", action="store_true",
                   help="no progress lines on stderr")
    s.set_defaults(func=cmd_fit)


def add_predict(sub) -> None:
    """Add the ``predict`` verb (a Monte Carlo prediction) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("predict", help="Monte Carlo prediction from a run's state at a start time")
    s.add_argument("model", help="model file (.h5, from cfbmarkov fit)")
    s.add_argument("--init", required=True, help="trajectory file giving the initial state")
    s.add_argument("--start", type=finite_float, required=True, help="initial frame time, s")
    s.add_argument("--duration", type=positive_float, required=True, help="simulated time, s")
    s.add_argument("--seed", type=seed, default=0, help="0 .. 2^64 - 1 (default 0)")
    s.add_argument("-o", "--output", required=True, help="prediction trajectory file (.h5)")
    s.add_argument("-q", "--quiet", action="store_true",
                   help="no progress on stderr (a bar on a terminal, whole lines in a log file)")
    s.set_defaults(func=cmd_predict)


def add_rtd(sub) -> None:
    """Add the ``rtd`` verb (a model's RTD) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("rtd", help="exact residence-time distribution of a model")
    s.add_argument("model", help="model file (.h5, from cfbmarkov fit)")
    s.add_argument("--window-length", type=positive_float, default=None,
                   help="observation window, s: the RTD as seen in such a window (default "
                        "none: the chain's intrinsic RTD)")
    s.add_argument("--json", action="store_true",
                   help="print rt_mean, rt_sd, direction, level, rt_mean_interval, "
                        "rt_sd_interval, rtd_interval, unresolved, warnings and the exact "
                        "RTD itself (rtd: lag, times, probability of each residence time "
                        "k lags) as JSON")
    s.add_argument("--level", type=level, default=None,
                   help="coverage of the interval (default: the model's, else 0.9; another "
                        "than the model's needs --resamples)")
    s.add_argument("--resamples", type=count(0, 100000), default=0,
                   help="form the interval of the intrinsic RTD anew from this many "
                        "bootstrap resamples of the model's fitting window (default 0: the "
                        "one stored in the model; not with --window-length)")
    s.add_argument("-q", "--quiet", action="store_true",
                   help="no progress on stderr while --resamples forms the interval")
    s.set_defaults(func=cmd_rtd)


def add_info(sub) -> None:
    """Add the ``info`` verb (describe a file) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("info", help="describe a trajectory or model file")
    s.add_argument("file", help="trajectory file or model file (.h5)")
    s.set_defaults(func=cmd_info)
