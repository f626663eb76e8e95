"""Residence times (SPEC section 3): the kernels on hand-worked cases, the events kernel
against the laps kernel, the file wrapper, the histogram and a statistical check."""

from __future__ import annotations


import numpy as np
import pytest

from cfbmarkov.observed import residence as rtd_module
from cfbmarkov.observed.residence import (
    ResidenceTimes,
    residence_times,
    residence_times_from_events,
    residence_times_from_laps,
    rtd_histogram,
)
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import PassEvents
from cfbmarkov.trajectory_writer import write_trajectories

WIDTH, HEIGHT = 0.09, 0.95


def laps_kernel(laps, times=None):
    laps = np.asarray(laps, dtype=np.int32)
    if laps.ndim == 1:
        laps = laps[:, None]
    times = np.arange(laps.shape[0], dtype=float) if times is None else times
    return residence_times_from_laps(times, laps)


# -- the laps kernel, by hand -----------------------------------------------------------------
def test_hand_worked_fall_back_is_not_a_new_record():
    # L: 0 0 1 1 1 2 1 1 2 3 at t = 0..9. Running max starts at L(0) = 0.
    # t=2: L=1 > 0, record (first record: its entry is unknown, no sample)
    # t=5: L=2 > 1, record -> sample 5 - 2 = 3
    # t=6: falls back to 1 (out of the bottom): same residence
    # t=8: L=2 again, not above the maximum 2: no record
    # t=9: L=3 > 2, record -> sample 9 - 5 = 4
    samples = laps_kernel([0, 0, 1, 1, 1, 2, 1, 1, 2, 3])
    np.testing.assert_array_equal(samples, [3.0, 4.0])


def test_counted_from_the_first_frame_value():
    # starts at lap 5: records at t=1 (6) and t=3 (7): one sample of 2
    np.testing.assert_array_equal(laps_kernel([5, 6, 6, 7]), [2.0])
    # starts at -2 and climbs: -1 at t=1 is already a record (above L(A) = -2)
    np.testing.assert_array_equal(laps_kernel([-2, -1, -1, 0, 0, 0, 1]), [2.0, 3.0])


def test_particles_that_never_pass_give_no_sample():
    laps = np.array([[0, 0, 0, 0, 0, 0],        # never moves
                     [0, -1, -2, 0, 0, 0],      # only falls and comes back: no record
                     [0, -1, -1, 1, 0, 0],      # one record (t=3): entry unknown
                     [0, 0, 0, 1, 0, 0],        # one record
                     [0, 0, 0, 1, 0, 1]],       # the re-pass to 1 at t=5 is no new record
                    np.int32).T                 # [T=6, N=5]
    assert residence_times_from_laps(np.arange(6.0), laps).size == 0


def test_time_before_the_first_record_is_excluded():
    # one pass only (at t=7): entry unknown, exit known -> no sample
    assert laps_kernel([0, 0, 0, 0, 0, 0, 0, 1, 1, 1]).size == 0
    # passes at 1 and 8: exactly one sample of 7 (not 1, not 8)
    np.testing.assert_array_equal(laps_kernel([0, 1, 1, 1, 1, 1, 1, 1, 2]), [7.0])


def test_a_jump_by_two_records_the_frame_time_twice():
    # 0 0 2 2 3: records at 2, 2, 4 -> samples 0 (a residence shorter than a frame) and 2
    np.testing.assert_array_equal(laps_kernel([0, 0, 2, 2, 3]), [0.0, 2.0])


def test_several_particles_and_real_times():
    times = 15.0 + 0.025 * np.arange(6)
    laps = np.array([[0, 1, 1, 2, 2, 3],        # records at frames 1, 3, 5
                     [3, 3, 4, 4, 4, 5],        # records at frames 2, 5
                     [0, 0, 0, 0, 0, 0]], np.int32).T
    samples = residence_times_from_laps(times, laps)
    # order of completion: frame 3 (p0), frame 5 (p0, then p1)
    np.testing.assert_allclose(samples, [0.05, 0.05, 0.075], rtol=0, atol=1e-12)


