"""The wall contacts and the pair contacts use one contact law (contact.contact_force).

A wall is a partner of infinite mass at rest, without spin, whose surface is the wall
plane: particle i touching the left wall with overlap d feels exactly what it feels from a
particle j with 1/m_j = 0, R_j/I_j = 0, placed so that the two overlap by d along -x. The
damping then uses m_ab = m_i in both (1/sqrt(1/m_i + 0)). The geometry below is dyadic, so
that the pair's normal is exactly (-1, 0) and the two overlaps are exactly equal. The law
takes the wall's tangential quantities as floats (1D) and the pair's as (x, y); for an
axis-aligned normal the 2D projection and the zero component only add zeros, so the
results must agree bit for bit, except at the Coulomb cap: there the wall sets its force
to exactly +-mu*Fn where the pair scales its force vector by mu*Fn/|Ft| (equal up to
round-off).
"""

import math

import numpy as np
import pytest

import cfbmarkov  # noqa: F401
from cfbmarkov.simulate.dem import ContactLaw
from cfbmarkov.simulate.dem.contact import pair_forces
from cfbmarkov.simulate.dem.integrate import fused_step
from cfbmarkov.simulate.dem.layout import DEMParams

R = 2.0**-11  # radius, m (~0.49 mm)
RHO = 2600.0
M = RHO * math.pi * (2 * R) ** 3 / 6
INV_I = 1.0 / (0.1 * M * (2 * R) ** 2)
GAP = 0.25  # centre distance of the mirror pair (a power of two: n is exact)
LAW = ContactLaw()
DT = 5e-6


def _params(floor):
    return DEMParams(
        dt=DT, width=1.0, height=1.0, gravity=0.0, kn=LAW.kn, kt=LAW.kt, inv_kt=1.0 / LAW.kt,
        mu=LAW.mu, etan_pp=0.0, etat_pp=0.0, etan_pw=0.0, etat_pw=0.0,
        cn=LAW.normal_damping_factor, ct=LAW.tangential_damping_factor, skin=3e-4,
        cell_w=1.0, cell_h=1.0, rmax=R, max_overlap=0.1, t0=0.0, ncx=1, ncy=1,
        periodic=False, floor=floor, mono=False)


def _record(x, y, vx, vy, u, radius, inv_m, r_over_i):
    return [x, y, vx, vy, u, radius, inv_m, r_over_i]


# wall -> (where particle i sits for the wall case, unit normal from i into the wall)
WALLS = {"left": ((R, 0.5), (-1.0, 0.0)), "right": ((1.0 - R, 0.5), (1.0, 0.0)),
         "floor": ((0.5, R), (0.0, -1.0))}


def _wall_path(wall, overlap, vel, spring, steps):
    """Steps of fused_step for one particle against ``wall`` (positions held fixed)."""
    (x, y), (nx, ny) = WALLS[wall]
    x += nx * overlap  # push into the wall by the overlap
    y += ny * overlap
    prm = _params(floor=wall == "floor")
    wh = np.zeros((1, 3))
    wh[0, {"left": 0, "right": 1, "floor": 2}[wall]] = spring
    out = []
    vx, vy, u = vel
    for _ in range(steps):
        st = np.array([_record(x, y, vx, vy, u, R, 1.0 / M, R * INV_I)])
        so = np.zeros_like(st)
        res = fused_step(st, so, np.array([[x, y, 0.0, 0.0]]), wh, np.zeros(1, np.int64),
                         np.zeros(2, np.int64), np.zeros(2, np.int64), np.zeros(1, np.int64),
                         np.zeros((1, 3)), np.zeros(1, np.int8), np.zeros(1, np.int8), prm)
        assert res[2] == 0
        vx, vy, u = so[0, 2], so[0, 3], so[0, 4]
        out.append((vx, vy, u, wh[0].sum()))
    return np.array(out)


def _pair_path(wall, overlap, vel, spring, steps):
    """The same particle in mid-domain against an infinite-mass partner at rest."""
    _, (nx, ny) = WALLS[wall]
    x = y = 0.5
    rj = GAP - R + overlap
    prm = _params(floor=False)
    springs = np.zeros((1, 2))
    # the pair's spring lies along the tangent: y for the side walls, x for the floor
    springs[0, 1 if ny == 0.0 else 0] = spring
    pi = np.zeros(1, np.int32)
    pj = np.ones(1, np.int32)
    out = []
    vx, vy, u = vel
    for _ in range(steps):
        st = np.array([_record(x, y, vx, vy, u, R, 1.0 / M, R * INV_I),
                       _record(x + GAP * nx, y + GAP * ny, 0.0, 0.0, 0.0, rj, 0.0, 0.0)])
        pf = np.zeros((1, 3))
        assert pair_forces(st, 1, pi, pj, springs, pf, prm, np.zeros(1, np.int64),
                           np.zeros(1, np.int64))[0] == 0
        so = np.zeros_like(st)
        aux = np.array([[x, y, 0.0, 0.0], [x + GAP * nx, y + GAP * ny, 0.0, 0.0]])
        fused_step(st, so, aux, np.zeros((2, 3)), np.zeros(2, np.int64),
                   np.array([0, 1, 1]), np.array([0, 0, 1]), np.zeros(1, np.int64), pf,
                   np.zeros(2, np.int8), np.zeros(2, np.int8), prm)
        vx, vy, u = so[0, 2], so[0, 3], so[0, 4]
        out.append((vx, vy, u, springs[0].sum()))
    return np.array(out)


@pytest.mark.parametrize("wall", sorted(WALLS))
@pytest.mark.parametrize("vel,spring", [
    ((0.0, 0.0, 0.0), 0.0),             # at rest, spring only from the overlap: none
    ((-0.3, 0.02, 0.01), 1e-9),         # approaching, sticking
    ((0.4, -0.015, 0.03), -2e-9),       # separating
])
def test_wall_is_an_infinite_mass_mirror_partner(wall, vel, spring):
    (_, _), (nx, ny) = WALLS[wall]
    # velocities given as (normal, tangential, spin) in the wall's frame -> x, y
    vn, vt, u = vel
    v = (vn * -nx + vt * ny, vn * -ny - vt * nx, u)  # vn > 0: moving away from the wall
    wall_run = _wall_path(wall, 2.0**-17, v, spring, 20)
    pair_run = _pair_path(wall, 2.0**-17, v, spring, 20)
    np.testing.assert_array_equal(wall_run, pair_run)


@pytest.mark.parametrize("wall", sorted(WALLS))
def test_sliding_contact_agrees_to_round_off(wall):
    """At the Coulomb cap the wall sets Ft = +-mu*Fn exactly, the pair scales its vector."""
    (_, _), (nx, ny) = WALLS[wall]
    v = (-0.05 * -nx + 1.0 * ny, -0.05 * -ny - 1.0 * nx, 0.0)  # fast tangential sliding
    wall_run = _wall_path(wall, 2.0**-17, v, 0.0, 10)
    pair_run = _pair_path(wall, 2.0**-17, v, 0.0, 10)
    np.testing.assert_allclose(wall_run, pair_run, rtol=1e-13, atol=1e-22)
    # the cap was active: without it the first step's spring would be +-|v_t| dt = +-dt
    assert abs(abs(wall_run[0, 3]) - DT) > 0.01 * DT
