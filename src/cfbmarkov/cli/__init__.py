"""Command line: ``cfbmarkov VERB ...``; every verb is a thin layer over the Python API.

This module is what the ``cfbmarkov`` program imports first, and imports nothing heavy: a
Ctrl-C while the command line's modules load (:mod:`cfbmarkov.cli.command`, the parser and
the verbs by theme) is one line and exit code 130, as it is while a verb runs.

Errors in the input (files, options) are reported as one line on stderr with exit code 2.
A verb whose standard output is closed by its reader (``cfbmarkov info model.h5 | head -1``)
stops quietly with exit code 141 (128 + SIGPIPE, as a shell reports for a program a closed
pipe stopped)."""

from __future__ import annotations

import sys


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
        interrupted (also while the modules load), 141 when the reader of standard output
        has gone (nothing printed on stderr).
    """
    previous = sys.unraisablehook
    try:
        from cfbmarkov.cli.command import main as run

        code = run(argv)
        sys.stdout.flush()            # what is still buffered meets a closed pipe here
        return code
    except BrokenPipeError:           # the reader of standard output has gone
        from cfbmarkov._console import quit_closed_stdout

        return quit_closed_stdout()
    except KeyboardInterrupt:
        # what the interrupt cut short (a module half imported) is freed after this block:
        # its failing finalizers print nothing ("Exception ignored ...") until the end
        sys.unraisablehook = _ignore
        try:
            print("cfbmarkov: interrupted", file=sys.stderr)
        except KeyboardInterrupt:       # a second Ctrl-C while the line is printed
            pass
        return 130
    finally:
        if sys.unraisablehook is _ignore:
            import gc

            gc.collect()
            sys.unraisablehook = previous


def program() -> None:
    """The ``cfbmarkov`` program (and ``python -m cfbmarkov``): :func:`main` on the
    process's arguments, then exit with its code.

    Once the verb has returned, its output is published and a Ctrl-C or a SIGTERM has
    nothing left to stop: both are ignored while the interpreter shuts down. Python puts the
    default handlers back as it finalizes, and a signal landing then would end the process
    by the signal (exit status -2 or -15, 130 or 143 in a shell) with nothing said, after a
    complete run. Before that, a SIGTERM is taken as a Ctrl-C, as while the verb runs.

    Raises
    ------
    SystemExit
        Always, with the code of :func:`main`.
    """
    import signal

    signal.signal(signal.SIGTERM, _term_as_interrupt)
    try:
        code = main()
    except KeyboardInterrupt:           # between the verb's end and main's return
        print("cfbmarkov: interrupted", file=sys.stderr)
        code = 130
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sys.exit(code)


def _term_as_interrupt(signum, frame) -> None:
    """SIGTERM outside a verb's own handler (:mod:`cfbmarkov._interrupt`): a Ctrl-C."""
    raise KeyboardInterrupt


def _ignore(unraisable) -> None:
    """``sys.unraisablehook`` while an interrupted start winds down: drops everything."""


def build_parser():
    """The argument parser of ``cfbmarkov`` with all its verbs.

    Returns
    -------
    argparse.ArgumentParser
        A parser whose usage errors exit with code 2; each verb sets ``func``.
    """
    from cfbmarkov.cli.command import build_parser as build

    return build()


#: names loaded on first use from the modules that define them
_LAZY = {"parse_cells": "cfbmarkov.cli.options", "parse_window": "cfbmarkov.cli.options",
         "InputError": "cfbmarkov.errors", "VERBS": "cfbmarkov.cli.command",
         "OUTPUTS": "cfbmarkov.cli.command"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'cfbmarkov.cli' has no attribute {name!r}")


__all__ = ["main", "program", "build_parser", "parse_cells", "parse_window", "InputError"]
