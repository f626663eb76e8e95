"""Neighbour search of the 2D DEM engine: cell sort, Verlet list, pair list, springs (numba).

A rebuild (:func:`rebuild`; when a particle has moved more than skin/2 since the last one,
relative to a frame drifting in y with the particles, :func:`drift_velocity`)
computes cell keys, does a serial stable counting sort, gathers the particles into the new
(cell) order, builds the half Verlet list (each particle's neighbours after it in cell
order; neighbour rows are contiguous ranges of the sorted particles), derives the pair list
from it and, by one serial transposition, each particle's pairs as second member (see
:class:`~cfbmarkov.simulate.dem.layout.PairList`), and moves each contact's tangential spring to the new pair list
(negated when the members swap order under the new numbering). The sort is stable and
every parallel loop writes only its own rows, so the lists do not depend on the thread
count. (Building the full list instead, each pair tested from both sides, and finding the
second-member lists by searching the first member's row, gives the same lists with twice
the distance tests.)
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from cfbmarkov.errors import InputError
from cfbmarkov.simulate.dem.layout import (C_BUILT, C_DRIFT, C_LIST, C_NREBUILD, C_PA,
                                           C_REBUILD, C_ST, C_STEP, DRIFT_UNIT)


def search_grid(width: float, height: float, cut: float, search_cells, periodic: bool
                ) -> tuple[int, int]:
    """The cells of the neighbour-search grid, checked against the list cutoff.

    Parameters
    ----------
    width, height : float
        W and H of the domain, m.
    cut : float
        The list cutoff 2 R_max + skin, m.
    search_cells : (int, int) or None
        Cells across and up, or None for the finest grid whose cells are no smaller than
        ``cut``.
    periodic : bool
        The domain is periodic in y (it then needs at least 3 rows).

    Returns
    -------
    (int, int)
        Cells across and up.

    Raises
    ------
    InputError
        For a cutoff wider than the domain or than a third of a periodic height (the skin
        at fault), and for cells that are not two positive integers, smaller than the
        cutoff, or fewer than 3 rows of a periodic height.
    """
    rows_needed = 3 if periodic else 1
    if cut > width * (1 + 1e-12) or cut * rows_needed > height * (1 + 1e-12):
        side = (f"the width W = {width * 1e3:.4g} mm" if cut > width * (1 + 1e-12) else
                f"a third of the periodic height H = {height * 1e3:.4g} mm")
        raise InputError(
            f"the neighbour cutoff 2*R_max + skin = {cut * 1e3:.4g} mm exceeds {side}: a "
            "smaller numerics.dem_skin (it changes the speed only; the default is 0.4 mm), "
            "or a wider or taller riser")
    most = (int(width / cut), int(height / cut))
    if search_cells is None:
        ncx, ncy = most
    else:
        try:
            ncx, ncy = (int(c) for c in search_cells)
        except (TypeError, ValueError):
            raise InputError(f"search_cells: expected two integers, got {search_cells!r}") from None
        if ncx < 1 or ncy < 1:
            raise InputError(f"search_cells must be positive, got {search_cells!r}")
    cw, ch = width / ncx, height / ncy
    if min(cw, ch) < cut * (1 - 1e-12):
        raise InputError(
            f"search cells {ncx} x {ncy} are {cw * 1e3:.4g} x {ch * 1e3:.4g} mm, smaller "
            f"than the neighbour cutoff 2*R_max + skin = {cut * 1e3:.4g} mm; use fewer "
            f"cells (at most {most[0]} x {most[1]}), or the automatic "
            "grid (numerics.dem_cells = \"auto\" in a case file, search_cells=None in "
            "Python)")
    if ncy < rows_needed:
        raise InputError(f"search cells {ncx} x {ncy}: a periodic height needs at least 3 rows "
                         f"of search cells; use 3 to {most[1]} rows, or the automatic grid "
                         "(numerics.dem_cells = \"auto\" in a case file, search_cells=None "
                         "in Python)")
    return ncx, ncy


@njit(cache=True, inline="always")
def _index_of(x, inv_w, n):
    """The search cell's column (row) of a coordinate x (y): clamped to 0 ... n - 1."""
    i = int(x * inv_w) if x > 0.0 else 0
    return n - 1 if i >= n else i


