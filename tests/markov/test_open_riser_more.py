"""Open risers beyond the plain case: tracks that leave the view at a side (censored), 3D
cells, and one long tracer resampled from irregular times (PEPT-like) in a periodic loop."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.errors import CfbmarkovError
from cfbmarkov.observed.residence import residence_times
from cfbmarkov.io import import_file
from cfbmarkov.markov import CellGrid, fit_model
from cfbmarkov.synthetic import RiserFlow, sample_run
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

from .open_chain import H, W, draw, open_chain, positions_of

LAG = 0.02


def _open_states(seed=21, n_steps=400):
    q, r, e = open_chain()
    states, ids = draw(q, r, e, n_steps=n_steps, inflow=6.0, n_start=150, seed=seed)
    return q, r, e, states, ids


def test_tracks_leaving_the_view_at_a_side_are_censored_not_exits(tmp_path):
    """A fifth of the tracks are cut at a random frame (out of a camera's view): the chain is
    still recovered within sampling error, the cut tracks are counted as censored (and a
    warning says so), and none of them is a residence-time sample."""
    q, r, e, states, ids = _open_states()
    rng = np.random.default_rng(5)
    cut = rng.random(states.shape[1]) < 0.2
    alive = states >= 0
    first = alive.argmax(axis=0)
    last = states.shape[0] - 1 - alive[::-1].argmax(axis=0)
    cut_at = first + 1 + (rng.random(states.shape[1]) * np.maximum(last - first, 1)).astype(int)
    truncated = states.copy()
    for p in np.flatnonzero(cut):
        truncated[cut_at[p]:, p] = -1
    mid_row = (states >= 0) & (states // 6 >= 3) & (states // 6 <= 34)
    lost = [p for p in np.flatnonzero(cut) if mid_row[cut_at[p] - 1, p]]
    pos = positions_of(truncated, seed=6)
    times = np.arange(states.shape[0]) * LAG
    path = write_trajectories(tmp_path / "cut.h5", times, pos, width=W, height=H, ids=ids,
                              present=truncated >= 0, boundary="open")
    model = fit_model(path, CellGrid(6, 38, W, H), LAG, estimator="mle")
    assert model.open_flow.censored_tracks[0] >= len(lost) > 20
    assert any("left out as censored" in line for line in model.warnings())
    visits = model.counts.sum(axis=1) + model.open_flow.exit_counts
    well = visits > 400
    sigma = np.sqrt(q * (1 - q) / np.maximum(visits, 1)[:, None])
    assert (np.abs(model.absorbing_matrix - q)[well] / np.maximum(sigma[well], 1e-12)).max() < 5
    with Trajectories(path) as t:
        samples = residence_times(t, (1.0, 7.0), face_band=H / 38).samples
    full = write_trajectories(tmp_path / "full.h5", times, positions_of(states, seed=6),
                              width=W, height=H, ids=ids, present=states >= 0, boundary="open")
    with Trajectories(full) as t:
        all_samples = residence_times(t, (1.0, 7.0), face_band=H / 38).samples
    assert 0 < samples.size < all_samples.size


def test_open_riser_in_3d_cells(tmp_path):
    """A depth coordinate added: 6x38 cells project (the same counts as in 2D); 6x2x38 cells
    give an exact RTD equal to the fundamental-matrix mean, matched by Monte Carlo."""
    q, r, e, states, ids = _open_states(seed=31)
    pos = positions_of(states, seed=7)
    rng = np.random.default_rng(8)
    depth = np.where(states[..., None] >= 0, rng.uniform(0, 0.01, states.shape + (1,)), np.nan)
    times = np.arange(states.shape[0]) * LAG
    flat = write_trajectories(tmp_path / "2d.h5", times, pos, width=W, height=H, ids=ids,
                              present=states >= 0, boundary="open")
    deep = write_trajectories(tmp_path / "3d.h5", times, np.concatenate([pos, depth], -1),
                              width=W, height=H, depth=0.01, ids=ids, present=states >= 0,
                              boundary="open")
    projected = fit_model(deep, CellGrid(6, 38, W, H), LAG, estimator="mle")
    plain = fit_model(flat, CellGrid(6, 38, W, H), LAG, estimator="mle")
    np.testing.assert_array_equal(projected.counts, plain.counts)
    np.testing.assert_array_equal(projected.open_flow.exit_counts, plain.open_flow.exit_counts)
    grid = CellGrid(6, 38, W, H, depth_columns=2, depth=0.01)
    model = fit_model(deep, grid, LAG, estimator="mle")
    assert model.n_states == 6 * 2 * 38
    np.testing.assert_array_equal(np.flatnonzero(model.open_flow.entry_counts), np.arange(12))
    qm = model.absorbing_matrix
    mean = model.open_flow.entry_distribution @ np.linalg.solve(np.eye(qm.shape[0]) - qm, np.ones(qm.shape[0]))
    assert model.rtd().mean == pytest.approx(mean * LAG, rel=1e-8)
    out = model.predict(deep, start=1.0, duration=7.0, seed=3, output=tmp_path / "p.h5")
    with Trajectories(out) as t:
        assert t.dimensions == 3 and t.boundary == "open"
        samples = residence_times(t, (1.0, 8.0), face_band=H / 38).samples
    exact = model.rtd(7.0)
    assert abs(samples.mean() - exact.mean) < 4 * samples.std(ddof=1) / np.sqrt(samples.size)


def test_one_long_pept_like_tracer_gives_the_model_of_many_particles(tmp_path):
    """One tracer of the synthetic periodic flow for 200 s, located at irregular times (a
    fifth of the frames missing) with a 2 s gap out of the field of view, written as the pept
    library writes (mm, ms, '# t x y z error'), resampled onto the frame interval: its model's
    E(RT) matches the one fitted on many particles of the same process."""
    flow = RiserFlow()
    times, _, pos, _ = sample_run(flow, 1, 8001, seed=4)
    rng = np.random.default_rng(9)
    keep = rng.random(times.size) > 0.2
    keep[(times > 100) & (times < 102)] = False                # out of the field of view
    keep[[0, -1]] = True
    t_ms = times[keep] * 1000
    rows = "".join(f"{a:.6f} {x * 1000:.6f} {y * 1000:.6f} 0.5 1.0\n"
                   for a, (x, y) in zip(t_ms, pos[keep, 0]))
    source = tmp_path / "pept.csv"
    source.write_text("# t x y z error\n" + rows)
    tracer = import_file(source, "csv", tmp_path / "tracer.h5", length_unit="mm", time_unit="ms",
                         vertical_axis="y", drop_depth=True, resample=flow.lag, max_gap=0.06,
                         width=0.09, height=0.95)
    with Trajectories(tracer) as t:
        present = t.present()[:, 0]
        assert not present[(t.times > 100.05) & (t.times < 101.95)].any()
        assert present.mean() > 0.9
    single = fit_model(tracer, CellGrid(6, 38, flow.width, flow.height), flow.lag, estimator="mle")
    many_times, _, many_pos, many_laps = sample_run(flow, 300, 801, seed=5)
    many = write_trajectories(tmp_path / "many.h5", many_times, many_pos, width=flow.width,
                              height=flow.height, laps=many_laps)
    reference = fit_model(many, CellGrid(6, 38, flow.width, flow.height), flow.lag,
                          estimator="mle")
    assert single.rtd().mean == pytest.approx(reference.rtd().mean, rel=0.1)


def test_an_inflow_that_does_not_balance_the_outflow_is_warned_of():
    """Entries through the inlet far below the exits through the outlet (most tracks begin
    away from the inlet and are censored): the window's flow was not steady, and a warning
    says so; counts that differ by their noise alone give no such line, and a fill is named
    as one."""
    from cfbmarkov.markov.open_flow import OpenFlow

    def lines(entries, exits):
        flow = OpenFlow(np.array([0.0, 0.2]), np.array([0, exits]), np.array([entries, 0]),
                        entries / 240)
        return [line for line in flow.warnings() if "does not balance" in line]

    drained = lines(185, 3847)
    assert len(drained) == 1 and "saw 185 entries through the inlet and 3847 exits" in \
        drained[0] and "riser drains over the window" in drained[0]
    assert lines(1000, 1080) == [] and lines(20, 34) == []      # noise: within 3 sigma
    assert "riser fills over the window" in lines(3000, 1200)[0]


def _small_chain_file(path, columns: int, rows: int, *, stay: float, inflow: float,
                      seed: int):
    """A known open chain (up 0.5 a lag, no sideways moves) drawn for 1500 lags of 0.01 s
    into a riser 0.02 m wide and 0.2 m high."""
    q, r, e = open_chain(columns=columns, rows=rows, up=0.5, stay=stay, side=0.0)
    states, ids = draw(q, r, e, n_steps=1500, inflow=inflow, n_start=0, seed=seed,
                       columns=columns, rows=rows)
    pos = positions_of(states, seed=seed + 1, columns=columns, rows=rows)
    pos[..., 0] *= 0.02 / W
    pos[..., 1] *= 0.2 / H
    return write_trajectories(path, 0.01 * np.arange(states.shape[0]), pos, width=0.02,
                              height=0.2, ids=ids, present=states >= 0, boundary="open")


def test_a_state_space_with_memory_counts_an_open_residence_from_the_inlet(tmp_path):
    """A known open chain on 1 x 10 cells (E(RT) 20 lags): a state space with memory gives a
    particle its first state a lag after it is first seen at the inlet. Its exact RTD, its
    exact exit conversion and the conversion integrated along the data's paths count that
    lag, as the cells do (they were one lag short: E(RT) 0.19 s against 0.20 s, conversion
    0.604 against 0.623 at a rate of 5 1/s), and a Monte Carlo carries it too."""
    from cfbmarkov.analysis.kinetics_reference import reference_kinetics
    from cfbmarkov.kinetics import Constant, FirstOrder, Kinetics, Property
    from cfbmarkov.markov.kinetics_exact import exact_kinetics
    from cfbmarkov.markov.kinetics_mc import exit_values, run_properties
    from cfbmarkov.markov.model_rtd import entry_delay
    from cfbmarkov.markov.spaces import state_space_from_name

    rows, lag = 10, 0.01
    path = _small_chain_file(tmp_path / "chain.h5", 1, rows, stay=0.5, inflow=2.0, seed=5)
    kinetics = Kinetics((Property("X", FirstOrder(), {"rate": Constant(5.0)}, "entry", 0.0),))
    answers = {}
    for name in ("cells", "cells-direction"):
        space = state_space_from_name(name, 1, rows, 0.02, 0.2)
        model = fit_model(path, space, lag, (1.0, 14.0), "mle")
        assert entry_delay(model) == (0 if name == "cells" else 1)
        sk = kinetics.per_state(space)
        exact = exact_kinetics(model, sk)["X"].exit_mean
        along = reference_kinetics(path, model, sk, (1.0, 14.0))["X"]
        answers[name] = (model.rtd().mean, exact, float(np.nanmean(along.exit_values)))
        # the Monte Carlo: newcomers carry the lag before their first state
        run_states, run_laps = model.monte_carlo(np.zeros(0, np.int64), 3000, seed=3)
        values = run_properties(sk, lag, run_states, run_laps, periodic=False,
                                entry_lags=entry_delay(model))
        a, b = sk.over(lag)
        exits, _, began = exit_values(run_states, run_laps, values[0], a[0], b[0],
                                      periodic=False)
        kept = exits[began < 2500]
        assert abs(kept.mean() - exact) < 3 * kept.std() / np.sqrt(kept.size), name
        # a prediction shows newcomers at the inlet from when the data would first see
        # them: its residences, counted as the data's, keep their count and their mean
        # (they were one lag short, and half of them, first seen above the inlet's cell,
        # were not counted)
        pred = model.predict(path, start=5.0, duration=9.0, seed=3,
                             output=tmp_path / f"pred-{name}.h5")
        with Trajectories(path) as data, Trajectories(pred) as predicted:
            seen = residence_times(data, (5.0, 14.0), face_band=0.02).samples
            drawn = residence_times(predicted, (5.0, 14.0), face_band=0.02).samples
        assert drawn.size > 0.9 * seen.size, name
        assert drawn.mean() == pytest.approx(seen.mean(), rel=0.03), name
    (rt_cells, x_cells, seen_cells), (rt_memory, x_memory, seen_memory) = answers.values()
    assert rt_cells == pytest.approx(0.2, rel=0.03)
    assert rt_memory == pytest.approx(rt_cells, rel=0.005)      # one lag is 5 %
    assert x_memory == pytest.approx(x_cells, rel=0.002)        # one lag is 3 %
    assert seen_memory == pytest.approx(seen_cells, rel=0.002)
    assert seen_memory == pytest.approx(x_memory, rel=0.02)


def test_compare_reads_an_open_riser_on_every_frame_at_any_lag(tmp_path):
    """Frames every 0.01 s of a known chain, models at lags of 1, 2 and 3 frames: the
    reference's residences are read on every frame (entries where first seen, exits where
    last seen, then timed on the lag's frames), so their count does not depend on the lag
    nor their mean beyond the lag's rounding (read a lag apart they
    lost 68 % at 3 frames, the short ones first, E(RT) +11 %); the prediction's, a Markov
    prediction's every appearance an entry and disappearance an exit, are counted whole
    (its newcomers are shown in their first state's cell, above the inlet's), so the
    model's E(RT) is not read biased; no track of this chain is censored: no warning."""
    from cfbmarkov.analysis.compare import compare_runs
    from cfbmarkov.markov.spaces import state_space_from_name

    path = _small_chain_file(tmp_path / "chain.h5", 2, 8, stay=0.4, inflow=3.0, seed=7)
    space = state_space_from_name("cells", 2, 8, 0.02, 0.2)
    seen = {}
    for lag in (0.01, 0.02, 0.03):
        model = fit_model(path, space, lag, (2.0, 8.0), "mle")
        pred = model.predict(path, start=8.0, duration=6.9, seed=1,
                             output=tmp_path / f"p{lag}.h5")
        comparison = compare_runs(path, pred, (8.0, 14.9))
        assert not [w for w in comparison.warnings if w.startswith("the reference:")]
        ref, mod = comparison.reference.residence, comparison.model.residence
        seen[lag] = (ref.count, ref.mean)
        assert mod.count > 0.9 * ref.count, lag
        assert mod.mean == pytest.approx(ref.mean, rel=0.03), lag
    for lag in (0.02, 0.03):          # the same residences, timed on the lag's frames
        assert seen[lag][0] == seen[0.01][0]
        assert seen[lag][1] == pytest.approx(seen[0.01][1], rel=0.01)
    # a property along the paths keeps every exit at a lag of 3 frames too (618 of 1986
    # were kept, those first seen above the inlet's band at the lag's frames dropped)
    from cfbmarkov.analysis.kinetics_reference import reference_kinetics
    from cfbmarkov.kinetics import Constant, FirstOrder, Kinetics, Property

    kinetics = Kinetics((Property("X", FirstOrder(), {"rate": Constant(5.0)}, "entry", 0.0),))
    along = reference_kinetics(path, model, kinetics.per_state(space), (8.0, 14.9))["X"]
    assert along.exit_values.size == seen[0.01][0]


