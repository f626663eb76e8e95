"""Exact answers of linear kinetics on small chains against hand-computed values, and the
Monte Carlo against them."""

import re

import numba as nb
import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.kinetics import Constant, Deactivation, FirstOrder, HeatExchange, Kinetics, Property
from cfbmarkov.markov.kinetics_exact import exact_kinetics, exit_moments
from cfbmarkov.markov.kinetics_mc import exit_values, run_properties
from cfbmarkov.markov.model import MarkovModel
from cfbmarkov.markov.open_flow import OpenFlow
from cfbmarkov.markov.states import CellGrid

LAG = 0.1


@nb.njit
def depleting(v, row, others):
    """dv/dt = -k while v > 0, else 0: a zero-order law with a kink at depletion."""
    return -row[0] if v > 0.0 else 0.0


@nb.njit
def first_order(v, row, others):
    """dv/dt = k (1 - v), k = row[0]: a custom law whose RK4 kernel compiles once per test
    process, shared by the tests that use it."""
    return row[0] * (1.0 - v)


def periodic_model(u=0.3, w=0.4):
    """Two states up a periodic riser: 0 (bottom) -> 1 with probability u a lag; 1 leaves
    through the top back to 0 with probability w (a pass up)."""
    p = np.array([[1 - u, u], [w, 1 - w]])
    up = np.array([[0.0, 0.0], [1.0, 0.0]])
    zeros = np.zeros((2, 2), np.int64)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 2, 0.1, 1.0), LAG,
                       estimator="given", pass_fractions=(up, np.zeros((2, 2))))


def open_model(r=0.25, inflow=2.0):
    """One state that particles leave with probability r a lag."""
    p = np.array([[1.0]])
    zeros = np.zeros((1, 1), np.int64)
    flow = OpenFlow(np.array([r]), np.array([1]), np.array([1]), inflow)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 1, 0.1, 1.0), LAG,
                       estimator="given", open_flow=flow)


def kinetics(rates, start="entry", law="first-order", temps=(0.0, 0.0), initial=None,
             wall=None):
    table = np.array([[0, i, k] for i, k in enumerate(rates)], dtype=float)
    from cfbmarkov.kinetics import ByCell
    if law == "heat-exchange":
        params = {"coefficient": ByCell(table),
                  "temperature": ByCell(np.array([[0, i, t] for i, t in enumerate(temps)],
                                                 dtype=float))}
        law_obj = HeatExchange(wall)
    else:
        params = {"rate": ByCell(table)}
        law_obj = FirstOrder() if law == "first-order" else Deactivation()
    return Kinetics((Property("v", law_obj, params, start, initial),))


def geometric(a, u):
    """E[a^n] (and helpers) for n >= 1 geometric with success probability u."""
    return a * u / (1 - a * (1 - u))


def test_affine_general_case_against_path_sums():
    # an independent summation over path lengths of the moments on a 2-state chain
    q = np.array([[0.2, 0.3], [0.1, 0.4]])
    r = 1 - q.sum(1)
    e = np.array([0.7, 0.3])
    a, b = np.array([0.9, 0.5]), np.array([0.1, 0.3])
    m = exit_moments(q, r, e, a, b)
    v0 = 0.2
    m0, m1, m2 = e.copy(), e * v0, e * v0 * v0
    ex = np.zeros(3)
    mass = np.zeros(2)
    for _ in range(200):
        mass += m1
        n1, n2 = a * m1 + b * m0, a * a * m2 + 2 * a * b * m1 + b * b * m0
        ex += [r @ m0, r @ n1, r @ n2]
        m0, m1, m2 = m0 @ q, n1 @ q, n2 @ q
    assert ex[0] == pytest.approx(1.0, abs=1e-14)
    assert m.exit_mean(v0) == pytest.approx(ex[1], abs=1e-12)
    assert m.exit_second(v0) == pytest.approx(ex[2], abs=1e-12)
    np.testing.assert_allclose(v0 * m.mass_per_start + m.mass_rest, mass, atol=1e-12)


@pytest.mark.parametrize("law", ["first-order", "deactivation"])
def test_open_riser_one_state(law):
    r, k = 0.25, 2.0
    a = np.exp(-k * LAG)
    ea = geometric(a, r)                    # E[a^n], n = lags to the exit
    ea2 = geometric(a * a, r)
    out = exact_kinetics(open_model(r), kinetics([k], law=law))["v"]
    mean, second = (1 - ea, 1 - 2 * ea + ea2) if law == "first-order" else (ea, ea2)
    assert out.exit_mean == pytest.approx(mean, abs=1e-12)
    assert out.exit_sd == pytest.approx(np.sqrt(second - mean ** 2), abs=1e-12)
    # the bed: a particle j lags after its entry (weight (1-r)^j) holds 1 - a^j (or a^j)
    bed = r / (1 - a * (1 - r))             # sum_j (1-r)^j r a^j
    assert out.bed_mean == pytest.approx(1 - bed if law == "first-order" else bed, abs=1e-12)


def test_open_riser_heat_exchange():
    r, h, t_gas, t0 = 0.25, 3.0, 800.0, 300.0
    a = np.exp(-h * LAG)
    out = exact_kinetics(open_model(r), kinetics([h], law="heat-exchange", temps=[t_gas],
                                                 initial=t0))["v"]
    ea, ea2 = geometric(a, r), geometric(a * a, r)
    mean = t_gas + (t0 - t_gas) * ea
    second = t_gas ** 2 + 2 * t_gas * (t0 - t_gas) * ea + (t0 - t_gas) ** 2 * ea2
    assert out.exit_mean == pytest.approx(mean, abs=1e-9)
    assert out.exit_sd == pytest.approx(np.sqrt(second - mean ** 2), rel=1e-10)


