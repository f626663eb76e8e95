"""The parser and the run of a verb with its output claimed (what :func:`cfbmarkov.cli.main`
loads): the verbs live in modules by theme (:mod:`~cfbmarkov.cli.data`,
:mod:`~cfbmarkov.cli.markov`, :mod:`~cfbmarkov.cli.kinetics`, :mod:`~cfbmarkov.cli.analysis`,
:mod:`~cfbmarkov.cli.simulate`, :mod:`~cfbmarkov.cli.run`), their option types in
:mod:`~cfbmarkov.cli.options`.

Errors in the input (files, options) are reported as one line on stderr with exit code 2."""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
from pathlib import Path

from cfbmarkov._console import stdout_closed
from cfbmarkov._names import one_line
from cfbmarkov.cli import analysis, data, kinetics, markov, run, simulate
from cfbmarkov.cli.options import join_dash_values
from cfbmarkov.errors import CfbmarkovError, HistoryError, InputError, LagError


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        # an option is given whole: a prefix (fit's --resample for --resamples, which is
        # import's --resample for something else) is refused with the nearest name
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    #: (the root parser, argv) while ``main`` parses: what a "required" error looks back at
    parsing = None

    def error(self, message: str):  # one line, exit code 2
        if message.startswith("the following arguments are required") and _Parser.parsing:
            _refuse_unknown_early(*_Parser.parsing)    # a required option typed short
        typed = re.match(r"argument command: invalid choice: '([^']*)'", message)
        if typed:                                       # a misspelt verb: the nearest named
            import difflib

            verbs = re.findall(r"'([^']+)'", message)[1:]      # the choices listed
            close = difflib.get_close_matches(typed.group(1), verbs, n=1)
            if close:
                message += f"; did you mean {close[0]}?"
        self.exit(2, f"{self.prog}: error: {message}\n")


#: the verbs in the order of ``cfbmarkov --help``, each adding its subparser
VERBS = (data.add_import, markov.add_fit, markov.add_predict, analysis.add_compare,
         markov.add_rtd, kinetics.add_react, analysis.add_stationarity, analysis.add_maps,
         markov.add_info,
         simulate.add_simulate, simulate.add_cases, run.add_reproduce, run.add_demo,
         data.add_export_vtk, run.add_bench)


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
    for add in VERBS:
        add(sub)
    # each verb's help page opens with what the verb does (its line in cfbmarkov --help)
    said = {action.dest: action.help for action in sub._choices_actions}
    for name, verb in sub.choices.items():
        if verb.description is None and said.get(name):
            verb.description = said[name][0].upper() + said[name][1:] + "."
    for name, verb in sub.choices.items():
        if name in OUTPUTS:
            verb.add_argument("--force", action="store_true",
                              help="replace an existing output of another kind (a file of "
                                   "another format, an empty folder, ...; never a FIFO, "
                                   "device or socket)"
                                   + ("; or one that holds a finished run, which keeps no "
                                      "checkpoint" if name == "simulate" else
                                      "; or a simulated or generated run (an earlier "
                                      "import's file is replaced without it)"
                                      if name == "import" else ""))
    return p


def _refuse_unknown(parser: argparse.ArgumentParser, verb: str, extra: list[str]) -> None:
    """Exit 2 with one line naming the verb, its unknown arguments, the options they may
    have meant (by spelling) and ``--help``."""
    import difflib

    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    options = [o for action in sub.choices[verb]._actions for o in action.option_strings]
    hints = []
    for word in extra:
        if word.startswith("-"):
            name = word.split("=")[0]
            # an option cut short (options are given whole) means the one it begins, where
            # only one does; else the nearest by spelling
            begun = [o for o in options if o.startswith(name) and o.startswith("--")]
            close = (begun if len(begun) == 1 else
                     difflib.get_close_matches(name, options, n=1, cutoff=0.6))
            if close:
                hints.append(f"{name}: did you mean {close[0]}?")
    said = f" ({'; '.join(hints)})" if hints else ""
    print(f"cfbmarkov {verb}: error: unrecognized arguments: {' '.join(extra)}{said}; see "
          f"cfbmarkov {verb} --help", file=sys.stderr)
    raise SystemExit(2)


