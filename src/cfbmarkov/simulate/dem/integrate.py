"""Time integration of the 2D DEM engine: the kernels of one step (numba; the loop over
steps is :func:`.stepping.advance`).

Per step: :func:`.contact.pair_forces` (every pair force once, into ``pf``),
:func:`sum_pairs` (each particle sums its pairs' forces and its external force, into
``fsum``), :func:`wall_contacts` (the few particles within the skin of a wall add their wall
contacts to ``fsum``; the candidates are found after each list build by
:func:`wall_candidates`) and :func:`move` (each particle adds gravity, integrates and checks
itself, with no branch but the loop-invariant periodic one); a list rebuild
(:func:`.neighbours.rebuild`) before a step whose particles may have left their lists.
Where few listed pairs touch (a dilute flow: 1 % of them in the paper's riser at 6 m/s),
``pair_forces`` also lists the pairs in contact, and only the particles in them sum their
pairs (:func:`touched_particles`, :func:`sum_touched_pairs`); every other particle's pair
forces are all +0.0, and it moves by its external force, the same bits (a sum of +0.0 terms
changes nothing but the sign of a -0.0 force, which moves nothing). In the dilute benchmark
that pass cost 104 us a step and now 22 (27000 particles, 2 threads; docs/performance.md).
:func:`fused_step` does the last three in one loop with the same bits; it is kept for
single-particle tests, as the step uses the separate loops: with the variable-length pair
loops inside the long per-particle body, that one loop took about 1.6 times as long as the
two together (dilute benchmark; docs/performance.md).

Determinism: each particle sums its pairs in a fixed order (pairs where it is the second
member, then those where it is the first), with no atomics and no shared accumulators, so
the results do not depend on the thread count. (The wall-force diagnostics are the only
sums in any order.)

Integrator: leapfrog (symplectic Euler on staggered velocities). Velocities are the
half-step values v(t - dt/2); a step is ``v += dt F(x, v)/m``, ``x += dt v``. This produces
exactly the position and half-step-velocity sequence of LAMMPS's velocity Verlet (which
also evaluates the dashpot with v(t - dt/2)), with force evaluation and integration fused
in one pass.
"""

from __future__ import annotations

import math

from numba import njit, prange

from cfbmarkov.simulate.dem.contact import CONTACT_BLOCK, FASTMATH, contact_force
from cfbmarkov.simulate.dem.layout import BAD_NAN, BAD_OVERLAP, BAD_RANGE, BAD_WALL


