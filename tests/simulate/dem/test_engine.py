"""DEM engine: periodic boundary, conservation, determinism, checkpoints, safety, beds."""

import math
import warnings

import numba
import numpy as np
import pytest

import cfbmarkov  # noqa: F401
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.simulate.dem import ContactLaw, DEMSystem, SimulationBlowUp

D, RHO = 1e-3, 2600.0
R = D / 2
M = RHO * math.pi * D**3 / 6
LAW = ContactLaw()


def make(pos, vel, W=0.01, H=0.02, dt=1e-6, law=LAW, g=0.0, cells=None, om=None, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return DEMSystem(np.asarray(pos, float), np.asarray(vel, float), kw.pop("radius", R),
                         kw.pop("density", RHO), law, W, H, gravity=g, time_step=dt,
                         search_cells=cells, skin=3e-4, angular_velocities=om, **kw)


def gas(n, W, H, seed, speed=1.0, frac=0.8, radius=None):
    """n non-overlapping particles on a jittered lattice, random velocities."""
    rng = np.random.default_rng(seed)
    ncol = int(W / (1.2 * D))
    nrow = math.ceil(n / ncol)
    sx, sy = W / ncol, H / nrow
    assert min(sx, sy) > 1.02 * D
    ix, iy = np.meshgrid(np.arange(ncol), np.arange(nrow))
    jit = 0.45 * (min(sx, sy) - D)
    pos = np.column_stack([(ix.ravel()[:n] + 0.5) * sx, (iy.ravel()[:n] + 0.5) * sy])
    pos += rng.uniform(-jit, jit, pos.shape)
    vel = rng.normal(0, speed / math.sqrt(2), (n, 2))
    om = rng.normal(0, 100.0, n)
    return pos, vel, om


# ---------------------------------------------------------------- periodic boundary
def test_pass_through_top_and_bottom():
    H = 0.02
    s = make([[0.003, H - 0.0005], [0.007, 0.0004]], [[0, 1.0], [0, -2.0]], H=H, dt=1e-6)
    s.step(1000)
    assert list(s.laps) == [1, -1]
    y = s.positions[:, 1]
    assert y[0] == pytest.approx(0.0005, abs=1e-12)
    assert y[1] == pytest.approx(H - 0.0016, abs=1e-12)
    t, p, d = s.drain_pass_events()
    assert list(p) == [1, 0] and list(d) == [-1, 1]
    assert t[0] == pytest.approx(0.0002, abs=1e-6)  # within one DEM step
    assert t[1] == pytest.approx(0.0005, abs=1e-6)
    assert np.all(np.abs(t - [0.0002, 0.0005]) < 1e-9)  # interpolated inside the step
    assert s.drain_pass_events()[0].size == 0
    # unwrapped height = y + laps * H
    assert y[0] + s.laps[0] * H == pytest.approx(H + 0.0005)


def test_initial_positions_are_wrapped():
    s = make([[0.005, 0.025], [0.005, -0.001]], [[0, 0], [0, 0]], H=0.02)
    assert list(s.laps) == [1, -1]
    assert np.allclose(s.positions[:, 1], [0.005, 0.019])


def test_collision_across_periodic_boundary():
    H = 0.02
    gap = 0.000213  # not a whole number of steps: the first touch is not a rounding tie

    def run(y0):
        ya = (y0 - (D + gap) / 2) % H
        yb = (y0 + (D + gap) / 2) % H
        s = make([[0.005, ya], [0.005, yb]], [[0, 1.0], [0, -1.0]], H=H, dt=2e-7,
                 om=[0, 0])
        s.step(1000)
        return s

    across = run(0.0)
    middle = run(H / 2)
    v = across.velocities
    assert v[0, 1] == pytest.approx(-0.97, abs=0.002) and v[1, 1] == pytest.approx(0.97, abs=0.002)
    assert np.allclose(v, middle.velocities, rtol=0, atol=1e-9)
    assert list(across.laps) == [0, 0]  # they bounced back before passing the boundary


# ---------------------------------------------------------------- conservation
def total_energy(s):
    """Kinetic plus normal-spring energy (mu = 0: no tangential springs)."""
    pos, r = s.positions, s.radius
    e = s.kinetic_energy()
    dx = pos[None, :, 0] - pos[:, None, 0]
    dy = pos[None, :, 1] - pos[:, None, 1]
    dy -= s.height * np.round(dy / s.height)
    ov = np.triu(np.maximum(r[None, :] + r[:, None] - np.hypot(dx, dy), 0), 1)
    wall = np.maximum(r - pos[:, 0], 0) + np.maximum(pos[:, 0] + r - s.width, 0)
    return e + 0.5 * s.law.kn * (np.sum(ov**2) + np.sum(wall**2))


def test_energy_conserved_elastic_frictionless():
    law = ContactLaw(en=1.0, et=1.0, mu=0.0)
    W, H = 0.02, 0.03
    pos, vel, om = gas(150, W, H, seed=3)
    dt = law.contact_time(M / 2) / 50
    s = make(pos, vel, W, H, dt=dt, law=law, om=om)
    om = s.angular_velocities
    e0 = total_energy(s)
    contacts = 0
    for _ in range(40):
        s.step(250)
        contacts += s.overlaps().size
    e1 = total_energy(s)
    print(f"energy drift {e1 / e0 - 1:.2e} over {s.steps_done} steps "
          f"({s.time * 1e3:.1f} ms, ~{s.time * 1.0 / 2e-3:.0f} free paths per particle)")
    assert contacts > 0
    assert abs(e1 / e0 - 1) < 1e-3
    # omega is untouched without friction
    assert np.array_equal(s.angular_velocities, om)


def test_momentum_conserved_with_friction():
    """Pair forces are exact negatives: total momentum is conserved to rounding when no
    wall is touched (gravity off)."""
    W, H = 0.06, 0.03
    pos, vel, om = gas(400, 0.02, H, seed=5, speed=1.0)
    pos[:, 0] += 0.02
    vel[:, 0] *= 0.05
    s = make(pos, vel, W, H, dt=2e-6, om=om)
    m = s.mass
    p0 = (m[:, None] * s.velocities).sum(0)
    scale = (m[:, None] * np.abs(s.velocities)).sum(0)
    contacts = 0
    for _ in range(20):
        s.step(100)
        contacts += s.overlaps().size
        x = s.positions[:, 0]
        assert x.min() > R + 1e-4 and x.max() < W - R - 1e-4  # no wall contact
    assert contacts > 20
    p1 = (m[:, None] * s.velocities).sum(0)
    assert np.all(np.abs(p1 - p0) <= 1e-13 * scale)
    assert s.kinetic_energy() < 0.5 * np.sum(m * (vel**2).sum(1)) + 0.5 * np.sum(
        s.moment_of_inertia * om**2)  # dissipative


# ---------------------------------------------------------------- determinism
def dense_mix(seed=1, n=500):
    W, H = 0.02, 0.04
    pos, vel, om = gas(n, W, H, seed=seed, speed=1.0)
    return make(pos, vel, W, H, dt=2e-6, g=9.81, om=om)


def snapshot(s):
    return [s.positions, s.velocities, s.angular_velocities, s.laps, *s.drain_pass_events()]


def same(a, b):
    return all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(a, b))


