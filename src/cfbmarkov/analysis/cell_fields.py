"""The time-averaged cell fields of a window of a trajectory file: per cell of a model's
grid, the solids fraction, the distance to the nearest wall and the mean vertical velocity
(``docs/definitions.md``, Properties along observed paths, Cell fields). Rates of a
kinetics file given as a function of them (``rate_from``) are evaluated on these fields of
the model's fitting window.

- *Solids fraction*: particle area (a 2D file: discs, pi d^2 / 4) or volume (a 3D file:
  spheres, pi d^3 / 6) per cell area or volume, averaged over the window's frames; the
  particle diameter d is the one the CFD-DEM wrote in the file's parameters
  (``particles.diameter``). Where the file gives none, the fraction is the cell's mean count
  relative to the mean over all cells (``relative`` is then true: 1 is the bed's mean).
- *Distance to the nearest wall*: from the cell's centre to the nearest side wall (x = 0
  or x = W, and the depth walls of a 3D grid), m.
- *Mean vertical velocity*: the particles' vertical velocity averaged over the
  particle-frames in the cell (the file's velocities, else displacements over one frame by
  the minimal-image rule in a periodic riser), m/s; NaN in a cell never visited.
"""

from __future__ import annotations

import math

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.frame_times import window_pair
from cfbmarkov.markov.cells import cell_index

#: frames read per block
_BLOCK = 128


def particle_diameter(parameters) -> float | None:
    """The particle diameter (m) a trajectory file's producer wrote, or None.

    Parameters
    ----------
    parameters : dict
        The file's ``parameters`` (a CFD-DEM run: its case, ``particles.diameter``).

    Returns
    -------
    float or None
    """
    if not isinstance(parameters, dict):
        return None
    particles = parameters.get("particles")
    value = particles.get("diameter") if isinstance(particles, dict) else None
    if value is None:
        value = parameters.get("particle_diameter", parameters.get("diameter"))
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) and value > 0 else None


def wall_distance(space) -> np.ndarray:
    """Distance (m) from each cell's centre to the nearest side wall.

    Parameters
    ----------
    space : StateSpace
        A sized state space (its cell grid).

    Returns
    -------
    ndarray of float64, shape (C,)
        In cell order ((row*d + k)*m + col).
    """
    m, d, n = space.columns, space.depth_columns, space.rows
    x = (np.arange(m) + 0.5) * space.width / m
    across = np.minimum(x, space.width - x)
    if space.depth is not None:
        z = (np.arange(d) + 0.5) * space.depth / d
        along = np.minimum(z, space.depth - z)
        per_row = np.minimum(across[None, :], along[:, None]).reshape(-1)     # [d * m]
    else:
        per_row = across
    return np.tile(per_row, n).astype(np.float64)


def _window_sums(traj, space, window: tuple[float, float]):
    """(space, particle-frames per cell, vertical velocity sum and count per cell, frames)
    of ``window`` of ``traj``: the sums the time averages are formed from."""
    if not space.sized:
        space = space.with_size(traj.width, traj.height)
    if space.depth is not None and traj.dimensions != 3:
        raise InputError(f"{traj.path}: a 3D grid needs a 3D file")
    frames = traj.window(*window_pair(window))
    n_cells = space.n_cells
    counts = np.zeros(n_cells)
    velocity_sum = np.zeros(n_cells)
    velocity_count = np.zeros(n_cells)
    has_velocity = traj.has_velocity
    periodic = not traj.boundary.is_open
    n_frames = frames.stop - frames.start
    dt = traj.frame_interval
    for k0 in range(frames.start, frames.stop, _BLOCK):
        k1 = min(k0 + _BLOCK, frames.stop)
        positions = traj.positions(slice(k0, k1))
        present = traj.present(slice(k0, k1)) if traj.has_absences else None
        cells = cell_index(np.nan_to_num(positions), space.width, space.height, space.columns,
                           space.rows, space.depth, space.depth_columns)
        here = np.ones(cells.shape, bool) if present is None else present
        counts += np.bincount(cells[here], minlength=n_cells)
        if has_velocity:
            vy = traj.velocities(slice(k0, k1))[..., 1]
            ok = here & np.isfinite(vy)
            velocity_sum += np.bincount(cells[ok], weights=vy[ok], minlength=n_cells)
            velocity_count += np.bincount(cells[ok], minlength=n_cells)
        else:
            stop = min(k1 + 1, frames.stop)       # one frame beyond the block for the last
            if stop - k0 < 2:
                continue
            y = traj.positions(slice(k0, stop))[..., 1]
            dy = np.diff(y, axis=0)
            if periodic:
                dy -= traj.height * np.rint(dy / traj.height)
            both = np.isfinite(dy)
            if present is not None:
                p_all = traj.present(slice(k0, stop))
                both &= p_all[:-1] & p_all[1:]
            c = cells[: dy.shape[0]]
            velocity_sum += np.bincount(c[both], weights=dy[both] / dt, minlength=n_cells)
            velocity_count += np.bincount(c[both], minlength=n_cells)
    return space, counts, velocity_sum, velocity_count, int(n_frames)


