"""``compare`` end to end on small generated files, its errors, the command line, and the
figure functions."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cfbmarkov.analysis.compare import RunComparison, compare_runs
from cfbmarkov.analysis.figure_inputs import map_times
from cfbmarkov.observed.metrics import minkowski_distance, mixing_rms, percentage_difference
from cfbmarkov.analysis.mixing import mixing_curve_of
from cfbmarkov.observed.residence import residence_times, rtd_histogram
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.report import figures as fg
from cfbmarkov.report.compare import compare
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

PNG = b"\x89PNG\r\n\x1a\n"
WINDOW = (0.5, 3.0)
SPEC_KEYS = {"window", "reference", "model", "pd_rt_mean", "pd_rt_sd", "md_rtd", "md_order",
             "mixing_rms"}


def assert_png(path):
    data = path.read_bytes()
    assert data[:8] == PNG and len(data) > 5000, path


def test_summary_matches_direct_calls(pair, tmp_path):
    ref_path, pred_path = pair
    out = tmp_path / "report"
    summary = compare(ref_path, pred_path, window=WINDOW, output=out, bin_width=0.05,
                      md_order=3.0)
    saved = json.loads((out / "summary.json").read_text())
    assert SPEC_KEYS <= saved.keys()
    assert saved["window"] == [0.5, 3.0]
    for side in ("reference", "model"):
        assert {"rt_mean", "rt_sd", "rt_count"} <= saved[side].keys()
    with Trajectories(ref_path) as ref, Trajectories(pred_path) as pred:
        rt_ref, rt_mod = residence_times(ref, WINDOW), residence_times(pred, WINDOW)
        _, p_ref = rtd_histogram(rt_ref.samples, 0.05, window_length=2.5)
        _, p_mod = rtd_histogram(rt_mod.samples, 0.05, window_length=2.5)
        rms = mixing_rms(*mixing_curve_of(ref, WINDOW), *mixing_curve_of(pred, WINDOW))
    assert rt_ref.count > 30 and rt_mod.count > 30
    assert saved["reference"]["rt_count"] == rt_ref.count
    assert saved["model"]["rt_count"] == rt_mod.count
    assert saved["reference"]["rt_mean"] == pytest.approx(rt_ref.mean)
    assert saved["reference"]["rt_sd"] == pytest.approx(rt_ref.sd)
    assert saved["model"]["rt_mean"] == pytest.approx(rt_mod.mean)
    assert saved["model"]["rt_sd"] == pytest.approx(rt_mod.sd)
    assert saved["pd_rt_mean"] == pytest.approx(percentage_difference(rt_mod.mean, rt_ref.mean))
    assert saved["pd_rt_sd"] == pytest.approx(percentage_difference(rt_mod.sd, rt_ref.sd))
    assert saved["md_rtd"] == pytest.approx(minkowski_distance(p_ref, p_mod, 3.0))
    assert saved["md_order"] == 3.0
    assert saved["mixing_rms"] == pytest.approx(rms)
    assert saved["bin_width"] == 0.05
    assert saved["exact_events"] == {"reference": False, "model": False}
    # the maximum norm's order is kept as "inf" (strict JSON writes infinity as null)
    compare(ref_path, pred_path, window=WINDOW, output=tmp_path / "inf", bin_width=0.05,
            md_order=math.inf, figures=False, resamples=0)
    inf = json.loads((tmp_path / "inf" / "summary.json").read_text())
    assert inf["md_order"] == "inf"
    assert inf["md_rtd"] == pytest.approx(np.abs(p_ref - p_mod).max())
    # coarse bins: an RTD spanning fewer than ten is warned of (it was said in the docs
    # only); the 0.05 s bins span more and say nothing
    coarse = [w for w in saved["warnings"] if "bins of" in w and "span only" in w]
    assert coarse == []
    compare(ref_path, pred_path, window=WINDOW, output=tmp_path / "coarse", bin_width=0.5,
            figures=False, resamples=0)
    coarse = json.loads((tmp_path / "coarse" / "summary.json").read_text())
    spans = coarse["rtd_bins_spanned"]
    assert min(spans.values()) < 10
    assert [w for w in coarse["warnings"] if w.startswith(
        f"the RTDs span only {spans['reference']} (reference) and {spans['model']} (model) "
        "bins of 0.5 s")]
    assert saved["same_tracer_groups"] is True
    assert saved["same_purple_particles"] is True          # the former name, kept
    assert saved["model_columns"] == 6
    # the model rises more slowly: longer residence times
    assert saved["pd_rt_mean"] > 0
    assert summary["pd_rt_mean"] == saved["pd_rt_mean"]
    for name in ("rtd.png", "snapshots.png", "mixing.png"):
        assert_png(out / name)
    assert set(saved["figures"]) == {"rtd.png", "snapshots.png", "mixing.png"}
    assert not list(out.glob(".*tmp*")), "temporary files left behind"


def test_no_figures_and_objects_accepted(pair, tmp_path):
    ref_path, pred_path = pair
    out = tmp_path / "plain"
    with Trajectories(ref_path) as ref, Trajectories(pred_path) as pred:
        summary = compare(ref, pred, window=WINDOW, output=out, figures=False)
        assert ref.n_frames > 0          # still open: compare does not close what it got
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]
    assert summary["figures"] == []


def test_exact_events_are_reported(tmp_path, make_run, events_of):
    run = make_run(n_particles=40, seed=8)
    ref = write_trajectories(tmp_path / "ref.h5", run.times, run.positions, width=0.09,
                             height=0.95, events=events_of(run))
    pred = write_trajectories(tmp_path / "pred.h5", run.times, run.positions, width=0.09,
                              height=0.95)
    saved = compare(ref, pred, window=WINDOW, output=tmp_path / "o", figures=False,
                    basis="events")
    assert saved["reference"]["exact_events"] and not saved["model"]["exact_events"]
    assert saved["exact_events"] == {"reference": True, "model": False}
    assert saved["mixing_rms"] == 0.0
    assert any("exact pass events" in w for w in saved["warnings"])
    assert saved["basis"] == "events" and saved["exact_reference"] is None


def test_like_for_like_basis_by_default_with_the_exact_figures_beside(tmp_path, make_run,
                                                                       events_of):
    """The default basis: the same frames on both sides (identical files give PD 0 and
    MD 0, where the exact events would not), and the exact-event figures reported beside."""
    run = make_run(n_particles=40, seed=8)
    ref = write_trajectories(tmp_path / "ref.h5", run.times, run.positions, width=0.09,
                             height=0.95, events=events_of(run))
    pred = write_trajectories(tmp_path / "pred.h5", run.times, run.positions, width=0.09,
                              height=0.95)
    saved = compare(ref, pred, window=WINDOW, output=tmp_path / "o", figures=False)
    assert saved["basis"] == "frames" and saved["reference_frame_stride"] == 1
    assert saved["exact_events"] == {"reference": False, "model": False}
    assert saved["pd_rt_mean"] == 0.0 and saved["md_rtd"] == 0.0
    exact = saved["exact_reference"]
    events = compare(ref, pred, window=WINDOW, output=tmp_path / "e", figures=False,
                     basis="events")
    assert exact["rt_mean"] == events["reference"]["rt_mean"]
    assert exact["pd_rt_mean"] == events["pd_rt_mean"] != 0.0
    # a model at twice the reference's frame interval: the reference's frames every second
    half = write_trajectories(tmp_path / "half.h5", run.times[::2], run.positions[::2],
                              width=0.09, height=0.95)
    strided = compare(ref, half, window=WINDOW, output=tmp_path / "h", figures=False)
    assert strided["reference_frame_stride"] == 2
    assert strided["reference"]["rt_mean"] == strided["model"]["rt_mean"]


def test_odd_column_count_is_refused(tmp_path, make_run):
    run = make_run(n_particles=10, seed=9)
    ref = write_trajectories(tmp_path / "ref.h5", run.times, run.positions, width=0.09,
                             height=0.95)
    pred = write_trajectories(tmp_path / "pred.h5", run.times, run.positions, width=0.09,
                              height=0.95, parameters={"columns": 5, "rows": 38})
    with pytest.raises(InputError, match=r"odd column count .* \(--cells \dxROWS\)"):
        compare(ref, pred, window=WINDOW, output=tmp_path / "o")
    assert not (tmp_path / "o" / "summary.json").exists()


def test_windows_outside_either_file_are_refused(pair, tmp_path):
    ref_path, pred_path = pair
    with pytest.raises(InputError, match="outside"):
        compare(ref_path, pred_path, window=(0.0, 3.0), output=tmp_path / "o")  # model from 0.5
    with pytest.raises(InputError, match="outside"):
        compare(ref_path, pred_path, window=(1.0, 4.0), output=tmp_path / "o")
    with pytest.raises(InputError, match="empty"):
        compare(ref_path, pred_path, window=(2.0, 1.0), output=tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_different_particles_are_refused(tmp_path, make_run):
    run = make_run(n_particles=10, seed=10)
    ref = write_trajectories(tmp_path / "ref.h5", run.times, run.positions, width=0.09,
                             height=0.95)
    pred = write_trajectories(tmp_path / "pred.h5", run.times, run.positions, width=0.09,
                              height=0.95, ids=np.arange(10) + 100)
    with pytest.raises(InputError, match="same particle ids"):
        compare(ref, pred, window=WINDOW, output=tmp_path / "o")


def test_too_short_a_window_is_refused_or_kept_with_nulls_and_warnings(pair, tmp_path):
    """A window without a complete residence is refused before anything is written; with
    ``allow_empty`` (as ``reproduce`` compares) its figures are null, with warnings."""
    ref_path, pred_path = pair
    with pytest.raises(InputError, match="no residence begins and ends in 0.5-0.55 s on the "
                                         "reference side"):
        compare(ref_path, pred_path, window=(0.5, 0.55), output=tmp_path / "o", figures=False)
    assert not (tmp_path / "o").exists()
    summary = compare(ref_path, pred_path, window=(0.5, 0.55), output=tmp_path / "o",
                      figures=False, allow_empty=True)
    saved = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert saved["reference"]["rt_count"] == 0 and saved["reference"]["rt_mean"] is None
    assert saved["md_rtd"] is None and saved["pd_rt_mean"] is None
    assert np.isnan(summary["pd_rt_mean"])
    assert saved["warnings"]


def test_cli_compare(pair, tmp_path, capsys):
    ref_path, pred_path = pair
    out = tmp_path / "cli"
    assert main(["compare", str(ref_path), str(pred_path), "--window", "0.5:3",
                 "-o", str(out), "--no-figures"]) == 0
    printed = capsys.readouterr().out
    assert "E(RT) reference" in printed and "; MD 0." in printed    # the default order: unsaid
    assert (out / "summary.json").exists()
    # another order is said where the text prints the MD (it read as the default order's)
    assert main(["compare", str(ref_path), str(pred_path), "--window", "0.5:3", "-o",
                 str(tmp_path / "inf"), "--no-figures", "--md-order", "inf",
                 "--resamples", "0"]) == 0
    assert "; MD (order inf) 0." in capsys.readouterr().out
    bad = tmp_path / "cli-bad"
    assert main(["compare", str(ref_path), str(pred_path), "--window", "5:9",
                 "-o", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "outside" in err and err.count("\n") == 1
    assert not (bad / "summary.json").exists()


def test_model_figures_from_an_attached_model(tmp_path, make_run, write_run):
    from cfbmarkov.markov import CellGrid, fit_model

    run = make_run(n_particles=300, t1=3.0, seed=11)
    ref = write_run(tmp_path / "ref.h5", run, source="cfd-dem")
    grid = CellGrid(6, 38, 0.09, 0.95)
    model = fit_model(ref, grid, 0.025, (0.0, 1.0))
    pred = model.predict(ref, start=1.0, duration=2.0, seed=3, output=tmp_path / "pred.h5")
    out = tmp_path / "report"
    from cfbmarkov.markov import MarkovModel, model as model_module

    read = []
    real_from_group = MarkovModel.from_group.__func__

    def counting(cls, group, *args):
        read.append(group.file.filename)
        return real_from_group(cls, group, *args)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(model_module.MarkovModel, "from_group", classmethod(counting))
        saved = compare(ref, pred, window=(1.0, 3.0), output=out)
    # the attached model read once for the intervals, verdict, exact RTD and maps
    assert read == [str(pred)], read
    for name in ("rtd.png", "snapshots.png", "mixing.png", "transition_matrix.png",
                 "probability_maps.png"):
        assert_png(out / name)
        assert name in saved["figures"]
    assert "transition_bars.png" not in saved["figures"]     # heat maps, not 3D stems
    assert saved["same_tracer_groups"] is True
    assert saved["model_columns"] == 6


# -- figure functions on plain arrays ---------------------------------------------------------
def test_figure_functions_write_pngs(tmp_path):
    rng = np.random.default_rng(0)
    s = 24
    P = np.zeros((s, s))
    for i in range(s):
        P[i, [(i + 4) % s, (i + 5) % s, i]] = [0.6, 0.3, 0.1]
    fg.plot_transition_matrix(P, 4, 6, tmp_path / "tm.png", grid=True)
    fg.plot_transition_bars(P, tmp_path / "tb.png")
    maps = rng.random((3, 6, 4))
    fg.plot_probability_maps(maps / maps.sum(axis=(1, 2), keepdims=True), [0.05, 0.1, 0.15],
                             0.09, 0.95, tmp_path / "pm.png", "maps")
    edges = 0.025 * np.arange(41)
    pr, pm = rng.random(40), rng.random(40)
    fg.plot_rtd(edges, pr / pr.sum(), pm / pm.sum(), (0.4, 0.2, 100), {"mean": 0.5, "sd": 0.1},
                tmp_path / "rtd.png")
    pos = rng.uniform(0, 1, (3, 200, 2)) * [0.09, 0.95]
    fg.plot_snapshots(pos, pos[::-1], pos[0, :, 0] < 0.045, pos[2, :, 0] < 0.045,
                      [15.0, 15.1, 15.2], 0.09, 0.95, tmp_path / "snap.png")
    t = np.linspace(15, 20, 50)
    curve = 0.5 * np.exp(-(t - 15) / 1.2) + 0.25
    fg.plot_mixing(t, 0.5 * np.exp(-(t - 15)) + 0.25, t, curve, tmp_path / "mix.png",
                   well_mixed=0.25, band=(t, np.vstack([curve - 0.02, curve + 0.02]), 0.9))
    for name in ("tm", "tb", "pm", "rtd", "snap", "mix"):
        assert_png(tmp_path / f"{name}.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        f"{n}.png" for n in ("tm", "tb", "pm", "rtd", "snap", "mix"))


def test_figure_functions_refuse_bad_shapes(tmp_path):
    with pytest.raises(InputError):
        fg.plot_transition_matrix(np.zeros((3, 4)), 1, 3, tmp_path / "x.png")
    with pytest.raises(InputError):
        fg.plot_probability_maps(np.zeros((2, 3, 2)), [0.1], 0.09, 0.95, tmp_path / "x.png")
    with pytest.raises(InputError):
        fg.plot_rtd([0, 1, 2], [0.5, 0.5], [1.0], (1, 1), (1, 1), tmp_path / "x.png")
    assert not list(tmp_path.iterdir())


def test_compare_runs_returns_the_numbers_of_the_summary(pair, tmp_path):
    ref_path, pred_path = pair
    summary = compare(ref_path, pred_path, window=WINDOW, output=tmp_path / "out",
                      figures=False)
    with Trajectories(ref_path) as ref, Trajectories(pred_path) as pred:
        comparison = compare_runs(ref, pred, WINDOW)
        numbers = comparison.summary()
    assert isinstance(comparison, RunComparison)
    assert comparison.edges.size == comparison.reference.rtd.size + 1
    assert comparison.reference.left_group.dtype == bool
    assert comparison.same_tracer_groups
    for key in ("pd_rt_mean", "pd_rt_sd", "md_rtd", "mixing_rms", "bin_width", "md_order"):
        assert numbers[key] == summary[key]
    for side in ("reference", "model"):
        assert numbers[side]["left_group_fraction"] == numbers[side]["purple_fraction"]
        assert numbers[side]["rt_mean"] == summary[side]["rt_mean"]
    # drawing adds only the files, warnings and the interval's level (null: no interval here)
    assert set(summary) - set(numbers) == {"figures", "warnings", "level"}
    assert summary["level"] is None and summary["model"]["rt_mean_interval"] is None


def test_map_times_in_whole_lags():
    assert map_times(0.4, 0.025) == pytest.approx([0.1, 0.2, 0.3])
    assert map_times(float("nan"), 0.025) == pytest.approx([0.05, 0.1, 0.15])
    assert map_times(0.02, 0.025) == pytest.approx([0.05, 0.1, 0.15])


def test_persistence_baseline_and_natural_variability_stand_beside_the_model(tmp_path):
    """A prediction carries its model's fitting window: the reference's RTD there, taken as
    the prediction of the analysis window, is the persistence baseline; the reference's two
    halves of the window are its natural variability. Both on the comparison's basis."""
    from cfbmarkov.observed.residence import residence_times, rtd_histogram
    from cfbmarkov.observed.metrics import minkowski_distance
    from cfbmarkov.markov import CellGrid, fit_model
    from cfbmarkov.synthetic import RiserFlow, write_run
    from cfbmarkov.trajectories import Trajectories

    run = write_run(tmp_path / "run.h5", RiserFlow(), 300, 4.0, seed=2)
    model = fit_model(run, CellGrid(6, 38), 0.025, (0.5, 2.0), "mle")
    pred = model.predict(run, 2.0, 2.0, seed=1, output=tmp_path / "p.h5")
    saved = compare(run, pred, window=(2.0, 4.0), output=tmp_path / "o", figures=False)
    base, halves = saved["baseline"], saved["natural_variability"]
    assert base["windows"] == [[0.5, 2.0], [2.0, 4.0]]
    assert halves["windows"] == [[2.0, 3.0], [3.0, 4.0]]
    with Trajectories(run) as t:
        fit_rt = residence_times(t, (0.5, 2.0), use_events=False)
        window_rt = residence_times(t, (2.0, 4.0), use_events=False)
    assert base["rt_mean"] == pytest.approx(fit_rt.mean, rel=1e-12)
    assert base["pd_rt_mean"] == pytest.approx(100 * (fit_rt.mean - window_rt.mean)
                                               / window_rt.mean, rel=1e-9)
    _, p_fit = rtd_histogram(fit_rt.samples, 0.025, window_length=2.0)
    _, p_win = rtd_histogram(window_rt.samples, 0.025, window_length=2.0)
    assert base["md_rtd"] == pytest.approx(minkowski_distance(p_fit, p_win, 2.0), rel=1e-12)
    assert np.isfinite(halves["md_rtd"]) and halves["rt_count"] > 0
    # the model on its own fitting window: its RTD against the fitting window's
    own = saved["model_on_fitting_window"]
    assert own["windows"] == [[2.0, 4.0], [0.5, 2.0]]
    with Trajectories(pred) as p:
        model_rt = residence_times(p, (2.0, 4.0), use_events=False)
    _, p_model = rtd_histogram(model_rt.samples, 0.025, window_length=2.0)
    assert own["rt_mean"] == pytest.approx(model_rt.mean, rel=1e-12)
    assert own["pd_rt_mean"] == pytest.approx(100 * (model_rt.mean - fit_rt.mean) / fit_rt.mean,
                                              rel=1e-9)
    assert own["pd_rt_sd"] == pytest.approx(100 * (model_rt.sd - fit_rt.sd) / fit_rt.sd,
                                            rel=1e-9)
    assert own["md_rtd"] == pytest.approx(minkowski_distance(p_model, p_fit, 2.0), rel=1e-12)
    assert own["md_rtd"] != pytest.approx(saved["md_rtd"])
    assert saved["long_run"] is None            # no span asked for
    with_long = compare(run, pred, window=(3.0, 4.0), output=tmp_path / "l", figures=False,
                        long_run_span=(0.5, 4.0))
    long_run = with_long["long_run"]
    assert long_run["windows"] == [[1.0, 4.0], [3.0, 4.0]]
    with Trajectories(run) as t:    # the other whole 1 s windows aligned with 3-4 s: 1-2, 2-3
        pooled = np.concatenate([residence_times(t, w, use_events=False).samples
                                 for w in ((1.0, 2.0), (2.0, 3.0))])
    assert long_run["rt_count"] == pooled.size
    assert long_run["rt_mean"] == pytest.approx(pooled.mean(), rel=1e-12)
    with pytest.raises(InputError, match="no other whole"):
        compare(run, pred, window=(2.0, 4.0), output=tmp_path / "m", figures=False,
                long_run_span=(2.0, 4.0))
    # a prediction without its model (plain arrays): no baseline, halves still given
    bare = write_trajectories(tmp_path / "bare.h5", *_frames(pred), width=0.09, height=0.95)
    plain = compare(run, bare, window=(2.0, 4.0), output=tmp_path / "b", figures=False)
    assert plain["baseline"] is None and plain["natural_variability"] is not None
    assert plain["model_on_fitting_window"] is None


