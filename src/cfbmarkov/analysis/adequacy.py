"""Whether a model's fitting sample can carry it: the verdict ``fit`` stores in the model
(``docs/definitions.md``, Sample adequacy).

A chain fitted on a window extrapolates the flow it saw to every later time. Three checks
tell from the window alone when that flow may not be the run's:

- **parts disagree**: the window's halves (and its quarters, where each holds at least
  :data:`MIN_PART_RESIDENCES` residences) are fitted with the same estimator and states,
  and their exact E(RT) compared: the spread (largest - smallest over the window model's
  E(RT)) beyond the limit (the relative width of the model's E(RT) interval where one is
  given, else :data:`DEFAULT_TOLERANCE`; quarters, twice as noisy in variance, get sqrt(2)
  times the limit) says the flow changed within the window;
- **the net flow turns**: the net solids flow direction
  (:func:`~cfbmarkov.observed.residence.net_flow_direction`) differs between parts;
- **long residences**: the model's exact RTD puts more than :data:`TAIL_LIMIT` of its mass
  beyond the window's length, residences the window cannot contain;
- **the window's throughput**: a periodic riser's model's E(RT) lies further than
  :data:`THROUGHPUT_LIMIT` from the window's own, its particle-time over its net passes (Little's law,
  :func:`~cfbmarkov.observed.residence.flux_residence_time`, which the window's length does
  not censor): the chain's stationary flow is not the flow it was fitted on (the paper's
  estimator weighting every frame's matrix alike whatever the cells' occupancy, or a flow
  still changing in the window); not formed from fewer than :data:`MIN_THROUGHPUT_PASSES`
  net passes;
- and halves with fewer than :data:`MIN_PART_RESIDENCES` residences leave E(RT)
  unjudged, itself a warning (in a pooled fit, where the halves pooled over the runs hold
  that few: a run whose own halves are too short is judged across the runs).

Every E(RT) is counted in the judged model's direction (its ``flow_direction``, the
direction of its fitting window's net solids flow; ``docs/definitions.md``, Net downflow).

A model fitted on several runs (a pooled fit) has these checks per run, each run's limit
sqrt(N) times the pooled interval's (a run holds 1/N of the data), and two across the runs:
the first halves of all the windows pooled against the second halves pooled (the flow
changing in step in every run), and each run's own model against the pooled one, the runs
further than the cross-run limit times sqrt(N - 1) named (:func:`_pooled_checks`).

The cross-run limit does not grow with the spread it tests. The pooled interval's flow
term is measured between the blocks of all the runs, so runs that disagree widen it; the
cross-run check takes instead the within-run part of the interval, the stratified block
bootstrap's (each resample draws every run's blocks from that run) with the flow's
variability measured within each run (:func:`within_run_limit`), at least
:data:`MIN_RUNS_LIMIT` and never more than :data:`DEFAULT_TOLERANCE` (the limit without an
interval). Two runs whose models differ by far more than each run's own uncertainty warn,
with or without an interval.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.adequacy import Adequacy
from cfbmarkov.markov.discrete import DiscreteTrajectories, discretize
from cfbmarkov.markov.estimate import estimator_from_name
from cfbmarkov.markov.model_summary import CLOSED_CLASSES_ADVICE
from cfbmarkov.observed.residence import net_flow_direction, residence_flux, residence_times
from cfbmarkov.trajectories import opened

#: relative spread of the halves' E(RT) beyond which they disagree, without an interval
DEFAULT_TOLERANCE = 0.3
#: the least cross-run limit: runs whose E(RT) lie within this fraction of the pooled one
#: are not named (runs of one flow from different seeds scatter by about 1 % on generated
#: risers, slightly more than the blocks within one run show)
MIN_RUNS_LIMIT = 0.05
#: residences a part must hold for its E(RT) to be compared
MIN_PART_RESIDENCES = 30
#: share of the model's RTD beyond the window length that is warned about
TAIL_LIMIT = 0.1
#: width of the model's E(RT) interval, relative to E(RT), beyond which the window cannot
#: pin the chain down (and the parts' check, whose limit that width is, cannot fail): the
#: paper-scale coverage study's median widths were 0.36-1.17 for windows of 0.5-5 s
WIDE_INTERVAL = 1.5
#: relative distance of the model's E(RT) from its window's own (from the net flux) beyond
#: which the chain does not carry the window's flow. Both are read from the same data: on
#: stationary generated risers both estimators agree within 2 %; on paper-scale CFD-DEM
#: windows of 2 and 5 s the maximum-likelihood chain was within 10 % in 36 of 48, the
#: paper's estimator in 5 of 24 at 3-4 m/s (docs/definitions.md, Sample adequacy)
THROUGHPUT_LIMIT = 0.1

_ADVICE = ("fit on a longer window or pool several runs (fit A.h5 B.h5 ...); `cfbmarkov "
           "stationarity RUN --sample-length` tells how long a window must be")
#: the part of the advice that a run with absences cannot follow (`stationarity` refuses it)
_STATIONARITY_ADVICE = ("; `cfbmarkov stationarity RUN --sample-length` tells how long a "
                        "window must be")
#: the aside on the sample length beside the flow term's length (left out, as
#: :data:`_STATIONARITY_ADVICE` is, for a run that `stationarity` cannot read)
_SAMPLE_LENGTH_ASIDE = (" (`cfbmarkov stationarity RUN --sample-length` tells from which "
                        "length the fitted E(RT) and SD(RT) settle, which can be shorter)")


#: the advice of a pooled fit's lines: it pools runs already
_POOLED_ADVICE = ("fit on longer windows or pool more runs; `cfbmarkov stationarity RUN "
                  "--sample-length` tells how long a window must be")


def _rt_mean(model, direction: str | None = None) -> float:
    """E(RT) of ``model``'s exact RTD counted in ``direction`` (default its own flow
    direction; the parts of a window are counted in the judged model's), NaN where none."""
    try:
        return float(model.rtd(direction=direction).mean)
    except (CfbmarkovError, ZeroDivisionError, FloatingPointError):
        return math.nan