@njit(cache=True, fastmath=FASTMATH)
def _walls(i, st, wh, fx, fy, tq, prm):
    """Particle i's contacts with the side walls and the floor (or their springs cleared),
    added to its force (fx, fy) and torque tq.

    Called by :func:`_finish` only for a particle within the skin of a wall (a few percent
    of them), and compiled as a function of its own rather than inlined: the three inlined
    contact laws made the per-particle kernels' compilation slow (12 s of the DEM's 28 s),
    while a call for so few particles costs nothing measurable.

    Returns (fx, fy, tq, bad reason or 0, side walls' vertical force, floor's vertical force).
    """
    dt = prm.dt
    W = prm.width
    floor = prm.floor
    ovl = prm.max_overlap
    xi = st[i, 0]
    yi = st[i, 1]
    vxi = st[i, 2]
    vyi = st[i, 3]
    ui = st[i, 4]
    Ri = st[i, 5]
    imi = st[i, 6]
    isbad = 0
    wall_fy = 0.0
    floor_fy = 0.0
    kn = prm.kn
    kt = prm.kt
    inv_kt = prm.inv_kt
    mu = prm.mu
    if prm.mono:
        etan = prm.etan_pw
        etat = prm.etat_pw
    else:
        sm = 1.0 / math.sqrt(imi)
        etan = prm.cn * sm
        etat = prm.ct * sm
    # a wall is a partner of infinite mass (m_ab = m) at rest without spin: the
    # relative velocity of the contact point is (vx - u ny, vy + u nx), the approach
    # speed its part along n, the tangential velocity (1D) its part along the wall
    if xi < Ri:  # left wall, n = (-1, 0)
        delta = Ri - xi
        if delta > 2.0 * ovl * Ri:
            isbad = BAD_OVERLAP
        fn, _, ft, _, wh[i, 0] = contact_force(delta, -vxi, 0.0, 0.0, 0.0, vyi - ui, 0.0,
                                               wh[i, 0], kn, kt, inv_kt, etan, etat, mu,
                                               dt, True)
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
        fn, _, ft, _, wh[i, 1] = contact_force(delta, vxi, 0.0, 0.0, 0.0, vyi + ui, 0.0,
                                               wh[i, 1], kn, kt, inv_kt, etan, etat, mu,
                                               dt, True)
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
        fn, _, ft, _, wh[i, 2] = contact_force(delta, -vyi, 0.0, 0.0, 0.0, vxi + ui, 0.0,
                                               wh[i, 2], kn, kt, inv_kt, etan, etat, mu,
                                               dt, True)
        fy += fn
        fx += ft
        tq += Ri * ft
        floor_fy += fn
    elif wh[i, 2] != 0.0:
        wh[i, 2] = 0.0
    return fx, fy, tq, isbad, wall_fy, floor_fy


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _integrate(i, st, so, aux, laps, evf, bad, fx, fy, tq, shift, prm):
    """Particle i's leapfrog update from its total force (fx, fy) and torque tq (pairs,
    external force and walls; gravity added here), written to ``so``, and its checks.

    Branch-free apart from the loop-invariant ``periodic`` and two rare writes: the new
    record, a move beyond skin/2 and the checks are selects and sums (no call inside the
    loop over all particles, :func:`move`); ``laps`` and ``evf`` are written only on a pass
    through the top or bottom (+-1; ``evf`` is all zeros between steps) and ``bad`` only
    where a reason is found. A branch that is almost never taken is predicted and costs
    nothing, where writing every particle's ``laps`` and ``bad`` cost 12 % of :func:`move`
    (docs/performance.md).

    ``shift`` (m) is the list's drift in y since its build (:func:`.neighbours.drift_velocity`):
    "moved beyond skin/2" is measured from the reference position moved by it.

    Returns (moved beyond skin/2, boundary passes, bad). Inlined into :func:`move` and
    :func:`fused_step`.
    """
    dt = prm.dt
    W = prm.width
    H = prm.height
    xi = st[i, 0]
    yi = st[i, 1]
    vxi = st[i, 2]
    vyi = st[i, 3]
    ui = st[i, 4]
    Ri = st[i, 5]
    imi = st[i, 6]
    rIi = st[i, 7]
    vxn = vxi + dt * (fx * imi)
    vyn = vyi + dt * (fy * imi - prm.gravity)
    wn = ui + dt * (tq * rIi)
    xn = xi + dt * vxn
    yn = yi + dt * vyn
    ddy = 0.0
    if prm.periodic:
        up = yn >= H
        down = yn < 0.0
        yn = yn - H if up else yn
        yn = yn + H if down else yn
        yn = 0.0 if (down and yn >= H) else yn  # a step of -1e-17 rounds to H: that is 0
        d = (1 if up else 0) - (1 if down else 0)
        if d != 0:  # rare: only then written (evf is all zeros between steps)
            laps[i] += d
            evf[i] = d
        nev = 1 if d != 0 else 0
        isbad = 0 if (yn >= 0.0 and yn < H) else BAD_RANGE
        ddy = yn - aux[i, 1]
        ddy = ddy - H if ddy > 0.5 * H else ddy
        ddy = ddy + H if ddy < -0.5 * H else ddy
    else:
        nev = 0
        isbad = BAD_WALL if yn < -Ri else 0
        ddy = yn - aux[i, 1]
    isbad = BAD_WALL if (xn < -Ri or xn > W + Ri) else isbad
    finite = xn == xn and yn == yn and wn == wn and vxn == vxn and vyn == vyn
    isbad = isbad if finite else BAD_NAN
    if isbad != 0:  # rare
        bad[i] = isbad
    ddy = ddy - shift
    ddx = xn - aux[i, 0]
    hs = 0.5 * prm.skin
    moved = 1 if ddx * ddx + ddy * ddy > hs * hs else 0
    so[i, 0] = xn
    so[i, 1] = yn
    so[i, 2] = vxn
    so[i, 3] = vyn
    so[i, 4] = wn
    so[i, 5] = Ri
    so[i, 6] = imi
    so[i, 7] = rIi
    return moved, nev, 1 if isbad != 0 else 0


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _near_wall(x, y, R, prm):
    """Whether a particle at (x, y) of radius R is within the skin of a side wall or the
    floor (it may touch it, or hold a spring to clear, during this step)."""
    skin = prm.skin
    return x < R + skin or x > prm.width - R - skin or (prm.floor and y < R + skin)


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _finish(i, st, so, aux, wh, laps, evf, bad, fx, fy, tq, prm):
    """The rest of particle i's step once its pair forces are summed into (fx, fy, tq): its
    wall contacts (:func:`_walls`, near a wall only), then :func:`_integrate`.

    Returns (moved beyond skin/2, boundary passes, bad, side walls' and floor's vertical
    force on it). Inlined into :func:`fused_step`.
    """
    wall_fy = 0.0
    floor_fy = 0.0
    wbad = 0
    # near a wall (within the skin): contact, or a spring to clear (a particle cannot
    # leave a contact by more than the skin in one step without tripping the checks)
    if _near_wall(st[i, 0], st[i, 1], st[i, 5], prm):
        fx, fy, tq, wbad, wall_fy, floor_fy = _walls(i, st, wh, fx, fy, tq, prm)
        if wbad != 0:
            bad[i] = wbad
    moved, nev, nbad = _integrate(i, st, so, aux, laps, evf, bad, fx, fy, tq, 0.0, prm)
    if wbad != 0:
        nbad = 1
    return moved, nev, nbad, wall_fy, floor_fy


