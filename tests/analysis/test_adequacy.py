"""The verdict on a fitting sample (fit), pooled fits of several runs, and how long a sample
must be (stationarity --sample-length), on generated risers."""

import contextlib
import json
import math
import warnings

import h5py
import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.analysis.adequacy import assess_adequacy
from cfbmarkov.analysis.sample_length import sample_length, verdict_text
from cfbmarkov.cli import main
from cfbmarkov.markov import MarkovModel, fit_model
from cfbmarkov.errors import InputError
from cfbmarkov.markov.adequacy import Adequacy
from cfbmarkov.markov.discrete import discretize
from cfbmarkov.markov.estimate import estimator_from_name
from cfbmarkov.markov.pooling import discretize_runs
from cfbmarkov.markov.states import CellGrid
from cfbmarkov.trajectories import Trajectories

FAST = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=2.5, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)
SLOW = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.6, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)
SWITCH = 3.0        # s between switches of the two-chain riser
DURATION = 24.0


def _write(path, period, seed=3, n=3000, slow=False):
    """All particles follow the fast chain, then the slow one, switching every ``period``
    s (0: the fast chain throughout, a stationary run; with ``slow``, the slow one)."""
    k = int(round(DURATION / FAST.lag)) + 1
    t = FAST.lag * np.arange(k)
    regimes = ((t + 1e-9) // period).astype(int) % 2 if period else np.full(k, int(slow))
    return synthetic.write_regime_run(path, [FAST, SLOW], np.eye(2), n, DURATION, seed=seed,
                                      regimes=regimes)


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("adequacy")
    return {"switching": _write(folder / "switching.h5", SWITCH),
            "stationary": _write(folder / "stationary.h5", 0),
            "stationary2": _write(folder / "stationary2.h5", 0, seed=4)}


def _space():
    return CellGrid(4, 16, FAST.width, FAST.height)


def _verdict(path, window):
    model = fit_model(path, _space(), 0.025, window, "paper")
    return assess_adequacy(model, [path], [window])


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_windows_holding_a_switch_warn(runs):
    # windows of one switching time that straddle a switch: the halves see different chains
    for start in (1.5, 4.5, 7.5):
        verdict = _verdict(runs["switching"], (start, start + SWITCH))
        assert any("disagree" in line for line in verdict.warnings), verdict
        assert verdict.spread > verdict.limit
        means = [m for _, _, m, _ in verdict.parts]
        assert max(means) / min(means) > 1.4      # the slow and the fast chain's E(RT)


def test_a_window_of_many_switches_and_a_stationary_chain_do_not_warn(runs):
    long = _verdict(runs["switching"], (0.0, 8 * SWITCH))
    assert not long.warnings, long.warnings
    for start in (0.0, 1.5, 4.5, 7.5, 13.0):
        verdict = _verdict(runs["stationary"], (start, start + SWITCH))
        assert verdict.adequate, verdict.warnings
        assert verdict.spread < 0.1
        assert verdict.tail_share < 0.1


def test_the_parts_limit_from_the_interval_is_the_range_of_k_parts():
    """Halves (quarters) of a window hold 1/2 (1/4) of its data: the limit is the 95 %
    range of 2 (4) normal values with sqrt(2) (2) times the window's standard error, kept
    within 10-25 %; the same whatever the interval's level, a tolerance as before."""
    from scipy.stats import norm, studentized_range

    from cfbmarkov.analysis.adequacy import MAX_PARTS_LIMIT, MIN_PARTS_LIMIT, parts_limit

    width = 0.1                                     # a 90 % interval 10 % of E(RT) wide
    sigma = width / (2 * norm.ppf(0.95))
    for k in (2, 4):
        q95 = studentized_range.ppf(0.95, k, 1e5)
        assert parts_limit(width, k) == pytest.approx(q95 * np.sqrt(k) * sigma, rel=1e-4)
        wider = 2 * norm.ppf(0.975) * sigma            # the same error at a 95 % level
        assert parts_limit(wider, k, level=0.95) == pytest.approx(parts_limit(width, k))
    assert parts_limit(0.01, 4) == MIN_PARTS_LIMIT
    assert parts_limit(0.6, 2) == MAX_PARTS_LIMIT         # halves a factor 1.5 apart warn
    assert parts_limit(0.15, 4, from_interval=False) == pytest.approx(0.15 * np.sqrt(2))
    assert parts_limit(0.3, 4, from_interval=False) == MAX_PARTS_LIMIT   # a quarter apart warns


def test_a_stationary_flow_with_memory_does_not_warn_that_it_changed(tmp_path):
    """The synthetic demo's flow (a hidden direction: the cells chain misses memory, its
    quarters scatter beyond their bootstrap interval) fitted as `fit` does on 2 and 5 s
    windows: no "disagree" warning, where the limit was the interval's width (times
    sqrt(2) for quarters) and half of such windows warned "the flow changed"."""
    from cfbmarkov.analysis.fit_checks import assess_fit

    run = synthetic.write_run(tmp_path / "memory.h5", synthetic.RiserFlow(), 1000, 10.0,
                              seed=5)
    for window in [(2.0, 4.0), (5.0, 7.0), (4.0, 9.0)]:
        model = assess_fit(fit_model(run, CellGrid(6, 38), 0.025, window, "paper"),
                           resamples=30)
        verdict = model.adequacy
        assert not any("disagree" in line for line in verdict.warnings), verdict.warnings
        assert verdict.spread < verdict.part_limit


def test_a_window_across_a_step_change_warns_though_its_interval_widens(tmp_path):
    """A generated flow whose E(RT) steps up by 30 % halfway: the window across the step
    warns that its quarters disagree, although the step widens the window's own interval
    (its flow term measures the step, and is left out of the limit; the limit is at most
    25 %); windows within one side do not warn."""
    from cfbmarkov.analysis.fit_checks import assess_fit

    a = synthetic.RiserFlow(persistence=False)
    c = synthetic.RiserFlow(persistence=False, rise_velocity=1.7, fall_velocity=-0.8)
    k = int(round(12.0 / a.lag)) + 1
    regimes = np.zeros(k, dtype=int)
    regimes[int(round(6.0 / a.lag)):] = 1
    run = synthetic.write_regime_run(tmp_path / "step.h5", [a, c], np.eye(2), 400, 12.0,
                                     seed=7, regimes=regimes)
    across = assess_fit(fit_model(run, CellGrid(6, 38), 0.025, (2.0, 10.0), "paper"),
                        resamples=30).adequacy
    assert any("quarters" in line and "disagree" in line for line in across.warnings), across
    assert across.spread > across.part_limit
    within = assess_fit(fit_model(run, CellGrid(6, 38), 0.025, (6.5, 11.5), "paper"),
                        resamples=30).adequacy
    assert not any("disagree" in line for line in within.warnings), within.warnings


def test_short_window_and_net_flow_turn_warn(runs, tmp_path):
    few = _verdict(runs["stationary"], (2.0, 2.6))    # halves of 0.3 s hold no residence
    assert any("residences" in line for line in few.warnings)
    # a riser whose net flow is up, then down: the turn is named with both parts
    up = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.5, fall_velocity=-0.3,
                             vertical_spread=0.5, persistence=False)
    down = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=0.3, fall_velocity=-1.5,
                               vertical_spread=0.5, persistence=False)
    k = int(round(4.0 / up.lag)) + 1
    path = synthetic.write_regime_run(tmp_path / "turn.h5", [up, down], np.eye(2), 500, 4.0,
                                      seed=1, regimes=(np.arange(k) >= k // 2).astype(int))
    model = fit_model(path, _space(), 0.025, (0.0, 4.0), "mle")
    turn = assess_adequacy(model, [path], [(0.0, 4.0)])
    line = next(line for line in turn.warnings if "turns" in line)
    assert "up in 0-2 s" in line and "down in 2-4 s" in line


def test_verdict_in_the_model_file_and_the_verbs(runs, tmp_path, capsys):
    out = tmp_path / "m.h5"
    code, printed, err = run_cli(capsys, "fit", runs["switching"], "--cells", "4x16",
                                 "--window", "1.5:4.5", "-o", out)
    assert code == 0
    warned = [line for line in err.splitlines() if line.startswith("warning:")]
    assert any("disagree" in line and "cfbmarkov stationarity" in line for line in warned)
    assert len(warned) == len(set(warned))                    # each line once
    model = MarkovModel.load(out)
    # standard output alone (a log) says there are warnings, and how many of the verdict's
    count = len(model.adequacy.warnings)
    others = len(warned) - count                # e.g. an interval cut at 0: counted apart
    beside = f", beside {others} more about the model" if others else ""
    assert len(warned) == len(model.warnings()) and others >= 0
    assert (f"  the fitting sample's verdict: {count} warning{'' if count == 1 else 's'} "
            f"(printed as `warning:` lines{beside}; `cfbmarkov info MODEL` repeats them)") \
        in printed
    assert model.adequacy is not None and not model.adequacy.adequate
    assert any("disagree" in line for line in model.warnings())
    assert Adequacy.from_attr(model.adequacy.to_attr()) == model.adequacy
    with h5py.File(out, "r+") as f:         # a file without the verdict still loads
        del f.attrs["adequacy"]
    assert MarkovModel.load(out).adequacy is None
    code, _, err = run_cli(capsys, "fit", runs["switching"], "--cells", "4x16", "--window",
                           "1.5:4.5", "-o", out, "--no-adequacy")
    assert code == 0 and "disagree" not in err and MarkovModel.load(out).adequacy is None
    # predict and compare repeat it
    run_cli(capsys, "fit", runs["switching"], "--cells", "4x16", "--window", "1.5:4.5",
            "-o", out)
    pred = tmp_path / "p.h5"
    code, _, err = run_cli(capsys, "predict", out, "--init", runs["switching"], "--start",
                           "4.5", "--duration", "2", "-o", pred, "--quiet")
    assert code == 0 and "warning: the model's fitting sample:" in err
    code, _, err = run_cli(capsys, "compare", runs["switching"], pred, "--window", "4.5:6.5",
                           "-o", tmp_path / "cmp", "--no-figures", "--resamples", "0")
    assert code == 0 and "fitting sample" in err
    summary = json.loads((tmp_path / "cmp" / "summary.json").read_text())
    assert summary["adequacy"]["warnings"]
    assert any("fitting sample" in w for w in summary["warnings"])


def test_assess_fit_in_python_warns_each_line_of_the_verdict(runs):
    """A model fitted in Python and given its verdict by assess_fit says it as it comes (a
    notebook shows it): each warning line of the verdict once, a SampleWarning; a window
    whose verdict has none warns nothing."""
    from cfbmarkov.analysis.fit_checks import assess_fit
    from cfbmarkov.errors import SampleWarning
    from cfbmarkov.markov import fit_model

    model = fit_model(runs["switching"], _space(), 0.025, (1.5, 4.5), "paper")
    with pytest.warns(SampleWarning) as caught:
        model = assess_fit(model, resamples=0)
    said = [str(w.message) for w in caught if issubclass(w.category, SampleWarning)]
    assert said == list(model.adequacy.warnings) and any("disagree" in w for w in said)
    steady = fit_model(runs["stationary"], _space(), 0.025, (1.5, 4.5), "paper")
    with warnings.catch_warnings():
        warnings.simplefilter("error", SampleWarning)
        steady = assess_fit(steady, resamples=0)
    assert steady.adequacy.warnings == ()


def test_rtd_with_a_new_interval_says_the_verdict_was_made_with_the_stored_one(
        runs, tmp_path, capsys):
    """`rtd --resamples N --level L` prints a new interval; the stored verdict's lines were
    judged (and quote) the interval fit stored: a line says so, naming its level and bounds."""
    out = tmp_path / "m.h5"
    assert run_cli(capsys, "fit", runs["switching"], "--cells", "4x16", "--window",
                   "1.5:4.5", "--resamples", "20", "-o", out)[0] == 0
    stored = MarkovModel.load(out).uncertainty
    code, text, _ = run_cli(capsys, "rtd", out, "--resamples", "20", "--level", "0.5", "--json")
    assert code == 0
    data = json.loads(text)
    assert data["level"] == 0.5 and data["rt_mean_interval"] != list(stored.rt_mean_interval)
    note = [w for w in data["warnings"] if w.startswith("the fitting sample's verdict above")]
    assert len(note) == 1 and "stored 90 % E(RT) interval" in note[0], data["warnings"]
    code, text, _ = run_cli(capsys, "rtd", out, "--json")      # the stored interval: no note
    assert code == 0 and not any("verdict above" in w for w in json.loads(text)["warnings"])
    # the same resamples and level form the same interval: nothing to tell apart
    code, text, _ = run_cli(capsys, "rtd", out, "--resamples", "20", "--json")
    data = json.loads(text)
    assert code == 0 and data["rt_mean_interval"] == list(stored.rt_mean_interval)
    assert not any("verdict above" in w for w in data["warnings"]), data["warnings"]


def test_pooling_windows_adds_their_counts(runs):
    """The counts of three windows of one run that do not overlap add; the same window
    pooled with itself is refused (here, from the files; by the estimators alike,
    test_python_api_fit)."""
    path = runs["stationary"]
    space = _space()
    windows = [(2.0, 4.0), (4.0, 6.0), (6.0, 8.0)]
    pooled_data = [discretize(path, space, 0.025, w) for w in windows]
    with Trajectories(path) as a, Trajectories(path) as b:
        with pytest.raises(InputError, match="same data"):
            discretize_runs([a, b], space, 0.025, [(2.0, 8.0)])
    for name in ("paper", "mle"):
        fitter = estimator_from_name(name, space, 0.025)
        each = [fit_model(path, space, 0.025, w, name) for w in windows]
        pooled = fitter.fit(pooled_data)
        np.testing.assert_array_equal(pooled.counts, sum(m.counts for m in each))
        assert pooled.frame_pairs == sum(m.frame_pairs for m in each)
        with pytest.raises(InputError, match="same data"):
            fitter.fit([pooled_data[0]] * 3)


def test_fit_several_runs(runs, tmp_path, capsys):
    out = tmp_path / "pooled.h5"
    code, _, err = run_cli(capsys, "fit", runs["stationary"], runs["stationary2"], "--cells",
                           "4x16", "--window", "2:8,3:9", "-o", out)
    assert code == 0, err
    model = MarkovModel.load(out)
    assert len(model.source) == 2 and model.adequacy.adequate
    assert len(model.adequacy.parts) >= 4         # the parts of both runs
    single = fit_model(runs["stationary"], _space(), 0.025, (2.0, 8.0), "paper")
    other = fit_model(runs["stationary2"], _space(), 0.025, (3.0, 9.0), "paper")
    np.testing.assert_array_equal(model.counts, single.counts + other.counts)
    # refused in one line: windows that do not match the runs
    code, _, err = run_cli(capsys, "fit", runs["stationary"], runs["stationary2"], "--window",
                           "1:2,2:3,3:4", "-o", tmp_path / "x.h5")
    assert code == 2 and "3 windows for 2 runs" in err
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize("change, named", [
    (dict(height=2 * FAST.height), "height"),
    (dict(width=2 * FAST.width), "width"),
    (dict(lag=2 * FAST.lag), "frame interval"),
])
def test_runs_of_another_geometry_or_frame_interval_are_refused(runs, tmp_path, capsys,
                                                                change, named):
    from dataclasses import replace

    other = synthetic.write_run(tmp_path / "other.h5", replace(FAST, **change), 200, 2.0,
                                seed=1)
    code, _, err = run_cli(capsys, "fit", runs["stationary"], other, "--cells", "4x16",
                           "--window", "0.5:1.5", "--lag", "0.05", "-o", tmp_path / "x.h5")
    assert code == 2 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert f"different {named}" in err
    assert not (tmp_path / "x.h5").exists()


def test_sample_length(runs, capsys):
    stationary = sample_length(runs["stationary"], _space(), lag=0.025, start=0.0)
    # every window's figures lie within the tolerance, but the shortest ones cannot contain
    # their model's residences (fit warns there): the sample length is the first that can
    outlasts = stationary.outlasts()
    assert outlasts[0] and not outlasts[2:].any()
    assert stationary.within()[~outlasts].all() and not stationary.within()[outlasts].any()
    assert stationary.sample_length == stationary.lengths[np.argmin(outlasts)]
    assert stationary.missed()[0] == "outlasts"
    switching = sample_length(runs["switching"], _space(), lag=0.025, start=0.0)
    assert not switching.within()[:3].any()       # windows within the first (fast) chain
    assert np.isnan(switching.sample_length) or switching.sample_length >= 2 * SWITCH
    code, out, _ = run_cli(capsys, "stationarity", runs["stationary"], "--sample-length",
                           "--cells", "4x16", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["sample_length"] == stationary.sample_length and data["tolerance"] == 0.1
    assert data["windows"][0]["outlasting_share"] > 0.1
    assert [w["length"] for w in data["windows"]] == [0.5, 1.0, 2.0, 5.0, 10.0, 20.0]
    code, out, _ = run_cli(capsys, "stationarity", runs["switching"], "--sample-length",
                           "--cells", "4x16", "--tolerance", "0.5")
    assert code == 0 and "sample length:" in out and "within 50 %" in out
    # --span bounds the windows and the long run: inside the first (fast) 3 s of the
    # switching run it is as stationary as the fast chain alone
    code, out, _ = run_cli(capsys, "stationarity", runs["switching"], "--sample-length",
                           "--cells", "4x16", "--span", "0:3", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["start"] == 0.0 and data["span_end"] == pytest.approx(3.0)
    assert [w["length"] for w in data["windows"]] == [0.5, 1.0, 2.0]
    inside = sample_length(runs["switching"], _space(), lag=0.025, start=0.0, stop=3.0)
    assert inside.long_run_mean == pytest.approx(data["long_run"]["rt_mean"])
    assert inside.long_run_mean < switching.long_run_mean
    code, _, err = run_cli(capsys, "stationarity", runs["switching"], "--sample-length",
                           "--cells", "4x16", "--span", "0:3", "--start", "5")
    assert code == 2 and "outside --span" in err and err.count("\n") == 1


def test_report_paragraph_repeats_the_verdict():
    from cfbmarkov.report.table3 import trust_text

    summary = {"md_rtd": 0.2, "adequacy": {"warnings": ["the halves disagree: 67 %"]}}
    assert "fitting sample was warned about" in trust_text("4", "paper", summary)
    assert "warned" not in trust_text("4", "paper", {"md_rtd": 0.2})


def test_pooled_verdict_names_the_run_that_disagrees_and_pooled_halves(runs, tmp_path):
    """Two fast runs and a slow one pooled: 'the runs disagree', the slow run named first;
    two stationary runs pooled: no warning, each run's E(RT) recorded; two switching runs
    in step: the pooled windows' halves disagree."""
    slow = _write(tmp_path / "slow.h5", 0, seed=5, n=1000, slow=True)
    paths = [runs["stationary"], runs["stationary2"], slow]
    window = (2.0, 8.0)
    with contextlib.ExitStack() as stack:
        opened = [stack.enter_context(Trajectories(p)) for p in paths]
        data = discretize_runs(opened, _space(), 0.025, [window])
    model = estimator_from_name("paper", _space(), 0.025).fit(data)
    verdict = assess_adequacy(model, paths, [window] * 3, discrete=data)
    line = next(line for line in verdict.warnings if "runs disagree" in line)
    # a pooled fit is not told to pool runs, but to pool more
    assert all("pool several runs" not in w for w in verdict.warnings)
    assert any("or pool more runs" in w for w in verdict.warnings)
    assert line.index(str(slow)) < min(line.find(str(p)) % len(line) for p in paths[:2])
    assert [r for r, _ in verdict.runs] == [str(p) for p in paths]
    assert Adequacy.from_dict(verdict.to_dict()) == verdict
    calm = estimator_from_name("paper", _space(), 0.025).fit(data[:2])
    quiet = assess_adequacy(calm, paths[:2], [window] * 2, discrete=data[:2])
    assert quiet.adequate, quiet.warnings
    assert len(quiet.runs) == 2 and all(m > 0 for _, m in quiet.runs)
    other = _write(tmp_path / "switching2.h5", SWITCH, seed=6, n=1000)
    pair = [runs["switching"], other]
    step = (1.5, 4.5)
    model = fit_model(pair[0], _space(), 0.025, step, "paper")
    with Trajectories(pair[0]) as a, Trajectories(pair[1]) as b:
        both = discretize_runs([a, b], _space(), 0.025, [step])
    model = estimator_from_name("paper", _space(), 0.025).fit(both)
    verdict = assess_adequacy(model, pair, [step] * 2, discrete=both)
    assert any("halves of the pooled windows disagree" in line for line in verdict.warnings)


def test_sample_length_of_several_runs_pools_windows_and_long_runs(runs, capsys):
    """Two stationary runs: the windows' models fitted on both runs' counts, the long run
    over both runs' residences; the table names both; the sliding windows refuse two runs,
    and a run pooled with itself is refused."""
    one = sample_length(runs["stationary"], _space(), lag=0.025, start=0.0)
    two = sample_length([runs["stationary"], runs["stationary2"]], _space(), lag=0.025,
                        start=0.0)
    assert two.long_run_count > 1.8 * one.long_run_count
    assert two.within()[~two.outlasts()].all()
    assert two.sample_length == one.sample_length == two.lengths[np.argmin(two.outlasts())]
    assert "2 runs pooled" in two.description
    code, out, _ = run_cli(capsys, "stationarity", runs["stationary"], runs["stationary2"],
                           "--sample-length", "--cells", "4x16")
    assert code == 0 and str(runs["stationary2"]) in out and "2 runs pooled" in out
    code, _, err = run_cli(capsys, "stationarity", runs["stationary"], runs["stationary2"])
    assert code == 2 and "--sample-length" in err and len(err.strip().splitlines()) == 1
    code, _, err = run_cli(capsys, "stationarity", runs["stationary"], runs["stationary"],
                           "--sample-length", "--cells", "4x16")
    assert code == 2 and "same data" in err


def _pair_runs(folder):
    """Two runs of one flow (seeds 1, 2) and one of a slower flow, as write_run stores them
    (their parameters hold no case settings, so pooling them is not refused)."""
    from dataclasses import replace

    flow = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=2.5, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)
    return (synthetic.write_run(folder / "fast.h5", flow, 400, 6.0, seed=1),
            synthetic.write_run(folder / "fast2.h5", flow, 400, 6.0, seed=2),
            synthetic.write_run(folder / "slow.h5", replace(flow, rise_velocity=1.4), 400,
                                6.0, seed=3))


@pytest.mark.parametrize("resamples", ["30", "0"])
def test_runs_of_different_flows_warn_with_and_without_an_interval(tmp_path, capsys,
                                                                   resamples):
    """The cross-run limit does not grow with the runs' disagreement: two flows pooled warn
    with an interval (whose flow term the disagreement widens) as without; two seeds of
    one flow do not."""
    fast, fast2, slow = _pair_runs(tmp_path)
    code, _, err = run_cli(capsys, "fit", fast, slow, "--cells", "4x16", "--window", "1:6",
                           "--resamples", resamples, "-q", "-o", tmp_path / "p.h5")
    assert code == 0, err
    assert any(line.startswith("warning: the runs disagree") and str(slow) in line
               for line in err.splitlines()), err
    code, _, err = run_cli(capsys, "fit", fast, fast2, "--cells", "4x16", "--window", "1:6",
                           "--resamples", resamples, "-q", "-o", tmp_path / "q.h5")
    assert code == 0, err
    assert "disagree" not in err, err


def _case_run(path, velocity, seed):
    """A generated run whose parameters record a simulated case's settings."""
    from cfbmarkov.config import CaseConfig
    from cfbmarkov.trajectory_writer import TrajectoryWriter

    case = json.loads(CaseConfig().model_dump_json())
    case["gas"]["superficial_velocity"] = velocity
    case["seed"] = seed
    times, positions, laps, _ = synthetic._sampled(FAST, 100, 2.0, seed, 0.0)
    with TrajectoryWriter(path, np.arange(100), width=FAST.width, height=FAST.height,
                          source="cfd-dem", parameters=case, frame_interval=FAST.lag) as w:
        w.append_frames(times, positions, laps=laps)
    return path


def test_runs_of_different_cases_are_refused(tmp_path, capsys):
    """Files recording different case settings are refused by fit and stationarity
    --sample-length in one line naming the setting and both values; the same case from
    two seeds pools."""
    u3 = _case_run(tmp_path / "u3.h5", 3.0, 1)
    u4 = _case_run(tmp_path / "u4.h5", 4.0, 2)
    u3b = _case_run(tmp_path / "u3b.h5", 3.0, 3)
    for argv in (["fit", u3, u4, "--cells", "4x16", "--window", "0.5:1.5", "-o",
                  tmp_path / "x.h5"],
                 ["stationarity", u3, u4, "--sample-length", "--cells", "4x16"]):
        code, out, err = run_cli(capsys, *argv)
        assert code == 2 and "Traceback" not in err, err
        assert len(err.strip().splitlines()) == 1
        assert "gas.superficial_velocity = 3" in err and "= 4" in err, err
        assert str(u3) in err and str(u4) in err
    assert not (tmp_path / "x.h5").exists()
    code, _, err = run_cli(capsys, "fit", u3, u3b, "--cells", "4x16", "--window", "0.5:1.5",
                           "--resamples", "0", "-q", "-o", tmp_path / "y.h5")
    assert code == 0, err


def test_sample_length_long_run_from_the_flux_where_the_span_cuts_residences(tmp_path, capsys):
    # a long-tailed flow (E(RT) 2.69 s) over a span of 6 s: its complete residences average
    # a fifth less than the flow's E(RT) and cover too little of the particle-time for
    # their SD(RT) to be judged; the long run's E(RT) comes from the net flux
    flow = synthetic.RiserFlow(persistence=False, rise_velocity=1.4, fall_velocity=-1.0,
                               lateral_probability=0.08)
    exact = synthetic.cell_chain(flow).rtd()
    path = synthetic.write_run(tmp_path / "tail.h5", flow, 2000, 6.0, seed=1)
    result = sample_length(path, flow.grid, lag=0.025, start=0.0, estimator="mle")
    assert result.long_run_mean == pytest.approx(exact.mean, rel=0.04)
    assert result.long_run_observed_mean < 0.9 * exact.mean
    assert result.censored_share > 0.3 and not result.sd_judged
    assert np.isnan(result.deviations()[1]).all()
    within = ((np.abs(result.rt_mean / result.long_run_mean - 1) <= result.tolerance)
              & ~result.outlasts())
    assert (result.within() == within).all() and within[-1]
    code, out, _ = run_cli(capsys, "stationarity", path, "--sample-length", "--cells", "6x38",
                           "--estimator", "mle", "--json")
    assert code == 0
    long_run = json.loads(out)["long_run"]
    assert long_run["rt_sd_judged"] is False
    assert long_run["rt_mean"] == pytest.approx(result.long_run_mean)
    assert long_run["rt_mean_observed"] < long_run["rt_mean"]
    assert json.loads(out)["verdict"].startswith(f"{result.sample_length:g} s")
    code, out, _ = run_cli(capsys, "stationarity", path, "--sample-length", "--cells", "6x38",
                           "--estimator", "mle")
    assert code == 0 and "SD(RT) not judged" in out and "from its net solids flux" in out
    code, _, err = run_cli(capsys, "stationarity", path, "--sample-length", "--judge", "1:2")
    assert code == 2 and "--judge" in err and err.count("\n") == 1
    # a short-tailed flow's span covers its residences: both figures judged
    stationary = sample_length(_write(tmp_path / "fast.h5", 0), _space(), lag=0.025, start=0.0)
    assert stationary.sd_judged and 0.0 < stationary.censored_share < 0.3
    assert stationary.long_run_mean == pytest.approx(stationary.long_run_observed_mean, rel=0.05)


def test_a_model_that_does_not_carry_its_windows_throughput_warns(runs, tmp_path):
    from cfbmarkov.analysis.adequacy import THROUGHPUT_LIMIT, window_rt_mean

    # on a stationary chain both estimators keep the window's throughput: the model's E(RT)
    # equals the window's particle-time over its net passes within a few per cent
    window = (2.0, 5.0)
    fast = window_rt_mean([runs["stationary"]], [window], "up")
    for estimator in ("paper", "mle"):
        model = fit_model(runs["stationary"], _space(), 0.025, window, estimator)
        verdict = assess_adequacy(model, [runs["stationary"]], [window])
        assert verdict.window_rt_mean == pytest.approx(fast)
        assert abs(verdict.rt_mean / fast - 1) < THROUGHPUT_LIMIT / 3
        assert not any("throughput E(RT)" in line for line in verdict.warnings)
        assert f"fitting window's own E(RT): {fast:.4g} s" in model.with_adequacy(
            verdict).summary()
    # the fast chain's model judged on the slow chain's window: its E(RT) lies far from the
    # throughput of the flow it is said to carry, and the line names the numbers and the cure
    slow_run = _write(tmp_path / "slow.h5", 0, slow=True)
    slow = window_rt_mean([slow_run], [window], "up")
    assert slow > 1.3 * fast
    model = fit_model(runs["stationary"], _space(), 0.025, window, "paper")
    verdict = assess_adequacy(model, [slow_run], [window])
    line = next(line for line in verdict.warnings if "throughput E(RT)" in line)
    assert f"{slow:.3g} s" in line and "--estimator mle" in line and "% below its" in line
    assert Adequacy.from_dict(verdict.to_dict()).window_rt_mean == pytest.approx(slow)
    mle = fit_model(runs["stationary"], _space(), 0.025, window, "mle")
    line = next(line for line in assess_adequacy(mle, [slow_run], [window]).warnings
                if "throughput E(RT)" in line)
    assert "--estimator mle" not in line and "longer window" in line
    # an open riser has no net flux to compare with
    open_run = synthetic.write_open_run(tmp_path / "open.h5", SLOW, 200, 2.0)
    assert np.isnan(window_rt_mean([open_run], [(0.0, 2.0)], "up"))


def test_no_throughput_is_formed_from_fewer_than_ten_net_passes(tmp_path):
    """One tracer passing the boundary a few times: its particle-time over so few passes is
    mostly the partial laps at the window's edges, so no throughput is formed or checked."""
    from cfbmarkov.analysis.adequacy import MIN_THROUGHPUT_PASSES, window_rt_mean
    from cfbmarkov.observed.residence import residence_flux

    few = synthetic.write_run(tmp_path / "few.h5", synthetic.RiserFlow(columns=2, rows=8), 1,
                              4.0, seed=3)
    with Trajectories(few) as run:
        _, passes = residence_flux(run, (0.0, 4.0), "up")
    assert 0 < passes < MIN_THROUGHPUT_PASSES
    assert np.isnan(window_rt_mean([few], [(0.0, 4.0)], "up"))
    many = synthetic.write_run(tmp_path / "many.h5", synthetic.RiserFlow(columns=2, rows=8), 40,
                               4.0, seed=3)
    assert np.isfinite(window_rt_mean([many], [(0.0, 4.0)], "up"))


def test_the_throughput_limit_widens_for_the_windows_cut_through_few_particles_laps(tmp_path):
    """The window's net passes differ from the chain's flux by what each particle still had
    ahead of it where the window cut it, g(s_start) - g(s_end), g the chain's pass
    potential: few particles over a short window leave the window's throughput E(RT) that
    uncertain, where the chain counts no cut. A stationary known chain of 300 particles over
    1 s (about 150 net passes): the limit is 3 x sqrt(2 Var(g) 300) / passes, wider than
    10 %, and no throughput line is printed where the chain is right; the same line still
    warns beyond it, naming the cut."""
    from cfbmarkov.analysis.adequacy import (THROUGHPUT_LIMIT, UNIFORM_POTENTIAL_VARIANCE,
                                             _throughput_line, pass_potential_variance,
                                             throughput_limit, window_throughput)
    from cfbmarkov.observed.residence import residence_flux

    flow = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)
    run = synthetic.write_run(tmp_path / "r.h5", flow, 300, 1.0, seed=1010)
    model = fit_model(run, CellGrid(4, 16), 0.025, (0.0, 1.0), "mle")
    mean, edge_sd = window_throughput([run], [(0.0, 1.0)], "up", model)
    with Trajectories(run) as traj:
        particle_time, passes = residence_flux(traj, (0.0, 1.0), "up")
    assert mean == pytest.approx(particle_time / passes)
    variance = pass_potential_variance(model)
    assert edge_sd == pytest.approx(np.sqrt(2 * variance * 300) / passes, rel=1e-12)
    # without the chain, heights uniform in a riser climbed alike: 1/12 lap^2
    assert window_throughput([run], [(0.0, 1.0)], "up")[1] == pytest.approx(
        np.sqrt(2 * UNIFORM_POTENTIAL_VARIANCE * 300) / passes, rel=1e-12)
    limit = throughput_limit(edge_sd)
    assert limit == pytest.approx(3.0 * edge_sd) and limit > THROUGHPUT_LIMIT
    assert throughput_limit(0.01) == THROUGHPUT_LIMIT
    assert throughput_limit(float("nan")) == THROUGHPUT_LIMIT
    truth = synthetic.cell_chain(flow).rtd().mean
    verdict = assess_adequacy(model, [run], [(0.0, 1.0)])
    assert verdict.throughput_limit == pytest.approx(limit)
    assert abs(model.rtd().mean / truth - 1) < 0.05     # the chain is right about the flow
    assert abs(model.rtd().mean / mean - 1) > THROUGHPUT_LIMIT      # the window's is off
    assert not any("throughput E(RT)" in line for line in verdict.warnings)
    assert Adequacy.from_dict(verdict.to_dict()).throughput_limit == pytest.approx(limit)
    assert f"the verdict warns beyond {100 * limit:.2g} %, widened from 10 %" in (
        model.with_adequacy(verdict).summary())
    # beyond the widened limit the line still warns, and names the cut
    line = _throughput_line(model, mean * (1 + 1.2 * limit), mean, edge_sd=edge_sd)
    assert line is not None and "cut through the particles' laps" in line
    assert _throughput_line(model, mean * (1 + 0.9 * limit), mean, edge_sd=edge_sd) is None


def test_a_figure_beyond_its_limit_is_printed_beyond_it():
    """A spread of 6.72 % against a limit of 6.58 % reads "6.7" and "6.6", not "7" twice;
    whole percents where they differ."""
    from cfbmarkov.analysis.adequacy import _percents

    assert _percents(0.0672, 0.0658) == ("6.7", "6.6")
    assert _percents(0.066051, 0.066049) == ("6.61", "6.60")
    assert _percents(0.25, 0.10) == ("25", "10")


def test_the_throughput_line_names_a_reducible_chain():
    """A chain of several closed classes weights them by their entry flux: the throughput
    line says so beside its estimator's reason; a chain of one class does not."""
    from types import SimpleNamespace

    from cfbmarkov.analysis.adequacy import _throughput_line

    two = SimpleNamespace(estimator="mle", closed_classes=[np.arange(3), np.arange(3, 5)])
    line = _throughput_line(two, 1.5, 1.0)
    assert "%): the chain is reducible (2 closed classes" in line
    assert "need not agree; coarser --cells" in line and "does not carry the flow" not in line
    assert "no 'does not carry its own fitting window' line" in line    # keep it only so
    paper = SimpleNamespace(estimator="paper", closed_classes=two.closed_classes)
    assert "need not agree; the paper's estimator averages" in _throughput_line(paper, 1.5, 1.0)
    one = SimpleNamespace(estimator="mle", closed_classes=[np.arange(5)])
    assert "reducible" not in _throughput_line(one, 1.5, 1.0)
    assert "does not carry the flow" in _throughput_line(one, 1.5, 1.0)
    assert _throughput_line(two, 1.05, 1.0) is None


def test_a_passed_verdict_says_so_with_its_numbers():
    """No warning: one line with the parts' spread and limit (times sqrt(2) for quarters, as
    they are judged; for pooled runs each run's E(RT) against the pool's instead), the
    throughput gap and the share of residences beyond the window; a warning: no such
    line."""
    from cfbmarkov.markov.adequacy import Adequacy

    parts = tuple((a, a + 1.0, 1.0, "up") for a in (0.0, 1.0, 2.0, 3.0))
    calm = Adequacy((), parts, 1.02, 0.031, 0.057, 4.0, 0.002, (), 1.0)
    assert calm.passed_line() == (
        "the fitting sample's verdict: no warning: the window's quarters agree (E(RT) spread "
        "3.1 %, limit 8.1 %); the chain carries the window's throughput (within 2 %); 0.2 % "
        "of its residences outlast the window (judged on this window alone: a flow that "
        "changes over longer times than it can lie elsewhere, which `cfbmarkov stationarity` "
        "on a longer run, or runs pooled, show)")
    assert "under 0.1 % of its" in Adequacy((), parts[:2], 1.0, 0.01, 0.05, 2.0, 1e-9, (),
                                            1.0).passed_line()
    halves = Adequacy((), parts[:2], 1.0, 0.01, 0.05, 2.0, 1e-9).passed_line()
    assert "halves agree (E(RT) spread 1 %, limit 5 %)" in halves
    pooled = Adequacy((), parts, 1.0, 0.01, 0.05, 2.0, 0.01, (("a.h5", 0.98), ("b.h5", 1.03)),
                      runs_limit=0.071)
    assert "quarters agree" not in pooled.passed_line()       # judged run by run, not here
    assert "judged on this window alone" not in pooled.passed_line()      # runs pooled
    # no throughput figure (a file with absences, which stationarity cannot read): the
    # aside does not send there
    gapped = Adequacy((), parts, 1.02, 0.031, 0.057, 4.0, 0.002, (), float("nan"))
    assert gapped.passed_line().endswith("which a longer run, or runs pooled, show)")
    assert ("the 2 runs agree (E(RT) fitted on each alone 0.980, 1.03 s, pooled 1.00 s; each "
            "within 3 % of the pooled model's, limit 7.1 %; their parts' spread 1 %)"
            ) in pooled.passed_line()
    # without an interval the runs are judged against the default tolerance alone: runs
    # 24 % apart passed it and read "agree"
    blunt = Adequacy((), parts, 2.08, 0.022, 0.3, 4.0, 0.013, (("a.h5", 2.37), ("b.h5", 1.86)),
                     runs_limit=0.3, runs_interval=False)
    line = blunt.passed_line()
    assert "runs agree" not in line and "2 runs are not judged against their own uncertainty" in line
    assert "each within 14 % of the pooled model's, limit 30 %" in line
    assert "give --resamples to judge them" in line
    assert Adequacy.from_dict(blunt.to_dict()) == blunt
    assert Adequacy(("a warning",), parts, 1.0, 0.1, 0.05).passed_line() is None


def test_a_pooled_fit_judges_short_halves_across_its_runs(tmp_path, capsys):
    """Three runs whose 4 s windows' halves hold 24-30 residences each: fitted alone, a run
    whose half holds fewer than 30 warns that the window is too short to judge; pooled, the
    halves hold three times as many, so no run is named (adding runs must not add that
    warning); pooled windows of 1 s still hold too few and warn once, for the pool."""
    flow = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)
    paths = [synthetic.write_run(tmp_path / f"run{s}.h5", flow, 500, 8.0, seed=s)
             for s in (11, 12, 13)]
    code, _, err = run_cli(capsys, "fit", paths[1], "--cells", "4x16", "--window", "1:5",
                           "--estimator", "mle", "--resamples", "0", "-o", tmp_path / "one.h5")
    assert code == 0 and "holds 24 residences (fewer than 30)" in err
    code, _, err = run_cli(capsys, "fit", *paths, "--cells", "4x16", "--window", "1:5",
                           "--estimator", "mle", "--resamples", "0", "-o", tmp_path / "p.h5")
    assert code == 0 and "residences (fewer than 30)" not in err, err
    code, _, err = run_cli(capsys, "fit", *paths, "--cells", "4x16", "--window", "1:2",
                           "--estimator", "mle", "--resamples", "0", "-o", tmp_path / "q.h5")
    short = [line for line in err.splitlines() if "(fewer than 30)" in line]
    assert code == 0 and len(short) == 1 and "of the pooled fitting windows (3 runs)" in short[0]


def test_the_summary_says_a_reducible_chain_need_not_carry_the_throughput(tmp_path):
    """Particles that never change column (each column a closed class): the summary's line
    of the window's own E(RT) says a reducible chain need not carry it; an irreducible
    chain's says it should."""
    from cfbmarkov.markov import CellGrid
    from cfbmarkov.trajectory_writer import write_trajectories

    rng = np.random.default_rng(4)
    t = 0.01 * np.arange(301)
    x = np.broadcast_to(rng.uniform(0.0, 0.04, 120), (t.size, 120))
    speed = np.where(x[0] < 0.02, 1.0, 0.6)
    y = np.mod(rng.uniform(0.0, 0.3, 120) + speed * t[:, None], 0.3)
    run = write_trajectories(tmp_path / "columns.h5", t, np.stack([x, y], axis=-1),
                             width=0.04, height=0.3, source="cfd-dem")
    space = CellGrid(4, 12, 0.04, 0.3)
    model = fit_model(run, space, 0.01, (0.0, 3.0), "mle")
    assert len(model.closed_classes) > 1
    summary = model.with_adequacy(assess_adequacy(model, [run], [(0.0, 3.0)])).summary()
    assert "a reducible chain, which weights its classes by their net entry flux, need not " \
           "carry it" in summary
    assert "the throughput the chain should carry" not in summary


def test_sample_length_of_runs_of_different_flows_is_not_judged(tmp_path, capsys):
    """Runs of two flows pooled (a fast and a slow chain): their long-run E(RT) lie far
    apart, so no sample length is given and the verdict names each run's E(RT) and says to
    judge each alone (it advised memory for the mixture's miss); two seeds of one flow are
    judged as before."""
    fast, fast2, slow = _pair_runs(tmp_path)
    mixed = sample_length([fast, slow], _space(), lag=0.025, start=0.5)
    assert len(mixed.run_rt_means) == 2 and math.isnan(mixed.sample_length)
    text = verdict_text(mixed, "cells")
    assert text.startswith("not judged: the runs' long-run E(RT) differ (fast.h5 ")
    assert "judge each run alone" in text and "memory" not in text
    same = sample_length([fast, fast2], _space(), lag=0.025, start=0.5)
    assert not verdict_text(same, "cells").startswith("not judged")
    code, out, _ = run_cli(capsys, "stationarity", fast, slow, "--sample-length", "--cells",
                           "4x16", "--start", "0.5")
    assert code == 0 and "sample length: not judged: the runs' long-run E(RT) differ" in out


def test_a_window_one_lag_long_is_judged_too_short_not_refused(runs):
    """A window of one lag: its quarters hold no frame; the verdict says its halves hold no
    residence (the window is too short), instead of failing on a quarter's window the user
    never gave."""
    verdict = _verdict(runs["stationary"], (10.0, 10.025))
    assert any("holds 0 residences" in line and "too short" in line
               for line in verdict.warnings), verdict.warnings


def test_the_flow_terms_absence_is_put_down_to_its_cause():
    """A window shorter than two blocks of three mean residence times is said to be short;
    a window long enough whose blocks saw too few residences whole (tracks of a second in a
    flow of E(RT) 2.4 s) is not told to be longer, which would not help."""
    from cfbmarkov.analysis.adequacy import flow_term_line

    short = flow_term_line(4.0, 0.86)
    assert "the 4 s fitting window is shorter than two blocks of three mean residence" in short
    # the length that gives the flow's term is named (2 x 3 x 0.86 s), and sample-length's
    # answer, which can be shorter, is not offered as that length
    assert "residence times, 5.16 s here" in short and "fit on a window of 5.16 s or more" \
        in short and "which can be shorter" in short
    assert "tells how long a window must be" in flow_term_line(4.0)   # E(RT) unknown
    # a pooled fit compares the blocks of all its runs: a block of each window will do (a
    # review was told to pool the runs it had pooled, and a length twice the one needed)
    pooled = flow_term_line(4.0, 2.387, runs=3)
    assert ("fewer than two of the 3 runs' fitting windows (the shortest 4 s) hold a block "
            "of three mean residence times, 7.17 s here") in pooled
    assert "fit on windows of 7.17 s or more" in pooled and "pool several" not in pooled
    assert "these windows' sampling alone" in pooled
    sparse = flow_term_line(30.0, 2.4)
    assert "fewer than two blocks of the 30 s fitting window hold two residences seen whole" \
        in sparse and "shorter than" not in sparse and "pool more runs or tracks" in sparse


def test_a_wide_interval_says_what_limit_the_parts_are_held_to(tmp_path):
    """An E(RT) interval three times E(RT) wide is warned of, and the warning says the
    checks of the window's parts still hold them to at most MAX_PARTS_LIMIT (it said no
    check could pass or fail, and then the halves' check warned at 25 %)."""
    from cfbmarkov.analysis.adequacy import MAX_PARTS_LIMIT

    run = synthetic.write_run(tmp_path / "wide.h5", synthetic.RiserFlow(), 300, 6.0, seed=2)
    model = fit_model(run, CellGrid(6, 38), 0.025, (1.0, 5.0), "paper")
    mean = model.rtd().mean
    verdict = assess_adequacy(model, [run], [(1.0, 5.0)], interval=(0.5 * mean, 3.5 * mean))
    wide = [line for line in verdict.warnings if "cannot pin the chain down" in line]
    assert len(wide) == 1
    assert f"hold them to at most {100 * MAX_PARTS_LIMIT:g} %" in wide[0]
    assert "no check of its parts can pass or fail" not in wide[0]


def test_a_python_fitted_model_judged_on_other_data_or_another_window_is_refused(tmp_path):
    """assess_fit on a model fitted in Python (it records no identity of its data): runs
    whose transitions are not its counts, or a window that is not its fitting window, are
    refused in one line, not judged (its verdict and fields were another file's); its own
    run and window, given or not, give the same model as leaving them out."""
    from cfbmarkov.analysis.fit_checks import assess_fit
    from cfbmarkov.markov import PaperEstimator

    grid = CellGrid(4, 16)
    run = synthetic.write_run(tmp_path / "run.h5", FAST, 300, 6.0, seed=1)
    other = synthetic.write_run(tmp_path / "other.h5", SLOW, 300, 6.0, seed=2)
    model = PaperEstimator(grid, FAST.lag).fit(discretize(run, grid, FAST.lag, (1.0, 5.0)))
    with pytest.raises(InputError, match=r"other.h5: not the data the model was fitted on "
                                         r"\(the windows' transitions are not the model's "
                                         r"counts\)"):
        assess_fit(model, runs=[other], resamples=0)
    with pytest.raises(InputError, match=r"window 0.5-4.5 s: not the model's fitting window "
                                         r"1-5 s; give the window it was fitted on"):
        assess_fit(model, windows=[(0.5, 4.5)], resamples=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        judged = assess_fit(model, resamples=20)
        again = assess_fit(model, runs=[run], windows=[(1.0, 5.0)], resamples=20)
        # a model that records its data's identity: another window is refused as well
        with pytest.raises(InputError, match=r"window 0.5-4.5 s: not the model's fitting"):
            assess_fit(judged, windows=[(0.5, 4.5)], resamples=0)
    assert judged.uncertainty.rt_mean_interval == again.uncertainty.rt_mean_interval
    assert judged.adequacy == again.adequacy


def test_the_chain_on_its_fitting_window_tells_a_memoryless_fit_from_a_missed_memory(
        tmp_path, capsys):
    """`on its fitting window`: a chain on the cells of a flow that is a chain on those
    cells carries its window's RTD; on a flow whose particles keep a hidden direction it
    makes the residences too alike (SD(RT) far too narrow), which the verdict of the
    sample does not judge. Stored in the verdict and printed by fit; the miss beyond 25 %
    is a warning of the model's (fit, rtd --json), not of the sample's verdict."""
    memoryless = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.6,
                                     fall_velocity=-0.6, vertical_spread=0.5,
                                     persistence=False)
    hidden = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.6, fall_velocity=-0.6,
                                 vertical_spread=0.5, persistence=True)
    pds, warned = {}, {}
    for name, flow in (("memoryless", memoryless), ("hidden", hidden)):
        run = synthetic.write_run(tmp_path / f"{name}.h5", flow, 1500, 8.0, seed=4)
        out = tmp_path / f"{name}-m.h5"
        assert main(["fit", str(run), "--cells", "4x16", "--window", "1:7", "--estimator",
                     "mle", "--resamples", "0", "-o", str(out)]) == 0
        printed, err = capsys.readouterr()
        warned[name] = [line for line in err.splitlines()
                        if line.startswith("warning: the chain does not carry its own")]
        assert main(["rtd", str(out), "--json"]) == 0
        listed = json.loads(capsys.readouterr().out)["warnings"]
        assert bool(warned[name]) == any("does not carry its own" in w for w in listed)
        verdict = MarkovModel.load(out).adequacy
        length, mean, sd, seen_mean, seen_sd, count = verdict.on_window
        assert length == pytest.approx(6.0) and count >= 30
        assert f"    {verdict.on_window_line()}\n" in printed
        assert Adequacy.from_attr(verdict.to_attr()).on_window == verdict.on_window
        pds[name] = (100 * (mean / seen_mean - 1), 100 * (sd / seen_sd - 1))
    # measured: memoryless +0.4 %, +1.0 %; hidden direction +8.1 %, -48.9 %
    assert abs(pds["memoryless"][0]) < 10 and abs(pds["memoryless"][1]) < 15, pds
    assert pds["hidden"][1] < -20, pds
    assert not warned["memoryless"]
    line = warned["hidden"][0] if pds["hidden"][1] < -25 else None
    if line is not None:
        assert "its SD(RT)" in line and "below the window's" in line and "limit 25 %" in line
        assert "`fit --states auto`" in line
    # react's answers rest on the chain's RTD: its --json warnings carry the line too
    (tmp_path / "k.toml").write_text('[[property]]\nname = "X"\nlaw = "first-order"\n'
                                     'rate = 1.0\n')
    assert main(["react", str(tmp_path / "hidden-m.h5"), "--kinetics",
                 str(tmp_path / "k.toml"), "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)["warnings"]
    assert any(w.startswith("the model: the chain does not carry its own") for w in listed)
    # the verdict's own lines and its judgement are the sample's: unchanged by the miss
    hidden_model = MarkovModel.load(tmp_path / "hidden-m.h5")
    assert not any("does not carry its own" in w for w in hidden_model.adequacy.warnings)
    # info's summary, where the model's lines stand inline, counts them beside a verdict
    # of "no warning" (a new user read "no warning" on a model 47 % too narrow)
    assert hidden_model.adequacy.adequate
    assert main(["info", str(tmp_path / "hidden-m.h5")]) == 0
    assert "warning about the model (the lines above)" in capsys.readouterr().out


def test_the_chains_miss_of_its_window_is_warned_beyond_the_limit():
    """Adequacy.on_window_warning: within 25 % nothing; beyond it, each figure that misses
    with its side and percentage; no line without the figures."""
    within = Adequacy(on_window=(5.0, 0.80, 0.50, 0.741, 0.532, 9920))
    assert within.on_window_warning() is None
    both = Adequacy(on_window=(5.0, 1.00, 0.281, 0.741, 0.532, 9920))
    line = both.on_window_warning()
    assert "its E(RT) 1 s lies 35 % above the window's 0.741 s" in line
    assert "its SD(RT) 0.281 s lies 47 % below the window's 0.532 s" in line
    assert "(its 9920 residences held whole; limit 25 %)" in line
    assert both.on_window_warning(limit=0.5) is None
    assert Adequacy().on_window_warning() is None and both.adequate
    # the advice: a state space the user named is sent to `fit --states auto`; one that
    # `--states auto` chose is not sent there again (a review followed the advice from a
    # coarse grid, got the same line back from the chosen model, and found finer cells
    # were what carried the window)
    from cfbmarkov.markov.model_summary import on_window_warning

    p = np.full((2, 2), 0.5)
    zeros = np.zeros((2, 2), np.int64)
    named = MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 2, 0.1, 1.0), 0.025,
                        adequacy=both)
    assert on_window_warning(named).endswith(
        "a state space with memory may carry it (`fit --states auto` compares them on this "
        "window)")
    chosen = named.with_selection({"chosen": {"states": "cells", "lag": 0.025}})
    advice = on_window_warning(chosen)
    assert "--states auto` compares" not in advice
    assert advice.endswith("finer --cells (more columns keep a downflowing wall layer apart "
                           "from the rising core) or more flow (a longer window, several "
                           "runs pooled) may carry it")
    assert on_window_warning(chosen.with_adequacy(within)) is None