def _part_rt_mean(model, direction: str | None = None) -> float:
    """E(RT) of the model of a part of the window: from its chain's lap drift where that is
    exact (residences in one closed class whose laps advance in ``direction``;
    :func:`~cfbmarkov.markov.model_rtd.drift_rt_mean`, one sparse LU), the exact RTD's
    E(RT) without its propagation. Otherwise from its exact RTD on the fewest lap deficits
    (:data:`~cfbmarkov.markov.first_passage.MIN_DEFICIT_LEVELS`): a part whose net flow
    runs the other way has residences that rarely end, and following them deeper would
    cost minutes for a figure that only says the part differs; NaN where none ends."""
    from cfbmarkov.markov.first_passage import MIN_DEFICIT_LEVELS
    from cfbmarkov.markov.model_rtd import drift_rt_mean, rtd_at_depth

    try:
        value = drift_rt_mean(model, direction)
    except (CfbmarkovError, ValueError, RuntimeError):
        value = None
    if value is not None:
        return float(value)
    try:
        return float(rtd_at_depth(model, direction, MIN_DEFICIT_LEVELS).mean)
    except (CfbmarkovError, ZeroDivisionError, FloatingPointError):
        return math.nan


#: the fewest net passes from which a window's throughput E(RT) is formed and checked
MIN_THROUGHPUT_PASSES = 10


def window_rt_mean(runs, windows, direction: str) -> float:
    """The fitting windows' own E(RT) from their net solids flux: their particle-time over
    their net passes in ``direction``, several runs' summed (Little's law,
    :func:`~cfbmarkov.observed.residence.residence_flux`, in a file with absent particles
    over the frame steps a particle is tracked through; s). NaN for an open riser (no flux
    to read), where the net passes do not run in ``direction``, and where they are fewer
    than :data:`MIN_THROUGHPUT_PASSES` (the partial laps at the window's edges would
    dominate the particle-time)."""
    return window_throughput(runs, windows, direction)[0]


#: standard deviations of the window's partial laps within which the model's E(RT) and the
#: window's throughput E(RT) are not told apart (:func:`throughput_limit`)
THROUGHPUT_EDGE_SDS = 3.0


def window_throughput(runs, windows, direction: str, model=None) -> tuple[float, float]:
    """:func:`window_rt_mean` and the relative standard deviation of its net passes that the
    window's cut through the particles' laps alone gives, where the chain, fitted on the
    same transitions, counts no cut.

    A window's net passes differ from the chain's flux times its particle-time by what each
    tracked stretch of a particle still had ahead of it where the window cut it: g(s_end) -
    g(s_start), g the chain's pass potential (the solution of (I - P) g = r - phi, r_i the
    expected net passes of a lag from state i, phi = pi r: the passes a particle in state i
    makes beyond the mean rate, Kemeny & Snell's fundamental matrix applied to a reward;
    W. J. Stewart, Introduction to the Numerical Solution of Markov Chains, 1994, Ch. 1).
    With the two ends far apart, each stretch adds 2 Var_pi(g) to the variance of the net
    passes: a particle's heights taken uniform in a riser it climbs alike everywhere give
    Var(g) = 1/12 lap^2, while a core rising beside falling walls spreads g further. Without
    ``model`` (or for a reducible chain) that 1/12 is taken. The stretches: the particles
    tracked in the window (each presence run in a file with absent particles; several
    runs' summed).

    Parameters
    ----------
    runs : sequence of str, os.PathLike or Trajectories
    windows : sequence of (float, float)
        Each run's window (s).
    direction : {"up", "down"}
        The net flow's direction.
    model : MarkovModel, optional
        The chain fitted on the windows (its pass potential).

    Returns
    -------
    (float, float)
        E(RT) (s) and the relative SD (fraction); NaN, NaN where :func:`window_rt_mean` is
        NaN.
    """
    particle_time, passes, stretches = 0.0, 0, 0
    for run, (a, b) in zip(runs, windows):
        with opened(run) as traj:
            try:
                part = residence_flux(traj, (a, b), direction)
            except InputError:
                return math.nan, math.nan
            if traj.has_absences:     # each presence run is cut at both its ends
                stretches += _presence_runs(traj, traj.window(a, b))
            else:
                stretches += int(traj.n_particles)
        particle_time += part[0]
        passes += part[1]
    if passes < MIN_THROUGHPUT_PASSES:
        return math.nan, math.nan
    variance = pass_potential_variance(model) if model is not None else math.nan
    if not math.isfinite(variance):
        variance = UNIFORM_POTENTIAL_VARIANCE
    return particle_time / passes, math.sqrt(2.0 * variance * stretches) / passes


def _presence_runs(traj, frames: slice, block: int = 256) -> int:
    """The runs of presence of the particles over ``frames``, read ``block`` frames at a
    time (a presence mask of many frames and particles is not read whole)."""
    runs, last = 0, None
    for start in range(frames.start, frames.stop, block):
        present = np.asarray(traj.present(slice(start, min(start + block, frames.stop))),
                             dtype=bool)
        before = np.zeros(present.shape[1], bool) if last is None else last
        runs += int((present[0] & ~before).sum() + (present[1:] & ~present[:-1]).sum())
        last = present[-1]
    return runs


#: Var(g) of the pass potential, in laps^2, of heights uniform in a riser climbed alike
#: everywhere (g = -h / H + const): what :func:`window_throughput` takes without a chain
UNIFORM_POTENTIAL_VARIANCE = 1.0 / 12.0


