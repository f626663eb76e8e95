"""``cfbmarkov reproduce``: the paper end to end, one file per stage, through an executor.

For each fluidizing velocity U (3, 4, 6 and 8 m/s by default) a *case* runs these stages in
its own folder ``DIR/u<U>/``; every stage is a file, written atomically, so a rerun skips
what is done and resumes what was interrupted (the CFD-DEM from its last checkpoint)::

    case.json                   the exact configuration, U included (a rerun with another one
                                is refused; a rerun of a folder without it writes it): the
                                report reads U from here, not from the folder name
    cfd-dem.h5                  CFD-DEM 0..end (frames, exact pass events, gas fields)
    cfd-dem-m<m>.h5             with ``ensemble`` N > 1 instead: the N members, the models
    ensemble.json               fitted on them pooled, N (:mod:`cfbmarkov.reproduce_ensemble`)
    model-<name>.h5             Markov model fitted on the fitting window (paper, mle, auto)
    prediction-<name>.h5        Monte Carlo over the prediction window, started from the
                                CFD-DEM state at its start
    compare-<name>/             RTD, mixing and figures against the CFD-DEM (summary.json)
    timings.json                wall and CPU times of the stages (s; CPU time of the
                                process that ran the stage, all its threads)

``DIR/reproduce.json`` names the scale and cases; ``DIR/report.html`` (with ``report.md``
and ``figures/``) is written when every case is done.

A case's stages are :func:`cfbmarkov.reproduce_case.run_case`; this module schedules the
cases. Cases run through a :class:`concurrent.futures.Executor`: in this process for one worker,
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

from cfbmarkov._atomic import write_text_atomic
from cfbmarkov._console import heartbeat
from cfbmarkov.cases.scales import (
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
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.reproduce_case import compile_kernels, run_case
from cfbmarkov.run_progress import EVERY as PROGRESS_EVERY
from cfbmarkov.run_progress import read_case, time_left_line


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


def _limit_threads(threads: int) -> None:
    """Worker initializer: the thread count, cfbmarkov's warnings as one line each (``note:
    ...``, they cannot reach the caller's filters), and Ctrl-C left to the parent (which stops
    the workers and says so in one line) instead of a traceback from every worker."""
    import signal

    import numba

    from cfbmarkov._console import install_one_line_notes

    install_one_line_notes()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # a parent killed (SIGKILL, SIGTERM) takes its workers with it, instead of leaving them
    # to finish the cases unwatched (Linux's PR_SET_PDEATHSIG = 1; elsewhere left as is)
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM), 0, 0, 0)
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _stop_workers(executor, folder: Path | None = None) -> None:
    """Terminate a process pool's workers now (Ctrl-C: their cases resume from their last
    checkpoint on a rerun), and remove the lock files, the temporaries and the empty
    checkpoint folders they leave in ``folder`` once they are gone
    (:func:`cfbmarkov._outputs.remove_free_locks`,
    :func:`cfbmarkov._outputs.remove_dead_temporaries`)."""
    processes = list(getattr(executor, "_processes", {}).values())
    for process in processes:
        with contextlib.suppress(Exception):
            process.terminate()
    if folder is None:
        return
    for process in processes:
        with contextlib.suppress(Exception):
            process.join(timeout=10)
    from cfbmarkov._outputs import remove_dead_temporaries, remove_free_locks

    with contextlib.suppress(OSError):
        remove_free_locks(folder)
    with contextlib.suppress(OSError):
        remove_dead_temporaries(folder)
    # a case stopped before its first checkpoint leaves its checkpoint folder empty
    for parts in folder.glob("*/*.parts"):
        with contextlib.suppress(OSError):
            parts.rmdir()                   # only if empty


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
    except (ValueError, TypeError) as exc:     # an address Dask cannot parse ("localhost")
        raise InputError(f"--scheduler {address!r} is not a scheduler's address ({exc}); give "
                         "it as tcp://HOST:PORT, e.g. tcp://localhost:8786") from None
    return client.get_executor(pure=False), client


# -- the whole reproduction --------------------------------------------------------------------
def reproduce(directory: str | os.PathLike, scale: str | Scale = "quick",
              velocities: Iterable[float] = VELOCITIES, *, overrides: dict | None = None,
              models: Sequence[str] = MODELS, executor: cf.Executor | None = None,
              scheduler: str | None = None, jobs: int | None = None, progress: bool = True,
              report: bool = True, log: Callable[[str], None] = print,
              kinetics: str | os.PathLike | None = None, ensemble: int = 1,
              device: str = "cpu") -> Path:
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
    kinetics : str or os.PathLike, optional
        A kinetics file: every comparison also integrates its properties
        (``compare --kinetics``; summary.json's ``kinetics`` block).
    ensemble : int, optional
        CFD-DEM runs per case, N (:mod:`cfbmarkov.reproduce_ensemble`): with N > 1 each
        model is fitted on the N runs' fitting windows pooled and compared on member 0's
        prediction window; ``reproduce.json`` and the report say N.
    device : {"cpu", "gpu"}, optional
        Where the CFD-DEM's DEM runs (``simulate --device``).

    Returns
    -------
    pathlib.Path
        ``report.html`` (the folder with ``report=False``).

    Raises
    ------
    InputError
        For an unknown model name or scale, unusable velocities or overrides, repeated
        velocities or models, an output that exists and is not a directory, a folder holding what a
        reproduction did not write or a case folder of another configuration
        (:func:`check_run_folder`, before anything is written), an unusable executor
        setting, an ensemble size out of range or another than the folder's, a failed case,
        or a report that cannot be written.
    GpuUnavailable
        ``device="gpu"`` where no CUDA device is usable (before any work).

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Section 3; ``docs/reproduce.md``.
    """
    from cfbmarkov.markov.select import parse_model_name

    for name in models:
        parse_model_name(name)
    repeated = sorted({m for m in models if list(models).count(m) > 1})
    if repeated:
        raise InputError(f"models repeat: {', '.join(repeated)} (each model is fitted and "
                         "compared once per case; give it once)")
    if kinetics is not None:
        from cfbmarkov.kinetics import load_kinetics

        loaded = load_kinetics(kinetics)          # a bad file: one line, before any work
        kinetics = str(Path(kinetics).resolve())
    from cfbmarkov.simulate.ensemble import MAX_MEMBERS

    ensemble = int(ensemble)
    if not 1 <= ensemble <= MAX_MEMBERS:
        raise InputError(f"--ensemble: expected 1 to {MAX_MEMBERS} runs per case, got {ensemble}")
    if device not in ("cpu", "gpu"):
        raise InputError(f"--device: expected cpu or gpu, got {device!r}")
    if device == "gpu":
        from cfbmarkov.simulate.gpu import require_gpu

        require_gpu()
    scale = as_scale(scale)
    cases = scale_cases(scale, velocities, overrides)
    names = [case_name(c.gas.superficial_velocity) for c in cases]
    if len(set(names)) != len(names):
        raise InputError(f"velocities repeat: {', '.join(names)}")
    if kinetics is not None:
        from cfbmarkov.markov.states import CellGrid

        for case in cases:                        # its tables on each case's grid, too
            loaded.check_cells(CellGrid(case.markov.columns, case.markov.rows))
    out = Path(directory)
    if out.exists() and not out.is_dir():
        raise InputError(f"output {out} exists and is not a directory")
    from cfbmarkov._outputs import claim_output

    with claim_output(out, "reproduce", "folder"):    # lock and folder before any work
        return _reproduce(out, scale, cases, names, overrides, models, executor, scheduler,
                          jobs, progress, report, log, kinetics, ensemble, device)


