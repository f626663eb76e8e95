"""Progress on stderr: a bar only where the terminal can draw one."""

from __future__ import annotations

import os
import struct
import sys

import pytest

from cfbmarkov._console import draws_bars, progress_mode

termios = pytest.importorskip("termios")
fcntl = pytest.importorskip("fcntl")


def _size(fd: int, rows: int, columns: int) -> None:
    fcntl.ioctl(fd, termios.TIOCSWINSZ, struct.pack("HHHH", rows, columns, 0, 0))


def test_a_terminal_of_no_width_gets_lines_not_an_empty_bar(monkeypatch):
    """A pseudo-terminal that reports 0 columns (``script``, some container shells) cuts
    a bar to nothing: simulate, predict and react write whole lines there."""
    main, side = os.openpty()
    try:
        with os.fdopen(side, "w", closefd=False) as stream:
            monkeypatch.setattr(sys, "stderr", stream)
            _size(side, 0, 0)
            assert not draws_bars() and progress_mode(True) == "lines"
            _size(side, 24, 100)
            assert draws_bars() and progress_mode(True) == "bar"
        with open(os.devnull, "w") as stream:
            monkeypatch.setattr(sys, "stderr", stream)
            assert not draws_bars() and progress_mode(True) == "lines"
    finally:
        os.close(main)
        os.close(side)


def test_a_warning_of_a_figure_that_may_be_far_off_is_printed_as_the_verbs_print_it(capsys):
    """The model's fitting-sample warning, repeated by a prediction run from Python (the
    synthetic demo), is a ``warning:`` line as `predict` prints it, not a ``note:``; an
    advisory stays a note."""
    import warnings

    from cfbmarkov._console import one_line_notes
    from cfbmarkov.errors import (CfbmarkovWarning, IntervalWarning, SampleWarning,
                                  TimeStepAdvisory, UnresolvedWarning)

    with one_line_notes():
        warnings.simplefilter("always")
        for category in (SampleWarning, UnresolvedWarning, IntervalWarning, TimeStepAdvisory,
                         CfbmarkovWarning):
            warnings.warn(f"the model:  {category.__name__}\n text", category)
    lines = capsys.readouterr().err.splitlines()
    assert lines == [f"warning: the model: {name} text" for name in
                     ("SampleWarning", "UnresolvedWarning", "IntervalWarning")] + [
        f"note: the model: {name} text" for name in ("TimeStepAdvisory", "CfbmarkovWarning")]
