"""Stability limit, checkpoints, semi-implicit drag, input checks."""

import numpy as np
import pytest

from cfbmarkov.config import CaseConfig, GasConfig
from cfbmarkov.errors import InputError
from cfbmarkov.simulate.cfd import (
    GasGrid,
    GasSolver,
    GasState,
    PressureSolveError,
    gas_stability_limit,
)

GRID = GasGrid(nx=9, ny=95, width=0.09, height=0.95)


def test_stability_limit_numbers():
    gas = GasConfig()
    nu = gas.viscosity / gas.density
    dx = dy = 0.01
    dt_adv = 0.5 / (2.0 / dx + 9.0 / dy)
    dt_visc = 1 / (2 * nu * (1 / dx**2 + 1 / dy**2))
    expected = 1 / (1 / dt_adv + 1 / dt_visc)
    assert gas_stability_limit(GRID, gas, (2.0, 9.0)) == pytest.approx(expected, rel=1e-14)
    assert gas_stability_limit(GRID, gas, 0.0) == pytest.approx(dt_visc, rel=1e-14)
    # the paper's 5e-5 s is well inside the limit at riser speeds (4.5e-4 s at |u| = 1, |v| = 10 m/s)
    assert gas_stability_limit(GRID, gas, (1.0, 10.0)) == pytest.approx(0.5 / 1100, rel=1e-3)


def test_too_large_step_is_refused_with_numbers():
    solver = GasSolver(GRID, superficial_velocity=6.0, time_step=2e-3)
    eps = np.full(GRID.cell_shape, 0.9)
    state = solver.initial_state(eps)
    limit = solver.stability_limit(state)
    with pytest.raises(InputError) as info:
        solver.step(state, eps, np.zeros(GRID.u_shape), np.zeros(GRID.v_shape))
    msg = str(info.value)
    assert "0.002 s exceeds the stability limit" in msg
    assert f"{limit:.6g} s" in msg and "advective limit" in msg and "viscous limit" in msg
    assert f"{6.0 / 0.9:.6g} m/s" in msg


def test_checkpoint_continues_bit_identically():
    case = CaseConfig()
    solver = GasSolver.from_config(case)
    rng = np.random.default_rng(2)
    base = np.clip(0.85 + 0.1 * rng.standard_normal(GRID.cell_shape), 0.4, 0.99)
    eps = [base + 1e-3 * rng.standard_normal(GRID.cell_shape) for _ in range(21)]
    fv = [100 * rng.standard_normal(GRID.v_shape) for _ in range(21)]
    fu = np.zeros(GRID.u_shape)
    state = solver.initial_state(eps[0])
    for n in range(1, 11):
        state = solver.step(state, eps[n], fu, fv[n])
    saved = state.state_dict()
    for n in range(11, 21):
        state = solver.step(state, eps[n], fu, fv[n])
    other = GasSolver.from_config(case)
    resumed = GasState.from_state_dict(saved)
    for n in range(11, 21):
        resumed = other.step(resumed, eps[n], fu, fv[n])
    for name in ("u", "v", "p", "void_fraction"):
        assert np.array_equal(getattr(state, name), getattr(resumed, name)), name
    assert state.driving_pressure_gradient == resumed.driving_pressure_gradient
    assert (state.time, state.steps) == (resumed.time, resumed.steps) == (pytest.approx(1e-3), 20)
    with pytest.raises(InputError, match="lacks 'p'"):
        GasState.from_state_dict({k: w for k, w in saved.items() if k != "p"})


def test_step_does_not_modify_its_input_state():
    solver = GasSolver(GRID)
    eps = np.full(GRID.cell_shape, 0.9)
    state = solver.initial_state(eps)
    before = state.state_dict()
    solver.step(state, eps * 0.99 + 0.001, np.zeros(GRID.u_shape), np.ones(GRID.v_shape))
    for k, val in before.items():
        assert np.array_equal(val, getattr(state, k))


def test_semi_implicit_drag_is_stable_where_explicit_is_not():
    """A stiff linear friction f = K v (eps = 1): dt K / rho = 5, forward Euler would blow up."""
    grid = GasGrid(nx=9, ny=10, width=0.09, height=0.1)
    dt, rho, U = 5e-5, 1.205, 6.0
    K = 5 * rho / dt
    solver = GasSolver(grid, density=rho, superficial_velocity=U, gravity=0.0, time_step=dt)
    eps = np.ones(grid.cell_shape)
    ku = np.full(grid.u_shape, K)
    kv = np.full(grid.v_shape, K)
    state = solver.initial_state(eps)
    for _ in range(200):
        state = solver.step(state, eps, K * state.u, K * state.v, ku, kv)
    assert np.all(np.abs(state.v) < 2 * U)
    # steady: the driving gradient carries the friction, G ~ K U (walls add a little)
    assert state.driving_pressure_gradient == pytest.approx(K * U, rel=0.02)
    explicit = solver.initial_state(eps)
    with pytest.raises((InputError, PressureSolveError)):  # refused or diverged
        for _ in range(200):
            explicit = solver.step(explicit, eps, K * explicit.u, K * explicit.v)


def test_input_checks():
    solver = GasSolver(GRID)
    eps = np.full(GRID.cell_shape, 0.9)
    state = solver.initial_state(eps)
    z_u, z_v = np.zeros(GRID.u_shape), np.zeros(GRID.v_shape)
    with pytest.raises(InputError, match="shape"):
        solver.step(state, eps[:, :-1], z_u, z_v)
    bad = eps.copy()
    bad[4, 7] = 1.2
    with pytest.raises(InputError, match=r"cell \(4, 7\)"):
        solver.step(state, bad, z_u, z_v)
    with pytest.raises(InputError):
        solver.initial_state(np.zeros(GRID.cell_shape))
    with pytest.raises(InputError, match="both"):
        solver.step(state, eps, z_u, z_v, z_u)
    with pytest.raises(InputError):
        GasSolver(GRID, formulation="C")
    with pytest.raises(InputError):
        GasGrid(nx=1, ny=95, width=0.09, height=0.95)
