"""The Python API does what the command line does: a fit gets its interval and verdict
(assess_fit), a prediction repeats the verdict's warnings and accepts a Kinetics, and
neither save nor predict overwrites a run or its own input without being told."""

import shutil
import warnings

import numpy as np
import pytest

from cfbmarkov.analysis.fit_checks import assess_fit
from cfbmarkov.errors import CfbmarkovWarning, InputError, SampleWarning
from cfbmarkov.kinetics import FirstOrder, Kinetics, Property
from cfbmarkov.kinetics.fields import Constant
from cfbmarkov.markov import CellGrid, MarkovModel, PaperEstimator, discretize
from cfbmarkov.trajectories import Trajectories

GRID = CellGrid(4, 16, 0.09, 0.95)


@pytest.fixture(scope="session")
def fitted(markov_run):
    window = discretize(markov_run, GRID, lag=0.1, window=(2.0, 6.0))
    return PaperEstimator(GRID, lag=0.1).fit(window)


def test_assess_fit_gives_a_python_fit_the_command_lines_interval_and_verdict(
        fitted, markov_run, tmp_path):
    from cfbmarkov.cli import main

    assert fitted.uncertainty is None and fitted.adequacy is None
    judged = assess_fit(fitted, resamples=20)
    assert judged.uncertainty is not None and judged.adequacy is not None
    low, high = judged.uncertainty.rt_mean_interval
    assert low < judged.rtd().mean < high
    assert "interval" in judged.summary()
    # the command line's fit of the same window stores the same figures
    out = tmp_path / "m.h5"
    assert main(["fit", str(markov_run), "--cells", "4x16", "--lag", "0.1", "--window", "2:6",
                 "--resamples", "20", "-q", "-o", str(out)]) == 0
    cli = MarkovModel.load(out)
    assert cli.uncertainty.rt_mean_interval == pytest.approx((low, high), rel=1e-12)
    assert cli.adequacy.warnings == judged.adequacy.warnings
    assert np.array_equal(cli.cell_fields.solids_fraction, judged.cell_fields.solids_fraction)


def test_assess_fit_finds_a_relative_source_beside_the_model_file(markov_run, tmp_path,
                                                                   monkeypatch):
    """A model fitted in Python on ``../run.h5`` from a folder, saved there and loaded from
    another folder: its source is a path from the folder it was fitted in, taken from the
    model file's folder where the current one has no such file (a review met "no such
    file"); the data are still checked to be the model's; neither found: one line."""
    (tmp_path / "a" / "fits").mkdir(parents=True)
    (tmp_path / "elsewhere").mkdir()
    shutil.copy(markov_run, tmp_path / "a" / "run.h5")
    monkeypatch.chdir(tmp_path / "a" / "fits")
    model = PaperEstimator(GRID, lag=0.1).fit(discretize("../run.h5", GRID, lag=0.1,
                                                         window=(2.0, 6.0)))
    model.save("m.h5")
    monkeypatch.chdir(tmp_path / "elsewhere")
    loaded = MarkovModel.load(tmp_path / "a" / "fits" / "m.h5")
    assert loaded.source == "../run.h5"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        judged = assess_fit(loaded, resamples=0)
    assert judged.adequacy is not None
    # the tutorial's layout: fitted on synth/run.h5 from a project's root, saved beside
    # it as synth/m.h5: from elsewhere its name alone is found beside the model file
    monkeypatch.chdir(tmp_path / "a")
    (tmp_path / "a" / "synth").mkdir()
    shutil.copy(markov_run, tmp_path / "a" / "synth" / "run.h5")
    PaperEstimator(GRID, lag=0.1).fit(discretize("synth/run.h5", GRID, lag=0.1,
                                                 window=(2.0, 6.0))).save("synth/m.h5")
    monkeypatch.chdir(tmp_path / "elsewhere")
    beside = MarkovModel.load(tmp_path / "a" / "synth" / "m.h5")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert assess_fit(beside, resamples=0).adequacy is not None
    (tmp_path / "a" / "run.h5").rename(tmp_path / "a" / "gone.h5")
    with pytest.raises(InputError, match=r"\.\./run.h5 \(the model's fitting file, named from "
                       r"the folder it was fitted in\): not found from this folder nor beside "
                       r"the model file \(.*fits\); give runs="):
        assess_fit(loaded, resamples=0)


