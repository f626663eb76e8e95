"""The option types of ``cfbmarkov``: argparse ``type`` functions and the limits they check.

Each parser returns the option's value or raises :class:`argparse.ArgumentTypeError`,
whose message argparse prints as the one-line usage error (exit code 2)."""

from __future__ import annotations

import argparse
import math
import re

from cfbmarkov.limits import MAX_SEED

def parse_window(text: str) -> tuple[float, float]:
    """Parse a time window: ``'10:15'`` -> (10.0, 15.0).

    Parameters
    ----------
    text : str
        ``START:STOP`` in seconds.

    Returns
    -------
    tuple of float
        (start, stop), s.

    Raises
    ------
    argparse.ArgumentTypeError
        When ``text`` is not two finite numbers or the window is empty.
    """
    try:
        a, b = text.split(":")
        start, stop = float(a), float(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"window '{text}' is not START:STOP in seconds") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise argparse.ArgumentTypeError(f"window '{text}' is not two finite times")
    if not stop > start:
        raise argparse.ArgumentTypeError(f"window '{text}' is empty: STOP must exceed START")
    return start, stop


def parse_windows(text: str) -> list[tuple[float, float]]:
    """Parse one time window or several, comma-separated: ``'10:15,12:17'`` ->
    [(10.0, 15.0), (12.0, 17.0)] (one per run of a pooled fit).

    Parameters
    ----------
    text : str
        ``START:STOP[,START:STOP...]`` in seconds.

    Returns
    -------
    list of (float, float)

    Raises
    ------
    argparse.ArgumentTypeError
        When a window is not two finite numbers or is empty (:func:`parse_window`).
    """
    return [parse_window(part.strip()) for part in text.split(",")]


def parse_region(text: str) -> tuple[tuple[float, float], ...]:
    """Parse a region: ``'-0.001:0.091,0:0.95'`` -> ((-0.001, 0.091), (0.0, 0.95)).

    Parameters
    ----------
    text : str
        Two or three ``LO:HI`` ranges (m), for x, y (, z), separated by commas.

    Returns
    -------
    tuple of (float, float)

    Raises
    ------
    argparse.ArgumentTypeError
        When a range is not two finite numbers with HI > LO, or there are not 2 or 3.
    """
    try:
        ranges = tuple(tuple(float(v) for v in part.split(":")) for part in text.split(","))
    except ValueError:
        ranges = ()
    if not 2 <= len(ranges) <= 3 or any(
            len(r) != 2 or not all(map(math.isfinite, r)) or not r[1] > r[0] for r in ranges):
        raise argparse.ArgumentTypeError(
            f"region '{text}' is not XMIN:XMAX,YMIN:YMAX[,ZMIN:ZMAX] in the source's units "
            "(finite, MAX > MIN)")
    return ranges


def parse_cells(text: str) -> tuple[int, int] | tuple[int, int, int]:
    """Parse a cell grid: ``'6x38'`` -> (6 columns, 38 rows); ``'6x3x38'`` -> (6 columns,
    3 depth columns, 38 rows), a 3D grid for 3D data (``docs/definitions.md``, Cells and
    state numbers).

    Parameters
    ----------
    text : str
        ``COLUMNSxROWS`` or ``COLUMNSxDEPTHxROWS``.

    Returns
    -------
    tuple of int
        (columns m, rows n), or (columns m, depth columns d, rows n).

    Raises
    ------
    argparse.ArgumentTypeError
        When ``text`` is not two or three whole numbers of at least 1.
    """
    try:
        values = tuple(int(v) for v in text.lower().split("x"))
    except ValueError:
        values = ()
    if len(values) not in (2, 3):
        raise argparse.ArgumentTypeError(
            f"cells '{text}' is not COLUMNSxROWS or COLUMNSxDEPTHxROWS (for example 6x38 or "
            "6x3x38)")
    if min(values) < 1:
        axes = "column and one row" if len(values) == 2 else "column, depth column and row"
        raise argparse.ArgumentTypeError(f"cells '{text}' needs at least one {axes}")
    return values


def number(text: str) -> float:
    """A number (NaN and infinities allowed), or an :class:`argparse.ArgumentTypeError`."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None


def finite_float(text: str) -> float:
    """A finite number (a time, s)."""
    value = number(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"'{text}' is not a finite number")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0."""
    value = finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be positive")
    if value < 1e-300:      # subnormal: a quotient by it overflows to inf
        raise argparse.ArgumentTypeError(f"'{text}' is too small to compute with (below "
                                         "1e-300): give the value in the option's unit")
    return value


def level(text: str) -> float:
    """A coverage level strictly between 0 and 1 (NaN refused)."""
    value = number(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"'{text}' must lie strictly between 0 and 1 (e.g. 0.9)")
    return value


def minkowski_order(text: str) -> float:
    """A Minkowski order k >= 1; ``inf`` (the largest difference) is allowed, NaN is not."""
    value = number(text)
    if math.isnan(value):
        raise argparse.ArgumentTypeError(f"'{text}' is not a number: give a finite number "
                                         ">= 1 (or inf, the largest difference)")
    if not value >= 1:
        raise argparse.ArgumentTypeError(f"'{text}' must be a finite number >= 1 (or inf, the "
                                         "largest difference): below 1 the Minkowski sum is "
                                         "not a distance")
    return value