def test_an_open_beds_means_count_the_lag_before_a_state_with_memory_at_the_inlet(tmp_path):
    """On a known open chain (2 x 8 cells), the bed's means under a state space with memory
    count each newcomer over the lag before its first state, where it is: at the inlet.
    Along the data's paths its frames had been left out (the bed mean 5 % high), and the
    exact answer per cell had put them in the first state's cell (the second row's cell
    low, the inlet's high); both now equal the cells' to the chains' own difference."""
    from cfbmarkov.analysis.kinetics_reference import reference_kinetics
    from cfbmarkov.kinetics import Constant, FirstOrder, Kinetics, Property
    from cfbmarkov.markov.kinetics_exact import exact_kinetics
    from cfbmarkov.markov.spaces import state_space_from_name

    columns, rows, lag = 2, 8, 0.01
    path = _small_chain_file(tmp_path / "chain.h5", columns, rows, stay=0.4, inflow=3.0,
                             seed=7)
    kinetics = Kinetics((Property("X", FirstOrder(), {"rate": Constant(5.0)}, "entry", 0.0),))
    got = {}
    for name in ("cells", "cells-direction"):
        space = state_space_from_name(name, columns, rows, 0.02, 0.2)
        model = fit_model(path, space, lag, (1.0, 14.0), "mle")
        sk = kinetics.per_state(space)
        exact = exact_kinetics(model, sk)["X"]
        along = reference_kinetics(path, model, sk, (1.0, 14.0))["X"]
        got[name] = (exact.bed_mean, np.asarray(exact.bed_mean_by_cell),
                     along.time_mean, np.asarray(along.cell_mean))
    (bed, by_cell, seen, seen_cells), (bed_m, by_cell_m, seen_m, seen_cells_m) = got.values()
    assert seen_m == pytest.approx(seen, rel=0.005)
    np.testing.assert_allclose(seen_cells_m, seen_cells, rtol=0.01)
    assert bed_m == pytest.approx(bed, rel=0.005)
    # the two chains differ by up to 3 % in the inlet's cells (they were 30 % apart in the
    # inlet's cells, 17 % in the second row's)
    np.testing.assert_allclose(by_cell_m, by_cell, rtol=0.04)
    # a carried property on an open riser: refused by compare as by react (compare had
    # judged the model's fresh newcomers against the reference's re-entries, +534 %)
    from cfbmarkov.errors import InputError
    from cfbmarkov.kinetics.laws import Deactivation
    from cfbmarkov.report.compare import compare

    model = fit_model(path, CellGrid(columns, rows, 0.02, 0.2), lag, (1.0, 8.0), "mle")
    pred = model.predict(path, start=8.0, duration=6.0, seed=2, output=tmp_path / "p.h5")
    carried = Kinetics((Property("a", Deactivation(), {"rate": Constant(1.0)}, "carried",
                                 1.0),))
    with pytest.raises(InputError, match="property a: a carried property needs a periodic "
                                         "riser"):
        compare(path, pred, window=(8.0, 14.0), output=tmp_path / "cmp", figures=False,
                resamples=0, kinetics=carried)
    assert not (tmp_path / "cmp").exists()


