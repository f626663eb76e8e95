"""Ensembles: N independent runs of one case, seeds derived from the case's (orchestration).

Member m of an ensemble written to ``RUN.h5`` is the case with seed
:func:`member_seeds` ``(case.seed, N)[m]``, written to ``RUN-m<m>.h5``
(:func:`member_paths`). The seeds are the first 64-bit word of each child of
``numpy.random.SeedSequence(case.seed).spawn(N)``: member m's seed depends on the case's seed
and on m only, not on N, so member 3 of a 4-member ensemble is member 3 of a 10-member one.

On the CPU (``device="cpu"``) the members run one after another through
:func:`cfbmarkov.simulate.run.simulate`, each with its own checkpoints. On the GPU
(``device="gpu"``) they run side by side in one
:class:`~cfbmarkov.simulate.gpu.riser.GpuEnsembleRiser`, each written through its own
:class:`~cfbmarkov.segmented.SegmentedTrajectoryWriter` (segments in ``RUN-m<m>.h5.parts/``);
one checkpoint, ``RUN.h5.parts/gpu-checkpoint.h5``, holds all members. Either way ``resume``
continues an interrupted ensemble, and the result equals an uninterrupted run bit for bit.
"""

from __future__ import annotations

import contextlib
import json
import time as _time
import warnings
from pathlib import Path

import h5py
import numpy as np

from cfbmarkov._atomic import atomic_path, h5_file
from cfbmarkov._console import progress_mode
from cfbmarkov._outputs import claim_output
from cfbmarkov.config import CaseConfig, case_difference
from cfbmarkov.errors import CfbmarkovError, InputError, TimeStepAdvisory
from cfbmarkov.segmented import SegmentedTrajectoryWriter
from cfbmarkov.simulate.cfd import GasGrid
from cfbmarkov.simulate.checkpoint import _read_group, _write_group
from cfbmarkov.simulate.progress import Progress
from cfbmarkov.simulate.run import (FRAMES_PER_WRITE, _advise_time_step, _check_safety,
                                    _complete, _PendingFrames, refuse_finished_run, simulate)

MAX_MEMBERS = 1000


def member_seeds(seed: int, n: int) -> list[int]:
    """The seeds of an ensemble's members.

    Parameters
    ----------
    seed : int
        The case's seed.
    n : int
        Members.

    Returns
    -------
    list of int
        Member m's seed: the first 64-bit word of child m of
        ``numpy.random.SeedSequence(seed).spawn(n)`` (independent of ``n``).
    """
    return [int(c.generate_state(1, np.uint64)[0]) for c in np.random.SeedSequence(seed).spawn(n)]


def member_case(case: CaseConfig, seed: int) -> CaseConfig:
    """The case with another seed."""
    return case.model_copy(update={"seed": int(seed)})


def member_paths(output: str | Path, n: int) -> list[Path]:
    """``RUN-m0.h5`` ... ``RUN-m<n-1>.h5`` for ``output`` ``RUN.h5``."""
    output = Path(output)
    return [output.with_name(f"{output.stem}-m{m}{output.suffix}") for m in range(n)]


def simulate_ensemble(case: CaseConfig, output: str | Path, members: int | None, *,
                      device: str = "cpu", until: float | None = None, checkpoint_every: float = 1.0,
                      resume: bool = False, progress: bool | str = True, threads=None,
                      stop_after_frames: int | None = None, label: str = "",
                      force: bool = False) -> list[Path]:
    """Run ``members`` independent runs of ``case`` (seeds :func:`member_seeds`) to ``until``.

    Parameters
    ----------
    case : CaseConfig
        The case; its seed is the ensemble's.
    output : str or pathlib.Path
        ``RUN.h5``: the members are written to :func:`member_paths`.
    members : int or None
        N >= 1; None: the case itself (its own seed) written to ``output``, as
        :func:`~cfbmarkov.simulate.run.simulate` does (with ``device="gpu"``, a one-member
        GPU run).
    device : {"cpu", "gpu"}
        Where the DEM runs (see the module doc).
    until, checkpoint_every, resume, progress, force
        As :func:`cfbmarkov.simulate.run.simulate` (``force``: replace members that hold
        finished runs).
    threads : int, optional
        GPU threads per member (default :func:`~cfbmarkov.simulate.gpu.ensemble.default_threads`).
    stop_after_frames : int, optional
        GPU only: stop (as if killed) once this many frames are written (tests of resume).
    label : str, optional
        Starts each progress line (``LABEL member 3``, ``LABEL ensemble``).

    Returns
    -------
    list of pathlib.Path
        The members' trajectory files.

    Raises
    ------
    InputError
        A bad member count or device, or what :func:`~cfbmarkov.simulate.run.simulate` raises.
    GpuUnavailable
        ``device="gpu"`` where no CUDA device is usable.
    """
    if members is not None and not 1 <= int(members) <= MAX_MEMBERS:
        raise InputError(f"--ensemble: expected 1 to {MAX_MEMBERS} members, got {members}")
    if device not in ("cpu", "gpu"):
        raise InputError(f"--device: expected cpu or gpu, got {device!r}")
    output = Path(output)
    if members is None:
        paths, seeds = [output], [case.seed]
    else:
        paths = member_paths(output, int(members))
        seeds = member_seeds(case.seed, int(members))
    if device == "gpu":
        from cfbmarkov.simulate.gpu import require_gpu
        require_gpu()
        mode = progress_mode(progress)
        with contextlib.ExitStack() as stack:
            for p, seed in zip(paths, seeds):
                stack.enter_context(claim_output(p, "simulate", "trajectory"))
                if not resume:
                    refuse_finished_run(p, member_case(case, seed), force)
            return _simulate_gpu(case, output, paths, seeds, until, checkpoint_every, resume,
                                 mode, threads, stop_after_frames, label)
    end = case.output.end_time if until is None else float(until)
    if resume and members is not None and not any(
            p.exists() or p.with_name(p.name + ".parts").exists() for p in paths):
        # as a single run's --resume: a mistyped -o must not start every member afresh
        raise InputError(f"nothing to resume: none of the {len(paths)} members of {output} "
                         f"({paths[0].name}, ...) nor their checkpoints exist; start the "
                         "ensemble again without --resume")
    for m, (path, seed) in enumerate(zip(paths, seeds)):
        mcase = member_case(case, seed)
        parts = path.with_name(path.name + ".parts")
        started = (parts / "checkpoint.h5").exists()
        if resume and not started and _complete(path, mcase, end):
            continue
        simulate(mcase, path, until=until, checkpoint_every=checkpoint_every,
                 resume=resume and started, progress=progress,
                 label=f"{label} member {m}".strip(), force=force)
    return paths


