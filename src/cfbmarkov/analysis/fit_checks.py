"""What ``cfbmarkov fit`` adds to a fitted model before it saves it: the fitting window's
identity and time-averaged cell fields, the exact RTD's check, the model's interval and the
verdict on its fitting sample. :func:`assess_fit` gives a model fitted in Python the same
figures and warnings as one fitted on the command line.
"""

from __future__ import annotations

import contextlib
import numbers
import os
import warnings
from collections.abc import Callable, Sequence

import numpy as np

from cfbmarkov.errors import (CfbmarkovError, CfbmarkovWarning, InputError,  # noqa: F401
                              IntervalWarning, SampleWarning)

__all__ = ["IntervalWarning", "assess_fit", "record_fitting_data"]


def _no_stage(short: str, text: str | None):
    return contextlib.nullcontext()


def assess_fit(model, runs: Sequence | None = None,
               windows: Sequence[tuple[float, float]] | None = None, *, level: float = 0.9,
               resamples: int = 100, verdict: bool = True,
               stage: Callable[[str, str | None], contextlib.AbstractContextManager] = _no_stage):
    """The model as ``cfbmarkov fit`` saves it: with its fitting window's identity and cell
    fields, its interval and the verdict on its fitting sample.

    A model fitted in Python (``PaperEstimator(...).fit(window)``) carries none of these;
    after this call ``model.uncertainty`` holds the interval of E(RT), SD(RT) and the RTD
    per bin (:func:`cfbmarkov.analysis.intervals.model_intervals`), ``model.adequacy`` the
    verdict (:func:`cfbmarkov.analysis.adequacy.assess_adequacy`), ``model.warnings()`` its
    warning lines and ``model.summary()`` prints the interval beside E(RT)
    (docs/definitions.md, The model's interval and Sample adequacy).

    Parameters
    ----------
    model : MarkovModel
        A model fitted on trajectory files (``model.source`` names them).
    runs : sequence of str, os.PathLike or Trajectories, optional
        The run(s) it was fitted on; default the files ``model.source`` names (one, or
        each run of a pooled fit).
    windows : sequence of (float, float), optional
        The fitting window (s) of each run; default ``model.window``, or for a pooled fit
        each run's own (``model.run_windows``).
    level : float, optional
        Coverage of the interval (default 0.9).
    resamples : int, optional
        Bootstrap resamples of the fitting window (default 100; 0 leaves the interval out,
        1-9 are refused).
    verdict : bool, optional
        Judge the fitting sample (its halves and quarters refitted; default True).
    stage : callable, optional
        ``stage(short, text)`` returns a context manager around each stage (the command
        line shows progress with it); default none.

    Returns
    -------
    MarkovModel
        The same chain with the figures attached (a new immutable model).

    Raises
    ------
    InputError
        If ``model`` is not a MarkovModel, the model was not fitted on files (no
        ``source``), ``runs`` and ``windows`` differ in number, a window given is not the
        model's fitting window, their windows' content differs from the one the model
        records (``source_identity``), or, where it records none (fitted in Python), their
        transitions are not the model's counts (not the data it was fitted on),
        ``resamples`` is negative, 1-9 or not a whole number, ``level`` lies outside (0, 1) or needs more resamples
        (:func:`cfbmarkov.analysis.bootstrap.check_interval_options`), or the chain traps
        residences.

    Warns
    -----
    IntervalWarning
        (:class:`cfbmarkov.analysis.fit_checks.IntervalWarning`) Where no interval can be
        formed (the model is returned without one), and where ``runs`` name one file more
        than once: windows of one run are not independent runs, so neither the interval
        nor the verdict of pooled runs is formed.
    SampleWarning
        (:class:`cfbmarkov.errors.SampleWarning`) Each warning line of the verdict
        (``model.adequacy.warnings``, the lines ``cfbmarkov fit`` prints), once, and the
        line of a chain that does not carry its own fitting window
        (:meth:`~cfbmarkov.markov.adequacy.Adequacy.on_window_warning`).
    """
    from cfbmarkov.markov.first_passage import TrappedResidences

    from cfbmarkov.markov.model import MarkovModel

    if not isinstance(model, MarkovModel):
        raise InputError(f"assess_fit takes a fitted MarkovModel, not a "
                         f"{type(model).__name__} ({model!r}): load a model file with "
                         "MarkovModel.load(path)")
    explicit_windows = windows is not None
    runs, windows = _runs_and_windows(model, runs, windows)
    if isinstance(resamples, bool) or not isinstance(resamples, numbers.Integral):
        raise InputError(f"resamples {resamples!r}: a whole number (0 leaves the interval out)")
    if resamples < 0 or 0 < resamples < 10:
        raise InputError(f"resamples {resamples}: an interval needs at least 10 bootstrap "
                         "resamples (0 leaves it out)")
    if resamples:
        from cfbmarkov.analysis.bootstrap import check_interval_options

        check_interval_options(level, resamples)
    repeated = _repeated_run(runs)
    if repeated is not None and (resamples or verdict):
        warnings.warn(f"{repeated}: the fitting windows "
                      f"{', '.join(f'{a:g}-{b:g} s' for a, b in windows)} are of one run, not "
                      "independent runs: no interval and no verdict of pooled runs (fit one "
                      "window spanning them for both)", IntervalWarning, stacklevel=2)
        resamples, verdict = 0, False
    recorded = model.source_identity
    # the windows as fitted, read once: the data checked to be the model's where it records
    # no identity of it (fitted in Python) or windows are given; then the verdict's read
    given = (_given_windows(model, runs, windows, check_counts=recorded is None)
             if recorded is None or explicit_windows else None)
    model = _with_window_fields(model, runs, windows)
    if recorded is not None and model.source_identity != recorded:
        raise InputError(f"{', '.join(map(str, runs))}: not the data the model was fitted on "
                         "(the content of the fitting windows differs from the one the model "
                         "records); give the runs and windows it was fitted on, or leave "
                         "runs= and windows= out")
    has_rtd = True
    try:
        model.rtd()
    except TrappedResidences as exc:
        text = str(exc)
        if model.connected:       # the advice is taken: say what else keeps the top away
            text = text.replace(
                "(they lead to states that are never left; fit with --connected, or on a "
                "longer window)",
                "(fitted with --connected: no transition of the window climbs past some "
                "height, as where a band of the riser is out of view; check where the "
                "particles are absent by height, or fit on coarser cells or a longer window)")
        raise InputError(f"{', '.join(map(str, runs))}: {text}") from None
    except CfbmarkovError:
        has_rtd = False            # no circulation at all: a model without residence times
    discrete = (_fitting_windows(model, runs, windows, given)
                if resamples and has_rtd and verdict else None)
    if not resamples and model.uncertainty is not None:
        model = model.with_uncertainty(None)     # 0 leaves the interval out, a stored one too
    if resamples and has_rtd:
        from cfbmarkov.analysis.intervals import model_intervals

        pooled = "s" if isinstance(model.source, (list, tuple)) else ""
        with stage("interval", f"the model's {100 * level:g} % interval: {resamples} "
                   f"bootstrap resamples of the fitting window{pooled}"):
            try:
                model = model.with_uncertainty(model_intervals(model, level=level,
                                                               resamples=resamples,
                                                               discrete=discrete))
            except CfbmarkovError as exc:
                warnings.warn(f"no interval for the model's E(RT) and SD(RT): {exc}",
                              IntervalWarning, stacklevel=2)
                model = model.with_uncertainty(None)     # not an interval of other data
    if verdict:
        from cfbmarkov.analysis.adequacy import assess_adequacy
        from cfbmarkov.markov.model_summary import on_window_warning

        with stage("sample verdict", "the fitting sample's verdict: the window's halves "
                   "and quarters refitted and compared"):
            model = model.with_adequacy(assess_adequacy(model, runs, windows,
                                                        discrete=discrete or given,
                                                        uncertainty=model.uncertainty))
        for line in model.adequacy.warnings:      # seen in a notebook, as predict repeats them
            warnings.warn(line, SampleWarning, stacklevel=2)
        missed = on_window_warning(model)     # the model's own, as fit prints it
        if missed:
            warnings.warn(missed, SampleWarning, stacklevel=2)
    return model