def test_same_run_twice_identical():
    a, b = dense_mix(), dense_mix()
    a.step(300)
    b.step(300)
    assert a.n_rebuilds > 2
    assert same(snapshot(a), snapshot(b))


def test_checkpoint_continues_bit_for_bit():
    a = dense_mix()
    a.step(200)
    b = dense_mix()
    b.step(100)
    st = b.state()
    assert all(isinstance(v, np.ndarray) for v in st.values())
    c = DEMSystem.from_state({k: v.copy() for k, v in st.items()})
    c.step(100)
    b.step(100)
    assert same(snapshot(a), snapshot(c))
    assert same(snapshot(a), snapshot(b))


def test_wall_candidates_hold_every_particle_near_a_wall():
    """The step adds wall contacts only for the candidates found after each list build (and
    after a restart): every particle within the skin of a side wall or the floor at the
    start of a step must be one of them, through rebuilds and a checkpoint."""
    W, H = 0.012, 0.04
    pos, vel, om = gas(150, W, H, seed=3, speed=3.0)
    s = make(pos, vel, W, H, dt=2e-6, g=9.81, om=om, bottom_wall=True)
    skin = 3e-4
    seen_near = 0
    for block in range(60):
        if block == 30:
            s = DEMSystem.from_state({k: v.copy() for k, v in s.state().items()})
        s.step(5)
        a, sc = s._arrays, s._scratch
        st = a["st"][a["ctl"][0]]
        x, y, r = st[:, 0], st[:, 1], st[:, 5]
        near = np.flatnonzero((x < r + skin) | (x > W - r - skin) | (y < r + skin))
        n_wall = int(sc["n_wall"][0])
        assert n_wall >= 0
        if a["ctl"][3]:  # C_REBUILD: the next step builds the lists and finds them anew
            continue
        assert set(near) <= set(sc["wall_ids"][:n_wall].tolist())
        seen_near += len(near)
    assert s.n_rebuilds > 5 and seen_near > 100


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2,
                    reason="NUMBA_NUM_THREADS=1 in the environment: a second thread cannot start")
