"""Numba kernels of the 2D DEM engine (no Python objects; see :mod:`.system` for the API).

Data layout (all arrays in *cell order*, i.e. sorted by search cell at the last rebuild):

``st``   float64 (2, N, 8): two buffers of one 64-byte record per particle,
         ``x, y, vx, vy, u = R*omega, R, 1/m, R/I`` (u, the surface speed, is what the
         contact kinematics needs: ``R_a*omega_a + R_b*omega_b = u_a + u_b``). A step reads
         buffer ``ctl[0]`` and writes the other one, then the buffers swap (no particle
         reads a half-updated neighbour).
``aux``  float64 (2, N, 4): ``x_ref, y_ref`` (position at the last list build), external
         force ``fx, fy``; ``wh`` float64 (2, N, 3) wall tangential springs (left, right,
         floor); ``ids`` int64 (2, N) caller's index of each sorted particle; ``laps``
         int64 (2, N). These swap buffers at each rebuild (``ctl[1]``).
lists    two list buffers ``A``/``B`` (``ctl[2]`` says which is current), each a tuple
         ``(nnb, nown, nbr, pstart, pi, pj, springs, lowstart, lowpid)``: the full Verlet
         list of each particle (fixed stride S, used while building) and the *pair list*
         derived from it: pairs (pi < pj) grouped by first member (``pstart``), the
         tangential spring of each pair (from the first member's side), and for each
         particle the pairs in which it is the second member (``lowstart``/``lowpid``).
         A step computes every pair force once (:func:`pair_forces`, into ``pf``), then
         each particle sums its pairs' forces in a fixed order (second-member pairs, then
         first-member pairs) inside the fused integration (:func:`fused_step`). No atomics,
         no shared accumulators: results do not depend on the thread count, and the two
         members of a pair get exactly opposite forces (one spring per contact, so there
         are no two copies to keep consistent). At a rebuild the springs move to the new
         pair list (negated when the members swap order under the new numbering).

``ctl``  int64: [0] st buffer, [1] particle-array buffer, [2] current list (0=A, 1=B),
         [3] rebuild needed, [4] step counter, [5] number of rebuilds, [6] events stored.
``P``    float64 parameters, ``IP`` int64 parameters: see the ``P_*`` / ``I_*`` constants.

Per step: 2 parallel loops (pair forces; sum + walls + integration + checks); per rebuild
(when a particle has moved more than skin/2 since the last one): cell keys, a serial stable
counting sort, gathers into the new order, list build (neighbour rows are contiguous ranges
of the sorted particles), pair list, spring carry-over.

Integrator: leapfrog (symplectic Euler on staggered velocities). Velocities are the half-step
values v(t - dt/2); a step is v += dt F(x, v)/m, x += dt v. This produces exactly the position
and half-step-velocity sequence of LAMMPS's velocity Verlet (which also evaluates the dashpot
with v(t - dt/2)), with force evaluation and integration fused in one pass.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# float parameters
P_DT, P_W, P_H, P_G, P_KN, P_KT, P_MU = 0, 1, 2, 3, 4, 5, 6
P_ETAN_PP, P_ETAT_PP, P_ETAN_PW, P_ETAT_PW = 7, 8, 9, 10
P_CN, P_CT, P_SKIN, P_CW, P_CH, P_RMAX, P_OVL, P_T0 = 11, 12, 13, 14, 15, 16, 17, 18
N_P = 19
# integer parameters
I_NCX, I_NCY, I_PERIODIC, I_FLOOR, I_MONO = 0, 1, 2, 3, 4
N_I = 5
# control slots
C_ST, C_PA, C_LIST, C_REBUILD, C_STEP, C_NREBUILD, C_NEV = 0, 1, 2, 3, 4, 5, 6
N_C = 7
# statuses returned by advance()
ST_OK, ST_STRIDE, ST_EVENTS, ST_BLOWUP = 0, 1, 2, 3
# reasons in bad[]
BAD_NAN, BAD_WALL, BAD_OVERLAP, BAD_RANGE = 1, 2, 3, 4


@njit(cache=True, inline="always")
def _cell_of(x, y, inv_cw, inv_ch, ncx, ncy):
    ix = int(x * inv_cw) if x > 0.0 else 0
    iy = int(y * inv_ch) if y > 0.0 else 0
    if ix >= ncx:
        ix = ncx - 1
    if iy >= ncy:
        iy = ncy - 1
    return iy * ncx + ix


_FM = {"contract", "arcp", "afn"}  # no nnan/ninf (NaN checks) and no reassoc (determinism)


@njit(parallel=True, cache=True, error_model="numpy", fastmath=_FM)
def pair_forces(st, npairs, pi, pj, hist, pf, P, IP):
    """Force of every listed pair (i < j), computed once: ``pf[p] = (fx, fy, c)`` with (fx, fy)
    the force on i (j gets the opposite) and c = n x Ft, so that the torque on either
    particle is its radius times c. Branch-free (contact or not, capped or not are selects),
    so the loop can use SIMD. Updates the tangential springs; returns the number of pairs
    that overlap by more than the blow-up limit."""
    dt = P[P_DT]
    H = P[P_H]
    halfH = 0.5 * H
    kn = P[P_KN]
    kt = P[P_KT]
    inv_kt = 1.0 / kt
    mu = P[P_MU]
    etan_pp = P[P_ETAN_PP]
    etat_pp = P[P_ETAT_PP]
    cn = P[P_CN]
    ct = P[P_CT]
    ovl = P[P_OVL]
    periodic = IP[I_PERIODIC] != 0
    mono = IP[I_MONO] != 0
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
            if hist[p, 0] != 0.0 or hist[p, 1] != 0.0:
                hist[p, 0] = 0.0
                hist[p, 1] = 0.0
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
        fn = kn * delta + etan * vn
        if fn < 0.0:
            fn = 0.0
        hx = hist[p, 0] + vtx * dt
        hy = hist[p, 1] + vty * dt
        hn = hx * nx + hy * ny
        hx -= hn * nx
        hy -= hn * ny
        ftx = -kt * hx - etat * vtx
        fty = -kt * hy - etat * vty
        ft2 = ftx * ftx + fty * fty
        fc = mu * fn
        if ft2 > fc * fc:
            sc = fc / math.sqrt(ft2)
            ftx *= sc
            fty *= sc
            hx = -(ftx + etat * vtx) * inv_kt
            hy = -(fty + etat * vty) * inv_kt
        hist[p, 0] = hx
        hist[p, 1] = hy
        pf[p, 0] = ftx - fn * nx
        pf[p, 1] = fty - fn * ny
        pf[p, 2] = nx * fty - ny * ftx
    return nbad


@njit(cache=True)
def flag_overlaps(st, npairs, pi, pj, bad, P, IP):
    """Mark the particles of pairs overlapping beyond the blow-up limit (after a bad step)."""
    H = P[P_H]
    for p in range(npairs):
        i = pi[p]
        j = pj[p]
        dx = st[j, 0] - st[i, 0]
        dy = st[j, 1] - st[i, 1]
        if IP[I_PERIODIC] != 0:
            dy -= H * np.round(dy / H)
        rs = st[i, 5] + st[j, 5]
        if rs - math.sqrt(dx * dx + dy * dy) > P[P_OVL] * rs:
            bad[i] = BAD_OVERLAP
            bad[j] = BAD_OVERLAP


@njit(cache=True, inline="always", fastmath=_FM)
def _wall_contact(delta, vn, vt, spring, kn, kt, etan, etat, mu, dt, inv_kt):
    """Spring-dashpot contact with a wall (Table 2, LAMMPS rescaling at the Coulomb cap).

    ``delta`` overlap (m), ``vn`` velocity along the wall's normal into the domain, ``vt``
    tangential velocity of the contact point, ``spring`` the tangential spring before the
    step. Returns (normal force >= 0 along the normal, tangential force, new spring)."""
    fn = kn * delta - etan * vn
    if fn < 0.0:
        fn = 0.0
    h = spring + vt * dt
    ft = -kt * h - etat * vt
    fc = mu * fn
    if ft * ft > fc * fc:
        ft = fc if ft > 0.0 else -fc
        h = -(ft + etat * vt) * inv_kt
    return fn, ft, h


@njit(parallel=True, cache=True, error_model="numpy", fastmath=_FM)
def fused_step(st, so, aux, wh, laps, pstart, lowstart, lowpid, pf, evf, bad, P, IP):
    """Sum the pair forces ``pf`` of each particle (pairs where it comes second, then pairs
    where it comes first: a fixed order), add walls, external force and gravity, integrate,
    and write ``so``. Returns (particles moved beyond skin/2, boundary passes, bad
    particles, vertical force of the side walls on the particles, force of the floor on
    them (N); the forces are diagnostics, summed in any order)."""
    N = st.shape[0]
    dt = P[P_DT]
    W = P[P_W]
    H = P[P_H]
    halfH = 0.5 * H
    g = P[P_G]
    kn = P[P_KN]
    kt = P[P_KT]
    inv_kt = 1.0 / kt
    mu = P[P_MU]
    etan_pw = P[P_ETAN_PW]
    etat_pw = P[P_ETAT_PW]
    cn = P[P_CN]
    ct = P[P_CT]
    skin = P[P_SKIN]
    hs = 0.5 * skin
    hs2 = hs * hs
    ovl = P[P_OVL]
    periodic = IP[I_PERIODIC] != 0
    floor = IP[I_FLOOR] != 0
    mono = IP[I_MONO] != 0
    nmove = 0
    nev = 0
    nbad = 0
    wall_fy = 0.0
    floor_fy = 0.0
    for i in prange(N):
        xi = st[i, 0]
        yi = st[i, 1]
        vxi = st[i, 2]
        vyi = st[i, 3]
        ui = st[i, 4]
        Ri = st[i, 5]
        imi = st[i, 6]
        rIi = st[i, 7]
        fx = aux[i, 2]
        fy = aux[i, 3]
        tq = 0.0
        isbad = 0
        for q in range(lowstart[i], lowstart[i + 1]):
            p = lowpid[q]
            fx -= pf[p, 0]
            fy -= pf[p, 1]
            tq += Ri * pf[p, 2]
        for p in range(pstart[i], pstart[i + 1]):
            fx += pf[p, 0]
            fy += pf[p, 1]
            tq += Ri * pf[p, 2]
        # near a wall (within the skin): contact, or a spring to clear (a particle cannot
        # leave a contact by more than the skin in one step without tripping the checks)
        if xi < Ri + skin or xi > W - Ri - skin or (floor and yi < Ri + skin):
            if mono:
                etan = etan_pw
                etat = etat_pw
            else:
                sm = 1.0 / math.sqrt(imi)
                etan = cn * sm
                etat = ct * sm
            if xi < Ri:  # left wall, n = (-1, 0)
                delta = Ri - xi
                if delta > 2.0 * ovl * Ri:
                    isbad = BAD_OVERLAP
                fn, ft, wh[i, 0] = _wall_contact(delta, vxi, vyi - ui, wh[i, 0], kn, kt, etan,
                                                 etat, mu, dt, inv_kt)
                fx += fn
                fy += ft
                tq -= Ri * ft
                wall_fy += ft
            elif wh[i, 0] != 0.0:
                wh[i, 0] = 0.0
            if xi > W - Ri:  # right wall, n = (1, 0)
                delta = xi + Ri - W
                if delta > 2.0 * ovl * Ri:
                    isbad = BAD_OVERLAP
                fn, ft, wh[i, 1] = _wall_contact(delta, -vxi, vyi + ui, wh[i, 1], kn, kt, etan,
                                                 etat, mu, dt, inv_kt)
                fx -= fn
                fy += ft
                tq += Ri * ft
                wall_fy += ft
            elif wh[i, 1] != 0.0:
                wh[i, 1] = 0.0
            if floor and yi < Ri:  # floor, n = (0, -1)
                delta = Ri - yi
                if delta > 2.0 * ovl * Ri:
                    isbad = BAD_OVERLAP
                fn, ft, wh[i, 2] = _wall_contact(delta, vyi, vxi + ui, wh[i, 2], kn, kt, etan,
                                                 etat, mu, dt, inv_kt)
                fy += fn
                fx += ft
                tq += Ri * ft
                floor_fy += fn
            elif wh[i, 2] != 0.0:
                wh[i, 2] = 0.0
        # integrate (leapfrog)
        vxn = vxi + dt * (fx * imi)
        vyn = vyi + dt * (fy * imi - g)
        wn = ui + dt * (tq * rIi)
        xn = xi + dt * vxn
        yn = yi + dt * vyn
        if periodic:
            if yn >= H:
                yn -= H
                laps[i] += 1
                evf[i] = 1
                nev += 1
            elif yn < 0.0:
                yn += H
                if yn >= H:  # a step of -1e-17 rounds to H: that is the point 0
                    yn = 0.0
                laps[i] -= 1
                evf[i] = -1
                nev += 1
            if not (yn >= 0.0 and yn < H):
                isbad = BAD_RANGE
        elif yn < -Ri:
            isbad = BAD_WALL
        if xn < -Ri or xn > W + Ri:
            isbad = BAD_WALL
        if not (xn == xn and yn == yn and wn == wn and vxn == vxn and vyn == vyn):
            isbad = BAD_NAN
        if isbad != 0:
            bad[i] = isbad
            nbad += 1
        ddx = xn - aux[i, 0]
        ddy = yn - aux[i, 1]
        if periodic:
            if ddy > halfH:
                ddy -= H
            elif ddy < -halfH:
                ddy += H
        if ddx * ddx + ddy * ddy > hs2:
            nmove += 1
        so[i, 0] = xn
        so[i, 1] = yn
        so[i, 2] = vxn
        so[i, 3] = vyn
        so[i, 4] = wn
        so[i, 5] = Ri
        so[i, 6] = imi
        so[i, 7] = rIi
    return nmove, nev, nbad, wall_fy, floor_fy


@njit(parallel=True, cache=True)
def _cell_keys(st, key, P, IP):
    N = st.shape[0]
    inv_cw = 1.0 / P[P_CW]
    inv_ch = 1.0 / P[P_CH]
    ncx = IP[I_NCX]
    ncy = IP[I_NCY]
    for i in prange(N):
        key[i] = _cell_of(st[i, 0], st[i, 1], inv_cw, inv_ch, ncx, ncy)


@njit(cache=True)
def _counting_sort(key, cstart, cfill, perm, invperm):
    """Stable counting sort by cell: perm[new] = old, invperm[old] = new; cstart[c] = first
    new index of cell c (cstart has ncells + 1 entries)."""
    N = key.shape[0]
    nc = cstart.shape[0] - 1
    cstart[:] = 0
    for i in range(N):
        cstart[key[i] + 1] += 1
    for c in range(nc):
        cstart[c + 1] += cstart[c]
    for c in range(nc):
        cfill[c] = cstart[c]
    for i in range(N):
        c = key[i]
        k = cfill[c]
        cfill[c] = k + 1
        perm[k] = i
        invperm[i] = k


@njit(parallel=True, cache=True)
def _gather_st(st, so, perm):
    N = st.shape[0]
    for k in prange(N):
        i = perm[k]
        for c in range(8):
            so[k, c] = st[i, c]


@njit(parallel=True, cache=True)
def _gather_rest(st, aux, auxo, wh, who, ids, idso, laps, lapso, perm, P, IP):
    """Per-particle arrays in the new order: reference positions (= current ones), external
    force, wall springs (cleared for particles farther than the skin from every wall: covers
    a particle that left a wall by more than the skin in one step), ids, laps."""
    N = st.shape[0]
    W = P[P_W]
    skin = P[P_SKIN]
    floor = IP[I_FLOOR] != 0
    for k in prange(N):
        i = perm[k]
        x = st[i, 0]
        R = st[i, 5]
        auxo[k, 0] = x
        auxo[k, 1] = st[i, 1]
        auxo[k, 2] = aux[i, 2]
        auxo[k, 3] = aux[i, 3]
        who[k, 0] = wh[i, 0] if x < R + skin else 0.0
        who[k, 1] = wh[i, 1] if x > W - R - skin else 0.0
        who[k, 2] = wh[i, 2] if (floor and st[i, 1] < R + skin) else 0.0
        idso[k] = ids[i]
        lapso[k] = laps[i]


@njit(parallel=True, cache=True, error_model="numpy")
def _build_list(so, cstart, nnb, nown, nbr, S, P, IP):
    """Full Verlet list of the sorted particles ``so`` (cutoff R_i + R_j + skin). Writes at most
    S entries per particle; returns the largest count (> S means: grow and rebuild).

    Cells are numbered row by row, so the (up to) three cells of a neighbour row hold one
    contiguous range of sorted particles; rows and columns that cannot hold a particle within
    the cutoff (from the particle's place in its cell) are skipped."""
    N = so.shape[0]
    H = P[P_H]
    halfH = 0.5 * H
    skin = P[P_SKIN]
    cw = P[P_CW]
    ch = P[P_CH]
    inv_cw = 1.0 / cw
    inv_ch = 1.0 / ch
    rmax = P[P_RMAX]
    ncx = IP[I_NCX]
    ncy = IP[I_NCY]
    periodic = IP[I_PERIODIC] != 0
    mono = IP[I_MONO] != 0
    rc_mono = 2.0 * rmax + skin
    rc2_mono = rc_mono * rc_mono
    nover = 0
    for k in prange(N):
        x = so[k, 0]
        y = so[k, 1]
        Rk = so[k, 5]
        cut = Rk + rmax + skin
        ix = int(x * inv_cw) if x > 0.0 else 0
        iy = int(y * inv_ch) if y > 0.0 else 0
        if ix >= ncx:
            ix = ncx - 1
        if iy >= ncy:
            iy = ncy - 1
        fxc = x - ix * cw
        fyc = y - iy * ch
        # neighbour columns/rows that can hold a particle within the cutoff
        c0 = ix - 1 if (ix > 0 and (fxc < cut or fxc > cw)) else ix
        c1 = ix + 1 if (ix < ncx - 1 and (cw - fxc < cut or fxc < 0.0)) else ix
        r0 = iy - 1 if (fyc < cut or fyc > ch) else iy
        r1 = iy + 1 if (ch - fyc < cut or fyc < 0.0) else iy
        cnt = 0
        own = 0
        base = k * S
        for rr in range(r0, r1 + 1):
            row = rr
            wrapped = False
            if row < 0:
                if not periodic:
                    continue
                row += ncy
                wrapped = True
            elif row >= ncy:
                if not periodic:
                    continue
                row -= ncy
                wrapped = True
            first = cstart[row * ncx + c0]
            last = cstart[row * ncx + c1 + 1]
            for jj in range(first, last):
                dx = so[jj, 0] - x
                dy = so[jj, 1] - y
                if wrapped:
                    if dy > halfH:
                        dy -= H
                    elif dy < -halfH:
                        dy += H
                d2 = dx * dx + dy * dy
                if mono:
                    inside = d2 < rc2_mono
                else:
                    rc = Rk + so[jj, 5] + skin
                    inside = d2 < rc * rc
                if inside and jj != k:
                    if cnt < S:
                        nbr[base + cnt] = jj
                    cnt += 1
                    if jj > k:
                        own += 1
        nnb[k] = cnt
        nown[k] = own
        if cnt > S:
            nover += 1
    if nover == 0:
        return S
    m = 0
    for k in range(N):
        if nnb[k] > m:
            m = nnb[k]
    return m


@njit(cache=True)
def _prefix(nnb, nown, pstart, lowstart):
    N = nnb.shape[0]
    pstart[0] = 0
    lowstart[0] = 0
    for k in range(N):
        pstart[k + 1] = pstart[k] + nown[k]
        lowstart[k + 1] = lowstart[k] + (nnb[k] - nown[k])


@njit(parallel=True, cache=True)
def _fill_pairs(nnb, nbr, S, pstart, pi, pj, hist, lowstart, lowpid):
    """Pairs (k, j > k) in the order the search met them (springs zeroed), and for each
    particle the pairs in which it is the second member: pair (j, k) with j < k is number
    pstart[j] + (how many neighbours of j above j come before k in j's list)."""
    N = nnb.shape[0]
    for k in prange(N):
        p = pstart[k]
        q = lowstart[k]
        for s in range(k * S, k * S + nnb[k]):
            jj = nbr[s]
            if jj > k:
                pi[p] = k
                pj[p] = jj
                hist[p, 0] = 0.0
                hist[p, 1] = 0.0
                p += 1
            else:
                c = pstart[jj]
                for s2 in range(jj * S, jj * S + nnb[jj]):
                    e = nbr[s2]
                    if e == k:
                        break
                    if e > jj:
                        c += 1
                lowpid[q] = c
                q += 1


@njit(parallel=True, cache=True)
def _carry_history(perm, invperm, pstart_o, pj_o, hist_o, pstart_n, pj_n, hist_n):
    """Copy each contact's tangential spring from the old pair list to the new one (negated
    when the pair's order of members flips with the new numbering)."""
    N = perm.shape[0]
    for k in prange(N):
        i = perm[k]
        for po in range(pstart_o[i], pstart_o[i + 1]):
            hx = hist_o[po, 0]
            hy = hist_o[po, 1]
            if hx != 0.0 or hy != 0.0:
                jj = invperm[pj_o[po]]
                kk = invperm[i]  # == k, typed like jj (a prange index may be unsigned)
                if kk < jj:
                    own = kk
                    oth = jj
                else:
                    own = jj
                    oth = kk
                    hx = -hx
                    hy = -hy
                for p in range(pstart_n[own], pstart_n[own + 1]):
                    if pj_n[p] == oth:
                        hist_n[p, 0] = hx
                        hist_n[p, 1] = hy
                        break


@njit(cache=True)
def rebuild(st, aux, wh, ids, laps, LA, LB, ctl, key, cstart, cfill, perm, invperm, P, IP):
    """Sort particles into cell order and build a new neighbour/pair list, carrying the
    tangential springs over. Commits (swaps buffers) only on success; returns 0, or the
    stride needed by the new list when it does not fit (nothing changed then)."""
    cs = ctl[C_ST]
    cp = ctl[C_PA]
    cur = st[cs]
    new = st[1 - cs]
    N = cur.shape[0]
    _cell_keys(cur, key, P, IP)
    _counting_sort(key, cstart, cfill, perm, invperm)
    _gather_st(cur, new, perm)
    if ctl[C_LIST] == 0:
        old_l = LA
        new_l = LB
    else:
        old_l = LB
        new_l = LA
    nnb, nown, nbr, pstart, pi, pj, hist, lowstart, lowpid = new_l
    S = nbr.shape[0] // N
    need = _build_list(new, cstart, nnb, nown, nbr, S, P, IP)
    if need > S:
        return need
    _prefix(nnb, nown, pstart, lowstart)
    _fill_pairs(nnb, nbr, S, pstart, pi, pj, hist, lowstart, lowpid)
    _carry_history(perm, invperm, old_l[3], old_l[5], old_l[6], pstart, pj, hist)
    _gather_rest(cur, aux[cp], aux[1 - cp], wh[cp], wh[1 - cp], ids[cp], ids[1 - cp], laps[cp],
                 laps[1 - cp], perm, P, IP)
    ctl[C_ST] = 1 - cs
    ctl[C_PA] = 1 - cp
    ctl[C_LIST] = 1 - ctl[C_LIST]
    ctl[C_REBUILD] = 0
    ctl[C_NREBUILD] += 1
    return 0


@njit(cache=True)
def _record_events(st_old, st_new, ids, evf, step, P, ev_t, ev_p, ev_d, ctl):
    N = st_old.shape[0]
    dt = P[P_DT]
    H = P[P_H]
    t0 = P[P_T0]
    n = ctl[C_NEV]
    for i in range(N):
        d = evf[i]
        if d != 0:
            evf[i] = 0
            y0 = st_old[i, 1]
            dy = dt * st_new[i, 3]
            if d > 0:
                frac = (H - y0) / dy if dy > 0.0 else 1.0
            else:
                frac = -y0 / dy if dy < 0.0 else 1.0
            if not (frac >= 0.0):
                frac = 0.0
            elif frac > 1.0:
                frac = 1.0
            ev_t[n] = t0 + (step + frac) * dt
            ev_p[n] = ids[i]
            ev_d[n] = d
            n += 1
    ctl[C_NEV] = n


@njit(cache=True)
def advance(st, aux, wh, ids, laps, LA, LB, pf, ctl, evf, bad, key, cstart, cfill, perm,
            invperm, P, IP, nsteps, ev_t, ev_p, ev_d, wall_impulse):
    """Advance up to ``nsteps`` steps, adding the walls' vertical impulse on the particles
    to ``wall_impulse`` ([side walls, floor], N s). Returns (steps done, status, info): status ST_OK;
    ST_STRIDE (info = stride the next list needs); ST_EVENTS (event buffer needs room);
    ST_BLOWUP (the step just done produced a bad particle, flagged in ``bad``)."""
    N = st.shape[1]
    done = 0
    while done < nsteps:
        if ctl[C_REBUILD] != 0:
            need = rebuild(st, aux, wh, ids, laps, LA, LB, ctl, key, cstart, cfill, perm,
                           invperm, P, IP)
            if need > 0:
                return done, ST_STRIDE, need
        if ev_t.shape[0] - ctl[C_NEV] < N:
            return done, ST_EVENTS, 0
        cs = ctl[C_ST]
        cp = ctl[C_PA]
        L = LA if ctl[C_LIST] == 0 else LB
        pstart = L[3]
        npairs = pstart[N]
        nbad_pairs = pair_forces(st[cs], npairs, L[4], L[5], L[6], pf, P, IP)
        nmove, nev, nbad, wall_fy, floor_fy = fused_step(
            st[cs], st[1 - cs], aux[cp], wh[cp], laps[cp], pstart, L[7], L[8], pf, evf, bad, P, IP)
        wall_impulse[0] += P[P_DT] * wall_fy
        wall_impulse[1] += P[P_DT] * floor_fy
        if nbad_pairs > 0:
            flag_overlaps(st[cs], npairs, L[4], L[5], bad, P, IP)
            nbad += nbad_pairs
        step = ctl[C_STEP]
        ctl[C_ST] = 1 - cs
        ctl[C_STEP] = step + 1
        done += 1
        if nev > 0:
            _record_events(st[cs], st[1 - cs], ids[cp], evf, step, P, ev_t, ev_p, ev_d, ctl)
        if nbad > 0:
            return done, ST_BLOWUP, 0
        if nmove > 0:
            ctl[C_REBUILD] = 1
    return done, ST_OK, 0


@njit(parallel=True, cache=True)
def scatter_external(ext, ids, aux):
    """aux[k, 2:4] = ext[ids[k]] (caller's order to cell order)."""
    N = ids.shape[0]
    for k in prange(N):
        i = ids[k]
        aux[k, 2] = ext[i, 0]
        aux[k, 3] = ext[i, 1]


@njit(parallel=True, cache=True)
def clear_external(aux):
    N = aux.shape[0]
    for k in prange(N):
        aux[k, 2] = 0.0
        aux[k, 3] = 0.0


def empty_list(n, stride):
    """A list buffer: (nnb, nown, nbr, pstart, pi, pj, springs, lowstart, lowpid); the pair
    arrays have room for n*stride pairs (each pair appears once in its first member's
    strided row, so there are at most n*stride/2)."""
    cap = max(1, n * stride // 2 + n)
    return (np.zeros(n, np.int32), np.zeros(n, np.int32), np.zeros(n * stride, np.int32),
            np.zeros(n + 1, np.int64), np.zeros(cap, np.int32), np.zeros(cap, np.int32),
            np.zeros((cap, 2), np.float64), np.zeros(n + 1, np.int64), np.zeros(cap, np.int64))
