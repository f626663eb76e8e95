"""Gas-particle drag law of the paper's Table 2 (``docs/definitions.md``, section riser), as numba kernels.

    beta = (1 - eps) / (eps^2 d) * (150 (1 - eps) mu / d + 1.75 rho eps |u - v|)   eps <= 0.8  (Ergun)
    beta = 3/4 C_D rho |u - v| (1 - eps) / d * eps^-2.7                            eps >  0.8  (Wen & Yu)
    C_D  = 24 / Re (1 + 0.15 Re^0.687)  (Re <= 1000),  0.44  (Re > 1000)           (Schiller-Naumann)
    Re   = rho eps |u - v| d / mu

``beta`` is in kg/(m^3 s); the drag force on one particle of volume Vp is
``beta * Vp / (1 - eps) * (u_gas - v_particle)`` and its reaction acts on the gas.

Which momentum equation this beta belongs to. With ``s = u - v`` the interstitial slip and
``U = eps * s`` the superficial one, the Ergun branch gives ``beta * s = 150 (1-eps)^2 mu U /
(eps^3 d^2) + 1.75 (1-eps) rho U^2 / (eps^3 d)``, i.e. ``beta * s`` *is* Ergun's pressure
gradient. The drag per unit volume therefore balances the whole pressure gradient, which
is the pairing of the "model B" (set I) gas equation ``-grad p - f`` with particles that
feel this drag only. In "model A" (set II, gas ``-eps grad p - f``, particles feel
``-Vp grad p`` besides the drag) the same steady bed gives ``-grad p = f / eps``: the
consistent model-A drag is ``eps * beta`` (Gidaspow's form, up to Wen & Yu's exponent,
2.65 there and 2.7 here). See :mod:`cfbmarkov.simulate.cfd.solver`.

The kernels are plain scalar ``numba.njit(cache=True)`` functions, callable from Python and
from other numba kernels (the particle loop). ``beta / (1 - eps)`` is computed without the
division so that a single particle (eps -> 1) has a finite force.
"""

from __future__ import annotations

import math

import numba as nb
from scipy.optimize import brentq

from cfbmarkov.errors import InputError

#: void fraction at and below which the Ergun branch is used
ERGUN_SWITCH_VOID_FRACTION = 0.8
#: particle Reynolds number above which C_D is constant
NEWTON_SWITCH_REYNOLDS = 1000.0
#: C_D in the Newton regime (``docs/definitions.md``, riser: the common 0.44; the paper prints 0.43)
NEWTON_DRAG_COEFFICIENT = 0.44


@nb.njit(cache=True)
def drag_coefficient(reynolds):
    """Schiller-Naumann single-particle drag coefficient C_D (-); 0.44 above Re = 1000.

    Infinite at Re = 0 (use :func:`interphase_momentum_coefficient`, which is finite there).
    """
    if reynolds > NEWTON_SWITCH_REYNOLDS:
        return NEWTON_DRAG_COEFFICIENT
    if reynolds <= 0.0:
        return math.inf
    return 24.0 / reynolds * (1.0 + 0.15 * reynolds ** 0.687)


@nb.njit(cache=True)
def particle_reynolds_number(void_fraction, slip_speed, diameter, gas_density, gas_viscosity):
    """Re = rho eps |u - v| d / mu (Table 2), -."""
    return gas_density * void_fraction * abs(slip_speed) * diameter / gas_viscosity


@nb.njit(cache=True)
def _beta_per_solid_fraction(void_fraction, slip_speed, diameter, gas_density, gas_viscosity):
    """beta / (1 - eps), kg/(m^3 s), finite at eps = 1 and at zero slip."""
    eps = void_fraction
    s = abs(slip_speed)
    if eps <= ERGUN_SWITCH_VOID_FRACTION:
        return (150.0 * (1.0 - eps) * gas_viscosity / diameter
                + 1.75 * gas_density * eps * s) / (eps * eps * diameter)
    re = gas_density * eps * s * diameter / gas_viscosity
    if re > NEWTON_SWITCH_REYNOLDS:
        cd_rho_s = NEWTON_DRAG_COEFFICIENT * gas_density * s
    else:
        # C_D * rho * |s| with C_D = 24/Re (1 + 0.15 Re^0.687), without dividing by Re
        cd_rho_s = 24.0 * gas_viscosity / (eps * diameter) * (1.0 + 0.15 * re ** 0.687)
    return 0.75 * cd_rho_s / diameter * eps ** -2.7


@nb.njit(cache=True)
def interphase_momentum_coefficient(void_fraction, slip_speed, diameter, gas_density,
                                    gas_viscosity):
    """beta of Table 2 (Ergun for eps <= 0.8, Wen & Yu above), kg/(m^3 s).

    ``slip_speed`` is |u_gas - v_particle| (m/s), ``void_fraction`` the gas fraction eps.
    """
    return (1.0 - void_fraction) * _beta_per_solid_fraction(
        void_fraction, slip_speed, diameter, gas_density, gas_viscosity)