def test_sample_length_of_runs_sharing_no_span_names_them_and_the_fix(tmp_path):
    """Runs of one flow written under two time origins (0-3 s and 100-103 s) share no
    window: the refusal named a start of 100 s "outside 100 to 3 s", which no start can
    meet; it now names the runs' spans and the two ways on."""
    a = synthetic.write_run(tmp_path / "a.h5", FAST, 200, 3.0, seed=1)
    b = synthetic.write_run(tmp_path / "b.h5", FAST, 200, 3.0, seed=2, start_time=100.0)
    with pytest.raises(InputError, match=r"the runs share no span of time \(.*a.h5 0-3 s, "
                       r".*b.h5 100-103 s\): --sample-length takes the same windows of every "
                       r"run; .*window per run"):
        sample_length([a, b], _space(), lag=0.025)


def test_parts_too_short_to_judge_by_residences_still_name_a_flow_that_changed(tmp_path):
    """A window across a fourfold change of the flow whose slow half holds no whole
    residence: the halves are too short to judge by their residences, but their chains
    (from thousands of transitions) differ far beyond the 25 % the parts are held to at
    most, and the line says the flow may have changed; the verdict keeps that spread."""
    flows = [synthetic.RiserFlow(columns=4, rows=16, rise_velocity=v, fall_velocity=-0.6,
                                 vertical_spread=0.5, persistence=False) for v in (2.4, 1.0)]
    times = 0.025 * np.arange(int(round(12 / 0.025)) + 1)
    run = synthetic.write_regime_run(tmp_path / "sw.h5", flows, [[0.99, 0.01], [0.01, 0.99]],
                                     300, 12.0, seed=9, regimes=(times >= 6.0).astype(int))
    model = fit_model(run, CellGrid(4, 16), 0.025, (5.0, 7.0), "mle")
    verdict = assess_adequacy(model, [run], [(5.0, 7.0)])
    line = next(x for x in verdict.warnings if x.startswith("a half of the fitting window"))
    assert ("beyond twice the 25 % the parts are held to at most: the flow may have "
            "changed") in line
    means = [m for _, _, m, _ in verdict.parts]
    assert max(means) > 2.5 * min(means)
    assert verdict.spread == pytest.approx((max(means) - min(means)) / verdict.rt_mean)