def _writer_options(case: CaseConfig, seed: int) -> dict:
    return dict(ids=np.arange(case.particles.number), width=case.riser.width,
                height=case.riser.height, source="cfd-dem",
                parameters=json.loads(member_case(case, seed).model_dump_json()),
                with_velocity=True, frame_interval=case.output.frame_interval)


class _Member:
    """One member of a GPU ensemble seen as a DEM system by :class:`_PendingFrames`."""

    def __init__(self, dem, k, positions, velocities, laps):
        self._dem, self._k = dem, k
        self.positions, self.velocities, self.laps = positions, velocities, laps

    def drain_pass_events(self):
        return self._dem.drain_pass_events(self._k)


def _simulate_gpu(case, output, paths, seeds, until, checkpoint_every, resume, progress,
                  threads, stop_after_frames, label="") -> list[Path]:
    from cfbmarkov.simulate.gpu.riser import GpuEnsembleRiser
    n = len(paths)
    end = case.output.end_time if until is None else float(until)
    frame_dt = case.output.frame_interval
    cfd_dt = case.numerics.cfd_time_step
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
        raise InputError(f"run length {end:g} s is shorter than one frame ({frame_dt:g} s)")
    parts = output.with_name(output.name + ".parts")
    checkpoint = parts / "gpu-checkpoint.h5"
    grid = GasGrid.from_config(case)
    spacing = (grid.dx, grid.dy)
    options = [_writer_options(case, s) for s in seeds]
    if resume:
        if not checkpoint.exists():
            if all(_complete(p, member_case(case, s), end) for p, s in zip(paths, seeds)):
                return paths
            raise InputError(f"nothing to resume: {checkpoint} does not exist (the run "
                             "stopped before its first checkpoint); start it again without "
                             "--resume")
        _advise_time_step(case, "ensemble")
        riser, n_segments, frames, wall_time, history = _read(checkpoint, case, n, threads)
        if riser.time > end + 0.5 * cfd_dt:
            raise InputError(f"{checkpoint} holds the run at t = {riser.time:g} s, past the "
                             f"end asked for ({end:g} s): resume to a later --until, or "
                             "delete the folder to start again")
        writers = [SegmentedTrajectoryWriter.resume(p, k, **o)
                   for p, k, o in zip(paths, n_segments, options)]
        wall_history = [tuple(row) for row in history]
    else:
        if checkpoint.exists():
            raise InputError(f"{parts} holds an interrupted GPU run: add --resume to continue "
                             "it, or delete the folder to start again")
        _check_safety(case)
        _advise_time_step(case, "ensemble")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TimeStepAdvisory)
            riser = GpuEnsembleRiser.initial(case, seeds, threads=threads)
        writers = [SegmentedTrajectoryWriter(p, **o) for p, o in zip(paths, options)]
        pos, vel = riser.dem.positions_velocities()
        laps = riser.dem.laps
        for k, w in enumerate(writers):
            w.append(0.0, pos[k], vel[k], laps[k])
            w.append_fields(0.0, spacing, **riser.gas_fields(k))
        frames, wall_time, wall_history = 1, 0.0, [(0.0, 0.0)]
        parts.mkdir(parents=True, exist_ok=True)
    bar = Progress(progress, riser.time, end, n * case.particles.number,
                   f"{label} ensemble".strip())
    finished = False
    started = _time.perf_counter() - wall_time
    pending = [_PendingFrames(w, spacing) for w in writers]
    try:
        while riser.cfd_steps < total_steps:
            for _ in range(steps_per_frame):
                riser.step()
            pos, vel = riser.dem.positions_velocities()
            laps = riser.dem.laps
            for k, pf in enumerate(pending):
                pf.add(riser.time, _Member(riser.dem, k, pos[k], vel[k], laps[k]),
                       riser.gas_fields(k))
            frames += 1
            bar.update(frame_dt, steps_per_frame * riser.dem_steps_per_cfd)
            checkpoint_now = (riser.cfd_steps % steps_per_checkpoint == 0
                              or riser.cfd_steps >= total_steps)
            if checkpoint_now or len(pending[0]) >= FRAMES_PER_WRITE:
                for pf in pending:
                    pf.flush()
            if checkpoint_now:
                segs = [w.close_segment() for w in writers]
                elapsed = _time.perf_counter() - started
                wall_history.append((riser.time, elapsed))
                _write(checkpoint, case, riser, segs, frames, elapsed, wall_history)
            if stop_after_frames is not None and frames >= stop_after_frames:
                for w in writers:
                    w.abort()
                return paths
    except CfbmarkovError as exc:
        for w in writers:
            w.abort()
        kept = f"; the last good checkpoint is in {checkpoint}" if checkpoint.exists() else ""
        raise type(exc)(f"{exc} (at t = {riser.time:.6g} s){kept}") from None
    except BaseException:
        for w in writers:
            w.abort()
        raise
    else:
        finished = True
    finally:
        bar.close(finished)
    wall = _time.perf_counter() - started
    for w in writers:
        w.finish(attach={"run": (
            {"wall_history": np.asarray(wall_history, dtype=np.float64)},
            {"wall_time_s": wall, "simulated_s": end, "particles": case.particles.number,
             "ensemble_members": n, "device": "gpu",
             "particle_steps_per_s": n * case.particles.number * total_steps
             * riser.dem_steps_per_cfd / max(wall, 1e-9), "exact_pass_events": True})})
    with contextlib.suppress(OSError):
        checkpoint.unlink()
    if parts.is_dir() and not any(parts.iterdir()):
        parts.rmdir()
    return paths


