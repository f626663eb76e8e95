"""The regime (cluster) model: a riser whose particles share a hidden global regime.

The synthetic riser moves its particles by one of two cell chains (a dilute rise and a
collapse) according to a regime that switches as its own Markov chain, common to every
particle (``synthetic.write_regime_run``). With the regime of a frame being that of the
step into it, (cell, regime) is a Markov chain J[(c, r), (c', r')] = G[r, r'] K_r'[c, c']
(``synthetic.regime_generator``), so the regime model can be checked against it exactly.
"""

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.markov import MarkovModel, fit_model
from cfbmarkov.markov.regime_chain import regime_matrix
from cfbmarkov.markov.regimes import DirectionRegimeCells, RegimeCells, regime_edges
from cfbmarkov.markov.first_passage import exact_rtd
from cfbmarkov.markov.model_summary import model_summary
from cfbmarkov.markov.select import select_model
from cfbmarkov.markov.spaces import state_space_from_attrs, state_space_from_name
from cfbmarkov.trajectories import Trajectories

_GRID = dict(columns=4, rows=16, persistence=False, vertical_spread=0.5)
#: regime 0 of the generator: a dilute rise; regime 1: a collapse (net downflow)
FLOWS = (synthetic.RiserFlow(rise_velocity=3.0, fall_velocity=-0.5, **_GRID),
         synthetic.RiserFlow(rise_velocity=0.5, fall_velocity=-1.5, **_GRID))
SWITCH = np.array([[0.9, 0.1], [0.2, 0.8]])
LAG, DURATION, PARTICLES = 0.025, 60.0, 300
# the fitted regimes are numbered by the flux, low first: fitted 0 = collapse = generator 1
ORDER = np.array([1, 0])


@pytest.fixture(scope="session")
def regime_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("regimes") / "run.h5"
    return synthetic.write_regime_run(path, FLOWS, SWITCH, PARTICLES, DURATION, seed=4)


@pytest.fixture(scope="session")
def joint():
    """The generator's joint chain in the fitted numbering (state = cell * 2 + fitted r)."""
    j, up, down = synthetic.regime_generator([FLOWS[k] for k in ORDER], SWITCH[ORDER][:, ORDER])
    return j, up, down


@pytest.fixture(scope="session")
def fitted(regime_run):
    space = state_space_from_name("cells-regime", 4, 16, 0.09, 0.95)
    return fit_model(regime_run, space, LAG, None)


def test_regime_edges_split_unequal_groups_where_they_separate():
    rng = np.random.default_rng(0)
    values = np.r_[rng.normal(2.0, 0.1, 900), rng.normal(-1.0, 0.1, 100), np.nan]
    (edge,) = regime_edges(values, 2)
    assert -0.7 < edge < 1.7               # between the groups, not at the median (about 1.9)
    assert len(regime_edges(np.r_[values, rng.normal(6.0, 0.1, 50)], 3)) == 2
    with pytest.raises(InputError, match="same in every frame"):
        regime_edges(np.ones(50), 2)
    with pytest.raises(InputError, match="too few"):
        regime_edges(np.array([1.0, 2.0, np.nan]), 2)


def test_space_fits_its_edges_on_the_window_and_round_trips(regime_run):
    space = RegimeCells(4, 16, 0.09, 0.95)
    assert not space.fitted and space.n_states == 128
    with Trajectories(regime_run) as traj:
        frames = traj.positions(slice(0, 200))
    with pytest.raises(InputError, match="not fitted"):
        space.discretize(frames, None, 1, LAG)
    fitted = space.fit_to_frames(frames, 1, LAG)
    assert fitted.fitted and space.accepts(fitted) and not fitted.accepts(space)
    assert fitted.fit_to_frames(frames, 1, LAG) is fitted
    back = state_space_from_attrs(fitted.to_attrs())
    assert back == fitted and type(back) is RegimeCells
    # every particle of a frame carries the frame's regime, the cell is the cell
    states = fitted.discretize(frames, None, 1, LAG)[1:]
    regimes = fitted.regime_of(states)
    assert np.all(regimes == regimes[:, :1])
    np.testing.assert_array_equal(regimes[:, 0], fitted.frame_regimes(frames, 1, LAG)[1:])
    with_direction = DirectionRegimeCells(4, 16, 0.09, 0.95, edges=fitted.edges)
    both = with_direction.discretize(frames, None, 1, LAG)[1:]
    np.testing.assert_array_equal(with_direction.regime_of(both), regimes)
    np.testing.assert_array_equal(with_direction.cell_of_state[both], fitted.cell_of_state[states])
    for bad in (dict(regimes=1), dict(regimes=2, edges=[1.0, 2.0]), dict(feature="colour")):
        with pytest.raises(InputError):
            RegimeCells(4, 16, **bad)


