"""One rule for "beats the persistence baseline", the same in Table 3, the summary and the
trust paragraphs; a verdict line on top; intervals that never collapse; windows, lags and the
flow's development said from the case data."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from cfbmarkov.analysis.baseline import judge_baseline
from cfbmarkov.analysis.development import development, mean_vertical_velocity
from cfbmarkov.report.document import interval_text, render_markdown
from cfbmarkov.report.summary import physics_checks, summary_blocks, windows_text
from cfbmarkov.report.table3 import (OUTCOME_WORDS, _baseline_cell, table3_blocks,
                                     trust_text)
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import TrajectoryWriter

from .test_summary import fake_run


def test_the_rule_on_the_trials_numbers():
    # 3 m/s mle: 0.3 % below the baseline, the halves 0.202 apart: a tie, not a win
    assert judge_baseline(0.2294, 0.2302, 0.202).outcome == "tie"
    # 6 m/s auto: 0.08439 against 0.08432: a tie
    assert judge_baseline(0.08439, 0.08432, 0.0341).outcome == "tie"
    # 3 m/s auto: 0.064 below, within the halves' 0.202: cannot be told apart
    assert judge_baseline(0.1665, 0.2301, 0.202).outcome == "not told apart"
    # 4 m/s: the baseline within the halves' variability: no model can be told better
    assert judge_baseline(0.135, 0.124, 0.218).outcome == "not told apart"
    # beyond the margin and the halves, either way
    j = judge_baseline(0.05, 0.10, 0.03)
    assert j.outcome == "beats" and j.beats and j.gap == pytest.approx(0.05)
    assert judge_baseline(0.15, 0.10, 0.03).outcome == "loses"
    # the gap must exceed the halves' MD, not merely reach it
    assert judge_baseline(0.07, 0.10, 0.03).outcome == "not told apart"
    # without the halves the tie margin alone judges
    assert judge_baseline(0.098, 0.10, None).outcome == "beats"
    assert judge_baseline(0.0995, 0.10, math.nan).outcome == "tie"
    with pytest.raises(ValueError, match="md must be a finite distance"):
        judge_baseline(math.nan, 0.1)


def _summary(md, md_base, md_halves, md_own=None):
    s = {"md_rtd": md, "pd_rt_mean": 10.0, "pd_rt_sd": 20.0, "level": 0.9,
         "baseline": {"md_rtd": md_base}, "natural_variability": {"md_rtd": md_halves},
         "reference": {"rt_mean": 0.5, "rt_sd": 0.1},
         "model": {"rt_mean": 0.55, "rt_sd": 0.12, "rt_mean_interval": [0.5, 0.6]}}
    if md_own is not None:
        s["model_on_fitting_window"] = {"windows": [[2, 3], [1, 2]], "md_rtd": md_own,
                                        "pd_rt_mean": 1.0, "pd_rt_sd": 2.0}
    return s


#: (MD, baseline's MD, halves' MD, model on its fitting window), over the outcomes
GRID = [(md, base, halves, own) for md, base, halves, own in itertools.product(
    (0.05, 0.099, 0.1, 0.12, 0.2, 0.3), (0.1,), (0.01, 0.08, 0.25), (0.02, 0.15))]


@pytest.mark.parametrize("md, base, halves, own", GRID)
def test_one_rule_in_the_table_the_summary_and_the_trust_paragraph(md, base, halves, own):
    s = _summary(md, base, halves, own)
    j = judge_baseline(md, base, halves)
    cell = _baseline_cell(s)
    assert cell.startswith(OUTCOME_WORDS[j.outcome])
    trust = trust_text("6", "paper", s)
    assert ("the model beats simply reusing" in trust) == j.beats
    assert ("beats the model" in trust) == (j.outcome == "loses")
    cases, measures = fake_run({6.0: 0.5}, summary=s)
    text = render_markdown("r", summary_blocks({"scale": "quick"}, cases, cases, measures,
                                               ["paper"], physics_checks(cases, measures)))
    # the count in the verdict line, by the same rule, and only there
    first = text.split("## Summary\n\n", 1)[1].split("\n", 1)[0]
    expected = {"beats": "the models beat the persistence baseline in the one velocity-model",
                "loses": "predicts better than the models in the one velocity-model pair",
                "tie": "(0 of 1 velocity-model pairs beat", "not told apart": "(0 of 1 "
                "velocity-model pairs beat"}[j.outcome]
    assert expected in first
    assert text.count("velocity-model pair") == 2    # the verdict line and the interval's
    # never both: the model's own error dominates, and within the reference's variability
    assert not ("own error dominates" in trust
                and "within the reference's own variability" in trust)
    assert not ("own error dominates" in trust and "within the CFD-DEM's own variability" in
                trust.split("fitting window (")[-1])
    if md <= halves:
        assert "dominates" not in trust and "limits this prediction" not in trust


def test_the_table_prints_both_mds_apart_from_the_models():
    # the trial's 3 m/s mle row: "yes (0.23)" beside 0.229 read like a rounding call
    cases, _ = fake_run({3.0: 0.2}, summary=_summary(0.2294, 0.2302, 0.202))
    table = render_markdown("r", table3_blocks(cases, ["paper"]))
    assert "| 0.2294 | tie (within 1 %) (0.2302 / 0.202) |" in table
    assert "by more than 1 % (the tie margin) and by more than the CFD-DEM's own" in table
    # what E(RT) counts is said: a review read the demo's +56 % as a miss of the flow's
    # long run, where the window's residences leave the long ones out
    assert ("of the residences that begin and end inside it (a particle's time from one "
            "pass through the boundary to the next), on both sides alike") in table


def test_intervals_never_collapse():
    """Enough decimals to keep the ends apart, and each end rounded outwards (the lower
    down, the upper up), so that the text holds every value the interval holds."""
    assert interval_text(0.01384, 0.01442) == "0.0138–0.0145"
    assert interval_text(0.2766, 0.3484) == "0.276–0.349"     # to the nearest: 0.277-0.348
    assert interval_text(0.01401, 0.01449) == "0.0140–0.0145"
    assert interval_text(0.276, 0.349) == "0.276–0.349"
    assert interval_text(0.0140001, 0.0140004, sep="-") == "0.0140001-0.0140004"
    assert interval_text(0.014, 0.014) == "0.014–0.014"          # a point is a point
    assert interval_text(None, 0.1) == "n/a"
    s = _summary(0.1, 0.2, 0.01)
    s["model"].update(rt_sd=0.0142, rt_sd_interval=[0.01401, 0.01449],
                      rt_mean_interval=[0.05401, 0.05449])
    s["reference"]["rt_mean"] = 0.054
    cases, _ = fake_run({8.0: 0.054}, summary=s)
    table = render_markdown("r", table3_blocks(cases, ["paper"]))
    assert "0.014 [0.0140–0.0145]" in table
    assert "[0.0540–0.0545]" in table
    # the trust paragraph refers to Table 3's interval, not repeating it
    trust = trust_text("8", "paper", s)
    assert "0.054" not in trust and "interval (Table 3)" in trust


def test_the_summary_opens_with_a_verdict_and_a_next_step():
    cases, measures = fake_run({3.0: 0.5, 6.0: 0.4}, summary=_summary(0.12, 0.1, 0.25))
    text = render_markdown("r", summary_blocks({"scale": "quick"}, cases, cases, measures,
                                               ["paper"], physics_checks(cases, measures)))
    first = text.split("## Summary\n\n", 1)[1].split("\n", 1)[0]
    assert first.startswith("Verdict at the quick scale: no model is shown to predict the "
                            "RTD better than reusing the fitting window's (0 of 2")
    assert "2 are tied with it or within the CFD-DEM's own variability)" in first
    assert "Next step: longer predict windows" in first
    cases, measures = fake_run({3.0: 0.5, 6.0: 0.4}, summary=_summary(0.05, 0.1, 0.01))
    first = render_markdown("r", summary_blocks(
        {"scale": "quick"}, cases, cases, measures, ["paper"],
        physics_checks(cases, measures))).split("## Summary\n\n", 1)[1].split("\n", 1)[0]
    assert "the models beat the persistence baseline in both velocity-model pairs" in first
    assert "Next step: use the models over windows like these" in first


def _run_file(path, velocity):
    """A 2-particle file, frames every 0.1 s over 0-3 s, with the given vertical velocity
    (m/s) per frame time."""
    times = np.round(np.arange(0.0, 3.0001, 0.1), 10)
    with TrajectoryWriter(path, [1, 2], width=0.04, height=0.3, source="synthetic",
                          with_velocity=True, frame_interval=0.1) as out:
        for t in times:
            v = velocity(t)
            out.append(float(t), [[0.01, 0.1], [0.03, 0.2]], [[0.0, v], [0.0, v + 0.2]], [0, 0])


def test_development_from_the_case_data(tmp_path):
    path = tmp_path / "run.h5"
    _run_file(path, lambda t: 1.0 if t < 1.0 else (2.0 if t < 2.0 else 3.0))
    with Trajectories(path) as traj:
        d = development(traj, (1.0, 2.0), (2.0, 3.0))
        assert d["before"] == pytest.approx(1.1, abs=0.1)      # frames 0-1 s, both ends
        assert d["fit"] == pytest.approx(2.1, abs=0.11)
        assert d["predict"] == pytest.approx(3.1, abs=0.11)
        assert mean_vertical_velocity(traj, (2.0, 3.0), max_frames=3) == pytest.approx(3.1)
    cases, measures = fake_run({6.0: 0.1})
    measures["u6"].development = {"before": 1.0, "fit": 2.0, "predict": 3.0}
    text = windows_text(cases, measures)
    assert "+1.00 / +2.00 / +3.00 m/s (33 %)" in text
    assert "still changing when the model was fitted (more than 10 %) at 6 m/s" in text
    measures["u6"].development = {"before": 1.0, "fit": 2.9, "predict": 3.0}
    assert "At every velocity the fitting window's lies within 10 %" in windows_text(cases,
                                                                                      measures)


def test_computing_time_gives_cpu_time_and_the_load():
    from cfbmarkov.report.sections import computing_blocks

    cases, _ = fake_run({8.0: 0.05})
    case = cases[0]
    case.timings = {"cfd_dem": {"wall_s": 400.0, "cpu_s": 75.0, "simulated_s": 3.0,
                                "particles": 3789, "predict_window_wall_s": 60.0},
                    "fit-paper": {"wall_s": 1.0, "cpu_s": 0.4},
                    "predict-paper": {"wall_s": 0.6, "cpu_s": 0.1}}
    md = render_markdown("r", computing_blocks(cases))
    # the predict window's CPU time: the run's pro rata, 75 s x 1 / 3
    assert "| 3 s / 6.67 min / 75 s | 60 s / 25 s |" in md
    assert "| 1 s / 0.4 s | 0.6 s / 0.1 s | 1.6 s / 0.5 s | 50 (37.5) |" in md
    assert "0.19 at 8 m/s; below 1 the process waited for the processor" in md
    assert "takes 50 to 50 times less CPU time than the CFD-DEM" in md
    assert "on wall time 37.5 to 37.5 times" in md
    # without CPU times: the wall times, said to carry the load
    case.timings = {"cfd_dem": {"wall_s": 400.0, "simulated_s": 3.0, "particles": 3789,
                                "predict_window_wall_s": 60.0},
                    "fit-paper": {"wall_s": 1.0}, "predict-paper": {"wall_s": 0.6}}
    md = render_markdown("r", computing_blocks(cases))
    assert "37.5 to 37.5 times faster than the CFD-DEM on wall time (no CPU times" in md
    # a speed-up of a thousand or more in whole numbers, not 1e+03
    case.timings["fit-paper"]["wall_s"], case.timings["predict-paper"]["wall_s"] = 0.03, 0.02
    md = render_markdown("r", computing_blocks(cases))
    assert "is 1200 to 1200 times faster" in md and "e+03" not in md


def test_one_sided_profiles_are_said_as_the_windows_flow():
    from cfbmarkov.report.figure_sections import _one_sided_text

    one_sided = np.r_[[0.13, 0.14], np.full(8, 0.17), [0.23, 0.23]]
    cases, measures = fake_run({3.0: 0.2}, fraction=one_sided)
    text = _one_sided_text(cases, measures)
    assert "solids fraction U = 3 m/s 0.135 at the left wall, 0.23 at the right" in text
    assert "over this window the flow keeps a dense layer along one wall" in text
    cases, measures = fake_run({3.0: 0.2})          # symmetric: nothing to say
    assert _one_sided_text(cases, measures) == ""


def test_narrow_intervals_keep_three_steps_between_their_ends():
    assert interval_text(0.01331, 0.01412) == "0.0133–0.0142"      # rounded outwards
    assert interval_text(0.051, 0.054) == "0.051–0.054"
    # a digit more where the outward rounding widens it by more than a quarter
    assert interval_text(0.05098, 0.05374) == "0.0509–0.0538"


def test_winners_named_without_the_halves_say_so():
    """Where the reference's halves hold no residence, a winner is named by the tie margin
    alone: Table 3's cell, the outcome counts and the verdict's clause say so."""
    from cfbmarkov.report.table3 import (BY_TIE_MARGIN_ALONE, _baseline_cell, baseline_clause,
                                         baseline_outcomes)

    def summary(md, base, halves):
        return {"md_rtd": md, "baseline": {"md_rtd": base, "rt_count": 10},
                "natural_variability": {"md_rtd": halves}}

    alone = summary(0.10676, 0.09676, None)
    assert judge_baseline(0.10676, 0.09676, None).by_tie_margin_alone
    assert not judge_baseline(0.10676, 0.09676, 0.001).by_tie_margin_alone
    assert _baseline_cell(alone) == "baseline better, by the tie margin alone (0.09676 / n/a)"
    counts = baseline_outcomes([alone, alone, summary(0.2, 0.1, 0.01)])
    assert counts["loses"] == 3 and counts[BY_TIE_MARGIN_ALONE] == 2
    clause = baseline_clause(counts)
    assert clause.startswith("reusing the fitting window's RTD (the persistence baseline) "
                             "predicts better than the models in all 3 velocity-model pairs")
    assert clause.endswith("(2 of the 3 with a winner by the 1 % tie margin alone: the "
                           "CFD-DEM's halves hold no residence, so its own variability is not "
                           "known and a gap may be its sampling noise)")
    counts = baseline_outcomes([summary(0.2, 0.1, 0.01)])
    assert "tie margin alone" not in baseline_clause(counts)


def test_the_cluster_clause_does_not_say_how_the_models_particles_move():
    """A low share of the clustering kept is said without claiming the model's particles
    move independently: a coherent model (moves shared by the particles of a cell) can keep
    a third."""
    from cfbmarkov.report.table3 import _cluster_clause

    clause = _cluster_clause(7.61, 3.44)
    assert clause.startswith(": the model keeps 37 % of the CFD-DEM's clustering above 1")
    assert "its particles move independently" not in clause
    assert _cluster_clause(2.0, 2.0) == ": the model keeps 100 % of the CFD-DEM's clustering above 1"
