"""Single-contact verification of the DEM contact law (head-on and oblique impacts)."""

import math
import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import cfbmarkov  # noqa: F401
from cfbmarkov.simulate.dem import ContactLaw, DEMSystem

D, RHO = 1e-3, 2600.0
R = D / 2
M = RHO * math.pi * D**3 / 6
INERTIA = M * D**2 / 10
LAW = ContactLaw()  # the paper's Table 2 values
W, H = 0.01, 0.02


def _system(pos, vel, dt, law=LAW, om=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return DEMSystem(np.array(pos, float), np.array(vel, float), R, RHO, law, W, H,
                         gravity=0.0, time_step=dt, search_cells=None, skin=3e-4,
                         angular_velocities=om)


def _crossings(times, gaps):
    """Times where the piecewise-linear gap(t) crosses zero: (first down, last up)."""
    t_in = t_out = None
    for k in range(1, len(gaps)):
        g0, g1 = gaps[k - 1], gaps[k]
        if g0 >= 0 > g1 and t_in is None:
            t_in = times[k - 1] + (times[k] - times[k - 1]) * g0 / (g0 - g1)
        if g0 < 0 <= g1:
            t_out = times[k - 1] + (times[k] - times[k - 1]) * (-g0) / (g1 - g0)
    return t_in, t_out


def head_on(kind, dt, gap, v=1.0, law=LAW):
    """Run one head-on impact; returns (restitution, contact duration)."""
    if kind == "pp":
        s = _system([[W / 2, 0.008], [W / 2, 0.008 + D + gap]], [[0, v / 2], [0, -v / 2]], dt, law)

        def gap_of(p):
            return p[1, 1] - p[0, 1] - D
    else:
        s = _system([[R + gap, 0.008]], [[-v, 0]], dt, law)

        def gap_of(p):
            return p[0, 0] - R
    times, gaps = [s.time], [gap_of(s.positions)]
    n_max = int(3 * (gap / v + 2 * s.contact_time().particle_wall) / dt) + 10
    for _ in range(n_max):
        s.step(1)
        times.append(s.time)
        gaps.append(gap_of(s.positions))
        if gaps[-1] > 0 and min(gaps) < 0:
            break
    t_in, t_out = _crossings(times, gaps)
    vel = s.velocities
    vrel = vel[1, 1] - vel[0, 1] if kind == "pp" else vel[0, 0]
    return vrel / v, t_out - t_in


def analytic_contact_time(m_ab, law=LAW):
    k = law.kn
    eta = law.normal_damping(m_ab)
    return math.pi / math.sqrt(k / m_ab - (eta / (2 * m_ab)) ** 2)


@pytest.mark.slow
@pytest.mark.parametrize("kind,m_ab", [("pp", M / 2), ("pw", M)])
def test_head_on_fine_step(kind, m_ab):
    tc = analytic_contact_time(m_ab)
    dt = tc / 50
    for frac in (0.0, 0.37, 0.71):  # where the first touch falls between steps
        e, t_c = head_on(kind, dt, gap=(10 + frac) * dt * 1.0)
        print(f"{kind}: dt = tc/50, phase {frac}: e = {e:.5f} (en {LAW.en}), "
              f"t_c = {t_c:.5e} s (analytic {tc:.5e}, {100 * (t_c / tc - 1):+.2f} %)")
        assert abs(e / LAW.en - 1) < 0.01
        assert abs(t_c / tc - 1) < 0.02


def test_contact_time_api():
    s = _system([[W / 2, 0.008]], [[0, 0]], 1e-7)
    pp, pw = s.contact_time()
    assert pp == pytest.approx(analytic_contact_time(M / 2), rel=1e-12)
    assert pw == pytest.approx(analytic_contact_time(M), rel=1e-12)
    assert s.steps_per_contact().particle_particle == pytest.approx(pp / 1e-7)
    # the paper's values: about 5.2 and 7.3 steps at 5e-6 s
    assert pp / 5e-6 == pytest.approx(5.2, abs=0.05)
    assert pw / 5e-6 == pytest.approx(7.3, abs=0.05)


@pytest.mark.parametrize("kind", ["pp", "pw"])
def test_head_on_paper_step(kind):
    """At the paper's step (~5.2 / 7.3 steps per contact) e depends on where the contact
    falls between steps; reported, and only loosely bounded."""
    es = [head_on(kind, 5e-6, gap=(10 + f) * 5e-6)[0] for f in np.linspace(0, 1, 11)[:-1]]
    print(f"{kind} at dt = 5e-6 s: e from {min(es):.4f} to {max(es):.4f}, mean {np.mean(es):.4f}")
    assert 0.94 < min(es) and max(es) < 1.0


# ---------------------------------------------------------------- oblique impacts on a wall
def oblique_reference(vn0, vt0, law=LAW, m=M, r=R, inertia=INERTIA):
    """Continuous-time linear spring-dashpot impact of a sphere on a wall, with the tangential
    spring, the Coulomb cap and the LAMMPS reset rule written as a stick/slip hybrid ODE and
    integrated by scipy's DOP853. Returns the rebound (v_n, v_t, omega) after the normal force
    has dropped to zero (the motion is force-free from then on)."""
    kn, kt, mu = law.kn, law.kt, law.mu
    etan, etat = law.normal_damping(m), law.tangential_damping(m)
    inv_mt = 1 / m + r * r / inertia  # contact-point tangential mobility

    def fn_of(y):
        return kn * y[0] + etan * y[1]

    def forces(y, mode, s):
        fn = max(fn_of(y), 0.0)
        u = y[2] - r * y[3]
        ft = -(kt * y[4] + etat * u) if mode == "stick" else mu * fn * s
        return fn, u, ft

    def rhs(t, y, mode, s):  # y = [delta, v_n (approach), v_t, omega, xi]
        fn, u, ft = forces(y, mode, s)
        return [y[1], -fn / m, ft / m, -r * ft / inertia, u if mode == "stick" else 0.0]

    def slip_rate(y, s):
        """Rate of the unconstrained trial force (toward the cap) minus the cap's rate."""
        fn, u, ft = forces(y, "slip", s)
        du = ft * inv_mt
        dfn = kn * y[1] - etan * fn / m
        return s * (-(kt * u + etat * du)) - mu * dfn

    y = np.array([0.0, vn0, vt0, 0.0, 0.0])
    t = 0.0
    u0 = vt0
    if etat * abs(u0) > mu * etan * vn0:
        mode, s = "slip", -math.copysign(1.0, u0)
    else:
        mode, s = "stick", 0.0
    atol = np.array([1e-17, 1e-14, 1e-14, 1e-11, 1e-17]) * max(vn0, 1e-3)
    for _ in range(100):
        if mode == "slip" and slip_rate(y, s) < 0:
            fn, u, _ = forces(y, "slip", s)
            y[4] = -(mu * fn * s + etat * u) / kt
            mode = "stick"
        ev_end = lambda t, y, *a: fn_of(y)  # noqa: E731
        ev_end.terminal, ev_end.direction = True, -1
        if mode == "stick":
            def ev_switch(t, y, *a):
                fn, u, _ = forces(y, "stick", 0.0)
                return mu * fn - abs(kt * y[4] + etat * u)
        else:
            def ev_switch(t, y, mode_, s_):
                return slip_rate(y, s_)
        ev_switch.terminal, ev_switch.direction = True, -1
        sol = solve_ivp(rhs, (t, t + 1e-3), y, method="DOP853", rtol=1e-12, atol=atol,
                        events=[ev_end, ev_switch], args=(mode, s))
        t, y = sol.t[-1], sol.y[:, -1].copy()
        if sol.t_events[0].size:
            return y[1], y[2], y[3]
        if not sol.t_events[1].size:
            raise RuntimeError("reference integration did not end the contact")
        if mode == "stick":
            fn, u, _ = forces(y, "stick", 0.0)
            s = math.copysign(1.0, -(kt * y[4] + etat * u))
            mode = "slip"
        else:
            fn, u, _ = forces(y, "slip", s)
            y[4] = -(mu * fn * s + etat * u) / kt
            mode = "stick"
            # step a hair into the stick phase so the switch event does not fire at once
    raise RuntimeError("too many stick/slip switches")


def dem_oblique(vn0, vt0, dt, law=LAW):
    gap = 5.3 * dt * vn0
    s = _system([[R + gap, 0.01]], [[-vn0, vt0]], dt, law)
    n = int((gap / vn0 + 3 * s.contact_time().particle_wall) / dt) + 20
    s.step(n)
    assert s.positions[0, 0] > R  # left the wall
    v = s.velocities[0]
    return -v[0], v[1], s.angular_velocities[0]


ANGLES = [2, 5, 10, 15, 20, 25, 30, 40, 50, 60, 70, 80]


def test_oblique_wall_impacts():
    """Rebound tangential velocity and spin vs incidence angle (Chung & Ooi 2011 tests 6/7
    with the linear model). Reference: the stick/slip ODE above for every angle and, where
    the contact slides throughout (large angles), the analytic impulse ratio mu(1+e).

    Tolerance: 0.1 % of the impact speed for v_t and R*omega (and 1e-3 for e). At 200 steps
    per contact the first-order errors of the discrete stick/slip switches are a small
    fraction of dt/t_c = 0.5 % of the tangential impulse (measured: at most 1.6e-4 of the
    speed, at the smallest angles where stick/slip switches matter most); 0.1 % leaves room
    for that but is far below the differences the tested effects make (sticking reverses the
    contact-point velocity, and the spin differs from the sliding value by up to 40 % of the
    speed)."""
    speed = 1.0
    dt = analytic_contact_time(M) / 200
    worst = 0.0
    rows = []
    for ang in ANGLES:
        th = math.radians(ang)
        vn0, vt0 = speed * math.cos(th), speed * math.sin(th)
        vn_d, vt_d, w_d = dem_oblique(vn0, vt0, dt)
        vn_r, vt_r, w_r = oblique_reference(vn0, vt0)
        err_t = abs(vt_d - vt_r) / speed
        err_w = abs(R * (w_d - w_r)) / speed
        worst = max(worst, err_t, err_w)
        rows.append((ang, vt_d, vt_r, R * w_d, R * w_r, err_t, err_w))
        assert abs(-vn_d / vn0 - (-vn_r / vn0)) < 1e-3
        assert err_t < 1e-3 and err_w < 1e-3, rows[-1]
        if math.tan(th) > 3.5 * LAW.mu * (1 + LAW.en) * 1.2:  # sliding throughout
            e = -vn_d / vn0
            jt = LAW.mu * (1 + e) * vn0
            assert abs(vt_d - (vt0 - jt)) / speed < 0.01
            assert abs(R * w_d - 2.5 * jt) / speed < 0.01
            jt_r = LAW.mu * (1 - vn_r / vn0) * vn0
            assert abs(vt_r - (vt0 - jt_r)) / speed < 1e-7  # the ODE agrees with the analytics
    for row in rows:
        print("angle %2d: vt %.5f (ref %.5f)  R*w %.5f (ref %.5f)  err %.1e %.1e" % row)
    print(f"worst error {worst:.2e} of the impact speed")


# ---------------------------------------------------------------- the two pair kernels
def _pair_problem(mono, periodic):
    """Pairs (2k, 2k + 1) at 0.9-1.1 times their contact distance, about half of them in
    contact, some sliding, some across the periodic boundary; more than two blocks of
    pairs, not a whole number of blocks."""
    from cfbmarkov.simulate.dem.contact import SIMD_BLOCK
    from cfbmarkov.simulate.dem.layout import DEMParams

    rng = np.random.default_rng(11)
    npairs = 2 * SIMD_BLOCK + 37
    n = 2 * npairs
    Hd = 0.05
    st = np.zeros((n, 8))
    rad = np.full(n, R) if mono else rng.uniform(0.8 * R, R, n)
    st[0::2, 0] = rng.uniform(0.0, 0.01, npairs)
    st[0::2, 1] = rng.uniform(0.0, Hd, npairs)
    # partners at 0.9-1.1 times the contact distance: about half of the pairs in contact
    ang = rng.uniform(0.0, 2 * math.pi, npairs)
    dist = rng.uniform(0.9, 1.1, npairs) * (rad[0::2] + rad[1::2])
    st[1::2, 0] = st[0::2, 0] + dist * np.cos(ang)
    st[1::2, 1] = st[0::2, 1] + dist * np.sin(ang)
    if periodic:
        st[:40, 1] = rng.uniform(0.0, 2e-4, 40)  # pairs across the top/bottom
        st[1:40:2, 1] = (st[0:40:2, 1] - 0.6e-3) % Hd
    st[:, 2:4] = rng.normal(0.0, 0.5, (n, 2))
    st[:, 4] = rng.normal(0.0, 0.05, n)
    st[:, 5] = rad
    mass = RHO * math.pi * (2 * rad) ** 3 / 6
    st[:, 6] = 1.0 / mass
    st[:, 7] = rad / (mass * (2 * rad) ** 2 / 10)
    pi = np.arange(0, n, 2, dtype=np.int32)
    pj = np.arange(1, n, 2, dtype=np.int32)
    springs = rng.normal(0.0, 2e-5, (npairs, 2))  # large ones slide (Coulomb cap)
    springs[::7] = 0.0
    springs[3::11, 1] = -0.0
    prm = DEMParams(
        dt=5e-6, width=0.01, height=Hd, gravity=0.0, kn=LAW.kn, kt=LAW.kt, inv_kt=1.0 / LAW.kt,
        mu=LAW.mu, etan_pp=LAW.normal_damping_factor * math.sqrt(M / 2),
        etat_pp=LAW.tangential_damping_factor * math.sqrt(M / 2), etan_pw=0.0, etat_pw=0.0,
        cn=LAW.normal_damping_factor, ct=LAW.tangential_damping_factor, skin=3e-4,
        cell_w=1.0, cell_h=1.0, rmax=R, max_overlap=0.05, t0=0.0, ncx=1, ncy=1,
        periodic=periodic, floor=not periodic, mono=mono)
    return st, npairs, pi, pj, springs, prm


@pytest.mark.parametrize("mono, periodic", [(True, True), (False, True), (True, False)])
def test_simd_pair_kernel_writes_the_same_bits(mono, periodic):
    """pair_forces_simd (the step's kernel where most listed pairs touch) and pair_forces
    (the branching one) give the same forces, springs, contact and blow-up counts, bit for
    bit (signs of zero included), over pairs in and out of contact, sticking and sliding,
    across the periodic boundary, equal and unequal particles, with a list longer than one
    SIMD block and not a multiple of it."""
    from cfbmarkov.simulate.dem.contact import (CONTACT_BLOCK, pair_forces,
                                                pair_forces_simd)

    st, npairs, pi, pj, springs, prm = _pair_problem(mono, periodic)
    contact_ids = np.full(npairs, -1, np.int64)
    block_contacts = np.full(npairs // CONTACT_BLOCK + 1, -1, np.int64)
    out = []
    for kernel in (pair_forces, pair_forces_simd):
        sp = springs.copy()
        pf = np.full((npairs, 3), np.nan)
        lists = (contact_ids, block_contacts) if kernel is pair_forces else ()
        counts = kernel(st, npairs, pi, pj, sp, pf, prm, *lists)
        out.append((counts, pf.view(np.uint64), sp.view(np.uint64)))
    (c_a, pf_a, sp_a), (c_b, pf_b, sp_b) = out
    assert c_a == c_b
    nbad, ncontacts = c_a
    assert 0.3 * npairs < ncontacts < 0.7 * npairs and nbad > 0
    capped = np.hypot(*springs.T) > 5e-6
    assert np.count_nonzero(capped) > 50
    assert np.array_equal(pf_a, pf_b)
    assert np.array_equal(sp_a, sp_b)
    assert not np.signbit(sp_a.view(np.float64)[np.all(pf_a.view(np.float64) == 0.0, axis=1)]).any()
    # pair_forces listed exactly the pairs in contact, block by block in pair order
    d = st[pj, :2] - st[pi, :2]
    if periodic:
        d[:, 1] -= prm.height * np.round(d[:, 1] / prm.height)
    touching = np.flatnonzero(np.hypot(*d.T) < st[pi, 5] + st[pj, 5])
    blocks = -(-npairs // CONTACT_BLOCK)
    listed = np.concatenate([contact_ids[b * CONTACT_BLOCK:b * CONTACT_BLOCK + block_contacts[b]]
                             for b in range(blocks)])
    np.testing.assert_array_equal(listed, touching)
    assert block_contacts[:blocks].sum() == ncontacts


@pytest.mark.parametrize("mono, periodic", [(True, True), (False, True)])
def test_summing_only_the_touched_particles_moves_them_by_the_same_bits(mono, periodic):
    """A dilute step sums the pair forces of the particles in a contact only (the members
    of the pairs that pair_forces listed) and moves every other particle by its external
    force: every particle ends the step with the bits of the step that sums all pairs,
    walls included."""
    from cfbmarkov.simulate.dem.contact import CONTACT_BLOCK, pair_forces
    from cfbmarkov.simulate.dem.integrate import (move, sum_pairs, sum_touched_pairs,
                                                  touched_particles, wall_contacts)

    st, npairs, pi, pj, springs, prm = _pair_problem(mono, periodic)
    n = st.shape[0]
    rng = np.random.default_rng(5)
    st[::5, 0] = rng.uniform(0.0, 0.5 * R, st[::5, 0].size)      # some at the left wall
    aux = np.zeros((n, 4))
    aux[:, :2] = st[:, :2]
    aux[:, 2:] = rng.normal(0.0, 1e-6, (n, 2))                    # external forces (N)
    pf = np.zeros((npairs, 3))
    contact_ids = np.zeros(npairs, np.int64)
    block_contacts = np.zeros(npairs // CONTACT_BLOCK + 1, np.int64)
    pair_forces(st, npairs, pi, pj, springs.copy(), pf, prm, contact_ids, block_contacts)
    # particle 2k is the first member of pair k, 2k + 1 the second
    pstart = np.zeros(n + 1, np.int64)
    pstart[1::2] = np.arange(npairs)
    pstart[2::2] = np.arange(1, npairs + 1)
    lowstart = np.zeros(n + 1, np.int64)
    lowstart[2::2] = np.arange(1, npairs + 1)
    lowstart[1::2] = np.arange(npairs)
    lowpid = np.arange(npairs, dtype=np.int64)
    wall_ids = np.arange(n, dtype=np.int64)
    results = []
    for summed in (True, False):
        fsum = np.full((n, 3), np.nan)
        touched = np.full(n, -1, np.int64)
        touched_ids = np.zeros(n, np.int64)
        stamp = 7
        if summed:
            sum_pairs(st, aux, pstart, lowstart, lowpid, pf, fsum)
        else:
            k = touched_particles(npairs, pi, pj, contact_ids, block_contacts, touched, stamp,
                                  touched_ids)
            assert 0 < k < n
            sum_touched_pairs(st, aux, pstart, lowstart, lowpid, pf, fsum, touched_ids, k)
        wh = np.zeros((n, 3))
        walls = wall_contacts(st, wh, aux, fsum, np.zeros(n, np.int8), wall_ids, n, touched,
                              stamp, summed, prm)
        so = np.zeros_like(st)
        moved = move(st, so, aux, np.zeros(n, np.int64), fsum,
                     touched, stamp, summed, np.zeros(n, np.int8), np.zeros(n, np.int8), 0.0,
                     prm)
        results.append((so.view(np.uint64), wh.view(np.uint64), walls, moved))
    (so_a, wh_a, walls_a, moved_a), (so_b, wh_b, walls_b, moved_b) = results
    assert walls_a[1] != 0.0 or walls_a[2] != 0.0                 # a wall touched someone
    np.testing.assert_array_equal(so_a, so_b)
    np.testing.assert_array_equal(wh_a, wh_b)
    assert walls_a == walls_b and moved_a == moved_b


def test_a_tangential_spring_stiffer_than_two_sevenths_kn_sets_the_step_check():
    """The tangential spring (effective mass 2/7 m_ab, its dashpot) oscillates with the
    half-period pi / omega_d that an integrated damped oscillator crosses zero at; with
    kt = kn it is about half the normal contact, and a step that resolves the normal
    contact in 12 steps resolves it in fewer than 10: the check says so (with the default
    kt = 2/7 kn the normal contact stays the shorter, the message unchanged)."""
    from cfbmarkov.simulate.dem.law import contact_resolution

    stiff = ContactLaw(kn=LAW.kn, kt=LAW.kn, en=LAW.en, et=LAW.et, mu=LAW.mu, mass=M)
    m_ab = M / 2
    m_t, eta = 2 / 7 * m_ab, stiff.tangential_damping(m_ab)
    crossing = lambda t, y: y[0]                       # noqa: E731
    crossing.terminal, crossing.direction = True, -1
    solution = solve_ivp(lambda t, y: [y[1], -(stiff.kt * y[0] + eta * y[1]) / m_t],
                         (0, 1.0), [0.0, 1.0], events=crossing, rtol=1e-11, atol=1e-14,
                         max_step=stiff.tangential_time(m_ab) / 200)
    assert solution.t_events[0][0] == pytest.approx(stiff.tangential_time(m_ab), rel=1e-6)
    dt = stiff.contact_times(M)[0] / 12                # the normal contact in 12 steps
    worst, message = contact_resolution(stiff, M, dt)
    assert worst < 10 and worst == pytest.approx(stiff.tangential_time(m_ab) / dt)
    assert "12.00 steps (particle-particle" in message
    assert "tangential spring's half-period in" in message
    plain = ContactLaw(kn=LAW.kn, kt=2 / 7 * LAW.kn * 0.999, en=LAW.en, et=LAW.et, mu=LAW.mu,
                       mass=M)
    worst, message = contact_resolution(plain, M, dt)
    assert worst == pytest.approx(min(plain.contact_times(M)) / dt)
    assert "tangential" not in message