def test_assess_fit_refuses_what_it_cannot_use(fitted, markov_run):
    with pytest.raises(InputError, match="one fitting window per run"):
        assess_fit(fitted, [markov_run, markov_run], [(2.0, 6.0)])
    with pytest.raises(InputError, match="at least 10 bootstrap"):
        assess_fit(fitted, resamples=5)
    with pytest.raises(InputError, match="give runs= and windows="):
        assess_fit(fitted._derived(source=""))
    for level, resamples, said in [(90, 100, "strictly between 0 and 1"),
                                   (0.9, -1, "at least 10 bootstrap"),
                                   (0.9, 2.5, "a whole number"),
                                   (0.999, 100, "at least 1000 bootstrap")]:
        with pytest.raises(InputError, match=said):
            assess_fit(fitted, level=level, resamples=resamples)


def test_windows_of_one_run_get_no_interval_of_pooled_runs(markov_run):
    """Two windows of one file pool their counts, but they are not independent runs: no
    interval (it would be narrowed by sqrt(2)) and no verdict that "the runs agree"."""
    from cfbmarkov.errors import IntervalWarning    # where the how-to names it

    windows = [(2.0, 4.0), (4.5, 6.5)]
    pooled = PaperEstimator(GRID, lag=0.1).fit(
        [discretize(markov_run, GRID, lag=0.1, window=w) for w in windows])
    with pytest.warns(IntervalWarning, match="are of one run, not independent runs"):
        judged = assess_fit(pooled, resamples=20)
    assert judged.uncertainty is None and judged.adequacy is None
    with pytest.warns(IntervalWarning, match="are of one run"):
        assess_fit(pooled, [markov_run, Trajectories(markov_run)], windows, resamples=20)


def test_a_python_prediction_repeats_the_verdicts_warnings(fitted, markov_run):
    from cfbmarkov.markov.adequacy import Adequacy

    warned = fitted.with_adequacy(Adequacy(warnings=("the halves disagree",)))
    with pytest.warns(SampleWarning, match="the model's fitting sample: the halves disagree"):
        warned.predict(markov_run, start=6.0, duration=0.5, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CfbmarkovWarning)
        fitted.predict(markov_run, start=6.0, duration=0.5, seed=1)   # no verdict: quiet


def test_predict_takes_a_kinetics_as_exact_kinetics_does(fitted, markov_run):
    kinetics = Kinetics((Property("X", FirstOrder(), {"rate": Constant(0.5)}),))
    *_, values = fitted.predict(markov_run, start=6.0, duration=0.5, seed=1,
                                kinetics=kinetics)
    *_, resolved = fitted.predict(markov_run, start=6.0, duration=0.5, seed=1,
                                  kinetics=kinetics.per_state(fitted.state_space))
    assert np.array_equal(values, resolved, equal_nan=True)
    assert np.nanmax(values) > 0


def test_save_and_predict_never_replace_a_run_or_their_input_unasked(fitted, markov_run,
                                                                     tmp_path):
    run = tmp_path / "run.h5"
    shutil.copy(markov_run, run)
    with pytest.raises(InputError, match="is a trajectory file, not a model file; add --force"):
        fitted.save(run)
    with pytest.raises(InputError, match="is one of the inputs"):
        fitted.predict(run, start=6.0, duration=0.5, output=run)
    other = tmp_path / "other.h5"
    shutil.copy(markov_run, other)
    with pytest.raises(InputError, match="simulated or imported trajectory file, not a "
                                         "prediction"):
        fitted.predict(run, start=6.0, duration=0.5, output=other)
    with Trajectories(other) as p:
        assert p.source != "markov-prediction"     # untouched
    # a prediction replaces a prediction; force replaces a run
    pred = fitted.predict(run, start=6.0, duration=0.5, output=tmp_path / "p.h5")
    fitted.predict(run, start=6.0, duration=1.0, seed=2, output=pred)
    with Trajectories(pred) as p:
        assert p.times[-1] == pytest.approx(7.0)
    fitted.predict(run, start=6.0, duration=0.5, output=other, force=True)
    with Trajectories(other) as p:
        assert p.source == "markov-prediction"
    model = tmp_path / "m.h5"
    fitted.save(model)
    fitted.save(model)                      # a model replaces a model
    with pytest.raises(InputError, match="is a model file, not a prediction"):
        fitted.predict(run, start=6.0, duration=0.5, output=model)
    fitted.save(run, force=True)
    assert MarkovModel.load(run).n_states == fitted.n_states


