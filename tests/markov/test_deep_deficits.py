"""Residences that fall many laps before they end: the exact RTD and the exact kinetics keep
as many lap deficits as the chain's residences need (first_passage.deeper_levels), so that
E(RT), SD(RT) and exit means are those of the whole chain, not of its first 8 deficits."""

import numba
import numpy as np
import pytest

from cfbmarkov.kinetics import Constant, FirstOrder, Kinetics, Property
import cfbmarkov.markov.first_passage as fp
from cfbmarkov.markov.first_passage import (DEFICIT_TOL, MIN_DEFICIT_LEVELS, deeper_levels,
                                            exact_rtd)
from cfbmarkov.markov.kinetics_exact import exact_kinetics
from cfbmarkov.markov.model import MarkovModel
from cfbmarkov.markov.states import CellGrid

LAG = 0.1


def walk(up=0.3, down=0.2):
    """One state of a periodic riser whose lap counter is a lazy random walk: a pass up
    with probability ``up`` a lag, a pass down with ``down``. A residence is the first
    passage of the walk to +1: mean 1 / mu lags and variance sigma^2 / mu^3 lags^2 (Wald's
    identities for a walk that cannot skip a level up; mu = up - down, sigma^2 the variance
    of a step); a residence reaches deficit -K with probability (down / up)^K (gambler's
    ruin), 0.67^8 = 0.04 here."""
    p = np.array([[1.0]])
    fractions = (np.array([[up]]), np.array([[down]]))
    zeros = np.zeros((1, 1), np.int64)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 1, 0.1, 1.0), LAG,
                       estimator="given", pass_fractions=fractions)


def test_exact_rtd_of_a_walk_that_falls_deep_has_wald_moments():
    up, down = 0.3, 0.2
    mu, step_variance = up - down, up + down - (up - down) ** 2
    rtd = walk(up, down).rtd()
    assert rtd.mean == pytest.approx(LAG / mu, rel=2e-5)                 # 1 s
    assert rtd.sd == pytest.approx(LAG * np.sqrt(step_variance / mu ** 3), rel=1e-4)
    assert rtd.deficit_levels > 4 * MIN_DEFICIT_LEVELS
    assert rtd.unresolved < 10 * DEFICIT_TOL
    assert rtd.drift_mean is None                 # nothing lost below: no check needed
    shallow = exact_rtd(np.array([[1.0]]), np.array([[up]]), np.array([[down]]), LAG,
                        deficit_levels=MIN_DEFICIT_LEVELS)
    assert shallow.mean < 0.9 * rtd.mean          # what 8 deficits alone gave


def test_a_chain_that_stays_shallow_keeps_the_first_depth():
    rtd = walk(0.4, 0.05).rtd()                   # (1/8)^9: nothing below 8 deficits
    assert rtd.deficit_levels == MIN_DEFICIT_LEVELS
    assert rtd.mean == pytest.approx(LAG / 0.35, rel=1e-6)


def test_first_order_exit_mean_of_a_deep_walk_is_its_generating_function():
    """X at the exit of dX/dt = k (1 - X), X = 0 at entry: 1 - E[z^T] with z = exp(-k lag),
    E[z^T] = G the root in (0, 1) of d z G^2 + (s z - 1) G + u z = 0 (first step of the
    walk: up and done, stay, or down and two first passages)."""
    up, down, k = 0.3, 0.2, 0.2
    stay = 1 - up - down
    z = np.exp(-k * LAG)
    g = ((1 - stay * z) - np.sqrt((1 - stay * z) ** 2 - 4 * up * down * z * z)) / (2 * down * z)
    kinetics = Kinetics((Property("x", FirstOrder(), {"rate": Constant(k)}),))
    answer = exact_kinetics(walk(up, down), kinetics)["x"]
    assert answer.exit_mean == pytest.approx(1 - g, rel=1e-6)
    shallow = exact_kinetics(walk(up, down), kinetics, deficit_levels=MIN_DEFICIT_LEVELS)
    assert abs(shallow["x"].exit_mean / (1 - g) - 1) > 1e-3   # what 8 deficits alone gave


