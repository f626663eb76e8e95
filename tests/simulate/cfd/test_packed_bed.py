"""Packed bed (eps = 0.4, particles fixed) below minimum fluidization: Ergun's pressure drop.

The bed fills cell rows 20..59 of the paper's 9 x 95 grid (L = 0.40 m), eps = 1 elsewhere,
U = 0.3 m/s (Ergun's Umf at eps = 0.4 is 0.58 m/s). The drag force density on the particles
is evaluated in each bed cell from the drag law with v_p = 0 and the cell's interstitial
gas velocity, and shared half-half by the two y-faces of the cell (the reaction rule of the
coupling), so the total drag is exactly (bed length) x (drag density). The pressure drop is
read between the centres of the cells just below and just above the bed, minus the gas
weight over that distance.

Discretisation error: in model A the two interface faces carry half the drag at face
eps 0.7 instead of 0.4, so -eps dp/dy gives Delta p = f (L/eps - dy/eps + dy/0.7):
-1.1 % for 40 cells.
"""

import numpy as np
import pytest

from cfbmarkov.simulate.cfd import GasGrid, GasSolver, interphase_momentum_coefficient

RHO, MU, D, G = 1.205, 1.8e-5, 1e-3, 9.81
EPS_BED, U = 0.4, 0.3
ROWS = slice(20, 60)


def ergun_gradient(eps, u_superficial):
    return (150 * (1 - eps) ** 2 * MU * u_superficial / (eps**3 * D**2)
            + 1.75 * (1 - eps) * RHO * u_superficial**2 / (eps**3 * D))


def run_bed(formulation, drag_factor, steps=200):
    """drag_factor(eps) multiplies the Table 2 drag density beta * u."""
    grid = GasGrid(nx=9, ny=95, width=0.09, height=0.95)
    solver = GasSolver(grid, density=RHO, viscosity=MU, superficial_velocity=U, gravity=G,
                       time_step=5e-5, formulation=formulation)
    eps = np.ones(grid.cell_shape)
    eps[:, ROWS] = EPS_BED
    bed = eps < 1.0
    fu = np.zeros(grid.u_shape)
    state = solver.initial_state(eps)
    history = []
    below, above = ROWS.start - 1, ROWS.stop
    y = grid.y_centres
    length = (ROWS.stop - ROWS.start) * grid.dy
    for _ in range(steps):
        ev = 0.5 * (np.roll(eps, 1, axis=1) + eps)
        m = ev * state.v
        vc = 0.5 * (m + np.roll(m, -1, axis=1)) / eps  # interstitial velocity in the cell
        beta = np.array([[interphase_momentum_coefficient(e, abs(w), D, RHO, MU)
                          for e, w in zip(er, wr)] for er, wr in zip(eps, vc)])
        fcell = np.where(bed, drag_factor(eps) * beta * vc, 0.0)
        fv = 0.5 * (fcell + np.roll(fcell, 1, axis=1))
        state = solver.step(state, eps, fu, fv)
        ptot = state.p - state.driving_pressure_gradient * y[None, :]
        history.append(np.mean(ptot[:, below] - ptot[:, above]) - RHO * G * (y[above] - y[below]))
    # the bed is steady (its relaxation time eps rho / beta is ~3 steps); the free gas
    # above keeps developing its wall boundary layers (viscous time W^2/nu ~ 500 s), which
    # does not touch the bed
    dp = history[-1]
    assert abs(history[-50] - dp) < 1e-6 * abs(dp)
    return dp, ergun_gradient(EPS_BED, U) * length, state


@pytest.mark.parametrize("formulation, factor, name", [
    ("A", lambda e: e, "model A with the model-A drag eps*beta"),
    ("B", lambda e: np.ones_like(e), "model B with the Table 2 drag beta"),
])
def test_packed_bed_pressure_drop_is_ergun(formulation, factor, name, record_property):
    dp, dp_ergun, state = run_bed(formulation, factor)
    err = dp / dp_ergun - 1
    record_property("ergun_relative_error", float(err))
    print(f"packed bed, {name}: dp = {dp:.2f} Pa, Ergun {dp_ergun:.2f} Pa, error {100 * err:+.2f} %")
    assert abs(err) < 0.05
    assert abs(state.mean_gas_flux() - U) < 1e-13
    # the bed carries the pressure drop: G H is about dp + gas weight
    g_total = state.driving_pressure_gradient * 0.95
    assert g_total == pytest.approx(dp_ergun + RHO * G * 0.95, rel=0.05)


def test_model_a_with_table2_drag_overshoots_by_one_over_eps():
    """Model A (-eps grad p - f) with beta of Table 2 as it stands: dp = Ergun / eps."""
    dp, dp_ergun, _ = run_bed("A", lambda e: np.ones_like(e))
    assert dp / dp_ergun == pytest.approx(1 / EPS_BED, rel=0.05)
