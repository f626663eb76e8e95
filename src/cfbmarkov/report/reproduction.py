"""The reproduction report: the paper's §3 (Table 3, computing time, Fig. 3-11) from a
reproduction run folder.

:func:`write_report` reads the folder with :func:`cfbmarkov.report.run_folder.read_run_folder`
(layout there), recomputes the RTDs (Fig. 8-9), mixing curves of the tracer groups
(Fig. 11) and solids profiles from the trajectory files over each case's predict window with
:func:`cfbmarkov.analysis.reproduction.measure_case` (bin width of the compare summaries;
Table 3 quotes the summaries), builds the sections (the verdict and the physics checks first,
:mod:`cfbmarkov.report.summary`; Table 3, :mod:`cfbmarkov.report.table3`;
:mod:`cfbmarkov.report.sections`, :mod:`cfbmarkov.report.figure_sections`,
:mod:`cfbmarkov.report.diagnostic_sections`; where the comparisons integrated a kinetics
file, the properties along particle paths, :mod:`cfbmarkov.report.kinetics_section`) and
writes ``DIR/report.html`` (self-contained: PNGs embedded as base64 ``data:`` URIs, inline
CSS), ``DIR/report.md`` (the same content, images linked as ``figures/NAME.png``) and the
PNGs in ``DIR/figures/``, each atomically; report.html is written last.
"""

from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path

import numpy as np

from cfbmarkov.analysis.reproduction import CaseMeasures, measure_case
from cfbmarkov.report.diagnostic_sections import diagnostics_blocks
from cfbmarkov.report.document import (
    FIGURES,
    finite_or_none,
    readable_mode,
    render_html,
    render_markdown,
    write_utf8,
)
from cfbmarkov.report.figure_sections import (
    fig3_blocks,
    maps_blocks,
    mixing_blocks,
    plausibility_blocks,
    rtd_blocks,
    snapshot_blocks,
)
from cfbmarkov.report.kinetics_section import kinetics_blocks
from cfbmarkov.report.run_folder import Case, read_run_folder
from cfbmarkov.report.sections import (
    DEFAULT_BIN_WIDTH,
    computing_blocks,
    header_blocks,
    not_finished_blocks,
    warning_blocks,
)
from cfbmarkov.report.summary import conditions_blocks, physics_checks, summary_blocks
from cfbmarkov.report.table3 import table3_blocks, table3_detail_blocks

REPORT_HTML = "report.html"
REPORT_MD = "report.md"
_STALE_FIGURE = re.compile(r"^(fig\d\d-.*|plausibility|its-.*|ck-.*|kinetics-.*)\.png$")


def _measure(case: Case, notes: list[str]) -> CaseMeasures:
    """Recompute the numbers of a finished case over its predict window, with the finest bin
    width of its compare summaries; notes a compare window that differs from it."""
    window = tuple(float(v) for v in case.config.markov.predict_window)
    widths = {finite_or_none(e.summary.get("bin_width")) for e in case.finished} - {None}
    bin_width = min(widths) if widths else DEFAULT_BIN_WIDTH
    for e in case.finished:
        w = e.summary.get("window")
        if isinstance(w, list) and len(w) == 2 and not np.allclose(w, window, atol=1e-9):
            notes.append(f"{case.name} / {e.name}: compare window {w[0]:g}-{w[1]:g} s differs "
                         f"from the case's predict window {window[0]:g}-{window[1]:g} s")
    chosen = case.finished[0]
    return measure_case(case.reference, {e.name: e.prediction for e in case.finished},
                        (chosen.name, chosen.model), window, bin_width, case.config)


def _section(builder, *args) -> tuple[list, list[str]]:
    """One section of the report, e.g. in a worker process: its blocks and the names of the
    figures it wrote (``builder(*args, written)``)."""
    written: list[str] = []
    blocks = builder(*args, written)
    return blocks, written


def _later_sections(done, measures, estimators, figures_dir, written) -> list:
    """The snapshot, mixing and plausibility sections, in the report's order."""
    return (snapshot_blocks(done, measures, figures_dir, written)
            + mixing_blocks(done, measures, estimators, figures_dir, written)
            + plausibility_blocks(done, measures, estimators, figures_dir, written))


