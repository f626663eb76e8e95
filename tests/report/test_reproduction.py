"""The reproduction report (paper §3): files, self-containment, sections, Table 3 against the
compare summaries, unfinished cases, errors and re-runs."""

from __future__ import annotations

import base64
import collections
import json
import re
import shutil

import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.analysis.reproduction import paper_map_times
from cfbmarkov.report.document import interval_text
from cfbmarkov.report.figure_sections import map_numbers
from cfbmarkov.report.reproduction import write_report
from cfbmarkov.report.run_folder import estimator_names
from cfbmarkov.report.sections import PAPER_TABLE3
from cfbmarkov.analysis.baseline import judge_baseline
from cfbmarkov.report.table3 import COMPACT_HEADER, OUTCOME_WORDS

PNG = b"\x89PNG\r\n\x1a\n"
EXPECTED_FIGURES = {"fig03-transition-matrices.png", "fig04-maps-u3.png", "fig05-maps-u6.png",
                    "fig08-rtd-cfd-dem.png", "fig09-rtd-mcm.png", "fig10-snapshots.png",
                    "fig11-mixing.png", "plausibility.png",
                    # beyond the paper: implied timescales and CK test per finished case
                    "its-u3.png", "its-u6.png", "ck-u3.png", "ck-u6.png"}
HEADINGS = ("Summary", "Operating conditions and physics checks", "Table 3",
            "Table 3 in detail", "Computing time", "Fig. 3", "Fig. 4", "Fig. 8", "Fig. 9", "Fig. 10",
            "Fig. 11", "Plausibility", "Beyond the paper", "Chapman-Kolmogorov errors",
            "Warnings", "Not finished")


def md_headings(md: str) -> list[str]:
    return [line.lstrip("#").strip() for line in md.splitlines() if line.startswith("#")]


def section(md: str, heading: str) -> str:
    """The text of a level-2 section of the report, from its heading to the next."""
    return md.split(f"\n## {heading}", 1)[1].split("\n## ", 1)[0]


def table_row(md: str, u: str, estimator: str, heading: str = "Table 3: RTD") -> list[str]:
    rows = [line for line in section(md, heading).splitlines()
            if line.startswith(f"| {u} | {estimator} |")]
    assert len(rows) == 1, f"expected one Table 3 row for U = {u}, {estimator}"
    return [cell.strip() for cell in rows[0].strip("|").split("|")]


def test_report_files_and_self_contained_html(report_of_template):
    root, html_path = report_of_template
    assert html_path == root / "report.html"
    html = html_path.read_text(encoding="utf-8")
    assert html.startswith("<!DOCTYPE html>") and "<style>" in html
    assert 'src="figures/' not in html
    # every src/href is a data: URI: no file, http or protocol-relative resource
    assert not re.findall(r"""(?:src|href)\s*=\s*["'](?!data:|#)""", html)
    # a link to a heading goes to a heading of this page
    ids = set(re.findall(r'<h[1-3] id="([^"]+)"', html))
    assert set(re.findall(r'href="#([^"]+)"', html)) <= ids
    assert "<link" not in html and "<script" not in html and "url(" not in html
    uris = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(uris) == len(EXPECTED_FIGURES)
    embedded = {base64.b64decode(u) for u in uris}
    on_disk = {(root / "figures" / name).read_bytes() for name in EXPECTED_FIGURES}
    assert embedded == on_disk
    assert not list(root.rglob("*.tmp*")), "temporary files left behind"


