"""Mean flux = U and discrete continuity for a non-uniform, time-varying void fraction."""

import numpy as np
import pytest
from scipy.optimize import brentq

from cfbmarkov.errors import InputError
from cfbmarkov.simulate.cfd import (
    GasGrid,
    GasSolver,
    PressureSolveError,
    continuity_residual,
    cross_section_flux,
)

U = 6.0


def blob_void_fraction(grid, t, speed=3.0, depth=0.55, radius=0.025, solid_total=None,
                       start=0.3):
    """A Gaussian blob of low eps moving up (periodic images), solid volume kept fixed."""
    x = grid.x_centres[:, None]
    y = grid.y_centres[None, :]
    yc = (start + speed * t) % grid.height
    dy = (y - yc + 0.5 * grid.height) % grid.height - 0.5 * grid.height
    phi = np.exp(-((x - 0.04) ** 2 + dy**2) / radius**2)
    solid = depth * phi
    if solid_total is not None:  # conserve the solid volume exactly (incompressible gas)
        solid *= solid_total / solid.sum()
    return 1.0 - solid


@pytest.mark.parametrize("distributor", [False, True])
def test_flux_and_continuity_with_moving_blob(record_property, distributor):
    """With a distributor (the y-face at the floor takes the void fraction of the cell
    above it) the blob starts on the floor face, where the two face rules differ."""
    grid = GasGrid(nx=9, ny=95, width=0.09, height=0.95, distributor=distributor)
    solver = GasSolver(grid, density=1.205, viscosity=1.8e-5, superficial_velocity=U,
                       gravity=9.81, time_step=5e-5)
    start = 0.02 if distributor else 0.3
    eps0 = blob_void_fraction(grid, 0.0, start=start)
    seam_mean = 0.5 * (eps0[:, -1] + eps0[:, 0])
    floor_face = grid.y_face_void_fraction(eps0)[:, 0]
    if distributor:
        np.testing.assert_array_equal(floor_face, eps0[:, 0])
        assert np.max(np.abs(floor_face - seam_mean)) > 0.05
    else:
        np.testing.assert_array_equal(floor_face, seam_mean)
    total = (1.0 - eps0).sum()
    assert eps0.min() < 0.5
    fu, fv = np.zeros(grid.u_shape), np.zeros(grid.v_shape)
    state = solver.initial_state(eps0)
    assert state.mean_gas_flux(grid) == pytest.approx(U, rel=1e-15)
    worst_flux = worst_cont = worst_res = 0.0
    rng = np.random.default_rng(1)
    for n in range(1, 301):
        eps = blob_void_fraction(grid, n * solver.time_step, solid_total=total, start=start)
        # a drag-like body force that varies in space and time
        fv = 200.0 * (1.0 - eps) * (1.0 + 0.3 * rng.standard_normal(eps.shape))
        new = solver.step(state, eps, fu, fv)
        flux_err = abs(new.mean_gas_flux(grid) - U) / U
        cont = np.max(np.abs(continuity_residual(grid, state, new, solver.time_step)))
        assert flux_err < 1e-13, n
        # continuity residual against the natural rate scale U/dy = 600 1/s
        assert cont < 1e-10 * U / grid.dy, n
        assert new.pressure_residual < 1e-11
        assert abs(new.continuity_defect) < 1e-9
        # the rows of faces differ by exactly the rate of change of gas volume between them
        q = cross_section_flux(new, grid)
        deps = np.mean((new.void_fraction - state.void_fraction) / solver.time_step, axis=0)
        assert np.allclose(np.roll(q, -1) - q, -grid.dy * deps, rtol=0, atol=1e-10 * U)
        worst_flux = max(worst_flux, flux_err)
        worst_cont = max(worst_cont, cont)
        worst_res = max(worst_res, new.pressure_residual)
        state = new
    spread = np.ptp(cross_section_flux(state, grid))
    record_property("worst_relative_flux_error", float(worst_flux))
    record_property("worst_continuity_residual_per_s", float(worst_cont))
    print(f"moving blob, 300 steps: max |<eps v> - U|/U = {worst_flux:.1e}, "
          f"max |div(eps u) + deps/dt| = {worst_cont:.1e} 1/s, max relative pressure residual "
          f"{worst_res:.1e}; cross-section fluxes spread {spread:.3e} m/s about U")
    assert spread > 1e-4  # the blob's motion does make the rows differ
    assert np.all(np.isfinite(state.p)) and np.max(np.abs(state.u)) > 0


