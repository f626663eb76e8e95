"""``cfbmarkov reproduce``: the paper end to end, one file per stage, through an executor.

For each fluidizing velocity U (3, 4, 6 and 8 m/s by default) a *case* runs these stages in
its own folder ``DIR/u<U>/``; every stage is a file, written atomically, so a rerun skips
what is done and resumes what was interrupted (the CFD-DEM from its last checkpoint)::

    case.json                   the exact configuration, U included (a rerun with another one
                                is refused; a rerun of a folder without it writes it): the
                                report reads U from here, not from the folder name
    cfd-dem.h5                  CFD-DEM 0..end (frames, exact pass events, gas fields)
    model-<name>.h5             Markov model fitted on the fitting window (paper, mle, auto)
    prediction-<name>.h5        Monte Carlo over the prediction window, started from the
                                CFD-DEM state at its start
    compare-<name>/             RTD, mixing and figures against the CFD-DEM (summary.json)
    timings.json                wall and CPU times of the stages (s; CPU time of the
                                process that ran the stage, all its threads)

``DIR/reproduce.json`` names the scale and cases; ``DIR/report.html`` (with ``report.md``
and ``figures/``) is written when every case is done.

Cases run through a :class:`concurrent.futures.Executor`: in this process for one worker,
a process pool on the local machine by default, or any executor given, such as a Dask
cluster's (``dask.distributed.Client(address).get_executor()``, ``--scheduler ADDRESS``);
the workers must see ``DIR`` on a shared file system.

Scales (:data:`cfbmarkov.cases.scales.SCALES`): ``paper`` is the paper's riser and times;
``quick`` is a reduced riser that keeps the particles, gas, hold-up, cell size and
contact-time resolution of the paper (see :data:`cfbmarkov.cases.scales.QUICK_REDUCTIONS`),
so that the whole pipeline runs in minutes.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import json
import math
import os
import time as _time
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from pydantic import ValidationError

from cfbmarkov._atomic import write_text_atomic
from cfbmarkov.config import SPEED_ONLY, CaseConfig, case_difference, flat_settings
from cfbmarkov.errors import CfbmarkovError, InputError

from cfbmarkov.cases.scales import (  # noqa: E402  (the scales and cases of a reproduction)
    MODELS,
    QUICK_REDUCTIONS,
    SCALES,
    VELOCITIES,
    Scale,
    as_scale,
    case_name,
    load_overrides,
    scale_cases,
)

__all__ = ["MODELS", "QUICK_REDUCTIONS", "SCALES", "VELOCITIES", "Scale", "case_name",
           "load_overrides", "reproduce", "run_case", "scale_cases"]


# -- one case ---------------------------------------------------------------------------------
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
        ``predict_window_wall_s`` (s) and ``predict_window_estimated``; empty when the file
        has no ``/provenance/run`` group.
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


def run_case(case_json: str, directory: str, models: Sequence[str] = MODELS,
             progress: bool = True, threads: int | None = None,
             checkpoint_every: float = 0.5) -> dict[str, Any]:
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

    Returns
    -------
    dict
        ``case`` (folder name), ``velocity`` (m/s), ``stages`` (stage -> "done",
        "resumed" or "skipped") and ``summaries`` (model -> compare summary).

    Raises
    ------
    InputError
        When the folder's ``case.json`` is unreadable or holds another configuration, a
        ``cfd-dem.h5`` in place comes from other physics or ends before the prediction
        window, or a stage refuses its input.
    """
    import numba

    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.select import fit_by_name
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
    if saved.exists():
        try:
            previous = CaseConfig.model_validate_json(saved.read_text())
        except (OSError, ValueError):
            raise InputError(f"{saved}: unreadable case file; delete it to start this case "
                             "again") from None
        if previous != case:
            raise InputError(f"{folder} holds a run of another configuration ({saved}: "
                             f"{case_difference(previous, case)}); use another output directory "
                             "or delete that folder")
    else:
        write_text_atomic(saved, case.model_dump_json(indent=2) + "\n")

    m = case.markov
    reference = folder / "cfd-dem.h5"
    timing = {}
    if reference.exists():
        _check_reference(reference, case)
        stages["cfd-dem"] = "skipped"
        previous = _read_json(folder / "timings.json").get("cfd_dem")
        if isinstance(previous, dict) and "cpu_s" in previous:
            timing["cpu_s"] = previous["cpu_s"]
    else:
        checkpoint = folder / "cfd-dem.h5.parts" / "checkpoint.h5"
        resume = checkpoint.exists()
        cpu = _time.process_time()
        simulate(case, reference, checkpoint_every=checkpoint_every, resume=resume,
                 progress="lines" if progress else False, label=label)
        # this process's CPU time (Numba's compilation included where it compiled here)
        timing["cpu_s"] = _time.process_time() - cpu
        stages["cfd-dem"] = "resumed" if resume else "done"
    _record(folder, "cfd_dem", {**cfd_dem_timing(reference, m.predict_window), **timing})

    summaries = {}
    with Trajectories(reference) as ref:
        start, stop = m.predict_window
        span = long_run_span(m.fit_window, m.predict_window, float(ref.times[0]),
                             float(ref.times[-1]))
        for name in models:
            model_path = folder / f"model-{name}.h5"
            if model_path.exists():
                model = MarkovModel.load(model_path)
                stages[f"fit-{name}"] = "skipped"
            else:
                t0, c0 = _time.perf_counter(), _time.process_time()
                model = fit_by_name(name, ref, window=m.fit_window, columns=m.columns,
                                    rows=m.rows, lag=m.lag,
                                    coherent=m.coherent_auto and name == "auto")
                model.save(model_path)
                _record(folder, f"fit-{name}", {"wall_s": _time.perf_counter() - t0,
                                                "cpu_s": _time.process_time() - c0})
                stages[f"fit-{name}"] = "done"
            prediction = folder / f"prediction-{name}.h5"
            if prediction.exists():
                stages[f"predict-{name}"] = "skipped"
            else:
                t0, c0 = _time.perf_counter(), _time.process_time()
                model.predict(ref, start=start, duration=stop - start, seed=case.seed,
                              output=prediction)
                _record(folder, f"predict-{name}", {"wall_s": _time.perf_counter() - t0,
                                                    "cpu_s": _time.process_time() - c0})
                stages[f"predict-{name}"] = "done"
            out = folder / f"compare-{name}"
            if (out / SUMMARY).exists():
                summaries[name] = _read_json(out / SUMMARY)
                stages[f"compare-{name}"] = "skipped"
            else:
                t0, c0 = _time.perf_counter(), _time.process_time()
                summaries[name] = compare(ref, prediction, window=(start, stop), output=out,
                                          bin_width=m.lag, level=m.interval_level,
                                          resamples=m.interval_resamples,
                                          long_run_span=span)
                _record(folder, f"compare-{name}", {"wall_s": _time.perf_counter() - t0,
                                                    "cpu_s": _time.process_time() - c0})
                stages[f"compare-{name}"] = "done"
    return {"case": label, "velocity": case.gas.superficial_velocity, "stages": stages,
            "summaries": summaries}


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


