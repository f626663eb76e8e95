"""Grid <-> particle transfers: interpolation, drag reaction, void fraction."""

import math

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.simulate.cfd import (
    GasGrid,
    deposit_drag,
    deposit_drag_jacobian,
    deposit_drag_reaction,
    gas_velocity_at,
    interpolate_gas_velocity,
    void_fraction_field,
)

GRID = GasGrid(nx=9, ny=95, width=0.09, height=0.95)
D = 1e-3


def test_uniform_and_linear_fields_interpolate_exactly():
    g = GRID
    rng = np.random.default_rng(0)
    n = 5000
    # away from the walls (within one cell, u and v see their wall values)
    x = rng.uniform(g.dx, g.width - g.dx, n)
    y = rng.uniform(0, g.height, n)
    u = np.full(g.u_shape, 1.7)
    u[0] = u[-1] = 0.0
    v = np.full(g.v_shape, -4.2)
    ux, uy = interpolate_gas_velocity(g, u, v, x, y)
    assert np.max(np.abs(ux - 1.7)) < 1e-14
    assert np.max(np.abs(uy + 4.2)) < 1e-14
    # a field linear in x and y is reproduced (away from the periodic seam for y)
    a, b, c = 0.3, 20.0, -7.0
    u = a + b * g.x_faces[:, None] + c * g.y_centres[None, :]
    v = a + b * g.x_centres[:, None] + c * g.y_faces[None, :]
    ys = rng.uniform(g.dy, g.height - g.dy, n)
    xs = rng.uniform(g.dx, g.width - g.dx, n)
    ux, uy = interpolate_gas_velocity(g, u, v, xs, ys)
    assert np.allclose(ux, a + b * xs + c * ys, rtol=0, atol=1e-13)
    assert np.allclose(uy, a + b * xs + c * ys, rtol=0, atol=1e-13)
    # periodic in y; no-slip at the walls; the scalar kernel agrees with the array one
    assert gas_velocity_at(u, v, g.dx, g.dy, 0.031, 0.0) == pytest.approx(
        gas_velocity_at(u, v, g.dx, g.dy, 0.031, g.height))
    vv = np.full(g.v_shape, 3.0)
    assert gas_velocity_at(u, vv, g.dx, g.dy, 0.0, 0.5)[1] == 0.0
    assert gas_velocity_at(u, vv, g.dx, g.dy, g.width, 0.5)[1] == 0.0
    assert gas_velocity_at(u, vv, g.dx, g.dy, 0.25 * g.dx, 0.5)[1] == pytest.approx(1.5)
    assert gas_velocity_at(u, vv, g.dx, g.dy, 0.5 * g.dx, 0.5)[1] == pytest.approx(3.0)


def test_reaction_conserves_momentum_and_is_the_transpose():
    g = GRID
    rng = np.random.default_rng(3)
    n = 27000
    x = rng.uniform(0.5 * D, g.width - 0.5 * D, n)
    x[:50] = rng.uniform(0, 0.004, 50)  # crowd the walls and the seam
    x[50:100] = g.width - rng.uniform(0, 0.004, 50)
    y = rng.uniform(0, g.height, n)
    y[100:150] = rng.uniform(0, 1e-4, 50)
    y[150:200] = g.height - rng.uniform(0, 1e-4, 50)
    fx = rng.normal(0, 1e-5, n)
    fy = rng.normal(1e-5, 1e-5, n)
    fu, fv = deposit_drag_reaction(g, x, y, fx, fy, thickness=D)
    vol = g.cell_volume(D)
    assert fu.sum() * vol == pytest.approx(fx.sum(), rel=1e-12, abs=1e-12 * np.abs(fx).sum())
    assert fv.sum() * vol == pytest.approx(fy.sum(), rel=1e-12, abs=1e-12 * np.abs(fy).sum())
    assert np.all(fu[0] == 0) and np.all(fu[-1] == 0)  # nothing lost into the walls
    # the semi-implicit drag coefficients are spread with the same weights
    coeff = rng.uniform(1e-4, 1e-3, n)
    ku, kv = deposit_drag_jacobian(g, x, y, coeff, thickness=D)
    assert ku.sum() * vol == pytest.approx(coeff.sum(), rel=1e-12)
    assert kv.sum() * vol == pytest.approx(coeff.sum(), rel=1e-12)
    assert ku.min() >= 0 and kv.min() >= 0
    # transpose: sum_faces f . w dV = sum_p F_p . w(x_p) for particles off the wall cells
    inner = (x > g.dx) & (x < g.width - g.dx)
    fu, fv = deposit_drag_reaction(g, x[inner], y[inner], fx[inner], fy[inner], thickness=D)
    wu = rng.normal(size=g.u_shape)
    wu[0] = wu[-1] = 0.0
    wv = rng.normal(size=g.v_shape)
    ux, uy = interpolate_gas_velocity(g, wu, wv, x[inner], y[inner])
    lhs = (np.sum(fu * wu) + np.sum(fv * wv)) * vol
    rhs = np.sum(fx[inner] * ux) + np.sum(fy[inner] * uy)
    assert lhs == pytest.approx(rhs, rel=1e-11)
    # the gas step deposits both in one pass: the same fields, bit for bit (particles with
    # no force, or no coefficient, or neither, included)
    fx[200:260] = 0.0
    fy[200:230] = 0.0
    coeff[230:290] = 0.0
    fused = deposit_drag(g, x, y, fx, fy, coeff, thickness=D)
    separate = (*deposit_drag_reaction(g, x, y, fx, fy, thickness=D),
                *deposit_drag_jacobian(g, x, y, coeff, thickness=D))
    for a, b in zip(fused, separate):
        assert a.shape == b.shape and np.array_equal(a, b)
    with pytest.raises(InputError, match="one value per particle"):
        deposit_drag(g, x, y, fx, fy, coeff[:-1], thickness=D)


