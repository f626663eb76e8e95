"""3D cells: depth columns of CellGrid, the projection of 3D data on a 2D grid, and the verbs
(fit, rtd, maps, predict, compare, export-vtk) on a 3D periodic run."""

from pathlib import Path

import h5py
import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.cli import main, parse_cells
from cfbmarkov.errors import InputError
from cfbmarkov.markov import CellGrid, MarkovModel, discretize, place_in_cells
from cfbmarkov.markov.cells import cell_index
from cfbmarkov.markov.spaces import state_space_from_attrs, state_space_from_name
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

DEPTH = 0.02
OLD_MODEL = Path(__file__).parent / "data" / "model_2d_before_3d_cells.h5"


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    """A small synthetic 2D periodic run and the same run with a random depth coordinate."""
    folder = tmp_path_factory.mktemp("cells3d")
    flow = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)
    run2 = synthetic.write_run(folder / "run2.h5", flow, 300, 4.0, seed=5)
    with Trajectories(run2) as t:
        times, pos, laps = t.times, t.positions(), t.laps()
    z = np.random.default_rng(1).uniform(0.0, DEPTH, pos.shape[:2] + (1,))
    run3 = write_trajectories(folder / "run3.h5", times, np.concatenate([pos, z], -1),
                              width=flow.width, height=flow.height, depth=DEPTH, laps=laps)
    return run2, run3


# -- numbering ------------------------------------------------------------------------------
def test_numbering_round_trip_and_bottom_row():
    m, d, n = 3, 4, 5
    grid = CellGrid(m, n, 0.3, 0.5, depth_columns=d, depth=0.4)
    assert grid.n_states == grid.n_cells == m * d * n and grid.cells_per_row == m * d
    col, lay, row = np.meshgrid(np.arange(m), np.arange(d), np.arange(n), indexing="ij")
    centres = np.stack([(col + 0.5) * 0.1, (row + 0.5) * 0.1, (lay + 0.5) * 0.1], -1)
    states = grid.discretize(centres.reshape(-1, 3))
    np.testing.assert_array_equal(states, ((row * d + lay) * m + col).ravel())
    assert np.unique(states).size == grid.n_states
    # state -> cell centre -> state, and Monte Carlo placement stays in the cell
    s = np.arange(grid.n_states)
    placed = place_in_cells(s, grid, seed=3, step=2)
    assert placed.shape == (grid.n_states, 3)
    np.testing.assert_array_equal(grid.discretize(placed), s)
    # the bottom row is 0 .. m*d - 1, and the inlet spreads evenly over it
    inlet = grid.inlet_distribution()
    np.testing.assert_allclose(inlet[: m * d], 1.0 / (m * d))
    assert not inlet[m * d:].any()
    # one depth column: numbered as the 2D grid
    one = CellGrid(m, n, 0.3, 0.5, depth_columns=1, depth=0.4)
    np.testing.assert_array_equal(one.discretize(centres.reshape(-1, 3)),
                                  CellGrid(m, n, 0.3, 0.5).discretize(centres.reshape(-1, 3)))