def _given_windows(model, runs, windows, check_counts: bool) -> list:
    """``runs``' ``windows`` discretised as the model was fitted (``short_history="skip"``:
    a space with memory starts after its history), once each is checked to be the model's
    fitting window (its end, and its start after the history), and with ``check_counts``
    their transitions to be the model's counts (the data it was fitted on, where it records
    no identity of it).

    Raises
    ------
    InputError
        Naming the window that is not the model's, or the runs whose transitions are not
        its counts.
    """
    from cfbmarkov.markov.counting import count_transitions
    from cfbmarkov.markov.discrete import discretize, held_window

    read = [discretize(run, model.state_space, model.lag, window, short_history="skip")
            for run, window in zip(runs, windows)]
    own = (list(model.run_windows) if model.run_windows is not None
           and len(model.run_windows) == len(read) else [model.window] * len(read))
    for run, d, window, mine in zip(runs, read, windows, own):
        # the frames the model's window holds: a model file may keep a window typed between
        # frames, which its fit read as the frames inside
        if mine is not None and d.window is not None and not np.allclose(
                d.window, held_window(run, mine), rtol=0, atol=1e-9):
            raise InputError(f"window {window[0]:g}-{window[1]:g} s: not the model's fitting "
                             f"window {mine[0]:g}-{mine[1]:g} s; give the window it was fitted "
                             "on, or leave windows= out")
    if check_counts:
        counts = count_transitions(read, sparse=True).counts
        if counts.shape != model.counts.shape or not np.array_equal(counts.toarray(),
                                                                    model.counts):
            names = ", ".join(str(getattr(run, "path", run)) for run in runs)
            raise InputError(f"{names}: not the data the model was fitted on (the windows' "
                             "transitions are not the model's counts); give the runs and "
                             "windows it was fitted on, or leave runs= and windows= out")
    return read


