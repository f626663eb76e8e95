"""``fit`` on a periodic file with particles absent from some frames (PEPT, PTV imports),
and the warnings of a fit whose exact RTD leaves mass unresolved, whose grid is mostly never
visited or whose interval reaches 0."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.markov import MarkovModel
from cfbmarkov.markov.uncertainty import ModelUncertainty
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_fit_of_a_periodic_file_with_absences_writes_the_model_with_verdict_and_interval(
        tmp_path, capsys):
    """Particles drop out of view for stretches of frames: the model, its sample verdict
    (residences counted within each stretch of presence) and its interval are all formed."""
    flow = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)
    full = synthetic.write_run(tmp_path / "full.h5", flow, 300, 6.0, seed=4)
    with Trajectories(full) as t:
        times, pos, laps = t.times, t.positions(), t.laps()
    rng = np.random.default_rng(2)
    present = np.ones(laps.shape, bool)
    for p in rng.choice(laps.shape[1], 120, replace=False):     # 40 % leave view once
        a = rng.integers(0, laps.shape[0] - 40)
        present[a:a + rng.integers(5, 40), p] = False
    path = write_trajectories(tmp_path / "gaps.h5", times, np.where(present[..., None], pos,
                                                                    np.nan),
                              width=flow.width, height=flow.height, laps=laps, present=present)
    model = tmp_path / "m.h5"
    code, out, err = run_cli(capsys, "fit", path, "--cells", "4x16", "--lag", "0.05",
                             "--window", "0:6", "-o", model, "--resamples", "20")
    assert code == 0, err
    assert "Traceback" not in err and "cannot" not in err, err
    assert out.strip().splitlines()[-1] == str(model)
    loaded = MarkovModel.load(model)
    assert loaded.adequacy is not None and loaded.uncertainty is not None
    assert loaded.adequacy.parts           # the halves (or quarters) were fitted and judged
    lo, hi = loaded.uncertainty.rt_mean_interval
    assert 0 < lo < loaded.rtd().mean < hi


def _trap_run(tmp_path):
    """4 x 10 cells of a 1 x 2 riser, frames 1 s apart: particle 0 climbs column 1 a row
    a frame and passes the top every 10 frames; particle 1 starts in the same cell, moves
    to column 2 of row 1 and stays there. The chain enters that cell from the entry state
    with probability 1/11 and never leaves it: unresolved mass about 0.09, and 29 of the
    40 states never visited."""
    frames = 101
    rows = np.arange(frames) % 10
    states = np.empty((frames, 2), np.int64)
    states[:, 0] = rows * 4 + 1
    states[:, 1] = 1 * 4 + 2
    states[0, 1] = 1
    col, row = states % 4, states // 4
    pos = np.stack([(col + 0.5) / 4, (row + 0.5) * 2.0 / 10], axis=-1)
    return write_trajectories(tmp_path / "trap.h5", np.arange(frames, dtype=float), pos,
                              width=1.0, height=2.0)


def test_unresolved_mass_and_a_grid_mostly_never_visited_are_warned_about(tmp_path, capsys):
    path, model = _trap_run(tmp_path), tmp_path / "m.h5"
    code, out, err = run_cli(capsys, "fit", path, "--cells", "4x10", "--lag", "1",
                             "--window", "0:100", "-o", model, "--resamples", "0",
                             "--no-adequacy")
    assert code == 0, err
    unresolved = MarkovModel.load(model).rtd().unresolved
    assert 0.05 < unresolved < 0.15
    warnings = [line for line in err.splitlines() if line.startswith("warning: ")]
    assert any("29 of 40 states never visited" in w and "coarser --cells" in w
               for w in warnings), err
    text = [w for w in warnings if "unresolved mass" in w]
    assert len(text) == 1 and f"describe only the resolved {100 * (1 - unresolved):.3g} %" \
        in text[0] and "coarser grid (--cells)" in text[0] and "longer window" in text[0]
    # the numbers themselves are unchanged: the summary still prints E(RT) and SD(RT)
    assert "exact residence time: E(RT) = " in out
    code, out, err = run_cli(capsys, "rtd", model)
    assert code == 0 and "unresolved mass" in err and err.startswith("warning: ")
    code, out, err = run_cli(capsys, "rtd", model, "--json")
    data = json.loads(out)
    assert code == 0 and any("describe only the resolved" in w for w in data["warnings"])
    assert data["unresolved"] == unresolved
    code, out, err = run_cli(capsys, "info", model)
    assert code == 0 and "describe only the resolved" in out and "29 of 40 states never" in out


def test_a_well_resolved_fit_has_none_of_these_warnings(tmp_path, capsys, markov_run):
    model = tmp_path / "m.h5"
    code, out, err = run_cli(capsys, "fit", markov_run, "--cells", "4x16", "--lag", "0.05",
                             "--window", "1:5", "-o", model, "--resamples", "0",
                             "--no-adequacy")
    assert code == 0, err
    assert "unresolved mass" not in err and "never visited (more than" not in err
    code, out, err = run_cli(capsys, "rtd", model, "--json")
    assert json.loads(out)["warnings"] == []


def test_an_interval_cut_at_zero_says_so_instead_of_printing_a_bare_zero():
    edges = np.array([0.0, 0.1, 0.2])
    band = np.array([[0.0, 0.0], [0.6, 0.6]])
    cut = ModelUncertainty(0.9, (0.129, 0.22), (0.0, 0.159), edges, band, 100, 10, 0.1,
                           (0.13, 0.842))
    text = cut.describe(0.1811, 0.06647)
    assert "0-0.159" not in text and "up to 0.1590 s, its lower end cut at 0" in text
    assert "(90 % interval 0.1290-0.2200 s)" in text
    lines = cut.cut_at_zero()
    assert len(lines) == 1 and lines[0].startswith("the 90 % interval of SD(RT) reaches 0")
    assert "84.2 % of SD(RT)" in lines[0]
    whole = ModelUncertainty(0.9, (0.129, 0.22), (0.03, 0.159), edges, band, 100, 10, 0.1,
                             (0.13, 0.2))
    assert whole.cut_at_zero() == [] and "0.03000-0.1590 s" in whole.describe(0.18, 0.066)
    # no flow term: the bootstrap's spread below the figure reached it (skewed resamples,
    # a few far below the figure or at 0), not "resamples give 0", which a window whose
    # net flow turns reaches without any resample at 0
    boot = ModelUncertainty(0.9, (0.129, 0.22), (0.0, 0.159), edges, band, 100, 10, 0.1,
                            bootstrap_widening=1.17)
    line = boot.cut_at_zero()[0]
    assert "the spread of the bootstrap resamples' SD(RT) below the figure, widened 1.17 " \
        "times for the few blocks drawn, exceeds the figure itself" in line
    assert "a few of them far below SD(RT) (or at 0)" in line and "give SD(RT) 0" not in line
    # a flow term too small to reach 0 alone: the bootstrap's spread with it added
    small = ModelUncertainty(0.9, (0.129, 0.22), (0.0, 0.159), edges, band, 100, 10, 0.1,
                             (0.13, 0.1))
    line = small.cut_at_zero()[0]
    assert "with the flow's variability between its blocks (16.4 % of SD(RT) with its " \
        "quantile) added exceeds the figure itself" in line
    assert "so the interval's lower half-width exceeds" not in line


def test_an_interval_on_fewer_resamples_than_drawn_says_so(tmp_path):
    """38 of 100 resamples with residences: a line says the interval rests on them; all of
    them, or no count drawn recorded (an older file): none. The count drawn survives the
    model file."""
    import h5py

    from cfbmarkov.markov.uncertainty import GROUP

    edges = np.array([0.0, 0.1, 0.2])
    band = np.array([[0.0, 0.0], [0.6, 0.6]])
    short = ModelUncertainty(0.9, (0.129, 0.22), (0.03, 0.159), edges, band, 38, 10, 0.1,
                             None, 100, bootstrap_widening=1.175)
    lines = short.warnings()
    assert len(lines) == 1 and lines[0].startswith(
        "the 90 % interval rests on 38 of the 100 bootstrap resamples drawn")
    assert short.to_dict()["requested"] == 100
    for whole in (ModelUncertainty(0.9, (0.129, 0.22), (0.03, 0.159), edges, band, 100, 10,
                                   0.1, None, 100, bootstrap_widening=1.175),
                  ModelUncertainty(0.9, (0.129, 0.22), (0.03, 0.159), edges, band, 38, 10,
                                   0.1, bootstrap_widening=1.175)):
        assert whole.warnings() == []
    with h5py.File(tmp_path / "u.h5", "w") as f:
        for name, value in short.file_fields().items():
            f[name] = value
        assert ModelUncertainty.from_group(f).requested == 100
        del f[f"{GROUP}/requested"]
        assert ModelUncertainty.from_group(f).requested is None


def test_an_interval_formed_without_the_bootstraps_widening_says_so(tmp_path):
    """A model file whose interval records no bootstrap widening (an earlier cfbmarkov's)
    loads with a warning naming the factor its bootstrap part lacks (1.17 for 10 blocks at
    90 %); the recorded factor survives the model file and silences it."""
    import h5py

    from cfbmarkov.markov.uncertainty import GROUP

    edges = np.array([0.0, 0.1, 0.2])
    band = np.array([[0.0, 0.0], [0.6, 0.6]])
    widened = ModelUncertainty(0.9, (0.129, 0.22), (0.03, 0.159), edges, band, 100, 10, 0.1,
                               bootstrap_widening=1.175)
    assert widened.warnings() == [] and widened.to_dict()["bootstrap_widening"] == 1.175
    with h5py.File(tmp_path / "u.h5", "w") as f:
        for name, value in widened.file_fields().items():
            f[name] = value
        assert ModelUncertainty.from_group(f).bootstrap_widening == 1.175
        del f[f"{GROUP}/bootstrap_widening"]
        older = ModelUncertainty.from_group(f)
    lines = older.warnings()
    assert older.bootstrap_widening is None and len(lines) == 1
    assert lines[0].startswith("the 90 % interval was formed without the bootstrap's widening "
                               "for its 10 blocks") and "about 1.17 times too narrow" in lines[0]
    pooled = ModelUncertainty(0.9, (0.129, 0.22), (0.03, 0.159), edges, band, 100, 40, 0.1)
    line = pooled.warnings(runs=4)[0]        # 10 blocks in each of 4 runs: t with 36 dof
    assert "for its 10 blocks in each of 4 runs" in line and "about 1.08 times" in line
    with pytest.raises(InputError, match="bootstrap_widening"):
        ModelUncertainty(0.9, (0.129, 0.22), (0.03, 0.159), edges, band, 100, 10, 0.1,
                         bootstrap_widening=0.5)


def test_interval_bounds_print_rounded_outwards():
    """The printed interval holds every value the stored one holds: each bound rounded to 3
    significant digits away from the centre (2.3593 down to 2.35, 2.3940 up to 2.40, where
    rounding to the nearest printed 2.36-2.39 and left 2.3595 outside), a bound already on
    the grid kept, trailing zeros kept."""
    from cfbmarkov.markov.uncertainty import outward_bounds

    assert outward_bounds(2.3593, 2.3940) == ("2.35", "2.40")
    assert outward_bounds(0.76809, 0.95003) == ("0.768", "0.951")
    assert outward_bounds(0.768, 0.95) == ("0.768", "0.950")
    assert outward_bounds(0.0, 1.95) == ("0", "1.95")
    assert outward_bounds(-2.3593, -1.2345) == ("-2.36", "-1.23")
    assert outward_bounds(-0.0, 1.0) == ("0", "1.00")
    assert outward_bounds(5e-324, float("inf")) == ("4.94e-324", "inf")   # no overflow
    # many digits (a reference within 1e-8 of a bound asks for them): still outwards, the
    # on-grid slack a few units in the last place, not a unit of the 9th or 10th digit
    assert outward_bounds(0.6480012345678, 0.6480012345699, 10) == ("0.6480012345",
                                                                     "0.6480012346")
    assert outward_bounds(0.9999999999944935, 0.999999999999519, 10) == ("0.9999999999",
                                                                         "1.000000000")
    assert outward_bounds(0.1 + 0.2, 0.3, 4) == ("0.3000", "0.3000")    # on the grid
    edges = np.array([0.0, 0.1, 0.2])
    band = np.array([[0.0, 0.0], [0.6, 0.6]])
    u = ModelUncertainty(0.9, (2.3593, 2.3940), (0.0, 0.8271), edges, band, 100, 10, 0.1,
                         bootstrap_widening=1.175)
    text = u.describe(2.377, 0.81)          # 4 digits, like the point values
    assert "(90 % interval 2.359-2.394 s)" in text
    assert "up to 0.8271 s, its lower end cut at 0" in text
    u = ModelUncertainty(0.9, (2.35934, 2.39401), (0.0, 0.82712), edges, band, 100, 10, 0.1,
                         bootstrap_widening=1.175)
    assert "(90 % interval 2.359-2.395 s)" in u.describe(2.377, 0.81)


def test_a_short_window_lengths_unresolved_mass_is_named_as_such(tmp_path, capsys):
    """`rtd --window-length` shorter than most residences: the mass not ended within the
    window is said to be the longer residences, not a chain that never reaches the top (the
    advice to coarsen the grid does not apply); the intrinsic RTD of the same model has
    none to speak of."""
    flow = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)
    run = synthetic.write_run(tmp_path / "run.h5", flow, 200, 4.0, seed=3)
    model = tmp_path / "m.h5"
    assert main(["fit", str(run), "--cells", "4x16", "--window", "0:4", "--estimator", "mle",
                 "--resamples", "0", "-o", str(model)]) == 0
    capsys.readouterr()
    assert main(["rtd", str(model), "--window-length", "2"]) == 0
    err = capsys.readouterr().err
    line = next(x for x in err.splitlines() if "unresolved mass" in x)
    assert "in the 2 s window: the share of the residences begun in the window that do " \
           "not end in it (those begun too late in it to end" in line
    assert "coarser grid" not in line and "longer --window-length" not in line
    assert main(["rtd", str(model)]) == 0
    assert "unresolved mass" not in capsys.readouterr().err
    # a window long for the flow: its share cut (about E(RT) / W) is stated, not warned of
    assert main(["rtd", str(model), "--window-length", "20"]) == 0
    out, err = capsys.readouterr()
    assert "unresolved mass" not in err
    share = float(out.split("unresolved mass ")[1].split(":")[0])
    assert 0.01 < share < 0.5
    assert out.splitlines()[0].endswith(": the share of the residences begun in the window "
                                        "that outlast it)")


def test_a_band_out_of_view_fitted_connected_is_not_told_to_fit_connected(tmp_path, capsys):
    """Tracers never seen between 0.30 and 0.60 m: no transition climbs past the band, so
    every residence is trapped below it, with or without --connected. The refusal with
    --connected names the band's kind of cause, not the option just given."""
    from cfbmarkov.cli import main
    from cfbmarkov.synthetic import RiserFlow, sample_run
    from cfbmarkov.trajectory_writer import write_trajectories

    flow = RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                     vertical_spread=0.5, persistence=False)
    times, _, pos, laps = sample_run(flow, 3, 2401, seed=42)
    present = ~((pos[..., 1] >= 0.30) & (pos[..., 1] < 0.60))
    pos = pos.copy()
    pos[~present] = np.nan
    run = write_trajectories(tmp_path / "blind.h5", times, pos, width=flow.width,
                             height=flow.height, laps=laps, present=present)
    code = main(["fit", str(run), "--cells", "4x16", "--lag", str(flow.lag), "--connected",
                 "-o", str(tmp_path / "m.h5")])
    err = capsys.readouterr().err
    assert code == 2 and "every residence is trapped" in err
    assert "fit with --connected" not in err
    assert "fitted with --connected: no transition of the window climbs past some height" \
        in err


