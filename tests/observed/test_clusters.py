"""The cluster index of snapshots: exact for constructed frames, about 1 for independent
uniform particles, and reported by compare for both sides."""

import numpy as np
import pytest

from cfbmarkov.observed.clusters import cluster_index
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

W, H = 0.09, 0.95


def test_index_of_dispersion_is_exact_for_constructed_frames(tmp_path):
    columns, rows, n = 3, 4, 24
    clump = np.tile([[0.01, 0.01]], (n, 1))                     # every particle in one cell
    centres = np.array([[(c + 0.5) * W / columns, (r + 0.5) * H / rows]
                        for r in range(rows) for c in range(columns)])
    even = np.concatenate([centres, centres])                    # two per cell
    path = write_trajectories(tmp_path / "c.h5", [0.0, 0.1], np.stack([clump, even]),
                              width=W, height=H)
    with Trajectories(path) as t:
        one = cluster_index(t, slice(0, 1), columns, rows)[0]
        two = cluster_index(t, slice(1, 2), columns, rows)[0]
        both = cluster_index(t, slice(0, 2), columns, rows)
    cells = columns * rows
    assert one == pytest.approx((n / cells) * (cells - 1), rel=1e-12)
    assert two == 0.0
    assert both[0] == pytest.approx(0.5 * one) and both[1] == pytest.approx(one / np.sqrt(2))


def test_independent_uniform_particles_give_about_one(tmp_path):
    rng = np.random.default_rng(1)
    pos = rng.uniform([0, 0], [W, H], size=(40, 2000, 2))
    path = write_trajectories(tmp_path / "u.h5", np.arange(40) * 0.01, pos, width=W, height=H)
    with Trajectories(path) as t:
        mean, sd = cluster_index(t, slice(0, 40), 6, 38)
    assert mean == pytest.approx(1.0, abs=0.05) and 0 < sd < 0.3


def test_snapshot_index_equals_numpy_and_maps_states_to_cells():
    """The kernel's integer sums give numpy's var / mean of the counts, absent particles
    and empty frames included, and ``cell_of_state`` equals mapping the states first."""
    from cfbmarkov.observed.clusters import snapshot_cluster_index

    rng = np.random.default_rng(3)
    n_cells, n_states = 12, 36
    states = rng.integers(-1, n_states, size=(9, 500))
    states[4] = -1                                              # an empty frame
    cell_of_state = rng.integers(0, n_cells, size=n_states)
    cells = np.where(states >= 0, cell_of_state[np.maximum(states, 0)], -1)
    counts = np.stack([np.bincount(row[row >= 0], minlength=n_cells) for row in cells])
    with np.errstate(invalid="ignore"):
        expected = counts.var(axis=1) / counts.mean(axis=1)
    got = snapshot_cluster_index(cells, n_cells)
    assert np.isnan(got[4]) and np.isnan(expected[4])
    keep = np.arange(9) != 4
    assert np.allclose(got[keep], expected[keep], rtol=1e-12, atol=0)
    assert np.array_equal(snapshot_cluster_index(states, n_cells, cell_of_state), got,
                          equal_nan=True)
    with pytest.raises(ValueError, match="outside the grid"):
        snapshot_cluster_index(states, n_cells)                  # states are not cells


def test_a_position_on_a_cell_edge_is_in_the_cell_the_models_states_give():
    """0.29 m on rows of 0.01 m is row 29 by the states' edge rule (28.999999999999996 in
    floating point): the cluster index counts it there, as the model's cells do."""
    import tempfile
    from pathlib import Path

    from cfbmarkov.markov.cells import EDGE_TOLERANCE, cell_index
    from cfbmarkov.observed import clusters

    assert clusters.EDGE_TOLERANCE == EDGE_TOLERANCE
    pos = np.array([[0.01, 0.29], [0.01, 0.29], [0.01, 0.295], [0.01, 0.295]])
    assert set(cell_index(pos, 0.04, 1.0, 2, 100)) == {58}          # all in row 29
    with tempfile.TemporaryDirectory() as folder:
        path = write_trajectories(Path(folder) / "e.h5", [0.0], pos[None], width=0.04,
                                  height=1.0)
        with Trajectories(path) as t:
            index = cluster_index(t, slice(0, 1), 2, 100)[0]
    cells = 200
    assert index == pytest.approx((4 / cells) * (cells - 1), rel=1e-12)   # one cell: 3.98