def _check_reference(path: Path, case: CaseConfig) -> None:
    """A CFD-DEM file found in place must come from this case's physics and cover its
    prediction window (one made by ``cfbmarkov simulate`` may be dropped in; the settings
    that change the speed only, :data:`cfbmarkov.config.SPEED_ONLY`, may differ)."""
    from cfbmarkov.trajectories import Trajectories

    with Trajectories(path) as traj:
        made_by, last = traj.parameters, float(traj.times[-1])
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


# -- executors ---------------------------------------------------------------------------------
class InlineExecutor(cf.Executor):
    """Runs each call at once in this process (one worker; errors surface in the future)."""

    def submit(self, fn, /, *args, **kwargs):
        """Run ``fn(*args, **kwargs)`` now.

        Parameters
        ----------
        fn : callable
            The call.
        *args, **kwargs
            Its arguments.

        Returns
        -------
        concurrent.futures.Future
            Done, holding the result or the exception (KeyboardInterrupt is raised).
        """
        future: cf.Future = cf.Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:      # noqa: B036 - handed to the caller via the future
            if isinstance(exc, KeyboardInterrupt):
                raise
            future.set_exception(exc)
        return future


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


def _limit_threads(threads: int) -> None:
    """Worker initializer: the thread count, cfbmarkov's warnings as one line each (``note:
    ...``, they cannot reach the caller's filters), and Ctrl-C left to the parent (which stops
    the workers and says so in one line) instead of a traceback from every worker."""
    import signal

    import numba

    from cfbmarkov._console import install_one_line_notes

    install_one_line_notes()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _stop_workers(executor) -> None:
    """Terminate a process pool's workers now (Ctrl-C: their cases resume from their last
    checkpoint on a rerun)."""
    for process in list(getattr(executor, "_processes", {}).values()):
        with contextlib.suppress(Exception):
            process.terminate()


