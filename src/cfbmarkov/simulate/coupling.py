"""Particle-fluid coupling kernels of the CFD-DEM (pure functions on arrays).

The gas runs the "model B" form (Zhou et al. 2010, set I): the gas momentum equation
carries ``-grad p`` and minus the whole particle-fluid force, and each particle receives
``F = beta Vp / (1 - eps) (u_gas - v_p)`` with the paper's Table 2 beta (docs/definitions.md, Drag).
Table 2's beta is Gidaspow's Ergun/Wen-Yu coefficient divided by eps, which is exactly the
form that reproduces Ergun's pressure drop in model B: the pressure-gradient (buoyancy)
force on the particles is contained in F, so no separate ``-Vp grad p`` term is added (it
would count it twice). The packed-bed test checks the pressure drop against Ergun.
The definitions are in docs/definitions.md (Drag), the choices in docs/simulation.md.

The drag is semi-implicit for the gas (see :class:`~cfbmarkov.simulate.cfd.GasSolver`):
with K_p = beta Vp / (1 - eps) frozen over a gas step, the gas feels
``sum_p w_p (F_p^n + K_p (u^{n+1} - u^n))`` and the particles then receive
``K_p (u^{n+1}(x_p) - v_p)``, so the momentum given to the particles is exactly the
momentum taken from the gas (the deposit is the transpose of the interpolation).

References
----------
- The paper, Table 2: *Markov Chain Based Statistic Model for Predicting Particle Movement
  in Circulating Fluidized Bed (CFB) Risers*, Preprints.org 202407.1963 (2024); Y. Zhuang,
  Processes 13(3), 614 (2025), https://doi.org/10.3390/pr13030614.
- Z. Y. Zhou, S. B. Kuang, K. W. Chu, A. B. Yu, Discrete particle simulation of
  particle-fluid flow: model formulations and their applicability, J. Fluid Mech. 661,
  482-510 (2010): model B.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.simulate.cfd.coupling import gas_velocity_at
from cfbmarkov.simulate.cfd.drag import particle_drag_jacobian


@nb.njit(cache=True, inline="always")
def cell_weights(nx, ny, dx, dy, x, y, periodic_y=True):
    """Cells and weights of the bilinear interpolation of a cell-centred field (nx, ny) at
    (x, y): ``(i0, i1, j0, j1, wx, wy)``, periodic in y (or, with ``periodic_y=False``,
    constant extrapolation to the floor and top too), constant extrapolation to the walls.

    A function of scalars, compiled for the CPU here and called by the GPU coupling kernels
    (:mod:`cfbmarkov.simulate.gpu.coupling`) as a device function.
    """
    fx = x / dx - 0.5
    fy = y / dy - 0.5
    if fx < 0.0:
        fx = 0.0
    elif fx > nx - 1:
        fx = nx - 1.0
    # the cases written out: numba-cuda does not type min() of these integers
    if nx > 1:
        i0 = int(fx)
        if i0 > nx - 2:
            i0 = nx - 2
        wx = fx - i0
        i1 = i0 + 1
    else:
        i0 = 0
        wx = 0.0
        i1 = 0
    if not periodic_y:
        if fy < 0.0:
            fy = 0.0
        elif fy > ny - 1:
            fy = ny - 1.0
    j = math.floor(fy)
    wy = fy - j
    j0 = int(j)
    if j0 < 0 or j0 >= ny:  # rare: an integer modulo costs a tenth of the drag kernel
        j0 = j0 % ny
    j1 = j0 + 1
    if j1 >= ny:
        j1 = 0
    return i0, i1, j0, j1, wx, wy


@nb.njit(cache=True, inline="always")
def _cell_value(field, dx, dy, x, y, periodic_y=True):
    """Bilinear interpolation of a cell-centred field (nx, ny) with :func:`cell_weights`."""
    i0, i1, j0, j1, wx, wy = cell_weights(field.shape[0], field.shape[1], dx, dy, x, y,
                                          periodic_y)
    return ((1.0 - wy) * ((1.0 - wx) * field[i0, j0] + wx * field[i1, j0])
            + wy * ((1.0 - wx) * field[i0, j1] + wx * field[i1, j1]))


@nb.njit(cache=True, parallel=True)
def drag_coefficients(positions, velocities, u, v, void_fraction, dx, dy, diameter,
                      gas_density, gas_viscosity, coefficient, force, periodic_y=True):
    """Per particle: K_p = beta Vp / (1 - eps) (kg/s) and the drag force K_p (u_gas - v_p)
    (N), with the gas velocity and void fraction interpolated to the particle centre
    (the void fraction across the seam only where the particles are periodic in y).

    Parameters
    ----------
    positions, velocities : numpy.ndarray
        [N, 2] particle centres (m) and velocities (m/s).
    u, v : numpy.ndarray
        Interstitial gas velocity on the staggered grid, m/s: u on the x faces [nx + 1, ny],
        v on the y faces [nx, ny].
    void_fraction : numpy.ndarray
        [nx, ny] gas void fraction eps at the cell centres.
    dx, dy : float
        Gas cell size, m.
    diameter : float
        Particle diameter d, m.
    gas_density, gas_viscosity : float
        rho_g (kg/m^3) and mu_g (Pa s).
    coefficient : numpy.ndarray
        [N] output: K_p, kg/s.
    force : numpy.ndarray
        [N, 2] output: the drag force, N.
    periodic_y : bool, optional
        Whether the void fraction is interpolated across the periodic seam.

    References
    ----------
    Table 2 of the paper (beta: Ergun for eps <= 0.8, Wen & Yu above); docs/definitions.md,
    Drag.
    """
    for p in nb.prange(positions.shape[0]):
        x = positions[p, 0]
        y = positions[p, 1]
        ux, uy = gas_velocity_at(u, v, dx, dy, x, y)
        eps = _cell_value(void_fraction, dx, dy, x, y, periodic_y)
        sx = ux - velocities[p, 0]
        sy = uy - velocities[p, 1]
        k = particle_drag_jacobian(eps, np.sqrt(sx * sx + sy * sy), diameter, gas_density,
                                   gas_viscosity)
        coefficient[p] = k
        force[p, 0] = k * sx
        force[p, 1] = k * sy


@nb.njit(cache=True, parallel=True)
def drag_force_at_new_gas(positions, velocities, u, v, dx, dy, coefficient, force):
    """F_p = K_p (u_gas^{n+1}(x_p) - v_p): the force the particles receive for a gas step.

    Parameters
    ----------
    positions, velocities : numpy.ndarray
        [N, 2] particle centres (m) and velocities (m/s).
    u, v : numpy.ndarray
        The new gas velocity on the staggered grid, m/s (as in :func:`drag_coefficients`).
    dx, dy : float
        Gas cell size, m.
    coefficient : numpy.ndarray
        [N] K_p from :func:`drag_coefficients`, kg/s.
    force : numpy.ndarray
        [N, 2] output: the force, N.
    """
    for p in nb.prange(positions.shape[0]):
        ux, uy = gas_velocity_at(u, v, dx, dy, positions[p, 0], positions[p, 1])
        force[p, 0] = coefficient[p] * (ux - velocities[p, 0])
        force[p, 1] = coefficient[p] * (uy - velocities[p, 1])


def check_placement(n: int, diameter: float, width: float, height: float,
                    gap: float = 0.1) -> tuple[int, int]:
    """The starting lattice of :func:`place_without_overlap`, refused where ``n`` discs do
    not fit on it.

    Parameters
    ----------
    n : int
        Number of discs.
    diameter : float
        Disc diameter d, m.
    width, height : float
        The riser, m.
    gap : float, optional
        Lattice spacing beyond one diameter, as a fraction of d.

    Returns
    -------
    (int, int)
        Lattice sites across and up.

    Raises
    ------
    InputError
        When ``n`` discs do not fit on the lattice, naming how many do.
    """
    spacing = (1.0 + gap) * diameter
    nx = max(int(np.floor((width - diameter) / spacing)) + 1, 0)
    ny = max(int(np.floor(height / spacing)), 0)
    if n > nx * ny:
        fix = ("give fewer particles (particles.number, or --particles)" if nx * ny > 0 else
               "give a particles.diameter smaller than the riser, or a wider and taller "
               "riser")
        raise InputError(f"{n} particles of {diameter:g} m do not fit in the {width:g} x "
                         f"{height:g} m riser (at most {nx * ny} on the starting lattice of "
                         f"{nx} x {ny} sites); {fix}")
    return nx, ny


def place_without_overlap(n: int, diameter: float, width: float, height: float,
                          seed: int, gap: float = 0.1) -> np.ndarray:
    """Positions of discs that do not overlap: random sites of a square lattice of spacing
    (1 + gap) d over the riser, each moved by a random offset that keeps the gap positive.

    Parameters
    ----------
    n : int
        Number of discs.
    diameter : float
        Disc diameter d, m.
    width, height : float
        The riser, m.
    seed : int
        Random seed.
    gap : float, optional
        Lattice spacing beyond one diameter, as a fraction of d.

    Returns
    -------
    numpy.ndarray
        [n, 2] positions, m.

    Raises
    ------
    InputError
        When ``n`` discs do not fit on the lattice (a packing denser than it allows).
    """
    spacing = (1.0 + gap) * diameter
    nx, ny = check_placement(n, diameter, width, height, gap)
    rng = np.random.default_rng(seed)
    sites = np.sort(rng.choice(nx * ny, size=n, replace=False))
    ix, iy = sites % nx, sites // nx
    jitter = 0.5 * (spacing - diameter) * 0.999
    x0 = 0.5 * (width - (nx - 1) * spacing)
    x = x0 + ix * spacing + rng.uniform(-jitter, jitter, n)
    y = (iy + 0.5) * spacing + rng.uniform(-jitter, jitter, n)
    x = np.clip(x, 0.5 * diameter, width - 0.5 * diameter)
    return np.stack([x, y % height], axis=1)


def hexagonal_bed(n: int, diameter: float, width: float, gap: float = 0.01) -> np.ndarray:
    """A packed bed on the floor: hexagonal rows of spacing (1 + gap) d, filled from y = 0 up
    (for packed- and fluidized-bed checks).

    Parameters
    ----------
    n : int
        Number of discs.
    diameter : float
        Disc diameter d, m.
    width : float
        The riser width, m.
    gap : float, optional
        Spacing beyond one diameter, as a fraction of d.

    Returns
    -------
    numpy.ndarray
        [n, 2] positions, m.
    """
    spacing = (1.0 + gap) * diameter
    per_row = int((width - diameter) / spacing)
    row, col = np.divmod(np.arange(n), per_row)
    return np.stack([(col + 0.5 + 0.5 * (row % 2)) * spacing + 0.2 * diameter,
                     (0.5 + row * np.sqrt(3.0) / 2.0) * spacing], axis=1)
