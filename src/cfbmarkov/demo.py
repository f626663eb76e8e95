"""``cfbmarkov demo``: the Markov-chain pipeline end to end on a fresh machine.

Until the CFD-DEM of the riser is available, the reference trajectories come from the
synthetic core-annulus generator (:mod:`cfbmarkov.synthetic`), whose particles carry a hidden
direction of motion, as clusters do in CFD-DEM. The demo fits the paper's model (6 x 38
cells, lag 0.025 s) on 10-15 s with both estimators, predicts 15-20 s from the reference
state at 15 s and compares the two on 15-20 s (RTD, mixing, figures).
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

from cfbmarkov import synthetic
from cfbmarkov._outputs import (describe, output_helper, refuse_foreign,
                                remove_stale_temporaries)
from cfbmarkov.analysis.fit_checks import assess_fit
from cfbmarkov.errors import InputError, SampleWarning
from cfbmarkov.observed.metrics import percentage_text
from cfbmarkov.markov import CellGrid, fit_model
from cfbmarkov.markov.uncertainty import outward_bounds

#: the estimators the demo fits, in order
ESTIMATORS = ("paper", "mle")
#: the demo's fit: cells, lag (s), fitting window (s); its prediction's window (s)
CELLS, LAG, FIT_WINDOW, PREDICT_WINDOW = (6, 38), 0.025, (10.0, 15.0), (15.0, 20.0)
#: the span of the synthetic reference, s
DURATION = 20.0


def _files(name: str) -> dict[str, str]:
    """The demo's files of one estimator: kind -> name."""
    return {"model": f"model-{name}.h5", "prediction": f"prediction-{name}.h5",
            "compare": f"compare-{name}"}


def demo_names() -> list[str]:
    """The names of everything the synthetic demo writes in its folder."""
    return (["reference.h5", "demo.json"]
            + [f for name in ESTIMATORS for f in _files(name).values()])


def _reference_text(path: Path, flow, particles: int, seed: int) -> str | None:
    """None where ``path`` is the reference this demo writes (a synthetic run of the same
    flow, particles, seed and span); else what it is, in words."""
    from cfbmarkov.trajectories import Trajectories

    kind = describe(path)
    if kind != "trajectory":
        return f"{_KIND_WORDS.get(kind, kind)}, which the demo did not write"
    try:
        with Trajectories(path) as run:
            source, params, n = run.source, run.parameters, run.n_particles
            span = (float(run.times[0]), float(run.times[-1]))
    except (InputError, OSError, KeyError, ValueError) as exc:
        return f"a trajectory file that cannot be read ({exc}), which the demo did not write"
    if source != "synthetic" or not isinstance(params, dict) or "seed" not in params:
        return f"a trajectory file of source {source!r}, which the demo did not write"
    expected = {k: getattr(flow, k) for k in flow.__dataclass_fields__}
    found = f"{n} particles, seed {params['seed']}"
    wanted = f"{particles} particles, seed {seed}"
    if found != wanted:
        return f"a synthetic reference of {found}, not this demo's {wanted}"
    if any(params.get(k) != v for k, v in expected.items()) or not (
            abs(span[0]) < 1e-9 and abs(span[1] - DURATION) < 1e-6):
        return (f"a synthetic reference of another flow or span ({span[0]:g}-{span[1]:g} s), "
                "not this demo's")
    return None


_KIND_WORDS = {"trajectory": "a trajectory file", "model": "a model file", "png": "a PNG image",
               "a folder": "a folder"}


def _attr_text(value) -> str:
    return value.decode(errors="replace") if isinstance(value, bytes) else str(value)


