"""Limits on what a run may ask for, checked before any work starts.

The memory a fit, a prediction, a residence-time distribution or a resampling will need is
estimated from the options and refused in one line (naming the estimate and the option)
when it exceeds :func:`memory_limit`: the memory available on the machine (``MemAvailable``
of ``/proc/meminfo``, else the physical memory), or the value of the environment variable
``CFBMARKOV_MEMORY_LIMIT`` (bytes, e.g. ``4e9``) where it is set. See ``docs/definitions.md``
(File formats, What is checked). The size of an output written uncompressed (a prediction)
is estimated likewise and refused where it exceeds the free space beside it.
"""

from __future__ import annotations

import math
import os

from cfbmarkov.errors import InputError

#: environment variable overriding the memory limit (bytes)
MEMORY_ENV = "CFBMARKOV_MEMORY_LIMIT"
#: the dense [S, S] arrays a fit holds at once (counts, passes up and down, the per-frame
#: sum, P, pass fractions): its memory is about FIT_ARRAYS x 8 bytes x S^2
FIT_ARRAYS = 6
#: the dense [S, S] arrays' worth of memory a model's exact RTD holds at its peak, the
#: model's own six included (its split chain, the levels' blocks, the entry chain's
#: eliminations): 12.8 measured on a velocity memory of 4104 states (1.98 GB peak of
#: ``cfbmarkov info MODEL``, ``/usr/bin/time -f %M``, less the 0.25 GB of an empty run;
#: 2026-12-07), 7.2 on the tutorial's 1596-state automatic model
RTD_ARRAYS = 13
#: below this estimate (bytes) a model's exact RTD is not checked against the memory limit
#: (a small model's arrays are a fraction of the process's own memory)
RTD_CHECK_FROM = 64e6
#: the largest seed (the Monte Carlo generator takes an unsigned 64-bit seed)
MAX_SEED = 2 ** 64 - 1
#: the most lags a residence-time distribution or a map may be propagated over
MAX_STEPS = 10_000_000
#: the most lags, frames or steps a time given may count (beyond, the quotient is refused
#: before it is rounded to a whole number: 1e308 s / 0.025 s is inf, which int() refuses
#: with a traceback); every run and its memory is refused well before
MAX_LAGS = 2.0 ** 62
#: the most bins of a residence-time histogram
MAX_BINS = 10_000_000


def available_memory() -> int:
    """Bytes of memory available now (``MemAvailable``), else the physical memory, else
    8 GiB where neither can be read."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 * 2 ** 30


def memory_limit() -> int:
    """The most memory (bytes) one estimate may reach: ``CFBMARKOV_MEMORY_LIMIT`` where set
    (a positive number of bytes), else :func:`available_memory`."""
    text = os.environ.get(MEMORY_ENV)
    if text:
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{MEMORY_ENV}={text!r} is not a positive number of bytes")
        return int(value)
    return available_memory()


def size_text(nbytes: float) -> str:
    """A byte count for a message: ``4.8 GB``."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes:.0f} bytes"


def check_memory(need: float, what: str, fix: str) -> None:
    """Refuse work whose estimated memory exceeds :func:`memory_limit`.

    Parameters
    ----------
    need : float
        The estimate, bytes.
    what : str
        What needs it (``"a fit of 90000 states"``).
    fix : str
        The option to change (``"use fewer --cells"``).

    Raises
    ------
    InputError
        Naming the estimate, the limit and the fix.
    """
    limit = memory_limit()
    if not need <= limit:
        source = MEMORY_ENV if os.environ.get(MEMORY_ENV) else "available memory"
        raise InputError(f"{what} would need about {size_text(need)} of memory, more than the "
                         f"{size_text(limit)} limit ({source}); {fix}")


def free_disk(folder) -> float:
    """Bytes free on the file system of ``folder`` (its nearest existing ancestor); inf
    where that cannot be told."""
    import shutil
    from pathlib import Path

    path = Path(folder).absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    try:
        return float(shutil.disk_usage(path).free)
    except OSError:
        return math.inf