def test_a_chain_whose_hold_up_is_not_the_datas_is_warned_of(tmp_path):
    """Little's law: an open chain holds its inflow x E(RT) particles in a steady state. On a
    known chain fitted whole, that is the data's mean hold-up (no line); with half the
    inflow (tracks lost as censored do that) its Monte Carlo would drain the riser to half,
    which `predict` had not said, and the line says so in numbers."""
    import dataclasses

    from cfbmarkov.markov.model_summary import hold_up_warning, monte_carlo_warnings

    q, r, e = open_chain(columns=2, rows=8, up=0.5, stay=0.4, side=0.0)
    states, ids = draw(q, r, e, n_steps=1200, inflow=3.0, n_start=0, seed=9, columns=2,
                       rows=8)
    pos = positions_of(states, seed=10, columns=2, rows=8)
    path = write_trajectories(tmp_path / "chain.h5", 0.01 * np.arange(states.shape[0]), pos,
                              width=W, height=H, ids=ids, present=states >= 0,
                              boundary="open")
    model = fit_model(path, CellGrid(2, 8, W, H), 0.01, (2.0, 11.0), "mle")
    seen = (model.counts.sum() + model.open_flow.exit_counts.sum()) / model.frame_pairs
    lags = model.rtd().mean / model.lag
    assert model.open_flow.inflow_per_lag * lags == pytest.approx(seen, rel=0.05)
    assert hold_up_warning(model) is None and monte_carlo_warnings(model) == []
    halved = dataclasses.replace(model, open_flow=dataclasses.replace(
        model.open_flow, inflow_per_lag=model.open_flow.inflow_per_lag / 2))
    line = hold_up_warning(halved)
    assert line is not None and "% below the fitting window's mean of" in line
    assert "its Monte Carlo (predict, react --init) drains the riser" in line
    assert line in halved.warnings() and line in monte_carlo_warnings(halved)
    # the stationary distribution of an open riser is where its steady particles are:
    # e (I - Q)^-1 normalised, as the data's particle-frames (the stationary vector of P,
    # which leaves the exits out, had put 88 % of them in the top two rows)
    q = model.absorbing_matrix
    lags = np.linalg.solve((np.eye(q.shape[0]) - q).T, model.open_flow.entry_distribution)
    np.testing.assert_allclose(model.stationary_distribution, lags / lags.sum(), atol=1e-12)
    frames = model.counts.sum(axis=1) + model.open_flow.exit_counts
    np.testing.assert_allclose(model.stationary_distribution, frames / frames.sum(), atol=0.01)


