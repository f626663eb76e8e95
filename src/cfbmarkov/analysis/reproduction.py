"""The numbers of the reproduction report, recomputed from the trajectory files of a case.

For each finished case of a run folder the report needs, over the case's predict window,
the residence times and RTD of the CFD-DEM and of each estimator's prediction (Fig. 8-9),
their mixing curves (Fig. 11), the CFD-DEM's radial solids profiles (plausibility), and
from the chosen Markov model the batch-injection maps (Fig. 4-7) and the mean vertical
velocity implied by its transition matrix (Fig. 3). :func:`measure_case` computes them;
:mod:`cfbmarkov.report` only draws and writes.

References
----------
docs/definitions.md, sections "riser", "states and transitions", "residence time" and
"mixing".
"""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from cfbmarkov.analysis.development import development
from cfbmarkov.analysis.mixing import mixing_curve_of
from cfbmarkov.errors import InputError
from cfbmarkov.observed.residence import (WHOLE_FRAMES, flux_residence_time,
                                          net_flow_direction, residence_times, rtd_histogram)


@contextlib.contextmanager
def reading_errors(path: str | os.PathLike):
    """Context manager: turn low-level read failures of ``path`` into one InputError line.

    HDF5 errors (OSError) and missing datasets (KeyError) become ``InputError("PATH:
    cannot be used (...)")``; InputErrors pass unchanged.

    Parameters
    ----------
    path : str or os.PathLike
        The file being read, named in the error.

    Returns
    -------
    contextlib.AbstractContextManager
        A context manager that yields None.

    Raises
    ------
    InputError
        When the body raises OSError or KeyError (or an InputError, passed on).
    """
    try:
        yield
    except InputError:
        raise
    except (OSError, KeyError) as exc:
        raise InputError(f"{path}: cannot be used ({' '.join(f'{type(exc).__name__}: {exc}'.split())})"
                         ) from None


@dataclass
class RunMeasures:
    """Residence times, RTD and mixing curve of one trajectory file over a window.

    Attributes
    ----------
    rt : cfbmarkov.observed.residence.ResidenceTimes
        Residence-time samples, s.
    prob : numpy.ndarray, shape (B,)
        RTD as probability per bin (bins of :attr:`CaseMeasures.edges`).
    mix_t : numpy.ndarray, shape (T,)
        Frame times of the mixing curve, s.
    mix_f : numpy.ndarray, shape (T,)
        Fraction of all particles in the left tracer group and at x < W/2 (-).
    """

    rt: Any
    prob: np.ndarray
    mix_t: np.ndarray
    mix_f: np.ndarray


@dataclass
class CaseMeasures:
    """The recomputed numbers of one finished case.

    Attributes
    ----------
    window : (float, float)
        The predict window, s.
    bin_width : float
        RTD bin width, s.
    edges : numpy.ndarray, shape (B + 1,)
        RTD bin edges, s.
    reference : RunMeasures
        The CFD-DEM.
    models : dict of str to RunMeasures
        Each estimator's prediction.
    band_positions : numpy.ndarray, shape (K,)
        Bin centres across the riser, x (m).
    solids_fraction : numpy.ndarray, shape (K,)
        Time-averaged solids volume fraction per bin (-).
    solids_velocity : numpy.ndarray, shape (K,)
        Mean vertical solids velocity per bin, m/s (NaN where no particle passed).
    model_name : str or None
        Estimator of the model used for Fig. 3-7.
    model : MarkovModel or None
        That model.
    development : dict or None
        The solids' mean vertical velocity before the fitting window, over it and over the
        predict window (:func:`cfbmarkov.analysis.development.development`).
    flux_rt_mean : float
        The CFD-DEM's E(RT) over the predict window from its net solids flux, in the net
        flow's direction (:func:`cfbmarkov.observed.residence.flux_residence_time`: free of
        the window's censoring of long residences), s; NaN where not computed.
    """

    window: tuple[float, float]
    bin_width: float
    edges: np.ndarray
    reference: RunMeasures
    models: dict[str, RunMeasures]
    band_positions: np.ndarray
    solids_fraction: np.ndarray
    solids_velocity: np.ndarray
    model_name: str | None = None
    model: Any = None
    development: dict | None = None
    flux_rt_mean: float = math.nan