def test_carried_needs_a_periodic_riser_and_a_relaxation():
    with pytest.raises(InputError, match="needs a periodic riser"):
        exact_kinetics(open_model(), kinetics([1.0], start="carried"))
    with pytest.raises(InputError, match="no steady state"):
        exact_kinetics(periodic_model(), kinetics([0.0, 0.0], start="carried"))


def _periodic_hand(u, w, k0, k1, t0, t1, v0):
    """Closed forms for the 2-state periodic ladder: n0 lags in 0, then n1 in 1."""
    a0, a1 = np.exp(-k0 * LAG), np.exp(-k1 * LAG)
    e0, e1 = geometric(a0, u), geometric(a1, w)
    f0, f1 = geometric(a0 * a0, u), geometric(a1 * a1, w)
    # v1 = t0 + (v0 - t0) A0, v = t1 + (v1 - t1) A1 (A0, A1 independent)
    mean = t1 + (t0 + (v0 - t0) * e0 - t1) * e1
    x1 = t0 - t1                              # v1 - t1 = x1 + (v0 - t0) A0
    y = v0 - t0
    second = (t1 ** 2 + 2 * t1 * (x1 + y * e0) * e1
              + (x1 ** 2 + 2 * x1 * y * e0 + y * y * f0) * f1)
    return mean, second, (e0, e1)


@pytest.mark.parametrize("law", ["first-order", "deactivation", "heat-exchange"])
def test_periodic_two_states(law):
    u, w, k0, k1 = 0.3, 0.4, 1.5, 6.0
    if law == "first-order":
        t, v0, temps, initial = (1.0, 1.0), 0.0, (0, 0), None
    elif law == "deactivation":
        t, v0, temps, initial = (0.0, 0.0), 1.0, (0, 0), None
    else:
        t, v0, temps, initial = (700.0, 900.0), 300.0, (700.0, 900.0), 300.0
    mean, second, (e0, e1) = _periodic_hand(u, w, k0, k1, *t, v0)
    out = exact_kinetics(periodic_model(u, w), kinetics([k0, k1], law=law, temps=temps,
                                                        initial=initial))["v"]
    assert out.exit_mean == pytest.approx(mean, abs=1e-12 * max(1, abs(mean)))
    assert out.exit_sd == pytest.approx(np.sqrt(second - mean ** 2), abs=1e-10)
    # the bed per state: in 0, j lags after entry; in 1, j lags after arriving there
    a0, a1 = np.exp(-k0 * LAG), np.exp(-k1 * LAG)
    g0 = u / (1 - a0 * (1 - u))              # E[a0^j] over the lags j spent in 0
    g1 = w / (1 - a1 * (1 - w))
    bed0 = t[0] + (v0 - t[0]) * g0
    bed1 = t[1] + (t[0] + (v0 - t[0]) * e0 - t[1]) * g1
    np.testing.assert_allclose(out.bed_mean_by_state, [bed0, bed1], rtol=1e-12)
    pi = np.array([w, u]) / (u + w)
    assert out.bed_mean == pytest.approx(pi @ [bed0, bed1], rel=1e-12)


def test_periodic_carried_is_the_fixed_point():
    u, w, k0, k1 = 0.3, 0.4, 1.5, 6.0
    t = (700.0, 900.0)
    m1 = _periodic_hand(u, w, k0, k1, *t, 1.0)[0]
    m0 = _periodic_hand(u, w, k0, k1, *t, 0.0)[0]
    fixed = m0 / (1 - (m1 - m0))
    out = exact_kinetics(periodic_model(u, w), kinetics([k0, k1], law="heat-exchange",
                                                        temps=t, initial=300.0,
                                                        start="carried"))["v"]
    assert out.exit_mean == pytest.approx(fixed, rel=1e-12)
    assert out.entry_value == pytest.approx(fixed, rel=1e-12)


def test_after_passes_by_hand_and_towards_the_carried_steady_state():
    """A carried deactivation's steady state is 0 (nothing regenerates it); after N passes
    its mean is E[A]^N (hand: the residence's E[A] from the closed form), with the SD of
    a product of N independent residences' A, and heat exchange after many passes reaches
    the carried fixed point."""
    u, w, k0, k1 = 0.3, 0.4, 1.5, 6.0
    model = periodic_model(u, w)
    out = exact_kinetics(model, kinetics([k0, k1], law="deactivation", start="carried",
                                         initial=1.0))["v"]
    assert out.exit_mean == 0 and out.initial == 1.0
    mean1, second1, _ = _periodic_hand(u, w, k0, k1, 0.0, 0.0, 1.0)
    for n in (1, 3, 10):
        mean, sd = out.after_passes(n)
        assert mean == pytest.approx(mean1 ** n, rel=1e-12)
        assert sd == pytest.approx(np.sqrt(second1 ** n - mean1 ** (2 * n)), rel=1e-10)
    with pytest.raises(InputError, match="at least 1"):
        out.after_passes(0)
    heat = exact_kinetics(model, kinetics([k0, k1], law="heat-exchange", temps=(700.0, 900.0),
                                          initial=300.0, start="carried"))["v"]
    assert heat.after_passes(1)[0] == pytest.approx(
        _periodic_hand(u, w, k0, k1, 700.0, 900.0, 300.0)[0], rel=1e-12)
    assert heat.after_passes(2000)[0] == pytest.approx(heat.exit_mean, rel=1e-12)
    assert heat.to_dict(passes=(1, 5))["after_passes"]["5"]["mean"] == heat.after_passes(5)[0]


