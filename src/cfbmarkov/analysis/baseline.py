"""What a model must beat: the persistence baseline and the reference's natural variability
(``docs/definitions.md``, Baseline and natural variability).

- The *persistence baseline* uses the reference's own RTD observed in the model's fitting
  window as the prediction of the analysis window: a model is only worth its name where it
  beats it. For a model fitted on several runs, the RTD of all its runs' fitting windows
  pooled (:func:`pooled_window_difference`), read from the runs.
- The *natural variability* is the reference's difference between the two halves of the
  analysis window: how much the "truth" itself moves at that scale (sampling noise and
  non-stationarity), the floor below which no model can be judged.
- The model *on its fitting window*: the prediction's RTD against the reference's RTD in the
  window the model was fitted on (the baseline's own RTD), the model's error where the flow
  did not change. Beside the baseline it splits a model's error on the analysis window into
  its own part and the flow's change between the windows.

Both use the comparison's time basis (frames at the model's lag, or exact events) and its
RTD bins, so their PD and MD stand beside the model's in Table 3.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cfbmarkov.observed.metrics import minkowski_distance, percentage_difference
from cfbmarkov.observed.residence import ResidenceTimes, residence_times, rtd_histogram
from cfbmarkov.trajectories import opened


@dataclass(frozen=True)
class WindowDifference:
    """The difference between two RTDs of the reference, as PD of E(RT) and SD(RT) and MD.

    Attributes
    ----------
    windows : tuple of two (float, float)
        The window standing in for the prediction, and the window it is judged against (s).
    predicted, observed : ResidenceTimes
        Their residence-time samples.
    pd_rt_mean, pd_rt_sd : float
        PD (%) of the first against the second (NaN where undefined).
    md_rtd : float
        Minkowski distance of their RTDs on the comparison's bins (NaN without samples).
    """

    windows: tuple[tuple[float, float], tuple[float, float]]
    predicted: ResidenceTimes
    observed: ResidenceTimes
    pd_rt_mean: float
    pd_rt_sd: float
    md_rtd: float
    runs: int = 1

    def summary(self) -> dict[str, Any]:
        """JSON-ready: windows (s), E(RT) and SD(RT) of the stand-in (s), counts, PD (%), MD,
        and the runs whose windows were pooled for it (1: one run's)."""
        return {"windows": [list(w) for w in self.windows],
                "rt_mean": self.predicted.mean, "rt_sd": self.predicted.sd,
                "rt_count": self.predicted.count, "pd_rt_mean": self.pd_rt_mean,
                "pd_rt_sd": self.pd_rt_sd, "md_rtd": self.md_rtd, "runs": self.runs}


#: MDs within this fraction of the baseline's MD are a tie
BASELINE_TIE = 0.01
#: the outcomes of :func:`judge_baseline`
OUTCOMES = ("beats", "loses", "tie", "not told apart")


@dataclass(frozen=True)
class BaselineJudgement:
    """A model's MD against the persistence baseline's, judged by one rule.

    Attributes
    ----------
    outcome : {"beats", "loses", "tie", "not told apart"}
        "beats": the model's MD is lower than the baseline's by more than the tie margin
        and by more than the reference's own variability; "loses": higher by as much;
        "tie": within the tie margin; "not told apart": outside the tie margin but within
        the reference's own variability.
    md, md_base : float
        The model's and the baseline's MD against the reference.
    md_halves : float or None
        The reference's own variability (MD of its predict window's halves); None where it
        is not known, and then only the tie margin judges.
    tie : float
        The tie margin as a fraction of ``md_base``.
    """

    outcome: str
    md: float
    md_base: float
    md_halves: float | None
    tie: float

    @property
    def beats(self) -> bool:
        """Whether the model beats the baseline."""
        return self.outcome == "beats"

    @property
    def by_tie_margin_alone(self) -> bool:
        """Whether a winner was named without the reference's own variability (its halves'
        MD unknown: a half without residences), by the tie margin alone."""
        return self.md_halves is None and self.outcome in ("beats", "loses")

    @property
    def gap(self) -> float:
        """The baseline's MD minus the model's (positive where the model is closer)."""
        return self.md_base - self.md


def judge_baseline(md: float, md_base: float, md_halves: float | None = None, *,
                   tie: float = BASELINE_TIE) -> BaselineJudgement:
    """Whether a model beats the persistence baseline: the one rule of the report.

    The model beats the baseline only where its MD is lower than the baseline's by more
    than ``tie`` times the baseline's MD and by more than ``md_halves``, the distance
    between the reference's two halves of the window. The second condition comes from the
    triangle inequality of the Minkowski distance: against the true RTD T instead of the
    reference's sampled R, each MD moves by at most MD(R, T), so their gap by at most
    2 MD(R, T); each half of the window carries about sqrt(2) times the sampling noise of
    the whole, so the halves' distance is about 2 MD(R, T) (more where the flow also
    changes within the window). A gap larger than it holds against the true RTD too.

    Parameters
    ----------
    md, md_base : float
        The model's and the baseline's MD against the reference (finite, >= 0).
    md_halves : float, optional
        The MD of the reference's halves; None (or NaN) where unknown: the tie margin
        alone then judges.
    tie : float, optional
        The tie margin as a fraction of ``md_base``; default :data:`BASELINE_TIE` (1 %).

    Returns
    -------
    BaselineJudgement

    Raises
    ------
    ValueError
        On an MD that is not finite, or negative.
    """
    for name, value in (("md", md), ("md_base", md_base)):
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite distance >= 0, got {value!r}")
    halves = (None if md_halves is None or not np.isfinite(md_halves)
              else float(md_halves))
    gap = md_base - md
    if abs(gap) <= tie * md_base:
        outcome = "tie"
    elif halves is not None and abs(gap) <= halves:
        outcome = "not told apart"
    else:
        outcome = "beats" if gap > 0 else "loses"
    return BaselineJudgement(outcome, float(md), float(md_base), halves, float(tie))


def window_difference(ref, stand_in: tuple[float, float], judged: tuple[float, float], *,
                      bin_width: float, md_order: float, use_events: bool, lag_frames: int,
                      face_band: float | None, window_length: float,
                      direction: str = "up") -> WindowDifference:
    """The reference's RTD in ``stand_in`` taken as the prediction of ``judged``.

    Parameters
    ----------
    ref : Trajectories
        The reference file.
    stand_in, judged : (float, float)
        The two windows (s).
    bin_width, md_order : float
        The comparison's RTD bins (s) and Minkowski order.
    use_events, lag_frames, face_band, direction
        The comparison's basis and direction (:func:`cfbmarkov.observed.residence.residence_times`).
    window_length : float
        Length (s) whose bins both RTDs use (the analysis window's).

    Returns
    -------
    WindowDifference
    """
    kwargs = {"use_events": use_events, "lag_frames": lag_frames, "face_band": face_band,
              "direction": direction}
    a = residence_times(ref, stand_in, **kwargs)
    b = residence_times(ref, judged, **kwargs)
    _, pa = rtd_histogram(a.samples, bin_width, window_length=window_length)
    _, pb = rtd_histogram(b.samples, bin_width, window_length=window_length)
    md = minkowski_distance(pa, pb, md_order) if pa.sum() > 0 and pb.sum() > 0 else float("nan")
    return WindowDifference((tuple(stand_in), tuple(judged)), a, b,
                            percentage_difference(a.mean, b.mean),
                            percentage_difference(a.sd, b.sd, scale=b.mean), md)


def pooled_window_difference(runs, ref, judged: tuple[float, float], *, bin_width: float,
                             md_order: float, use_events: bool, lag_frames: int,
                             face_band: float | None, window_length: float,
                             direction: str = "up") -> WindowDifference:
    """The RTD of several runs' windows pooled taken as the prediction of ``judged`` in the
    reference: the persistence baseline of a pooled fit.

    Parameters
    ----------
    runs : sequence of (str, (float, float))
        Each run's trajectory file and window (s), as a pooled model records them.
    ref : Trajectories
        The reference file.
    judged : (float, float)
        The window judged (s).
    bin_width, md_order, use_events, lag_frames, face_band, window_length, direction
        As :func:`window_difference`.

    Returns
    -------
    WindowDifference
        ``windows``: (the first run's window, ``judged``); ``predicted``: the pooled samples.

    Raises
    ------
    InputError
        If a run cannot be read or a window holds no frame of it.
    """
    kwargs = {"use_events": use_events, "lag_frames": lag_frames, "face_band": face_band,
              "direction": direction}
    samples, exact = [], True
    for path, window in runs:
        with opened(path) as run:
            got = residence_times(run, window, **kwargs)
        samples.append(got.samples)
        exact = exact and got.exact
    a = ResidenceTimes(np.concatenate(samples), exact, tuple(runs[0][1]))
    b = residence_times(ref, judged, **kwargs)
    _, pa = rtd_histogram(a.samples, bin_width, window_length=window_length)
    _, pb = rtd_histogram(b.samples, bin_width, window_length=window_length)
    md = minkowski_distance(pa, pb, md_order) if pa.sum() > 0 and pb.sum() > 0 else float("nan")
    return WindowDifference((tuple(runs[0][1]), tuple(judged)), a, b,
                            percentage_difference(a.mean, b.mean),
                            percentage_difference(a.sd, b.sd, scale=b.mean), md, len(runs))


def model_on_fitting_window(model: ResidenceTimes, model_rtd: np.ndarray,
                            baseline: WindowDifference, *, bin_width: float, md_order: float,
                            window_length: float) -> WindowDifference:
    """The prediction's residence times against the reference's in the model's fitting
    window: the model's own (in-sample) error.

    A model fitted on a window can at best reproduce that window's RTD, which the persistence
    baseline uses as it is; its error on the analysis window is its own error here plus the
    flow's change between the windows (the baseline's), so it beats the baseline only where
    its own error is small against the flow's change and happens to lean towards it.

    Parameters
    ----------
    model : ResidenceTimes
        The prediction's residence times in the analysis window.
    model_rtd : ndarray (bins,)
        Their RTD on the comparison's bins.
    baseline : WindowDifference
        The persistence baseline (:func:`window_difference` of the fitting window against
        the analysis window); its ``predicted`` are the fitting window's residence times.
    bin_width, md_order : float
        The comparison's RTD bins (s) and Minkowski order.
    window_length : float
        Length (s) whose bins both RTDs use (the analysis window's).

    Returns
    -------
    WindowDifference
        ``windows``: (analysis window, fitting window); ``predicted`` the model's,
        ``observed`` the fitting window's residence times (of every run the baseline
        pooled, ``runs`` as the baseline's); PD (%) and MD of the first against the second
        (Eq. 7-9 of the paper, as the comparison's).
    """
    fit = baseline.predicted
    _, p_fit = rtd_histogram(fit.samples, bin_width, window_length=window_length)
    md = (minkowski_distance(model_rtd, p_fit, md_order)
          if model_rtd.sum() > 0 and p_fit.sum() > 0 else float("nan"))
    return WindowDifference((tuple(baseline.windows[1]), tuple(baseline.windows[0])), model,
                            fit, percentage_difference(model.mean, fit.mean),
                            percentage_difference(model.sd, fit.sd, scale=fit.mean), md,
                            runs=baseline.runs)


def fitting_window(pred) -> tuple[float, float] | None:
    """The fitting window (A, B) of the model behind a prediction, or None.

    Parameters
    ----------
    pred : Trajectories
        A prediction (its ``/provenance/model`` group holds the window).

    Returns
    -------
    (float, float) or None
    """
    group = pred.group("model")
    if group is None or "window" not in group.attrs:
        return None
    window = np.asarray(group.attrs["window"], dtype=float)
    if window.shape != (2,) or not np.all(np.isfinite(window)) or not window[1] > window[0]:
        return None
    return float(window[0]), float(window[1])


def fitting_runs_of(pred) -> list[tuple[str, tuple[float, float]]] | None:
    """The runs and windows of the pooled model behind a prediction (its
    ``/provenance/model`` group's ``source`` and ``run_windows``), or None for a model of
    one run or where they cannot be read.

    Parameters
    ----------
    pred : Trajectories
        A prediction.

    Returns
    -------
    list of (str, (float, float)) or None
    """
    import json

    group = pred.group("model")
    if group is None or "run_windows" not in group.attrs or "source" not in group.attrs:
        return None
    try:
        text = [group.attrs[k] for k in ("source", "run_windows")]
        source, windows = (json.loads(t.decode() if isinstance(t, bytes) else t) for t in text)
        runs = [(str(p), (float(w[0]), float(w[1]))) for p, w in zip(source, windows)]
    except (ValueError, TypeError, IndexError):
        return None
    return runs if len(runs) == len(source) and len(runs) > 1 else None