#: what a reproduction writes at the top of its folder, beside its case folders
TOP_LEVEL = ("reproduce.json", "report.html", "report.md", "figures")


def _is_case_folder(entry: Path) -> bool:
    """Whether ``entry`` is named and made as a case folder (``u<U>``, a folder)."""
    name = entry.name
    try:
        velocity = float(name[1:]) if name.startswith("u") else math.nan
    except ValueError:
        return False
    return math.isfinite(velocity) and case_name(velocity) == name and entry.is_dir()


def is_reproduce_entry(entry: str | os.PathLike) -> bool:
    """Whether ``entry`` of a folder is part of a reproduction written there: its manifest
    ``reproduce.json``, its report (``report.html``, ``report.md``, ``figures/``), a case
    folder (``u<U>``), or a lock or temporary of one of them.

    Parameters
    ----------
    entry : str or os.PathLike
        A path inside the folder.

    Returns
    -------
    bool
    """
    from cfbmarkov._outputs import output_helper

    entry = Path(entry)
    if entry.name in TOP_LEVEL or _is_case_folder(entry):
        return True
    cases = [p.name for p in entry.parent.iterdir() if _is_case_folder(p)]
    return output_helper(entry, [*TOP_LEVEL, *cases])


def check_run_folder(out: str | os.PathLike, cases, names, ensemble: int = 1) -> None:
    """Refuse, before anything is written, a folder that a reproduction must not write into:
    one holding entries that are not a reproduction's (:func:`is_reproduce_entry`), a case
    folder of another configuration (:func:`~cfbmarkov.reproduce_case.check_case_folder`)
    or of another ensemble size (:func:`~cfbmarkov.reproduce_ensemble.check_ensemble_folder`),
    or a CFD-DEM file linked into a new case folder that does not serve its case
    (:func:`~cfbmarkov.reproduce_case.check_reference`).

    Parameters
    ----------
    out : str or os.PathLike
        The run folder (missing: nothing to check).
    cases : sequence of CaseConfig
        The cases about to run.
    names : sequence of str
        Their folder names.
    ensemble : int, optional
        CFD-DEM runs per case.

    Raises
    ------
    InputError
        One line naming the folder, what it holds and the fix.
    """
    from cfbmarkov._outputs import refuse_foreign
    from cfbmarkov.reproduce_case import check_case_folder, check_reference
    from cfbmarkov.reproduce_ensemble import check_ensemble_folder

    out = Path(out)
    refuse_foreign(out, is_reproduce_entry, "a reproduction",
                   "write into it (give a new or empty folder with -o, or that of an earlier "
                   "reproduction to resume it)")
    for case, name in zip(cases, names):
        check_case_folder(out / name, case)
        check_ensemble_folder(out / name, ensemble, record=False)
        dropped_in = out / name / "cfd-dem.h5"
        if ensemble == 1 and dropped_in.is_file() and not (out / name / "case.json").exists():
            check_reference(dropped_in, case)       # a file linked in: before any writing