@pytest.mark.parametrize("rate", [1e-10, 1e-12, 3e-13, 1e-14, 1e-200])
def test_a_carried_property_at_tiny_rates_keeps_every_digit(rate):
    """1 - E[A] is computed from 1 - a = -expm1(-k lag), not by subtraction: a carried
    conversion at a tiny rate is its fixed point 1 exactly enough (never above 1), a carried
    temperature the time-weighted mean of the targets, with no spurious SD; a rate of 0 has
    no steady state."""
    model = periodic_model(0.3, 0.4)
    x = exact_kinetics(model, kinetics([rate, 2 * rate], start="carried"))["v"]
    assert x.exit_mean == pytest.approx(1.0, abs=1e-12) and x.exit_mean <= 1.0 + 1e-15
    assert x.exit_sd == 0.0
    heat = exact_kinetics(model, kinetics([rate, rate], law="heat-exchange",
                                          temps=(700.0, 900.0), initial=300.0,
                                          start="carried"))["v"]
    # a uniform vanishing rate: each state's target weighted by the lags spent there
    time_weighted = (700.0 / 0.3 + 900.0 / 0.4) / (1 / 0.3 + 1 / 0.4)
    assert heat.exit_mean == pytest.approx(time_weighted, rel=1e-9)
    assert heat.exit_sd < 1e-3


def test_wall_temperature_replaces_the_wall_cells():
    space = CellGrid(3, 1, 0.09, 1.0)
    k = Kinetics((Property("T", HeatExchange(500.0), {"coefficient": Constant(1.0),
                                                       "temperature": Constant(800.0)},
                           initial=300.0),))
    np.testing.assert_array_equal(k.per_state(space).target[0], [500.0, 800.0, 500.0])


def test_a_grid_of_wall_cells_only_is_warned_of():
    """wall_temperature where every cell touches a wall (two depth columns of a 3D grid,
    or two columns): a note says temperature is used nowhere; with a middle depth column
    or without wall_temperature, none."""
    k = Kinetics((Property("T", HeatExchange(500.0), {"coefficient": Constant(1.0),
                                                       "temperature": Constant(800.0)},
                           initial=300.0),))
    flat = Kinetics((Property("T", HeatExchange(), {"coefficient": Constant(1.0),
                                                    "temperature": Constant(800.0)},
                              initial=300.0),))
    two = CellGrid(4, 16, 0.09, 0.95, depth_columns=2, depth=0.02)
    notes = k.grid_notes(two)
    assert len(notes) == 1 and "its 2 depth columns put every cell at the front or back" \
        in notes[0] and "temperature nowhere" in notes[0]
    assert "its 2 columns put every cell at a side wall" in k.grid_notes(CellGrid(2, 8))[0]
    assert k.grid_notes(CellGrid(4, 16, 0.09, 0.95, depth_columns=3, depth=0.03)) == ()
    assert flat.grid_notes(two) == ()
    # one depth column spans front to back: every cell at those walls, as the wall distance
    # measures it (the two had disagreed: a 6x1x38 grid's core cells were no wall cells
    # but 0.015 m from a wall)
    from cfbmarkov.analysis.cell_fields import wall_distance
    from cfbmarkov.kinetics import wall_cells

    one = CellGrid(6, 38, 0.09, 0.95, depth_columns=1, depth=0.03)
    assert wall_cells(one).all() and (wall_distance(one) <= 0.015 + 1e-15).all()
    assert "its 1 depth column puts every cell at the front or back wall" in k.grid_notes(one)[0]
    plane = CellGrid(6, 38, 0.09, 0.95)
    assert wall_cells(plane).sum() == 2 * 38 and wall_distance(plane).max() > 0.03


def _draw(p, n, seed):
    rng = np.random.default_rng(seed)
    return rng.choice(p.size, size=n, p=p / p.sum()).astype(np.int32)


@pytest.mark.parametrize("law", ["first-order", "heat-exchange"])
def test_monte_carlo_agrees_periodic(law):
    model = periodic_model()
    temps, initial = ((700.0, 900.0), 300.0) if law == "heat-exchange" else ((0, 0), None)
    kin = kinetics([1.5, 6.0], law=law, temps=temps, initial=initial)
    exact = exact_kinetics(model, kin)["v"]
    states, laps = model.monte_carlo(_draw(model.stationary_distribution, 4000, 1), 400,
                                     seed=3)
    sk = kin.per_state(model.state_space)
    values = run_properties(sk, LAG, states, laps, periodic=True)
    a, b = sk.over(LAG)
    exits, _, entered = exit_values(states, laps, values[0], a[0], b[0], periodic=True)
    exits = exits[entered < 300]        # residences that have ended (P(RT > 100 lags) ~ 1e-12)
    se = exits.std(ddof=1) / np.sqrt(exits.size)
    assert exits.size > 10000
    assert abs(exits.mean() - exact.exit_mean) < 3 * se
    assert exits.std(ddof=1) == pytest.approx(exact.exit_sd, rel=0.03)


def test_monte_carlo_agrees_open():
    model = open_model(0.25, inflow=50.0)
    kin = kinetics([2.0])
    exact = exact_kinetics(model, kin)["v"]
    states, laps = model.monte_carlo(np.zeros(100, np.int32), 600, seed=5)
    sk = kin.per_state(model.state_space)
    values = run_properties(sk, LAG, states, laps, periodic=False)
    a, b = sk.over(LAG)
    exits, _, entered = exit_values(states, laps, values[0], a[0], b[0], periodic=False)
    exits = exits[(entered > 0) & (entered < 500)]
    se = exits.std(ddof=1) / np.sqrt(exits.size)
    assert exits.size > 20000
    assert abs(exits.mean() - exact.exit_mean) < 3 * se
    # present particles: NaN exactly where absent
    assert np.array_equal(np.isnan(values[0]), states < 0)


