"""The CFD-DEM run: orchestration of the DEM, the gas and the output (no maths here).

:class:`CoupledRiser` holds a DEM system and a gas state and advances them one gas step at a
time (the coupling kernels are in :mod:`cfbmarkov.simulate.coupling`). :func:`simulate` runs
a case to its end time, writing frames every ``output.frame_interval`` s with exact pass
events, showing progress (simulated time, particle-steps/s, ETA), writing atomic checkpoints,
and resuming a killed run so that the result equals an uninterrupted run bit for bit.

Files of a run ``RUN.h5``: while it runs, ``RUN.h5.parts/`` holds complete trajectory
segments and ``checkpoint.h5`` (written atomically after its segment is closed); at the end
the segments are merged into ``RUN.h5`` and the folder is removed.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import sys
import time as _time
import warnings
from pathlib import Path

import h5py
import numba
import numpy as np

from cfbmarkov._atomic import atomic_path, h5_file
from cfbmarkov._outputs import claim_output
from cfbmarkov.config import CaseConfig, case_difference
from cfbmarkov.errors import CfbmarkovError, CfbmarkovWarning, InputError, TimeStepAdvisory
from cfbmarkov.simulate.cfd import (GasGrid, GasSolver, GasState, deposit_drag,
                                    void_fraction_field)
from cfbmarkov.simulate.coupling import (drag_coefficients, drag_force_at_new_gas,
                                         place_without_overlap)
from cfbmarkov.simulate.dem import ContactLaw, DEMSystem
from cfbmarkov.simulate.dem.system import contact_resolution
from cfbmarkov.segmented import SegmentedTrajectoryWriter

CHECKPOINT_VERSION = 1


class CoupledRiser:
    """DEM particles and the gas of the periodic riser, advanced one gas step at a time.

    Parameters
    ----------
    case : CaseConfig
        The case (riser, particles, gas, contact law, numerics).
    dem : DEMSystem
        The particles.
    gas : GasState
        The gas on the staggered grid.
    cfd_steps : int, optional
        Gas steps already taken (the time is ``cfd_steps`` x the gas step).
    """

    def __init__(self, case: CaseConfig, dem: DEMSystem, gas: GasState, cfd_steps: int = 0):
        self.case = case
        self.dem = dem
        self.gas = gas
        self.cfd_steps = int(cfd_steps)
        # a bed on a floor: the gas enters through a distributor at y = 0 (see .cfd.grid)
        self.solver = GasSolver.from_config(case, distributor=dem.bottom_wall, formulation="B")
        self.grid = self.solver.grid
        self.dem_steps_per_cfd = case.numerics.dem_steps_per_cfd_step
        n = dem.n_particles
        self._coefficient = np.empty(n)
        self._force = np.empty((n, 2))

    # -- construction ----------------------------------------------------------------
    @classmethod
    def initial(cls, case: CaseConfig) -> "CoupledRiser":
        """Particles on random lattice sites without overlap, at rest; gas at U (plug flow).

        Parameters
        ----------
        case : CaseConfig
            The case; ``case.seed`` seeds the placement.

        Returns
        -------
        CoupledRiser
            The riser at t = 0.
        """
        p, r = case.particles, case.riser
        positions = place_without_overlap(p.number, p.diameter, r.width, r.height, case.seed)
        return cls.from_particles(case, positions, np.zeros_like(positions))

    @classmethod
    def from_particles(cls, case: CaseConfig, positions, velocities, *, bottom_wall: bool = False,
                       angular_velocities=None) -> "CoupledRiser":
        """Given particles; gas at U (plug flow).

        Parameters
        ----------
        case : CaseConfig
            The case.
        positions, velocities : array_like
            [N, 2] particle centres (m) and velocities (m/s).
        bottom_wall : bool, optional
            Put a contact floor at y = 0 for the particles (the gas stays periodic, as
            through a distributor): packed beds.
        angular_velocities : array_like, optional
            [N] spins, rad/s (default 0).

        Returns
        -------
        CoupledRiser
            The riser at t = 0.
        """
        p, r = case.particles, case.riser
        positions = np.asarray(positions, dtype=np.float64)
        law = ContactLaw.from_config(case.contact, p.diameter, p.density)
        dem = DEMSystem(positions, velocities, 0.5 * p.diameter, p.density, law,
                        r.width, r.height, gravity=r.gravity,
                        time_step=case.numerics.dem_time_step,
                        search_cells=_search_cells(case), skin=case.numerics.dem_skin,
                        angular_velocities=angular_velocities, bottom_wall=bottom_wall)
        grid = GasGrid.from_config(case)
        eps = void_fraction_field(grid, positions[:, 0], positions[:, 1], p.diameter,
                                  periodic_y=not bottom_wall)
        gas = GasSolver.from_config(case, distributor=bottom_wall,
                                    formulation="B").initial_state(eps)
        return cls(case, dem, gas)

    # -- stepping ----------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time, s."""
        return self.cfd_steps * self.case.numerics.cfd_time_step

    #: below this many particles the coupling kernels run on one thread (thread start-up
    #: costs more than the work; results do not depend on it)
    serial_below = 2000

    def step(self) -> None:
        """One gas step and the DEM steps inside it."""
        threads = numba.get_num_threads()
        if self.dem.n_particles < self.serial_below and threads > 1:
            numba.set_num_threads(1)
        try:
            self._step()
        finally:
            if numba.get_num_threads() != threads:
                numba.set_num_threads(threads)

    def _step(self) -> None:
        self._gas_step()
        self.dem.step(self.dem_steps_per_cfd, external_force=self._force)
        self.cfd_steps += 1

    def _gas_step(self) -> None:
        """The gas step and the drag it leaves on the particles (``self._force``), before the
        DEM steps inside it."""
        case, grid = self.case, self.grid
        d = case.particles.diameter
        positions, velocities = self.dem.positions, self.dem.velocities
        x, y = positions[:, 0], positions[:, 1]
        periodic_y = not self.dem.bottom_wall
        eps = void_fraction_field(grid, x, y, d, periodic_y=periodic_y)
        drag_coefficients(positions, velocities, self.gas.u, self.gas.v, eps, grid.dx,
                          grid.dy, d, case.gas.density, case.gas.viscosity,
                          self._coefficient, self._force, periodic_y)
        fu, fv, ku, kv = deposit_drag(grid, x, y, self._force[:, 0], self._force[:, 1],
                                      self._coefficient, d)
        self.gas = self.solver.step(self.gas, eps, fu, fv, ku, kv)
        drag_force_at_new_gas(positions, velocities, self.gas.u, self.gas.v, grid.dx, grid.dy,
                              self._coefficient, self._force)

    def gas_fields(self) -> dict[str, np.ndarray]:
        """The gas at cell centres, arrays [ny, nx] (row 0 at the bottom): ``void_fraction``,
        ``gas_velocity`` [ny, nx, 2] (interstitial, m/s) and ``pressure`` (periodic part, Pa)."""
        u, v = self.gas.u, self.gas.v
        uc = 0.5 * (u[:-1] + u[1:])
        vc = 0.5 * (v + np.roll(v, -1, axis=1))
        return {"void_fraction": self.gas.void_fraction.T,
                "gas_velocity": np.stack([uc.T, vc.T], axis=-1),
                "pressure": self.gas.p.T}

    # -- checkpoints -----------------------------------------------------------------
    def state(self) -> dict[str, dict[str, np.ndarray] | int]:
        """Everything needed to continue bit for bit: ``{'dem': ..., 'gas': ..., 'cfd_steps': k}``."""
        return {"dem": self.dem.state(), "gas": self.gas.state_dict(), "cfd_steps": self.cfd_steps}

    @classmethod
    def from_state(cls, case: CaseConfig, state: dict) -> "CoupledRiser":
        """The riser saved by :meth:`state` (with the same ``case``)."""
        return cls(case, DEMSystem.from_state(state["dem"]),
                   GasState.from_state_dict(state["gas"]), int(state["cfd_steps"]))


