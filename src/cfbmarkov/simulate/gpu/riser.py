"""GpuEnsembleRiser: M independent coupled risers, the particles of all of them on the GPU.

Per gas step (:meth:`GpuEnsembleRiser.step`), as :class:`cfbmarkov.simulate.riser.CoupledRiser`
does for one riser: the void fraction, the drag coefficients and forces and their deposit
to the gas grid, the gas step (the existing :class:`~cfbmarkov.simulate.cfd.GasSolver`, one
member after another) and the drag at the new gas are computed **on the host** with the CPU
kernels, then every member's ``dem_steps_per_cfd_step`` DEM steps run on the device in one
launch with the drag held (no host round trip inside them). Bytes moved per gas step
(:attr:`GpuEnsembleRiser.bytes_per_gas_step`): positions and velocities out (32 bytes a
particle), drag forces in (16 bytes a particle), the control slots (56 bytes a member), and
25 bytes per pass event through the top or bottom when there are any.
"""

from __future__ import annotations

import numba
import numpy as np

from cfbmarkov.config import CaseConfig
from cfbmarkov.simulate.cfd import GasGrid, GasState, deposit_drag, void_fraction_field
from cfbmarkov.simulate.coupling import (drag_coefficients, drag_force_at_new_gas,
                                         place_without_overlap)
from cfbmarkov.simulate.dem import ContactLaw
from cfbmarkov.simulate.gpu.ensemble import GpuEnsembleDEM
from cfbmarkov.simulate.riser import _search_cells, gas_solver


