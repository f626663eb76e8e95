"""Manufactured check of the explicit momentum operator -div(eps u u) + nu div(eps grad u).

Smooth fields on the unit square (walls at x = 0, 1; periodic in y), eps variable:

    eps = 0.8 + 0.1 sin(pi x) cos(2 pi y)
    u   = 0.3 sin(pi x) cos(2 pi y)                   (zero on the walls)
    v   = 1 + 0.5 cos(pi x) sin(2 pi y)   (advection)  /  sin(pi x)(1 + 0.5 sin(2 pi y)) (viscous)

The discrete operator is compared with the analytical one at the faces on refined grids:
first order for upwind, close to second order (in the mean) for van Leer, which falls to
first order only at extrema; second order for the viscous term away from the wall-adjacent
v-faces. On those, the ghost value gives the wall gradient to O(dx^2), i.e. a first-order
term for uniform eps; with variable eps the wall flux is weighted by the eps of the wall
cell (at x = dx/2, not x = 0), an O(1) local error confined to that row of faces.
"""

import numpy as np
import pytest

from cfbmarkov.simulate.cfd import GasGrid, momentum_tendency

PI = np.pi


def fields(x, y, v_kind, eps_amplitude=0.1):
    a = eps_amplitude
    e = 0.8 + a * np.sin(PI * x) * np.cos(2 * PI * y)
    ex = a * PI * np.cos(PI * x) * np.cos(2 * PI * y)
    ey = -2 * a * PI * np.sin(PI * x) * np.sin(2 * PI * y)
    u = 0.3 * np.sin(PI * x) * np.cos(2 * PI * y)
    ux = 0.3 * PI * np.cos(PI * x) * np.cos(2 * PI * y)
    uy = -0.6 * PI * np.sin(PI * x) * np.sin(2 * PI * y)
    uxx = -PI**2 * u
    uyy = -4 * PI**2 * u
    if v_kind == "advection":
        v = 1 + 0.5 * np.cos(PI * x) * np.sin(2 * PI * y)
        vx = -0.5 * PI * np.sin(PI * x) * np.sin(2 * PI * y)
        vy = PI * np.cos(PI * x) * np.cos(2 * PI * y)
        vxx = vyy = None
    else:
        s = 1 + 0.5 * np.sin(2 * PI * y)
        v = np.sin(PI * x) * s
        vx = PI * np.cos(PI * x) * s
        vy = np.sin(PI * x) * PI * np.cos(2 * PI * y)
        vxx = -PI**2 * v
        vyy = -2 * PI**2 * np.sin(PI * x) * np.sin(2 * PI * y)
    return dict(e=e, ex=ex, ey=ey, u=u, ux=ux, uy=uy, uxx=uxx, uyy=uyy, v=v, vx=vx, vy=vy,
                vxx=vxx, vyy=vyy)


def discrete_and_exact(n, scheme, kind, eps_amplitude=0.1):
    grid = GasGrid(nx=n, ny=n, width=1.0, height=1.0)
    xc, yc = np.meshgrid(grid.x_centres, grid.y_centres, indexing="ij")
    xu, yu = np.meshgrid(grid.x_faces, grid.y_centres, indexing="ij")
    xv, yv = np.meshgrid(grid.x_centres, grid.y_faces, indexing="ij")
    eps = fields(xc, yc, kind, eps_amplitude)["e"]
    fu, fv = fields(xu, yu, kind, eps_amplitude), fields(xv, yv, kind, eps_amplitude)
    tu, tv = momentum_tendency(grid, fu["u"], fv["v"], eps, 0.0, scheme)
    if kind == "viscous":  # the viscous part alone: nu = 1 minus nu = 0
        tu1, tv1 = momentum_tendency(grid, fu["u"], fv["v"], eps, 1.0, scheme)
        tu, tv = tu1 - tu, tv1 - tv
    if kind == "advection":
        # -(d(eps u u)/dx + d(eps u v)/dy), -(d(eps u v)/dx + d(eps v v)/dy)
        f = fu
        ex_u = -(f["ex"] * f["u"] ** 2 + 2 * f["e"] * f["u"] * f["ux"]
                 + f["ey"] * f["u"] * f["v"] + f["e"] * f["uy"] * f["v"] + f["e"] * f["u"] * f["vy"])
        f = fv
        ex_v = -(f["ex"] * f["u"] * f["v"] + f["e"] * f["ux"] * f["v"] + f["e"] * f["u"] * f["vx"]
                 + f["ey"] * f["v"] ** 2 + 2 * f["e"] * f["v"] * f["vy"])
    else:
        f = fu
        ex_u = f["ex"] * f["ux"] + f["e"] * f["uxx"] + f["ey"] * f["uy"] + f["e"] * f["uyy"]
        f = fv
        ex_v = f["ex"] * f["vx"] + f["e"] * f["vxx"] + f["ey"] * f["vy"] + f["e"] * f["vyy"]
    return tu[1:-1], ex_u[1:-1], tv, ex_v