def whole(text: str) -> int:
    """A whole number, or an :class:`argparse.ArgumentTypeError`."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None


def seed(text: str) -> int:
    """A seed of the counter-based generator: a whole number in 0 .. 2^64 - 1."""
    value = whole(text)
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"'{text}' must lie in 0 .. 2^64 - 1")
    return value


def count(low: int, high: int):
    """An argparse type: a whole number in low .. high."""
    def parse(text: str) -> int:
        value = whole(text)
        if value < low:
            raise argparse.ArgumentTypeError(f"'{text}' must be at least {low}")
        if value > high:
            raise argparse.ArgumentTypeError(f"'{text}' must be at most {high}")
        return value
    parse.__name__ = "count"
    return parse


#: the most particles a synthetic demo, a case or a benchmark may be given
MAX_PARTICLES = 10_000_000
#: the most worker processes
MAX_JOBS = 1024


def _entries(text: str, what: str) -> list[str]:
    """The comma-separated entries of ``text``; an empty one between commas is refused (a
    typo, not a value left out on purpose); one trailing comma is let pass."""
    entries = [v.strip() for v in text.split(",")]
    if entries and not entries[-1] and len(entries) > 1:
        entries = entries[:-1]
    if any(not v for v in entries):
        raise argparse.ArgumentTypeError(f"{what} '{text}' hold an empty entry between commas")
    return entries


def parse_times(text: str) -> list[float]:
    """argparse type of ``--times``: comma-separated times (s), each finite, >= 0 and
    given once.

    Raises
    ------
    argparse.ArgumentTypeError
        Naming what is wrong with the text.
    """
    try:
        times = [float(v) for v in _entries(text, "times")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"times '{text}' are not comma-separated seconds") from None
    if not all(map(math.isfinite, times)):
        raise argparse.ArgumentTypeError(f"times '{text}' must be finite numbers of seconds")
    if not times or min(times) < 0:
        raise argparse.ArgumentTypeError(f"times '{text}' must be one or more values >= 0 s")
    if len(set(times)) != len(times):
        raise argparse.ArgumentTypeError(f"times '{text}' repeat a time: give each once")
    return times


def parse_velocities(text: str) -> list[float]:
    """argparse type of ``--velocities``: comma-separated superficial gas velocities (m/s),
    each positive and finite.

    Raises
    ------
    argparse.ArgumentTypeError
        Naming what is wrong with the text.
    """
    try:
        values = [float(v) for v in _entries(text, "velocities")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"velocities '{text}' are not comma-separated numbers "
                                         "in m/s") from None
    if not values or any(not (v > 0 and math.isfinite(v)) for v in values):
        raise argparse.ArgumentTypeError(f"velocities '{text}' must be positive numbers in m/s")
    return values


def parse_names(text: str) -> list[str]:
    """argparse type of a list of names (comma-separated, each given once).

    Raises
    ------
    argparse.ArgumentTypeError
        Where no name is given or one repeats.
    """
    if not text.strip():
        raise argparse.ArgumentTypeError("no names given")
    names = _entries(text, "names")
    if len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"names '{text}' repeat a name: give each once")
    return names


#: an option value that argparse would take for an option: a minus and then a digit or a
#: point (``-0.045:0.045,0:0.95``, ``-1e-3``), which argparse reads as a value only when it
#: is a plain negative number
_DASH_VALUE = re.compile(r"^-(\.?\d|inf(inity)?$|nan$)", re.IGNORECASE)


def join_dash_values(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """``argv`` with each option that takes one value and is followed by a value starting
    with ``-`` and a digit (or ``-inf``, ``-nan``) joined to it (``--region
    -0.045:0.045,0:0.95`` -> ``--region=-0.045:0.045,0:0.95``), so that argparse reads
    the value as written and the option's own check names what is wrong with it.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The parser, with its verbs as subparsers.
    argv : list of str
        The arguments after the program name.

    Returns
    -------
    list of str
        The arguments, unchanged but for the joins.
    """
    actions = _single_value_options(parser)
    out: list[str] = []
    k = 0
    while k < len(argv):
        word = argv[k]
        if word == "--":
            out.extend(argv[k:])
            break
        if word in actions and k + 1 < len(argv) and _DASH_VALUE.match(argv[k + 1]):
            out.append(f"{word}={argv[k + 1]}")
            k += 2
            continue
        if word in _verbs(parser):
            actions = actions | _single_value_options(_verbs(parser)[word])
        out.append(word)
        k += 1
    return out


def _verbs(parser: argparse.ArgumentParser) -> dict:
    """The parser's verbs (name -> subparser)."""
    for action in parser._actions:  # noqa: SLF001 -- argparse keeps subparsers there only
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            return action.choices
    return {}


def _single_value_options(parser: argparse.ArgumentParser) -> frozenset[str]:
    """The option strings of ``parser`` that take exactly one value."""
    return frozenset(name for action in parser._actions  # noqa: SLF001
                     if action.option_strings and action.nargs in (None, "?")
                     and not isinstance(action, argparse._SubParsersAction)  # noqa: SLF001
                     for name in action.option_strings)


def relative_tolerance(text: str) -> float:
    """A relative tolerance, a fraction strictly between 0 and 1 (``0.1`` for 10 %); a
    percentage such as ``10`` is refused naming the fraction meant."""
    value = number(text)
    if not 0.0 < value < 1.0:
        hint = (f"{value / 100:g} for {value:g} %" if 1.0 <= value < 100.0
                else "e.g. 0.1 for 10 %")
        raise argparse.ArgumentTypeError(f"'{text}' must be a fraction strictly between 0 and "
                                         f"1 ({hint})")
    return value
