"""GpuEnsembleDEM: M independent DEM systems of N particles each on a CUDA device.

The geometry, contact law and integrator are the CPU engine's
(:class:`cfbmarkov.simulate.dem.DEMSystem`): discs between contact walls at x = 0 and W,
periodic in y with period H (or a floor at y = 0), leapfrog with half-step velocities, laps
and pass events. The kernels are in :mod:`.kernels` (one thread block per member, every DEM
step of a :meth:`GpuEnsembleDEM.step` call in one launch unless an event buffer fills).
Between calls the particles stay on the device; a call moves only the external forces in
and the control slots out (and the pass events, when there are any).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numba.core.errors import NumbaPerformanceWarning

from cfbmarkov.errors import CfbmarkovError, InputError, TimeStepAdvisory
from cfbmarkov.simulate.dem.law import ContactLaw, contact_resolution, too_coarse_a_step
from cfbmarkov.simulate.dem.neighbours import search_grid
from cfbmarkov.simulate.dem.system import _REASONS, MAX_OVERLAP, SimulationBlowUp
from cfbmarkov.simulate.gpu import require_gpu, simulator

STATE_VERSION = 1
#: neighbours a particle's list holds (a list build that finds more stops the run with an
#: error naming the fix: a smaller skin)
MAX_NEIGHBOURS = 32


def _per_particle(value, m, n, name):
    a = np.asarray(value, dtype=np.float64)
    a = np.broadcast_to(a, (m, n)) if a.ndim < 2 else a
    if a.shape != (m, n):
        raise InputError(f"{name}: expected a number, {n} or {m} x {n} values, got shape "
                         f"{np.shape(value)}")
    if not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise InputError(f"{name}: values must be positive and finite")
    return np.ascontiguousarray(a)


def default_threads() -> int:
    """Threads per block (per member): 256 on a GPU, 16 under the CUDA simulator (where each
    thread is a Python thread)."""
    return 16 if simulator() else 256


class GpuEnsembleDEM:
    """M independent 2D DEM systems on a CUDA device, stepped together.

    Parameters
    ----------
    positions, velocities : array_like (M, N, 2)
        Centres (m) and half-step velocities v(t - dt/2) (m/s) of member m's particles.
    radius, density : number, (N,) or (M, N) array
        R (m) and rho (kg/m^3).
    law : ContactLaw
    width, height : float
        W and H, m.
    gravity : float, optional
        m/s^2 in -y.
    time_step : float, optional
        DEM step, s.
    skin : float, optional
        Verlet skin, m: a member's lists are rebuilt when one of its particles has moved
        more than skin/2 since the last build.
    search_cells : (int, int), optional
        Cells of the search grid (default: the finest no smaller than 2 R_max + skin).
    angular_velocities : array_like (M, N), optional
        rad/s (default 0).
    bottom_wall : bool, optional
        A contact floor at y = 0 instead of periodicity in y.
    laps : array_like (M, N) of int, optional
        Passes so far (positions outside [0, H) are wrapped and counted as by DEMSystem).
    threads : int, optional
        Threads per block (:func:`default_threads`); results do not depend on it.
    blocks_per_member : int, optional
        1 (default): one thread block per member. More: the grid-synchronised kernel
        (:func:`.kernels.grid_advance`, a cooperative launch: every block must be resident
        on the GPU at once), for members too large for one block; not available under the
        CUDA simulator. The same results, bit for bit.
    max_neighbours : int, optional
        Capacity of each particle's neighbour list.

    Raises
    ------
    GpuUnavailable
        No CUDA device, and the simulator is not switched on.
    InputError
        Bad shapes or values, or a time step that resolves a contact in fewer than 5 steps.
    """

    def __init__(self, positions, velocities, radius, density, law: ContactLaw, width, height,
                 *, gravity=9.81, time_step=5e-6, skin=3e-4, search_cells=None,
                 angular_velocities=None, bottom_wall=False, laps=None, threads=None,
                 blocks_per_member=1, max_neighbours=MAX_NEIGHBOURS, time=0.0):
        require_gpu()
        pos = np.array(positions, dtype=np.float64)
        if pos.ndim != 3 or pos.shape[2] != 2 or pos.shape[0] < 1 or pos.shape[1] < 1:
            raise InputError(f"positions: expected an (M, N, 2) array, got shape {pos.shape}")
        m, n = pos.shape[:2]
        vel = np.array(velocities, dtype=np.float64)
        if vel.shape != pos.shape:
            raise InputError(f"velocities: expected shape {pos.shape}, got {vel.shape}")
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(vel))):
            raise InputError("positions and velocities must be finite")
        rad = _per_particle(radius, m, n, "radius")
        rho = _per_particle(density, m, n, "density")
        om = (np.zeros((m, n)) if angular_velocities is None
              else np.array(angular_velocities, dtype=np.float64).reshape(m, n))
        if not isinstance(law, ContactLaw):
            raise InputError("law: expected a ContactLaw")
        width, height, dt, skin = float(width), float(height), float(time_step), float(skin)
        for name, v in (("width", width), ("height", height), ("time_step", dt), ("skin", skin)):
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a positive number, got {v!r}")
        periodic = not bottom_wall
        lp = np.zeros((m, n), np.int64) if laps is None else np.array(laps, np.int64).reshape(m, n)
        if periodic:
            wrap = np.floor(pos[..., 1] / height).astype(np.int64)
            lp = lp + wrap
            pos[..., 1] -= wrap * height
            pos[..., 1] = np.where(pos[..., 1] >= height, 0.0, pos[..., 1])
        x = pos[..., 0]
        if np.any(x < -rad) or np.any(x > width + rad):
            raise InputError(f"a particle is outside the walls (0 <= x <= {width:g} m) by more "
                             f"than its radius")
        rmax = float(rad.max())
        cells = search_grid(width, height, 2.0 * rmax + skin, search_cells, periodic)
        mass = rho * math.pi * (2 * rad) ** 3 / 6.0
        inertia = 0.1 * mass * (2 * rad) ** 2
        mono = bool(np.all(rad == rad.flat[0]) and np.all(rho == rho.flat[0]))
        mmin = float(mass.min())
        worst, msg = contact_resolution(law, mmin, dt)
        if worst < 5:
            raise InputError(too_coarse_a_step(worst, dt, msg))
        if worst < 10:
            warnings.warn(msg + "; 10 or more are recommended", TimeStepAdvisory, stacklevel=2)
        rec = np.zeros((8, m * n))
        rec[0] = pos[..., 0].reshape(-1)
        rec[1] = pos[..., 1].reshape(-1)
        rec[2] = vel[..., 0].reshape(-1)
        rec[3] = vel[..., 1].reshape(-1)
        rec[4] = (rad * om).reshape(-1)
        rec[5] = rad.reshape(-1)
        rec[6] = (1.0 / mass).reshape(-1)
        rec[7] = (rad / inertia).reshape(-1)
        self._setup(m, n, law, width, height, float(gravity), dt, skin, cells, bool(bottom_wall),
                    mono, mmin, rmax, threads, int(max_neighbours), float(time),
                    blocks_per_member)
        from cfbmarkov.simulate.gpu import kernels as K
        ctl = np.zeros((m, K.N_CTL), np.int64)
        ctl[:, K.C_REBUILD] = 1
        self._upload(rec, rec[0:2].copy(), np.zeros((3, m * n)), lp.reshape(-1), ctl,
                     None, None, None)

    # ------------------------------------------------------------------ set-up
    def _setup(self, m, n, law, width, height, gravity, dt, skin, cells, bottom_wall, mono,
               mmin, rmax, threads, max_neighbours, t0, blocks_per_member=1):
        from cfbmarkov.simulate.gpu import kernels as K
        self._bpm = int(blocks_per_member)
        if self._bpm < 1:
            raise InputError(f"blocks_per_member must be >= 1, got {blocks_per_member!r}")
        if self._bpm > 1 and simulator():
            raise InputError("blocks_per_member > 1 needs grid synchronisation, which the "
                             "CUDA simulator does not have; use 1")
        self._kernel = K.advance if self._bpm == 1 else K.grid_advance()
        self._m, self._n = m, n
        self._law = law
        self._width, self._height, self._gravity, self._dt = width, height, gravity, dt
        self._skin, self._cells, self._bottom_wall = skin, tuple(cells), bottom_wall
        self._t0 = t0
        self._threads = default_threads() if threads is None else int(threads)
        self._k = max_neighbours
        fp = np.zeros(K.N_F)
        fp[K.F_DT], fp[K.F_W], fp[K.F_H], fp[K.F_G] = dt, width, height, gravity
        fp[K.F_KN], fp[K.F_KT], fp[K.F_INV_KT] = law.kn, law.kt, 1.0 / float(law.kt)
        fp[K.F_MU] = law.mu
        fp[K.F_ETAN_PP] = law.normal_damping(0.5 * mmin)
        fp[K.F_ETAT_PP] = law.tangential_damping(0.5 * mmin)
        fp[K.F_ETAN_PW] = law.normal_damping(mmin)
        fp[K.F_ETAT_PW] = law.tangential_damping(mmin)
        fp[K.F_CN], fp[K.F_CT] = law.normal_damping_factor, law.tangential_damping_factor
        fp[K.F_SKIN] = skin
        fp[K.F_CELL_W], fp[K.F_CELL_H] = width / cells[0], height / cells[1]
        fp[K.F_OVL] = MAX_OVERLAP
        fp[K.F_CUT] = 2.0 * rmax + skin
        self._evcap = max(4 * n, 4096)
        ip = np.zeros(K.N_I, np.int64)
        ip[K.I_N], ip[K.I_NCX], ip[K.I_NCY] = n, cells[0], cells[1]
        ip[K.I_PERIODIC], ip[K.I_FLOOR] = int(not bottom_wall), int(bottom_wall)
        ip[K.I_MONO], ip[K.I_K], ip[K.I_EVCAP] = int(mono), max_neighbours, self._evcap
        self._fp, self._ip = fp, ip
        self._events = [[] for _ in range(m)]
        self._ext_set = False

    def _upload(self, rec, ref, wh, laps, ctl, nbr, nnb, spr):
        """Device arrays from host values (buffer 0 current: ``ctl`` C_CUR and C_LIST 0)."""
        from cfbmarkov.simulate.gpu._cuda import cuda
        m, n, k = self._m, self._n, self._k
        mn = m * n
        ncell = self._cells[0] * self._cells[1]
        s = np.zeros((2, 8, mn))
        s[0] = rec
        s[1] = rec
        nn = np.zeros((2, mn), np.int32)
        # list buffers: only the first nnb entries of a particle are ever read, so they are
        # left uninitialised (no host copy of their size)
        nb = cuda.device_array((2, k, mn), np.int32)
        sp = cuda.device_array((2, 2, k, mn), np.float64)
        if nbr is not None:
            nn[0] = nnb
            nb[0].copy_to_device(np.ascontiguousarray(nbr, np.int32))
            sp[0].copy_to_device(np.ascontiguousarray(spr, np.float64))
        self._d = dict(
            s=cuda.to_device(s), aux=cuda.to_device(np.ascontiguousarray(ref)),
            ext=cuda.to_device(np.zeros((2, mn))), wh=cuda.to_device(np.ascontiguousarray(wh)),
            laps=cuda.to_device(np.ascontiguousarray(laps, np.int64)), nbr=nb,
            nnb=cuda.to_device(nn), spr=sp,
            cstart=cuda.to_device(np.zeros((m, ncell + 1), np.int32)),
            part=cuda.to_device(np.zeros((m, self._threads * self._bpm), np.int64)),
            cfill=cuda.to_device(np.zeros((m, ncell), np.int32)),
            cidx=cuda.to_device(np.zeros(mn, np.int32)), key=cuda.to_device(np.zeros(mn, np.int32)),
            ctl=cuda.to_device(ctl),
            ev_s=cuda.to_device(np.zeros((m, self._evcap), np.int64)),
            ev_f=cuda.to_device(np.zeros((m, self._evcap))),
            ev_p=cuda.to_device(np.zeros((m, self._evcap), np.int64)),
            ev_d=cuda.to_device(np.zeros((m, self._evcap), np.int8)),
            bad=cuda.to_device(np.zeros(mn, np.int8)),
            fp=cuda.to_device(self._fp), ip=cuda.to_device(self._ip))
        self._ctl = ctl.copy()

    # ------------------------------------------------------------------ information
    @property
    def n_members(self) -> int:
        return self._m

    @property
    def n_particles(self) -> int:
        """Particles per member."""
        return self._n

    @property
    def time_step(self) -> float:
        return self._dt

    @property
    def bottom_wall(self) -> bool:
        return self._bottom_wall

    @property
    def search_cells(self) -> tuple[int, int]:
        return self._cells

    @property
    def steps_done(self) -> int:
        from cfbmarkov.simulate.gpu.kernels import C_STEP
        return int(self._ctl[0, C_STEP])

    @property
    def time(self) -> float:
        return self._t0 + self.steps_done * self._dt

    def _current(self, name, fields):
        """Member-wise current buffer of a double-buffered device array: (M, fields, N),
        for ``fields`` a contiguous range ``[f0, f0 + 1, ...]``. Members step together, so
        they share the current buffer and only those rows are copied."""
        from cfbmarkov.simulate.gpu.kernels import C_CUR
        m, n = self._m, self._n
        f0, f1 = fields[0], fields[-1] + 1
        curs = self._ctl[:, C_CUR]
        if np.all(curs == curs[0]):
            a = self._d[name][int(curs[0])][f0:f1].copy_to_host()
            return a.reshape(f1 - f0, m, n).transpose(1, 0, 2)
        a = self._d[name].copy_to_host()
        out = np.empty((m, f1 - f0, n))
        for k in range(m):
            out[k] = a[curs[k]][f0:f1, k * n:(k + 1) * n]
        return out

    @property
    def positions(self) -> np.ndarray:
        """(M, N, 2) positions, m (a copy)."""
        return self._current("s", [0, 1]).transpose(0, 2, 1).copy()

    @property
    def velocities(self) -> np.ndarray:
        """(M, N, 2) half-step velocities v(t - dt/2), m/s (a copy)."""
        return self._current("s", [2, 3]).transpose(0, 2, 1).copy()

    def positions_velocities(self) -> tuple[np.ndarray, np.ndarray]:
        """Both, from one copy of the particle fields: (M, N, 2) each."""
        a = self._current("s", [0, 1, 2, 3]).transpose(0, 2, 1)
        return a[..., 0:2].copy(), a[..., 2:4].copy()

    @property
    def angular_velocities(self) -> np.ndarray:
        """(M, N) spins, rad/s."""
        a = self._current("s", [4, 5])
        return a[:, 0] / a[:, 1]

    @property
    def laps(self) -> np.ndarray:
        """(M, N) passes up through the top (+1) and down through the bottom (-1)."""
        return self._d["laps"].copy_to_host().reshape(self._m, self._n)

    # ------------------------------------------------------------------ running
    @property
    def device_arrays(self) -> dict:
        """The device arrays by name (the layout of :mod:`.kernels`), for kernels that work
        on the members' particles in place (:mod:`cfbmarkov.simulate.gpu.coupling`): ``s``
        the particle fields, ``ctl`` the control slots, ``ext`` the external force."""
        return self._d

    def step(self, n_steps: int = 1, external_force=None, *, external_on_device=False
             ) -> None:
        """Advance every member ``n_steps`` DEM steps.

        Parameters
        ----------
        n_steps : int
            Steps (>= 0).
        external_force : array_like (M, N, 2), optional
            Force on each particle, N, held during these steps (e.g. drag).
        external_on_device : bool, optional
            The external force was written on the device (``device_arrays['ext']``, by a
            kernel) and is held as it is; ``external_force`` must then be None.

        Raises
        ------
        InputError
            Negative ``n_steps`` or a wrong ``external_force`` shape.
        SimulationBlowUp
            A member's particle became unphysical (the message names the member).
        CfbmarkovError
            A particle had more neighbours than its list holds.
        """
        from cfbmarkov.simulate.gpu import kernels as K
        from cfbmarkov.simulate.gpu._cuda import cuda
        n_steps = int(n_steps)
        if n_steps < 0:
            raise InputError(f"n_steps must be >= 0, got {n_steps}")
        d = self._d
        if external_on_device:
            if external_force is not None:
                raise InputError("external_force and external_on_device: give one of them")
            self._ext_set = True
        elif external_force is not None:
            ext = np.asarray(external_force, dtype=np.float64)
            if ext.shape != (self._m, self._n, 2):
                raise InputError(f"external_force: expected shape {(self._m, self._n, 2)}, "
                                 f"got {ext.shape}")
            d["ext"].copy_to_device(np.ascontiguousarray(ext.reshape(-1, 2).T))
            self._ext_set = True
        elif self._ext_set:
            d["ext"].copy_to_device(np.zeros((2, self._m * self._n)))
            self._ext_set = False
        target = self.steps_done + n_steps
        while True:
            with warnings.catch_warnings():
                # numba-cuda's "grid size will likely under-utilise the GPU" for a few members:
                # one block per member is the design (docs/simulation.md)
                warnings.simplefilter("ignore", NumbaPerformanceWarning)
                self._kernel[self._m * self._bpm, self._threads](
                    d["s"], d["aux"], d["ext"], d["wh"], d["laps"], d["nbr"], d["nnb"],
                    d["spr"], d["cstart"], d["cfill"], d["part"], d["cidx"], d["key"], d["ctl"],
                    d["ev_s"], d["ev_f"], d["ev_p"], d["ev_d"], d["bad"], d["fp"], d["ip"],
                    self._bpm, target)
            ctl = d["ctl"].copy_to_host()
            self._ctl = ctl
            if np.any(ctl[:, K.C_NEV] > 0):
                self._drain_device_events(ctl)
                d["ctl"].copy_to_device(ctl)
            if np.any(ctl[:, K.C_BAD] != 0):
                self._raise_blowup(ctl)
            if np.any(ctl[:, K.C_OVERFLOW] != 0):
                k = int(np.flatnonzero(ctl[:, K.C_OVERFLOW])[0])
                raise CfbmarkovError(
                    f"GPU DEM, member {k}: a particle has {int(ctl[k, K.C_OVERFLOW])} "
                    f"neighbours, more than the {self._k} its list holds; use a smaller skin "
                    f"or a larger max_neighbours")
            if np.all(ctl[:, K.C_STEP] >= target):
                break
        cuda.synchronize()

    def _drain_device_events(self, ctl):
        from cfbmarkov.simulate.gpu.kernels import C_NEV
        d = self._d
        for k in range(self._m):
            c = int(ctl[k, C_NEV])
            if c:  # only the events written: 25 bytes each
                es, ef, ep, ed = (d[x][k][:c].copy_to_host()
                                  for x in ("ev_s", "ev_f", "ev_p", "ev_d"))
                t = self._t0 + (es + ef) * self._dt
                self._events[k].append((t, ep, ed))
            ctl[k, C_NEV] = 0

    def _raise_blowup(self, ctl):
        from cfbmarkov.simulate.gpu.kernels import C_BAD, C_STEP
        k = int(np.flatnonzero(ctl[:, C_BAD])[0])
        bad = self._d["bad"].copy_to_host()[k * self._n:(k + 1) * self._n]
        where = np.flatnonzero(bad)
        pid = int(where[0])
        code = int(bad[pid])
        step = int(ctl[k, C_STEP]) - 1
        p = self.positions[k, pid]
        reason = _REASONS.get(code, "is invalid")
        raise SimulationBlowUp(
            f"DEM blow-up in member {k}, step {step} (t = {self._t0 + (step + 1) * self._dt:.9g}"
            f" s): particle {pid} {reason} (x = {p[0]:.6g} m, y = {p[1]:.6g} m); "
            f"{len(where)} particle(s) affected. Reduce the time step "
            "(numerics.dem_time_step), stiffen soft contacts (contact.normal_stiffness) or "
            "check the input.",
            step=step, particle=pid, reason=reason)

    def drain_pass_events(self, member: int):
        """(time, particle, direction) of member ``member``'s boundary passes since its last
        drain, sorted by time then particle; direction +1 up through the top, -1 down."""
        parts = self._events[member]
        self._events[member] = []
        if not parts:
            return np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int8)
        t = np.concatenate([p[0] for p in parts])
        p = np.concatenate([p[1] for p in parts])
        d = np.concatenate([p[2] for p in parts])
        o = np.lexsort((p, t))
        return t[o], p[o], d[o]

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        """Everything needed to continue bit for bit, as numpy arrays (member-major rows):
        the current particle records, reference positions, wall springs, laps, neighbour
        lists with their springs, control slots, parameters and pending events."""
        from cfbmarkov.simulate.gpu import kernels as K
        m, n, k = self._m, self._n, self._k
        d = self._d
        rec = self._current("s", list(range(8))).transpose(1, 0, 2).reshape(8, m * n)
        nbr_all, nnb_all, spr_all = (d[x].copy_to_host() for x in ("nbr", "nnb", "spr"))
        nbr = np.empty((k, m * n), np.int32)
        nnb = np.empty(m * n, np.int32)
        spr = np.empty((2, k, m * n))
        for q in range(m):
            sl = slice(q * n, (q + 1) * n)
            b = self._ctl[q, K.C_LIST]
            nbr[:, sl], nnb[sl] = nbr_all[b][:, sl], nnb_all[b][sl]
            spr[:, :, sl] = spr_all[b][..., sl]
        law = self._law
        events = [self.drain_pass_events(q) for q in range(m)]
        for q, ev in enumerate(events):
            if ev[0].size:
                self._events[q].append(ev)
        return {
            "version": np.asarray(STATE_VERSION), "members": np.asarray(m),
            "particles": np.asarray(n), "record": rec,
            "reference": d["aux"].copy_to_host(), "wall_springs": d["wh"].copy_to_host(),
            "laps": d["laps"].copy_to_host(), "neighbours": nbr, "neighbour_count": nnb,
            "springs": spr, "step": self._ctl[:, K.C_STEP].copy(),
            "rebuild": self._ctl[:, K.C_REBUILD].copy(),
            "width": np.asarray(self._width), "height": np.asarray(self._height),
            "gravity": np.asarray(self._gravity), "time_step": np.asarray(self._dt),
            "skin": np.asarray(self._skin), "search_cells": np.asarray(self._cells, np.int64),
            "bottom_wall": np.asarray(self._bottom_wall), "max_neighbours": np.asarray(k),
            "law": np.asarray([law.kn, law.kt, law.en, law.et, law.mu]),
            "law_mass": np.asarray(np.nan if law.mass is None else law.mass),
            "start_time": np.asarray(self._t0),
            "event_member": np.concatenate([np.full(e[0].size, q, np.int64)
                                            for q, e in enumerate(events)]),
            "event_time": np.concatenate([e[0] for e in events]),
            "event_particle": np.concatenate([e[1] for e in events]),
            "event_direction": np.concatenate([e[2] for e in events]),
        }

    @classmethod
    def from_state(cls, state: dict, *, threads=None, blocks_per_member=1) -> "GpuEnsembleDEM":
        """The ensemble saved by :meth:`state`; it continues exactly as the original would."""
        from cfbmarkov.simulate.gpu import kernels as K
        require_gpu()
        try:
            if int(np.asarray(state["version"])) != STATE_VERSION:
                raise InputError("GPU DEM state: unsupported version")
            m, n = int(np.asarray(state["members"])), int(np.asarray(state["particles"]))
            rec = np.asarray(state["record"], np.float64)
            lm = float(np.asarray(state["law_mass"]))
            law = ContactLaw(*[float(v) for v in np.asarray(state["law"])],
                             mass=None if math.isnan(lm) else lm)
            rad, im = rec[5], rec[6]
            mono = bool(np.all(rad == rad[0]) and np.all(im == im[0]))
            self = cls.__new__(cls)
            cells = tuple(int(c) for c in np.asarray(state["search_cells"]))
            self._setup(m, n, law, float(np.asarray(state["width"])),
                        float(np.asarray(state["height"])), float(np.asarray(state["gravity"])),
                        float(np.asarray(state["time_step"])), float(np.asarray(state["skin"])),
                        cells, bool(np.asarray(state["bottom_wall"])), mono,
                        float(np.min(1.0 / im)), float(rad.max()), threads,
                        int(np.asarray(state["max_neighbours"])),
                        float(np.asarray(state["start_time"])), blocks_per_member)
            if not np.all(np.isfinite(rec)):
                raise InputError("GPU DEM state: non-finite particle record")
            ctl = np.zeros((m, K.N_CTL), np.int64)
            ctl[:, K.C_STEP] = np.asarray(state["step"])
            ctl[:, K.C_REBUILD] = np.asarray(state["rebuild"])
            self._upload(rec, np.asarray(state["reference"], np.float64),
                         np.asarray(state["wall_springs"], np.float64),
                         np.asarray(state["laps"], np.int64), ctl,
                         np.asarray(state["neighbours"], np.int32),
                         np.asarray(state["neighbour_count"], np.int32),
                         np.asarray(state["springs"], np.float64))
            em = np.asarray(state["event_member"], np.int64)
            for q in range(m):
                w = em == q
                if np.any(w):
                    self._events[q].append((np.asarray(state["event_time"])[w],
                                            np.asarray(state["event_particle"])[w],
                                            np.asarray(state["event_direction"])[w]))
        except KeyError as exc:
            raise InputError(f"GPU DEM state: missing entry {exc.args[0]!r}") from None
        return self