def _write_group(group: h5py.Group, values: dict) -> None:
    for key, value in values.items():
        if isinstance(value, dict):
            _write_group(group.create_group(key), value)
        else:
            group.create_dataset(key, data=np.asarray(value))


def _read_group(group: h5py.Group) -> dict:
    return {k: (_read_group(v) if isinstance(v, h5py.Group) else v[()]) for k, v in group.items()}


def write_checkpoint(path: Path, riser: CoupledRiser, n_segments: int, frames: int,
                     wall_time: float, wall_history=None) -> None:
    """Atomically write everything needed to continue the run bit for bit.

    Parameters
    ----------
    path : pathlib.Path
        The checkpoint file (HDF5).
    riser : CoupledRiser
        The state to save, with its case.
    n_segments, frames : int
        Trajectory segments closed and frames written so far.
    wall_time : float
        Wall time spent so far, s.
    wall_history : array_like, optional
        Rows of (simulated time s, wall time s) at each checkpoint.
    """
    with atomic_path(path) as tmp:
        with h5_file(tmp, path) as f:
            f.attrs.update({"version": CHECKPOINT_VERSION, "n_segments": n_segments,
                            "frames": frames, "wall_time": wall_time,
                            "case": riser.case.model_dump_json()})
            f.create_dataset("wall_history", data=np.asarray(
                wall_history if wall_history is not None else np.empty((0, 2)),
                dtype=np.float64).reshape(-1, 2))
            state = riser.state()
            _write_group(f.create_group("dem"), state["dem"])
            _write_group(f.create_group("gas"), state["gas"])
            f.attrs["cfd_steps"] = state["cfd_steps"]