def test_a_prediction_from_a_frame_where_tracks_are_out_of_view_says_who_it_leaves_out(
        tmp_path):
    """Tracks seen one second in four: at the start frame most particles are out of view;
    the prediction moves those present and says how many it leaves out (it printed "23
    particles" for a file of 500, nothing more)."""
    from cfbmarkov.errors import CfbmarkovWarning
    from cfbmarkov.markov import CellGrid, fit_model
    from cfbmarkov.synthetic import RiserFlow, sample_run
    from cfbmarkov.trajectory_writer import write_trajectories

    flow = RiserFlow(columns=4, rows=8, persistence=False)
    times, _, pos, laps = sample_run(flow, 40, 401, seed=3)
    present = np.zeros(pos.shape[:2], bool)
    for p in range(40):
        for start in range(p % 4 * 10, 401, 160):
            present[start:start + 40, p] = True
    pos = pos.copy()
    pos[~present] = np.nan
    run = write_trajectories(tmp_path / "ptv.h5", times, pos, width=flow.width,
                             height=flow.height, laps=laps, present=present)
    model = fit_model(run, CellGrid(4, 8), flow.lag, None, "mle")
    at = int(np.argmax(present.sum(axis=1) < 40))
    here = int(present[at].sum())
    with pytest.warns(CfbmarkovWarning, match=rf"{40 - here} of the 40 particles of .* are "
                      rf"absent at .* and left out: the prediction moves the {here} present"):
        model.predict(run, start=float(times[at]), duration=4 * flow.lag, seed=1,
                      output=tmp_path / "p.h5")


