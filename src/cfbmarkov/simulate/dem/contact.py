"""The contact law of the 2D DEM engine and the pair-force kernel (numba).

One function, :func:`contact_force`, holds the law; it is inlined (``inline="always"``)
into both the pair loop (:func:`pair_forces`) and the wall loop
(:func:`cfbmarkov.simulate.dem.integrate.fused_step`). A wall contact is the contact with a
mirror particle of infinite mass at rest, without spin: the normal points from the particle
into the wall, the relative velocity is the particle's own contact-point velocity, and the
damping uses ``m_ab = m``.

The law is the linear spring-dashpot with tangential history of the paper's Table 2
(:class:`cfbmarkov.simulate.dem.law.ContactLaw`; ``docs/definitions.md``, section riser),
with the Coulomb cap of LAMMPS ``pair_style gran/hooke/history``.

Pair forces: a step computes every pair force once (:func:`pair_forces`, into ``pf``);
each particle then sums its pairs' forces in a fixed order inside the fused integration, so
the two members of a pair get exactly opposite forces (one spring per contact, so there are
no two copies to keep consistent).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from cfbmarkov.simulate.dem.layout import BAD_OVERLAP

#: fast-math flags of the force kernels: no nnan/ninf (the NaN checks must work) and no
#: reassoc (results must not depend on how the compiler groups a sum)
FASTMATH = {"contract", "arcp", "afn"}


@njit(cache=True, inline="always", fastmath=FASTMATH)
def contact_force(delta, vn, nx, ny, vtx, vty, hx, hy, etan, etat, prm, axis_tangent):
    """Force of one contact: linear spring-dashpot, tangential spring, Coulomb cap.

    Normal force ``Fn = max(kn*delta + eta_n*v_n, 0)`` (repulsive, no tension). Tangential
    spring ``h <- h + v_t*dt``, projected on the current tangent (the contact may have
    turned); trial force ``Ft = -kt*h - eta_t*v_t``; if ``|Ft| > mu*Fn`` it is scaled to
    ``mu*Fn`` and the spring reset to ``-(Ft + eta_t*v_t)/kt``, so that it holds the force
    the cap allows.

    Parameters
    ----------
    delta : float
        Overlap, m (> 0 in contact).
    vn : float
        Approach speed along the normal (relative velocity dotted with ``n``), m/s.
    nx, ny : float
        Unit normal from the particle to its partner (into the wall for a wall), -.
    vtx, vty : float
        Tangential relative velocity of the contact point (normal part removed), m/s.
    hx, hy : float
        Tangential spring before the step, m.
    etan, etat : float
        Normal and tangential damping coefficients eta_n, eta_t of this contact, kg/s.
    prm : DEMParams
        Uses ``kn``, ``kt``, ``inv_kt`` (N/m, m/N), ``mu`` (-), ``dt`` (s).
    axis_tangent : bool
        The tangent is a coordinate axis and only its component of ``vt`` and ``h`` is
        non-zero (a wall; pass a constant). The cap then sets that component to exactly
        ``+-mu*Fn``, which the scaling ``Ft*mu*Fn/|Ft|`` equals only up to round-off.
        Everything else is exact for such a tangent (the projection only adds zeros).

    Returns
    -------
    fn : float
        Normal force magnitude, N (>= 0); the force on the particle is ``-fn*n``.
    ftx, fty : float
        Tangential force on the particle, N.
    hx, hy : float
        Tangential spring after the step, m.

    References
    ----------
    Table 2 of the paper (contact law and its values); ``docs/definitions.md`` (riser).
    Damping ``eta_n = 2 sqrt(m_ab kn)|ln en|/sqrt(pi^2 + ln^2 en)``, ``eta_t`` the same with
    ``2/7 m_ab``, ``kt``, ``et`` (:class:`~cfbmarkov.simulate.dem.law.ContactLaw`).
    Coulomb cap and spring rescaling as in LAMMPS ``pair_style gran/hooke/history``
    (Silbert et al., Phys. Rev. E 64 (2001) 051302; LAMMPS documentation).
    """
    kt = prm.kt
    fn = prm.kn * delta + etan * vn
    if fn < 0.0:
        fn = 0.0
    dt = prm.dt
    hx = hx + vtx * dt
    hy = hy + vty * dt
    hn = hx * nx + hy * ny
    hx -= hn * nx
    hy -= hn * ny
    ftx = -kt * hx - etat * vtx
    fty = -kt * hy - etat * vty
    ft2 = ftx * ftx + fty * fty
    fc = prm.mu * fn
    if ft2 > fc * fc:
        if axis_tangent:
            ftx = min(max(ftx, -fc), fc)
            fty = min(max(fty, -fc), fc)
        else:
            sc = fc / math.sqrt(ft2)
            ftx *= sc
            fty *= sc
        inv_kt = prm.inv_kt
        hx = -(ftx + etat * vtx) * inv_kt
        hy = -(fty + etat * vty) * inv_kt
    return fn, ftx, fty, hx, hy


@njit(parallel=True, cache=True, error_model="numpy", fastmath=FASTMATH)
def pair_forces(st, npairs, pi, pj, springs, pf, prm):
    """Force of every listed pair (i < j), computed once.

    Branch-free apart from the contact test (contact or not, capped or not are selects),
    so the loop can use SIMD.

    Parameters
    ----------
    st : float64 (N, 8)
        Particle records (see :mod:`.layout`).
    npairs : int
        Number of pairs in the list.
    pi, pj : int32 (>= npairs,)
        First and second member of each pair.
    springs : float64 (>= npairs, 2)
        Tangential springs (m), updated in place (cleared for pairs not in contact).
    pf : float64 (>= npairs, 3)
        Output: ``pf[p] = (fx, fy, c)`` with (fx, fy) the force on i (N; j gets the
        opposite) and ``c = n x Ft`` (N), so that the torque on either particle is its
        radius times c.
    prm : DEMParams

    Returns
    -------
    int
        Number of pairs overlapping by more than ``max_overlap*(R_i + R_j)`` (blow-up).
    """
    H = prm.height
    halfH = 0.5 * H
    etan_pp = prm.etan_pp
    etat_pp = prm.etat_pp
    cn = prm.cn
    ct = prm.ct
    ovl = prm.max_overlap
    periodic = prm.periodic
    mono = prm.mono
    nbad = 0
    for p in prange(npairs):
        i = pi[p]
        j = pj[p]
        dx = st[j, 0] - st[i, 0]
        dy = st[j, 1] - st[i, 1]
        if periodic:
            if dy > halfH:
                dy -= H
            elif dy < -halfH:
                dy += H
        rs = st[i, 5] + st[j, 5]
        r2 = dx * dx + dy * dy
        if r2 >= rs * rs:
            if springs[p, 0] != 0.0 or springs[p, 1] != 0.0:
                springs[p, 0] = 0.0
                springs[p, 1] = 0.0
            pf[p, 0] = 0.0
            pf[p, 1] = 0.0
            pf[p, 2] = 0.0
            continue
        r = math.sqrt(r2)
        inv_r = 1.0 / r
        nx = dx * inv_r
        ny = dy * inv_r
        delta = rs - r
        if delta > ovl * rs:
            nbad += 1
        wsum = st[i, 4] + st[j, 4]
        vrx = (st[i, 2] - st[j, 2]) - wsum * ny
        vry = (st[i, 3] - st[j, 3]) + wsum * nx
        vn = vrx * nx + vry * ny
        vtx = vrx - vn * nx
        vty = vry - vn * ny
        if mono:
            etan = etan_pp
            etat = etat_pp
        else:
            sm = 1.0 / math.sqrt(st[i, 6] + st[j, 6])
            etan = cn * sm
            etat = ct * sm
        fn, ftx, fty, hx, hy = contact_force(delta, vn, nx, ny, vtx, vty, springs[p, 0],
                                             springs[p, 1], etan, etat, prm, False)
        springs[p, 0] = hx
        springs[p, 1] = hy
        pf[p, 0] = ftx - fn * nx
        pf[p, 1] = fty - fn * ny
        pf[p, 2] = nx * fty - ny * ftx
    return nbad


@njit(cache=True)
def flag_overlaps(st, npairs, pi, pj, bad, prm):
    """Mark the particles of pairs overlapping beyond the blow-up limit (after a bad step).

    Parameters
    ----------
    st : float64 (N, 8)
        Particle records.
    npairs : int
        Number of pairs.
    pi, pj : int32 (>= npairs,)
        Pair members.
    bad : int8 (N,)
        Set to ``BAD_OVERLAP`` for both members of such a pair.
    prm : DEMParams
    """
    H = prm.height
    for p in range(npairs):
        i = pi[p]
        j = pj[p]
        dx = st[j, 0] - st[i, 0]
        dy = st[j, 1] - st[i, 1]
        if prm.periodic:
            dy -= H * np.round(dy / H)
        rs = st[i, 5] + st[j, 5]
        if rs - math.sqrt(dx * dx + dy * dy) > prm.max_overlap * rs:
            bad[i] = BAD_OVERLAP
            bad[j] = BAD_OVERLAP
