"""DEMSystem: the orchestration object of the 2D DEM engine. Kernels: :mod:`.contact` (law,
pair forces), :mod:`.neighbours` (cell sort, lists), :mod:`.integrate` (one step),
:mod:`.stepping` (the advance loop), :mod:`.order` (caller's order and cell order); their
arrays: :mod:`~cfbmarkov.simulate.dem.layout`.

Geometry: discs in the plane, x across between contact walls at x = 0 and x = W, y up and
periodic with period H (positions kept in [0, H), minimal image for contacts). With
``bottom_wall=True`` y is not periodic and a contact wall sits at y = 0 instead (a floor for
settled beds; nothing bounds the top). Mass and inertia are those of spheres:
m = rho*pi*d^3/6, I = m*d^2/10.

Time integration is leapfrog: ``velocities`` and ``angular_velocities`` are the half-step
values v(t - dt/2) that the next step's forces use (the sequence LAMMPS's velocity Verlet
produces; in free flight they equal v(t)). Initial velocities are taken as these values.

Laps: ``laps[i]`` counts passes up through the top (+1) and down through the bottom (-1);
the unwrapped height is ``y + laps*H`` (initial positions outside [0, H) are wrapped and
their laps set accordingly). Each pass is also logged as an event (time, particle,
direction) with the time interpolated inside the DEM step (the motion in one step is a
straight line); :meth:`DEMSystem.drain_pass_events` hands them over.

Determinism: each pair force is computed once and each particle sums its pairs in a fixed
order (no atomics), so results are bit-identical for any number of threads, and
:meth:`state` / :meth:`from_state` continue a run bit for bit (the state holds the internal
cell order, the neighbour and pair lists and their springs). Systems of fewer than
``serial_below`` (default 2000) particles run on one thread: the parallel start-up costs more
than it saves there, and it changes no result.

Performance (2-core machine, 27000 particles, paper's law and step): see ``bench.py``.
"""

from __future__ import annotations

import math
import warnings
import numba
import numpy as np

from cfbmarkov.errors import CfbmarkovError, InputError, TimeStepAdvisory
from cfbmarkov.simulate.dem import order, stepping
from cfbmarkov.simulate.dem import layout as L
from cfbmarkov.simulate.dem.contact import CONTACT_BLOCK
from cfbmarkov.simulate.dem.layout import DEMParams, empty_list, particle_arrays
from cfbmarkov.simulate.dem.law import ContactLaw, ContactTimes, contact_resolution, too_coarse_a_step
from cfbmarkov.simulate.dem.neighbours import search_grid

STATE_VERSION = 1
MAX_OVERLAP = 0.1  # blow-up: an overlap above this fraction of the (mean) diameter
# systems smaller than this run on one thread (parallel start-up costs more than it saves;
# results are bit-identical for any thread count)
SERIAL_BELOW = 2000


class SimulationBlowUp(CfbmarkovError):
    """The DEM state became unphysical (NaN, a particle through a wall, a huge overlap)."""

    def __init__(self, message: str, step: int, particle: int, reason: str):
        super().__init__(message)
        self.step = step
        self.particle = particle
        self.reason = reason


_REASONS = {L.BAD_NAN: "has a non-finite position or velocity",
            L.BAD_WALL: "is outside a wall by more than its radius",
            L.BAD_OVERLAP: f"overlaps a neighbour or wall by more than {MAX_OVERLAP:.0%} of d",
            L.BAD_RANGE: "moved by more than the period in one step"}