def test_monte_carlo_values_depend_on_each_particle_alone():
    model = periodic_model()
    sk = kinetics([1.5, 6.0]).per_state(model.state_space)
    states, laps = model.monte_carlo(np.array([0, 1, 0, 1] * 50, np.int32), 50, seed=2)
    whole = run_properties(sk, LAG, states, laps, periodic=True)
    part = run_properties(sk, LAG, states[:, 7:9], laps[:, 7:9], periodic=True)
    np.testing.assert_array_equal(whole[:, :, 7:9], part)


def test_custom_law_integrates_like_the_linear_one():
    from cfbmarkov.kinetics import Custom

    model = periodic_model()
    states, laps = model.monte_carlo(np.array([0, 1] * 20, np.int32), 60, seed=4)
    linear = kinetics([1.5, 6.0]).per_state(model.state_space)
    from cfbmarkov.kinetics import ByCell
    table = np.array([[0, 0, 1.5], [0, 1, 6.0]])
    custom = Kinetics((Property("v", Custom(first_order, ("rate",), substeps=8),
                                {"rate": ByCell(table)}),)).per_state(model.state_space)
    exact = run_properties(linear, LAG, states, laps, periodic=True)
    rk4 = run_properties(custom, LAG, states, laps, periodic=True)
    np.testing.assert_allclose(rk4, exact, atol=1e-6)   # RK4: error ~ (k lag / 8)^4
    with pytest.raises(InputError, match="no exact answer"):
        exact_kinetics(model, custom)


def test_too_few_rk4_substeps_are_warned_while_the_values_are_finite():
    """A custom first-order law with k lag / substeps beyond RK4's stability limit (about
    2.8) grows its values by orders of magnitude each lag while they stay finite: warned
    from the step-doubling check; with enough sub-steps, not warned, and the values equal
    the exact linear law's."""
    import warnings

    from cfbmarkov.errors import CfbmarkovWarning
    from cfbmarkov.kinetics import Constant, Custom

    model = periodic_model()
    states, laps = model.monte_carlo(np.array([0, 1] * 20, np.int32), 12, seed=4)
    rate = 4.0 * 8 / LAG          # k lag / substeps = 4 with 8 sub-steps
    few = Kinetics((Property("v", Custom(first_order, ("rate",), substeps=8),
                             {"rate": Constant(rate)}),)).per_state(model.state_space)
    with pytest.warns(CfbmarkovWarning, match=r"with 8 sub-steps and with 16 differ by up "
                                              r"to [0-9.e+]+ (times its largest value|% of "
                                              r"its largest value) .* the sub-steps are too "
                                              r"few") as said:
        values = run_properties(few, LAG, states, laps, periodic=True)
    checked = int(re.search(r"on (\d+) particle-lags", str(said[0].message)).group(1))
    assert 0 < checked <= 4096
    assert np.isfinite(values).all() and np.abs(values).max() > 10.0     # finite, wrong
    enough = Kinetics((Property("v", Custom(first_order, ("rate",), substeps=400),
                                {"rate": Constant(rate)}),)).per_state(model.state_space)
    exact = kinetics([rate, rate]).per_state(model.state_space)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CfbmarkovWarning)
        rk4 = run_properties(enough, LAG, states, laps, periodic=True)
    np.testing.assert_allclose(rk4, run_properties(exact, LAG, states, laps, periodic=True),
                               atol=1e-6)
    # a rate with a kink (zero order until depleted) and enough sub-steps: no false alarm
    # where the value nears 0
    kinked = Kinetics((Property("v", Custom(depleting, ("rate",), substeps=64),
                                {"rate": Constant(3.0)}, start="carried", initial=1.0),)
                      ).per_state(model.state_space)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CfbmarkovWarning)
        run_properties(kinked, LAG, states, laps, periodic=True)


def test_a_coupled_custom_law_declared_too_early_is_refused_and_divergence_warned():
    """An Arrhenius-like rate of a custom temperature declared after it reads NaN: refused
    before the run, naming the property and what it can read (not a bare SystemError from
    the compiled run); declared after it, it runs. A rate growing with its value that blows
    up is stored with a warning."""
    import numba as nb

    from cfbmarkov.errors import CfbmarkovWarning
    from cfbmarkov.kinetics import Custom

    @nb.njit
    def heating(v, row, others):
        return row[0] * (900.0 - v)

    @nb.njit
    def arrhenius(v, row, others):
        return row[0] * np.exp(-1000.0 / others[1]) * (1.0 - v)   # others[1]: temperature

    @nb.njit
    def runaway(v, row, others):
        return row[0] * v * v

    model = periodic_model()
    states, laps = model.monte_carlo(np.array([0, 1] * 20, np.int32), 60, seed=4)
    one = {"k": Constant(2.0)}
    temperature = Property("T", Custom(heating, ("k",), initial=300.0), one)
    conversion = Property("X", Custom(arrhenius, ("k",)), one)
    early = Kinetics((conversion, temperature)).per_state(model.state_space)
    with pytest.raises(InputError, match="property X: its rate function gives nan at its start "
                                         "value 0 in state 0, with the properties it can read "
                                         r"filled \(none; the others NaN\)"):
        run_properties(early, LAG, states, laps, periodic=True)
    ordered = Kinetics((Property("X0", FirstOrder(), {"rate": Constant(1.0)}), temperature,
                        conversion)).per_state(model.state_space)
    values = run_properties(ordered, LAG, states, laps, periodic=True)
    assert np.isfinite(values[2]).all() and values[2].max() > 0
    blowing = Kinetics((Property("Y", Custom(runaway, ("k",), initial=1.0),
                                 {"k": Constant(50.0)}),)).per_state(model.state_space)
    with pytest.warns(CfbmarkovWarning, match="property Y is not finite for"):
        run_properties(blowing, LAG, states, laps, periodic=True)