def test_sections_and_paper_numbers(report_of_template):
    root, html_path = report_of_template
    md = (root / "report.md").read_text(encoding="utf-8")
    html = html_path.read_text(encoding="utf-8")
    headings = md_headings(md)
    html_headings = re.findall(r"<h[1-3][^>]*>(.*?)</h[1-3]>", html)
    for wanted in HEADINGS:
        assert any(h.startswith(wanted) for h in headings), wanted
        assert any(h.startswith(wanted) for h in html_headings), wanted
    # the fit times are the paper's steps: what fit adds beyond them is said not timed
    assert ("The model's interval (its block bootstrap) and the verdict on its fitting "
            "sample" in " ".join(section(md, "Computing time (paper §3.1)").split()))
    # the paper's Table 3 beside ours, for each U the paper has (U = 3, 6 finished; 8 not)
    for u in ("3", "6", "8"):
        for estimator in ("paper", "mle"):
            row = table_row(md, u, estimator)
            assert row[-1] == " / ".join(PAPER_TABLE3[float(u)]), (u, estimator, row)
            if u != "8":    # the template's intervals leave out the flow's variability: marked
                assert row[3].endswith("]†") and row[6].endswith("]†"), row
    assert "†: the interval leaves out the flow's variability between windows" in md
    assert "4 of the 4 intervals leave out the flow's variability" in section(md, "Summary")
    assert "0.380" in md and "11.89" in html and "-45.16" in html
    assert not [line for line in md.splitlines() if line.startswith("| 4 |")]   # no U = 4
    # the verdict first, its physics checks judged from the run's numbers (E(RT) 0.746 s at
    # 3 m/s, 0.452 s at 6 m/s in the synthetic stand-in)
    assert headings[1] == "Summary"
    assert [h for h in headings if not h.startswith("What the")][2].startswith("Operating")
    assert "E(RT) of the CFD-DEM falls as U rises: PASSED" in section(md, "Summary")
    assert "doi:10.3390/pr13030614" in section(md, "Summary")
    # the paper's computing time (§3.1)
    assert "about 50 h" in md and "about 30 min" in md and "about 100" in md
    assert "(wall estimated)" in md  # u6's CFD-DEM time of the predict window is an estimate
    # header
    for text in ("Scale: quick", "6 columns x 12 rows", "cfbmarkov version: "):
        assert text in md, text
    assert re.search(r"^- Made by: cfbmarkov reproduce --scale quick --velocities 3,6,8 "
                     rf"(--models \S+ )?-o {root.name}$", md, re.MULTILINE)
    # the riser, particles, windows and lag once, in the operating conditions
    conditions = section(md, "Operating conditions and physics checks")
    row = [line for line in conditions.splitlines() if line.startswith("| 3 |")][0]
    for text in ("400 x ", "| 0.09 x 0.95 |", "| 2-4 / 4-6 |", "| 0.025 |"):
        assert text in row, text
    assert "Particles: " not in md and "Lag: " not in md


def test_table3_quotes_the_summaries(report_of_template):
    root, _ = report_of_template
    md = (root / "report.md").read_text(encoding="utf-8")
    for case, u in (("u3", "3"), ("u6", "6")):
        for estimator in ("paper", "mle"):
            s = json.loads((root / case / f"compare-{estimator}" / "summary.json").read_text())
            row = table_row(md, u, estimator)
            lo, hi = s["model"]["rt_mean_interval"]
            # the interval in the cell, beside its value; marked where it leaves out the
            # flow's variability (the method says so)
            mark = "" if "flow's variability" in s["intervals"]["method"] else "†"
            assert row[3] == f"{s['model']['rt_mean']:.3f} [{interval_text(lo, hi)}]{mark}"
            lo, hi = s["model"]["rt_sd_interval"]
            assert row[6] == f"{s['model']['rt_sd']:.3f} [{interval_text(lo, hi)}]{mark}"
            assert row[2] == f"{s['reference']['rt_mean']:.3f}"
            assert row[4] == f"{s['pd_rt_mean']:.2f}"
            assert row[5] == f"{s['reference']['rt_sd']:.3f}"
            assert row[7] == f"{s['pd_rt_sd']:.2f}"
            assert row[8] == f"{s['md_rtd']:.4g}"
            j = judge_baseline(s["md_rtd"], s["baseline"]["md_rtd"],
                               s["natural_variability"]["md_rtd"])
            assert row[9] == (f"{OUTCOME_WORDS[j.outcome]} ({s['baseline']['md_rtd']:.4g} / "
                              f"{s['natural_variability']['md_rtd']:.4g})")
            detail = table_row(md, u, estimator, "Table 3 in detail")
            assert detail[2] == f"{s['mixing_rms']:.3g}"
    assert len(COMPACT_HEADER) == 11          # one row per velocity and model, compact
    # the MD footnote states the order and the bins
    assert "order k = 2" in md and "0.025 s bin" in md and "'%' heading" in md


