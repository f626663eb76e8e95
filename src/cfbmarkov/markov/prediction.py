"""Predictions: a Monte Carlo run of a fitted model from the state of a trajectory file
at a given time, returned as arrays or written as a trajectory file like any other (the
model attached as ``/provenance/model``).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from cfbmarkov._console import clock_text, progress_mode, write_line
from cfbmarkov.errors import InputError
from cfbmarkov.kinetics.fingerprint import FINGERPRINT_METHOD, property_fingerprint
from cfbmarkov.kinetics.spec import on_states
from cfbmarkov.limits import check_disk, check_finite, check_memory, check_seed
from cfbmarkov.markov.discrete import discretize_frame
from cfbmarkov.markov.model_file import model_datasets_and_attrs
from cfbmarkov.markov.states import place_in_cells
from cfbmarkov.trajectories import opened
from cfbmarkov.trajectory_groups import COMPACT_FRAMES, MIN_CHUNK_PARTICLES
from cfbmarkov.trajectory_writer import TrajectoryWriter

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel


def predict(model: "MarkovModel", trajectories, start: float, duration: float, seed: int = 0,
            output: str | os.PathLike | None = None, progress: bool | str = False,
            kinetics=None, force: bool = False):
    """Monte Carlo prediction of ``model`` from the particles' states in the frame at
    ``start``.

    Parameters
    ----------
    model : MarkovModel
        The fitted model.
    trajectories : str, os.PathLike or Trajectories
        The file whose frame at ``start`` gives the initial states.
    start, duration : float
        Start time and length of the prediction (s); ``duration`` a whole number of lags.
    seed : int
        Seed of the Monte Carlo.
    output : str or os.PathLike, optional
        Write the prediction as a trajectory file (positions drawn uniformly inside the
        cells, the model attached as ``/provenance/model``).
    progress : bool or {"bar", "lines"}
        Show progress on stderr while a prediction is run and written to ``output``
        (:class:`PredictionProgress`): True a bar on a terminal and whole lines elsewhere (a
        log file, a pipe); ``"bar"`` or ``"lines"`` that; False quiet.
    kinetics : Kinetics or StateKinetics, optional
        Particle properties carried along the paths (:mod:`cfbmarkov.kinetics`; a
        :class:`~cfbmarkov.kinetics.Kinetics` is resolved on the model's states with the
        model's cell fields, :meth:`~cfbmarkov.kinetics.Kinetics.per_state`): computed by :func:`cfbmarkov.markov.kinetics_mc.run_properties`
        and stored as ``/properties/NAME`` [K+1, N] float64 with the attributes ``law``,
        ``start``, ``initial`` and ``fingerprint`` (the definition on the model's states at
        its lag, :func:`cfbmarkov.kinetics.fingerprint.property_fingerprint`; with
        ``fingerprint_method``). A ``reference`` start takes the file's own values of the
        property at ``start`` for the particles present then.

    force : bool, optional
        Replace an existing ``output`` that is a simulated or imported run or a model
        file; without it those are refused (a prediction replaces a prediction), and
        ``output`` may never be ``trajectories`` itself.

    Returns
    -------
    pathlib.Path or tuple
        The output path, or (times [K+1] s, states [K+1, N], laps [K+1, N]) without one
        (and the properties [P, K+1, N] as a fourth item with ``kinetics``).

    Raises
    ------
    InputError
        If the file cannot be read or does not fit the model, has no frame at
        ``start`` (or lacks the history before it), ``duration`` is not a whole number
        of lags or is shorter than one, the run would not fit in memory or its output on
        the disk (estimated before either is allocated), or the output cannot be
        written (it is the input, or a run or model file without ``force``).

    References
    ----------
    Y. Zhuang, "Markov-Chain-Based Statistic Model for Predicting Particle Movement in
    Circulating Fluidized Bed Risers", Processes 13(3), 614 (2025),
    doi:10.3390/pr13030614 (Eq. 7).
    """
    _warn_sample(model)
    if output is None:
        return _predict(model, trajectories, start, duration, seed, None, progress, kinetics)
    from cfbmarkov._outputs import claim_output

    source = getattr(trajectories, "path", trajectories)
    with claim_output(output, "predict", "prediction", [source], force=force):
        return _predict(model, trajectories, start, duration, seed, output, progress, kinetics)


def _warn_sample(model: "MarkovModel") -> None:
    """Repeat the warnings of the model's fitting-sample verdict, and the one of a chain that
    misses its own fitting window (:class:`SampleWarning`)."""
    import warnings

    from cfbmarkov.errors import SampleWarning

    for line in model.adequacy.warnings if model.adequacy is not None else ():
        warnings.warn(f"the model's fitting sample: {line}", SampleWarning, stacklevel=4)
    from cfbmarkov.markov.model_summary import on_window_warning

    missed = on_window_warning(model)
    if missed:                   # the chain misses its own fitting window
        warnings.warn(f"the model: {missed}", SampleWarning, stacklevel=4)


def _predict(model, trajectories, start, duration, seed, output, progress, kinetics):
    """:func:`predict`, its output claimed."""
    if kinetics is not None:
        kinetics = on_states(kinetics, model.state_space, model.cell_fields)
    with opened(trajectories) as traj:
        seed = check_seed(seed)
        duration = check_finite(duration, "duration", "s", positive=True)
        check_finite(start, "start time", "s")
        n_steps = model.steps_for(duration, "duration")
        if n_steps < 1:
            raise InputError(f"duration {duration:g} s is shorter than one lag ({model.lag:g} s)")
        particles = traj.n_particles + (model.open_flow.inflow_per_lag * n_steps
                                        if model.open_flow is not None else 0)
        # states and laps (int32 each) of every particle at every lag, and the positions;
        # each property carried: a float64 of every particle at every lag
        n_properties = 0 if kinetics is None else len(kinetics.names)
        carried = f" with {n_properties} properties" if n_properties else ""
        check_memory((n_steps + 1.0) * particles * (8 + 8 * n_properties)
                     + 8.0 * particles * traj.dimensions,
                     f"a prediction of {duration:g} s ({n_steps} lags of {model.lag:g} s x "
                     f"{particles:.0f} particles{carried})", "shorten --duration")
        if output is not None:          # uncompressed: every particle a column in every frame;
            stored = particles          # an open riser's file stores the blocks of 256
            if model.open_flow is not None:     # particles present (trajectory_groups)
                stored = min(particles, traj.n_particles + 2.0 * MIN_CHUNK_PARTICLES)
            check_disk((n_steps + 1.0) * stored * (8.0 * traj.dimensions + 5.0
                                                    + 8.0 * n_properties) + 1e6,
                       output, f"a prediction of {duration:g} s ({n_steps + 1} frames x "
                       f"{stored:.0f} particles stored per frame{carried})",
                       "shorten --duration, or write to a disk with more space")
        if model.boundary.is_open and not traj.boundary.is_open:
            raise InputError(f"{traj.path} is a periodic riser; the model is of an open one "
                             "(fit it on this file, or predict from an open riser's file)")
        if not model.boundary.is_open and traj.boundary.is_open:
            raise InputError(f"{traj.path} is an open riser; the model is of a periodic one "
                             "(fit a model on open data)")
        states0, positions0, laps0 = initial_states(model, traj, start)
        # the frame read, within the file's time tolerance of the typed start: its own
        # time dates the prediction (10.0333 typed for a frame at 10.033333333333333)
        start = float(traj.times[traj.frame_index(start)])
        ids = traj.ids
        present0 = states0 >= 0
        here = np.isfinite(positions0).all(axis=1)      # present, with or without a state
        if not present0.any() and model.open_flow is None and here.any():
            memory = model.state_space.memory_lags
            raise InputError(f"{traj.path}: the {int(here.sum())} particles present at "
                             f"{start:g} s have no state in {model.state_space.kind}, which "
                             f"needs them present {memory} lag(s) before (they were absent "
                             "then: a gap in the file), so the prediction has nothing to "
                             f"move; give a later --start (from {start + memory * model.lag:g} "
                             "s, where their history is whole)")
        if not present0.any() and model.open_flow is None:   # nothing to move, no newcomers
            seen = traj.present(slice(None)).any(axis=1) if traj.has_absences else None
            where = ""
            if seen is not None and seen.any():
                where = (f"; particles are present from {traj.times[np.argmax(seen)]:g} s "
                         f"to {traj.times[len(seen) - 1 - np.argmax(seen[::-1])]:g} s (some "
                         "frames between may hold none)")
            raise InputError(f"{traj.path}: no particle is present (with a state) at "
                             f"{start:g} s, so the prediction has nothing to move; give "
                             f"--start at a frame where particles are present{where}")
        _warn_stateless(states0, positions0, model, start)
        if not present0.all():          # only the particles present at the start move
            if model.open_flow is None and not here.all():  # a periodic riser's: out of view
                import warnings

                from cfbmarkov.errors import CfbmarkovWarning

                warnings.warn(f"{int(np.count_nonzero(~here))} of the "
                              f"{present0.size} particles of {traj.path} are absent at "
                              f"{start:g} s and left out: the prediction moves the "
                              f"{int(np.count_nonzero(present0))} present there with a state "
                              "(`compare` follows those on both sides over a window where "
                              "the others stay absent throughout)", CfbmarkovWarning,
                              stacklevel=2)
            states0, positions0, laps0, ids = (states0[present0], positions0[present0],
                                               laps0[present0], ids[present0])
        shown = (PredictionProgress(progress, start, n_steps, model.lag, states0.size)
                 if output is not None else None)
        states, laps = model.monte_carlo(states0, n_steps, seed, laps0,
                                         None if shown is None else shown.ran)
        inlet = None
        if model.open_flow is not None:
            states, inlet = with_inlet_frames(model, states, states0.size)
        times = start + model.lag * np.arange(n_steps + 1)
        if states.shape[1] > ids.size:      # newcomers through the inlet: new ids
            first = int(traj.ids.max()) + 1 if traj.ids.size else 0
            ids = np.concatenate([ids, first + np.arange(states.shape[1] - ids.size)])
        values = None
        if kinetics is not None:
            values = _properties(model, traj, kinetics, start, states, laps,
                                 np.flatnonzero(present0),
                                 None if shown is None else shown.carried)
        if shown is not None:
            shown.chain_done()
        if output is None:
            return (times, states, laps) if values is None else (times, states, laps, values)
        return write_prediction(model, traj, times, states, laps, positions0, seed, output,
                                shown, duration=duration, ids=ids,
                                properties=None if values is None else (kinetics, values),
                                inlet=inlet)


def with_inlet_frames(model: "MarkovModel", states: np.ndarray, n_initial: int
                      ) -> tuple[np.ndarray, np.ndarray | None]:
    """An open riser's run with each newcomer present from the inlet: a state space with
    memory gives a particle its first state :func:`~cfbmarkov.markov.model_rtd.entry_delay`
    lags after it is first seen at the inlet (its entry is counted into that state), so the
    chain's newcomers are shown at the inlet over those lags, in the entry state, as the
    data's particles were; their residences then run from the inlet as the data's do.

    Parameters
    ----------
    model : MarkovModel
        An open riser's model.
    states : ndarray of int32, shape (T, N)
        The run (-1 where absent); the newcomers follow the ``n_initial`` particles.
    n_initial : int
        The particles present at the start.

    Returns
    -------
    states : ndarray of int32, shape (T, N)
        The run with each newcomer (but those of the first lags: frame 0 holds the initial
        file's particles alone) present over the delay before its first state, in that
        state.
    inlet : ndarray of bool, shape (T, N), or None
        Where a particle is shown at the inlet (placed in the bottom row's cell below its
        state's cell); None where the delay is 0 (the cells).
    """
    from cfbmarkov.markov.model_rtd import entry_delay

    delay = entry_delay(model)
    if not delay or states.shape[1] <= n_initial:
        return states, None
    states = np.array(states)
    newcomers = states[:, n_initial:]
    present = newcomers >= 0
    first = np.where(present.any(axis=0), present.argmax(axis=0), -1)
    inlet = np.zeros(states.shape, dtype=bool)
    for shift in range(1, delay + 1):
        has = first - shift >= 1        # frame 0 holds the initial file's particles alone
        columns = np.flatnonzero(has)
        rows = first[has] - shift
        newcomers[rows, columns] = newcomers[first[has], columns]
        inlet[rows, n_initial + columns] = True
    return states, inlet


def _properties(model, traj, kinetics, start, states, laps, present, progress=None
                ) -> np.ndarray:
    """The properties [P, K+1, N] of a run (:func:`predict`), the reference's values at
    ``start`` for a ``reference`` start; ``progress(done, total)`` as in
    :func:`~cfbmarkov.markov.kinetics_mc.run_properties`."""
    from cfbmarkov.markov.kinetics_mc import run_properties

    if model.boundary.is_open and "carried" in kinetics.starts:
        raise InputError("a carried property needs a periodic riser: particles that leave an "
                         "open riser do not come back (use start = entry)")
    initial = np.repeat(kinetics.initial[:, None], states.shape[1], axis=1)
    frame = check_reference_starts(traj, kinetics, start)
    for q, (name, rule) in enumerate(zip(kinetics.names, kinetics.starts)):
        if rule == "reference":
            initial[q, :present.size] = traj.property_values(name, frame)[present]
    # a newcomer shown at the inlet over the lags before its first state
    # (with_inlet_frames) carries its value over them there, with its state's law (one of
    # the first lags, with no earlier frame, starts at the entry value in its first state)
    return run_properties(kinetics, model.lag, states, laps,
                          periodic=not model.boundary.is_open, initial=initial,
                          direction=model.flow_direction, progress=progress,
                          entry_lags=0)


def check_reference_starts(traj, kinetics, start: float) -> int:
    """Check the properties that start from the reference (``start = "reference"``) against
    the file a prediction starts from, before its Monte Carlo runs.

    Parameters
    ----------
    traj : Trajectories
        The open file the prediction starts from.
    kinetics : Kinetics or StateKinetics
        The properties (``names``/``starts`` and their laws).
    start : float
        The start time (s); its nearest frame is read.

    Returns
    -------
    int
        The frame read.

    Raises
    ------
    InputError
        Where the file holds no values of such a property, stores them for another law
        (the file's ``law`` attribute), or holds values at the start outside the law's range
        (a temperature read as a conversion).
    """
    frame = int(np.argmin(np.abs(traj.times - start)))
    properties = getattr(kinetics, "properties", None)
    names = [p.name for p in properties] if properties is not None else list(kinetics.names)
    starts = ([p.start for p in properties] if properties is not None
              else list(kinetics.starts))
    laws = [p.law for p in properties] if properties is not None else list(kinetics.laws)
    for name, rule, law in zip(names, starts, laws):
        if rule != "reference":
            continue
        if name not in traj.property_names:
            raise InputError(f"property {name} starts from the reference, but {traj.path} "
                             f"holds no values of it (properties: "
                             f"{', '.join(traj.property_names) or 'none'}); use start = "
                             "entry (or carried, on a periodic riser)")
        stored = traj.property_attrs(name).get("law")
        if isinstance(stored, bytes):
            stored = stored.decode(errors="replace")
        if stored is not None and str(stored) != law.key:
            raise InputError(f"property {name} starts from the reference, but {traj.path} "
                             f"stores {name} of law {stored}, not {law.key}: its values are "
                             "another quantity; name the property as the file does, or use "
                             "start = entry")
        low, high = getattr(law, "initial_range", (None, None))
        values = np.asarray(traj.property_values(name, frame), dtype=np.float64)
        finite = values[np.isfinite(values)]
        if finite.size and ((low is not None and finite.min() < low)
                            or (high is not None and finite.max() > high)):
            span = f"[{low:g}, {high:g}]" if high is not None else f"[{low:g}, inf)"
            raise InputError(f"property {name} starts from the reference, but {traj.path}'s "
                             f"values of it at {float(traj.times[frame]):g} s run "
                             f"{finite.min():g} to {finite.max():g}, outside {span}, the "
                             f"range of {law.quantity} (law {law.key}); name the property as "
                             "the file does, or use start = entry")
    return frame


def _warn_stateless(states0: np.ndarray, positions0: np.ndarray, model: "MarkovModel",
                    start: float) -> None:
    """Warn where particles present in the start frame have no state: on an open riser,
    those that entered within the state space's memory before it, on a periodic one those
    absent within it (a gap); their history is incomplete, and they are left out of the
    prediction."""
    import warnings

    from cfbmarkov.errors import CfbmarkovWarning

    seen = np.isfinite(positions0).all(axis=1)
    missing = int(np.count_nonzero(seen & (states0 < 0)))
    if not missing:
        return
    memory = model.state_space.memory_lags
    if model.open_flow is not None:
        why = (f"they entered less than its memory, {memory} lag(s), before that frame) and "
               "are left out of the prediction (its newcomers of the next lags stand for "
               "them; ")
    else:
        why = (f"they were absent within its memory, {memory} lag(s), before that frame: a "
               "gap in the file) and are left out of the prediction (a later --start, where "
               "their history is whole, keeps them; ")
    warnings.warn(f"{missing} of {int(seen.sum())} particles present at {start:g} s have no "
                  f"state in {model.state_space.kind} ({why}`compare` follows the particles "
                  "it started on both sides); a model on cells keeps them all",
                  CfbmarkovWarning, stacklevel=3)


def initial_states(model: "MarkovModel", trajectories, start: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States, positions and laps of the particles in the frame at ``start``.

    The frame is discretised with the history the state space needs.

    Parameters
    ----------
    model : MarkovModel
    trajectories : str, os.PathLike or Trajectories
        A trajectory file, by path or open.
    start : float
        Time of the frame (s).

    Returns
    -------
    states : ndarray of int32, shape (N,)
    positions : ndarray of float64, shape (N, 2)
        Positions (m).
    laps : ndarray of int32, shape (N,)

    Raises
    ------
    InputError
        If the file does not fit the model's domain, has no frame at ``start``, lacks
        the history before it, or the lag is not a whole number of its frames.
    """
    frame = discretize_frame(trajectories, model.state_space, model.lag, start)
    return frame.states[-1], frame.positions[-1], frame.laps[-1]


def write_prediction(model: "MarkovModel", trajectories, times: np.ndarray,
                     states: np.ndarray, laps: np.ndarray, first_positions: np.ndarray,
                     seed: int, output: str | os.PathLike,
                     progress: "bool | str | PredictionProgress" = False,
                     duration: float | None = None, ids: np.ndarray | None = None,
                     properties=None, inlet: np.ndarray | None = None) -> Path:
    """Write a Monte Carlo run of ``model`` as a trajectory file (a prediction).

    The first frame keeps the actual positions it started from; later frames place each
    particle uniformly inside the cell of its state (seeded by (seed, particle, step)). The
    model is attached as ``/provenance/model``. From a 3D file the prediction is 3D (same
    depth); a 2D grid's cell spans the whole depth, so there the depth is drawn uniformly.

    Parameters
    ----------
    model : MarkovModel
    trajectories : Trajectories
        The open file the run started from (ids, domain, provenance).
    times : ndarray of float64, shape (K + 1,)
        Frame times (s), one lag apart.
    states, laps : ndarray of int32, shape (K + 1, N)
        The Monte Carlo states and lap counters.
    first_positions : ndarray of float64, shape (N, D)
        Positions (m) of the first frame (D = 3 from a 3D file).
    seed : int
        The seed of the run (also seeds the placement inside cells).
    output : str or os.PathLike
        The trajectory file to write (atomically).
    progress : bool, {"bar", "lines"} or PredictionProgress
        Show the frames written on stderr (as ``progress`` of :func:`predict`; a
        :class:`PredictionProgress` already started goes on).
    duration : float, optional
        The prediction's length as asked for (s), recorded in the file's parameters
        (default: K lags).
    ids : ndarray of int64, shape (N,), optional
        The particles' ids (default: the file's). Where a state is -1 the particle is
        absent (an open riser's newcomers before they enter, particles after they leave);
        the first frame's positions are those of the first ``first_positions.shape[0]``.
    properties : tuple (StateKinetics, ndarray of float64 [P, K+1, N]), optional
        Particle properties to store as ``/properties/NAME`` (:func:`predict`).
    inlet : ndarray of bool, shape (K+1, N), optional
        Where a newcomer is shown at the inlet before its first state
        (:func:`with_inlet_frames`): placed in the bottom row's cell below its state's.

    Returns
    -------
    pathlib.Path
        ``output``.

    Raises
    ------
    InputError
        If the file cannot be written.
    """
    traj = trajectories
    n_steps = times.size - 1
    duration = float(n_steps * model.lag if duration is None else duration)
    start = float(times[0])
    parameters = {"model": model.describe(), "seed": int(seed), "start": start,
                  "duration": duration, "initial_frames": str(traj.path),
                  "columns": model.state_space.columns, "rows": model.state_space.rows}
    if model.state_space.is_3d:
        parameters["depth_columns"] = model.state_space.depth_columns
    ids = traj.ids if ids is None else ids
    some_absent = bool((states < 0).any())
    with TrajectoryWriter(output, ids, width=traj.width, height=traj.height,
                          depth=traj.depth, source="markov-prediction", parameters=parameters,
                          frame_interval=model.lag, boundary=model.boundary.value,
                          axes=dict(traj.axes), region_origin=traj.region_origin
                          ) as writer:        # the source's frame, as the initial file's
        writer.attach("model", *model_datasets_and_attrs(model))
        bar = (progress if isinstance(progress, PredictionProgress)
               else PredictionProgress(progress, start, n_steps, model.lag, ids.size))
        first = np.full((ids.size, first_positions.shape[1]), np.nan)
        first[:first_positions.shape[0]] = first_positions
        cells = model.state_space.cell_of_state
        # blocks of whole chunks of frames (an open riser's file holds 16 frames a chunk):
        # a block that ended inside a chunk would have it read back, merged and deflated again
        block = 2 * COMPACT_FRAMES
        for k0 in range(0, n_steps + 1, block):
            ks = range(k0, min(k0 + block, n_steps + 1))
            k1 = max(ks.start, 1)       # the first frame is the initial file's
            block_states = states[k1:ks.stop]
            block_cells = np.where(block_states >= 0, cells[np.maximum(block_states, 0)], -1)
            if inlet is not None:       # at the inlet: the bottom row's cell below it
                per_row = model.state_space.columns * (
                    model.state_space.depth_columns if model.state_space.is_3d else 1)
                block_cells = np.where(inlet[k1:ks.stop], block_cells % per_row, block_cells)
            positions = place_in_cells(block_cells, model.state_space, seed, k1, traj.depth)
            if ks.start == 0:
                positions = np.concatenate([first[None], positions])
            writer.append_frames(times[ks.start:ks.stop], positions, laps=laps[ks.start:ks.stop],
                                 present=(states[ks.start:ks.stop] >= 0) if some_absent else None)
            bar.written(ks.stop - 1)
        if properties is not None:
            kin, values = properties
            for q, name in enumerate(kin.names):
                writer.add_property(name, values[q], {
                    "law": kin.laws[q].key, "start": kin.starts[q],
                    "initial": float(kin.initial[q]),
                    "entries": model.flow_direction,
                    "fingerprint": property_fingerprint(kin, q, model.lag,
                                                        model.flow_direction),
                    "fingerprint_method": FINGERPRINT_METHOD})
    bar.close(output)
    return Path(output)


#: wall seconds between two lines of progress (``progress="lines"``) while the Monte Carlo
#: runs, its properties are carried or frames are written
LINE_INTERVAL = 10.0


class PredictionProgress:
    """Progress of a prediction on stderr: the Monte Carlo run (with the properties it
    carries), then its frames written.

    As bars redrawn in place (for a terminal: the lags run, the properties' share done,
    then the lags written), or as whole lines starting with ``predict:`` (readable in a log
    file): one at the start, one every :data:`LINE_INTERVAL` s of wall time while the Monte
    Carlo runs, its properties are carried or frames are written, one when the Monte Carlo
    is done and one at the end.

    Parameters
    ----------
    progress : bool, None or {"bar", "lines"}
        As ``progress`` of :func:`predict`: True a bar where stderr is a terminal and lines
        where it is not; False or None quiet.
    start : float
        Time of the first frame (s).
    n_steps : int
        Number of lags predicted.
    lag : float
        The model's lag (s).
    particles : int
        Particles at the start.

    Raises
    ------
    InputError
        If ``progress`` is none of these.
    """

    def __init__(self, progress, start: float, n_steps: int, lag: float, particles: int):
        self.mode = progress_mode(progress)
        self.start, self.n_steps, self.lag = start, n_steps, lag
        self.t0 = self.t_line = self.t_stage = time.perf_counter()
        self.t_chain = None
        self.done = 0
        self.bar = self.run_bar = None
        self.carrying = False
        span = f"{n_steps * lag:g} s from t = {start:g} s ({n_steps} lags of {lag:g} s)"
        if self.mode == "bar":
            self.run_bar = self._bar(n_steps, f"predict {n_steps * lag:g} s: Monte Carlo",
                                     "lags run", leave=False)
        elif self.mode == "lines":
            self._line(f"{span}, {particles} particles: Monte Carlo, then the frames written")

    @staticmethod
    def _bar(total: int, desc: str, counted: str, leave: bool):
        from tqdm import tqdm

        return tqdm(total=total, file=sys.stderr, leave=leave, desc=desc, dynamic_ncols=True,
                    bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} "
                               f"{counted} [{{elapsed}} so far, {{remaining}} left]")

    def _line(self, text: str) -> None:
        write_line(f"predict: {text}")

    def _due(self) -> float | None:
        """The wall time now where a line is due, else None."""
        now = time.perf_counter()
        return now if now - self.t_line >= LINE_INTERVAL else None

    def ran(self, steps: int) -> None:
        """The Monte Carlo has run ``steps`` of its lags (0 .. n_steps)."""
        if self.run_bar is not None:
            self.run_bar.update(steps - self.run_bar.n)
        elif self.mode == "lines" and 0 < steps < self.n_steps and (now := self._due()):
            left = (now - self.t0) * (self.n_steps - steps) / steps
            self._line(f"Monte Carlo {steps * self.lag:g}/{self.n_steps * self.lag:g} s run, "
                       f"{clock_text(now - self.t0)} so far, about {clock_text(left)} left")
            self.t_line = now

    def carried(self, done: int, total: int) -> None:
        """The properties are carried along ``done`` of the ``total`` lags to go over (a
        pass over the run for the linear laws, one for each custom law)."""
        if not self.carrying:
            self.carrying, self.t_stage = True, time.perf_counter()
            if self.run_bar is not None:
                self.run_bar.reset(total=total)
                self.run_bar.set_description_str(f"predict {self.n_steps * self.lag:g} s: "
                                                 "properties")
        if self.run_bar is not None:
            self.run_bar.update(done - self.run_bar.n)
        elif self.mode == "lines" and 0 < done < total and (now := self._due()):
            left = (now - self.t_stage) * (total - done) / done
            self._line(f"properties {100.0 * done / total:.0f} % carried, "
                       f"{clock_text(now - self.t0)} so far, about {clock_text(left)} left")
            self.t_line = now

    def chain_done(self) -> None:
        """The Monte Carlo run (and its properties) is done; the frames are written next."""
        self.t_chain = time.perf_counter()
        if self.run_bar is not None:
            self.run_bar.close()
            self.run_bar = None
        if self.mode == "bar":
            self.bar = self._bar(self.n_steps, f"predict {self.n_steps * self.lag:g} s",
                                 "lags written", leave=True)
        elif self.mode == "lines":
            self._line(f"Monte Carlo done in {clock_text(self.t_chain - self.t0)}; writing "
                       f"{self.n_steps + 1} frames")

    def written(self, steps: int) -> None:
        """Frames up to lag ``steps`` (0 .. n_steps) are written."""
        if self.mode is None or steps <= self.done:
            return
        if self.bar is not None:
            self.bar.update(steps - self.done)
        elif steps < self.n_steps:
            now = time.perf_counter()
            if now - self.t_line >= LINE_INTERVAL:
                begun = self.t_chain if self.t_chain is not None else self.t0
                left = (now - begun) * (self.n_steps - steps) / steps
                self._line(f"{steps * self.lag:g}/{self.n_steps * self.lag:g} s written, "
                           f"{clock_text(now - self.t0)} so far, about {clock_text(left)} left")
                self.t_line = now
        self.done = steps

    def close(self, output) -> None:
        """The prediction is written to ``output``."""
        if self.bar is not None:
            self.bar.close()
        elif self.mode == "lines":
            self._line(f"{self.n_steps * self.lag:g} s written to {output} in "
                       f"{clock_text(time.perf_counter() - self.t0)}")
