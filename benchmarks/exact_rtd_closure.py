"""How fast is a model's exact RTD, and how far does its tail closure move it?

    python benchmarks/exact_rtd_closure.py MODEL.h5 [MODEL.h5 ...] [--repeats 11]
                                           [--dimensions 40] [--eigenvalues 4]

For each model file (``cfbmarkov fit ... -o MODEL.h5``; ``long-tail``: the bench's
:func:`cfbmarkov.synthetic.long_tail_chain`): the median time of ``--repeats``
calls of ``model.rtd()`` (a fresh load each, the first call, which may compile, left out),
as the tool computes it (the tail past lag 512 closed by a Krylov projection,
:mod:`cfbmarkov.markov.tail_closure`, and the entry chain eliminated with dense blocks
where :func:`cfbmarkov.markov.entry_chain.entry_matrix` takes them) and lag by lag (the
closure left out, sparse blocks in SuperLU's default column order); the lap deficits K,
the lags to a mass of 1e-10, the lag at which the closure was taken and its bound; and
the relative differences of E(RT) and SD(RT) between the two, and the largest and the
summed absolute differences of their f(k). ``--dimensions`` times the
tool's way at other Krylov dimensions too (e.g. 30,40,60,80). ``--eigenvalues N`` prints
the N largest eigenvalue moduli of the chain on its lap-deficit levels (the augmented Q of
:func:`cfbmarkov.markov.first_passage.deficit_matrix` on its live pairs; ARPACK), whose
closeness sets how long the tail is.
"""

from __future__ import annotations

import argparse
import time
from contextlib import contextmanager

import numpy as np


@contextmanager
def lag_by_lag():
    """The exact RTD without the tail closure, with sparse blocks in SuperLU's default
    order."""
    import cfbmarkov.markov.entry_chain as entry_chain
    import cfbmarkov.markov.first_passage as first_passage

    saved = (first_passage.krylov_dimension, entry_chain.DENSE_STATES, entry_chain.ORDERING)
    first_passage.krylov_dimension = lambda *args: 0
    entry_chain.DENSE_STATES, entry_chain.ORDERING = 0, "COLAMD"
    try:
        yield
    finally:
        (first_passage.krylov_dimension, entry_chain.DENSE_STATES,
         entry_chain.ORDERING) = saved


@contextmanager
def dimension(value: int):
    import cfbmarkov.markov.tail_closure as tail_closure

    saved = tail_closure.DIMENSION
    tail_closure.DIMENSION = value
    try:
        yield
    finally:
        tail_closure.DIMENSION = saved


LONG_TAIL = "long-tail"


def load(path: str):
    """The model in ``path``; ``long-tail``: :func:`cfbmarkov.synthetic.long_tail_chain`."""
    from cfbmarkov import synthetic
    from cfbmarkov.markov.model import MarkovModel

    return synthetic.long_tail_chain() if path == LONG_TAIL else MarkovModel.load(path)


def timed(path: str, repeats: int):
    """(median seconds, the last RTD) of ``repeats`` + 1 calls, the first left out."""
    times = []
    for _ in range(repeats + 1):
        model = load(path)
        start = time.perf_counter()
        rtd = model.rtd()
        times.append(time.perf_counter() - start)
    return float(np.median(times[1:])), rtd


def closure_taken(path: str):
    """(lag, bound) of the closure the tool takes on the model's RTD, or None."""
    import cfbmarkov.markov.first_passage as first_passage

    taken = []
    original = first_passage.try_closure

    def recording(*args, **kwargs):
        steps, bound = original(*args, **kwargs)
        if steps >= 0:
            taken.append((args[5], bound))
        return steps, bound

    first_passage.try_closure = recording
    try:
        load(path).rtd()
    finally:
        first_passage.try_closure = original
    return taken[0] if taken else None


def eigenvalues(path: str, count: int) -> np.ndarray:
    """The ``count`` largest eigenvalue moduli of the model's chain on its live lap-deficit
    levels (as deep as its exact RTD keeps)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import eigs

    from cfbmarkov.markov import first_passage as fp
    from cfbmarkov.markov.model_rtd import net_entry_flux

    model = load(path)
    levels = model.rtd().deficit_levels + 1
    chain = sp.csr_matrix(model.transition_matrix)
    parts = fp.split_by_pass(chain, model.up_fraction, model.down_fraction)
    start = fp._start_on_levels(*parts, levels, None, net_entry_flux(model), chain)
    q, _ = fp.deficit_matrix(*parts, levels)
    live = sp.diags(start.live.ravel().astype(float))
    values = eigs(live @ q @ live, k=count, which="LM", return_eigenvectors=False)
    return np.sort(np.abs(values))[::-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+",
                        help="model files (cfbmarkov fit -o), or long-tail for the bench's chain")
    parser.add_argument("--repeats", type=int, default=11,
                        help="timed calls per model and way, after a first one left out")
    parser.add_argument("--dimensions", default="",
                        help="Krylov dimensions to time besides the tool's, comma-separated")
    parser.add_argument("--eigenvalues", type=int, default=0,
                        help="print this many of the largest eigenvalue moduli")
    args = parser.parse_args()
    extra = [int(d) for d in args.dimensions.split(",") if d.strip()]
    print("model | K, lags to 1e-10 | closure at lag (bound) | model.rtd() | lag by lag | "
          "E(RT), SD(RT) relative differences | f(k) largest and summed differences")
    for path in args.models:
        seconds, rtd = timed(path, args.repeats)
        with lag_by_lag():
            plain_seconds, plain = timed(path, args.repeats)
        taken = closure_taken(path)
        where = f"{taken[0]} ({taken[1]:.1e})" if taken else "none"
        size = max(rtd.probability.size, plain.probability.size)
        gap = np.zeros(size)
        gap[:rtd.probability.size] += rtd.probability
        gap[:plain.probability.size] -= plain.probability
        print(f"{path} | {rtd.deficit_levels}, {rtd.probability.size} | {where} | "
              f"{seconds:.3f} s | {plain_seconds:.3f} s | "
              f"{abs(rtd.mean / plain.mean - 1):.1e}, {abs(rtd.sd / plain.sd - 1):.1e} | "
              f"{np.abs(gap).max():.1e}, {np.abs(gap).sum():.1e}", flush=True)
        for value in extra:
            with dimension(value):
                print(f"  Krylov dimension {value}: {timed(path, args.repeats)[0]:.3f} s",
                      flush=True)
        if args.eigenvalues:
            moduli = ", ".join(f"{v:.5f}" for v in eigenvalues(path, args.eigenvalues))
            print(f"  largest eigenvalue moduli on the levels: {moduli}", flush=True)


if __name__ == "__main__":
    main()
