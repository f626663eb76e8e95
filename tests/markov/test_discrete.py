"""The discrete-trajectory layer: windows, history frames, blocks, absent particles."""

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.markov import (ABSENT, CellGrid, DirectionCells, DiscreteTrajectories,
                              count_transitions, discretize, discretize_frame, read_frames)
from cfbmarkov.trajectories import Trajectories


def _cells(write_states, tmp_path, states, rows=4):
    return write_states(tmp_path / "s.h5", states, columns=1, rows=rows, height=float(rows))


def test_window_states_times_and_lag_in_frames(tmp_path, write_states):
    path = _cells(write_states, tmp_path, [[0, 1], [1, 2], [2, 3], [3, 0], [0, 1]])
    grid = CellGrid(1, 4, 1.0, 4.0)
    d = discretize(path, grid, 2.0, (1.0, 4.0))
    np.testing.assert_array_equal(d.states, [[1, 2], [2, 3], [3, 0], [0, 1]])
    np.testing.assert_array_equal(d.times, [1.0, 2.0, 3.0, 4.0])
    assert (d.lag_frames, d.frame_interval, d.lag, d.window) == (2, 1.0, 2.0, (1.0, 4.0))
    np.testing.assert_allclose(d.vertical, d.states + 0.5)
    # the deeptime layout: one sequence per particle
    assert [list(t) for t in d.trajectories()] == [[1, 2, 3, 0], [2, 3, 0, 1]]
    with pytest.raises(InputError, match="fewer than two frames one lag"):
        discretize(path, grid, 2.0, (1.0, 2.0))


def test_history_frames_are_read_and_dropped(tmp_path, write_states):
    """A direction state needs the frame one lag before: the window's first state uses it,
    and the window starts where asked; without history before it, it is refused, unless
    the window is 'all frames' (which then starts at the first frame that has history)."""
    # one particle rising one row per frame on 1 x 4 cells, one falling
    path = _cells(write_states, tmp_path, [[0, 3], [1, 2], [2, 1], [3, 0], [0, 3]])
    space = DirectionCells(1, 4, 1.0, 4.0)
    d = discretize(path, space, 1.0, (1.0, 4.0))
    assert d.n_frames == 4 and d.times[0] == 1.0
    np.testing.assert_array_equal(space.falling(d.states[:, 0]), False)   # rising throughout
    np.testing.assert_array_equal(space.falling(d.states[:, 1]), True)
    with pytest.raises(InputError, match="history"):
        discretize(path, space, 1.0, (0.0, 4.0))
    everything = discretize(path, space, 1.0)
    assert everything.times[0] == 1.0 and everything.n_frames == 4
    # the frames read once serve every state space; too little history moves the start
    with Trajectories(path) as traj:
        frames = read_frames(traj, (0.0, 4.0), 1, short_history="skip")
        assert frames.history == 0
        moved = frames.discretize(space, 1)
        assert moved.times[0] == 1.0 and moved.window == (1.0, 4.0)
        cells = frames.discretize(CellGrid(1, 4, 1.0, 4.0), 1)
        assert cells.times[0] == 0.0 and cells.window == (0.0, 4.0)
    first = discretize_frame(path, space, 1.0, 2.0)
    assert first.n_frames == 1 and first.positions.shape == (1, 2, 2)
    np.testing.assert_array_equal(first.states[0], d.states[1])
    with pytest.raises(InputError, match="history"):
        discretize_frame(path, space, 1.0, 0.0)


def test_blocks_select_frames_without_rereading(tmp_path, write_states):
    path = _cells(write_states, tmp_path, [[k % 4] for k in range(11)])
    d = discretize(path, CellGrid(1, 4, 1.0, 4.0), 1.0, (0.0, 10.0))
    b = d.block(2.0, 5.0)
    np.testing.assert_array_equal(b.times, [2.0, 3.0, 4.0, 5.0])
    np.testing.assert_array_equal(b.states[:, 0], [2, 3, 0, 1])
    assert b.window == (2.0, 5.0) and b.lag_frames == d.lag_frames
    # the blocks' counts add up to the window's where the blocks share their edges
    whole = count_transitions(d)
    parts = count_transitions(d.block(0.0, 5.0)) + count_transitions(d.block(5.0, 10.0))
    np.testing.assert_array_equal(whole.counts, parts.counts)
    assert whole.frame_pairs == parts.frame_pairs == 10
    with pytest.raises(InputError, match="fewer than two frames"):
        d.block(3.0, 3.0)


def test_transitions_with_an_absent_end_are_not_counted():
    """State -1 marks an absent particle (the layout ready for presence masks)."""
    grid = CellGrid(1, 2, 1.0, 2.0)
    states = np.array([[0, 0, 1],
                       [1, ABSENT, 1],
                       [1, 0, ABSENT]], np.int32)
    d = DiscreteTrajectories(states=states, vertical=states + 0.5, times=np.arange(3.0),
                             lag_frames=1, frame_interval=1.0, height=2.0, state_space=grid)
    c = count_transitions(d)
    # pairs: t0->t1: 0->1, (0->absent), 1->1 ; t1->t2: 1->1, (absent->0), (1->absent)
    np.testing.assert_array_equal(c.counts, [[0, 1], [0, 2]])
    # P'(t) rows are normalised over particles present at both ends
    np.testing.assert_allclose(c.frame_average_sum, [[0, 1], [0, 2]])
    np.testing.assert_array_equal(c.occupied_frames, [1, 2])


def test_discrete_trajectories_refuse_inconsistent_arrays():
    grid = CellGrid(1, 2, 1.0, 2.0)
    ok = dict(states=np.zeros((3, 2), np.int32), vertical=np.zeros((3, 2)),
              times=np.arange(3.0), lag_frames=1, frame_interval=1.0, height=2.0,
              state_space=grid)
    for change, match in ((dict(vertical=np.zeros((3, 3))), "heights"),
                          (dict(times=np.arange(2.0)), "times"),
                          (dict(lag_frames=0), "at least 1"),
                          (dict(frame_interval=float("nan")), "frame interval")):
        with pytest.raises(InputError, match=match):
            DiscreteTrajectories(**{**ok, **change})