def test_the_verdict_on_tracks_with_absences_does_not_send_to_stationarity(tmp_path, capsys):
    """`stationarity` refuses a periodic run whose particles are absent from some frames
    (no residence is observed across an absence), so the verdict's advice on such a run
    leaves it out; on a run without absences it is kept."""
    from cfbmarkov.cli import main
    from cfbmarkov.synthetic import RiserFlow, sample_run
    from cfbmarkov.trajectory_writer import write_trajectories

    flow = RiserFlow(columns=4, rows=8, persistence=False)
    times, _, pos, laps = sample_run(flow, 40, 201, seed=3)
    for name, hidden in (("gaps", True), ("whole", False)):
        present = np.ones(pos.shape[:2], bool)
        if hidden:
            present[50:60, :20] = False
        seen = np.where(present[..., None], pos, np.nan)
        run = write_trajectories(tmp_path / f"{name}.h5", times, seen, width=flow.width,
                                 height=flow.height, laps=laps, present=present)
        assert main(["fit", str(run), "--cells", "4x8", "--lag", str(flow.lag), "--window",
                     "0:1.5", "--estimator", "mle", "-o", str(tmp_path / f"{name}-m.h5"),
                     "-q"]) == 0
        err = capsys.readouterr().err
        assert "warning:" in err
        assert ("stationarity RUN --sample-length" in err) is not hidden
    # an open riser's absences are its entries and exits, which stationarity reads
    from cfbmarkov.synthetic import write_open_run

    run = write_open_run(tmp_path / "open.h5", flow, 40, 5.0, seed=3)
    assert main(["fit", str(run), "--cells", "4x8", "--lag", str(flow.lag), "--window",
                 "0:1.5", "-o", str(tmp_path / "open-m.h5"), "-q"]) == 0
    err = capsys.readouterr().err
    assert "warning:" in err and "stationarity RUN --sample-length" in err