def errors(n, scheme, kind, skip_wall_v=False, wall_v_only=False, eps_amplitude=0.1):
    tu, eu, tv, ev = discrete_and_exact(n, scheme, kind, eps_amplitude)
    if skip_wall_v:
        tv, ev = tv[1:-1], ev[1:-1]
    if wall_v_only:
        tu = eu = np.zeros(1)
        tv, ev = tv[[0, -1]], ev[[0, -1]]
    du, dv = np.abs(tu - eu), np.abs(tv - ev)
    return max(du.mean(), dv.mean()), max(du.max(), dv.max())


@pytest.mark.parametrize("scheme, min_order", [("upwind", 0.9), ("vanleer", 1.6)])
def test_advection_converges(scheme, min_order):
    (m1, _), (m2, _) = errors(32, scheme, "advection"), errors(64, scheme, "advection")
    order = np.log2(m1 / m2)
    print(f"advection {scheme}: mean error {m1:.2e} (32) -> {m2:.2e} (64), order {order:.2f}")
    assert order > min_order
    # (the terms themselves are of order 5-10 here)
    assert m2 < (0.08 if scheme == "upwind" else 0.01)


def test_viscous_term_second_order():
    (m1, x1), (m2, x2) = errors(32, "upwind", "viscous", True), errors(64, "upwind", "viscous", True)
    assert np.log2(m1 / m2) > 1.9 and np.log2(x1 / x2) > 1.8
    # wall-adjacent v-faces: first order for uniform eps ...
    (_, w1), (_, w2) = [errors(n, "upwind", "viscous", wall_v_only=True, eps_amplitude=0.0)
                        for n in (32, 64)]
    assert np.log2(w1 / w2) > 0.9
    # ... and bounded (O(1), not growing) with an eps gradient at the wall
    (_, z1), (_, z2) = [errors(n, "upwind", "viscous", wall_v_only=True) for n in (32, 64)]
    assert z2 < 1.1 * z1
    print(f"viscous: interior mean error {m1:.2e} -> {m2:.2e}, max {x1:.2e} -> {x2:.2e}; "
          f"wall faces {w1:.2e} -> {w2:.2e} (eps uniform), {z1:.2e} -> {z2:.2e} (eps varying)")


def test_advection_conserves_y_momentum():
    """Flux form: the v-tendencies sum to zero (periodic in y, no mass flux through walls)."""
    rng = np.random.default_rng(4)
    grid = GasGrid(nx=9, ny=95, width=0.09, height=0.95)
    u = rng.normal(size=grid.u_shape)
    u[0] = u[-1] = 0
    v = 6 + rng.normal(size=grid.v_shape)
    eps = rng.uniform(0.4, 1.0, grid.cell_shape)
    for scheme in ("upwind", "vanleer"):
        tu, tv = momentum_tendency(grid, u, v, eps, 0.0, scheme)
        assert abs(tv.sum()) < 1e-12 * np.abs(tv).sum()
