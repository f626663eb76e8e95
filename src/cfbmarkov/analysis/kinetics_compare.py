"""Properties along particle paths in ``cfbmarkov compare --kinetics``: the reference, the
model and the segregated-flow baseline side by side (``docs/definitions.md``, Properties
along observed paths).

Per property of a kinetics file (linear laws):

- *reference*: the property integrated along the reference's paths over the window, on the
  model's states at its lag (:mod:`cfbmarkov.analysis.kinetics_reference`);
- *model*: the prediction's values over the same window, the ones its Monte Carlo stored
  (``/properties/NAME``) where their fingerprint is that of this kinetics on the model's
  states (:func:`stored_definition_differs`) and the window starts at the prediction's
  first frame, else (none stored, another definition, no fingerprint, a window that starts
  later, whose stored values carry what happened before it while the reference's start
  there; with a warning) the same integration along the prediction's own paths from the
  window's start (on
  a space of cells these are the chain's states, so the values are those a Monte Carlo
  with properties gives); beside them the chain's exact answers
  (:func:`cfbmarkov.markov.kinetics_exact.exact_kinetics`), its exact exit mean as a window
  of the comparison's length sees it (short residences more often than long ones, as the
  reference's exits; :func:`cfbmarkov.markov.kinetics_exact.windowed_exit_means`) and an
  interval from the block bootstrap of the fitting window, as for the RTD;
- *segregated flow*: the bed-averaged law over the fitting window's observed RTD
  (:mod:`cfbmarkov.analysis.segregated_flow`).

A carried property's exact exit mean is the long-run steady state of the circulating
inventory, which a window's exits do not show: it has no PD (null, with a note) and no
segregated-flow baseline (null, with a note). A state space with memory takes its history
from the prediction's first frame(s) where the window starts there; both sides then start
that many lags later (``window``, ``window_note``).

Each side gives the mean at exit and its distribution, the bed's mean over time and per
cell; between sides the PD of the exit mean and the Minkowski distance (MD) of the exit
distributions on shared bins: the range of the values of the three sides cut into as many
equal bins as the RTD has, at most :data:`EXIT_BINS`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from cfbmarkov.analysis.compare_inputs import grid_parameter
from cfbmarkov.analysis.kinetics_reference import (PathKinetics, integrate_along_paths,
                                                   linear_maps, reference_kinetics,
                                                   reference_starts)
from cfbmarkov.analysis.segregated_flow import SegregatedFlow, segregated_flow
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.observed.metrics import minkowski_distance, percentage_difference

#: the group of a prediction file that holds its properties, one [T, N] dataset each
PROPERTIES_GROUP = "properties"
#: at most this many bins of the exit distributions (a few hundred exits per window)
EXIT_BINS = 50


#: why a carried property has no segregated-flow baseline (``summary.json``'s note)
CARRIED_SEGREGATED_NOTE = ("not defined for a carried property (the segregated flow restarts "
                           "every residence at the entry value)")


def carried_exact_note(length: float) -> str:
    """What the chain's exact exit mean of a carried property is, against a window of
    ``length`` s: its long-run steady state, which no PD against the window's exits
    judges (``summary.json``'s ``exact.note``)."""
    return (f"the circulating inventory's long-run steady state; not comparable with a "
            f"{length:g} s window")


def needs_cell_fields(kinetics) -> bool:
    """Whether a parameter of ``kinetics`` is a function of the cell fields."""
    from cfbmarkov.kinetics import FromField

    return any(isinstance(v, FromField) for p in kinetics.properties
               for v in p.parameters.values())


def _on_particles(values: np.ndarray, ids: np.ndarray, wanted: np.ndarray,
                  default: float) -> np.ndarray:
    """``values`` (one per particle of ``ids``) taken for the particles ``wanted``, by id
    (``default`` for an id not among ``ids``)."""
    ids, wanted = np.asarray(ids), np.asarray(wanted)
    if ids.size == 0:
        return np.full(wanted.size, float(default))
    order = np.argsort(ids, kind="stable")
    at = np.clip(np.searchsorted(ids[order], wanted), 0, ids.size - 1)
    found = ids[order][at] == wanted
    return np.where(found, np.asarray(values, dtype=np.float64)[order][at], float(default))


def stored_property(traj, name: str, frames: slice) -> np.ndarray | None:
    """The values of property ``name`` a prediction file stored for ``frames``, or None.

    Parameters
    ----------
    traj : Trajectories
        An open prediction file.
    name : str
        The property.
    frames : slice
        The frames.

    Returns
    -------
    ndarray of float64, shape (T, N), or None
        None where the file holds no ``/properties/NAME`` of the file's shape.
    """
    if name not in traj.property_names:
        return None
    data = traj.property_values(name, frames)
    if data.shape[-1] != traj.n_particles:
        raise InputError(f"{traj.path}: /{PROPERTIES_GROUP}/{name} holds {data.shape[-1]} "
                         f"particles for the file's {traj.n_particles}")
    return np.asarray(data, dtype=np.float64)


def stored_definition_differs(traj, name: str, state_kinetics, lag: float,
                              direction: str = "up") -> str | None:
    """Why the values a prediction stored for ``name`` cannot stand for the property as
    ``state_kinetics`` defines it, or None where they can.

    The stored values stand for it only where the fingerprint stored with them
    (:func:`cfbmarkov.kinetics.fingerprint.property_fingerprint`: law, start rule, entry
    value, lag, residence direction and the per-state rates and targets) is that of
    ``state_kinetics`` at ``lag`` in ``direction``.

    Parameters
    ----------
    traj : Trajectories
        An open prediction file holding ``/properties/NAME``.
    name : str
        The property.
    state_kinetics : StateKinetics
        The comparison's kinetics on the model's states.
    lag : float
        The model's lag (s).
    direction : {"up", "down"}, optional
        The model's residence direction (``MarkovModel.flow_direction``).

    Returns
    -------
    str or None
        The reason in words (what differs), or None where the fingerprints match.
    """
    from cfbmarkov.kinetics.fingerprint import FINGERPRINT_METHOD, property_fingerprint

    attrs = traj.property_attrs(name)
    q = state_kinetics.index(name)
    stored = attrs.get("fingerprint")
    if not stored:
        return (f"{traj.path} stores {name} without the fingerprint of its definition (a file "
                "written by an older cfbmarkov): its values may be those of another kinetics")
    if str(stored) == property_fingerprint(state_kinetics, q, lag, direction):
        return None
    differ = []
    entries = attrs.get("entries")
    if isinstance(entries, bytes):
        entries = entries.decode(errors="replace")
    if entries is None and str(attrs.get("fingerprint_method", "")) != FINGERPRINT_METHOD:
        differ.append(f"stored by an older recipe ({attrs.get('fingerprint_method')}), "
                      "which did not record the direction residences are counted in")
    elif entries is not None and str(entries) != direction:
        differ.append(f"entries counted {entries} stored, {direction} here")
    law = state_kinetics.laws[q].key
    if str(attrs.get("law", law)) != law:
        differ.append(f"law {attrs.get('law')} stored, {law} here")
    if str(attrs.get("start", state_kinetics.starts[q])) != state_kinetics.starts[q]:
        differ.append(f"start {attrs.get('start')} stored, {state_kinetics.starts[q]} here")
    initial = float(state_kinetics.initial[q])
    if not np.isclose(float(attrs.get("initial", initial)), initial, rtol=1e-12, atol=0.0):
        differ.append(f"initial {float(attrs.get('initial')):g} stored, {initial:g} here")
    what = "; ".join(differ) if differ else "the rates or targets per state (or the lag) differ"
    return f"stored values of another definition of {name} in {traj.path}: {what}"


def _prediction_states(pred, model, window, warnings):
    """The prediction's states over ``window`` (positions kept) and the lags by which they
    start after the window's start: where the file starts less than the history the
    state space needs before the window, its first frames serve as that history (as
    ``fit`` does at a file's start) and the comparison starts later, with a warning."""
    from cfbmarkov.markov.discrete import discretize

    start, stop = window
    try:
        discrete = discretize(pred, model.state_space, model.lag, (start, stop),
                              keep_positions=True, short_history="skip")
    except InputError as exc:
        memory = int(model.state_space.memory_lags)
        hint = (f"; the model's states ({model.state_space.kind}) take their {memory} lag(s) "
                "of history from the file's first frames: give a window ending at "
                f"{start + (memory + 1) * model.lag:g} s or later" if memory else "")
        raise InputError(f"{exc}{hint}") from None
    first = float(discrete.times[0])
    late = int(round((first - start) / model.lag)) if first > start + pred.time_tolerance else 0
    if late:
        warnings.append(f"kinetics: the model's states ({model.state_space.kind}) need "
                        f"{model.state_space.memory_lags} lag(s) of history and {pred.path} "
                        f"starts at {float(pred.times[0]):g} s: its first frame(s) serve as "
                        f"that history, so the kinetics comparison starts {late} lag(s) "
                        f"later, over {first:g}-{stop:g} s on both sides")
    return discrete, late


def _with_source_found(model, pred, ref):
    """``model`` with its fitting file found wherever the comparison runs from: as recorded,
    beside the prediction that carries it, or the reference
    (:func:`~cfbmarkov.analysis.intervals.resolve_source`); as it is where none is found
    (the bootstrap then says why it formed no interval)."""
    import os

    from cfbmarkov.analysis.intervals import resolve_source

    model._cache.setdefault("file", os.path.abspath(pred.path))
    try:
        return resolve_source(model, candidates=[ref.path])
    except InputError:
        return model


def _fitting_source(model, ref):
    """The file and window the model was fitted on: for a model that records its fitting
    window's identity, the file that holds it (:func:`~cfbmarkov.analysis.intervals.
    resolve_source`: as recorded, beside the model file, or the reference; of a pooled
    fit, the reference where it is one of the runs); for one that records none, its own
    source where that is one readable file, else the reference where the window lies
    inside it. (None, None) where none is found."""
    import os

    from cfbmarkov.analysis.intervals import resolve_source

    window = model.window
    if window is None:
        return None, None
    if model.source_identity:
        try:
            found = resolve_source(model, candidates=[ref.path])
        except InputError:
            return None, None       # another file of that name, or none: no baseline
        if isinstance(found.source, (str, Path)):
            return found.source, tuple(window)
        runs = [os.path.abspath(str(p)) for p in found.source]
        if os.path.abspath(str(ref.path)) in runs:      # a pooled fit: its reference run
            return ref, tuple(model.run_windows[runs.index(os.path.abspath(str(ref.path)))]
                              if model.run_windows else window)
        return None, None
    source = model.source
    if isinstance(source, (str, Path)) and str(source) and Path(source).is_file():
        return source, tuple(window)
    tol = ref.time_tolerance
    if window[0] >= ref.times[0] - tol and window[1] <= ref.times[-1] + tol:
        return ref, tuple(window)
    return None, None


def _cell_fields(model, ref, warnings):
    """The fitting window's cell fields: the model's own, else computed on its fitting
    window (its source file, or the reference where the window lies inside it)."""
    from cfbmarkov.analysis.cell_fields import cell_fields_of
    from cfbmarkov.trajectories import opened

    fields = model.cell_fields
    if fields is None:
        source, window = _fitting_source(model, ref)
        if source is None:
            raise InputError("the kinetics' rates depend on the fitting window's cell fields, "
                             "but the model stores none and its fitting file is not readable: "
                             "give rates per cell (rate_by_cell) or keep the fitting file "
                             "where the model says")
        with opened(source) as traj:
            fields = cell_fields_of(traj, model.state_space, window)
    return fields


def _fitting_rtd_and_occupancy(model, ref, on, warnings, length: float | None = None):
    """The fitting window's residence-time samples (on the comparison's basis) and state
    occupancy at the model's lag; (None, None) with a warning where unreadable. Where the
    fitting window's length differs from the compared one's (``length``, s), a warning that
    the segregated-flow baseline is built from residences a window of another length sees
    (as the persistence baseline's)."""
    from cfbmarkov.markov.discrete import discretize
    from cfbmarkov.observed.residence import residence_times
    from cfbmarkov.trajectories import opened

    source, window = _fitting_source(model, ref)
    if source is None:
        warnings.append("kinetics: no segregated-flow baseline: the model's fitting window "
                        "is not readable")
        return None, None
    try:
        with opened(source) as traj:
            lag_frames = traj.lag_frames(model.lag)
            rt = residence_times(traj, window, use_events=on.events, face_band=on.band,
                                 lag_frames=1 if on.events else lag_frames,
                                 direction=on.direction)
            discrete = discretize(traj, model.state_space, model.lag, window)
    except InputError as exc:
        warnings.append(f"kinetics: no segregated-flow baseline ({exc})")
        return None, None
    states = discrete.states[::discrete.lag_frames]
    occupancy = np.bincount(states[states >= 0], minlength=model.n_states).astype(float)
    fit_length = float(window[1] - window[0])
    # within a lag and a half: a comparison of a model with memory starts a lag late (its
    # first frame is the states' history), which the user cannot lengthen
    if length is not None and abs(fit_length - length) > max(1.5 * model.lag, 1e-6 * length):
        warnings.append(f"kinetics: the segregated-flow baseline's residences are those of the "
                        f"{fit_length:g} s fitting window {window[0]:g}-{window[1]:g} s and the "
                        f"compared window is {length:g} s long: a window sees residences up "
                        "to its own length, so the baseline is not like for like; fit on a "
                        "window as long as the compared one for a fair baseline")
    return rt.samples, occupancy


def _exact(model, sk, warnings, direction="up"):
    try:
        from cfbmarkov.markov.kinetics_exact import exact_kinetics
    except ImportError:          # pragma: no cover - the exact module is part of the package
        return None
    try:
        return exact_kinetics(model, sk, direction=direction)
    except CfbmarkovError as exc:
        warnings.append(f"kinetics: no exact answers ({exc})")
        return None


def _windowed(model, sk, length: float, warnings, direction: str = "up",
              occupancy=None) -> dict:
    """The chain's exact exit means as a window of ``length`` s sees them, its particles
    starting in ``occupancy`` (:func:`cfbmarkov.markov.kinetics_exact.windowed_exit_means`);
    {} with a warning where they cannot be had."""
    from cfbmarkov.markov.kinetics_exact import windowed_exit_means

    try:
        return windowed_exit_means(model, sk, length, direction=direction,
                                   occupancy=occupancy)
    except CfbmarkovError as exc:
        warnings.append(f"kinetics: no windowed exact answers ({exc})")
        return {}


#: the relative change of every rate by which :func:`stretch_sensitivity` differentiates
STRETCH_STEP = 0.01


def stretch_sensitivity(model, sk, direction: str = "up") -> dict[str, float]:
    """How much each property's exact exit mean moves per relative stretch of every
    residence: d(exit mean) / d(ln s) at s = 1, where every time the chain spends in a
    state lasts s times as long.

    For a linear law dv/dt = k_s (v_s - v) a stretch of time by s is the rate k_s s, so
    the derivative is taken by central differences of :data:`STRETCH_STEP` in every rate
    (``docs/kinetics-reference.md``, the model block's intervals).

    Parameters
    ----------
    model : MarkovModel
        The fitted model.
    sk : StateKinetics
        The properties resolved on its states (linear laws).
    direction : {"up", "down"}, optional
        The direction exits are counted in.

    Returns
    -------
    dict of str to float
        Per property, in its own unit; {} where the exact answers cannot be had.
    """
    from cfbmarkov.markov.kinetics_exact import exact_kinetics

    rate = np.asarray(sk.rate, dtype=np.float64)
    try:
        faster, slower = (exact_kinetics(model, dataclasses.replace(sk, rate=rate * factor),
                                         direction=direction)
                          for factor in (1.0 + STRETCH_STEP, 1.0 - STRETCH_STEP))
    except CfbmarkovError:
        return {}
    return {name: (faster[name].exit_mean - slower[name].exit_mean) / (2.0 * STRETCH_STEP)
            for name in faster if name in slower}


#: state count up to which the kinetics interval takes every bootstrap resample
KINETICS_FULL_STATES = 500
#: the fewest resamples the kinetics interval takes on a large state space
KINETICS_MIN_RESAMPLES = 20


def kinetics_resamples(n_states: int, resamples: int) -> int:
    """Bootstrap resamples the kinetics interval solves exactly: all of ``resamples`` up to
    :data:`KINETICS_FULL_STATES` states, beyond that fewer, as (KINETICS_FULL_STATES /
    states)^2 of them (an exact solve's cost grows about as the square of the states), and
    never fewer than :data:`KINETICS_MIN_RESAMPLES` (nor more than ``resamples``).

    A rule on the state count, not on a measured time, so that the interval is the same on
    every machine. On the paper's riser the exact answers of two properties took 0.5 s on
    the 228 states of the paper's cells and 4.2 s on the 1824 states of ``cells-velocity``
    (``react``, cfbmarkov 0.1.0, 2026-12-04): 100 resamples there took more than 8 minutes,
    20 take about 1.5.

    Parameters
    ----------
    n_states : int
        The model's states.
    resamples : int
        The resamples asked for (``--resamples``).

    Returns
    -------
    int
    """
    resamples = int(resamples)
    if resamples <= 0 or n_states <= KINETICS_FULL_STATES:
        return max(resamples, 0)
    scaled = int(round(resamples * (KINETICS_FULL_STATES / float(n_states)) ** 2))
    return min(resamples, max(KINETICS_MIN_RESAMPLES, scaled))


def bootstrap_exit_means(model, kinetics, fields, resamples: int, warnings,
                          direction: str = "up", passes=(), after_passes=None):
    """Exact exit means of each property on block-bootstrap resamples of the model's fitting
    window (:func:`cfbmarkov.analysis.bootstrap.block_bootstrap_models`,
    :data:`~cfbmarkov.analysis.bootstrap.BOOTSTRAP_BLOCKS` blocks, seed 0),
    what the model's interval of an exit mean is formed from (`compare --kinetics`,
    `react --resamples`). A periodic riser's resamples start their residences from the
    fitted model's entry distribution, as the RTD's interval's resamples do
    (:func:`cfbmarkov.analysis.bootstrap.bootstrap_figures`: the spread of the entry
    distribution left out, one definition for both).

    Parameters
    ----------
    model : MarkovModel
        The fitted model, its fitting file found (:func:`cfbmarkov.analysis.intervals.
        resolve_source`).
    kinetics : Kinetics
        The properties (linear laws).
    fields : CellFields or None
        The cell fields the properties' parameters take (None: none needed).
    resamples : int
        Resamples asked for; fewer are solved on a large state space
        (:func:`kinetics_resamples`, with a line in ``warnings``).
    warnings : list of str
        Appended to: why fewer resamples, or none, were taken.
    direction : {"up", "down"}, optional
        The direction exits are counted in.
    passes : sequence of int, optional
        Numbers of passes after which a carried property's mean exit value is also taken
        (:meth:`~cfbmarkov.markov.kinetics_exact.PropertyAnswer.after_passes`).
    after_passes : dict, optional
        Filled, for each carried property and each of ``passes``, with
        ``after_passes[(name, n)]``: its mean after n passes over the same resamples.

    Returns
    -------
    dict of str to list of float, or None
        Each property's exit means over the resamples that have residences (a resample of
        the lap deficits' depth cut to :data:`~cfbmarkov.analysis.intervals.
        BOOTSTRAP_DEFICIT_LEVELS` is scaled by the model's full-depth ratio); None for no
        resamples or a model whose fitting data cannot be read.
    """
    if not resamples:
        return None
    from cfbmarkov.analysis.bootstrap import BOOTSTRAP_BLOCKS, block_bootstrap_models
    from cfbmarkov.kinetics import Kinetics
    from cfbmarkov.markov.kinetics_exact import exact_kinetics

    taken = kinetics_resamples(model.n_states, resamples)
    if taken < resamples:
        warnings.append(f"kinetics: the model's interval from {taken} of {resamples} bootstrap "
                        f"resamples ({model.n_states} states: each resample is an exact solve "
                        "that grows as the square of the states)")
    resamples = taken
    from cfbmarkov.analysis.intervals import BOOTSTRAP_DEFICIT_LEVELS

    # the resamples keep 8 lap deficits; where the model keeps more, their exit means are
    # scaled by the model's full-depth / 8-deficit ones (as model_intervals does the RTD)
    depth = model.rtd(direction=direction).deficit_levels if model.open_flow is None else None
    scale = {}
    if depth is not None and depth > BOOTSTRAP_DEFICIT_LEVELS:
        per_state = kinetics.per_state(model.state_space, fields)
        full = exact_kinetics(model, per_state, direction=direction)
        part = exact_kinetics(model, per_state, direction=direction,
                              deficit_levels=BOOTSTRAP_DEFICIT_LEVELS)
        scale = {name: full[name].exit_mean / part[name].exit_mean for name in full
                 if part[name].exit_mean != 0}
        scale.update({(name, n): full[name].after_passes(n)[0] / part[name].after_passes(n)[0]
                      for name in full if full[name].start == "carried" for n in passes
                      if part[name].after_passes(n)[0] != 0})
    depth = None if depth is None else min(depth, BOOTSTRAP_DEFICIT_LEVELS)
    # a periodic riser's resamples start from the fitted model's entry distribution, as its
    # RTD's resamples do (bootstrap_figures): the same definition as the E(RT) interval's
    # (a resample's own would re-weight a reducible chain's classes, spreading the exit
    # mean ten times as far as E(RT) on a LAMMPS riser of six column classes)
    # A carried property's steady state is the resample's own circulation (its landings
    # fed back as its entries), which a foreign entry distribution would not close: those
    # keep each resample's own
    entry = (None if model.open_flow is not None
             else model.rtd(direction=direction).entry_distribution)
    groups = [(Kinetics(tuple(group), kinetics.source), entry if not carried else None)
              for carried in (False, True)
              for group in [[p for p in kinetics.properties
                             if (p.start == "carried") == carried]] if group]
    try:
        drawn = block_bootstrap_models(model, blocks=BOOTSTRAP_BLOCKS, resamples=resamples, seed=0)
        means: dict[str, list[float]] = {name: [] for name in kinetics.names}
        for resampled in drawn:
            try:
                answers = {}
                for group, start_from in groups:
                    answers.update(exact_kinetics(
                        resampled, group.per_state(resampled.state_space, fields),
                        direction=direction, deficit_levels=depth, entry=start_from))
            except (CfbmarkovError, ValueError):
                continue
            for name, answer in answers.items():
                means[name].append(answer.exit_mean * scale.get(name, 1.0))
                if after_passes is not None and answer.start == "carried":
                    for n in passes:
                        after_passes.setdefault((name, n), []).append(
                            answer.after_passes(n)[0] * scale.get((name, n), 1.0))
    except InputError as exc:
        warnings.append(f"kinetics: no model intervals ({exc})")
        return None
    return means


def exit_mean_intervals(model, kinetics, answers=None, *, level: float = 0.9,
                        resamples: int = 100, fields=None, direction: str | None = None,
                        passes=(), candidates=(), warnings: list | None = None,
                        resolve: bool = True) -> dict:
    """The intervals of a model's exact exit means (``react --resamples``): each property's
    exit mean solved exactly on block-bootstrap resamples of the fitting window
    (:func:`bootstrap_exit_means`, as ``compare --kinetics`` forms the model's), the
    interval of :func:`cfbmarkov.analysis.bootstrap.interval_bounds` centred on the exact
    value, its ends cut to the law's range (a conversion's to [0, 1], an activity's at 0,
    as SD(RT)'s lower end is cut at 0).

    Parameters
    ----------
    model : MarkovModel
        A model fitted on trajectory files (its fitting file found from the current folder,
        beside the model file or among ``candidates``:
        :func:`cfbmarkov.analysis.intervals.resolve_source`).
    kinetics : Kinetics
        The properties (linear laws).
    answers : dict of str to PropertyAnswer, optional
        The exact answers the intervals are centred on (default: solved here,
        :func:`~cfbmarkov.markov.kinetics_exact.exact_kinetics`).
    level : float, optional
        Coverage, in (0, 1); default 0.9.
    resamples : int, optional
        Bootstrap resamples (fewer are solved on a large state space,
        :func:`kinetics_resamples`); 0 forms none.
    fields : CellFields, optional
        The cell fields the properties' parameters take (default the model's).
    direction : {"up", "down"}, optional
        The direction exits are counted in (default the model's ``flow_direction``).
    passes : sequence of int, optional
        Numbers of passes after which a carried property's mean exit value gets an
        interval too.
    candidates : sequence of str or os.PathLike, optional
        Files that may be the fitting file.
    warnings : list of str, optional
        Appended to: why fewer resamples, or none, were taken.
    resolve : bool, optional
        Find the fitting file (default); False for a model that
        :func:`~cfbmarkov.analysis.intervals.resolve_source` returned, whose file is not
        read again to check it.

    Returns
    -------
    dict
        ``exit_mean``: {name: [lo, hi] or None (fewer than 10 resamples solved)};
        ``after_passes``: {(name, n): [lo, hi] or None} of the carried properties;
        ``resamples``: the resamples solved; ``level``; ``flow_sd``: {name: {"exit_mean":
        absolute SD, "rt_mean_relative": E(RT)'s, "degrees_of_freedom": ...}} of the
        properties whose exit-mean interval carries the flow's variability between windows
        (the model's own, :attr:`MarkovModel.uncertainty` ``flow_sd``, as a stretch of every
        residence: :func:`stretch_sensitivity`; a property that starts at entry; none where
        the model's interval has no flow term).

    Raises
    ------
    InputError
        Where the level or resamples cannot form an interval, or the fitting file is not
        found or is not the model's (:func:`~cfbmarkov.analysis.intervals.resolve_source`).
    """
    from cfbmarkov.analysis.bootstrap import (BOOTSTRAP_BLOCKS, check_interval_options,
                                              fitting_runs, interval_bounds)
    from cfbmarkov.analysis.intervals import resolve_source
    from cfbmarkov.markov.kinetics_exact import exact_kinetics

    direction = model.flow_direction if direction is None else direction
    fields = model.cell_fields if fields is None else fields
    warnings = [] if warnings is None else warnings
    if answers is None:
        answers = exact_kinetics(model, kinetics.per_state(model.state_space, fields),
                                 direction=direction)
    if not resamples or not answers:
        return {"exit_mean": {}, "after_passes": {}, "resamples": 0, "level": level,
                "flow_sd": {}}
    check_interval_options(level, resamples)
    source = resolve_source(model, candidates) if resolve else model
    after: dict = {}
    means = bootstrap_exit_means(source, kinetics, fields, resamples, warnings,
                                 direction=direction, passes=passes, after_passes=after)
    drawn = {"blocks": BOOTSTRAP_BLOCKS, "runs": len(fitting_runs(source))}
    ranges = {p.name: getattr(p.law, "initial_range", (None, None))
              for p in kinetics.properties}
    # the model's own flow term (E(RT)'s relative SD between windows, as its E(RT)
    # interval carries it), as a stretch of every residence, for the properties that
    # start at entry (a carried one's exit mean is a long-run steady state)
    uncertainty = getattr(model, "uncertainty", None)
    relative = (None if uncertainty is None or uncertainty.flow_sd is None
                else float(uncertainty.flow_sd[0]))
    flow: dict = {}
    if relative is not None and np.isfinite(relative) and relative >= 0:
        entering = [p.name for p in kinetics.properties if p.start != "carried"]
        if entering:
            sensitivity = stretch_sensitivity(
                model, kinetics.per_state(model.state_space, fields), direction)
            flow = {name: {"exit_mean": abs(sensitivity[name]) * relative,
                           "rt_mean_relative": relative,
                           "degrees_of_freedom": uncertainty.flow_degrees_of_freedom}
                    for name in entering if np.isfinite(sensitivity.get(name, np.nan))}

    def bounds(name, point, values, with_flow=False):
        boot = np.asarray(values, dtype=float)
        boot = boot[np.isfinite(boot)]
        if boot.size < 10:
            return None
        term = flow.get(name) if with_flow else None
        lo, hi = interval_bounds(point, boot, point, level, 0.0,
                                 0.0 if term is None else term["exit_mean"],
                                 None if term is None else term["degrees_of_freedom"],
                                 **drawn)
        low, high = ranges.get(name, (None, None))
        return [float(lo if low is None else max(lo, low)),
                float(hi if high is None else min(hi, high))]

    return {"exit_mean": {name: bounds(name, answer.exit_mean, (means or {}).get(name, []),
                                       with_flow=True)
                          for name, answer in answers.items()},
            "flow_sd": flow,
            "after_passes": {(name, n): bounds(name, answers[name].after_passes(n)[0], values)
                             for (name, n), values in after.items()},
            "resamples": kinetics_resamples(model.n_states, resamples) if means else 0,
            "level": level}


def exit_mean_agreement(reference_mean, model_interval, reference_interval=None
                        ) -> str | None:
    """How a reference's exit mean stands against the model's interval of it, as
    ``compare --kinetics`` judges it.

    Parameters
    ----------
    reference_mean : float or None
        The reference's exit mean.
    model_interval : (float, float) or None
        The model's interval of its exit mean (``model.exit_mean_interval`` of the
        summary's kinetics block).
    reference_interval : (float, float), optional
        The reference's own interval (its exits' sampling).

    Returns
    -------
    {"inside", "not told apart", "missed"} or None
        ``inside``: the reference's value lies in the model's interval (the model is
        consistent with it within its uncertainty); ``not told apart``: it lies outside but
        the reference's own interval overlaps the model's; ``missed``: neither. None where
        the model has no interval or the reference no finite exit mean.
    """
    def finite(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)

    if (not finite(reference_mean) or not isinstance(model_interval, (list, tuple))
            or len(model_interval) != 2 or not all(finite(v) for v in model_interval)):
        return None
    lo, hi = model_interval
    if lo <= reference_mean <= hi:
        return "inside"
    if (isinstance(reference_interval, (list, tuple)) and len(reference_interval) == 2
            and all(finite(v) for v in reference_interval)
            and reference_interval[0] <= hi and lo <= reference_interval[1]):
        return "not told apart"
    return "missed"


def _interval(value, se, level):
    from scipy.special import ndtri      # the normal quantile, scipy.stats.norm.ppf's

    if not (np.isfinite(value) and np.isfinite(se)):
        return None
    z = float(ndtri(0.5 * (1 + level)))
    return [float(value - z * se), float(value + z * se)]


def _side(values: np.ndarray, mean: float, sd: float, se: float, level: float) -> dict:
    return {"exit_mean": mean, "exit_sd": sd, "exit_count": int(values.size),
            "exit_mean_interval": _interval(mean, se, level)}


def _paths(p: PathKinetics) -> dict:
    return {"bed_mean": p.time_mean,
            "bed_mean_over_time": {"times": p.times.tolist(),
                                   "mean": [None if not np.isfinite(x) else float(x)
                                            for x in p.bed_mean]},
            "bed_mean_by_cell": [None if not np.isfinite(x) else float(x) for x in p.cell_mean]}


def exit_bins(samples, count: int) -> np.ndarray:
    """Shared bins of the exit distributions: the values' range cut into ``count`` bins.

    Parameters
    ----------
    samples : sequence of array_like
        The sides' exit values.
    count : int
        Number of bins (the comparison's RTD bins).

    Returns
    -------
    ndarray of float64, shape (count + 1,)
        Edges (a range of zero width is widened by 1e-9 either side).
    """
    finite = [np.asarray(s, float)[np.isfinite(s)] for s in samples]
    finite = [s for s in finite if s.size]
    if not finite:
        return np.linspace(0.0, 1.0, count + 1)
    lo = min(float(s.min()) for s in finite)
    hi = max(float(s.max()) for s in finite)
    if not hi > lo:
        lo, hi = lo - 1e-9, hi + 1e-9
    return np.linspace(lo, hi, count + 1)


def exit_distribution(values, edges: np.ndarray) -> np.ndarray:
    """Probability per bin of exit values (all zero without values)."""
    counts, _ = np.histogram(np.asarray(values, float), bins=edges)
    total = counts.sum()
    return counts / total if total else counts.astype(float)


def check_kinetics_inputs(pred, kinetics):
    """The prediction's model, once the kinetics can be compared on it: what
    :func:`compare_kinetics` refuses before any work, so that ``compare`` refuses it in one
    line before its progress line (a rate table is checked against the model's grid here
    where no parameter needs the fitting window's cell fields; else where they are read).

    Parameters
    ----------
    pred : Trajectories
        The prediction (it carries its model).
    kinetics : Kinetics
        The properties.

    Returns
    -------
    MarkovModel

    Raises
    ------
    InputError
        When the prediction carries no model, a law is not linear, or a rate table does not
        fit the model's grid.
    """
    from cfbmarkov.markov import MarkovModel

    model = MarkovModel.from_trajectories(pred)
    if model is None:
        raise InputError(f"{pred.path} carries no model (/provenance/model): --kinetics needs "
                         "the model's states and lag; predict with cfbmarkov predict")
    if not kinetics.linear:
        raise InputError(f"{kinetics.source or 'kinetics'}: a custom law has no reference "
                         "side here; compare needs linear laws")
    if not needs_cell_fields(kinetics):
        kinetics.per_state(model.state_space)
    return model


def compare_kinetics(ref, pred, comparison, kinetics, *, level: float = 0.9,
                     resamples: int = 100, warnings: list[str]) -> dict[str, Any]:
    """The ``kinetics`` block of ``summary.json`` and the figures' inputs.

    Parameters
    ----------
    ref, pred : Trajectories
        The open reference and prediction files of ``comparison``.
    comparison : RunComparison
        The comparison (its window, basis, direction and RTD bins are used).
    kinetics : Kinetics
        The properties (linear laws only).
    level : float, optional
        Coverage of the intervals.
    resamples : int, optional
        Bootstrap resamples of the fitting window for the model's interval (0: none).
    warnings : list of str
        Appended to.

    Returns
    -------
    dict
        ``{"summary": {NAME: {...}}, "figures": {NAME: {...}}}``: the summary block
        (module docstring) and, per property, what the report draws.

    Raises
    ------
    InputError
        When the prediction carries no model, a law is not linear, a rate table does not
        fit the model's grid, a property is carried on an open riser, or the reference
        cannot be discretised on its states.
    """
    from cfbmarkov.analysis.compare import _Basis, reading_band

    model = check_kinetics_inputs(pred, kinetics)
    fields = _cell_fields(model, ref, warnings) if needs_cell_fields(kinetics) else None
    warnings.extend(f"kinetics: {note}" for note in kinetics.field_notes(fields))
    warnings.extend(f"kinetics: {note}" for note in kinetics.grid_notes(model.state_space))
    sk = kinetics.per_state(model.state_space, fields)
    if model.open_flow is not None and "carried" in sk.starts:
        name = sk.names[list(sk.starts).index("carried")]
        where = f"{sk.source}: " if getattr(sk, "source", "") else ""
        raise InputError(f"{where}property {name}: a carried property needs a periodic riser: "
                         "particles that leave an open riser do not come back (use start = "
                         "entry)")
    maps = linear_maps(sk, model.lag)
    start, stop = comparison.window
    on = _Basis(comparison.basis, comparison.basis == "events", comparison.lag_frames,
                ref.height / float(grid_parameter(pred, "rows") or model.state_space.rows),
                comparison.direction)
    pred_discrete, late = _prediction_states(pred, model, (start, stop), warnings)
    start = float(pred_discrete.times[0]) if late else start
    ref_starts = None
    if any(m["start"] == "reference" for m in maps):
        # the values both sides start from: the reference's at the window's start (those a
        # prediction with --init takes), on the prediction's particles by id
        ref_starts = reference_starts(ref, model, sk, start, direction=on.direction)
    reference = reference_kinetics(ref, model, sk, (start, stop), direction=on.direction,
                                   starts=ref_starts)
    frames = pred.window(start, stop)
    model_paths, sources, notes = {}, {}, {}
    for m in maps:
        name = m["name"]
        stored = stored_property(pred, name, slice(frames.start, frames.stop))
        if stored is not None:
            notes[name] = stored_definition_differs(pred, name, sk, model.lag,
                                                    model.flow_direction)
            if notes[name] is None and stored.shape[0] != pred_discrete.n_frames:
                notes[name] = (f"{pred.path} stores {name} in {stored.shape[0]} frames of "
                               f"{start:g}-{stop:g} s, not the {pred_discrete.n_frames} the "
                               "comparison reads")
            first = float(pred.times[0])
            if notes[name] is None and start > first + pred.time_tolerance:
                # the stored values carry what happened since the prediction's start; the
                # reference's start every particle at the window's start
                notes[name] = (f"the {name} stored in {pred.path} has run since its first "
                               f"frame at {first:g} s, while the reference's starts at "
                               f"{start:g} s")
            if notes[name] is not None:
                warnings.append(f"kinetics: {notes[name]}; the model side integrates {name} "
                                "along the prediction's paths instead")
                stored = None
        sources[name] = "stored" if stored is not None else "paths"
        initial = m["initial"]
        if m["start"] == "reference" and stored is None:
            initial = _on_particles(ref_starts[maps.index(m)], ref.ids, pred.ids,
                                    m["initial"])
        model_paths[name] = integrate_along_paths(     # read as its residences are
            pred_discrete, m["a"], m["b"], initial, entry_value=m["initial"],
            reset=m["reset"], name=name, direction=on.direction, stored=stored,
            face_band=reading_band(pred, None))
    unstored = [m["name"] for m in maps if m["name"] not in notes]
    if unstored:
        warnings.append(f"kinetics: the prediction stored no values of {', '.join(unstored)}; "
                        "the model side integrates them along the prediction's paths")
    exact = _exact(model, sk, warnings, on.direction)
    from cfbmarkov.markov.model_rtd import occupancy_at

    found = occupancy_at(model, pred, start)     # the reference's where pred lacks history
    windowed = (_windowed(model, sk, stop - start, warnings, on.direction,
                          found if found is not None else occupancy_at(model, ref, start))
                if exact else {})
    boot = (bootstrap_exit_means(_with_source_found(model, pred, ref), kinetics, fields,
                                 resamples, warnings, on.direction)
            if exact and resamples else None)
    rt_fit, occupancy = _fitting_rtd_and_occupancy(model, ref, on, warnings, stop - start)
    # the flow's variability between windows, as the RTD's interval carries it (E(RT)'s
    # relative SD), taken into the exit means as a stretch of every residence
    intervals = getattr(comparison, "intervals", None)
    stretch = getattr(intervals, "flow_relative", None)
    sensitivity = (stretch_sensitivity(model, sk, on.direction)
                   if stretch is not None and boot is not None else {})
    n_bins = min(int(comparison.edges.size - 1), EXIT_BINS)
    summary, figures = {}, {}
    for m in maps:
        name = m["name"]
        r, p = reference[name], model_paths[name]
        carried = not m["reset"]
        seg: SegregatedFlow | None = None
        if rt_fit is not None and not carried:
            seg = segregated_flow(rt_fit, m["rate"], m["target"], occupancy, m["initial"],
                                  name=name, lag=model.lag)
        edges = exit_bins([r.exit_values, p.exit_values]
                          + ([seg.exit_values] if seg is not None else []), n_bins)
        dist_ref = exit_distribution(r.exit_values, edges)
        dist_mod = exit_distribution(p.exit_values, edges)

        def md(dist):
            return (minkowski_distance(dist_ref, dist, comparison.md_order)
                    if dist_ref.sum() > 0 and dist.sum() > 0 else float("nan"))

        ref_block = {**_side(r.exit_values, r.exit_mean, r.exit_sd, r.exit_se, level),
                     **_paths(r)}
        mod_block = {**_side(p.exit_values, p.exit_mean, p.exit_sd, p.exit_se, level),
                     **_paths(p), "values_from": sources[name],
                     **({"values_note": notes[name]} if notes.get(name) else {}),
                     "pd_exit_mean": percentage_difference(p.exit_mean, r.exit_mean),
                     "md_exit": md(dist_mod)}
        answer = None if exact is None else exact.get(name)
        if answer is not None:
            mod_block["exact"] = {"exit_mean": answer.exit_mean, "exit_sd": answer.exit_sd,
                                  "bed_mean": answer.bed_mean,
                                  "pd_exit_mean": percentage_difference(answer.exit_mean,
                                                                        r.exit_mean)}
            if carried:
                mod_block["exact"]["pd_exit_mean"] = None
                mod_block["exact"]["note"] = carried_exact_note(stop - start)
            if name in windowed:
                mod_block["exact"]["windowed_exit_mean"] = windowed[name]
                mod_block["exact"]["pd_windowed_exit_mean"] = percentage_difference(
                    windowed[name], r.exit_mean)
            values = None if boot is None else np.asarray(boot.get(name, []), float)
            if carried:
                mod_block["interval_method"] = (
                    "Monte Carlo noise only (the fitting window's bootstrap spreads the "
                    "long-run steady state of a carried property, not a window's values)")
                mod_block["interval_not_formed"] = "not formed for a carried property"
            elif values is not None and values.size >= 2:
                from cfbmarkov.analysis.bootstrap import (BOOTSTRAP_BLOCKS, fitting_runs,
                                                          interval_bounds)

                flow_sd = (abs(sensitivity[name]) * stretch[0] if name in sensitivity
                           and np.isfinite(sensitivity[name]) else None)
                dof = None if flow_sd is None else intervals.flow_degrees_of_freedom
                lo, hi = interval_bounds(p.exit_mean, values, answer.exit_mean, level,
                                         se=p.exit_se if np.isfinite(p.exit_se) else 0.0,
                                         se_flow=flow_sd or 0.0, flow_degrees_of_freedom=dof,
                                         blocks=BOOTSTRAP_BLOCKS,
                                         runs=len(fitting_runs(model)))
                low, high = getattr(kinetics.properties[kinetics.names.index(name)].law,
                                    "initial_range", (None, None))
                mod_block["exit_mean_interval"] = [float(lo if low is None else max(lo, low)),
                                                   float(hi if high is None
                                                         else min(hi, high))]
                mod_block["interval_method"] = (
                    "block bootstrap of the fitting window (exact exit means), Monte Carlo "
                    "noise" + ("" if flow_sd is None else
                               f" and the flow's variability between windows (E(RT)'s "
                               f"{100 * stretch[0]:.3g} %, taken as a stretch of every "
                               "residence)") + ", in quadrature")
                mod_block["flow_sd"] = None if flow_sd is None else {
                    "exit_mean": float(flow_sd), "rt_mean_relative": float(stretch[0]),
                    "degrees_of_freedom": dof}
                mod_block["interval_resamples"] = int(values.size)
            elif resamples:
                mod_block["interval_not_formed"] = (
                    "not formed: the fitting window could not be resampled, as the warning "
                    "says" if values is None else
                    "not formed: fewer than 2 bootstrap resamples have exact answers")
        elif resamples:            # the bootstrap spreads the exact answers, and none exist
            mod_block["interval_not_formed"] = (
                "not formed for a carried property" if carried else
                "not formed without the chain's exact answers, which the bootstrap spreads")
        seg_block = None
        dist_seg = None
        if seg is not None:
            dist_seg = exit_distribution(seg.exit_values, edges)
            seg_block = {**_side(seg.exit_values, seg.exit_mean, seg.exit_sd, seg.exit_se,
                                 level),
                         "bed_mean": seg.bed_mean, "rate": seg.rate, "target": seg.target,
                         "fitting_window": list(model.window),
                         "pd_exit_mean": percentage_difference(seg.exit_mean, r.exit_mean),
                         "md_exit": md(dist_seg)}
        summary[name] = {"law": kinetics.properties[kinetics.names.index(name)].law.key,
                         "start": m["start"], "initial": m["initial"],
                         "reference": ref_block, "model": mod_block,
                         "segregated_flow": seg_block,
                         **({"segregated_flow_note": CARRIED_SEGREGATED_NOTE}
                            if carried else {}),
                         # a frame's time (k x interval) to the digits it is given in
                         "window": [float(f"{start:.12g}"), float(f"{stop:.12g}")],
                         **({"window_note": f"starts {late} lag(s) after the window's start "
                                            "(the prediction's first frames serve as the "
                                            "model's states' history)"} if late else {}),
                         "exit_bins": {"from": float(edges[0]), "to": float(edges[-1]),
                                       "count": n_bins}}
        figures[name] = {"edges": edges, "reference": dist_ref, "model": dist_mod,
                         "segregated_flow": dist_seg, "cell_reference": r.cell_mean,
                         "cell_model": p.cell_mean,
                         "cell_exact": None if answer is None else answer.bed_mean_by_cell,
                         "space": model.state_space,
                         "means": (r.exit_mean, p.exit_mean,
                                   None if seg is None else seg.exit_mean)}
    return {"summary": summary, "figures": figures}


__all__ = ["CARRIED_SEGREGATED_NOTE", "EXIT_BINS", "PROPERTIES_GROUP", "carried_exact_note",
           "check_kinetics_inputs", "exit_mean_agreement", "exit_mean_intervals",
           "compare_kinetics", "exit_bins", "exit_distribution", "needs_cell_fields",
           "stored_definition_differs", "stored_property"]