def test_deeper_levels_from_the_losses_of_two_tries():
    assert deeper_levels([(8, 1e-9)]) == 8                       # lost little: done
    assert deeper_levels([(8, 1e-2)]) == 16                      # one try: double
    # lost 1e-2 at 8 and 1e-3 at 16: rho^8 = 0.1, a tenth of 1e-7 needs 40 more levels
    nxt = deeper_levels([(8, 1e-2), (16, 1e-3)])
    assert nxt in (16 + 40, 16 + 41)                              # ceil of 40 in floats
    assert deeper_levels([(8, 1e-2), (16, 2e-2)]) == 16          # no decay: laps run away
    assert deeper_levels([(8, 0.81153), (16, 0.81152)]) == 16      # nor a tenth of one
    assert deeper_levels([(8, 0.005), (16, 0.0049)]) > 16         # unwarned: go deeper
    assert deeper_levels([(4, 1e-2), (8, 1e-3)]) == 8 + 20        # rho^4 = 0.1
    assert deeper_levels([(64, 0.5)]) == 64                      # the cap
    # one try and its decay: where a tenth of 1e-7 would be lost, at most four times as
    # deep (the paper-scale 3 m/s mle model: 8 then 32, where at most twice gave 8, 16, 32)
    assert fp.MEASURED_DEPTH_FACTOR == 4
    assert deeper_levels([(8, 3e-7)], decay=0.18) == 8 + 2       # 3e-7 * 0.18^2 < 1e-8
    assert deeper_levels([(8, 1e-2)], decay=0.5) == 8 + 20       # 0.5^20 < 1e-6
    assert deeper_levels([(8, 1e-2)], decay=0.6) == 32           # 8 + 28 capped
    assert deeper_levels([(8, 1e-2)], decay=1.0) == 16           # no decay: double


def test_one_try_measures_the_decay_of_the_loss_and_the_depth_follows():
    """A walk's residences reach deficit -K before they end with probability
    (r - 1) / (r^(K+1) - 1), r = up / down (gambler's ruin): the decay the first try's
    block elimination measures is down / up, and the depth kept is where a
    tenth of DEFICIT_TOL would be lost by it (13 for 0.1 / 0.4; doubling gave 16), with
    the walk's Wald mean."""
    import scipy.sparse as sp

    from cfbmarkov.markov.entry_chain import entry_matrix
    from cfbmarkov.markov.first_passage import split_by_pass

    up, down = 0.4, 0.1
    model = walk(up, down)
    parts = split_by_pass(sp.csr_matrix(model.transition_matrix), model.up_fraction,
                          model.down_fraction)
    live = np.ones((MIN_DEFICIT_LEVELS + 1, 1), bool)
    _, h0, decay = entry_matrix(*parts, live, np.array([0]), with_falls=True, with_decay=True)
    assert decay == pytest.approx(down / up, rel=1e-4)
    r, depth = up / down, MIN_DEFICIT_LEVELS + 1        # below level 8: deficit -9 first
    assert h0[0] == pytest.approx((r - 1) / (r ** (depth + 1) - 1), rel=1e-9)  # ruin
    rtd = model.rtd()
    assert rtd.deficit_levels == MIN_DEFICIT_LEVELS + 5     # 0.25^14 < 1e-8 < 0.25^13
    assert rtd.unresolved < DEFICIT_TOL
    assert rtd.mean == pytest.approx(LAG / (up - down), rel=1e-7)