def test_windowed_exit_mean_by_hand_open_riser():
    from cfbmarkov.markov.kinetics_exact import windowed_exit_means

    r, k, length = 0.25, 1.7, 1.5          # one state; a window of 15 lags
    steps = int(round(length / LAG))
    n = np.arange(1, steps)
    p = r * (1 - r) ** (n - 1)
    w = steps - n
    by_hand = np.sum(w * p * (1 - np.exp(-k * n * LAG))) / np.sum(w * p)
    got = windowed_exit_means(open_model(r), kinetics([k]), length)["v"]
    assert got == pytest.approx(by_hand, abs=1e-12)
    # a long window sees every residence nearly alike (bias of order E(n) / M)
    assert windowed_exit_means(open_model(r), kinetics([k]), 400.0)["v"] == pytest.approx(
        exact_kinetics(open_model(r), kinetics([k]))["v"].exit_mean, rel=2e-3)
    # carried properties are left out; a window shorter than a lag is refused
    assert windowed_exit_means(periodic_model(), kinetics([1.0, 1.0], start="carried"),
                               1.0) == {}
    with pytest.raises(InputError, match="shorter than the lag"):
        windowed_exit_means(open_model(r), kinetics([k]), 0.01)


def test_down_residences_mirror_up_ones():
    from cfbmarkov.markov.kinetics_exact import windowed_exit_means

    up_model = periodic_model()
    p = up_model.transition_matrix
    passes = np.array([[0.0, 0.0], [1.0, 0.0]])
    zeros = np.zeros((2, 2), np.int64)
    # the same chain whose 1 -> 0 move passes down through the bottom: a net downflow
    down_model = MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 2, 0.1, 1.0), LAG,
                             estimator="given", pass_fractions=(np.zeros((2, 2)), passes))
    kin = kinetics([0.7, 2.0])
    up = exact_kinetics(up_model, kin)["v"]
    down = exact_kinetics(down_model, kin, direction="down")["v"]
    assert down.exit_mean == pytest.approx(up.exit_mean, rel=1e-12)
    assert down.exit_sd == pytest.approx(up.exit_sd, rel=1e-10)
    assert windowed_exit_means(down_model, kin, 2.0, direction="down")["v"] == pytest.approx(
        windowed_exit_means(up_model, kin, 2.0)["v"], rel=1e-12)
    with pytest.raises(InputError, match="up or down"):
        exact_kinetics(up_model, kin, direction="sideways")


def test_monte_carlo_of_a_net_downflow_resets_at_the_passes_down():
    """A model of a net downflow counts residences from one pass down through the bottom to
    the next: its Monte Carlo resets an entry property there, so that its exits agree with
    the exact answer; reset at the passes up (which it never makes) they do not."""
    p = periodic_model().transition_matrix
    passes = np.array([[0.0, 0.0], [1.0, 0.0]])
    zeros = np.zeros((2, 2), np.int64)
    model = MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 2, 0.1, 1.0), LAG,
                        estimator="given", pass_fractions=(np.zeros((2, 2)), passes),
                        flow_direction="down")
    kin = kinetics([1.5, 6.0])
    exact = exact_kinetics(model, kin)["v"]
    states, laps = model.monte_carlo(_draw(model.stationary_distribution, 4000, 1), 400,
                                     seed=3)
    assert laps.min() < -50 and laps.max() <= 0
    sk = kin.per_state(model.state_space)
    a, b = sk.over(LAG)
    values = run_properties(sk, LAG, states, laps, periodic=True, direction=model.flow_direction)
    exits, _, entered = exit_values(states, -laps, values[0], a[0], b[0], periodic=True)
    exits = exits[entered < 300]
    se = exits.std(ddof=1) / np.sqrt(exits.size)
    assert exits.size > 10000
    assert abs(exits.mean() - exact.exit_mean) < 3 * se
    upward = run_properties(sk, LAG, states, laps, periodic=True, direction="up")
    never_reset, _, _ = exit_values(states, -laps, upward[0], a[0], b[0], periodic=True)
    assert never_reset.mean() > exact.exit_mean + 0.1
    with pytest.raises(ValueError, match="up or down"):
        run_properties(sk, LAG, states, laps, periodic=True, direction="sideways")


def test_an_exit_mean_beyond_its_range_by_round_off_is_put_on_it():
    """A conversion's exit mean 1 + 7e-16 (a carried conversion's round-off) is 1, one
    -1e-17 is 0; a value beyond the range by more than round-off is left as it is (a fault
    to see, not to hide), and a law without a range leaves every value."""
    from cfbmarkov.kinetics.laws import FirstOrder, HeatExchange
    from cfbmarkov.markov.kinetics_exact import _in_range

    assert _in_range(1.0000000000000007, FirstOrder()) == 1.0
    assert _in_range(-1e-17, FirstOrder()) == 0.0
    assert _in_range(1.01, FirstOrder()) == 1.01 and _in_range(0.5, FirstOrder()) == 0.5
    assert _in_range(-5.0, HeatExchange()) == -5.0