def test_a_particle_outside_the_riser_in_every_frame_leaves_predict_and_compare_to_the_others(
        tmp_path, capsys):
    """A periodic run with one particle absent from every frame (a dump's atom beyond the
    walls, cut by --region): predict moves the others and says so, and compare follows the
    same particles on both sides, its reference residences those of the file without the
    absent particle (compare refused the file, pointing to an import that refuses a
    periodic box). A particle absent from part of the window is still refused."""
    from cfbmarkov.observed.residence import residence_times
    from cfbmarkov.synthetic import RiserFlow, sample_run

    flow = RiserFlow(columns=4, rows=8, persistence=False)
    times, _, pos, laps = sample_run(flow, 60, 321, seed=5)
    present = np.ones(pos.shape[:2], bool)
    present[:, 7] = False
    ghost = pos.copy()
    ghost[:, 7] = np.nan
    run = write_trajectories(tmp_path / "ghost.h5", times, ghost, width=flow.width,
                             height=flow.height, laps=laps, present=present)
    keep = np.arange(60) != 7
    plain = write_trajectories(tmp_path / "plain.h5", times, pos[:, keep], width=flow.width,
                               height=flow.height, laps=laps[:, keep],
                               ids=np.arange(60)[keep])
    model = tmp_path / "m.h5"
    assert run_cli(capsys, "fit", run, "--cells", "4x8", "--lag", str(flow.lag), "--window",
                   "0:4", "--resamples", "0", "-o", model)[0] == 0
    code, _, err = run_cli(capsys, "predict", model, "--init", run, "--start", "4",
                           "--duration", "4", "--seed", "3", "-q", "-o", tmp_path / "p.h5")
    assert code == 0 and "1 of the 60 particles" in err
    code, _, err = run_cli(capsys, "compare", run, tmp_path / "p.h5", "--window", "4:8",
                           "--resamples", "0", "--no-figures", "-o", tmp_path / "cmp")
    assert code == 0, err
    summary = json.loads((tmp_path / "cmp" / "summary.json").read_text())
    with Trajectories(plain) as t:
        own = residence_times(t, (4.0, 8.0), use_events=False)
    assert summary["reference"]["rt_count"] == own.count > 20
    with Trajectories(run) as t:
        got = residence_times(t, (4.0, 8.0), use_events=False)
    np.testing.assert_array_equal(np.sort(got.samples), np.sort(own.samples))
    # a particle out of view in part of the window hides passes: refused, as before
    present[200:240, 3] = False
    ghost[200:240, 3] = np.nan
    gap = write_trajectories(tmp_path / "gap.h5", times, ghost, width=flow.width,
                             height=flow.height, laps=laps, present=present)
    code, _, err = run_cli(capsys, "compare", gap, tmp_path / "p.h5", "--window", "4:8",
                           "--resamples", "0", "--no-figures", "-o", tmp_path / "cmp2")
    assert code == 2 and "absent from some frames" in err