def test_the_pass_potential_takes_the_gap_between_the_window_and_its_chain_exactly(tmp_path):
    """For the maximum-likelihood chain fitted on a window, the window's net passes minus
    the chain's expected ones over the window's frame pairs are exactly the pass potential
    summed over the particles' first states minus their last (n (I - P) = starts - ends),
    the identity the throughput limit's spread rests on; a core rising beside falling walls
    spreads the potential beyond the uniform climb's 1/12."""
    from cfbmarkov.analysis.adequacy import (UNIFORM_POTENTIAL_VARIANCE,
                                             pass_potential_variance)
    from cfbmarkov.analysis.bootstrap import fitting_windows
    from cfbmarkov.markov.counting import count_transitions

    flow = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.5, fall_velocity=-1.2,
                               lateral_probability=0.03, vertical_spread=0.5,
                               persistence=False)
    run = synthetic.write_run(tmp_path / "c.h5", flow, 200, 3.0, seed=3)
    model = fit_model(run, CellGrid(4, 16), 0.025, (0.5, 2.5), "mle")
    (window,) = fitting_windows(model)
    counts = count_transitions(window)
    p = np.asarray(model.transition_matrix.toarray() if hasattr(model.transition_matrix,
                                                                "toarray")
                   else model.transition_matrix)
    net = np.asarray(model.up_fraction) - np.asarray(model.down_fraction)
    reward = (p * net).sum(axis=1)
    occupancy = np.asarray(counts.counts.sum(axis=1)).ravel()
    observed = float(np.sum(np.asarray(counts.counts_up) - np.asarray(counts.counts_down)))
    assert observed == pytest.approx(float(occupancy @ reward), rel=1e-9)
    pi = np.asarray(model.stationary_distribution)
    phi = float(pi @ reward)
    a = np.eye(p.shape[0]) - p
    g = np.zeros(p.shape[0])
    g[1:] = np.linalg.solve(a[1:, 1:], (reward - phi)[1:])
    starts, ends = window.states[0], window.states[-1]
    assert occupancy @ (reward - phi) == pytest.approx(float(g[starts].sum() - g[ends].sum()),
                                                       abs=1e-6)
    assert pass_potential_variance(model) == pytest.approx(
        float(pi @ (g - pi @ g) ** 2), rel=1e-9)
    assert pass_potential_variance(model) > 1.3 * UNIFORM_POTENTIAL_VARIANCE


