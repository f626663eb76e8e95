"""The report's section on properties along particle paths: a small generated reproduction
whose comparisons integrated a kinetics file (zone-dependent first-order rate)."""

from __future__ import annotations

import json
import re

import numba
import pytest

from cfbmarkov.report.compare import compare
from cfbmarkov.report.kinetics_section import HEADING, KineticsRow, verdict_sentence
from tests.shared_builds import built_once

KINETICS = """
[[property]]
name = "X"
law = "first-order"
rate_by_cell = "rates.csv"
"""


def _rates(columns: int, rows: int) -> str:
    """Tenfold slower in the wall columns than in the core."""
    return "col,row,rate\n" + "".join(
        f"{c},{r},{0.3 if c in (0, columns - 1) else 3.0}\n"
        for r in range(rows) for c in range(columns))


@pytest.fixture(scope="session")
def reported(reproduction_template, tmp_path_factory):
    """(folder, report.html) of the template with kinetics compared in u3 and u6 and its
    report written: built once per test run, shared by the workers (read only)."""
    def build(folder):
        _build_reported(reproduction_template, folder / "reproduction")

    root = built_once(tmp_path_factory, "kinetics-reported", build) / "reproduction"
    return root, root / "report.html"


def _build_reported(reproduction_template, root):
    import shutil

    from cfbmarkov.report.reproduction import write_report
    from tests.report.conftest import COLUMNS, PREDICT, ROWS

    shutil.copytree(reproduction_template, root)
    kin = root / "kinetics.toml"
    kin.write_text(KINETICS)
    (root / "rates.csv").write_text(_rates(COLUMNS, ROWS))
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        for case in ("u3", "u6"):
            folder = root / case
            shutil.rmtree(folder / "compare-paper")
            compare(folder / "cfd-dem.h5", folder / "prediction-paper.h5", window=PREDICT,
                    output=folder / "compare-paper", kinetics=kin, resamples=10)
    finally:
        numba.set_num_threads(threads)
    write_report(root)


def test_the_section_quotes_summary_json(reported):
    root, html_path = reported
    md = (root / "report.md").read_text()
    assert f"## {HEADING}" in md and "### X (first-order)" in md
    section = md[md.index(f"## {HEADING}"):]
    section = section[:section.index("\n## ", 3)] if "\n## " in section[3:] else section
    for case, label in (("u3", "U = 3 m/s"), ("u6", "U = 6 m/s")):
        entry = json.loads((root / case / "compare-paper" / "summary.json").read_text()
                           )["kinetics"]["X"]
        row = next(line for line in section.splitlines()
                   if line.startswith(f"| {label} | paper |"))
        ref, mod, seg = entry["reference"], entry["model"], entry["segregated_flow"]
        assert f"{ref['exit_mean']:.4g} [" in row
        assert f"{mod['exit_mean']:.4g} [" in row
        assert f"| {mod['exact']['windowed_exit_mean']:.4g} | {mod['exact']['exit_mean']:.4g} |" in row
        assert f"{seg['exit_mean']:.4g} [" in row
        assert f"| {mod['exact']['pd_windowed_exit_mean']:+.2f} |" in row
        assert f"| {seg['pd_exit_mean']:+.2f} |" in row
        assert f"| {ref['exit_count']} |" in row
        # the figure of the case is copied and linked
        file = f"kinetics-{case}-paper-X.png"
        assert (root / "figures" / file).is_file() and f"figures/{file}" in section
    # the mle comparisons have no kinetics: no row for them
    assert "| mle |" not in section
    # one sentence written from the numbers
    assert re.search(r"in \d of 2 comparisons", section)
    # and the summary's verdict counts them the same way
    beats = sum(abs(e["model"]["exact"]["pd_windowed_exit_mean"])
                <= abs(e["segregated_flow"]["pd_exit_mean"]) for e in (
        json.loads((root / case / "compare-paper" / "summary.json").read_text())["kinetics"]["X"]
        for case in ("u3", "u6")))
    summary = md[:md.index(f"## {HEADING}")]
    assert (f"the segregated-flow baseline's (the property as a function of residence time "
            f"alone) for X in {beats} of 2 comparisons") in summary
    html = html_path.read_text()
    assert f'id="{HEADING.lower().replace(" ", "-")}"' in html


def test_a_report_without_kinetics_has_no_section(report_of_template):
    root, _ = report_of_template
    assert HEADING not in (root / "report.md").read_text()


