"""The reference side of the kinetics: properties integrated along the observed paths of a
CFD-DEM run or an imported file (``docs/definitions.md``, Properties along observed paths).

The file's frames of a window are turned into the model's states at the model's lag
(:func:`cfbmarkov.markov.discretize`, every ``lag_frames``-th frame), and each particle's
value is advanced lag by lag with the same per-state affine maps the chain uses
(:meth:`cfbmarkov.kinetics.StateKinetics.over`), restarting at each entry where the
property's start rule is ``entry``: a periodic riser's record pass up through the top (as
:mod:`cfbmarkov.observed.residence` counts residences), an open riser's appearance at the
inlet. What comes out is the value at every exit (with its residence time) and the bed's
mean over time, per frame and per cell: what the model is judged against, like for like.

All particles start the window at the property's entry value, as a prediction started at
the window's first frame does; with ``start = reference`` at the values integrated along
the file's paths from its first frame (:func:`values_at`). Where the value restarts at
entry (``entry`` and ``reference``) only the exits of residences that began inside the
window count (those whose start value is known: the residence-time samples of the RTD);
with ``carried`` every exit counts.

With a ``history`` (:func:`reference_kinetics`), the exits are instead every exit inside the
window whose residence began after the window's start minus the history: the paths are
followed back before the window, so that a residence that began before the window counts
with its whole path. Counted by their exits, residences are a fair sample of the flow's
(each residence ends once, whatever its length), which the exits of residences wholly
inside a window are not: a window of W s sees a residence of t s only where it begins in
the first W - t s, so long residences are under-counted. Exits whose residence began
before the history's start are left out and counted (``exits_censored``). The bed's means
stay those of the window.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfbmarkov.analysis.kinetics_paths import integrate_open, integrate_periodic, records_bound
from cfbmarkov.analysis.exit_statistics import ExitStatistics
from cfbmarkov.errors import InputError
from cfbmarkov.markov.cells import cell_index
from cfbmarkov.observed.residence import DEFAULT_FACE_ROWS, lag_face_heights


@dataclass(frozen=True)
class PathKinetics(ExitStatistics):
    """One property integrated along the paths of one window.

    Attributes
    ----------
    name : str
        The property.
    exit_values : ndarray of float64, shape (K,)
        The value at each counted exit, in the order the exits happen (by frame, then
        particle).
    exit_times : ndarray of float64, shape (K,)
        Their times (s).
    residence_times : ndarray of float64, shape (K,)
        Their residence times (s; NaN where the entry lies before the window, only with a
        carried property).
    times : ndarray of float64, shape (T,)
        The frames one lag apart (s).
    bed_mean : ndarray of float64, shape (T,)
        The mean value over the particles in the riser in each frame.
    cell_mean : ndarray of float64, shape (C,)
        The mean value per cell over the window's particle-frames (NaN in a cell never
        visited), cells of the model's grid.
    cell_occupancy : ndarray of float64, shape (C,)
        The particle-frames counted per cell.
    final_values : ndarray of float64, shape (N,)
        Each particle's value in the last frame.
    exits_censored : int
        With a history (:func:`reference_kinetics`): the exits inside the window whose
        residence began before the history's start, left out; 0 otherwise.
    """

    name: str
    exit_values: np.ndarray
    exit_times: np.ndarray
    residence_times: np.ndarray
    times: np.ndarray
    bed_mean: np.ndarray
    cell_mean: np.ndarray
    cell_occupancy: np.ndarray
    final_values: np.ndarray | None = None
    exits_censored: int = 0

    @property
    def time_mean(self) -> float:
        """The bed's mean value averaged over the frames."""
        finite = self.bed_mean[np.isfinite(self.bed_mean)]
        return float(finite.mean()) if finite.size else float("nan")


