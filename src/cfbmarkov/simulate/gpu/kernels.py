"""CUDA kernels of the GPU DEM (numba-cuda): an ensemble of independent members, several
DEM steps per launch. No I/O.

Layout (structure of arrays; M members of N particles, member m at rows m*N ... m*N+N-1;
contacts only within a member)::

    s     float64 (2, 8, M*N): two buffers of the particle fields x, y, vx, vy,
          u = R*omega, R, 1/m, R/I (the CPU engine's record, one row per field); a step
          reads buffer ctl[m, C_CUR] and writes the other
    aux   float64 (2, M*N): x_ref, y_ref (position at the member's last list build)
    ext   float64 (2, M*N): external force fx, fy (N), held during the steps
    wh    float64 (3, M*N): wall tangential springs (left, right, floor), m
    laps  int64 (M*N): passes through the top (+1) / bottom (-1)
    nbr   int32 (2, K, M*N), nnb int32 (2, M*N): two buffers of each particle's full
          neighbour list (up to K neighbours, global rows, ascending), ctl[m, C_LIST] current
    spr   float64 (2, 2, K, M*N): the tangential spring of each listed contact, from the
          particle's own side (a pair's two copies are opposite, up to round-off)
    cells int32 (M, ncell + 1) starts, (M, ncell) fill counts, (M*N) particle rows by cell;
          key int32 (M*N) each particle's cell at the build; part int64 (M, threads) the
          prefix sum's chunk offsets
    ctl   int64 (M, N_CTL): per member C_CUR, C_LIST, C_STEP, C_REBUILD, C_NEV, C_BAD,
          C_OVERFLOW
    ev_*  (M, cap): pass events (step, fraction of the step, particle, direction)

The step is the CPU engine's (:mod:`cfbmarkov.simulate.dem.integrate`): the same contact law
(:func:`cfbmarkov.simulate.dem.contact.contact_law`, compiled here as a device function),
the same wall contacts, the same leapfrog update in the same order; only the order in which
a particle sums its pair forces differs (ascending partner index here), so float64 results
agree with the CPU to round-off. Each particle evaluates its own side of each contact (a
full list), so no atomics touch the forces and the results do not depend on the launch
shape, the other members, or when the lists are built (a touching pair is in every valid
list, and a pair's spring is zero whenever it does not touch).

Launch: :data:`advance` (one thread block per member) runs the members' steps up to
``target`` with ``cuda.syncthreads()`` between the phases: a list build when a particle of
the member has moved more than skin/2 since the last one (cell counts, a prefix sum over
the cells in chunks, cell fill, each particle's neighbours from the 3 x 3 cells around it,
sorted by index, springs carried over), then the step (forces, walls, integration, checks,
events). :func:`grid_advance` is the same source with several blocks per member and a
grid-wide synchronisation (a cooperative launch; GPU only). A member stops early when its
event buffer could overflow, a particle went bad or a list overflowed; the host
(:class:`~.ensemble.GpuEnsembleDEM`) then handles that and launches again.
"""

from __future__ import annotations

import math

from cfbmarkov.simulate.dem.contact import contact_law
from cfbmarkov.simulate.dem.layout import BAD_NAN, BAD_OVERLAP, BAD_RANGE, BAD_WALL
from cfbmarkov.simulate.gpu._cuda import cuda

# control slots of ctl[m]
C_CUR, C_LIST, C_STEP, C_REBUILD, C_NEV, C_BAD, C_OVERFLOW = 0, 1, 2, 3, 4, 5, 6
N_CTL = 7
# float parameters (fp)
F_DT, F_W, F_H, F_G, F_KN, F_KT, F_INV_KT, F_MU = 0, 1, 2, 3, 4, 5, 6, 7
F_ETAN_PP, F_ETAT_PP, F_ETAN_PW, F_ETAT_PW, F_CN, F_CT = 8, 9, 10, 11, 12, 13
F_SKIN, F_CELL_W, F_CELL_H, F_OVL, F_CUT = 14, 15, 16, 17, 18
N_F = 19
# integer parameters (ip)
I_N, I_NCX, I_NCY, I_PERIODIC, I_FLOOR, I_MONO, I_K, I_EVCAP = 0, 1, 2, 3, 4, 5, 6, 7
N_I = 8

law = cuda.jit(device=True)(contact_law)


@cuda.jit(device=True)
def _cell_index(x, inv_w, n):
    """The search cell's column (row) of a coordinate: clamped to 0 ... n - 1 (as the CPU)."""
    i = int(x * inv_w) if x > 0.0 else 0
    return n - 1 if i >= n else i


