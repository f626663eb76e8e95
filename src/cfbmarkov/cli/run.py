"""The verbs that run whole jobs: ``reproduce``, ``demo`` and ``bench``."""

from __future__ import annotations

import argparse

from cfbmarkov.cli.options import (MAX_JOBS, MAX_PARTICLES, count, parse_names,
                                   parse_velocities, seed)


def cmd_reproduce(args) -> int:
    """``cfbmarkov reproduce``: the paper end to end; print the report's path.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    from cfbmarkov.reproduce import load_overrides, reproduce

    overrides = load_overrides(args.overrides) if args.overrides else None
    report = reproduce(args.output, args.scale, args.velocities, overrides=overrides,
                       models=args.models, scheduler=args.scheduler, jobs=args.jobs,
                       progress=not args.quiet, log=lambda line: print(line, flush=True),
                       kinetics=args.kinetics, ensemble=args.ensemble, device=args.device)
    _print_verdict(report)
    print(report)
    return 0


def cmd_demo(args) -> int:
    """``cfbmarkov demo``: the quick reproduction (or the synthetic demo); print its output.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    _check_demo_folder(args.output, args.synthetic)
    if args.synthetic:
        from cfbmarkov.demo import run_demo

        particles = SYNTHETIC_PARTICLES if args.particles is None else args.particles
        seed_ = SYNTHETIC_SEED if args.seed is None else args.seed
        out = run_demo(args.output, particles=particles, seed=seed_,
                       progress=None if args.quiet else _stderr_line, force=args.force,
                       note=_stderr_line, warn=_stderr_line)
        print(out)
        return 0
    from cfbmarkov.reproduce import reproduce

    report = reproduce(args.output, "quick", jobs=args.jobs, progress=not args.quiet,
                       log=lambda line: print(line, flush=True))
    _print_verdict(report)
    print(f"report: {report}")
    return 0


def _print_verdict(report) -> None:
    """The report's verdict line on the terminal, as the synthetic demo prints its own
    (nothing where the run wrote no report)."""
    if report is None or not str(report).endswith(".html"):
        return
    from cfbmarkov.report.reproduction import report_verdict

    verdict = report_verdict(report)
    if verdict:
        print(f"verdict: {verdict}")


def _stderr_line(text: str) -> None:
    from cfbmarkov._console import write_line

    write_line(text)


#: the default output folders of ``cfbmarkov demo`` and ``cfbmarkov demo --synthetic``
DEMO_FOLDER, SYNTHETIC_FOLDER = "cfbmarkov-demo", "cfbmarkov-demo-synthetic"


#: the synthetic demo's default particles and seed
SYNTHETIC_PARTICLES, SYNTHETIC_SEED = 6000, 1
#: the options of ``cfbmarkov demo`` that apply only with --synthetic
SYNTHETIC_ONLY = ("particles", "seed")


def demo_option_error(args) -> str | None:
    """Why the options of ``cfbmarkov demo`` cannot run together, in one line (None where
    they can): the synthetic demo's options given without ``--synthetic``, which the
    CFD-DEM demo would otherwise drop.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options (``particles`` and ``seed`` None where not given).

    Returns
    -------
    str or None
    """
    if args.synthetic:
        return None
    given = [f"--{name}" for name in SYNTHETIC_ONLY if getattr(args, name) is not None]
    if not given:
        return None
    named = " and ".join(given)
    return (f"{named} {'applies' if len(given) == 1 else 'apply'} only with --synthetic (the "
            "synthetic demo); the CFD-DEM demo (reproduce --scale quick) has no such option: "
            f"add --synthetic, or leave out {named}")


def demo_output(output: str | None, synthetic: bool) -> str:
    """The demo's output folder: ``output``, or the default of its kind (the CFD-DEM demo
    and the synthetic demo never share a default folder)."""
    if output is not None:
        return output
    return SYNTHETIC_FOLDER if synthetic else DEMO_FOLDER


def _check_demo_folder(output: str, synthetic: bool) -> None:
    """Refuse, in one line, a demo into a folder that holds the demo of the other kind
    (the CFD-DEM demo leaves ``reproduce.json``, the synthetic one ``demo.json`` or
    ``reference.h5``): their files would mix."""
    from pathlib import Path

    from cfbmarkov.errors import InputError

    folder = Path(output)
    if not folder.is_dir():
        return
    cfd_dem = (folder / "reproduce.json").exists()
    synthetic_files = [n for n in ("demo.json", "reference.h5") if (folder / n).exists()]
    if synthetic and cfd_dem:
        raise InputError(f"{output} holds the CFD-DEM demo (reproduce.json): the synthetic "
                         f"demo's files would mix with it; give it its own folder (-o "
                         f"{SYNTHETIC_FOLDER}, its default) or remove {output}")
    if not synthetic and synthetic_files and not cfd_dem:
        raise InputError(f"{output} holds the synthetic demo ({synthetic_files[0]}): the "
                         f"CFD-DEM demo's files would mix with it; give it its own folder "
                         f"(-o {DEMO_FOLDER}, its default) or remove {output}")


