"""A Markov core that is right on awkward data: each case with its hand-computed value."""

import numpy as np
import pytest

from cfbmarkov.markov import CellGrid, cell_index


@pytest.mark.parametrize("columns, rows, width, height, step", [
    (9, 95, 0.09, 0.95, 0.001),          # the paper's CFD grid: 0.01 m cells
    (6, 38, 0.09, 0.95, 0.001),          # the paper's Markov grid: 0.015 x 0.025 m cells
    (10, 10, 1.0, 1.0, 0.01),
    (3, 7, 0.3, 0.7, 0.01),
])
def test_positions_on_decimal_edges_land_in_the_cell_above(columns, rows, width, height, step):
    """0.29 x 95 / 0.95 = 28.999999999999996: a position on an edge written in decimals
    must land in the cell above it, so every row and column gets the same number of the
    evenly spaced decimal positions (before: 9 or 11 of every 10 on the 9 x 95 grid)."""
    ys = np.round(np.arange(0.0, height - step / 2, step), 6)
    xs = np.round(np.arange(0.0, width - step / 2, step), 6)
    pos = np.stack(np.broadcast_arrays(xs[:, None], ys[None, :]), axis=-1).reshape(-1, 2)
    cells = cell_index(pos, width, height, columns, rows)
    per_row = np.bincount(cells // columns, minlength=rows)
    per_column = np.bincount(cells % columns, minlength=columns)
    assert np.all(per_row == per_row[0]) and per_row.sum() == cells.size
    assert np.all(per_column == per_column[0])
    # an edge itself is in the cell above; a point just below it (1e-6 of a cell) is not
    edge = 29 * 0.01
    assert cell_index(np.array([[0.005, 0.29]]), 0.09, 0.95, 9, 95)[0] // 9 == 29
    assert cell_index(np.array([[0.005, edge - 1e-8]]), 0.09, 0.95, 9, 95)[0] // 9 == 28
    assert CellGrid(9, 95).discretize(np.array([[0.005, 0.57], [0.005, 0.58]])).tolist() \
        == [57 * 9, 58 * 9]


@pytest.mark.parametrize("matrix, expected", [
    ([[0.0, 1.0], [1.0, 0.0]], [np.inf]),                              # periodic: lambda = -1
    ([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]], [np.inf, np.inf]),   # period 3
    ([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.3, 0.3, 0.4]],              # two absorbing states
     [np.inf, -0.05 / np.log(0.4)]),
])
def test_implied_timescale_of_a_unit_eigenvalue_is_plus_infinity(matrix, expected):
    """-lag / ln|lambda| with |lambda| = 1 is +inf (a mode that never decays), not -inf."""
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.diagnostics import model_timescales

    p = np.asarray(matrix)
    zeros = np.zeros_like(p, dtype=np.int64)
    model = MarkovModel(p, zeros, zeros, zeros, CellGrid(1, p.shape[0], 0.1, 1.0), 0.05)
    its = model_timescales(model, k=len(expected), connected=False)
    np.testing.assert_allclose(its.timescales[0], expected, rtol=1e-12)
    assert np.all(its.timescales[0] > 0)