def write_report(directory: str | os.PathLike, *, title: str | None = None,
                 executor=None) -> Path:
    """Write the reproduction report of a run folder.

    Parameters
    ----------
    directory : str or os.PathLike
        The run folder of ``cfbmarkov reproduce``.
    title : str, optional
        Title of the report (default: names the scale).
    executor : concurrent.futures.Executor, optional
        Draws two groups of sections (the lag diagnostics; the snapshots, mixing and
        plausibility) there while this process draws the rest: the same report, sooner
        (``cfbmarkov reproduce`` passes its idle process pool).

    Returns
    -------
    pathlib.Path
        ``DIR/report.html`` (beside it ``DIR/report.md`` and ``DIR/figures/*.png``).

    Raises
    ------
    InputError
        One line naming the file, when reproduce.json is missing or unusable, when a file
        that exists cannot be read, when a case folder has neither case.json nor a case
        stored in its cfd-dem.h5, or when no case is finished. Unfinished cases are listed
        as "not finished".

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Section 3: Table 3,
    Figs. 3-11; ``docs/definitions.md`` (Residence time, Mixing, Metrics).
    """
    folder = read_run_folder(directory)
    root, meta, cases, estimators = folder.root, folder.manifest, folder.cases, folder.estimators
    done = folder.finished
    figures_dir = root / FIGURES
    figures_dir.mkdir(parents=True, exist_ok=True)
    if executor is not None:
        diagnostics = executor.submit(_section, diagnostics_blocks, done, figures_dir)
    notes: list[str] = []
    measures = {c.name: _measure(c, notes) for c in done}
    if executor is not None:
        later = executor.submit(_section, _later_sections, done, measures, estimators,
                                figures_dir)
    for c in done:
        if measures[c.name].model_name != "paper":
            notes.append(f"{c.name}: Fig. 3-7 use the {measures[c.name].model_name} estimator "
                         "(no finished paper estimator)")
        if not c.timings:
            notes.append(f"{c.name}: no timings.json; computing times are n/a")

    written: list[str] = []
    blocks: list = []
    checks = physics_checks(done, measures)
    blocks += summary_blocks(meta, cases, done, measures, estimators, checks)
    blocks += conditions_blocks(done, measures, checks)
    blocks += header_blocks(meta, cases, estimators, root)
    blocks += not_finished_blocks(cases)
    blocks += table3_blocks(cases, estimators)
    blocks += computing_blocks(cases)
    blocks += fig3_blocks(done, measures, figures_dir, written)
    blocks += maps_blocks(cases, done, measures, figures_dir, written)
    blocks += rtd_blocks(done, measures, estimators, figures_dir, written)
    blocks += kinetics_blocks(done, figures_dir, written, meta.get("kinetics"))
    parts = ([later.result(), diagnostics.result()] if executor is not None else
             [_section(_later_sections, done, measures, estimators, figures_dir),
              _section(diagnostics_blocks, done, figures_dir)])
    for part_blocks, part_written in parts:
        blocks += part_blocks
        written += part_written
    blocks += table3_detail_blocks(cases)
    blocks += warning_blocks(cases, notes)

    # figures of an earlier run that this run did not draw (e.g. a case since removed)
    for p in figures_dir.iterdir():
        if p.is_file() and _STALE_FIGURE.match(p.name) and p.name not in written:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
    mode = readable_mode()
    for name in written:
        with contextlib.suppress(OSError):
            os.chmod(figures_dir / name, mode)

    title = title or ("cfbmarkov reproduction of the Markov chain riser paper "
                      f"({meta.get('scale', 'n/a')} scale)")
    write_utf8(root / REPORT_MD, render_markdown(title, blocks))
    html_path = root / REPORT_HTML
    write_utf8(html_path, render_html(title, blocks, figures_dir))
    return html_path


__all__ = ["REPORT_HTML", "REPORT_MD", "report_verdict", "write_report"]


def report_verdict(report) -> str | None:
    """The report's verdict line (its summary's first sentence, "Verdict at the ... scale:
    ... Next step: ..."), as plain text for a terminal: read from the ``report.md`` beside
    ``report`` (the HTML's path), its links reduced to their text.

    Parameters
    ----------
    report : str or os.PathLike
        The report's HTML file (what :func:`write_report` returns).

    Returns
    -------
    str or None
        None where the markdown report or its verdict line cannot be read.
    """
    markdown = Path(report).with_name(REPORT_MD)
    try:
        lines = markdown.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    line = next((x for x in lines if x.startswith("Verdict at the ")), None)
    if line is None:
        return None
    return re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", line)

