"""A state space made without the riser's size takes the size of the file it is fitted on;
one made with a size refuses a file of another size (never a silent mis-binning)."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.markov import CellGrid, DirectionCells, fit_model, state_space_from_name
from cfbmarkov.trajectory_writer import write_trajectories

WIDTH, HEIGHT = 0.04, 0.3


@pytest.fixture
def small_riser(tmp_path):
    """A 0.04 x 0.3 m periodic riser: 60 particles rising through it, frames 0.01 s apart."""
    rng = np.random.default_rng(3)
    times = 0.01 * np.arange(201)
    x = rng.uniform(0.001, WIDTH - 0.001, 60)
    y0 = rng.uniform(0.0, HEIGHT, 60)
    speed = rng.uniform(0.5, 1.5, 60)
    y = y0 + speed * times[:, None] + np.cumsum(rng.normal(0, 0.003, (201, 60)), axis=0)
    positions = np.stack([np.broadcast_to(x, y.shape), np.mod(y, HEIGHT)], axis=-1)
    return write_trajectories(tmp_path / "small.h5", times, positions, width=WIDTH,
                              height=HEIGHT, source="cfd-dem")


@pytest.mark.parametrize("make", [lambda: CellGrid(4, 12), lambda: DirectionCells(4, 12),
                                  lambda: state_space_from_name("cells-velocity", 4, 12)])
def test_a_space_without_a_size_takes_the_files(small_riser, make):
    space = make()
    assert not space.sized
    model = fit_model(small_riser, space, 0.01, (0.1, 2.0), "mle")
    assert (model.state_space.width, model.state_space.height) == (WIDTH, HEIGHT)
    # every particle rises through the whole riser: all 4 x 12 cells are visited
    assert model.state_space.kind == space.kind
    cells = model.state_space.cell_of_state
    visited = np.unique(cells[np.asarray(model.counts).sum(axis=1) > 0])
    assert visited.size == 48


def test_a_space_with_another_size_is_refused_naming_both(small_riser):
    with pytest.raises(InputError, match=r"covers 0.09 x 0.95 m but .*small.h5 is 0.04 x "
                                         r"0.3 m"):
        fit_model(small_riser, CellGrid(4, 12, 0.09, 0.95), 0.01, (0.1, 2.0), "mle")


def test_explicit_sizes_keep_their_attributes(small_riser):
    given = fit_model(small_riser, CellGrid(4, 12, WIDTH, HEIGHT), 0.01, (0.1, 2.0), "mle")
    taken = fit_model(small_riser, CellGrid(4, 12), 0.01, (0.1, 2.0), "mle")
    assert given.state_space.to_attrs() == taken.state_space.to_attrs() == {
        "kind": "cells", "columns": 4, "rows": 12, "width": WIDTH, "height": HEIGHT}
    np.testing.assert_array_equal(given.transition_matrix, taken.transition_matrix)
    with pytest.raises(InputError, match="width and height, or neither"):
        CellGrid(4, 12, 0.04)
    with pytest.raises(InputError, match="no riser size"):
        CellGrid(4, 12).discretize(np.zeros((3, 2)))
