"""Data layout of the 2D DEM engine: parameters, array records, list buffers, control slots.

The numba kernels (:mod:`.contact`, :mod:`.neighbours`, :mod:`.integrate`) work on plain
arrays and on the named parameter tuple :class:`DEMParams`; :mod:`.system` owns them all.
All per-particle arrays are in *cell order*, i.e. sorted by search cell at the last list
build (:func:`.neighbours.rebuild`).

Arrays (N particles)::

    st    float64 (2, N, 8): two buffers of one 64-byte record per particle,
          x, y, vx, vy, u = R*omega, R, 1/m, R/I (u, the surface speed, is what the
          contact kinematics needs: R_a*omega_a + R_b*omega_b = u_a + u_b). A step reads
          buffer ctl[C_ST] and writes the other one, then the buffers swap (no particle
          reads a half-updated neighbour).
    aux   float64 (2, N, 4): x_ref, y_ref (position at the last list build), external
          force fx, fy; wh float64 (2, N, 3) wall tangential springs (left, right,
          floor); ids int64 (2, N) caller's index of each sorted particle; laps
          int64 (2, N). These swap buffers at each rebuild (ctl[C_PA]).
    lists two PairList buffers A/B (ctl[C_LIST] says which is current): the full
          Verlet list of each particle (fixed stride S, used while building) and the
          pair list derived from it (see PairList).
    ctl   int64 (N_C,): the mutable control slots C_* (saved with a checkpoint; a state
          saved with fewer slots is read with zeros in the missing ones).
    prm   DEMParams: the constant parameters of a system (floats, ints, flags).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# control slots of ``ctl``
C_ST, C_PA, C_LIST, C_REBUILD, C_STEP, C_NREBUILD, C_NEV = 0, 1, 2, 3, 4, 5, 6
#: the list's drift velocity in y (nm/s, an integer) and the step of its build: a list
#: stays valid while every particle stays within skin/2 of its reference position moved by
#: the drift since the build (:func:`.neighbours.drift_velocity`)
C_DRIFT, C_BUILT = 7, 8
N_C = 9
#: units of ``ctl[C_DRIFT]``, m/s
DRIFT_UNIT = 1e-9
# statuses returned by advance()
ST_OK, ST_STRIDE, ST_EVENTS, ST_BLOWUP = 0, 1, 2, 3
# reasons in bad[]
BAD_NAN, BAD_WALL, BAD_OVERLAP, BAD_RANGE = 1, 2, 3, 4


class DEMParams(NamedTuple):
    """Constant parameters of a DEM system, passed by value into the numba kernels.

    A heterogeneous named tuple: numba passes it by value as a struct (no load through a
    pointer, as from a parameter array, a ``structref`` or a jitclass), and cached
    compilation (``cache=True``) works with it. Kernels read the fields they need into
    locals before their loops.

    Attributes
    ----------
    dt : float
        DEM time step, s.
    width, height : float
        W and H of the domain, m.
    gravity : float
        Gravitational acceleration acting in -y, m/s^2.
    kn, kt : float
        Normal and tangential spring stiffness, N/m.
    inv_kt : float
        1/kt, m/N.
    mu : float
        Coulomb friction coefficient, -.
    etan_pp, etat_pp, etan_pw, etat_pw : float
        Normal/tangential damping coefficients (kg/s) of particle-particle (reduced mass
        m/2) and particle-wall (m_ab = m) contacts of equal particles (used when ``mono``).
    cn, ct : float
        Damping factors c with eta = c*sqrt(m_ab), kg^(1/2)/s (used when not ``mono``).
    skin : float
        Verlet skin, m.
    cell_w, cell_h : float
        Search-cell width and height, m.
    rmax : float
        Largest particle radius, m.
    max_overlap : float
        Blow-up limit: an overlap above this fraction of R_a + R_b (of 2R at a wall), -.
    t0 : float
        Time at step 0, s.
    ncx, ncy : int
        Search cells across and up.
    periodic : bool
        y is periodic with period ``height``.
    floor : bool
        A contact wall at y = 0 (instead of periodicity).
    mono : bool
        All particles have the same radius and density.
    """

    dt: float
    width: float
    height: float
    gravity: float
    kn: float
    kt: float
    inv_kt: float
    mu: float
    etan_pp: float
    etat_pp: float
    etan_pw: float
    etat_pw: float
    cn: float
    ct: float
    skin: float
    cell_w: float
    cell_h: float
    rmax: float
    max_overlap: float
    t0: float
    ncx: int
    ncy: int
    periodic: bool
    floor: bool
    mono: bool


class PairList(NamedTuple):
    """One neighbour/pair-list buffer (all arrays; N particles, stride S, capacity P pairs).

    The half Verlet list of each particle (its neighbours that come after it in cell
    order) and the *pair list* derived from it: pairs (pi < pj) grouped by first member
    (``pstart``), the tangential spring of each pair (from the first member's side), and for
    each particle the pairs in which it is the second member (``lowstart``/``lowpid``).

    Attributes
    ----------
    nnb, nown : int32 (N,)
        Neighbours of each particle, and how many of them come after it.
    nbr : int32 (N*S,)
        Indices of the neighbours after each particle, row k at ``k*S``.
    pstart : int64 (N + 1,)
        First pair of each particle as first member; ``pstart[N]`` is the number of pairs.
    pi, pj : int32 (P,)
        First and second member of each pair.
    springs : float64 (P, 2)
        Tangential spring of each pair (x, y), m.
    lowstart : int64 (N + 1,)
        Start of each particle's row in ``lowpid``.
    lowpid : int64 (P,)
        Pairs in which the particle is the second member.
    """

    nnb: np.ndarray
    nown: np.ndarray
    nbr: np.ndarray
    pstart: np.ndarray
    pi: np.ndarray
    pj: np.ndarray
    springs: np.ndarray
    lowstart: np.ndarray
    lowpid: np.ndarray


def empty_list(n: int, stride: int) -> PairList:
    """A zeroed list buffer for ``n`` particles with ``stride`` neighbours each.

    Parameters
    ----------
    n : int
        Number of particles.
    stride : int
        Room for neighbours per particle (S).

    Returns
    -------
    PairList
        The pair arrays have room for ``n*stride`` pairs (each pair appears once, in its
        first member's strided row).
    """
    cap = max(1, n * stride)
    return PairList(np.zeros(n, np.int32), np.zeros(n, np.int32), np.zeros(n * stride, np.int32),
                    np.zeros(n + 1, np.int64), np.zeros(cap, np.int32), np.zeros(cap, np.int32),
                    np.zeros((cap, 2), np.float64), np.zeros(n + 1, np.int64),
                    np.zeros(cap, np.int64))


def particle_arrays(positions, velocities, radius, spin, mass, inertia, laps) -> dict:
    """The double-buffered particle arrays of a new system, in the caller's order (its
    first list build sorts them into cell order).

    Parameters
    ----------
    positions, velocities : ndarray of float64, shape (N, 2)
        Centres (m) and half-step velocities (m/s).
    radius, spin, mass, inertia : ndarray of float64, shape (N,)
        R (m), omega (rad/s), m (kg) and I (kg m^2).
    laps : ndarray of int64, shape (N,)
        Passes through the periodic boundary so far.

    Returns
    -------
    dict
        ``st``, ``aux``, ``wh``, ``ids``, ``laps`` (buffer 0 filled, see the module
        docstring) and ``ctl`` (a list build due).
    """
    n = positions.shape[0]
    st = np.zeros((2, n, 8))
    st[0, :, 0:2] = positions
    st[0, :, 2:4] = velocities
    st[0, :, 4] = radius * spin  # surface speed R*omega
    st[0, :, 5] = radius
    st[0, :, 6] = 1.0 / mass
    st[0, :, 7] = radius / inertia
    st[1] = st[0]
    aux = np.zeros((2, n, 4))
    aux[0, :, 0:2] = positions
    ids = np.zeros((2, n), np.int64)
    ids[0] = np.arange(n)
    lp = np.zeros((2, n), np.int64)
    lp[0] = laps
    ctl = np.zeros(N_C, np.int64)
    ctl[C_REBUILD] = 1
    return dict(st=st, aux=aux, wh=np.zeros((2, n, 3)), ids=ids, laps=lp, ctl=ctl)