def read_checkpoint(path: Path, case: CaseConfig
                    ) -> tuple[CoupledRiser, int, int, float, np.ndarray]:
    """Read a checkpoint written by :func:`write_checkpoint`.

    Parameters
    ----------
    path : pathlib.Path
        The checkpoint file.
    case : CaseConfig
        The case being run; it must equal the one saved.

    Returns
    -------
    riser : CoupledRiser
        The saved state.
    n_segments, frames : int
        Segments closed and frames written.
    wall_time : float
        Wall time spent, s.
    wall_history : numpy.ndarray
        [K, 2] (simulated time s, wall time s) at each checkpoint.

    Raises
    ------
    InputError
        When the file cannot be read or was made with another configuration.
    """
    try:
        with h5py.File(path, "r") as f:
            saved = CaseConfig.model_validate_json(f.attrs["case"])
            if saved != case:
                raise InputError(f"{path}: the checkpoint was made with another configuration "
                                 f"({case_difference(saved, case)}); run without --resume to "
                                 "start again, or with the saved value")
            state = {"dem": _read_group(f["dem"]), "gas": _read_group(f["gas"]),
                     "cfd_steps": int(f.attrs["cfd_steps"])}
            meta = int(f.attrs["n_segments"]), int(f.attrs["frames"]), float(f.attrs["wall_time"])
            history = (f["wall_history"][()] if "wall_history" in f
                       else np.empty((0, 2)))
    except (OSError, KeyError) as exc:
        raise InputError(f"{path}: unreadable checkpoint ({exc})") from None
    return (CoupledRiser.from_state(case, state), *meta, history)


def _search_cells(case: CaseConfig) -> tuple[int, int] | None:
    """The DEM's ``search_cells`` for a case: None (the engine's automatic grid) for "auto"."""
    cells = case.numerics.dem_cells
    return None if cells == "auto" else tuple(int(c) for c in cells)


