"""A Markov core that is right on awkward data: each case with its hand-computed value."""

import dataclasses

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
    assert CellGrid(9, 95, 0.09, 0.95).discretize(np.array([[0.005, 0.57], [0.005, 0.58]])).tolist() \
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

    from cfbmarkov.observed.metrics import percentage_difference
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


# -- reducible chains, traps and trapped residences ------------------------------------------
def _two_speed_run(tmp_path, write_states, frames=800):
    """Two particles that never share a cell of a 2 x 38 grid (0.09 x 0.95 m, frames every
    0.025 s): one rises 2 rows per frame in column 0 (a lap every 0.475 s), the other 1 row
    per frame in column 1 (0.95 s)."""
    t = np.arange(frames)
    states = np.stack([((2 * t) % 38) * 2, (t % 38) * 2 + 1], axis=1)
    return write_states(tmp_path / "two.h5", states, columns=2, rows=38, width=0.09,
                        height=0.95, dt=0.025)


def test_reducible_chain_exact_rtd_weights_classes_by_their_flux(tmp_path, write_states):
    """The right E(RT) is the flux-weighted mean of 0.475 s and 0.95 s: the fast particle
    completes twice as many residences, so 2/(1/0.475 + 1/0.95) = 0.6333 s (SD 0.2239 s);
    an arbitrary eigenvector of the reducible entry chain gave 0.475 s, SD 0."""
    from cfbmarkov.markov import fit_model

    run = _two_speed_run(tmp_path, write_states)
    model = fit_model(run, CellGrid(2, 38, 0.09, 0.95), 0.025)
    assert [c.size for c in model.closed_classes] == [38, 19]
    rtd = model.rtd()
    assert rtd.closed_classes == 2
    # observed entries: 42 of the fast particle, 21 of the slow one in 799 transitions
    harmonic = (42 * 0.475 + 21 * 0.95) / 63
    assert rtd.mean == pytest.approx(harmonic, rel=1e-9)
    assert rtd.mean == pytest.approx(0.6333, abs=1e-4)
    assert rtd.sd == pytest.approx(np.sqrt((42 * (0.475 - harmonic) ** 2
                                            + 21 * (0.95 - harmonic) ** 2) / 63), rel=1e-9)
    assert model.rtd(window=20.0).mean == pytest.approx(0.631, abs=2e-3)
    assert "closed classes: 2 (sizes 38, 19)" in model.summary()
    assert "E(RT) = 0.6333 s" in model.summary()


def test_state_entered_in_the_last_frame_is_reported_and_connected_set_frees_it(
        tmp_path, write_states, capsys):
    """Particle 1 steps into column 1 (state 5) in the last frame: state 5 is entered but
    never left, a trap (P_55 = 1) that every state of the ring can reach; --connected fits on
    the largest strongly connected set (the ring of column 0) and nothing is trapped."""
    from cfbmarkov.cli import main
    from cfbmarkov.markov import fit_model

    t = np.arange(41)
    states = np.stack([(t % 4) * 2, ((t + 2) % 4) * 2], axis=1)      # column 0 ring
    states[-1, 1] = 5                                                 # row 2, column 1
    path = write_states(tmp_path / "last.h5", states, columns=2, rows=4)
    grid = CellGrid(2, 4, 1.0, 2.0)
    model = fit_model(path, grid, 1.0)
    assert model.entered_never_left.tolist() == [5]
    assert model.transition_matrix[5, 5] == 1.0
    assert model.trap_share == pytest.approx(1.0)
    pi = model.stationary_distribution
    assert pi[5] == pytest.approx(1.0)                 # the trap takes all the mass
    text = model.summary()
    assert "states entered but never left: 1 of 8 (cell (1,2) as column,row)" in text
    assert "states never visited: 3 of 8 (cells (1,0), (1,1), (1,3) as column,row)" in text
    connected = fit_model(path, grid, 1.0, connected=True)
    assert connected.connected and connected.trap_share == 0.0
    assert ("entered but never left: 1 of 8 (cell (1,2) as column,row): no state that holds "
            "particles in the window leads to those that keep their particles"
            in connected.summary())
    # its row led on (as a state space with memory fills it from its cell's other states):
    # it traps nothing, and the summary says that, not that no state leads to it
    led_on = connected.transition_matrix.copy()
    led_on[5] = 0.0
    led_on[5, 4] = 1.0
    filled = dataclasses.replace(connected, transition_matrix=led_on)
    assert filled.entered_never_left.tolist() == [5] and filled.trap_share == 0.0
    assert ("1 of 8 (cell (1,2) as column,row): their rows lead on (none keeps its "
            "particles), so they trap nothing" in filled.summary())
    assert connected.transition_matrix[:, 5].sum() == 1.0      # only its own row, P_55
    assert connected.stationary_distribution[[0, 2, 4, 6]].sum() == pytest.approx(1.0)
    # the CLI warns in fit (exit 0) and info, and --connected is recorded in the file
    out = tmp_path / "m.h5"
    assert main(["fit", str(path), "--cells", "2x4", "--lag", "1", "--window", "0:40",
                 "-o", str(out)]) == 0
    printed, err = capsys.readouterr()
    assert "warning: states entered but never left: 1 of 8 (cell (1,2) as column,row)" in err
    assert "100.0 %" in err
    assert "never left" not in printed          # each warning once: on stderr, not repeated
    assert main(["info", str(out)]) == 0
    assert "entered but never left" in capsys.readouterr().out
    assert main(["fit", str(path), "--cells", "2x4", "--lag", "1", "--window", "0:40",
                 "--connected", "-o", str(out)]) == 0
    assert "never left" not in capsys.readouterr().err
    from cfbmarkov.markov import MarkovModel
    assert MarkovModel.load(out).connected