def earlier_manifest(out: Path, scale: Scale, overrides, ensemble: int,
                     kinetics: dict | None = None) -> dict:
    """The manifest of an earlier reproduction in ``out`` (empty where there is none), once
    checked to be of the same scale, overrides, ensemble size and kinetics (``kinetics``:
    ``{"file", "digest"}`` or None; an earlier reproduction without kinetics takes a
    kinetics file, whose comparisons are formed in the cases run now, but one with a
    kinetics file takes no other and cannot drop it): cases of another
    configuration beside its cases would make one report of two experiments.

    Raises
    ------
    InputError
        One line naming what differs and the fix.
    """
    path = out / "reproduce.json"
    if not path.is_file():
        return {}
    try:
        earlier = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}           # unreadable: written anew (its cases are checked one by one)
    if not isinstance(earlier, dict):
        return {}
    for key, now, shown in (("scale", scale.name, "scale"),
                            ("overrides", overrides or {}, "--overrides"),
                            ("ensemble", ensemble, "--ensemble")):
        before = earlier.get(key, 1 if key == "ensemble" else None)
        now = json.loads(json.dumps(now))          # as the manifest stores it (tuples: lists)
        if before != now:
            hint = ""
            if (key == "overrides" and isinstance(before, dict) and isinstance(now, dict)
                    and {k: v for k, v in before.items() if k != "markov"}
                    == {k: v for k, v in now.items() if k != "markov"}):
                hint = (" (they differ in [markov] alone: to fit those on the same CFD-DEM, "
                        f"link each case's cfd-dem.h5, {out / '<case>' / 'cfd-dem.h5'}, into "
                        "the new folder's <case>/ before the run, and only the Markov stages "
                        "run)")
            raise InputError(f"{out}: holds a reproduction of another {shown} ({key} "
                             f"{json.dumps(before)}, now {json.dumps(now)}) whose cases its "
                             "report covers; give another folder with -o, or the same "
                             f"{shown} to add cases to it{hint}")
    before = earlier.get("kinetics")
    if isinstance(before, dict) and (kinetics is None
                                     or before.get("digest") != kinetics.get("digest")):
        now = ("none" if kinetics is None else
               f"{kinetics.get('file')} (another definition)"
               if before.get("file") == kinetics.get("file") else kinetics.get("file"))
        raise InputError(f"{out}: holds a reproduction whose comparisons integrate the "
                         f"kinetics of {before.get('file')}, now {now}: its report would mix "
                         "two kinetics; give another folder with -o, or --kinetics "
                         f"{before.get('file')} as it was to add or resume cases")
    return earlier