def conveyor_model(eps, columns=3, rows=5):
    """Particles rise one row a lag in their column and pass up through the top after
    ``rows`` lags, landing in the same column with probability 1 - eps (as a pass up on a
    riser's cells mostly does), else in any column alike."""
    n = columns * rows
    p = np.zeros((n, n))
    up = np.zeros((n, n))
    landing = (1 - eps) * np.eye(columns) + eps / columns
    for c in range(columns):
        for i in range(rows - 1):
            p[i * columns + c, (i + 1) * columns + c] = 1.0
        top = (rows - 1) * columns + c
        p[top, :columns] = landing[c]
        up[top, :columns] = 1.0
    zeros = np.zeros((n, n), np.int64)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(columns, rows, 0.3, 1.0), LAG,
                       estimator="given", pass_fractions=(up, np.zeros((n, n)))), landing


@pytest.mark.parametrize("eps", [1.0, 0.3, 0.05])
def test_a_carried_value_follows_where_each_pass_lands(eps):
    """Heat exchange carried across passes on a conveyor whose passes mostly land in the
    column they left (wall columns fast, 5 1/s toward 600 K; the core slow, 0.5 1/s toward
    800 K): the next residence starts where the last one landed, so the passes are not
    independent. Hand: from column c a residence maps v to A_c v + B_c (A_c = exp(-5 h_c
    lag), B_c = T_c (1 - A_c)), and the value mass u entering each column solves
    u = L^T (A u + B nu), nu uniform; the mean is sum u, the second moment likewise, after
    N passes the same recursion from v0 nu, the bed's value per cell T_c + (u_c / nu_c - T_c)
    exp(-h_c i lag) in row i. Independent passes gave one answer for every eps (the eps = 1
    one: 621.5 K against 659.9 K at eps = 0.05)."""
    from cfbmarkov.kinetics import ByCell

    model, landing = conveyor_model(eps)
    h, target = np.array([5.0, 0.5, 5.0]), np.array([600.0, 800.0, 600.0])
    cells = [(c, i) for i in range(5) for c in range(3)]
    coefficient = ByCell(np.array([[c, i, h[c]] for c, i in cells]))
    temperature = ByCell(np.array([[c, i, target[c]] for c, i in cells]))
    kin = Kinetics((Property("T", HeatExchange(None), {"coefficient": coefficient,
                                                        "temperature": temperature},
                             "carried", 300.0),))
    out = exact_kinetics(model, kin)["T"]
    a_c = np.exp(-5 * h * LAG)
    b_c = target * (1 - a_c)
    nu = np.full(3, 1 / 3)
    u = np.linalg.solve(np.eye(3) - landing.T @ np.diag(a_c), landing.T @ (b_c * nu))
    s = np.linalg.solve(np.eye(3) - landing.T @ np.diag(a_c ** 2),
                        landing.T @ (2 * a_c * b_c * u + b_c ** 2 * nu))
    assert out.exit_mean == pytest.approx(u.sum(), rel=1e-12)
    assert out.exit_sd == pytest.approx(np.sqrt(s.sum() - u.sum() ** 2), rel=1e-9)
    entering = u / nu
    for c, i in cells:
        expected = target[c] + (entering[c] - target[c]) * np.exp(-h[c] * i * LAG)
        assert out.bed_mean_by_cell[i * 3 + c] == pytest.approx(expected, rel=1e-12)
    v = 300.0 * nu
    for n in range(1, 6):
        v = landing.T @ (a_c * v + b_c * nu)
        assert out.after_passes(n)[0] == pytest.approx(v.sum(), rel=1e-12)
    if eps < 1:       # what independent passes give: the eps = 1 answer
        independent = exact_kinetics(conveyor_model(1.0)[0], kin)["T"].exit_mean
        assert abs(out.exit_mean - independent) > 5.0


@pytest.mark.parametrize("index, named", [((0.7, 1), "col 0.7"), ((1, -0.5), "row -0.5"),
                                          ((np.nan, 1), "col nan")])
def test_a_cell_numbered_by_a_fraction_is_refused_not_truncated(index, named):
    """A Python table's cell indices cast to integers moved col 0.7 to column 0 and row
    -0.5 to row 0 without a word (the CSV reader refuses them): refused in one line."""
    from cfbmarkov.kinetics import ByCell

    table = np.array([[c, r, 1.0] for r in range(2) for c in range(2)], dtype=float)
    table[0, :2] = index
    with pytest.raises(InputError, match=rf"row 0 gives {named}: cells are numbered by whole"):
        ByCell(table, "rates", "rate").per_cell(CellGrid(2, 2, 0.1, 1.0))


def _trap_model(f=0.01):
    """Two states; a pass up from state 0 lands back in 0, but 1 % of state 0's moves go
    to state 1, which is never left (a trap that residences land in)."""
    p = np.array([[0.5 + 0.5 * (1 - f), 0.5 * f], [0.0, 1.0]])
    up = np.array([[0.5 * (1 - f) / (0.5 + 0.5 * (1 - f)), 1.0], [0.0, 0.0]])
    zeros = np.zeros((2, 2), np.int64)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(2, 1, 0.1, 1.0), LAG,
                       estimator="given", pass_fractions=(up, np.zeros((2, 2))))


