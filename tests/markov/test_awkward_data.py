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


def _one_tracer(path, period, n=400, dt=0.01):
    """One particle rising one H = 1 m lap every ``period`` frames: all residence times
    are equal, and their SD is round-off (about 1.5e-16 s)."""
    from cfbmarkov.trajectory_writer import write_trajectories

    y = (np.arange(n) % period + 0.5) / period
    pos = np.stack([np.full(n, 0.05), y], axis=-1)[:, None, :]
    return write_trajectories(path, dt * np.arange(n), pos, width=0.1, height=1.0)


def test_percentage_difference_of_round_off_is_undefined(tmp_path, capsys):
    """A reference SD(RT) that is zero to round-off has no PD: null in summary.json, 'n/d'
    in the CLI line, a warning that says why; the PD of E(RT) stays a number."""
    import json

    from cfbmarkov.analysis.metrics import percentage_difference
    from cfbmarkov.cli import main
    from cfbmarkov.report.compare import compare

    assert np.isnan(percentage_difference(1.9e-16, 2.2e-16, scale=0.37))
    assert percentage_difference(0.3, 0.2, scale=0.37) == pytest.approx(50.0)
    assert np.isnan(percentage_difference(1.0, 0.0))
    ref, pred = _one_tracer(tmp_path / "ref.h5", 37), _one_tracer(tmp_path / "pred.h5", 29)
    summary = compare(ref, pred, window=(0.0, 3.99), output=tmp_path / "cmp", figures=False)
    assert 0 < summary["reference"]["rt_sd"] < 1e-15
    assert np.isnan(summary["pd_rt_sd"])
    assert summary["pd_rt_mean"] == pytest.approx(100 * (0.29 / 0.37 - 1))
    saved = json.loads((tmp_path / "cmp" / "summary.json").read_text())
    assert saved["pd_rt_sd"] is None
    assert any("zero to round-off" in w for w in saved["warnings"])
    assert main(["compare", str(ref), str(pred), "--window", "0:3.99", "-o",
                 str(tmp_path / "cli"), "--no-figures"]) == 0
    assert "SD(RT) PD n/d %" in capsys.readouterr().out