def test_the_sentence_names_where_the_chain_loses():
    def row(case, chain, seg, half_width=0.03, method="block bootstrap of the fitting "
            "window (exact exit means) and Monte Carlo noise, in quadrature"):
        mean = 0.5 * (1 + chain / 100)
        return KineticsRow(case, "paper", {
            "reference": {"exit_mean": 0.5, "exit_mean_interval": [0.49, 0.51]},
            "model": {"exit_mean": mean, "pd_exit_mean": chain,
                      "exit_mean_interval": [mean - half_width, mean + half_width],
                      "interval_method": method,
                      "exact": {"exit_mean": mean, "pd_exit_mean": chain}},
            "segregated_flow": {"exit_mean": 0.5 * (1 + seg / 100), "pd_exit_mean": seg}})

    text = verdict_sentence("X", [row("U = 3 m/s", 0.5, -4.0), row("U = 6 m/s", 3.0, 1.0)])
    assert "in 1 of 2 comparisons (the chain's error from its exact answer" in text
    assert "among these, the largest is 0.50 %" in text
    assert "U = 6 m/s (paper): chain +3.00 %, segregated flow +1.00 %" in text
    # the test compare's verdict makes: the reference inside the chain's interval (both
    # chains' intervals of +-0.03 hold 0.5), not the chain's mean in the reference's
    # narrow sampling interval (the second's 0.515 lies outside 0.49-0.51)
    assert "lies inside the chain's interval" in text and "in 2 of 2 comparisons" in text
    # "consistent" says no more than the intervals' width: given (+-0.03 of 0.5025, 0.515)
    assert ("which is no closer than those intervals' half-widths, 5.8 to 6 % of the "
            "chain's exit mean") in text
    # written out, not 1.2e+02, beside the other end (a slow reaction's wide interval)
    wide = verdict_sentence("X", [row("a", 0.5, -4.0, 0.6), row("b", 0.5, -4.0, 0.01)])
    assert "half-widths, 2 to 120 % of the chain's exit mean" in wide
    text = verdict_sentence("X", [row("a", 3.0, 1.0, 0.006), row("b", 6.0, 1.0, 0.003),
                                  row("c", 0.5, 1.0)])
    assert "in 1 of 3 comparisons: there the chain is consistent" in text
    assert "in 1 it lies outside but the reference's own interval overlaps" in text
    assert "in 1 the chain misses it beyond its uncertainty" in text
    # an interval of the Monte Carlo noise alone draws no verdict, as compare says
    text = verdict_sentence("X", [row("a", 3.0, 1.0, 0.006), row("b", 6.0, 1.0, 0.003,
                                                                 "Monte Carlo noise only")])
    assert "in 0 of 1 comparisons" in text and "misses it" not in text
    assert "consistent" not in text           # none inside: nothing said to be consistent
    assert "In 1 comparison the chain's interval holds the Monte Carlo noise alone" in text
    assert "flow's variability" not in text
    # an interval that carries the flow's variability says so, and in how many
    flowing = row("a", 0.5, -4.0)
    flowing.side("model")["flow_sd"] = {"exit_mean": 0.01, "rt_mean_relative": 0.05,
                                        "degrees_of_freedom": 2}
    text = verdict_sentence("X", [flowing, row("b", 0.5, -4.0)])
    assert ("the fitting window's bootstrap and the Monte Carlo noise, with the flow's "
            "variability between windows as a stretch of every residence in 1 of them, "
            "around") in text


def test_a_carried_propertys_chain_is_its_monte_carlo_not_the_steady_state():
    row = KineticsRow("U = 3 m/s", "mle", {
        "start": "carried",
        "reference": {"exit_mean": 0.6, "exit_mean_interval": [0.58, 0.62]},
        "model": {"exit_mean": 0.62, "pd_exit_mean": 3.33,
                  "exact": {"exit_mean": 0.0, "pd_exit_mean": None,
                            "note": "the circulating inventory's long-run steady state"}},
        "segregated_flow": None, "segregated_flow_note": "not defined for a carried property"})
    assert row.chain_mean == pytest.approx(0.62) and row.chain_error == pytest.approx(3.33)
    assert row.baseline_error is None
    # the table marks the steady state, which a reader would take for a miss of the window
    from cfbmarkov.report.kinetics_section import _table

    table = _table([row])
    assert table.rows[0][6] == "0 (long run)"
    assert any("'(long run)': a carried property's exact answer is the circulating "
               "inventory's long-run steady state" in note for note in table.notes)
    plain = KineticsRow("U = 3 m/s", "mle", {
        "reference": {"exit_mean": 0.6}, "model": {"exit_mean": 0.62,
                                                   "exact": {"exit_mean": 0.61}},
        "segregated_flow": None})
    table = _table([plain])
    assert table.rows[0][6] == "0.61" and not any("long run" in n for n in table.notes)


def test_the_reference_interval_of_a_kinetics_verdict_is_rounded_outwards():
    """Both intervals of a 'not told apart' line hold what they hold: the reference's
    0.905656-0.921391 prints 0.9056-0.9214, not 0.9057-0.9214 (which leaves out its own
    lower end)."""
    from cfbmarkov.cli.analysis import kinetics_verdict

    model = {"exit_mean": 0.93, "exit_mean_interval": [0.92, 0.94],
             "interval_method": "block bootstrap of the fitting window and Monte Carlo noise"}
    line = kinetics_verdict("X", 0.9135, model, 0.9,
                            reference_interval=(0.905656, 0.921391))
    assert "the reference's own 90 % interval 0.9056-0.9214" in line, line


def test_the_section_names_its_kinetics_file_and_what_it_holds(tmp_path):
    """The kinetics file, its digest and settings are named: the report can be made
    again from its own text; a file changed since is said to differ."""
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.kinetics.fingerprint import kinetics_digest
    from cfbmarkov.report.kinetics_section import source_text

    kin = tmp_path / "kin.toml"
    kin.write_text('# a comment\n[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.1\n')
    source = {"file": str(kin), "digest": kinetics_digest(load_kinetics(kin))}
    rows = {"X": [KineticsRow("U = 3 m/s", "paper", {"law": "first-order", "start": "entry",
                                                      "initial": 0.0})]}
    text = source_text(source, rows)
    assert text.startswith(f"The kinetics file {kin} ({source['digest']}): X: first-order, "
                           "start entry, initial 0.")
    assert 'It holds: [[property]]; name = "X"; law = "first-order"; rate = 1.1.' in text
    assert "comment" not in text and "rates in 1/s" in text
    kin.write_text('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 2.2\n')
    text = source_text(source, rows)
    assert "rate = 2.2" not in text and "its definition has changed since" in text
    kin.unlink()
    assert "no longer there" in source_text(source, rows)
    assert source_text(None, rows).startswith("The properties: X: first-order, start entry")