def test_the_summary_counts_the_verdicts_lines_and_the_models_others_apart(markov_run,
                                                                           markov_flow):
    """A verdict of two lines on a model whose interval is cut at 0: the `warning:` lines
    ``fit`` prints are said as the verdict's two and the others about the model (the lines
    add up)."""
    from cfbmarkov.markov import fit_model
    from cfbmarkov.markov.adequacy import Adequacy

    model = fit_model(markov_run, markov_flow.grid, markov_flow.lag, (2.0, 6.0), "mle")
    edges = np.array([0.0, 0.1, 0.2])
    band = np.array([[0.0, 0.0], [0.6, 0.6]])
    cut = ModelUncertainty(0.9, (0.129, 0.22), (0.0, 0.159), edges, band, 100, 10, 0.1,
                           (0.13, 0.842))
    model = model.with_uncertainty(cut).with_adequacy(
        Adequacy(warnings=("the halves disagree", "the runs disagree")))
    others = len(model.warnings()) - 2
    assert others >= 1 and any("cut there" in line for line in model.warnings())
    text = model.summary(warnings=False)
    assert ("the fitting sample's verdict: 2 warnings (printed as `warning:` lines, beside "
            f"{others} more about the model; `cfbmarkov info MODEL` repeats them)") in text
    alone = model.with_uncertainty(None).summary(warnings=False)
    assert "2 warnings (printed as `warning:` lines; `cfbmarkov info" in alone
