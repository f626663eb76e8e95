"""Data layout of the gas step: the named tuples that :func:`.solver._step_kernel` takes.

The numba kernel works on plain arrays grouped in four named tuples, passed by value
(numba passes a heterogeneous named tuple as a struct, and cached compilation works with
it): :class:`GasParams` (the constants of a step), :class:`GasStepFields` (the fields it
starts from), :class:`GasStepOutput` (the fields it writes) and :class:`GasWorkspace` (a
solver's scratch and its cached factorisation). :class:`.solver.GasSolver` owns them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class GasParams(NamedTuple):
    """Constant parameters of one gas step, passed by value into :func:`_step_kernel`.

    Attributes
    ----------
    nx, ny : int
        Cells across and up.
    dx, dy : float
        Cell width and height, m.
    dt : float
        Time step, s.
    rho : float
        Gas density, kg/m^3.
    nu : float
        Kinematic viscosity, m^2/s.
    gravity : float
        Gravitational acceleration acting in -y, m/s^2.
    U : float
        Superficial velocity (domain mean of eps v), m/s.
    model_a : bool
        Formulation A (``w = eps``), else B (``w = 1``).
    scheme : int
        Advection scheme (a value of :data:`~.momentum.SCHEMES`).
    rtol : float
        Relative continuity residual at which a step fails.
    distributor : bool
        The grid has a distributor at the floor (see :mod:`.grid`).
    """

    nx: int
    ny: int
    dx: float
    dy: float
    dt: float
    rho: float
    nu: float
    gravity: float
    U: float
    model_a: bool
    scheme: int
    rtol: float
    distributor: bool


class GasStepFields(NamedTuple):
    """The fields one gas step starts from (read only).

    Attributes
    ----------
    u, v : ndarray of float64, shape (nx+1, ny), (nx, ny)
        Velocities on the x- and y-faces, m/s.
    eps_old, eps_new : ndarray of float64, shape (nx, ny)
        Void fraction before and after the step.
    fu, fv : ndarray of float64, shapes of u, v
        Drag force per unit volume on the particles, N/m^3.
    ku, kv : ndarray of float64, shapes of u, v
        Drag jacobian K, kg/(m^3 s) (read only where ``has_k``).
    has_k : bool
        The drag is semi-implicit.
    """

    u: np.ndarray
    v: np.ndarray
    eps_old: np.ndarray
    eps_new: np.ndarray
    fu: np.ndarray
    fv: np.ndarray
    ku: np.ndarray
    kv: np.ndarray
    has_k: bool


class GasStepOutput(NamedTuple):
    """The fields one gas step writes.

    Attributes
    ----------
    u_out, v_out : ndarray of float64, shape (nx+1, ny), (nx, ny)
        Velocities after the step, m/s.
    p_out : ndarray of float64, shape (nx, ny)
        Periodic pressure after the step, Pa.
    """

    u_out: np.ndarray
    v_out: np.ndarray
    p_out: np.ndarray


class GasWorkspace(NamedTuple):
    """A solver's scratch arrays and the cached factorisation (see :mod:`.pressure`).

    Attributes
    ----------
    mu_s, mv_s : ndarray of float64, face shapes
        Predicted face mass fluxes m*.
    cu, cv : ndarray of float64, face shapes
        Projection weights c of this step.
    cu_fac, cv_fac : ndarray of float64, face shapes
        The weights of the cached factorisation.
    band : ndarray of float64, shape (nx ny, 2 nx + 1)
        Banded Cholesky factor.
    invdiag, ra, rb : ndarray of float64, shape (nx ny,)
        Inverse pivots and the two right-hand sides / solutions.
    numbering : ndarray of int64
        Cell numbering of the banded matrix.
    tend_u, tend_v : ndarray of float64, face shapes
        Advective and viscous tendencies.
    ey_old, ey_new : ndarray of float64, shape (nx, ny)
        Void fraction on the y-faces before and after the step.
    factor_state : ndarray of int64, shape (1,)
        Whether a factorisation is cached.
    info : ndarray of float64
        Diagnostics of the step (slots ``_I_*`` of :mod:`.pressure`).
    """

    mu_s: np.ndarray
    mv_s: np.ndarray
    cu: np.ndarray
    cv: np.ndarray
    cu_fac: np.ndarray
    cv_fac: np.ndarray
    band: np.ndarray
    invdiag: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    numbering: np.ndarray
    tend_u: np.ndarray
    tend_v: np.ndarray
    ey_old: np.ndarray
    ey_new: np.ndarray
    factor_state: np.ndarray
    info: np.ndarray
