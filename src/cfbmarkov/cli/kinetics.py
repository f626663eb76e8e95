"""The ``react`` verb: particle properties along the chain's paths (reactions, heat
exchange, deactivation; ``docs/how-to/kinetics.md``)."""

from __future__ import annotations

import sys
import time

from cfbmarkov._names import one_line
from cfbmarkov.cli.options import count, finite_float, level, positive_float, seed
from cfbmarkov.errors import CfbmarkovError, InputError


def cmd_react(args) -> int:
    """``cfbmarkov react``: exact answers of a kinetics file on a model, and a Monte Carlo
    with the properties where ``--init`` is given.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    mc = {"--init RUN": args.init, "--start T": args.start, "--duration D": args.duration,
          "-o OUT": args.output}
    missing = [name for name, value in mc.items() if value is None]
    if len(missing) < len(mc) and missing:
        raise InputError(f"the Monte Carlo needs all of --init RUN --start T --duration D "
                         f"-o OUT: add {' '.join(missing)}")
    if not len(missing) < len(mc) and args.seed != 0:
        raise InputError("--seed seeds the Monte Carlo (--init RUN --start T --duration D "
                         "-o OUT); the exact answers use none: leave it out, or add those")
    if args.passes and len(set(args.passes)) < len(args.passes):
        twice = sorted({n for n in args.passes if args.passes.count(n) > 1})
        raise InputError(f"--passes gives {', '.join(map(str, twice))} more than once: give "
                         "each number of passes once")
    if 0 < args.resamples < 10:
        raise InputError(f"--resamples {args.resamples}: an interval needs at least 10 "
                         "bootstrap resamples (0 leaves it out)")
    if args.level is not None and not args.resamples:
        from cfbmarkov.cli.markov import resamples_for

        raise InputError(f"--level {args.level:g} sets the intervals' coverage, which "
                         "--resamples N forms (the exact values carry none without it): add "
                         f"--resamples {resamples_for(args.level)}")
    args.level = 0.9 if args.level is None else args.level
    from cfbmarkov.cli.markov import _check_resamples

    _check_resamples(args.resamples, args.level)
    if args.output is not None:
        # the Monte Carlo's output claimed (locked, checked) before any work, as every
        # writing verb's is: a second writer of it is refused at once, not overwritten later
        from cfbmarkov._outputs import claim_output

        with claim_output(args.output, "react", "prediction", [args.model, args.init],
                          force=args.force):
            return _react(args)
    return _react(args)


def _react(args) -> int:
    """:func:`cmd_react` once its options are checked (and its output claimed)."""
    import json

    from cfbmarkov._json import jsonable
    from cfbmarkov.analysis.cell_fields import model_cell_fields
    from cfbmarkov.analysis.kinetics_compare import needs_cell_fields
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.kinetics_exact import exact_kinetics

    kinetics = load_kinetics(args.kinetics)
    model = MarkovModel.load(args.model)
    fields, fields_from = None, None
    if needs_cell_fields(kinetics):
        fields = model_cell_fields(model, args.run, what=str(args.kinetics),
                                   model_name=str(args.model))
        fields_from = "model" if model.cell_fields is not None else str(args.run)
    elif args.run is not None:      # a file that is not the model's is refused all the same
        from cfbmarkov.analysis.cell_fields import check_fitting_file

        check_fitting_file(model, args.run, model_name=str(args.model))
    state_kinetics = kinetics.per_state(model.state_space, fields)
    notes = list(kinetics.field_notes(fields)) + list(kinetics.grid_notes(model.state_space))
    for note in notes:
        print(f"warning: {one_line(note)}", file=sys.stderr)
    # the model's own verdict, printed once the answers stand (a refusal stays one line):
    # exact answers rest on the chain as much as a Monte Carlo does
    verdict = [f"the model's fitting sample: {line}"
               for line in (model.adequacy.warnings if model.adequacy is not None else ())]
    verdict += _chain_warnings(model)
    if args.resamples:          # the exit means' intervals share the model's bootstrap
        verdict += [line for line in _interval_warnings(model) if line not in verdict]
    if args.init is not None:        # what its Monte Carlo inherits (an open riser's hold-up)
        from cfbmarkov.markov.model_summary import monte_carlo_warnings

        verdict += [line for line in (f"the model: {text}" for text in
                                      monte_carlo_warnings(model)) if line not in verdict]
    said = []                # notes that --json's warnings repeat
    if args.passes and "carried" not in [p.start for p in kinetics.properties]:
        said.append("--passes follows carried properties (start = \"carried\"); this "
                    "kinetics file has none, so it is left out")
        print(f"note: {said[-1]}", file=sys.stderr)
    passes = tuple(args.passes) if args.passes else PASSES
    if args.init is not None:       # a start from the reference, checked before the run
        from cfbmarkov.trajectories import Trajectories

        from cfbmarkov.markov.prediction import check_reference_starts

        with Trajectories(args.init) as run:
            check_reference_starts(run, kinetics, float(args.start))
    answers, seconds = {}, None
    if kinetics.linear:
        t0 = time.perf_counter()
        answers = exact_kinetics(model, state_kinetics)
        seconds = time.perf_counter() - t0
    elif args.init is None:
        raise InputError(f"{args.kinetics}: a law without an exact answer; run the Monte "
                         "Carlo with --init RUN --start T --duration D -o OUT")
    if args.init is not None:
        import warnings

        from cfbmarkov._outputs import claim_output
        from cfbmarkov.errors import SampleWarning
        from cfbmarkov.trajectories import Trajectories

        with claim_output(args.output, "react", "prediction", [args.model, args.init],
                          force=args.force):         # re-entrant: claimed by cmd_react
            with Trajectories(args.init) as run, warnings.catch_warnings():
                warnings.simplefilter("ignore", SampleWarning)  # printed below
                model.predict(run, start=args.start, duration=args.duration, seed=args.seed,
                              output=args.output, progress=not args.quiet,
                              kinetics=state_kinetics)
    # exits are counted in the model's direction: down through the bottom for a periodic
    # model of a net downflow (docs/definitions.md, Net downflow), as fit and rtd say
    direction = model.flow_direction
    intervals, taken, after_intervals, flow = _exit_mean_intervals(
        args, model, kinetics, fields, answers, direction, passes)
    for line in verdict:
        print(f"warning: {one_line(line)}", file=sys.stderr)
    if args.json:
        space = model.state_space
        out = {"properties": {name: {**a.to_dict(passes if p.start == "carried" else ()),
                                     "law": p.law.key,
                                     "exit_mean_interval": intervals.get(name),
                                     "exit_mean_flow_sd": flow.get(name)}
                              for (name, a), p in zip(answers.items(), kinetics.properties)},
               "level": args.level, "interval_resamples": taken,
               "exact_seconds": seconds, "prediction": args.output,
               "monte_carlo": (None if args.output is None else
                               _monte_carlo_bed_means(args.output, kinetics.names)),
               "cell_fields_from": fields_from, "direction": direction,
               "grid": {"columns": space.columns, "rows": space.rows,
                        "depth_columns": space.depth_columns,
                        "bed_mean_by_cell": "cell = (row * depth_columns + depth column) * "
                                            "columns + column, from the bottom left"},
               "warnings": [one_line(n) for n in notes + said + verdict]}
        for name, entry in out["properties"].items():
            for n, after in entry.get("after_passes", {}).items():
                after["mean_interval"] = after_intervals.get((name, int(n)))
        print(json.dumps(jsonable(out)))
        return 0
    if answers:
        print(f"{'property':<14} {'law':<14} {'start':<9} {'exit mean':>12} {'exit SD':>12} "
              f"{'bed mean':>12} {'bed min..max per cell':>26}")
        for p in kinetics.properties:
            a = answers[p.name]
            finite = a.bed_mean_by_cell[a.bed_mean_by_cell == a.bed_mean_by_cell]
            span = f"{finite.min():.6g} .. {finite.max():.6g}" if finite.size else "-"
            print(f"{p.name:<14} {p.law.key:<14} {p.start:<9} {a.exit_mean:>12.6g} "
                  f"{a.exit_sd:>12.6g} {a.bed_mean:>12.6g} {span:>26}")
        print("exact, per residence at the exit and over the bed in steady state, in the "
              f"units of the kinetics file's values; computed in {seconds:.3g} s")
        if args.resamples:
            for p in kinetics.properties:
                bounds = intervals.get(p.name)
                print(f"  {100 * args.level:g} % interval of {p.name}'s exit mean: "
                      + ("none (too few resamples with residences)" if bounds is None else
                         _span(bounds))
                      + f" (the fitting window's block bootstrap, {taken} resamples"
                      + ("; the flow's variability between windows left out)"
                         if p.name not in flow else
                         f", with the flow's variability between windows as its E(RT) "
                         f"interval carries it, {100 * flow[p.name]['rt_mean_relative']:.3g} "
                         "%, as a stretch of every residence)"))
        else:
            print("  exact for the fitted chain, without its sampling uncertainty: "
                  "--resamples 100 adds the exit means' intervals (an exact solve per "
                  "resample), `compare RUN PRED --kinetics FILE` judges them against a run")
        for p in kinetics.properties:
            if p.start == "carried":
                a = answers[p.name]
                after = [a.after_passes(n) for n in passes]
                print(f"  {p.name} (carried): the circulating inventory's steady state, every "
                      "particle entering with its previous exit value"
                      + (" (nothing brings it back: it tends to 0)" if a.exit_mean == 0
                         and a.initial != 0 else ""))
                print(f"  {p.name} after {' / '.join(map(str, passes))} passes from "
                      f"{a.initial:g}: exit mean {' / '.join(f'{m:.6g}' for m, _ in after)}"
                      f" (SD {' / '.join(f'{sd:.3g}' for _, sd in after)}; --passes N for "
                      "others)")
                bounds = [after_intervals.get((p.name, n)) for n in passes]
                if args.resamples:
                    print(f"  {100 * args.level:g} % intervals of {p.name}'s mean after "
                          f"{' / '.join(map(str, passes))} passes: "
                          + " / ".join("none" if b is None else _span(b) for b in bounds)
                          + (" (cut at the least value its law allows)" if any(
                              b is not None and b[0] == getattr(p.law, "initial_range",
                                                                (None,))[0]
                              for b in bounds) else ""))
            elif p.start == "reference" and args.init is None:
                print(f"  {p.name} (start = reference): the exact answers are those of a fresh "
                      f"feed entering at {p.initial:g} (start = entry); the reference's values "
                      "are taken by the Monte Carlo, with --init RUN --start T")
        if direction == "down":
            from cfbmarkov.markov.model_summary import DOWNWARD_LINE

            print("  exits counted downward, at the pass down through the bottom "
                  f"({DOWNWARD_LINE})")
    if args.output is not None:
        _print_monte_carlo(args.output, [p.name for p in kinetics.properties])
        print(args.output)
    sys.stdout.flush()
    return 0


def _chain_warnings(model) -> list[str]:
    """What `fit`, `rtd` and `info` say of the chain that the exact answers rest on as
    well: residences it never ends (unresolved mass), states that trap particles, closed
    classes its exact answers leave out, and a chain that misses its own fitting window."""
    from cfbmarkov.markov.model_summary import (left_out_classes_warning, on_window_warning,
                                                trap_warning, unresolved_warning)

    lines = []
    from cfbmarkov.markov.first_passage import DEFICIT_TOL

    try:
        rtd = model.rtd()
        unresolved = unresolved_warning(rtd)
    except CfbmarkovError:      # no residence: exact_kinetics refuses it in its own words
        rtd, unresolved = None, None
    if unresolved is not None and (rtd.deficit_unresolved or 0.0) > DEFICIT_TOL:
        lines.append(f"the model: {unresolved}; the exact exit values and bed means likewise "
                     "follow only the residences that stay within the lap deficits computed, "
                     "and lean as E(RT) does")
    elif unresolved is not None:
        lines.append(f"the model: {unresolved}; the exit values likewise average only the "
                     "residences that end, and the bed means leave the particles that never "
                     "leave out")
    trapped = trap_warning(model)
    if trapped is not None:
        lines.append(f"the model: {trapped}")
    left_out = left_out_classes_warning(model)
    if left_out is not None:
        lines.append(f"the model: {left_out}; the bed means are those of the other classes "
                     "(the cells of the classes left out have none)")
    missed = on_window_warning(model)
    if missed:           # an RTD that misses its window's spread misses the conversion too
        lines.append(f"the model: {missed}")
    if model.open_flow is not None:     # returns through the inlet, censored tracks: the
        # exits the exact answers follow are read as the chain's
        lines += [f"the model: {text.strip()}" for text in model.open_flow.warnings()]
    return lines


def _interval_warnings(model) -> list[str]:
    """The model's lines on its E(RT) interval (one-sided, or its lower end cut at 0):
    the bootstrap of the fitting window that the exit means' intervals come from has the
    same resamples (:func:`~cfbmarkov.markov.model_summary.one_sided_interval_warnings`)."""
    from cfbmarkov.markov.model_summary import fitting_run_count, one_sided_interval_warnings

    if model.uncertainty is None:
        return []
    return [f"the model: {line}" for line in
            model.uncertainty.warnings(fitting_run_count(model))
            + one_sided_interval_warnings(model)]


def _exit_mean_intervals(args, model, kinetics, fields, answers, direction, passes=()):
    """:func:`cfbmarkov.analysis.kinetics_compare.exit_mean_intervals` at ``args.level``
    from ``args.resamples`` resamples, its progress shown: ({name: [lo, hi] or None},
    resamples solved, {(name, n): [lo, hi] or None}, {name: the flow term} of the
    properties whose interval carries it). Warnings go to stderr."""
    if not args.resamples or not answers:
        return {}, 0, {}, {}
    from cfbmarkov.analysis.intervals import resolve_source
    from cfbmarkov.analysis.kinetics_compare import exit_mean_intervals

    from cfbmarkov.cli.markov import _stage

    notes: list[str] = []
    source = resolve_source(model, [args.run] if args.run else [])     # its refusal first
    runs = len(source.source) if isinstance(source.source, (list, tuple)) else 1
    where = (f"the {runs} runs' fitting windows" if runs > 1 else "the fitting window")
    with _stage(args, "intervals", f"the exit means' {100 * args.level:g} % intervals: "
                f"{args.resamples} bootstrap resamples of {where}, each solved exactly"):
        formed = exit_mean_intervals(source, kinetics, answers, level=args.level,
                                     resamples=args.resamples, fields=fields,
                                     direction=direction, passes=passes, warnings=notes,
                                     resolve=False)
    for note in notes:
        print(f"warning: {one_line(note)}", file=sys.stderr)
    return formed["exit_mean"], formed["resamples"], formed["after_passes"], formed["flow_sd"]


def _span(bounds) -> str:
    """An interval as text, 'a-b', or 'a to b' where an end is negative (a minus beside
    the dash cannot be read)."""
    lo, hi = bounds
    return f"{lo:.6g} to {hi:.6g}" if min(lo, hi) < 0 else f"{lo:.6g}-{hi:.6g}"


def _monte_carlo_bed_means(prediction, names) -> dict:
    """The Monte Carlo's bed mean of each property at its first and last frames, over the
    particles present, with its standard error (SD / sqrt(n) of the frame's particles, as
    independent draws) and the particle count: ``{name: {"times": [t0, t1], "bed_mean":
    [m0, m1], "bed_mean_se": [s0, s1], "particles": [n0, n1]}}``."""
    import numpy as np

    from cfbmarkov.trajectories import Trajectories

    out = {}
    with Trajectories(prediction) as pred:
        times = [float(pred.times[0]), float(pred.times[-1])]
        for name in names:
            values = [pred.property_values(name, k)[pred.present(k)] for k in (0, -1)]
            values = [v[np.isfinite(v)] for v in values]
            out[name] = {"times": times,
                         "bed_mean": [float(v.mean()) if v.size else float("nan")
                                      for v in values],
                         "bed_mean_se": [float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1
                                         else float("nan") for v in values],
                         "particles": [int(v.size) for v in values]}
    return out


def _print_monte_carlo(prediction, names) -> None:
    """The Monte Carlo's bed means at its first and last frames (over the particles
    present), and where to judge it: its exits carry the start's transient."""
    parts = [f"{name} {m['bed_mean'][0]:.6g} at {m['times'][0]:g} s, {m['bed_mean'][1]:.6g} "
             f"at {m['times'][1]:g} s (standard error {m['bed_mean_se'][1]:.2g} over its "
             f"{m['particles'][1]} particles)"
             for name, m in _monte_carlo_bed_means(prediction, names).items()]
    print(f"Monte Carlo, bed mean over the particles present: {'; '.join(parts)} (its "
          "particles start from the values at the start, so a window shorter than a few "
          "E(RT) carries that transient; `cfbmarkov compare RUN PREDICTION --kinetics FILE` "
          "judges the exits and the bed over the window)")