def test_cell_maps_sum_over_depth_or_by_depth():
    grid = CellGrid(2, 3, 1.0, 1.0, depth_columns=2, depth=1.0)
    dist = np.arange(grid.n_states, dtype=float)
    by_depth = grid.cell_maps(dist, by_depth=True)
    assert by_depth.shape == (2, 3, 2)
    for s in range(grid.n_states):     # state (row*d + k)*m + col sits at [k, row, col]
        col, rest = s % 2, s // 2
        assert by_depth[rest % 2, rest // 2, col] == s
    np.testing.assert_array_equal(grid.cell_maps(dist), by_depth.sum(axis=0))
    assert grid.cell_maps(np.stack([dist, dist])).shape == (2, 3, 2)


def test_depth_column_confinement(tmp_path):
    """Particles confined to depth column k of a 3D file get states only in that column."""
    rng = np.random.default_rng(4)
    m, d, n, k = 3, 4, 6, 2
    pos = rng.uniform(0, 1, (5, 40, 3)) * [0.3, 0.6, 1.0]
    pos[..., 2] = (k + rng.uniform(0.01, 0.99, pos.shape[:2])) * DEPTH / d
    path = write_trajectories(tmp_path / "layer.h5", 0.1 * np.arange(5), pos, width=0.3,
                              height=0.6, depth=DEPTH)
    grid = CellGrid(m, n, 0.3, 0.6, depth_columns=d, depth=DEPTH)
    states = discretize(path, grid, 0.1).states
    assert np.all((states // m) % d == k)
    assert set(np.unique(states % m)) == set(range(m))


def test_2d_grid_on_3d_data_is_the_projection(runs):
    run2, run3 = runs
    for space in (CellGrid(4, 16, 0.09, 0.95),
                  state_space_from_name("cells-direction", 4, 16, 0.09, 0.95)):
        a = discretize(run2, space, 0.05, (0.5, 3.0))
        b = discretize(run3, space, 0.05, (0.5, 3.0))
        np.testing.assert_array_equal(a.states, b.states)
    from cfbmarkov.markov import fit_model

    fa = fit_model(run2, CellGrid(4, 16, 0.09, 0.95), 0.05, (0.5, 3.0))
    fb = fit_model(run3, CellGrid(4, 16, 0.09, 0.95), 0.05, (0.5, 3.0))
    np.testing.assert_array_equal(fa.counts, fb.counts)
    np.testing.assert_array_equal(fa.transition_matrix, fb.transition_matrix)
    # cell_index projects 3D positions without a depth
    pos = np.random.default_rng(0).uniform(0, 1, (7, 3))
    np.testing.assert_array_equal(cell_index(pos, 1, 1, 3, 4), cell_index(pos[:, :2], 1, 1, 3, 4))


def test_3d_grid_refuses_2d_positions_and_data(runs):
    grid = CellGrid(4, 16, 0.09, 0.95, depth_columns=2, depth=DEPTH)
    with pytest.raises(InputError, match="needs 3D positions"):
        grid.discretize(np.zeros((3, 2)))
    with pytest.raises(InputError, match="is 2D"):
        discretize(runs[0], grid, 0.05)
    with pytest.raises(InputError, match="depth of 0.03 m.*: give a run of the riser the "
                                         "model was fitted on, or fit a model on this one"):
        discretize(runs[1], CellGrid(4, 16, 0.09, 0.95, depth_columns=2, depth=0.03), 0.05)
    with pytest.raises(InputError, match=r"2 depth column\(s\) need 3D data .*: give a 3D "
                                         "file, or cells as COLUMNSxROWS"):
        state_space_from_name("cells", 4, 16, 0.09, 0.95, 2, None)
    with pytest.raises(InputError, match="need the riser's depth"):
        CellGrid(4, 16, depth_columns=2)
    with pytest.raises(InputError, match="positive size"):
        CellGrid(4, 16, depth_columns=2, depth=0.0)
    with pytest.raises(InputError, match="no depth columns yet"):
        state_space_from_name("cells-velocity", 4, 16, 0.09, 0.95, 2, DEPTH)


def test_parse_cells():
    assert parse_cells("6x38") == (6, 38)
    assert parse_cells("6X3x38") == (6, 3, 38)
    for bad in ("6", "6x0x38", "6x3x38x2", "axb"):
        with pytest.raises(Exception, match="cells"):
            parse_cells(bad)


# -- model files ------------------------------------------------------------------------------
def test_model_save_load_3d_grid(tmp_path, runs):
    from cfbmarkov.markov import fit_model

    grid = CellGrid(4, 16, 0.09, 0.95, depth_columns=3, depth=DEPTH)
    model = fit_model(runs[1], grid, 0.05, (0.5, 3.0))
    model.save(tmp_path / "m.h5")
    back = MarkovModel.load(tmp_path / "m.h5")
    assert back.state_space == grid and back.state_space.depth_columns == 3
    assert back.state_space.depth == DEPTH
    np.testing.assert_array_equal(back.transition_matrix, model.transition_matrix)
    assert "cells 4x3x16 (192 states)" in back.summary()
    assert state_space_from_attrs(grid.to_attrs()) == grid
    assert repr(grid) == "CellGrid(4, 16, width=0.09, height=0.95, depth_columns=3, depth=0.02)"


def test_old_2d_model_files_load_unchanged():
    """A model file written by cfbmarkov before depth columns existed."""
    model = MarkovModel.load(OLD_MODEL)
    space = model.state_space
    assert type(space) is CellGrid and not space.is_3d and space.depth_columns == 1
    assert (space.columns, space.rows, space.n_states) == (2, 4, 8)
    with h5py.File(OLD_MODEL) as f:
        import json

        stored = json.loads(f.attrs["state_space"])
    assert space.to_attrs() == stored        # a 2D grid saves exactly as before
    assert space.describe() == "cells 2x4 (8 states)"


# -- the verbs on a 3D periodic run ----------------------------------------------------------
def test_fit_rtd_maps_predict_compare_vtk_on_3d_run(tmp_path, capsys, runs, monkeypatch):
    _, run3 = runs
    model = tmp_path / "m3.h5"
    code, out, _ = run_cli(capsys, "fit", run3, "--cells", "4x2x16", "--lag", "0.05",
                           "--window", "0.5:3", "-o", model)
    assert code == 0 and "cells 4x2x16 (128 states)" in out
    code, out, _ = run_cli(capsys, "rtd", model)
    assert code == 0 and "E(RT)" in out
    code, out, _ = run_cli(capsys, "maps", model, "--times", "0.05,0.1", "-o", tmp_path / "maps.png")
    assert code == 0 and (tmp_path / "maps.png").stat().st_size > 0
    assert "fraction in riser 1.0000" in out
    pred = tmp_path / "p3.h5"
    code, _, _ = run_cli(capsys, "predict", model, "--init", run3, "--start", "1", "--duration",
                         "2", "--seed", "4", "-o", pred, "--quiet")
    assert code == 0
    grid = MarkovModel.load(model).state_space
    with Trajectories(pred) as p, Trajectories(run3) as r:
        assert p.dimensions == 3 and p.depth == pytest.approx(DEPTH)
        np.testing.assert_array_equal(p.positions(0), r.positions(r.frame_index(1.0)))
        later = p.positions(slice(1, None))
        assert later.shape[-1] == 3 and np.all((later >= 0) & (later <= [0.09, 0.95, DEPTH]))
        attrs = p.attrs
    assert '"depth_columns": 2' in attrs["parameters"]
    # every later position lies in the 3D cell of its Monte Carlo state (same seed, same run)
    _, states, _ = MarkovModel.load(model).predict(run3, start=1.0, duration=2.0, seed=4)
    np.testing.assert_array_equal(grid.discretize(later), states[1:])
    import cfbmarkov.report.figures as figures

    titles = []
    drawn = figures.plot_probability_maps
    monkeypatch.setattr(figures, "plot_probability_maps",
                        lambda *a, **k: (titles.append(k.get("title")), drawn(*a, **k))[1])
    code, out, err = run_cli(capsys, "compare", run3, pred, "--window", "1:3", "-o",
                             tmp_path / "cmp")
    assert code == 0, err
    assert (tmp_path / "cmp" / "summary.json").exists()
    assert (tmp_path / "cmp" / "probability_maps.png").exists()
    # the maps are the depth's sums, and the title says so, as `maps` does
    assert len(titles) == 1 and "summed over the depth" in titles[0]
    code, out, err = run_cli(capsys, "export-vtk", pred, "-o", tmp_path / "vtk", "--quiet",
                             "--every", "20")
    assert code == 0, err
    assert (tmp_path / "vtk" / "particles_000020.vtu").exists()


def test_predict_2d_grid_on_3d_run_draws_depth_uniformly(tmp_path, capsys, runs):
    _, run3 = runs
    model, pred = tmp_path / "m2.h5", tmp_path / "p.h5"
    assert run_cli(capsys, "fit", run3, "--cells", "4x16", "--lag", "0.05", "--window",
                   "0.5:3", "-o", model)[0] == 0
    assert run_cli(capsys, "predict", model, "--init", run3, "--start", "1", "--duration",
                   "2", "-o", pred, "--quiet")[0] == 0
    with Trajectories(pred) as p:
        z = p.positions(slice(1, None))[..., 2]
        assert p.dimensions == 3
    assert z.min() >= 0 and z.max() <= DEPTH
    assert abs(z.mean() - DEPTH / 2) < 0.05 * DEPTH       # uniform over the depth
    # across and vertical draws are those of the 2D placement
    s = np.arange(64)
    grid = CellGrid(4, 16, 0.09, 0.95)
    np.testing.assert_array_equal(place_in_cells(s, grid, 1, 2, depth=DEPTH)[:, :2],
                                  place_in_cells(s, grid, 1, 2))


def test_3d_cells_on_2d_file_refused_in_one_line(tmp_path, capsys, runs):
    out = tmp_path / "m.h5"
    code, _, err = run_cli(capsys, "fit", runs[0], "--cells", "4x2x16", "--window", "0.5:3",
                           "-o", out)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "is 2D" in err
    assert not out.exists()
    code, _, err = run_cli(capsys, "fit", runs[1], "--cells", "4x2x16", "--states",
                           "cells-previous", "--window", "0.5:3", "-o", out)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "no depth columns" in err


def test_compare_refuses_2d_against_3d(tmp_path, capsys, runs):
    code, _, err = run_cli(capsys, "compare", runs[0], runs[1], "--window", "1:3", "-o",
                           tmp_path / "cmp", "--no-figures")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "3D" in err


def test_a_rate_table_cell_outside_a_3d_grid_names_its_depth():
    """col 0, row 0 is a cell of the grid; its depth 4 is not: the refusal names the depth
    and its range, not a cell that looks valid."""
    from cfbmarkov.errors import InputError
    from cfbmarkov.kinetics.fields import ByCell

    grid = CellGrid(2, 3, 1.0, 1.0, depth_columns=2, depth=1.0)
    rows = [(c, r, k, 1.0) for r in range(3) for k in range(2) for c in range(2)]
    ByCell(np.array(rows, dtype=float)).per_cell(grid)            # the whole grid: accepted
    rows[0] = (0, 0, 4, 1.0)
    with pytest.raises(InputError, match=r"cell col 0, row 0, depth 4 is outside the grid "
                                         r".*\(col 0\.\.1, row 0\.\.2, depth 0\.\.1\)"):
        ByCell(np.array(rows, dtype=float)).per_cell(grid)


def test_a_particles_depth_is_drawn_apart_from_its_pass(tmp_path):
    """A 3D prediction on rows so coarse that a move from the upper to the lower half is a
    pass up through the top or a fall: the particle's depth in its cell after the move is
    uniform whether it passed or fell (it was drawn from the pass direction's own random
    stream, which put the passes at the front of the cell and the falls at the back)."""
    from scipy import stats

    from cfbmarkov.markov import fit_model

    run = synthetic.write_run(tmp_path / "r2.h5", synthetic.RiserFlow(), 300, 12.0, seed=2)
    with Trajectories(run) as t:
        times, positions, laps = t.times[:], t.positions(), t.laps()
        width, height = t.width, t.height
    depth = np.random.default_rng(0).uniform(0.0, 0.03, positions.shape[:2])
    run3d = write_trajectories(tmp_path / "r3.h5", times, np.concatenate(
        [positions, depth[..., None]], axis=2), width=width, height=height, depth=0.03,
        laps=laps)
    model = fit_model(run3d, CellGrid(6, 2, width, height, depth_columns=1, depth=0.03),
                      0.025, (2.0, 10.0))
    pred = model.predict(run3d, 10.0, 2.0, seed=4, output=tmp_path / "p.h5")
    with Trajectories(pred) as p:
        y, z, lap = p.positions()[..., 1] / height, p.positions()[..., 2] / 0.03, p.laps()
    moved = (y[:-1] >= 0.5) & (y[1:] < 0.5)
    passed = np.diff(lap, axis=0) == 1
    after_pass, after_fall = z[1:][moved & passed], z[1:][moved & ~passed]
    assert after_pass.size > 200 and after_fall.size > 200
    assert stats.ks_2samp(after_pass, after_fall).pvalue > 1e-3
    assert abs(after_pass.mean() - 0.5) < 0.05 and abs(after_fall.mean() - 0.5) < 0.05
