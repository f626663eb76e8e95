"""One case of ``cfbmarkov reproduce``: its stages, each a file in the case's folder.

:func:`run_case` runs (or finishes) the stages of one case in ``DIR/u<U>/``: the CFD-DEM
(``cfd-dem.h5``, resumed from its last checkpoint), then per model the fit
(``model-<name>.h5``), the prediction (``prediction-<name>.h5``) and the comparison
(``compare-<name>/``), recording wall and CPU times in ``timings.json``; a stage whose file
exists is skipped. :func:`compile_kernels` compiles the CFD-DEM's Numba kernels on a tiny
copy of a case before the workers start. :mod:`cfbmarkov.reproduce` schedules the cases.
"""

from __future__ import annotations

import json
import math
import os
import time as _time
import warnings
from pathlib import Path
from typing import Any, Sequence

from pydantic import ValidationError

from cfbmarkov._atomic import write_text_atomic
from cfbmarkov._names import parts_folder
from cfbmarkov._outputs import remove_stale_temporaries
from cfbmarkov.cases.scales import MODELS
from cfbmarkov.config import SPEED_ONLY, CaseConfig, case_difference, flat_settings
from cfbmarkov.errors import InputError, TimeStepAdvisory
from cfbmarkov.reproduce_ensemble import check_ensemble_folder, run_ensemble_cfd_dem


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def _record(folder: Path, stage: str, values: dict) -> None:
    timings = _read_json(folder / "timings.json")
    timings[stage] = values
    write_text_atomic(folder / "timings.json", json.dumps(timings, indent=2) + "\n")


def cfd_dem_timing(path: str | os.PathLike, window: tuple[float, float]) -> dict[str, Any]:
    """Wall time of a CFD-DEM file's run, in all and for a window.

    The window's wall time comes from the run's checkpoint wall-time history where it covers
    the window, else pro rata (``predict_window_estimated`` true).

    Parameters
    ----------
    path : str or os.PathLike
        A CFD-DEM trajectory file.
    window : (float, float)
        (start, stop), s of simulated time.

    Returns
    -------
    dict
        ``wall_s`` and ``simulated_s`` (s), ``particles``, ``particle_steps_per_s``,
        ``predict_window_wall_s`` (s) and ``predict_window_estimated``, and ``cpu_s`` where
        the run recorded its CPU time over all its resumes; empty when the file has no
        ``/provenance/run`` group.
    """
    import numpy as np

    from cfbmarkov.trajectories import Trajectories

    with Trajectories(path) as traj:
        group = traj.group("run")
        if group is None:
            return {}
        attrs = dict(group.attrs)
        history = group["wall_history"][()] if "wall_history" in group else np.empty((0, 2))
    wall = float(attrs.get("wall_time_s", float("nan")))
    simulated = float(attrs.get("simulated_s", float("nan")))
    out = {"wall_s": wall, "simulated_s": simulated,
           "particles": int(attrs.get("particles", 0)),
           "particle_steps_per_s": float(attrs.get("particle_steps_per_s", float("nan")))}
    cpu = float(attrs.get("cpu_time_s", float("nan")))
    if np.isfinite(cpu):            # the run's own, across its resumes
        out["cpu_s"] = cpu
    a, b = window
    times = history[:, 0] if history.size else np.empty(0)
    if times.size >= 2 and times[0] <= a + 1e-9 and times[-1] >= b - 1e-9:
        out["predict_window_wall_s"] = float(np.interp(b, times, history[:, 1])
                                             - np.interp(a, times, history[:, 1]))
        out["predict_window_estimated"] = False
    else:
        out["predict_window_wall_s"] = wall * (b - a) / simulated if simulated > 0 else float("nan")
        out["predict_window_estimated"] = True
    return out


def check_case_folder(folder: str | os.PathLike, case: CaseConfig) -> bool:
    """Refuse a case folder whose ``case.json`` holds another configuration than ``case``.

    Parameters
    ----------
    folder : str or os.PathLike
        The case folder (``DIR/u<U>``; missing: nothing to check).
    case : CaseConfig
        The case about to run there.

    Returns
    -------
    bool
        Whether the folder holds ``case.json`` (of this very configuration).

    Raises
    ------
    InputError
        One line: ``case.json`` is unreadable (delete it), or holds another configuration
        (naming the first differences; use another output directory or delete the folder).
    """
    folder = Path(folder)
    saved = folder / "case.json"
    if not saved.exists():
        return False
    try:
        previous = CaseConfig.model_validate_json(saved.read_text())
    except (OSError, ValueError):
        raise InputError(f"{saved}: unreadable case file; delete it to start this case "
                         "again") from None
    if previous != case:
        raise InputError(f"{folder} holds a run of another configuration ({saved}: "
                         f"{case_difference(previous, case)}); use another output directory "
                         "or delete that folder" + markov_only_hint(previous, case, folder))
    return True