#: the passes after which ``react`` gives a carried property's exit value by default
PASSES = (1, 10, 100)


def add_react(sub) -> None:
    """Add the ``react`` verb (kinetics along particle paths) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("react", help="properties along particle paths (reaction, heat, "
                                     "deactivation): exact answers, and a Monte Carlo")
    s.add_argument("model", help="model file (.h5, from cfbmarkov fit)")
    s.add_argument("--kinetics", required=True,
                   help="kinetics file (TOML, one [[property]] table per property)")
    s.add_argument("--run", default=None, metavar="RUN.h5",
                   help="the model's fitting file, for rates given as a function of a cell "
                        "field (rate_from = ...) where the model stores no cell fields "
                        "(cfbmarkov fit stores them)")
    s.add_argument("--json", action="store_true",
                   help="print {\"properties\": {NAME: {exit_mean, exit_sd, bed_mean, "
                        "bed_mean_by_cell, ...}}, \"direction\": up or down (exits counted "
                        "downward through the bottom: a net downflow), ...} as JSON")
    s.add_argument("--passes", type=count(1, 10 ** 6), nargs="+", default=None, metavar="N",
                   help="for a carried property, the exit mean and SD after N passes "
                        "through the riser from its initial value (default "
                        f"{' '.join(map(str, PASSES))})")
    s.add_argument("--init", default=None,
                   help="trajectory file giving the initial state of a Monte Carlo with the "
                        "properties (with --start, --duration and -o)")
    s.add_argument("--start", type=finite_float, default=None, help="initial frame time, s")
    s.add_argument("--duration", type=positive_float, default=None, help="simulated time, s")
    s.add_argument("--seed", type=seed, default=0, help="0 .. 2^64 - 1 (default 0)")
    s.add_argument("-o", "--output", default=None,
                   help="prediction trajectory file (.h5) with /properties/NAME per frame")
    s.add_argument("--force", action="store_true",
                   help="replace an existing output of another kind")
    s.add_argument("--resamples", type=count(0, 10 ** 4), default=0,
                   help="block-bootstrap resamples of the model's fitting window for the "
                        "exit means' intervals, each an exact solve (default 0: none; 100 "
                        "as fit; at least 10)")
    s.add_argument("--level", type=level, default=None,
                   help="coverage of the exit means' intervals (default 0.9; with "
                        "--resamples)")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_react)