def _as_per_particle(value, n, name):
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise InputError(f"{name}: expected a number or {n} values, got shape {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise InputError(f"{name}: values must be positive and finite")
    return a


class DEMSystem:
    """A 2D DEM system of discs between two walls, periodic in y (see the module doc).

    Parameters
    ----------
    positions, velocities : (N, 2) arrays, m and m/s (velocities at t - dt/2).
    radius, density : number or (N,) array, m and kg/m^3.
    law : ContactLaw
    width, height : W and H, m.
    gravity : m/s^2 acting in -y (0 switches it off).
    time_step : DEM step, s.
    search_cells : (nx, ny) cells of the neighbour-search grid, or None for the finest grid
        whose cells are no smaller than the list cutoff (2 R_max + skin).
    skin : Verlet skin, m; the list is rebuilt (and particles re-sorted into cell order)
        when a particle has moved more than skin/2 since the last build, measured in a frame
        drifting in y with the particles where the domain is periodic in y
        (:func:`.neighbours.drift_velocity`).
    angular_velocities : (N,) rad/s, default 0.
    bottom_wall : contact wall at y = 0 instead of periodicity in y.
    time : starting time, s.
    """

    def __init__(self, positions, velocities, radius, density, law: ContactLaw, width, height,
                 gravity=9.81, time_step=5e-6, search_cells=(30, 351), skin=3e-4,
                 angular_velocities=None, *, bottom_wall=False, time=0.0):
        pos = np.array(positions, dtype=np.float64)
        vel = np.array(velocities, dtype=np.float64)
        if pos.ndim != 2 or pos.shape[1] != 2 or pos.shape[0] < 1:
            raise InputError(f"positions: expected an (N, 2) array, got shape {pos.shape}")
        n = pos.shape[0]
        if vel.shape != (n, 2):
            raise InputError(f"velocities: expected shape {(n, 2)}, got {vel.shape}")
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(vel))):
            raise InputError("positions and velocities must be finite")
        rad = _as_per_particle(radius, n, "radius")
        rho = _as_per_particle(density, n, "density")
        if angular_velocities is None:
            om = np.zeros(n)
        else:
            om = np.array(angular_velocities, dtype=np.float64).reshape(-1)
            if om.shape != (n,) or not np.all(np.isfinite(om)):
                raise InputError(f"angular_velocities: expected {n} finite values")
        if not isinstance(law, ContactLaw):
            raise InputError("law: expected a ContactLaw")
        width = float(width)
        height = float(height)
        gravity = float(gravity)
        dt = float(time_step)
        skin = float(skin)
        for name, v in (("width", width), ("height", height), ("time_step", dt), ("skin", skin)):
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a positive number, got {v!r}")
        if not math.isfinite(gravity):
            raise InputError(f"gravity must be finite, got {gravity!r}")
        periodic = not bottom_wall
        x = pos[:, 0]
        if np.any(x < -rad) or np.any(x > width + rad):
            i = int(np.flatnonzero((x < -rad) | (x > width + rad))[0])
            raise InputError(f"particle {i} at x = {x[i]:g} m is outside the walls "
                             f"(0 <= x <= {width:g} m) by more than its radius")
        laps = np.zeros(n, np.int64)
        if periodic:
            laps = np.floor(pos[:, 1] / height).astype(np.int64)
            pos[:, 1] -= laps * height
            pos[:, 1] = np.where(pos[:, 1] >= height, 0.0, pos[:, 1])
        elif np.any(pos[:, 1] < -rad):
            i = int(np.flatnonzero(pos[:, 1] < -rad)[0])
            raise InputError(f"particle {i} at y = {pos[i, 1]:g} m is below the bottom wall")
        ncx, ncy = search_grid(width, height, 2.0 * float(rad.max()) + skin, search_cells,
                               periodic)

        mass = rho * math.pi * (2 * rad) ** 3 / 6.0
        inertia = 0.1 * mass * (2 * rad) ** 2
        mono = bool(np.all(rad == rad[0]) and np.all(rho == rho[0]))
        mmin = float(mass.min())

        self._law = law
        self._n = n
        self._width, self._height, self._gravity, self._dt = width, height, gravity, dt
        self._skin = skin
        self._cells = (ncx, ncy)
        self._bottom_wall = bool(bottom_wall)
        self._density = rho
        self._mono = mono
        self._min_mass = mmin
        self._check_steps_per_contact()

        self._arrays = particle_arrays(pos, vel, rad, om, mass, inertia, laps)
        self._lists = [empty_list(n, 4), empty_list(n, 4)]
        self._pair_scratch(self._lists[0].pi.shape[0])
        self._fsum = np.zeros((n, 3))
        self._t0 = float(time)
        self.serial_below = SERIAL_BELOW
        self._prm = self._parameters()
        self._alloc_scratch(capacity=max(4 * n, 4096))

    # ------------------------------------------------------------------ set-up helpers
    def _parameters(self) -> DEMParams:
        law = self._law
        m = self._min_mass  # all particles share it when mono
        return DEMParams(
            dt=self._dt, width=self._width, height=self._height, gravity=self._gravity,
            kn=float(law.kn), kt=float(law.kt), inv_kt=1.0 / float(law.kt), mu=float(law.mu),
            etan_pp=law.normal_damping(0.5 * m), etat_pp=law.tangential_damping(0.5 * m),
            etan_pw=law.normal_damping(m), etat_pw=law.tangential_damping(m),
            cn=law.normal_damping_factor, ct=law.tangential_damping_factor, skin=self._skin,
            cell_w=self._width / self._cells[0], cell_h=self._height / self._cells[1],
            rmax=float(self._arrays["st"][0, :, 5].max()), max_overlap=MAX_OVERLAP,
            t0=self._t0, ncx=int(self._cells[0]), ncy=int(self._cells[1]),
            periodic=not self._bottom_wall, floor=self._bottom_wall, mono=self._mono)

    def _pair_scratch(self, capacity):
        """Per-pair scratch for lists of up to ``capacity`` pairs: forces, and the pairs in
        contact by blocks (:func:`.contact.pair_forces`)."""
        self._pf = np.zeros((capacity, 3))
        self._contact_ids = np.zeros(capacity, np.int64)
        self._block_contacts = np.zeros(capacity // CONTACT_BLOCK + 1, np.int64)

    def _alloc_scratch(self, capacity):
        n = self._n
        ncell = self._cells[0] * self._cells[1]
        self._scratch = dict(evf=np.zeros(n, np.int8), bad=np.zeros(n, np.int8),
                             key=np.zeros(n, np.int64), cstart=np.zeros(ncell + 1, np.int64),
                             cfill=np.zeros(ncell, np.int64), perm=np.zeros(n, np.int64),
                             invperm=np.zeros(n, np.int64), wall_ids=np.zeros(n, np.int64),
                             n_wall=np.full(1, -1, np.int64),
                             n_contacts=np.full(1, -1, np.int64),
                             touched=np.full(n, -1, np.int64), touched_ids=np.zeros(n, np.int64),
                             stamp=np.zeros(1, np.int64))
        self._ev = (np.zeros(capacity), np.zeros(capacity, np.int64), np.zeros(capacity, np.int8))
        self._ext_set = False
        self._wall_impulse = np.zeros(2)
        # the caller's particles' cell-order index (_internal_index), and the list build
        # it belongs to
        self._where = np.zeros(n, np.int64)
        self._where_key = None

    def _check_steps_per_contact(self):
        worst, msg = contact_resolution(self._law, self._min_mass, self._dt)
        if worst < 5:
            raise InputError(too_coarse_a_step(worst, self._dt, msg))
        if worst < 10:
            warnings.warn(msg + "; 10 or more are recommended", TimeStepAdvisory, stacklevel=3)

    # ------------------------------------------------------------------ information
    def contact_time(self) -> ContactTimes:
        """Linear spring-dashpot contact durations (particle-particle, particle-wall) of the
        lightest particle, s."""
        pp, pw = self._law.contact_times(self._min_mass)
        return ContactTimes(pp, pw)

    def steps_per_contact(self) -> ContactTimes:
        pp, pw = self.contact_time()
        return ContactTimes(pp / self._dt, pw / self._dt)

    @property
    def n_particles(self) -> int:
        return self._n

    @property
    def law(self) -> ContactLaw:
        return self._law

    @property
    def time_step(self) -> float:
        return self._dt

    @property
    def width(self) -> float:
        return self._width

    @property
    def height(self) -> float:
        return self._height

    @property
    def bottom_wall(self) -> bool:
        """A contact floor at y = 0 instead of periodicity in y."""
        return self._bottom_wall

    @property
    def search_cells(self) -> tuple[int, int]:
        return self._cells

    @property
    def steps_done(self) -> int:
        return int(self._arrays["ctl"][L.C_STEP])

    @property
    def time(self) -> float:
        return self._t0 + self.steps_done * self._dt

    @property
    def n_rebuilds(self) -> int:
        """Neighbour-list builds so far (each also re-sorts the particles)."""
        return int(self._arrays["ctl"][L.C_NREBUILD])

    def _cur(self):
        a = self._arrays
        ctl = a["ctl"]
        return a["st"][ctl[L.C_ST]], a["ids"][ctl[L.C_PA]], ctl[L.C_PA]

    def _to_caller(self, values):
        st, ids, _ = self._cur()
        out = np.empty_like(values)
        out[ids] = values
        return out

    def _internal_index(self) -> np.ndarray:
        """Each caller's particle's index in cell order, remade after a list build (the
        order changes only then)."""
        ctl = self._arrays["ctl"]
        key = (int(ctl[L.C_NREBUILD]), int(ctl[L.C_PA]))
        if self._where_key != key:
            order.internal_index(self._cur()[1], self._where)
            self._where_key = key
        return self._where

    def _pair_to_caller(self, column: int) -> np.ndarray:
        st = self._cur()[0]
        out = np.empty((self._n, 2))
        order.gather_pairs(st[:, column:column + 2], self._internal_index(), out)
        return out

    @property
    def positions(self) -> np.ndarray:
        """(N, 2) positions, caller's order (a copy)."""
        return self._pair_to_caller(0)

    @property
    def velocities(self) -> np.ndarray:
        """(N, 2) half-step velocities v(t - dt/2), caller's order (a copy)."""
        return self._pair_to_caller(2)

    @property
    def angular_velocities(self) -> np.ndarray:
        st = self._cur()[0]
        return self._to_caller(st[:, 4] / st[:, 5])

    @property
    def radius(self) -> np.ndarray:
        return self._to_caller(self._cur()[0][:, 5])

    @property
    def mass(self) -> np.ndarray:
        return self._to_caller(1.0 / self._cur()[0][:, 6])

    @property
    def moment_of_inertia(self) -> np.ndarray:
        st = self._cur()[0]
        return self._to_caller(st[:, 5] / st[:, 7])

    @property
    def laps(self) -> np.ndarray:
        a = self._arrays
        return self._to_caller(a["laps"][a["ctl"][L.C_PA]])

    @property
    def order(self) -> np.ndarray:
        """Caller's index of each particle in the internal (cell) order."""
        return self._cur()[1].copy()

    def kinetic_energy(self) -> float:
        """Translational plus rotational kinetic energy from the half-step velocities, J."""
        st = self._cur()[0]
        return float(0.5 * np.sum((st[:, 2] ** 2 + st[:, 3] ** 2) / st[:, 6])
                     + 0.5 * np.sum(st[:, 4] ** 2 / (st[:, 5] * st[:, 7])))

    def overlaps(self) -> np.ndarray:
        """Overlap of every pair in contact and every wall contact (diagnostics; O(N) with
        the neighbour list when it is current, else a brute-force O(N^2) check)."""
        st = self._cur()[0]
        x, y, r = st[:, 0], st[:, 1], st[:, 5]
        out = [np.maximum(r - x, 0.0), np.maximum(x + r - self._width, 0.0)]
        if self._bottom_wall:
            out.append(np.maximum(r - y, 0.0))
        n = self._n
        for i0 in range(0, n, 2048):
            sl = slice(i0, min(n, i0 + 2048))
            dx = x[None, :] - x[sl, None]
            dy = y[None, :] - y[sl, None]
            if not self._bottom_wall:
                dy -= self._height * np.round(dy / self._height)
            d = r[None, :] + r[sl, None] - np.hypot(dx, dy)
            idx = np.arange(sl.start, sl.stop)
            d[np.arange(len(idx)), idx] = 0.0
            out.append(d[d > 0])
        return np.concatenate([o[o > 0] for o in out])

    # ------------------------------------------------------------------ running
    def step(self, n_steps: int = 1, external_force=None) -> None:
        """Advance ``n_steps`` DEM steps.

        Parameters
        ----------
        n_steps : int
            Steps to do (>= 0).
        external_force : array_like (N, 2), optional
            Force on each particle (caller's order), N, added during these steps (e.g. drag).

        Raises
        ------
        InputError
            Negative ``n_steps`` or a wrong ``external_force`` shape.
        SimulationBlowUp
            A particle became unphysical; the state is that after the bad step.
        """
        n_steps = int(n_steps)
        if n_steps < 0:
            raise InputError(f"n_steps must be >= 0, got {n_steps}")
        a = self._arrays
        ctl = a["ctl"]
        aux_cur = a["aux"][ctl[L.C_PA]]
        if external_force is not None:
            ext = np.ascontiguousarray(external_force, dtype=np.float64)
            if ext.shape != (self._n, 2):
                raise InputError(f"external_force: expected shape {(self._n, 2)}, got {ext.shape}")
            order.scatter_external(ext, a["ids"][ctl[L.C_PA]], aux_cur)
            self._ext_set = True
        elif self._ext_set:
            order.clear_external(aux_cur)
            self._ext_set = False
        threads = numba.get_num_threads()
        if self._n < self.serial_below and threads > 1:
            numba.set_num_threads(1)  # results do not depend on it; small systems run faster
        try:
            self._advance(n_steps)
        finally:
            if numba.get_num_threads() != threads:
                numba.set_num_threads(threads)

    def _advance(self, n_steps):
        a = self._arrays
        ctl = a["ctl"]
        left = n_steps
        sc = self._scratch
        while left > 0:
            done, status, info = stepping.advance(
                a["st"], a["aux"], a["wh"], a["ids"], a["laps"], self._lists[0], self._lists[1],
                self._pf, self._fsum, ctl, sc["evf"], sc["bad"], sc["key"], sc["cstart"],
                sc["cfill"], sc["perm"], sc["invperm"], sc["wall_ids"], sc["n_wall"],
                sc["n_contacts"], self._contact_ids, self._block_contacts, sc["touched"],
                sc["touched_ids"], sc["stamp"], self._prm,
                left, *self._ev, self._wall_impulse)
            left -= done
            if status == L.ST_OK:
                continue
            if status == L.ST_STRIDE:
                new = 1 if ctl[L.C_LIST] == 0 else 0
                self._lists[new] = empty_list(self._n, int(info) + 2)
                cap = max(lst.pi.shape[0] for lst in self._lists)
                if self._pf.shape[0] < cap:
                    self._pair_scratch(cap)
            elif status == L.ST_EVENTS:
                n_ev = int(ctl[L.C_NEV])
                cap = max(2 * self._ev[0].shape[0], n_ev + 4 * self._n)
                self._ev = tuple(np.concatenate([e[:n_ev], np.zeros(cap - n_ev, e.dtype)])
                                 for e in self._ev)
            elif status == L.ST_BLOWUP:
                self._raise_blowup()

    def _raise_blowup(self):
        bad = self._scratch["bad"]
        st, ids, _ = self._cur()
        where = np.flatnonzero(bad)
        # report the particle with the smallest caller index, for a stable message
        k = int(where[np.argmin(ids[where])])
        code = int(bad[k])
        step = self.steps_done - 1
        pid = int(ids[k])
        msg = (f"DEM blow-up in step {step} (t = {self._t0 + (step + 1) * self._dt:.9g} s): "
               f"particle {pid} {_REASONS.get(code, 'is invalid')} (x = {st[k, 0]:.6g} m, "
               f"y = {st[k, 1]:.6g} m, v = ({st[k, 2]:.4g}, {st[k, 3]:.4g}) m/s); "
               f"{len(where)} particle(s) affected. {self._blowup_advice(code)}")
        raise SimulationBlowUp(msg, step=step, particle=pid, reason=_REASONS.get(code, "invalid"))

    def _blowup_advice(self, code: int) -> str:
        """What to change after a blow-up: the time step, and where the contacts are soft
        enough that a collision at 1 m/s alone overlaps by more than half the blow-up limit
        (the linear spring's largest overlap v sqrt(m / kn)), the normal stiffness."""
        advice = "Reduce the time step (numerics.dem_time_step) or check the input."
        if code != L.BAD_OVERLAP:
            return advice
        # the lightest particle's diameter (its mass at the densest particles' density)
        diameter = (6.0 * self._min_mass / (math.pi * float(np.max(self._density)))) ** (1 / 3)
        kn = float(self._law.kn)
        overlap = 1.0 * math.sqrt(self._min_mass / kn)      # m, at 1 m/s
        if math.isfinite(diameter) and overlap > 0.5 * MAX_OVERLAP * diameter:
            return (f"The contacts are soft: contact.normal_stiffness {kn:g} N/m lets a "
                    f"collision at 1 m/s overlap by {100 * overlap / diameter:.0f} % of d "
                    f"(v sqrt(m / kn)); stiffen them (the overlap falls as 1 / sqrt(kn), and "
                    "the time step with it: numerics.dem_time_step), or check the input.")
        return advice

    @property
    def wall_impulse(self) -> np.ndarray:
        """Vertical impulse the walls gave the particles since the last
        :meth:`reset_wall_impulse` (or since this object was made; not part of the state):
        [side walls (friction and tangential damping), floor (normal)], N s."""
        return self._wall_impulse.copy()

    def reset_wall_impulse(self) -> None:
        self._wall_impulse[:] = 0.0

    def drain_pass_events(self):
        """(time, particle, direction) of the boundary passes since the last drain, sorted by
        time (stable); direction +1 up through the top, -1 down through the bottom."""
        ctl = self._arrays["ctl"]
        n = int(ctl[L.C_NEV])
        t, p, d = (e[:n].copy() for e in self._ev)
        ctl[L.C_NEV] = 0
        o = np.argsort(t, kind="stable")
        return t[o], p[o], d[o]

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        """Everything needed to continue bit for bit, as a dict of numpy arrays (scalars are
        0-d arrays; writable to HDF5 as is). ``positions``, ``velocities``,
        ``angular_velocities`` and ``laps`` are in the caller's order for convenience; the
        ``internal_*`` arrays are in the engine's cell order."""
        a = self._arrays
        ctl = a["ctl"]
        cs, cp, cl = ctl[L.C_ST], ctl[L.C_PA], ctl[L.C_LIST]
        nnb, nown, nbr, pstart, pi, pj, hist, lowstart, lowpid = self._lists[cl]
        stride = nbr.shape[0] // self._n
        npairs = int(pstart[-1])
        law = self._law
        n_ev = int(ctl[L.C_NEV])
        return {
            "version": np.asarray(STATE_VERSION),
            "positions": self.positions, "velocities": self.velocities,
            "angular_velocities": self.angular_velocities, "laps": self.laps,
            "density": self._density.copy(),
            "width": np.asarray(self._width), "height": np.asarray(self._height),
            "gravity": np.asarray(self._gravity), "time_step": np.asarray(self._dt),
            "skin": np.asarray(self._skin), "search_cells": np.asarray(self._cells, np.int64),
            "bottom_wall": np.asarray(self._bottom_wall),
            "law": np.asarray([law.kn, law.kt, law.en, law.et, law.mu]),
            "law_mass": np.asarray(np.nan if law.mass is None else law.mass),
            "start_time": np.asarray(self._t0), "time": np.asarray(self.time),
            "internal_state": a["st"][cs].copy(), "internal_aux": a["aux"][cp].copy(),
            "internal_wall_springs": a["wh"][cp].copy(), "internal_order": a["ids"][cp].copy(),
            "internal_laps": a["laps"][cp].copy(),
            "internal_control": ctl.copy(),
            "internal_neighbour_count": nnb.copy(),
            "internal_neighbour_count_own": nown.copy(),
            "internal_neighbours": nbr.reshape(self._n, stride).copy(),
            "internal_pair_start": pstart.copy(), "internal_pair_first": pi[:npairs].copy(),
            "internal_pair_second": pj[:npairs].copy(),
            "internal_springs": hist[:npairs].copy(),
            "internal_second_start": lowstart.copy(),
            "internal_second_pairs": lowpid[:npairs].copy(),
            "pending_event_time": self._ev[0][:n_ev].copy(),
            "pending_event_particle": self._ev[1][:n_ev].copy(),
            "pending_event_direction": self._ev[2][:n_ev].copy(),
        }

    @classmethod
    def from_state(cls, state: dict) -> DEMSystem:
        """Rebuild a system from :meth:`state`; it continues exactly as the original would."""
        try:
            version = int(np.asarray(state["version"]))
            if version != STATE_VERSION:
                raise InputError(f"DEM state version {version} is not supported "
                                 f"(expected {STATE_VERSION})")
            st = np.asarray(state["internal_state"], np.float64)
            n = st.shape[0]
            law_v = [float(v) for v in np.asarray(state["law"])]
            lm = float(np.asarray(state["law_mass"]))
            law = ContactLaw(*law_v, mass=None if math.isnan(lm) else lm)
            self = cls.__new__(cls)
            self._law = law
            self._n = n
            self._width = float(np.asarray(state["width"]))
            self._height = float(np.asarray(state["height"]))
            self._gravity = float(np.asarray(state["gravity"]))
            self._dt = float(np.asarray(state["time_step"]))
            self._skin = float(np.asarray(state["skin"]))
            self._cells = tuple(int(c) for c in np.asarray(state["search_cells"]))
            self._bottom_wall = bool(np.asarray(state["bottom_wall"]))
            self._density = np.asarray(state["density"], np.float64).copy()
            rad = st[:, 5]
            self._mono = bool(np.all(rad == rad[0]) and np.all(self._density == self._density[0]))
            self._min_mass = float(np.min(1.0 / st[:, 6]))
            self._t0 = float(np.asarray(state["start_time"]))
            self.serial_below = SERIAL_BELOW
            saved = np.asarray(state["internal_control"], np.int64)
            ctl = np.zeros(max(L.N_C, saved.shape[0]), np.int64)
            ctl[:saved.shape[0]] = saved  # a state from before the drifting list: no drift
            ctl[L.C_ST] = 0
            ctl[L.C_PA] = 0
            ctl[L.C_LIST] = 0
            sta = np.zeros((2, n, 8))
            sta[0] = st
            sta[1] = st
            aux = np.zeros((2, n, 4))
            aux[0] = np.asarray(state["internal_aux"], np.float64)
            wh = np.zeros((2, n, 3))
            wh[0] = np.asarray(state["internal_wall_springs"], np.float64)
            ids = np.zeros((2, n), np.int64)
            ids[0] = np.asarray(state["internal_order"], np.int64)
            lp = np.zeros((2, n), np.int64)
            lp[0] = np.asarray(state["internal_laps"], np.int64)
            self._arrays = dict(st=sta, aux=aux, wh=wh, ids=ids, laps=lp, ctl=ctl)
            nbr = np.ascontiguousarray(state["internal_neighbours"], np.int32)
            stride = nbr.shape[1]
            lst = empty_list(n, stride)
            npairs = int(np.asarray(state["internal_pair_start"])[-1])
            lst.nnb[:] = state["internal_neighbour_count"]
            lst.nown[:] = state["internal_neighbour_count_own"]
            lst.nbr[:] = nbr.reshape(-1)
            lst.pstart[:] = state["internal_pair_start"]
            lst.pi[:npairs] = state["internal_pair_first"]
            lst.pj[:npairs] = state["internal_pair_second"]
            lst.springs[:npairs] = state["internal_springs"]
            lst.lowstart[:] = state["internal_second_start"]
            lst.lowpid[:npairs] = state["internal_second_pairs"]
            self._lists = [lst, empty_list(n, stride)]
            self._pair_scratch(lst.pi.shape[0])
            self._fsum = np.zeros((n, 3))
            self._prm = self._parameters()
            ev_t = np.asarray(state["pending_event_time"], np.float64)
            self._alloc_scratch(capacity=max(4 * n, 4096, 2 * ev_t.shape[0]))
            k = ev_t.shape[0]
            self._ev[0][:k] = ev_t
            self._ev[1][:k] = np.asarray(state["pending_event_particle"], np.int64)
            self._ev[2][:k] = np.asarray(state["pending_event_direction"], np.int8)
            ctl[L.C_NEV] = k
        except KeyError as exc:
            raise InputError(f"DEM state: missing entry {exc.args[0]!r}") from None
        return self
