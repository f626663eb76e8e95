"""The CFD-DEM run: orchestration of the riser, the output and the checkpoints (no maths here).

:func:`simulate` runs a case to its end time with a :class:`~.riser.CoupledRiser`, writing
frames every ``output.frame_interval`` s with exact pass events, showing progress
(:mod:`.progress`: simulated time, particle-steps/s, ETA), writing atomic checkpoints
(:mod:`.checkpoint`), and resuming a killed run so that the result equals an uninterrupted
run bit for bit.

Files of a run ``RUN.h5``: while it runs, ``RUN.h5.parts/`` holds complete trajectory
segments and ``checkpoint.h5`` (written atomically after its segment is closed); at the end
the segments are merged into ``RUN.h5`` and the folder is removed.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import secrets
import shutil
import time as _time
import warnings
from pathlib import Path

import h5py
import numpy as np

from cfbmarkov._console import progress_mode
from cfbmarkov._names import parts_folder
from cfbmarkov._outputs import claim_output
from cfbmarkov.config import CaseConfig
from cfbmarkov.errors import CfbmarkovError, CfbmarkovWarning, InputError, TimeStepAdvisory
from cfbmarkov.limits import MAX_LAGS
from cfbmarkov.segmented import SegmentedTrajectoryWriter
from cfbmarkov.simulate.cfd import GasGrid, gas_stability_limit
from cfbmarkov.simulate.checkpoint import checkpoint_cpu_time, read_checkpoint, write_checkpoint
from cfbmarkov.simulate.coupling import check_placement
from cfbmarkov.simulate.dem.law import ContactLaw, contact_resolution
from cfbmarkov.simulate.dem.neighbours import search_grid
from cfbmarkov.simulate.progress import Progress
from cfbmarkov.simulate.riser import CoupledRiser


def simulate(case: CaseConfig, output: str | os.PathLike, *, until: float | None = None,
             checkpoint_every: float = 1.0, resume: bool = False, progress: bool | str = True,
             stop_after_frames: int | None = None, fields: bool = True, label: str = "",
             force: bool = False) -> Path:
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
    force : bool, optional
        Replace ``output`` where it holds a finished CFD-DEM run (of this case or another):
        without it such a file is refused, since a finished run keeps no checkpoint and
        cannot be had back.

    Returns
    -------
    pathlib.Path
        The trajectory file (when the run is complete).

    Raises
    ------
    InputError
        For settings that do not fit (a frame interval that is not a whole number of gas
        steps, a gas step beyond its stability limit, nothing to resume, an interrupted run
        without ``resume``), or an ``output`` that holds a finished run, without ``force``.
    CfbmarkovError
        When the simulation fails (e.g. a blow-up); the last good checkpoint stays on disk.

    Warns
    -----
    TimeStepAdvisory
        Once per call, when the DEM step resolves a contact in fewer than 10 steps (the
        command line prints it as one line, ``note: ...``).
    """
    mode = progress_mode(progress)
    output = Path(output)
    with claim_output(output, "simulate", "trajectory"):   # before any work: lock, folder
        if not resume:
            refuse_finished_run(output, case, force)
        parts = parts_folder(output)
        try:
            return _simulate(case, output, until, checkpoint_every, resume, mode,
                             stop_after_frames, fields, label)
        except BaseException:
            if not (parts / "checkpoint.h5").exists() and not _complete(
                    output, case, case.output.end_time if until is None else until):
                _remove_parts(parts)        # nothing to resume from: leave no folder
            raise


