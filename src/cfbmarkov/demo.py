"""``cfbmarkov demo``: the Markov-chain pipeline end to end on a fresh machine.

Until the CFD-DEM of the riser is available, the reference trajectories come from the
synthetic core-annulus generator (:mod:`cfbmarkov.synthetic`), whose particles carry a hidden
direction of motion, as clusters do in CFD-DEM. The demo fits the paper's model (6 x 38
cells, lag 0.025 s) on 10-15 s with both estimators, predicts 15-20 s from the reference
state at 15 s and compares the two on 15-20 s (RTD, mixing, figures).
"""

from __future__ import annotations

import json
from pathlib import Path

from cfbmarkov import synthetic
from cfbmarkov.observed.metrics import percentage_text
from cfbmarkov.markov import CellGrid, fit_model


def run_demo(output: str | Path, particles: int = 6000, seed: int = 1, log=print,
             progress=None) -> Path:
    """Run the Markov-chain pipeline on a synthetic reference (``cfbmarkov demo --synthetic``).

    Writes into ``output``: ``reference.h5`` (kept and reused if present), and per estimator
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

    Returns
    -------
    pathlib.Path
        The output folder.
    """
    import contextlib
    import time

    from cfbmarkov._console import clock_text, heartbeat
    from cfbmarkov.report.compare import compare

    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    flow = synthetic.RiserFlow()
    reference = out / "reference.h5"
    started = time.perf_counter()
    # the stages' relative lengths (their wall times on 2 cores, 1000-6000 particles): the
    # comparisons most of the run, the reference a good part
    weights = {"reference": 3.0, "fit": 0.3, "predict": 0.5, "compare": 5.0}
    plan = ([("reference", None)] if not reference.exists() else []) + [
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
    if not reference.exists():
        with stage(step, f"synthetic reference: {particles} particles, 0-20 s"):
            synthetic.write_run(reference, flow, particles, 20.0, seed=seed)
        step += 1
    grid = CellGrid(6, 38, flow.width, flow.height)
    rows = {}
    for name in ("paper", "mle"):
        with stage(step, f"{name}: fitting 6x38 cells at lag 0.025 s on 10-15 s"):
            model = fit_model(reference, grid, 0.025, (10.0, 15.0), name)
            model.save(out / f"model-{name}.h5")
        with stage(step + 1, f"{name}: predicting 15-20 s from the reference's state at 15 s"):
            prediction = model.predict(reference, start=15.0, duration=5.0, seed=seed,
                                       output=out / f"prediction-{name}.h5")
        with stage(step + 2, f"{name}: comparing the prediction with the reference on 15-20 s "
                             "(residence times, baselines, mixing, figures)"):
            summary = compare(reference, prediction, window=(15.0, 20.0),
                              output=out / f"compare-{name}")
        step += 3
        exact = model.rtd(window=5.0)
        rows[name] = {**summary, "exact_model_rt_mean": exact.mean, "exact_model_rt_sd": exact.sd}
        log(f"{name:>5}: E(RT) reference {summary['reference']['rt_mean']:.3f} s, model "
            f"{summary['model']['rt_mean']:.3f} s (its Monte Carlo sample; exact, from the "
            f"chain without sampling: {exact.mean:.3f} s), PD E(RT) "
            f"{percentage_text(summary['pd_rt_mean'], '+.1f')} %, PD SD(RT) "
            f"{percentage_text(summary['pd_rt_sd'], '+.1f')} %, "
            f"MD {summary['md_rtd']:.3g}, mixing RMS {summary['mixing_rms']:.3g}")
    (out / "demo.json").write_text(json.dumps(rows, indent=2))
    if progress is not None:
        progress(f"demo: done in {clock_text(time.perf_counter() - started)}")
    return out