def test_a_particle_stuck_in_a_cell_of_its_own_leaves_the_pass_potential_of_the_flow(
        tmp_path):
    """One particle held in a cell no other visits is a closed class of one state, with
    long-run probability and no passes: the potential is solved on the flow's one closed
    class, as without it (no singular solve, no numpy warning, no fallback to 1/12)."""
    import warnings

    from cfbmarkov.analysis.adequacy import pass_potential_variance
    from cfbmarkov.trajectory_writer import TrajectoryWriter

    flow = synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)
    times, _, positions, laps = synthetic.sample_run(flow, 30, 101, seed=4)
    cw, ch = flow.width / 12, flow.height / 48
    cells = (np.clip((positions[..., 1] / ch).astype(int), 0, 47) * 12
             + np.clip((positions[..., 0] / cw).astype(int), 0, 11))
    free = np.setdiff1d(np.arange(576), cells)
    c = int(free[free.size // 2])
    positions[:, 0] = ((c % 12 + 0.5) * cw, (c // 12 + 0.5) * ch)
    laps[:, 0] = 0
    with TrajectoryWriter(tmp_path / "stuck.h5", np.arange(30), width=flow.width,
                          height=flow.height, source="test", frame_interval=flow.lag) as w:
        w.append_frames(times, positions, laps=laps)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = fit_model(tmp_path / "stuck.h5", CellGrid(12, 48), flow.lag, (0.0, 2.5), "mle")
        variance = pass_potential_variance(model)
    assert np.isfinite(variance) and 0.02 < variance < 0.3


def test_presence_runs_are_counted_block_by_block_as_whole():
    """The runs of presence a window's cut counts: read a few frames at a time, the same
    as over the whole mask (a run across a block's edge counted once)."""
    from types import SimpleNamespace

    from cfbmarkov.analysis.adequacy import _presence_runs

    rng = np.random.default_rng(2)
    mask = rng.random((53, 7)) < 0.7
    traj = SimpleNamespace(present=lambda frames: mask[frames])
    whole = int(mask[5].sum() + (mask[6:50] & ~mask[5:49]).sum())
    for block in (1, 3, 8, 256):
        assert _presence_runs(traj, slice(5, 50), block) == whole