def markov_only_hint(previous: CaseConfig, case: CaseConfig, folder: Path) -> str:
    """The way to other Markov settings on a case's CFD-DEM, where the two cases differ in
    their ``[markov]`` tables alone (else "")."""
    if previous.model_dump(exclude={"markov"}) != case.model_dump(exclude={"markov"}):
        return ""
    return (f" (the two differ in [markov] alone: to fit them on this CFD-DEM, link "
            f"{folder / 'cfd-dem.h5'} into the new folder's {folder.name}/ before the run, "
            "and only the Markov stages run)")


def run_case(case_json: str, directory: str, models: Sequence[str] = MODELS,
             progress: bool = True, threads: int | None = None,
             checkpoint_every: float = 0.5, kinetics: str | None = None,
             time_step_note: bool = True, ensemble: int = 1,
             device: str = "cpu") -> dict[str, Any]:
    """Run (or finish) every stage of one case in a folder.

    A module-level function, so that any executor (process pool, Dask) can run it.

    Parameters
    ----------
    case_json : str
        The case (a :class:`~cfbmarkov.config.CaseConfig` as JSON).
    directory : str
        The case folder (created).
    models : sequence of str, optional
        The models to fit, predict with and compare.
    progress : bool, optional
        Show the CFD-DEM's progress as whole lines on stderr, each starting with the case's
        folder name (``u6: CFD-DEM ...``; :func:`cfbmarkov.simulate.run.simulate`).
    threads : int, optional
        Numba threads of this worker.
    checkpoint_every : float, optional
        Simulated time between CFD-DEM checkpoints, s.
    kinetics : str, optional
        A kinetics file passed to each comparison (``compare --kinetics``); a comparison
        in place of another kinetics definition (or without one, or with one where none is
        given now) is redone.
    time_step_note : bool, optional
        Let the CFD-DEM say when its DEM time step resolves a contact in fewer than 10
        steps (:class:`~cfbmarkov.errors.TimeStepAdvisory`); False where the caller says it
        once for every case of its scale (:func:`cfbmarkov.reproduce.reproduce`).
    ensemble : int, optional
        CFD-DEM runs of the case (N > 1: an ensemble, :mod:`cfbmarkov.reproduce_ensemble`:
        members ``cfd-dem-m<m>.h5``, the models fitted on their fitting windows pooled and
        compared on member 0's prediction window).
    device : {"cpu", "gpu"}, optional
        Where the DEM runs (``simulate --device``).

    Returns
    -------
    dict
        ``case`` (folder name), ``velocity`` (m/s), ``stages`` (stage -> "done",
        "resumed" or "skipped") and ``summaries`` (model -> compare summary).

    Raises
    ------
    InputError
        When the folder's ``case.json`` is unreadable or holds another configuration or
        another ensemble size, a ``cfd-dem.h5`` in place comes from other physics or ends
        before the prediction window, or a stage refuses its input.
    GpuUnavailable
        ``device="gpu"`` where no CUDA device is usable.
    """
    import numba

    from cfbmarkov.analysis.fit_checks import IntervalWarning, assess_fit
    from cfbmarkov.errors import SampleWarning
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.report.compare import SUMMARY, compare
    from cfbmarkov.simulate.run import simulate
    from cfbmarkov.trajectories import Trajectories

    if threads:
        numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    case = CaseConfig.model_validate_json(case_json)
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    label = folder.name
    stages: dict[str, str] = {}

    saved = folder / "case.json"
    if not check_case_folder(folder, case):
        write_text_atomic(saved, case.model_dump_json(indent=2) + "\n")

    m = case.markov
    check_ensemble_folder(folder, ensemble)
    reference = folder / "cfd-dem.h5"
    members = [reference]
    timing = {}
    if ensemble > 1:
        cpu = _time.process_time()
        with warnings.catch_warnings():
            if not time_step_note:
                warnings.simplefilter("ignore", TimeStepAdvisory)
            stages["cfd-dem"], members = run_ensemble_cfd_dem(
                case, folder, ensemble, device=device, checkpoint_every=checkpoint_every,
                progress=progress, label=label, check=check_reference)
        reference = members[0]
        if stages["cfd-dem"] != "skipped":
            timing["cpu_s"] = _time.process_time() - cpu
        timing["ensemble_members"] = ensemble
        timing["ensemble_device"] = device
    elif reference.exists():
        check_reference(reference, case)
        stages["cfd-dem"] = "skipped"
        previous = _read_json(folder / "timings.json").get("cfd_dem")
        if isinstance(previous, dict) and "cpu_s" in previous:
            timing["cpu_s"] = previous["cpu_s"]
    else:
        checkpoint = parts_folder(folder / "cfd-dem.h5") / "checkpoint.h5"
        resume = checkpoint.exists()
        cpu = _time.process_time()
        with warnings.catch_warnings():
            if not time_step_note:
                warnings.simplefilter("ignore", TimeStepAdvisory)
            if device == "gpu":       # the case itself, one member on the GPU
                from cfbmarkov.simulate.ensemble import simulate_ensemble

                resume = (folder / "cfd-dem.h5.parts" / "gpu-checkpoint.h5").exists()
                simulate_ensemble(case, reference, None, device="gpu",
                                  checkpoint_every=checkpoint_every, resume=resume,
                                  progress="lines" if progress else False, label=label)
            else:
                simulate(case, reference, checkpoint_every=checkpoint_every, resume=resume,
                         progress="lines" if progress else False, label=label)
        # this process's CPU time (Numba's compilation included where it compiled here);
        # a resumed run's own record, which holds the earlier processes' too, replaces it
        timing["cpu_s"] = _time.process_time() - cpu
        stages["cfd-dem"] = "resumed" if resume else "done"
    run_timing = cfd_dem_timing(reference, m.predict_window)
    if "cpu_s" in run_timing and stages["cfd-dem"] == "resumed":
        timing["cpu_s"] = run_timing["cpu_s"]
    elif stages["cfd-dem"] == "resumed":
        timing.pop("cpu_s")                 # the earlier processes' time is unknown
    _record(folder, "cfd_dem", {**run_timing, **timing})

    summaries = {}
    kinetics_id = None
    if kinetics is not None:
        from cfbmarkov.kinetics import load_kinetics
        from cfbmarkov.kinetics.fingerprint import kinetics_digest

        kinetics_id = kinetics_digest(load_kinetics(kinetics)) or "unserialisable"
    with Trajectories(reference) as ref:
        start, stop = m.predict_window
        span = long_run_span(m.fit_window, m.predict_window, float(ref.times[0]),
                             float(ref.times[-1]))
        for name in models:
            model_path = folder / f"model-{name}.h5"
            # what a worker stopped by the parent (terminate) or killed left half-written:
            # the reproduction holds its folder's lock, so no live writer owns them
            for target in (model_path, folder / f"prediction-{name}.h5",
                           folder / f"compare-{name}"):
                remove_stale_temporaries(target)
            if model_path.exists():
                model = MarkovModel.load(model_path)
                stages[f"fit-{name}"] = "skipped"
            else:
                t0, c0 = _time.perf_counter(), _time.process_time()
                model = _fit(name, ref, members, m)
                # what fit records (the fitting window's identity, by which the fitting
                # file is found wherever the folder goes, the cell fields for react, the
                # model's interval and the verdict on its sample, which predict, compare
                # and the report repeat), not the paper's fit: not timed
                t1, c1 = _time.perf_counter(), _time.process_time()
                with warnings.catch_warnings():     # no interval, the verdict: the report
                    warnings.simplefilter("ignore", IntervalWarning)        # says them
                    warnings.simplefilter("ignore", SampleWarning)
                    model = assess_fit(model, [ref, *members[1:]],
                                       [m.fit_window] * len(members),
                                       level=m.interval_level,
                                       resamples=m.interval_resamples)
                t0 += _time.perf_counter() - t1
                c0 += _time.process_time() - c1
                model.save(model_path)
                _record(folder, f"fit-{name}", {"wall_s": _time.perf_counter() - t0,
                                                "cpu_s": _time.process_time() - c0})
                stages[f"fit-{name}"] = "done"
            prediction = folder / f"prediction-{name}.h5"
            if prediction.exists():
                stages[f"predict-{name}"] = "skipped"
            else:
                t0, c0 = _time.perf_counter(), _time.process_time()
                with warnings.catch_warnings():     # the verdict: in the report's warnings
                    warnings.simplefilter("ignore", SampleWarning)
                    model.predict(ref, start=start, duration=stop - start, seed=case.seed,
                                  output=prediction)
                _record(folder, f"predict-{name}", {"wall_s": _time.perf_counter() - t0,
                                                    "cpu_s": _time.process_time() - c0})
                stages[f"predict-{name}"] = "done"
            out = folder / f"compare-{name}"
            done = _read_json(out / SUMMARY) if (out / SUMMARY).exists() else None
            if done is not None and _same_kinetics(done, kinetics_id):
                summaries[name] = done
                stages[f"compare-{name}"] = "skipped"
            else:
                t0, c0 = _time.perf_counter(), _time.process_time()
                summaries[name] = compare(ref, prediction, window=(start, stop), output=out,
                                          bin_width=m.lag, level=m.interval_level,
                                          resamples=m.interval_resamples,
                                          long_run_span=span, kinetics=kinetics,
                                          allow_empty=True)   # Table 3: "no residences"
                _record(folder, f"compare-{name}", {"wall_s": _time.perf_counter() - t0,
                                                    "cpu_s": _time.process_time() - c0})
                stages[f"compare-{name}"] = "done"
    return {"case": label, "velocity": case.gas.superficial_velocity, "stages": stages,
            "summaries": summaries}


