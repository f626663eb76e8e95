"""The contact law of the 2D DEM engine and the pair-force kernel (numba).

One plain Python function of scalars, :func:`contact_law`, holds the law; it is compiled
for the CPU as :func:`contact_force` and for the GPU as a device function
(:mod:`cfbmarkov.simulate.gpu.kernels`). On the CPU it is inlined (``inline="always"``)
into both the pair loop (:func:`pair_forces`) and the wall loop
(:func:`cfbmarkov.simulate.dem.integrate.fused_step`). A wall contact is the contact with a
mirror particle of infinite mass at rest, without spin: the normal points from the particle
into the wall, the relative velocity is the particle's own contact-point velocity, and the
damping uses ``m_ab = m``.

The law is the linear spring-dashpot with tangential history of the paper's Table 2
(:class:`cfbmarkov.simulate.dem.law.ContactLaw`; ``docs/definitions.md``, section riser),
with the Coulomb cap of LAMMPS ``pair_style gran/hooke/history``.

Pair forces: a step computes every pair force once (:func:`pair_forces`, or
:func:`pair_forces_simd` eight pairs at a time where many listed pairs touch: the same
bits; into ``pf``);
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


def contact_law(delta, vn, nx, ny, vtx, vty, hx, hy, kn, kt, inv_kt, etan, etat, mu, dt,
                wall):
    """Force of one contact: linear spring-dashpot, tangential spring, Coulomb cap.

    A plain Python function of scalars, compiled for the CPU (:func:`contact_force`,
    ``numba.njit``, inlined into the pair and wall loops) and for the GPU
    (``cuda.jit(device=True)`` in :mod:`cfbmarkov.simulate.gpu.kernels`): the one source of
    the law for both targets.

    Normal force ``Fn = max(kn*delta + eta_n*v_n, 0)`` (repulsive, no tension). Tangential
    spring ``h <- h + v_t*dt``, projected on the current tangent (a pair's contact turns);
    trial force ``Ft = -kt*h - eta_t*v_t``; if ``|Ft| > mu*Fn`` it is scaled to ``mu*Fn``
    and the spring reset to ``-(Ft + eta_t*v_t)/kt``, the spring that gives the capped force.

    A wall (``wall`` true) has a tangent along a fixed coordinate axis: its tangential
    quantities are the single components ``vty``, ``hy`` (``nx``, ``ny``, ``vtx``, ``hx``
    are not used, and the returned ``ftx``, ``hx`` are 0), there is no projection, and the
    cap sets exactly ``+-mu*Fn``, which the scaling ``Ft*mu*Fn/|Ft|`` equals only up to
    round-off.

    Parameters
    ----------
    delta : float
        Overlap, m (> 0 in contact).
    vn : float
        Approach speed: the relative velocity of the contact point along the normal, m/s.
    nx, ny : float
        Unit normal from the particle to its partner, - (pairs).
    vtx, vty : float
        Tangential relative velocity of the contact point (normal part removed), m/s.
    hx, hy : float
        Tangential spring before the step, m.
    kn, kt : float
        Normal and tangential stiffness, N/m.
    inv_kt : float
        1/kt, m/N.
    etan, etat : float
        Normal and tangential damping coefficients eta_n, eta_t of this contact, kg/s.
    mu : float
        Friction coefficient, -.
    dt : float
        Time step, s.
    wall : bool
        The partner is a wall (one tangential component, ``vty``/``hy``).

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
    fn = kn * delta + etan * vn
    if fn < 0.0:
        fn = 0.0
    fc = mu * fn
    if wall:
        h = hy + vty * dt
        ft = -kt * h - etat * vty
        if ft * ft > fc * fc:  # exactly +-fc (ft != 0 here)
            ft = math.copysign(fc, ft)
            h = -(ft + etat * vty) * inv_kt
        return fn, 0.0, ft, 0.0, h
    hx = hx + vtx * dt
    hy = hy + vty * dt
    hn = hx * nx + hy * ny
    hx = hx - hn * nx
    hy = hy - hn * ny
    ftx = -kt * hx - etat * vtx
    fty = -kt * hy - etat * vty
    ft2 = ftx * ftx + fty * fty
    if ft2 > fc * fc:
        sc = fc / math.sqrt(ft2)
        ftx = ftx * sc
        fty = fty * sc
        hx = -(ftx + etat * vtx) * inv_kt
        hy = -(fty + etat * vty) * inv_kt
    return fn, ftx, fty, hx, hy


#: the law compiled for the CPU, inlined into the pair loop (:func:`pair_forces`) and the
#: wall loop (:func:`cfbmarkov.simulate.dem.integrate.fused_step`)
contact_force = njit(cache=True, inline="always", fastmath=FASTMATH)(contact_law)


#: pairs per work item of :func:`pair_forces`, and per block of its lists of contacts
CONTACT_BLOCK = 256


@njit(parallel=True, cache=True, error_model="numpy", fastmath=FASTMATH)
def pair_forces(st, npairs, pi, pj, springs, pf, prm, contact_ids, block_contacts):
    """Force of every listed pair (i < j), computed once, and the pairs in contact listed.

    Branch-free apart from the contact test (contact or not, capped or not are selects).
    The pairs go in blocks of :data:`CONTACT_BLOCK`, one block a work item; each block lists
    its pairs in contact, in pair order, at its own place in ``contact_ids``, so the lists
    do not depend on the thread count. Where few pairs touch (a dilute flow), the step
    sums the forces of the particles in those pairs only (:mod:`.integrate`).

    Parameters
    ----------
    st : float64 (N, 8)
        Particle records (see :mod:`~cfbmarkov.simulate.dem.layout`).
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
    contact_ids : int64 (>= npairs,)
        Output: the pairs in contact of block b are
        ``contact_ids[b*CONTACT_BLOCK : b*CONTACT_BLOCK + block_contacts[b]]``.
    block_contacts : int64 (>= number of blocks,)
        Output: pairs in contact per block of :data:`CONTACT_BLOCK` pairs.

    Returns
    -------
    nbad : int
        Number of pairs overlapping by more than ``max_overlap*(R_i + R_j)`` (blow-up).
    ncontacts : int
        Number of pairs in contact.

    Notes
    -----
    Every result of a pair in contact is written as ``value + 0.0`` (a -0.0 becomes +0.0),
    and a pair out of contact gets +0.0 in its force and spring, so that this kernel and
    :func:`pair_forces_simd` write the same bits.
    """
    dt = prm.dt
    H = prm.height
    halfH = 0.5 * H
    kn = prm.kn
    kt = prm.kt
    inv_kt = prm.inv_kt
    mu = prm.mu
    etan_pp = prm.etan_pp
    etat_pp = prm.etat_pp
    cn = prm.cn
    ct = prm.ct
    ovl = prm.max_overlap
    periodic = prm.periodic
    mono = prm.mono
    nbad = 0
    ncontacts = 0
    B = CONTACT_BLOCK
    for b in prange((npairs + B - 1) // B):
        first = b * B
        listed = 0
        for p in range(first, min(npairs, first + B)):
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
                springs[p, 0] = 0.0
                springs[p, 1] = 0.0
                pf[p, 0] = 0.0
                pf[p, 1] = 0.0
                pf[p, 2] = 0.0
                continue
            ncontacts += 1
            contact_ids[first + listed] = p
            listed += 1
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
                                                 springs[p, 1], kn, kt, inv_kt, etan, etat,
                                                 mu, dt, False)
            springs[p, 0] = hx + 0.0
            springs[p, 1] = hy + 0.0
            pf[p, 0] = (ftx - fn * nx) + 0.0
            pf[p, 1] = (fty - fn * ny) + 0.0
            pf[p, 2] = (nx * fty - ny * ftx) + 0.0
        block_contacts[b] = listed
    return nbad, ncontacts


#: pairs per block of :func:`pair_forces_simd` (its buffers, 9 x 256 doubles, stay in L1)
SIMD_BLOCK = 256


@njit(parallel=True, cache=True, error_model="numpy", fastmath=FASTMATH)
def pair_forces_simd(st, npairs, pi, pj, springs, pf, prm):
    """:func:`pair_forces` for lists with many contacts: the same results, bit for bit,
    computed eight pairs at a time (SIMD).

    The pairs go in blocks of :data:`SIMD_BLOCK`: a scalar loop gathers each pair's relative
    position, velocity, surface speeds, radii and spring from the particle records into
    contiguous buffers; a loop without branches (contact or not, capped or not are
    multiplications by 0/1 and selects, so that the compiler vectorises it) evaluates the
    law of :func:`contact_force` for every pair of the block, in or out of contact, and
    writes the results. A pair out of contact thus costs the whole law (the results are
    multiplied by 0), which pays where most listed pairs touch (a bed, a cluster; 2.2-2.5
    times faster than :func:`pair_forces` with 70 % of the pairs in contact) and not in a
    dilute flow (1.4 times slower with 3 %); the step picks one by the last step's share of
    contacts (:func:`cfbmarkov.simulate.dem.stepping.advance`).

    Parameters and returns as :func:`pair_forces`.
    """
    dt = prm.dt
    H = prm.height
    halfH = 0.5 * H
    kn = prm.kn
    kt = prm.kt
    inv_kt = prm.inv_kt
    mu = prm.mu
    etan_pp = prm.etan_pp
    etat_pp = prm.etat_pp
    cn = prm.cn
    ct = prm.ct
    ovl = prm.max_overlap
    periodic = prm.periodic
    mono = prm.mono
    B = SIMD_BLOCK
    nblk = (npairs + B - 1) // B
    nbad = 0
    ncontacts = 0
    sp = springs.reshape(-1)
    pf1 = pf.reshape(-1)
    for b in prange(nblk):
        buf = np.empty((9, B))
        dxa = buf[0]
        dya = buf[1]
        dvxa = buf[2]
        dvya = buf[3]
        wsa = buf[4]
        rsa = buf[5]
        ima = buf[6]
        h0x = buf[7]
        h0y = buf[8]
        p0 = b * B
        n = min(B, npairs - p0)
        for q in range(n):
            p = p0 + q
            i = pi[p]
            j = pj[p]
            dx = st[j, 0] - st[i, 0]
            dy = st[j, 1] - st[i, 1]
            if periodic:
                if dy > halfH:
                    dy -= H
                elif dy < -halfH:
                    dy += H
            dxa[q] = dx
            dya[q] = dy
            dvxa[q] = st[i, 2] - st[j, 2]
            dvya[q] = st[i, 3] - st[j, 3]
            wsa[q] = st[i, 4] + st[j, 4]
            rsa[q] = st[i, 5] + st[j, 5]
            ima[q] = st[i, 6] + st[j, 6]
            h0x[q] = springs[p, 0]
            h0y[q] = springs[p, 1]
        nb = 0
        nc = 0
        # unsigned indices: no negative-index wrap-around, so the compiler sees the
        # stores' addresses as affine and vectorises the loop
        p0u = np.uint64(p0)
        for q in range(n):
            pu = np.uint64(q) + p0u
            dx = dxa[q]
            dy = dya[q]
            rs = rsa[q]
            r2 = dx * dx + dy * dy
            touch = r2 < rs * rs
            mf = 1.0 if touch else 0.0
            r = math.sqrt(r2)
            inv_r = 1.0 / r
            nx = dx * inv_r
            ny = dy * inv_r
            delta = rs - r
            nb += 1 if (touch and delta > ovl * rs) else 0
            nc += 1 if touch else 0
            wsum = wsa[q]
            vrx = dvxa[q] - wsum * ny
            vry = dvya[q] + wsum * nx
            vn = vrx * nx + vry * ny
            vtx = vrx - vn * nx
            vty = vry - vn * ny
            if mono:
                etan = etan_pp
                etat = etat_pp
            else:
                sm = 1.0 / math.sqrt(ima[q])
                etan = cn * sm
                etat = ct * sm
            # contact_force, written out with selects
            fn = kn * delta + etan * vn
            fn = 0.0 if fn < 0.0 else fn
            hx = h0x[q] + vtx * dt
            hy = h0y[q] + vty * dt
            hn = hx * nx + hy * ny
            hx = hx - hn * nx
            hy = hy - hn * ny
            ftx = -kt * hx - etat * vtx
            fty = -kt * hy - etat * vty
            ft2 = ftx * ftx + fty * fty
            fc = mu * fn
            cap = ft2 > fc * fc
            sc = fc / math.sqrt(ft2)
            ftxc = ftx * sc
            ftyc = fty * sc
            hxc = -(ftxc + etat * vtx) * inv_kt
            hyc = -(ftyc + etat * vty) * inv_kt
            ftx = ftxc if cap else ftx
            fty = ftyc if cap else fty
            hx = hxc if cap else hx
            hy = hyc if cap else hy
            sp[np.uint64(2) * pu] = hx * mf + 0.0
            sp[np.uint64(2) * pu + np.uint64(1)] = hy * mf + 0.0
            pf1[np.uint64(3) * pu] = (ftx - fn * nx) * mf + 0.0
            pf1[np.uint64(3) * pu + np.uint64(1)] = (fty - fn * ny) * mf + 0.0
            pf1[np.uint64(3) * pu + np.uint64(2)] = (nx * fty - ny * ftx) * mf + 0.0
        nbad += nb
        ncontacts += nc
    return nbad, ncontacts


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