def test_thread_count_does_not_change_results():
    n0 = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = dense_mix()
        a.step(300)
        ra = snapshot(a)
        numba.set_num_threads(2)
        b = dense_mix()
        b.serial_below = 0  # really use both threads on this small system
        b.step(300)
        assert same(ra, snapshot(b))
    finally:
        numba.set_num_threads(n0)


def test_pair_lists_are_consistent():
    """Every touching pair is listed exactly once (first member < second), each particle
    sees each of its pairs once (as first or second member), also after rebuilds and with
    polydisperse particles; springs live only on touching pairs."""
    rng = np.random.default_rng(2)
    for poly in (False, True):
        W, H = 0.02, 0.04
        sp = D - 1e-7  # a slightly compressed hexagonal block: contacts everywhere at once
        pos = np.array([[(0.5 + c + 0.5 * (r % 2)) * sp + 1e-4, (0.5 + r * 0.866) * sp]
                        for r in range(12) for c in range(19)])
        vel = rng.normal(0, 0.3, pos.shape)
        om = rng.normal(0, 300.0, len(pos))
        rad = rng.uniform(0.4998e-3, 0.5e-3, len(pos)) if poly else R
        s = make(pos, vel, W, H, dt=2e-6, g=9.81, om=om, radius=rad, bottom_wall=True)
        for n_steps, min_springs in ((5, 200), (1000, 1)):
            s.step(n_steps)
            st = s.state()
            x = st["internal_state"]
            pi, pj = st["internal_pair_first"], st["internal_pair_second"]
            springs = st["internal_springs"]
            assert np.all(pi < pj)
            pairs = set(zip(pi.tolist(), pj.tolist()))
            assert len(pairs) == len(pi)
            d = np.hypot(x[pj, 0] - x[pi, 0], x[pj, 1] - x[pi, 1])
            near = d < x[pi, 5] + x[pj, 5] + 1e-6  # springs are from the last force pass
            assert np.all(springs[~near] == 0)
            assert np.count_nonzero(np.any(springs != 0, axis=1)) >= min_springs
            # brute force: every touching pair is in the list
            dd = np.hypot(x[:, None, 0] - x[None, :, 0], x[:, None, 1] - x[None, :, 1])
            ii, jj = np.nonzero(np.triu(dd < x[:, None, 5] + x[None, :, 5], 1))
            assert set(zip(ii.tolist(), jj.tolist())) <= pairs
            # second-member lists point at the right pairs
            ls, lp = st["internal_second_start"], st["internal_second_pairs"]
            for k in range(len(x)):
                assert np.all(pj[lp[ls[k]:ls[k + 1]]] == k)
            assert ls[-1] == len(pi)
        assert s.n_rebuilds > 1


def test_list_drifting_with_the_particles_misses_no_contact():
    """A gas rising at 3 m/s as a whole: the list's frame drifts with it (builds are
    needed only for the particles' motion relative to each other, not for the 3 m/s that the
    usual rule would count), and every touching pair is listed at every step, across the
    periodic boundary too."""
    W, H = 0.02, 0.03
    n = 300
    pos, vel, om = gas(n, W, H, seed=11, speed=0.3)
    vel[:, 1] += 3.0
    dt = 2e-6
    s = make(pos, vel, W, H, dt=dt, om=om)
    skin = float(s.state()["skin"])
    steps = 600
    collisions = 0
    for _ in range(steps):
        s.step(1)
        st = s.state()
        x = st["internal_state"]
        pairs = set(zip(st["internal_pair_first"].tolist(), st["internal_pair_second"].tolist()))
        dx = x[:, None, 0] - x[None, :, 0]
        dy = x[:, None, 1] - x[None, :, 1]
        dy -= H * np.round(dy / H)
        ii, jj = np.nonzero(np.triu(np.hypot(dx, dy) < x[:, None, 5] + x[None, :, 5], 1))
        touching = set(zip(ii.tolist(), jj.tolist()))
        assert touching <= pairs
        collisions += len(touching)
    assert collisions > 50  # the particles do meet
    # the usual rule (each particle within skin/2 of where it was at the build) would have
    # built the list at least every skin/2 / (2.5 m/s dt) steps
    assert s.n_rebuilds < 0.5 * steps * 2.5 * dt / (0.5 * skin)