def _clock(seconds: float) -> str:
    """``H:MM:SS`` or ``M:SS``."""
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(max(seconds, 0.0)))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def _rate(value: float) -> str:
    """``2.1e7``: two digits, the exponent without sign or zeros."""
    if not (math.isfinite(value) and value > 0):
        return "?"
    mantissa, exponent = f"{value:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"


#: a line of progress (``progress="lines"``) at every this fraction of the simulated time
LINE_EVERY = 0.1


class _Progress:
    """Progress in simulated seconds with particle-steps/s and the time left.

    ``mode`` ``"bar"``: a tqdm bar on stderr; ``"lines"``: whole lines on stderr, one at the
    start, one at every :data:`LINE_EVERY` of the simulated time and one at the end, each
    starting with the label (lines of parallel cases never interleave); ``None``: quiet.
    """

    def __init__(self, mode: str | None, start: float, end: float, particles: int,
                 label: str = ""):
        self.mode, self.start, self.end, self.particles = mode, start, end, particles
        self.prefix = f"{label}: CFD-DEM" if label else "CFD-DEM"
        self.bar = None
        self.done = start
        self.t_wall = self.t_start = self.t_line = _time.perf_counter()
        self.steps = self.steps_line = 0
        self.line_done = start
        self.next_line = start + LINE_EVERY * (end - start)
        if mode == "bar":
            from tqdm import tqdm

            self.bar = tqdm(total=round(end - start, 6), initial=0, unit="s", file=sys.stderr,
                            desc=f"{label} CFD-DEM (simulated s)".lstrip(),
                            mininterval=1.0 if sys.stderr.isatty() else 30.0,
                            bar_format="{desc}: {n:.3f}/{total:.3f} [{elapsed}<{remaining}{postfix}]")
        elif mode == "lines":
            what = "resumed at" if start > 0 else "starting at"
            self._line(f"{what} {start:g}/{end:g} s simulated, {particles} particles")

    def _line(self, text: str) -> None:
        from cfbmarkov._console import write_line

        write_line(f"{self.prefix} {text}")

    def update(self, simulated: float, dem_steps: int) -> None:
        if self.mode is None:
            return
        now = _time.perf_counter()
        self.done += simulated
        self.steps += dem_steps
        if self.bar is not None:
            rate = self.particles * dem_steps / max(now - self.t_wall, 1e-9)
            self.t_wall = now
            self.bar.set_postfix_str(f"{rate:.3g} particle-steps/s", refresh=False)
            self.bar.update(simulated)
            return
        mark = first = self.steps == dem_steps      # rates count from the first frame
        if self.done >= self.next_line - 1e-9 and self.done < self.end - 1e-9:
            if first or self.done <= self.line_done:   # no frame since the last mark
                rate = self.particles * self.steps / max(now - self.t_start, 1e-9)
                left = (self.end - self.done) / (self.done - self.start) * (now - self.t_start)
            else:       # since the last line (or the first frame: Numba compiles before it)
                rate = self.particles * (self.steps - self.steps_line) / max(now - self.t_line,
                                                                             1e-9)
                left = (self.end - self.done) / (self.done - self.line_done) * (now - self.t_line)
            self._line(f"{self.done:.2f}/{self.end:g} s simulated, {_rate(rate)} particle-steps/s, "
                       f"{_clock(now - self.t_start)} so far, about {_clock(left)} left")
            while self.next_line <= self.done + 1e-9:
                self.next_line += LINE_EVERY * (self.end - self.start)
            mark = True
        if mark:
            self.t_line, self.steps_line, self.line_done = now, self.steps, self.done

    def close(self, finished: bool = False) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self.mode == "lines" and finished:
            wall = _time.perf_counter() - self.t_start
            rate = self.particles * self.steps / max(wall, 1e-9)
            self._line(f"{self.end:g}/{self.end:g} s simulated in {_clock(wall)} "
                       f"({_rate(rate)} particle-steps/s)")


