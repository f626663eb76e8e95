"""Mean flux = U and discrete continuity for a non-uniform, time-varying void fraction."""

import numpy as np
import pytest

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
    record_property("worst_relative_flux_error", worst_flux)
    record_property("worst_continuity_residual_per_s", worst_cont)
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