# ---------------------------------------------------------------- independent reference
def reference_run(pos, vel, om, rad, law, W, H, g, dt, nsteps):
    """Plain numpy/Python implementation of the same model (pair loop i < j, dict history)."""
    pos, vel, om = pos.copy(), vel.copy(), om.copy()
    n = len(pos)
    m = RHO * math.pi * (2 * rad) ** 3 / 6
    inertia = 0.1 * m * (2 * rad) ** 2
    hist, whist = {}, {}
    for _ in range(nsteps):
        f = np.zeros((n, 2))
        tq = np.zeros(n)
        for i in range(n):
            for j in range(i + 1, n):
                d = pos[j] - pos[i]
                d[1] -= H * round(d[1] / H)
                r = math.hypot(*d)
                if r >= rad[i] + rad[j]:
                    hist.pop((i, j), None)
                    continue
                nv = d / r
                mab = m[i] * m[j] / (m[i] + m[j])
                vr = vel[i] - vel[j] + (rad[i] * om[i] + rad[j] * om[j]) * np.array([-nv[1], nv[0]])
                vn = vr @ nv
                vt = vr - vn * nv
                fn = max(law.kn * (rad[i] + rad[j] - r) + law.normal_damping(mab) * vn, 0.0)
                h = hist.get((i, j), np.zeros(2)) + vt * dt
                h -= (h @ nv) * nv
                etat = law.tangential_damping(mab)
                ft = -law.kt * h - etat * vt
                if np.hypot(*ft) > law.mu * fn:
                    ft *= law.mu * fn / np.hypot(*ft)
                    h = -(ft + etat * vt) / law.kt
                hist[(i, j)] = h
                fi = ft - fn * nv
                f[i] += fi
                f[j] -= fi
                c = nv[0] * ft[1] - nv[1] * ft[0]
                tq[i] += rad[i] * c
                tq[j] += rad[j] * c
            for side, (delta, nvec) in enumerate(((rad[i] - pos[i, 0], (-1.0, 0.0)),
                                                  (pos[i, 0] + rad[i] - W, (1.0, 0.0)))):
                if delta <= 0:
                    whist.pop((i, side), None)
                    continue
                nv = np.array(nvec)
                vr = vel[i] + rad[i] * om[i] * np.array([-nv[1], nv[0]])
                vn = vr @ nv
                vt = vr[1]
                fn = max(law.kn * delta + law.normal_damping(m[i]) * vn, 0.0)
                h = whist.get((i, side), 0.0) + vt * dt
                etat = law.tangential_damping(m[i])
                ft = -law.kt * h - etat * vt
                if abs(ft) > law.mu * fn:
                    ft = math.copysign(law.mu * fn, ft)
                    h = -(ft + etat * vt) / law.kt
                whist[(i, side)] = h
                f[i] += [-fn * nv[0], ft]
                tq[i] += rad[i] * nv[0] * ft
        vel += dt * (f / m[:, None] - [0.0, g])
        om += dt * tq / inertia
        pos += dt * vel
        pos[:, 1] %= H
    return pos, vel, om


def test_matches_independent_reference():
    """Lists, cell reordering, spring carry-over, periodic images, walls and polydispersity
    against a straightforward O(N^2) implementation of the same equations."""
    W, H = 0.006, 0.005
    rng = np.random.default_rng(7)
    pos, vel, om = gas(14, W, H, seed=7, speed=1.5)
    rad = rng.uniform(0.42e-3, 0.5e-3, len(pos))
    s = make(pos, vel, W, H, dt=1e-6, g=9.81, om=om, radius=rad)
    s.step(400)
    rp, rv, ro = reference_run(pos, vel, om, rad, LAW, W, H, 9.81, 1e-6, 400)
    assert s.n_rebuilds >= 3
    dy = s.positions[:, 1] - rp[:, 1]
    dy -= H * np.round(dy / H)
    assert np.max(np.abs(s.positions[:, 0] - rp[:, 0])) < 1e-12
    assert np.max(np.abs(dy)) < 1e-12
    assert np.max(np.abs(s.velocities - rv)) < 1e-8
    assert np.max(np.abs(s.angular_velocities - ro)) < 1e-4


