"""The linear spring-dashpot contact law with tangential history (paper Table 2;
``docs/definitions.md``, section riser); the numba form is :func:`.contact.contact_force`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from cfbmarkov.errors import InputError


def damping_ratio(restitution: float) -> float:
    """|ln e| / sqrt(pi^2 + ln^2 e): the damping ratio of a linear oscillator that rebounds
    with coefficient of restitution ``e`` (0 for e = 1)."""
    le = math.log(restitution)
    return abs(le) / math.sqrt(math.pi**2 + le * le)


@dataclass(frozen=True)
class ContactLaw:
    """Linear spring-dashpot normal force, tangential spring with history and Coulomb cap.

    Normal (magnitude, repulsive): ``Fn = kn*delta + eta_n*v_n`` with ``v_n`` the approach
    speed, clamped at 0 (no tensile force: when the dashpot would pull during separation the
    contact simply carries no force). ``eta_n = 2*sqrt(m_ab*kn)*|ln en|/sqrt(pi^2+ln^2 en)``.

    Tangential: spring ``delta_t`` (sum of v_t*dt over the contact, projected on the current
    tangent each step), ``Ft = -kt*delta_t - eta_t*v_t`` with
    ``eta_t = 2*sqrt(2/7*m_ab*kt)*|ln et|/sqrt(pi^2+ln^2 et)``; if ``|Ft| > mu*Fn`` it is
    scaled to ``mu*Fn`` and the spring reset to ``-(Ft + eta_t*v_t)/kt`` (LAMMPS
    gran/hooke/history). ``m_ab`` is the reduced mass; against a wall it is the particle mass.

    ``mass`` (optional) is a reference particle mass, set by :meth:`from_config` from the
    diameter and density, used as the default of :meth:`contact_times`.
    """

    kn: float = 10000.0
    kt: float = 2857.0
    en: float = 0.97
    et: float = 0.33
    mu: float = 0.1
    mass: float | None = None

    def __post_init__(self):
        for name in ("kn", "kt"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"contact law: {name} must be a positive number, got {v!r}")
        for name in ("en", "et"):
            v = getattr(self, name)
            if not (0 < v <= 1):
                raise InputError(f"contact law: {name} must be in (0, 1], got {v!r}")
        if not (math.isfinite(self.mu) and self.mu >= 0):
            raise InputError(f"contact law: mu must be >= 0, got {self.mu!r}")
        if self.mass is not None and not (math.isfinite(self.mass) and self.mass > 0):
            raise InputError(f"contact law: mass must be positive, got {self.mass!r}")

    @classmethod
    def from_config(cls, config, diameter: float | None = None,
                    density: float | None = None) -> ContactLaw:
        """From a :class:`cfbmarkov.config.ContactConfig`; with ``diameter`` (m) and
        ``density`` (kg/m^3) the sphere mass is kept as the reference mass."""
        mass = None
        if diameter is not None or density is not None:
            if diameter is None or density is None:
                raise InputError("contact law: give both diameter and density, or neither")
            if not (diameter > 0 and density > 0):
                raise InputError(
                    f"contact law: diameter and density must be positive, got {diameter!r}, "
                    f"{density!r}")
            mass = density * math.pi * diameter**3 / 6.0
        return cls(kn=config.normal_stiffness, kt=config.tangential_stiffness,
                   en=config.normal_restitution, et=config.tangential_restitution,
                   mu=config.friction_coefficient, mass=mass)

    # damping coefficients: eta = c * sqrt(m_ab)
    @property
    def normal_damping_factor(self) -> float:
        """c_n with eta_n = c_n*sqrt(m_ab)."""
        return 2.0 * math.sqrt(self.kn) * damping_ratio(self.en)

    @property
    def tangential_damping_factor(self) -> float:
        """c_t with eta_t = c_t*sqrt(m_ab) (includes the 2/7 of m'_ab)."""
        return 2.0 * math.sqrt(2.0 / 7.0 * self.kt) * damping_ratio(self.et)

    def normal_damping(self, m_ab: float) -> float:
        return self.normal_damping_factor * math.sqrt(m_ab)

    def tangential_damping(self, m_ab: float) -> float:
        return self.tangential_damping_factor * math.sqrt(m_ab)

    def contact_time(self, m_ab: float) -> float:
        """Duration of a linear spring-dashpot normal contact of reduced mass ``m_ab``:
        pi / sqrt(kn/m_ab - (eta_n/(2 m_ab))^2)."""
        eta = self.normal_damping(m_ab)
        return math.pi / math.sqrt(self.kn / m_ab - (eta / (2.0 * m_ab)) ** 2)

    def tangential_time(self, m_ab: float) -> float:
        """Half-period of the tangential spring-dashpot of a contact of reduced mass
        ``m_ab`` (effective mass 2/7 m_ab): pi / sqrt(kt/m_t - (eta_t/(2 m_t))^2), or inf
        where the dashpot damps it past oscillating. With kt = 2/7 kn (the default) it is
        the normal contact's duration but for the damping; a stiffer tangential spring
        oscillates faster than the normal contact lasts, and the step must resolve it
        too."""
        m_t = 2.0 / 7.0 * m_ab
        eta = self.tangential_damping(m_ab)
        omega2 = self.kt / m_t - (eta / (2.0 * m_t)) ** 2
        return math.pi / math.sqrt(omega2) if omega2 > 0 else math.inf

    def contact_times(self, mass: float | None = None) -> tuple[float, float]:
        """(particle-particle, particle-wall) contact durations for equal particles of
        ``mass`` (default: the reference mass)."""
        m = self.mass if mass is None else mass
        if m is None:
            raise InputError("contact law: no particle mass given")
        return self.contact_time(0.5 * m), self.contact_time(m)


class ContactTimes(NamedTuple):
    """Contact durations, or steps per contact, of the lightest particle.

    Attributes
    ----------
    particle_particle : float
        Of a particle-particle contact (s, or steps).
    particle_wall : float
        Of a particle-wall contact (s, or steps).
    """

    particle_particle: float
    particle_wall: float


def too_coarse_a_step(worst: float, time_step: float, message: str) -> str:
    """The refusal of a DEM step that resolves a contact in fewer than 5 steps, naming the
    settings to change and the largest step that would do.

    Parameters
    ----------
    worst : float
        Steps in the shortest contact (:func:`contact_resolution`).
    time_step : float
        The DEM step, s.
    message : str
        :func:`contact_resolution`'s sentence.

    Returns
    -------
    str
        The message, ending with the fix: ``numerics.dem_time_step`` at most a fifth of the
        shortest contact (a tenth recommended), or softer contacts.
    """
    shortest = worst * time_step
    return (f"{message}; at least 5 are needed (10 or more recommended): "
            f"numerics.dem_time_step at most {shortest / 5:.3g} s ({shortest / 10:.3g} s "
            "recommended; cfd_time_step a whole multiple of it), or softer contacts "
            "(contact.normal_stiffness and tangential_stiffness)")


def contact_resolution(law: ContactLaw, mass: float, time_step: float) -> tuple[float, str]:
    """How many DEM steps a contact of the lightest particle lasts, and a sentence saying it.

    Parameters
    ----------
    law : ContactLaw
        The contact law.
    mass : float
        The lightest particle's mass, kg.
    time_step : float
        The DEM step, s.

    Returns
    -------
    worst : float
        The fewer steps of a particle-particle and a particle-wall contact, or of the
        tangential spring's half-period where that is shorter
        (:meth:`ContactLaw.tangential_time`).
    message : str
        ``DEM time step ... resolves a contact in ... steps (particle-particle, ...) and ...``.
    """
    pp, pw = law.contact_times(mass)
    spp, spw = pp / time_step, pw / time_step
    message = (f"DEM time step {time_step:g} s resolves a contact in {spp:.2f} steps "
               f"(particle-particle, t_c = {pp:.4g} s) and {spw:.2f} steps (particle-wall, "
               f"t_c = {pw:.4g} s)")
    tangential = min(law.tangential_time(0.5 * mass), law.tangential_time(mass))
    worst = min(spp, spw)
    if tangential / time_step < worst:      # a tangential spring stiffer than 2/7 kn
        worst = tangential / time_step
        message += (f", and the tangential spring's half-period in {worst:.2f} steps "
                    f"({tangential:.4g} s; kt = {law.kt:g} N/m against kn = {law.kn:g} N/m)")
    return worst, message