def test_entries_and_exits_at_a_lag_of_several_frames_are_judged_where_seen(tmp_path):
    """At a lag of 3 frames, a pair (t, t + lag) judged an exit by the height at t and an
    entry by the height at t + lag, frames away from the face: 45 % of complete tracks were
    censored and the inflow undercounted (5.4 a lag for 9). They are judged where the
    particle was last and first seen: the inflow is three times the one-frame lag's, no
    track is censored, and the chain's hold-up is the data's. A grid with cells nobody
    visits keeps a stationary distribution (0 there); a trap the entries reach has none,
    and the hold-up line says the Monte Carlo fills the riser."""
    import warnings as _warnings

    from cfbmarkov.markov.model_summary import hold_up_warning

    q, r, e = open_chain(columns=2, rows=8, up=0.5, stay=0.4, side=0.0)
    states, ids = draw(q, r, e, n_steps=1200, inflow=3.0, n_start=0, seed=9, columns=2,
                       rows=8)
    pos = positions_of(states, seed=10, columns=2, rows=8)
    times = 0.01 * np.arange(states.shape[0])
    path = write_trajectories(tmp_path / "chain.h5", times, pos, width=W, height=H, ids=ids,
                              present=states >= 0, boundary="open")
    one, three = (fit_model(path, CellGrid(2, 8, W, H), lag, (2.0, 11.0), "mle")
                  for lag in (0.01, 0.03))
    assert three.open_flow.censored_tracks == (0, 0)
    assert three.open_flow.inflow_per_lag == pytest.approx(
        3 * one.open_flow.inflow_per_lag, rel=0.01)
    assert hold_up_warning(three) is None
    # half the riser's width: columns 2 and 3 of a 4-column grid are never visited
    narrow = pos.copy()
    narrow[..., 0] *= 0.5
    half = write_trajectories(tmp_path / "half.h5", times, narrow, width=W, height=H,
                              ids=ids, present=states >= 0, boundary="open")
    wide = fit_model(half, CellGrid(4, 8, W, H), 0.01, (2.0, 11.0), "mle")
    with _warnings.catch_warnings():
        _warnings.simplefilter("error")            # no scipy rank warning either
        pi = wide.stationary_distribution
    cells = wide.state_space.cell_of_state % 4
    assert pi[cells >= 2].sum() == 0 and pi.sum() == pytest.approx(1.0)
    # 20 particles that enter and stay for ever in column 3
    trapped = np.full((times.size, 20, 2), np.nan)
    for k in range(20):
        trapped[300 + 10 * k, k] = (0.1 * W, 0.01)
        trapped[301 + 10 * k:, k] = (0.9 * W, 0.5 * H)
    with_trap = np.concatenate([narrow, trapped], axis=1)
    path = write_trajectories(tmp_path / "trap.h5", times, with_trap, width=W, height=H,
                              ids=np.arange(with_trap.shape[1]),
                              present=np.isfinite(with_trap[..., 0]), boundary="open")
    trap = fit_model(path, CellGrid(4, 8, W, H), 0.01, (2.0, 11.0), "mle")
    line = hold_up_warning(trap)
    assert line is not None and "never leave" in line and "fills the riser" in line
    with pytest.raises(CfbmarkovError, match="a trap"):
        trap.stationary_distribution