def _frames(path):
    from cfbmarkov.trajectories import Trajectories

    with Trajectories(path) as t:
        return t.times, t.positions()


def test_an_in_sample_window_and_a_baseline_of_another_length_are_warned(tmp_path, capsys):
    """A compared window that overlaps the model's fitting window on its own run judges the
    fit, not a prediction; a persistence baseline of another length than the compared
    window is not like for like. Each says so once; a later window as long as the fitting
    one says neither."""
    from cfbmarkov.cli import main
    from cfbmarkov.synthetic import RiserFlow, write_run

    run = write_run(tmp_path / "run.h5", RiserFlow(), 300, 4.0, seed=2)
    model = tmp_path / "m.h5"
    assert main(["fit", str(run), "--window", "0.5:2", "--resamples", "0", "--no-adequacy",
                 "-q", "-o", str(model)]) == 0
    overlap, length = "overlaps the model's fitting window 0.5-2 s", "is 1.5 s long"
    cases = [(1.0, 1.0, True, True), (2.0, 1.5, False, False), (2.0, 2.0, False, True)]
    for start, duration, inside, other_length in cases:
        pred = tmp_path / f"p{start}-{duration}.h5"
        assert main(["predict", str(model), "--init", str(run), "--start", str(start),
                     "--duration", str(duration), "-q", "-o", str(pred)]) == 0
        saved = compare(run, pred, window=(start, start + duration), figures=False,
                        output=tmp_path / f"o{start}-{duration}")
        said = saved["warnings"]
        assert sum(overlap in line for line in said) == inside, said
        assert sum(length in line for line in said) == other_length, said
        assert sum("nor is the model's own error on its fitting window" in line
                   for line in said) == other_length
        assert not any("mixing curves stay flat" in line for line in said)
    capsys.readouterr()


