"""Ctrl-C that is never swallowed.

Python delivers SIGINT as a KeyboardInterrupt wherever the main thread happens to be; when
that is inside a finalizer or a weakref callback (h5py objects are collected all the time),
the interpreter prints "Exception ignored" and carries on, so a verb could finish as if
nothing had been asked. The command line installs :func:`handler`, which also records the
request; the writers call :func:`check` before each block of frames and before an output is
renamed into place, so a swallowed interrupt is raised again at the next of those points and
the output is never published. While a verb runs, such a swallowed KeyboardInterrupt is
not printed ("Exception ignored ...", a traceback; nor where C code that meets it prints it
through ``sys.excepthook`` and carries on): the one line comes when it is raised again.
"""

from __future__ import annotations

import contextlib
import gc
import signal
import sys
import threading

#: whether Ctrl-C was pressed since the verb started
requested = False


def handler(signum, frame) -> None:
    """SIGINT (and SIGTERM) handler: record the request and interrupt (KeyboardInterrupt)."""
    global requested
    requested = True
    raise KeyboardInterrupt


def check() -> None:
    """Raise KeyboardInterrupt if Ctrl-C was pressed (and perhaps swallowed) earlier.

    Raises
    ------
    KeyboardInterrupt
    """
    if requested:
        raise KeyboardInterrupt


@contextlib.contextmanager
def deferred():
    """Context manager: a Ctrl-C during the block is held until the block ends, then raised
    (KeyboardInterrupt). For the calls of Numba kernels: the interrupt is then never raised
    inside Numba's dispatch or compilation, or while its threading layer starts, and the
    arrays a kernel works on stay referenced and unchanged until it has returned. Outside
    the main thread, or nested, the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if getattr(previous, "cfbmarkov_deferred", False) or not callable(previous):
        yield                           # nested, or SIGINT ignored (worker processes)
        return
    held = []

    def hold(signum, frame):
        held.append(signum)

    hold.cfbmarkov_deferred = True
    signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if held:
        global requested
        if previous is handler:
            requested = True
        raise KeyboardInterrupt


def ignore_unraisable(unraisable) -> None:
    """An ``sys.unraisablehook`` that drops everything: set while an interrupted verb winds
    down, where the finalizers of objects whose construction the interrupt cut short fail as
    they are freed (e.g. llvmlite's ``ObjectRef.__del__``: "Exception ignored ...
    AttributeError"), which would print a traceback after the one line."""


@contextlib.contextmanager
def finalizers_quiet():
    """Context manager: :func:`ignore_unraisable` from here until the block ends; at the end
    the cycles are collected (their finalizers run quietly) and the previous hook restored.
    Enter it where an interrupt is caught, so that the exception and the frames it holds are
    freed inside."""
    previous = sys.unraisablehook
    sys.unraisablehook = ignore_unraisable
    try:
        yield
    finally:
        gc.collect()
        sys.unraisablehook = previous


class installed:
    """Context manager: :func:`handler` for SIGINT and SIGTERM while a verb runs (main thread
    only), the previous handlers and a cleared request afterwards."""

    def __enter__(self):
        global requested
        requested = False
        self._previous = None
        self._hook = sys.unraisablehook
        self._excepthook = sys.excepthook
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, handler)
            # SIGTERM (kill, a batch scheduler's stop) ends the verb as Ctrl-C does: one
            # line, the temporaries removed, the previous output kept
            self._previous_term = signal.signal(signal.SIGTERM, handler)
            previous_hook, previous_except = self._hook, self._excepthook

            def quiet(unraisable):          # swallowed there, raised again at check()
                if unraisable.exc_type is not None and issubclass(unraisable.exc_type,
                                                                  KeyboardInterrupt):
                    return
                previous_hook(unraisable)

            def quiet_print(exc_type, value, tb):
                # C code that meets the interrupt (an import it makes, with the handler
                # raising inside importlib) may print it with PyErr_Print, through this
                # hook, and carry on: not printed; the request stands, raised at check()
                if exc_type is not None and issubclass(exc_type, KeyboardInterrupt):
                    return
                previous_except(exc_type, value, tb)

            sys.unraisablehook = quiet
            sys.excepthook = quiet_print
        return self

    def __exit__(self, *exc):
        global requested
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            signal.signal(signal.SIGTERM, self._previous_term)
            sys.unraisablehook = self._hook
            sys.excepthook = self._excepthook
        requested = False
        return False
