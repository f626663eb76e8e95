"""The coupled riser: a DEM system and the gas, advanced one gas step at a time.

:class:`CoupledRiser` holds the particles (:class:`~cfbmarkov.simulate.dem.DEMSystem`), the
gas (:class:`~cfbmarkov.simulate.cfd.GasState`) and the one gas solver that advances it; the
coupling kernels (void fraction, drag) are in :mod:`cfbmarkov.simulate.coupling` and
:mod:`cfbmarkov.simulate.cfd`. The run loop that writes its frames is
:func:`cfbmarkov.simulate.run.simulate`.
"""

from __future__ import annotations

import numba
import numpy as np

from cfbmarkov.config import CaseConfig
from cfbmarkov.simulate.cfd import (GasGrid, GasSolver, GasState, deposit_drag,
                                    void_fraction_field)
from cfbmarkov.simulate.coupling import (drag_coefficients, drag_force_at_new_gas,
                                         place_without_overlap)
from cfbmarkov.simulate.dem import ContactLaw, DEMSystem


def gas_solver(case: CaseConfig, bottom_wall: bool) -> GasSolver:
    """The gas solver of a riser (formulation B).

    Parameters
    ----------
    case : CaseConfig
        The case.
    bottom_wall : bool
        The particles rest on a floor: the gas enters through a distributor at y = 0 (see
        :mod:`cfbmarkov.simulate.cfd.grid`).

    Returns
    -------
    GasSolver
    """
    return GasSolver.from_config(case, distributor=bottom_wall, formulation="B")