def _fitting_windows(model, runs, windows, read=None):
    """The fitting windows discretised once, for the interval's bootstrap and the verdict's
    parts (0.22 s a read of the paper-scale 3 m/s window: ``python
    benchmarks/interval_cost.py MODEL.h5``, 2026-12-07), where ``runs`` and ``windows``
    are the files and windows the model names, in its order (the interval reads those);
    else None (each stage reads its own, and says why where it cannot)."""
    from cfbmarkov.analysis.bootstrap import fitting_runs, fitting_windows

    try:
        named = fitting_runs(model)
        if len(named) != len(runs):
            return None
        for (source, window), run, given in zip(named, runs, windows):
            path = getattr(run, "path", run)
            if (os.path.realpath(path) != os.path.realpath(source)
                    or tuple(map(float, window)) != tuple(map(float, given))):
                return None
        return read if read is not None else fitting_windows(model)   # read once
    except (CfbmarkovError, TypeError, OSError):
        return None


def record_fitting_data(model, runs: Sequence | None = None,
                        windows: Sequence[tuple[float, float]] | None = None):
    """The model with what ``cfbmarkov fit`` records of its fitting data: the fitting
    window's content identity (``source_identity``, by which its fitting file is found
    again wherever it lies: :func:`cfbmarkov.analysis.intervals.resolve_source`) and its
    time-averaged cell fields; no interval, no verdict (:func:`assess_fit` adds those).

    Parameters
    ----------
    model : MarkovModel
        A model fitted on trajectory files.
    runs : sequence of str, os.PathLike or Trajectories, optional
        The run(s) it was fitted on; default ``[model.source]``.
    windows : sequence of (float, float), optional
        The fitting window (s) of each run; default ``[model.window]``.

    Returns
    -------
    MarkovModel
        The same chain with its identity and cell fields (a pooled fit's fields where the
        grid fits the files).

    Raises
    ------
    InputError
        If the model names no trajectory file and ``runs`` is not given, ``runs`` and
        ``windows`` differ in number, or the fitting window lies outside the file.
    """
    return _with_window_fields(model, *_runs_and_windows(model, runs, windows))


def _repeated_run(runs) -> str | None:
    """The file named more than once among ``runs`` (paths or open Trajectories), or None:
    windows of one run are not the independent runs a pooled interval takes."""
    from pathlib import Path

    seen = set()
    for run in runs:
        path = getattr(run, "path", run)
        try:
            key = os.path.realpath(Path(path))
        except TypeError:
            continue
        if key in seen:
            return str(path)
        seen.add(key)
    return None


