"""CUDA kernels of the particle-fluid coupling of a GPU ensemble (numba-cuda). No I/O.

The formulas are the CPU's (:mod:`cfbmarkov.simulate.cfd.coupling`,
:mod:`cfbmarkov.simulate.coupling`): the kernels call the same scalar functions
(:func:`~cfbmarkov.simulate.cfd.coupling.solid_weights`,
:func:`~cfbmarkov.simulate.cfd.coupling._face_weights`, ``_u_weights``/``_v_weights``,
:func:`~cfbmarkov.simulate.coupling.cell_weights`,
:func:`~cfbmarkov.simulate.cfd.drag.particle_drag_jacobian`), which numba compiles for the
device where a kernel calls them, and write the same sums in the same order.

Deterministic deposits, no float atomics: member m's particles are cut by index into C
fixed chunks (``[c N / C, (c + 1) N / C)``, as the CPU's ``DEPOSIT_CHUNKS`` of
:mod:`cfbmarkov.simulate.cfd.coupling`); thread (m, c) adds its chunk's particles, in index
order, to its own copy of the fields, and one thread per grid node then sums the copies in
chunk order and zeroes them for the next gas step (so no thread clears a whole grid). The
results depend on C only (not on the launch shape or the other members); with
C = DEPOSIT_CHUNKS the sums are the CPU's, term for term.

On a GPU numba compiles each of those CPU functions once more for the device where a
kernel calls it (a numba ``njit`` function called from a CUDA kernel); the kernels compile
to PTX for sm_90 (checked with libNVVM, without a GPU: :func:`compile_ptx`), and under the
CUDA simulator the CPU functions run as they are.

Layout (member-major, as :mod:`.kernels`): particle fields from ``s[ctl[m, C_CUR]]``;
grid fields ``(M, nx, ny)`` (cells, v faces) and ``(M, nx + 1, ny)`` (u faces); chunk copies
``(M, C, ...)``; per particle ``coef (M*N)`` K_p and ``frc (2, M*N)`` the drag at the old gas;
the drag at the new gas goes into the DEM's external force ``ext (2, M*N)``.

Parameters ``cp`` (float64): 1/dx, 1/dy, dx, dy, solid volume of a particle, cell volume,
void fraction floor, 1 / cell volume, d, rho_g, mu_g; ``cq`` (int64): N, M, C, nx, ny,
periodic in y.
"""

from __future__ import annotations

import math

from cfbmarkov.simulate.cfd.coupling import _face_weights, _u_weights, _v_weights, solid_weights
from cfbmarkov.simulate.cfd.drag import particle_drag_jacobian
from cfbmarkov.simulate.coupling import cell_weights
from cfbmarkov.simulate.gpu._cuda import cuda
from cfbmarkov.simulate.gpu.kernels import C_CUR

P_IDX, P_IDY, P_DX, P_DY, P_VOLUME, P_CELL, P_FLOOR, P_INV_CELL, P_D, P_RHO, P_MU = range(11)
N_P = 11
Q_N, Q_M, Q_C, Q_NX, Q_NY, Q_PERIODIC = range(6)
N_Q = 6


@cuda.jit(device=True)
def _gas_velocity(u, v, m, nx, ny, idx, idy, x, y):
    """Member m's gas velocity at (x, y): the CPU's ``_gas_velocity``, line for line."""
    i0, j0, j1, wx, wy = _u_weights(x, y, nx, ny, idx, idy)
    ux = ((1.0 - wy) * ((1.0 - wx) * u[m, i0, j0] + wx * u[m, i0 + 1, j0])
          + wy * ((1.0 - wx) * u[m, i0, j1] + wx * u[m, i0 + 1, j1]))
    ia, ib, wa, wb, k0, k1, vy = _v_weights(x, y, nx, ny, idx, idy)
    uy = ((1.0 - vy) * (wa * v[m, ia, k0] + wb * v[m, ib, k0])
          + vy * (wa * v[m, ia, k1] + wb * v[m, ib, k1]))
    return ux, uy


