"""Lag diagnostics: implied timescales (by hand and on generated data) and the
Chapman-Kolmogorov test on coarse groups of cells, with and without a hidden direction."""

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.errors import InputError
from cfbmarkov.markov import CellGrid, MarkovModel, discretize, fit_model
from cfbmarkov.markov.diagnostics import (active_set, ck_test, core_annulus, group_labels,
                                          height_bands, implied_timescales, model_timescales,
                                          product_groups)
from cfbmarkov.markov.cells import cell_index
from cfbmarkov.markov.states import StateSpace
from cfbmarkov.trajectory_writer import write_trajectories

LAGS = (0.025, 0.05, 0.1, 0.2)


def _flow(persistence):
    return synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=persistence)


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    """1500 particles x 5 s of the generator without (Markov on cells) and with the hidden
    direction of motion."""
    folder = tmp_path_factory.mktemp("diagnostics")
    out = {}
    for persistence in (False, True):
        path = folder / f"run-{persistence}.h5"
        synthetic.write_run(path, _flow(persistence), 1500, 5.0, seed=5)
        out[persistence] = path
    return out


@pytest.fixture(scope="session")
def results(runs):
    """ITS and CK (height thirds, 8 steps) of a cells-only MLE model on both runs."""
    out = {}
    for persistence, path in runs.items():
        grid = _flow(persistence).grid
        its = implied_timescales(path, grid, LAGS, k=4)
        model = fit_model(path, grid, 0.025)
        ck = ck_test(discretize(path, grid, 0.025), model, height_bands(grid, 3), steps=8)
        out[persistence] = its, model, ck
    return out


def _given(p, lag=0.05):
    p = np.asarray(p, dtype=float)
    zeros = np.zeros_like(p, dtype=np.int64)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(1, p.shape[0], 0.1, 1.0), lag,
                       estimator="given")


# -- implied timescales by hand -----------------------------------------------------------------
def test_two_state_timescale_by_hand():
    a, b, lag = 0.1, 0.3, 0.05
    its = model_timescales(_given([[1 - a, a], [b, 1 - b]], lag), k=3)
    assert its.timescales.shape == (1, 3)
    assert its.timescales[0, 0] == pytest.approx(-lag / np.log(1 - a - b), rel=1e-12)
    assert its.eigenvalues[0, 0] == pytest.approx(1 - a - b)
    assert np.all(np.isnan(its.timescales[0, 1:]))      # a 2-state chain has one process
    assert its.lags.tolist() == [lag]


def test_three_state_cycle_has_complex_pair():
    """P = (1 - a) I + a C (C the cyclic shift): not reversible, lambda = 1 - a + a w with
    w = exp(+-2 pi i / 3), one conjugate pair with t = -tau / ln|lambda|."""
    a, lag = 0.2, 0.025
    cycle = np.roll(np.eye(3), 1, axis=1)
    its = model_timescales(_given((1 - a) * np.eye(3) + a * cycle, lag), k=2)
    lam = 1 - a + a * np.exp(2j * np.pi / 3)
    np.testing.assert_allclose(its.timescales[0], -lag / np.log(abs(lam)), rtol=1e-10)
    np.testing.assert_allclose(sorted(its.eigenvalues[0], key=np.imag), [lam.conjugate(), lam],
                               atol=1e-12)


def test_disconnected_state_is_left_out():
    a, b = 0.1, 0.3
    p = [[1 - a, a, 0.0], [b, 1 - b, 0.0], [0.0, 0.0, 1.0]]   # state 2 never left nor entered
    np.testing.assert_array_equal(active_set(np.asarray(p)), [0, 1])
    its = model_timescales(_given(p), k=1)
    assert its.timescales[0, 0] == pytest.approx(-0.05 / np.log(1 - a - b))
    assert its.n_active.tolist() == [2]
    assert np.isinf(model_timescales(_given(p), k=1, connected=False).timescales[0, 0])


# -- generated data ---------------------------------------------------------------------------
def test_markov_generator_has_lag_independent_timescales(results):
    its = results[False][0]
    true = model_timescales(synthetic.cell_chain(_flow(False)), k=4).timescales[0]
    slow = its.timescales[:, 0]
    assert slow.max() / slow.min() < 1.05
    np.testing.assert_allclose(its.timescales, np.broadcast_to(true, its.timescales.shape),
                               rtol=0.05)
    assert np.all(its.timescales > its.lags[:, None])       # resolved at every lag


def test_markov_generator_passes_ck_test(results):
    s = results[False][2].summary()
    assert s["max_abs_error"] < 0.01
    assert s["max_z"] < 4.0
    assert s["rms_error_diagonal"] < 0.005