def test_every_figure_linked_and_valid(report_of_template):
    root, _ = report_of_template
    md = (root / "report.md").read_text(encoding="utf-8")
    linked = re.findall(r"!\[[^\]]+\]\(figures/([^)]+)\)", md)
    assert set(linked) == EXPECTED_FIGURES and len(linked) == len(EXPECTED_FIGURES)
    assert {p.name for p in (root / "figures").iterdir()} == EXPECTED_FIGURES
    for name in linked:
        data = (root / "figures" / name).read_bytes()
        assert data[:8] == PNG and len(data) > 10_000, name
    # Fig. 10 is the snapshot figure of the case nearest 6 m/s
    assert (root / "figures" / "fig10-snapshots.png").read_bytes() == \
        (root / "u6" / "compare-paper" / "snapshots.png").read_bytes()
    # one sentence under every figure, generated from the numbers
    captions = re.findall(r"^\*\*(Fig\. \d+|Plausibility|Implied timescales|Chapman-Kolmogorov)"
                          r"[^*]*\*\* (.+)$", md, flags=re.M)
    assert len(captions) == len(EXPECTED_FIGURES)
    assert all(len(text) > 40 for _, text in captions)
    assert "widest at U = 3 m/s" in md
    assert "falls as U rises" in md
    # the plausibility figure draws the E(RT) the physics check judges beside Table 3's
    assert "dotted, the E(RT) from the window's net solids flux, which the physics check" in md


def test_unfinished_case_is_reported(report_of_template):
    root, _ = report_of_template
    md = (root / "report.md").read_text(encoding="utf-8")
    section = md.split("## Not finished", 1)[1].split("\n## ", 1)[0]
    assert "u8 (U = 8 m/s): not finished" in section
    assert "no compare-paper/summary.json" in section and "no model-mle.h5" in section
    row = table_row(md, "8", "paper")
    assert row[2:10] == ["not finished"] * 8
    assert "u8" not in " ".join(re.findall(r"figures/\S+", md))


def test_no_finished_case_is_an_input_error(reproduction):
    for compare_dir in reproduction.glob("u*/compare-*"):
        shutil.rmtree(compare_dir)
    with pytest.raises(InputError, match="no finished case") as info:
        write_report(reproduction)
    assert "\n" not in str(info.value) and str(reproduction) in str(info.value)
    assert not (reproduction / "report.html").exists()


