"""The advance loop of the 2D DEM engine (numba): steps until done, a list rebuild is due
with a larger stride, the event buffer is full, or a particle goes bad.

Each step: a list rebuild (:func:`.neighbours.rebuild`) when due, the pair forces
(:mod:`.contact`), their sums, the wall contacts and the move (:mod:`.integrate`), and the
boundary passes logged with their time inside the step.
"""

from __future__ import annotations

from numba import njit

from cfbmarkov.simulate.dem.contact import flag_overlaps, pair_forces, pair_forces_simd
from cfbmarkov.simulate.dem.integrate import (move, sum_pairs, sum_touched_pairs,
                                             touched_particles, wall_candidates, wall_contacts)
from cfbmarkov.simulate.dem.layout import (C_BUILT, C_DRIFT, C_LIST, C_NEV, C_PA, C_REBUILD,
                                           C_ST, C_STEP, DRIFT_UNIT, ST_BLOWUP, ST_EVENTS,
                                           ST_OK, ST_STRIDE)
from cfbmarkov.simulate.dem.neighbours import rebuild


#: share of the listed pairs in contact from which the step uses
#: :func:`.contact.pair_forces_simd`: measured on the DEM benchmark problems (2 threads), the
#: branching kernel costs about 4.6 ns per listed pair plus 10 ns per contact, the SIMD one
#: 5-6.5 ns per listed pair whatever the contacts (docs/performance.md)
SIMD_CONTACT_SHARE = 0.15