@njit(parallel=True, cache=True, error_model="numpy", fastmath=FASTMATH)
def fused_step(st, so, aux, wh, laps, pstart, lowstart, lowpid, pf, evf, bad, prm):
    """Sum the forces on each particle, add walls, external force and gravity, integrate.

    The pair forces ``pf`` are summed in a fixed order (pairs where the particle comes
    second, then pairs where it comes first). The wall contacts use
    :func:`.contact.contact_force` with the wall as a mirror particle of infinite mass.

    The step itself (:func:`.stepping.advance`) runs this as :func:`sum_pairs` then :func:`move`
    (the same bits, faster); this one loop is kept for tests of single contacts.

    Parameters
    ----------
    st : float64 (N, 8)
        Particle records at the start of the step (read).
    so : float64 (N, 8)
        Particle records after the step (written).
    aux : float64 (N, 4)
        Reference positions (m) and external force (N) of each particle.
    wh : float64 (N, 3)
        Wall tangential springs (left, right, floor), m; updated.
    laps : int64 (N,)
        Passes through the top (+1) / bottom (-1); updated.
    pstart, lowstart, lowpid : int64 arrays
        Pair-list index arrays (see :class:`~cfbmarkov.simulate.dem.layout.PairList`).
    pf : float64 (npairs, 3)
        Pair forces from :func:`.contact.pair_forces`.
    evf : int8 (N,)
        Set to +1/-1 for a particle that passed the top/bottom in this step.
    bad : int8 (N,)
        Set to a ``BAD_*`` reason for a particle that became unphysical.
    prm : DEMParams

    Returns
    -------
    nmove : int
        Particles moved beyond skin/2 since the last list build.
    nev : int
        Boundary passes.
    nbad : int
        Bad particles.
    wall_fy, floor_fy : float
        Vertical force of the side walls and of the floor on the particles, N
        (diagnostics, summed in any order).
    """
    N = st.shape[0]
    nmove = 0
    nev = 0
    nbad = 0
    wall_fy = 0.0
    floor_fy = 0.0
    for i in prange(N):
        fx, fy, tq = _pair_sum(i, st, aux, pstart, lowstart, lowpid, pf)
        m, e, nb, wf, ff = _finish(i, st, so, aux, wh, laps, evf, bad, fx, fy, tq, prm)
        nmove += m
        nev += e
        nbad += nb
        wall_fy += wf
        floor_fy += ff
    return nmove, nev, nbad, wall_fy, floor_fy


