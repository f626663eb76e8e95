"""What does a model's interval cost, and where does the time go?

    python benchmarks/interval_cost.py MODEL.h5 [MODEL.h5 ...] [--resamples 100]
                                       [--repeats 5] [--widths 16,56,104]

For each model file (``cfbmarkov fit RUN.h5 ... -o MODEL.h5``, its fitting run where the
model names it): the median wall time of ``--repeats`` calls of
:func:`cfbmarkov.analysis.intervals.model_intervals` (the first call, which loads the
compiled kernels, left out), the window read for it alone (``fitting_windows``: what
``fit`` shares with the verdict), and the propagation of the resamples' RTD heads side by
side (:func:`cfbmarkov.markov.first_passage.heads`, the lags the interval's bins reach) in
chunks of each of ``--widths`` chains (default: the tool's chunk for Numba's thread count,
:func:`~cfbmarkov.markov.first_passage.head_chunk`, and 16). Every width gives the same
bits (checked here). Run with ``NUMBA_NUM_THREADS=1`` for one thread.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _median_time(call, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def _head_starts(model, resamples: int):
    """The resamples' starts on the levels and the lags the interval's bins reach, as
    ``model_intervals`` forms them (seed 0)."""
    from cfbmarkov.analysis import bootstrap
    from cfbmarkov.analysis.intervals import (BOOTSTRAP_DEFICIT_LEVELS, model_rtd_edges,
                                              resolve_source)
    from cfbmarkov.markov.first_passage import rtd_moments_and_start

    model = resolve_source(model)
    direction = model.flow_direction
    exact = model.rtd(None, direction)
    edges = model_rtd_edges(exact)
    levels = min(exact.deficit_levels, BOOTSTRAP_DEFICIT_LEVELS)
    starts = []
    for chain in bootstrap._bootstrap_chains(model, bootstrap.BOOTSTRAP_BLOCKS, resamples, 0):
        up, down = (chain.up, chain.down) if direction == "up" else (chain.down, chain.up)
        starts.append(rtd_moments_and_start(up, down, chain.stay, chain.lag, levels,
                                            exact.entry_distribution)[3])
    return starts, bootstrap._reach(edges, model.lag)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+")
    parser.add_argument("--resamples", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--widths", default="",
                        help="chains per chunk of the heads, comma-separated (default: the "
                             "tool's and 16)")
    args = parser.parse_args(argv)

    import numba

    from cfbmarkov.analysis.bootstrap import fitting_windows
    from cfbmarkov.analysis.intervals import model_intervals
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.first_passage import head_chunk, heads

    threads = numba.get_num_threads()
    for path in args.models:
        model = MarkovModel.load(path)
        model.rtd()
        model_intervals(model, resamples=args.resamples)          # loads the kernels
        whole = _median_time(lambda m=model: model_intervals(m, resamples=args.resamples),
                             args.repeats)
        read = _median_time(lambda m=model: fitting_windows(m), args.repeats)
        starts, steps = _head_starts(model, args.resamples)
        widths = ([int(w) for w in args.widths.split(",")] if args.widths else
                  sorted({head_chunk(len(starts), threads), 16}))
        reference = None
        print(f"{path}: {model.n_states} states, {args.resamples} resamples, {threads} "
              f"thread(s), median of {args.repeats}")
        print(f"  model_intervals: {whole:.3f} s (its window read alone: {read:.3f} s)")
        for width in widths:
            got = heads(starts, steps, chunk=width)
            if reference is None:
                reference = got
            same = "same bits" if np.array_equal(got, reference) else "BITS DIFFER"
            seconds = _median_time(lambda s=starts, n=steps, w=width: heads(s, n, chunk=w),
                                   args.repeats)
            chunks = -(-len(starts) // width)
            print(f"  heads, {steps} lags, {chunks} chunk(s) of {width}: {seconds:.3f} s "
                  f"({same})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
