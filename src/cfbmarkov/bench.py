"""Benchmarks behind ``cfbmarkov bench``: each yields (name, median value, unit).

The Markov-chain figures are measured at the paper's scale on synthetic riser-like data
(27000 particles, 201 frames every 0.025 s = 200 lags, 6 x 38 cells):

- ``mcm-fit``: reading the window from the trajectory file, assigning states and
  estimating P (paper estimator), 5.4 M transitions;
- ``mcm-predict``: Monte Carlo of 27000 particles x 200 steps with lap counting;
- ``mcm-predict-file``: the same plus placing particles in their cells and writing the
  prediction file;
- ``mcm-predict-file-kinetics``: ``mcm-predict-file`` with two particle properties (a
  first-order reaction and heat exchange with a wall temperature) carried and stored per
  frame (goal <= 1.5 x ``mcm-predict-file``);
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


#: the figures of the Markov layer, in the order they are measured (``mcm-fit-chosen`` is
#: printed with the chosen space's kind, ``mcm-fit-chosen-KIND``)
MCM_NAMES = ("mcm-fit", "mcm-predict", "mcm-predict-file", "mcm-predict-file-kinetics",
             "mcm-exact-rtd",
             "mcm-exact-rtd-long-tail", "mcm-fit-intervals", "mcm-fit-open",
             "mcm-fit-open-ratio", "mcm-predict-open", "mcm-predict-open-ratio", "mcm-fit-auto",
             "mcm-fit-chosen", "mcm-predict-file-auto", "mcm-fit-auto-coherent",
             "mcm-predict-file-auto-coherent", "mcm-fit-predict-auto-coherent",
             "mcm-fit-regime", "mcm-predict-file-regime")
#: the figures of the simulation (each DEM figure followed by its LAMMPS lines where LAMMPS
#: is installed: ``NAME-lammps-NrankS`` and ``NAME-over-lammps``)
SIMULATION_NAMES = ("dem-throughput", "dem-throughput-dense", "cfd-dem-throughput",
                    "cfd-dem-throughput-over-lammps-dense")
#: groups that ``--only`` takes for all their figures
GROUPS = ("mcm", "dem", "cfd-dem")


def check_names(only: list[str] | None) -> None:
    """Refuse a name that is neither a figure nor a group.

    Parameters
    ----------
    only : list of str or None
        Names given to ``--only``.

    Raises
    ------
    InputError
        Naming the unknown names and listing the valid ones.
    """
    from cfbmarkov.errors import InputError

    unknown = [o for o in only or () if o not in (*GROUPS, *MCM_NAMES, *SIMULATION_NAMES)]
    if unknown:
        raise InputError(f"unknown benchmark {', '.join(map(repr, unknown))}: choose a group "
                         f"({', '.join(GROUPS)}) or a figure ({', '.join(MCM_NAMES)}, "
                         f"{', '.join(SIMULATION_NAMES)})")


def selects(only: list[str] | None, name: str) -> bool:
    """Whether the figure ``name`` is run for ``--only`` names ``only``.

    A group (``mcm``, ``dem``, ``cfd-dem``) selects all its figures; a figure's name selects
    that figure, with its LAMMPS lines (``NAME-lammps-...``, ``NAME-over-lammps``) and, for
    ``mcm-fit-chosen``, the chosen kind's suffix.

    Parameters
    ----------
    only : list of str or None
        The names given (None: everything).
    name : str
        A figure's name as printed.

    Returns
    -------
    bool
    """
    if not only:
        return True
    group = "mcm" if name.startswith("mcm") else (
        "cfd-dem" if name.startswith("cfd-dem") else "dem")
    return any(o == group or o == name or (o == "mcm-fit-chosen" and name.startswith(o))
               or name.startswith(f"{o}-lammps-") or name == f"{o}-over-lammps"
               for o in only)


def markov_benchmarks(repeat: int = 5, particles: int = 27000, workdir: Path | None = None,
                      only: list[str] | None = None) -> Iterator[tuple[str, float, str]]:
    """The ``mcm-*`` figures (module docstring; docs/performance.md).

    Parameters
    ----------
    repeat : int, optional
        Timed runs per figure (the median is reported), after one warm-up run.
    particles : int, optional
        Particles of the synthetic run.
    workdir : pathlib.Path, optional
        Folder for the temporary trajectory and prediction files (default: the system's).
    only : list of str, optional
        Measure only these figures (:func:`selects`); all when None.

    Yields
    ------
    tuple of (str, float, str)
        (name, median seconds, ``'s'``).
    """
    from cfbmarkov import synthetic
    from cfbmarkov.markov import CellGrid, PaperEstimator, discretize, exact_rtd

    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        run = Path(tmp) / "bench-run.h5"
        flow = synthetic.RiserFlow()
        # 10-15 s with 0.1 s before it: the history states with memory need at 10 s
        synthetic.write_run(run, flow, particles, 5.1, seed=1, start_time=9.9)
        grid = CellGrid(6, 38, flow.width, flow.height)
        estimator = PaperEstimator(grid, lag=0.025)

        def fit():      # read the window, discretise, count, estimate
            return estimator.fit(discretize(run, grid, 0.025, (10.0, 15.0)))

        def want(*names: str) -> bool:
            return any(selects(only, n) for n in names)

        if want("mcm-fit"):
            yield "mcm-fit", _median_time(fit, repeat), "s"
        model = fit()
        if want("mcm-predict"):
            states0, _, laps0 = model.initial_states(run, 10.0)
            yield "mcm-predict", _median_time(
                lambda: model.monte_carlo(states0, 200, 7, laps0), repeat), "s"
        pred = Path(tmp) / "bench-pred.h5"
        if want("mcm-predict-file"):
            yield "mcm-predict-file", _median_time(
                lambda: model.predict(run, 10.0, 5.0, seed=7, output=pred), repeat), "s"
        if want("mcm-predict-file-kinetics"):
            from cfbmarkov.kinetics import (Constant, FirstOrder, HeatExchange, Kinetics,
                                            Property)

            kinetics = Kinetics((
                Property("conversion", FirstOrder(), {"rate": Constant(1.0)}),
                Property("temperature", HeatExchange(600.0),
                         {"coefficient": Constant(2.0), "temperature": Constant(800.0)},
                         initial=300.0))).per_state(model.state_space)
            yield "mcm-predict-file-kinetics", _median_time(
                lambda: model.predict(run, 10.0, 5.0, seed=7, output=pred, kinetics=kinetics),
                repeat), "s"
        if want("mcm-exact-rtd"):
            yield "mcm-exact-rtd", _median_time(
                lambda: exact_rtd(model.transition_matrix, model.up_fraction,
                                  model.down_fraction, model.lag), repeat), "s"
        yield from _long_tail_benchmark(want, repeat)
        if want("mcm-fit-intervals"):
            from cfbmarkov.analysis.intervals import model_intervals

            yield "mcm-fit-intervals", _median_time(
                lambda: model_intervals(fit(), level=0.9, resamples=100), repeat), "s"
        if want("mcm-fit-open", "mcm-fit-open-ratio", "mcm-predict-open",
                "mcm-predict-open-ratio"):
            for row in _open_benchmarks(Path(tmp), flow, grid, particles, repeat, run, pred):
                if want(row[0]):
                    yield row
        # beyond the paper: the automatic choice of state space (5 candidates judged by
        # their exact RTD on the window), then the chosen model's prediction
        from cfbmarkov.markov.select import select_model

        def choose():
            return select_model(run, window=(10.0, 15.0), columns=6, rows=38, lag=0.025)

        if want("mcm-fit-auto"):
            yield "mcm-fit-auto", _median_time(choose, max(1, repeat // 2)), "s"
        if want("mcm-fit-chosen", "mcm-predict-file-auto"):
            chosen = choose()
            if want("mcm-fit-chosen"):
                yield f"mcm-fit-chosen-{chosen.state_space.kind}", _median_time(
                    lambda: _refit(chosen, run), repeat), "s"
            pred_auto = Path(tmp) / "bench-pred-auto.h5"
            if want("mcm-predict-file-auto"):
                yield "mcm-predict-file-auto", _median_time(
                    lambda: chosen.predict(run, 10.0, 5.0, seed=7, output=pred_auto),
                    repeat), "s"
        # the reproductions' chosen model: with coherent moves (the cluster model)
        names = ("mcm-fit-auto-coherent", "mcm-predict-file-auto-coherent",
                 "mcm-fit-predict-auto-coherent")
        if want(*names):
            fit_time = _median_time(lambda: select_model(run, window=(10.0, 15.0), columns=6,
                                                         rows=38, lag=0.025, coherent=True),
                                    max(1, repeat // 2))
            coherent = select_model(run, window=(10.0, 15.0), columns=6, rows=38, lag=0.025,
                                    coherent=True)
            pred_coherent = Path(tmp) / "bench-pred-coherent.h5"
            predict_time = _median_time(
                lambda: coherent.predict(run, 10.0, 5.0, seed=7, output=pred_coherent), repeat)
            for name, value in zip(names, (fit_time, predict_time, fit_time + predict_time)):
                if want(name):
                    yield name, value, "s"
        # the regime model (912 states) and its prediction along one common regime path
        if want("mcm-fit-regime", "mcm-predict-file-regime"):
            for row in _regime_benchmarks(run, Path(tmp), repeat):
                if want(row[0]):
                    yield row


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


def _simulation_benchmarks(repeat: int, particles: int, only: list[str] | None
                           ) -> Iterator[tuple[str, float, str]]:
    try:
        from cfbmarkov.simulate.bench import simulation_benchmarks
    except ImportError:
        return
    yield from simulation_benchmarks(repeat=repeat, particles=particles,
                                     wanted=lambda name: selects(only, name))


def run_benchmarks(only: list[str] | None = None, repeat: int = 5, particles: int = 27000
                   ) -> Iterator[tuple[str, float, str]]:
    """All benchmarks, or those ``only`` names (``cfbmarkov bench``).

    Parameters
    ----------
    only : list of str, optional
        Groups (``mcm``, ``dem``, ``cfd-dem``) or figures (:data:`MCM_NAMES`,
        :data:`SIMULATION_NAMES`) to run (:func:`selects`); all when None.
    repeat : int, optional
        Timed runs per figure (the median is reported).
    particles : int, optional
        Number of particles (default the paper's 27000).

    Yields
    ------
    tuple of (str, float, str)
        (name, value, unit), one per figure; see docs/performance.md.

    Raises
    ------
    InputError
        For a name that is neither a group nor a figure (:func:`check_names`).
    """
    check_names(only)
    if not only or any(o.startswith("mcm") for o in only):
        yield from markov_benchmarks(repeat, particles, only=only)
    if not only or any(not o.startswith("mcm") for o in only):
        for row in _simulation_benchmarks(repeat, particles, only):
            if selects(only, row[0]):
                yield row
