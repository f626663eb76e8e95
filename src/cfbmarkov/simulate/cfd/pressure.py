"""Pressure projection of the gas step: the variable-coefficient Poisson equation.

``div(c grad phi) = div m* + deps/dt + g' div(c y^)``, periodic in y, zero normal flux at
the walls, is assembled as a banded SPD matrix (one cell pinned), factorised by banded
Cholesky (:mod:`._banded`) only when ``c`` changes, and solved for ``phi_a`` and ``phi_b``
(``phi = phi_a + g' phi_b``); ``g'`` follows from the prescribed mean flux U. Steps 2-4 of
the algorithm in :mod:`.solver`.
"""

from __future__ import annotations

import numba as nb

from cfbmarkov.simulate.cfd._banded import band_cholesky, band_solve2

# status codes of a gas step
_OK, _UNSTABLE, _BAD_VOID, _NOT_SPD, _RESIDUAL, _BAD_FLUX, _BAD_INPUT = range(7)
# info slots
(_I_G, _I_RES_REL, _I_RES_ABS, _I_DEFECT, _I_UMAX, _I_VMAX, _I_DTMAX, _I_DTADV, _I_DTVIS,
 _I_FLUXERR, _I_PIVOT, _I_REFACTORED, _I_BADCELL) = range(13)
_INFO_SIZE = 13


@nb.njit(cache=True)
def factorise_if_changed(nx, ny, dx, dy, cu, cv, cu_fac, cv_fac, band, invdiag, numbering,
                         factor_state, info):
    """(Re)factorise the pressure matrix ``-div(c grad .)`` if its coefficients changed.

    Parameters
    ----------
    nx, ny : int
        Cells across and up.
    dx, dy : float
        Cell size, m.
    cu, cv : float64 (nx+1, ny), (nx, ny)
        Projection weights c on the x- and y-faces (0 on the walls), -.
    cu_fac, cv_fac : float64, same shapes
        The weights of the current factorisation (updated).
    band, invdiag : float64 (nx*ny, 2*nx+1), (nx*ny,)
        Banded Cholesky factor and inverse diagonal (updated).
    numbering : int64 (nx, ny)
        Unknown of each cell (:func:`._banded.cell_numbering`).
    factor_state : int64 (1,)
        1 when ``band`` holds the factor of ``cu_fac, cv_fac``.
    info : float64 (_INFO_SIZE,)
        ``info[_I_REFACTORED]`` set to 1 or 0; ``info[_I_PIVOT]`` on failure.

    Returns
    -------
    int
        ``_OK``, or ``_NOT_SPD`` when the matrix is not positive definite.
    """
    idx2 = 1.0 / (dx * dx)
    idy2 = 1.0 / (dy * dy)
    same = factor_state[0] == 1
    if same:
        for i in range(nx + 1):
            for j in range(ny):
                if cu[i, j] != cu_fac[i, j]:
                    same = False
                    break
            if not same:
                break
    if same:
        for i in range(nx):
            for j in range(ny):
                if cv[i, j] != cv_fac[i, j]:
                    same = False
                    break
            if not same:
                break
    info[_I_REFACTORED] = 0.0
    if not same:
        factor_state[0] = 0
        n = nx * ny
        b = band.shape[1] - 1
        for k in range(n):
            for o in range(b + 1):
                band[k, o] = 0.0
        # matrix of -div(c grad .) (SPD on the complement of the constants)
        for i in range(nx):
            for j in range(ny):
                k = numbering[i, j]
                jp = j + 1 if j + 1 < ny else 0
                band[k, 0] += (cu[i, j] + cu[i + 1, j]) * idx2 + (cv[i, j] + cv[i, jp]) * idy2
                if i + 1 < nx:
                    k2 = numbering[i + 1, j]
                    lo = k if k < k2 else k2
                    band[lo, abs(k2 - k)] -= cu[i + 1, j] * idx2
                k2 = numbering[i, jp]
                lo = k if k < k2 else k2
                band[lo, abs(k2 - k)] -= cv[i, jp] * idy2
        # pin unknown 0 (cell (0, 0)): drop its couplings, keep its diagonal
        for o in range(1, b + 1):
            band[0, o] = 0.0
        piv = band_cholesky(band, invdiag)
        if piv >= 0:
            info[_I_PIVOT] = piv
            return _NOT_SPD
        for i in range(nx + 1):
            for j in range(ny):
                cu_fac[i, j] = cu[i, j]
        for i in range(nx):
            for j in range(ny):
                cv_fac[i, j] = cv[i, j]
        factor_state[0] = 1
        info[_I_REFACTORED] = 1.0
    return _OK


