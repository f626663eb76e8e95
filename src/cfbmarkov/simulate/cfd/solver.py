"""Locally volume-averaged incompressible gas on the staggered grid.

The model is that of ``docs/definitions.md`` (section riser).

Equations (rho constant, eps the void fraction given each step from the particles)::

    d(eps)/dt + div(eps u) = 0
    d(eps rho u)/dt + div(eps rho u u) = -w grad p + div(eps mu grad u) + eps rho g - f + w G y^

* ``formulation="A"`` (default; "model A" / "set II" of Zhou et al., J. Fluid Mech. 661
  (2010) 482): ``w = eps``. The particles must then also feel the pressure-gradient force
  ``-Vp grad p_total`` (``p_total = p - G y``, so this includes ``+Vp G`` upwards), and a
  drag consistent with Ergun's pressure drop is ``eps * beta`` with the Table 2 beta.
* ``formulation="B"`` ("model B" / "set I"): ``w = 1``; ``f`` is the whole fluid force on
  the particles, and the Table 2 beta as it stands (``docs/definitions.md``, riser) reproduces Ergun's
  pressure drop. See :mod:`cfbmarkov.simulate.cfd.drag` for why.

``f`` is the drag force per unit volume that the gas exerts on the particles (x on the
x-faces, y on the y-faces), ``G`` a uniform driving pressure gradient (Pa/m, +y), so that the
full pressure is ``p_total(x, y) = p(x, y) - G y`` with ``p`` periodic in y (zero mean).
``G`` includes the weight of the gas (eps rho g), so a gas-only channel has
``G = rho g + 12 mu U / W^2``. The viscous stress is the usual CFD-DEM simplification
``div(eps mu grad u)``: the transpose and dilatation parts of ``div(eps tau)`` are dropped
(they vanish for eps = const).

Discretisation and step (numba kernels, serial: 9 x 95 cells are too few for threads to
pay; :func:`_step_kernel` here checks the input and forms the predictor of step 1 with the
explicit terms of :mod:`.momentum`; :mod:`.pressure` does steps 2-4; :mod:`.state` holds
:class:`GasState`):

1. Predictor for the face mass fluxes ``m = eps_face u`` (eps_face the mean of the two
   cells beside the face; on a grid with a ``distributor`` the y-face at the floor takes
   the cell above it, see :mod:`.grid`):
   ``R = m^n + dt (-div(eps u u) + nu div(eps grad u) - f / rho + K u^n / rho)
   - dt eps_face^{n+1} g``. Advection is flux-form on the staggered control
   volumes with van Leer-limited (TVD, second order where smooth) or first-order upwind
   face values; forward Euler. ``K >= 0`` (optional ``drag_jacobian``, kg/(m^3 s)) makes the
   drag semi-implicit, ``f -> f + K (u^{n+1} - u^n)``: then ``m* = a R`` with
   ``a = eps/(eps + dt K/rho)``, else ``a = 1``.
2. Projection: ``m^{n+1} = m* + c (g' y^ - grad phi)``, ``c = a w``, ``phi = dt p / rho``,
   ``g' = dt G / rho``. Continuity ``div m^{n+1} = -(eps^{n+1} - eps^n)/dt`` gives the
   variable-coefficient Poisson equation ``div(c grad phi) = div m* + deps/dt + g' div(c y^)``,
   periodic in y, zero normal flux at the walls (``c = 0`` on the wall faces). It is linear
   in the unknown ``g'``: ``phi = phi_a + g' phi_b``, both solved with one banded Cholesky
   factorisation (one cell pinned to remove the constant null space; ``p`` is then shifted
   to zero mean). The factorisation is redone only when ``c`` changes.
3. ``g'`` is then fixed so that the domain mean of ``eps v`` over all y-faces equals U
   exactly (to round-off). With continuity satisfied, the mean over one cross-section row of
   faces differs from U only by the rate of change of the gas volume between the rows
   (:func:`cross_section_flux`); averaged over the domain, or over time at one section, it is U.
4. The continuity residual ``max |div m^{n+1} + deps/dt|`` is computed over every cell and
   compared with ``residual_tolerance`` times a rate scale; a failure raises
   :class:`PressureSolveError`.

A void fraction field whose total changes between steps cannot be followed by an
incompressible gas in a closed periodic box: the mean of ``deps/dt`` is removed before the
solve and reported as ``continuity_defect`` (1/s); it is zero when the solid volume is
conserved (no clipping at the void fraction floor).

The explicit step is stable under :func:`gas_stability_limit`; a larger step is refused
with an :class:`~cfbmarkov.errors.InputError`. An explicit drag (no ``K``) adds the limit
``dt K / (eps rho) < 2`` (< 1 to avoid oscillation), which this solver cannot check: in
the dense regions of the paper's riser K ~ 1e4 kg/(m^3 s) and dt = 5e-5 s give about 1
(a test with 27000 particles and a dense cluster diverged at once), so a coupled run
should pass ``drag_jacobian`` (see :func:`~cfbmarkov.simulate.cfd.coupling.deposit_drag_jacobian`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.simulate.cfd._banded import cell_numbering
from cfbmarkov.simulate.cfd.grid import GasGrid
from cfbmarkov.simulate.cfd.layout import (GasParams, GasStepFields, GasStepOutput,
                                          GasWorkspace)
from cfbmarkov.simulate.cfd.momentum import (  # noqa: F401  (momentum_tendency re-exported)
    ADVECTIVE_COURANT,
    SCHEMES,
    _momentum_tendency,
    _stability_limits_jit,
    _y_face_void_fraction,
    gas_stability_limit,
    momentum_tendency,
)
from cfbmarkov.simulate.cfd.pressure import (
    _BAD_FLUX,
    _BAD_INPUT,
    _BAD_VOID,
    _I_BADCELL,
    _I_DEFECT,
    _I_DTADV,
    _I_DTMAX,
    _I_DTVIS,
    _I_FLUXERR,
    _I_G,
    _I_PIVOT,
    _I_REFACTORED,
    _I_RES_ABS,
    _I_RES_REL,
    _I_UMAX,
    _I_VMAX,
    _INFO_SIZE,
    _NOT_SPD,
    _OK,
    _RESIDUAL,
    _UNSTABLE,
    factorise_if_changed,
    project,
)
from cfbmarkov.simulate.cfd.state import (  # noqa: F401  (re-exported)
    GasState,
    continuity_residual,
    cross_section_flux,
)

FORMULATIONS = ("A", "B")


class PressureSolveError(CfbmarkovError):
    """The pressure equation could not be solved to its tolerance (or its matrix is not SPD)."""


# --------------------------------------------------------------------------- step kernel

@nb.njit(cache=True, nogil=True)
def _step_kernel(prm, fields, out, work):
    """One gas step; see the module docstring. Returns a status code (0 = success).

    Parameters
    ----------
    prm : GasParams
    fields : GasStepFields
    out : GasStepOutput
        Written.
    work : GasWorkspace
        Scratch, the cached factorisation and ``info`` (updated).
    """
    nx, ny, dx, dy, dt = prm.nx, prm.ny, prm.dx, prm.dy, prm.dt
    rho, nu, gravity, U, model_a = prm.rho, prm.nu, prm.gravity, prm.U, prm.model_a
    scheme, rtol, distributor = prm.scheme, prm.rtol, prm.distributor
    u, v, eps_old, eps_new = fields.u, fields.v, fields.eps_old, fields.eps_new
    fu, fv, ku, kv, has_k = fields.fu, fields.fv, fields.ku, fields.kv, fields.has_k
    u_out, v_out, p_out = out.u_out, out.v_out, out.p_out
    mu_s, mv_s, cu, cv = work.mu_s, work.mv_s, work.cu, work.cv
    cu_fac, cv_fac, band, invdiag = work.cu_fac, work.cv_fac, work.band, work.invdiag
    ra, rb, numbering, tend_u, tend_v = work.ra, work.rb, work.numbering, work.tend_u, work.tend_v
    ey_old, ey_new, factor_state, info = work.ey_old, work.ey_new, work.factor_state, work.info
    # ---- 1. stability of the explicit step, from the current velocities
    umax = 0.0
    vmax = 0.0
    for i in range(nx + 1):
        for j in range(ny):
            a = abs(u[i, j])
            if a > umax or a != a:  # a NaN sticks
                umax = a
    for i in range(nx):
        for j in range(ny):
            a = abs(v[i, j])
            if a > vmax or a != a:
                vmax = a
    dtmax, dtadv, dtvis = _stability_limits_jit(dx, dy, nu, umax, vmax)
    info[_I_UMAX] = umax
    info[_I_VMAX] = vmax
    info[_I_DTMAX] = dtmax
    info[_I_DTADV] = dtadv
    info[_I_DTVIS] = dtvis
    if not dt <= dtmax * (1.0 + 1e-12):
        return _UNSTABLE
    # ---- 2. the new void fraction must be usable
    for i in range(nx):
        for j in range(ny):
            e = eps_new[i, j]
            if not (e > 0.0 and e <= 1.0 + 1e-12):
                info[_I_BADCELL] = i * ny + j
                return _BAD_VOID
    if has_k:
        for i in range(nx + 1):
            for j in range(ny):
                if not ku[i, j] >= 0.0:
                    return _BAD_INPUT
        for i in range(nx):
            for j in range(ny):
                if not kv[i, j] >= 0.0:
                    return _BAD_INPUT
    # ---- 3. advection and viscous tendencies from the old velocities and void fraction
    _y_face_void_fraction(eps_old, distributor, ey_old)
    _y_face_void_fraction(eps_new, distributor, ey_new)
    _momentum_tendency(nx, ny, dx, dy, nu, scheme, u, v, eps_old, ey_old, tend_u, tend_v)
    # ---- 4. predictor R and the projection weights
    inv_rho = 1.0 / rho
    dtk = dt * inv_rho
    for i in range(1, nx):
        for j in range(ny):
            ef_old = 0.5 * (eps_old[i - 1, j] + eps_old[i, j])
            ef_new = 0.5 * (eps_new[i - 1, j] + eps_new[i, j])
            r = ef_old * u[i, j] + dt * (tend_u[i, j] - fu[i, j] * inv_rho)
            w = ef_new if model_a else 1.0
            if has_k:
                r += dtk * ku[i, j] * u[i, j]
                alpha = ef_new / (ef_new + dtk * ku[i, j])
            else:
                alpha = 1.0
            mu_s[i, j] = alpha * r
            cu[i, j] = alpha * w
    for j in range(ny):
        mu_s[0, j] = 0.0
        mu_s[nx, j] = 0.0
        cu[0, j] = 0.0
        cu[nx, j] = 0.0
    for i in range(nx):
        for j in range(ny):
            ef_old = ey_old[i, j]
            ef_new = ey_new[i, j]
            r = (ef_old * v[i, j] + dt * (tend_v[i, j] - fv[i, j] * inv_rho)
                 - dt * ef_new * gravity)
            w = ef_new if model_a else 1.0
            if has_k:
                r += dtk * kv[i, j] * v[i, j]
                alpha = ef_new / (ef_new + dtk * kv[i, j])
            else:
                alpha = 1.0
            mv_s[i, j] = alpha * r
            cv[i, j] = alpha * w
    # ---- 5. (re)factorise the pressure matrix if its coefficients changed
    code = factorise_if_changed(nx, ny, dx, dy, cu, cv, cu_fac, cv_fac, band, invdiag,
                                numbering, factor_state, info)
    if code != _OK:
        return code
    # ---- 6.-9. pressure, corrected fluxes, continuity check, velocities
    return project(nx, ny, dx, dy, dt, rho, U, rtol, eps_old, eps_new, ey_new, mu_s, mv_s,
                   cu, cv, band, invdiag, ra, rb, numbering, u_out, v_out, p_out, info)


# --------------------------------------------------------------------------- solver

class GasSolver:
    """Advances a :class:`GasState` by one gas step at a time (see the module docstring).

    Parameters are SI: ``density`` kg/m^3, ``viscosity`` Pa s, ``superficial_velocity`` U
    (m/s; the domain mean of eps v), ``gravity`` m/s^2 acting in -y, ``time_step`` s.
    ``scheme`` is ``"vanleer"`` (default) or ``"upwind"``; ``formulation`` ``"A"`` (default)
    or ``"B"``; ``residual_tolerance`` the relative continuity residual at which a step is
    refused with :class:`PressureSolveError`.

    ``distributor_pressure_drop`` (Pa, on a grid with a ``distributor`` only): a porous plate
    at the floor face whose pressure drop is this at the superficial velocity U and linear in
    each column's flux (``dp_i = distributor_pressure_drop * eps v / U``). It acts on the gas
    as an implicit resistance at the faces j = 0, like a drag with no particle, and spreads
    the gas evenly over the columns as a real distributor does (without it the gas channels
    through one loose column and the rest of the bed rests on the floor). Its mean is
    reported as :attr:`GasState.distributor_pressure_drop`; the bed's own pressure drop is
    ``(G - rho g <eps>) H`` minus it.

    :meth:`step` returns a new state and leaves its argument untouched. The solver keeps
    only workspace and the last factorisation (a cache: results do not depend on it), so a
    state saved with :meth:`GasState.state_dict` continues bit-identically in a new solver.
    """

    def __init__(self, grid: GasGrid, density: float = 1.205, viscosity: float = 1.8e-5,
                 superficial_velocity: float = 6.0, gravity: float = 9.81,
                 time_step: float = 5e-5, *, formulation: str = "A", scheme: str = "vanleer",
                 residual_tolerance: float = 1e-9, distributor_pressure_drop: float = 0.0):
        if not (np.isfinite(distributor_pressure_drop) and distributor_pressure_drop >= 0):
            raise InputError("distributor pressure drop must be finite and non-negative, "
                             f"got {distributor_pressure_drop}")
        if distributor_pressure_drop > 0 and not grid.distributor:
            raise InputError("a distributor pressure drop needs a grid with a distributor "
                             "(a bed on a floor)")
        if distributor_pressure_drop > 0 and not superficial_velocity > 0:
            raise InputError("a distributor pressure drop needs a positive superficial velocity")
        for name, val in (("density", density), ("viscosity", viscosity),
                          ("time_step", time_step), ("residual_tolerance", residual_tolerance)):
            if not (np.isfinite(val) and val > 0):
                raise InputError(f"gas solver {name} must be positive and finite, got {val}")
        if not (np.isfinite(superficial_velocity) and np.isfinite(gravity)):
            raise InputError("gas solver superficial_velocity and gravity must be finite")
        if formulation not in FORMULATIONS:
            raise InputError(f"gas formulation must be one of {FORMULATIONS}, got {formulation!r}")
        if scheme not in SCHEMES:
            raise InputError(f"advection scheme must be one of {tuple(SCHEMES)}, got {scheme!r}")
        self.grid = grid
        self.density = float(density)
        self.viscosity = float(viscosity)
        self.superficial_velocity = float(superficial_velocity)
        self.gravity = float(gravity)
        self.time_step = float(time_step)
        self.formulation = formulation
        self.scheme = scheme
        self.residual_tolerance = float(residual_tolerance)
        self.distributor_pressure_drop = float(distributor_pressure_drop)
        nx, ny = grid.nx, grid.ny
        n = nx * ny
        self._work = GasWorkspace(
            mu_s=np.zeros(grid.u_shape), mv_s=np.zeros(grid.v_shape),
            cu=np.zeros(grid.u_shape), cv=np.zeros(grid.v_shape),
            cu_fac=np.zeros(grid.u_shape), cv_fac=np.zeros(grid.v_shape),
            band=np.zeros((n, 2 * nx + 1)), invdiag=np.zeros(n), ra=np.zeros(n),
            rb=np.zeros(n), numbering=cell_numbering(nx, ny),
            tend_u=np.zeros(grid.u_shape), tend_v=np.zeros(grid.v_shape),
            ey_old=np.zeros(grid.v_shape), ey_new=np.zeros(grid.v_shape),
            factor_state=np.zeros(1, dtype=np.int64), info=np.zeros(_INFO_SIZE))
        self._zero_u = np.zeros(grid.u_shape)
        self._zero_v = np.zeros(grid.v_shape)
        #: number of factorisations done (diagnostic)
        self.factorisations = 0

    @classmethod
    def from_config(cls, case, *, distributor: bool = False, **kwargs) -> "GasSolver":
        """A solver for a :class:`cfbmarkov.config.CaseConfig` (Table 1 values);
        ``distributor``: the gas enters a bed on a floor at y = 0 (see :mod:`.grid`), through
        a plate with the case's ``riser.distributor_pressure_drop``."""
        if distributor:
            kwargs.setdefault("distributor_pressure_drop", case.riser.distributor_pressure_drop)
        elif case.riser.distributor_pressure_drop > 0:
            raise InputError(f"riser.distributor_pressure_drop "
                             f"{case.riser.distributor_pressure_drop:g} Pa: the periodic riser "
                             "has no distributor (the plate is a bed's on a floor, "
                             "bottom_wall=True in Python); leave it out")
        return cls(GasGrid.from_config(case, distributor=distributor), density=case.gas.density,
                   viscosity=case.gas.viscosity,
                   superficial_velocity=case.gas.superficial_velocity,
                   gravity=case.riser.gravity, time_step=case.numerics.cfd_time_step, **kwargs)

    @property
    def kinematic_viscosity(self) -> float:
        return self.viscosity / self.density

    def stability_limit(self, state: GasState) -> float:
        """:func:`gas_stability_limit` at the state's largest |u| and |v| (s)."""
        return gas_stability_limit(self.grid, self, (np.max(np.abs(state.u)), np.max(np.abs(state.v))))

    # ----------------------------------------------------------------- helpers
    def _parameters(self) -> GasParams:
        g = self.grid
        return GasParams(nx=g.nx, ny=g.ny, dx=g.dx, dy=g.dy, dt=self.time_step,
                         rho=self.density, nu=self.kinematic_viscosity, gravity=self.gravity,
                         U=self.superficial_velocity, model_a=self.formulation == "A",
                         scheme=SCHEMES[self.scheme], rtol=self.residual_tolerance,
                         distributor=g.distributor)

    def _field(self, arr, shape, name) -> np.ndarray:
        a = np.ascontiguousarray(arr, dtype=np.float64)
        if a.shape != shape:
            raise InputError(f"{name} must have shape {shape}, got {a.shape}")
        return a

    def _void_fraction(self, eps) -> np.ndarray:
        e = self._field(eps, self.grid.cell_shape, "void fraction")
        if not (np.all(np.isfinite(e)) and e.min() > 0.0 and e.max() <= 1.0 + 1e-12):
            raise InputError(
                f"void fraction must lie in (0, 1], got values in [{np.nanmin(e):g}, {np.nanmax(e):g}]")
        return e

    def initial_state(self, void_fraction) -> GasState:
        """Plug flow at U: u = 0 and eps_face v = U on every y-face (so v = U / eps_face).

        This field satisfies continuity for a steady eps and has the right mean flux; the
        no-slip walls act from the first step on. ``p`` and ``G`` start at zero (they are
        outputs of a step, not inputs).
        """
        e = self._void_fraction(void_fraction).copy()
        v = self.superficial_velocity / self.grid.y_face_void_fraction(e)
        return GasState(u=np.zeros(self.grid.u_shape), v=v, p=np.zeros(self.grid.cell_shape),
                        void_fraction=e)

    def step(self, state: GasState, void_fraction, drag_force_u, drag_force_v,
             drag_jacobian_u=None, drag_jacobian_v=None) -> GasState:
        """Advance ``state`` by one time step to the void fraction ``void_fraction``.

        Parameters
        ----------
        state : GasState
            The gas now (not modified).
        void_fraction : array_like (nx, ny)
            eps after the step, in (0, 1].
        drag_force_u, drag_force_v : array_like (nx+1, ny), (nx, ny)
            Drag force per unit volume exerted by the gas on the particles, on the x- and
            y-faces, N/m^3; the gas feels its reaction.
        drag_jacobian_u, drag_jacobian_v : array_like, same shapes, optional
            K = d f / d u_gas >= 0, kg/(m^3 s), for a semi-implicit drag (the drag the gas
            feels becomes ``f + K (u^{n+1} - u^n)``). Both or neither.

        Returns
        -------
        GasState
            The gas after the step.

        Raises
        ------
        InputError
            Wrong shapes, a void fraction outside (0, 1], a negative or non-finite jacobian,
            or a time step above the stability limit (:func:`gas_stability_limit`).
        PressureSolveError
            The pressure equation could not be solved to ``residual_tolerance`` (or its
            matrix is not positive definite, or the state's velocity is not finite).
        """
        g = self.grid
        eps_new = self._field(void_fraction, g.cell_shape, "void fraction")
        fu = self._field(drag_force_u, g.u_shape, "drag_force_u")
        fv = self._field(drag_force_v, g.v_shape, "drag_force_v")
        if (drag_jacobian_u is None) != (drag_jacobian_v is None):
            raise InputError("give both drag_jacobian_u and drag_jacobian_v, or neither")
        has_k = drag_jacobian_u is not None
        if has_k:
            ku = self._field(drag_jacobian_u, g.u_shape, "drag_jacobian_u")
            kv = self._field(drag_jacobian_v, g.v_shape, "drag_jacobian_v")
        else:
            ku, kv = self._zero_u, self._zero_v
        plate = None
        if self.distributor_pressure_drop > 0:
            # K v = dp_d (eps_face v / U) / dy on the floor faces, fully implicit:
            # explicit part K v^n here, K (v^{n+1} - v^n) through the jacobian
            plate = (self.distributor_pressure_drop / (self.superficial_velocity * g.dy)
                     * g.y_face_void_fraction(eps_new)[:, 0])
            fv = fv.copy()
            fv[:, 0] += plate * state.v[:, 0]
            kv = kv.copy()
            kv[:, 0] += plate
            has_k = True
        u_new = np.empty(g.u_shape)
        v_new = np.empty(g.v_shape)
        p_new = np.empty(g.cell_shape)
        info = self._work.info
        code = _step_kernel(self._parameters(),
                            GasStepFields(state.u, state.v, state.void_fraction, eps_new, fu, fv,
                                          ku, kv, has_k),
                            GasStepOutput(u_new, v_new, p_new), self._work)
        if code != _OK:
            self._raise(code, info, eps_new, fu, fv)
        if info[_I_REFACTORED]:
            self.factorisations += 1
        return GasState(
            u=u_new, v=v_new, p=p_new, void_fraction=eps_new.copy(),
            driving_pressure_gradient=float(info[_I_G]),
            pressure_residual=float(info[_I_RES_REL]),
            continuity_defect=float(info[_I_DEFECT]),
            time=state.time + self.time_step, steps=state.steps + 1,
            distributor_pressure_drop=(0.0 if plate is None
                                       else float(np.mean(plate * v_new[:, 0]) * g.dy)),
            diagnostics={"continuity_residual": float(info[_I_RES_ABS]),
                         "flux_error": float(info[_I_FLUXERR]),
                         "max_u": float(info[_I_UMAX]), "max_v": float(info[_I_VMAX]),
                         "dt_max": float(info[_I_DTMAX])})

    def _raise(self, code, info, eps_new, fu, fv):
        dt = self.time_step
        if code == _UNSTABLE and not (np.isfinite(info[_I_UMAX]) and np.isfinite(info[_I_VMAX])):
            raise PressureSolveError("the gas velocity of the state is not finite (the run diverged)")
        if code == _UNSTABLE:
            raise InputError(
                f"gas time step {dt:.6g} s exceeds the stability limit {info[_I_DTMAX]:.6g} s "
                f"(advective limit {info[_I_DTADV]:.6g} s at max |u| = {info[_I_UMAX]:.6g} m/s, "
                f"max |v| = {info[_I_VMAX]:.6g} m/s, Courant {ADVECTIVE_COURANT}; "
                f"viscous limit {info[_I_DTVIS]:.6g} s): give a smaller "
                "numerics.cfd_time_step, or fewer numerics.cfd_cells")
        if code == _BAD_VOID:
            k = int(info[_I_BADCELL])
            i, j = divmod(k, self.grid.ny)
            raise InputError(
                f"void fraction must lie in (0, 1]; cell ({i}, {j}) has {float(eps_new[i, j])!r}")
        if code == _BAD_INPUT:
            raise InputError("drag_jacobian must be finite and non-negative")
        if code == _NOT_SPD:
            raise PressureSolveError(
                f"pressure matrix not positive definite at unknown {int(info[_I_PIVOT])} "
                "(non-finite void fraction or drag jacobian?)")
        if code == _BAD_FLUX:
            raise PressureSolveError("driving pressure gradient undefined (zero flux response)")
        if code == _RESIDUAL:
            finite = bool(np.all(np.isfinite(fu)) and np.all(np.isfinite(fv)))
            raise PressureSolveError(
                f"pressure solve failed: relative continuity residual {info[_I_RES_REL]:.3g} "
                f"exceeds {self.residual_tolerance:.3g} (absolute {info[_I_RES_ABS]:.3g} 1/s)"
                + ("" if finite else "; the drag force field is not finite"))
        raise PressureSolveError(f"gas step failed with code {code}")