def _progress_mode(progress) -> str | None:
    """``progress`` of :func:`simulate` as a mode of :class:`_Progress`."""
    if progress in (False, None):
        return None
    if progress in ("bar", "lines"):
        return progress
    if progress is True:
        return "bar" if sys.stderr.isatty() else "lines"
    raise InputError(f"progress {progress!r}: choose True, False, 'bar' or 'lines'")


def simulate(case: CaseConfig, output: str | os.PathLike, *, until: float | None = None,
             checkpoint_every: float = 1.0, resume: bool = False, progress: bool | str = True,
             stop_after_frames: int | None = None, fields: bool = True, label: str = ""
             ) -> Path:
    """Run a case from t = 0 (or the last checkpoint with ``resume``) to ``until`` (default:
    the case's end time) and write the trajectory file ``output``.

    ``/provenance/run`` records the wall time, and ``wall_history`` rows of (simulated time,
    wall time since the start) at every checkpoint.

    Parameters
    ----------
    case : CaseConfig
        The case to run.
    output : str or os.PathLike
        The trajectory file (layout in docs/definitions.md, Trajectory files).
    until : float, optional
        Simulated time to reach, s (default ``case.output.end_time``).
    checkpoint_every : float, optional
        Simulated time between checkpoints, s.
    resume : bool, optional
        Continue from the last checkpoint of an interrupted run.
    progress : bool or {"bar", "lines"}, optional
        Show progress on stderr: ``"bar"`` a tqdm bar; ``"lines"`` one whole line at the
        start, at every tenth of the simulated time (particle-steps/s, time left) and at the
        end, each starting with ``label`` (for cases run in parallel); True: the bar on a
        terminal, else lines; False: none.
    stop_after_frames : int, optional
        End the process's work early, as a kill would, after that many frames (for tests of
        resume); the run is then left to be resumed.
    fields : bool, optional
        Store the gas (void fraction, velocity, pressure at cell centres) with every frame
        under ``/fields``.
    label : str, optional
        Prefix of the progress and of the time-step advisory (e.g. the case, ``u6``).

    Returns
    -------
    pathlib.Path
        The trajectory file (when the run is complete).

    Raises
    ------
    InputError
        For settings that do not fit (a frame interval that is not a whole number of gas
        steps, a gas step beyond its stability limit, nothing to resume, an interrupted run
        without ``resume``).
    CfbmarkovError
        When the simulation fails (e.g. a blow-up); the last good checkpoint stays on disk.

    Warns
    -----
    TimeStepAdvisory
        Once per call, when the DEM step resolves a contact in fewer than 10 steps (the
        command line prints it as one line, ``note: ...``).
    """
    mode = _progress_mode(progress)
    output = Path(output)
    with claim_output(output, "simulate", "trajectory"):   # before any work: lock, folder
        return _simulate(case, output, until, checkpoint_every, resume, mode,
                         stop_after_frames, fields, label)


