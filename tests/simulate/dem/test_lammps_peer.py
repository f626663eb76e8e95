"""The LAMMPS peer: the problem files it is given, and (where LAMMPS is installed) that it
and our DEM compute the same collisions."""

import math
import warnings

import numpy as np
import pytest

from cfbmarkov.simulate.dem import ContactLaw, DEMSystem
from cfbmarkov.simulate.dem import lammps as peer

D, RHO = 1e-3, 2600.0
MASS = RHO * math.pi * D**3 / 6


def test_contact_law_translates_to_lammps_damping():
    """LAMMPS's damping force is m_eff * gamma * v; ours eta(m_eff) * v: equal for a pair."""
    law = ContactLaw()
    kn, kt, gn, gt, mu = peer.lammps_parameters(law, MASS)
    m_eff = MASS / 2
    assert (kn, kt, mu) == (law.kn, law.kt, law.mu)
    assert m_eff * gn == pytest.approx(law.normal_damping(m_eff), rel=1e-14)
    assert m_eff * gt == pytest.approx(law.tangential_damping(m_eff), rel=1e-14)
    assert gn > 0 and gt > 0


def test_problem_files_hold_the_particles_exactly(tmp_path):
    rng = np.random.default_rng(3)
    pos = np.column_stack([rng.uniform(0.001, 0.089, 7), rng.uniform(0, 0.95, 7)])
    vel = rng.normal(size=(7, 2))
    spin = rng.normal(size=7)
    script = peer.write_problem(tmp_path, pos, vel, spin, D / 2, RHO, ContactLaw(), 0.09, 0.95,
                                5e-6, 3e-4, 9.81, True, 10, 100, 3)
    text = script.read_text()
    assert "boundary f f p" in text and "yplane 0.0 NULL" in text and "gravity" in text
    assert text.count("run 100") == 3 and "run 10" in text
    lines = (tmp_path / "problem.data").read_text().splitlines()
    atoms = np.array([row.split() for row in lines[lines.index("Atoms # sphere") + 2:][:7]],
                     dtype=float)
    np.testing.assert_array_equal(atoms[:, 4:6], pos)         # exact round trip
    np.testing.assert_array_equal(atoms[:, 2:4], [[D, RHO]] * 7)
    start = lines.index("Velocities") + 2
    vels = np.array([row.split() for row in lines[start:start + 7]], dtype=float)
    np.testing.assert_array_equal(vels[:, 1:3], vel)
    np.testing.assert_array_equal(vels[:, 6], spin)


def test_missing_lammps_is_not_found(monkeypatch, tmp_path):
    monkeypatch.setenv("CFBMARKOV_LAMMPS", str(tmp_path / "no-such-lmp"))
    assert peer.find_lammps() is None
    with pytest.raises(RuntimeError, match="LAMMPS not found"):
        peer.lammps_throughput("dilute", 10)


@pytest.mark.skipif(peer.find_lammps() is None, reason="LAMMPS is not installed")
def test_same_collisions_as_lammps():
    """Two head-on pairs and two oblique pairs (one nearly head-on with spin, one sliding at
    the Coulomb cap), run 300 steps in LAMMPS gran/hooke/history and in our DEM from the same
    state: the collisions are over by then, and positions, velocities and spins agree to
    round-off (the same law, and leapfrog is the sequence velocity Verlet produces).
    Measured with LAMMPS 2025.7.22 (PyPI): 5e-15 m, 4e-12 m/s, 3e-9 rad/s; with mu = 0.2 in
    our law instead the sliding pair differs by 0.11 m/s."""
    pos = np.array([[0.020, 0.300], [0.0212, 0.300],            # head-on
                    [0.050, 0.300], [0.0512, 0.3003],           # oblique, sticking
                    [0.020, 0.600], [0.0215, 0.6007],           # oblique, sliding
                    [0.060, 0.600], [0.0614, 0.600]])           # head-on, unequal speeds
    vel = np.array([[1.0, 0.0], [-1.0, 0.0], [0.5, 0.1], [-0.5, 0.0],
                    [2.0, 0.0], [-1.0, 0.0], [0.3, 0.0], [-2.0, 0.0]])
    spin = np.array([0.0, 0.0, 50.0, -20.0, 0.0, 300.0, 0.0, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ours = DEMSystem(pos, vel, D / 2, RHO, ContactLaw(), 0.09, 0.95, gravity=0.0,
                         time_step=5e-6, angular_velocities=spin)
    ours.step(300)
    theirs = peer.lammps_final_state(pos, vel, spin, 300)
    assert np.all(np.abs(ours.velocities - vel).max(axis=1) > 0.05)   # all collided
    assert abs(ours.angular_velocities[4]) > 100.0              # the oblique one spins
    np.testing.assert_allclose(ours.positions, theirs["positions"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours.velocities, theirs["velocities"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours.angular_velocities, theirs["angular_velocities"],
                               rtol=0, atol=1e-6)


def test_bench_lines_beside_ours(monkeypatch, capsys):
    """`cfbmarkov bench` adds LAMMPS's rate and our ratio where LAMMPS runs, and nothing
    (with a warning if it fails) elsewhere."""
    from cfbmarkov.simulate import bench

    monkeypatch.setattr(peer, "find_lammps", lambda: None)
    assert list(bench._lammps_lines("dem-throughput", "dilute", 9e7, 100, 1)) == []
    monkeypatch.setattr(peer, "find_lammps", lambda: "lmp")
    monkeypatch.setattr(peer, "lammps_throughput", lambda *a, **k: (4.5e7, 2))
    lines = list(bench._lammps_lines("dem-throughput", "dilute", 9e7, 100, 1))
    assert lines == [("dem-throughput-lammps-2ranks", 4.5e7, "particle-steps/s"),
                     ("dem-throughput-over-lammps", 2.0, "x")]

    def broken(*args, **kwargs):
        raise RuntimeError("LAMMPS failed (exit 1): ERROR: Unrecognized pair style")

    monkeypatch.setattr(peer, "lammps_throughput", broken)
    assert list(bench._lammps_lines("dem-throughput", "dilute", 9e7, 100, 1)) == []
    assert "Unrecognized pair style" in capsys.readouterr().err