@njit(inline="always", error_model="numpy", fastmath=FASTMATH)
def _pair_sum(i, st, aux, pstart, lowstart, lowpid, pf):
    """Particle i's external force plus its pairs' forces, and the pairs' torque: (fx, fy,
    torque), in the order of :func:`sum_pairs`."""
    Ri = st[i, 5]
    fx = aux[i, 2]
    fy = aux[i, 3]
    tq = 0.0
    for q in range(lowstart[i], lowstart[i + 1]):
        p = lowpid[q]
        fx -= pf[p, 0]
        fy -= pf[p, 1]
        tq += Ri * pf[p, 2]
    for p in range(pstart[i], pstart[i + 1]):
        fx += pf[p, 0]
        fy += pf[p, 1]
        tq += Ri * pf[p, 2]
    return fx, fy, tq


@njit(inline="always", error_model="numpy", fastmath=FASTMATH)
def _sum_pairs_of(i, st, aux, pstart, lowstart, lowpid, pf, fsum):
    """fsum[i] = :func:`_pair_sum` of particle i."""
    fx, fy, tq = _pair_sum(i, st, aux, pstart, lowstart, lowpid, pf)
    fsum[i, 0] = fx
    fsum[i, 1] = fy
    fsum[i, 2] = tq


@njit(parallel=True, cache=True, error_model="numpy", fastmath=FASTMATH)
def sum_pairs(st, aux, pstart, lowstart, lowpid, pf, fsum):
    """Sum the pair forces on each particle in a fixed order (pairs where it comes second,
    then pairs where it comes first), starting from its external force: ``fsum[i] = (fx, fy,
    torque)``."""
    for i in prange(st.shape[0]):
        _sum_pairs_of(i, st, aux, pstart, lowstart, lowpid, pf, fsum)