def test_maps_feed_no_cell_never_visited_and_runs_repeat_the_trap(tmp_path, write_states,
                                                                   capsys):
    """The ring of column 0 with a trap entered in column 1: column 1's bottom cell was
    never visited, so Eq. (8)'s batch goes to column 0's alone (fed there it would stay in
    place at every time); `maps` says so and, as `predict` does, repeats the trap."""
    from cfbmarkov.cli import main
    from cfbmarkov.markov import fit_model
    from cfbmarkov.markov.propagation import fed_inlet_cells, inlet_batch

    t = np.arange(41)
    states = np.stack([(t % 4) * 2, ((t + 2) % 4) * 2], axis=1)      # column 0 ring
    states[-1, 1] = 5                                                 # row 2, column 1
    path = write_states(tmp_path / "last.h5", states, columns=2, rows=4)
    model = fit_model(path, CellGrid(2, 4, 1.0, 2.0), 1.0)
    assert fed_inlet_cells(model).tolist() == [True, False]
    np.testing.assert_array_equal(inlet_batch(model), np.eye(8)[0])
    maps = model.batch_injection_maps([0.0, 1.0, 4.0])
    assert maps[0, 0].tolist() == [1.0, 0.0]
    assert maps[:, [0, 1, 3], 1].sum() == 0.0 and maps[2, 2, 1] > 0.0   # only the trap
    saved = model.save(tmp_path / "m.h5")
    assert main(["maps", str(saved), "--times", "1,2", "-o", str(tmp_path / "maps.png")]) == 0
    err = capsys.readouterr().err
    assert ("note: the batch is fed over 1 of the 2 bottom cells: cell (1,0) as column,row "
            "was never left in the fitting window (never visited, or entered last)") in err
    assert "warning: the model: states entered but never left: 1 of 8" in err
    assert main(["predict", str(saved), "--init", str(path), "--start", "0", "--duration",
                 "2", "-q", "-o", str(tmp_path / "p.h5")]) == 0
    assert "warning: the model: states entered but never left: 1 of 8" in \
        capsys.readouterr().err
    # a bottom cell entered only in the last frame keeps what it gets (P_ii = 1): left out
    last = states.copy()
    last[-1, 1] = 1                                                   # row 0, column 1
    entered = fit_model(write_states(tmp_path / "entered.h5", last, columns=2, rows=4),
                        CellGrid(2, 4, 1.0, 2.0), 1.0)
    assert entered.entered_never_left.tolist() == [1]
    assert fed_inlet_cells(entered).tolist() == [True, False]
    start, late = entered.batch_injection_maps([0.0, 20.0], outflow=True)
    assert start[0].tolist() == [1.0, 0.0]
    assert late[0, 1] < 0.1          # what the ring's transitions carry in, not half the batch
    # a grid whose bottom cells were all visited: Eq. (8) as the paper gives it
    ring = write_states(tmp_path / "ring.h5", np.stack([(t % 8), ((t + 3) % 8)], axis=1),
                        columns=2, rows=4)
    full = fit_model(ring, CellGrid(2, 4, 1.0, 2.0), 1.0)
    assert fed_inlet_cells(full).all()
    np.testing.assert_array_equal(inlet_batch(full), full.state_space.inlet_distribution())