def test_a_carried_value_of_particles_that_keep_circulating_ignores_those_trapped():
    """Particles that land in a trap never come back: the carried steady state is that of
    the particles that keep circulating (every cell relaxes to 600 K: 600 K, no spread;
    the trapped mass dropped at every pass gave 606 K, above every target), and a carried
    activity after N passes is E[A]^N where the landing does not depend on the path."""
    from cfbmarkov.kinetics import ByCell

    model = _trap_model()
    cells = [[0, 0], [1, 0]]
    heat = Kinetics((Property("T", HeatExchange(None), {
        "coefficient": ByCell(np.array([c + [5.0] for c in cells])),
        "temperature": ByCell(np.array([c + [600.0] for c in cells]))}, "carried", 300.0),))
    out = exact_kinetics(model, heat)["T"]
    assert out.exit_mean == pytest.approx(600.0, rel=1e-12) and out.exit_sd == 0.0
    activity = Kinetics((Property("a", Deactivation(), {
        "rate": ByCell(np.array([c + [0.1] for c in cells]))}, "carried", 1.0),))
    a = exact_kinetics(model, activity)["a"]
    one = a.after_passes(1)[0]
    for n in (10, 100):
        assert a.after_passes(n)[0] == pytest.approx(one ** n, rel=1e-10)


def test_a_carried_value_without_relaxation_in_a_closed_set_of_entries_is_refused():
    """Two columns whose passes land back in their own column, the value relaxing in one
    only: no steady state for the other column's particles. Refused in one line (the
    solve raised a singular-matrix traceback); after a million passes the relaxing case
    is its steady state, at once."""
    from cfbmarkov.kinetics import ByCell

    model, _ = conveyor_model(0.0, columns=2, rows=3)
    cells = [(c, i) for i in range(3) for c in range(2)]
    for rates, refused in (((0.0, 2.0), True), ((1.0, 2.0), False)):
        kin = Kinetics((Property("T", HeatExchange(None), {
            "coefficient": ByCell(np.array([[c, i, rates[c]] for c, i in cells])),
            "temperature": ByCell(np.array([[c, i, 600.0 + 100 * c] for c, i in cells]))},
            "carried", 300.0),))
        if refused:
            with pytest.raises(InputError, match="land back among themselves"):
                exact_kinetics(model, kin)
        else:
            out = exact_kinetics(model, kin)["T"]
            assert out.after_passes(10 ** 6)[0] == pytest.approx(out.exit_mean, rel=1e-12)


def test_windowed_exit_means_count_records_from_the_first_frame_read():
    """Walkers of a chain whose particles often fall a lap before they climb back, the
    records of their lap counters counted from the first frame (as the reference's paths
    are), exits inside a window after a history: their mean 1 - exp(-k t) equals
    windowed_exit_means with that history and the walkers' start within 3 standard errors,
    and without a history equals the RTD as the window sees it, averaged, to round-off."""
    import sys
    from pathlib import Path

    from cfbmarkov.markov.kinetics_exact import windowed_exit_means
    from cfbmarkov.observed.residence import residence_times_from_laps

    sys.path.insert(0, str(Path(__file__).parents[1] / "markov"))
    from test_model import _walk, two_column_model

    model = two_column_model()
    rate, window, history = 3.0, 0.6, 0.3
    kinetics = Kinetics((Property("X", FirstOrder(), {"rate": Constant(rate)}),))
    pi = np.asarray(model.stationary_distribution)
    seen = model.rtd(window=window, occupancy=pi)
    t = seen.lag * np.arange(1, seen.probability.size + 1)
    assert windowed_exit_means(model, kinetics, window, occupancy=pi)["X"] == pytest.approx(
        float(seen.probability @ -np.expm1(-rate * t)), rel=1e-12)
    rng = np.random.default_rng(11)
    _, laps = _walk(model, rng.choice(pi.size, size=40_000, p=pi), 90, rng)
    times = 0.01 * np.arange(91)

    def converted(frames):
        samples = residence_times_from_laps(times[:frames], laps[:frames])
        return -np.expm1(-rate * samples)

    every, early = converted(91), converted(31)        # exits by frame 30 left out
    total = every.sum() - early.sum()
    count = every.size - early.size
    mean = total / count
    sd = np.sqrt((np.square(every).sum() - np.square(early).sum()) / count - mean ** 2)
    expected = windowed_exit_means(model, kinetics, window, history=history, occupancy=pi)["X"]
    assert abs(mean - expected) < 3 * sd / np.sqrt(count), (mean, expected)


@pytest.mark.parametrize("start", ["entry", "carried"])
def test_the_exit_sd_keeps_its_digits_far_from_zero(start):
    """Values far from zero against their spread (a heat exchange 300 -> 700-900 shifted
    by up to 1e12), where E[v^2] - E[v]^2 keeps few digits: a shift moves the mean with it
    and leaves the exit SD and the SD after N passes as they are; a carried value at a
    uniform target keeps an SD of exactly 0."""
    u, w, k0, k1 = 0.3, 0.4, 1.5, 6.0
    model = periodic_model(u, w)

    def answer(offset, temps=(700.0, 900.0)):
        return exact_kinetics(model, kinetics(
            [k0, k1], law="heat-exchange", temps=tuple(t + offset for t in temps),
            initial=300.0 + offset, start=start))["v"]

    plain = answer(0.0)
    assert plain.exit_sd > 10.0
    for offset in (1e7, 1e8, 1e12):
        shifted = answer(offset)
        assert shifted.exit_mean - offset == pytest.approx(plain.exit_mean,
                                                           abs=1e-15 * offset * 8)
        assert shifted.exit_sd == pytest.approx(plain.exit_sd, rel=1e-18 * offset + 1e-10)
        if start == "carried":      # and after a few passes from the first entry
            for n in (1, 3):
                mean, sd = shifted.after_passes(n)
                assert mean - offset == pytest.approx(plain.after_passes(n)[0],
                                                      abs=1e-15 * offset * 8)
                assert sd == pytest.approx(plain.after_passes(n)[1],
                                           rel=1e-18 * offset + 1e-10)
    if start == "carried":
        assert answer(1e8, (800.0, 800.0)).exit_sd == 0.0
        assert answer(0.0, (800.0, 800.0)).exit_sd == 0.0