def _model_is_demo(path: Path, name: str) -> bool:
    """Whether ``path`` is a model the demo fits with estimator ``name``."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            a = f.attrs
            space = json.loads(_attr_text(a.get("state_space", "{}")))
            source = json.loads(_attr_text(a.get("source", '""')))
            return (_attr_text(a.get("estimator")) == name
                    and abs(float(a.get("lag", 0)) - LAG) < 1e-9
                    and [float(v) for v in a.get("window", [])] == list(FIT_WINDOW)
                    and (space.get("kind"), space.get("columns"), space.get("rows"))
                    == ("cells", *CELLS)
                    and isinstance(source, str) and Path(source).name == "reference.h5")
    except (OSError, ValueError, TypeError, KeyError):
        return False


def _prediction_is_demo(path: Path, name: str) -> bool:
    """Whether ``path`` is a prediction the demo makes with the model of estimator ``name``."""
    from cfbmarkov.trajectories import Trajectories

    try:
        with Trajectories(path) as run:
            source, params = run.source, run.parameters
    except (OSError, ValueError, KeyError, InputError):
        return False
    if source != "markov-prediction" or not isinstance(params, dict):
        return False
    model = params.get("model") or {}
    return (isinstance(model, dict) and model.get("estimator") == name
            and params.get("start") == PREDICT_WINDOW[0]
            and params.get("duration") == PREDICT_WINDOW[1] - PREDICT_WINDOW[0])


def check_demo_folder(output: str | Path, particles: int, seed: int,
                      force: bool = False) -> bool:
    """Check what a folder holds before the synthetic demo writes into it.

    The demo reuses its reference only where it is its own, of the same parameters; it
    replaces its other files, where they are its own. Anything else is refused unless
    ``force``: files the demo does not write, a reference it did not write or wrote with
    other parameters, and a model, prediction or ``demo.json`` that is not the demo's. A
    comparison folder holding other files than a comparison's is refused even with
    ``force`` (``compare`` replaces it whole).

    Parameters
    ----------
    output : str or pathlib.Path
        The demo's folder (missing: nothing to check).
    particles, seed : int
        The demo's parameters.
    force : bool, optional
        Write anyway: the reference is made again, the demo's files are replaced, other
        files are left beside them.

    Returns
    -------
    bool
        Whether ``reference.h5`` is reused.

    Raises
    ------
    InputError
        Naming what the folder holds and the fix (``--force``, or another folder).
    """
    from cfbmarkov.report.compare import is_comparison_file

    out = Path(output)
    if not out.is_dir():
        return False
    fix = "add --force to overwrite it, or give another folder with -o"
    names = demo_names()
    if not force:
        refuse_foreign(out, lambda p: p.name in names or output_helper(p, names),
                       "a synthetic demo",
                       "write into it (give a new or empty folder with -o, or add --force "
                       "to write the demo's files beside it)")
    reference = out / "reference.h5"
    reuse = False
    if reference.exists():
        why = _reference_text(reference, synthetic.RiserFlow(), particles, seed)
        if why is None:
            reuse = True
        elif not force:
            raise InputError(f"{reference}: {why}; {fix}")
    for name in ESTIMATORS:      # a comparison's folder is replaced whole: never forced
        folder = out / _files(name)["compare"]
        if folder.exists() and not folder.is_dir():
            raise InputError(f"{folder}: not a comparison's folder; give the demo another "
                             "folder with -o")
        refuse_foreign(folder, is_comparison_file, "a comparison",
                       "replace it (give the demo another folder with -o)")
    if force:
        return reuse
    for name in ESTIMATORS:
        files = _files(name)
        checks = (("model", _model_is_demo, "a model the demo did not fit"),
                  ("prediction", _prediction_is_demo,
                   "a trajectory file the demo did not predict"))
        for kind, own, words in checks:
            path = out / files[kind]
            if path.exists() and not own(path, name):
                raise InputError(f"{path}: {words}; {fix}")
    summary = out / "demo.json"
    if summary.exists():
        try:
            rows = json.loads(summary.read_text())
            mine = isinstance(rows, dict) and set(rows) <= set(ESTIMATORS)
        except (OSError, ValueError):
            mine = False
        if not mine:
            raise InputError(f"{summary}: not the demo's summary; {fix}")
    return reuse


def _remove_own_summary(summary: Path) -> None:
    """Delete ``demo.json`` where it is the demo's (a dict keyed by its estimators)."""
    try:
        rows = json.loads(summary.read_text())
    except (OSError, ValueError):
        return
    if isinstance(rows, dict) and set(rows) <= set(ESTIMATORS):
        summary.unlink(missing_ok=True)