def pass_potential_variance(model) -> float:
    """Var_pi(g) of a periodic riser's chain's pass potential g, laps^2: (I - P) g = r - phi
    with r_i = sum_j P_ij (up_ij - down_ij), the expected net passes up of a lag from state
    i, and phi = pi r (:func:`window_throughput`), on the chain's one closed class of two or
    more states (states outside it, transient or single traps, hold no probability in the
    long run and make no passes). Solved with g fixed at 0 in one state of the class (the
    minor of I - P is regular on a closed communicating class; Var does not depend on the
    constant), and checked against its equations.

    Returns
    -------
    float
        NaN for an open riser, a chain of several closed classes (or none), or a system
        that does not solve.
    """
    import warnings

    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from cfbmarkov.markov.connectivity import closed_classes

    if getattr(model, "open_flow", None) is not None:
        return math.nan
    p = sp.csr_array(model.transition_matrix, dtype=np.float64)
    classes = closed_classes(p, min_size=2)
    if len(classes) != 1:
        return math.nan
    keep = np.sort(classes[0])
    p = p[keep][:, keep]
    net = sp.csr_array(np.asarray(model.up_fraction) - np.asarray(model.down_fraction)
                       )[keep][:, keep]
    reward = np.asarray(p.multiply(net).sum(axis=1)).ravel()
    a = sp.identity(keep.size, format="csr") - p
    try:
        # the class's own stationary vector: the left null vector of I - P on it
        pi = np.zeros(keep.size)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rest = spla.spsolve(sp.csc_array(a[1:, 1:].T), -np.asarray(a[0, 1:].todense()
                                                                        ).ravel())
            pi[0], pi[1:] = 1.0, rest
            pi /= pi.sum()
            centred = reward - float(pi @ reward)
            g = np.zeros(keep.size)
            g[1:] = spla.spsolve(sp.csc_array(a[1:, 1:]), centred[1:])
    except (ValueError, RuntimeError, np.linalg.LinAlgError):
        return math.nan
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(pi)) and np.all(pi >= -1e-12)):
        return math.nan
    scale = max(float(np.abs(centred).max()), 1e-300)
    if np.abs(a @ g - centred).max() > 1e-6 * scale * max(1.0, float(np.abs(g).max())):
        return math.nan          # the minor was singular: g solves no equation
    mean = float(pi @ g)
    return float(pi @ (g - mean) ** 2)


def throughput_limit(edge_sd: float) -> float:
    """The relative distance between the model's E(RT) and the window's throughput E(RT)
    beyond which the throughput line warns: :data:`THROUGHPUT_LIMIT`, or
    :data:`THROUGHPUT_EDGE_SDS` times the relative SD the window's cut gives its net passes
    (:func:`window_throughput`) where that is larger (a short window of few particles)."""
    if not math.isfinite(edge_sd):
        return THROUGHPUT_LIMIT
    return max(THROUGHPUT_LIMIT, THROUGHPUT_EDGE_SDS * edge_sd)


def _percents(value: float, limit: float) -> tuple[str, str]:
    """``value`` and ``limit`` (fractions, ``value`` beyond ``limit``) as percents with the
    fewest decimals (0 to 2) that print them apart: "6.7" and "6.6", never "7" and "7"."""
    for decimals in (0, 1, 2):
        shown = f"{100 * value:.{decimals}f}", f"{100 * limit:.{decimals}f}"
        if shown[0] != shown[1]:
            break
    return shown


def _throughput_line(model, rt_mean: float, window_mean: float,
                     limit: float = THROUGHPUT_LIMIT, edge_sd: float = math.nan
                     ) -> str | None:
    """The warning where the model's E(RT) lies further than ``limit`` (widened by
    :func:`throughput_limit` for the window's cut, ``edge_sd``) from the window's own from
    its net flux (None where it does not, or either is not finite)."""
    if not (math.isfinite(rt_mean) and math.isfinite(window_mean) and window_mean > 0):
        return None
    gap = rt_mean / window_mean - 1.0
    widened = throughput_limit(edge_sd)
    if widened > limit:
        limit = widened
    if abs(gap) <= limit:
        return None
    occupancy = ("the window's occupancy is not the chain's stationary one: a flow still "
                 "changing in the window, or loops slower than the window (particles held "
                 "in a downflowing wall layer longer than the window shows)")
    why = ("the paper's estimator averages every frame's matrix alike whatever the cells' "
           "occupancy (--estimator mle keeps the window's transitions and its throughput; "
           f"where it shows the same gap, {occupancy})"
           if model.estimator == "paper" else occupancy)
    side = "above" if gap > 0 else "below"
    gap_text, limit_text = _percents(abs(gap), limit)
    cut = (f", {THROUGHPUT_EDGE_SDS:g} times the {100 * edge_sd:.2g} % that the window's "
           "cut through the particles' laps gives its net passes"
           if limit > THROUGHPUT_LIMIT else "")
    head = (f"the model's E(RT) {rt_mean:.3g} s lies {gap_text} % {side} its fitting "
            f"window's own throughput E(RT), {window_mean:.3g} s (the window's particle-time "
            f"over its net passes; limit {limit_text} %{cut})")
    classes = len(model.closed_classes)
    if classes > 1:
        # a reducible chain: its classes weighted by their net entry flux, while the
        # throughput counts every particle's time, in classes of no net flow too
        reason = (f"; {why}" if model.estimator == "paper"
                  else "")
        return (f"{head}: the chain is reducible ({classes} closed classes: particles in "
                "some cells never reach others, as none did in the window), and its E(RT) "
                "weights the classes by their net entry flux while the throughput counts "
                "every particle's time, in classes whose net flow runs the other way (left "
                "out of the E(RT)) too, so the two need not "
                f"agree{reason}; {CLOSED_CLASSES_ADVICE}")
    return (f"{head}: the chain does not carry the flow it was fitted on; {why}. The "
            f"window's own flow may itself lie far from the run's long run: {_ADVICE}")


def _split(window: tuple[float, float], n: int) -> list[tuple[float, float]]:
    a, b = window
    edges = np.round(np.linspace(a, b, n + 1), 9)
    return [(float(edges[k]), float(edges[k + 1])) for k in range(n)]