def test_laps_kernel_refuses_bad_shapes():
    with pytest.raises(InputError):
        residence_times_from_laps(np.arange(3.0), np.zeros((4, 2), np.int32))
    with pytest.raises(InputError):
        residence_times_from_laps(np.arange(3.0), np.zeros((3, 2)))
    assert residence_times_from_laps(np.zeros(0), np.zeros((0, 3), np.int32)).size == 0


# -- the events kernel ------------------------------------------------------------------------
def events_from_laps(times, laps):
    """Unit pass events at the frame times where the lap counters change."""
    t_list, p_list, d_list = [], [], []
    for k in range(1, laps.shape[0]):
        for p in range(laps.shape[1]):
            step = int(laps[k, p] - laps[k - 1, p])
            for _ in range(abs(step)):
                t_list.append(times[k])
                p_list.append(p)
                d_list.append(1 if step > 0 else -1)
    order = np.argsort(t_list, kind="stable")
    return (np.array(t_list)[order], np.array(p_list, dtype=np.int64)[order],
            np.array(d_list, dtype=np.int64)[order])


def test_events_kernel_on_the_hand_worked_case():
    laps = np.array([0, 0, 1, 1, 1, 2, 1, 1, 2, 3], np.int32)[:, None]
    t, p, d = events_from_laps(np.arange(10.0), laps)
    samples = residence_times_from_events(laps[0], t, p, d, 0.0, 9.0)
    np.testing.assert_array_equal(samples, [3.0, 4.0])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_events_agree_with_laps_when_placed_at_frame_times(seed):
    rng = np.random.default_rng(seed)
    n_frames, n = 120, 40
    steps = rng.choice([-1, 0, 0, 0, 1, 1, 2], size=(n_frames - 1, n))
    laps = np.vstack([rng.integers(-3, 3, n), steps]).cumsum(axis=0).astype(np.int32)
    times = 10.0 + 0.025 * np.arange(n_frames)
    from_laps = residence_times_from_laps(times, laps)
    t, p, d = events_from_laps(times, laps)
    from_events = residence_times_from_events(laps[0], t, p, d, times[0], times[-1])
    assert from_laps.size > 50
    np.testing.assert_allclose(np.sort(from_events), np.sort(from_laps), rtol=0, atol=1e-12)


def test_exact_events_differ_from_frame_times():
    # passes up at 0.31 s and 0.74 s; frames every 0.1 s see them at 0.4 and 0.8
    times = 0.1 * np.arange(10)
    laps = np.array([0, 0, 0, 0, 1, 1, 1, 1, 2, 2], np.int32)[:, None]
    np.testing.assert_allclose(residence_times_from_laps(times, laps), [0.4])
    exact = residence_times_from_events(np.array([0]), np.array([0.31, 0.74]), np.array([0, 0]),
                                        np.array([1, 1]), 0.0, 0.9)
    np.testing.assert_allclose(exact, [0.43])


def test_events_kernel_window_and_fall_back():
    t = np.array([0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5])
    p = np.zeros(7, np.int64)
    d = np.array([1, 1, -1, 1, 1, 1, 1])
    # start 0.5: the event at 0.5 is already in lap_at_start (start < t only)
    # levels 1: 1.0 rec, 1.5 fall, 2.0 back (no rec), 2.5 rec, 3.0 rec; 3.5 after stop
    samples = residence_times_from_events(np.array([1]), t, p, d, 0.5, 3.2)
    np.testing.assert_allclose(samples, [1.5, 0.5])


def test_events_kernel_refuses_damaged_events():
    with pytest.raises(InputError, match="sorted"):
        residence_times_from_events([0], [2.0, 1.0], [0, 0], [1, 1], 0.0, 3.0)
    with pytest.raises(InputError, match="particle index"):
        residence_times_from_events([0], [1.0], [3], [1], 0.0, 3.0)
    with pytest.raises(InputError, match="direction"):
        residence_times_from_events([0], [1.0], [0], [2], 0.0, 3.0)
    with pytest.raises(InputError, match="length"):
        residence_times_from_events([0], [1.0, 2.0], [0], [1], 0.0, 3.0)


