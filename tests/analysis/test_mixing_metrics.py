"""Mixing by halves (SPEC section 4) and the comparison metrics, on hand-made arrays."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.analysis import mixing as mixing_module
from cfbmarkov.observed.metrics import minkowski_distance, mixing_rms, percentage_difference
from cfbmarkov.analysis.mixing import mixing_curve, mixing_curve_of
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

WIDTH, HEIGHT = 0.09, 0.95


def test_mixing_curve_by_hand():
    half = WIDTH / 2
    x = np.array([[0.01, 0.02, 0.06, 0.08],     # left group: particles 0 and 1 -> 2/4
                  [0.01, 0.07, 0.02, 0.08],     # left group on the left: 0 only -> 1/4
                  [0.05, 0.07, 0.01, 0.02],     # none (the left holds two of the right group) -> 0
                  [0.03, 0.04, 0.01, 0.02]])    # both of the left group back, all four left -> 2/4
    np.testing.assert_allclose(mixing_curve(x, half), [0.5, 0.25, 0.0, 0.5])


def test_mixing_curve_starts_at_the_left_group_share():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, WIDTH, (5, 1000))
    curve = mixing_curve(x, WIDTH / 2)
    assert curve[0] == pytest.approx(np.mean(x[0] < WIDTH / 2))
    assert np.all(curve <= curve[0])


def test_mixing_curve_edge_and_given_mask():
    # x exactly at W/2 is in the right group (x < W/2 is the left group)
    np.testing.assert_allclose(mixing_curve(np.array([[0.045, 0.01]]), 0.045), [0.5])
    left_group = np.array([True, True])
    np.testing.assert_allclose(mixing_curve(np.array([[0.045, 0.01]]), 0.045, left_group), [0.5])
    with pytest.raises(InputError):
        mixing_curve(np.zeros(3), 0.045)


def test_mixing_curve_of_a_file_reads_blocks(tmp_path, make_run, write_run, monkeypatch):
    run = make_run(n_particles=40, t1=2.0, seed=7, lateral=0.01)
    path = write_run(tmp_path / "run.h5", run)
    with Trajectories(path) as traj:
        sl = traj.window(0.5, 1.5)
        expected = mixing_curve(traj.positions(sl)[..., 0], WIDTH / 2)
        times, fraction = mixing_curve_of(traj, (0.5, 1.5), block=3)
        np.testing.assert_allclose(times, traj.times[sl])
    np.testing.assert_allclose(fraction, expected)
    assert fraction[0] == pytest.approx(np.mean(run.positions[20, :, 0] < WIDTH / 2))
    assert mixing_module.mixing_curve_of is mixing_curve_of


def test_mixing_curve_of_a_window_outside(tmp_path):
    path = write_trajectories(tmp_path / "r.h5", [0.0, 0.1], np.full((2, 3, 2), 0.02),
                              width=WIDTH, height=HEIGHT)
    with Trajectories(path) as traj, pytest.raises(InputError):
        mixing_curve_of(traj, (0.0, 0.5))


def test_percentage_difference():
    assert percentage_difference(110.0, 100.0) == pytest.approx(10.0)
    assert percentage_difference(0.45, 0.5) == pytest.approx(-10.0)
    assert np.isnan(percentage_difference(1.0, 0.0))
    assert np.isnan(percentage_difference(1.0, np.nan))
    np.testing.assert_allclose(percentage_difference([2.0, 3.0], [1.0, 4.0]), [100.0, -25.0])


def test_minkowski_distance():
    e = [0.1, 0.2, 0.7]
    f = [0.2, 0.2, 0.6]
    assert minkowski_distance(e, f) == pytest.approx(np.sqrt(0.02))
    assert minkowski_distance(e, f, order=1) == pytest.approx(0.2)
    assert minkowski_distance(e, f, order=3) == pytest.approx(0.002 ** (1 / 3))
    assert minkowski_distance(e, f, order=np.inf) == pytest.approx(0.1)
    assert minkowski_distance(e, e) == 0.0
    with pytest.raises(InputError):
        minkowski_distance([1, 2], [1, 2, 3])
    with pytest.raises(InputError):
        minkowski_distance(e, f, order=0)


def test_mixing_rms():
    # reference at 0.5 s and 1.5 s by interpolation: 0.4 and 0.2; model 0.4 and 0.3
    rms = mixing_rms([0.0, 1.0, 2.0], [0.5, 0.3, 0.1], [0.5, 1.5], [0.4, 0.3])
    assert rms == pytest.approx(np.sqrt(0.01 / 2))
    assert mixing_rms([0.0, 1.0], [0.5, 0.3], [0.0, 1.0], [0.5, 0.3]) == 0.0
    # round-off at the ends is accepted
    assert mixing_rms([15.0, 20.0], [0.5, 0.3], [15.0, 20.0 + 1e-12], [0.5, 0.3]) == 0.0


def test_mixing_rms_weights_frames_by_their_tracers():
    """An open riser's frames weigh as the tracers still present: the last frame's few
    tracers move the RMS little; a weight of 0 leaves a frame out, and the frames
    compared are counted."""
    times = [0.0, 1.0, 2.0, 3.0]
    reference = [0.5, 0.4, 0.3, 0.2]
    model = [0.5, 0.5, 0.3, 0.9]           # 0.1 off at 1 s, 0.7 off at 3 s
    plain, n = mixing_rms(times, reference, times, model, frames=True)
    assert n == 4 and plain == pytest.approx(np.sqrt((0.01 + 0.49) / 4))
    weighted = mixing_rms(times, reference, times, model, [100, 100, 90, 2])
    assert weighted == pytest.approx(np.sqrt((100 * 0.01 + 2 * 0.49) / 292))
    assert weighted < plain / 3
    assert mixing_rms(times, reference, times, model, [1, 1, 1, 0], frames=True) == \
        (pytest.approx(np.sqrt(0.01 / 3)), 3)
    assert mixing_rms(times, [0.5, 0.4, np.nan, np.nan], times, model, frames=True)[1] == 2
    with pytest.raises(InputError, match="weights"):
        mixing_rms(times, reference, times, model, [1, 1, -1, 1])


def test_mixing_rms_takes_a_time_within_round_off_of_a_frame_as_that_frame():
    """An open riser's reference curve defined up to 0.02 s: a prediction's time one ulp
    above it (2.2800000000000002 for 2.28, as a run's times accumulate) is that frame, not
    a time beside it where the reference is undefined: the frame was dropped and the RMS
    read 0 instead of 0.577 (0.311 instead of 0.337 on a review's open riser)."""
    times = np.array([0.0, 0.01, 0.02, 0.03])
    reference = np.array([0.5, 0.5, 1.0, np.nan])
    model = np.array([0.5, 0.5, 0.0, np.nan])
    nudged = times.copy()
    nudged[2] = np.nextafter(0.02, 1.0)
    assert mixing_rms(times, reference, nudged, model) == pytest.approx(np.sqrt(1 / 3))
    assert mixing_rms(times, reference, times, model) == pytest.approx(np.sqrt(1 / 3))


def test_mixing_rms_refuses_model_times_outside_the_reference():
    with pytest.raises(InputError, match="leave"):
        mixing_rms([0.0, 1.0], [0.5, 0.3], [0.5, 1.5], [0.4, 0.3])
    with pytest.raises(InputError, match="leave"):
        mixing_rms([1.0, 2.0], [0.5, 0.3], [0.9, 1.5], [0.4, 0.3])
    with pytest.raises(InputError):
        mixing_rms([0.0, 1.0], [0.5], [0.5], [0.4])
