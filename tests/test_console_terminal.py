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