def test_regime_model_recovers_both_chains_and_the_switching(fitted, joint):
    j, _, _ = joint
    assert fitted.state_space.fitted
    # the switching rates: G within 4 standard errors of the frames' transitions
    g = fitted.regime_chain
    truth = SWITCH[ORDER][:, ORDER]
    frames_in = fitted.counts.reshape(-1, 2, 128).sum(axis=(0, 2)) / PARTICLES
    se = np.sqrt(truth * (1 - truth) / frames_in[:, None])
    assert np.all(np.abs(g - truth) < 4 * se), (g, truth)
    # both cell chains: the product chain equals J on well-visited rows (5 standard errors)
    rows = fitted.counts.sum(axis=1)
    visited = rows > 2000
    assert visited.sum() > 40
    p = fitted.transition_matrix[visited]
    se = np.sqrt(j[visited] * (1 - j[visited]) / rows[visited, None]) + 1e-3
    assert np.all(np.abs(p - j[visited]) < 5 * se)


def test_exact_rtd_is_the_joint_chains_and_the_cells_chain_misses_the_spread(
        fitted, joint, regime_run):
    j, up, down = joint
    truth = exact_rtd(j, up, down, LAG)
    # the product space's exact RTD machinery on J itself: the same numbers
    zeros = np.zeros_like(j, dtype=np.int64)
    exact = MarkovModel(j, zeros, zeros, zeros, fitted.state_space, LAG,
                        pass_fractions=(up, down)).rtd()
    assert exact.mean == pytest.approx(truth.mean, rel=1e-9)
    assert exact.sd == pytest.approx(truth.sd, rel=1e-9)
    # fitted on 60 s: within 5 % (mean) and 10 % (SD) of the joint chain
    rtd = fitted.rtd()
    assert abs(rtd.mean / truth.mean - 1) < 0.05 and abs(rtd.sd / truth.sd - 1) < 0.10, (
        rtd.mean, rtd.sd, truth.mean, truth.sd)
    cells = fit_model(regime_run, state_space_from_name("cells", 4, 16, 0.09, 0.95), LAG, None)
    assert cells.rtd().sd / truth.sd - 1 < -0.20          # no regime: too narrow an RTD
    assert abs(cells.rtd().sd / truth.sd - 1) > 2 * abs(rtd.sd / truth.sd - 1)