def test_a_pooled_models_in_sample_window_and_baseline_length_are_warned(tmp_path, capsys):
    """The same two warnings for a model fitted on two runs: a compared window over one
    run's fitting window on that run, and a baseline whose windows (one per run) are of
    another length than the compared one; a window after both fitting windows, as long as
    they are, says neither."""
    from cfbmarkov.cli import main
    from cfbmarkov.synthetic import RiserFlow, write_run

    runs = [write_run(tmp_path / f"run{k}.h5", RiserFlow(), 300, 4.0, seed=k) for k in (2, 3)]
    model = tmp_path / "m.h5"
    assert main(["fit", *map(str, runs), "--window", "0.5:2", "--resamples", "0",
                 "--no-adequacy", "-q", "-o", str(model)]) == 0
    overlap = "overlaps the model's fitting window 0.5-2 s of this run (run 2 of 2 pooled)"
    length = "windows (one per pooled run) are 1.5 s long and the compared one 1 s"
    for start, duration, inside, other_length in [(1.0, 1.0, True, True),
                                                  (2.0, 1.5, False, False)]:
        pred = tmp_path / f"p{start}.h5"
        assert main(["predict", str(model), "--init", str(runs[1]), "--start", str(start),
                     "--duration", str(duration), "-q", "-o", str(pred)]) == 0
        saved = compare(runs[1], pred, window=(start, start + duration), figures=False,
                        output=tmp_path / f"o{start}")
        said = saved["warnings"]
        # the model's own error is against both runs' fitting windows, pooled: said so
        assert saved["baseline"]["runs"] == saved["model_on_fitting_window"]["runs"] == 2
        assert sum(overlap in line for line in said) == inside, said
        assert sum(length in line for line in said) == other_length, said
        assert not any("could not pool" in line for line in said)
    # fitted on the runs' names from their folder, compared from another: the baseline
    # finds them beside the prediction, as the intervals do (a review saw it fall back to
    # one run's window while the intervals used all three)
    import os

    here = os.getcwd()
    try:
        os.chdir(tmp_path)
        assert main(["fit", "run2.h5", "run3.h5", "--window", "0.5:2", "--resamples", "0",
                     "--no-adequacy", "-q", "-o", "named.h5"]) == 0
        assert main(["predict", "named.h5", "--init", "run3.h5", "--start", "2",
                     "--duration", "1.5", "-q", "-o", "pn.h5"]) == 0
        (tmp_path / "sub").mkdir()
        os.chdir(tmp_path / "sub")
        saved = compare("../run3.h5", "../pn.h5", window=(2.0, 3.5), figures=False,
                        output="o")
    finally:
        os.chdir(here)
    assert not any("could not pool" in line for line in saved["warnings"])
    assert saved["baseline"]["runs"] == 2
    # a run gone: the baseline falls back to the reference's own window, and says so
    runs[0].rename(tmp_path / "moved.h5")
    saved = compare(runs[1], tmp_path / "p2.0.h5", window=(2.0, 3.5), figures=False,
                    output=tmp_path / "gone")
    [note] = [line for line in saved["warnings"] if "could not pool" in line]
    assert str(runs[0]) in note and note.endswith(
        "the reference's own window 0.5-2 s instead (one run's, not the model's pooled runs')")
    assert saved["baseline"]["runs"] == 1
    capsys.readouterr()


