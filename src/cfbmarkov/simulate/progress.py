"""Progress of a running simulation on stderr: simulated time, particle-steps/s and the time
left, as a tqdm bar or as whole lines (:class:`Progress`).
"""

from __future__ import annotations

import math
import sys
import time as _time

from cfbmarkov._console import clock_text as _clock


def _rate(value: float) -> str:
    """``2.1e7``: two digits, the exponent without sign or zeros."""
    if not (math.isfinite(value) and value > 0):
        return "?"
    mantissa, exponent = f"{value:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"


#: a line of progress (``progress="lines"``) at every this fraction of the simulated time
LINE_EVERY = 0.1


class Progress:
    """Progress in simulated seconds with particle-steps/s and the time left.

    ``mode`` ``"bar"``: a tqdm bar on stderr; ``"lines"``: whole lines on stderr, one at the
    start, one at every :data:`LINE_EVERY` of the simulated time and one at the end, each
    starting with the label (lines of parallel cases never interleave); ``None``: quiet.
    """

    def __init__(self, mode: str | None, start: float, end: float, particles: int,
                 label: str = ""):
        self.mode, self.start, self.end, self.particles = mode, start, end, particles
        self.prefix = f"{label}: CFD-DEM" if label else "CFD-DEM"
        self.bar = None
        self.done = start
        self.t_wall = self.t_start = self.t_line = _time.perf_counter()
        self.steps = self.steps_line = 0
        self.line_done = start
        self.next_line = start + LINE_EVERY * (end - start)
        if mode == "bar":
            from tqdm import tqdm

            self.bar = tqdm(total=round(end - start, 6), initial=0, unit="s", file=sys.stderr,
                            desc=f"{label} CFD-DEM (simulated s)".lstrip(),
                            mininterval=1.0 if sys.stderr.isatty() else 30.0,
                            bar_format="{desc}: {n:.3f}/{total:.3f} [{elapsed}<{remaining}{postfix}]")
        elif mode == "lines":
            what = "resumed at" if start > 0 else "starting at"
            self._line(f"{what} {start:g}/{end:g} s simulated, {particles} particles")

    def _line(self, text: str) -> None:
        from cfbmarkov._console import write_line

        write_line(f"{self.prefix} {text}")

    def update(self, simulated: float, dem_steps: int) -> None:
        if self.mode is None:
            return
        now = _time.perf_counter()
        self.done += simulated
        self.steps += dem_steps
        if self.bar is not None:
            rate = self.particles * dem_steps / max(now - self.t_wall, 1e-9)
            self.t_wall = now
            self.bar.set_postfix_str(f"{rate:.3g} particle-steps/s", refresh=False)
            # never past the total: frame times summed in floats overshoot it by an ulp,
            # which tqdm shows as a time left of "-00:00"
            self.bar.update(min(simulated, max(self.bar.total - self.bar.n, 0.0)))
            return
        mark = first = self.steps == dem_steps      # rates count from the first frame
        if self.done >= self.next_line - 1e-9 and self.done < self.end - 1e-9:
            if first or self.done <= self.line_done:   # no frame since the last mark
                rate = self.particles * self.steps / max(now - self.t_start, 1e-9)
                left = (self.end - self.done) / (self.done - self.start) * (now - self.t_start)
            else:       # since the last line (or the first frame: Numba compiles before it)
                rate = self.particles * (self.steps - self.steps_line) / max(now - self.t_line,
                                                                             1e-9)
                left = (self.end - self.done) / (self.done - self.line_done) * (now - self.t_line)
            self._line(f"{self.done:.2f}/{self.end:g} s simulated, {_rate(rate)} particle-steps/s, "
                       f"{_clock(now - self.t_start)} so far, about {_clock(left)} left")
            while self.next_line <= self.done + 1e-9:
                self.next_line += LINE_EVERY * (self.end - self.start)
            mark = True
        if mark:
            self.t_line, self.steps_line, self.line_done = now, self.steps, self.done

    def close(self, finished: bool = False) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self.mode == "lines" and finished:
            wall = _time.perf_counter() - self.t_start
            rate = self.particles * self.steps / max(wall, 1e-9)
            self._line(f"{self.end:g}/{self.end:g} s simulated in {_clock(wall)} "
                       f"({_rate(rate)} particle-steps/s)")
