"""The CFD-DEM of one reproduction case as an ensemble (``reproduce --ensemble N``).

With N > 1 the case's CFD-DEM stage runs N independent members
(:func:`cfbmarkov.simulate.ensemble.simulate_ensemble`, seeds derived from the case's; on
the CPU one after another, or side by side with ``--device gpu``) to
``cfd-dem-m0.h5 ... cfd-dem-m<N-1>.h5`` in the case folder, and ``ensemble.json`` records
N. Each model is fitted on the members' fitting windows pooled
(:func:`cfbmarkov.markov.select.choice.fit_pooled_by_name`) and predicts and is compared on
member 0's prediction window, as a single run's model is on its run's: the pooled fit is
what more runs buy (a fitting window's transitions scatter between runs), and the
comparison stays one run's CFD-DEM against the model started from that run's state, so its
figures mean what they mean without an ensemble.
"""

from __future__ import annotations

import json
from pathlib import Path

from cfbmarkov._atomic import write_text_atomic
from cfbmarkov.config import CaseConfig
from cfbmarkov.errors import InputError

#: the file of a case folder that records the ensemble's size
ENSEMBLE_FILE = "ensemble.json"
#: the CFD-DEM file of a case (an ensemble's member m: ``cfd-dem-m<m>.h5``)
REFERENCE = "cfd-dem.h5"


def ensemble_paths(folder: Path, members: int) -> list[Path]:
    """The members' CFD-DEM files of a case folder: ``cfd-dem-m0.h5``, ..."""
    from cfbmarkov.simulate.ensemble import member_paths

    return member_paths(Path(folder) / REFERENCE, members)


def check_ensemble_folder(folder: Path, members: int, record: bool = True) -> None:
    """Refuse a case folder made with another ensemble size; record N (> 1) in it (unless
    ``record`` is False).

    A folder without ``ensemble.json`` holds a single run when it has any stage's file.

    Parameters
    ----------
    folder : pathlib.Path
        The case folder.
    members : int
        CFD-DEM runs per case (1: no ensemble).
    record : bool, optional
        Write ``ensemble.json`` where the folder has none.

    Raises
    ------
    InputError
        When the folder holds a reproduction with another number of runs per case.
    """
    folder = Path(folder)
    path = folder / ENSEMBLE_FILE
    previous = None
    if path.exists():
        try:
            previous = int(json.loads(path.read_text())["members"])
        except (OSError, ValueError, KeyError, TypeError):
            raise InputError(f"{path}: unreadable; delete the case folder to start it "
                             "again") from None
    elif (folder / REFERENCE).exists() or any(folder.glob("model-*.h5")):
        previous = 1
    if previous is not None and previous != members:
        raise InputError(f"{folder} holds a reproduction with {previous} CFD-DEM run(s) per "
                         f"case, not {members}; use another output directory or "
                         f"--ensemble {previous}")
    if record and members > 1 and previous is None:
        folder.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, json.dumps({"members": members}) + "\n")


def run_ensemble_cfd_dem(case: CaseConfig, folder: Path, members: int, *, device: str = "cpu",
                         checkpoint_every: float = 0.5, progress: bool = True,
                         label: str = "", check=None) -> tuple[str, list[Path]]:
    """Run (resume, or skip when done) the case's CFD-DEM as ``members`` runs.

    Parameters
    ----------
    case : CaseConfig
        The case; its seed is the ensemble's.
    folder : pathlib.Path
        The case folder.
    members : int
        N >= 2.
    device : {"cpu", "gpu"}, optional
        Where the DEM runs (:func:`~cfbmarkov.simulate.ensemble.simulate_ensemble`).
    checkpoint_every : float, optional
        Simulated time between checkpoints, s.
    progress : bool, optional
        Progress lines on stderr.
    label : str, optional
        Starts each progress line (the case's folder name).
    check : callable, optional
        ``check(path, member_case)``, called on each member file found in place (a
        reproduction's check that it comes from the member's physics).

    Returns
    -------
    stage : str
        "done", "resumed" or "skipped".
    paths : list of pathlib.Path
        The members' files.

    Raises
    ------
    InputError
        What :func:`~cfbmarkov.simulate.ensemble.simulate_ensemble` or ``check`` raises.
    GpuUnavailable
        ``device="gpu"`` where no CUDA device is usable.
    """
    from cfbmarkov.simulate.ensemble import member_case, member_seeds, simulate_ensemble

    folder = Path(folder)
    paths = ensemble_paths(folder, members)
    seeds = member_seeds(case.seed, members)
    if all(p.exists() for p in paths):
        if check is not None:
            for p, s in zip(paths, seeds):
                check(p, member_case(case, s))
        return "skipped", paths
    if device == "gpu":
        resume = (folder / (REFERENCE + ".parts") / "gpu-checkpoint.h5").exists()
    else:
        resume = any(p.exists() or (p.parent / (p.name + ".parts") / "checkpoint.h5").exists()
                     for p in paths)
    simulate_ensemble(case, folder / REFERENCE, members, device=device,
                      checkpoint_every=checkpoint_every, resume=resume,
                      progress="lines" if progress else False, label=label)
    return ("resumed" if resume else "done"), paths


__all__ = ["ENSEMBLE_FILE", "check_ensemble_folder", "ensemble_paths", "run_ensemble_cfd_dem"]
