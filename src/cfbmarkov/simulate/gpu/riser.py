"""GpuEnsembleRiser: M independent coupled risers, the particles of all of them on the GPU.

Per gas step (:meth:`GpuEnsembleRiser.step`), as :class:`cfbmarkov.simulate.riser.CoupledRiser`
does for one riser. With ``coupling="device"`` (the default) the void fraction, the drag
coefficients and forces and their deposit onto the gas grid are computed on the device
(:mod:`cfbmarkov.simulate.gpu.coupling`: deterministic chunked deposits, no float
atomics); only grid-sized fields cross: the void fraction and the four drag fields come to
the host, each member's gas step runs there (the existing
:class:`~cfbmarkov.simulate.cfd.GasSolver`, each member its own, on host threads at once
up to the cores: its kernel releases the GIL), the new gas
velocities go back, and the drag at the new gas is computed on
the device straight into the DEM's external force. Then every member's
``dem_steps_per_cfd_step`` DEM steps run on the device in one launch with the drag held.
Bytes moved per gas step (:attr:`GpuEnsembleRiser.bytes_per_gas_step`), per member with a
gas grid of nx x ny cells: ``8 (4 nx ny + 3 (nx + 1) ny)`` (eps, fv, kv, v: nx ny values
each; fu, ku, u: (nx + 1) ny each) and the control slots (56 bytes), whatever the number of
particles; plus 25 bytes per pass event through the top or bottom when there are any.

``coupling="host"`` computes the coupling on the host with the CPU kernels instead:
positions and velocities out (32 bytes a particle), drag forces in (16 bytes a particle),
the control slots (56 bytes a member).
"""

from __future__ import annotations

import math
import os
import time
import warnings
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from numba.core.errors import NumbaPerformanceWarning

from cfbmarkov.config import CaseConfig
from cfbmarkov.errors import InputError
from cfbmarkov.simulate.cfd import GasGrid, GasState, deposit_drag, void_fraction_field
from cfbmarkov.simulate.cfd.coupling import VOID_FRACTION_FLOOR
from cfbmarkov.simulate.coupling import (drag_coefficients, drag_force_at_new_gas,
                                         place_without_overlap)
from cfbmarkov.simulate.dem import ContactLaw
from cfbmarkov.simulate.gpu import simulator
from cfbmarkov.simulate.gpu.ensemble import GpuEnsembleDEM
from cfbmarkov.simulate.riser import _search_cells, gas_solver


#: chunks per member of the device deposits (threads per member of the deposit kernels, each
#: adding N / C particles in order; each chunk's copies of the fields are five grid-sized
#: arrays, 10 MB a member at paper scale)
GPU_DEPOSIT_CHUNKS = 256