def _fields(space, traj, counts, velocity_sum, velocity_count, n_frames: int,
            diameter: float | None) -> dict:
    """The cell fields from the sums of :func:`_window_sums` (of one window or several)."""
    n_cells = space.n_cells
    mean_count = counts / max(n_frames, 1)
    if diameter is not None:
        cell_area = (space.width / space.columns) * (space.height / space.rows)
        if traj.dimensions == 3:
            size = math.pi * diameter ** 3 / 6.0
            across_depth = (space.depth / space.depth_columns if space.depth is not None
                            else traj.depth)
            cell_size = cell_area * float(across_depth)
        else:
            size, cell_size = math.pi * diameter ** 2 / 4.0, cell_area
        solids = mean_count * size / cell_size
        relative = False
    else:
        average = mean_count.mean()
        solids = mean_count / average if average > 0 else np.zeros(n_cells)
        relative = True
    with np.errstate(invalid="ignore", divide="ignore"):
        velocity = np.where(velocity_count > 0, velocity_sum / np.maximum(velocity_count, 1),
                            np.nan)
    return {"solids_fraction": solids, "wall_distance": wall_distance(space),
            "vertical_velocity": velocity, "relative": relative, "frames": int(n_frames)}


def window_cell_fields(traj, space, window: tuple[float, float]) -> dict:
    """The time-averaged cell fields of ``window`` of ``traj`` on the cells of ``space``.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.
    space : StateSpace
        The model's state space (sized; its cell grid is used).
    window : (float, float)
        The window (s), usually the model's fitting window.

    Returns
    -------
    dict
        ``solids_fraction``, ``wall_distance`` (m), ``vertical_velocity`` (m/s), each
        ndarray of float64 [C]; ``relative`` (bool: the solids fraction is a count relative
        to the mean, the file gives no particle diameter) and ``frames`` (frames averaged).

    Raises
    ------
    InputError
        When the window holds no frame or lies outside the file, or the grid does not
        cover the file's riser.
    """
    space, counts, v_sum, v_count, n_frames = _window_sums(traj, space, window)
    return _fields(space, traj, counts, v_sum, v_count, n_frames,
                   particle_diameter(traj.parameters))


def pooled_cell_fields(runs, space, windows):
    """The cell fields of a pooled fit: each field's time average over all the runs'
    windows together, as if they were one longer window.

    The solids fraction is the particle-frames per cell summed over every run's window over
    the frames of all the windows (each run weighs by its frames); the mean vertical
    velocity is the velocities summed over all the runs' particle-frames in the cell over
    their number (each run weighs by its particle-frames in that cell). The solids fraction
    is relative (a count relative to the mean over the cells) unless every run's file gives
    the particle diameter.

    Parameters
    ----------
    runs : sequence of Trajectories
        The open runs of the pooled fit, in its order.
    space : StateSpace
        The model's state space.
    windows : sequence of (float, float)
        The fitting window (s) of each run.

    Returns
    -------
    CellFields

    Raises
    ------
    InputError
        As :func:`window_cell_fields`, for any run.
    """
    from cfbmarkov.kinetics import CellFields

    total = None
    diameters = []
    for traj, window in zip(runs, windows):
        sized, *sums = _window_sums(traj, space, window)
        total = sums if total is None else [a + b for a, b in zip(total, sums)]
        diameters.append(particle_diameter(traj.parameters))
    diameter = diameters[0] if all(d is not None and d == diameters[0]
                                   for d in diameters) else None
    f = _fields(sized, runs[0], *total, diameter)
    return CellFields(f["solids_fraction"], f["wall_distance"], f["vertical_velocity"],
                      relative=f["relative"])


def cell_fields_of(traj, space, window: tuple[float, float]):
    """:func:`window_cell_fields` as a :class:`~cfbmarkov.kinetics.CellFields`.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.
    space : StateSpace
        The model's state space.
    window : (float, float)
        The window (s).

    Returns
    -------
    CellFields

    Raises
    ------
    InputError
        As :func:`window_cell_fields`.
    """
    from cfbmarkov.kinetics import CellFields

    f = window_cell_fields(traj, space, window)
    return CellFields(f["solids_fraction"], f["wall_distance"], f["vertical_velocity"],
                      relative=f["relative"])


def fitting_cell_fields(traj, model):
    """The cell fields of ``model``'s fitting window of ``traj`` (its fitting file), for
    ``fit`` to store in the model; None where they cannot be computed there (the grid does
    not fit the file).

    Parameters
    ----------
    traj : Trajectories
        The open fitting file.
    model : MarkovModel
        The fitted model (its state space and window; None: every frame).

    Returns
    -------
    CellFields or None
    """
    window = model.window or (float(traj.times[0]), float(traj.times[-1]))
    try:
        return cell_fields_of(traj, model.state_space, window)
    except InputError:
        return None