def test_a_window_pooled_with_itself_is_refused_as_on_the_command_line(markov_run):
    from cfbmarkov.markov import MaximumLikelihoodEstimator

    window = discretize(markov_run, GRID, lag=0.1, window=(2.0, 6.0))
    overlapping = discretize(markov_run, GRID, lag=0.1, window=(4.0, 7.0))
    later = discretize(markov_run, GRID, lag=0.1, window=(6.0, 8.0))
    for estimator in (PaperEstimator(GRID, lag=0.1), MaximumLikelihoodEstimator(GRID, lag=0.1)):
        with pytest.raises(InputError, match="hold the same data"):
            estimator.fit([window, window])
        with pytest.raises(InputError, match="2-6 s and 4-7 s\\) overlap: pooling"):
            estimator.fit([window, overlapping])
        pooled = estimator.fit([window, later])       # windows that do not overlap: pooled
        assert pooled.counts.sum() > estimator.fit(window).counts.sum()


def test_arguments_of_the_wrong_kind_are_named_in_one_line(markov_run):
    """Text for a number, a tuple for a state space, '10:15' for a window: one InputError
    naming the form expected, not a numpy TypeError; a plain number is a constant rate."""
    for call, message in [
            (lambda: discretize(markov_run, GRID, lag="0.1", window=(2.0, 6.0)),
             "lag '0.1' is a str, not a number of seconds"),
            (lambda: discretize(markov_run, GRID, lag=0.1, window="2:6"),
             "window '2:6' is not \\(start, stop\\) in s"),
            (lambda: discretize(markov_run, (4, 16), lag=0.1, window=(2.0, 6.0)),
             "state space \\(4, 16\\) is a tuple, not a state space"),
            (lambda: PaperEstimator(GRID, lag="0.1"), "is a str, not a number"),
            (lambda: Property("X", FirstOrder(), {"rate": "fast"}),
             "parameter rate = 'fast' is a str; give a number")]:
        with pytest.raises(InputError, match=message):
            call()
    assert Property("X", FirstOrder(), {"rate": 0.5}).parameters["rate"] == Constant(0.5)


def test_numbers_given_as_text_are_named_in_one_line(markov_run, tmp_path):
    """Text for a size, a lag or a bin width: one InputError naming the argument, not a
    TypeError from a comparison deep inside."""
    from cfbmarkov import write_trajectories
    from cfbmarkov.analysis.compare import compare_runs
    from cfbmarkov.markov.diagnostics import implied_timescales
    from cfbmarkov.markov.select import select_model

    times = np.arange(3) * 0.1
    positions = np.full((3, 2, 2), 0.05)
    for call, message in [
            (lambda: CellGrid(6, 38, 0.09, "0.95"), "cell grid height '0.95' is not a number"),
            (lambda: write_trajectories(tmp_path / "w.h5", times, positions, width="0.09",
                                        height=0.95), "width '0.09' is not a number"),
            (lambda: select_model(markov_run, window=(2.0, 6.0), columns=4, rows=16,
                                  lag="0.1"), "lag '0.1' is not a number"),
            (lambda: implied_timescales(markov_run, GRID, lags="0.1", window=(2.0, 6.0)),
             "lag '0.1' is not a number"),
            (lambda: compare_runs(markov_run, markov_run, (2.0, 6.0), bin_width="0.1"),
             "bin width '0.1' is not a number")]:
        with pytest.raises(InputError, match=message):
            call()


def test_laps_that_are_not_whole_numbers_are_refused(tmp_path):
    from cfbmarkov import write_trajectories

    times = np.arange(3) * 0.1
    positions = np.full((3, 2, 2), 0.05)
    with pytest.raises(InputError, match="laps: 0.5 is not a whole number"):
        write_trajectories(tmp_path / "w.h5", times, positions, width=0.09, height=0.95,
                           laps=np.full((3, 2), 0.5))
    assert not (tmp_path / "w.h5").exists()
    write_trajectories(tmp_path / "w.h5", times, positions, width=0.09, height=0.95,
                       laps=np.zeros((3, 2)))          # whole numbers as floats: accepted