def test_mixing_curves_that_stay_flat_on_both_sides_are_warned_of(tmp_path, capsys):
    """Particles that only rise, each at its own x: no tracer crosses W/2 in the run or in
    the prediction (the chain's columns never change), so the mixing RMS of 0 is warned as
    testing nothing."""
    from cfbmarkov.cli import main

    rng = np.random.default_rng(1)
    t = 0.005 * np.arange(801)
    x = np.broadcast_to(rng.uniform(0.0, 0.04, 200), (t.size, 200))
    y = np.mod(rng.uniform(0.0, 0.3, 200) + rng.uniform(0.5, 1.5, 200) * t[:, None], 0.3)
    run = write_trajectories(tmp_path / "r.h5", t, np.stack([x, y], axis=-1), width=0.04,
                             height=0.3, source="cfd-dem")
    model, pred = tmp_path / "m.h5", tmp_path / "p.h5"
    assert main(["fit", str(run), "--cells", "4x12", "--lag", "0.01", "--window", "0:2",
                 "--resamples", "0", "--no-adequacy", "-q", "-o", str(model)]) == 0
    assert main(["predict", str(model), "--init", str(run), "--start", "2", "--duration", "2",
                 "-q", "-o", str(pred)]) == 0
    saved = compare(run, pred, window=(2.0, 4.0), figures=False, output=tmp_path / "o")
    assert saved["mixing_rms"] == 0
    flat = [line for line in saved["warnings"] if "mixing curves stay flat" in line]
    assert len(flat) == 1 and "mixing RMS 0 tests nothing" in flat[0]
    capsys.readouterr()
    # another run as the reference: refused, naming the file the prediction started from
    other = write_trajectories(tmp_path / "other.h5", t, np.stack([x, y], axis=-1)[:, :150],
                               width=0.04, height=0.3, source="cfd-dem")
    with pytest.raises(InputError, match=r"was predicted from \S*r\.h5: give that as the "
                                         r"reference"):
        compare(other, pred, window=(2.0, 4.0), figures=False, output=tmp_path / "x")