class CoupledRiser:
    """DEM particles and the gas of the periodic riser, advanced one gas step at a time.

    Parameters
    ----------
    case : CaseConfig
        The case (riser, particles, gas, contact law, numerics).
    dem : DEMSystem
        The particles.
    gas : GasState
        The gas on the staggered grid.
    cfd_steps : int, optional
        Gas steps already taken (the time is ``cfd_steps`` x the gas step).
    solver : GasSolver, optional
        The gas solver (:func:`gas_solver`); made for the case when not given.
    """

    def __init__(self, case: CaseConfig, dem: DEMSystem, gas: GasState, cfd_steps: int = 0,
                 solver: GasSolver | None = None):
        self.case = case
        self.dem = dem
        self.gas = gas
        self.cfd_steps = int(cfd_steps)
        # a bed on a floor: the gas enters through a distributor at y = 0 (see .cfd.grid)
        self.solver = gas_solver(case, dem.bottom_wall) if solver is None else solver
        self.grid = self.solver.grid
        self.dem_steps_per_cfd = case.numerics.dem_steps_per_cfd_step
        n = dem.n_particles
        self._coefficient = np.empty(n)
        self._force = np.empty((n, 2))

    # -- construction ----------------------------------------------------------------
    @classmethod
    def initial(cls, case: CaseConfig) -> "CoupledRiser":
        """Particles on random lattice sites without overlap, at rest; gas at U (plug flow).

        Parameters
        ----------
        case : CaseConfig
            The case; ``case.seed`` seeds the placement.

        Returns
        -------
        CoupledRiser
            The riser at t = 0.
        """
        p, r = case.particles, case.riser
        positions = place_without_overlap(p.number, p.diameter, r.width, r.height, case.seed)
        return cls.from_particles(case, positions, np.zeros_like(positions))

    @classmethod
    def from_particles(cls, case: CaseConfig, positions, velocities, *, bottom_wall: bool = False,
                       angular_velocities=None) -> "CoupledRiser":
        """Given particles; gas at U (plug flow).

        Parameters
        ----------
        case : CaseConfig
            The case.
        positions, velocities : array_like
            [N, 2] particle centres (m) and velocities (m/s).
        bottom_wall : bool, optional
            Put a contact floor at y = 0 for the particles (the gas stays periodic, as
            through a distributor): packed beds.
        angular_velocities : array_like, optional
            [N] spins, rad/s (default 0).

        Returns
        -------
        CoupledRiser
            The riser at t = 0.
        """
        p, r = case.particles, case.riser
        positions = np.asarray(positions, dtype=np.float64)
        law = ContactLaw.from_config(case.contact, p.diameter, p.density)
        dem = DEMSystem(positions, velocities, 0.5 * p.diameter, p.density, law,
                        r.width, r.height, gravity=r.gravity,
                        time_step=case.numerics.dem_time_step,
                        search_cells=_search_cells(case), skin=case.numerics.dem_skin,
                        angular_velocities=angular_velocities, bottom_wall=bottom_wall)
        grid = GasGrid.from_config(case)
        eps = void_fraction_field(grid, positions[:, 0], positions[:, 1], p.diameter,
                                  periodic_y=not bottom_wall)
        solver = gas_solver(case, bottom_wall)
        return cls(case, dem, solver.initial_state(eps), solver=solver)

    # -- stepping ----------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time, s."""
        return self.cfd_steps * self.case.numerics.cfd_time_step

    #: below this many particles the coupling kernels run on one thread (thread start-up
    #: costs more than the work; results do not depend on it)
    serial_below = 2000

    def step(self) -> None:
        """One gas step and the DEM steps inside it."""
        threads = numba.get_num_threads()
        if self.dem.n_particles < self.serial_below and threads > 1:
            numba.set_num_threads(1)
        try:
            self._step()
        finally:
            if numba.get_num_threads() != threads:
                numba.set_num_threads(threads)

    def _step(self) -> None:
        self._gas_step()
        self.dem.step(self.dem_steps_per_cfd, external_force=self._force)
        self.cfd_steps += 1

    def _gas_step(self) -> None:
        """The gas step and the drag it leaves on the particles (``self._force``), before the
        DEM steps inside it."""
        case, grid = self.case, self.grid
        d = case.particles.diameter
        positions, velocities = self.dem.positions, self.dem.velocities
        x, y = positions[:, 0], positions[:, 1]
        periodic_y = not self.dem.bottom_wall
        eps = void_fraction_field(grid, x, y, d, periodic_y=periodic_y)
        drag_coefficients(positions, velocities, self.gas.u, self.gas.v, eps, grid.dx,
                          grid.dy, d, case.gas.density, case.gas.viscosity,
                          self._coefficient, self._force, periodic_y)
        fu, fv, ku, kv = deposit_drag(grid, x, y, self._force[:, 0], self._force[:, 1],
                                      self._coefficient, d)
        self.gas = self.solver.step(self.gas, eps, fu, fv, ku, kv)
        drag_force_at_new_gas(positions, velocities, self.gas.u, self.gas.v, grid.dx, grid.dy,
                              self._coefficient, self._force)

    def gas_fields(self) -> dict[str, np.ndarray]:
        """The gas at cell centres, arrays [ny, nx] (row 0 at the bottom): ``void_fraction``,
        ``gas_velocity`` [ny, nx, 2] (interstitial, m/s) and ``pressure`` (periodic part, Pa)."""
        u, v = self.gas.u, self.gas.v
        uc = 0.5 * (u[:-1] + u[1:])
        vc = 0.5 * (v + np.roll(v, -1, axis=1))
        return {"void_fraction": self.gas.void_fraction.T,
                "gas_velocity": np.stack([uc.T, vc.T], axis=-1),
                "pressure": self.gas.p.T}

    # -- checkpoints -----------------------------------------------------------------
    def state(self) -> dict[str, dict[str, np.ndarray] | int]:
        """Everything needed to continue bit for bit: ``{'dem': ..., 'gas': ..., 'cfd_steps': k}``."""
        return {"dem": self.dem.state(), "gas": self.gas.state_dict(), "cfd_steps": self.cfd_steps}

    @classmethod
    def from_state(cls, case: CaseConfig, state: dict) -> "CoupledRiser":
        """The riser saved by :meth:`state` (with the same ``case``)."""
        return cls(case, DEMSystem.from_state(state["dem"]),
                   GasState.from_state_dict(state["gas"]), int(state["cfd_steps"]))


def _search_cells(case: CaseConfig) -> tuple[int, int] | None:
    """The DEM's ``search_cells`` for a case: None (the engine's automatic grid) for "auto"."""
    cells = case.numerics.dem_cells
    return None if cells == "auto" else tuple(int(c) for c in cells)