def _same_kinetics(summary: dict, digest: str | None) -> bool:
    """Whether a finished comparison's summary holds the kinetics asked for now: none where
    none is asked for, else the same definition (:func:`cfbmarkov.kinetics.fingerprint.kinetics_digest`;
    a summary that does not record it is formed again)."""
    if digest is None:
        return "kinetics" not in summary
    source = summary.get("kinetics_source")
    return (bool(summary.get("kinetics")) and isinstance(source, dict)
            and source.get("digest") == digest)


def _fit(name: str, ref, members: Sequence[Path], m) -> Any:
    """Model ``name`` on the fitting window of ``ref`` (one run), or of every member
    pooled (an ensemble, ``members`` its files with ``ref`` open on the first)."""
    from cfbmarkov.markov.select import fit_by_name
    from cfbmarkov.markov.select.choice import fit_pooled_by_name
    from cfbmarkov.trajectories import Trajectories

    coherent = m.coherent_auto and name == "auto"
    if len(members) == 1:
        return fit_by_name(name, ref, window=m.fit_window, columns=m.columns, rows=m.rows,
                           lag=m.lag, coherent=coherent)
    import contextlib

    with contextlib.ExitStack() as stack:
        runs = [ref] + [stack.enter_context(Trajectories(p)) for p in members[1:]]
        return fit_pooled_by_name(name, runs, window=m.fit_window, columns=m.columns,
                                  rows=m.rows, lag=m.lag, coherent=coherent)