@njit(cache=True, inline="always")
def _cell_of(x, y, inv_cw, inv_ch, ncx, ncy):
    return _index_of(y, inv_ch, ncy) * ncx + _index_of(x, inv_cw, ncx)


@njit(parallel=True, cache=True)
def _cell_keys(st, key, prm):
    N = st.shape[0]
    inv_cw = 1.0 / prm.cell_w
    inv_ch = 1.0 / prm.cell_h
    ncx = prm.ncx
    ncy = prm.ncy
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
    """``so[k] = st[perm[k]]``; returns the smallest and largest vy (exact whatever the
    threads: a minimum and a maximum do not depend on the order)."""
    N = st.shape[0]
    lo = np.inf
    hi = -np.inf
    for k in prange(N):
        i = perm[k]
        for c in range(8):
            so[k, c] = st[i, c]
        vy = st[i, 3]
        lo = min(lo, vy)
        hi = max(hi, vy)
    return lo, hi


@njit(cache=True)
def drift_velocity(vy_min, vy_max, prm):
    """The list's drift velocity in y, in units of :data:`~cfbmarkov.simulate.dem.layout.DRIFT_UNIT` (an integer,
    saved in ``ctl[C_DRIFT]``): the middle of the particles' vertical velocities at the
    build, where the domain is periodic in y; 0 with a floor.

    Between two builds the list stays valid while every particle stays within skin/2 of its
    reference position moved by ``drift * (steps since the build) * dt`` in y: any two
    particles then moved by at most a skin relative to each other, which is all a Verlet
    list needs (the usual rule is the special case of no drift). Moving the frame with the
    particles' middle velocity halves their largest displacement in a riser, where the core
    rises at up to 6 m/s while the wall layers fall: at 6 m/s the list is built every 9-11
    steps instead of every 7. Any drift is valid; this
    one only makes the builds rarer. x is not moved, so the side walls' candidates
    (:func:`.integrate.wall_candidates`) keep their rule; with a floor nothing is moved.
    """
    if not prm.periodic or not (vy_min <= vy_max):
        return 0
    mid = 0.5 * (vy_min + vy_max)
    if not (abs(mid) < 1e6):
        return 0
    return int(round(mid / DRIFT_UNIT))