def test_every_residence_trapped_is_one_line_and_exit_2(tmp_path, write_states, capsys):
    """A particle rises through column 0 and passes the top into column 1 in the last
    frame: the only entry state is never left, so no residence can end."""
    from cfbmarkov.cli import main
    from cfbmarkov.markov import MarkovModel, fit_model
    from cfbmarkov.markov.first_passage import TrappedResidences

    states = np.array([[0], [2], [4], [6], [1]])
    path = write_states(tmp_path / "trap.h5", states, columns=2, rows=4)
    model = fit_model(path, CellGrid(2, 4, 1.0, 2.0), 1.0)
    with pytest.raises(TrappedResidences, match="every residence is trapped"):
        model.rtd()
    assert main(["fit", str(path), "--cells", "2x4", "--lag", "1", "--window", "0:4",
                 "-o", str(tmp_path / "m.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "every residence is trapped" in err and "nan" not in err
    assert not (tmp_path / "m.h5").exists()
    saved = model.save(tmp_path / "given.h5")
    assert main(["rtd", str(saved)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "every residence is trapped" in err
    assert "exact residence time: none (every residence is trapped" in \
        MarkovModel.load(saved).summary()


def _ring(rows, up, down, stay_first=0):
    """A ring of ``rows`` states: up one row with ``up``, down with ``down``, else stay; the
    wrap from the top row up is a pass up through the top."""
    p = np.zeros((rows, rows))
    pass_up = np.zeros((rows, rows))
    pass_down = np.zeros((rows, rows))
    for r in range(rows):
        p[r, (r + 1) % rows] += up
        p[r, (r - 1) % rows] += down
        p[r, r] += 1 - up - down
    pass_up[rows - 1, 0] = 1.0
    pass_down[0, rows - 1] = 1.0
    return p, pass_up, pass_down


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("reducible", [False, True])
def test_exact_rtd_mean_equals_monte_carlo_for_random_chains(seed, reducible):
    """Random small ring chains, one closed class or two: the exact windowed RTD's mean
    equals the Monte Carlo's within sampling error, the classes weighted by the flux
    observed in that same Monte Carlo run."""
    from scipy.linalg import block_diag

    from cfbmarkov.markov import MarkovModel

    rng = np.random.default_rng(seed)
    parts = [_ring(int(rng.integers(4, 9)), rng.uniform(0.4, 0.8), rng.uniform(0.0, 0.15))
             for _ in range(2 if reducible else 1)]
    p, up, down = (block_diag(*[part[k] for part in parts]) for k in range(3))
    s = p.shape[0]
    zeros = np.zeros((s, s), np.int64)
    grid = CellGrid(1, s, 0.1, 1.0)
    lag, n_steps = 0.01, 400
    given = MarkovModel(p, zeros, zeros, zeros, grid, lag, pass_fractions=(up, down))
    start = rng.integers(0, s, size=3000)
    states, laps = given.monte_carlo(start, n_steps, seed=seed)
    # the passes this run observed: landing states of the passes up through the top and
    # departure states of the passes down through the bottom (net entries per class)
    step = np.diff(laps, axis=0)
    counts_up = np.diag(np.bincount(states[1:][step > 0], minlength=s)).astype(np.int64)
    counts_down = np.diag(np.bincount(states[:-1][step < 0], minlength=s)).astype(np.int64)
    model = MarkovModel(p, zeros, counts_up, counts_down, grid, lag,
                        pass_fractions=(up, down))
    assert model.rtd().closed_classes == (2 if reducible else 1)
    from cfbmarkov.observed.residence import residence_times_from_laps

    samples = residence_times_from_laps(lag * np.arange(n_steps + 1), laps)
    exact = model.rtd(window=n_steps * lag)
    se = samples.std(ddof=1) / np.sqrt(samples.size)
    assert abs(samples.mean() - exact.mean) < 5 * se, (samples.mean(), exact.mean, se)


def test_a_lag_typed_near_a_frame_takes_the_frames_lag(tmp_path):
    """Frames of a 120 Hz camera (times to 5 decimals) and --lag 0.0083 s: within the
    files' tolerance of one frame, so accepted, and the model's lag is the frame's 1/120 s
    that the transitions span; a tracer rising one lap every 37 frames then resides
    37/120 s exactly (the typed lag gave 37 x 0.0083 s, 0.4 % short, and predictions
    whose times no longer fell on the file's frames)."""
    from cfbmarkov.markov import fit_model
    from cfbmarkov.trajectory_writer import write_trajectories

    n, period = 600, 37
    y = (np.arange(n) % period + 0.5) / period
    pos = np.stack([np.full(n, 0.05), y], axis=-1)[:, None, :]
    run = write_trajectories(tmp_path / "cam.h5", np.round(np.arange(n) / 120, 5), pos,
                             width=0.1, height=1.0)
    model = fit_model(run, CellGrid(1, 8, 0.1, 1.0), 0.0083)
    assert model.lag == pytest.approx(1 / 120, rel=1e-6)
    exact = fit_model(run, CellGrid(1, 8, 0.1, 1.0), 1 / 120)
    assert model.lag == pytest.approx(exact.lag, rel=1e-8)
    assert model.rtd().mean == pytest.approx(exact.rtd().mean, rel=1e-8)
    assert model.rtd().mean == pytest.approx(period / 120, rel=0.01)
    # typed to 4 digits, 4e-5 short: the frames' lag too; within round-off: kept as given
    assert fit_model(run, CellGrid(1, 8, 0.1, 1.0), 0.008333).lag == model.lag
    assert fit_model(run, CellGrid(1, 8, 0.1, 1.0), 0.0083333334).lag == 0.0083333334


def test_a_window_late_in_a_long_record_is_printed_as_given():
    """A window of a record an hour long, 3600.005-3600.78 s: `:g` printed 3600.01, which
    typed back selects another window; printed to 10 digits."""
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.model_summary import model_summary

    p = np.full((2, 2), 0.5)
    zeros = np.zeros((2, 2), np.int64)
    model = MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 2, 0.1, 1.0), 0.005,
                        window=(3600.005, 3600.78))
    assert "window 3600.005:3600.78 s" in model_summary(model)


def test_a_class_whose_net_flow_runs_down_is_named_as_left_out(tmp_path, write_states, capsys):
    """Three particles in columns that never exchange: two rise (one a row a frame, one
    every other frame) and one falls a row a frame. The falling particle's class has a
    negative net entry flux, gets no weight in the exact RTD (which is the two risers'
    alone) and is named in a warning with its share of the particle-frames (a review found
    40 % of a LAMMPS riser left out without a word); two rising classes give none."""
    from cfbmarkov.markov import fit_model

    t = np.arange(400)
    states = np.stack([(t % 38) * 3, ((t // 2) % 38) * 3 + 1, ((-t) % 38) * 3 + 2], axis=1)
    run = write_states(tmp_path / "three.h5", states, columns=3, rows=38, width=0.09,
                       height=0.95, dt=0.025)
    model = fit_model(run, CellGrid(3, 38, 0.09, 0.95), 0.025)
    assert model.flow_direction == "up" and len(model.closed_classes) == 3
    left = [line for line in model.warnings() if "closed classes" in line]
    assert len(left) == 1 and left[0].startswith(
        "1 of the chain's 3 closed classes (38 states, 33.3 % of the fitting window's "
        "particle-frames) have no net upward flow")
    # coarser cells join the classes, kept only where they carry the fitting window
    assert left[0].endswith("the finer cells' figures describe those that flow through")
    two = write_states(tmp_path / "two.h5", states[:, :2], columns=3, rows=38, width=0.09,
                       height=0.95, dt=0.025)
    rising = fit_model(two, CellGrid(3, 38, 0.09, 0.95), 0.025)
    assert not [line for line in rising.warnings() if "closed classes" in line]
    # the exact RTD is the two risers' alone (0.95 s and 1.9 s laps)
    assert model.rtd().mean == pytest.approx(rising.rtd().mean, rel=1e-9)
    assert 0.95 < rising.rtd().mean < 1.9
    # maps: a third of Eq. (8)'s batch fed into the falling column stays there, so the
    # fraction in riser levels off at 1/3 with --outflow; the maps say so (a review saw
    # 0.3333 at 5 s printed with no word)
    from cfbmarkov.cli import main

    saved = model.save(tmp_path / "m.h5")
    assert main(["maps", str(saved), "--times", "2,5", "--outflow",
                 "-o", str(tmp_path / "maps.png")]) == 0
    out, err = capsys.readouterr()
    assert "t = 5 s: fraction in riser 0.3333" in out
    assert ("warning: the model: 0.333 of the batch is fed into 1 closed class of the chain "
            "with no net upward flow through the boundary (38 states;") in err
    assert "0.333 of the batch is still there at 5 s and counted in the fraction" in err
    # without --outflow a periodic riser keeps the whole batch, whatever its classes: no line
    assert main(["maps", str(saved), "--times", "2,5", "-o", str(tmp_path / "k.png")]) == 0
    assert "closed class" not in capsys.readouterr().err
    assert main(["maps", str(fit_model(two, CellGrid(3, 38, 0.09, 0.95), 0.025).save(
        tmp_path / "r.h5")), "--times", "2", "--outflow", "-o", str(tmp_path / "r.png")]) == 0
    assert "closed class" not in capsys.readouterr().err
