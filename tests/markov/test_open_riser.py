"""Open risers: particles enter through the inlet and leave through the outlet. A known open
chain on 6 x 38 cells, drawn and written as a LAMMPS dump with `ff` bounds, gives back its
matrix within sampling error; the reference RTD from frames equals the one computed by hand;
the model's exact RTD equals the chain's fundamental-matrix result to round-off."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.observed.residence import residence_times
from cfbmarkov.errors import InputError
from cfbmarkov.io import import_file
from cfbmarkov.markov import CellGrid, MarkovModel, fit_model
from cfbmarkov.trajectories import Trajectories

from .open_chain import H, W, draw, lammps_dump, open_chain, positions_of

LAG = 0.02
STEP = 1e-5


@pytest.fixture(scope="session")
def open_run(tmp_path_factory):
    q, r, e = open_chain()
    states, ids = draw(q, r, e, n_steps=400, inflow=6.0, n_start=150, seed=11)
    pos = positions_of(states, seed=12)
    times = np.arange(states.shape[0]) * LAG
    folder = tmp_path_factory.mktemp("open")
    dump = folder / "open.dump"
    dump.write_text(lammps_dump(times, ids, pos, STEP))
    run = import_file(dump, "lammps", folder / "open.h5", time_step=STEP)
    return {"q": q, "r": r, "e": e, "states": states, "ids": ids, "times": times, "run": run,
            "pos": pos}


def test_import_marks_the_riser_open_and_the_particles_that_come_and_go(open_run):
    with Trajectories(open_run["run"]) as t:
        assert t.boundary == "open" and t.has_absences
        order = np.argsort(t.ids)
        present = t.present()[:, order]
    np.testing.assert_array_equal(t.ids[order], open_run["ids"])
    np.testing.assert_array_equal(present, open_run["states"] >= 0)


def test_fit_gives_back_the_open_chain_within_sampling_error(open_run):
    space = CellGrid(6, 38, W, H)
    model = fit_model(open_run["run"], space, LAG, estimator="mle")
    assert model.boundary == "open"
    q_hat = model.absorbing_matrix
    visits = model.counts.sum(axis=1) + model.open_flow.exit_counts
    well = visits > 400
    assert well.sum() > 100
    sigma = np.sqrt(open_run["q"] * (1 - open_run["q"]) / np.maximum(visits, 1)[:, None])
    z = np.abs(q_hat - open_run["q"])[well] / np.maximum(sigma[well], 1e-12)
    assert z.max() < 5.0
    r_sigma = np.sqrt(open_run["r"] * (1 - open_run["r"]) / np.maximum(visits, 1))
    assert (np.abs(model.open_flow.exit_probability - open_run["r"])[well] <= 5 * r_sigma[well] + 1e-12).all()
    # entries only into the bottom row, evenly
    np.testing.assert_array_equal(np.flatnonzero(model.open_flow.entry_counts), np.arange(6))
    assert model.open_flow.inflow_per_lag == pytest.approx(6.0, rel=0.1)
    # saved and loaded unchanged
    with pytest.raises(InputError, match="paper's estimator .* --estimator mle"):
        fit_model(open_run["run"], space, LAG, estimator="paper")


def test_exact_rtd_is_the_fundamental_matrix_result(open_run, tmp_path):
    model = fit_model(open_run["run"], CellGrid(6, 38, W, H), LAG, estimator="mle")
    path = model.save(tmp_path / "m.h5")
    loaded = MarkovModel.load(path)
    np.testing.assert_array_equal(loaded.open_flow.exit_probability, model.open_flow.exit_probability)
    np.testing.assert_array_equal(loaded.open_flow.entry_counts, model.open_flow.entry_counts)
    assert loaded.open_flow.inflow_per_lag == model.open_flow.inflow_per_lag and loaded.boundary == "open"
    q, r, e = model.absorbing_matrix, model.open_flow.exit_probability, model.open_flow.entry_distribution
    fundamental = np.linalg.inv(np.eye(q.shape[0]) - q)
    mean_lags = e @ fundamental @ np.ones(q.shape[0])
    second = e @ fundamental @ (2 * fundamental - np.eye(q.shape[0])) @ np.ones(q.shape[0])
    rtd = loaded.rtd()
    assert rtd.unresolved < 1e-9
    assert rtd.mean == pytest.approx(mean_lags * LAG, rel=1e-8)
    assert rtd.sd == pytest.approx(np.sqrt(second - mean_lags ** 2) * LAG, rel=1e-6)
    v = e.copy()
    for k in range(5):                      # f(k) = e Q^(k-1) r
        assert rtd.probability[k] == pytest.approx(v @ r, abs=1e-15)
        v = v @ q
    # as a window sees it: the share of the residences begun in it that do not end in it,
    # 1 - sum f(k) (n_W - k)+ / n_W, as a periodic riser's window says it
    n_window = 40
    seen = loaded.rtd(window=n_window * LAG)
    k = np.arange(1, rtd.probability.size + 1)
    outlast = 1.0 - np.sum(rtd.probability * np.clip(n_window - k, 0, None)) / n_window
    assert seen.unresolved == pytest.approx(outlast, rel=1e-12) and outlast > 0.05


def test_reference_rtd_from_frames_equals_the_hand_count(open_run):
    states, times = open_run["states"], open_run["times"]
    window = (2.0, 7.0)
    inside = (times >= window[0] - 1e-9) & (times <= window[1] + 1e-9)
    k0, k1 = np.flatnonzero(inside)[[0, -1]]
    by_hand = []
    for p in range(states.shape[1]):
        alive = np.flatnonzero(states[:, p] >= 0)
        first, last = alive[0], alive[-1]
        exited = last + 1 < states.shape[0] and states[last, p] // 6 == 37
        if first > k0 and exited and last + 1 <= k1 and states[first, p] // 6 == 0:
            by_hand.append(times[last + 1] - times[first])
    with Trajectories(open_run["run"]) as t:
        samples = residence_times(t, window, face_band=H / 38).samples
    assert len(by_hand) > 100
    np.testing.assert_allclose(np.sort(samples), np.sort(by_hand), rtol=0, atol=1e-9)


def test_monte_carlo_of_the_open_riser_agrees_with_the_exact_rtd(open_run, tmp_path):
    """Particles present at the start move by the chain, newcomers enter at the fitted rate
    from the entry distribution, absorbed ones leave: the RTD of the prediction's frames
    agrees with the model's exact RTD in the window within sampling error, the inflow
    matches, and the run is the same for the same seed."""
    model = fit_model(open_run["run"], CellGrid(6, 38, W, H), LAG, estimator="mle")
    out = model.predict(open_run["run"], start=1.0, duration=7.0, seed=5, output=tmp_path / "p.h5")
    window = (1.0, 8.0)
    with Trajectories(out) as t:
        assert t.boundary == "open" and t.has_absences
        present = t.present()
        samples = residence_times(t, window, face_band=H / 38).samples
        with Trajectories(open_run["run"]) as ref:
            start_ids = ref.ids[ref.present(ref.frame_index(1.0))]
        np.testing.assert_array_equal(t.ids[present[0]], start_ids)
        entered = (present[1:] & ~present[:-1]).sum()
        assert entered / (t.n_frames - 1) == pytest.approx(model.open_flow.inflow_per_lag, rel=0.1)
    exact = model.rtd(window[1] - window[0])
    assert samples.size > 500
    se = samples.std(ddof=1) / np.sqrt(samples.size)
    assert abs(samples.mean() - exact.mean) < 4 * se
    again = model.predict(open_run["run"], start=1.0, duration=7.0, seed=5)
    states, _ = model.monte_carlo(np.zeros(0, np.int32), 3, seed=5)
    assert states.shape[0] == 4
    np.testing.assert_array_equal(again[1] >= 0, present)


def test_open_and_periodic_models_and_data_do_not_mix(open_run, tmp_path, capsys):
    from cfbmarkov.cli import main
    from cfbmarkov.synthetic import RiserFlow, write_run

    periodic = write_run(tmp_path / "per.h5", RiserFlow(), 50, 1.0, seed=1)
    open_model = fit_model(open_run["run"], CellGrid(6, 38, W, H), LAG, estimator="mle")
    open_model.save(tmp_path / "open.h5")
    fit_model(periodic, CellGrid(6, 38, W, H), 0.025, estimator="mle").save(tmp_path / "per-model.h5")
    for model, data, match in (("open.h5", periodic, "periodic riser; the model is of an open one"),
                               ("per-model.h5", open_run["run"], "open riser; the model is of a "
                                                                 "periodic one")):
        code = main(["predict", str(tmp_path / model), "--init", str(data), "--start", "0.5",
                     "--duration", "0.2", "-o", str(tmp_path / "x.h5")])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and match in err, err
    assert not (tmp_path / "x.h5").exists()


def test_the_verbs_work_on_an_open_riser(open_run, tmp_path, capsys, monkeypatch):
    """fit (mle by default), info, rtd, predict, compare and maps on open data."""
    from cfbmarkov.cli import main

    run, model = str(open_run["run"]), str(tmp_path / "m.h5")
    assert main(["fit", run, "--lag", "0.02", "--window", "0:4", "-o", model]) == 0
    out = capsys.readouterr().out
    assert "estimator 'mle'" in out and "open riser:" in out and "exits through the outlet" in out
    assert main(["rtd", model, "--window-length", "3"]) == 0
    assert "E(RT)" in capsys.readouterr().out
    pred = str(tmp_path / "p.h5")
    assert main(["predict", model, "--init", run, "--start", "4", "--duration", "3", "--seed",
                 "2", "-o", pred, "--quiet"]) == 0
    assert main(["compare", run, pred, "--window", "4:7", "-o", str(tmp_path / "cmp"),
                 "--no-figures"]) == 0
    import json

    summary = json.loads((tmp_path / "cmp" / "summary.json").read_text())
    assert summary["reference"]["rt_count"] > 50 and summary["model"]["rt_count"] > 50
    assert abs(summary["model"]["rt_mean"] / summary["reference"]["rt_mean"] - 1) < 0.15
    assert summary["units"]["mixing_rms"] == "fraction of the tracers still present"
    # a later window holds other particles on the two sides: refused, naming where to start
    capsys.readouterr()
    assert main(["compare", run, pred, "--window", "5:7", "-o", str(tmp_path / "cmp5"),
                 "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert "do not start from the same particles" in err
    assert "start the window at the prediction's first frame (4 s)" in err
    import cfbmarkov.report.figures as figures

    titles = []
    draw = figures.plot_probability_maps
    monkeypatch.setattr(figures, "plot_probability_maps",
                        lambda *a, title, **k: titles.append(title) or draw(*a, title=title, **k))
    assert main(["maps", model, "--times", "0.1,0.2", "-o", str(tmp_path / "maps.png")]) == 0
    plain = capsys.readouterr()
    assert "--outflow changes nothing" not in plain.err
    # the title says what an open riser's maps are, with --outflow or without
    assert titles[-1].endswith(", what has left taken out)")
    # --outflow: the same maps (an open riser always takes out what leaves), said so
    assert main(["maps", model, "--times", "0.1,0.2", "--outflow",
                 "-o", str(tmp_path / "maps-outflow.png")]) == 0
    outflow = capsys.readouterr()
    assert "note: an open riser's maps always take out what leaves through its outlet; " \
           "--outflow changes nothing here" in outflow.err
    assert outflow.out.splitlines()[:2] == plain.out.splitlines()[:2]
    assert titles[0] == titles[1]
    assert main(["info", pred]) == 0
    assert "vertical boundary open" in capsys.readouterr().out


def test_no_entry_in_the_window_and_no_complete_residence_are_refused(open_run, tmp_path, capsys):
    """An open riser's window in which no particle enters (an empty entry distribution) and a
    comparison window without a complete residence: one line, exit 2, nothing written."""
    from cfbmarkov.cli import main

    with Trajectories(open_run["run"]) as t:
        pos, present, times = t.positions(), t.present(), t.times
        ids = t.ids
    present = present.copy()
    born = present.argmax(axis=0)
    present[:, born > 0] = False            # only the particles there from the start
    path = tmp_path / "closed-inlet.h5"
    from cfbmarkov.trajectory_writer import write_trajectories

    write_trajectories(path, times, np.where(present[..., None], pos, np.nan), width=W, height=H,
                       ids=ids, present=present, boundary="open")
    code = main(["fit", str(path), "--lag", "0.02", "--window", "0:4", "-o", str(tmp_path / "m.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "entry distribution is empty" in err
    assert not (tmp_path / "m.h5").exists()
    model = tmp_path / "ok.h5"
    assert main(["fit", str(open_run["run"]), "--lag", "0.02", "--window", "0:4", "-o",
                 str(model)]) == 0
    pred = tmp_path / "p.h5"
    assert main(["predict", str(model), "--init", str(open_run["run"]), "--start", "4",
                 "--duration", "0.1", "-o", str(pred), "--quiet"]) == 0
    capsys.readouterr()
    code = main(["compare", str(open_run["run"]), str(pred), "--window", "4:4.1", "-q", "-o",
                 str(tmp_path / "cmp")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no residence begins and ends" in err
    assert not (tmp_path / "cmp").exists()


def _fast_open_riser(path, rise=0.05, n=150, frames=200, dt=0.01):
    """Particles entering one per frame at the inlet and rising ``rise`` of the height a
    frame: each is last seen up to ``rise`` H below the outlet (below a face band of H/38
    about half of them), then vanishes."""
    from cfbmarkov.trajectory_writer import write_trajectories

    height = 0.95
    k = np.arange(frames)[:, None] - np.arange(n)[None, :]      # frames since entry
    y = (0.005 + rise * k + 0.013 * (np.arange(n) % 4)) * height
    present = (k >= 0) & (y < height)
    x = np.broadcast_to(0.01 + 0.02 * (np.arange(n) % 4), y.shape)
    positions = np.stack([x, np.where(present, y, np.nan)], axis=-1)
    return write_trajectories(path, dt * np.arange(frames), positions, width=0.09,
                              height=height, present=present, boundary="open")


def test_an_open_riser_counts_exits_within_one_cell_row_of_the_outlet(tmp_path, capsys):
    """The fit's verdict and --states auto count an open riser's residences as compare does,
    a particle vanishing within one cell row of the outlet having left: on 4 x 10 cells the
    halves of the window hold their residences (no 'holds 0 residences' warning), where the
    paper's face band of H/38 would miss about half of the exits; auto judges by the
    Chapman-Kolmogorov test, and an RTD criterion is refused on an open riser."""
    from cfbmarkov.cli import main
    from cfbmarkov.markov.select import select_model

    run = _fast_open_riser(tmp_path / "fast.h5")
    with Trajectories(run) as t:
        band = residence_times(t, (0.3, 1.5), face_band=t.height / 10).count
        thin = residence_times(t, (0.3, 1.5)).count
    assert band >= 100 and thin < 0.75 * band
    assert main(["fit", str(run), "--cells", "4x10", "--lag", "0.01", "--window", "0.3:1.5",
                 "-o", str(tmp_path / "m.h5")]) == 0
    err = capsys.readouterr().err
    assert "residences (fewer than" not in err
    longer = _fast_open_riser(tmp_path / "longer.h5", n=350, frames=400)
    model = select_model(longer, window=(0.3, 3.5), columns=4, rows=10, lag=0.01,
                         states=("cells", "cells-direction"))
    assert "Chapman-Kolmogorov" in model.selection["reason"]
    with pytest.raises(InputError, match="the window criterion judges a periodic riser's RTD"):
        select_model(run, window=(0.3, 1.5), columns=4, rows=10, lag=0.01,
                     states=("cells", "cells-direction"), criterion="window")


def test_a_memory_model_says_which_particles_it_cannot_start(tmp_path):
    """On an open riser a particle that entered within the memory of the state space has no
    state at the start frame: the prediction leaves it out and says so; a model on cells
    starts every particle present."""
    import warnings

    from cfbmarkov.errors import CfbmarkovWarning
    from cfbmarkov.markov import state_space_from_name

    run = _fast_open_riser(tmp_path / "fast.h5", n=350, frames=400)
    memory = state_space_from_name("cells-direction", 4, 10, 0.09, 0.95)
    model = fit_model(run, memory, 0.01, (0.3, 2.5), estimator="mle")
    with pytest.warns(CfbmarkovWarning, match=r"1 of \d+ particles present at 2\.5 s have no "
                                              r"state in cells-direction"):
        model.predict(run, 2.5, 0.2, seed=1)
    cells = fit_model(run, CellGrid(4, 10, 0.09, 0.95), 0.01, (0.3, 2.5), estimator="mle")
    with warnings.catch_warnings():
        warnings.simplefilter("error", CfbmarkovWarning)
        cells.predict(run, 2.5, 0.2, seed=1)
    # compare takes the particles the prediction started as the tracers on both sides
    from cfbmarkov.report.compare import compare

    with pytest.warns(CfbmarkovWarning):
        pred = model.predict(run, 2.5, 1.4, seed=1, output=tmp_path / "p.h5")
    summary = compare(run, pred, window=(2.5, 3.9), output=tmp_path / "cmp", figures=False,
                      resamples=0)
    said = [w for w in summary["warnings"] if "the prediction started" in w]
    assert said and "the mixing curves follow those it started, on both sides" in said[0]
    assert summary["mixing_rms"] == summary["mixing_rms"]        # a number, not NaN
    # the frames weigh as the tracers still present on both sides (the fewer of the two)
    from cfbmarkov.analysis.mixing import mixing_curve_of
    from cfbmarkov.trajectories import Trajectories

    with Trajectories(run) as ref, Trajectories(pred) as mod:
        tracers = mod.ids[mod.present(mod.window(2.5, 3.9).start)]
        t_ref, f_ref, n_ref = mixing_curve_of(ref, (2.5, 3.9), tracers=tracers, counts=True)
        t_mod, f_mod, n_mod = mixing_curve_of(mod, (2.5, 3.9), tracers=tracers, counts=True)
    assert n_mod[0] == n_ref[0] == tracers.size and n_mod[-1] < n_mod[0]
    weights = np.minimum(n_mod, n_ref)
    both = np.isfinite(f_ref) & np.isfinite(f_mod) & (weights > 0)
    hand = np.sqrt(np.sum(weights[both] * (f_mod[both] - f_ref[both]) ** 2) / weights[both].sum())
    assert summary["mixing_rms"] == pytest.approx(hand, rel=1e-9)
    assert summary["mixing_frames"] == both.sum()


def test_a_memory_space_counts_the_entries_where_the_particles_were_first_seen(tmp_path):
    """A state space with memory gives a newcomer its first state a lag after it is first
    seen; a particle first seen within one cell of the inlet entered there, even where it
    has risen past that cell by its first state. cells-direction then counts every entry
    that cells counts, none censored (it counted the risen ones as tracks that began away
    from the inlet, and its inflow fell short)."""
    from cfbmarkov.markov import state_space_from_name

    run = _fast_open_riser(tmp_path / "fast.h5", rise=0.08, n=300, frames=300)
    cells = fit_model(run, CellGrid(4, 10, 0.09, 0.95), 0.01, (0.3, 2.5), estimator="mle")
    memory = fit_model(run, state_space_from_name("cells-direction", 4, 10, 0.09, 0.95), 0.01,
                       (0.3, 2.5), estimator="mle")
    entered = int(cells.open_flow.entry_counts.sum())
    assert entered > 150 and cells.open_flow.censored_tracks == (0, 0)
    assert int(memory.open_flow.entry_counts.sum()) == entered
    assert memory.open_flow.censored_tracks[1] == 0
    assert memory.open_flow.inflow_per_lag == pytest.approx(cells.open_flow.inflow_per_lag)


def test_an_open_memory_models_batch_enters_as_its_particles_entered(tmp_path):
    """Eq. (8)'s batch on an open riser with a state space with memory: each bottom cell's
    share is split over its states as the fitting window's particles entered them through
    the inlet face (all rising here), not evenly."""
    from cfbmarkov.markov import state_space_from_name
    from cfbmarkov.markov.propagation import inlet_batch

    run = _fast_open_riser(tmp_path / "fast.h5", n=300, frames=300)
    memory = fit_model(run, state_space_from_name("cells-direction", 4, 10, 0.09, 0.95), 0.01,
                       (0.3, 2.5), estimator="mle")
    space, entries = memory.state_space, memory.open_flow.entry_counts
    batch = inlet_batch(memory)
    bottom = space.cell_of_state < space.cells_per_row
    assert batch.sum() == pytest.approx(1.0)
    rising = bottom & ~space.falling(np.arange(memory.n_states))
    assert entries[bottom & ~rising].sum() == 0 and entries[rising].sum() > 100
    assert np.all(batch[bottom & ~rising] == 0)
    assert batch[rising] == pytest.approx(np.full(rising.sum(), 1.0 / space.cells_per_row))


def test_stationarity_on_an_open_riser_takes_the_models_face_band_and_warns(tmp_path, capsys):
    """The sliding windows of an open riser count entries and exits within a face band of
    one cell (H/38 by default, --cells sets the rows): where most tracks end outside it, a
    warning names how many and the option; with the model's 10 rows every residence counts
    as compare counts it."""
    import json

    from cfbmarkov.analysis.stationarity import check_stationarity
    from cfbmarkov.cli import main

    run = _fast_open_riser(tmp_path / "fast.h5", rise=0.08, n=300, frames=300)
    thin = check_stationarity(run, window_length=1.0, step=1.0, span=(0.5, 2.5))
    band = check_stationarity(run, window_length=1.0, step=1.0, span=(0.5, 2.5),
                              face_band=0.95 / 10)
    with Trajectories(run) as t:
        counted = residence_times(t, (0.5, 1.5), face_band=t.height / 10).count
    assert band.statistics.rt_count[0] == counted > 50
    assert thin.statistics.rt_count[0] < 0.5 * counted
    [line] = thin.warnings
    assert "tracks that ended in 0.5-2.5 s ended farther than the face band from the outlet" \
        in line and "give --cells with the rows of your model" in line
    assert band.warnings == ()
    assert main(["stationarity", str(run), "--span", "0.5:2.5", "--window-length", "1",
                 "--cells", "4x10", "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["warnings"] == [] and "warning:" not in out.err
    assert main(["stationarity", str(run), "--span", "0.5:2.5", "--window-length", "1"]) == 0
    assert capsys.readouterr().err.count("warning: ") == 1


def test_an_open_riser_imported_as_periodic_is_refused_at_fit(tmp_path, capsys):
    """An open riser written as periodic (imported without --boundary open): its particles
    come and go and none passes through the boundary; fit refuses in one line naming
    --boundary open, and writes no model."""
    from cfbmarkov.cli import main
    from cfbmarkov.trajectory_writer import write_trajectories

    with Trajectories(_fast_open_riser(tmp_path / "fast.h5", n=300, frames=300)) as t:
        times, positions, present = t.times[:], t.positions(), t.present(slice(None))
    periodic = write_trajectories(tmp_path / "as-periodic.h5", times, positions, width=0.09,
                                  height=0.95, present=present)
    out = tmp_path / "m.h5"
    assert main(["fit", str(periodic), "--cells", "4x10", "--lag", "0.01", "--window",
                 "0.3:2.5", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is read as a periodic riser" in err
    assert "imported with --boundary open" in err and not out.exists()


def test_compare_against_another_open_run_names_the_run_the_prediction_started_from(
        tmp_path, capsys):
    """A prediction compared from its first frame with another run's file: the particles
    differ because the reference is not the run it started from, and the refusal says so
    (it advised starting the window at the prediction's first frame, where it started)."""
    from cfbmarkov.cli import main

    from cfbmarkov.trajectory_writer import write_trajectories

    run = _fast_open_riser(tmp_path / "fast.h5", n=300, frames=300)
    with Trajectories(run) as t:            # another run: the same riser, other particles
        other = write_trajectories(tmp_path / "other.h5", t.times[:], t.positions(),
                                   width=0.09, height=0.95, ids=t.ids + 1000,
                                   present=t.present(slice(None)), boundary="open")
    model = tmp_path / "m.h5"
    assert main(["fit", str(run), "--cells", "4x10", "--lag", "0.01", "--window", "0.3:2",
                 "--resamples", "0", "--no-adequacy", "-q", "-o", str(model)]) == 0
    pred = tmp_path / "p.h5"
    assert main(["predict", str(model), "--init", str(run), "--start", "2", "--duration", "0.9",
                 "-q", "-o", str(pred)]) == 0
    capsys.readouterr()
    assert main(["compare", str(other), str(pred), "--window", "2:2.9", "-q",
                 "-o", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"was predicted from {run}: give that as the reference" in err


def test_auto_on_an_open_riser_says_it_judges_by_the_chapman_kolmogorov_test(tmp_path, capsys):
    """The progress line of fit --states auto names the criterion it uses: on an open riser
    the Chapman-Kolmogorov test (it said the candidates' RTDs were compared)."""
    from cfbmarkov.cli import main

    run = _fast_open_riser(tmp_path / "fast.h5", n=350, frames=400)
    assert main(["fit", str(run), "--cells", "4x10", "--lag", "0.01", "--window", "0.3:3.5",
                 "--states", "auto", "--resamples", "0", "--no-adequacy",
                 "-o", str(tmp_path / "m.h5")]) == 0
    err = capsys.readouterr().err
    assert "(each fitted and judged by the Chapman-Kolmogorov test, an open riser's criterion)" \
        in err and "RTD" not in err.split("judging the candidate", 1)[1].split("\n", 1)[0]