def local_executor(jobs: int | None = None, n_cases: int = 1) -> tuple[cf.Executor, int]:
    """Executor on this machine: in-process for one job, else a process pool.

    Parameters
    ----------
    jobs : int, optional
        Workers (default: min(cases, cores)).
    n_cases : int, optional
        Number of cases to run.

    Returns
    -------
    executor : concurrent.futures.Executor
        :class:`InlineExecutor` for one job, else a spawn-based process pool.
    threads : int
        Numba threads per worker (cores // jobs, at least 1).

    Raises
    ------
    InputError
        When ``jobs`` is less than 1.
    """
    cores = os.cpu_count() or 1
    jobs = min(n_cases, cores) if jobs is None else int(jobs)
    if jobs < 1:
        raise InputError(f"--jobs {jobs} must be at least 1")
    threads = max(1, cores // jobs)
    if jobs == 1:
        return InlineExecutor(), threads
    import multiprocessing

    return cf.ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                                  initializer=_limit_threads, initargs=(threads,)), threads


def dask_executor(address: str) -> tuple[cf.Executor, Any]:
    """A Dask distributed cluster's executor.

    Parameters
    ----------
    address : str
        The scheduler's address.

    Returns
    -------
    executor : concurrent.futures.Executor
        The client's executor.
    client : dask.distributed.Client
        The client, to close afterwards.

    Raises
    ------
    InputError
        When dask.distributed is not installed or the scheduler cannot be reached.
    """
    try:
        from dask.distributed import Client
    except ImportError:
        raise InputError("--scheduler needs dask.distributed: pip install 'cfbmarkov[distributed]'"
                         ) from None
    try:
        client = Client(address, timeout=30)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
    return client.get_executor(pure=False), client


# -- the whole reproduction --------------------------------------------------------------------
def reproduce(directory: str | os.PathLike, scale: str | Scale = "quick",
              velocities: Iterable[float] = VELOCITIES, *, overrides: dict | None = None,
              models: Sequence[str] = MODELS, executor: cf.Executor | None = None,
              scheduler: str | None = None, jobs: int | None = None, progress: bool = True,
              report: bool = True, log: Callable[[str], None] = print) -> Path:
    """Run every case of a scale into a folder (resuming what is there) and write the report.

    Cases go to ``executor`` if given, else to the Dask cluster at ``scheduler``, else to
    :func:`local_executor` with ``jobs`` workers.

    Parameters
    ----------
    directory : str or os.PathLike
        The run folder (created).
    scale : str or Scale, optional
        A name in :data:`SCALES` or a scale.
    velocities : iterable of float, optional
        Superficial gas velocities U, m/s.
    overrides : dict, optional
        Changes to every case (nested tables of a case file).
    models : sequence of str, optional
        The models of each case.
    executor : concurrent.futures.Executor, optional
        Runs the cases (left open).
    scheduler : str, optional
        Address of a Dask scheduler.
    jobs : int, optional
        Local workers.
    progress : bool, optional
        Show the CFD-DEM's progress: whole lines on stderr, each starting with its case
        (``u6: CFD-DEM 1.50/5 s simulated, ...``), at the start, at every tenth of the
        simulated time and at the end.
    report : bool, optional
        Write ``report.html`` when every case is done.
    log : callable, optional
        Receives one line per event.

    Returns
    -------
    pathlib.Path
        ``report.html`` (the folder with ``report=False``).

    Raises
    ------
    InputError
        For an unknown model name or scale, unusable velocities or overrides, repeated
        velocities, an output that exists and is not a directory, an unusable executor
        setting, a failed case, or a report that cannot be written.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Section 3; ``docs/reproduce.md``.
    """
    from cfbmarkov.markov.select import parse_model_name

    for name in models:
        parse_model_name(name)
    scale = as_scale(scale)
    cases = scale_cases(scale, velocities, overrides)
    names = [case_name(c.gas.superficial_velocity) for c in cases]
    if len(set(names)) != len(names):
        raise InputError(f"velocities repeat: {', '.join(names)}")
    out = Path(directory)
    if out.exists() and not out.is_dir():
        raise InputError(f"output {out} exists and is not a directory")
    from cfbmarkov._outputs import claim_output

    with claim_output(out, "reproduce", "folder"):    # lock and folder before any work
        return _reproduce(out, scale, cases, names, overrides, models, executor, scheduler,
                          jobs, progress, report, log)