# ---------------------------------------------------------------- external force
def _rising_and_falling_columns(seed, W=0.02, H=0.02):
    """Ten columns 2 mm apart (D = 1 mm) in a shuffled caller's order: the left five rise,
    the right five fall, and no two particles ever touch, while their relative motion
    makes the list be built again."""
    cx, cy = np.meshgrid(0.001 + 0.002 * np.arange(10), 0.001 + 0.002 * np.arange(10))
    pos = np.column_stack([cx.ravel(), cy.ravel()])
    pos = pos[np.random.default_rng(seed).permutation(100)]
    vel = np.column_stack([np.zeros(100), np.where(pos[:, 0] < W / 2, 4.0, -4.0)])
    return pos, vel, make(pos, vel, W, H, dt=2e-6, om=np.zeros(100))


def test_external_force_in_callers_order_through_rebuilds():
    pos, vel, s = _rising_and_falling_columns(4)
    f = np.random.default_rng(1).uniform(-1, 1, (100, 2)) * 1e-6  # ~0.7 m/s^2
    s.step(500, external_force=f)
    assert s.n_rebuilds > 5 and not np.array_equal(s.order, np.arange(100))
    dv = s.velocities - vel
    assert np.allclose(dv, f / M * 500 * 2e-6, rtol=1e-9, atol=1e-12)
    s.step(10)  # no force now
    assert np.allclose(s.velocities - vel, f / M * 500 * 2e-6, rtol=1e-9, atol=1e-12)


def test_positions_in_callers_order_after_every_list_build():
    """The caller's order is kept by an index remade after each list build: read between
    builds and right after them, positions and velocities are those of each caller's
    particle (free flight: x unchanged, y wrapped)."""
    H = 0.02
    pos, vel, s = _rising_and_falling_columns(5, H=H)
    builds = set()
    for k in range(1, 60):
        s.step(7)
        builds.add(s.n_rebuilds)
        p = s.positions
        assert np.array_equal(p[:, 0], pos[:, 0])
        expected = np.mod(pos[:, 1] + vel[:, 1] * 7 * k * 2e-6, H)
        gap = np.abs(p[:, 1] - expected)
        assert np.all(np.minimum(gap, H - gap) < 1e-12)
        assert np.array_equal(s.velocities, vel)
    assert len(builds) > 10 and not np.array_equal(s.order, np.arange(100))


def test_gravity_free_fall():
    s = make([[0.005, 0.015]], [[0.0, 0.0]], H=0.02, dt=2e-6, g=9.81)
    s.step(100)
    # leapfrog: v_{n-1/2} = -g n dt, y_n = y0 - g dt^2 n(n+1)/2
    assert s.velocities[0, 1] == pytest.approx(-9.81 * 2e-4, rel=1e-12)
    assert s.positions[0, 1] == pytest.approx(0.015 - 9.81 * 4e-12 * 100 * 101 / 2, rel=1e-12)