def _simulate(case: CaseConfig, output: Path, until, checkpoint_every, resume, progress,
              stop_after_frames, fields, label) -> Path:
    end = case.output.end_time if until is None else float(until)
    frame_dt = case.output.frame_interval
    cfd_dt = case.numerics.cfd_time_step
    for what, value in (("--until (the run's end)", end),
                        ("--checkpoint-every", float(checkpoint_every))):
        if not value / cfd_dt < MAX_LAGS:    # inf beyond the floats: int() would overflow
            raise InputError(f"{what} {value:g} s is {value / cfd_dt:.3g} gas steps of "
                             f"{cfd_dt:g} s, beyond any run: give a time of seconds to hours")
    steps_per_frame = frame_dt / cfd_dt
    if abs(steps_per_frame - round(steps_per_frame)) > 1e-6 * steps_per_frame:
        raise InputError(f"frame interval {frame_dt:g} s is not a whole number of gas steps "
                         f"({cfd_dt:g} s): give an output.frame_interval that is (e.g. "
                         f"{max(1, round(steps_per_frame)) * cfd_dt:.10g} s), or another "
                         "numerics.cfd_time_step")
    steps_per_frame = int(round(steps_per_frame))
    steps_per_checkpoint = max(1, int(round(checkpoint_every / frame_dt))) * steps_per_frame
    total_steps = int(round(end / cfd_dt))
    if total_steps < steps_per_frame:
        raise InputError(f"run length {end:g} s is shorter than one frame ({frame_dt:g} s): "
                         "give a later --until or output.end_time")
    whole = end / frame_dt
    if abs(whole - round(whole)) > 1e-6 * max(whole, 1.0):
        # the run steps whole frames: it would end at the next one and say it ended here
        below, above = math.floor(whole) * frame_dt, math.ceil(whole) * frame_dt
        where = "--until" if until is not None else "output.end_time in the case file"
        raise InputError(f"end time {end:g} s is not a whole number of frames "
                         f"({frame_dt:g} s apart): give {below:.10g} or {above:.10g} s "
                         f"({where})")
    parts = parts_folder(output)
    checkpoint = parts / "checkpoint.h5"
    grid = GasGrid.from_config(case)
    spacing = (grid.dx, grid.dy)
    writer_options = dict(
        ids=np.arange(case.particles.number), width=case.riser.width, height=case.riser.height,
        source="cfd-dem", parameters=json.loads(case.model_dump_json()), with_velocity=True,
        frame_interval=frame_dt)
    if resume and not checkpoint.exists() and _complete(output, case, end):
        _remove_parts(parts)     # killed while cleaning up after the final rename
        warnings.warn(f"nothing left to resume: {output} already holds this run to "
                      f"{end:g} s, finished (a finished run keeps no checkpoint, so it cannot "
                      "be extended: a longer run starts again from t = 0, with --until and "
                      "--force)", CfbmarkovWarning, stacklevel=2)
        return output
    if not checkpoint.exists() and parts.is_dir():
        _remove_parts(parts)     # segments of a run whose checkpoint is gone: useless
    if resume:
        if not checkpoint.exists() and (finished := _finished_run(output, case)):
            raise InputError(f"nothing to resume: {output} is {finished}, and a finished run "
                             "keeps no checkpoint to continue from; run the case without "
                             "--resume and with --force (which replaces the file) or to "
                             "another output")
        if not checkpoint.exists():
            raise InputError(f"nothing to resume: {checkpoint} does not exist (the run "
                             "stopped before its first checkpoint); start it again without "
                             "--resume")
        check_resources(case, output, end, fields, resuming=True)
        check_periodic_case(case)
        _note_unlikely_units(case, label)
        _advise_time_step(case, label)
        riser, n_segments, frames, wall_time, history, run_id = read_checkpoint(checkpoint,
                                                                                case)
        cpu_time = checkpoint_cpu_time(checkpoint)
        if riser.time > end + 0.5 * cfd_dt:
            raise InputError(f"{checkpoint} holds the run at t = {riser.time:g} s, past the "
                             f"end asked for ({end:g} s): resume to a later --until, or "
                             "delete the folder to start again")
        wall_history = [tuple(row) for row in history]
        writer = SegmentedTrajectoryWriter.resume(output, n_segments, run_id=run_id,
                                                  **writer_options)
    else:
        if parts.exists() and checkpoint.exists():
            raise InputError(f"{parts} holds an interrupted run: add --resume to continue it, "
                             "or delete the folder to start again")
        _check_safety(case)
        check_resources(case, output, end, fields, resuming=False)
        check_periodic_case(case)
        _note_unlikely_units(case, label)
        _advise_time_step(case, label)
        with warnings.catch_warnings():     # said once above, with the label
            warnings.simplefilter("ignore", TimeStepAdvisory)
            riser = CoupledRiser.initial(case)
        run_id = secrets.token_hex(16)      # carried by the checkpoint and every segment
        writer = SegmentedTrajectoryWriter(output, run_id=run_id, **writer_options)
        writer.append(0.0, riser.dem.positions, riser.dem.velocities, riser.dem.laps)
        if fields:
            writer.append_fields(0.0, spacing, **riser.gas_fields())
        frames, wall_time, cpu_time = 1, 0.0, 0.0
        wall_history = [(0.0, 0.0)]
    bar = Progress(progress, riser.time, end, case.particles.number, label)
    finished = False
    started = _time.perf_counter() - wall_time
    cpu_started = _time.process_time() - cpu_time     # NaN where a resumed part is unknown
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
                write_checkpoint(checkpoint, riser, n_segments, frames, elapsed, wall_history,
                                 run_id, cpu_time=_time.process_time() - cpu_started)
            if stop_after_frames is not None and frames >= stop_after_frames:
                writer.abort()
                return output
    except CfbmarkovError as exc:
        writer.abort()
        kept = f"; the last good checkpoint is in {checkpoint}" if checkpoint.exists() else ""
        # the same error (its type and attributes: a SimulationBlowUp's step, particle and
        # reason), its message told when and where the last good state is
        exc.args = (f"{exc} (at t = {riser.time:.6g} s){kept}", *exc.args[1:])
        raise exc from None
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
                "exact_pass_events": True,
                # this process's CPU time and, across resumes, the earlier ones' (NaN where a
                # checkpoint recorded none): Numba's threads count, other processes not
                "cpu_time_s": _time.process_time() - cpu_started}
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


