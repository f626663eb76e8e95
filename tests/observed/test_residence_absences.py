"""Residence times of a periodic riser whose particles are absent from some frames: each
stretch of presence counts as a window of its own (split_at_absences), and the default
refusal names the way through."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.observed.residence import residence_times
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

W, H = 0.09, 0.95


def _one_particle(tmp_path, laps, present):
    """One particle at frames t = 0, 1, ... s with the given laps and presence."""
    laps = np.asarray(laps, np.int32)[:, None]
    present = np.asarray(present, bool)[:, None]
    pos = np.tile([0.045, 0.4], (laps.shape[0], 1, 1))
    return write_trajectories(tmp_path / "a.h5", np.arange(laps.shape[0], dtype=float), pos,
                              width=W, height=H, laps=laps, present=present)


def test_an_absence_ends_the_record_chain_and_the_next_stretch_starts_anew(tmp_path):
    # L: 0 1 1 2 . 2 3 3 4 5 at t = 0..9, absent at t = 4.
    # Without the absence: records at 1, 3, 6, 8, 9 -> samples 2, 3, 2, 1.
    # With it: records at 1, 3 (sample 2); the chain ends at 4; from 5 (L = 2) records at
    # 6 (its first: no sample), 8 (sample 2), 9 (sample 1).
    laps = [0, 1, 1, 2, 2, 2, 3, 3, 4, 5]
    present = np.ones(10, bool)
    present[4] = False
    with Trajectories(_one_particle(tmp_path, laps, present)) as t:
        rt = residence_times(t, (0, 9), split_at_absences=True)
        np.testing.assert_array_equal(rt.samples, [2.0, 2.0, 1.0])
        assert not rt.exact
        # every other frame (lag 2): frames 0, 2, 4, 6, 8; frame 4 absent ends the chain
        rt2 = residence_times(t, (0, 9), lag_frames=2, split_at_absences=True)
        np.testing.assert_array_equal(rt2.samples, [])


def test_an_absence_between_used_frames_ends_the_chain_too(tmp_path):
    # L: 0 0 1 1 2 2 3 3 4 4, used every 2 frames (0, 2, 4, 6, 8: L 0 1 2 3 4); absent at
    # frame 3 (unused) -> the chain ends at frame 4, which saw the absence since frame 2
    laps = [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    present = np.ones(10, bool)
    with Trajectories(_one_particle(tmp_path, laps, present)) as t:
        whole = residence_times(t, (0, 9), lag_frames=2).samples
    np.testing.assert_array_equal(whole, [2.0, 2.0, 2.0])
    present[3] = False
    (tmp_path / "a.h5").unlink()
    with Trajectories(_one_particle(tmp_path, laps, present)) as t:
        cut = residence_times(t, (0, 9), lag_frames=2, split_at_absences=True).samples
        # frame 4 unseen (absence at 3); from 6 (L 3): 8 is its first record
        np.testing.assert_array_equal(cut, [])
        # lag 1: records at 2 (first), absent 3, restart at 4 (L 2), records 6 (first), 8 -> 2
        np.testing.assert_array_equal(
            residence_times(t, (0, 9), split_at_absences=True).samples, [2.0])


def test_split_residences_of_a_complete_file_are_the_usual_ones(tmp_path):
    rng = np.random.default_rng(5)
    steps = rng.integers(0, 2, size=(200, 6))
    steps[np.arange(200) % 3 != 0] = 0     # at most one pass within any 3 frames (the lag)
    laps = np.cumsum(steps, axis=0).astype(np.int32)
    pos = np.tile([0.045, 0.4], (200, 6, 1))
    path = write_trajectories(tmp_path / "c.h5", 0.01 * np.arange(200), pos, width=W,
                              height=H, laps=laps)
    with Trajectories(path) as t:
        for lag in (1, 3):
            np.testing.assert_array_equal(
                residence_times(t, (0.1, 1.9), lag_frames=lag, split_at_absences=True).samples,
                residence_times(t, (0.1, 1.9), lag_frames=lag).samples)


def test_without_the_split_a_periodic_file_with_absences_is_refused_naming_the_way(tmp_path):
    present = np.ones(10, bool)
    present[4] = False
    with Trajectories(_one_particle(tmp_path, [0] * 10, present)) as t:
        with pytest.raises(InputError, match=r"across particles' absences.*--states cells.*"
                                             r"present throughout.*--boundary open only where"
                                             r".*not where a tracer is out of view"):
            residence_times(t, (0, 9))
    # a window of the file without the gap is read as it is: its residences counted
    (tmp_path / "laps").mkdir()
    with Trajectories(_one_particle(tmp_path / "laps", [0, 1, 1, 2, 2, 2, 3, 3, 4, 5],
                                    present)) as t:
        np.testing.assert_array_equal(residence_times(t, (5, 9)).samples, [2.0, 1.0])


def test_net_passes_count_each_particle_between_its_frames_present(tmp_path):
    """Particle 0 passes up twice; particle 1 sits at lap 3 and leaves the view for the last
    frames (stored lap 0 there): the net flow is 2 passes up, not 2 - 3."""
    from cfbmarkov.observed.residence import net_flow_direction, net_passes

    laps = np.zeros((10, 2), np.int32)
    laps[:, 0] = [0, 0, 1, 1, 1, 1, 2, 2, 2, 2]
    laps[:6, 1] = 3
    present = np.ones((10, 2), bool)
    present[6:, 1] = False
    pos = np.tile([0.045, 0.4], (10, 2, 1))
    path = write_trajectories(tmp_path / "n.h5", np.arange(10.0), pos, width=W, height=H,
                              laps=laps, present=present)
    with Trajectories(path) as t:
        assert net_passes(t, (0, 9)) == 2 and net_flow_direction(t, (0, 9)) == "up"
        assert net_passes(t, (2, 9)) == 1