def _simulate(case: CaseConfig, output: Path, until, checkpoint_every, resume, progress,
              stop_after_frames, fields, label) -> Path:
    end = case.output.end_time if until is None else float(until)
    frame_dt = case.output.frame_interval
    cfd_dt = case.numerics.cfd_time_step
    steps_per_frame = frame_dt / cfd_dt
    if abs(steps_per_frame - round(steps_per_frame)) > 1e-6 * steps_per_frame:
        raise InputError(f"frame interval {frame_dt:g} s is not a whole number of gas steps "
                         f"({cfd_dt:g} s)")
    steps_per_frame = int(round(steps_per_frame))
    steps_per_checkpoint = max(1, int(round(checkpoint_every / frame_dt))) * steps_per_frame
    total_steps = int(round(end / cfd_dt))
    if total_steps < steps_per_frame:
        raise InputError(f"run length {end:g} s is shorter than one frame ({frame_dt:g} s)")
    parts = output.with_name(output.name + ".parts")
    checkpoint = parts / "checkpoint.h5"
    grid = GasGrid.from_config(case)
    spacing = (grid.dx, grid.dy)
    writer_options = dict(
        ids=np.arange(case.particles.number), width=case.riser.width, height=case.riser.height,
        source="cfd-dem", parameters=json.loads(case.model_dump_json()), with_velocity=True,
        frame_interval=frame_dt)
    if resume and not checkpoint.exists() and _complete(output, case, end):
        _remove_parts(parts)     # killed while cleaning up after the final rename
        return output
    if not checkpoint.exists() and parts.is_dir():
        _remove_parts(parts)     # segments of a run whose checkpoint is gone: useless
    if resume:
        if not checkpoint.exists():
            raise InputError(f"nothing to resume: {checkpoint} does not exist")
        _advise_time_step(case, label)
        riser, n_segments, frames, wall_time, history = read_checkpoint(checkpoint, case)
        wall_history = [tuple(row) for row in history]
        writer = SegmentedTrajectoryWriter.resume(output, n_segments, **writer_options)
    else:
        if parts.exists() and checkpoint.exists():
            raise InputError(f"{parts} holds an interrupted run: add --resume to continue it, "
                             "or delete the folder to start again")
        _check_safety(case)
        _advise_time_step(case, label)
        with warnings.catch_warnings():     # said once above, with the label
            warnings.simplefilter("ignore", TimeStepAdvisory)
            riser = CoupledRiser.initial(case)
        writer = SegmentedTrajectoryWriter(output, **writer_options)
        writer.append(0.0, riser.dem.positions, riser.dem.velocities, riser.dem.laps)
        if fields:
            writer.append_fields(0.0, spacing, **riser.gas_fields())
        frames, wall_time = 1, 0.0
        wall_history = [(0.0, 0.0)]
    bar = _Progress(progress, riser.time, end, case.particles.number, label)
    finished = False
    started = _time.perf_counter() - wall_time
    pending = _PendingFrames(writer, spacing)
    try:
        while riser.cfd_steps < total_steps:
            for _ in range(steps_per_frame):
                riser.step()
            pending.add(riser.time, riser.dem, riser.gas_fields() if fields else None)
            frames += 1
            bar.update(frame_dt, steps_per_frame * riser.dem_steps_per_cfd)
            checkpoint_now = (riser.cfd_steps % steps_per_checkpoint == 0
                              or riser.cfd_steps >= total_steps)
            if checkpoint_now or len(pending) >= FRAMES_PER_WRITE:
                pending.flush()
            if checkpoint_now:
                n_segments = writer.close_segment()
                elapsed = _time.perf_counter() - started
                wall_history.append((riser.time, elapsed))
                write_checkpoint(checkpoint, riser, n_segments, frames, elapsed, wall_history)
            if stop_after_frames is not None and frames >= stop_after_frames:
                writer.abort()
                return output
    except CfbmarkovError as exc:
        writer.abort()
        kept = f"; the last good checkpoint is in {checkpoint}" if checkpoint.exists() else ""
        raise type(exc)(f"{exc} (at t = {riser.time:.6g} s){kept}") from None
    except BaseException:
        writer.abort()
        raise
    else:
        finished = True
    finally:
        bar.close(finished)
    wall = _time.perf_counter() - started
    run_info = {"wall_time_s": wall, "simulated_s": end, "particles": case.particles.number,
                "particle_steps_per_s": case.particles.number * total_steps
                * riser.dem_steps_per_cfd / max(wall, 1e-9),
                "exact_pass_events": True}
    writer.finish(attach={"run": ({"wall_history": np.asarray(wall_history, dtype=np.float64)},
                                  run_info)})
    return output


#: frames held in memory between two writes of a running simulation (at most; a checkpoint
#: writes them all first): one h5py call per dataset and block instead of per frame, which
#: was 8 ms a frame (11 % of a quick-scale step at 0.002 s frames)
FRAMES_PER_WRITE = 50