def _complete(output: Path, case: CaseConfig, end) -> bool:
    """Whether ``output`` is the finished run of ``case`` up to ``end`` (s)."""
    if not output.is_file():
        return False
    try:
        end = float(end)
        with h5py.File(output, "r") as f:
            same = json.loads(f.attrs["parameters"]) == json.loads(case.model_dump_json())
            last = float(f["frames/time"][-1])
    except (OSError, KeyError, ValueError, IndexError, TypeError):
        return False
    return same and abs(last - end) <= 0.5 * case.output.frame_interval


def _finished_run(output: Path, case: CaseConfig) -> str | None:
    """Why ``output``, a finished run that ``--resume`` cannot continue, is not this one: of
    another case, or of this case to another end (a clause); None where it is no finished
    run."""
    if not output.is_file():
        return None
    try:
        with h5py.File(output, "r") as f:
            same = json.loads(f.attrs["parameters"]) == json.loads(case.model_dump_json())
            last = float(f["frames/time"][-1])
    except (OSError, KeyError, ValueError, IndexError, TypeError):
        return None
    if not same:
        return "a finished run of another case (its settings differ from these)"
    return f"this case's finished run, which ends at {last:g} s"


def refuse_finished_run(output: Path, case: CaseConfig, force: bool) -> None:
    """Refuse to start a run over ``output`` where it holds a finished CFD-DEM run, unless
    ``force``: a finished run keeps no checkpoint, so what it took is lost once replaced.

    Raises
    ------
    InputError
        Naming what the file holds and the fixes.
    """
    finished = None if force else _finished_run(Path(output), case)
    if finished is not None:
        raise InputError(f"{output}: holds {finished}; a finished run is not replaced "
                         "without --force (in Python force=True): give another output name, "
                         "or add --force to run it again")