def test_states_auto_names_why_it_kept_the_cells(tmp_path):
    """On 2 columns no candidate of the CK criterion can be judged (no core column); the
    record said the blocks held too few residences ("only 543 ... fewer than 30"), which
    was not the reason. It now names the candidates' own."""
    from cfbmarkov.markov.select import select_model

    path = _small_chain_file(tmp_path / "chain.h5", 2, 8, stay=0.4, inflow=3.0, seed=7)
    reason = select_model(path, window=(2.0, 8.0), columns=2, rows=8,
                          lag=0.01).selection["reason"]
    assert "fewer than" not in reason and "leave no core in 2 columns" in reason
    assert reason.endswith("so the paper's cells were kept")


def _rows_file(path, pattern, starts, frames: int = 41):
    """An open 1x4 riser whose particle p follows ``pattern`` (rows; -1 absent) from frame
    ``starts[p]``, frames 0.1 s apart."""
    rows = np.full((frames, len(starts)), -1)
    for p, s in enumerate(starts):
        for i, r in enumerate(pattern):
            rows[s + i, p] = r
    present = rows >= 0
    y = np.where(present, (rows + 0.5) * 0.95 / 4, np.nan)
    x = np.where(present, 0.02, np.nan)
    return write_trajectories(path, np.round(np.arange(frames) * 0.1, 10),
                              np.stack([x, y], -1), width=0.09, height=0.95, present=present,
                              boundary="open")