def _spread(values: Sequence[float], reference: float) -> float:
    finite = [v for v in values if math.isfinite(v)]
    if len(finite) < 2 or not reference > 0:
        return math.nan
    return (max(finite) - min(finite)) / reference


def _parts_of(traj, discrete: DiscreteTrajectories, window, model, fitter):
    """Parts of one run's window: halves, or quarters where each holds enough residences;
    (parts as (start, stop, E(RT), direction), fewest residences of a half)."""
    lag_frames = int(discrete.lag_frames)
    counts, directions = {}, {}
    for n in (2, 4):
        for part in _split(window, n):
            try:
                d = net_flow_direction(traj, part)
                count = residence_times(traj, part, use_events=False,
                                        lag_frames=lag_frames, direction=d,
                                        split_at_absences=True,
                                        face_band=traj.height / discrete.state_space.rows
                                        ).count
            except InputError:      # a part of a window a lag or two long holds no frame
                d, count = model.flow_direction, 0
            directions[part], counts[part] = d, count
    halves, quarters = _split(window, 2), _split(window, 4)
    use = quarters if min(counts[q] for q in quarters) >= MIN_PART_RESIDENCES else halves
    parts = []
    for a, b in use:
        try:
            mean = _part_rt_mean(fitter.fit(discrete.block(a, b)), model.flow_direction)
        except CfbmarkovError:
            mean = math.nan
        parts.append((a, b, mean, directions[(a, b)]))
    return parts, min(counts[h] for h in halves)


def _turn_line(path, parts) -> str | None:
    directions = {d for _, _, _, d in parts}
    if len(directions) < 2:
        return None
    text = ", ".join(f"{d} in {a:g}-{b:g} s" for a, b, _, d in parts)
    return (f"the net solids flow turns inside the fitting window of {path} ({text}): a model "
            "fitted across it mixes two flows; fit on a window of one direction or a longer "
            "one (`cfbmarkov stationarity RUN` gives each window's direction)")


def within_run_limit(model, uncertainty, rt_mean: float,
                     tolerance: float = DEFAULT_TOLERANCE) -> float:
    """The relative width of a pooled model's E(RT) interval with its flow term measured
    within the runs, at most ``tolerance``: the limit of a pooled fit's cross-run check
    (the module docstring).

    The interval's half-widths are the stratified block bootstrap's and the flow's
    standard error times its quantile added in quadrature
    (:func:`~cfbmarkov.analysis.bootstrap.interval_bounds`: Student's t at (1 + level) / 2
    with the flow term's degrees of freedom, :func:`~cfbmarkov.analysis.bootstrap.flow_quantile`).
    The stored flow term (``flow_sd``, measured between the blocks of all
    the runs, so widened by their disagreement) is taken out of each half-width in
    quadrature, and the flow's variability within the runs
    (:func:`~cfbmarkov.analysis.bootstrap.flow_variability` with ``within_runs``, over
    sqrt(runs) as the interval's) put in its place.

    Parameters
    ----------
    model : MarkovModel
        The pooled model (its fitting windows are re-read for the within-run term).
    uncertainty : ModelUncertainty or None
        The model's interval (None: ``tolerance``).
    rt_mean : float
        The model's exact E(RT) (s).
    tolerance : float, optional
        The most the limit may be (default :data:`DEFAULT_TOLERANCE`).

    Returns
    -------
    float
        The limit, a fraction of E(RT), between :data:`MIN_RUNS_LIMIT` and ``tolerance``.
    """
    if uncertainty is None or not rt_mean > 0:
        return tolerance
    from cfbmarkov.analysis.bootstrap import fitting_runs, flow_quantile, flow_variability

    lo, hi = (float(v) for v in uncertainty.rt_mean_interval)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return tolerance
    level = float(uncertainty.level)
    pooled = (0.0 if uncertainty.flow_sd is None else
              flow_quantile(level, uncertainty.flow_degrees_of_freedom)
              * float(uncertainty.flow_sd[0]) * rt_mean)
    try:
        runs = fitting_runs(model)
        length = float(np.mean([b - a for _, (a, b) in runs]))
        relative = flow_variability(model, length, within_runs=True)
    except CfbmarkovError:
        relative, runs = None, [None]
    within = (0.0 if relative is None else flow_quantile(level, relative.degrees_of_freedom)
              * relative.mean / math.sqrt(len(runs)) * rt_mean)
    down = math.sqrt(max((rt_mean - lo) ** 2 - pooled ** 2, 0.0) + within ** 2)
    up = math.sqrt(max((hi - rt_mean) ** 2 - pooled ** 2, 0.0) + within ** 2)
    return min(max((down + up) / rt_mean, MIN_RUNS_LIMIT), tolerance)


