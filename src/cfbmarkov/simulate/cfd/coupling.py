"""Grid <-> particle transfers for the CFD-DEM coupling (numba kernels, serial).

* :func:`gas_velocity_at` / :func:`interpolate_gas_velocity`: bilinear interpolation of the
  staggered velocities to a point, periodic in y. ``u`` uses its own nodes (the wall faces
  carry u = 0); ``v`` uses its nodes at the cell centres in x and the wall value v = 0 *on*
  the walls x = 0 and x = W (half a cell from the first node), so the interpolated gas
  velocity satisfies no-slip at the wall. A uniform field is reproduced exactly away from
  the walls.
* :func:`deposit_drag_reaction`: the transpose of that interpolation. A particle force F
  adds ``w_k F / (dx dy d)`` to node k with the interpolation weight w_k, so that
  ``sum_k f_k dx dy d = sum_p F_p``. The share a wall node would receive (u on a wall face;
  the wall value of v) is given to the interior node of the same pair, so no momentum
  goes into the walls: the total is conserved to round-off. ``d`` is the pseudo-2D
  thickness (one particle diameter, ``docs/definitions.md``, riser).
* :func:`deposit_solid_volume` / :func:`void_fraction_field`: the solid volume of each
  particle (sphere volume pi d^3 / 6) is spread over the cells by area weighting
  (cloud-in-cell: a cell-sized square centred on the particle, i.e. bilinear weights on
  the cell centres), periodic in y, with the share beyond a wall folded back into the wall
  cell, so every particle counts fully. eps = 1 - solid volume / (dx dy d), clipped below at
  a floor (default 0.35) for robustness; the clipping is the only place solid volume is
  not conserved, and the gas solver reports the resulting continuity defect.

The deposits run in parallel and give the same bits for any number of threads: the
particles are cut by index into :data:`DEPOSIT_CHUNKS` fixed chunks, each chunk adds its
particles, in order, to its own copy of the fields, and the copies are summed in chunk
order (:func:`_sum_chunks`). :func:`interpolate_gas_velocity` is serial; the coupled step's
drag kernels (:mod:`cfbmarkov.simulate.coupling`) call :func:`gas_velocity_at` inline in
their parallel particle loops.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.simulate.cfd.grid import GasGrid

#: default lower clip of the void fraction
VOID_FRACTION_FLOOR = 0.35

#: the particles are deposited on the grid in this many fixed chunks of consecutive indices,
#: each into its own copy of the fields, summed in chunk order: parallel over the chunks, and
#: the same bits for any thread count (a constant, never the number of threads)
DEPOSIT_CHUNKS = 8


@nb.njit(cache=True, inline="always")
def _chunk_range(c, n):
    """Particles ``[lo, hi)`` of chunk ``c`` of :data:`DEPOSIT_CHUNKS` over ``n``."""
    return c * n // DEPOSIT_CHUNKS, (c + 1) * n // DEPOSIT_CHUNKS


@nb.njit(cache=True, parallel=True)
def _sum_chunks(partial, out):
    """``out += partial[0] + partial[1] + ...`` in chunk order (each element's sum in the
    same order whatever the threads). ``partial`` (C, a, b), ``out`` (a, b)."""
    C, a, b = partial.shape
    for i in nb.prange(a):
        for j in range(b):
            acc = out[i, j]
            for c in range(C):
                acc += partial[c, i, j]
            out[i, j] = acc


@nb.njit(cache=True, inline="always")
def _wrap_index(j, ny):
    if j < 0 or j >= ny:  # rare: an integer modulo costs as much as the rest of a particle
        j = j % ny
    return j


@nb.njit(cache=True, inline="always")
def _u_weights(x, y, nx, ny, idx, idy):
    """Nodes and weights of u at (x, y): (i0, j0, j1, wx, wy); nodes i0, i0 + 1.

    ``idx``, ``idy`` are 1/dx, 1/dy.
    """
    fi = x * idx
    i0 = int(fi)
    if i0 > nx - 1:
        i0 = nx - 1
    elif i0 < 0:
        i0 = 0
    wx = fi - i0
    if wx < 0.0:
        wx = 0.0
    elif wx > 1.0:
        wx = 1.0
    fj = y * idy - 0.5
    jf = math.floor(fj)
    wy = fj - jf
    j0 = _wrap_index(int(jf), ny)
    j1 = j0 + 1
    if j1 >= ny:
        j1 = 0
    return i0, j0, j1, wx, wy


@nb.njit(cache=True, inline="always")
def _v_weights(x, y, nx, ny, idx, idy):
    """Nodes and weights of v at (x, y): (ia, ib, wa, wb, j0, j1, wy).

    Between a wall and the first node (half a cell) ``ia == ib`` is that node and its
    weight is the linear factor towards the wall value 0 (the wall's own weight is dropped).
    """
    fi = x * idx - 0.5
    ia = int(math.floor(fi))
    wb = fi - ia
    wa = 1.0 - wb
    ib = ia + 1
    if ia < 0:
        ia = 0
        ib = 0
        wa = 0.0
        wb = 2.0 * x * idx
        if wb < 0.0:
            wb = 0.0
    elif ib > nx - 1:
        ia = nx - 1
        ib = nx - 1
        wb = 0.0
        wa = 2.0 * (nx - x * idx)
        if wa < 0.0:
            wa = 0.0
    fj = y * idy
    jf = math.floor(fj)
    wy = fj - jf
    j0 = _wrap_index(int(jf), ny)
    j1 = j0 + 1
    if j1 >= ny:
        j1 = 0
    return ia, ib, wa, wb, j0, j1, wy


@nb.njit(cache=True, inline="always")
def _gas_velocity(u, v, idx, idy, x, y):
    nx = v.shape[0]
    ny = v.shape[1]
    i0, j0, j1, wx, wy = _u_weights(x, y, nx, ny, idx, idy)
    ux = ((1.0 - wy) * ((1.0 - wx) * u[i0, j0] + wx * u[i0 + 1, j0])
          + wy * ((1.0 - wx) * u[i0, j1] + wx * u[i0 + 1, j1]))
    ia, ib, wa, wb, k0, k1, vy = _v_weights(x, y, nx, ny, idx, idy)
    uy = ((1.0 - vy) * (wa * v[ia, k0] + wb * v[ib, k0])
          + vy * (wa * v[ia, k1] + wb * v[ib, k1]))
    return ux, uy


@nb.njit(cache=True, inline="always")
def gas_velocity_at(u, v, dx, dy, x, y):
    """Gas velocity (ux, uy) at the point (x, y) by bilinear interpolation (m/s).

    ``u`` (nx+1, ny) and ``v`` (nx, ny) as in :class:`GasState`; 0 <= x <= W, and y in
    [0, H) (other y are wrapped periodically). Inlined where a kernel calls it (the drag
    kernels' particle loops: called, it cost them a third of their time at the quick scale).
    """
    return _gas_velocity(u, v, 1.0 / dx, 1.0 / dy, x, y)


@nb.njit(cache=True)
def _interpolate_kernel(u, v, dx, dy, x, y, out_x, out_y):
    # the body of _gas_velocity, written out: calling it here is twice as slow
    nx = v.shape[0]
    ny = v.shape[1]
    idx = 1.0 / dx
    idy = 1.0 / dy
    for p in range(x.shape[0]):
        xp = x[p]
        yp = y[p]
        i0, j0, j1, wx, wy = _u_weights(xp, yp, nx, ny, idx, idy)
        a = ((1.0 - wy) * ((1.0 - wx) * u[i0, j0] + wx * u[i0 + 1, j0])
             + wy * ((1.0 - wx) * u[i0, j1] + wx * u[i0 + 1, j1]))
        ia, ib, wa, wb, k0, k1, vy = _v_weights(xp, yp, nx, ny, idx, idy)
        b = ((1.0 - vy) * (wa * v[ia, k0] + wb * v[ib, k0])
             + vy * (wa * v[ia, k1] + wb * v[ib, k1]))
        out_x[p] = a
        out_y[p] = b


@nb.njit(cache=True, inline="always")
def _face_weights(x, y, nx, ny, idx, idy):
    """The faces a particle at (x, y) deposits on and their weights, the transpose of the
    interpolation (:func:`_u_weights`, :func:`_v_weights`) except at the walls, whose share
    goes to the neighbouring interior face (u) or node (v): (i0, j0, j1, w0, w1, wy) for u,
    (ia, ib, wa, wb, k0, k1, vy) for v."""
    i0, j0, j1, wx, wy = _u_weights(x, y, nx, ny, idx, idy)
    w0 = 1.0 - wx
    w1 = wx
    if i0 == 0:
        w1 = 1.0
        w0 = 0.0
    elif i0 + 1 == nx:
        w0 = 1.0
        w1 = 0.0
    ia, ib, wa, wb, k0, k1, vy = _v_weights(x, y, nx, ny, idx, idy)
    if ia == ib:
        wa = 1.0
        wb = 0.0
    return i0, j0, j1, w0, w1, wy, ia, ib, wa, wb, k0, k1, vy


@nb.njit(cache=True, inline="always")
def _add_to_faces(fu, fv, gx, gy, w):
    """Add (gx, gy) to the faces ``w`` of :func:`_face_weights` with their weights."""
    i0, j0, j1, w0, w1, wy, ia, ib, wa, wb, k0, k1, vy = w
    fu[i0, j0] += (1.0 - wy) * w0 * gx
    fu[i0 + 1, j0] += (1.0 - wy) * w1 * gx
    fu[i0, j1] += wy * w0 * gx
    fu[i0 + 1, j1] += wy * w1 * gx
    fv[ia, k0] += (1.0 - vy) * wa * gy
    fv[ib, k0] += (1.0 - vy) * wb * gy
    fv[ia, k1] += vy * wa * gy
    fv[ib, k1] += vy * wb * gy


@nb.njit(cache=True)
def _chunk_faces(nx, ny):
    """Each chunk's own copy of the u- and v-face fields, zero: (C, nx + 1, ny), (C, nx, ny)."""
    return np.zeros((DEPOSIT_CHUNKS, nx + 1, ny)), np.zeros((DEPOSIT_CHUNKS, nx, ny))


@nb.njit(cache=True, parallel=True)
def _deposit_forces_kernel(x, y, fx, fy, dx, dy, inv_volume, fu, fv):
    """Add the particle forces (fx, fy) per unit volume to the faces (fu, fv), by chunks."""
    nx = fv.shape[0]
    ny = fv.shape[1]
    idx = 1.0 / dx
    idy = 1.0 / dy
    n = x.shape[0]
    pu, pv = _chunk_faces(nx, ny)
    for c in nb.prange(DEPOSIT_CHUNKS):
        lo, hi = _chunk_range(c, n)
        cu = pu[c]
        cv = pv[c]
        for p in range(lo, hi):
            gx = fx[p] * inv_volume
            gy = fy[p] * inv_volume
            if gx == 0.0 and gy == 0.0:
                continue
            w = _face_weights(x[p], y[p], nx, ny, idx, idy)
            _add_to_faces(cu, cv, gx, gy, w)
    _sum_chunks(pu, fu)
    _sum_chunks(pv, fv)


@nb.njit(cache=True, inline="always")
def _deposit_particle(x, y, gx, gy, gk, nx, ny, idx, idy, cu, cv, cku, ckv):
    """One particle's force (gx, gy) and coefficient gk (per unit volume) onto one chunk's
    fields (as :func:`_deposit_forces_kernel` for each)."""
    if gx == 0.0 and gy == 0.0 and gk == 0.0:
        return
    w = _face_weights(x, y, nx, ny, idx, idy)
    if gx != 0.0 or gy != 0.0:
        _add_to_faces(cu, cv, gx, gy, w)
    if gk != 0.0:
        _add_to_faces(cku, ckv, gk, gk, w)


@nb.njit(cache=True, parallel=True)
def _deposit_drag_kernel(x, y, fx, fy, k, dx, dy, inv_volume, fu, fv, ku, kv):
    """:func:`_deposit_forces_kernel` for the forces (fx, fy) into (fu, fv) and for the
    coefficients k into (ku, kv), in one pass: each particle's weights are computed once,
    and every field receives the same sums in the same order (the same bits)."""
    nx = fv.shape[0]
    ny = fv.shape[1]
    idx = 1.0 / dx
    idy = 1.0 / dy
    n = x.shape[0]
    pu, pv = _chunk_faces(nx, ny)
    pku, pkv = _chunk_faces(nx, ny)
    for c in nb.prange(DEPOSIT_CHUNKS):
        lo, hi = _chunk_range(c, n)
        cu = pu[c]
        cv = pv[c]
        cku = pku[c]
        ckv = pkv[c]
        for p in range(lo, hi):
            _deposit_particle(x[p], y[p], fx[p] * inv_volume, fy[p] * inv_volume,
                              k[p] * inv_volume, nx, ny, idx, idy, cu, cv, cku, ckv)
    _sum_chunks(pu, fu)
    _sum_chunks(pv, fv)
    _sum_chunks(pku, ku)
    _sum_chunks(pkv, kv)


@nb.njit(cache=True, inline="always")
def solid_weights(x, y, nx, ny, idx, idy, periodic_y):
    """Cells and cloud-in-cell weights of a particle at (x, y): ``(i0, i1, j0, j1, wx, wy)``
    (cell (i0, j0) receives ``(1 - wx) (1 - wy)`` of its volume, and so on), the share
    beyond a wall folded back into the wall cell. ``idx``, ``idy`` are 1/dx, 1/dy.

    A function of scalars, compiled for the CPU here and called by the GPU coupling kernels
    (:mod:`cfbmarkov.simulate.gpu.coupling`) as a device function.
    """
    fi = x * idx - 0.5
    ifl = math.floor(fi)
    wx = fi - ifl
    i0 = int(ifl)
    i1 = i0 + 1
    if i0 < 0:  # fold the share beyond the wall back into the wall cell
        i0 = 0
    if i1 > nx - 1:
        i1 = nx - 1
    if i0 > nx - 1:
        i0 = nx - 1
    if i1 < 0:
        i1 = 0
    fj = y * idy - 0.5
    jfl = math.floor(fj)
    wy = fj - jfl
    if periodic_y:
        j0 = _wrap_index(int(jfl), ny)
        j1 = j0 + 1 if j0 + 1 < ny else 0
    else:  # clamped by comparisons: numba-cuda does not type min/max of these integers
        j0 = int(jfl)
        j1 = j0 + 1
        if j0 < 0:
            j0 = 0
        elif j0 > ny - 1:
            j0 = ny - 1
        if j1 < 0:
            j1 = 0
        elif j1 > ny - 1:
            j1 = ny - 1
    return i0, i1, j0, j1, wx, wy


@nb.njit(cache=True, inline="always")
def _add_solid_volume(x, y, volume, nx, ny, idx, idy, solid, periodic_y):
    """One particle's solid volume onto ``solid`` by cloud-in-cell."""
    i0, i1, j0, j1, wx, wy = solid_weights(x, y, nx, ny, idx, idy, periodic_y)
    solid[i0, j0] += (1.0 - wx) * (1.0 - wy) * volume
    solid[i1, j0] += wx * (1.0 - wy) * volume
    solid[i0, j1] += (1.0 - wx) * wy * volume
    solid[i1, j1] += wx * wy * volume


@nb.njit(cache=True, parallel=True)
def deposit_solid_volume(x, y, volume, dx, dy, solid, periodic_y=True):
    """Add each particle's solid volume (m^3, scalar) to ``solid`` (nx, ny) by cloud-in-cell
    (in :data:`DEPOSIT_CHUNKS` chunks, the same bits for any thread count).
    ``periodic_y=False`` (a bed on a floor): the share beyond the bottom (top) row is folded
    back into it, as at the side walls, instead of going across the periodic seam."""
    nx = solid.shape[0]
    ny = solid.shape[1]
    idx = 1.0 / dx
    idy = 1.0 / dy
    n = x.shape[0]
    partial = np.zeros((DEPOSIT_CHUNKS, nx, ny))
    for c in nb.prange(DEPOSIT_CHUNKS):
        lo, hi = _chunk_range(c, n)
        part = partial[c]
        for p in range(lo, hi):
            _add_solid_volume(x[p], y[p], volume, nx, ny, idx, idy, part, periodic_y)
    _sum_chunks(partial, solid)


def _positions(x, y):
    # views such as positions[:, 0] are used as they are (no copy; the kernels read x and
    # y of a particle from one cache line)
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 1:
        raise InputError(f"particle x and y must be 1-D arrays of one length, got {x.shape}, {y.shape}")
    return x, y


def interpolate_gas_velocity(grid: GasGrid, u, v, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Gas velocity at particle positions (x, y): two arrays (m/s)."""
    x, y = _positions(x, y)
    ox = np.empty(x.shape)
    oy = np.empty(y.shape)
    _interpolate_kernel(np.ascontiguousarray(u, dtype=np.float64),
                        np.ascontiguousarray(v, dtype=np.float64), grid.dx, grid.dy, x, y, ox, oy)
    return ox, oy


def deposit_drag_reaction(grid: GasGrid, x, y, fx, fy, thickness: float,
                          out: tuple[np.ndarray, np.ndarray] | None = None):
    """Force per unit volume (N/m^3) on the u- and v-faces from particle forces (N).

    Pass the drag force each particle *receives* from the gas; the result is the
    ``drag_force_u/v`` argument of :meth:`GasSolver.step` (the gas feels minus this).
    With ``out`` the fields are added to the given arrays.
    """
    x, y = _positions(x, y)
    fx = np.ascontiguousarray(fx, dtype=np.float64)
    fy = np.ascontiguousarray(fy, dtype=np.float64)
    if fx.shape != x.shape or fy.shape != x.shape:
        raise InputError("particle forces must have one value per particle")
    if out is None:
        fu = np.zeros(grid.u_shape)
        fv = np.zeros(grid.v_shape)
    else:
        fu, fv = out
    _deposit_forces_kernel(x, y, fx, fy, grid.dx, grid.dy, 1.0 / grid.cell_volume(thickness), fu, fv)
    return fu, fv


def deposit_drag_jacobian(grid: GasGrid, x, y, coefficient, thickness: float):
    """``drag_jacobian_u/v`` (kg/(m^3 s)) for a semi-implicit drag in :meth:`GasSolver.step`.

    ``coefficient`` is each particle's beta Vp / (1 - eps) (kg/s,
    :func:`~cfbmarkov.simulate.cfd.drag.particle_drag_jacobian`), spread with the weights of
    :func:`deposit_drag_reaction`.
    """
    x, y = _positions(x, y)
    k = np.ascontiguousarray(coefficient, dtype=np.float64)
    if k.shape != x.shape:
        raise InputError("drag coefficients must have one value per particle")
    ku = np.zeros(grid.u_shape)
    kv = np.zeros(grid.v_shape)
    _deposit_forces_kernel(x, y, k, k, grid.dx, grid.dy, 1.0 / grid.cell_volume(thickness), ku, kv)
    return ku, kv


def deposit_drag(grid: GasGrid, x, y, fx, fy, coefficient, thickness: float):
    """:func:`deposit_drag_reaction` and :func:`deposit_drag_jacobian` of the same particles
    in one pass over them (the same four fields, bit for bit; a gas step needs both).

    Parameters
    ----------
    grid : GasGrid
        The gas grid.
    x, y : array_like
        [N] particle centres, m.
    fx, fy : array_like
        [N] drag force each particle receives from the gas, N.
    coefficient : array_like
        [N] beta Vp / (1 - eps) of each particle, kg/s.
    thickness : float
        Depth of the pseudo-2D cells, m.

    Returns
    -------
    fu, fv : numpy.ndarray
        Force per unit volume on the u faces [nx + 1, ny] and v faces [nx, ny], N/m^3.
    ku, kv : numpy.ndarray
        ``drag_jacobian_u/v`` on the same faces, kg/(m^3 s).

    Raises
    ------
    InputError
        If the arrays do not have one value per particle.
    """
    x, y = _positions(x, y)
    fx = np.asarray(fx, dtype=np.float64)
    fy = np.asarray(fy, dtype=np.float64)
    k = np.asarray(coefficient, dtype=np.float64)
    if fx.shape != x.shape or fy.shape != x.shape or k.shape != x.shape:
        raise InputError("particle forces and drag coefficients must have one value per particle")
    fu = np.zeros(grid.u_shape)
    fv = np.zeros(grid.v_shape)
    ku = np.zeros(grid.u_shape)
    kv = np.zeros(grid.v_shape)
    _deposit_drag_kernel(x, y, fx, fy, k, grid.dx, grid.dy, 1.0 / grid.cell_volume(thickness),
                         fu, fv, ku, kv)
    return fu, fv, ku, kv


def void_fraction_field(grid: GasGrid, x, y, diameter: float,
                        floor: float = VOID_FRACTION_FLOOR, periodic_y: bool = True
                        ) -> np.ndarray:
    """Void fraction on the cells (nx, ny) from particle centres, pseudo-2D cells dx dy d
    (``floor``: its lower bound; ``periodic_y=False``: a bed on a floor, see
    :func:`deposit_solid_volume`)."""
    x, y = _positions(x, y)
    if not diameter > 0:
        raise InputError(f"particle diameter must be positive, got {diameter}")
    solid = np.zeros(grid.cell_shape)
    deposit_solid_volume(x, y, math.pi * diameter ** 3 / 6.0, grid.dx, grid.dy, solid,
                         bool(periodic_y))
    eps = 1.0 - solid / grid.cell_volume(diameter)
    return np.maximum(eps, floor)
