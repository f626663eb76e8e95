"""Explicit momentum terms of the gas step: advection, viscous stress, stability limit.

``-div(eps u u) + nu div(eps grad u)`` on the faces of the staggered grid (:mod:`.grid`),
in flux form on the staggered control volumes with first-order upwind or van Leer-limited
(TVD) face values, and the stable step of the explicit scheme. The step itself is in
:mod:`.solver`, the pressure projection in :mod:`.pressure`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.simulate.cfd.grid import GasGrid

#: Courant number of the advective limit (forward Euler with a van Leer-limited scheme)
ADVECTIVE_COURANT = 0.5

SCHEMES = {"upwind": 0, "vanleer": 1}


def _stability_limits(dx, dy, nu, umax, vmax):
    rate = umax / dx + vmax / dy
    dt_adv = ADVECTIVE_COURANT / rate if rate > 0 else math.inf
    dt_visc = 1.0 / (2.0 * nu * (1.0 / dx ** 2 + 1.0 / dy ** 2))
    return 1.0 / (1.0 / dt_adv + 1.0 / dt_visc), dt_adv, dt_visc


_stability_limits_jit = nb.njit(cache=True)(_stability_limits)


def gas_stability_limit(grid: GasGrid, gas, max_velocity) -> float:
    """Largest stable gas time step of the explicit scheme.

    Advective limit ``dt_a = 0.5 / (|u|/dx + |v|/dy)`` (forward Euler with a TVD scheme),
    viscous limit ``dt_v = 1 / (2 nu (1/dx^2 + 1/dy^2))``; both acting together:
    ``dt_max = 1 / (1/dt_a + 1/dt_v)``. (The eps-weighted viscous term can be up to
    eps_max/eps_min stiffer at a void-fraction jump; at the paper's scale dt_v ~ 1.7 s, far
    from binding.)

    Parameters
    ----------
    grid : GasGrid
        Uses ``dx``, ``dy`` (m).
    gas : object
        Anything with ``viscosity`` (Pa s) and ``density`` (kg/m^3), e.g. a
        :class:`~cfbmarkov.simulate.cfd.solver.GasSolver` or a case's gas config.
    max_velocity : float or (float, float)
        One speed used for both directions, or ``(max |u|, max |v|)``, m/s.

    Returns
    -------
    float
        dt_max, s.
    """
    try:
        umax, vmax = (float(abs(max_velocity[0])), float(abs(max_velocity[1])))
    except (TypeError, IndexError):
        umax = vmax = float(abs(max_velocity))
    nu = float(gas.viscosity) / float(gas.density)
    return _stability_limits(grid.dx, grid.dy, nu, umax, vmax)[0]


@nb.njit(cache=True, inline="always")
def _limited(up, upup, down, scheme):
    """Face value from the upwind cell: first-order upwind or van Leer (TVD)."""
    if scheme == 0:
        return up
    a = up - upup
    b = down - up
    ab = a * b
    if ab > 0.0:
        return up + ab / (a + b)
    return up


@nb.njit(cache=True)
def _y_face_void_fraction(eps, distributor, out):
    """Void fraction on the y-faces into ``out``: the mean of the cells below and above
    (across the periodic seam at j = 0), or with ``distributor`` the cell above at j = 0."""
    nx, ny = eps.shape
    for i in range(nx):
        for j in range(ny):
            jm = j - 1 if j >= 1 else ny - 1
            out[i, j] = 0.5 * (eps[i, jm] + eps[i, j])
        if distributor:
            out[i, 0] = eps[i, 0]


@nb.njit(cache=True)
def _momentum_tendency(nx, ny, dx, dy, nu, scheme, u, v, eps, eps_y, tend_u, tend_v):
    """tend = -div(eps u u) + nu div(eps grad u) on the faces (m/s^2; 0 on the wall faces).

    ``eps_y`` is the void fraction on the y-faces (:func:`_y_face_void_fraction`).

    Advection is flux form on the staggered control volumes: mass fluxes eps_face u
    averaged to the control-volume faces, transported velocity from the upwind side
    (first-order upwind or van Leer limited). Ghost values at the walls: u beyond a wall
    is -u (no penetration), v is -v (no slip).
    """
    for i in range(nx + 1):
        for j in range(ny):
            tend_u[i, j] = 0.0
    for i in range(nx):
        for j in range(ny):
            tend_v[i, j] = 0.0
    # u-momentum, x-fluxes at cell centres c (between u-faces c and c+1)
    for c in range(nx):
        for j in range(ny):
            mc0 = 0.0 if (c == 0) else 0.5 * (eps[c - 1, j] + eps[c, j]) * u[c, j]
            mc1 = 0.0 if (c == nx - 1) else 0.5 * (eps[c, j] + eps[c + 1, j]) * u[c + 1, j]
            F = 0.5 * (mc0 + mc1)
            if F >= 0.0:
                upv = u[c, j]
                uu = u[c - 1, j] if c >= 1 else -u[1, j]
                dn = u[c + 1, j]
            else:
                upv = u[c + 1, j]
                uu = u[c + 2, j] if c + 2 <= nx else -u[nx - 1, j]
                dn = u[c, j]
            flux = F * _limited(upv, uu, dn, scheme) / dx
            tend_u[c, j] -= flux
            tend_u[c + 1, j] += flux
    # u-momentum, y-fluxes at corners (x_i, y_j), interior i
    for i in range(1, nx):
        for j in range(ny):
            jm = j - 1 if j >= 1 else ny - 1
            jmm = jm - 1 if jm >= 1 else ny - 1
            jp = j + 1 if j + 1 < ny else 0
            mvl = eps_y[i - 1, j] * v[i - 1, j]
            mvr = eps_y[i, j] * v[i, j]
            F = 0.5 * (mvl + mvr)
            if F >= 0.0:
                face = _limited(u[i, jm], u[i, jmm], u[i, j], scheme)
            else:
                face = _limited(u[i, j], u[i, jp], u[i, jm], scheme)
            flux = F * face / dy
            tend_u[i, jm] -= flux
            tend_u[i, j] += flux
    # v-momentum, y-fluxes at cell centres (i, j) (between v-faces j and j+1)
    for i in range(nx):
        for j in range(ny):
            jm = j - 1 if j >= 1 else ny - 1
            jp = j + 1 if j + 1 < ny else 0
            jpp = jp + 1 if jp + 1 < ny else 0
            m0 = eps_y[i, j] * v[i, j]
            m1 = eps_y[i, jp] * v[i, jp]
            F = 0.5 * (m0 + m1)
            if F >= 0.0:
                face = _limited(v[i, j], v[i, jm], v[i, jp], scheme)
            else:
                face = _limited(v[i, jp], v[i, jpp], v[i, j], scheme)
            flux = F * face / dy
            tend_v[i, j] -= flux
            tend_v[i, jp] += flux
    # v-momentum, x-fluxes at corners (x_i, y_j), interior i (zero mass flux on the walls)
    for i in range(1, nx):
        for j in range(ny):
            jm = j - 1 if j >= 1 else ny - 1
            mub = 0.5 * (eps[i - 1, jm] + eps[i, jm]) * u[i, jm]
            mut = 0.5 * (eps[i - 1, j] + eps[i, j]) * u[i, j]
            F = 0.5 * (mub + mut)
            if F >= 0.0:
                uu = v[i - 2, j] if i >= 2 else -v[0, j]
                face = _limited(v[i - 1, j], uu, v[i, j], scheme)
            else:
                uu = v[i + 1, j] if i + 1 < nx else -v[nx - 1, j]
                face = _limited(v[i, j], uu, v[i - 1, j], scheme)
            flux = F * face / dx
            tend_v[i - 1, j] -= flux
            tend_v[i, j] += flux
    # viscous term nu div(eps grad u) (the usual CFD-DEM simplification of div(eps tau))
    idx2 = 1.0 / (dx * dx)
    idy2 = 1.0 / (dy * dy)
    for i in range(1, nx):
        for j in range(ny):
            jm = j - 1 if j >= 1 else ny - 1
            jp = j + 1 if j + 1 < ny else 0
            # corner eps at (x_i, y_j) and (x_i, y_{j+1})
            ec_s = 0.25 * (eps[i - 1, jm] + eps[i, jm] + eps[i - 1, j] + eps[i, j])
            ec_n = 0.25 * (eps[i - 1, j] + eps[i, j] + eps[i - 1, jp] + eps[i, jp])
            visc = ((eps[i, j] * (u[i + 1, j] - u[i, j])
                     - eps[i - 1, j] * (u[i, j] - u[i - 1, j])) * idx2
                    + (ec_n * (u[i, jp] - u[i, j]) - ec_s * (u[i, j] - u[i, jm])) * idy2)
            tend_u[i, j] += nu * visc
    for j in range(ny):
        tend_u[0, j] = 0.0
        tend_u[nx, j] = 0.0
    for i in range(nx):
        for j in range(ny):
            jm = j - 1 if j >= 1 else ny - 1
            jp = j + 1 if j + 1 < ny else 0
            if i == 0:  # wall: ghost v = -v, corner eps from the wall cells
                ec_w = 0.5 * (eps[0, jm] + eps[0, j])
                vw = -v[0, j]
            else:
                ec_w = 0.25 * (eps[i - 1, jm] + eps[i, jm] + eps[i - 1, j] + eps[i, j])
                vw = v[i - 1, j]
            if i == nx - 1:
                ec_e = 0.5 * (eps[nx - 1, jm] + eps[nx - 1, j])
                ve = -v[nx - 1, j]
            else:
                ec_e = 0.25 * (eps[i, jm] + eps[i + 1, jm] + eps[i, j] + eps[i + 1, j])
                ve = v[i + 1, j]
            visc = ((ec_e * (ve - v[i, j]) - ec_w * (v[i, j] - vw)) * idx2
                    + (eps[i, j] * (v[i, jp] - v[i, j])
                       - eps[i, jm] * (v[i, j] - v[i, jm])) * idy2)
            tend_v[i, j] += nu * visc

def momentum_tendency(grid: GasGrid, u, v, void_fraction, kinematic_viscosity: float,
                      scheme: str = "vanleer") -> tuple[np.ndarray, np.ndarray]:
    """The explicit part ``-div(eps u u) + nu div(eps grad u)`` of a step, on the faces.

    This is what :meth:`GasSolver.step` adds, times dt, to eps u (before drag, gravity and
    the pressure); exposed for verification and diagnostics.

    Parameters
    ----------
    grid : GasGrid
    u, v : array_like (nx+1, ny), (nx, ny)
        Gas velocities on the x- and y-faces, m/s.
    void_fraction : array_like (nx, ny)
        eps at the cell centres, -.
    kinematic_viscosity : float
        nu, m^2/s.
    scheme : {"vanleer", "upwind"}
        Face values of the advected velocity.

    Returns
    -------
    tend_u, tend_v : ndarray (nx+1, ny), (nx, ny)
        The tendency on the x- and y-faces, m/s^2 (0 on the wall faces).

    Raises
    ------
    InputError
        Unknown ``scheme``.
    """
    if scheme not in SCHEMES:
        raise InputError(f"advection scheme must be one of {tuple(SCHEMES)}, got {scheme!r}")
    tu = np.zeros(grid.u_shape)
    tv = np.zeros(grid.v_shape)
    eps = np.ascontiguousarray(void_fraction, dtype=np.float64)
    _momentum_tendency(grid.nx, grid.ny, grid.dx, grid.dy, float(kinematic_viscosity),
                       SCHEMES[scheme], np.ascontiguousarray(u, dtype=np.float64),
                       np.ascontiguousarray(v, dtype=np.float64), eps,
                       grid.y_face_void_fraction(eps), tu, tv)
    return tu, tv