# ---------------------------------------------------------------- safety
def test_steps_per_contact_checks():
    with pytest.warns(UserWarning, match=r"5\.18 steps"):
        DEMSystem([[0.005, 0.005]], [[0, 0]], R, RHO, LAW, 0.01, 0.02, time_step=5e-6,
                  search_cells=None)
    with pytest.raises(InputError, match=r"4\.32 steps .* at least 5"):
        DEMSystem([[0.005, 0.005]], [[0, 0]], R, RHO, LAW, 0.01, 0.02, time_step=6e-6,
                  search_cells=None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        DEMSystem([[0.005, 0.005]], [[0, 0]], R, RHO, LAW, 0.01, 0.02, time_step=2e-6,
                  search_cells=None)


def test_bad_input():
    with pytest.raises(InputError, match="search cells"):
        make([[0.005, 0.005]], [[0, 0]], cells=(30, 351))  # 0.33 mm cells in a 1 cm box
    with pytest.raises(InputError, match="outside the walls"):
        make([[0.02, 0.005]], [[0, 0]])
    with pytest.raises(InputError):
        make([[0.005, 0.005]], [[np.nan, 0]])
    s = make([[0.005, 0.005]], [[0, 0]])
    with pytest.raises(InputError, match="external_force"):
        s.step(1, external_force=np.zeros((2, 2)))


def test_blow_up_is_reported():
    s = make([[0.003, 0.005], [0.007, 0.01]], [[0, 0], [-2000.0, 0]], dt=1e-6)
    with pytest.raises(SimulationBlowUp, match=r"step \d+ .*particle 1") as exc:
        s.step(100)
    assert isinstance(exc.value, CfbmarkovError) and exc.value.particle == 1
    s = make([[0.005, 0.005], [0.005, 0.0058]], [[0, 0], [0, 0]])  # 20 % overlap
    with pytest.raises(SimulationBlowUp, match=r"step 0 .*overlaps") as exc:
        s.step(1)
    assert exc.value.step == 0
    assert "Reduce the time step" in str(exc.value) and "soft" not in str(exc.value)
    # contacts too soft, not a step too long: the message names the stiffness
    soft = ContactLaw(kn=2.0, kt=0.57)
    s = make([[0.005, 0.005], [0.005, 0.0058]], [[0, 0], [0, 0]], law=soft)
    with pytest.raises(SimulationBlowUp, match=r"overlaps") as exc:
        s.step(1)
    assert "contact.normal_stiffness 2 N/m lets a collision at 1 m/s overlap by" in str(exc.value)


def test_settled_bed_is_stable():
    """A bed poured between the walls onto a floor (``bottom_wall``: without gas nothing else
    carries it) settles and stays put at the paper's time step and contact law."""
    W, H = 0.015, 0.1
    n = 200
    pos, vel, om = gas(n, W, 0.02, seed=9, speed=0.1)
    s = make(pos, vel, W, H, dt=5e-6, g=9.81, om=om, bottom_wall=True)
    s.step(40000)  # 0.2 s
    ov = s.overlaps()
    y = s.positions[:, 1]
    ke = s.kinetic_energy() / (n * M)
    print(f"bed: top {y.max() * 1e3:.2f} mm, max overlap {ov.max() / D:.2%} of d, "
          f"{ov.size} contacts, KE/m {ke:.2e} m^2/s^2")
    assert ov.max() < 0.1 * D and ov.max() < 0.01 * D
    assert ke < 1e-5
    top = y.max()
    s.step(5000)
    assert abs(s.positions[:, 1].max() - top) < 0.05 * D
    assert s.overlaps().max() < 0.01 * D


# ---------------------------------------------------------------- wall forces (diagnostics)
@pytest.mark.parametrize("push, sticking", [(10.0, True), (0.5, False)])
def test_wall_impulse_of_friction_sticking_and_sliding(push, sticking):
    """A particle pressed against the left wall by an external force F (x, in units of its
    weight) under gravity rolls down the wall. Rolling without slip needs a friction force
    of m g I / (I + m R^2) = 2/7 m g (a sphere's inertia): when mu F exceeds it the wall's
    vertical impulse is that; when mu F is smaller the particle slides and the wall carries
    mu F (Coulomb)."""
    g = 9.81
    law = ContactLaw()                                   # mu = 0.1
    s = make([[R, 0.01]], [[0.0, 0.0]], W=0.01, H=0.02, dt=1e-6, g=g, law=law)
    force = np.array([[-push * M * g, 0.0]])
    s.step(20000, external_force=force)                   # settle the contact (20 ms)
    s.reset_wall_impulse()
    v0 = s.velocities[0, 1]
    steps = 20000
    s.step(steps, external_force=force)
    t = steps * 1e-6
    side, floor = s.wall_impulse
    assert floor == 0.0
    expected = 2.0 / 7.0 * M * g if sticking else law.mu * push * M * g
    assert side == pytest.approx(expected * t, rel=0.02)
    # the particle's momentum change closes the balance: wall + gravity
    assert M * (s.velocities[0, 1] - v0) == pytest.approx(side - M * g * t, abs=0.02 * M * g * t)


def test_floor_carries_a_settled_column():
    """Particles resting on the floor: the floor's impulse equals their weight's."""
    g = 9.81
    pos = np.array([[0.005, R * (1 + 2 * k) * 1.001] for k in range(5)])
    s = make(pos, np.zeros_like(pos), W=0.01, H=0.02, dt=1e-6, g=g, bottom_wall=True)
    s.step(60000)
    s.reset_wall_impulse()
    s.step(20000)
    side, floor = s.wall_impulse
    assert floor == pytest.approx(5 * M * g * 0.02, rel=0.01)
    assert abs(side) < 1e-3 * floor