def test_unusable_inputs_name_the_file(reproduction, tmp_path):
    with pytest.raises(InputError, match="reproduce.json: no such file"):
        write_report(tmp_path)
    with pytest.raises(InputError, match="no such directory"):
        write_report(tmp_path / "absent")
    summary = reproduction / "u3" / "compare-mle" / "summary.json"
    text = summary.read_text()
    summary.write_text(text[: len(text) // 2])
    with pytest.raises(InputError, match=re.escape(str(summary)) + ": not valid JSON"):
        write_report(reproduction)
    summary.write_text(text)
    case = reproduction / "u6" / "case.json"
    case.write_text(case.read_text().replace('"number": 400', '"number": -1'))
    with pytest.raises(InputError, match=re.escape(str(case)) + ".*particles.number") as info:
        write_report(reproduction)
    assert "\n" not in str(info.value)
    assert not (reproduction / "report.html").exists()


def test_rerun_overwrites_cleanly(reproduction):
    first = write_report(reproduction, title="First title")
    md_first = (reproduction / "report.md").read_text(encoding="utf-8")
    assert "<title>First title</title>" in first.read_text(encoding="utf-8")
    # u3 loses its comparisons and timings; a stray figure of an older run lies around
    for compare_dir in (reproduction / "u3").glob("compare-*"):
        shutil.rmtree(compare_dir)
    (reproduction / "u6" / "timings.json").unlink()
    (reproduction / "figures" / "fig07-maps-u9.png").write_bytes(PNG)
    (reproduction / "figures" / "notes.txt").write_text("mine")
    second = write_report(reproduction)
    assert second == first
    html = second.read_text(encoding="utf-8")
    md = (reproduction / "report.md").read_text(encoding="utf-8")
    assert md != md_first and "First title" not in html
    names = {p.name for p in (reproduction / "figures").iterdir()}
    assert "fig04-maps-u3.png" not in names and "fig07-maps-u9.png" not in names
    assert "notes.txt" in names                  # not ours: left alone
    assert "fig05-maps-u6.png" in names
    assert "u3 (U = 3 m/s): not finished" in md
    assert table_row(md, "6", "paper")[1:2] == ["paper"]
    timing_rows = [line for line in md.splitlines() if line.startswith("| 6 | n/a |")]
    assert len(timing_rows) == 2                 # no timings.json: n/a, not a crash
    assert not list(reproduction.rglob(".*.tmp*"))
    linked = re.findall(r"\]\(figures/([^)]+)\)", md)
    assert len(re.findall("data:image/png;base64,", html)) == len(linked)


def test_report_drawn_with_a_process_pool_is_the_same(reproduction, report_of_template):
    """``cfbmarkov reproduce`` hands its idle process pool to the report, which draws two
    groups of sections there: the same markdown, the same figures (names and PNGs), and no
    stray figure left behind."""
    import concurrent.futures as cf
    import multiprocessing

    serial_root, _ = report_of_template
    with cf.ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        write_report(reproduction, executor=pool)
    md = (reproduction / "report.md").read_text(encoding="utf-8")
    assert md == (serial_root / "report.md").read_text(encoding="utf-8")
    names = sorted(p.name for p in (reproduction / "figures").iterdir())
    assert names == sorted(p.name for p in (serial_root / "figures").iterdir())
    assert {"fig10-snapshots.png", "fig11-mixing.png", "plausibility.png"} <= set(names)
    assert any(n.startswith("ck-") for n in names) and any(n.startswith("its-") for n in names)


def test_estimators_discovered_in_order(tmp_path):
    a, b = tmp_path / "u3", tmp_path / "u4"
    a.mkdir()
    b.mkdir()
    for path in (a / "model-auto.h5", a / "model-mle.h5", b / "prediction-paper.h5",
                 b / "notes-x.h5"):
        path.write_bytes(b"")
    (b / "compare-zeta").mkdir()
    (b / "compare-mle.tmp-9ba5c0d3").mkdir()          # a stopped writer's: no estimator
    assert estimator_names([a, b, tmp_path / "absent"]) == ["paper", "mle", "auto", "zeta"]
    (b / "compare-omega.tmp-9ba5c0d3").mkdir()
    assert "omega" not in estimator_names([b])


def test_map_times_and_numbers():
    assert paper_map_times(3.0, 0.025)[1:] == ([0.25, 0.5, 0.75], False)
    wanted, used, rounded = paper_map_times(6.0, 0.04)
    assert wanted == [0.05, 0.10, 0.15] and rounded
    assert used == pytest.approx([0.04, 0.12, 0.16])

    class Case:
        def __init__(self, u):
            self.name, self.velocity = f"u{u:g}", u

    few = [Case(u) for u in (2.5, 3.0, 8.0)]
    assert map_numbers(few) == {"u2.5": 4, "u3": 5, "u8": 6}
    many = [Case(u) for u in (2.5, 3.0, 4.0, 5.0, 6.0, 8.0)]
    assert map_numbers(many) == {"u2.5": 4, "u3": 4, "u4": 5, "u5": 5, "u6": 6, "u8": 7}


def test_trust_paragraph_is_written_from_the_numbers():
    from cfbmarkov.report.table3 import trust_text

    summary = {"md_rtd": 0.33, "baseline": {"md_rtd": 0.076}, "natural_variability":
               {"md_rtd": 0.05}, "level": 0.9, "reference": {"rt_mean": 0.86},
               "model": {"rt_mean_interval": [0.9, 1.1]}}
    text = trust_text("6", "paper", summary)
    # MD 0.33 against 0.076: higher by more than the halves' 0.05
    assert "simply reusing the fitting window's RTD beats the model" in text
    assert "6.6 times" in text and "outside the model's 90 %" in text
    summary.update(md_rtd=0.04, model={"rt_mean_interval": [0.8, 0.9]})
    text = trust_text("6", "auto", summary)
    # lower by 0.036, within the halves' 0.05: not told apart, never "beats"
    assert "cannot tell the model from simply reusing" in text and "beats" not in text
    assert "within the reference's own variability" in text
    assert "inside" in text
    assert "too few residences" in trust_text("3", "mle", {"md_rtd": None})
    # the value and its interval at one precision, so that a miss reads as one
    text = trust_text("6", "auto", dict(summary, reference={"rt_mean": 0.39952},
                                        model={"rt_mean_interval": [0.2293, 0.3984]}))
    assert "E(RT) lies outside the model's 90 % interval (Table 3)" in text
    assert "0.398" not in text             # the interval is Table 3's, not repeated
    # the MDs are Table 3's too: the rule's outcome and the gap in words
    assert "0.33" not in text and "0.076" not in text
    # the model's own error on its fitting window, against the flow's change (the baseline):
    # not split where the model's MD is within the reference's own variability
    summary["model_on_fitting_window"] = {"windows": [[15, 20], [10, 15]], "md_rtd": 0.02,
                                          "pd_rt_mean": 1.25, "pd_rt_sd": -3.0}
    text = trust_text("6", "auto", summary)
    assert "On its own fitting window (10-15 s) the model is 0.02" in text
    assert "+1.2 %" in text and "-3.0 %" in text
    assert "cannot tell how much of it is the model's own error" in text
    assert "limits this prediction" not in text and "dominates" not in text
    summary["md_rtd"] = 0.2      # beyond the halves: the flow's change since the fitting window
    text = trust_text("6", "a", summary)
    assert "smaller than the flow's change" in text
    assert "the rest is the flow's change since the fitting window" in text
    summary["model_on_fitting_window"]["md_rtd"] = 0.2
    text = trust_text("6", "auto", summary)
    assert "the model's own error dominates" in text and "the difference is the model's" in text
    # without the run's long run, the paragraph says why
    assert "perfect stationary model would predict (the CFD-DEM's RTD pooled" in text
    assert "is not given" in text
    # the best stationary prediction (the run's long run), where the summary has it
    summary["long_run"] = {"windows": [[5, 20], [15, 20]], "md_rtd": 0.08, "pd_rt_mean": -19.84,
                           "pd_rt_sd": -33.2}
    text = trust_text("6", "auto", summary)
    assert "other windows of 5-20 s pooled, is 0.08 from it (PD of E(RT) -19.8 %" in text
    assert "the model is 2.5 times as far." in text
    summary["md_rtd"] = 0.05
    assert "the model is closer than that." in trust_text("6", "auto", summary)


def test_the_long_run_span_of_a_reproduction():
    """One window before the fitting window, never the run's first window (its start-up);
    none where fewer than two other whole windows fit."""
    from cfbmarkov.reproduce_case import long_run_span

    assert long_run_span((10, 15), (15, 20), 0.0, 20.0) == (5.0, 20.0)
    assert long_run_span((5, 10), (10, 15), 0.0, 20.0) == (5.0, 20.0)
    assert long_run_span((2.5, 3.5), (3.5, 4.5), 0.0, 4.5) == (1.5, 4.5)
    assert long_run_span((0, 1), (1, 2), 0.0, 2.0) is None
    # the fitting window alone besides the analysis window: the persistence baseline again
    assert long_run_span((1, 2), (2, 3), 0.0, 3.0) is None
    assert long_run_span((1, 2), (2, 3), 0.0, 4.0) == (1.0, 4.0)


def test_a_side_without_residences_is_said_so_not_n_a(reproduction):
    """A model that predicts no residence in the net flow's direction: 'no residences' and a
    note saying why, not a row of n/a (issue 14, net downflow)."""
    from cfbmarkov.report.table3 import NO_RESIDENCES

    path = reproduction / "u3" / "compare-mle" / "summary.json"
    s = json.loads(path.read_text())
    s["model"].update(rt_mean=None, rt_sd=None, rt_count=0)
    s.update(pd_rt_mean=None, pd_rt_sd=None, md_rtd=None)
    s["baseline"] = dict(s.get("baseline") or {}, rt_count=0, pd_rt_mean=None, pd_rt_sd=None,
                         md_rtd=None)
    path.write_text(json.dumps(s))
    write_report(reproduction)
    md = (reproduction / "report.md").read_text(encoding="utf-8")
    row = table_row(md, "3", "mle")
    assert row[2] == f"{s['reference']['rt_mean']:.3f}"          # the CFD-DEM side stays
    assert [row[k] for k in (3, 4, 6, 7, 8, 9)] == [NO_RESIDENCES] * 6
    assert "n/a" not in row
    assert f"{NO_RESIDENCES}: that side holds no complete residence" in md
    assert NO_RESIDENCES not in table_row(md, "3", "paper")      # the others untouched


def test_fig8_counts_residences_as_table3_does(report_of_template):
    """Fig. 8's CFD-DEM E(RT) is Table 3's: one basis (frames at the lag) and direction."""
    root, _ = report_of_template
    md = (root / "report.md").read_text(encoding="utf-8")
    for case, u in (("u3", "3"), ("u6", "6")):
        s = json.loads((root / case / "compare-paper" / "summary.json").read_text())
        assert f"{s['reference']['rt_mean']:.3f} s at U = {u} m/s" in md


def numbered_clauses(md: str) -> list[str]:
    """The report's prose cut into clauses (at ``. ``, ``;``, ``:``, brackets and line
    ends) that hold a decimal number: tables, headings and figure links left out. A
    paragraph about one case and model ("U = 6 m/s, paper: ...") or one figure ("**Fig. 4:
    ...**") keys its clauses by that subject: the same ratio of two models, or the riser's
    height beside two figures' heights, is not a repeat."""
    out = []
    for line in md.splitlines():
        if not line or line.startswith(("|", "#", "![")):
            continue
        subject = re.match(r"(U = [^,:]+, [^:]+:|\*\*[^*]+\*\*)", line)
        prefix = subject.group(1) + " " if subject else ""
        for clause in re.split(r"[;:()]|\. ", line):
            clause = clause.strip().rstrip(".")
            if len(clause) >= 15 and re.search(r"\d\.\d", clause):
                out.append(prefix + clause)
    return out


def test_each_number_is_said_once(report_of_template):
    """The physics checks' evidence, and every clause of the prose that holds a number,
    once in the report: the summary states the verdict and links to the evidence."""
    root, _ = report_of_template
    md = (root / "report.md").read_text(encoding="utf-8")
    repeated = [c for c, n in collections.Counter(numbered_clauses(md)).items() if n > 1]
    assert repeated == []
    evidence = section(md, "Operating conditions and physics checks")
    profiles = re.findall(r"solids fraction wall/core [\d.]+/[\d.]+", evidence)
    assert profiles, "the physics checks give the wall and core solids fractions"
    for text in profiles:
        assert md.count(text) == 1, text
    assert "wall/core" not in section(md, "Summary") + section(md, "Plausibility")
    # the headline comparison with the paper's Table 3 once, in the summary
    assert md.count("the paper: narrower at all four") == 1
    assert "PD of E(RT) ranges" not in md and "narrower than the CFD-DEM's in" not in \
        section(md, "Fig. 9: RTD of the MCM")


def test_the_dedup_check_finds_a_repeat():
    md = ("## A\n\nE(RT) 0.746 s at 3 m/s; the core is dense.\n\n| 1 | 0.746 |\n\n"
          "## B\n\nAgain: E(RT) 0.746 s at 3 m/s.\n\n"
          "U = 6 m/s, paper: the error is 2.9 times the halves'.\n\n"
          "U = 6 m/s, mle: the error is 2.9 times the halves'.\n")
    counts = collections.Counter(numbered_clauses(md))
    assert counts["0.746 s at 3 m/s"] == 2
    assert [n for n in counts.values() if n > 1] == [2]
