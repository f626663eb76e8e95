"""Do `fit`'s bootstrap intervals hold a known chain's E(RT) on a stationary generated flow?

    python benchmarks/interval_scatter.py [--length 12] [--windows 30] [--blocks 10,5,3]
                                          [--particles 500] [--seed 5] [--independent]
                                          [--estimator mle] [-o run.h5]

A run of ``--particles`` particles is sampled from the generated riser's known chain
(:class:`cfbmarkov.synthetic.RiserFlow` with 4 x 16 cells, rising at 1.2 m/s in the core
and falling at 0.6 m/s at the walls, without velocity persistence, so that the cells are
the chain's own states: E(RT) 2.384 s), long enough for ``--windows`` windows of
``--length`` s one after another; with ``--independent``, ``--windows`` runs of ``--length``
s each, every one started from the chain's stationary distribution with its own seed (the
windows of one run share its particles; independent runs give the sampling spread
without that). On each window the chain of ``--estimator`` (default the maximum-likelihood
one; ``paper``, `fit`'s default on cells, is the paper's) is fitted on the generator's
cells and its interval formed from the window alone
(:func:`cfbmarkov.analysis.intervals.model_intervals`, 100 resamples, 90 %) for each number
of bootstrap blocks in ``--blocks``. Printed: how many intervals hold the generator's exact
E(RT), and how many would without the bootstrap's widening for its blocks
(:func:`cfbmarkov.markov.uncertainty.bootstrap_widening`), their median width, the fitted
E(RT)'s mean over the windows (its bias) and its standard deviation between windows beside
the bootstrap's standard error (the median half-width over the widening times 1.645).
Windows shorter than two blocks of three mean residence times (here shorter than about
14 s) carry no flow term, so the interval is the bootstrap's alone; on longer windows the
unwidened count (the half-widths divided by the widening) is approximate, the flow term
being divided too.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from cfbmarkov import synthetic
from cfbmarkov.analysis.bootstrap import bootstrap_widening
from cfbmarkov.analysis.intervals import model_intervals
from cfbmarkov.markov import CellGrid, fit_model

FLOW = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)
LEVEL = 0.9


def _windows(args, folder: Path):
    """(trajectory file, window) of each window judged."""
    if args.independent:
        for k in range(args.windows):
            path = folder / f"interval-scatter-{args.length:g}-{k}.h5"
            if not path.exists():
                synthetic.write_run(path, FLOW, args.particles, args.length,
                                    seed=args.seed * 100003 + k)
            yield path, (0.0, args.length)
        return
    path = Path(args.output or f"interval-scatter-{args.length:g}.h5")
    if not path.exists():
        synthetic.write_run(path, FLOW, args.particles, args.length * args.windows + 1.0,
                            seed=args.seed)
    for k in range(args.windows):
        yield path, (k * args.length, (k + 1) * args.length)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--length", type=float, default=12.0, help="window length, s")
    parser.add_argument("--windows", type=int, default=30)
    parser.add_argument("--blocks", default="10,5,3", help="bootstrap blocks to compare")
    parser.add_argument("--particles", type=int, default=500)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--independent", action="store_true",
                        help="independent runs, one window each (written to a temporary "
                        "folder)")
    parser.add_argument("--estimator", default="mle", choices=("mle", "paper"),
                        help="the estimator fitted (default mle)")
    parser.add_argument("-o", "--output", default=None, help="the run (default "
                        "interval-scatter-LENGTH.h5 here; reused where it exists)")
    args = parser.parse_args(argv)
    blocks = [int(b) for b in args.blocks.split(",")]
    truth = synthetic.cell_chain(FLOW).rtd().mean
    hits = {b: 0 for b in blocks}
    unwidened = {b: 0 for b in blocks}
    widths: dict[int, list[float]] = {b: [] for b in blocks}
    estimates = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        for k, (path, window) in enumerate(_windows(args, Path(folder))):
            model = fit_model(path, CellGrid(4, 16), 0.025, window, args.estimator)
            centre = model.rtd().mean
            estimates.append(centre)
            for b in blocks:
                lo, hi = model_intervals(model, blocks=b, resamples=100, seed=k).rt_mean_interval
                hits[b] += lo <= truth <= hi
                w = bootstrap_widening(LEVEL, b)
                unwidened[b] += centre - (centre - lo) / w <= truth <= centre + (hi - centre) / w
                widths[b].append(hi - lo)
    est = np.asarray(estimates)
    kind = "independent runs" if args.independent else "windows of one run"
    print(f"{args.windows} {kind} of {args.length:g} s, the {args.estimator} estimator, "
          f"generator's E(RT) {truth:.4f} s; "
          f"fitted E(RT) mean {est.mean():.4f} s (bias {est.mean() - truth:+.4f}), SD between "
          f"windows {est.std(ddof=1):.4f} s")
    for b in blocks:
        half = np.median(widths[b]) / 2
        print(f"  {b:>2} blocks: {hits[b]} of {args.windows} intervals hold it "
              f"({100 * hits[b] / args.windows:.1f} %; unwidened {unwidened[b]}, "
              f"{100 * unwidened[b] / args.windows:.1f} %), median width {2 * half:.4f} s, "
              f"bootstrap standard error {half / bootstrap_widening(LEVEL, b) / 1.645:.4f} s")
    print(f"({time.perf_counter() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