def test_void_fraction_conserves_solid_volume():
    g = GRID
    rng = np.random.default_rng(5)
    n = 27000
    x = rng.uniform(0.5 * D, g.width - 0.5 * D, n)
    y = rng.uniform(0, g.height, n)
    eps = void_fraction_field(g, x, y, D, floor=0.0)
    vp = math.pi * D**3 / 6
    solid = np.sum(1 - eps) * g.cell_volume(D)
    assert solid == pytest.approx(n * vp, rel=1e-12)
    # the paper's mean: 27000 spheres in 855 cells of 1e-7 m^3 -> eps = 0.835
    assert eps.mean() == pytest.approx(1 - n * vp / (g.width * g.height * D), rel=1e-12)
    # a dense heap is clipped at the floor
    xs = np.full(2000, 0.045)
    ys = np.full(2000, 0.5)
    assert void_fraction_field(g, xs, ys, D).min() == 0.35


def test_void_fraction_of_a_bed_on_a_floor_does_not_cross_the_seam():
    """Periodic in y, a particle just above y = 0 shares its volume with the top row; on a
    floor (``periodic_y=False``) that share stays in the bottom row, and the drag kernels
    read the bottom row's void fraction there, not a mean with the empty top."""
    from cfbmarkov.simulate.coupling import drag_coefficients

    g = GRID
    x, y = np.array([0.045]), np.array([0.2 * g.dy])
    periodic = void_fraction_field(g, x, y, D, floor=0.0)
    floor = void_fraction_field(g, x, y, D, floor=0.0, periodic_y=False)
    solid = 1.0 - floor
    assert solid[:, -1].sum() == 0.0 and (1.0 - periodic)[:, -1].sum() > 0
    assert solid.sum() == pytest.approx((1.0 - periodic).sum(), rel=1e-12)
    # a bed filling the bottom row: the particles in its lower half see its void fraction
    eps = np.ones(g.cell_shape)
    eps[:, 0] = 0.4
    u, v = np.zeros(g.u_shape), np.full(g.v_shape, 1.0)
    out = {}
    for periodic_y in (True, False):
        k, f = np.zeros(1), np.zeros((1, 2))
        drag_coefficients(np.array([[0.045, 0.1 * g.dy]]), np.zeros((1, 2)), u, v, eps, g.dx,
                          g.dy, D, 1.205, 1.8e-5, k, f, periodic_y)
        out[periodic_y] = k[0]
    # denser gas-solid mixture, more drag per particle at the same slip
    assert out[False] > 1.5 * out[True]


def test_deposits_are_the_same_bits_for_any_thread_count():
    """The deposits run over fixed chunks of particles, summed in chunk order: one thread
    and two give the same bits; the chunked sum differs from a plain serial sum only at
    round-off."""
    import numba

    g = GRID
    rng = np.random.default_rng(8)
    n = 5001  # not a multiple of the chunks
    x = rng.uniform(0, g.width, n)
    y = rng.uniform(0, g.height, n)
    fx, fy = rng.normal(0, 1e-5, n), rng.normal(0, 1e-5, n)
    coeff = rng.uniform(1e-4, 1e-3, n)
    threads = numba.get_num_threads()
    out = []
    try:
        for t in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(t)
            out.append((*deposit_drag(g, x, y, fx, fy, coeff, thickness=D),
                        void_fraction_field(g, x, y, D, floor=0.0)))
    finally:
        numba.set_num_threads(threads)
    for a, b in zip(*out):
        assert np.array_equal(a, b)
    # against a plain serial sum in particle order
    solid = np.zeros(g.cell_shape)
    fi = x / g.dx - 0.5
    i0 = np.floor(fi).astype(int)
    wx = fi - i0
    fj = y / g.dy - 0.5
    j0 = np.floor(fj).astype(int)
    wy = fj - j0
    vol = math.pi * D**3 / 6
    for di, dj, w in ((0, 0, (1 - wx) * (1 - wy)), (1, 0, wx * (1 - wy)), (0, 1, (1 - wx) * wy),
                      (1, 1, wx * wy)):
        np.add.at(solid, (np.clip(i0 + di, 0, g.nx - 1), (j0 + dj) % g.ny), w * vol)
    eps = 1 - solid / g.cell_volume(D)
    assert np.allclose(out[0][4], eps, rtol=0, atol=1e-13)