@pytest.mark.parametrize("states", [12, 150])
def test_the_threaded_propagation_gives_the_same_bits(monkeypatch, states):
    """The threaded kernel (destinations in blocks, fewer states than blocks and more)
    gives the serial kernel's bits."""
    import cfbmarkov.markov.first_passage as fp

    rng = np.random.default_rng(3)
    n, edge = states, max(3, states // 12)
    p = rng.random((n, n)) * (rng.random((n, n)) < min(0.4, 5 / n)) + np.eye(n)
    p /= p.sum(axis=1, keepdims=True)
    up = np.zeros((n, n))
    down = np.zeros((n, n))
    up[n - edge:, :edge] = 1.0          # the top rows pass up onto the bottom ones
    down[:edge, n - edge:] = 0.25       # and the bottom ones fall back often
    serial = fp.exact_rtd(p, up, down, LAG)
    monkeypatch.setattr(fp, "PARALLEL_LEVEL_WORK", 0)
    calls = []
    kernel = fp._first_passage_levels_parallel

    def counted(*args):
        calls.append(args[11].shape)          # the state [S, L]
        return kernel(*args)

    monkeypatch.setattr(fp, "_first_passage_levels_parallel", counted)
    threads = numba.get_num_threads()
    numba.set_num_threads(2)                  # the suite's workers run one thread
    try:
        threaded = fp.exact_rtd(p, up, down, LAG)
    finally:
        numba.set_num_threads(threads)
    assert calls and calls[0][0] == n         # the threaded kernel ran
    assert (n > fp.PARALLEL_CHUNKS) == (states == 150)
    assert serial.deficit_levels == threaded.deficit_levels
    assert serial.probability.size > 10
    assert np.array_equal(serial.probability, threaded.probability)


def test_a_walk_deeper_than_the_deficits_kept_says_so_with_its_drift_mean():
    """a few in a thousand residences fall below the 64 deficits kept: the RTD
    says so and gives Wald's mean beside; fit's summary warns with both numbers."""
    from cfbmarkov.markov.first_passage import MAX_DEFICIT_LEVELS
    from cfbmarkov.markov.model_summary import unresolved_warning

    model = walk(0.3, 0.29)
    rtd = model.rtd()
    assert rtd.deficit_levels == MAX_DEFICIT_LEVELS
    assert rtd.deficit_unresolved > 1e-3
    assert rtd.drift_mean == pytest.approx(LAG / 0.01, rel=1e-9)       # 10 s
    assert rtd.mean < 0.8 * rtd.drift_mean
    line = unresolved_warning(rtd)
    assert "64 laps" in line and "10 s" in line
    # react's exact answers lean as E(RT) does: said of residences followed too short, not
    # of particles that never leave
    from cfbmarkov.cli.kinetics import _chain_warnings

    said = _chain_warnings(model)
    assert said and "follow only the residences that stay within the lap deficits" in said[0]
    assert "never leave" not in said[0]


def test_the_drift_mean_is_the_exact_rtds_mean():
    """drift_rt_mean (one sparse LU) equals the exact RTD's E(RT): on the walk, and on a
    generated riser's chain in both directions (its net downflow counted too)."""
    from cfbmarkov import synthetic
    from cfbmarkov.markov.model_rtd import drift_rt_mean

    assert drift_rt_mean(walk(0.3, 0.2)) == pytest.approx(LAG / 0.1, rel=1e-12)
    assert walk(0.3, 0.2).rtd().mean == pytest.approx(LAG / 0.1, rel=2e-5)
    flow = synthetic.RiserFlow(columns=3, rows=8, rise_velocity=1.5, fall_velocity=-1.5,
                               vertical_spread=1.0, lateral_probability=0.05,
                               persistence=False)
    chain = synthetic.cell_chain(flow)
    assert drift_rt_mean(chain) == pytest.approx(chain.rtd().mean, rel=1e-6)
    falling = walk(0.2, 0.3)                      # laps go down: residences end at the bottom
    assert drift_rt_mean(falling, "down") == pytest.approx(falling.rtd(direction="down").mean,
                                                           rel=2e-5)
    assert drift_rt_mean(falling, "up") is None


def test_the_drift_mean_ignores_a_state_that_no_residence_reaches():
    """A walk beside a state never left and never entered (an unvisited state kept in place):
    two closed classes, the residences in one; the drift mean is still the RTD's."""
    from cfbmarkov.markov.model_rtd import drift_rt_mean

    p = np.eye(2)
    up = np.array([[0.3, 0.0], [0.0, 0.0]])
    down = np.array([[0.2, 0.0], [0.0, 0.0]])
    zeros = np.zeros((2, 2), np.int64)
    model = MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 2, 0.1, 1.0), LAG,
                        estimator="given", pass_fractions=(up, down))
    assert drift_rt_mean(model) == pytest.approx(LAG / 0.1, rel=1e-12)
    assert model.rtd().mean == pytest.approx(LAG / 0.1, rel=2e-5)


def test_the_loss_left_unfollowed_is_one_the_summaries_warn_of():
    from cfbmarkov.markov.first_passage import UNRESOLVED_WARNED
    from cfbmarkov.markov.model_summary import UNRESOLVED_LIMIT

    assert UNRESOLVED_WARNED == UNRESOLVED_LIMIT