def long_run_span(fit_window, predict_window, first: float, last: float
                  ) -> tuple[float, float] | None:
    """The span of a reproduction's CFD-DEM whose other windows give the long-run baseline.

    From one window length before the fitting window (never within the run's first window
    length, its start-up from rest) to the file's last frame; None when that span holds
    fewer than two whole windows, aligned with the analysis window, besides it (one would
    be the persistence baseline again; :func:`cfbmarkov.analysis.stationarity.long_run_baseline`).

    Parameters
    ----------
    fit_window, predict_window : (float, float)
        The case's fitting and analysis windows (s).
    first, last : float
        The CFD-DEM file's first and last frame times (s).

    Returns
    -------
    (float, float) or None
        The span (s). The paper's protocol (fit 10-15 s, analysis 15-20 s of a 0-20 s
        run): 5-20 s, whose other windows are 5-10 and 10-15 s.
    """
    a, b = (float(t) for t in predict_window)
    length = b - a
    tol = 1e-9 * max(1.0, abs(last))
    start = max(first, float(fit_window[0]) - length, first + length)
    if not (length > 0 and last > start):
        return None
    before = math.floor((a - start + tol) / length)
    after = math.floor((last - b + tol) / length)
    return (start, last) if before + after >= 2 else None


#: the parts of a case that make the CFD-DEM (the Markov model and output times may differ)
PHYSICS = ("seed", "riser", "particles", "gas", "contact", "numerics")