@cuda.jit
def solid_chunks(s, ctl, part, cp, cq):
    """Thread (m, c): member m's chunk c of particles, their solid volume onto
    ``part[m, c]`` (zero on entry: :func:`void_fraction` zeroes it after reading) by
    cloud-in-cell (the CPU's ``_add_solid_volume``)."""
    t = cuda.grid(1)
    n, nm, nc, nx, ny = cq[Q_N], cq[Q_M], cq[Q_C], cq[Q_NX], cq[Q_NY]
    if t >= nm * nc:
        return
    m = t // nc
    c = t - m * nc
    cur = ctl[m, C_CUR]
    idx, idy, volume = cp[P_IDX], cp[P_IDY], cp[P_VOLUME]
    periodic = cq[Q_PERIODIC] != 0
    for p in range(c * n // nc, (c + 1) * n // nc):
        r = m * n + p
        i0, i1, j0, j1, wx, wy = solid_weights(s[cur, 0, r], s[cur, 1, r], nx, ny, idx, idy,
                                               periodic)
        part[m, c, i0, j0] += (1.0 - wx) * (1.0 - wy) * volume
        part[m, c, i1, j0] += wx * (1.0 - wy) * volume
        part[m, c, i0, j1] += (1.0 - wx) * wy * volume
        part[m, c, i1, j1] += wx * wy * volume


@cuda.jit
def void_fraction(part, eps, cp, cq):
    """Thread (m, cell): the chunks' solid volume summed in chunk order, eps = 1 - solid /
    (dx dy d), clipped below at the floor (the CPU's ``void_fraction_field``); the copies
    are left zero for the next gas step."""
    t = cuda.grid(1)
    nm, nc, nx, ny = cq[Q_M], cq[Q_C], cq[Q_NX], cq[Q_NY]
    if t >= nm * nx * ny:
        return
    m = t // (nx * ny)
    k = t - m * nx * ny
    i = k // ny
    j = k - i * ny
    acc = 0.0
    for c in range(nc):
        acc += part[m, c, i, j]
        part[m, c, i, j] = 0.0
    e = 1.0 - acc / cp[P_CELL]
    eps[m, i, j] = e if e >= cp[P_FLOOR] else cp[P_FLOOR]


@cuda.jit
def drag_at_old_gas(s, ctl, u, v, eps, coef, frc, cp, cq):
    """Thread per particle: K_p and the drag force K_p (u_gas - v_p) at the gas of the step's
    start (the CPU's ``drag_coefficients``)."""
    r = cuda.grid(1)
    n, nm, nx, ny = cq[Q_N], cq[Q_M], cq[Q_NX], cq[Q_NY]
    if r >= nm * n:
        return
    m = r // n
    cur = ctl[m, C_CUR]
    x = s[cur, 0, r]
    y = s[cur, 1, r]
    ux, uy = _gas_velocity(u, v, m, nx, ny, cp[P_IDX], cp[P_IDY], x, y)
    i0, i1, j0, j1, wx, wy = cell_weights(nx, ny, cp[P_DX], cp[P_DY], x, y,
                                          cq[Q_PERIODIC] != 0)
    e = ((1.0 - wy) * ((1.0 - wx) * eps[m, i0, j0] + wx * eps[m, i1, j0])
         + wy * ((1.0 - wx) * eps[m, i0, j1] + wx * eps[m, i1, j1]))
    sx = ux - s[cur, 2, r]
    sy = uy - s[cur, 3, r]
    k = particle_drag_jacobian(e, math.sqrt(sx * sx + sy * sy), cp[P_D], cp[P_RHO], cp[P_MU])
    coef[r] = k
    frc[0, r] = k * sx
    frc[1, r] = k * sy


@cuda.jit(device=True)
def _add_to_faces(fu, fv, m, c, gx, gy, i0, j0, j1, w0, w1, wy, ia, ib, wa, wb, k0, k1, vy):
    """The CPU's ``_add_to_faces`` on chunk copy (m, c)."""
    fu[m, c, i0, j0] += (1.0 - wy) * w0 * gx
    fu[m, c, i0 + 1, j0] += (1.0 - wy) * w1 * gx
    fu[m, c, i0, j1] += wy * w0 * gx
    fu[m, c, i0 + 1, j1] += wy * w1 * gx
    fv[m, c, ia, k0] += (1.0 - vy) * wa * gy
    fv[m, c, ib, k0] += (1.0 - vy) * wb * gy
    fv[m, c, ia, k1] += vy * wa * gy
    fv[m, c, ib, k1] += vy * wb * gy


@cuda.jit
def drag_chunks(s, ctl, coef, frc, pu, pv, pku, pkv, cp, cq):
    """Thread (m, c): chunk c's drag forces and coefficients per unit volume onto its
    copies of the u and v faces (zero on entry: :func:`face_sums` zeroes them after
    reading), the CPU's ``_deposit_particle``."""
    t = cuda.grid(1)
    n, nm, nc, nx, ny = cq[Q_N], cq[Q_M], cq[Q_C], cq[Q_NX], cq[Q_NY]
    if t >= nm * nc:
        return
    m = t // nc
    c = t - m * nc
    cur = ctl[m, C_CUR]
    idx, idy, inv = cp[P_IDX], cp[P_IDY], cp[P_INV_CELL]
    for p in range(c * n // nc, (c + 1) * n // nc):
        r = m * n + p
        gx = frc[0, r] * inv
        gy = frc[1, r] * inv
        gk = coef[r] * inv
        if gx == 0.0 and gy == 0.0 and gk == 0.0:
            continue
        i0, j0, j1, w0, w1, wy, ia, ib, wa, wb, k0, k1, vy = _face_weights(
            s[cur, 0, r], s[cur, 1, r], nx, ny, idx, idy)
        if gx != 0.0 or gy != 0.0:
            _add_to_faces(pu, pv, m, c, gx, gy, i0, j0, j1, w0, w1, wy, ia, ib, wa, wb, k0,
                          k1, vy)
        if gk != 0.0:
            _add_to_faces(pku, pkv, m, c, gk, gk, i0, j0, j1, w0, w1, wy, ia, ib, wa, wb, k0,
                          k1, vy)


@cuda.jit
def face_sums(pu, pv, pku, pkv, fu, fv, ku, kv, cq):
    """Thread (m, u face): the chunk copies summed in chunk order into fu, ku (and fv, kv
    where the face index is also a v node), the CPU's ``_sum_chunks``; the copies are left
    zero for the next gas step."""
    t = cuda.grid(1)
    nm, nc, nx, ny = cq[Q_M], cq[Q_C], cq[Q_NX], cq[Q_NY]
    if t >= nm * (nx + 1) * ny:
        return
    m = t // ((nx + 1) * ny)
    k = t - m * (nx + 1) * ny
    i = k // ny
    j = k - i * ny
    a = 0.0
    b = 0.0
    for c in range(nc):
        a += pu[m, c, i, j]
        b += pku[m, c, i, j]
        pu[m, c, i, j] = 0.0
        pku[m, c, i, j] = 0.0
    fu[m, i, j] = a
    ku[m, i, j] = b
    if i < nx:
        a = 0.0
        b = 0.0
        for c in range(nc):
            a += pv[m, c, i, j]
            b += pkv[m, c, i, j]
            pv[m, c, i, j] = 0.0
            pkv[m, c, i, j] = 0.0
        fv[m, i, j] = a
        kv[m, i, j] = b


@cuda.jit
def drag_at_new_gas(s, ctl, u, v, coef, ext, cp, cq):
    """Thread per particle: F_p = K_p (u_gas^{n+1}(x_p) - v_p) into the DEM's external force
    (the CPU's ``drag_force_at_new_gas``)."""
    r = cuda.grid(1)
    n, nm, nx, ny = cq[Q_N], cq[Q_M], cq[Q_NX], cq[Q_NY]
    if r >= nm * n:
        return
    m = r // n
    cur = ctl[m, C_CUR]
    ux, uy = _gas_velocity(u, v, m, nx, ny, cp[P_IDX], cp[P_IDY], s[cur, 0, r], s[cur, 1, r])
    ext[0, r] = coef[r] * (ux - s[cur, 2, r])
    ext[1, r] = coef[r] * (uy - s[cur, 3, r])


#: the kernels of this module by name, with their argument kinds for :func:`compile_ptx`:
#: "p" particle fields (3-D), "c" control slots (2-D int64), "g" a grid field per member
#: (3-D), "k" chunk copies (4-D), "v" per-particle (1-D), "f" per-particle pairs (2-D),
#: "P"/"Q" the float/int parameters
KERNEL_ARGS = {"solid_chunks": "pckPQ", "void_fraction": "kgPQ",
               "drag_at_old_gas": "pcgggvfPQ", "drag_chunks": "pcvfkkkkPQ",
               "face_sums": "kkkkggggQ", "drag_at_new_gas": "pcggvfPQ"}


def compile_ptx(cc=(9, 0)) -> dict[str, int]:
    """Compile every kernel of this module to PTX for compute capability ``cc``, without a
    GPU (libNVVM only): a check that numba-cuda types and lowers them, CPU functions
    called as device functions included.

    Returns
    -------
    dict
        Kernel name -> PTX length (characters).

    Raises
    ------
    Exception
        What numba-cuda raises: a typing or lowering error, or no libNVVM.
    """
    import types as _types
    from unittest import mock

    from numba import types as T

    import numba.cuda.dispatcher as dispatcher

    kinds = {"p": T.Array(T.float64, 3, "C"), "c": T.Array(T.int64, 2, "C"),
             "g": T.Array(T.float64, 3, "C"), "k": T.Array(T.float64, 4, "C"),
             "v": T.Array(T.float64, 1, "C"), "f": T.Array(T.float64, 2, "C"),
             "P": T.Array(T.float64, 1, "C"), "Q": T.Array(T.int64, 1, "C")}
    out = {}
    # device functions are compiled for the current device's compute capability: give it
    device = _types.SimpleNamespace(compute_capability=tuple(cc))
    with mock.patch.object(dispatcher, "get_current_device", lambda: device):
        for name, args in KERNEL_ARGS.items():
            ptx, _ = cuda.compile_ptx(globals()[name].py_func, tuple(kinds[a] for a in args),
                                      cc=tuple(cc))
            out[name] = len(ptx)
    return out