@njit(parallel=True, cache=True)
def _gather_rest(st, aux, auxo, wh, who, ids, idso, laps, lapso, perm, prm):
    """Per-particle arrays in the new order: reference positions (= current ones), external
    force, wall springs (cleared for particles farther than the skin from every wall: covers
    a particle that left a wall by more than the skin in one step), ids, laps."""
    N = st.shape[0]
    W = prm.width
    skin = prm.skin
    floor = prm.floor
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
def _build_list(so, cstart, nown, nbr, S, prm):
    """Half Verlet list of the sorted particles ``so``: for each particle the neighbours that
    come after it in cell order (cutoff R_i + R_j + skin).

    Cells are numbered row by row, so the (up to) three cells of a neighbour row hold one
    contiguous range of sorted particles, of which only the part after the particle is
    tested; rows and columns that cannot hold a particle within the cutoff (from the
    particle's place in its cell) are skipped. The rows are visited from below to above
    (a row reached across the periodic boundary in its place in that order), so a row of
    the list holds its neighbours in the order of a full search.

    The (up to) three ranges are walked as one loop, and each candidate is written to the
    row's next free slot whether it is within the cutoff or not (it counts only if it is):
    a dilute list finds a neighbour in about a fifth of its candidates, and a branch on
    that, or the end of a short loop per row, is mispredicted often enough to cost more
    than the tests (22 % less time than three loops with a branch, measured on the dilute
    benchmark; docs/performance.md). The lists are the same.

    Parameters
    ----------
    so : float64 (N, 8)
        Particle records in cell order.
    cstart : int64 (ncells + 1,)
        First sorted particle of each cell.
    nown : int32 (N,)
        Output: how many neighbours come after each particle.
    nbr : int32 (N*S,)
        Output: those neighbours, row k at ``k*S`` (at most S written per row; the slots
        after a row's ``nown[k]`` hold nothing of meaning).
    S : int
        Stride of ``nbr``.
    prm : DEMParams

    Returns
    -------
    int
        S when every row fits, else the largest count (grow to it and rebuild).
    """
    N = so.shape[0]
    H = prm.height
    halfH = 0.5 * H
    skin = prm.skin
    cw = prm.cell_w
    ch = prm.cell_h
    inv_cw = 1.0 / cw
    inv_ch = 1.0 / ch
    rmax = prm.rmax
    ncx = prm.ncx
    ncy = prm.ncy
    periodic = prm.periodic
    mono = prm.mono
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
        # the candidates of rows r0 ... r1: ranges [f_t, f_t + n_t), w_t: across the boundary
        f0 = 0
        f1 = 0
        f2 = 0
        n0 = 0
        n1 = 0
        n2 = 0
        w0 = False
        w1 = False
        w2 = False
        for t in range(3):
            row = r0 + t
            use = row <= r1
            wrapped = False
            if row < 0:
                row += ncy
                wrapped = True
            elif row >= ncy:
                row -= ncy
                wrapped = True
            use = use and (periodic or not wrapped)
            first = 0
            n = 0
            if use:
                first = cstart[row * ncx + c0]
                last = cstart[row * ncx + c1 + 1]
                if first <= k:
                    first = k + 1
                n = last - first if last > first else 0
            if t == 0:
                f0 = first
                n0 = n
                w0 = wrapped
            elif t == 1:
                f1 = first
                n1 = n
                w1 = wrapped
            else:
                f2 = first
                n2 = n
                w2 = wrapped
        n01 = n0 + n1
        own = 0
        base = k * S
        for q in range(n01 + n2):
            jj = f0 + q if q < n0 else (f1 + (q - n0) if q < n01 else f2 + (q - n01))
            wrapped = w0 if q < n0 else (w1 if q < n01 else w2)
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
            # the row's next free slot (its last once full: kept there unless a neighbour,
            # which makes the row overflow and the list be built again with a larger S)
            slot = base + (own if own < S else S - 1)
            nbr[slot] = jj if (inside or own < S) else nbr[slot]
            own += 1 if inside else 0
        nown[k] = own
        if own > S:
            nover += 1
    if nover == 0:
        return S
    m = 0
    for k in range(N):
        if nown[k] > m:
            m = nown[k]
    return m


@njit(cache=True)
def _prefix(nown, pstart):
    N = nown.shape[0]
    pstart[0] = 0
    for k in range(N):
        pstart[k + 1] = pstart[k] + nown[k]


@njit(parallel=True, cache=True)
def _fill_pairs(nown, nbr, S, pstart, pi, pj, springs):
    """Pairs (k, j > k) in the order the search met them, springs zeroed."""
    N = nown.shape[0]
    for k in prange(N):
        p = pstart[k]
        for s in range(k * S, k * S + nown[k]):
            pi[p] = k
            pj[p] = nbr[s]
            springs[p, 0] = 0.0
            springs[p, 1] = 0.0
            p += 1


@njit(cache=True)
def _second_members(so, npairs, pi, pj, nown, nnb, lowstart, lowpid, prm):
    """For each particle the pairs in which it is the second member (``lowstart``,
    ``lowpid``), in the order a full search from it would meet their first members, and its
    total neighbour count ``nnb``.

    That order is the ascending order of the first members, except that a search from the
    top row of cells meets the bottom row (across the periodic boundary) last: those pairs
    come after the others. One serial pass counts, one fills (pairs ascending), so the lists
    do not depend on the thread count.
    """
    N = nown.shape[0]
    periodic = prm.periodic
    inv_ch = 1.0 / prm.cell_h
    ncy = prm.ncy
    nlow = nnb  # low counts first, totals at the end
    nlow[:] = 0
    nwrap = np.zeros(N, np.int32)
    wrapped = np.zeros(npairs, np.bool_)
    for p in range(npairs):
        k = pj[p]
        nlow[k] += 1
        if periodic:
            if _index_of(so[k, 1], inv_ch, ncy) - _index_of(so[pi[p], 1], inv_ch, ncy) > 1:
                wrapped[p] = True
                nwrap[k] += 1
    lowstart[0] = 0
    for k in range(N):
        lowstart[k + 1] = lowstart[k] + nlow[k]
    fill = np.empty(N, np.int64)
    fillw = np.empty(N, np.int64)
    for k in range(N):
        fill[k] = lowstart[k]
        fillw[k] = lowstart[k + 1] - nwrap[k]
    for p in range(npairs):
        k = pj[p]
        if wrapped[p]:
            lowpid[fillw[k]] = p
            fillw[k] += 1
        else:
            lowpid[fill[k]] = p
            fill[k] += 1
    for k in range(N):
        nnb[k] = nlow[k] + nown[k]