def _reproduce(out: Path, scale: Scale, cases, names, overrides, models, executor, scheduler,
               jobs, progress, report, log, kinetics=None, ensemble=1, device="cpu") -> Path:
    check_run_folder(out, cases, names, ensemble)    # refused: nothing written
    source = None
    if kinetics is not None:
        from cfbmarkov.kinetics import load_kinetics
        from cfbmarkov.kinetics.fingerprint import kinetics_digest

        source = {"file": str(kinetics), "digest": kinetics_digest(load_kinetics(kinetics))}
    earlier = earlier_manifest(out, scale, overrides, ensemble, source)
    client = None
    threads = None
    own = executor is None
    if executor is None and scheduler:      # refused settings leave no folder behind
        executor, client = dask_executor(scheduler)
    elif executor is None:
        executor, threads = local_executor(jobs, len(cases))
    out.mkdir(parents=True, exist_ok=True)
    from cfbmarkov import __version__

    # an earlier reproduction's cases that are still there stay in its report
    kept = [n for n in earlier.get("cases") or [] if isinstance(n, str) and (out / n).is_dir()]
    listed = list(dict.fromkeys([*kept, *names]))
    used = list(dict.fromkeys([*(earlier.get("models") or []), *models]))
    changed = overridden_settings(overrides)
    description, reductions = scale.description, list(scale.reductions)
    if changed:
        description += f", every case then changed by the overrides of {', '.join(changed)}"
        reductions.append("then the overrides, which replace what the lines above say of "
                          "the same settings: " + ", ".join(f"{k} = {v}"
                                                            for k, v in changed.items()))
    manifest = {"scale": scale.name, "description": description,
                "reductions": reductions, "overrides": overrides or {},
                "cases": listed, "models": used, "version": __version__,
                "ensemble": ensemble, "device": device,
                "kinetics": source or earlier.get("kinetics")}
    write_text_atomic(out / "reproduce.json", json.dumps(manifest, indent=2) + "\n")
    runs = "" if ensemble == 1 else f", {ensemble} CFD-DEM runs each ({device})"
    log(f"reproduce ({scale.name} scale): {len(cases)} case(s) {', '.join(names)}{runs} in {out}")
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
                                   tuple(models), progress, threads,
                                   kinetics=kinetics, time_step_note=False,
                                   ensemble=ensemble, device=device): name
                   for case, name in zip(cases, names)}
        workers = getattr(executor, "_max_workers", None) or len(cases)
        finished: set[str] = set()

        def whole_run() -> None:        # the whole run's time left (cfbmarkov.run_progress)
            states = [read_case(out / n, c.output.end_time, c.particles.number, n in finished)
                      for c, n in zip(cases, names)]
            line = time_left_line(states, workers, _time.perf_counter() - started)
            if line is not None:
                log(line)

        pending, last = set(futures), _time.perf_counter()
        while pending:
            done_now, pending = cf.wait(pending, timeout=PROGRESS_EVERY,
                                        return_when=cf.FIRST_COMPLETED)
            for future in done_now:
                name = futures[future]
                finished.add(name)
                try:
                    result = future.result()
                except CfbmarkovError as exc:
                    failures.append(f"{name}: {exc}")
                    log(f"{name}: failed: {exc}")
                    continue
                _log_case(log, name, result)
            if progress and pending and (done_now or _time.perf_counter() - last
                                         >= PROGRESS_EVERY - 0.5):
                whole_run()
                last = _time.perf_counter()
        if not failures:
            log(f"all cases done in {_time.perf_counter() - started:.0f} s")
            # said once for the run, and only for a run that finished: a refusal stays one line
            _advise_time_step(scale, cases, names, any(
                k.startswith(("contact.", "particles.diameter", "particles.density",
                              "numerics.dem_time_step")) for k in changed))
            if report:
                from cfbmarkov.report.reproduction import write_report

                # a process pool of its own, idle now, draws half the report's figures
                pool = executor if own and isinstance(executor, cf.ProcessPoolExecutor) else None
                if progress:
                    log("report: drawing the figures and writing report.html")
                with heartbeat("report" if progress else "", write=log):
                    html = write_report(out, executor=pool)
                if progress:
                    log(f"report: done, {_time.perf_counter() - started:.0f} s in all")
    except KeyboardInterrupt:
        if own:
            _stop_workers(executor, out)
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
        # a rerun resumes a case stopped on its way, not one refused for its input or folder
        resumable = "; rerun to resume" if not all(
            "another configuration" in f or "delete that folder" in f for f in failures) else ""
        raise InputError(f"{len(failures)} case(s) failed{resumable}: " + "; ".join(failures))
    return html if report else out