# -- the wrapper on files ---------------------------------------------------------------------
def test_wrapper_uses_the_window_and_blocks(tmp_path, make_run, write_run, monkeypatch):
    run = make_run(n_particles=50, t1=4.0, seed=3)
    path = write_run(tmp_path / "run.h5", run)
    with Trajectories(path) as traj:
        sl = traj.window(1.0, 3.5)
        expected = residence_times_from_laps(traj.times[sl], traj.laps(sl))
        monkeypatch.setattr(rtd_module, "_BLOCK_FRAMES", 7)
        got = residence_times(traj, (1.0, 3.5))
    assert isinstance(got, ResidenceTimes)
    assert got.exact is False and got.window == (1.0, 3.5)
    assert got.count == expected.size > 20
    np.testing.assert_allclose(np.sort(got.samples), np.sort(expected), atol=1e-12)
    assert got.mean == pytest.approx(expected.mean())
    assert got.sd == pytest.approx(expected.std(ddof=1))


def test_wrapper_prefers_exact_events(tmp_path, make_run, events_of):
    run = make_run(n_particles=30, t1=3.0, seed=4)
    events = events_of(run)
    path = write_trajectories(tmp_path / "run.h5", run.times, run.positions, width=WIDTH,
                              height=HEIGHT, events=events)
    with Trajectories(path) as traj:
        exact = residence_times(traj, (0.5, 3.0))
        frames = residence_times(traj, (0.5, 3.0), use_events=False)
        i0 = traj.frame_index(0.5)
        direct = residence_times_from_events(traj.laps(i0), events.time[np.argsort(events.time)],
                                             events.particle[np.argsort(events.time)],
                                             events.direction[np.argsort(events.time)],
                                             traj.times[i0], 3.0)
    assert exact.exact and not frames.exact
    assert exact.count == frames.count > 10
    np.testing.assert_allclose(np.sort(exact.samples), np.sort(direct))
    # frame-based samples are whole frame intervals; exact ones are not
    assert np.allclose(frames.samples / 0.025, np.round(frames.samples / 0.025))
    assert not np.allclose(exact.samples / 0.025, np.round(exact.samples / 0.025))
    assert abs(exact.mean - frames.mean) < 0.025


def test_wrapper_window_outside_the_data(tmp_path, make_run, write_run):
    path = write_run(tmp_path / "run.h5", make_run(n_particles=5, t1=1.0))
    with Trajectories(path) as traj, pytest.raises(InputError, match="outside"):
        residence_times(traj, (0.5, 2.0))


def test_residence_times_statistics_without_samples():
    empty = ResidenceTimes(np.zeros(0), False, (0.0, 1.0))
    assert empty.count == 0 and np.isnan(empty.mean) and np.isnan(empty.sd)
    one = ResidenceTimes(np.array([0.3]), False, (0.0, 1.0))
    assert one.mean == 0.3 and np.isnan(one.sd)
    two = ResidenceTimes(np.array([0.3, 0.5]), True, (0.0, 1.0))
    assert two.sd == pytest.approx(np.sqrt(0.02))