@njit(parallel=True, cache=True)
def _carry_springs(invperm, npairs_o, pi_o, pj_o, springs_o, pstart_n, pj_n, springs_n):
    """Copy each contact's tangential spring from the old pair list to the new one (negated
    when the pair's order of members flips with the new numbering).

    One pass over the old pairs (each old pair is at most one new pair, so no two write the
    same place): only the few with a spring (in contact, or just out of it) look for their
    new pair. Springs of pairs no longer listed are dropped (they are farther apart than
    the skin).
    """
    for po in prange(npairs_o):
        hx = springs_o[po, 0]
        hy = springs_o[po, 1]
        if hx != 0.0 or hy != 0.0:
            kk = invperm[pi_o[po]]
            jj = invperm[pj_o[po]]
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
                    springs_n[p, 0] = hx
                    springs_n[p, 1] = hy
                    break


@njit(cache=True)
def rebuild(st, aux, wh, ids, laps, LA, LB, ctl, key, cstart, cfill, perm, invperm, prm):
    """Sort the particles into cell order and build a new neighbour/pair list.

    The tangential springs are carried over. Commits (swaps the buffers) only on success.

    Parameters
    ----------
    st, aux, wh, ids, laps : arrays
        The double-buffered particle arrays (see :mod:`~cfbmarkov.simulate.dem.layout`).
    LA, LB : PairList
        The two list buffers; the one not current (``ctl[C_LIST]``) receives the new list.
    ctl : int64 (N_C,)
        Control slots, updated on success.
    key, cstart, cfill, perm, invperm : int64 arrays
        Scratch: cell keys (N,), cell starts (ncells + 1,), fill counters (ncells,), the
        permutation new -> old and its inverse (N,).
    prm : DEMParams

    Returns
    -------
    int
        0, or the stride the new list needs when it does not fit (nothing changed then).
    """
    cs = ctl[C_ST]
    cp = ctl[C_PA]
    cur = st[cs]
    new = st[1 - cs]
    N = cur.shape[0]
    _cell_keys(cur, key, prm)
    _counting_sort(key, cstart, cfill, perm, invperm)
    vy_min, vy_max = _gather_st(cur, new, perm)
    if ctl[C_LIST] == 0:
        old_l = LA
        new_l = LB
    else:
        old_l = LB
        new_l = LA
    S = new_l.nbr.shape[0] // N
    need = _build_list(new, cstart, new_l.nown, new_l.nbr, S, prm)
    if need > S:
        return need
    _prefix(new_l.nown, new_l.pstart)
    npairs = new_l.pstart[N]
    _fill_pairs(new_l.nown, new_l.nbr, S, new_l.pstart, new_l.pi, new_l.pj, new_l.springs)
    _second_members(new, npairs, new_l.pi, new_l.pj, new_l.nown, new_l.nnb, new_l.lowstart,
                    new_l.lowpid, prm)
    _carry_springs(invperm, old_l.pstart[N], old_l.pi, old_l.pj, old_l.springs, new_l.pstart,
                   new_l.pj, new_l.springs)
    _gather_rest(cur, aux[cp], aux[1 - cp], wh[cp], wh[1 - cp], ids[cp], ids[1 - cp], laps[cp],
                 laps[1 - cp], perm, prm)
    ctl[C_ST] = 1 - cs
    ctl[C_PA] = 1 - cp
    ctl[C_LIST] = 1 - ctl[C_LIST]
    ctl[C_REBUILD] = 0
    ctl[C_NREBUILD] += 1
    ctl[C_DRIFT] = drift_velocity(vy_min, vy_max, prm)
    ctl[C_BUILT] = ctl[C_STEP]
    return 0