def _remove_parts(parts: Path) -> None:
    """Remove the checkpoint folder (checkpoint first, so no state names missing segments)."""
    with contextlib.suppress(OSError):
        (parts / "checkpoint.h5").unlink()
    shutil.rmtree(parts, ignore_errors=True)


def time_step_advisory(case: CaseConfig) -> str | None:
    """What :func:`simulate` says (:class:`~cfbmarkov.errors.TimeStepAdvisory`) of a case
    whose DEM time step resolves a contact in fewer than the recommended 10 steps.

    Parameters
    ----------
    case : CaseConfig
        The case.

    Returns
    -------
    str or None
        ``DEM time step ... s resolves a contact in ... steps (...); 10 or more are
        recommended``, or None where the step resolves a contact in 10 or more steps (below
        5 the DEM refuses the run).
    """
    p = case.particles
    law = ContactLaw.from_config(case.contact, p.diameter, p.density)
    worst, message = contact_resolution(law, law.mass, case.numerics.dem_time_step)
    return message + "; 10 or more are recommended" if 5 <= worst < 10 else None


def check_periodic_case(case: CaseConfig) -> None:
    """Refuse, before anything is said or allocated, settings that the periodic riser's
    CFD-DEM cannot run: a DEM neighbour-search grid that does not fit the riser
    (:func:`cfbmarkov.simulate.dem.neighbours.search_grid`, with the cutoff of its
    particles, d + ``numerics.dem_skin``, and a periodic height), and a distributor
    pressure drop (a bed on a floor's, which the periodic riser has not).

    Parameters
    ----------
    case : CaseConfig
        The case.

    Raises
    ------
    InputError
        For ``numerics.dem_cells`` smaller than the cutoff or with fewer than 3 rows, a
        skin that makes the cutoff wider than the riser, or a positive
        ``riser.distributor_pressure_drop``; the message names the setting.
    """
    if case.riser.distributor_pressure_drop > 0:
        raise InputError(f"riser.distributor_pressure_drop {case.riser.distributor_pressure_drop:g}"
                         " Pa: the periodic riser has no distributor (the plate is a bed's on "
                         "a floor, bottom_wall=True in Python); leave it out")
    cells = case.numerics.dem_cells
    search_grid(case.riser.width, case.riser.height,
                case.particles.diameter + case.numerics.dem_skin,
                None if cells == "auto" else cells, periodic=True)


#: riser sizes beyond this many particle diameters are noted as a likely slip of units
#: (the paper's riser: 90 across, 950 up)
DIAMETERS_NOTED = 2000.0

#: particle densities below this (kg/m^3) are noted as a likely slip of units (g/cm^3)
DENSITY_NOTED = 100.0


def unlikely_units(case: CaseConfig) -> list[str]:
    """Settings whose values look like a slip of units: a riser more than
    :data:`DIAMETERS_NOTED` particle diameters across (a width in mm given as m), a
    particle density below :data:`DENSITY_NOTED` kg/m^3 (g/cm^3 given as kg/m^3).

    Parameters
    ----------
    case : CaseConfig
        The case.

    Returns
    -------
    list of str
        One sentence per such setting, naming it and the value in the case's units.
    """
    p, r = case.particles, case.riser
    notes = []
    for name, length in (("width", r.width), ("height", r.height)):
        across = length / p.diameter
        if across > (DIAMETERS_NOTED if name == "width" else 50 * DIAMETERS_NOTED):
            notes.append(f"riser.{name} {length:g} m is {across:.0f} particle diameters "
                         f"(d = {p.diameter:g} m): lengths are in m ({length:g} mm would be "
                         f"{length / 1000:g})")
    if p.density < DENSITY_NOTED:
        notes.append(f"particles.density {p.density:g} kg/m^3 is below {DENSITY_NOTED:g} kg/m^3: "
                     f"densities are in kg/m^3 ({p.density:g} g/cm^3 would be "
                     f"{p.density * 1000:g})")
    return notes