def test_returns_through_the_inlet_are_no_entries_and_their_time_out_of_view_is_warned_of(
        tmp_path, capsys):
    """Every particle rises a row, drops back, falls out through the inlet for two frames
    and rises through to the outlet: each observed residence runs 0.9 s across the fall.
    The chain had taken each return for a new entry (a review found 45 entries counted
    where 22 particles entered, its inflow and hold-up 66 % high, and no word); a return
    is now no entry: the residence goes on, as observed, and the 0.3 s out of view (last
    seen to seen again), which no transition counts, is named beside the chain's E(RT);
    beyond 5 % of the entries `fit` warns and `predict` repeats it. The same particles
    without the fall make the same entries and no return."""
    from cfbmarkov.cli import main
    from cfbmarkov.markov import MarkovModel

    fall = _rows_file(tmp_path / "fall.h5", [0, 1, 0, -1, -1, 0, 1, 2, 3], range(1, 26))
    model = fit_model(fall, CellGrid(1, 4, 0.09, 0.95), 0.1, window=(0.0, 4.0),
                      estimator="mle")
    flow = model.open_flow
    assert int(flow.entry_counts.sum()) == 25 and flow.returned_entries == 25
    assert int(flow.exit_counts.sum()) == 25 and flow.censored_tracks == (0, 0)
    assert flow.returned_time == pytest.approx(25 * 0.3)
    with Trajectories(fall) as t:
        observed = residence_times(t, (0.0, 4.0), face_band=0.95 / 4).samples
    np.testing.assert_allclose(observed, 0.9)            # the residence runs across the fall
    # nor does compare's face-band check count the falls that came back as tracks ended
    # away from the outlet (a review saw it warn of 189 left out, none of them)
    from cfbmarkov.analysis.stationarity import face_band_warning
    from cfbmarkov.observed.residence import open_face_tracks

    with Trajectories(fall) as t:
        assert open_face_tracks(t, (0.0, 4.0), 0.95 / 4) == (25, 25, 25, 25)
        assert face_band_warning(t, (0.0, 4.0), 0.95 / 4, limit=0.05) is None
    # the chain's transitions leave the 0.3 s out of view out: 0.6 s, and with it 0.9 s
    assert model.rtd().mean == pytest.approx(0.6, abs=1e-9)
    line = [w for w in model.warnings() if "returns through the inlet" in w]
    assert len(line) == 1 and line[0].strip().startswith(
        "25 returns through the inlet against 25 entries: particles that fell back out "
        "through it (or left the view) and came back within the fitting window")
    assert ("its transitions leave out the time from a particle's last state before the "
            "fall to its first after it, 0.3 s a residence on average") in line[0]
    assert ", 25 returns through it (back after a fall out or out of view: no entry)" \
        in model.summary()
    saved = model.save(tmp_path / "m.h5")
    loaded = MarkovModel.load(saved).open_flow
    assert (loaded.returned_entries, loaded.returned_time) == (25, flow.returned_time)
    assert main(["predict", str(saved), "--init", str(fall), "--start", "1", "--duration",
                 "1", "-q", "-o", str(tmp_path / "p.h5")]) == 0
    assert "warning: the model: 25 returns through the inlet against 25 entries" in \
        capsys.readouterr().err
    # at a lag of two frames each sequence of lag frames has its own chain: a particle seen
    # first on a frame between a sequence's makes that sequence's entry when it comes back
    # (a review found 4 % of the entries filed as returns at a lag of two frames)
    quick = _rows_file(tmp_path / "quick.h5", [0, -1, -1, 0, 1, 2, 3], range(2, 26))
    flow2 = fit_model(quick, CellGrid(1, 4, 0.09, 0.95), 0.2, window=(0.0, 4.0),
                      estimator="mle").open_flow
    assert (int(flow2.entry_counts.sum()), flow2.returned_entries) == (48, 24)
    # the time no transition counts, from the last state before the fall to the first
    # after it, on each lag sequence: at a lag of two frames, and with a memory whose first
    # state comes a lag after a particle is seen, the chain's E(RT) and it give the 1.5 s
    # observed (a review found 1.42 and 1.2 s: the time from last seen to seen again)
    long = _rows_file(tmp_path / "long.h5", [0, 0, 0, 0, -1, -1, -1, -1, 0, 0, 0, 0, 1, 2, 3],
                      range(4, 20), frames=45)
    with Trajectories(long) as t:
        np.testing.assert_allclose(
            residence_times(t, (0.3, 4.4), face_band=0.95 / 4).samples, 1.5)
    for lag, states in ((0.2, "cells"), (0.1, "cells-direction")):
        from cfbmarkov.markov.spaces import state_space_from_name

        m = fit_model(long, state_space_from_name(states, 1, 4, 0.09, 0.95), lag,
                      window=(0.3, 4.4), estimator="mle")
        per_return = m.open_flow.returned_time / m.open_flow.returned_entries
        assert m.rtd().mean + per_return == pytest.approx(1.5, abs=1e-9), (lag, states)
    # a track begun mid-riser (no entry, as the residence times read it) that falls out and
    # comes back through the inlet enters there, as it begins its residence there
    mid = _rows_file(tmp_path / "mid.h5", [2, 1, 0, -1, -1, 0, 1, 2, 3], range(1, 26))
    begun = fit_model(mid, CellGrid(1, 4, 0.09, 0.95), 0.1, window=(0.0, 4.0),
                      estimator="mle").open_flow
    assert (int(begun.entry_counts.sum()), begun.returned_entries) == (25, 0)
    # so on every lag sequence: a particle first seen mid-riser on a frame between the
    # window's first frame and a sequence's is not inside at the window's start there
    late = _rows_file(tmp_path / "late.h5", [2, 1, 0, -1, -1, 0, 1, 2, 3],
                      [1] * 10 + [3] * 10, frames=30)
    two = fit_model(late, CellGrid(1, 4, 0.09, 0.95), 0.2, window=(0.0, 2.9),
                    estimator="mle").open_flow
    assert (int(two.entry_counts.sum()), two.returned_entries) == (40, 0)
    # a residence's start is its first entry, not a return after a stay too short for a
    # memory's state: the second fall's return is a return too (it was counted an entry)
    twice = _rows_file(tmp_path / "twice.h5", [0, 1, 2, 1, 0, -1, -1, 0, -1, -1, 0, 1, 2, 3],
                       range(2, 22), frames=45)
    from cfbmarkov.markov.spaces import state_space_from_name

    memory = fit_model(twice, state_space_from_name("cells-direction", 1, 4, 0.09, 0.95), 0.1,
                       window=(0.1, 4.4), estimator="mle").open_flow
    assert (int(memory.entry_counts.sum()), memory.returned_entries) == (20, 20)
    # a gap shorter than the lag ends no presence, as the residence times read it: seen at
    # the window's first frame and two frames later (lag three frames), the particle is
    # inside at the start on every sequence, and its return through the inlet is one
    gap = _rows_file(tmp_path / "gap.h5", [1, -1, 1, -1, -1, -1, -1, -1, 0, 1, 2, 3],
                     [0] * 20, frames=14)
    lag3 = fit_model(gap, CellGrid(1, 4, 0.09, 0.95), 0.3, window=(0.0, 1.3),
                     estimator="mle").open_flow
    assert lag3.returned_entries == 40              # on the sequences from frames 0 and 2
    # ... and a memory's first state after such a gap is no entry on the sequence that saw
    # the particle mid-riser at the window's first frame (it was counted one there); the
    # sequence that first sees it at the inlet, after the gap, enters it
    mid_gap = _rows_file(tmp_path / "midgap.h5", [1, -1, -1, 0, 0, 1, 2, 3], [3] * 20,
                         frames=12)
    seen = fit_model(mid_gap, state_space_from_name("cells-direction", 1, 4, 0.09, 0.95), 0.3,
                     window=(0.3, 1.1), estimator="mle").open_flow
    assert int(seen.entry_counts.sum()) == 20 and seen.censored_tracks[1] == 20
    stay = _rows_file(tmp_path / "stay.h5", [0, 1, 0, 0, 1, 2, 3], range(1, 26))
    kept = fit_model(stay, CellGrid(1, 4, 0.09, 0.95), 0.1, window=(0.0, 4.0),
                     estimator="mle").open_flow
    assert kept.returned_entries == 0 and int(kept.entry_counts.sum()) == 25
    assert not any("returns" in w for w in kept.warnings())