def check_reference(path: Path, case: CaseConfig) -> None:
    """Refuse a CFD-DEM file found in place that does not serve ``case``.

    It must come from this case's physics and cover its
    prediction window (one made by ``cfbmarkov simulate`` may be dropped in; the settings
    that change the speed only, :data:`cfbmarkov.config.SPEED_ONLY`, may differ); a file
    of another source must hold the case's particles in its riser (the report states the
    case's operating conditions).

    Parameters
    ----------
    path : pathlib.Path
        The trajectory file (``DIR/u<U>/cfd-dem.h5``).
    case : CaseConfig
        The case it is to serve.

    Raises
    ------
    InputError
        One line: another particle count or riser size, another physics than the case's
        (a file made by ``simulate``), or an end before the prediction window's.
    """
    from cfbmarkov.trajectories import Trajectories

    with Trajectories(path) as traj:
        made_by, last = traj.parameters, float(traj.times[-1])
        held = (traj.n_particles, float(traj.width), float(traj.height))
    wanted = (case.particles.number, case.riser.width, case.riser.height)
    if held[0] != wanted[0] or any(abs(a - b) > 1e-9 * max(1.0, b)
                                   for a, b in zip(held[1:], wanted[1:])):
        # the report's operating conditions (hold-up, particles) are the case's: a file of
        # another riser would be reported as this case's
        raise InputError(f"{path} holds {held[0]} particles in a {held[1]:g} m x {held[2]:g} m "
                         f"riser, case {case.name} {wanted[0]} in {wanted[1]:g} m x "
                         f"{wanted[2]:g} m: give overrides that match the file "
                         "(particles.number, riser.width, riser.height), or move it away")
    if made_by:
        try:
            made = CaseConfig.model_validate(made_by)
        except ValidationError:         # not a case: another source, e.g. imported data
            made = None
        if made is not None:
            a, b = flat_settings(made), flat_settings(case)
            differs = sorted({k.split(".")[0] for k in set(a) | set(b)
                              if k.split(".")[0] in PHYSICS and k not in SPEED_ONLY
                              and a.get(k) != b.get(k)}, key=PHYSICS.index)
            if differs:
                raise InputError(f"{path} was simulated with other {', '.join(differs)} than "
                                 f"case {case.name}; move it away or use another directory")
    if last < case.markov.predict_window[1] - 1e-9:
        raise InputError(f"{path} ends at {last:g} s, before the end of the prediction window "
                         f"({case.markov.predict_window[1]:g} s)")


#: particles of the tiny riser that compiles the kernels (:func:`compile_kernels`)
WARM_UP_PARTICLES = 60


def compile_kernels(case_json: str, part: str) -> float:
    """Compile one part of the Numba kernels a case's CFD-DEM runs, on a tiny copy of the
    case (``WARM_UP_PARTICLES`` particles, one gas step), so that Numba writes them to its
    cache: ``"dem"`` the DEM step (neighbour list, contacts, integration), ``"gas"``
    everything else of a gas step (void fraction, drag, deposits, the gas solve).

    Two workers that each compile one part at the same time, then load the other from the
    cache, spend about 15 s instead of 26 s each before their first step (the quick scale,
    measured). Results do not depend on it: the kernels are the same, compiled once.

    Parameters
    ----------
    case_json : str
        A case (:class:`~cfbmarkov.config.CaseConfig` as JSON) of the run.
    part : {"dem", "gas"}
        Which kernels.

    Raises
    ------
    pydantic.ValidationError
        For a case that is not valid JSON of a case.

    Returns
    -------
    float
        Seconds spent.
    """
    import warnings

    import numpy as np

    from cfbmarkov.simulate.riser import CoupledRiser

    started = _time.perf_counter()
    case = CaseConfig.model_validate_json(case_json)
    case = case.model_copy(update={"particles": case.particles.model_copy(
        update={"number": WARM_UP_PARTICLES})})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # the case's own run gives its notes
        riser = CoupledRiser.initial(case)
    if part == "dem":
        riser.dem.step(1, external_force=np.zeros((riser.dem.n_particles, 2)))
    else:
        riser._gas_step()
    return _time.perf_counter() - started


__all__ = ["PHYSICS", "WARM_UP_PARTICLES", "cfd_dem_timing", "check_case_folder",
           "check_reference", "compile_kernels", "long_run_span", "run_case"]