def _flux_spread(states, space):
    """SD over steps of the cloud's mean vertical move (cells per lag) of a state history."""
    rows = space.cell_of_state[states] // space.columns
    step = np.diff(rows, axis=0).astype(np.float64)
    step[step > space.rows // 2] -= space.rows         # through the periodic boundary
    step[step < -space.rows // 2] += space.rows
    return float(step.mean(axis=1).std())


def test_monte_carlo_follows_one_common_regime_path(fitted, regime_run):
    space = fitted.state_space
    states0, _, _ = fitted.initial_states(regime_run, 10.0)
    states, laps = fitted.monte_carlo(states0, 800, seed=5)
    regimes = space.regime_of(states)
    assert np.all(regimes == regimes[:, :1])            # one regime per step for every particle
    path = regimes[:, 0]
    assert 20 < np.count_nonzero(np.diff(path)) < 400    # it switches, as G does
    share = np.mean(path == 1)                           # the dilute rise: 2/3 of the time
    assert 0.5 < share < 0.8
    # surges and collapses move the whole cloud: its mean move fluctuates as in the data
    observed = fitted.state_space.discretize(
        Trajectories(regime_run).positions(slice(400, 1201)), None, 1, LAG)[1:]
    data_spread = _flux_spread(observed, space)
    model_spread = _flux_spread(states, space)
    assert abs(model_spread / data_spread - 1) < 0.3, (model_spread, data_spread)
    cells = fit_model(regime_run, state_space_from_name("cells", 4, 16, 0.09, 0.95), LAG, None)
    cell_states, _ = cells.monte_carlo(space.cell_of_state[states0], 800, seed=5)
    assert _flux_spread(cell_states, cells.state_space) < 0.5 * data_spread
    # bit for bit the same run for the same seed; laps follow the passes
    again, laps_again = fitted.monte_carlo(states0, 800, seed=5)
    np.testing.assert_array_equal(again, states)
    np.testing.assert_array_equal(laps_again, laps)
    assert laps[-1].mean() > 1.0


def test_regime_matrix_from_counts():
    space = RegimeCells(2, 2, 1.0, 1.0, edges=[0.0])
    counts = np.zeros((8, 8), np.int64)
    counts[0, 1] = 3          # regime 0 -> 1
    counts[2, 2] = 1          # regime 0 -> 0
    g = regime_matrix(counts, space)
    np.testing.assert_allclose(g, [[0.25, 0.75], [0.0, 1.0]])   # regime 1 never left: stays


def _two_regime_model(counts):
    space = RegimeCells(2, 2, 1.0, 1.0, edges=[0.0])
    rows = counts.sum(axis=1)
    matrix = np.eye(8)
    matrix[rows > 0] = counts[rows > 0] / rows[rows > 0, None]
    return MarkovModel(transition_matrix=matrix, counts=counts, counts_up=np.zeros_like(counts),
                       counts_down=np.zeros_like(counts), state_space=space, lag=0.01,
                       estimator="paper", window=None, source="x.h5", frame_pairs=5)


def test_summary_tells_a_regime_never_visited_from_one_never_left():
    counts = np.zeros((8, 8), np.int64)
    for cell in range(4):                    # regime 0 (even states) cycles through the cells
        counts[2 * cell, 2 * ((cell + 1) % 4)] = 5
    line = [s for s in model_summary(_two_regime_model(counts)).splitlines()
            if "regime chain" in s][0]
    assert line.endswith("(mean durations never left in the fitting window, "
                         "never visited in the fitting window)"), line
    counts[0, 1] = 3                         # regime 1 entered (last), never left
    line = [s for s in model_summary(_two_regime_model(counts)).splitlines()
            if "regime chain" in s][0]
    assert line.endswith("entered but never left in the fitting window)"), line
    counts[0, 1] = 0
    counts[1, 1] = 4                         # regime 1 entered, its particles stay in it
    line = [s for s in model_summary(_two_regime_model(counts)).splitlines()
            if "regime chain" in s][0]
    assert line.endswith("never left in the fitting window, never left in the fitting window)")


def test_auto_considers_and_picks_the_regime_model(regime_run):
    model = select_model(regime_run, window=(1.0, 31.0), columns=4, rows=16, lag=LAG)
    chosen = model.selection["chosen"]["states"]
    assert "regime" in chosen, model.selection["reason"]
    assert isinstance(model.state_space, RegimeCells) and model.state_space.fitted


def test_cli_fits_and_predicts_with_regimes(regime_run, tmp_path, capsys):
    out = tmp_path / "model.h5"
    assert main(["fit", str(regime_run), "--states", "cells-direction-regime", "--cells", "4x16",
                 "--lag", "0.025", "--window", "1:30", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "cells-direction-regime" in text and "regimes of the solids flux at" in text
    model = MarkovModel.load(out)
    assert isinstance(model.state_space, DirectionRegimeCells) and model.state_space.fitted
    pred = tmp_path / "pred.h5"
    assert main(["predict", str(out), "--init", str(regime_run), "--start", "30",
                 "--duration", "5", "-q", "-o", str(pred)]) == 0
    with Trajectories(pred) as traj:
        assert traj.n_frames == 201


def test_open_riser_regime_model_enters_newcomers_in_the_paths_regime(tmp_path):
    path = synthetic.write_regime_run(tmp_path / "open.h5", FLOWS, SWITCH, 200, 20.0, seed=6,
                                      boundary="open")
    model = fit_model(path, state_space_from_name("cells-regime", 4, 16, 0.09, 0.95), LAG,
                      (1.0, 20.0))
    assert model.boundary == "open" and model.state_space.fitted
    rtd = model.rtd()
    assert np.isfinite(rtd.mean) and rtd.mean > 0
    states0, _, _ = model.initial_states(path, 10.0)
    present0 = states0[states0 >= 0]
    states, _ = model.monte_carlo(present0, 200, seed=2)
    assert states.shape[1] > present0.size                    # newcomers entered
    space = model.state_space
    for row in states[1:]:
        here = row[row >= 0]
        assert here.size and np.all(space.regime_of(here) == space.regime_of(here[0]))


def test_height_feature_is_the_centre_of_mass_and_absent_particles_are_left_out():
    space = RegimeCells(4, 16, 0.09, 0.95, feature="height")
    rng = np.random.default_rng(2)
    frames = rng.uniform([0, 0], [0.09, 0.95], size=(30, 50, 2))
    frames[:15, :, 1] *= 0.3                       # a collapse: the bed low, then spread
    frames[3, :5] = np.nan                         # five particles absent in frame 3
    features = space.frame_features(frames, 1, 0.025)
    np.testing.assert_allclose(features, np.nanmean(frames[..., 1], axis=1))
    fitted = space.fit_to_frames(frames, 1, 0.025)
    np.testing.assert_array_equal(fitted.frame_regimes(frames, 1, 0.025), [0] * 15 + [1] * 15)
    assert "centre-of-mass height" in fitted.describe()