@cuda.jit(device=True)
def _count(m, t, nt, s, cur, cfill, key, ip, fp):
    """List build, phase 1: each particle's cell (``key``) and the cells' counts."""
    N = ip[I_N]
    ncx = ip[I_NCX]
    inv_cw = 1.0 / fp[F_CELL_W]
    inv_ch = 1.0 / fp[F_CELL_H]
    for i in range(t, N, nt):
        g = m * N + i
        c = (_cell_index(s[cur, 1, g], inv_ch, ip[I_NCY]) * ncx
             + _cell_index(s[cur, 0, g], inv_cw, ncx))
        key[g] = c
        cuda.atomic.add(cfill, (m, c), 1)


@cuda.jit(device=True)
def _chunk(t, nt, ncell):
    """Thread t's contiguous range of cells in the prefix sum."""
    size = (ncell + nt - 1) // nt
    lo = t * size
    hi = lo + size
    return (ncell if lo > ncell else lo), (ncell if hi > ncell else hi)


@cuda.jit(device=True)
def _scan_partial(m, t, nt, cfill, part, ip):
    """Prefix sum, phase 1: each thread's total over its chunk of cells."""
    lo, hi = _chunk(t, nt, ip[I_NCX] * ip[I_NCY])
    acc = 0
    for c in range(lo, hi):
        acc += cfill[m, c]
    part[m, t] = acc


@cuda.jit(device=True)
def _scan_totals(m, nt, part):
    """Prefix sum, phase 2 (one thread): the chunks' totals to their exclusive offsets."""
    acc = 0
    for q in range(nt):
        v = part[m, q]
        part[m, q] = acc
        acc += v


@cuda.jit(device=True)
def _scan_cells(m, t, nt, cfill, cstart, part, ip):
    """Prefix sum, phase 3: each chunk's cell starts from its offset; counts cleared."""
    ncell = ip[I_NCX] * ip[I_NCY]
    lo, hi = _chunk(t, nt, ncell)
    acc = part[m, t]
    for c in range(lo, hi):
        cstart[m, c] = acc
        acc += cfill[m, c]
        cfill[m, c] = 0
    if t == nt - 1:
        cstart[m, ncell] = ip[I_N]


@cuda.jit(device=True)
def _fill(m, t, nt, cstart, cfill, cidx, key, ip):
    """List build, phase 3: the particles' rows by cell (order within a cell arbitrary:
    each list is sorted afterwards)."""
    N = ip[I_N]
    base = m * N
    for i in range(t, N, nt):
        g = base + i
        c = key[g]
        slot = cstart[m, c] + cuda.atomic.add(cfill, (m, c), 1)
        cidx[base + slot] = g


@cuda.jit(device=True)
def _lists(m, t, nt, s, cur, aux, nbr, nnb, spr, lst, cstart, cidx, ctl, fp, ip):
    """List build, phase 4: each particle's neighbours within the cutoff from the 3 x 3
    cells around it, ascending, into list buffer 1 - lst, with the springs of the contacts
    it already had; its reference position."""
    N = ip[I_N]
    ncx = ip[I_NCX]
    ncy = ip[I_NCY]
    K = ip[I_K]
    periodic = ip[I_PERIODIC] != 0
    inv_cw = 1.0 / fp[F_CELL_W]
    inv_ch = 1.0 / fp[F_CELL_H]
    H = fp[F_H]
    halfH = 0.5 * H
    cut2 = fp[F_CUT] * fp[F_CUT]
    base = m * N
    new = 1 - lst
    for i in range(t, N, nt):
        g = base + i
        xi = s[cur, 0, g]
        yi = s[cur, 1, g]
        cx = _cell_index(xi, inv_cw, ncx)
        cy = _cell_index(yi, inv_ch, ncy)
        n = 0
        for oy in range(-1, 2):
            ry = cy + oy
            if periodic:
                ry = ry + ncy if ry < 0 else ry
                ry = ry - ncy if ry >= ncy else ry
            elif ry < 0 or ry >= ncy:
                continue
            for ox in range(-1, 2):
                rx = cx + ox
                if rx < 0 or rx >= ncx:
                    continue
                c = ry * ncx + rx
                for q in range(cstart[m, c], cstart[m, c + 1]):
                    j = cidx[base + q]
                    if j == g:
                        continue
                    dx = s[cur, 0, j] - xi
                    dy = s[cur, 1, j] - yi
                    if periodic:
                        if dy > halfH:
                            dy -= H
                        elif dy < -halfH:
                            dy += H
                    if dx * dx + dy * dy >= cut2:
                        continue
                    if n < K:
                        # insert j in ascending order, with its spring from the old list
                        hx = 0.0
                        hy = 0.0
                        for k in range(nnb[lst, g]):
                            if nbr[lst, k, g] == j:
                                hx = spr[lst, 0, k, g]
                                hy = spr[lst, 1, k, g]
                                break
                        k = n
                        while k > 0 and nbr[new, k - 1, g] > j:
                            nbr[new, k, g] = nbr[new, k - 1, g]
                            spr[new, 0, k, g] = spr[new, 0, k - 1, g]
                            spr[new, 1, k, g] = spr[new, 1, k - 1, g]
                            k -= 1
                        nbr[new, k, g] = j
                        spr[new, 0, k, g] = hx
                        spr[new, 1, k, g] = hy
                    n += 1
        if n > K:
            ctl[m, C_OVERFLOW] = n
            n = K
        nnb[new, g] = n
        aux[0, g] = xi
        aux[1, g] = yi