def assess_adequacy(model, runs: Sequence, windows: Sequence[tuple[float, float]], *,
                    discrete: Sequence[DiscreteTrajectories] | None = None,
                    interval: tuple[float, float] | None = None,
                    tolerance: float = DEFAULT_TOLERANCE, uncertainty=None) -> Adequacy:
    """The verdict on a model's fitting sample (the checks of the module docstring).

    Parameters
    ----------
    model : MarkovModel
        The model fitted on the windows (its state space, lag, estimator and
        ``connected`` are used for the parts).
    runs : sequence of str, os.PathLike or Trajectories
        The trajectory file(s) it was fitted on.
    windows : sequence of (float, float)
        The fitting window (s) of each run, in the order of ``runs``.
    discrete : sequence of DiscreteTrajectories, optional
        The windows already discretised in the model's state space (one per run); read
        from the files where not given.
    interval : (float, float), optional
        The model's E(RT) interval (s); its width over E(RT) is then the limit of the
        parts' spread instead of ``tolerance``.
    tolerance : float, optional
        The relative spread of the halves' E(RT) beyond which they disagree, without an
        interval (default :data:`DEFAULT_TOLERANCE`).
    uncertainty : ModelUncertainty, optional
        The model's interval; a pooled fit's cross-run check takes its within-run part
        (:func:`within_run_limit`), else ``tolerance``. ``interval`` defaults to its
        E(RT) interval.

    Returns
    -------
    Adequacy
        The warnings (empty: none) and the numbers behind them.

    Raises
    ------
    InputError
        If a file cannot be read or a window lies outside it.
    """
    fitter = estimator_from_name(model.estimator, model.state_space, model.lag,
                                 connected=model.connected)
    rt_mean = _rt_mean(model)
    if interval is None and uncertainty is not None:
        interval = uncertainty.rt_mean_interval
    limit, limit_source = tolerance, ", the default tolerance"
    level = float(uncertainty.level) if uncertainty is not None else 0.9
    from_interval = False
    sampling = math.nan
    if interval is not None and rt_mean > 0 and all(map(math.isfinite, interval)):
        limit = (float(interval[1]) - float(interval[0])) / rt_mean
        sampling = _sampling_width(interval, uncertainty, rt_mean, len(runs))
        from_interval = True
        limit_source = (": the range 95 % of {k} parts stay within where they scatter as "
                        "the window's sampling says (the model's interval without the flow's "
                        f"variability, which is what the parts test), kept within "
                        f"{100 * MIN_PARTS_LIMIT:g}-{100 * MAX_PARTS_LIMIT:g} %")
    lines: list[str] = []
    applied = math.nan
    if limit > WIDE_INTERVAL and interval is not None:
        from cfbmarkov.markov.uncertainty import outward_bounds

        lo_text, hi_text = outward_bounds(float(interval[0]), float(interval[1]), digits=4)
        shown = (f"{lo_text}-{hi_text} s" if float(interval[0]) > 0 else
                 f"up to {hi_text} s (its lower end cut at 0)")
        lines.append(f"the model's {100 * level:g} % E(RT) interval {shown} is "
                     f"{100 * limit:.0f} % of its intrinsic E(RT) "
                     f"{rt_mean:.4g} s wide: the fitting window cannot pin the chain down (the "
                     f"checks of its parts hold them to at most "
                     f"{100 * MAX_PARTS_LIMIT:g} %, not to that width); {_ADVICE}")
    all_parts: list[tuple[float, float, float, str]] = []
    spread = math.nan
    pooled = len(runs) > 1
    data, names, pooled_fewest = [], [], 0
    for k, (run, window) in enumerate(zip(runs, windows)):
        with opened(run) as traj:
            # as the model was fitted: an automatic choice of a space with memory on a
            # window at the file's start takes its first frames as history ("skip")
            d = discrete[k] if discrete is not None else discretize(
                traj, model.state_space, model.lag, window, short_history="skip")
            parts, fewest = _parts_of(traj, d, window, model, fitter)
            name = traj.path
        data.append(d)
        names.append(str(name))
        pooled_fewest += fewest
        all_parts += parts
        turn = _turn_line(name, parts)
        if turn:
            lines.append(turn)
        if fewest < MIN_PART_RESIDENCES:
            # a pooled fit is judged across its runs where one run's halves are too short
            # (the pooled halves' line below, where those too hold too few)
            if not pooled:
                means = [m for _, _, m, _ in parts if math.isfinite(m)]
                part_spread = _spread(means, rt_mean) if len(means) >= 2 else math.nan
                if math.isfinite(part_spread):     # the parts' chains, from transitions
                    spread = (part_spread if not math.isfinite(spread)
                              else max(spread, part_spread))
                # twice the most the parts are held to: halves of few residences scatter
                # by their sampling up to about that on a steady flow
                far = math.isfinite(part_spread) and part_spread > 2 * MAX_PARTS_LIMIT
                seen = ("" if len(means) < 2 else
                        f" (its parts' chains give E(RT) "
                        f"{', '.join(f'{m:.3g}' for m in means)} s"
                        + (f", a spread of {100 * part_spread:.0f} % of the model's "
                           f"{rt_mean:.3g} s, beyond twice the {100 * MAX_PARTS_LIMIT:g} % the "
                           "parts are held to at most: the flow may have changed within the "
                           "window, which its residences are too few to confirm)" if far else
                           ", too few residences to judge the difference)"))
                lines.append(f"a half of the fitting window {window[0]:g}-{window[1]:g} s of "
                             f"{name} holds {fewest} residences (fewer than "
                             f"{MIN_PART_RESIDENCES}): the window is too short to judge its "
                             f"E(RT){seen}; {_ADVICE}")
            continue
        # one run of a pooled fit is N times less data than the interval's: sqrt(N) wider
        part_limit = parts_limit(sampling if from_interval else limit, len(parts), level,
                                 from_interval) * math.sqrt(len(runs))
        applied = part_limit if not math.isfinite(applied) else max(applied, part_limit)
        part_spread = _spread([m for _, _, m, _ in parts], rt_mean)
        spread = part_spread if not math.isfinite(spread) else max(spread, part_spread)
        if math.isfinite(part_spread) and part_spread > part_limit:
            text = ", ".join(f"{m:.3g} s in {a:g}-{b:g} s" for a, b, m, _ in parts)
            kind = "quarters" if len(parts) == 4 else "halves"
            spread_text, limit_text = _percents(part_spread, part_limit)
            lines.append(f"the {kind} of the fitting window of {name} disagree: E(RT) {text}, "
                         f"a spread of {spread_text} % of the model's {rt_mean:.3g} s "
                         f"(limit {limit_text} %{limit_source.format(k=len(parts))}"
                         f"{f', times sqrt({len(runs)}) for one of {len(runs)} runs' if pooled else ''}"
                         f"): the flow changed within the window, and the model may lie far "
                         f"from the flow's long run; {_ADVICE}")
    run_means: tuple[tuple[str, float], ...] = ()
    runs_limit, runs_interval = math.nan, True
    if pooled:
        cross_limit = within_run_limit(model, uncertainty, rt_mean, tolerance)
        runs_limit = cross_limit * math.sqrt(len(runs) - 1)
        runs_interval = from_interval and cross_limit < tolerance
        run_means, pooled_lines, pooled_spread = _pooled_checks(
            fitter, data, names, windows, rt_mean,
            parts_limit(sampling if from_interval else limit, 2, level, from_interval),
            cross_limit,
            halves=pooled_fewest >= MIN_PART_RESIDENCES, direction=model.flow_direction)
        lines += pooled_lines
        if pooled_fewest < MIN_PART_RESIDENCES:
            lines.append(f"a half of the pooled fitting windows ({len(runs)} runs) holds "
                         f"{pooled_fewest} residences (fewer than {MIN_PART_RESIDENCES}): "
                         f"the windows are too short to judge their E(RT); {_ADVICE}")
        if math.isfinite(pooled_spread):
            spread = pooled_spread if not math.isfinite(spread) else max(spread, pooled_spread)
    window_mean, edge_sd = window_throughput(runs, windows, model.flow_direction, model)
    throughput = _throughput_line(model, rt_mean, window_mean, edge_sd=edge_sd)
    if throughput:
        lines.append(throughput)
    length = min(b - a for a, b in windows)
    if uncertainty is not None and getattr(uncertainty, "flow_sd", 0) is None:
        lines.append(flow_term_line(length, rt_mean, len(runs)))
    tail = _tail_share(model, length)
    if math.isfinite(tail) and tail > TAIL_LIMIT:
        lines.append(f"{100 * tail:.0f} % of the model's residences last longer than the "
                     f"{length:g} s fitting window (E(RT) {rt_mean:.3g} s): the window cannot "
                     f"contain them, so the long residences rest on few observations; "
                     f"{_ADVICE}")
    if pooled:
        lines = [line.replace(_ADVICE, _POOLED_ADVICE) for line in lines]
    if _any_absences(runs):     # stationarity reads no periodic run with absences
        lines = [line.replace(_STATIONARITY_ADVICE, "").replace(_SAMPLE_LENGTH_ASIDE, "")
                 for line in lines]
    on_window = (_pooled_on_window(model, runs, data) if pooled
                 else _on_window(model, runs[0], data[0]))
    return Adequacy(tuple(lines), tuple(all_parts), rt_mean, spread, limit, length, tail,
                    run_means, window_mean, applied if not pooled else math.nan, on_window,
                    runs_limit, runs_interval,
                    throughput_limit(edge_sd) if math.isfinite(window_mean) else math.nan)