@nb.njit(cache=True)
def particle_drag_force(void_fraction, gas_u, gas_v, particle_u, particle_v, diameter,
                        gas_density, gas_viscosity):
    """Drag force (N) on one sphere of diameter d: beta Vp / (1 - eps) (u_gas - v_p).

    Returns ``(fx, fy)``. At eps = 1 this is the single-particle drag
    C_D (pi d^2 / 4) rho |s| s / 2.
    """
    sx = gas_u - particle_u
    sy = gas_v - particle_v
    s = math.sqrt(sx * sx + sy * sy)
    vp = math.pi * diameter ** 3 / 6.0
    k = _beta_per_solid_fraction(void_fraction, s, diameter, gas_density, gas_viscosity) * vp
    return k * sx, k * sy


@nb.njit(cache=True)
def particle_drag_jacobian(void_fraction, slip_speed, diameter, gas_density, gas_viscosity):
    """beta Vp / (1 - eps) (kg/s): the force per unit slip, i.e. d(force)/d(u_gas) at fixed beta.

    Summed over the particles of a face's control volume and divided by that volume, this
    is the ``drag_jacobian`` of :meth:`GasSolver.step` for a semi-implicit drag.
    """
    vp = math.pi * diameter ** 3 / 6.0
    return _beta_per_solid_fraction(void_fraction, slip_speed, diameter, gas_density,
                                    gas_viscosity) * vp


def _gas_properties(gas) -> tuple[float, float]:
    try:
        rho, mu = float(gas.density), float(gas.viscosity)
    except AttributeError:
        raise InputError("gas must have 'density' and 'viscosity' (e.g. a GasConfig)") from None
    if not (rho > 0 and mu > 0):
        raise InputError(f"gas density and viscosity must be positive, got {rho}, {mu}")
    return rho, mu


def terminal_velocity(diameter: float, density: float, gas, gravity: float = 9.81) -> float:
    """Terminal velocity (m/s) of a single sphere falling in still gas (eps -> 1).

    Root of ``drag(u) = (rho_p - rho_g) Vp g`` with the Table 2 drag at eps = 1 (the
    Schiller-Naumann C_D, 0.44 above Re = 1000), by Brent's method. ``docs/definitions.md``: about 7 m/s for
    the paper's particles.
    """
    rho, mu = _gas_properties(gas)
    if not (diameter > 0 and density > rho and gravity > 0):
        raise InputError("terminal velocity needs d > 0, rho_p > rho_g and g > 0")
    vp = math.pi * diameter ** 3 / 6.0
    weight = (density - rho) * vp * gravity

    def balance(speed: float) -> float:
        return particle_drag_force(1.0, 0.0, speed, 0.0, 0.0, diameter, rho, mu)[1] - weight

    upper = 1.0
    while balance(upper) < 0.0:
        upper *= 2.0
        if upper > 1e6:
            raise InputError("terminal velocity not bracketed below 1e6 m/s")
    return float(brentq(balance, 0.0, upper, xtol=1e-14, rtol=8.9e-16, maxiter=200))


def minimum_fluidization_velocity(diameter: float, density: float, gas, voidage: float | None = None,
                                  gravity: float = 9.81) -> float:
    """Minimum fluidization velocity (m/s, superficial).

    With ``voidage`` given: the root of Ergun's equation
    ``(1-e)(rho_p-rho_g) g = 150 (1-e)^2 mu U / (e^3 d^2) + 1.75 (1-e) rho_g U^2 / (e^3 d)``
    (a quadratic, solved in closed form; the same balance as the Ergun branch of
    :func:`interphase_momentum_coefficient`). The paper's 0.44 m/s needs e ~ 0.36.

    Without: the Wen & Yu (1966) correlation ``Re_mf = sqrt(33.7^2 + 0.0408 Ar) - 33.7``
    (``docs/definitions.md``: about 0.55 m/s for the paper's particles).
    """
    rho, mu = _gas_properties(gas)
    if not (diameter > 0 and density > rho and gravity > 0):
        raise InputError("minimum fluidization needs d > 0, rho_p > rho_g and g > 0")
    if voidage is None:
        archimedes = rho * (density - rho) * gravity * diameter ** 3 / mu ** 2
        re_mf = math.sqrt(33.7 ** 2 + 0.0408 * archimedes) - 33.7
        return re_mf * mu / (rho * diameter)
    e = float(voidage)
    if not 0.0 < e < 1.0:
        raise InputError(f"bed voidage must lie in (0, 1), got {voidage}")
    a = 1.75 * (1.0 - e) * rho / (e ** 3 * diameter)
    b = 150.0 * (1.0 - e) ** 2 * mu / (e ** 3 * diameter ** 2)
    c = (1.0 - e) * (density - rho) * gravity
    # positive root of a U^2 + b U - c = 0, in the cancellation-free form
    return 2.0 * c / (b + math.sqrt(b * b + 4.0 * a * c))
