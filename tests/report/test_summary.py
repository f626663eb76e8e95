"""The report's opening: the verdict and physics checks written from the numbers, each
warning once, one interval stated once, matrices as heat maps labelled by their states."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from cfbmarkov.report.document import render_html, render_markdown
from cfbmarkov.report.sections import warning_blocks
from cfbmarkov.report.summary import conditions_blocks, physics_checks, summary_blocks

from cfbmarkov.config import CaseConfig


def case_config(u: float) -> CaseConfig:
    return CaseConfig.model_validate({
        "name": f"u{u:g}", "riser": {"width": 0.04, "height": 0.30},
        "particles": {"number": 3789}, "gas": {"superficial_velocity": u},
        "markov": {"columns": 4, "rows": 12, "lag": 0.01, "fit_window": [2.5, 3.5],
                   "predict_window": [3.5, 4.5]}})

#: solids fraction across the riser (12 bins): dense wall layers, a dilute core
ANNULUS = np.r_[[0.3, 0.3], np.full(8, 0.1), [0.3, 0.3]]
VELOCITY = np.r_[[-0.5, -0.5], np.full(8, 2.0), [-0.5, -0.5]]


def fake_run(means: dict[float, float], fraction=ANNULUS, velocity=VELOCITY,
             summary: dict | None = None, flux: dict[float, float] | None = None):
    """Finished cases at the velocities of ``means`` (CFD-DEM E(RT) in s, of the residences
    held whole and, unless ``flux`` gives others, from the net solids flux) with one
    'paper' comparison each, and their measures."""
    cases, measures = [], {}
    for u, mean in means.items():
        s = summary or {"pd_rt_mean": 50.0, "pd_rt_sd": -20.0, "md_rtd": 0.3,
                        "baseline": {"md_rtd": 0.1}, "natural_variability": {"md_rtd": 0.05},
                        "model_on_fitting_window": {"md_rtd": 0.25},
                        "reference": {"rt_mean": mean},
                        "model": {"rt_mean_interval": [mean * 1.3, mean * 1.6]}, "level": 0.9}
        estimator = SimpleNamespace(name="paper", summary=s)
        case = SimpleNamespace(name=f"u{u:g}", velocity=u, label=f"U = {u:g} m/s",
                               config=case_config(u), finished=[estimator],
                               estimators=[estimator], problems=[], complete=True)
        cases.append(case)
        measures[case.name] = SimpleNamespace(
            reference=SimpleNamespace(rt=SimpleNamespace(mean=mean)),
            flux_rt_mean=mean if flux is None else flux[u],
            solids_fraction=np.asarray(fraction, dtype=float),
            solids_velocity=np.asarray(velocity, dtype=float))
    return cases, measures


def summary_text(cases, measures, meta=None) -> str:
    checks = physics_checks(cases, measures)
    blocks = (summary_blocks(meta or {"scale": "quick"}, cases, cases, measures, ["paper"],
                             checks) + conditions_blocks(cases, measures, checks))
    return render_markdown("report", blocks)


def test_e_rt_falling_with_u_passes_and_rising_fails():
    cases, measures = fake_run({3.0: 0.8, 4.0: 0.6, 6.0: 0.4, 8.0: 0.3})
    fall, annulus = physics_checks(cases, measures)
    assert fall.passed is True and annulus.passed is True
    md = summary_text(cases, measures)
    assert "E(RT) of the CFD-DEM falls as U rises: PASSED" in md
    assert "core-annulus structure (wall layers denser than the core): PASSED" in md
    # E(RT) rises from 4 to 6 m/s: the check fails, names where, and the summary says so
    cases, measures = fake_run({3.0: 0.8, 4.0: 0.5, 6.0: 0.7, 8.0: 0.3})
    fall, _ = physics_checks(cases, measures)
    assert fall.passed is False and "4 -> 6 m/s (0.500 -> 0.700 s)" in fall.evidence
    md = summary_text(cases, measures)
    summary = md.split("## Operating conditions", 1)[0]
    assert "E(RT) of the CFD-DEM falls as U rises: FAILED" in summary
    assert "What the quick scale cannot show" in summary
    assert ("which the paper's riser passes; this run's CFD-DEM fails it ([the numbers]"
            "(#operating-conditions-and-physics-checks))") in summary
    # the evidence once, in the physics checks, not in the summary
    assert "0.800 s at 3 m/s" not in summary and md.count("0.800 s at 3 m/s") == 1
    # cases with other windows and lags: said, the windows themselves left to the table
    cases, measures = fake_run({3.0: 0.8, 6.0: 0.4})
    config = cases[1].config
    cases[1].config = config.model_copy(update={"markov": config.markov.model_copy(
        update={"predict_window": (2.0, 3.0), "lag": 0.002})})
    summary = summary_text(cases, measures).split("## Operating conditions", 1)[0]
    assert ("the cases differ in more than U (their predict windows and lags, [operating "
            "conditions](#operating-conditions-and-physics-checks))") in summary
    assert "2-3" not in summary
    # one case: not judged
    cases, measures = fake_run({6.0: 0.4})
    assert physics_checks(cases, measures)[0].passed is None
    # judged on the flux's E(RT): the residences held whole in a short window leave out
    # the long ones (the demo's 0.200 s at 3 m/s against 0.301 s at 4 m/s read FAILED,
    # while the flux's 0.401 and 0.354 s fall)
    cases, measures = fake_run({3.0: 0.200, 4.0: 0.301, 6.0: 0.12, 8.0: 0.06},
                               flux={3.0: 0.401, 4.0: 0.354, 6.0: 0.0965, 8.0: 0.0549})
    fall, _ = physics_checks(cases, measures)
    assert fall.passed is True and "0.401 s at 3 m/s, 0.354 s at 4 m/s" in fall.evidence
    assert fall.evidence.startswith("E(RT) from the net solids flux over each predict window")


def test_a_dense_core_fails_the_core_annulus_check():
    core = np.r_[[0.1, 0.1], np.full(8, 0.3), [0.1, 0.1]]
    cases, measures = fake_run({3.0: 0.8, 6.0: 0.4}, fraction=core)
    _, annulus = physics_checks(cases, measures)
    assert annulus.passed is False
    assert "the core is as dense or denser at 3 m/s, 6 m/s" in annulus.evidence
    assert "wall/core 0.1/0.3" in annulus.evidence
    md = summary_text(cases, measures)
    assert "core-annulus structure (wall layers denser than the core): FAILED" in md


def test_the_verdict_is_written_from_the_numbers():
    cases, measures = fake_run({3.0: 0.8, 6.0: 0.4})
    md = summary_text(cases, measures)
    summary = md.split("## Operating conditions", 1)[0]
    assert "doi:10.3390/pr13030614" in summary and "at the quick scale" in summary
    assert "misses the CFD-DEM's mean residence time E(RT) by +50 % at 3 m/s, +50 % at 6 m/s" \
        in summary
    assert "(the paper: +0.54 to +11.89 %)" in summary
    assert "the models' own error" not in summary
    assert ("At 3 m/s, against the baseline's 0.1: paper 0.3 worse: the model's own error "
            "(0.25 already on its fitting window).") in summary
    assert summary.count("against the baseline's 0.1") == 2      # once per velocity
    # the count once, in the verdict line; the details name the pairs
    assert summary.count("Verdict at the quick scale: reusing the fitting window's RTD (the "
                         "persistence baseline) predicts better than the models in both") == 1
    assert summary.count("velocity-model pairs") == 2        # the verdict line and the interval
    assert "is beaten, by the rule of Table 3" in summary and "by none of the models" in summary
    assert "inside the model's 90 % interval in 0 of 2" in summary
    # a model that beats the baseline is named
    good = {"pd_rt_mean": 2.0, "pd_rt_sd": -40.0, "md_rtd": 0.05, "baseline": {"md_rtd": 0.1},
            "natural_variability": {"md_rtd": 0.01}, "reference": {"rt_mean": 0.5},
            "model": {"rt_mean_interval": [0.4, 0.6]}}
    cases, measures = fake_run({3.0: 0.8}, summary=good)
    summary = summary_text(cases, measures).split("## Operating conditions", 1)[0]
    assert "the models beat the persistence baseline in the one velocity-model pair" in summary
    assert "by paper at 3 m/s." in summary and "Not beating it" not in summary
    assert "(within its largest miss, 11.89 %) in its one case" in summary
    # the verdict leads: the first paragraph after the heading
    first = summary.split("## Summary", 1)[1].strip().splitlines()[0]
    assert first.startswith("Verdict at the quick scale: the models beat the persistence")
    assert "the paper's estimator is as close" in first
    assert ("physics checks of the CFD-DEM ([evidence](#operating-conditions-and-physics-"
            "checks)): E(RT) of the CFD-DEM falls as U rises: NOT JUDGED") in first
    assert first.endswith("Next step: use the models over windows like these, with their "
                          "intervals.")
    # the link to the evidence goes to a heading of the page
    checks = physics_checks(cases, measures)
    html = render_html("r", summary_blocks({"scale": "quick"}, cases, cases, measures,
                                           ["paper"], checks)
                       + conditions_blocks(cases, measures, checks), None)
    assert '<a href="#operating-conditions-and-physics-checks">' in html
    assert '<p class="verdict">Verdict at the quick scale:' in html
    assert 'id="operating-conditions-and-physics-checks"' in html


def test_operating_conditions_from_the_profiles():
    cases, measures = fake_run({6.0: 0.4})
    md = summary_text(cases, measures)
    section = md.split("## Operating conditions and physics checks", 1)[1]
    row = [line for line in section.splitlines() if line.startswith("| 6 |")][0]
    cells = [c.strip() for c in row.strip("|").split("|")]
    config = cases[0].config
    p = config.particles
    hold_up = p.number * math.pi * p.diameter ** 3 / 6 / (config.riser.width
                                                          * config.riser.height * p.diameter)
    assert cells[3] == f"{100 * hold_up:.3g} / {100 * ANNULUS.mean():.3g}"
    flux = p.density * np.mean(ANNULUS * VELOCITY)
    assert cells[4] == f"{flux:+.3g}"
    # the DEM step's advisory: once, as a property of the run's settings
    assert section.count("resolves a contact in") == 1


def test_a_warning_given_by_several_comparisons_is_listed_once():
    def case(name, warnings):
        return SimpleNamespace(name=name, finished=[
            SimpleNamespace(name=e, summary={"warnings": warnings}) for e in ("paper", "mle")])

    same = "the intervals leave out the flow's variability between windows"
    cases = [case("u3", [same, "only at u3"]), case("u6", [same])]
    md = render_markdown("r", warning_blocks(cases, ["a note", "a note"]))
    assert md.count(same) == 1
    assert f"{same} (every comparison)" in md
    assert "only at u3 (u3 / paper, u3 / mle)" in md
    assert md.count("a note") == 1


def test_one_interval_is_stated_once():
    from cfbmarkov.report.table3 import trust_text

    summary = {"md_rtd": 0.3, "level": 0.9, "reference": {"rt_mean": 0.4},
               "model": {"rt_mean_interval": [0.276, 0.349],
                         "model_rt_mean_interval": [0.2761, 0.3488]}}
    text = trust_text("6", "paper", summary)
    # Table 3 holds the value and its interval, its detail the model's own interval
    assert "0.276" not in text and "0.349" not in text and "own value" not in text
    assert "lies outside the model's 90 % interval (Table 3)" in text


def test_a_reference_within_its_own_sampling_is_not_told_apart_in_the_report():
    """Where the model's intervals leave the flow's term out, a reference figure outside
    them whose own interval overlaps them is "not told apart" in the report as `compare`
    says, not "outside"; with the flow's term (or no overlap) it stays outside."""
    from cfbmarkov.report.summary import _interval_sentence
    from cfbmarkov.report.table3 import reference_place, trust_text

    own = {"md_rtd": 0.3, "level": 0.9,
           "intervals": {"method": "block bootstrap of the fitting window, Monte Carlo "
                                   "noise, in quadrature"},
           "reference": {"rt_mean": 0.36, "rt_mean_interval": [0.34, 0.38],
                         "rt_sd": 0.2, "rt_sd_interval": [0.13, 0.27]},
           "model": {"rt_mean_interval": [0.276, 0.349], "rt_sd_interval": [0.1, 0.14]}}
    assert reference_place(own) == "not told apart" and reference_place(own, "rt_sd") == \
        "not told apart"
    assert "not told apart" in trust_text("6", "paper", own)
    flow = dict(own, intervals={"method": "block bootstrap of the fitting window, Monte "
                                          "Carlo noise and the flow's variability between "
                                          "windows, in quadrature"})
    assert reference_place(flow) == "outside"
    far = dict(own, reference=dict(own["reference"], rt_mean_interval=[0.355, 0.365]))
    assert reference_place(far) == "outside"
    def sentence(summary):
        return _interval_sentence([SimpleNamespace(
            name="u6", velocity=6.0, problems=[],
            finished=[SimpleNamespace(name="paper", summary=summary)])])

    text = sentence(own)
    assert "inside the model's 90 % interval in 0 of 1" in text
    assert "In 1 more (paper at 6 m/s) its E(RT) lies outside, but within its own" in text
    assert "too narrow" not in text
    # SD(RT) intervals that miss in most pairs are remarked on too (E(RT)'s hold here)
    wide_mean = dict(own, model=dict(own["model"], rt_mean_interval=[0.3, 0.4]),
                     reference=dict(own["reference"], rt_sd_interval=[0.19, 0.21]))
    text = sentence(wide_mean)
    assert "inside the model's 90 % interval in 1 of 1" in text
    assert " SD(RT) intervals that miss it this often are too narrow" in text
    assert "E(RT) and SD(RT) intervals" not in text