def _on_window(model, run, discrete: DiscreteTrajectories) -> tuple[float, ...]:
    """The chain against its own fitting window (:attr:`Adequacy.on_window`): its RTD as a
    window of that length sees it, from where the window's particles are at its first
    frame (:func:`~cfbmarkov.markov.model_rtd.occupancy_at`), against the residences the
    window holds whole, counted at the model's lag in its flow direction, as
    ``--states auto`` judges its candidates; empty for an open riser, fewer than
    :data:`MIN_PART_RESIDENCES` residences, or a chain whose window RTD cannot be had."""
    from cfbmarkov.markov.model_rtd import occupancy_at

    if model.open_flow is not None or discrete.window is None:
        return ()
    a, b = (float(v) for v in discrete.window)
    try:
        with opened(run) as traj:
            seen = residence_times(traj, (a, b), use_events=False,
                                   lag_frames=traj.lag_frames(model.lag),
                                   direction=model.flow_direction,
                                   face_band=traj.height / model.state_space.rows)
            if seen.count < MIN_PART_RESIDENCES:
                return ()
            occupancy = occupancy_at(model, traj, a)
        chain = model.rtd(window=b - a, direction=model.flow_direction, occupancy=occupancy)
    except CfbmarkovError:
        return ()
    return (b - a, float(chain.mean), float(chain.sd), float(seen.mean), float(seen.sd),
            float(seen.count))


def _pooled_on_window(model, runs, data) -> tuple[float, ...]:
    """:func:`_on_window` of a pooled fit: each run's window against the chain, pooled (the
    residences' mean and SD from their counts, means and SDs together; the chain's, as each
    window sees it, weighted by the residences that window holds); empty where the windows
    differ in length or one run gives none."""
    each = [_on_window(model, run, discrete) for run, discrete in zip(runs, data)]
    if not each or any(len(e) != 6 for e in each) or len({e[0] for e in each}) != 1:
        return ()
    counts = np.array([e[5] for e in each], dtype=np.float64)
    weights = counts / counts.sum()

    def pooled(means, sds, samples: bool):
        """The mixture's mean and SD: of distributions (the chain's), or of samples whose
        SDs are with ddof = 1 (the residences', the pooled SD then with ddof = 1 too)."""
        means, sds = np.asarray(means), np.asarray(sds)
        mean = float(weights @ means)
        if samples:
            squares = float(np.sum((counts - 1.0) * sds ** 2 + counts * (means - mean) ** 2))
            return mean, math.sqrt(max(squares / max(counts.sum() - 1.0, 1.0), 0.0))
        second = float(weights @ (sds ** 2 + means ** 2))
        return mean, math.sqrt(max(second - mean * mean, 0.0))

    chain_mean, chain_sd = pooled([e[1] for e in each], [e[2] for e in each], False)
    seen_mean, seen_sd = pooled([e[3] for e in each], [e[4] for e in each], True)
    return (each[0][0], chain_mean, chain_sd, seen_mean, seen_sd, float(counts.sum()))


#: the least limit of the parts' spread (-). A short window's interval is narrower than
#: its parts' scatter on stationary flows (its bootstrap blocks, a tenth of the window,
#: are shorter than a residence): on the synthetic demo's flow (`RiserFlow()`, 2000
#: particles) the quarters of 2 s windows spread 1-5 % of E(RT), up to three times their
#: interval's width, and those of 5 s windows 4-7 %; the flow's own changes that matter
#: (the paper's riser: E(RT) 10-28 % apart between 5 s windows) are larger
MIN_PARTS_LIMIT = 0.1
#: the largest limit of the parts' spread (-): parts whose E(RT) differ by a quarter of the
#: model's or more always warn, however wide the interval. A window that straddles a change
#: of the flow widens its own interval (its blocks differ), so the limit from the interval
#: grows with the change it tests: an 8 s window across a 30 % step of a generated flow
#: (quarters 1.18, 1.18, 1.55, 1.52 s) got a limit of 31 %; a paper-scale 1 s window at
#: 4 m/s whose halves gave 0.67 and 0.40 s lay 84 % from the flow's long run
MAX_PARTS_LIMIT = 0.25