def cmd_bench(args) -> int:
    """``cfbmarkov bench``: one line per benchmark figure.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    import sys
    import time

    from cfbmarkov.bench import check_names, run_benchmarks

    check_names(args.only)
    started = time.perf_counter()
    if not args.quiet:
        print(f"bench: {', '.join(args.only) if args.only else 'all figures'}, "
              f"{args.particles} particles, median of {args.repeat}; each figure is printed "
              "when measured", file=sys.stderr, flush=True)
    for name, value, unit in run_benchmarks(only=args.only, repeat=args.repeat,
                                            particles=args.particles):
        print(f"{name}: {value:.4g} {unit}", flush=True)
        if not args.quiet:
            print(f"bench: {name} done, {time.perf_counter() - started:.0f} s so far",
                  file=sys.stderr, flush=True)
    return 0


def add_reproduce(sub) -> None:
    """Add the ``reproduce`` verb (the paper end to end) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("reproduce", help="the paper end to end at U = 3, 4, 6, 8 m/s: CFD-DEM, "
                       "Markov models, predictions, comparison, report")
    s.add_argument("--scale", choices=["paper", "quick"], default="quick",
                   help="paper: the paper's riser and 0-20 s (hours); quick: a reduced riser "
                        "(minutes); default quick")
    s.add_argument("-o", "--output", required=True, help="output directory (rerun to resume)")
    s.add_argument("--velocities", type=parse_velocities, default=[3.0, 4.0, 6.0, 8.0],
                   help="comma-separated superficial gas velocities U, m/s (default 3,4,6,8)")
    s.add_argument("--models", type=parse_names, default=["paper", "mle", "auto"],
                   help="comma-separated models: paper, mle (the paper's cells with that "
                        "estimator), auto (state space and lag chosen on the fitting window), "
                        "or STATES[:ESTIMATOR] (default paper,mle,auto)")
    s.add_argument("--overrides", default=None,
                   help="TOML file of changes applied to every case (same tables as a case file)")
    s.add_argument("--jobs", type=count(1, MAX_JOBS), default=None,
                   help="local worker processes (default: min(cases, cores))")
    s.add_argument("--scheduler", default=None,
                   help="address of a Dask distributed scheduler (tcp://host:8786) to run the "
                        "cases on; the workers must see the output directory")
    s.add_argument("--kinetics", default=None, metavar="FILE",
                   help="a kinetics file (TOML): every comparison also gives its properties "
                        "for the CFD-DEM, the model and the segregated-flow baseline "
                        "(compare --kinetics)")
    s.add_argument("--ensemble", type=count(1, 1000), default=1, metavar="N",
                   help="N independent CFD-DEM runs per case (seeds as simulate --ensemble), "
                        "written to cfd-dem-m0.h5 ...: each model is fitted on their fitting "
                        "windows pooled and compared on member 0's prediction window "
                        "(default 1)")
    s.add_argument("--device", choices=("cpu", "gpu"), default="cpu",
                   help="where the CFD-DEM's DEM runs (default cpu; gpu needs an NVIDIA GPU "
                        "and numba-cuda)")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=cmd_reproduce)


def add_demo(sub) -> None:
    """Add the ``demo`` verb (the demo) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("demo", help="the main job on a fresh machine: 'reproduce --scale quick' "
                       "(about 4 min on 2 quiet cores), ending with the path of its report")
    s.add_argument("-o", "--output", default=None,
                   help=f"output directory (default {DEMO_FOLDER}; with --synthetic "
                        f"{SYNTHETIC_FOLDER}); a folder holding the demo of the other kind "
                        "is refused, and with --synthetic one holding files the demo did not "
                        "write or wrote with other --particles or --seed (--force to write "
                        "anyway); the synthetic reference of the same parameters is reused")
    s.add_argument("--jobs", type=count(1, MAX_JOBS), default=None,
                   help="local worker processes running the cases side by side (default: "
                        "min(4 cases, cores))")
    s.add_argument("--synthetic", action="store_true",
                   help="instead, the Markov part alone on synthetic core-annulus trajectories "
                        "of 0-20 s (under a minute on 2 quiet cores): its verdict on stdout, "
                        "demo.json and each model's comparison, no report")
    s.add_argument("--particles", type=count(1, MAX_PARTICLES), default=None,
                   help=f"with --synthetic only (refused without it): particles (default "
                        f"{SYNTHETIC_PARTICLES})")
    s.add_argument("--seed", type=seed, default=None,
                   help=f"with --synthetic only (refused without it): seed (default "
                        f"{SYNTHETIC_SEED})")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=cmd_demo)


class _NamesKeptWhole(argparse.HelpFormatter):
    """Help lines wrapped at spaces only, so that figure names such as ``mcm-fit-regime``
    are never split at their hyphens."""

    def _split_lines(self, text, width):
        import textwrap

        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)


def add_bench(sub) -> None:
    """Add the ``bench`` verb (benchmarks) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    from cfbmarkov.bench import GROUPS, MCM_NAMES, SIMULATION_NAMES

    s = sub.add_parser("bench", help="benchmarks; one line per figure as 'name: value unit'",
                       formatter_class=_NamesKeptWhole)
    s.add_argument("--only", action="append", default=None, metavar="NAME",
                   help="run only this group or figure (repeatable; default all): groups "
                        f"{', '.join(GROUPS)}; figures {', '.join(MCM_NAMES)}, "
                        f"{', '.join(SIMULATION_NAMES)} (a DEM figure brings its LAMMPS lines)"
                        .replace("%", "%%"))
    s.add_argument("--repeat", type=count(1, 1000), default=5,
                   help="repetitions (median reported; default 5)")
    s.add_argument("--particles", type=count(1, MAX_PARTICLES), default=27000,
                   help="particles of the benchmarks' problems (default 27000, the paper's)")
    s.add_argument("-q", "--quiet", action="store_true",
                   help="no progress lines on stderr (the figures still go to stdout)")
    s.set_defaults(func=cmd_bench)