def test_void_volume_change_is_reported_as_defect():
    grid = GasGrid(nx=9, ny=20, width=0.09, height=0.2)
    solver = GasSolver(grid, superficial_velocity=U, time_step=5e-5)
    eps0 = np.full(grid.cell_shape, 0.9)
    state = solver.initial_state(eps0)
    eps1 = eps0.copy()
    eps1[3, 5] -= 0.01  # a particle appeared (e.g. clipping at the floor): not conserved
    new = solver.step(state, eps1, np.zeros(grid.u_shape), np.zeros(grid.v_shape))
    expected = -0.01 / solver.time_step / eps0.size
    assert new.continuity_defect == pytest.approx(expected, rel=1e-9)
    assert np.max(np.abs(continuity_residual(grid, state, new, solver.time_step))) < 1e-9
    assert new.mean_gas_flux() == pytest.approx(U, rel=1e-14)


def test_pressure_residual_is_checked():
    grid = GasGrid(nx=9, ny=20, width=0.09, height=0.2)
    strict = GasSolver(grid, superficial_velocity=U, time_step=5e-5, residual_tolerance=1e-300)
    eps = blob_void_fraction(grid, 0.0, radius=0.03)
    state = strict.initial_state(eps)
    with pytest.raises(PressureSolveError, match="relative continuity residual"):
        strict.step(state, eps * 0.999, np.zeros(grid.u_shape), np.zeros(grid.v_shape))
    ok = GasSolver(grid, superficial_velocity=U, time_step=5e-5)
    bad = np.zeros(grid.v_shape)
    bad[2, 3] = np.nan
    with pytest.raises(PressureSolveError, match="not finite"):
        ok.step(state, eps, np.zeros(grid.u_shape), bad)


@pytest.mark.parametrize("plate", [0.0, 1000.0])
def test_distributor_spreads_the_gas_over_the_columns(plate):
    """Columns of a bed that fills the whole height, one of them loose (eps 0.7, next to
    beds at 0.45), held by a fully implicit linear drag K_i (kg/(m^3 s)) as from particles
    at rest, and kept apart by a large drag on the x-faces (as by thin partitions). Each
    column is then a 1D channel, and in the steady state its gas flux
    m_i = eps_i v_i follows from the resistance network
    ``G H - eps_i rho g H = m_i (K_i H / eps_i + dp_d / U)`` with mean(m_i) = U. Without a
    distributor plate the gas channels through the loose column; with one (dp_d = 1000 Pa
    at U) the fluxes are spread as the network says, and the solver reports the plate's
    mean pressure drop."""
    u_s, rho, mu, d = 1.0, 1.205, 1.8e-5, 1e-3
    grid = GasGrid(nx=9, ny=20, width=0.09, height=0.2, distributor=True)
    solver = GasSolver(grid, density=rho, viscosity=mu, superficial_velocity=u_s,
                       time_step=5e-5, formulation="B", distributor_pressure_drop=plate)
    eps_col = np.full(grid.nx, 0.45)
    eps_col[4] = 0.7
    k_col = 150.0 * (1.0 - eps_col) ** 2 * mu / (eps_col * d**2)
    eps = np.repeat(eps_col[:, None], grid.ny, axis=1)
    kv = np.repeat(k_col[:, None], grid.ny, axis=1)
    ku = np.full(grid.u_shape, 1e7)
    state = solver.initial_state(eps)
    for _ in range(1000):     # 20 relaxation times rho eps / K of the loose column
        state = solver.step(state, eps, ku * state.u, kv * state.v, ku, kv)
    flux = grid.y_face_void_fraction(eps) * state.v
    h = grid.height
    resistance = k_col * h / eps_col + plate / u_s
    driving = brentq(lambda gh: np.mean((gh - eps_col * rho * 9.81 * h) / resistance) - u_s,
                     0.0, 1e7)
    expected = (driving - eps_col * rho * 9.81 * h) / resistance
    # (the gas viscosity couples neighbouring columns: 0.2 % next to the loose one)
    np.testing.assert_allclose(flux[:, 0], expected, rtol=5e-3)
    np.testing.assert_allclose(flux, np.broadcast_to(flux[:, :1], flux.shape), rtol=0.02)
    assert state.distributor_pressure_drop == pytest.approx(plate, rel=1e-9, abs=1e-12)
    assert state.driving_pressure_gradient * h == pytest.approx(driving, rel=2e-3)
    share = flux[4, 0] / u_s
    assert share > 4.0 if plate == 0 else share < 2.0            # channelling, or not


def test_distributor_pressure_drop_needs_a_distributor():
    grid = GasGrid(nx=9, ny=20, width=0.09, height=0.2)
    with pytest.raises(InputError, match="distributor"):
        GasSolver(grid, distributor_pressure_drop=100.0)
    with pytest.raises(InputError, match="non-negative"):
        GasSolver(GasGrid(nx=9, ny=20, width=0.09, height=0.2, distributor=True),
                  distributor_pressure_drop=-1.0)
