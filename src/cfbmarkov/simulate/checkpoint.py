"""Checkpoints of a run: everything needed to continue a :class:`~.riser.CoupledRiser` bit
for bit, written atomically to HDF5, with the run's progress (segments, frames, wall time).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from cfbmarkov._atomic import atomic_path, h5_file
from cfbmarkov._names import first_line
from cfbmarkov.config import CaseConfig, case_difference
from cfbmarkov.errors import InputError
from cfbmarkov.simulate.riser import CoupledRiser

CHECKPOINT_VERSION = 1


def _write_group(group: h5py.Group, values: dict) -> None:
    for key, value in values.items():
        if isinstance(value, dict):
            _write_group(group.create_group(key), value)
        else:
            group.create_dataset(key, data=np.asarray(value))


def _read_group(group: h5py.Group) -> dict:
    return {k: (_read_group(v) if isinstance(v, h5py.Group) else v[()]) for k, v in group.items()}


def write_checkpoint(path: Path, riser: CoupledRiser, n_segments: int, frames: int,
                     wall_time: float, wall_history=None, run_id: str | None = None,
                     cpu_time: float | None = None) -> None:
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
    run_id : str, optional
        The run's identity, which its segments carry too.
    cpu_time : float, optional
        CPU time spent so far, s (of the processes that ran it; NaN where a part is
        unknown).
    """
    with atomic_path(path) as tmp:
        with h5_file(tmp, path) as f:
            f.attrs.update({"version": CHECKPOINT_VERSION, "n_segments": n_segments,
                            "frames": frames, "wall_time": wall_time,
                            "case": riser.case.model_dump_json()})
            if run_id is not None:
                f.attrs["run_id"] = run_id
            if cpu_time is not None:
                f.attrs["cpu_time"] = float(cpu_time)
            f.create_dataset("wall_history", data=np.asarray(
                wall_history if wall_history is not None else np.empty((0, 2)),
                dtype=np.float64).reshape(-1, 2))
            state = riser.state()
            _write_group(f.create_group("dem"), state["dem"])
            _write_group(f.create_group("gas"), state["gas"])
            f.attrs["cfd_steps"] = state["cfd_steps"]


def checkpoint_cpu_time(path: Path) -> float:
    """The CPU time (s) a checkpoint records as spent so far; NaN where it records none.

    Parameters
    ----------
    path : pathlib.Path
        A checkpoint written by :func:`write_checkpoint`.

    Returns
    -------
    float
    """
    try:
        with h5py.File(path, "r") as f:
            return float(f.attrs.get("cpu_time", float("nan")))
    except (OSError, ValueError, TypeError):
        return float("nan")


def read_checkpoint(path: Path, case: CaseConfig
                    ) -> tuple[CoupledRiser, int, int, float, np.ndarray, str | None]:
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
    run_id : str or None
        The run's identity (None in a checkpoint that records none).

    Raises
    ------
    InputError
        When the file cannot be read (damaged: truncated, zeroed, overwritten; named in one
        line) or was made with another configuration.
    """
    try:
        return _read_checkpoint(path, case)
    except InputError:
        raise
    except Exception as exc:        # noqa: BLE001 - whatever a damaged file raises
        raise InputError(f"{path}: damaged checkpoint, cannot resume ({first_line(exc)}); "
                         f"delete {path.parent} to start the run again") from None


def _read_checkpoint(path: Path, case: CaseConfig):
    with h5py.File(path, "r") as f:
        saved = CaseConfig.model_validate_json(f.attrs["case"])
        if saved != case:
            raise InputError(f"{path}: the checkpoint was made with another configuration "
                             f"({case_difference(saved, case)}); resume with the saved value, "
                             f"or delete {path.parent} and run without --resume to start "
                             "again")
        state = {"dem": _read_group(f["dem"]), "gas": _read_group(f["gas"]),
                 "cfd_steps": int(f.attrs["cfd_steps"])}
        meta = int(f.attrs["n_segments"]), int(f.attrs["frames"]), float(f.attrs["wall_time"])
        history = (f["wall_history"][()] if "wall_history" in f
                   else np.empty((0, 2)))
        run_id = f.attrs.get("run_id")
    if isinstance(run_id, bytes):
        run_id = run_id.decode(errors="replace")
    return (CoupledRiser.from_state(case, state), *meta, history,
            None if run_id is None else str(run_id))