@cuda.jit(device=True)
def _walls(g, s, cur, wh, fx, fy, tq, fp, ip):
    """Particle g's contacts with the side walls and the floor (or their springs cleared),
    added to (fx, fy, tq), as :func:`cfbmarkov.simulate.dem.integrate._walls`. Returns
    (fx, fy, tq, bad reason or 0)."""
    dt = fp[F_DT]
    W = fp[F_W]
    ovl = fp[F_OVL]
    xi = s[cur, 0, g]
    yi = s[cur, 1, g]
    vxi = s[cur, 2, g]
    vyi = s[cur, 3, g]
    ui = s[cur, 4, g]
    Ri = s[cur, 5, g]
    kn = fp[F_KN]
    kt = fp[F_KT]
    inv_kt = fp[F_INV_KT]
    mu = fp[F_MU]
    if ip[I_MONO] != 0:
        etan = fp[F_ETAN_PW]
        etat = fp[F_ETAT_PW]
    else:
        sm = 1.0 / math.sqrt(s[cur, 6, g])
        etan = fp[F_CN] * sm
        etat = fp[F_CT] * sm
    isbad = 0
    if xi < Ri:  # left wall, n = (-1, 0)
        delta = Ri - xi
        if delta > 2.0 * ovl * Ri:
            isbad = BAD_OVERLAP
        fn, _, ft, _, h = law(delta, -vxi, 0.0, 0.0, 0.0, vyi - ui, 0.0, wh[0, g], kn, kt,
                              inv_kt, etan, etat, mu, dt, True)
        wh[0, g] = h
        fx += fn
        fy += ft
        tq -= Ri * ft
    else:
        wh[0, g] = 0.0
    if xi > W - Ri:  # right wall, n = (1, 0)
        delta = xi + Ri - W
        if delta > 2.0 * ovl * Ri:
            isbad = BAD_OVERLAP
        fn, _, ft, _, h = law(delta, vxi, 0.0, 0.0, 0.0, vyi + ui, 0.0, wh[1, g], kn, kt,
                              inv_kt, etan, etat, mu, dt, True)
        wh[1, g] = h
        fx -= fn
        fy += ft
        tq += Ri * ft
    else:
        wh[1, g] = 0.0
    if ip[I_FLOOR] != 0 and yi < Ri:  # floor, n = (0, -1)
        delta = Ri - yi
        if delta > 2.0 * ovl * Ri:
            isbad = BAD_OVERLAP
        fn, _, ft, _, h = law(delta, -vyi, 0.0, 0.0, 0.0, vxi + ui, 0.0, wh[2, g], kn, kt,
                              inv_kt, etan, etat, mu, dt, True)
        wh[2, g] = h
        fy += fn
        fx += ft
        tq += Ri * ft
    else:
        wh[2, g] = 0.0
    return fx, fy, tq, isbad