def test_a_window_after_the_predictions_start_is_said_to_be_so(tmp_path):
    """A window that starts after the prediction's first frame (where it holds the
    reference's state): the tracer groups differ because the particles have moved apart
    since, and the warning says so, with the window that starts alike; from the
    prediction's start the groups agree and nothing is warned."""
    from cfbmarkov.synthetic import RiserFlow, write_run

    run = write_run(tmp_path / "run.h5", RiserFlow(), 300, 4.0, seed=1)
    model, pred = tmp_path / "m.h5", tmp_path / "p.h5"
    assert main(["fit", str(run), "--window", "0:2", "--resamples", "0", "--no-adequacy",
                 "-q", "-o", str(model)]) == 0
    assert main(["predict", str(model), "--init", str(run), "--start", "2", "--duration", "2",
                 "--seed", "3", "-q", "-o", str(pred)]) == 0
    later = compare(run, pred, window=(2.5, 4.0), figures=False, output=tmp_path / "later")
    moved = [line for line in later["warnings"] if "left tracer group" in line]
    assert len(moved) == 1, later["warnings"]
    assert ("(t = 2.5 s) disagree on which particles are in the left tracer group" in moved[0]
            and "the window starts after the prediction's first frame (2 s)" in moved[0]
            and "(--window 2:...)" in moved[0])
    alike = compare(run, pred, window=(2.0, 4.0), figures=False, output=tmp_path / "alike")
    assert not [line for line in alike["warnings"] if "left tracer group" in line]