@njit(cache=True)
def _record_events(st_old, st_new, ids, evf, step, prm, ev_t, ev_p, ev_d, ctl):
    """Log the boundary passes flagged in ``evf`` (and clear the flags): time interpolated
    inside the step (straight-line motion), caller's particle index, direction."""
    N = st_old.shape[0]
    dt = prm.dt
    H = prm.height
    t0 = prm.t0
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
def advance(st, aux, wh, ids, laps, LA, LB, pf, fsum, ctl, evf, bad, key, cstart, cfill, perm,
            invperm, wall_ids, n_wall, n_contacts, contact_ids, block_contacts, touched,
            touched_ids, stamp, prm, nsteps, ev_t, ev_p, ev_d, wall_impulse):
    """Advance up to ``nsteps`` steps (rebuilding the lists when needed).

    Parameters
    ----------
    st, aux, wh, ids, laps : arrays
        The double-buffered particle arrays (see :mod:`~cfbmarkov.simulate.dem.layout`).
    LA, LB : PairList
        The two list buffers.
    pf : float64 (>= npairs, 3)
        Pair-force scratch.
    fsum : float64 (N, 3)
        Scratch: each particle's summed force and torque (:func:`.integrate.sum_pairs`).
    ctl : int64 (N_C,)
        Control slots.
    evf, bad : int8 (N,)
        Event flags and bad-particle reasons.
    key, cstart, cfill, perm, invperm : int64 arrays
        Rebuild scratch (see :func:`.neighbours.rebuild`).
    wall_ids : int64 (N,)
        The wall candidates (:func:`.integrate.wall_candidates`) of the current list.
    n_wall : int64 (1,)
        Their number; -1 when not yet found for the current list (after a restart): they
        are found then, and after every list build.
    n_contacts : int64 (1,)
        Pairs in contact at the last step (-1 before the first): where they were at least
        :data:`SIMD_CONTACT_SHARE` of the listed pairs, the step computes the pair forces
        with :func:`.contact.pair_forces_simd` and sums every particle's pairs
        (:func:`.integrate.sum_pairs`), else with :func:`.contact.pair_forces`, which lists
        the pairs in contact, and sums the pairs of their members only
        (:func:`.integrate.touched_particles`, :func:`.integrate.sum_touched_pairs`; the
        others move by their external force). The same bits either way; only the speed
        differs.
    contact_ids, block_contacts : int64 (>= pairs,), (>= pairs / CONTACT_BLOCK + 1,)
        Scratch: the pairs in contact (:func:`.contact.pair_forces`).
    touched, touched_ids : int64 (N,)
        Scratch: ``touched[i] == stamp[0]`` marks a particle whose forces were summed in the
        current step; ``touched_ids`` lists them. Values of earlier steps mean nothing.
    stamp : int64 (1,)
        The step's mark, incremented at every step (never reused with the same
        ``touched``).
    prm : DEMParams
    nsteps : int
        Steps to do.
    ev_t, ev_p, ev_d : float64, int64, int8 (capacity,)
        Event buffer (time s, particle, direction); ``ctl[C_NEV]`` entries are used.
    wall_impulse : float64 (2,)
        The walls' vertical impulse on the particles is added here ([side walls, floor],
        N s).

    Returns
    -------
    done : int
        Steps done.
    status : int
        ``ST_OK``; ``ST_STRIDE`` (a list needs a larger stride, given as ``info``);
        ``ST_EVENTS`` (the event buffer needs room); ``ST_BLOWUP`` (the step just done
        produced a bad particle, flagged in ``bad``).
    info : int
        See ``status``.
    """
    N = st.shape[1]
    done = 0
    while done < nsteps:
        if ctl[C_REBUILD] != 0:
            need = rebuild(st, aux, wh, ids, laps, LA, LB, ctl, key, cstart, cfill, perm,
                           invperm, prm)
            if need > 0:
                return done, ST_STRIDE, need
            n_wall[0] = wall_candidates(aux[ctl[C_PA]], wall_ids, prm)
        elif n_wall[0] < 0:
            n_wall[0] = wall_candidates(aux[ctl[C_PA]], wall_ids, prm)
        if ev_t.shape[0] - ctl[C_NEV] < N:
            return done, ST_EVENTS, 0
        cs = ctl[C_ST]
        cp = ctl[C_PA]
        L = LA if ctl[C_LIST] == 0 else LB
        npairs = L.pstart[N]
        stamp[0] += 1
        summed = n_contacts[0] >= SIMD_CONTACT_SHARE * npairs and npairs > 0
        if summed:
            nbad_pairs, nc = pair_forces_simd(st[cs], npairs, L.pi, L.pj, L.springs, pf, prm)
            sum_pairs(st[cs], aux[cp], L.pstart, L.lowstart, L.lowpid, pf, fsum)
        else:
            nbad_pairs, nc = pair_forces(st[cs], npairs, L.pi, L.pj, L.springs, pf, prm,
                                         contact_ids, block_contacts)
            n_touched = touched_particles(npairs, L.pi, L.pj, contact_ids, block_contacts,
                                          touched, stamp[0], touched_ids)
            sum_touched_pairs(st[cs], aux[cp], L.pstart, L.lowstart, L.lowpid, pf, fsum,
                              touched_ids, n_touched)
        n_contacts[0] = nc
        nbad, wall_fy, floor_fy = wall_contacts(st[cs], wh[cp], aux[cp], fsum, bad, wall_ids,
                                                n_wall[0], touched, stamp[0], summed, prm)
        # the list's frame drifts in y (neighbours.drift_velocity): its shift after this step
        shift = (ctl[C_STEP] + 1 - ctl[C_BUILT]) * prm.dt * (ctl[C_DRIFT] * DRIFT_UNIT)
        nmove, nev, nbad_move = move(st[cs], st[1 - cs], aux[cp], laps[cp], fsum, touched,
                                     stamp[0], summed, evf, bad, shift, prm)
        nbad += nbad_move
        wall_impulse[0] += prm.dt * wall_fy
        wall_impulse[1] += prm.dt * floor_fy
        if nbad_pairs > 0:
            flag_overlaps(st[cs], npairs, L.pi, L.pj, bad, prm)
            nbad += nbad_pairs
        step = ctl[C_STEP]
        ctl[C_ST] = 1 - cs
        ctl[C_STEP] = step + 1
        done += 1
        if nev > 0:
            _record_events(st[cs], st[1 - cs], ids[cp], evf, step, prm, ev_t, ev_p, ev_d, ctl)
        if nbad > 0:
            return done, ST_BLOWUP, 0
        if nmove > 0:
            ctl[C_REBUILD] = 1
    return done, ST_OK, 0