def _reproduce(out: Path, scale: Scale, cases, names, overrides, models, executor, scheduler,
               jobs, progress, report, log) -> Path:
    client = None
    threads = None
    own = executor is None
    if executor is None and scheduler:      # refused settings leave no folder behind
        executor, client = dask_executor(scheduler)
    elif executor is None:
        executor, threads = local_executor(jobs, len(cases))
    out.mkdir(parents=True, exist_ok=True)
    from cfbmarkov import __version__

    manifest = {"scale": scale.name, "description": scale.description,
                "reductions": list(scale.reductions), "overrides": overrides or {},
                "cases": names, "models": list(models), "version": __version__}
    write_text_atomic(out / "reproduce.json", json.dumps(manifest, indent=2) + "\n")
    log(f"reproduce ({scale.name} scale): {len(cases)} case(s) {', '.join(names)} in {out}")
    started = _time.perf_counter()
    failures: list[str] = []
    try:
        if isinstance(executor, cf.ProcessPoolExecutor) and own and cases:
            # two workers compile half the CFD-DEM's kernels each, then load the other half
            # from Numba's cache (a run whose kernels are cached loses about a second)
            warm = [executor.submit(compile_kernels, cases[0].model_dump_json(), part)
                    for part in ("dem", "gas")]
            for future in warm:
                with contextlib.suppress(Exception):    # the case itself will say what fails
                    future.result()
        futures = {executor.submit(run_case, case.model_dump_json(), str(out / name),
                                   tuple(models), progress, threads): name
                   for case, name in zip(cases, names)}
        for future in cf.as_completed(futures):
            name = futures[future]
            try:
                result = future.result()
            except CfbmarkovError as exc:
                failures.append(f"{name}: {exc}")
                log(f"{name}: failed: {exc}")
                continue
            done = ", ".join(f"{k} {v}" for k, v in result["stages"].items())
            log(f"{name}: {done}")
            for est, s in result["summaries"].items():
                log(f"{name} {est:>5}: PD E(RT) {_fmt(s.get('pd_rt_mean'), '+.1f')} %, PD SD(RT) "
                    f"{_fmt(s.get('pd_rt_sd'), '+.1f')} %, MD {_fmt(s.get('md_rtd'), '.3g')}, "
                    f"mixing RMS {_fmt(s.get('mixing_rms'), '.3g')}")
            if result["summaries"]:
                log(rtd_line(name, result["summaries"]))
        if not failures:
            log(f"all cases done in {_time.perf_counter() - started:.0f} s")
            if report:
                from cfbmarkov.report.reproduction import write_report

                # a process pool of its own, idle now, draws half the report's figures
                pool = executor if own and isinstance(executor, cf.ProcessPoolExecutor) else None
                html = write_report(out, executor=pool)
    except KeyboardInterrupt:
        if own:
            _stop_workers(executor)
        raise
    finally:
        if own:
            try:
                executor.shutdown(wait=True, cancel_futures=True)
            except TypeError:             # Dask's ClientExecutor has no cancel_futures
                executor.shutdown(wait=True)
        if client is not None:
            with contextlib.suppress(Exception):
                client.close()
    if failures:
        raise InputError(f"{len(failures)} case(s) failed; rerun to resume: " + "; ".join(failures))
    return html if report else out


def rtd_line(case: str, summaries: dict[str, dict]) -> str:
    """One line on how finely a case's RTDs are resolved: bins spanned (the 1-99 % range of
    the residences, :func:`cfbmarkov.observed.metrics.rtd_span`) and residences counted, for
    the CFD-DEM and each model.

    Parameters
    ----------
    case : str
        The case's name (``u8``).
    summaries : dict
        Model name -> its compare summary (``summary.json``).

    Returns
    -------
    str
        ``u8 RTD (bins of 0.005 s spanned, residences): CFD-DEM 14, 5321; paper 16, 5100; ...``
    """
    def side(summary, which):
        spanned = (summary.get("rtd_bins_spanned") or {}).get(which)
        count = (summary.get(which) or {}).get("rt_count")
        return f"{'n/a' if spanned is None else spanned}, {'n/a' if count is None else count}"

    first = next(iter(summaries.values()))
    width = first.get("bin_width")
    parts = [f"CFD-DEM {side(first, 'reference')}"]
    parts += [f"{est} {side(s, 'model')}" for est, s in summaries.items()]
    return (f"{case} RTD (bins of {_fmt(width, 'g')} s spanned, residences): "
            + "; ".join(parts))


def _fmt(value, spec: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return format(value, spec)


__all__ = ["MODELS", "InlineExecutor", "QUICK_REDUCTIONS", "SCALES", "Scale", "VELOCITIES",
           "case_name", "cfd_dem_timing", "dask_executor", "load_overrides", "local_executor",
           "reproduce", "rtd_line", "run_case", "scale_cases"]