@njit(cache=True)
def touched_particles(npairs, pi, pj, contact_ids, block_contacts, touched, stamp,
                      touched_ids):
    """The particles in a contact: the members of the pairs in contact that
    :func:`.contact.pair_forces` listed, marked ``touched[i] = stamp`` and listed in
    ``touched_ids`` (in the order met, each once). Serial: a dilute flow has few contacts.

    Parameters
    ----------
    npairs : int
        Number of listed pairs.
    pi, pj : int32 (>= npairs,)
        First and second member of each pair.
    contact_ids, block_contacts : int64 arrays
        The pairs in contact by blocks of ``CONTACT_BLOCK`` pairs, as
        :func:`.contact.pair_forces` wrote them.
    touched : int64 (N,)
        Marks, updated: ``touched[i] = stamp`` for every particle listed.
    stamp : int
        This step's mark (never used before with this ``touched``).
    touched_ids : int64 (N,)
        Output: the particles in a contact, first ``n`` entries.

    Returns
    -------
    n : int
        Number of particles listed.
    """
    n = 0
    B = CONTACT_BLOCK
    for b in range((npairs + B - 1) // B):
        for q in range(b * B, b * B + block_contacts[b]):
            p = contact_ids[q]
            i = pi[p]
            if touched[i] != stamp:
                touched[i] = stamp
                touched_ids[n] = i
                n += 1
            j = pj[p]
            if touched[j] != stamp:
                touched[j] = stamp
                touched_ids[n] = j
                n += 1
    return n


@njit(parallel=True, cache=True, error_model="numpy", fastmath=FASTMATH)
def sum_touched_pairs(st, aux, pstart, lowstart, lowpid, pf, fsum, touched_ids, n_touched):
    """:func:`sum_pairs` for the particles in ``touched_ids[:n_touched]`` only: every other
    particle is in no contact, its pair forces are all +0.0, and its sum is its external
    force, which :func:`wall_contacts` and :func:`move` take from ``aux`` instead (the same
    value: adding +0.0 changes no bits but a -0.0, and a force of -0.0 moves nothing).

    Parameters
    ----------
    st, aux : float64 (N, 8), (N, 4)
        Particle records and reference positions with external forces.
    pstart, lowstart, lowpid : int64 arrays
        Pair-list index arrays (see :class:`~cfbmarkov.simulate.dem.layout.PairList`).
    pf : float64 (>= npairs, 3)
        Pair forces from :func:`.contact.pair_forces`.
    fsum : float64 (N, 3)
        Output: (fx, fy, torque) of the listed particles; other rows are left as they were.
    touched_ids : int64 (N,)
        The particles to sum (:func:`touched_particles`).
    n_touched : int
        Their number.
    """
    for k in prange(n_touched):
        _sum_pairs_of(touched_ids[k], st, aux, pstart, lowstart, lowpid, pf, fsum)


@njit(cache=True)
def wall_candidates(aux, wall_ids, prm):
    """The particles that may come within the skin of a wall before the next list build.

    Between two builds a particle stays within skin/2 of its reference position (the step
    that takes it farther asks for a build), so one within the skin of a wall during a step
    has its reference position within 1.5 skins of it; this takes 2 skins (and the largest
    radius), a superset, and :func:`wall_contacts` checks each candidate exactly.

    Parameters
    ----------
    aux : float64 (N, 4)
        Reference positions (m) in columns 0-1.
    wall_ids : int64 (N,)
        Output: the candidates' indices (cell order), ascending.
    prm : DEMParams

    Returns
    -------
    int
        Number of candidates (the first entries of ``wall_ids``).
    """
    lim = prm.rmax + 2.0 * prm.skin
    right = prm.width - lim
    floor = prm.floor
    n = 0
    for i in range(aux.shape[0]):
        x = aux[i, 0]
        if x < lim or x > right or (floor and aux[i, 1] < lim):
            wall_ids[n] = i
            n += 1
    return n


@njit(parallel=True, cache=True, error_model="numpy", fastmath=FASTMATH)
def wall_contacts(st, wh, aux, fsum, bad, wall_ids, n_wall, touched, stamp, summed, prm):
    """Wall contacts of the candidates near a wall (:func:`wall_candidates`), added to their
    summed force ``fsum`` (N, 3) before :func:`move`; each adds to its own row only. A
    particle whose pairs were not summed (``summed`` false and ``touched[i] != stamp``:
    :func:`sum_touched_pairs`) starts from its external force in ``aux`` and is marked
    ``touched[i] = stamp``.

    Returns
    -------
    nbad : int
        Particles overlapping a wall beyond the blow-up limit (flagged in ``bad``).
    wall_fy, floor_fy : float
        Vertical force of the side walls and of the floor on the particles, N
        (diagnostics, summed in any order).
    """
    nbad = 0
    wall_fy = 0.0
    floor_fy = 0.0
    for q in prange(n_wall):
        i = wall_ids[q]
        if _near_wall(st[i, 0], st[i, 1], st[i, 5], prm):
            if summed or touched[i] == stamp:
                fx, fy, tq, isbad, wf, ff = _walls(i, st, wh, fsum[i, 0], fsum[i, 1],
                                                   fsum[i, 2], prm)
            else:
                touched[i] = stamp
                fx, fy, tq, isbad, wf, ff = _walls(i, st, wh, aux[i, 2], aux[i, 3], 0.0, prm)
            fsum[i, 0] = fx
            fsum[i, 1] = fy
            fsum[i, 2] = tq
            wall_fy += wf
            floor_fy += ff
            if isbad != 0:
                bad[i] = isbad
                nbad += 1
    return nbad, wall_fy, floor_fy


@njit(parallel=True, cache=True, error_model="numpy", fastmath=FASTMATH)
def move(st, so, aux, laps, fsum, touched, stamp, summed, evf, bad, shift, prm):
    """Gravity, integration and checks of every particle (:func:`_integrate`) from its
    summed force ``fsum`` (pairs, external force and walls: :func:`sum_pairs`, then
    :func:`wall_contacts`), or from its external force in ``aux`` where its pairs were not
    summed (``summed`` false and ``touched[i] != stamp``: a particle in no contact).
    ``shift`` (m): the list's drift in y since its build (:func:`_integrate`).

    Returns
    -------
    nmove, nev, nbad : int
        Particles moved beyond skin/2 since the last list build, boundary passes, bad
        particles.
    """
    N = st.shape[0]
    nmove = 0
    nev = 0
    nbad = 0
    for i in prange(N):
        use = summed or touched[i] == stamp
        fx = fsum[i, 0] if use else aux[i, 2]
        fy = fsum[i, 1] if use else aux[i, 3]
        tq = fsum[i, 2] if use else 0.0
        m, e, nb = _integrate(i, st, so, aux, laps, evf, bad, fx, fy, tq, shift, prm)
        nmove += m
        nev += e
        nbad += nb
    return nmove, nev, nbad