def test_prediction_intervals_bracket_the_prediction_and_shrink_with_data(tmp_path):
    """Block-bootstrap and Monte Carlo intervals: around the prediction's value, narrower at a
    lower level, the model's own wider for a model fitted on less data; none when
    resamples = 0. The mixing
    curve's band too (on its frames, none at the window start, wider on less data)."""
    from cfbmarkov.markov import CellGrid, fit_model
    from cfbmarkov.synthetic import RiserFlow, write_run

    run = write_run(tmp_path / "run.h5", RiserFlow(), 200, 5.0, seed=3)
    widths, mixing_widths = {}, {}
    for name, fit_window in (("long", (0.5, 3.0)), ("short", (2.5, 3.0))):
        model = fit_model(run, CellGrid(6, 38), 0.025, fit_window, "mle")
        pred = model.predict(run, 3.0, 2.0, seed=1, output=tmp_path / f"{name}.h5")
        saved = compare(run, pred, window=(3.0, 5.0), output=tmp_path / name, figures=False,
                        resamples=30)
        lo, hi = saved["model"]["rt_mean_interval"]
        assert saved["level"] == 0.9 and lo < saved["model"]["rt_mean"] < hi
        s_lo, s_hi = saved["model"]["rt_sd_interval"]
        assert s_lo < saved["model"]["rt_sd"] < s_hi
        band = np.asarray(saved["model"]["rtd_interval"])
        assert band.shape == (2, len(saved_bins(saved))) and (band[0] <= band[1]).all()
        # the mixing band: on the prediction's frames, around its curve, none at the start
        mixing = saved["model"]["mixing_interval"]
        with Trajectories(pred) as t:
            times, curve = mixing_curve_of(t, (3.0, 5.0))
        lower, upper = np.asarray(mixing["lower"]), np.asarray(mixing["upper"])
        assert np.allclose(mixing["times"], times) and lower.shape == upper.shape == curve.shape
        assert (lower <= curve + 1e-12).all() and (curve <= upper + 1e-12).all()
        assert upper[0] - lower[0] < 1e-9 < (upper[1:] - lower[1:]).min()
        mixing_widths[name] = float(np.mean(upper - lower))
        own_lo, own_hi = saved["model"]["model_rt_mean_interval"]
        assert lo <= own_lo < own_hi <= hi          # the flow's variability only widens them
        # the reference's own intervals: its window's residences' sampling, mean +- z SE
        ref = saved["reference"]
        r_lo, r_hi = ref["rt_mean_interval"]
        assert r_lo < ref["rt_mean"] < r_hi and ref["rt_sd_interval"][0] < ref["rt_sd"]
        z_se = 1.6448536 * ref["rt_sd"] / np.sqrt(ref["rt_count"])
        assert 0.5 * (r_hi - r_lo) == pytest.approx(z_se, rel=1e-6)
        widths[name] = own_hi - own_lo
        if name == "long":
            half = compare(run, pred, window=(3.0, 5.0), output=tmp_path / "half",
                           figures=False, level=0.5, resamples=30)
            assert half["model"]["rt_mean_interval"][1] - half["model"]["rt_mean_interval"][0] \
                < hi - lo
            none = compare(run, pred, window=(3.0, 5.0), output=tmp_path / "none",
                           figures=False, resamples=0)
            assert none["level"] is None and none["model"]["rt_mean_interval"] is None
            assert none["model"]["rt_sd_interval"] is None and none["model"]["rtd_interval"] is None
    assert widths["short"] > widths["long"]
    assert mixing_widths["short"] > mixing_widths["long"]


def saved_bins(saved):
    return range(saved["rtd_bins"]["count"])


def test_net_downflow_counts_residences_downward(tmp_path):
    """A run mirrored top to bottom flows down on net: residences are counted from the top
    down, the same as the original's upward ones; the exact RTD of a model fitted on the
    mirror, taken downward, is the original model's upward one; no table of n/a."""
    from cfbmarkov.markov import CellGrid, fit_model
    from cfbmarkov.synthetic import RiserFlow, sample_run

    flow = RiserFlow()
    times, _, pos, laps = sample_run(flow, 200, 161, seed=4)
    up = write_trajectories(tmp_path / "up.h5", times, pos, width=flow.width, height=flow.height,
                            laps=laps)
    mirrored = pos.copy()
    mirrored[..., 1] = np.nextafter(flow.height, 0) - pos[..., 1]
    down = write_trajectories(tmp_path / "down.h5", times, mirrored, width=flow.width,
                              height=flow.height, laps=-laps)
    a = compare(up, up, window=(1.0, 4.0), output=tmp_path / "a", figures=False)
    b = compare(down, down, window=(1.0, 4.0), output=tmp_path / "b", figures=False)
    assert a["direction"] == "up" and b["direction"] == "down"
    assert b["reference"]["rt_count"] == a["reference"]["rt_count"] > 50
    assert b["reference"]["rt_mean"] == pytest.approx(a["reference"]["rt_mean"], rel=1e-12)
    assert any("net flow over the window is downward" in w for w in b["warnings"])
    grid = CellGrid(6, 38, flow.width, flow.height)
    m_up = fit_model(up, grid, flow.lag, (0.0, 4.0), "mle")
    m_down = fit_model(down, grid, flow.lag, (0.0, 4.0), "mle")
    assert m_down.rtd(direction="down").mean == pytest.approx(m_up.rtd().mean, rel=1e-6)


def test_cli_compare_bins_the_rtd_at_the_models_lag_by_default(tmp_path, make_run, write_run,
                                                                capsys):
    """Without --bin-width the RTD bins are the model's lag (as ``reproduce`` bins), printed
    and stored; not a fixed 0.025 s."""
    from cfbmarkov.markov import CellGrid, fit_model

    run = make_run(n_particles=200, t1=3.0, dt=0.005, seed=5)
    ref = write_run(tmp_path / "ref.h5", run, source="cfd-dem")
    model = fit_model(ref, CellGrid(6, 38, 0.09, 0.95), 0.01, (0.0, 1.0))
    pred = model.predict(ref, start=1.0, duration=2.0, seed=3, output=tmp_path / "pred.h5")
    out = tmp_path / "cli"
    assert main(["compare", str(ref), str(pred), "--window", "1:3", "-o", str(out),
                 "--no-figures", "--resamples", "0"]) == 0
    printed = capsys.readouterr().out
    saved = json.loads((out / "summary.json").read_text())
    assert saved["bin_width"] == pytest.approx(0.01)
    assert saved["bin_width_from"] == "the model's lag"
    assert "RTD bins 0.01 s wide (the model's lag" in printed
    given = tmp_path / "given"
    assert main(["compare", str(ref), str(pred), "--window", "1:3", "-o", str(given),
                 "--no-figures", "--resamples", "0", "--bin-width", "0.05"]) == 0
    assert json.loads((given / "summary.json").read_text())["bin_width"] == pytest.approx(0.05)
    assert "RTD bins 0.05 s wide (--bin-width)" in capsys.readouterr().out