def test_maps_refuse_a_bottom_row_the_chain_never_leaves(tmp_path, capsys):
    """Every particle rises a row a frame from the inlet: a direction space counts each
    entry into the state a row up, a lag after it is first seen, and never visits the
    bottom row, so Eq. (8)'s batch fed there stayed in the riser at every time (a review
    saw "fraction in riser 1.0000" at 2 s against an RTD over by 0.4 s); refused in one
    line. The cells' maps feed it: gone by 0.4 s."""
    from cfbmarkov.cli import main

    run = _rows_file(tmp_path / "rise.h5", [0, 1, 2, 3], range(1, 30))
    for states, code in (("cells-direction", 2), ("cells", 0)):
        model = tmp_path / f"{states}.h5"
        assert main(["fit", str(run), "--cells", "1x4", "--lag", "0.1", "--window", "0.1:4",
                     "--states", states, "--resamples", "0", "-q", "-o", str(model)]) == 0
        capsys.readouterr()
        assert main(["maps", str(model), "--times", "0.4,2", "-o",
                     str(tmp_path / f"{states}.png")]) == code
        out, err = capsys.readouterr()
        if code:
            assert err.count("\n") == 1 and ("no cell of the chain's bottom row was left in "
                                              "the fitting window") in err
            assert "fit with --states cells for the maps" in err
            # with --outflow too: the refusal comes before any note
            assert main(["maps", str(model), "--times", "0.4", "--outflow", "-o",
                         str(tmp_path / "o.png")]) == 2
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and "no cell of the chain's bottom row" in err
        else:
            assert "t = 0.4 s: fraction in riser 0.0000" in out