class _PendingFrames:
    """Frames, pass events and gas fields of a running simulation not yet written.

    Orchestration only: copies of the DEM state per frame, written as blocks by
    :meth:`flush` (the writer validates them as it does frame by frame).
    """

    def __init__(self, writer: SegmentedTrajectoryWriter, spacing) -> None:
        self._writer, self._spacing = writer, spacing
        self._frames: list[tuple] = []
        self._events: list[tuple] = []
        self._fields: list[tuple[float, dict]] = []

    def __len__(self) -> int:
        return len(self._frames)

    def add(self, time: float, dem, gas_fields: dict | None) -> None:
        self._events.append(dem.drain_pass_events())
        self._frames.append((time, np.array(dem.positions), np.array(dem.velocities),
                             np.array(dem.laps)))
        if gas_fields is not None:
            self._fields.append((time, {k: np.array(v) for k, v in gas_fields.items()}))

    def flush(self) -> None:
        if self._events:
            t, p, d = (np.concatenate(parts) for parts in zip(*self._events))
            self._writer.add_events(t, p, d)
        if self._frames:
            times, positions, velocities, laps = zip(*self._frames)
            self._writer.append_frames(np.asarray(times), np.stack(positions),
                                       np.stack(velocities), np.stack(laps))
        if self._fields:
            names = self._fields[0][1].keys()
            self._writer.append_field_frames(
                np.asarray([t for t, _ in self._fields]), self._spacing,
                **{name: np.stack([f[name] for _, f in self._fields]) for name in names})
        self._frames, self._events, self._fields = [], [], []


def _complete(output: Path, case: CaseConfig, end: float) -> bool:
    """Whether ``output`` is the finished run of ``case`` up to ``end``."""
    if not output.is_file():
        return False
    try:
        with h5py.File(output, "r") as f:
            same = json.loads(f.attrs["parameters"]) == json.loads(case.model_dump_json())
            last = float(f["frames/time"][-1])
    except (OSError, KeyError, ValueError, IndexError):
        return False
    return same and abs(last - end) <= 0.5 * case.output.frame_interval


def _remove_parts(parts: Path) -> None:
    """Remove the checkpoint folder (checkpoint first, so no state names missing segments)."""
    with contextlib.suppress(OSError):
        (parts / "checkpoint.h5").unlink()
    shutil.rmtree(parts, ignore_errors=True)


def _advise_time_step(case: CaseConfig, label: str = "") -> None:
    """Warn (:class:`~cfbmarkov.errors.TimeStepAdvisory`) when the DEM step resolves a
    contact in fewer than 10 steps; ``label`` (a case) starts the message."""
    p = case.particles
    law = ContactLaw.from_config(case.contact, p.diameter, p.density)
    worst, message = contact_resolution(law, law.mass, case.numerics.dem_time_step)
    if 5 <= worst < 10:     # below 5 the DEM refuses the run
        warnings.warn((f"{label}: " if label else "") + message + "; 10 or more are recommended",
                      TimeStepAdvisory, stacklevel=3)


def _check_safety(case: CaseConfig) -> None:
    """Refuse a gas step beyond its stability limit at the expected velocities."""
    from cfbmarkov.simulate.cfd import gas_stability_limit

    grid = GasGrid.from_config(case)
    expected = 2.0 * case.gas.superficial_velocity / 0.5       # slip through dense clusters
    limit = gas_stability_limit(grid, case.gas, (expected, expected))
    if case.numerics.cfd_time_step > limit:
        raise InputError(f"gas time step {case.numerics.cfd_time_step:g} s exceeds its stability "
                         f"limit {limit:.3g} s at velocities up to {expected:g} m/s "
                         f"(grid {grid.nx} x {grid.ny})")
    if not math.isfinite(limit):
        warnings.warn("gas stability limit could not be evaluated", CfbmarkovWarning, stacklevel=2)