def _write(path: Path, case, riser, n_segments, frames, wall_time, wall_history) -> None:
    """Atomically write the ensemble's checkpoint (all members)."""
    with atomic_path(path) as tmp:
        with h5_file(tmp, path) as f:
            f.attrs.update({"version": 1, "frames": frames, "wall_time": wall_time,
                            "case": case.model_dump_json(), "members": riser.n_members})
            f.create_dataset("n_segments", data=np.asarray(n_segments, np.int64))
            f.create_dataset("wall_history", data=np.asarray(wall_history, np.float64))
            state = riser.state()
            _write_group(f.create_group("dem"), state["dem"])
            _write_group(f.create_group("gas"), state["gas"])
            f.attrs["cfd_steps"] = state["cfd_steps"]
            f.attrs["coupling"] = state["coupling"]
            f.attrs["deposit_chunks"] = state["deposit_chunks"]


def _read(path: Path, case: CaseConfig, n: int, threads):
    """The ensemble saved by :func:`_write`, and its progress."""
    from cfbmarkov.simulate.gpu.riser import GpuEnsembleRiser
    try:
        with h5py.File(path, "r") as f:
            saved = CaseConfig.model_validate_json(f.attrs["case"])
            if saved != case:
                raise InputError(f"{path}: the checkpoint was made with another configuration "
                                 f"({case_difference(saved, case)}); resume with the saved value, "
                                 f"or delete {path.parent} and run without --resume to start "
                                 "again")
            if int(f.attrs["members"]) != n:
                raise InputError(f"{path}: the checkpoint holds {int(f.attrs['members'])} "
                                 f"members, not {n}; resume with --ensemble "
                                 f"{int(f.attrs['members'])}")
            state = {"dem": _read_group(f["dem"]), "gas": _read_group(f["gas"]),
                     "cfd_steps": int(f.attrs["cfd_steps"])}
            if "coupling" in f.attrs:
                state["coupling"] = str(f.attrs["coupling"])
                state["deposit_chunks"] = int(f.attrs["deposit_chunks"])
            segs = [int(k) for k in f["n_segments"][()]]
            frames, wall = int(f.attrs["frames"]), float(f.attrs["wall_time"])
            history = f["wall_history"][()]
    except (OSError, KeyError) as exc:
        raise InputError(f"{path}: unreadable checkpoint ({exc})") from None
    return GpuEnsembleRiser.from_state(case, state, threads=threads), segs, frames, wall, history