def _any_absences(runs) -> bool:
    """Whether a periodic run holds particles absent from some frames (PTV, PEPT out of
    view), which `stationarity` refuses (an open riser's entries and exits it reads)."""
    for run in runs:
        with opened(run) as traj:
            if traj.has_absences and not traj.boundary.is_open:
                return True
    return False


def flow_term_line(length: float, rt_mean: float | None = None, runs: int = 1) -> str:
    """The verdict's line on an interval formed without the flow's variability between
    windows (:func:`cfbmarkov.analysis.bootstrap.flow_variability`): a fitting window of
    ``length`` s shorter than two blocks of three mean residence times, or, where it is
    longer than that by the model's ``rt_mean``, one whose blocks hold fewer than two
    residences seen whole (tracks too short or too few).

    Parameters
    ----------
    length : float
        The fitting window's length (s; the shortest of a pooled fit's).
    rt_mean : float, optional
        The model's E(RT) (s), which tells the two reasons apart.
    runs : int, optional
        The runs of a pooled fit, whose blocks are compared across its runs: each run's
        window needs one block, not two.

    Returns
    -------
    str
    """
    from cfbmarkov.analysis.bootstrap import FLOW_BLOCK_RESIDENCES

    blocks = 1 if runs > 1 else 2              # of each window, for two blocks in all
    if rt_mean is not None and length >= blocks * FLOW_BLOCK_RESIDENCES * rt_mean:
        why = (f"fewer than two blocks of the {length:g} s fitting window hold two "
               "residences seen whole: the tracks are too short or too few to see residences "
               "end to end")
        advice = "pool more runs or tracks (fit A.h5 B.h5 ...)"
    elif rt_mean is not None and math.isfinite(rt_mean) and rt_mean > 0:
        from cfbmarkov.markov.uncertainty import outward_bounds

        # rounded up: a window of the printed length holds at least what is asked
        need = outward_bounds(0.0, blocks * FLOW_BLOCK_RESIDENCES * rt_mean, digits=3)[1]
        if runs > 1:       # pooled: a block of each run's window, compared across the runs
            why = (f"fewer than two of the {runs} runs' fitting windows (the shortest "
                   f"{length:g} s) hold a block of three mean residence times, {need} s here "
                   "by the model's E(RT) or a little less by the shorter residences a window "
                   "holds whole, and a pooled fit compares the blocks of all its runs")
            advice = (f"fit on windows of {need} s or more for the interval to hold it"
                      + _SAMPLE_LENGTH_ASIDE)
        else:
            why = (f"the {length:g} s fitting window is shorter than two blocks of three "
                   f"mean residence times, {need} s here by the model's E(RT) or a little "
                   "less by the shorter residences a window holds whole")
            advice = (f"fit on a window of {need} s or more, or pool several runs (fit A.h5 "
                      "B.h5 ...), for the interval to hold it" + _SAMPLE_LENGTH_ASIDE)
    else:
        why = (f"the {length:g} s fitting window is shorter than two blocks of three mean "
               "residence times")
        advice = _ADVICE
    held = "these windows'" if runs > 1 else "this window's"
    return (f"the model's interval leaves out the flow's variability between windows ({why})"
            f": it holds {held} sampling alone, and the flow's long run may lie "
            f"outside it; {advice}")


def _sampling_width(interval, uncertainty, rt_mean: float, runs: int = 1) -> float:
    """The width of the model's E(RT) interval over E(RT) without its flow term, as a
    normal interval of the window's own sampling (the block bootstrap) would be: each
    half-width with the flow's term (its quantile times its sigma,
    :func:`~cfbmarkov.analysis.bootstrap.flow_quantile`) taken out in quadrature
    (:func:`~cfbmarkov.analysis.bootstrap.interval_bounds` adds it so), and the rest
    divided by the bootstrap's Student's t over the normal quantile where the interval was
    so widened (its degrees of freedom from the blocks of ``runs`` runs,
    :func:`~cfbmarkov.markov.uncertainty.bootstrap_widening`): the width the parts' limit
    (:func:`parts_limit`) reads as 2 z standard errors. The parts' check tests the flow's
    changes within the window, so its limit must not grow with them (a window straddling a
    30 % step of a generated flow got a flow term of 17 % of E(RT) and a limit that passed
    the step)."""
    lo, hi = (float(v) for v in interval)
    flow = getattr(uncertainty, "flow_sd", None)
    if flow is None or not math.isfinite(float(flow[0])):
        down, up = rt_mean - lo, hi - rt_mean
    else:
        from cfbmarkov.analysis.bootstrap import flow_quantile

        term = (flow_quantile(float(uncertainty.level),
                              getattr(uncertainty, "flow_degrees_of_freedom", None))
                * float(flow[0]) * rt_mean)
        down = math.sqrt(max((rt_mean - lo) ** 2 - term ** 2, 0.0))
        up = math.sqrt(max((hi - rt_mean) ** 2 - term ** 2, 0.0))
    blocks = int(getattr(uncertainty, "blocks", 0) or 0) // max(int(runs), 1)
    widening = getattr(uncertainty, "bootstrap_widening", None)
    if blocks >= 2 and widening is not None:
        # t / z = the stored widening over its bias correction sqrt(B / (B - 1))
        down, up = (v * math.sqrt(blocks / (blocks - 1.0)) / float(widening)
                    for v in (down, up))
    return (down + up) / rt_mean


