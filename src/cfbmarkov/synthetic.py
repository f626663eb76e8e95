"""Synthetic riser-like trajectories with a known generator, for tests, benchmarks and the demo.

The generator is a Markov chain on cells x {rising, falling}: particles in the core mostly
rise, near the walls they switch to falling more often (a core-annulus structure; with the
defaults the outer columns still rise on average, 0.5 m/s against 1.7 m/s in the core, and
about 4 lags in 10 there are falling), each keeps its direction with
some persistence, drifts vertically by a discretised normal displacement per lag and steps
sideways to neighbouring columns. Only positions are written, so a model on cells alone
does not see the hidden direction, as with CFD-DEM clusters. With ``persistence=0`` (no
hidden direction) the generator is itself a chain on cells and a fitted model must
recover it exactly (:func:`cell_chain`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.limits import check_finite, check_memory, check_seed
from cfbmarkov.markov.montecarlo import SparseChain, run_chain
from cfbmarkov.markov.states import CellGrid, place_in_cells


@dataclass(frozen=True)
class RiserFlow:
    """Parameters of the synthetic core-annulus flow.

    Attributes
    ----------
    columns, rows : int
        Cells m across and n up (default the paper's 6 x 38).
    width, height : float
        Riser width W and height H, m.
    lag : float
        Time between frames and transition step, s.
    rise_velocity : float
        Mean upward velocity of rising particles in the core, m/s.
    fall_velocity : float
        Mean velocity of falling particles, m/s (negative: downward).
    vertical_spread : float
        Standard deviation of the vertical displacement per lag, in cells.
    lateral_probability : float
        Probability per lag of stepping to each neighbouring column.
    switch_probability : float
        Base probability per lag of changing direction (more towards the walls).
    persistence : bool
        True: particles carry a hidden direction; False: a pure chain on cells.
    """

    columns: int = 6
    rows: int = 38
    width: float = 0.09
    height: float = 0.95
    lag: float = 0.025
    rise_velocity: float = 2.0       # mean upward velocity of rising particles in the core
    fall_velocity: float = -0.8      # mean velocity of falling particles
    vertical_spread: float = 0.6     # SD of the vertical displacement per lag, in cells
    lateral_probability: float = 0.15  # probability of stepping to each neighbouring column
    switch_probability: float = 0.08   # base probability per lag of changing direction
    persistence: bool = True           # False: no hidden direction (a pure chain on cells)

    def __post_init__(self):
        """Refuse parameters that give no chain (InputError naming the parameter): whole
        numbers of at least 1 column and 4 rows, finite sizes, lag, velocities and spread
        (positive where a size), probabilities whose stay probabilities stay in [0, 1]."""
        for name, least in (("columns", 1), ("rows", 4)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                    or value < least:
                raise InputError(f"RiserFlow {name} {value!r}: a whole number >= {least}")
        for name in ("width", "height", "lag", "vertical_spread"):
            check_finite(getattr(self, name), f"RiserFlow {name}", positive=True)
        for name in ("rise_velocity", "fall_velocity"):
            check_finite(getattr(self, name), f"RiserFlow {name}")
        # each side's step and the switches toward the walls (1.7 x) are probabilities
        for name, most in (("lateral_probability", 0.5), ("switch_probability", 1 / 1.7)):
            value = check_finite(getattr(self, name), f"RiserFlow {name}", non_negative=True)
            if value > most:
                raise InputError(f"RiserFlow {name} {value:g} must be at most {most:.4g} (the "
                                 "probability of staying would be negative)")

    @property
    def grid(self) -> CellGrid:
        """The cells of the flow as a :class:`~cfbmarkov.markov.states.CellGrid`."""
        return CellGrid(self.columns, self.rows, self.width, self.height)


def _vertical_kernel(mean_rows: float, spread: float, reach: int) -> np.ndarray:
    d = np.arange(-reach, reach + 1)
    w = np.exp(-0.5 * ((d - mean_rows) / max(spread, 1e-3)) ** 2)
    return w / w.sum()


def generator(flow: RiserFlow) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The generator as a Markov chain on hidden states (cell x direction).

    Parameters
    ----------
    flow : RiserFlow
        The flow parameters.

    Returns
    -------
    P : numpy.ndarray
        [S, S] transition matrix on the hidden states (S = 2 m n, or m n without
        persistence).
    up, down : numpy.ndarray
        [S, S] indicators (0 or 1) of the transitions that pass up through the top / down
        through the bottom of the periodic riser.
    cell_of_state : numpy.ndarray
        [S] the cell s = row*m + col of each hidden state.
    """
    m, n = flow.columns, flow.rows
    cell_h = flow.height / n
    reach = n // 2 - 2
    regimes = 2 if flow.persistence else 1
    s = m * n * regimes
    p = np.zeros((s, s))
    up = np.zeros((s, s))
    down = np.zeros((s, s))
    centre = (np.arange(m) + 0.5) / m - 0.5            # -0.5..0.5 across
    wall_weight = np.clip(np.abs(centre) * 2.0, 0, 1) ** 2   # 0 in the core, 1 at walls
    for g in range(regimes):
        for c in range(m):
            if flow.persistence:
                velocity = flow.rise_velocity * (1.3 - 0.6 * wall_weight[c]) if g == 0 else flow.fall_velocity
                to_fall = flow.switch_probability * (0.3 + 1.4 * wall_weight[c])
                to_rise = flow.switch_probability * (1.7 - 1.4 * wall_weight[c])
                switch = np.array([[1 - to_fall, to_fall], [to_rise, 1 - to_rise]])
            else:
                mix = 0.35 + 0.4 * wall_weight[c]
                rising = flow.rise_velocity * (1.3 - 0.6 * wall_weight[c])
                velocity = (1 - mix) * rising + mix * flow.fall_velocity
                switch = np.ones((1, 1))
            vertical = _vertical_kernel(velocity * flow.lag / cell_h, flow.vertical_spread, reach)
            lateral = np.zeros(m)
            for dc, prob in ((-1, flow.lateral_probability), (1, flow.lateral_probability)):
                lateral[min(max(c + dc, 0), m - 1)] += prob
            lateral[c] += 1 - 2 * flow.lateral_probability
            for r in range(n):
                i = (g * n + r) * m + c
                for k, pv in enumerate(vertical):
                    target = r + k - reach
                    row = target % n
                    for c2 in np.flatnonzero(lateral):
                        for g2 in range(regimes):
                            j = (g2 * n + row) * m + c2
                            p[i, j] += pv * lateral[c2] * switch[g, g2]
                            if target >= n:
                                up[i, j] = 1.0
                            elif target < 0:
                                down[i, j] = 1.0
    cell_of_state = np.arange(s) % (m * n)
    return p, up, down, cell_of_state


def cell_chain(flow: RiserFlow):
    """The generator as a :class:`~cfbmarkov.markov.model.MarkovModel` on cells.

    Parameters
    ----------
    flow : RiserFlow
        Flow parameters with ``persistence=False``.

    Returns
    -------
    MarkovModel
        The exact chain on cells (estimator ``'synthetic'``, zero counts).

    Raises
    ------
    ValueError
        When ``flow.persistence`` is true: with a hidden direction the generator is not a
        chain on cells.
    """
    from cfbmarkov.markov.model import MarkovModel

    if flow.persistence:
        raise ValueError("a generator with a hidden direction is not a chain on cells")
    p, up, down, _ = generator(flow)
    zeros = np.zeros_like(p, dtype=np.int64)
    return MarkovModel(p, zeros, zeros, zeros, flow.grid, flow.lag, estimator="synthetic",
                       source="synthetic", pass_fractions=(up, down))


def long_tail_chain(columns: int = 6, rows: int = 38, cutoff: float = 1e-4):
    """A chain on cells with slow wall states and a long-tailed RTD, as fitted on a real riser.

    The generator on cells (:func:`cell_chain`) of a slow flow: core particles rise at
    1.4 m/s (less towards the walls), wall particles fall at up to 0.5 m/s net and fall out
    through the bottom (several laps down before they rise again), 8 % lateral steps per
    lag. Transition probabilities below ``cutoff`` are dropped and the rows renormalised,
    as the finite counts of a fitted model leave them out (about 12 non-zeros per row).
    On the paper's 6 x 38 cells at 0.025 s its E(RT) is 108 lags (2.7 s), SD(RT) 59 lags,
    and the exact RTD takes 1333 lags to resolve all but 1e-10 of its mass: the benchmark
    ``mcm-exact-rtd-long-tail``.

    Parameters
    ----------
    columns, rows : int, optional
        Cells across and up.
    cutoff : float, optional
        Transition probabilities below it are set to 0.

    Returns
    -------
    MarkovModel
        Estimator ``'synthetic'``, zero counts, pass fractions of the generator.
    """
    from cfbmarkov.markov.model import MarkovModel

    flow = RiserFlow(columns=columns, rows=rows, persistence=False, rise_velocity=1.4,
                     fall_velocity=-1.0, lateral_probability=0.08)
    p, up, down, _ = generator(flow)
    p[p < cutoff] = 0.0
    p /= p.sum(axis=1, keepdims=True)
    zeros = np.zeros_like(p, dtype=np.int64)
    return MarkovModel(p, zeros, zeros, zeros, flow.grid, flow.lag, estimator="synthetic",
                       source="synthetic", pass_fractions=(up, down))


def _seed(seed: int, offset: int) -> int:
    """The seed ``offset`` streams on from ``seed``, within the generators' 0 .. 2^64 - 1."""
    return (int(seed) + offset) % 2 ** 64


#: bytes a synthetic run holds per particle and frame (states, cells, laps, positions)
RUN_BYTES = 40


def sample_run(flow: RiserFlow, n_particles: int, n_frames: int, seed: int = 0,
               start_time: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A synthetic run in memory, started from the generator's stationary distribution.

    Parameters
    ----------
    flow : RiserFlow
        The flow parameters.
    n_particles : int
        Number of particles N.
    n_frames : int
        Number of frames T, ``flow.lag`` apart.
    seed : int, optional
        Random seed; the same seed gives the same run.
    start_time : float, optional
        Time of the first frame, s.

    Returns
    -------
    times : numpy.ndarray
        [T] frame times, s.
    cells : numpy.ndarray
        [T, N] cell of each particle.
    positions : numpy.ndarray
        [T, N, 2] positions, m, uniform inside the cells.
    laps : numpy.ndarray
        [T, N] lap counters.

    Raises
    ------
    InputError
        Where the counts are not whole numbers >= 1, the seed not one of 0 .. 2^64 - 1, the
        start time not finite, or the run would not fit in memory
        (:func:`cfbmarkov.limits.check_memory`).
    """
    for name, value in (("n_particles", n_particles), ("n_frames", n_frames)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InputError(f"{name} {value!r}: a whole number >= 1")
    seed = check_seed(seed)
    start_time = check_finite(start_time, "start_time", "s")
    check_memory(RUN_BYTES * float(n_frames) * float(n_particles),
                 f"a synthetic run of {n_particles} particles x {n_frames} frames",
                 "give fewer particles (--particles) or a shorter run")
    p, up, down, cell_of_state = generator(flow)
    chain = SparseChain.from_matrix(p, up, down)
    # start from the stationary distribution of the generator
    values, vectors = np.linalg.eig(p.T)
    pi = np.abs(vectors[:, int(np.argmin(np.abs(values - 1)))].real)
    rng = np.random.default_rng(seed)
    initial = rng.choice(p.shape[0], size=n_particles, p=pi / pi.sum())
    hidden, laps = run_chain(chain, initial, n_frames - 1, _seed(seed, 1))
    cells = cell_of_state[hidden]
    grid = flow.grid
    positions = np.empty((n_frames, n_particles, 2))
    for k in range(n_frames):      # one vectorised placement per frame
        positions[k] = place_in_cells(cells[k], grid, _seed(seed, 2), k)
    times = start_time + flow.lag * np.arange(n_frames)
    return times, cells, positions, laps


def _sampled(flow: RiserFlow, n_particles: int, duration: float, seed: int, start_time: float):
    """(times, positions, laps, parameters) of a sampled run for the writers."""
    duration = check_finite(duration, "duration", "s", positive=True)
    n_frames = int(round(duration / flow.lag)) + 1
    times, _, positions, laps = sample_run(flow, n_particles, n_frames, seed, start_time)
    params = {k: getattr(flow, k) for k in flow.__dataclass_fields__}
    params["seed"] = seed
    return times, positions, laps, params


def write_run(path: str | os.PathLike, flow: RiserFlow, n_particles: int, duration: float,
              seed: int = 0, start_time: float = 0.0) -> Path:
    """Write a synthetic run as a trajectory file (source ``'synthetic'``).

    Parameters
    ----------
    path : str or os.PathLike
        The trajectory file to write.
    flow : RiserFlow
        The flow parameters (stored in the file's ``parameters``).
    n_particles : int
        Number of particles.
    duration : float
        Simulated time, s; frames every ``flow.lag`` from ``start_time`` to
        ``start_time + duration``.
    seed : int, optional
        Random seed.
    start_time : float, optional
        Time of the first frame, s.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    from cfbmarkov.trajectory_writer import TrajectoryWriter

    times, positions, laps, params = _sampled(flow, n_particles, duration, seed, start_time)
    with TrajectoryWriter(path, np.arange(n_particles), width=flow.width, height=flow.height,
                          source="synthetic", parameters=params, frame_interval=flow.lag) as w:
        w.append_frames(times, positions, laps=laps)
    return Path(path)


def write_open_run(path: str | os.PathLike, flow: RiserFlow, n_particles: int, duration: float,
                   seed: int = 0, start_time: float = 0.0) -> Path:
    """Write the synthetic flow as an *open* riser (source ``'synthetic-open'``).

    The periodic run of :func:`write_run` with each pass through the top or the bottom
    turned into a visit outside: the particle is absent from the frame after the pass (it
    left through the outlet, or fell back out through the inlet) and present again from the
    next one where the periodic run has it then: after a pass up, two frames' travel above
    the bottom (a median 0.09 m on the default flow, not within a cell of the inlet), after
    a pass down, as far below the top. Those tracks begin (and the ones before a pass down
    end) away from the faces: the fit counts most of them as censored, not as entries
    (117 entries and 32 returns against 3215 exits on 1000 particles, 2-7 s, seed 1), and
    warns that the inflow does not balance the outflow, so a prediction from such a model
    drains the riser. It is
    therefore not a clean open riser of the periodic chain, only a file of the open kind
    whose particle-frames, and so the work of a fit or a prediction, stay those of the
    periodic run (``cfbmarkov bench``'s open figures); the open risers of the tests are
    drawn from known absorbing chains.

    Parameters
    ----------
    path, flow, n_particles, duration, seed, start_time
        As for :func:`write_run`.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    from cfbmarkov.trajectory_writer import TrajectoryWriter

    times, positions, laps, params = _sampled(flow, n_particles, duration, seed, start_time)
    present = np.ones(laps.shape, dtype=bool)
    present[1:] = laps[1:] == laps[:-1]
    with TrajectoryWriter(path, np.arange(n_particles), width=flow.width, height=flow.height,
                          source="synthetic-open", parameters=params, frame_interval=flow.lag,
                          boundary="open") as w:
        w.append_frames(times, positions, present=present)
    return Path(path)


# -- a riser with a hidden global regime (issue 14: the regime model's test case) ------------
#
# Two chains on cells (two RiserFlow's without persistence, e.g. a dilute rise and a
# collapse) and a regime chain G that switches between them; all particles share one regime
# path. With the regime of frame t taken as that of the step t-1 -> t (what the flux over the
# previous lag reveals), the pair (cell, regime) is a Markov chain,
#
#     J[(c, r), (c', r')] = G[r, r'] K_r'[c, c'],      state = c * R + r,
#
# the layout of cfbmarkov.markov.regimes.RegimeCells without direction.


def regime_generator(flows, switching) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint chain J of a riser whose particles follow a common hidden regime.

    Parameters
    ----------
    flows : sequence of RiserFlow
        One flow per regime, each with ``persistence=False`` and the same grid and lag.
    switching : array_like, shape (R, R)
        The regime chain G per lag, row-stochastic.

    Returns
    -------
    J : numpy.ndarray
        [S, S] joint transition matrix on (cell, regime), S = m n R, state = cell*R + r.
    up, down : numpy.ndarray
        [S, S] indicators of the transitions passing up through the top / down through the
        bottom.

    Raises
    ------
    ValueError
        If a flow has persistence, the grids differ, or G is not R x R row-stochastic.
    """
    g = np.asarray(switching, dtype=np.float64)
    r = len(flows)
    if g.shape != (r, r) or np.any(g < 0) or not np.allclose(g.sum(axis=1), 1.0):
        raise ValueError(f"switching must be a {r} x {r} row-stochastic matrix")
    if any(f.persistence for f in flows) or len({(f.columns, f.rows, f.width, f.height, f.lag)
                                                 for f in flows}) != 1:
        raise ValueError("regime flows need persistence=False and one grid and lag")
    chains = [generator(f)[:3] for f in flows]
    n = chains[0][0].shape[0]
    joint = np.zeros((n * r, n * r))
    up = np.zeros_like(joint)
    down = np.zeros_like(joint)
    for a in range(r):
        for b in range(r):       # R x R blocks of (cells x cells)
            joint[a::r, b::r] = g[a, b] * chains[b][0]
            up[a::r, b::r] = chains[b][1]
            down[a::r, b::r] = chains[b][2]
    return joint, up, down


def write_regime_run(path: str | os.PathLike, flows, switching, n_particles: int,
                     duration: float, seed: int = 0, boundary: str = "periodic",
                     regimes=None) -> Path:
    """Write a periodic run whose particles share one hidden regime path (source
    ``'synthetic-regimes'``).

    The regime path is drawn from G (stationary start); at each step every particle moves
    by the cell chain of the step's regime. Only positions and laps are written.

    Parameters
    ----------
    path : str or os.PathLike
        The trajectory file to write.
    flows, switching
        As :func:`regime_generator`.
    n_particles : int
        Number of particles.
    duration : float
        Simulated time (s); frames every ``flows[0].lag``.
    seed : int, optional
        Random seed.
    boundary : {"periodic", "open"}, optional
        ``open``: each pass through the top or bottom is a visit outside, as in
        :func:`write_open_run`.
    regimes : array_like of int, optional
        The regime of each frame (``duration / lag + 1`` of them), given instead of drawn
        from G (e.g. a switch at a known time).

    Returns
    -------
    pathlib.Path
        The path written.
    """
    from cfbmarkov.trajectory_writer import TrajectoryWriter

    regime_generator(flows, switching)      # validates
    flow = flows[0]
    g = np.asarray(switching, dtype=np.float64)
    blocks = [generator(f)[:3] for f in flows]
    cells_n = blocks[0][0].shape[0]
    stacked = SparseChain.from_matrix(np.vstack([b[0] for b in blocks]),
                                      np.vstack([b[1] for b in blocks]),
                                      np.vstack([b[2] for b in blocks]))
    n_frames = int(round(duration / flow.lag)) + 1
    rng = np.random.default_rng(seed)
    values, vectors = np.linalg.eig(g.T)
    pi = np.abs(vectors[:, int(np.argmin(np.abs(values - 1)))].real)
    path_ = np.empty(n_frames, np.int64)
    path_[0] = rng.choice(len(flows), p=pi / pi.sum())
    for k in range(1, n_frames):         # one draw per frame (the regime path), not per particle
        path_[k] = rng.choice(len(flows), p=g[path_[k - 1]])
    if regimes is not None:
        path_ = np.asarray(regimes, dtype=np.int64)
        if path_.shape != (n_frames,) or path_.min() < 0 or path_.max() >= len(flows):
            raise ValueError(f"regimes must be {n_frames} regime numbers below {len(flows)}")
    initial = rng.integers(0, cells_n, n_particles)
    cells, laps = run_chain(stacked, initial, n_frames - 1, _seed(seed, 1), row_offset=path_ * cells_n)
    positions = np.empty((n_frames, n_particles, 2))
    for k in range(n_frames):      # one vectorised placement per frame
        positions[k] = place_in_cells(cells[k], flow.grid, _seed(seed, 2), k)
    times = flow.lag * np.arange(n_frames)
    params = {"flows": [{k: getattr(f, k) for k in f.__dataclass_fields__} for f in flows],
              "switching": g.tolist(), "seed": seed}
    with TrajectoryWriter(path, np.arange(n_particles), width=flow.width, height=flow.height,
                          source="synthetic-regimes", parameters=params,
                          frame_interval=flow.lag, boundary=boundary) as w:
        if w.boundary.is_open:
            present = np.ones(laps.shape, dtype=bool)
            present[1:] = laps[1:] == laps[:-1]
            w.append_frames(times, positions, present=present)
        else:
            w.append_frames(times, positions, laps=laps)
    return Path(path)
