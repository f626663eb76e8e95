"""Trajectory store version 2: 3D positions, axes and region, the vertical boundary, the
presence mask (particles absent from frames), particles added after the first frame, version-1
files still read, and what the periodic 2D pipeline refuses in one line."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import VERSION, lap_increments
from cfbmarkov.trajectory_info import describe
from cfbmarkov.trajectory_writer import TrajectoryWriter, write_trajectories

W, H = 0.09, 0.95


def test_3d_positions_axes_region_and_boundary_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    pos = rng.uniform([0, 0, 0], [W, H, 0.01], size=(4, 3, 3))
    path = write_trajectories(tmp_path / "d.h5", np.arange(4) * 0.01, pos, width=W, height=H,
                              depth=0.01, boundary="open",
                              axes={"across": "x", "vertical": "z", "depth": "y"},
                              region_origin=[-0.045, 0.0, -0.005])
    with Trajectories(path) as t:
        assert (t.version, t.dimensions, t.depth, t.boundary) == (VERSION, 3, 0.01, "open")
        assert t.axes == {"across": "x", "vertical": "z", "depth": "y"}
        np.testing.assert_array_equal(t.region_origin, [-0.045, 0.0, -0.005])
        np.testing.assert_array_equal(t.positions(), pos)
        assert not t.has_absences and t.present().all()
        assert t.laps().max() == 0                       # open: no laps
        assert t.unsupported() == ["3D positions", "an open riser (particles enter and leave)"]
    with pytest.raises(InputError, match=r"positions must have shape \(T, N, 3\)"):
        write_trajectories(tmp_path / "x.h5", [0.0], pos[:1, :, :2], width=W, height=H, depth=0.01)
    with pytest.raises(InputError, match="outside the domain 0..0.09 x 0..0.95 x 0..0.01 m"):
        write_trajectories(tmp_path / "x.h5", [0.0], pos[:1] + [0, 0, 0.02], width=W, height=H,
                           depth=0.01)


def test_presence_mask_laps_across_gaps_and_late_particles(tmp_path):
    """Laps count between consecutive frames where a particle is present: a pass while it is
    absent is not seen, and the counter carries on when it reappears; a particle added later
    is absent before."""
    path = tmp_path / "p.h5"
    y = [0.9, 0.05, 0.5, 0.9, 0.1]           # passes up at frame 1 and (while absent) never
    present = [True, True, False, True, True]
    with TrajectoryWriter(path, [7], width=W, height=H, source="test") as w:
        for k in range(5):
            if k == 2:
                w.add_particles([3])
            n = w.ids.size
            p = np.full((n, 2), np.nan)
            p[0] = (0.01, y[k])
            mask = np.zeros(n, bool)
            mask[0] = present[k]
            if n > 1:
                p[1] = (0.02, 0.3 + 0.01 * k)
                mask[1] = True
            w.append(0.01 * k, p, present=mask)
    with Trajectories(path) as t:
        np.testing.assert_array_equal(t.ids, [7, 3])
        pres = t.present()
        np.testing.assert_array_equal(pres[:, 0], present)
        np.testing.assert_array_equal(pres[:, 1], [False, False, True, True, True])
        np.testing.assert_array_equal(t.laps()[:, 0], [0, 1, 0, 1, 2])
        assert np.isnan(t.positions(2)[0]).all() and np.isnan(t.positions(0)[1]).all()
        np.testing.assert_array_equal(t.present(slice(1, 3)), pres[1:3])
        text = "\n".join(describe(t))
        assert t.unsupported() == ["particles absent from some frames"]
    assert "present per frame: min 1, max 2 of 2" in text
    assert "passes through the periodic boundary: 2 up, 0 down" in text
    assert "tracks begun 2, ended 1 (after the first frame, anywhere" in text


def test_a_step_across_a_gap_is_not_refused_but_one_between_present_frames_is(tmp_path):
    with TrajectoryWriter(tmp_path / "a.h5", [1], width=W, height=H, source="test",
                          max_step=0.25) as w:
        w.append(0.0, [[0.01, 0.1]])
        w.append(0.01, [[np.nan, np.nan]], present=[False])
        w.append(0.02, [[0.01, 0.6]])                   # 0.5 m, but across an absence
    with pytest.raises(InputError, match="particle 1 moved 0.45 m"):
        with TrajectoryWriter(tmp_path / "b.h5", [1], width=W, height=H, source="test",
                              max_step=0.25) as w:
            w.append(0.0, [[0.01, 0.1]])
            w.append(0.01, [[0.01, 0.6]])
    assert not (tmp_path / "b.h5").exists()


def test_nothing_present_or_no_particle_is_refused(tmp_path):
    with pytest.raises(InputError, match="no particle in any frame to write"):
        with TrajectoryWriter(tmp_path / "e.h5", [], width=W, height=H, source="test") as w:
            w.append(0.0, np.zeros((0, 2)))
    with pytest.raises(InputError, match="ids added twice"):
        with TrajectoryWriter(tmp_path / "e.h5", [1], width=W, height=H, source="test") as w:
            w.add_particles([1])
    with pytest.raises(InputError, match="boundary 'closed'"):
        TrajectoryWriter(tmp_path / "e.h5", [1], width=W, height=H, source="test", boundary="closed")
    assert not list(tmp_path.iterdir())


def _write_version_1(path, times, positions, laps):
    """The layout before version 2, written by hand as cfbmarkov 0.x did."""
    with h5py.File(path, "w") as f:
        f.attrs.update({"format": "cfbmarkov.trajectories", "version": 1, "width": W,
                        "height": H, "length_unit": "m", "time_unit": "s", "source": "old",
                        "parameters": "{}"})
        f["particles/id"] = np.arange(positions.shape[1])
        f["frames/time"] = times
        f["frames/position"] = positions
        f["frames/lap"] = laps


def test_version_1_files_still_read_and_a_newer_version_is_refused(tmp_path, capsys):
    rng = np.random.default_rng(2)
    pos = rng.uniform([0, 0], [W, H], size=(5, 4, 2))
    laps = np.concatenate([np.zeros((1, 4), int), np.cumsum(  # consistent with the positions
        lap_increments(pos[:-1, :, 1], pos[1:, :, 1], H), axis=0)]).astype(np.int32)
    _write_version_1(tmp_path / "v1.h5", np.arange(5) * 0.02, pos, laps)
    with Trajectories(tmp_path / "v1.h5") as t:
        assert (t.version, t.dimensions, t.boundary, t.depth) == (1, 2, "periodic", None)
        assert t.axes == {"across": "x", "vertical": "y", "depth": ""}
        np.testing.assert_array_equal(t.positions(), pos)
        np.testing.assert_array_equal(t.laps(), laps)
        assert t.present().all() and t.unsupported() == []
        t.require_supported("anything")
    with h5py.File(tmp_path / "v1.h5", "r+") as f:
        f.attrs["version"] = VERSION + 1
    assert main(["info", str(tmp_path / "v1.h5")]) == 2
    err = capsys.readouterr().err
    assert f"layout version {VERSION + 1}" in err and "upgrade cfbmarkov" in err


@pytest.mark.parametrize("argv, purpose", [
    (["compare", "{f}", "{p}", "--window", "0:0.1", "-o", "{o}"], "comparing runs"),
])
def test_what_cannot_use_absent_particles_refuses_them_in_one_line(tmp_path, capsys, argv,
                                                                       purpose):
    rng = np.random.default_rng(3)
    pos = rng.uniform([0.001, 0.001], [W - 0.001, H - 0.001], size=(6, 5, 2))
    pos = np.cumsum(np.full((6, 5, 2), 0.001), axis=0) + pos[0]
    present = np.ones((6, 5), bool)
    present[3:, 2] = False
    f = write_trajectories(tmp_path / "a.h5", np.arange(6) * 0.02, np.mod(pos, [W, H]),
                           width=W, height=H, present=present)
    p = write_trajectories(tmp_path / "p.h5", np.arange(6) * 0.02, np.mod(pos, [W, H]),
                           width=W, height=H, present=present, source="markov-prediction")
    out = tmp_path / "out"
    args = [a.format(f=f, p=p, o=out) for a in argv]
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert f"{purpose} cannot use particles absent from some frames yet" in err
    assert "--boundary open where particles enter and leave" in err
    assert "not where a tracer is out of view" in err
    assert not out.exists()


@pytest.mark.parametrize("error, message", [
    (PermissionError(13, "Permission denied"), "cannot read (permission denied)"),
    (OSError("Unable to synchronously open file (unable to lock file, errno = 11, error "
             "message = 'Resource temporarily unavailable')"), "locked by another program"),
    (OSError("Unable to synchronously open file (file signature not found)"),
     "not a readable HDF5 file: truncated (copy it or write it again"),
])
def test_open_errors_say_what_happened(tmp_path, monkeypatch, capsys, error, message):
    """A file unreadable for lack of permission, or locked by a writer, is not called
    damaged (this machine runs as root, so the errors are raised by a stand-in)."""
    import h5py

    path = write_trajectories(tmp_path / "a.h5", [0.0, 0.02], np.full((2, 1, 2), 0.05),
                              width=W, height=H)

    def refuse(*args, **kwargs):
        raise error

    monkeypatch.setattr(h5py, "File", refuse)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_a_non_finite_velocity_is_refused_when_read(tmp_path):
    import h5py

    vel = np.zeros((2, 2, 2))
    path = write_trajectories(tmp_path / "v.h5", [0.0, 0.02], np.full((2, 2, 2), 0.05),
                              width=W, height=H, velocities=vel)
    with h5py.File(path, "r+") as f:
        f["frames/velocity"][1, 1, 0] = np.inf
    with Trajectories(path) as t:
        assert np.isfinite(t.velocities(0)).all()
        with pytest.raises(InputError, match="velocity of particle 1 is not a finite number"):
            t.velocities()