def _found_sources(model, sources: list) -> list:
    """The fitting files a model names (paths from the folder it was fitted in), found as
    ``rtd``, ``compare`` and ``react`` find them: a model that records its data's identity
    by :func:`~cfbmarkov.analysis.intervals.resolve_source` (the path from this folder,
    beside the model file, its name alone beside it; each kept only where its fitting
    window's content is the model's); one that records none (fitted in Python) at the
    first of those places that holds a file, its counts then checked to be the model's."""
    if model.source_identity:
        from cfbmarkov.analysis.intervals import resolve_source

        found = resolve_source(model).source
        return list(found) if isinstance(found, (list, tuple)) else [found]
    home = model._cache.get("file")
    found = []
    for source in map(str, sources):
        tried = [source]
        if home is not None:
            folder = os.path.dirname(home)
            if not os.path.isabs(source):
                tried.append(os.path.join(folder, source))
            tried.append(os.path.join(folder, os.path.basename(source)))
        match = next((path for path in tried if os.path.isfile(path)), None)
        if match is None:
            where = ("from this folder nor beside the model file "
                     f"({os.path.dirname(home)})" if home is not None else "from this folder")
            raise InputError(f"{source} (the model's fitting file, named from the folder it "
                             f"was fitted in): not found {where}; give runs= (the files it "
                             "was fitted on)")
        found.append(match)
    return found


def _runs_and_windows(model, runs, windows) -> tuple[list, list]:
    """The runs and their fitting windows: as given, else the model's source and window (a
    model fitted on several runs: each run and its own window, ``run_windows``); one window
    per run."""
    pooled = (isinstance(model.source, (list, tuple)) and len(model.source) > 1
              and model.run_windows is not None)
    if runs is None:
        if pooled:                       # a fit on several runs names each and its window
            runs = list(model.source)
        elif isinstance(model.source, (list, tuple)) and len(model.source) == 1:
            runs = list(model.source)
        elif not model.source or not isinstance(model.source, str):
            raise InputError("the model names no trajectory file it was fitted on: give "
                             "runs= and windows= (the files and fitting windows)")
        else:
            runs = [model.source]
        runs = _found_sources(model, runs)
    if isinstance(runs, (str, os.PathLike)) or hasattr(runs, "positions"):
        runs = [runs]                    # one run given alone, not in a list
    runs = list(runs)
    if windows is None:
        if pooled and len(runs) == len(model.run_windows):
            windows = [tuple(w) for w in model.run_windows]
        else:
            windows = [model.window] * len(runs)
    windows = list(windows)
    if len(windows) != len(runs):
        raise InputError(f"{len(runs)} runs and {len(windows)} windows: give one fitting "
                         "window per run")
    return runs, windows


def _with_window_fields(model, runs, windows):
    """``model`` with its fitting window's identity and time-averaged cell fields. Where the
    model records an identity already, each run's is formed by the rule it was recorded
    with (:func:`~cfbmarkov.trajectory_identity.identity_version`), so that a model
    recorded by the earlier rule still matches its own data."""
    from cfbmarkov.trajectories import Trajectories, opened
    from cfbmarkov.trajectory_identity import identity_version

    recorded = (str(model.source_identity).split(";") if model.source_identity else [])
    if len(recorded) != len(runs):
        recorded = [""] * len(runs)

    def window_identity(run, window, k=0):
        from cfbmarkov.trajectory_identity import window_identity as identity

        return identity(run, window, identity_version(recorded[k]))

    if len(runs) == 1:
        from cfbmarkov.analysis.cell_fields import fitting_cell_fields

        with opened(runs[0]) as run:    # the window the model holds (a choice with memory
            # at the file's start begins it after the first frames, its history)
            window = model.window if model.window is not None else windows[0]
            model = model.with_source_identity(window_identity(run, window))
            return model.with_cell_fields(fitting_cell_fields(run, model))
    from cfbmarkov.analysis.cell_fields import pooled_cell_fields

    with contextlib.ExitStack() as stack:
        files = [stack.enter_context(Trajectories(p)) if not isinstance(p, Trajectories)
                 else p for p in runs]
        model = model.with_source_identity(";".join(
            window_identity(run, w, k) for k, (run, w) in enumerate(zip(files, windows))))
        try:
            return model.with_cell_fields(pooled_cell_fields(files, model.state_space,
                                                             windows))
        except InputError:         # the grid does not fit the files: no fields
            return model