def test_hidden_direction_fails_ck_test(results):
    markov, hidden = results[False][2].summary(), results[True][2].summary()
    assert hidden["max_abs_error"] > 0.05
    assert hidden["max_abs_error"] > 10 * markov["max_abs_error"]
    assert hidden["rms_error_diagonal"] > 10 * markov["rms_error_diagonal"]
    assert hidden["max_z"] > 10
    # the model keeps too many particles in their band: the data leave faster
    ck = results[True][2]
    diag = np.diagonal(ck.predicted - ck.estimated, axis1=1, axis2=2)
    assert np.all(diag[2:] > 0)


def test_hidden_direction_makes_slow_timescale_depend_on_lag(results):
    """Not reversible, so no variational bound: the cells-only model forgets the direction
    every lag, spreads particles around the loop too slowly and overestimates the slowest
    (circulation) timescale at short lags; it falls towards the hidden generator's value
    (about 0.29 s here) as the lag grows. The lateral process (t4), independent of the
    direction, stays put."""
    its = results[True][0]
    slow = its.timescales[:, 0]
    assert slow[0] > 1.5 * slow[2]                # 0.025 s vs 0.1 s
    assert np.all(np.diff(slow[:3]) < 0)
    flow = _flow(True)
    p, *_ = synthetic.generator(flow)
    hidden = model_timescales(_given(p, flow.lag), k=1).timescales[0, 0]
    assert abs(slow[-1] - hidden) < abs(slow[0] - hidden) / 3
    lateral = its.timescales[:3, 2]
    assert lateral.max() / lateral.min() < 1.05


def test_core_annulus_is_markov_even_with_hidden_direction(runs, results):
    """Sideways steps do not depend on the hidden direction, so the column process is itself
    Markov and a core/annulus CK test cannot see the hidden state: the choice of groups
    matters."""
    model = results[True][1]
    s = ck_test(discretize(runs[True], model.state_space, model.lag), model,
                core_annulus(model.state_space), steps=8).summary()
    assert s["max_abs_error"] < 0.01


def test_lag_must_be_whole_frames(runs):
    with pytest.raises(InputError, match="whole multiple"):
        implied_timescales(runs[False], _flow(False).grid, [0.03])


# -- the CK test by hand ------------------------------------------------------------------------
def test_ck_test_by_hand(tmp_path, write_states):
    """2 x 2 cells, bands low = {0, 1}, high = {2, 3}; particle 0: 0 -> 1 -> 3,
    particle 1: 1 -> 2 -> 3, one frame per second, lag 1 s."""
    path = write_states(tmp_path / "hand.h5", [[0, 1], [1, 2], [3, 3]], columns=2, rows=2)
    grid = CellGrid(2, 2, width=1.0, height=2.0)
    rng = np.random.default_rng(1)
    p = rng.random((4, 4))
    p /= p.sum(axis=1, keepdims=True)
    model = MarkovModel(p, *(np.zeros((4, 4), np.int64),) * 3, state_space=grid, lag=1.0)
    ck = ck_test(discretize(path, grid, 1.0), model, height_bands(grid, 2), steps=(1, 2))
    assert ck.group_names == ["bottom", "top"]
    # step 1: start frames 0, 1; low holds 0, 1 (t = 0) and 1 (t = 1): w_low = [1, 2, 0, 0]/3
    np.testing.assert_array_equal(ck.counts, [[3, 1], [2, 0]])
    np.testing.assert_allclose(ck.estimated[0], [[1 / 3, 2 / 3], [0, 1]])
    w_low = np.array([1, 2, 0, 0]) / 3
    np.testing.assert_allclose(ck.predicted[0, 0], [(w_low @ p)[:2].sum(), (w_low @ p)[2:].sum()])
    np.testing.assert_allclose(ck.predicted[0, 1], [p[2, :2].sum(), p[2, 2:].sum()])
    # step 2: start frame 0 only; w_low = [1, 1, 0, 0]/2, top empty -> nan
    p2 = p @ p
    w_low = np.array([0.5, 0.5, 0, 0])
    np.testing.assert_allclose(ck.estimated[1, 0], [0, 1])
    np.testing.assert_allclose(ck.predicted[1, 0], [(w_low @ p2)[:2].sum(), (w_low @ p2)[2:].sum()])
    assert np.all(np.isnan(ck.estimated[1, 1])) and np.all(np.isnan(ck.predicted[1, 1]))
    # binomial standard error with n_eff = n_A / (k * lag_frames)
    assert ck.stderr[0, 0, 0] == pytest.approx(np.sqrt(1 / 3 * 2 / 3 / 3))
    assert ck.effective_counts[1, 0] == pytest.approx(1.0)
    np.testing.assert_allclose(ck.times, [1.0, 2.0])
    s = ck.summary()
    assert s["max_abs_error"] == pytest.approx(np.nanmax(np.abs(ck.predicted - ck.estimated)))