@cuda.jit(device=True)
def _step_particle(m, g, s, cur, aux, ext, wh, laps, nbr, nnb, spr, lst, ctl, ev_s, ev_f, ev_p,
                   ev_d, bad, step, fp, ip):
    """Particle g's forces (its list, walls, external, gravity), leapfrog update into buffer
    1 - cur and checks, as :func:`cfbmarkov.simulate.dem.integrate._integrate`. Returns
    whether it moved beyond skin/2 since the build."""
    dt = fp[F_DT]
    W = fp[F_W]
    H = fp[F_H]
    halfH = 0.5 * H
    kn = fp[F_KN]
    kt = fp[F_KT]
    inv_kt = fp[F_INV_KT]
    mu = fp[F_MU]
    ovl = fp[F_OVL]
    mono = ip[I_MONO] != 0
    periodic = ip[I_PERIODIC] != 0
    xi = s[cur, 0, g]
    yi = s[cur, 1, g]
    vxi = s[cur, 2, g]
    vyi = s[cur, 3, g]
    ui = s[cur, 4, g]
    Ri = s[cur, 5, g]
    imi = s[cur, 6, g]
    rIi = s[cur, 7, g]
    fx = ext[0, g]
    fy = ext[1, g]
    tq = 0.0
    isbad = 0
    for k in range(nnb[lst, g]):
        j = nbr[lst, k, g]
        dx = s[cur, 0, j] - xi
        dy = s[cur, 1, j] - yi
        if periodic:
            if dy > halfH:
                dy -= H
            elif dy < -halfH:
                dy += H
        rs = Ri + s[cur, 5, j]
        r2 = dx * dx + dy * dy
        if r2 >= rs * rs:
            spr[lst, 0, k, g] = 0.0
            spr[lst, 1, k, g] = 0.0
            continue
        r = math.sqrt(r2)
        inv_r = 1.0 / r
        nx = dx * inv_r
        ny = dy * inv_r
        delta = rs - r
        if delta > ovl * rs:
            isbad = BAD_OVERLAP
        wsum = ui + s[cur, 4, j]
        vrx = (vxi - s[cur, 2, j]) - wsum * ny
        vry = (vyi - s[cur, 3, j]) + wsum * nx
        vn = vrx * nx + vry * ny
        vtx = vrx - vn * nx
        vty = vry - vn * ny
        if mono:
            etan = fp[F_ETAN_PP]
            etat = fp[F_ETAT_PP]
        else:
            sm = 1.0 / math.sqrt(imi + s[cur, 6, j])
            etan = fp[F_CN] * sm
            etat = fp[F_CT] * sm
        fn, ftx, fty, hx, hy = law(delta, vn, nx, ny, vtx, vty, spr[lst, 0, k, g],
                                   spr[lst, 1, k, g], kn, kt, inv_kt, etan, etat, mu, dt,
                                   False)
        spr[lst, 0, k, g] = hx
        spr[lst, 1, k, g] = hy
        fx += ftx - fn * nx
        fy += fty - fn * ny
        tq += Ri * (nx * fty - ny * ftx)
    fx, fy, tq, wbad = _walls(g, s, cur, wh, fx, fy, tq, fp, ip)
    if wbad != 0:
        isbad = wbad
    # leapfrog, in the CPU engine's order
    vxn = vxi + dt * (fx * imi)
    vyn = vyi + dt * (fy * imi - fp[F_G])
    wn = ui + dt * (tq * rIi)
    xn = xi + dt * vxn
    yn = yi + dt * vyn
    if periodic:
        up = yn >= H
        down = yn < 0.0
        if up:
            yn = yn - H
        if down:
            yn = yn + H
            if yn >= H:  # a step of -1e-17 rounds to H: that is 0
                yn = 0.0
        d = (1 if up else 0) - (1 if down else 0)
        if d != 0:
            laps[g] += d
            e = cuda.atomic.add(ctl, (m, C_NEV), 1)
            if e < ip[I_EVCAP]:
                dyy = dt * vyn
                if d > 0:
                    frac = (H - yi) / dyy if dyy > 0.0 else 1.0
                else:
                    frac = -yi / dyy if dyy < 0.0 else 1.0
                if not (frac >= 0.0):
                    frac = 0.0
                elif frac > 1.0:
                    frac = 1.0
                ev_s[m, e] = step
                ev_f[m, e] = frac
                ev_p[m, e] = g - m * ip[I_N]
                ev_d[m, e] = d
        if not (yn >= 0.0 and yn < H):
            isbad = BAD_RANGE
        ddy = yn - aux[1, g]
        if ddy > halfH:
            ddy -= H
        if ddy < -halfH:
            ddy += H
    else:
        if yn < -Ri:
            isbad = BAD_WALL
        ddy = yn - aux[1, g]
    if xn < -Ri or xn > W + Ri:
        isbad = BAD_WALL
    if not (xn == xn and yn == yn and wn == wn and vxn == vxn and vyn == vyn):
        isbad = BAD_NAN
    if isbad != 0:
        bad[g] = isbad
        cuda.atomic.add(ctl, (m, C_BAD), 1)
    o = 1 - cur
    s[o, 0, g] = xn
    s[o, 1, g] = yn
    s[o, 2, g] = vxn
    s[o, 3, g] = vyn
    s[o, 4, g] = wn
    s[o, 5, g] = Ri
    s[o, 6, g] = imi
    s[o, 7, g] = rIi
    ddx = xn - aux[0, g]
    hs = 0.5 * fp[F_SKIN]
    return ddx * ddx + ddy * ddy > hs * hs