def check_disk(need: float, output, what: str, fix: str) -> None:
    """Refuse an output whose estimated size exceeds the free space beside it.

    Parameters
    ----------
    need : float
        The estimate, bytes.
    output : str or os.PathLike
        The file to be written.
    what : str
        What it holds (``"a prediction of 2000 s ..."``).
    fix : str
        The option to change.

    Raises
    ------
    InputError
        Naming the estimate, the free space and the fix.
    """
    from pathlib import Path

    free = free_disk(Path(output).absolute().parent)
    if not need <= free:
        raise InputError(f"{what} would take about {size_text(need)} on disk, more than the "
                         f"{size_text(free)} free beside {output}; {fix}")


def fit_memory(n_states: int) -> float:
    """Estimated bytes of a fit over ``n_states`` states: FIT_ARRAYS dense [S, S] float64."""
    return FIT_ARRAYS * 8.0 * float(n_states) ** 2


def check_fit(state_space) -> None:
    """Refuse a state space whose fit would not fit in memory: its counting
    (:func:`fit_memory`) or the exact RTD its summary needs (:data:`RTD_ARRAYS`),
    whichever is larger.

    Raises
    ------
    InputError
        Naming the states, the estimate and the limit.
    """
    s = int(state_space.n_states)
    arrays = max(FIT_ARRAYS, RTD_ARRAYS)
    check_memory(arrays * 8.0 * float(s) ** 2, f"a fit of {state_space.describe()} (its "
                 f"exact RTD: about {arrays} dense {s} x {s} arrays of 8 bytes)",
                 "use fewer --cells, or a state space with fewer states per cell")


def rtd_memory(n_states: int) -> float:
    """Estimated peak bytes of a model's exact RTD (:data:`RTD_ARRAYS` dense [S, S]
    arrays); 0 below :data:`RTD_CHECK_FROM`, where it is not counted."""
    need = RTD_ARRAYS * 8.0 * float(n_states) ** 2
    return need if need >= RTD_CHECK_FROM else 0.0


def check_rtd(n_states: int, extra: float = 0.0, what: str = "") -> None:
    """Refuse an exact RTD of a model of ``n_states`` states that would not fit in memory
    (:data:`RTD_ARRAYS` dense [S, S] arrays, plus ``extra`` bytes; not checked below
    :data:`RTD_CHECK_FROM`).

    Raises
    ------
    InputError
        Naming the states, the estimate and the limit.
    """
    s = int(n_states)
    if rtd_memory(s) < RTD_CHECK_FROM:
        return
    check_memory(RTD_ARRAYS * 8.0 * float(s) ** 2 + extra,
                 what or f"the exact RTD of a model of {s} states (about {RTD_ARRAYS} dense "
                         f"{s} x {s} arrays of 8 bytes)",
                 "fit the model on fewer --cells, or a state space with fewer states per "
                 "cell")


def check_finite(value, name: str, unit: str = "", *, positive: bool = False,
                 non_negative: bool = False) -> float:
    """``value`` as a float, refused unless finite (and positive / non-negative).

    Raises
    ------
    InputError
        Naming the option and the value.
    """
    if isinstance(value, (str, bytes, bool)) or getattr(getattr(value, "dtype", None),
                                                        "kind", "") == "b":
        # float("5") and float(True) would pass
        raise InputError(f"{name} {value!r} is not a number")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} {value!r} is not a number") from None
    suffix = f" {unit}" if unit else ""
    if not math.isfinite(number):
        raise InputError(f"{name} {number:g}{suffix} is not a finite number")
    if positive and not number > 0:
        raise InputError(f"{name} {number:g}{suffix} must be positive")
    if non_negative and not number >= 0:
        raise InputError(f"{name} {number:g}{suffix} must be >= 0")
    return number


def check_seed(seed) -> int:
    """``seed`` as an int in 0 .. 2^64 - 1 (the generator's unsigned 64-bit seed).

    Raises
    ------
    InputError
        For anything else.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int,)) and not (
            hasattr(seed, "__index__")):
        raise InputError(f"seed {seed!r} is not a whole number")
    seed = int(seed)
    if not 0 <= seed <= MAX_SEED:
        raise InputError(f"seed {seed} must lie in 0 .. 2^64 - 1")
    return seed
