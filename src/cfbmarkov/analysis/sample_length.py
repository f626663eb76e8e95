"""How long a fitting sample must be: models fitted on growing windows of a run against the
run's long run (``docs/definitions.md``, Sample length; ``cfbmarkov stationarity
--sample-length``).

From a start time, windows of growing length (0.5, 1, 2, 5, 10, 20, ... s, as far as the
run reaches) are fitted with the same estimator and states, and each model's exact E(RT)
and SD(RT) compared with the run's long-run values. The long run's E(RT) of a periodic
riser comes from its net solids flux over the span (Little's law,
:func:`~cfbmarkov.observed.residence.flux_residence_time`), which the span's length does not
censor; its SD(RT) from the observed residence times of the span, pooled, and it is judged
only where their mean lies within the tolerance of that E(RT): a span that cuts off the
long residences lowers their mean, and their SD more. An open riser's long run is its
pooled residences. The sample length is the shortest window from
which every longer window's judged figures lie within the tolerance of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from cfbmarkov._json import jsonable
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.discrete import discretize
from cfbmarkov.markov.estimate import default_estimator, estimator_from_name
from cfbmarkov.markov.model_summary import CLOSED_CLASSES_ADVICE
from cfbmarkov.observed.residence import net_flow_direction, residence_flux, residence_times
from cfbmarkov.trajectories import Trajectories

#: the window lengths tried, s (those the run's span holds)
LENGTHS = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0)


@dataclass(frozen=True)
class SampleLength:
    """Models on growing windows of one run against its long run.

    Attributes
    ----------
    file : str
        The trajectory file.
    start : float
        Where every window starts (s).
    span_end : float
        The end of the long run (s): the run's last frame.
    long_run_mean : float
        The long run's E(RT) (s): of a periodic riser from its net flux over
        ``start``-``span_end`` (:func:`~cfbmarkov.observed.residence.flux_residence_time`,
        several runs' particle-time over their passes), of an open riser its residences'.
    long_run_sd : float
        SD(RT) (s) of the observed residence times of ``start``-``span_end`` pooled.
    long_run_count : int
        Their number.
    lengths : ndarray, shape (n,)
        Window lengths (s).
    rt_mean, rt_sd : ndarray, shape (n,)
        The exact E(RT), SD(RT) (s) of the model fitted on each window (NaN where none).
    tolerance : float
        Relative tolerance (-).
    sample_length : float
        The shortest length from which every longer window's E(RT) and SD(RT) lie within
        ``tolerance`` of the long run's (s; NaN where none does, even the longest).
    description : str
        The states, lag and estimator of the models.
    long_run_observed_mean : float
        The mean of those observed residence times (s): lower than ``long_run_mean`` where
        the span cuts long residences off (SD(RT) is then judged only where it lies within
        ``tolerance`` of ``long_run_mean``, :attr:`sd_judged`).
    censored_share : float
        The share of the span's particle-time outside its complete residences, 1 - (their
        sum) / (N x span), in [0, 1]; NaN for an open riser (not measured).
    closed_classes : int
        The closed classes of the longest window's chain that residences run in (more than
        1: a reducible chain, whose particles in some states never reach others; 0 where
        no window gave a model).
    run_rt_means : tuple of (str, float)
        Several runs of a periodic riser: each run's long-run E(RT) over the span (its
        particle-time over its passes, s); empty for one run. Runs more than
        :data:`RUNS_DISAGREE` apart are not judged (:func:`verdict_text`).
    outlasting_share : ndarray, shape (n,), optional
        The share of each window's model's residences that last longer than the window
        (its exact RTD's mass beyond the length; NaN where no model): a window whose share
        is above :data:`cfbmarkov.analysis.adequacy.TAIL_LIMIT` is not within, whatever
        its E(RT), since ``fit`` warns that such a window cannot contain its residences.
    fit_failure : str, optional
        Why the longest window whose model failed has none (the fit's refusal), or "".
    """

    file: str
    start: float
    span_end: float
    long_run_mean: float
    long_run_sd: float
    long_run_count: int
    lengths: np.ndarray
    rt_mean: np.ndarray
    rt_sd: np.ndarray
    tolerance: float
    sample_length: float
    description: str
    long_run_observed_mean: float = math.nan
    censored_share: float = math.nan
    closed_classes: int = 0
    run_rt_means: tuple = ()
    outlasting_share: np.ndarray | None = None
    fit_failure: str = ""

    def outlasts(self) -> np.ndarray:
        """Whether each window's model has more than ``TAIL_LIMIT`` of its residences
        longer than the window (``fit``'s warning), shape (n,)."""
        from cfbmarkov.analysis.adequacy import TAIL_LIMIT

        if self.outlasting_share is None:
            return np.zeros(self.lengths.shape, bool)
        return np.asarray(self.outlasting_share, float) > TAIL_LIMIT

    @property
    def observed_shortfall(self) -> float:
        """How far the mean of the long run's complete residences lies below its E(RT),
        1 - ``long_run_observed_mean`` / ``long_run_mean`` (-; 0 for an open riser, NaN
        where not measured)."""
        return 1.0 - self.long_run_observed_mean / self.long_run_mean

    @property
    def sd_judged(self) -> bool:
        """Whether SD(RT) is judged: the mean of the long run's complete residences lies
        within the tolerance of its E(RT) (:attr:`observed_shortfall`; always for an open
        riser, whose long run is its residences)."""
        return not self.observed_shortfall > self.tolerance

    def deviations(self) -> tuple[np.ndarray, np.ndarray]:
        """Each window's E(RT) and SD(RT) relative to the long run's, minus 1 (NaN where
        the window has no model, and SD(RT)'s everywhere where it is not judged,
        :attr:`sd_judged`), two arrays of shape (n,)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            sd = (self.rt_sd / self.long_run_sd - 1.0 if self.sd_judged
                  else np.full(self.rt_sd.shape, np.nan))
            return self.rt_mean / self.long_run_mean - 1.0, sd

    def within(self) -> np.ndarray:
        """Whether each window's judged figures lie within the tolerance, shape (n,)."""
        m, s = self.deviations()
        return ((np.abs(m) <= self.tolerance) & ((np.abs(s) <= self.tolerance)
                                                 | (not self.sd_judged)) & ~self.outlasts())

    def missed(self) -> list[str]:
        """Which figure each window misses the tolerance by: "", "E(RT)", "SD(RT)",
        "both", "no model", or "outlasts" (its model's residences outlast it)."""
        out = []
        for m, s, long in zip(*self.deviations(), self.outlasts()):
            if not (np.isfinite(m) and (np.isfinite(s) or not self.sd_judged)):
                out.append("no model")
                continue
            if long:
                out.append("outlasts")
                continue
            names = [n for n, d in (("E(RT)", m), ("SD(RT)", s)) if abs(d) > self.tolerance]
            out.append("both" if len(names) == 2 else (names[0] if names else ""))
        return out

    def steady_misses(self) -> dict[str, tuple[float, float]]:
        """The figures off by a similar amount at every length: those no longer window
        cures (the states cannot show them).

        Returns
        -------
        dict of str to (float, float)
            "E(RT)" and/or "SD(RT)" -> the smallest and largest deviation (relative, -),
            where every window's deviation of that figure lies beyond the tolerance, on one
            side, and the deviations spread over no more than the tolerance.
        """
        out = {}
        for name, dev in zip(("E(RT)", "SD(RT)"), self.deviations()):
            dev = dev[np.isfinite(dev)]
            if dev.size < 2 or not (np.abs(dev) > self.tolerance).all():
                continue
            if (np.sign(dev) == np.sign(dev[0])).all() and dev.max() - dev.min() <= self.tolerance:
                out[name] = (float(dev.min()), float(dev.max()))
        return out

    @property
    def at_most(self) -> bool:
        """Whether the sample length is the longest window's alone ("at most" that length:
        no longer window confirms it); False where it is not reached."""
        return bool(np.isfinite(self.sample_length) and self.lengths.size > 1
                    and self.sample_length == self.lengths[-1])

    def settled_from(self, figure: str) -> float:
        """The shortest length from which every longer window has ``figure`` ("E(RT)" or
        "SD(RT)") within the tolerance (s; NaN: none)."""
        dev = self.deviations()[0 if figure == "E(RT)" else 1]
        return _first_stable(np.abs(dev) <= self.tolerance, self.lengths)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as None), the output of ``stationarity --sample-length --json``."""
        pd_mean, pd_sd = self.deviations()
        return jsonable({
            "file": self.file, "start": self.start, "span_end": self.span_end,
            "models": self.description, "tolerance": self.tolerance,
            "long_run": {"rt_mean": self.long_run_mean, "rt_sd": self.long_run_sd,
                         "rt_count": self.long_run_count,
                         "rt_mean_observed": self.long_run_observed_mean,
                         "censored_share": self.censored_share,
                         "rt_sd_judged": self.sd_judged},
            "windows": [{"length": float(n), "rt_mean": float(m), "rt_sd": float(s),
                         "within": bool(w), "pd_rt_mean": 100 * float(a),
                         "pd_rt_sd": 100 * float(b), "missed": miss or None,
                         "outlasting_share": float(o)}
                        for n, m, s, w, a, b, miss, o in zip(
                            self.lengths, self.rt_mean, self.rt_sd, self.within(), pd_mean,
                            pd_sd, self.missed(),
                            (self.outlasting_share if self.outlasting_share is not None
                             else np.full(self.lengths.shape, np.nan)))],
            "fit_failure": self.fit_failure or None,
            "steady_misses": {k: [100 * lo, 100 * hi]
                              for k, (lo, hi) in self.steady_misses().items()},
            "closed_classes": self.closed_classes,
            "run_rt_means": {name: mean for name, mean in self.run_rt_means},
            "sample_length": self.sample_length,
            "sample_length_at_most": self.at_most})


def missed_text(miss: str, pd_mean: float, pd_sd: float, outlasting: float = math.nan) -> str:
    """A window's "within" cell of ``stationarity --sample-length``: "yes", or which figure
    misses and by how much.

    Parameters
    ----------
    miss : str
        :meth:`SampleLength.missed` of the window.
    pd_mean, pd_sd : float
        :meth:`SampleLength.deviations` of the window (relative, -).
    outlasting : float, optional
        The window's :attr:`SampleLength.outlasting_share`.

    Returns
    -------
    str
        E.g. "no: SD(RT) -56.2 %" or "no: both (E(RT) +12.1 %, SD(RT) -56.2 %)".
    """
    if not miss:
        return "yes"
    if miss == "no model":
        return "no: no model (the window's fit failed)"
    # three digits: a figure 10.14 % off is not printed "10 %" beside a 10 % tolerance
    mean, sd = f"E(RT) {100 * pd_mean:+.3g} %", f"SD(RT) {100 * pd_sd:+.3g} %"
    if miss == "outlasts":
        # the figures as well: a window that cannot hold its residences may miss by far
        off = ", ".join(text for text, value in ((mean, pd_mean), (sd, pd_sd))
                        if math.isfinite(value))
        return (f"no: {100 * outlasting:.0f} % of its model's residences outlast the window "
                f"(fit warns{f'; {off}' if off else ''})")
    return f"no: {mean if miss == 'E(RT)' else sd if miss == 'SD(RT)' else f'both ({mean}, {sd})'}"


def _percent(fraction: float) -> str:
    """A relative difference in % with its sign: whole percent from 1 % up, two significant
    digits below (a tolerance under 1 % is not answered "+0 % off")."""
    value = 100 * fraction
    return f"{value:+.0f}" if abs(value) >= 1 else f"{value:+.2g}"


#: the relative spread of several runs' long-run E(RT) beyond which they are judged not to
#: be runs of one steady flow: runs of one case from different seeds scatter by a few % on
#: generated risers, and a CFD-DEM riser's E(RT) moves by 10-28 % between 5 s windows, so
#: only a larger gap is judged a different flow
RUNS_DISAGREE = 0.25


def verdict_text(result: SampleLength, states: str) -> str:
    """The closing line of ``stationarity --sample-length``: the length, or which figure
    misses and the cure (a longer run where a figure still drifts with the length, a state
    space with memory where it stays off by a similar amount at every length).

    Parameters
    ----------
    result : SampleLength
        The windows against the long run.
    states : str
        The models' state space, as ``--states`` names it.

    Returns
    -------
    str
        The text after "sample length: ".
    """
    tol = 100 * result.tolerance
    if _runs_disagree(result):
        each = ", ".join(f"{Path(name).name} {m:.3g} s" for name, m in result.run_rt_means)
        return (f"not judged: the runs' long-run E(RT) differ ({each}; pooled "
                f"{result.long_run_mean:.3g} s), more than {100 * RUNS_DISAGREE:g} % apart: "
                "they are not runs of one steady flow, and windows of their pool judge a "
                "mixture; judge each run alone (stationarity RUN --sample-length)")
    if np.isfinite(result.sample_length):
        figures = "E(RT) and SD(RT) lie" if result.sd_judged else "E(RT) lies"
        if result.at_most:
            return (f"{result.sample_length:g} s at most: only the longest window's {figures} "
                    f"within {tol:g} % of the long run's, and no longer window confirms it "
                    "(a longer run, or pool runs with fit A B ...)")
        return (f"{result.sample_length:g} s (from it on, every window's {figures} "
                f"within {tol:g} % of the long run's)")
    longest = result.lengths[-1]
    if result.fit_failure and not np.isfinite(result.rt_mean[-1]):
        # its fit's refusal names the fix (a lag, the cells), which a longer run may not be
        return (f"not judged: the longest window ({longest:g} s) has no model: its fit was "
                "refused (\"no model:\" above, fit_failure in --json), which says what to "
                "change")
    steady = result.steady_misses()
    if result.outlasts()[-1]:
        share = float(result.outlasting_share[-1])
        return (f"not reached within {longest:g} s: {100 * share:.0f} % of the longest "
                "window's model's residences outlast it, so no window of this run can "
                "contain them (fit warns so); a longer run, or pool runs with fit A B ...")

    def settled(figure: str) -> str:
        length = result.settled_from(figure)
        if length == longest and result.lengths.size > 1:
            return f"{figure} lies within {tol:g} % at the longest window ({length:g} s) only"
        return f"{figure} settles (within {tol:g} % from {length:g} s)"

    settles = [settled(figure) for figure in ("E(RT)", "SD(RT)")
               if np.isfinite(result.settled_from(figure))]
    stays = [f"the {states} model's {figure} stays {_percent(0.5 * (lo + hi))} % off at every "
             f"length ({_percent(lo)} to {_percent(hi)} %)"
             for figure, (lo, hi) in steady.items()]
    judged = ("E(RT)", "SD(RT)") if result.sd_judged else ("E(RT)",)
    drifting = [f for f in judged
                if f not in steady and not np.isfinite(result.settled_from(f))]
    said = " but ".join(p for p in (", ".join(settles), " and ".join(stays)) if p)
    said = f": {said}" if said else ""
    memory = ("with memory (fit --states auto chooses one, e.g. --states cells-direction, "
              "cells-previous or, for a flow that alternates between regimes, cells-regime; "
              "try it here with --states)"
              if states == "cells" else "with more memory (fit --states auto chooses one)")
    if result.closed_classes > 1 and steady and not drifting:
        # a reducible chain: memory cannot join what the counts keep apart
        return (f"not reached within {longest:g} s{said}: neither a longer run nor memory "
                f"cures that: the chain has {result.closed_classes} closed classes (its "
                "particles in some cells never reach others, as none did in the windows); "
                + CLOSED_CLASSES_ADVICE)
    if steady and not drifting:
        return (f"not reached within {longest:g} s{said}: a longer run does not cure that; a "
                f"state space {memory} does")
    pd_mean, pd_sd = result.deviations()
    last = {"E(RT)": pd_mean[-1], "SD(RT)": pd_sd[-1]}
    off = " and ".join(f"{f} {_percent(last[f])} %" for f in drifting if np.isfinite(last[f]))
    off = f"; the longest window's {off} off" if off else ""
    cure = "a longer run, or pool runs with fit A B ..."
    if steady:
        cure = (f"for {' and '.join(drifting)} {cure}; for {' and '.join(steady)} a state "
                f"space {memory}")
    else:       # too few lengths may hide a miss that no length cures
        cure += f"; if it stays off as the windows grow, a state space {memory}"
    return f"not reached within {longest:g} s{said}{off}: {cure}"


def _first_stable(within: np.ndarray, lengths: np.ndarray) -> float:
    """The shortest length from which every longer one is within (NaN: none)."""
    for k in range(within.size):
        if within[k:].all():
            return float(lengths[k])
    return math.nan


def sample_length(path, state_space, *, lag: float = 0.025, start: float | None = None,
                  estimator: str | None = None, tolerance: float = 0.1,
                  lengths: Sequence[float] = LENGTHS, stop: float | None = None
                  ) -> SampleLength:
    """Fit models on growing windows of a run from ``start`` and find the length from which
    their E(RT) and SD(RT) stay within ``tolerance`` of the run's long run.

    Several runs of one case (a sequence of paths) are pooled: each window length is taken
    from ``start`` in every run and the model fitted on their counts pooled
    (:mod:`cfbmarkov.markov.pooling`), and the long run is every run's span from ``start``
    to its last frame (its E(RT) from their particle-time over their net passes, its SD(RT)
    from their residences pooled; module docstring); the lengths are per run.

    Parameters
    ----------
    path : str, os.PathLike or sequence of them
        A trajectory file, or several runs of one case.
    state_space : StateSpace
        The states of the models (as ``fit --states``/``--cells``).
    lag : float, optional
        The lag (s).
    start : float, optional
        Where the windows start (s); default the run's first frame (the latest first frame
        of several runs).
    estimator : {"paper", "mle"}, optional
        Default: ``paper`` for the paper's cells on a periodic riser, else ``mle`` (as
        ``fit``, :func:`~cfbmarkov.markov.estimate.default_estimator`).
    tolerance : float, optional
        Relative tolerance, default 0.1.
    lengths : sequence of float, optional
        The lengths tried (s); those that do not end before the (shortest) run's last frame
        or ``stop`` are left out (a window spanning the whole long run would be judged
        against itself).
    stop : float, optional
        Where the long run ends (s); default each run's last frame. Windows end by it.

    Returns
    -------
    SampleLength
        ``file``: the path, or the runs' paths joined by ", ".

    Raises
    ------
    InputError
        On a tolerance that is not positive, a start outside the run, a stop beyond it, a run
        shorter than
        the shortest length, a long run without two residences in its direction or (a
        periodic riser) without a net flux in it, runs that
        cannot be pooled (:func:`~cfbmarkov.markov.pooling.check_runs_match`,
        :func:`~cfbmarkov.markov.pooling.check_runs_distinct`), or the errors of
        :func:`~cfbmarkov.markov.discretize`.
    """
    import contextlib
    import os

    from cfbmarkov.markov.pooling import check_runs_distinct, check_runs_match

    if not (math.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance {tolerance!r} must be a positive number (e.g. 0.1)")
    paths = [path] if isinstance(path, (str, os.PathLike)) else list(path)
    name = ", ".join(str(p) for p in paths)
    with contextlib.ExitStack() as stack:
        runs = [stack.enter_context(Trajectories(p)) for p in paths]
        check_runs_match(runs)
        first = max(float(t.times[0]) for t in runs)
        lasts = [float(t.times[-1]) for t in runs]
        tol = runs[0].time_tolerance
        if stop is not None:
            if not (math.isfinite(stop) and stop <= min(lasts) + tol):
                raise InputError(f"the span's end {stop:g} s lies beyond the last frame of "
                                 f"{name} ({min(lasts):g} s)")
            lasts = [min(t_last, float(stop)) for t_last in lasts]
        last = min(lasts)
        if len(runs) > 1 and first >= last - tol:
            spans = ", ".join(f"{t.path} {float(t.times[0]):g}-{float(t.times[-1]):g} s"
                              for t in runs)
            raise InputError(f"the runs share no span of time ({spans}): --sample-length "
                             "takes the same windows of every run; give runs on one time "
                             "axis (their times from a common origin), or fit them with a "
                             "window per run (fit A.h5 B.h5 --window 10:15,110:115)")
        a = first if start is None else float(start)
        held = f"the frames of {name}" if len(runs) == 1 else f"the frames all of {name} hold"
        if not first - tol <= a < last:
            raise InputError(f"start {a:g} s lies outside {held} ({first:g} to {last:g} s): "
                             "give a start inside them")
        if estimator is None:
            estimator = default_estimator(runs[0].boundary.is_open, state_space.kind)
        # a window as long as the span would be the long run itself, judged against itself
        usable = [float(n) for n in sorted(lengths) if a + n < last - tol]
        if not usable:
            fix = ("an earlier --start" if a > first + tol else
                   f"a run longer than {min(lengths):g} s")
            raise InputError(f"{name} runs {last - a:g} s from {a:g} s: no window of "
                             f"{min(lengths):g} s or more is shorter than that span, the long "
                             f"run each window is judged against; {fix}")
        if len(runs) > 1:
            check_runs_distinct(runs, [(a, t_last) for t_last in lasts])
        fitter = estimator_from_name(estimator, state_space, lag)
        data = [discretize(t, state_space, lag, (a, a + usable[-1])) for t in runs]
        means, sds, outlasting, classes, failure = [], [], [], 0, ""
        for n in usable:
            try:
                rtd = fitter.fit([d.block(a, a + n) for d in data]).rtd()
                means.append(rtd.mean)
                sds.append(rtd.sd)
                p = np.asarray(rtd.probability, float)
                outlasting.append(float(p[rtd.times > n + 1e-9].sum() / p.sum())
                                  if p.sum() > 0 else math.nan)
                classes = int(rtd.closed_classes)
            except CfbmarkovError as exc:
                failure = str(exc)         # the longest window's that failed
                means.append(math.nan)
                sds.append(math.nan)
                outlasting.append(math.nan)
        directions = [net_flow_direction(t, (a, t_last)) for t, t_last in zip(runs, lasts)]
        long_run = np.concatenate([
            residence_times(t, (a, t_last), use_events=False, lag_frames=t.lag_frames(lag),
                            direction=d, face_band=t.height / state_space.rows).samples
            for t, t_last, d in zip(runs, lasts, directions)])
        if long_run.size < 2:
            raise InputError(f"{name} holds {long_run.size} residences from {a:g} s: no long "
                             "run to judge the windows by (a longer run)")
        long_mean, censored = float(long_run.mean()), math.nan
        if not runs[0].boundary.is_open:
            # Little's law over the span: particle-time over the passes that end residences
            flux = [residence_flux(t, (a, t_last), d)
                    for t, t_last, d in zip(runs, lasts, directions)]
            particle_time = sum(f[0] for f in flux)
            passes = sum(f[1] for f in flux)
            if passes <= 0:
                raise InputError(f"{name} has no net solids flux from {a:g} s (its runs' net "
                                 "flows run opposite ways): no long-run E(RT) to judge the "
                                 "windows by (runs of one case, a longer span)")
            long_mean = particle_time / passes
            censored = min(1.0, max(0.0, 1.0 - float(long_run.sum()) / particle_time))
            run_means = tuple((str(t.path), f[0] / f[1] if f[1] > 0 else math.nan)
                              for t, f in zip(runs, flux)) if len(runs) > 1 else ()
    lengths_ = np.asarray(usable)
    runs_text = f", {len(paths)} runs pooled" if len(paths) > 1 else ""
    result = SampleLength(name, a, max(lasts), long_mean,
                          float(long_run.std(ddof=1)), int(long_run.size), lengths_,
                          np.asarray(means, float), np.asarray(sds, float), float(tolerance),
                          math.nan, f"{state_space.describe()}, lag {lag:g} s, estimator "
                                    f"'{estimator}'{runs_text}",
                          float(long_run.mean()), censored, classes,
                          run_means if not runs[0].boundary.is_open else (),
                          np.asarray(outlasting, float), failure)
    return _with_length(result)


def _runs_disagree(result: SampleLength) -> bool:
    """Whether several runs' long-run E(RT) lie more than :data:`RUNS_DISAGREE` apart."""
    means = [m for _, m in result.run_rt_means if math.isfinite(m)]
    return len(means) > 1 and (max(means) - min(means)) / result.long_run_mean > RUNS_DISAGREE


def _with_length(result: SampleLength) -> SampleLength:
    from dataclasses import replace

    length = (math.nan if _runs_disagree(result)      # a mixture of flows is not judged
              else _first_stable(result.within(), result.lengths))
    return replace(result, sample_length=length)