def _log_case(log, name: str, result: dict) -> None:
    """The lines of a finished case: its stages, each model's figures, its RTDs' sizes."""
    done = ", ".join(f"{k} {v}" for k, v in result["stages"].items())
    log(f"{name}: {done}")
    for est, s in result["summaries"].items():
        log(f"{name} {est:>5}: PD E(RT) {_fmt(s.get('pd_rt_mean'), '+.1f')} %, PD SD(RT) "
            f"{_fmt(s.get('pd_rt_sd'), '+.1f')} %, MD {_fmt(s.get('md_rtd'), '.3g')}, "
            f"mixing RMS {_fmt(s.get('mixing_rms'), '.3g')}{_judged(s, est)}")
    if result["summaries"]:
        log(rtd_line(name, result["summaries"]))


def overridden_settings(overrides: dict | None) -> dict[str, object]:
    """The settings an overrides table sets, as ``{"section.key": value}`` in file order.

    Parameters
    ----------
    overrides : dict or None
        Nested tables of a case file.

    Returns
    -------
    dict
        Dotted names to the values given (empty for none).
    """
    from cfbmarkov.config import flat_tables

    return flat_tables(overrides or {})


def _advise_time_step(scale: Scale, cases, names, overridden: bool = False) -> None:
    """Say once for the run (:class:`~cfbmarkov.errors.TimeStepAdvisory`), not once per
    case, where the scale's DEM time step resolves a contact in fewer than 10 steps: the
    step is the scale's (with the overrides, where they change the step, the contacts or
    the particles), the same in each case."""
    import warnings

    from cfbmarkov.config import CaseConfig
    from cfbmarkov.errors import TimeStepAdvisory
    from cfbmarkov.simulate.dem.law import ContactLaw, contact_resolution
    from cfbmarkov.simulate.run import time_step_advisory

    paper = CaseConfig.model_validate({})       # the paper's particles, contact and step
    law = ContactLaw.from_config(paper.contact, paper.particles.diameter,
                                 paper.particles.density)
    paper_steps, _ = contact_resolution(law, law.mass, paper.numerics.dem_time_step)
    said: dict[str, list[str]] = {}
    for case, name in zip(cases, names):
        message = time_step_advisory(case)
        if message is not None:
            said.setdefault(message, []).append(name)
    for message, which in said.items():
        where = ("" if len(names) == 1 else ", the same in every case"
                 if len(which) == len(names) else ", in " + ", ".join(which))
        whose = (f"the {scale.name} scale's step and contacts with the overrides" if overridden
                 else f"the {scale.name} scale's step")
        warnings.warn(f"{message} ({whose}{where}; the paper's settings "
                      f"give {paper_steps:.2f} steps)", TimeStepAdvisory, stacklevel=4)


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


def _judged(summary: dict, model: str) -> str:
    """The clause after a model's figures: where the CFD-DEM's E(RT) lies against the
    model's interval, and how many warnings its comparison carries (its ``summary.json``),
    so that no figure reaches the terminal without its uncertainty and warnings."""
    out = ""
    interval = (summary.get("model") or {}).get("rt_mean_interval")
    reference = (summary.get("reference") or {}).get("rt_mean")
    level = summary.get("level")
    if (interval and reference is not None and level
            and all(v is not None and math.isfinite(float(v))
                    for v in (*interval, reference))):
        lo, hi = interval
        place = ("inside" if lo <= reference <= hi else "below" if reference < lo else
                 "above")
        out += (f"; the CFD-DEM's E(RT) {reference:.4g} s lies {place} the model's "
                f"{100 * level:g} % interval {lo:.4g}-{hi:.4g} s")
    warned = len(summary.get("warnings") or [])
    if warned:
        out += (f"; {warned} warning{'' if warned == 1 else 's'} (compare-{model}/"
                "summary.json, the report's How far to trust)")
    return out


def _fmt(value, spec: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return format(value, spec)


__all__ = ["MODELS", "InlineExecutor", "QUICK_REDUCTIONS", "SCALES", "Scale", "VELOCITIES",
           "case_name", "check_run_folder", "dask_executor", "is_reproduce_entry",
           "load_overrides", "local_executor", "overridden_settings", "reproduce", "rtd_line",
           "scale_cases"]