def test_a_window_and_its_blocks_are_read_only(markov_run):
    window = discretize(markov_run, GRID, lag=0.1, window=(2.0, 6.0))
    half = window.block(2.0, 4.0)
    for arrays in (window, half):
        for name in ("states", "vertical", "times"):
            with pytest.raises(ValueError, match="read-only"):
                getattr(arrays, name)[:] = 0


def test_result_objects_echo_in_a_line_or_two(fitted):
    """A notebook cell's echo of an RTD, an interval or a kinetics answer shows arrays by
    shape, not thousands of numbers."""
    from cfbmarkov.markov.kinetics_exact import exact_kinetics

    rtd = fitted.rtd()
    text = repr(rtd)
    assert text.startswith(f"ResidenceTimeDistribution(mean={rtd.mean:.6g} s, "
                           f"sd={rtd.sd:.6g} s, lag=0.1, probability=<array ")
    assert len(text) < 400 and str(rtd.probability.size) in text
    answer = exact_kinetics(fitted, Kinetics((Property("X", FirstOrder(), {"rate": 0.5}),)))
    assert "bed_mean_by_cell=<array 64 float64>" in repr(answer["X"])
    assert len(repr(answer["X"])) < 400
    # the fields a model carries, and a comparison's sides, by shape too
    from cfbmarkov.kinetics import CellFields

    fields = CellFields(np.zeros(64), np.ones(64), np.zeros(64))
    assert repr(fields).startswith("CellFields(solids_fraction=<array 64 float64>")
    assert len(repr(fields)) < 200


def test_a_prediction_keeps_the_source_frame_of_its_initial_file(markov_run, tmp_path):
    """A run imported with z vertical and its origin moved: the prediction from it records
    the same axis letters and origin (info and export-vtk read them), not x, y at 0."""
    from cfbmarkov.trajectory_writer import write_trajectories

    with Trajectories(markov_run) as run:
        times, positions, laps = run.times, run.positions(), run.laps()
    moved = write_trajectories(tmp_path / "z.h5", times, positions, laps=laps, width=0.09,
                               height=0.95, axes={"across": "x", "vertical": "z"},
                               region_origin=[-0.045, 0.1])
    model = PaperEstimator(GRID, lag=0.1).fit(discretize(moved, GRID, 0.1, (2.0, 6.0)))
    pred = model.predict(moved, start=6.0, duration=0.5, output=tmp_path / "p.h5")
    with Trajectories(pred) as p, Trajectories(moved) as r:
        assert p.axes == r.axes and p.axes["vertical"] == "z"
        np.testing.assert_array_equal(p.region_origin, r.region_origin)


def test_a_prediction_from_a_frame_with_no_particle_is_refused_first(markov_run, tmp_path):
    """A tracked file (particles absent from frames) whose start frame holds no particle:
    refused before any Monte Carlo, naming when particles are present."""
    from cfbmarkov.trajectory_writer import write_trajectories

    with Trajectories(markov_run) as run:
        times, positions, laps = run.times, run.positions()[:, :5], run.laps()[:, :5]
    present = np.ones(positions.shape[:2], dtype=bool)
    present[(times > 5.95) & (times < 7.0)] = False        # 6-7 s: nobody seen
    positions = np.where(present[..., None], positions, np.nan)
    gappy = write_trajectories(tmp_path / "gap.h5", times, positions, laps=laps, width=0.09,
                               height=0.95, present=present)
    model = PaperEstimator(GRID, lag=0.1).fit(discretize(gappy, GRID, 0.1, (1.0, 5.0)))
    with pytest.raises(InputError, match="no particle is present \\(with a state\\) at 6.5 s.*"
                                         "present from 0 s to 8 s"):
        model.predict(gappy, start=6.5, duration=0.5, output=tmp_path / "p.h5")
    assert not (tmp_path / "p.h5").exists()


def test_a_window_of_another_lag_names_its_frames_in_words(markov_run):
    """The estimator's refusal of discrete trajectories at another lag says "1 frame",
    not "1 frames"."""
    window = discretize(markov_run, GRID, lag=0.025, window=(2.0, 4.0))
    with pytest.raises(InputError, match=r"a lag of 0.025 s \(1 frame\), the estimator's is "
                                         r"0.05 s"):
        PaperEstimator(GRID, lag=0.05).fit(window)