def test_no_entry_names_the_tracks_begun_away_from_the_inlet(tmp_path, capsys):
    """Particles inserted two rows above the inlet: no entry, and the refusal says how many
    tracks began away from the inlet and what counts them (it sent the user to `info`,
    whose "entries" were every track begun, a review found); `info` says what it counts."""
    from cfbmarkov.cli import main

    run = _rows_file(tmp_path / "high.h5", [2, 3], range(1, 30))
    assert main(["fit", str(run), "--cells", "1x4", "--lag", "0.1", "--window", "0:4",
                 "-o", str(tmp_path / "m.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ("29 tracks began in it more than one cell from the "
                                      "inlet, censored") in err
    assert "taller --cells (or a shorter lag) count them as entries" in err
    assert main(["info", str(run)]) == 0
    assert ("tracks begun 29, ended 29 (after the first frame, anywhere; fit counts those "
            "within one cell of the inlet and the outlet as entries and exits)"
            ) in capsys.readouterr().out


def test_a_memory_trapped_by_falls_is_refused_naming_them(tmp_path, capsys):
    """Every particle's one state before its fall has no transition out (the fall is none):
    every residence is trapped, and the refusal names the falls and their cure beside a
    longer window (which cannot help here)."""
    from cfbmarkov.cli import main

    run = _rows_file(tmp_path / "trap.h5", [0, 0, -1, -1, 0, 1, 2, 3], range(1, 30))
    assert main(["fit", str(run), "--cells", "1x4", "--lag", "0.1", "--window", "0.1:4",
                 "--states", "cells-direction", "-o", str(tmp_path / "m.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "every residence is trapped" in err
    assert ("falls back out through the inlet, out of view), the states they end in keep "
            "them: import the riser from farther below its inlet") in err


@pytest.mark.parametrize("boundary", ["open", "periodic"])
def test_memory_of_a_fast_rise_takes_the_minimal_image_only_through_a_periodic_boundary(
        tmp_path, boundary):
    """A particle rising 0.65 m of a 1 m riser in one lag: on an open riser (no top joined
    to the bottom) it rose, and came from 3 rows below; through a periodic boundary the
    minimal image reads it as a fall of 0.35 m from above."""
    from cfbmarkov.markov import discretize
    from cfbmarkov.markov.spaces import state_space_from_name

    times = np.round(0.1 * np.arange(6), 10)
    y = np.array([0.05, 0.1, 0.2, 0.85, 0.9, 0.95])
    pos = np.stack([np.full(6, 0.05), y], -1)[:, None, :]
    path = write_trajectories(tmp_path / "fast.h5", times, pos, width=0.1, height=1.0,
                              boundary=boundary, present=np.ones((6, 1), bool))
    direction = state_space_from_name("cells-direction", 1, 4, 0.1, 1.0)
    states = discretize(path, direction, 0.1, (0.1, 0.5)).states[:, 0]
    jump = int(np.flatnonzero(np.round(times[1:], 10) == 0.3)[0])      # frame 0.3 s
    falling = direction.falling(states)
    assert falling[jump] == (boundary == "periodic")
    assert not falling[jump + 1]
    previous = state_space_from_name("cells-previous", 1, 4, 0.1, 1.0)
    drow, _ = previous.offsets(discretize(path, previous, 0.1, (0.1, 0.5)).states[:, 0])
    # rows 0 -> 3 in one lag: 3 rows below on an open riser, 1 row above (of 4) periodic
    assert drow[jump] == (-3 if boundary == "open" else 1)


def test_an_open_risers_counts_at_a_lag_of_several_frames_are_one_sequences(tmp_path):
    """At a lag of k frames every frame starts a transition, so the model's counts hold
    each exit, entry and censored track once for each of the lag's k sequences of frames:
    its summary and warnings give one sequence's (the counts over k; 598 exits had printed
    for the 200 of a lag of one frame, and the inflow-outflow test ran on k-fold counts),
    and the model file keeps k."""
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.spaces import state_space_from_name

    path = _small_chain_file(tmp_path / "chain.h5", 2, 8, stay=0.4, inflow=3.0, seed=7)
    space = state_space_from_name("cells", 2, 8, 0.02, 0.2)
    lines = {}
    for k in (1, 3):
        model = fit_model(path, space, 0.01 * k, (2.0, 8.0), "mle")
        flow = model.open_flow
        assert flow.lag_sequences == k
        lines[k] = flow.summary_line()
        assert MarkovModel.load(model.save(tmp_path / f"m{k}.h5")).open_flow.lag_sequences == k
    exits = {k: int(line.split("open riser: ")[1].split(" exits")[0]) for k, line in
             lines.items()}
    assert abs(exits[3] - exits[1]) <= 0.02 * exits[1] + 2, lines
    assert "are 3 times these" in lines[3] and "times these" not in lines[1]
