"""Arrays and arguments built by hand in a notebook: discrete trajectories whose states
or heights the counting kernels cannot take, windows given as text, histograms of
impossible residence times, a writer given what it cannot store, and the arrays a model
returns. Each is refused in one line (never a crash or a silently wrong number)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.markov import MaximumLikelihoodEstimator, discretize, fit_model
from cfbmarkov.markov.discrete import DiscreteTrajectories


@pytest.fixture(scope="module")
def window(markov_flow, markov_run):
    return discretize(markov_run, markov_flow.grid, markov_flow.lag, (2.0, 4.0))


def _made(window, **arrays):
    """The window rebuilt from plain (writeable) copies of its arrays, some replaced."""
    given = {"states": np.array(window.states), "vertical": np.array(window.vertical),
             "times": np.array(window.times)}
    given.update(arrays)
    return DiscreteTrajectories(lag_frames=window.lag_frames,
                                frame_interval=window.frame_interval, height=window.height,
                                state_space=window.state_space, window=window.window,
                                **given)


def test_states_outside_the_state_space_are_refused_not_counted(window):
    """States numbered from 1 (one past the last state) crashed the counting kernel; other
    negatives than -1 were taken as absent and fractions truncated."""
    n = window.state_space.n_states
    for states, message in ((np.array(window.states) + 1, f"states run 1 .. {n}"),
                            (np.where(window.states == 0, -5, window.states), "states run -5"),
                            (np.array(window.states) + 0.7, "must be integers")):
        with pytest.raises(InputError, match=message):
            _made(window, states=states)
    # int64 states in range are taken (as int32), and fit as the window does
    made = _made(window, states=np.array(window.states, dtype=np.int64))
    assert made.states.dtype == np.int32
    estimator = MaximumLikelihoodEstimator(window.state_space, lag=window.lag)
    np.testing.assert_array_equal(estimator.fit(made).transition_matrix,
                                  estimator.fit(window).transition_matrix)


def test_heights_that_are_not_finite_or_leave_the_riser_are_refused(window):
    """Heights in mm (1000 times the riser) or NaN where a particle is present gave a
    wrong RTD; NaN is still taken where the particle is absent (state -1)."""
    with pytest.raises(InputError, match=r"heights run .* outside the riser's 0 \.\. "):
        _made(window, vertical=np.array(window.vertical) * 1000.0)
    vertical = np.array(window.vertical)
    vertical[3, 5] = np.nan
    with pytest.raises(InputError, match="NaN or infinite where its particle is present"):
        _made(window, vertical=vertical)
    states = np.array(window.states)
    states[3, 5] = -1
    assert _made(window, states=states, vertical=vertical).states[3, 5] == -1


def test_times_off_the_frame_interval_and_lists_are_handled(window):
    with pytest.raises(InputError, match="not spaced by the frame interval"):
        _made(window, times=window.times[0] + 2.0 * (window.times - window.times[0]))
    made = _made(window, times=list(window.times), states=window.states.tolist())
    np.testing.assert_array_equal(made.states, window.states)


def test_the_callers_arrays_are_copied_so_writing_them_changes_nothing(window):
    states = np.array(window.states)
    made = _made(window, states=states)
    estimator = MaximumLikelihoodEstimator(window.state_space, lag=window.lag)
    before = estimator.fit(made).transition_matrix
    states[:] = 0                                  # the caller reuses its buffer
    assert not np.shares_memory(made.states, states)
    np.testing.assert_array_equal(estimator.fit(made).transition_matrix, before)
    with pytest.raises(ValueError):
        made.states[0, 0] = 1


def test_a_window_given_as_text_is_refused_not_split_into_characters(markov_flow,
                                                                       markov_run):
    """residence_times(run, "15") was read as the window 1:5 s."""
    from cfbmarkov.analysis.mixing import mixing_curve_of
    from cfbmarkov.markov.select import select_model
    from cfbmarkov.observed.residence import flux_residence_time, residence_times

    from cfbmarkov.trajectories import opened

    with opened(markov_run) as run:
        for window in ("15", "2:6", None, (2.0,)):
            with pytest.raises(InputError, match="is not \\(start, stop\\) in s"):
                residence_times(run, window)
        with pytest.raises(InputError, match="is not \\(start, stop\\) in s"):
            flux_residence_time(run, "26")
        with pytest.raises(InputError, match="is not \\(start, stop\\) in s"):
            mixing_curve_of(run, "26")
        assert residence_times(run, np.array([2.0, 6.0])).window == (2.0, 6.0)
    with pytest.raises(InputError, match="is not \\(start, stop\\) in s"):
        select_model(markov_run, window="2:6", columns=4, rows=16, lag=markov_flow.lag)
    with pytest.raises(InputError, match="folds='x'"):
        select_model(markov_run, window=(2.0, 6.0), columns=4, rows=16,
                     lag=markov_flow.lag, folds="x")


def test_an_rtd_histogram_of_impossible_times_is_refused():
    from cfbmarkov.observed.residence import rtd_histogram

    for samples in ([np.nan, 0.3, 0.61], [-0.3, 0.61]):
        with pytest.raises(InputError, match="1 of .* residence times are not finite "
                                             "numbers >= 0"):
            rtd_histogram(samples, 0.05, window_length=1.0)


def test_a_writer_refuses_velocities_it_does_not_store_and_no_frame(tmp_path):
    from cfbmarkov.trajectory_writer import TrajectoryWriter, write_trajectories

    positions = np.full((1, 2, 2), 0.05)
    with pytest.raises(InputError, match="velocities given to a file made without them"):
        with TrajectoryWriter(tmp_path / "v.h5", np.arange(2), width=0.1, height=0.2,
                              source="test") as w:
            w.append(0.0, positions[0], velocity=np.zeros((2, 2)))
    assert not (tmp_path / "v.h5").exists()
    with pytest.raises(InputError, match="no frame to append"):
        write_trajectories(tmp_path / "e.h5", np.zeros(0), np.zeros((0, 2, 2)), width=0.1,
                           height=0.2)
    assert not (tmp_path / "e.h5").exists()


def test_a_models_arrays_cannot_be_made_writeable_and_rtd_takes_window_length(
        markov_flow, markov_run):
    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag, (2.0, 6.0), "mle")
    for values in (model.transition_matrix, model.stationary_distribution):
        with pytest.raises(ValueError):
            values.setflags(write=True)
    seen = model.rtd(window_length=2.0)
    assert seen.mean == model.rtd(window=2.0).mean and seen.window == pytest.approx(2.0)
    with pytest.raises(InputError, match="window_length=stop - start"):
        model.rtd(window=model.window)
    with pytest.raises(InputError, match="once"):
        model.rtd(window=2.0, window_length=2.0)
    assert dataclasses.is_dataclass(model)


def test_an_interval_with_no_room_on_one_side_is_read_as_one_sided(markov_flow, markov_run):
    """A bootstrap whose resamples lie nearly all above the fitted chain's E(RT) gives an
    interval whose lower end is the figure itself (0.4750-0.7089 s on 0.4751 s on a LAMMPS
    riser), printed with no word; the model now says it is one-sided and the figure likely
    low. A two-sided interval says nothing."""
    from cfbmarkov.markov.model_summary import one_sided_interval_warnings
    from cfbmarkov.analysis.fit_checks import assess_fit

    model = assess_fit(fit_model(markov_run, markov_flow.grid, markov_flow.lag, (2.0, 6.0),
                                 "mle"), resamples=20, verdict=False)
    assert one_sided_interval_warnings(model) == []
    mean = model.rtd().mean
    skewed = dataclasses.replace(model, uncertainty=dataclasses.replace(
        model.uncertainty, rt_mean_interval=(mean - 1e-4, mean + 0.2)))
    lines = one_sided_interval_warnings(skewed)
    assert len(lines) == 1 and lines[0].startswith("the E(RT) interval ")
    assert "almost no lower side" in lines[0] and "nothing of the other side" in lines[0]
    assert lines[0] in skewed.warnings()


def test_a_fractional_lag_and_mismatched_arrays_are_refused(window):
    """lag_frames=1.5 counted one-frame transitions labelled with a 1.5-frame lag (E(RT)
    1.5 times too long): refused, as are a state space that is none, positions or laps of
    another shape, a height other than the grid's and a window holding none of the frames;
    a lag computed as a quotient (0.3 / 0.1 = 2.9999999999999996) is taken as 3."""
    def made(**changes):
        given = {"states": np.array(window.states), "vertical": np.array(window.vertical),
                 "times": np.array(window.times), "lag_frames": window.lag_frames,
                 "frame_interval": window.frame_interval, "height": window.height,
                 "state_space": window.state_space, "window": window.window}
        given.update(changes)
        return DiscreteTrajectories(**given)

    shape = window.states.shape
    for changes, message in (
            ({"lag_frames": 1.5}, r"lag of 1.5 frames: a whole number of frames"),
            ({"lag_frames": True}, r"lag of True frames"),
            ({"state_space": (6, 38)}, r"state_space \(6, 38\) is no state space"),
            ({"positions": np.zeros(shape + (3,))[:, :-1]}, r"positions .* for states"),
            ({"laps": np.zeros((shape[0], 5), int)}, r"laps \(.*, 5\) of type"),
            ({"height": 950.0}, r"height 950 m, but the state space's grid is 0.95 m high"),
            ({"window": (100.0, 200.0)}, r"window 100:200 s holds none of the frames")):
        with pytest.raises(InputError, match=message):
            made(**changes)
    assert made(lag_frames=0.3 / 0.1 * window.lag_frames / 3).lag_frames == window.lag_frames