class GpuEnsembleRiser:
    """M coupled risers of one case: DEM on the GPU, coupling and gas on the host.

    Parameters
    ----------
    case : CaseConfig
        The case (all members share it; they differ in their particles).
    dem : GpuEnsembleDEM
        The members' particles.
    gases : list of GasState
        Each member's gas.
    cfd_steps : int, optional
        Gas steps already taken.
    """

    #: below this many particles a member's coupling kernels run on one thread
    serial_below = 2000

    def __init__(self, case: CaseConfig, dem: GpuEnsembleDEM, gases: list, cfd_steps: int = 0):
        self.case = case
        self.dem = dem
        self.gases = list(gases)
        self.cfd_steps = int(cfd_steps)
        self.solver = gas_solver(case, dem.bottom_wall)
        self.grid = self.solver.grid
        self.dem_steps_per_cfd = case.numerics.dem_steps_per_cfd_step
        m, n = dem.n_members, dem.n_particles
        self._coefficient = np.empty(n)
        self._force = np.empty((m, n, 2))

    # -- construction ----------------------------------------------------------------
    @classmethod
    def initial(cls, case: CaseConfig, seeds, *, threads=None, blocks_per_member=1
                ) -> "GpuEnsembleRiser":
        """Member m's particles on random lattice sites placed with ``seeds[m]`` (as
        :meth:`CoupledRiser.initial` with that seed), at rest; gas at U. ``threads`` and
        ``blocks_per_member``: see :class:`~.ensemble.GpuEnsembleDEM`."""
        p, r = case.particles, case.riser
        pos = np.stack([place_without_overlap(p.number, p.diameter, r.width, r.height, int(s))
                        for s in seeds])
        return cls.from_particles(case, pos, np.zeros_like(pos), threads=threads,
                                  blocks_per_member=blocks_per_member)

    @classmethod
    def from_particles(cls, case: CaseConfig, positions, velocities, *, bottom_wall=False,
                       angular_velocities=None, threads=None, blocks_per_member=1
                       ) -> "GpuEnsembleRiser":
        """Given particles (M, N, 2) positions (m) and velocities (m/s); gas at U."""
        p, r = case.particles, case.riser
        positions = np.asarray(positions, dtype=np.float64)
        law = ContactLaw.from_config(case.contact, p.diameter, p.density)
        dem = GpuEnsembleDEM(positions, velocities, 0.5 * p.diameter, p.density, law,
                             r.width, r.height, gravity=r.gravity,
                             time_step=case.numerics.dem_time_step,
                             search_cells=_search_cells(case), skin=case.numerics.dem_skin,
                             angular_velocities=angular_velocities, bottom_wall=bottom_wall,
                             threads=threads, blocks_per_member=blocks_per_member)
        grid = GasGrid.from_config(case)
        solver = gas_solver(case, bottom_wall)
        gases = [solver.initial_state(void_fraction_field(grid, x[:, 0], x[:, 1], p.diameter,
                                                          periodic_y=not bottom_wall))
                 for x in positions]
        return cls(case, dem, gases)

    # -- stepping ----------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time, s."""
        return self.cfd_steps * self.case.numerics.cfd_time_step

    @property
    def n_members(self) -> int:
        return self.dem.n_members

    @property
    def bytes_per_gas_step(self) -> int:
        """Bytes moved between host and device per gas step, pass events (25 bytes each)
        not counted."""
        from cfbmarkov.simulate.gpu.kernels import N_CTL
        m, n = self.dem.n_members, self.dem.n_particles
        return m * n * (32 + 16) + m * N_CTL * 8

    def step(self) -> None:
        """One gas step of every member and the DEM steps inside it."""
        threads = numba.get_num_threads()
        if self.dem.n_particles < self.serial_below and threads > 1:
            numba.set_num_threads(1)
        try:
            positions, velocities = self.dem.positions_velocities()
            for k in range(self.dem.n_members):
                self._gas_step(k, positions[k], velocities[k])
        finally:
            if numba.get_num_threads() != threads:
                numba.set_num_threads(threads)
        self.dem.step(self.dem_steps_per_cfd, external_force=self._force)
        self.cfd_steps += 1

    def _gas_step(self, k, positions, velocities) -> None:
        """Member k's gas step and the drag it leaves on its particles (``self._force[k]``),
        as :meth:`CoupledRiser._gas_step`."""
        case, grid = self.case, self.grid
        d = case.particles.diameter
        x, y = positions[:, 0], positions[:, 1]
        periodic_y = not self.dem.bottom_wall
        gas = self.gases[k]
        force = self._force[k]
        eps = void_fraction_field(grid, x, y, d, periodic_y=periodic_y)
        drag_coefficients(positions, velocities, gas.u, gas.v, eps, grid.dx, grid.dy, d,
                          case.gas.density, case.gas.viscosity, self._coefficient, force,
                          periodic_y)
        fu, fv, ku, kv = deposit_drag(grid, x, y, force[:, 0], force[:, 1], self._coefficient, d)
        gas = self.solver.step(gas, eps, fu, fv, ku, kv)
        drag_force_at_new_gas(positions, velocities, gas.u, gas.v, grid.dx, grid.dy,
                              self._coefficient, force)
        self.gases[k] = gas

    def gas_fields(self, member: int) -> dict[str, np.ndarray]:
        """Member ``member``'s gas at cell centres, as :meth:`CoupledRiser.gas_fields`."""
        gas = self.gases[member]
        u, v = gas.u, gas.v
        uc = 0.5 * (u[:-1] + u[1:])
        vc = 0.5 * (v + np.roll(v, -1, axis=1))
        return {"void_fraction": gas.void_fraction.T,
                "gas_velocity": np.stack([uc.T, vc.T], axis=-1), "pressure": gas.p.T}

    # -- checkpoints -----------------------------------------------------------------
    def state(self) -> dict:
        """Everything needed to continue bit for bit: ``{'dem': ..., 'gas': {'m0': ...,
        ...}, 'cfd_steps': k}``."""
        return {"dem": self.dem.state(),
                "gas": {f"m{k}": g.state_dict() for k, g in enumerate(self.gases)},
                "cfd_steps": self.cfd_steps}

    @classmethod
    def from_state(cls, case: CaseConfig, state: dict, *, threads=None, blocks_per_member=1
                   ) -> "GpuEnsembleRiser":
        """The ensemble saved by :meth:`state` (with the same ``case``)."""
        dem = GpuEnsembleDEM.from_state(state["dem"], threads=threads,
                                        blocks_per_member=blocks_per_member)
        gases = [GasState.from_state_dict(state["gas"][f"m{k}"]) for k in range(dem.n_members)]
        return cls(case, dem, gases, int(np.asarray(state["cfd_steps"])))