def test_matrix_heat_map_labelled_by_its_state_space(tmp_path):
    from cfbmarkov.report.figures import plot_transition_matrix, row_ticks

    # 48 cells x 7 velocity bins, ordered by cell: 336 states, rows ticked where they start
    rows_of_state = np.repeat(np.arange(12), 4 * 7)
    ticks, labels = row_ticks(rows_of_state, 12)
    assert labels[0] == "0" and ticks[1] == 2 * 28 - 0.5
    assert row_ticks(rows_of_state[::-1], 12) is None          # not ordered by row: no ticks
    P = np.eye(336)
    path = plot_transition_matrix(P, 4, 12, tmp_path / "tm.png",
                                  states="velocity 4x12x7 (336 states)",
                                  row_of_state=rows_of_state)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_long_state_space_description_leaves_the_matrix_title_whole(tmp_path, monkeypatch):
    """The title of a transition-matrix figure lies inside the figure, however long the state
    space's description (a cells-previous space's was cut at the left edge)."""
    import numpy as np

    from cfbmarkov.report import figures

    drawn = {}

    def keep(fig, path):
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        drawn["fig"], drawn["renderer"] = fig, canvas.get_renderer()
        return path

    monkeypatch.setattr(figures, "_save", keep)
    p = np.full((60, 60), 1 / 60)
    figures.plot_transition_matrix(p, 6, 10, tmp_path / "m.png",
                                   states="cells-previous 6x38x7 (1596 states; the previous "
                                          "cell up to 3 rows and 1 column away, kept apart)")
    fig = drawn["fig"]
    renderer = drawn["renderer"]
    title = fig.axes[0].title.get_window_extent(renderer)
    width = fig.bbox.width
    assert title.x0 >= 0 and title.x1 <= width, (title.x0, title.x1, width)