class _DirectionSpace(StateSpace):
    """Test space: 2*cell + (1 if the particle fell over the previous lag) (memory_lags = 1),
    or + (1 if v_y < 0) from velocities (needs_velocity)."""

    def __init__(self, grid, velocity=False):
        self.kind = "test-direction"          # an instance attribute: not registered
        self.columns, self.rows, self.width, self.height = (grid.columns, grid.rows,
                                                            grid.width, grid.height)
        self.memory_lags = 0 if velocity else 1
        self.needs_velocity = velocity

    @property
    def n_states(self):
        return 2 * self.columns * self.rows

    @property
    def cell_of_state(self):
        return np.arange(self.n_states, dtype=np.int64) // 2

    def discretize(self, positions, velocities=None, lag_frames=1, frame_interval=None, *,
                   memo=None):
        cells = cell_index(positions, self.width, self.height, self.columns, self.rows)
        if self.needs_velocity:
            falling = velocities[..., 1] < 0
        else:
            dy = np.zeros(positions.shape[:-1])
            dy[lag_frames:] = positions[lag_frames:, :, 1] - positions[:-lag_frames, :, 1]
            dy = (dy + self.height / 2) % self.height - self.height / 2
            falling = dy < 0
        return (2 * cells + falling).astype(np.int32)

    def to_attrs(self):
        return {"kind": self.kind}


@pytest.mark.parametrize("velocity", [False, True], ids=["memory", "velocity"])
def test_ck_step_one_of_fitted_mle_is_exact_for_spaces_with_memory(tmp_path, velocity):
    """For an MLE model fitted on the same window, step 1 of the CK test holds exactly
    (w_A P = pooled counts of A / n_A), which needs ck_test to discretise the frames exactly
    as the estimator did, history before the window included."""
    flow = _flow(True)
    times, _, positions, _ = synthetic.sample_run(flow, 300, 41, seed=2)
    rng = np.random.default_rng(3)
    path = write_trajectories(tmp_path / "v.h5", times, positions, width=flow.width,
                              height=flow.height, velocities=rng.normal(size=positions.shape))
    space = _DirectionSpace(flow.grid, velocity)
    window = (0.1, 1.0)
    lag = 0.05                                   # two frames
    model = fit_model(path, space, lag, window)
    ck = ck_test(discretize(path, space, lag, window), model,
                 product_groups(height_bands(space, 2), core_annulus(space)), steps=3)
    np.testing.assert_allclose(ck.predicted[0], ck.estimated[0], atol=1e-12)
    assert ck.summary()["max_abs_error"] > 1e-4           # later steps are not exact
    if not velocity:
        with pytest.raises(InputError, match="history"):
            discretize(path, space, lag, (0.0, 1.0))
        # no window: every frame that has the history
        assert ck_test(discretize(path, space, lag), model, height_bands(space, 2),
                       steps=1).counts[0].sum() == 300 * (41 - 2 - 2)
    with pytest.raises(InputError, match="state space and lag"):
        ck_test(discretize(path, space, 0.025, window), model, height_bands(space, 2))


# -- groups -------------------------------------------------------------------------------------
def test_group_helpers_partition_the_cells():
    grid = CellGrid(6, 38)
    bands = height_bands(grid, 3)
    assert list(bands) == ["bottom", "middle", "top"]
    assert [v.size for v in bands.values()] == [13 * 6, 13 * 6, 12 * 6]
    names, label = group_labels(grid, bands)
    assert label[0] == 0 and label[grid.n_cells - 1] == 2
    ca = core_annulus(grid, wall_columns=1)
    assert set(ca["annulus"] % 6) == {0, 5} and set(ca["core"] % 6) == {1, 2, 3, 4}
    assert set(core_annulus(grid, 2)["core"] % 6) == {2, 3}
    both = product_groups(bands, ca)
    assert len(both) == 6 and sum(v.size for v in both.values()) == grid.n_cells
    with pytest.raises(InputError, match="overlaps"):
        group_labels(grid, {"a": np.arange(10), "b": np.arange(5, grid.n_cells)})
    with pytest.raises(InputError, match="unassigned"):
        group_labels(grid, {"a": np.arange(10)})
    with pytest.raises(InputError, match="no core"):
        core_annulus(grid, wall_columns=3)


# -- figures and numbers for the report ----------------------------------------------------------
def test_figures_and_tables(tmp_path, results):
    from cfbmarkov.report.diagnostics import plot_ck_test, plot_implied_timescales

    its, _, ck = results[True]
    for path in (plot_implied_timescales(its, tmp_path / "its.png"),
                 plot_ck_test(ck, tmp_path / "ck.png"),
                 plot_ck_test(ck, tmp_path / "ck-full.png", full=True, title="full")):
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = its.table()
    assert table.splitlines()[0].split()[:2] == ["lag", "(s)"] and len(table.splitlines()) == 5
    import json

    json.dumps(its.as_dict())
    json.dumps(ck.as_dict())
    assert set(ck.summary()) >= {"max_abs_error", "rms_error"}