def demo_verdict(summaries: dict[str, dict]) -> str:
    """The demo's closing line: the models against the persistence baseline by the report's
    rule, in the words of the report's verdict
    (:func:`cfbmarkov.report.table3.baseline_clause`), and the next step.

    Parameters
    ----------
    summaries : dict of str to dict
        Estimator -> its compare summary.

    Returns
    -------
    str
        "verdict: ...; Next step: ...".
    """
    from cfbmarkov.report.table3 import baseline_clause, baseline_outcomes, baseline_step

    counts = baseline_outcomes(summaries.values())
    reference = "the reference"
    clause = baseline_clause(counts, unit="estimator", reference=reference)
    if clause is None:
        return "verdict: no comparison could be judged against the persistence baseline"
    judged = {name: s for name, s in summaries.items()
              if (s.get("baseline") or {}).get("md_rtd") is not None}
    base = ", ".join(f"{name} MD {s['md_rtd']:.3g} against the baseline's "
                     f"{s['baseline']['md_rtd']:.3g}" for name, s in judged.items())
    stand_in, target = next(iter(judged.values()))["baseline"]["windows"]
    return (f"verdict: {clause} ({base}; the persistence baseline takes the reference's RTD "
            f"of {_span(stand_in)} s as the prediction of {_span(target)} s). Next step: "
            f"{baseline_step(counts, reference=reference)}.")


def _span(window) -> str:
    return f"{window[0]:g}-{window[1]:g}"