def test_the_command_that_makes_the_run_again():
    from types import SimpleNamespace

    from cfbmarkov.report.sections import command_text

    cases = [SimpleNamespace(velocity=3.0), SimpleNamespace(velocity=6.5)]
    meta = {"scale": "paper", "models": ["paper", "mle"], "ensemble": 3, "device": "gpu",
            "kinetics": {"file": "/a b/kin.toml", "digest": "sha256:x"},
            "overrides": {"output": {"end_time": 30}}}
    assert command_text(meta, cases, "/runs/out") == (
        "cfbmarkov reproduce --scale paper --velocities 3,6.5 --models paper,mle --kinetics "
        "'/a b/kin.toml' --ensemble 3 --device gpu --overrides OVERRIDES.toml -o out "
        '(OVERRIDES.toml holding {"output": {"end_time": 30}})')
    assert command_text({"scale": "quick", "models": ["auto"], "device": "cpu"},
                        cases[:1], "r") == (
        "cfbmarkov reproduce --scale quick --velocities 3 --models auto -o r")


def test_snapshot_caption_ends_at_the_last_snapshot_in_the_window(tmp_path):
    """compare draws snapshots at the window start + 0, 0.1, ... 0.7 s inside its window:
    a 0.2 s predict window gives three, and the caption's times and mixing figures end at
    the last of them, not 0.7 s after the start."""
    from cfbmarkov.report.document import FigureBlock
    from cfbmarkov.report.figure_sections import PNG_SIGNATURE, snapshot_blocks

    compare_dir = tmp_path / "compare-paper"
    compare_dir.mkdir()
    (compare_dir / "snapshots.png").write_bytes(PNG_SIGNATURE + b"rest")
    cases, measures = fake_run({5.0: 0.2})
    cases[0].finished[0].compare_dir = compare_dir
    times = np.array([0.4, 0.5, 0.6])

    def side(shares):
        return SimpleNamespace(mix_t=times, mix_f=np.asarray(shares))

    measures["u5"].window = (0.4, 0.6)
    measures["u5"].reference = side([0.51, 0.40, 0.33])
    measures["u5"].models = {"paper": side([0.51, 0.45, 0.30])}
    blocks = snapshot_blocks(cases, measures, tmp_path, [])
    caption = next(b for b in blocks if isinstance(b, FigureBlock)).sentence
    assert "from 0.4 to 0.6 s" in caption and "by 0.6 s" in caption
    assert "0.510 to 0.330 (CFD-DEM) and 0.300 (MCM)" in caption and "n/a" not in caption
    # a window of 1 s: the last snapshot is 0.7 s after its start
    measures["u5"].window = (0.4, 1.4)
    caption = next(b for b in snapshot_blocks(cases, measures, tmp_path, [])
                   if isinstance(b, FigureBlock)).sentence
    assert "from 0.4 to 1.1 s" in caption