#: the 95th percentile of the range of k independent standard normal values (Tukey's
#: studentized range with infinite degrees of freedom, q(0.95; k, inf); H. L. Harter,
#: "Tables of range and studentized range", Ann. Math. Statist. 31, 1122 (1960);
#: scipy.stats.studentized_range.ppf(0.95, k, df) for large df)
RANGE_95 = {2: 2.7718, 4: 3.6332}


def parts_limit(width: float, parts: int, level: float = 0.9, from_interval: bool = True
                ) -> float:
    """The largest spread (max - min, relative to E(RT)) of the E(RT) of a window's
    ``parts`` equal parts that a stationary flow gives in 95 % of windows.

    Each part holds 1/k of the window's data, so its E(RT) scatters sqrt(k) times as much
    as the whole window's, whose standard error is the interval's relative width over
    2 z (z the normal quantile at (1 + level) / 2): the limit is
    q95(k) sqrt(k) width / (2 z), with q95(k) the 95th percentile of the range of k
    normal values (:data:`RANGE_95`). For a 90 % interval that is 1.19 times its width
    for halves and 2.21 times for quarters, at least :data:`MIN_PARTS_LIMIT` and at most
    :data:`MAX_PARTS_LIMIT`. Without
    an interval ``width`` is a tolerance, taken as it is for halves and sqrt(2) times for
    quarters, and at most :data:`MAX_PARTS_LIMIT` too (parts a quarter apart always
    warn).

    Parameters
    ----------
    width : float
        The model's E(RT) interval's width over E(RT) (-), or the tolerance.
    parts : {2, 4}
        Halves or quarters.
    level : float, optional
        The interval's level.
    from_interval : bool, optional
        Whether ``width`` is an interval's (else a tolerance).

    Returns
    -------
    float
    """
    if not from_interval:
        return min(width * (math.sqrt(2.0) if parts == 4 else 1.0), MAX_PARTS_LIMIT)
    from scipy.special import ndtri      # the normal quantile, scipy.stats.norm.ppf's

    z = float(ndtri(0.5 * (1.0 + level)))
    return min(max(RANGE_95[parts] * math.sqrt(parts) * width / (2.0 * z), MIN_PARTS_LIMIT),
               MAX_PARTS_LIMIT)


def _pooled_checks(fitter, data, names, windows, rt_mean: float, limit: float,
                   cross_limit: float, halves: bool = True, direction: str = "up"):
    """A pooled fit's checks across its runs: the first halves of all the windows pooled
    against the second halves pooled (limit ``limit``), and each run's own model against
    the pooled one (limit ``cross_limit`` sqrt(N - 1), ``cross_limit`` the within-run
    limit of :func:`within_run_limit`: a run holds 1/N of the data, so its E(RT)
    scatters sqrt(N) times the pooled interval's, and sqrt(1 - 1/N) of that about the
    pooled value). The halves are compared only with ``halves`` (where the pooled halves
    hold at least MIN_PART_RESIDENCES residences each). E(RT) counted in ``direction``
    (the pooled model's). Returns ((run, E(RT)) per run,
    warning lines, the halves' spread)."""
    lines = []
    runs = len(data)
    means = []
    for d in data:
        try:
            means.append(_part_rt_mean(fitter.fit(d), direction))
        except CfbmarkovError:
            means.append(math.nan)
    run_limit = cross_limit * math.sqrt(runs - 1)
    off = sorted(((name, m) for name, m in zip(names, means)
                  if math.isfinite(m) and rt_mean > 0 and abs(m / rt_mean - 1.0) > run_limit),
                 key=lambda item: -abs(item[1] / rt_mean - 1.0))     # the furthest first
    if off:
        text = ", ".join(f"{name} {m:.3g} s" for name, m in off)
        lines.append(f"the runs disagree: E(RT) of the model fitted on each run alone, {text}, "
                     f"{'lies' if len(off) == 1 else 'lie'} more than "
                     f"{100 * run_limit:.0f} % from the pooled model's "
                     f"{rt_mean:.3g} s (all runs: "
                     + ", ".join(f"{m:.3g}" for m in means) + " s): the runs are of "
                     "different cases, or each window saw its own state of a flow that "
                     "changes slower than a window (`cfbmarkov stationarity` each shows "
                     "it); check their cases: where they are one, the pooled model "
                     "averages the states the runs saw, and more runs or longer windows "
                     "narrow its interval")
    means_of_halves = []
    for side in ((0, 1) if halves else ()):
        blocks = []
        for d, (a, b) in zip(data, windows):
            cut = _split((a, b), 2)[side]
            try:
                blocks.append(d.block(*cut))
            except InputError:      # a run's window too short to halve: the others' halves
                continue
        try:
            if not blocks:
                raise CfbmarkovError("no run's window can be halved")
            means_of_halves.append(_part_rt_mean(fitter.fit(blocks), direction))
        except CfbmarkovError:
            means_of_halves.append(math.nan)
    spread = _spread(means_of_halves, rt_mean)
    if math.isfinite(spread) and spread > limit:
        first, second = means_of_halves
        spread_text, limit_text = _percents(spread, limit)
        lines.append(f"the halves of the pooled windows disagree: E(RT) {first:.3g} s "
                     f"from the first halves of all {runs} runs, {second:.3g} s from the "
                     f"second, a spread of {spread_text} % of the pooled model's "
                     f"{rt_mean:.3g} s (limit {limit_text} %): the flow changed within "
                     f"the windows; {_ADVICE}")
    return tuple(zip(names, means)), lines, spread


def _tail_share(model, length: float) -> float:
    """The model's exact RTD mass beyond ``length`` (s), of its resolved mass."""
    try:
        rtd = model.rtd()
    except CfbmarkovError:
        return math.nan
    p = np.asarray(rtd.probability, dtype=float)
    total = p.sum()
    if not total > 0:
        return math.nan
    return float(p[rtd.times > length + 1e-9].sum() / total)