#: gas cells narrower than this many particle diameters are noted: the void fraction of a
#: cell then moves by a large step with each particle that enters it (unresolved CFD-DEM
#: wants cells of several diameters: Z. Peng, E. Doroodchi, C. Luo, B. Moghtaderi,
#: AIChE J. 60, 2000 (2014), on the void fraction's calculation in CFD-DEM)
CELL_DIAMETERS_NOTED = 3.0


def doubtful_physics(case: CaseConfig) -> list[str]:
    """Settings the CFD-DEM runs but whose results may not be what the case means: gas cells
    fewer than :data:`CELL_DIAMETERS_NOTED` particle diameters across, a superficial
    velocity below the case's minimum fluidization velocity, and frames so far apart that a
    particle rising at the superficial velocity or falling at its terminal velocity would
    cross the riser's height between two of them (the trajectory file cannot hold that
    move, and the run would stop at its next checkpoint).

    Parameters
    ----------
    case : CaseConfig
        The case.

    Returns
    -------
    list of str
        One sentence per such setting, with its numbers and what to change.
    """
    from cfbmarkov.simulate.cfd import terminal_velocity

    p, r, gas = case.particles, case.riser, case.gas
    notes = []
    nx, ny = case.numerics.cfd_cells
    cell = min(r.width / nx, r.height / ny)
    if cell < CELL_DIAMETERS_NOTED * p.diameter:
        notes.append(f"gas cells {r.width / nx:.3g} x {r.height / ny:.3g} m are "
                     f"{cell / p.diameter:.2g} particle diameters across (d = {p.diameter:g} "
                     f"m; {CELL_DIAMETERS_NOTED:g} or more recommended): a cell's void fraction "
                     "jumps with each particle that enters it, and the drag follows; give "
                     "fewer gas cells (numerics.cfd_cells)")
    if gas.superficial_velocity < gas.minimum_fluidization_velocity:
        notes.append(f"gas.superficial_velocity {gas.superficial_velocity:g} m/s is below the "
                     f"case's minimum fluidization velocity {gas.minimum_fluidization_velocity:g}"
                     " m/s: the gas does not carry the solids, which fall through the periodic "
                     "riser as in a downer")
    try:
        fastest = max(gas.superficial_velocity,
                      terminal_velocity(p.diameter, p.density, gas, r.gravity))
    except (InputError, ValueError, ZeroDivisionError):
        fastest = math.nan
    frame = case.output.frame_interval
    if math.isfinite(fastest) and fastest * frame > r.height:
        notes.append(f"frames {frame:g} s apart: a particle rising with the gas or falling at "
                     f"its terminal velocity ({fastest:.3g} m/s) crosses the riser's height "
                     f"{r.height:g} m in {r.height / fastest:.3g} s, and a move of more than "
                     "the height between two frames stops the run at its next checkpoint; "
                     f"give output.frame_interval at most {r.height / fastest:.2g} s")
    return notes


def _note_unlikely_units(case: CaseConfig, label: str = "") -> None:
    """Warn (:class:`~cfbmarkov.errors.CfbmarkovWarning`) of :func:`unlikely_units` and
    :func:`doubtful_physics`."""
    for note in unlikely_units(case) + doubtful_physics(case):
        warnings.warn((f"{label}: " if label else "") + note, CfbmarkovWarning, stacklevel=3)


def _advise_time_step(case: CaseConfig, label: str = "") -> None:
    """Warn (:class:`~cfbmarkov.errors.TimeStepAdvisory`) when the DEM step resolves a
    contact in fewer than 10 steps; ``label`` (a case) starts the message."""
    message = time_step_advisory(case)
    if message is not None:
        warnings.warn((f"{label}: " if label else "") + message, TimeStepAdvisory, stacklevel=3)