def test_python_compare_bins_the_rtd_at_the_models_lag_by_default(tmp_path, make_run,
                                                                   write_run):
    """``report.compare.compare`` called from Python without ``bin_width`` bins as the
    command line does: at the lag of the model attached to the prediction (0.01 s here, not
    0.025 s), else at the reference's frame interval; the summary says which."""
    from cfbmarkov.markov import CellGrid, fit_model

    run = make_run(n_particles=200, t1=3.0, dt=0.005, seed=5)
    ref = write_run(tmp_path / "ref.h5", run, source="cfd-dem")
    model = fit_model(ref, CellGrid(6, 38, 0.09, 0.95), 0.01, (0.0, 1.0))
    pred = model.predict(ref, start=1.0, duration=2.0, seed=3, output=tmp_path / "pred.h5")
    summary = compare(ref, pred, window=(1.0, 3.0), output=tmp_path / "lag", figures=False,
                      resamples=0)
    assert summary["bin_width"] == pytest.approx(0.01)
    assert summary["bin_width_from"] == "the model's lag"
    plain = compare(ref, ref, window=(1.0, 3.0), output=tmp_path / "frames", figures=False,
                    resamples=0)        # no model attached: the reference's frames
    assert plain["bin_width"] == pytest.approx(0.005)
    assert plain["bin_width_from"] == "the reference's frame interval"


def test_the_models_exact_e_rt_as_the_window_sees_it_stands_beside_the_prediction(
        tmp_path, capsys):
    """A prediction that carries its model: summary.json gives the chain's exact E(RT) as a
    window of the comparison's length sees it (MarkovModel.rtd(window=W)), and the
    prediction's residences estimate it within their standard error; compare prints it.
    Files without a model: no such block."""
    from cfbmarkov.markov import CellGrid, fit_model
    from cfbmarkov.synthetic import RiserFlow, write_run

    flow = RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                     vertical_spread=0.5, persistence=False)
    run = write_run(tmp_path / "run.h5", flow, 1500, 6.0, seed=5)
    model = fit_model(run, CellGrid(4, 16), 0.025, (0.0, 6.0), "mle")
    pred = model.predict(run, 1.0, 5.0, seed=2, output=tmp_path / "p.h5")
    saved = compare(run, pred, window=(1.0, 6.0), output=tmp_path / "o", figures=False,
                    resamples=0)
    exact = saved["model"]["exact"]
    # the window counts records from its first frame, the particles where the prediction's
    # are there
    states = model.initial_states(pred, 1.0)[0]
    seen = model.rtd(window=5.0, occupancy=np.bincount(states, minlength=model.n_states))
    assert exact["window_length"] == 5.0
    assert exact["windowed_rt_mean"] == pytest.approx(seen.mean, rel=1e-12)
    assert exact["rt_mean"] == pytest.approx(model.rtd().mean, rel=1e-12)
    assert exact["windowed_rt_mean"] < exact["rt_mean"]          # the window cuts the tail
    predicted = saved["model"]
    standard_error = predicted["rt_sd"] / np.sqrt(predicted["rt_count"])
    assert abs(predicted["rt_mean"] - exact["windowed_rt_mean"]) < 3 * standard_error
    assert exact["pd_windowed_rt_mean"] == pytest.approx(
        100 * (seen.mean / saved["reference"]["rt_mean"] - 1), rel=1e-9)
    assert main(["compare", str(run), str(pred), "--window", "1:6", "-o", str(tmp_path / "c"),
                 "--no-figures", "--resamples", "0", "-q"]) == 0
    assert (f"  the model's exact E(RT) as a 5 s window sees it: {seen.mean:.4g} s"
            in capsys.readouterr().out)
    # a window given between frames: the frames it holds, 1.025 to 5.975 s, are what the
    # residences are counted on and what the chain's window is (it said 4.98 s)
    off = compare(run, pred, window=(1.01, 5.99), output=tmp_path / "off", figures=False,
                  resamples=0)["model"]["exact"]
    states = model.initial_states(pred, 1.025)[0]
    seen = model.rtd(window=4.95, occupancy=np.bincount(states, minlength=model.n_states))
    assert off["window_length"] == pytest.approx(4.95, abs=1e-9)
    assert off["windowed_rt_mean"] == pytest.approx(seen.mean, rel=1e-12)
    bare = compare(run, run, window=(1.0, 6.0), output=tmp_path / "b", figures=False,
                   resamples=0)
    assert "exact" not in bare["model"]


def test_a_heat_map_of_more_states_than_pixels_keeps_every_non_zero(tmp_path):
    """A 1500-state matrix is drawn by the largest entry of each 3 x 3 block (500 x 500
    cells on the same state axes): an isolated entry, which a renderer sampling one entry a
    pixel could drop, stays in its block; a matrix of at most HEATMAP_PIXELS states is
    drawn as it is."""
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    from cfbmarkov.report.figures import HEATMAP_PIXELS, draw_heatmap, pooled_max

    s = 1500
    P = np.zeros((s, s))
    P[np.arange(s), np.arange(s)] = 0.5
    P[1000, 7] = 1e-4                            # isolated: row 1000 -> block 333, col 2
    pooled = pooled_max(P, HEATMAP_PIXELS)
    assert pooled.shape == (500, 500)
    assert pooled[333, 2] == 1e-4 and np.count_nonzero(pooled) == 500 + 1
    ax = Figure().add_subplot()
    image = draw_heatmap(ax, P, LogNorm(1e-5, 1.0))
    assert image.get_array().shape == (500, 500)
    assert image.get_extent() == [-0.5, s - 0.5, s - 0.5, -0.5]
    small = np.eye(HEATMAP_PIXELS)
    assert pooled_max(small, HEATMAP_PIXELS) is small
    odd = pooled_max(np.ones((601, 601)), HEATMAP_PIXELS)  # padded: 301 blocks of 2
    assert odd.shape == (301, 301) and odd.min() == 1.0


