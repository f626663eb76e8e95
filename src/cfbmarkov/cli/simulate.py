"""The verbs of the CFD-DEM: ``simulate`` and ``cases``."""

from __future__ import annotations

from cfbmarkov.cli.options import MAX_PARTICLES, count, positive_float


def cmd_simulate(args) -> int:
    """``cfbmarkov simulate``: run a case; print the trajectory file.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    from cfbmarkov.config import load_case
    from cfbmarkov.simulate.run import simulate

    case = load_case(args.case)
    if args.particles is not None:
        case = case.model_copy(update={"particles": case.particles.model_copy(
            update={"number": args.particles})})
    if args.ensemble is None and args.device == "cpu":
        out = simulate(case, args.output, until=args.until,
                       checkpoint_every=args.checkpoint_every, resume=args.resume,
                       progress=not args.quiet, force=args.force)
        print(out)
        return 0
    from cfbmarkov.simulate.ensemble import simulate_ensemble
    for out in simulate_ensemble(case, args.output, args.ensemble, device=args.device,
                                 until=args.until, checkpoint_every=args.checkpoint_every,
                                 resume=args.resume, progress=not args.quiet,
                                 force=args.force):
        print(out)
    return 0


def cmd_cases(args) -> int:
    """``cfbmarkov cases``: one line per shipped case.

    Parameters
    ----------
    args : argparse.Namespace
        The verb's parsed options.

    Returns
    -------
    int
        The exit code, 0 (errors are raised as :class:`~cfbmarkov.errors.CfbmarkovError`).
    """
    from cfbmarkov.config import case_names, load_case

    for name in case_names():
        c = load_case(name)
        print(f"{name}: U = {c.gas.superficial_velocity:g} m/s, {c.particles.number} particles, "
              f"{c.riser.width:g} x {c.riser.height:g} m, 0-{c.output.end_time:g} s")
    return 0


def add_simulate(sub) -> None:
    """Add the ``simulate`` verb (CFD-DEM of a case) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("simulate", help="CFD-DEM of the periodic riser (a TOML case or a shipped name)")
    s.add_argument("case", help="case file (.toml) or shipped case name (see 'cfbmarkov cases')")
    s.add_argument("-o", "--output", required=True, help="trajectory file (.h5)")
    s.add_argument("--until", type=positive_float, default=None, help="end time, s (default: the case's)")
    s.add_argument("--checkpoint-every", type=positive_float, default=1.0,
                   help="simulated seconds between checkpoints (default 1)")
    s.add_argument("--resume", action="store_true", help="continue an interrupted run")
    s.add_argument("--particles", type=count(1, MAX_PARTICLES), default=None,
                   help="override the number of particles")
    s.add_argument("--ensemble", type=count(1, 1000), default=None, metavar="N",
                   help="N independent runs of the case, written to RUN-m0.h5 ... "
                        "RUN-m<N-1>.h5 for -o RUN.h5; member m's seed is word 0 of child m "
                        "of numpy SeedSequence(case seed).spawn(N)")
    s.add_argument("--device", choices=("cpu", "gpu"), default="cpu",
                   help="where the DEM runs (default cpu): cpu, members one after another, or "
                        "gpu (numba-cuda), members side by side; needs an NVIDIA GPU")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_simulate)


def add_cases(sub) -> None:
    """Add the ``cases`` verb (the shipped cases) to the subparsers ``sub``.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        The subparsers of ``cfbmarkov`` (:func:`cfbmarkov.cli.build_parser`).
    """
    s = sub.add_parser("cases", help="list the shipped cases")
    s.set_defaults(func=cmd_cases)