def _refuse_unknown_early(parser: argparse.ArgumentParser, argv: list[str]) -> None:
    """Where argparse finds a required option missing, refuse the verb's unknown
    ``--option`` instead: a required option typed short (``--out`` for ``--output``) is then
    named as mistyped, not reported as missing."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    verb = next((word for word in argv if not word.startswith("-")), None)
    if verb not in sub.choices or "--" in argv:
        return
    known = {o for action in sub.choices[verb]._actions for o in action.option_strings}
    unknown = [word for word in argv if word.startswith("--") and len(word) > 2
               and word.split("=")[0] not in known]
    if unknown and not any(word in ("-h", "--help") for word in argv):
        _refuse_unknown(parser, verb, unknown)


def _refuse_repeated(parser: argparse.ArgumentParser, verb: str, argv: list[str]) -> None:
    """Exit 2 with one line where an option that takes one value is given twice (argparse
    would keep the last silently: ``fit --window 5:10 --window 10:15`` fits 10:15)."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    single = {o: action for action in sub.choices[verb]._actions
              if isinstance(action, argparse._StoreAction) for o in action.option_strings}
    seen: dict[str, list[str]] = {}
    expects_value = False
    for word in argv[argv.index(verb) + 1:] if verb in argv else []:
        if word == "--":
            break
        if expects_value:           # the value of the option before, whatever it looks like
            expects_value = False
            continue
        name = word.split("=")[0]
        attached = False
        if name not in single and word[:1] == "-" and word[1:2] != "-" and word[:2] in single:
            name, attached = word[:2], True             # a short option's value attached: -oX
        action = single.get(name)
        if action is not None:
            seen.setdefault(action.dest, []).append(name)
            expects_value = "=" not in word and not attached
    for names in seen.values():
        if len(names) > 1:
            shown = " and ".join(dict.fromkeys(names))
            sub.choices[verb].exit(2, f"cfbmarkov {verb}: error: {shown} given {len(names)} "
                                      "times, and only the last would be taken: give it "
                                      "once\n")


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
            argv = list(sys.argv[1:] if argv is None else argv)
            _Parser.parsing = (parser, argv)
            try:
                args, extra = parser.parse_known_args(join_dash_values(parser, argv))
            finally:
                _Parser.parsing = None
            if extra:
                _refuse_unknown(parser, args.command, extra)
            _refuse_repeated(parser, args.command, join_dash_values(parser, argv))
            if args.command == "demo":     # each kind of demo its own default folder
                refused = run.demo_option_error(args)
                if refused is not None:     # before anything starts: one line
                    print(f"cfbmarkov demo: error: {refused}", file=sys.stderr)
                    return 2
                args.output = run.demo_output(args.output, args.synthetic)
        except SystemExit as exc:      # usage errors (2), --help and --version (0)
            return int(exc.code or 0)
    except KeyboardInterrupt:
        print("cfbmarkov: interrupted", file=sys.stderr)
        return 130
    from cfbmarkov._console import one_line_notes

    with one_line_notes():             # cfbmarkov's warnings: one line, "note: ..."
        import warnings

        from cfbmarkov.errors import UnresolvedWarning

        # the verbs that print E(RT) print the unresolved mass's line as a warning: of theirs
        warnings.simplefilter("ignore", UnresolvedWarning)
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
           "predict": ("prediction", ("model", "init")),
           "compare": ("folder", ("reference", "prediction")), "maps": ("png", ("model",)),
           "simulate": ("trajectory", ("case",)), "reproduce": ("folder", ("overrides",)),
           "demo": ("folder", ()), "export-vtk": ("folder", ("run",))}