def _lap_file(path, times, laps, **kw):
    laps = np.asarray(laps, np.int32)
    t, n = laps.shape
    pos = np.empty((t, n, 2))
    pos[..., 0], pos[..., 1] = 0.025, 0.5
    return write_trajectories(path, np.asarray(times, float), pos, width=0.1, height=1.0,
                              laps=laps, **kw)


def test_a_lag_of_a_fraction_of_a_frame_more_is_not_rounded_to_whole_frames(tmp_path):
    """Frames of 0.01 s against a model's lag of 1.005 s (100.5 frames): the stride is not
    taken as 101 frames (a tolerance of 1 % of the lag allowed it) but every frame is used,
    with the warning the docs give."""
    from cfbmarkov.observed.residence import WHOLE_FRAMES
    from cfbmarkov.trajectory_format import FRAME_SPACING_TOLERANCE

    assert WHOLE_FRAMES == 0.5 * FRAME_SPACING_TOLERANCE
    tr = np.round(0.01 * np.arange(2011), 10)
    tp = np.round(1.005 * np.arange(21), 10)
    phase = np.array([0.1, 0.7, 1.3, 1.9])
    lr = np.floor((tr[:, None] + phase) / 2.5).astype(int)
    lp = np.floor((tp[:, None] + phase) / 2.5).astype(int)
    ref = _lap_file(tmp_path / "r.h5", tr, lr - lr[0], source="cfd-dem")
    pred = _lap_file(tmp_path / "p.h5", tp, lp - lp[0], source="markov-prediction",
                     parameters={"columns": 2})
    c = compare_runs(ref, pred, (0, 20.1), bin_width=1.005)
    assert c.lag_frames == 1
    assert any("is not a whole number of the reference's frames" in w for w in c.warnings)


def test_flat_mixing_curves_of_an_open_riser_whose_tracers_leave_are_warned_of(tmp_path):
    """Both curves flat (every tracer stays in the left half) until the tracers leave
    (NaN after): the mixing RMS of 0 tests nothing, and compare says so."""
    t = np.arange(8.0)
    y = np.array([[.5, .7, .95, np.nan, np.nan, np.nan, np.nan, np.nan],
                  [np.nan, .05, .3, .5, .7, .95, np.nan, np.nan]]).T

    def run(path, source, parameters=None):
        return write_trajectories(path, t, np.stack([np.full_like(y, .02), y], -1), width=0.1,
                                  height=1.0, present=np.isfinite(y), boundary="open",
                                  source=source, parameters=parameters)

    c = compare_runs(run(tmp_path / "r.h5", "cfd-dem"),
                     run(tmp_path / "m.h5", "markov-prediction", {"columns": 2, "rows": 10}),
                     (0, 7))
    assert np.isnan(c.reference.mixing_fraction).any() and c.mixing_rms == 0.0
    assert any("the mixing curves stay flat in both files" in w for w in c.warnings)


def test_first_frames_on_other_grids_are_said_with_both_times(tmp_path):
    """A window that starts on a frame of the reference but between the prediction's (its
    frames twice as far apart): the warning names both first frames and a start on both
    grids, not one time for the two files."""
    from tests.observed.conftest import HEIGHT, WIDTH, generate_run

    ref = generate_run(seed=1, dt=0.025)
    pred = generate_run(seed=2, rise=1.3, t0=0.5, dt=0.05, initial=ref.positions[20])
    ref_path = write_trajectories(tmp_path / "reference.h5", ref.times, ref.positions,
                                  width=WIDTH, height=HEIGHT, source="cfd-dem")
    pred_path = write_trajectories(tmp_path / "prediction.h5", pred.times, pred.positions,
                                   width=WIDTH, height=HEIGHT, source="markov-prediction",
                                   parameters={"columns": 6, "rows": 38})
    said = compare(ref_path, pred_path, window=(0.525, 3.0), figures=False, resamples=0,
                   output=tmp_path / "c")["warnings"]
    [line] = [w for w in said if "first frames" in w]
    assert line.startswith("the window's first frames differ: the reference's at 0.525 s, the "
                           "prediction's at 0.55 s (its frames are 0.05 s apart from 0.5 s)")
    assert line.endswith("(--window 0.55:... or 0.5:...)")


def test_the_references_own_sd_interval_covers_a_long_tailed_rtd():
    """The reference's own 90 % interval of SD(RT) on exponential residence times (a long
    tail, as a riser's RTD has): the delta method's standard error covers the true SD in
    about 90 % of samples, where SD / sqrt(2 (n - 1)) (normal samples) covers about 60 %."""
    from cfbmarkov.report.compare import reference_sampling_intervals

    rng = np.random.default_rng(11)
    held_sd = held_mean = 0
    draws = 400
    for _ in range(draws):
        samples = rng.exponential(0.8, 300)
        (m0, m1), (s0, s1) = reference_sampling_intervals(samples, 0.9)
        held_mean += m0 <= 0.8 <= m1
        held_sd += s0 <= 0.8 <= s1
    assert 0.85 <= held_sd / draws <= 0.95 and 0.85 <= held_mean / draws <= 0.95
    assert reference_sampling_intervals(np.array([1.0]), 0.9) is None


def test_a_model_fitted_on_another_run_says_why_it_has_no_baseline(tmp_path):
    """The model's fitting window lies outside the reference's frames (fitted on another
    run): no persistence baseline, and a warning names the windows and the model's run."""
    from cfbmarkov.markov import CellGrid, fit_model
    from cfbmarkov.synthetic import RiserFlow, write_run

    other = write_run(tmp_path / "other.h5", RiserFlow(), 200, 4.0, seed=3)
    run = write_run(tmp_path / "run.h5", RiserFlow(), 200, 1.6, seed=4)
    model = fit_model(other, CellGrid(6, 38), 0.025, (2.0, 4.0), "mle")
    pred = model.predict(run, 0.4, 1.2, seed=1, output=tmp_path / "p.h5")
    saved = compare(run, pred, window=(0.4, 1.6), output=tmp_path / "c", figures=False,
                    resamples=0)
    assert saved["baseline"] is None
    said = [w for w in saved["warnings"] if w.startswith("no persistence baseline")]
    assert len(said) == 1 and "fitting window 2-4 s does not lie in the reference's frames " \
        "(0-1.6 s)" in said[0] and f"another run ({other})" in said[0]