def run_demo(output: str | Path, particles: int = 6000, seed: int = 1, log=print,
             progress=None, force: bool = False, note=None, warn=None) -> Path:
    """Run the Markov-chain pipeline on a synthetic reference (``cfbmarkov demo --synthetic``).

    Writes into ``output``: ``reference.h5`` (reused where the folder holds this demo's, of
    the same particles and seed: :func:`check_demo_folder`, which refuses a folder holding
    anything else unless ``force``), and per estimator
    (``paper``, ``mle``) ``model-NAME.h5``, ``prediction-NAME.h5`` and ``compare-NAME/``,
    plus ``demo.json`` with the comparison summaries and the models' exact E(RT), SD(RT).

    Parameters
    ----------
    output : str or pathlib.Path
        Output folder (created if needed).
    particles : int, optional
        Number of particles of the synthetic reference.
    seed : int, optional
        Seed of the reference and of the Monte Carlo predictions.
    log : callable, optional
        Called with one line of results per estimator (default :func:`print`).
    progress : callable, optional
        Called with one line at the start of each stage (the reference, then per estimator
        the fit, the prediction and the comparison), naming the stage, its number of the
        seven, the time so far and, from the second stage on, the time left estimated from
        the stages done (default None: quiet).
    force : bool, optional
        Write into a folder holding other files, and make the reference again where the
        folder's is not this demo's (:func:`check_demo_folder`).
    note : callable, optional
        Called with the line saying that the reference is reused (default None: quiet).
    warn : callable, optional
        Called with each warning of a model's fitting sample (its interval and verdict, as
        ``cfbmarkov fit`` prints them: :func:`~cfbmarkov.analysis.fit_checks.assess_fit`),
        ``warning: `` and the estimator's name first (default: printed on stderr). The
        model files carry them, so that ``rtd`` and ``info`` repeat them.

    Returns
    -------
    pathlib.Path
        The output folder.

    Raises
    ------
    InputError
        Where the folder holds what the demo must not overwrite or reuse
        (:func:`check_demo_folder`); nothing is written then.
    """
    import contextlib
    import time

    from cfbmarkov._console import clock_text, heartbeat
    from cfbmarkov.report.compare import compare

    if warn is None:
        def warn(line: str) -> None:
            print(line, file=sys.stderr)
    out = Path(output)
    reuse = check_demo_folder(out, particles, seed, force)
    out.mkdir(parents=True, exist_ok=True)
    if not reuse:
        # a new reference (other parameters, or none yet): the summary of an earlier set
        # goes first, so that a run cut short leaves no demo.json of files replaced since
        _remove_own_summary(out / "demo.json")
    flow = synthetic.RiserFlow()
    reference = out / "reference.h5"
    if reuse and note is not None:
        note(f"demo: reusing {reference} (same parameters: {particles} particles, seed {seed})")
    started = time.perf_counter()
    # the stages' relative lengths (their wall times on 2 cores, 1000-6000 particles): the
    # comparisons most of the run, the reference a good part
    weights = {"reference": 3.0, "fit": 0.3, "predict": 0.5, "compare": 5.0}
    plan = ([("reference", None)] if not reuse else []) + [
        (stage, name) for name in ("paper", "mle") for stage in ("fit", "predict", "compare")]
    total = sum(weights[stage] for stage, _ in plan)
    done = [0.0]

    @contextlib.contextmanager
    def stage(number: int, text: str):
        what, name = plan[number]
        if progress is not None:
            elapsed = time.perf_counter() - started
            left = (f", about {clock_text(elapsed * (total - done[0]) / done[0])} left"
                    if done[0] > 0 else "")
            progress(f"demo: [{number + 1}/{len(plan)}] {text} ({clock_text(elapsed)} so far"
                     f"{left})")
        label = f"demo: {what}" + (f" {name}" if name else "")
        with heartbeat(label if progress is not None else "", write=progress):
            yield
        done[0] += weights[what]

    step = 0
    if not reuse:
        with stage(step, f"synthetic reference: {particles} particles, 0-20 s"):
            synthetic.write_run(reference, flow, particles, DURATION, seed=seed)
        step += 1
    grid = CellGrid(*CELLS, flow.width, flow.height)
    rows = {}
    for name in ESTIMATORS:
        # what an earlier demo killed in this folder left half-written (a comparison's
        # NAME.tmp-XXXXXXXX folder of partial figures): the demo holds the folder's lock
        for target in (out / f"model-{name}.h5", out / f"prediction-{name}.h5",
                       out / f"compare-{name}"):
            remove_stale_temporaries(target)
        with stage(step, f"{name}: fitting 6x38 cells at lag 0.025 s on 10-15 s"):
            # as fit makes it: its fitting file found by its window's content wherever
            # the folder goes (cfbmarkov.analysis.intervals.resolve_source), its interval
            # and the verdict on its fitting sample, whose warnings are said
            with warnings.catch_warnings():        # the verdict's lines: said below
                warnings.simplefilter("ignore", SampleWarning)
                model = assess_fit(fit_model(reference, grid, LAG, FIT_WINDOW, name),
                                   [reference], [FIT_WINDOW])
            model.save(out / f"model-{name}.h5")
            for line in model.warnings():
                warn(f"warning: {name}: {line}")
        with stage(step + 1, f"{name}: predicting 15-20 s from the reference's state at 15 s"):
            prediction = model.predict(reference, start=PREDICT_WINDOW[0],
                                       duration=PREDICT_WINDOW[1] - PREDICT_WINDOW[0], seed=seed,
                                       output=out / f"prediction-{name}.h5")
        with stage(step + 2, f"{name}: comparing the prediction with the reference on 15-20 s "
                             "(residence times, baselines, mixing, figures)"):
            summary = compare(reference, prediction, window=PREDICT_WINDOW,
                              output=out / f"compare-{name}")
        step += 3
        seen = PREDICT_WINDOW[1] - PREDICT_WINDOW[0]
        exact = model.rtd(window=seen)
        rows[name] = {**summary, "exact_model_rt_mean": exact.mean, "exact_model_rt_sd": exact.sd,
                      "fit_warnings": model.warnings()}
        interval = summary["model"].get("rt_mean_interval")
        level = summary.get("level") or 0.9
        within = ("" if not interval else f", {100 * level:g} % interval with the flow's "
                  f"variability {'-'.join(outward_bounds(*interval, digits=4))} s")
        log(f"{name:>5}: E(RT) reference {summary['reference']['rt_mean']:.3f} s, model "
            f"{summary['model']['rt_mean']:.3f} s (its Monte Carlo sample{within}; exact, as a "
            f"{seen:g} s window sees it: {exact.mean:.3f} s), PD E(RT) "
            f"{percentage_text(summary['pd_rt_mean'], '+.1f')} %, PD SD(RT) "
            f"{percentage_text(summary['pd_rt_sd'], '+.1f')} %, "
            f"MD {summary['md_rtd']:.3g}, mixing RMS {summary['mixing_rms']:.3g}")
    log(demo_verdict(rows))
    (out / "demo.json").write_text(json.dumps(rows, indent=2))
    if progress is not None:
        progress(f"demo: done in {clock_text(time.perf_counter() - started)}")
    return out