#: bytes of memory per particle: the DEM state and scratch (positions, velocities, forces,
#: spins, neighbour and contact lists of about 4 pairs per particle, pass events), and the
#: FRAMES_PER_WRITE frames held before a write (positions, velocities, laps)
PARTICLE_BYTES = 1200 + FRAMES_PER_WRITE * 40
#: bytes of memory per gas cell: the gas solver's fields and work arrays, and the held frames
#: of the stored fields (void fraction, velocity, pressure as float32)
CELL_BYTES = 60 * 8 + FRAMES_PER_WRITE * 16


def check_resources(case: CaseConfig, output: Path, end: float, fields: bool,
                    resuming: bool) -> None:
    """Refuse, before anything is allocated, a run whose memory or output would not fit.

    The memory is estimated as particles x :data:`PARTICLE_BYTES` + gas cells x
    (:data:`CELL_BYTES` + the pressure solver's band, 8 bytes x columns), against
    :func:`cfbmarkov.limits.memory_limit`; the disk as the frames x (36 bytes a particle:
    position, velocity, lap; 16 bytes a gas cell with ``fields``), twice (the segments and
    the merged file exist together before the segments are removed; once for a resumed run,
    whose segments so far are on disk already), against the free space beside ``output``.

    Raises
    ------
    InputError
        Naming the estimate, what is available and the fix.
    """
    from cfbmarkov.limits import check_disk, check_memory

    n = case.particles.number
    nx, ny = case.numerics.cfd_cells
    cells = nx * ny
    check_memory(n * PARTICLE_BYTES + cells * (CELL_BYTES + 8.0 * nx) + 50e6,
                 f"a CFD-DEM run of {n} particles on {nx} x {ny} gas cells",
                 "run fewer particles (particles.number, or --particles) or a coarser gas "
                 "grid (numerics.cfd_cells)")
    frames = math.floor(end / case.output.frame_interval + 1e-9) + 1
    per_frame = 36.0 * n + (16.0 * cells if fields else 0.0)
    copies = 1.0 if resuming else 2.0
    stored = f"{n} particles and the gas fields" if fields else f"{n} particles"
    check_disk(copies * frames * per_frame + 1e6, output,
               f"the run's output ({frames} frames x {stored}, with its segments until they "
               "are merged)", "shorten the run (--until), store fewer frames (a longer "
               "output.frame_interval), or write to a disk with more space")


def _check_safety(case: CaseConfig) -> None:
    """Refuse a gas step beyond its stability limit at the expected velocities, and more
    particles than the riser holds at the start."""
    p = case.particles
    check_placement(p.number, p.diameter, case.riser.width, case.riser.height)
    grid = GasGrid.from_config(case)
    expected = 2.0 * case.gas.superficial_velocity / 0.5       # slip through dense clusters
    limit = gas_stability_limit(grid, case.gas, (expected, expected))
    if case.numerics.cfd_time_step > limit:
        raise InputError(f"gas time step {case.numerics.cfd_time_step:g} s exceeds its stability "
                         f"limit {limit:.3g} s at velocities up to {expected:g} m/s "
                         f"(grid {grid.nx} x {grid.ny}): numerics.cfd_time_step at most "
                         f"{limit:.3g} s (a whole multiple of dem_time_step), or fewer, larger "
                         "gas cells (numerics.cfd_cells)")
    if min(grid.dx, grid.dy) < p.diameter:
        raise InputError(f"gas cells {grid.dx:.3g} x {grid.dy:.3g} m are smaller than the "
                         f"particles (d = {p.diameter:g} m): one particle fills a cell to the "
                         "void fraction's floor, and the drag is computed on that clipped "
                         f"value; give fewer gas cells (numerics.cfd_cells), each at least "
                         f"{CELL_DIAMETERS_NOTED:g} d across")
    if not math.isfinite(limit):
        warnings.warn("gas stability limit could not be evaluated", CfbmarkovWarning, stacklevel=2)