class GpuEnsembleRiser:
    """M coupled risers of one case: DEM and coupling on the GPU, gas on the host.

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
    coupling : {"device", "host"}, optional
        Where the void fraction, the drag and its deposit are computed (module docstring).
    deposit_chunks : int, optional
        Chunks per member of the device deposits (default :data:`GPU_DEPOSIT_CHUNKS`); with
        the CPU's ``DEPOSIT_CHUNKS`` (8) the sums are the CPU's term for term. Results
        depend on it (to round-off), not on the launch shape; a checkpoint keeps it.

    Raises
    ------
    InputError
        An unknown ``coupling`` or ``deposit_chunks`` < 1.

    Notes
    -----
    With ``coupling="device"`` the gas velocities the device kernels use are uploaded at
    construction and after every gas step: replace ``gases`` only through a new object.
    """

    #: below this many particles a member's host coupling kernels run on one thread
    serial_below = 2000

    def __init__(self, case: CaseConfig, dem: GpuEnsembleDEM, gases: list, cfd_steps: int = 0,
                 *, coupling: str = "device", deposit_chunks: int | None = None):
        self.case = case
        self.dem = dem
        self.gases = list(gases)
        self.cfd_steps = int(cfd_steps)
        self.solver = gas_solver(case, dem.bottom_wall)
        self.grid = self.solver.grid
        # each member its own solver (workspace), so that their gas steps can run at once
        self._solvers = [self.solver] + [gas_solver(case, dem.bottom_wall)
                                         for _ in range(dem.n_members - 1)]
        self._pool = None
        self.dem_steps_per_cfd = case.numerics.dem_steps_per_cfd_step
        m, n = dem.n_members, dem.n_particles
        if coupling not in ("device", "host"):
            raise InputError(f"coupling: expected 'device' or 'host', got {coupling!r}")
        self.coupling = coupling
        #: wall time spent in the members' gas solves on the host (device coupling), s
        self.host_gas_seconds = 0.0
        if deposit_chunks is None:
            deposit_chunks = GPU_DEPOSIT_CHUNKS
        if int(deposit_chunks) < 1:
            raise InputError(f"deposit_chunks must be >= 1, got {deposit_chunks!r}")
        self.deposit_chunks = int(deposit_chunks)
        if coupling == "host":
            self._coefficient = np.empty(n)
            self._force = np.empty((m, n, 2))
        else:
            self._setup_device()

    # -- construction ----------------------------------------------------------------
    @classmethod
    def initial(cls, case: CaseConfig, seeds, *, threads=None, blocks_per_member=1,
                **coupling) -> "GpuEnsembleRiser":
        """Member m's particles on random lattice sites placed with ``seeds[m]`` (as
        :meth:`CoupledRiser.initial` with that seed), at rest; gas at U. ``threads`` and
        ``blocks_per_member``: see :class:`~.ensemble.GpuEnsembleDEM`; ``coupling`` and
        ``deposit_chunks``: see the class."""
        p, r = case.particles, case.riser
        pos = np.stack([place_without_overlap(p.number, p.diameter, r.width, r.height, int(s))
                        for s in seeds])
        return cls.from_particles(case, pos, np.zeros_like(pos), threads=threads,
                                  blocks_per_member=blocks_per_member, **coupling)

    @classmethod
    def from_particles(cls, case: CaseConfig, positions, velocities, *, bottom_wall=False,
                       angular_velocities=None, threads=None, blocks_per_member=1,
                       **coupling) -> "GpuEnsembleRiser":
        """Given particles (M, N, 2) positions (m) and velocities (m/s); gas at U
        (``coupling``: the class's keywords)."""
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
        return cls(case, dem, gases, **coupling)

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
        not counted: per member ``8 (4 nx ny + 3 (nx + 1) ny) + 56`` with the device
        coupling, ``48 N + 56`` with the host coupling (module docstring)."""
        from cfbmarkov.simulate.gpu.kernels import N_CTL
        m, n = self.dem.n_members, self.dem.n_particles
        if self.coupling == "host":
            return m * n * (32 + 16) + m * N_CTL * 8
        nx, ny = self.grid.cell_shape
        return m * 8 * (4 * nx * ny + 3 * (nx + 1) * ny) + m * N_CTL * 8

    def step(self) -> None:
        """One gas step of every member and the DEM steps inside it."""
        if self.coupling == "device":
            self._device_step()
            self.cfd_steps += 1
            return
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

    # -- the device coupling -------------------------------------------------------------
    def _setup_device(self) -> None:
        """Device arrays and parameters of :mod:`cfbmarkov.simulate.gpu.coupling`; the gas
        velocities uploaded."""
        from cfbmarkov.simulate.gpu import coupling as K
        from cfbmarkov.simulate.gpu._cuda import cuda
        case, grid = self.case, self.grid
        m, n, c = self.dem.n_members, self.dem.n_particles, self.deposit_chunks
        nx, ny = grid.cell_shape
        d = case.particles.diameter
        cp = np.zeros(K.N_P)
        cp[K.P_IDX], cp[K.P_IDY] = 1.0 / grid.dx, 1.0 / grid.dy
        cp[K.P_DX], cp[K.P_DY] = grid.dx, grid.dy
        cp[K.P_VOLUME] = math.pi * d ** 3 / 6.0
        cp[K.P_CELL] = grid.cell_volume(d)
        cp[K.P_FLOOR] = VOID_FRACTION_FLOOR
        cp[K.P_INV_CELL] = 1.0 / grid.cell_volume(d)
        cp[K.P_D], cp[K.P_RHO], cp[K.P_MU] = d, case.gas.density, case.gas.viscosity
        cq = np.zeros(K.N_Q, np.int64)
        cq[K.Q_N], cq[K.Q_M], cq[K.Q_C], cq[K.Q_NX], cq[K.Q_NY] = n, m, c, nx, ny
        cq[K.Q_PERIODIC] = int(not self.dem.bottom_wall)
        u_shape, v_shape = (m, nx + 1, ny), (m, nx, ny)
        # the chunk copies start zero and the summing kernels leave them zero
        pu, pv = np.zeros((m, c, nx + 1, ny)), np.zeros((m, c, nx, ny))
        self._dev = dict(
            cp=cuda.to_device(cp), cq=cuda.to_device(cq),
            ps=cuda.to_device(pv), eps=cuda.device_array(v_shape),
            coef=cuda.device_array(m * n), frc=cuda.device_array((2, m * n)),
            pu=cuda.to_device(pu), pv=cuda.to_device(pv),
            pku=cuda.to_device(pu), pkv=cuda.to_device(pv),
            fu=cuda.device_array(u_shape), fv=cuda.device_array(v_shape),
            ku=cuda.device_array(u_shape), kv=cuda.device_array(v_shape),
            u=cuda.device_array(u_shape), v=cuda.device_array(v_shape))
        self._tpb = 16 if simulator() else 128
        self._upload_gas()

    def _upload_gas(self) -> None:
        self._dev["u"].copy_to_device(np.stack([g.u for g in self.gases]).astype(np.float64))
        self._dev["v"].copy_to_device(np.stack([g.v for g in self.gases]).astype(np.float64))

    def _launch(self, kernel, threads, *args) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NumbaPerformanceWarning)
            kernel[(threads + self._tpb - 1) // self._tpb, self._tpb](*args)

    def _device_step(self) -> None:
        """Every member's gas step with the coupling on the device, and its DEM steps."""
        from cfbmarkov.simulate.gpu import coupling as K
        g, e = self._dev, self.dem.device_arrays
        m, n, c = self.dem.n_members, self.dem.n_particles, self.deposit_chunks
        nx, ny = self.grid.cell_shape
        cp, cq = g["cp"], g["cq"]
        self._launch(K.solid_chunks, m * c, e["s"], e["ctl"], g["ps"], cp, cq)
        self._launch(K.void_fraction, m * nx * ny, g["ps"], g["eps"], cp, cq)
        self._launch(K.drag_at_old_gas, m * n, e["s"], e["ctl"], g["u"], g["v"], g["eps"],
                     g["coef"], g["frc"], cp, cq)
        self._launch(K.drag_chunks, m * c, e["s"], e["ctl"], g["coef"], g["frc"], g["pu"],
                     g["pv"], g["pku"], g["pkv"], cp, cq)
        self._launch(K.face_sums, m * (nx + 1) * ny, g["pu"], g["pv"], g["pku"], g["pkv"],
                     g["fu"], g["fv"], g["ku"], g["kv"], cq)
        eps, fu, fv, ku, kv = (g[x].copy_to_host() for x in ("eps", "fu", "fv", "ku", "kv"))
        started = time.perf_counter()

        def solve(k):
            return self._solvers[k].step(self.gases[k], eps[k], fu[k], fv[k], ku[k], kv[k])

        workers = min(m, os.cpu_count() or 1)
        if workers > 1:  # the solver's kernel releases the GIL: members on host threads
            if self._pool is None:
                self._pool = ThreadPoolExecutor(max_workers=workers)
            self.gases = list(self._pool.map(solve, range(m)))
        else:
            self.gases = [solve(k) for k in range(m)]
        self.host_gas_seconds += time.perf_counter() - started
        self._upload_gas()
        self._launch(K.drag_at_new_gas, m * n, e["s"], e["ctl"], g["u"], g["v"], g["coef"],
                     e["ext"], cp, cq)
        self.dem.step(self.dem_steps_per_cfd, external_on_device=True)

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
        ...}, 'cfd_steps': k, 'coupling': ..., 'deposit_chunks': C}`` (a state without the
        last two continues with the host coupling)."""
        return {"dem": self.dem.state(),
                "gas": {f"m{k}": g.state_dict() for k, g in enumerate(self.gases)},
                "cfd_steps": self.cfd_steps, "coupling": self.coupling,
                "deposit_chunks": self.deposit_chunks}

    @classmethod
    def from_state(cls, case: CaseConfig, state: dict, *, threads=None, blocks_per_member=1
                   ) -> "GpuEnsembleRiser":
        """The ensemble saved by :meth:`state` (with the same ``case``)."""
        dem = GpuEnsembleDEM.from_state(state["dem"], threads=threads,
                                        blocks_per_member=blocks_per_member)
        gases = [GasState.from_state_dict(state["gas"][f"m{k}"]) for k in range(dem.n_members)]
        coupling = str(state.get("coupling", "host"))
        chunks = state.get("deposit_chunks")
        return cls(case, dem, gases, int(np.asarray(state["cfd_steps"])), coupling=coupling,
                   deposit_chunks=None if chunks is None else int(np.asarray(chunks)))
