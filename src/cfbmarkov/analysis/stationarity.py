"""How much a run's flow changes from window to window, and how far one window lies from
the run's long run (``docs/definitions.md``, Stationarity).

A Markov model fitted on one window is a stationary description of the flow: it predicts
one RTD for every later window. Where the flow drifts or surges on the scale of the
windows (a riser's clusters and inventory swings), the RTD of a 5 s window scatters about
the flow's long-run RTD, and a stationary model's prediction of a given window carries that
scatter, whatever its states. Two figures measure it on the reference:

- :func:`window_statistics`: E(RT), SD(RT) and residence counts of sliding windows, and
  their relative standard deviations;
- :func:`long_run_baseline`: the reference's RTD pooled over every window of a span that
  does not overlap the judged window (whole windows of its length, aligned with it), taken
  as the prediction of the judged window: the run's long-run RTD without the judged window,
  what a perfect stationary model fitted on the rest of the run would predict. Beside the
  persistence baseline (:func:`cfbmarkov.analysis.baseline.window_difference`) it shows how
  much of a model's error on the judged window is the flow's scatter about its long run.

:func:`check_stationarity` gives both for a trajectory file, the numbers of ``cfbmarkov
stationarity``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cfbmarkov._json import jsonable
from cfbmarkov.analysis.baseline import WindowDifference, window_difference
from cfbmarkov.observed.metrics import minkowski_distance, percentage_difference
from cfbmarkov.observed.residence import (DEFAULT_FACE_ROWS, ResidenceTimes,
                                          flux_residence_time, net_flow_direction,
                                          residence_times, rtd_histogram)
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import time_text

#: residence directions a caller may ask for; "auto" follows each window's net solids flow
DIRECTIONS = ("auto", "up", "down")


@dataclass(frozen=True)
class WindowStatistics:
    """E(RT), SD(RT) and residence counts of a run's sliding windows.

    Attributes
    ----------
    window_length : float
        Length of every window (s).
    step : float
        Time between the starts of consecutive windows (s).
    starts : numpy.ndarray, shape (n,)
        Window starts (s); window ``i`` is ``[starts[i], starts[i] + window_length]``.
    rt_mean, rt_sd : numpy.ndarray, shape (n,)
        E(RT) and SD(RT) of each window's residence-time samples (s; NaN with fewer than one
        or two samples).
    rt_count : numpy.ndarray of int, shape (n,)
        Residences per window.
    direction : tuple of str, length n
        "up" or "down": the residences' direction in each window (docs/definitions.md, Net
        downflow).
    exact : bool
        Whether the samples come from the file's exact pass events (else frames).
    flux_rt_mean : numpy.ndarray, shape (n,), or None
        Each window's E(RT) from its net solids flux, particle-time over net passes in its
        direction (s; docs/definitions.md, Long-run E(RT)): the flow's mean residence time
        over the window, which the window's length does not censor as it does ``rt_mean``;
        ``inf`` where no net pass runs that way; None for an open riser or a file with
        absent particles.
    """

    window_length: float
    step: float
    starts: np.ndarray
    rt_mean: np.ndarray
    rt_sd: np.ndarray
    rt_count: np.ndarray
    direction: tuple[str, ...]
    exact: bool
    flux_rt_mean: np.ndarray | None = None

    @staticmethod
    def _relative_sd(values: np.ndarray) -> float:
        finite = values[np.isfinite(values)]
        if finite.size < 2 or not finite.mean() > 0:
            return float("nan")
        return float(finite.std(ddof=1) / finite.mean())

    @staticmethod
    def _average(values: np.ndarray) -> float:
        finite = values[np.isfinite(values)]
        return float(finite.mean()) if finite.size else float("nan")

    @property
    def average_rt_mean(self) -> float:
        """Mean of the windows' E(RT) (s; NaN where none is defined)."""
        return self._average(self.rt_mean)

    @property
    def average_rt_sd(self) -> float:
        """Mean of the windows' SD(RT) (s; NaN where none is defined)."""
        return self._average(self.rt_sd)

    @property
    def relative_sd_rt_mean(self) -> float:
        """Standard deviation of the windows' E(RT) over their mean (-; NaN with fewer than
        two windows). Windows closer than their length overlap, so they are not independent
        samples: the figure estimates the scatter of one window, not its uncertainty."""
        return self._relative_sd(self.rt_mean)

    @property
    def relative_sd_rt_sd(self) -> float:
        """Standard deviation of the windows' SD(RT) over their mean (-), as
        :attr:`relative_sd_rt_mean`."""
        return self._relative_sd(self.rt_sd)

    @property
    def average_flux_rt_mean(self) -> float | None:
        """Mean of the windows' flux E(RT) (s; None for an open riser, which has none)."""
        return None if self.flux_rt_mean is None else self._average(self.flux_rt_mean)

    @property
    def relative_sd_flux_rt_mean(self) -> float | None:
        """Standard deviation of the windows' flux E(RT) over their mean (-), as
        :attr:`relative_sd_rt_mean`: the scatter from window to window of the throughput a
        chain fitted on one window carries (None for an open riser)."""
        return None if self.flux_rt_mean is None else self._relative_sd(self.flux_rt_mean)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: the windows (s), their E(RT), SD(RT) (s), counts and directions, the
        averages (s) and the relative standard deviations (-); undefined values as None."""
        def finite(values):
            return [float(v) if np.isfinite(v) else None for v in values]
        return {"window_length": self.window_length, "step": self.step,
                "exact_events": self.exact,
                "average_rt_mean": finite([self.average_rt_mean])[0],
                "average_rt_sd": finite([self.average_rt_sd])[0],
                "windows": [[float(a), round(float(a + self.window_length), 9)]
                            for a in self.starts],
                "rt_mean": finite(self.rt_mean), "rt_sd": finite(self.rt_sd),
                "rt_count": [int(c) for c in self.rt_count], "direction": list(self.direction),
                "relative_sd_rt_mean": finite([self.relative_sd_rt_mean])[0],
                "relative_sd_rt_sd": finite([self.relative_sd_rt_sd])[0],
                "flux_rt_mean": (None if self.flux_rt_mean is None
                                 else finite(self.flux_rt_mean)),
                "average_flux_rt_mean": (None if self.flux_rt_mean is None
                                         else finite([self.average_flux_rt_mean])[0]),
                "relative_sd_flux_rt_mean": (None if self.flux_rt_mean is None else
                                             finite([self.relative_sd_flux_rt_mean])[0])}


def _span(traj, span: tuple[float, float] | None, option: str = "--span"
          ) -> tuple[float, float]:
    """The span of ``traj`` asked for (s), all of it for None; a refusal names the
    ``option`` that gave it."""
    first, last = float(traj.times[0]), float(traj.times[-1])
    if span is None:
        return first, last
    a, b = float(span[0]), float(span[1])
    tol = traj.time_tolerance
    if not (np.isfinite(a) and np.isfinite(b) and b > a):
        raise InputError(f"span {a:g}:{b:g} s must be finite with its end after its start")
    if a < first - tol or b > last + tol:
        partly = not (b <= first or a >= last)
        inside = f"; only {max(a, first):g}:{min(b, last):g} s lies inside" if partly else ""
        raise InputError(f"span {a:g}:{b:g} s lies {'partly ' if partly else ''}outside the "
                         f"frames of {traj.path} ({first:g} to {last:g} s{inside}): give "
                         f"{option} inside them, e.g. "
                         f"{option} {first:g}:{last:g}"
                         + (", or leave --span out for all of them" if option == "--span"
                            else ""))
    return a, b


def _direction_of(traj, window: tuple[float, float], direction: str) -> str:
    if direction not in DIRECTIONS:
        raise InputError(f"residence direction {direction!r}: auto, up or down")
    return net_flow_direction(traj, window) if direction == "auto" else direction


#: most windows one stationarity check computes (each reads its window's residences)
MAX_WINDOWS = 10_000


def window_statistics(traj, *, window_length: float = 5.0, step: float = 1.0,
                      span: tuple[float, float] | None = None, use_events: bool = False,
                      lag_frames: int = 1, face_band: float | None = None,
                      direction: str = "auto") -> WindowStatistics:
    """E(RT), SD(RT) and residence counts of sliding windows of a trajectory file.

    Windows of ``window_length`` start at the span's start and every ``step`` after it, as
    long as they end within the span (a tolerance of the file's ``time_tolerance``).

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file (periodic or open riser).
    window_length : float, optional
        Length of each window (s), default 5 (the paper's fitting and analysis windows).
    step : float, optional
        Time between window starts (s), default 1.
    span : (float, float), optional
        The part of the file the windows cover (s); default all of it. Leave out a run's
        start-up from rest.
    use_events, lag_frames, face_band
        The residence times' basis (:func:`cfbmarkov.observed.residence.residence_times`): exact
        events, or frames every ``lag_frames``-th (a model's lag).
    direction : {"auto", "up", "down"}, optional
        "auto": each window's own net solids flow decides (docs/definitions.md, Net
        downflow).

    Returns
    -------
    WindowStatistics

    Raises
    ------
    InputError
        On a window length or step that is not finite and positive, a span outside the
        file's frames, a span that holds fewer than two windows or more than
        ``MAX_WINDOWS``, (from frames) a step shorter than the frame interval, or (a
        periodic riser) no pass through the boundary over the span.
    """
    length, step = float(window_length), float(step)
    if not (np.isfinite(length) and length > 0):
        raise InputError(f"window length {window_length} s must be finite and positive")
    if not (np.isfinite(step) and step > 0):
        raise InputError(f"window step {step} s must be finite and positive")
    a, b = _span(traj, span)
    tol = traj.time_tolerance
    interval = float(traj.frame_interval)
    if not use_events and np.isfinite(interval) and step < interval - tol:
        raise InputError(f"window step {step:g} s is shorter than the frame interval of "
                         f"{traj.path} ({interval:g} s): windows starting between two frames "
                         f"hold the same frames; give --step {interval:g} or more")
    count = int(np.floor((b - a - length + tol) / step)) + 1 if b - a + tol >= length else 0
    if count > MAX_WINDOWS:
        raise InputError(f"{a:g}:{b:g} s of {traj.path} holds {count} windows {step:g} s apart, "
                         f"more than {MAX_WINDOWS}; give --step {(b - a - length) / MAX_WINDOWS:.3g}"
                         " or more (or a shorter --span)")
    if count < 2:
        fix = (f"a --window-length of at most half the span's {b - a:g} s"
               if length > 0.5 * (b - a) + tol else "a shorter --window-length or --step")
        raise InputError(f"{a:g}:{b:g} s of {traj.path} holds {max(count, 0)} window(s) of "
                         f"{length:g} s {step:g} s apart: two at least are needed ({fix})")
    if lag_frames * traj.frame_interval >= length - tol:
        raise InputError(f"frames every {lag_frames * traj.frame_interval:g} s leave no residence "
                         f"time inside a {length:g} s window: a lag shorter than the window")
    starts = np.round(a + step * np.arange(count), 9)    # no 0.30000000000000004 s
    means, sds, counts, directions, fluxes = [], [], [], [], []
    with_flux = not traj.boundary.is_open
    exact = False
    for start in starts:
        window = (float(start), float(start + length))
        d = _direction_of(traj, window, direction)
        rt = residence_times(traj, window, use_events=use_events, lag_frames=lag_frames,
                             face_band=face_band, direction=d)
        means.append(rt.mean)
        sds.append(rt.sd)
        counts.append(rt.count)
        directions.append(d)
        if with_flux:
            fluxes.append(flux_residence_time(traj, window, d))
        exact = rt.exact
    if not any(counts) and not traj.boundary.is_open and not _passes_in(traj, (a, b)):
        raise InputError(f"{traj.path}: no particle passes the periodic boundary over "
                         f"{a:g}-{b:g} s (its lap counters never change), so no window "
                         "holds a residence and no flow's stationarity can be judged; check "
                         "the span, or with cfbmarkov info the file's height and vertical "
                         "axis")
    return WindowStatistics(length, step, starts, np.asarray(means, float),
                            np.asarray(sds, float), np.asarray(counts, np.int64),
                            tuple(directions), exact,
                            np.asarray(fluxes, float) if with_flux else None)


def _passes_in(traj, span: tuple[float, float]) -> bool:
    """Whether some particle's lap counter changes between two frames of ``span`` (a pass
    through the periodic boundary, in either direction)."""
    frames = traj.window(float(span[0]), float(span[1]))
    for k in range(frames.start, frames.stop - 1, 1024):
        laps = traj.laps(slice(k, min(k + 1025, frames.stop)))
        if np.any(laps[1:] != laps[:-1]):
            return True
    return False


def long_run_baseline(traj, judged: tuple[float, float], *, span: tuple[float, float] | None
                      = None, bin_width: float, md_order: float = 2.0, use_events: bool = False,
                      lag_frames: int = 1, face_band: float | None = None,
                      direction: str = "auto", option: str = "--span",
                      at_least: int = 1) -> WindowDifference:
    """The reference's RTD pooled over the span's other windows, as the prediction of one.

    The span is tiled with whole windows of the judged window's length, aligned with it
    (``judged[0] + k L`` for whole k), and every tile that lies in the span and does not
    overlap the judged window contributes its residence-time samples. The pooled samples
    are the run's long-run RTD without the judged window: what a stationary model that
    reproduced the rest of the run perfectly would predict. Their PD and MD against the
    judged window measure the flow's scatter about its long run: a stationary model's
    prediction carries that scatter whatever its states, though one may, by chance, lean
    the judged window's way (the persistence baseline sometimes does).

    Parameters
    ----------
    traj : Trajectories
        The reference file.
    judged : (float, float)
        The window judged (s).
    span : (float, float), optional
        The part of the file whose other windows are pooled (s); default all of it.
    bin_width : float
        The RTD bins (s), keyword only.
    md_order : float, optional
        Minkowski order (Eq. 9), default 2.
    use_events, lag_frames, face_band
        The residence times' basis (:func:`cfbmarkov.observed.residence.residence_times`).
    direction : {"auto", "up", "down"}, optional
        "auto": the judged window's net solids flow decides, and the pooled windows use the
        same direction.
    option : str, optional
        The command-line option that gave ``span``, named in the refusals (``--span`` of
        ``stationarity``, ``--long-run-span`` of ``compare``).
    at_least : int, optional
        The fewest other windows the span must hold (``compare`` asks for 2: one other
        window beside the fitting window's is the persistence baseline again).

    Returns
    -------
    WindowDifference
        ``windows``: (the extent of the pooled windows and the judged one, the judged
        window); ``predicted``: the pooled samples (their ``window`` is that extent); PD (%)
        of E(RT) and SD(RT) and MD against the judged window.

    Raises
    ------
    InputError
        On a judged window that is empty or outside the span, or a span without
        ``at_least`` other whole windows of the judged window's length.
    """
    a, b = _span(traj, span, option)
    j0, j1 = float(judged[0]), float(judged[1])
    length = j1 - j0
    tol = traj.time_tolerance
    if not (np.isfinite(length) and length > 0):
        raise InputError(f"judged window {j0:g}:{j1:g} s is empty")
    if j0 < a - tol or j1 > b + tol:
        raise InputError(f"judged window {j0:g}:{j1:g} s lies outside the span {a:g}:{b:g} "
                         f"s: judge a window inside it, or widen the span ({option})")
    d = _direction_of(traj, (j0, j1), direction)
    k_lo = int(np.ceil((a - j0 - tol) / length))
    k_hi = int(np.floor((b - j1 + tol) / length))
    tiles = [(j0 + k * length, j1 + k * length) for k in range(k_lo, k_hi + 1) if k != 0]
    if not tiles:
        raise InputError(f"span {a:g}:{b:g} s holds no other whole {length:g} s window beside "
                         f"{j0:g}:{j1:g} s (give a longer {option})")
    if len(tiles) < at_least:
        raise InputError(f"span {a:g}:{b:g} s holds only {len(tiles)} other whole {length:g} s "
                         f"window beside {j0:g}:{j1:g} s: one window is a persistence baseline "
                         f"again, not a long run; give a longer {option} (at least "
                         f"{at_least} other windows)")
    kwargs = {"use_events": use_events, "lag_frames": lag_frames, "face_band": face_band,
              "direction": d}
    pooled = [residence_times(traj, tile, **kwargs) for tile in tiles]
    samples = np.concatenate([p.samples for p in pooled])
    extent = (min(tiles[0][0], j0), max(tiles[-1][1], j1))
    predicted = ResidenceTimes(samples, pooled[0].exact, extent)
    observed = residence_times(traj, (j0, j1), **kwargs)
    _, pa = rtd_histogram(predicted.samples, bin_width, window_length=length)
    _, pb = rtd_histogram(observed.samples, bin_width, window_length=length)
    md = minkowski_distance(pa, pb, md_order) if pa.sum() > 0 and pb.sum() > 0 else float("nan")
    return WindowDifference((extent, (j0, j1)), predicted, observed,
                            percentage_difference(predicted.mean, observed.mean),
                            percentage_difference(predicted.sd, observed.sd, scale=observed.mean),
                            md)


@dataclass(frozen=True)
class JudgedWindow:
    """One window of a run against the run's long run and against the window before it.

    Attributes
    ----------
    window : (float, float)
        The judged window (start, stop), s.
    direction : {"up", "down"}
        The residences' direction, from the judged window's net solids flow.
    long_run : WindowDifference
        The run's RTD pooled over the span's other whole windows as the prediction of the
        judged window (:func:`long_run_baseline`); its ``observed`` samples are the judged
        window's.
    persistence : WindowDifference or None
        The window of the same length just before it as the prediction
        (:func:`cfbmarkov.analysis.baseline.window_difference`); None where that window
        does not lie whole in the span.
    """

    window: tuple[float, float]
    direction: str
    long_run: WindowDifference
    persistence: WindowDifference | None

    def to_dict(self) -> dict[str, Any]:
        """The ``judged`` part of :meth:`StationarityCheck.to_dict`.

        Returns
        -------
        dict
            ``window`` (s), ``direction``, the judged window's ``rt_mean`` and ``rt_sd``
            (s) and ``rt_count``, and the ``long_run`` and ``persistence`` differences
            (:meth:`~cfbmarkov.analysis.baseline.WindowDifference.summary`, or None).
        """
        observed = self.long_run.observed
        return {"window": list(self.window), "direction": self.direction,
                "rt_mean": observed.mean, "rt_sd": observed.sd, "rt_count": observed.count,
                "long_run": self.long_run.summary(),
                "persistence": None if self.persistence is None else self.persistence.summary()}


@dataclass(frozen=True)
class StationarityCheck:
    """How much a run's RTD changes from window to window (``cfbmarkov stationarity``).

    Attributes
    ----------
    file : str
        The trajectory file, as named by the caller.
    span : (float, float)
        The part of the file the windows cover, s.
    exact_events : bool
        Whether residence times come from the file's exact pass events (else frames).
    rtd_bin_width : float
        The RTD bins of the Minkowski distances, s: the lag, else the frame interval.
    statistics : WindowStatistics
        The sliding windows (:func:`window_statistics`).
    judged : JudgedWindow or None
        The judged window, where one was asked for.
    warnings : tuple of str
        What the figures leave out: on an open riser, tracks that begin or end away from
        its faces (:func:`face_band_warning`).
    """

    file: str
    span: tuple[float, float]
    exact_events: bool
    rtd_bin_width: float
    statistics: WindowStatistics
    judged: JudgedWindow | None = None
    warnings: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, the output of ``cfbmarkov stationarity --json``.

        Returns
        -------
        dict
            ``file``, ``span`` (s), ``basis`` (``events`` or ``frames``), ``rtd_bin_width``
            (s), the keys of :meth:`WindowStatistics.summary` and, where a window was judged,
            ``judged`` (:meth:`JudgedWindow.to_dict`), and ``warnings`` (a list of
            lines); undefined values as None.
        """
        summary = {"file": self.file, "span": list(self.span),
                   "basis": "events" if self.exact_events else "frames",
                   "rtd_bin_width": self.rtd_bin_width, **self.statistics.summary(),
                   "warnings": list(self.warnings)}
        if self.judged is not None:
            summary["judged"] = self.judged.to_dict()
        return jsonable(summary)


#: the share of an open riser's tracks beginning (or ending) away from its faces beyond
#: which the residence times' face band is warned of
FACE_MISS_LIMIT = 0.2


def face_band_warning(traj, span: tuple[float, float], band: float, lag_frames: int = 1,
                      option: str = "--cells", limit: float = FACE_MISS_LIMIT,
                      fix: str | None = None) -> str | None:
    """The warning where an open riser's residence times leave out many of its tracks: more
    than :data:`FACE_MISS_LIMIT` of those begun in ``span`` began farther than ``band`` from
    the inlet, or of those ended farther from the outlet (counted as censored, not as
    entries or exits; :func:`cfbmarkov.observed.residence.open_face_tracks`).

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.
    span : (float, float)
        The part of the file read, s.
    band : float
        The face band, m (one cell height of the model, H / rows).
    lag_frames : int, optional
        Every ``lag_frames``-th frame, as the residence times read them.
    option : str, optional
        The option that sets the band, named in the fix.
    limit : float, optional
        The share of the tracks begun (ended) away from the face beyond which it warns
        (default :data:`FACE_MISS_LIMIT`; ``compare`` takes the model's
        :data:`~cfbmarkov.markov.open_flow.CENSORED_SHARE`, as ``fit`` warns of its window).
    fix : str, optional
        What to do, in place of the advice naming ``option``.

    Returns
    -------
    str or None
        The line, or None on a periodic riser or where few tracks are left out.
    """
    from cfbmarkov.observed.residence import open_face_tracks

    if not traj.boundary.is_open:
        return None
    begun, at_inlet, ended, at_outlet = open_face_tracks(traj, span, band, lag_frames)
    missed = [(begun - at_inlet, begun, "began", "inlet"),
              (ended - at_outlet, ended, "ended", "outlet")]
    missed = [m for m in missed if m[1] and m[0] > limit * m[1]]
    if not missed:
        return None
    rows = traj.height / band
    said = " and ".join(f"{away} of the {total} tracks that {verb} in {span[0]:g}-{span[1]:g} s "
                        f"{verb} farther than the face band from the {face}"
                        for away, total, verb, face in missed)
    return (f"{said} (the band: {1e3 * band:.3g} mm, H/{rows:.3g}, one cell of {rows:.3g} "
            "rows): the residence times count only those within it as entries and exits and "
            "leave the others out as censored; "
            + (fix if fix is not None else
               f"where particles enter or leave the riser there (an insertion region, "
               f"frames far apart), give {option} with the rows of your model (the band is "
               "one cell height)"))


def check_stationarity(path, *, window_length: float = 5.0, step: float = 1.0,
                       span: tuple[float, float] | None = None, lag: float | None = None,
                       basis: str = "frames", judge: tuple[float, float] | None = None,
                       face_band: float | None = None) -> StationarityCheck:
    """Sliding-window statistics of a trajectory file and, optionally, one window judged
    against the run's long run and against the window before it (persistence).

    Parameters
    ----------
    path : str or os.PathLike
        A trajectory file.
    window_length, step : float, optional
        Window length and the time between window starts, s (:func:`window_statistics`).
    span : (float, float), optional
        The part of the file used, s; default all of it.
    lag : float, optional
        Frames every ``lag`` s (a model's lag), also the RTD bins (s); default every frame
        and bins of the frame interval.
    basis : {"frames", "events"}, optional
        Residence times from frames, or from the file's exact pass events.
    judge : (float, float), optional
        A window (s) to compare with the span's other whole windows of its length, pooled
        (:func:`long_run_baseline`), and with the window of its length before it.
    face_band : float, optional
        Open riser: how close to a face (m) a track must begin or end to have entered or
        left (a model's cell height, H / rows); default H / 38, the paper's rows. Where many
        tracks begin or end outside it, the result carries a warning
        (:func:`face_band_warning`).

    Returns
    -------
    StationarityCheck

    Raises
    ------
    InputError
        For ``basis="events"`` on a file without exact pass events (or an open riser), a
        lag that is not a whole number of frames, windows none of which holds a residence,
        a judged window outside the span, and
        the errors of :func:`window_statistics` and :func:`long_run_baseline`.
    """
    events = basis == "events"
    with Trajectories(path) as traj:
        if events and not (traj.has_events and not traj.boundary.is_open):
            raise InputError(f"{path} holds no exact pass events: residence times from "
                             "frames need no --basis events")
        if face_band is not None and not traj.boundary.is_open:
            raise InputError(f"{path} is a periodic riser: a face band (--cells) sets where "
                             "an open riser's particles enter and leave; leave it out")
        lag_frames = traj.lag_frames(lag) if lag is not None else 1
        _check_on_frames(traj, window_length, step, judge)
        bin_width = lag if lag is not None else traj.frame_interval
        kwargs = {"use_events": events, "lag_frames": 1 if events else lag_frames,
                  "face_band": face_band}
        extent = span or (float(traj.times[0]), float(traj.times[-1]))
        stats = window_statistics(traj, window_length=window_length, step=step, span=span,
                                  **kwargs)
        if stats.starts.size and not np.any(stats.rt_count > 0):
            band = traj.height / DEFAULT_FACE_ROWS if face_band is None else float(face_band)
            missed = face_band_warning(traj, extent, band, kwargs["lag_frames"])
            # an open riser whose tracks begin and end away from a thin face band has no
            # residence at any window length: the band is the cause, and the line names it
            raise InputError(f"no residence begins and ends in any of the {stats.starts.size} "
                             f"windows of {stats.window_length:g} s in {path} "
                             f"({extent[0]:g}-{extent[1]:g} s): "
                             + (f"{missed}; and " if missed else "")
                             + "a residence must fit in a window: give a longer "
                             "--window-length (several mean residence times)")
        judged = None
        if judge is not None:
            judged = _judged_window(traj, judge, span, extent, bin_width, kwargs)
        band = traj.height / DEFAULT_FACE_ROWS if face_band is None else float(face_band)
        warning = face_band_warning(traj, extent, band, kwargs["lag_frames"])
    warnings = [] if warning is None else [warning]
    turned = turned_direction_warning(stats)
    if turned:
        warnings.append(turned)
    return StationarityCheck(str(path), extent, events, bin_width, stats, judged,
                             tuple(warnings))


def turned_direction_warning(stats: WindowStatistics) -> str | None:
    """A warning where the windows count residences in different directions (the net solids
    flow turns within the span): their average and scatter then mix residences up through
    the top with residences down through the bottom, which are not one flow's figures.

    Returns
    -------
    str or None
        The warning, naming the windows of each direction; None where all agree.
    """
    directions = list(stats.direction)
    if len(set(directions)) < 2:
        return None
    length = stats.window_length
    named = {d: [f"{a:g}-{a + length:g}" for a, w in zip(stats.starts, directions) if w == d]
             for d in ("up", "down")}

    def listed(d):
        windows = named[d]
        return (", ".join(windows[:3]) + (f" and {len(windows) - 3} more" if len(windows) > 3
                                          else ""))
    return (f"the net solids flow turns within the span: {len(named['up'])} window(s) count "
            f"residences up through the top ({listed('up')} s), {len(named['down'])} down "
            f"through the bottom ({listed('down')} s); the averages and relative SDs below "
            "mix the two directions, which are not one flow's figures: judge the windows of "
            "one direction (a --span where the flow runs one way; docs/definitions.md, Net "
            "downflow)")


def _check_on_frames(traj, window_length: float, step: float,
                     judge: tuple[float, float] | None) -> None:
    """Refuse a window length or step that is not a whole number of frame intervals, and a
    judged window whose ends fall between frames: the windows hold whole frames, so their
    figures were of other windows than their labels said (a row "0.03-5.03" of the frames
    0.05-5.025 s)."""
    interval = float(traj.frame_interval)
    if not np.isfinite(interval):
        return
    tol = traj.time_tolerance

    def off(value: float) -> bool:
        return abs(value - round(value / interval) * interval) > tol

    for option, value in (("--window-length", window_length), ("--step", step)):
        if np.isfinite(value) and value > 0 and off(value):
            below = max(np.floor(value / interval), 1.0) * interval
            raise InputError(f"{option} {value:g} s is not a whole number of the file's frame "
                             f"intervals ({time_text(interval)} s): give {below:.10g} or "
                             f"{below + interval:.10g} s")
    if judge is not None:
        times = np.asarray(traj.times)
        for end in judge:
            if not times[0] - tol <= end <= times[-1] + tol:
                continue                # outside the frames: refused as such later
            nearest = float(times[np.argmin(np.abs(times - end))])
            if abs(nearest - end) > tol:
                raise InputError(f"--judge {judge[0]:g}:{judge[1]:g} s: {end:g} s falls "
                                 f"between the file's frames (the nearest at "
                                 f"{time_text(nearest)} s): give a window on its frames")


def _judged_window(traj, judge: tuple[float, float], span: tuple[float, float] | None,
                   extent: tuple[float, float], bin_width: float, kwargs: dict
                   ) -> JudgedWindow:
    """The judged window of :func:`check_stationarity` against the long run and the window
    before it; ``extent`` is the span in use, ``kwargs`` the residence times' basis."""
    j0, j1 = judge
    length = j1 - j0
    tol = traj.time_tolerance
    if j0 < extent[0] - tol or j1 > extent[1] + tol:
        raise InputError(f"--judge {j0:g}:{j1:g} s lies outside the span "
                         f"{extent[0]:g}:{extent[1]:g} s: judge a window inside it, or widen "
                         "--span")
    direction = net_flow_direction(traj, judge)
    long_run = long_run_baseline(traj, judge, span=span, bin_width=bin_width,
                                 direction=direction, **kwargs)
    persistence = None
    if j0 - length >= extent[0] - tol:
        persistence = window_difference(
            traj, (j0 - length, j0), (j0, j1), bin_width=bin_width, md_order=2.0,
            window_length=length, direction=direction, **kwargs)
    return JudgedWindow((j0, j1), direction, long_run, persistence)
