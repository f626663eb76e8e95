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


def run_demo(output: str | Path, particles: int = 6000, seed: int = 1, log=print) -> Path:
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
        Called with one line of progress per step (default :func:`print`).

    Returns
    -------
    pathlib.Path
        The output folder.
    """
    from cfbmarkov.report.compare import compare

    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    flow = synthetic.RiserFlow()
    reference = out / "reference.h5"
    if not reference.exists():
        log(f"synthetic reference: {particles} particles, 0-20 s ...")
        synthetic.write_run(reference, flow, particles, 20.0, seed=seed)
    grid = CellGrid(6, 38, flow.width, flow.height)
    rows = {}
    for name in ("paper", "mle"):
        model = fit_model(reference, grid, 0.025, (10.0, 15.0), name)
        model.save(out / f"model-{name}.h5")
        prediction = model.predict(reference, start=15.0, duration=5.0, seed=seed,
                                   output=out / f"prediction-{name}.h5")
        summary = compare(reference, prediction, window=(15.0, 20.0), output=out / f"compare-{name}")
        exact = model.rtd(window=5.0)
        rows[name] = {**summary, "exact_model_rt_mean": exact.mean, "exact_model_rt_sd": exact.sd}
        log(f"{name:>5}: E(RT) reference {summary['reference']['rt_mean']:.3f} s, model "
            f"{summary['model']['rt_mean']:.3f} s (exact {exact.mean:.3f} s), PD E(RT) "
            f"{percentage_text(summary['pd_rt_mean'], '+.1f')} %, PD SD(RT) "
            f"{percentage_text(summary['pd_rt_sd'], '+.1f')} %, "
            f"MD {summary['md_rtd']:.3g}, mixing RMS {summary['mixing_rms']:.3g}")
    (out / "demo.json").write_text(json.dumps(rows, indent=2))
    return out