def integrate_along_paths(discrete, a, b, initial, *, reset: bool, name: str = "",
                          direction: str = "up", face_band: float | None = None,
                          entry_value: float | None = None, stored=None) -> PathKinetics:
    """Integrate one property along discrete trajectories (states one lag apart).

    Parameters
    ----------
    discrete : DiscreteTrajectories
        The window's states; a periodic riser's must hold ``laps``, and an open riser's
        with a state space with memory ``positions`` (:func:`cfbmarkov.markov.discretize`
        with ``keep_positions=True``). Every
        ``lag_frames``-th frame from the first is used.
    a, b : array_like of float64, shape (S,)
        The lag's affine map per state, v' = a v + b.
    initial : float or array_like of float64, shape (N,)
        Every particle's value in the first frame (one number: all alike).
    reset : bool
        Restart at ``initial`` at each entry (``start = entry``); else carried.
    name : str, optional
        The property's name.
    direction : {"up", "down"}, optional
        Periodic riser: exits are record passes up through the top, or down through the
        bottom where the net solids flow is downward.
    face_band : float, optional
        Open riser: how close to a face (m) a particle must appear or vanish to have
        crossed it (default one row of the model's grid).
    entry_value : float, optional
        The value v0 after each entry with ``reset`` (default ``initial``, which must then
        be one number).
    stored : array_like of float64, shape (T', N), optional
        The values a Monte Carlo run stored in the same frames (every frame of
        ``discrete``): they stand in each frame instead of the integrated ones, and each
        exit's value is the lag's map of the stored value in the frame before it
        (the model side of a comparison).

    Returns
    -------
    PathKinetics

    Raises
    ------
    InputError
        When the maps do not hold one value per state, are not finite, a periodic riser's
        trajectories carry no laps, an open riser's with a state space with memory no
        positions, or ``direction`` is unknown.
    """
    space = discrete.state_space
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    if a.shape != (space.n_states,) or b.shape != a.shape:
        raise InputError(f"property {name}: maps of shape {a.shape}, {b.shape} for "
                         f"{space.n_states} states")
    n_particles = discrete.states.shape[1]
    value = np.array(np.broadcast_to(np.asarray(initial, dtype=np.float64), (n_particles,)))
    if entry_value is None:
        if np.ndim(initial) != 0:
            raise InputError(f"property {name}: give its entry value beside per-particle "
                             "start values")
        entry_value = float(initial)
    if not (np.isfinite(a).all() and np.isfinite(b).all() and np.isfinite(value).all()
            and np.isfinite(entry_value)):
        raise InputError(f"property {name}: its per-state maps or start value are not finite")
    if direction not in ("up", "down"):
        raise InputError(f"residence direction {direction!r}: up or down")
    rows = slice(None, None, int(discrete.lag_frames))
    states = np.ascontiguousarray(discrete.states[rows], dtype=np.int32)
    times = np.ascontiguousarray(discrete.times[rows], dtype=np.float64)
    n_frames, n_particles = states.shape
    cell_of_state = np.ascontiguousarray(space.cell_of_state, dtype=np.int64)
    n_cells = int(space.n_cells)
    bed_mean = np.empty(n_frames)
    use_stored = stored is not None
    if use_stored:
        stored = np.ascontiguousarray(np.asarray(stored, dtype=np.float64)[rows])
        if stored.shape != states.shape:
            raise InputError(f"property {name}: stored values of shape {stored.shape} for "
                             f"{states.shape} frames x particles")
    else:
        stored = np.zeros((1, 1))
    cell_sum, cell_count = np.zeros(n_cells), np.zeros(n_cells)
    bed_cells = np.where(states >= 0, cell_of_state[np.maximum(states, 0)], -1)
    if discrete.boundary == "open":
        # the heights where a particle is first and last seen on the frames between the
        # lag's: it crosses a face there (judged on the lag's frames alone, the exits of
        # those first seen above the inlet's band were dropped, the conversion biased)
        first_seen, last_seen = lag_face_heights(discrete.vertical, discrete.lag_frames,
                                                 np.arange(discrete.n_frames)[rows])
        present = np.isfinite(np.asarray(discrete.vertical[rows], dtype=np.float64))
        vertical = np.ascontiguousarray(first_seen)
        stateless = present & (states < 0)
        if stateless.any():
            # a particle in the riser without a state yet (a state space with memory, the
            # lag after its entry) is in the bed: in the cell where it is
            if discrete.positions is None:
                raise InputError("the discrete trajectories of an open riser with a state "
                                 "space with memory carry no positions: discretise with "
                                 "keep_positions=True")
            bed_cells[stateless] = cell_index(
                discrete.positions[rows][stateless], space.width, space.height,
                space.columns, space.rows, space.depth, space.depth_columns)
        band = discrete.height / space.rows if face_band is None else float(face_band)
        if not np.isfinite(band):
            band = discrete.height / DEFAULT_FACE_ROWS
        size = int(present.sum())
        exit_value, exit_time, exit_rt = np.empty(size), np.empty(size), np.empty(size)
        n = integrate_open(times, states, present, np.nan_to_num(vertical),
                           np.ascontiguousarray(np.nan_to_num(last_seen)), band,
                           float(discrete.height), a, b, float(entry_value), bool(reset), value,
                           stored, use_stored, bed_cells, exit_value, exit_time, exit_rt,
                           bed_mean, cell_sum, cell_count)
    else:
        if discrete.laps is None:
            raise InputError("the discrete trajectories carry no lap counters: discretise "
                             "with keep_positions=True")
        sign = 1 if direction == "up" else -1
        laps = np.ascontiguousarray(sign * discrete.laps[rows].astype(np.int64))
        size = records_bound(laps)
        exit_value, exit_time, exit_rt = np.empty(size), np.empty(size), np.empty(size)
        n = integrate_periodic(times, states, laps, a, b, float(entry_value), bool(reset), value,
                               stored, use_stored, bed_cells, exit_value, exit_time,
                               exit_rt, bed_mean, cell_sum, cell_count)
    keep = np.isfinite(exit_rt[:n]) if reset else np.ones(n, bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        cell_mean = np.where(cell_count > 0, cell_sum / np.maximum(cell_count, 1), np.nan)
    return PathKinetics(name, exit_value[:n][keep].copy(), exit_time[:n][keep].copy(),
                        exit_rt[:n][keep].copy(), times, bed_mean, cell_mean, cell_count, value)


def reference_kinetics(source, model, state_kinetics, window: tuple[float, float], *,
                       direction: str = "up", face_band: float | None = None,
                       history: float = 0.0, starts: np.ndarray | None = None
                       ) -> dict[str, PathKinetics]:
    """Every property of ``state_kinetics`` integrated along the paths of a file's window.

    Every particle starts the window at the property's entry value; a property whose start
    rule is ``reference`` starts at the values :func:`values_at` gives (integrated from the
    file's first frame), as a prediction that takes the reference's values does.

    With ``history`` > 0 the exits of a property that restarts at entry are every exit
    inside the window whose residence began at most ``history`` s before the window's start
    (cut at the file's first frame), its value integrated along the whole path; the exits
    of residences that began earlier are left out and counted (module docstring). These
    exits sample the residences fairly, and their mean is comparable with the chain's exact
    exit mean per residence (:func:`cfbmarkov.markov.kinetics_exact.exact_kinetics`);
    without a history the exits are those of residences wholly inside the window, which
    favour short residences (compare with
    :func:`cfbmarkov.markov.kinetics_exact.windowed_exit_means`).

    Parameters
    ----------
    source : str, os.PathLike or Trajectories
        The reference trajectory file (CFD-DEM or imported).
    model : MarkovModel
        The model whose state space and lag the states use.
    state_kinetics : StateKinetics
        The kinetics per state of the model's space
        (:meth:`cfbmarkov.kinetics.Kinetics.per_state`); only linear laws.
    window : (float, float)
        The window (s).
    direction : {"up", "down"}, optional
        As :func:`integrate_along_paths`.
    face_band : float, optional
        As :func:`integrate_along_paths`.
    history : float, optional
        Seconds before the window from which exits' paths are followed (>= 0; 0: only
        residences wholly inside the window). Needs a periodic riser.
    starts : ndarray of float64, shape (P, N), optional
        The values at the window's first frame of the properties that start from the
        reference (:func:`reference_starts`, computed here where not given).

    Returns
    -------
    dict of str to PathKinetics
        By property name, in the kinetics' order.

    Raises
    ------
    InputError
        When the file cannot be discretised on the model's states at its lag over the
        window (:func:`cfbmarkov.markov.discretize`), a property's law is not linear, or the
        history is negative, not finite, or given for an open riser.
    """
    from cfbmarkov.markov.discrete import discretize
    from cfbmarkov.trajectories import opened

    maps = linear_maps(state_kinetics, model.lag)
    with opened(source) as traj:
        discrete = discretize(traj, model.state_space, model.lag, tuple(window),
                              keep_positions=True)
        if starts is None and any(m["start"] == "reference" for m in maps):
            starts = reference_starts(traj, model, state_kinetics, float(discrete.times[0]),
                                      direction=direction, face_band=face_band)
    out = {}
    for i, m in enumerate(maps):
        initial = starts[i] if m["start"] == "reference" else m["initial"]
        out[m["name"]] = integrate_along_paths(discrete, m["a"], m["b"], initial,
                                               entry_value=m["initial"], reset=m["reset"],
                                               name=m["name"], direction=direction,
                                               face_band=face_band)
    if history:
        out = _with_history(source, model, maps, tuple(window), out, history, direction)
    return out


def _with_history(source, model, maps, window, out, history, direction):
    """``out`` with each restarting property's exits replaced by every exit inside the
    window whose path is followed back at most ``history`` s (:func:`reference_kinetics`)."""
    from dataclasses import replace

    from cfbmarkov.markov.discrete import discretize
    from cfbmarkov.trajectories import opened

    history = float(history)
    if not (np.isfinite(history) and history >= 0):
        raise InputError(f"history {history!r} s: a finite number of seconds >= 0")
    with opened(source) as traj:
        if traj.boundary.is_open:
            raise InputError(f"{traj.path}: the history of exits is read from a periodic "
                             "riser's lap counters (an open riser's residences are its "
                             "passes from the inlet to the outlet)")
        first = max(float(traj.times[0]), window[0] - history)
        discrete = discretize(traj, model.state_space, model.lag, (first, window[1]),
                              keep_positions=True, short_history="skip")
    start = window[0] + 1e-9 * max(1.0, abs(window[0]))
    # a particle's first record in the read span ends a residence of unknown entry: censored
    # where it lies inside the window
    rows = slice(None, None, int(discrete.lag_frames))
    sign = 1 if direction == "up" else -1
    laps = sign * discrete.laps[rows].astype(np.int64)
    raised = np.maximum.accumulate(laps, axis=0) > laps[0]
    first = np.where(raised.any(axis=0), raised.argmax(axis=0), -1)
    times = discrete.times[rows]
    censored = int(np.count_nonzero((first > 0) & (times[np.maximum(first, 0)] > start)))
    for m in maps:
        if not m["reset"]:
            continue
        whole = integrate_along_paths(discrete, m["a"], m["b"], m["initial"], reset=True,
                                      name=m["name"], direction=direction)
        inside = whole.exit_times > start
        out[m["name"]] = replace(out[m["name"]], exit_values=whole.exit_values[inside].copy(),
                                 exit_times=whole.exit_times[inside].copy(),
                                 residence_times=whole.residence_times[inside].copy(),
                                 exits_censored=censored)
    return out


def reference_starts(source, model, state_kinetics, time: float, *, direction: str = "up",
                     face_band: float | None = None) -> np.ndarray:
    """Every particle's values at ``time`` of the properties that start from the reference
    (``start = "reference"``): those the file stores there (``/properties/NAME``, the values
    a prediction with ``--init`` that file takes; the entry value where a particle's is
    NaN), else the values integrated along its paths from its first frame
    (:func:`values_at`); the other properties' entry values.

    Parameters
    ----------
    source : str, os.PathLike or Trajectories
        The reference trajectory file.
    model, state_kinetics, time, direction, face_band
        As :func:`values_at`.

    Returns
    -------
    ndarray of float64, shape (P, N)
        Per property, each particle's value (the file's particle order).

    Raises
    ------
    InputError
        As :func:`reference_kinetics`.
    """
    from cfbmarkov.trajectories import opened

    maps = linear_maps(state_kinetics, model.lag)
    with opened(source) as traj:
        stored = set(traj.property_names)
        integrate = any(m["start"] == "reference" and m["name"] not in stored for m in maps)
        values = (values_at(traj, model, state_kinetics, time, direction=direction,
                            face_band=face_band) if integrate
                  else np.array([np.full(traj.n_particles, m["initial"]) for m in maps]))
        frame = int(np.argmin(np.abs(traj.times - time)))
        for i, m in enumerate(maps):
            if m["start"] == "reference" and m["name"] in stored:
                law = traj.property_attrs(m["name"]).get("law")
                law = law.decode(errors="replace") if isinstance(law, bytes) else law
                if law is not None and str(law) != state_kinetics.laws[i].key:
                    raise InputError(
                        f"property {m['name']} starts from the reference, but {traj.path} "
                        f"stores {m['name']} of law {law}, not {state_kinetics.laws[i].key}: "
                        "its values cannot start it (a prediction from that file refuses "
                        "them too); rename the property, or use start = entry")
                held = np.asarray(traj.property_values(m["name"], frame), dtype=np.float64)
                values[i] = np.where(np.isfinite(held), held, m["initial"])
    return values


def values_at(source, model, state_kinetics, time: float, *, direction: str = "up",
              face_band: float | None = None) -> np.ndarray:
    """Every particle's values at ``time``, integrated along the file's paths from its first
    frame (all particles at the entry value there): the reference's values where it stores
    none (:func:`reference_starts`).

    Parameters
    ----------
    source : str, os.PathLike or Trajectories
        The reference trajectory file.
    model : MarkovModel
        The model whose state space and lag the states use.
    state_kinetics : StateKinetics
        The kinetics per state of the model's space.
    time : float
        A frame time of the file (s).
    direction, face_band
        As :func:`integrate_along_paths`.

    Returns
    -------
    ndarray of float64, shape (P, N)
        Per property, each particle's value (the file's particle order); the entry value
        for all where ``time`` is the file's first frame (or lies within one lag of it).

    Raises
    ------
    InputError
        As :func:`reference_kinetics`.
    """
    from cfbmarkov.markov.discrete import discretize
    from cfbmarkov.trajectories import opened

    maps = linear_maps(state_kinetics, model.lag)
    with opened(source) as traj:
        first = float(traj.times[0])
        n = traj.n_particles
        values = np.array([np.full(n, m["initial"]) for m in maps])
        if time - first < model.lag * (1 - 1e-9):
            return values
        discrete = discretize(traj, model.state_space, model.lag, (first, float(time)),
                              keep_positions=True, short_history="skip")
    for i, m in enumerate(maps):
        values[i] = integrate_along_paths(discrete, m["a"], m["b"], m["initial"],
                                          reset=m["reset"], direction=direction,
                                          face_band=face_band).final_values
    return values


def linear_maps(state_kinetics, lag: float) -> list[dict]:
    """The per-state maps of every property of a :class:`~cfbmarkov.kinetics.StateKinetics`.

    Parameters
    ----------
    state_kinetics : StateKinetics
        Per-state kinetics of a model's space.
    lag : float
        The lag (s).

    Returns
    -------
    list of dict
        Per property: ``name``, ``a`` and ``b`` [S], ``initial`` (the entry value),
        ``start``, ``reset`` (whether the value restarts at each entry: every start rule
        but ``carried``), ``rate`` and ``target`` [S] (k in 1/s and v_inf).

    Raises
    ------
    InputError
        For a law that is not a linear relaxation.
    """
    a, b = state_kinetics.over(lag)
    out = []
    for i, name in enumerate(state_kinetics.names):
        if not state_kinetics.linear[i]:
            raise InputError(f"property {name}: law {state_kinetics.laws[i].key} is not a "
                             "linear relaxation; the reference side and the segregated-flow "
                             "baseline need one")
        start = state_kinetics.starts[i]
        out.append({"name": name, "a": a[i], "b": b[i],
                    "initial": float(state_kinetics.initial[i]), "start": start,
                    "reset": start != "carried", "rate": state_kinetics.rate[i],
                    "target": state_kinetics.target[i]})
    return out


__all__ = ["PathKinetics", "integrate_along_paths", "linear_maps", "reference_kinetics",
           "reference_starts", "values_at"]