def _make_advance(grid):
    """The advance kernel; ``grid``: several blocks per member, synchronised grid-wide
    (a cooperative launch; not available under the CUDA simulator), else one block per
    member synchronised with ``cuda.syncthreads()``. One source for both."""
    if grid:
        @cuda.jit(device=True)
        def sync():
            cuda.cg.this_grid().sync()
    else:
        @cuda.jit(device=True)
        def sync():
            cuda.syncthreads()

    @cuda.jit(device=True)
    def halted(ctl, m, target, N, cap):
        """Whether member m (every member, on a grid) must stop before its next step."""
        lo = 0 if grid else m
        hi = ctl.shape[0] if grid else m + 1
        stop = False
        for q in range(lo, hi):
            if (ctl[q, C_STEP] >= target or ctl[q, C_BAD] != 0 or ctl[q, C_OVERFLOW] != 0
                    or ctl[q, C_NEV] + N > cap):
                stop = True
        return stop

    @cuda.jit(device=True)
    def overflowed(ctl, m):
        lo = 0 if grid else m
        hi = ctl.shape[0] if grid else m + 1
        stop = False
        for q in range(lo, hi):
            if ctl[q, C_OVERFLOW] != 0:
                stop = True
        return stop

    @cuda.jit
    def advance(s, aux, ext, wh, laps, nbr, nnb, spr, cstart, cfill, part, cidx, key, ctl,
                ev_s, ev_f, ev_p, ev_d, bad, fp, ip, blocks_per_member, target):
        """Advance every member to step ``target``: list builds when due, then the steps,
        until ``target``, an event buffer that could overflow in the next step, a bad
        particle or a list overflow (see the module doc)."""
        b = cuda.blockIdx.x
        m = b // blocks_per_member
        t = (b - m * blocks_per_member) * cuda.blockDim.x + cuda.threadIdx.x
        nt = blocks_per_member * cuda.blockDim.x
        N = ip[I_N]
        base = m * N
        cap = ip[I_EVCAP]
        while True:
            sync()
            # every thread reads the control slots after the barrier: the branches below
            # are uniform over the member (the grid)
            step = ctl[m, C_STEP]
            stop = halted(ctl, m, target, N, cap)
            rebuild = ctl[m, C_REBUILD] != 0
            cur = ctl[m, C_CUR]
            lst = ctl[m, C_LIST]
            sync()
            if stop:
                return
            if grid:  # members in step: any member's rebuild is every member's
                for q in range(ctl.shape[0]):
                    if ctl[q, C_REBUILD] != 0:
                        rebuild = True
                sync()
            if rebuild:
                for c in range(t, ip[I_NCX] * ip[I_NCY], nt):
                    cfill[m, c] = 0
                sync()
                _count(m, t, nt, s, cur, cfill, key, ip, fp)
                sync()
                _scan_partial(m, t, nt, cfill, part, ip)
                sync()
                if t == 0:
                    _scan_totals(m, nt, part)
                sync()
                _scan_cells(m, t, nt, cfill, cstart, part, ip)
                sync()
                _fill(m, t, nt, cstart, cfill, cidx, key, ip)
                sync()
                _lists(m, t, nt, s, cur, aux, nbr, nnb, spr, lst, cstart, cidx, ctl, fp, ip)
                sync()
                if t == 0:
                    ctl[m, C_LIST] = 1 - lst
                    ctl[m, C_REBUILD] = 0
                lst = 1 - lst
                sync()
                if overflowed(ctl, m):
                    return
            moved = False
            for i in range(t, N, nt):
                if _step_particle(m, base + i, s, cur, aux, ext, wh, laps, nbr, nnb, spr, lst,
                                  ctl, ev_s, ev_f, ev_p, ev_d, bad, step, fp, ip):
                    moved = True
            if moved:
                ctl[m, C_REBUILD] = 1
            sync()
            if t == 0:
                ctl[m, C_CUR] = 1 - cur
                ctl[m, C_STEP] = step + 1

    return advance


#: one block per member (tested under the CUDA simulator)
advance = _make_advance(False)
_grid_advance = []


def grid_advance():
    """The grid-synchronised variant of :data:`advance` (several blocks per member; made on
    first use: it needs a GPU, as the CUDA simulator has no grid synchronisation)."""
    if not _grid_advance:
        _grid_advance.append(_make_advance(True))
    return _grid_advance[0]