def _run(args) -> int:
    """Run the verb of ``args`` with its output claimed; errors become one line."""
    from cfbmarkov import _interrupt

    before = _output_stamp(args)
    with contextlib.ExitStack() as winding_down:
        try:
            with _interrupt.installed():
                return _run_claimed(args)
        except CfbmarkovError as exc:
            text = _for_verb(exc, args)
            if args.command == "simulate" and "cannot write (" in text and _resumable(args):
                # a full disk or a write error mid-run: the checkpoint written before it stays
                text += ("; its last checkpoint is kept: once it can write there again, "
                         "rerun with --resume")
            print(f"cfbmarkov {args.command}: error: {one_line(text)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            # what the interrupt cut short is freed with it, after this block: its failing
            # finalizers stay quiet until the stack closes
            winding_down.enter_context(_interrupt.finalizers_quiet())
            print(f"cfbmarkov {args.command}: interrupted{_resumable(args)}"
                  f"{_written_whole(args, before)}", file=sys.stderr)
            return 130
        except (OSError, KeyError, RuntimeError) as exc:
            if isinstance(exc, BrokenPipeError) and stdout_closed():
                raise                       # cfbmarkov.cli.main stops quietly
            damaged = _damaged_input(exc)   # an HDF5 input that fails only where it is read
            if damaged is not None:
                print(f"cfbmarkov {args.command}: error: {one_line(damaged)}",
                      file=sys.stderr)
                return 2
            if not isinstance(exc, OSError):
                raise
            from cfbmarkov._atomic import write_error     # a write failed outside the writers

            name = exc.filename or getattr(args, "output", "")
            print(f"cfbmarkov {args.command}: error: {one_line(str(write_error(exc, name)))}",
                  file=sys.stderr)
            return 2


def _for_verb(exc: CfbmarkovError, args) -> str:
    """The message of ``exc`` as advice the verb of ``args`` can follow: a lag that does
    not fit a file's frames, on a verb without ``--lag``, is a fitted model's, which only a
    refit changes; a window short of history is moved with the verb's ``--window`` or
    ``--start``, or with neither named."""
    if isinstance(exc, LagError) and not hasattr(args, "lag"):
        return exc.for_model()
    if isinstance(exc, HistoryError):
        return exc.advice(next((option for option in ("--window", "--start")
                                if hasattr(args, option[2:])), None))
    return str(exc)


def _damaged_input(exc: BaseException) -> str | None:
    """The one-line error for an h5py failure while an input file was being read (a
    damaged model or trajectory file whose damage shows only in a dataset), naming the file;
    None where ``exc`` did not come from reading an HDF5 file opened for reading."""
    tb = exc.__traceback__
    name = None
    in_h5py = False
    while tb is not None:
        where = tb.tb_frame.f_code.co_filename.replace(os.sep, "/")
        in_h5py = in_h5py or "/h5py/" in where or where.startswith("h5py/")
        for value in tb.tb_frame.f_locals.values():
            with contextlib.suppress(Exception):   # a closed h5py object has no file
                file = getattr(value, "file", None) if "h5py" in type(value).__module__ else None
                if file is not None and file.mode == "r":
                    name = file.filename
        tb = tb.tb_next
    if name is None or not in_h5py:
        return None
    from cfbmarkov._names import first_line

    return f"{name}: damaged file, cannot be read ({first_line(exc)})"


def _check_environment() -> None:
    """Refuse, in one line, an environment setting the run cannot honour: a
    ``NUMBA_NUM_THREADS`` that is not a positive whole number (Numba would warn over
    several lines and take its default)."""
    threads = os.environ.get("NUMBA_NUM_THREADS")
    if threads is not None and not (threads.strip().isdigit() and int(threads) > 0):
        raise InputError(f"NUMBA_NUM_THREADS={threads!r} is not a positive whole number of "
                         "threads; set it to one (e.g. NUMBA_NUM_THREADS=4) or unset it")


def _run_claimed(args) -> int:
    """The verb with its output claimed; a Ctrl-C swallowed on the way is raised at the end."""
    from cfbmarkov import _interrupt

    try:
        _check_environment()
        if args.command in OUTPUTS:
            from cfbmarkov._outputs import claim_output

            kind, inputs = OUTPUTS[args.command]
            if args.command == "import" and not getattr(args, "force", False):
                _refuse_replacing_a_run(args.output)
            named = [getattr(args, name, None) for name in inputs]   # a list: several runs
            named = [v for n in named for v in (n if isinstance(n, list) else [n])]
            with claim_output(args.output, args.command, kind, named,
                              force=getattr(args, "force", False)):
                return int(args.func(args) or 0)
        return int(args.func(args) or 0)
    finally:
        _interrupt.check()


def _refuse_replacing_a_run(output) -> None:
    """``import`` replaces an earlier import's file, not a run it did not write: a CFD-DEM
    simulation (hours of computing) or a generated run is refused without --force."""
    from cfbmarkov._outputs import describe

    path = Path(os.fspath(output))
    if not path.is_file() or describe(path) != "trajectory":
        return
    import h5py

    try:
        with h5py.File(path, "r") as f:
            source = f.attrs.get("source", "")
    except (OSError, RuntimeError):
        return
    source = source.decode() if isinstance(source, bytes) else str(source)
    if source.startswith("import"):
        return
    raise InputError(f"{path}: exists and holds a trajectory file of source '{source}' (a "
                     "simulated or generated run, not an earlier import); import does not "
                     "replace it without --force: give another output name, or add --force")


#: the verbs whose output folder is published whole (written aside, renamed into place)
WHOLE_FOLDERS = ("compare", "export-vtk")


def _output_stamp(args):
    """The output's identity and time of change: a file's, or a folder published whole
    (:data:`WHOLE_FOLDERS`); None where absent or a folder built in place."""
    # react writes a prediction file only with --init (claimed then by its own code)
    kind = OUTPUTS.get(args.command, ("prediction" if args.command == "react"
                                      else "folder",))[0]
    if (kind == "folder" and args.command not in WHOLE_FOLDERS) or not getattr(
            args, "output", None):
        return None
    try:
        stat = os.stat(args.output)
    except (OSError, ValueError, TypeError):
        return None
    return stat.st_ino, stat.st_mtime_ns


def _written_whole(args, before) -> str:
    """Where an interrupted verb had already published its file output (written to a
    temporary and renamed into place, so whole): says so, as the summary it prints after
    it was cut short; empty otherwise."""
    after = _output_stamp(args)
    if after is None or after == before:
        return ""
    what = "folder" if args.command in WHOLE_FOLDERS else "file"
    return (f" after {args.output} was written whole (the {what} is complete; only the lines "
            "printed after it were cut short)")


def _resumable(args) -> str:
    """What an interrupted verb can be resumed with."""
    if args.command == "simulate":
        from cfbmarkov._names import parts_folder

        out = Path(str(args.output))
        parts = [parts_folder(out)]
        if getattr(args, "ensemble", None):   # CPU members' own checkpoints
            parts += [parts_folder(out.with_name(f"{out.stem}-m{m}{out.suffix}"))
                      for m in range(args.ensemble)]
        if any((p / name).exists() for p in parts
               for name in ("checkpoint.h5", "gpu-checkpoint.h5")):
            return "; the run can be resumed with --resume (from its last checkpoint)"
    if args.command in ("reproduce", "demo") and not getattr(args, "synthetic", False):
        return "; rerun the same command to resume"
    return ""


__all__ = ["OUTPUTS", "VERBS", "build_parser", "main"]