@pytest.mark.filterwarnings("ignore::cfbmarkov.errors.UnresolvedWarning")    # the trapped
def test_a_carried_value_where_survival_depends_on_the_entry_state():
    """Two columns whose passes keep their column but for a share eps; their tops leak
    into a trap, column 0's more, so its residences end less often than column 1's. The
    carried value after N passes is that of the particles that complete N passes (not each
    entry state's moments conditioned on leaving, which puts survivors of its own column
    in place of the trapped), and the steady state that of the particles still
    circulating. By hand: from column c, E[a^n; pass] = (a u / (1 - a (1 - u)))
    (a w / (1 - a (1 - w - f_c))), the pass landing in the other column with
    probability eps."""
    from cfbmarkov.kinetics import ByCell

    u, w, f0, f1, eps, lag = 0.3, 0.4, 0.15, 0.05, 0.05, LAG
    k, target = np.array([5.0, 0.5]), np.array([600.0, 800.0])
    p = np.zeros((5, 5))
    p[0, :2] = 1 - u, u
    p[1, [0, 1, 2, 4]] = w * (1 - eps), 1 - w - f0, w * eps, f0
    p[2, 2:4] = 1 - u, u
    p[3, [0, 2, 3, 4]] = w * eps, w * (1 - eps), 1 - w - f1, f1
    p[4, 4] = 1.0
    up = np.zeros((5, 5))
    up[1, [0, 2]] = up[3, [0, 2]] = 1.0
    zeros = np.zeros((5, 5), np.int64)
    model = MarkovModel(p, zeros, zeros, zeros, CellGrid(5, 1, 0.5, 1.0), lag,
                        estimator="given", pass_fractions=(up, np.zeros((5, 5))))
    column = [0, 0, 1, 1, 0]
    heat = Kinetics((Property("T", HeatExchange(None), {
        "coefficient": ByCell(np.array([[i, 0, k[c]] for i, c in enumerate(column)])),
        "temperature": ByCell(np.array([[i, 0, target[c]] for i, c in enumerate(column)]))},
        "carried", 300.0),))
    out = exact_kinetics(model, heat)["T"]
    nu = out.moments.entry                          # the two entry states' first entries
    assert nu.min() > 0.1
    a = np.exp(-k * lag)
    f = np.array([f0, f1])
    g = (a * u / (1 - a * (1 - u))) * (a * w / (1 - a * (1 - w - f)))
    survive = w / (w + f)
    land = np.array([[1 - eps, eps], [eps, 1 - eps]])
    mass, value = nu.copy(), 300.0 * nu
    for n in range(1, 2001):
        mass, value = ((survive * mass) @ land,
                       ((target * survive * mass) + g * (value - target * mass)) @ land)
        if n in (1, 2, 5, 60):
            assert out.after_passes(n)[0] == pytest.approx(value.sum() / mass.sum(),
                                                           rel=1e-12), n
    assert out.exit_mean == pytest.approx(value.sum() / mass.sum(), rel=1e-10)
    # many passes: the surviving mass (0.73 and 0.89 a pass in the columns) underflows
    # after a few thousand; the ratio goes on to the steady state
    for n in (5000, 1_000_000):
        assert out.after_passes(n)[0] == pytest.approx(out.exit_mean, rel=1e-10)
    # one pass is the residence of a property reset at entry, with the same first entries
    once = exact_kinetics(model, Kinetics((Property("T", HeatExchange(None), dict(
        heat.properties[0].parameters), "entry", 300.0),)))["T"]
    assert out.after_passes(1)[0] == pytest.approx(once.exit_mean, rel=1e-12)


def test_properties_in_pieces_equal_one_piece(monkeypatch):
    """run_properties goes over a long run in pieces (a Ctrl-C between them): the linear
    and the custom laws' values, with resets at passes and a carried property, are the same
    bits in pieces of 3 frames as in one, and the progress reaches its total."""
    from cfbmarkov.kinetics import ByCell, Custom
    from cfbmarkov.markov import montecarlo

    model = periodic_model()
    states, laps = model.monte_carlo(np.array([0, 1] * 30, np.int32), 40, seed=6)
    table = np.array([[0, 0, 1.5], [0, 1, 6.0]])
    props = (Property("v", FirstOrder(), {"rate": ByCell(table)}),
             Property("w", FirstOrder(), {"rate": Constant(0.7)}, start="carried"),
             Property("c", Custom(first_order, ("rate",), substeps=4), {"rate": ByCell(table)}))
    sk = Kinetics(props).per_state(model.state_space)
    whole = run_properties(sk, LAG, states, laps, periodic=True)
    shown = []
    monkeypatch.setattr(montecarlo, "PIECE_PARTICLE_STEPS", 3 * 60 * 2)    # linear: 3 frames
    pieces = run_properties(sk, LAG, states, laps, periodic=True,
                            progress=lambda done, total: shown.append((done, total)))
    np.testing.assert_array_equal(whole, pieces)
    assert shown[-1] == (80, 80) and len(shown) > 20                 # two passes of 40 lags
    assert all(b[0] >= a[0] for a, b in zip(shown, shown[1:]))
    assert np.any(laps[-1] > laps[0]) and not np.allclose(whole[0], whole[1], equal_nan=True)