# -- statistics: constant speed with a known period -------------------------------------------
@pytest.mark.parametrize("period", [0.5, 0.4375])
def test_constant_speed_gives_the_period(tmp_path, period, events_of):
    """Particles rising at H/period m/s: every sample equals the period when the period is a
    whole number of frames; otherwise each is within a frame and they average to it."""
    dt = 0.025
    n, t_end = 400, 4.0
    times = dt * np.arange(round(t_end / dt) + 1)
    y0 = np.random.default_rng(5).uniform(0.0, HEIGHT, n)
    unwrapped = y0 + (HEIGHT / period) * times[:, None]
    x = np.full((times.size, n), 0.02)
    positions = np.stack([x, np.mod(unwrapped, HEIGHT)], axis=-1)
    path = write_trajectories(tmp_path / "rise.h5", times, positions, width=WIDTH, height=HEIGHT)
    with Trajectories(path) as traj:
        rt = residence_times(traj, (0.0, t_end))
    assert rt.count >= n * (int(t_end / period) - 2)
    whole = abs(period / dt - round(period / dt)) < 1e-9
    if whole:
        np.testing.assert_allclose(rt.samples, period, atol=1e-9)
    else:
        assert np.all(np.abs(rt.samples - period) < dt + 1e-9)
        assert rt.mean == pytest.approx(period, abs=2e-3)
    # exact events give the period itself
    run = type("R", (), {"times": times, "unwrapped_y": unwrapped})()
    events = events_of(run)
    path = write_trajectories(tmp_path / "rise-events.h5", times, positions, width=WIDTH,
                              height=HEIGHT, events=events)
    with Trajectories(path) as traj:
        exact = residence_times(traj, (0.0, t_end))
    assert exact.exact
    np.testing.assert_allclose(exact.samples, period, atol=1e-9)


def test_kernel_at_paper_size_counts_every_completed_lap():
    """27000 particles x 201 frames (speed is measured by ``cfbmarkov bench``, not here):
    every lap completed after a particle's first lap in the window is one sample."""
    rng = np.random.default_rng(0)
    laps = np.cumsum(rng.random((201, 27000)) < 0.04, axis=0).astype(np.int32)
    times = 15.0 + 0.025 * np.arange(201)
    samples = residence_times_from_laps(times, laps)
    gained = laps[-1] - laps[0]
    assert samples.size == int(np.clip(gained - 1, 0, None).sum())
    assert np.all(samples > 0) and samples.max() <= times[-1] - times[0]


# -- histogram --------------------------------------------------------------------------------
def test_histogram_bins_and_probability():
    samples = np.array([0.0, 0.0249, 0.025, 0.075 - 1e-13, 0.075 + 1e-13, 0.09, 0.5])
    edges, prob = rtd_histogram(samples, 0.025, window_length=0.1)
    np.testing.assert_allclose(edges, [0.0, 0.025, 0.05, 0.075, 0.1])
    # 0.5 s is outside 0..0.1 s; the two samples at 0.075 +- round-off share a bin
    np.testing.assert_allclose(prob, np.array([2, 1, 0, 3]) / 6)
    assert prob.sum() == pytest.approx(1.0)


def test_histogram_frame_multiples_land_in_their_own_bin():
    samples = np.array([15.075 - 15.0, 15.1 - 15.025, 0.3 * 0.25])   # all "0.075"
    _, prob = rtd_histogram(samples, 0.025, window_length=0.2)
    assert prob[3] == 1.0


def test_histogram_window_not_a_multiple_and_empty():
    edges, prob = rtd_histogram([], 0.025, window_length=0.11)
    assert edges[-1] == pytest.approx(0.125) and prob.size == 5 and not prob.any()
    with pytest.raises(InputError):
        rtd_histogram([0.1], 0.0, window_length=1.0)
    with pytest.raises(InputError):
        rtd_histogram([0.1], 0.025, window_length=-1.0)


def test_passevents_type_is_accepted(tmp_path):
    # events given through the store's own type round-trip to the same samples
    times = 0.1 * np.arange(6)
    y = np.array([0.9, 0.05, 0.5, 0.94, 0.1, 0.6])[:, None]
    positions = np.stack([np.full_like(y, 0.01), y], axis=-1)
    events = PassEvents(np.array([0.05, 0.35]), np.array([0, 0]), np.array([1, 1]))
    path = write_trajectories(tmp_path / "e.h5", times, positions, width=WIDTH, height=HEIGHT,
                              events=events)
    with Trajectories(path) as traj:
        rt = residence_times(traj, (0.0, 0.5))
    np.testing.assert_allclose(rt.samples, [0.3])