def measure_run(traj, window: tuple[float, float], bin_width: float, *,
                use_events: bool = True, lag_frames: int = 1, direction: str = "up") -> RunMeasures:
    """Residence times, RTD and mixing curve of an open trajectory file.

    Parameters
    ----------
    traj : cfbmarkov.trajectories.Trajectories
    window : (float, float)
        (start, stop), s.
    bin_width : float
        RTD bin width, s.
    use_events, lag_frames, direction : optional
        The residence times' basis and direction, as in
        :func:`cfbmarkov.observed.residence.residence_times`.

    Returns
    -------
    RunMeasures

    Raises
    ------
    InputError
        When the window is empty or leaves the file's frames, or the file's pass events
        are damaged (:func:`cfbmarkov.observed.residence.residence_times`).
    """
    rt = residence_times(traj, window, use_events=use_events, lag_frames=lag_frames,
                         direction=direction)
    _, prob = rtd_histogram(rt.samples, bin_width, window_length=window[1] - window[0])
    t, f = mixing_curve_of(traj, window)
    return RunMeasures(rt, prob, t, f)


def solids_profile(traj, window: tuple[float, float], config
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radial (across the riser) solids profiles over a window, two bins per gas cell.

    Parameters
    ----------
    traj : cfbmarkov.trajectories.Trajectories
        An open CFD-DEM file.
    window : (float, float)
        (start, stop), s.
    config : cfbmarkov.config.CaseConfig
        The case (gas cells across, particle diameter d in m).

    Returns
    -------
    centres : numpy.ndarray, shape (K,)
        Bin centres x, m.
    fraction : numpy.ndarray, shape (K,)
        Time-averaged solids volume fraction, pseudo-2D: N pi d^3 / 6 over H dx d (-).
    velocity : numpy.ndarray, shape (K,)
        Mean vertical solids velocity, m/s; NaN where no particle passed or the file has
        no velocities.

    Raises
    ------
    InputError
        When the window is empty or leaves the file's frames.

    References
    ----------
    docs/definitions.md, section "riser" (the pseudo-2D solids fraction).
    """
    bins = 2 * int(config.numerics.cfd_cells[0])
    edges = np.linspace(0.0, traj.width, bins + 1)
    counts = np.zeros(bins)
    momentum = np.zeros(bins)
    frames = traj.window(*window)
    n_frames = 0
    for k0 in range(frames.start, frames.stop, 32):
        block = slice(k0, min(k0 + 32, frames.stop))
        positions = traj.positions(block)
        x = positions[..., 0].ravel()
        counts += np.histogram(x, bins=edges)[0]
        velocities = traj.velocities(block)
        if velocities is not None:
            momentum += np.histogram(x, bins=edges, weights=velocities[..., 1].ravel())[0]
        n_frames += positions.shape[0]
    d = float(config.particles.diameter)
    fraction = counts / max(n_frames, 1) * (math.pi * d * d / 6.0) / (traj.height * np.diff(edges))
    velocity = np.divide(momentum, counts, out=np.full(bins, np.nan), where=counts > 0)
    if not traj.has_velocity:
        velocity[:] = np.nan
    return 0.5 * (edges[:-1] + edges[1:]), fraction, velocity


def measure_case(reference: Path, predictions: Mapping[str, Path], model: tuple[str, Path],
                 window: tuple[float, float], bin_width: float, config) -> CaseMeasures:
    """The recomputed numbers of one case.

    Parameters
    ----------
    reference : pathlib.Path
        The CFD-DEM trajectory file.
    predictions : mapping of str to pathlib.Path
        Each estimator's prediction file.
    model : (str, pathlib.Path)
        Estimator name and model file of the model drawn in Fig. 3-7.
    window : (float, float)
        The predict window, s.
    bin_width : float
        RTD bin width, s.
    config : cfbmarkov.config.CaseConfig
        The case.

    Returns
    -------
    CaseMeasures

    Raises
    ------
    InputError
        Naming the file that cannot be read (HDF5 error, missing dataset, damaged pass
        events), or when the window leaves a file's frames.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 3-9 and 11.
    """
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.trajectories import Trajectories

    # the basis and direction of the compare summaries (like for like, net downflow):
    # frames at the models' lag on both sides, counted in the direction of the net flow
    lag_frames, lag, first = 1, math.nan, next(iter(predictions.values()), None)
    if first is not None:
        with reading_errors(first), Trajectories(first) as pred:
            lag = pred.frame_interval
    with reading_errors(reference), Trajectories(reference) as ref:
        ratio = lag / ref.frame_interval
        if math.isfinite(ratio) and round(ratio) >= 1 and abs(ratio - round(ratio)) <= WHOLE_FRAMES:
            lag_frames = int(round(ratio))
        direction = net_flow_direction(ref, window)
        measured = measure_run(ref, window, bin_width, use_events=False, lag_frames=lag_frames,
                               direction=direction)
        across, solids, solids_velocity = solids_profile(ref, window, config)
        flow = development(ref, tuple(config.markov.fit_window), window)
        flux_rt = flux_residence_time(ref, window, direction)
    edges, _ = rtd_histogram(np.zeros(0), bin_width, window_length=window[1] - window[0])
    models = {}
    for name, path in predictions.items():
        with reading_errors(path), Trajectories(path) as pred:
            models[name] = measure_run(pred, window, bin_width, direction=direction)
    measures = CaseMeasures(window, bin_width, edges, measured, models, across, solids,
                            solids_velocity)
    measures.model_name = model[0]
    measures.development = flow
    measures.flux_rt_mean = float(flux_rt)
    with reading_errors(model[1]):
        measures.model = MarkovModel.load(model[1])
    return measures


def implied_vertical_velocity(model) -> float:
    """Mean vertical particle velocity implied by a model's transition matrix.

    Parameters
    ----------
    model : cfbmarkov.markov.MarkovModel

    Returns
    -------
    float
        The stationary average of the expected row displacement per lag, passes through
        the periodic boundary included, in m/s.

    References
    ----------
    docs/definitions.md, section "states and transitions";
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 3.
    """
    space = model.state_space
    P = np.asarray(model.transition_matrix)
    row = space.cell_of_state // space.cells_per_row
    shift = (row[None, :] - row[:, None]) + space.rows * (model.up_fraction - model.down_fraction)
    per_state = (P * shift).sum(axis=1)
    return float(model.stationary_distribution @ per_state) * (space.height / space.rows) \
        / model.lag


def paper_map_times(velocity: float, lag: float) -> tuple[list[float], list[float], bool]:
    """Times of the batch-injection maps of the paper's Fig. 4-7, in whole lags.

    Parameters
    ----------
    velocity : float
        Superficial gas velocity U, m/s: the paper shows 0.25, 0.5, 0.75 s below 3.5 m/s,
        else 0.05, 0.10, 0.15 s.
    lag : float
        The model's lag, s.

    Returns
    -------
    wanted : list of float
        The paper's times, s.
    used : list of float
        Each rounded to the nearest whole lag (halves up, at least one lag), s.
    rounded : bool
        Whether any time was changed.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 4-7.
    """
    wanted = [0.25, 0.5, 0.75] if velocity < 3.5 else [0.05, 0.10, 0.15]
    used = [max(1, math.floor(t / lag + 0.5 + 1e-9)) * lag for t in wanted]   # halves up
    rounded = any(abs(a - b) > 1e-9 * max(1.0, b) for a, b in zip(used, wanted))
    return wanted, used, rounded


@dataclass
class BatchInjection:
    """A batch fed evenly over the inlet cells at t = 0 (Eq. 8), at some times.

    Attributes
    ----------
    maps : numpy.ndarray, shape (K, rows, columns)
        Probability per cell (what leaves through the top re-enters at the bottom).
    inside : numpy.ndarray, shape (K, rows, columns)
        The same with what passes up through the top taken out (a periodic riser's: at its
        first pass, first passages only; an open riser's: what leaves).
    mean_heights : list of float
        Mean height of the part still inside at each time, m.
    left_share : float
        Share of the batch that has passed up through the top by the last time (-).
    fallen_share : float or None
        Share of the batch that has passed down through the bottom by the last time (-),
        first passages only (a periodic riser's; None for an open riser).
    """

    maps: np.ndarray
    inside: np.ndarray
    mean_heights: list[float]
    left_share: float
    fallen_share: float | None = None


def batch_injection(model, times) -> BatchInjection:
    """Batch-injection maps of a model (Eq. 5-6, 8) and where the batch is.

    Parameters
    ----------
    model : cfbmarkov.markov.MarkovModel
    times : sequence of float
        Times after injection, whole multiples of the lag, s.

    Returns
    -------
    BatchInjection

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Eqs. 5-6 and 8, Figs. 4-7;
    ``docs/definitions.md`` (States and transitions, Batch injection).
    """
    from cfbmarkov.markov.propagation import inlet_batch

    maps = np.asarray(model.batch_injection_maps(times), dtype=np.float64)
    space = model.state_space
    fallen = None
    if model.open_flow is None:
        # the batch with the passes up through the top taken out (``inside``: what is
        # missing has passed up through the top at least once; not where its residences
        # end, which the lap deficits of maps --outflow follow), and with the passes down
        # through the bottom taken out (what is missing has fallen through it at least once)
        above = model.transition_matrix * (1.0 - model.up_fraction)
        below = model.transition_matrix * (1.0 - model.down_fraction)
        steps = [model.steps_for(t) for t in times]
        s = a = np.asarray(inlet_batch(model), dtype=np.float64)
        kept = {0: a}
        for k in range(1, max(steps) + 1):
            a, s = a @ above, s @ below
            kept[k] = a
        inside = space.cell_maps(np.array([kept[k] for k in steps]))
        fallen = 1.0 - float(s.sum())
    else:
        inside = np.asarray(model.batch_injection_maps(times, outflow=True), dtype=np.float64)
    centres = (np.arange(space.rows) + 0.5) * space.height / space.rows
    heights = [float((m.sum(axis=1) * centres).sum() / max(m.sum(), 1e-300)) for m in inside]
    return BatchInjection(maps, inside, heights, 1.0 - float(inside[-1].sum()), fallen)


def nanmean(values: np.ndarray) -> float:
    """Mean of the finite values.

    Parameters
    ----------
    values : numpy.ndarray
        Any shape; NaN and infinite entries are ignored.

    Returns
    -------
    float
        The mean of the finite entries (NaN when there is none).
    """
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else math.nan


#: the share of the riser's width that each wall layer takes in the wall/core figures
WALL_LAYER = 1.0 / 6.0


def wall_zone_weights(bins: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How much of each of ``bins`` equal bins across the riser lies in the left wall
    layer, the core and the right wall layer (each wall layer the outer sixth of the width).

    A bin cut by a layer's edge counts for the part of its width inside the layer, so the
    layers are a sixth of the width whatever the number of bins (with 8 bins, one bin and a
    third of the next).

    Parameters
    ----------
    bins : int
        Number of equal bins across the riser, at least 1.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray), each shape (bins,)
        The fraction (0 to 1) of each bin's width in the left wall layer, the core and the
        right wall layer; the three sum to 1 for every bin.
    """
    edges = np.linspace(0.0, 1.0, int(bins) + 1)
    low, high = edges[:-1], edges[1:]

    def inside(a: float, b: float) -> np.ndarray:
        return np.clip(np.minimum(high, b) - np.maximum(low, a), 0.0, None) * bins

    return (inside(0.0, WALL_LAYER), inside(WALL_LAYER, 1.0 - WALL_LAYER),
            inside(1.0 - WALL_LAYER, 1.0))


def zone_mean(values: np.ndarray, weights: np.ndarray) -> float:
    """The mean of a binned profile over a zone across the riser.

    Parameters
    ----------
    values : numpy.ndarray, shape (K,)
        The profile's value in each of K equal bins (NaN where a bin has none).
    weights : numpy.ndarray, shape (K,)
        The fraction of each bin's width in the zone (:func:`wall_zone_weights`).

    Returns
    -------
    float
        The mean over the zone, each finite bin by its share of the zone's width; NaN where
        no finite bin lies in it.
    """
    weights = np.where(np.isfinite(values), weights, 0.0)
    total = weights.sum()
    return float(np.sum(np.where(weights > 0, values, 0.0) * weights) / total) if total > 0 \
        else math.nan


def wall_core_contrast(fraction: np.ndarray, velocity: np.ndarray
                       ) -> tuple[float, float, float, float]:
    """Wall and core averages of radial solids profiles (the core-annulus structure).

    Parameters
    ----------
    fraction, velocity : numpy.ndarray, shape (K,)
        Solids volume fraction (-) and mean vertical solids velocity (m/s) across the riser
        in K equal bins (:func:`solids_profile`).

    Returns
    -------
    (float, float, float, float)
        Solids fraction at the walls and in the core, velocity (m/s) at the walls and in
        the core. The walls are the outer sixth of the width on each side
        (:func:`wall_zone_weights`: a bin cut by a layer's edge counts for its part inside),
        the core the middle two thirds; each is the mean of the bins' values over its
        width, and a bin with no particles (velocity NaN) is left out of the velocity's.
    """
    left, core, right = wall_zone_weights(len(fraction))
    walls = left + right
    return (zone_mean(np.asarray(fraction, float), walls),
            zone_mean(np.asarray(fraction, float), core),
            zone_mean(np.asarray(velocity, float), walls),
            zone_mean(np.asarray(velocity, float), core))


@dataclass
class OperatingPoint:
    """The operating conditions of a case, as set and as the CFD-DEM ran them.

    Attributes
    ----------
    velocity : float
        Superficial gas velocity U, m/s.
    particles : int
        Number of particles.
    diameter, density : float
        Particle diameter d (m) and density (kg/m^3).
    hold_up : float
        Solids volume fraction of the riser as set: N pi d^3 / 6 over W H d (pseudo-2D,
        one particle diameter thick), -.
    measured_hold_up : float
        The CFD-DEM's solids volume fraction averaged over the window and across the riser, -.
    solids_flux : float
        Net vertical solids mass flux G_s of the CFD-DEM, averaged over the window and the
        cross-section, kg/(m^2 s) (positive upward; NaN without velocities).
    """

    velocity: float
    particles: int
    diameter: float
    density: float
    hold_up: float
    measured_hold_up: float
    solids_flux: float


def operating_point(config, measures: CaseMeasures) -> OperatingPoint:
    """The operating conditions of a case from its configuration and its solids profiles.

    Parameters
    ----------
    config : cfbmarkov.config.CaseConfig
        The case.
    measures : CaseMeasures
        Its recomputed numbers (:func:`measure_case`; the profiles of :func:`solids_profile`).

    Returns
    -------
    OperatingPoint

    Notes
    -----
    Over bins of equal width the profile's fraction times velocity is the time-averaged
    solids volume flux of the bin (the velocity is the mean over the particles that passed),
    so G_s = rho_p mean_k(eps_k v_k).

    References
    ----------
    docs/definitions.md, section "riser" (the pseudo-2D solids fraction).
    """
    p, r = config.particles, config.riser
    volume = math.pi * p.diameter ** 3 / 6.0
    hold_up = p.number * volume / (r.width * r.height * p.diameter)
    fraction = np.asarray(measures.solids_fraction, dtype=np.float64)
    velocity = np.asarray(measures.solids_velocity, dtype=np.float64)
    measured = float(fraction.mean()) if fraction.size else math.nan
    flux_per_bin = np.where(fraction > 0, fraction * velocity, 0.0)
    flux = (float(p.density * flux_per_bin.mean())
            if fraction.size and np.isfinite(flux_per_bin).all() else math.nan)
    return OperatingPoint(float(config.gas.superficial_velocity), int(p.number),
                          float(p.diameter), float(p.density), float(hold_up), measured, flux)


__all__ = ["BatchInjection", "CaseMeasures", "OperatingPoint", "RunMeasures", "batch_injection",
           "implied_vertical_velocity", "measure_case", "measure_run", "nanmean",
           "operating_point",
           "paper_map_times", "reading_errors", "solids_profile", "wall_core_contrast",
           "wall_zone_weights", "zone_mean"]
