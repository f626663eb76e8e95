"""Benchmarks behind ``cfbmarkov bench``: each yields (name, median value, unit).

The Markov-chain figures are measured at the paper's scale on synthetic riser-like data
(27000 particles, 201 frames every 0.025 s = 200 lags, 6 x 38 cells):

- ``mcm-fit``: reading the window from the trajectory file, assigning states and
  estimating P (paper estimator), 5.4 M transitions;
- ``mcm-predict``: Monte Carlo of 27000 particles x 200 steps with lap counting;
- ``mcm-predict-file``: the same plus placing particles in their cells and writing the
  prediction file;
- ``mcm-fit-intervals``: ``mcm-fit`` plus the model's 90 % intervals (a block bootstrap of
  the window's counts, 100 resamples; :func:`cfbmarkov.analysis.intervals.model_intervals`);
- ``mcm-exact-rtd``: the exact residence-time distribution of the 228-state model;
- ``mcm-exact-rtd-long-tail``: the same for a 228-state chain with slow wall states and laps
  down through the bottom (:func:`cfbmarkov.synthetic.long_tail_chain`: E(RT) 108 lags, 1333
  lags to resolve);
- ``mcm-fit-auto``: ``--states auto``, choosing among 5 state spaces by their exact RTD
  against the window's and forming the chosen one; ``mcm-fit-chosen``: fitting
  the chosen state space alone; ``mcm-predict-file-auto``: its prediction file;
  ``mcm-fit-auto-coherent``, ``mcm-predict-file-auto-coherent`` and their sum
  ``mcm-fit-predict-auto-coherent``: the same with coherent moves (the reproductions' chosen
  model; goal <= 2 s); ``mcm-fit-regime``, ``mcm-predict-file-regime``: the regime model
  cells x 2 regimes x direction (912 states) and its prediction along one regime path.
- ``mcm-fit-open``, ``mcm-predict-open``: the same fit (pooled counts, exits and entries)
  and prediction file for an open riser (:func:`cfbmarkov.synthetic.write_open_run`: the
  same flow and particle-frames, every pass through a face a visit outside), and their
  ratios over the periodic ``mcm-fit`` (same estimator) and ``mcm-predict-file``
  (``mcm-fit-open-ratio``, ``mcm-predict-open-ratio``; goal <= 1.5).

Times are medians over ``repeat`` runs after one warm-up run (numba compilation excluded).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Callable, Iterator


def _median_time(fn: Callable[[], object], repeat: int) -> float:
    fn()  # warm-up (compilation, file cache)
    samples = []
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def markov_benchmarks(repeat: int = 5, particles: int = 27000, workdir: Path | None = None,
                      wanted: Callable[[str], bool] | None = None
                      ) -> Iterator[tuple[str, float, str]]:
    """The ``mcm-*`` figures (module docstring; docs/performance.md).

    Parameters
    ----------
    repeat : int, optional
        Timed runs per figure (the median is reported), after one warm-up run.
    particles : int, optional
        Particles of the synthetic run.
    workdir : pathlib.Path, optional
        Folder for the temporary trajectory and prediction files (default: the system's).
    wanted : callable, optional
        Takes a figure's name, true for those to measure (default: all); the others are
        not timed.

    Yields
    ------
    tuple of (str, float, str)
        (name, median seconds, ``'s'``).
    """
    from cfbmarkov import synthetic
    from cfbmarkov.markov import CellGrid, PaperEstimator, discretize, exact_rtd

    wanted = wanted or (lambda name: True)
    if not any(wanted(name) for name in MARKOV_FIGURES if name != "mcm-exact-rtd-long-tail"):
        yield from _long_tail_benchmark(wanted, repeat)     # no trajectory file needed
        return
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        run = Path(tmp) / "bench-run.h5"
        flow = synthetic.RiserFlow()
        # 10-15 s with 0.1 s before it: the history states with memory need at 10 s
        synthetic.write_run(run, flow, particles, 5.1, seed=1, start_time=9.9)
        grid = CellGrid(6, 38, flow.width, flow.height)
        estimator = PaperEstimator(grid, lag=0.025)

        def fit():      # read the window, discretise, count, estimate
            return estimator.fit(discretize(run, grid, 0.025, (10.0, 15.0)))

        if wanted("mcm-fit"):
            yield "mcm-fit", _median_time(fit, repeat), "s"
        model = fit()
        states0, _, laps0 = model.initial_states(run, 10.0)
        pred = Path(tmp) / "bench-pred.h5"
        if wanted("mcm-predict"):
            yield "mcm-predict", _median_time(
                lambda: model.monte_carlo(states0, 200, 7, laps0), repeat), "s"
        if wanted("mcm-predict-file"):
            yield "mcm-predict-file", _median_time(
                lambda: model.predict(run, 10.0, 5.0, seed=7, output=pred), repeat), "s"
        if wanted("mcm-exact-rtd"):
            yield "mcm-exact-rtd", _median_time(
                lambda: exact_rtd(model.transition_matrix, model.up_fraction,
                                  model.down_fraction, model.lag), repeat), "s"
        yield from _long_tail_benchmark(wanted, repeat)
        if wanted("mcm-fit-intervals"):
            from cfbmarkov.analysis.intervals import model_intervals

            yield "mcm-fit-intervals", _median_time(
                lambda: model_intervals(fit(), level=0.9, resamples=100), repeat), "s"
        if not any(wanted(name) for name in MARKOV_FIGURES[6:]):
            return
        yield from _open_benchmarks(Path(tmp), flow, grid, particles, repeat, run, pred)
        # beyond the paper: the automatic choice of state space (5 candidates judged by
        # their exact RTD on the window), then the chosen model's prediction
        from cfbmarkov.markov.select import select_model

        def choose():
            return select_model(run, window=(10.0, 15.0), columns=6, rows=38, lag=0.025)

        yield "mcm-fit-auto", _median_time(choose, max(1, repeat // 2)), "s"
        chosen = choose()
        yield f"mcm-fit-chosen-{chosen.state_space.kind}", _median_time(
            lambda: _refit(chosen, run), repeat), "s"
        pred_auto = Path(tmp) / "bench-pred-auto.h5"
        yield "mcm-predict-file-auto", _median_time(
            lambda: chosen.predict(run, 10.0, 5.0, seed=7, output=pred_auto), repeat), "s"
        # the reproductions' chosen model: with coherent moves (the cluster model)
        fit_time = _median_time(lambda: select_model(run, window=(10.0, 15.0), columns=6,
                                                     rows=38, lag=0.025, coherent=True),
                                max(1, repeat // 2))
        coherent = select_model(run, window=(10.0, 15.0), columns=6, rows=38, lag=0.025,
                                coherent=True)
        predict_time = _median_time(
            lambda: coherent.predict(run, 10.0, 5.0, seed=7, output=pred_auto), repeat)
        yield "mcm-fit-auto-coherent", fit_time, "s"
        yield "mcm-predict-file-auto-coherent", predict_time, "s"
        yield "mcm-fit-predict-auto-coherent", fit_time + predict_time, "s"
        # the regime model (912 states) and its prediction along one common regime path
        yield from _regime_benchmarks(run, Path(tmp), repeat)


def _long_tail_benchmark(wanted, repeat: int) -> Iterator[tuple[str, float, str]]:
    """``mcm-exact-rtd-long-tail``: the exact RTD of :func:`cfbmarkov.synthetic.long_tail_chain`."""
    if not wanted("mcm-exact-rtd-long-tail"):
        return
    from cfbmarkov import synthetic
    from cfbmarkov.markov import exact_rtd

    chain = synthetic.long_tail_chain()
    yield "mcm-exact-rtd-long-tail", _median_time(
        lambda: exact_rtd(chain.transition_matrix, chain.up_fraction, chain.down_fraction,
                          chain.lag), repeat), "s"


def _regime_benchmarks(run: Path, tmp: Path, repeat: int) -> Iterator[tuple[str, float, str]]:
    """``mcm-fit-regime`` and ``mcm-predict-file-regime``: cells x regimes x direction."""
    from cfbmarkov.markov import fit_model, state_space_from_name

    space = state_space_from_name("cells-direction-regime", 6, 38, 0.09, 0.95)
    yield "mcm-fit-regime", _median_time(
        lambda: fit_model(run, space, 0.025, (10.0, 15.0)), repeat), "s"
    model = fit_model(run, space, 0.025, (10.0, 15.0))
    pred = tmp / "bench-pred-regime.h5"
    yield "mcm-predict-file-regime", _median_time(
        lambda: model.predict(run, 10.0, 5.0, seed=7, output=pred), repeat), "s"


def _open_benchmarks(tmp: Path, flow, grid, particles: int, repeat: int, run: Path,
                     pred: Path) -> Iterator[tuple[str, float, str]]:
    """``mcm-fit-open`` and ``mcm-predict-open`` beside their periodic peers (pooled counts
    on both sides: the paper's estimator is for periodic risers)."""
    from cfbmarkov import synthetic
    from cfbmarkov.markov import MaximumLikelihoodEstimator, discretize

    open_run = tmp / "bench-open.h5"
    synthetic.write_open_run(open_run, flow, particles, 5.1, seed=1, start_time=9.9)
    estimator = MaximumLikelihoodEstimator(grid, lag=0.025)
    periodic = _median_time(lambda: estimator.fit(discretize(run, grid, 0.025, (10.0, 15.0))),
                            repeat)
    opened = _median_time(lambda: estimator.fit(discretize(open_run, grid, 0.025, (10.0, 15.0))),
                          repeat)
    yield "mcm-fit-open", opened, "s"
    yield "mcm-fit-open-ratio", opened / periodic, "x"
    model = estimator.fit(discretize(run, grid, 0.025, (10.0, 15.0)))
    open_model = estimator.fit(discretize(open_run, grid, 0.025, (10.0, 15.0)))
    open_pred = tmp / "bench-pred-open.h5"
    periodic = _median_time(lambda: model.predict(run, 10.0, 5.0, seed=7, output=pred), repeat)
    opened = _median_time(lambda: open_model.predict(open_run, 10.0, 5.0, seed=7,
                                                     output=open_pred), repeat)
    yield "mcm-predict-open", opened, "s"
    yield "mcm-predict-open-ratio", opened / periodic, "x"


def _refit(model, run):
    from cfbmarkov.markov import fit_model

    return fit_model(run, model.state_space, model.lag, model.window, model.estimator)


BENCHMARKS = {"mcm": markov_benchmarks}

#: the names of the Markov chain figures (``mcm-fit-chosen-<kind>`` names the chosen space)
MARKOV_FIGURES = (
    "mcm-fit", "mcm-predict", "mcm-predict-file", "mcm-exact-rtd", "mcm-exact-rtd-long-tail",
    "mcm-fit-intervals", "mcm-fit-open", "mcm-fit-open-ratio",
    "mcm-predict-open", "mcm-predict-open-ratio", "mcm-fit-auto", "mcm-fit-chosen-",
    "mcm-predict-file-auto", "mcm-fit-auto-coherent", "mcm-predict-file-auto-coherent",
    "mcm-fit-predict-auto-coherent", "mcm-fit-regime", "mcm-predict-file-regime")


def _simulation_benchmarks(repeat: int, particles: int) -> Iterator[tuple[str, float, str]]:
    try:
        from cfbmarkov.simulate.bench import simulation_benchmarks
    except ImportError:
        return
    yield from simulation_benchmarks(repeat=repeat, particles=particles)


def run_benchmarks(only: list[str] | None = None, repeat: int = 5, particles: int = 27000
                   ) -> Iterator[tuple[str, float, str]]:
    """All benchmarks, or those named by ``only`` (``cfbmarkov bench``).

    Parameters
    ----------
    only : list of str, optional
        Names to keep: a figure's whole name keeps that figure alone (``mcm-fit``), any
        other text the figures whose names start with it (``['mcm']``, ``['dem',
        'cfd-dem']``); all when None. Figures not kept are not measured.
    repeat : int, optional
        Timed runs per figure (the median is reported).
    particles : int, optional
        Number of particles (default the paper's 27000).

    Yields
    ------
    tuple of (str, float, str)
        (name, value, unit), one per figure; see docs/performance.md.
    """
    def group_wanted(group: str) -> bool:
        return not only or any(o.startswith(group) or group.startswith(o) for o in only)

    def wanted(name: str) -> bool:
        return not only or any(name == o or (o not in MARKOV_FIGURES and name.startswith(o))
                               for o in only)

    if group_wanted("mcm"):
        for row in markov_benchmarks(repeat, particles, wanted=wanted):
            if wanted(row[0]):
                yield row
    if group_wanted("dem") or group_wanted("cfd-dem"):
        for row in _simulation_benchmarks(repeat, particles):
            if wanted(row[0]):
                yield row