def test_events_of_a_window_that_starts_between_frames_count_from_its_start(tmp_path):
    """Passes up at 1.3, 3.1 (after one down at 2.6), 5.7 and 8.2 s on frames every second,
    the window 1.2-9 s: the counter at 1.2 s is 0, so the records are 1.3, 5.7 and 8.2
    (samples 4.4 and 2.5), not those after the first frame at 2 s (the pass at 1.3 lost)."""
    passes = [(1.3, 1), (2.6, -1), (3.1, 1), (5.7, 1), (8.2, 1)]
    times = np.arange(10.0)
    laps = np.array([[sum(d for t, d in passes if t <= ti)] for ti in times], np.int32)
    positions = np.stack([np.full((10, 1), 0.025), np.full((10, 1), 0.5)], axis=-1)
    events = PassEvents(np.array([t for t, _ in passes]), np.zeros(5, np.int32),
                        np.array([d for _, d in passes], np.int8))
    path = write_trajectories(tmp_path / "e.h5", times, positions, width=0.1, height=1.0,
                              laps=laps, events=events)
    with Trajectories(path) as traj:
        np.testing.assert_allclose(residence_times(traj, (1.2, 9.0)).samples, [4.4, 2.5])
        np.testing.assert_allclose(residence_times(traj, (0.0, 8.5)).samples, [4.4, 2.5])
        np.testing.assert_allclose(residence_times(traj, (2.7, 9.0)).samples, [2.6, 2.5])


def test_an_open_risers_particle_inside_at_the_start_that_returns_through_the_inlet():
    """Inside at the window's first frame, back out through the inlet, in again and out
    through the outlet: one residence begun before the window (no sample), not a new one
    from its return; a particle that enters in the window gives its sample."""
    from cfbmarkov.observed.residence import open_residence_times

    nan = np.nan
    times = np.arange(9.0)
    y = np.array([[0.3, 0.05, nan, nan, 0.05, 0.5, 0.9, 0.99, nan],     # the returning one
                  [nan, 0.05, 0.4, 0.8, 0.99, nan, nan, nan, nan]]).T   # in at 1, out at 5
    samples = open_residence_times(times, np.isfinite(y), y, 0.1, 1.0)
    np.testing.assert_allclose(samples, [4.0])


def test_an_open_riser_read_a_lag_apart_judges_its_faces_on_the_frames_between(tmp_path):
    """Frames every 0.01 s, a lag of 3 frames: particle 0 is first seen at frame 5 at the
    inlet (at frame 6, the lag's, it is above the inlet's band), climbs, hovers at the
    outlet, drops out of view at frame 28 alone and is last seen at frame 30: one residence
    from the lag's frame 6 to 33, 0.27 s (read on the lag's frames alone its entry was not
    seen: no residence). Particle 1 appears and vanishes between two lag frames: never
    seen at a lag frame, no residence (it had given one of 0 s)."""
    from cfbmarkov.observed.residence import lag_face_heights

    times = 0.01 * np.arange(60)
    y = np.full((60, 2), np.nan)
    y[5:20, 0] = np.linspace(0.015, 0.19, 15)    # frame 6: 0.0275 m, above the band
    y[20:31, 0] = 0.19                        # hovering in the outlet's band
    y[28, 0] = np.nan                         # out of view for one frame
    y[40:42, 1] = (0.01, 0.19)
    present = np.isfinite(y)
    pos = np.stack([np.full_like(y, 0.01), np.nan_to_num(y, nan=0.1)], axis=-1)
    path = write_trajectories(tmp_path / "open.h5", times, pos, width=0.02, height=0.2,
                              present=present, boundary="open")
    with Trajectories(path) as traj:
        samples = residence_times(traj, (0.0, 0.59), lag_frames=3, face_band=0.02).samples
        np.testing.assert_allclose(samples, [0.27])
        # at the frames' own lag the gap at the outlet is an exit (0.23 s), and particle
        # 1 crosses the riser in 0.02 s
        np.testing.assert_allclose(
            residence_times(traj, (0.0, 0.59), face_band=0.02).samples, [0.23, 0.02])
    first, last = lag_face_heights(y, 3, np.arange(0, 60, 3))
    assert first[2, 0] == pytest.approx(0.015)          # frame 6: first seen at frame 5
    assert last[9, 0] == pytest.approx(0.19)            # frame 27: last seen at 29/30