@nb.njit(cache=True)
def project(nx, ny, dx, dy, dt, rho, U, rtol, eps_old, eps_new, ey_new, mu_s, mv_s, cu, cv,
            band, invdiag, ra, rb, numbering, u_out, v_out, p_out, info):
    """Solve for the pressure, correct the predicted mass fluxes, check continuity.

    Parameters
    ----------
    nx, ny : int
        Cells across and up.
    dx, dy : float
        Cell size, m.
    dt : float
        Gas time step, s.
    rho : float
        Gas density, kg/m^3.
    U : float
        Superficial velocity (domain mean of eps v), m/s.
    rtol : float
        Relative continuity residual allowed.
    eps_old, eps_new : float64 (nx, ny)
        Void fraction before and after the step, -.
    ey_new : float64 (nx, ny)
        New void fraction on the y-faces, -.
    mu_s, mv_s : float64 (nx+1, ny), (nx, ny)
        Predicted mass fluxes m* = eps u on the faces, m/s.
    cu, cv : float64, same shapes
        Projection weights c, -.
    band, invdiag : float64
        The factorised pressure matrix (:func:`factorise_if_changed`).
    ra, rb : float64 (nx*ny,)
        Workspace: right-hand sides, then phi_a + g' phi_b and phi_b.
    numbering : int64 (nx, ny)
        Unknown of each cell.
    u_out, v_out : float64 (nx+1, ny), (nx, ny)
        Output: new interstitial velocities, m/s.
    p_out : float64 (nx, ny)
        Output: periodic part of the pressure (zero mean), Pa.
    info : float64 (_INFO_SIZE,)
        G, residuals, continuity defect, flux error.

    Returns
    -------
    int
        ``_OK``, ``_BAD_FLUX`` (no flux response to G) or ``_RESIDUAL`` (continuity
        residual above ``rtol`` times the rate scale).
    """
    # ---- 6. right-hand sides: -L phi_a = -(div m* + deps/dt'), -L phi_b = -div(c y^)
    inv_dt = 1.0 / dt
    defect = 0.0
    for i in range(nx):
        for j in range(ny):
            defect += eps_new[i, j] - eps_old[i, j]
    defect *= inv_dt / (nx * ny)
    suma = 0.0
    sumb = 0.0
    scale_div = 0.0
    scale_et = 0.0
    scale_c = 0.0
    for i in range(nx):
        for j in range(ny):
            jp = j + 1 if j + 1 < ny else 0
            k = numbering[i, j]
            div = (mu_s[i + 1, j] - mu_s[i, j]) / dx + (mv_s[i, jp] - mv_s[i, j]) / dy
            et = (eps_new[i, j] - eps_old[i, j]) * inv_dt - defect
            dc = (cv[i, jp] - cv[i, j]) / dy
            ra[k] = -(div + et)
            rb[k] = -dc
            suma += ra[k]
            sumb += rb[k]
            scale_div = max(scale_div, abs(div))
            scale_et = max(scale_et, abs(et))
            scale_c = max(scale_c, abs(dc))
    n = nx * ny
    suma /= n
    sumb /= n
    for k in range(n):
        ra[k] -= suma
        rb[k] -= sumb
    ra[0] = 0.0
    rb[0] = 0.0
    band_solve2(band, invdiag, ra, rb)
    # ---- 7. driving pressure gradient from the mean flux, then the corrected fluxes
    qa = 0.0
    qb = 0.0
    for i in range(nx):
        for j in range(ny):
            jm = j - 1 if j >= 1 else ny - 1
            ka = numbering[i, j]
            km = numbering[i, jm]
            qa += mv_s[i, j] - cv[i, j] * (ra[ka] - ra[km]) / dy
            qb += cv[i, j] * (1.0 - (rb[ka] - rb[km]) / dy)
    qa /= n
    qb /= n
    if not qb > 0.0:
        return _BAD_FLUX
    gp = (U - qa) / qb
    info[_I_G] = gp * rho * inv_dt
    # phi = phi_a + g' phi_b (into ra)
    for k in range(n):
        ra[k] += gp * rb[k]
    # new mass fluxes into the output arrays (as m), then divide by eps_face
    for j in range(ny):
        u_out[0, j] = 0.0
        u_out[nx, j] = 0.0
    for i in range(1, nx):
        for j in range(ny):
            u_out[i, j] = mu_s[i, j] - cu[i, j] * (ra[numbering[i, j]] - ra[numbering[i - 1, j]]) / dx
    flux = 0.0
    for i in range(nx):
        for j in range(ny):
            jm = j - 1 if j >= 1 else ny - 1
            m = mv_s[i, j] + cv[i, j] * (gp - (ra[numbering[i, j]] - ra[numbering[i, jm]]) / dy)
            v_out[i, j] = m
            flux += m
    info[_I_FLUXERR] = flux / n - U
    # ---- 8. continuity residual on every cell
    res = 0.0
    for i in range(nx):
        for j in range(ny):
            jp = j + 1 if j + 1 < ny else 0
            r = ((u_out[i + 1, j] - u_out[i, j]) / dx + (v_out[i, jp] - v_out[i, j]) / dy
                 + (eps_new[i, j] - eps_old[i, j]) * inv_dt - defect)
            a = abs(r)
            if a > res or a != a:
                res = a
    scale = scale_div + scale_et + abs(gp) * scale_c
    floor = abs(U) / min(dx, dy)
    if scale < floor:
        scale = floor
    info[_I_RES_ABS] = res
    info[_I_RES_REL] = res / scale
    info[_I_DEFECT] = defect
    if not res <= rtol * scale:
        return _RESIDUAL
    # ---- 9. velocities and pressure (zero mean)
    for i in range(1, nx):
        for j in range(ny):
            u_out[i, j] /= 0.5 * (eps_new[i - 1, j] + eps_new[i, j])
    for i in range(nx):
        for j in range(ny):
            v_out[i, j] /= ey_new[i, j]
    pmean = 0.0
    for k in range(n):
        pmean += ra[k]
    pmean /= n
    pf = rho * inv_dt
    for i in range(nx):
        for j in range(ny):
            p_out[i, j] = (ra[numbering[i, j]] - pmean) * pf
    return _OK
