"""The long-run E(RT) from the net solids flux (Little's law): exact on hand-made lap
counters, unbiased where the window censors the residences, refused where it is undefined."""

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.errors import InputError
from cfbmarkov.observed.residence import (flux_residence_time, residence_flux,
                                          residence_times)
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

from .conftest import HEIGHT, WIDTH

#: a slow flow whose walls fall out through the bottom: E(RT) 2.69 s, a long tail
LONG_TAIL = synthetic.RiserFlow(persistence=False, rise_velocity=1.4, fall_velocity=-1.0,
                                lateral_probability=0.08)


def _laps_file(path, laps, dt=0.1, present=None):
    laps = np.asarray(laps, dtype=np.int64)
    times = dt * np.arange(laps.shape[0])
    positions = np.full(laps.shape + (2,), 0.5)
    positions[..., 0] *= WIDTH
    positions[..., 1] *= HEIGHT
    return write_trajectories(path, times, positions, width=WIDTH, height=HEIGHT, laps=laps,
                              present=present)


def test_hand_made_laps(tmp_path):
    # two particles, one lap every 0.5 s and every 1 s, over 2 s: 4 + 2 passes for 4
    # particle-seconds -> 2/3 s; counted down, a net downflow of the same laps
    t = np.arange(21) * 0.1
    laps = np.column_stack([np.floor(t / 0.5 + 1e-9), np.floor(t / 1.0 + 1e-9)])
    with Trajectories(_laps_file(tmp_path / "up.h5", laps)) as traj:
        assert residence_flux(traj, (0.0, 2.0)) == (pytest.approx(4.0), 6)
        assert flux_residence_time(traj, (0.0, 2.0)) == pytest.approx(2.0 / 3.0, rel=1e-12)
        assert flux_residence_time(traj, (0.0, 2.0), "down") == np.inf
        with pytest.raises(InputError, match="up or down"):
            flux_residence_time(traj, (0.0, 2.0), "sideways")
    with Trajectories(_laps_file(tmp_path / "down.h5", -laps)) as traj:
        assert flux_residence_time(traj, (0.0, 2.0)) == pytest.approx(2.0 / 3.0, rel=1e-12)


def test_unbiased_where_the_window_censors_the_residences(tmp_path):
    exact = synthetic.cell_chain(LONG_TAIL).rtd().mean
    path = synthetic.write_run(tmp_path / "tail.h5", LONG_TAIL, 2000, 6.0, seed=1)
    with Trajectories(path) as traj:
        flux = flux_residence_time(traj, (0.0, 6.0))
        inside = residence_times(traj, (0.0, 6.0), use_events=False).mean
    # a window about twice E(RT) long: the residences wholly inside it are a fifth short,
    # the flux is not (2000 particles: about 1 % sampling error)
    assert flux == pytest.approx(exact, rel=0.04)
    assert inside < 0.9 * exact


def test_refused_without_lap_counters(tmp_path):
    open_run = synthetic.write_open_run(tmp_path / "open.h5", LONG_TAIL, 50, 1.0)
    with Trajectories(open_run) as traj, pytest.raises(InputError, match="open riser"):
        flux_residence_time(traj, (0.0, 1.0))


def test_with_absences_the_steps_tracked_at_both_ends_count(tmp_path):
    """A particle never present (outside the walls) adds nothing: the same flux as the file
    without it. A tracer absent for a while counts neither the time nor a lap change across
    its absence: only the frame steps present at both ends (hand-counted)."""
    t = np.arange(21) * 0.1
    laps = np.column_stack([np.floor(t / 0.5 + 1e-9), np.floor(t / 1.0 + 1e-9),
                            np.zeros(21)])
    with Trajectories(_laps_file(tmp_path / "all.h5", laps[:, :2])) as traj:
        whole = residence_flux(traj, (0.0, 2.0))
    never = np.ones((21, 3), dtype=bool)
    never[:, 2] = False
    with Trajectories(_laps_file(tmp_path / "never.h5", laps, present=never)) as traj:
        assert traj.has_absences
        assert residence_flux(traj, (0.0, 2.0)) == (pytest.approx(whole[0]), whole[1])
        assert flux_residence_time(traj, (0.0, 2.0)) == pytest.approx(2.0 / 3.0, rel=1e-12)
    # particle 0 away over frames 4-11 (0.4-1.1 s): the steps 0.3-0.4 s ... 1.1-1.2 s are
    # not tracked at both ends (9 steps of 0.1 s), and its lap change across them (1 -> 2,
    # at 0.5 and 1.0 s: two passes) is not counted: 4 - 0.9 particle-s, 6 - 2 passes
    gap = never.copy()
    gap[4:12, 0] = False
    with Trajectories(_laps_file(tmp_path / "gap.h5", laps, present=gap)) as traj:
        particle_time, passes = residence_flux(traj, (0.0, 2.0))
        assert particle_time == pytest.approx(3.1) and passes == 4