def _fitting_runs(model) -> list[tuple[str, tuple[float, float] | None]]:
    """(source, window) of each run a model was fitted on (one, or a pooled fit's)."""
    if isinstance(model.source, (list, tuple)):
        windows = model.run_windows or [model.window] * len(model.source)
        return [(str(s), tuple(w) if w is not None else None)
                for s, w in zip(model.source, windows)]
    return [(str(model.source), model.window)]


def check_fitting_file(model, run, *, model_name: str = "the model") -> tuple[float, float]:
    """Refuse a trajectory file that is not the model's fitting file (one of a pooled fit's
    runs); the fitting window of that run.

    The file's window is compared by content (:func:`~cfbmarkov.trajectory_identity.
    window_identity`) with the identity ``fit`` recorded (``source_identity``; a pooled
    fit's, one per run joined by ``;``), and by path where the model records none.

    Parameters
    ----------
    model : MarkovModel
        The fitted model.
    run : str, os.PathLike or Trajectories
        The file given as its fitting file.
    model_name : str, optional
        How the message names the model (its file).

    Returns
    -------
    (float, float)
        The fitting window (s) of that run (its whole span where the model has none).

    Raises
    ------
    InputError
        One line naming the file, the model's fitting file(s) and the fix, where the file
        is none of them.
    """
    import os

    from cfbmarkov.trajectories import opened
    from cfbmarkov.trajectory_identity import same_window

    runs = _fitting_runs(model)
    identities = (str(model.source_identity).split(";") if model.source_identity else None)
    if identities is not None and len(identities) != len(runs):
        identities = None
    with opened(run) as traj:
        path = str(traj.path)
        span = (float(traj.times[0]), float(traj.times[-1]))
        for k, (source, window) in enumerate(runs):
            window = window or span
            if identities is not None:
                try:
                    if same_window(traj, window, identities[k]):
                        return window
                except InputError:        # the window lies outside this file
                    continue
            elif os.path.realpath(path) == os.path.realpath(source):
                return window
    fitted = ", ".join(f"{s} ({w[0]:g}-{w[1]:g} s)" if w else s for s, w in runs)
    how = "" if identities is None else ", its window's content compared"
    raise InputError(f"{path}: not the model's fitting file ({model_name} was fitted on "
                     f"{fitted}{how}): "
                     f"give --run {runs[0][0]}"
                     f"{' or another of its runs' if len(runs) > 1 else ''}, or leave --run "
                     "out where the model stores its cell fields")


def model_cell_fields(model, run=None, *, what: str = "the kinetics",
                      model_name: str = "the model"):
    """The fitting window's cell fields of ``model``: the ones it stores (``fit`` records
    them, a pooled fit the pooled ones), else computed on its fitting window of ``run``.

    Parameters
    ----------
    model : MarkovModel
        The fitted model.
    run : str, os.PathLike or Trajectories, optional
        Its fitting file (a pooled fit's: one of its runs), checked to be so wherever it is
        given (:func:`check_fitting_file`) and read where the model stores no fields.
    what : str, optional
        Names what needs the fields, for the message.
    model_name : str, optional
        How the messages name the model (its file).

    Returns
    -------
    CellFields

    Raises
    ------
    InputError
        One line: the run is not the model's fitting file (:func:`check_fitting_file`),
        the model stores no fields and no run is given (give ``--run`` or refit), or a
        pooled model stores none (one run's fields are not the pooled ones: refit).
    """
    from cfbmarkov.trajectories import opened

    window = check_fitting_file(model, run, model_name=model_name) if run is not None else None
    if model.cell_fields is not None:
        return model.cell_fields
    pooled = isinstance(model.source, (list, tuple)) and len(model.source) > 1
    if pooled:
        raise InputError(f"{what}: rates given as a function of a cell field (*_from) need the "
                         f"fitting windows' cell fields, and {model_name}, fitted on "
                         f"{len(model.source)} runs pooled, stores none (one run's fields are "
                         "not the pooled ones): refit it with cfbmarkov fit RUN1.h5 RUN2.h5 "
                         "... (which stores the pooled fields)")
    if run is None:
        raise InputError(f"{what}: rates given as a function of a cell field (*_from) need the "
                         "fitting window's cell fields, and the model stores none: give its "
                         "fitting file with --run RUN.h5, or refit it with cfbmarkov fit "
                         "(which stores them)")
    with opened(run) as traj:
        return cell_fields_of(traj, model.state_space, window)


__all__ = ["cell_fields_of", "check_fitting_file", "fitting_cell_fields",
           "model_cell_fields", "particle_diameter", "pooled_cell_fields", "wall_distance",
           "window_cell_fields"]
