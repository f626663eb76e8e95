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
    if not space.sized:
        space = space.with_size(traj.width, traj.height)
    if space.depth is not None and traj.dimensions != 3:
        raise InputError(f"{traj.path}: a 3D grid needs a 3D file")
    frames = traj.window(float(window[0]), float(window[1]))
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
    mean_count = counts / max(n_frames, 1)
    diameter = particle_diameter(traj.parameters)
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


def model_cell_fields(model, run=None, *, what: str = "the kinetics"):
    """The fitting window's cell fields of ``model``: the ones it stores (``fit`` records
    them), else computed on its fitting window of ``run``.

    Parameters
    ----------
    model : MarkovModel
        The fitted model.
    run : str, os.PathLike or Trajectories, optional
        Its fitting file, used where the model stores no fields. Its window must hold the
        model's fitting window, and where the model recorded the window's content identity
        the file must match it.
    what : str, optional
        Names what needs the fields, for the message.

    Returns
    -------
    CellFields

    Raises
    ------
    InputError
        One line: the model stores no fields and no run is given (give ``--run`` or refit),
        or the run is not the model's fitting file or does not hold its window.
    """
    from cfbmarkov.trajectories import opened
    from cfbmarkov.trajectory_identity import window_identity

    if model.cell_fields is not None:
        return model.cell_fields
    if run is None:
        raise InputError(f"{what}: rates given as a function of a cell field (*_from) need the "
                         "fitting window's cell fields, and the model stores none: give its "
                         "fitting file with --run RUN.h5, or refit it with cfbmarkov fit "
                         "(which stores them)")
    with opened(run) as traj:
        window = model.window or (float(traj.times[0]), float(traj.times[-1]))
        if model.source_identity and window_identity(traj, window) != model.source_identity:
            raise InputError(f"{traj.path}: not the model's fitting file (its window "
                             f"{window[0]:g}-{window[1]:g} s differs from the one the model "
                             "was fitted on); give the file it was fitted on")
        return cell_fields_of(traj, model.state_space, window)


__all__ = ["cell_fields_of", "fitting_cell_fields", "model_cell_fields", "particle_diameter",
           "wall_distance", "window_cell_fields"]
