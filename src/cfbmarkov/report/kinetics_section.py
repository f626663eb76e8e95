"""The report's section on properties along particle paths (reactions, heat exchange,
deactivation), from the ``kinetics`` blocks of the compare summaries
(``cfbmarkov reproduce --kinetics``; :func:`cfbmarkov.analysis.kinetics_compare.compare_kinetics`).

Per property: a table with one row per case and estimator (the exit mean of the reference,
the chain's Monte Carlo and exact answer, and the segregated-flow baseline, with their
intervals; the relative errors of the chain and of the baseline against the reference; the
Minkowski distances of the exit distributions), a paragraph written from those numbers
(where the chain is closer to the reference than the segregated-flow baseline and where
not) and, per case, the figure of the comparison (``kinetics-NAME.png``: per-cell maps of
the bed's mean and the exit distribution), copied into the report's figures as
``kinetics-CASE-ESTIMATOR-NAME.png``.

Choices:

- The chain's error is that of its exact exit mean as a window of the comparison's length
  sees it where the summary holds it (no sampling noise, and the same window bias as the
  reference's exits: :func:`cfbmarkov.markov.kinetics_exact.windowed_exit_means`), else
  that of its exact exit mean, else that of its Monte Carlo; the table's note says so.
- The chain *beats* the baseline in a row where the magnitude of its relative error is at
  most the baseline's; the paragraph names every row where it does not, with both errors.
- The figure of each case is that of its first finished estimator with one (paper, mle,
  then the others).

References
----------
``docs/definitions.md``, Properties along observed paths; O. Levenspiel, Chemical Reaction
Engineering, 3rd ed., Wiley (1999), ch. 15 (segregated flow).
"""

from __future__ import annotations

import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cfbmarkov._atomic import atomic_path
from cfbmarkov.report.document import Bullets, FigureBlock, Heading, Para, Table, finite_or_none
from cfbmarkov.report.run_folder import input_error

#: the heading of the section
HEADING = "Properties along particle paths"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@dataclass
class KineticsRow:
    """One property in one case and estimator, as the summary gives it.

    Attributes
    ----------
    case, estimator : str
        The case's label (U) and the estimator.
    entry : dict
        The property's block of the summary's ``kinetics``.
    """

    case: str
    estimator: str
    entry: dict

    def side(self, key: str) -> dict:
        """The block of one side (``reference``, ``model``, ``segregated_flow``), or {}."""
        value = self.entry.get(key)
        return value if isinstance(value, dict) else {}

    def _chain(self, key: str) -> float | None:
        """The chain's exact figure ``key`` as the window sees it, else its exact one, else
        its Monte Carlo's (``key``: ``exit_mean`` or ``pd_exit_mean``). A carried
        property's exact answer is the long-run steady state, not a window's: its Monte
        Carlo's then."""
        exact = self.side("model").get("exact")
        if isinstance(exact, dict) and self.entry.get("start") != "carried":
            for k in (key.replace("exit_mean", "windowed_exit_mean"), key):
                if finite_or_none(exact.get(k)) is not None:
                    return finite_or_none(exact.get(k))
        return finite_or_none(self.side("model").get(key))

    @property
    def chain_mean(self) -> float | None:
        """The chain's exit mean the errors are judged on (module docstring), or None."""
        return self._chain("exit_mean")

    @property
    def chain_error(self) -> float | None:
        """The chain's relative error in the exit mean (%), on :attr:`chain_mean`; None
        where undefined."""
        return self._chain("pd_exit_mean")

    @property
    def baseline_error(self) -> float | None:
        """The segregated-flow baseline's relative error in the exit mean (%), or None."""
        return finite_or_none(self.side("segregated_flow").get("pd_exit_mean"))


def safe_name(name: str) -> str:
    """A property name as a file-name part (letters, digits, ``-`` and ``_``)."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", str(name)) or "property"


def _value(v) -> str:
    x = finite_or_none(v)
    return "n/a" if x is None else f"{x:.4g}"


def _with_interval(block: dict) -> str:
    text = _value(block.get("exit_mean"))
    interval = block.get("exit_mean_interval")
    if (text != "n/a" and isinstance(interval, list) and len(interval) == 2
            and all(finite_or_none(v) is not None for v in interval)):
        from cfbmarkov.markov.uncertainty import outward_bounds

        lo, hi = outward_bounds(float(interval[0]), float(interval[1]), digits=4)
        text += f" [{lo}, {hi}]"          # rounded outwards: it holds what the interval holds
    return text


def _pd(v) -> str:
    x = finite_or_none(v)
    return "n/d" if x is None else f"{x:+.2f}"


def collect_rows(done) -> dict[str, list[KineticsRow]]:
    """The kinetics blocks of the finished comparisons, by property name.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.

    Returns
    -------
    dict of str to list of KineticsRow
        In the order the properties first appear; rows in case, then estimator order.
    """
    rows: dict[str, list[KineticsRow]] = {}
    for c in done:
        for e in c.finished:
            block = e.summary.get("kinetics")
            if not isinstance(block, dict):
                continue
            for name, entry in block.items():
                if isinstance(entry, dict):
                    rows.setdefault(name, []).append(KineticsRow(c.label, e.name, entry))
    return rows


def verdict_sentence(name: str, rows: list[KineticsRow]) -> str:
    """The paragraph on one property, written from the numbers: in how many rows the chain's
    exit mean is at least as close to the reference as the segregated-flow baseline's, the
    rows where it is not (both errors), and in how many the reference's exit mean lies
    inside the chain's interval, outside it but not told apart, or missed
    (:func:`~cfbmarkov.analysis.kinetics_compare.exit_mean_agreement`, as ``compare`` says).

    Parameters
    ----------
    name : str
        The property.
    rows : list of KineticsRow
        Its rows.

    Returns
    -------
    str
    """
    judged = [r for r in rows if r.chain_error is not None and r.baseline_error is not None]
    parts = []
    if not judged:
        parts.append(f"No comparison of {name} has both the chain's and the segregated-flow "
                     "baseline's error, so the two are not ranked here.")
    else:
        beats = [r for r in judged if abs(r.chain_error) <= abs(r.baseline_error)]
        worse = [r for r in judged if r not in beats]
        parts.append(f"For {name} at the exit the chain is at least as close to the reference "
                     f"as the segregated-flow baseline in {len(beats)} of {len(judged)} "
                     "comparisons (the chain's error from its exact answer as the window "
                     "sees it, free of Monte Carlo noise"
                     + (f"; among these, the largest is "
                        f"{max(abs(r.chain_error) for r in beats):.2f} %" if beats else "")
                     + ").")
        if worse:
            parts.append("It is not in " + "; ".join(
                f"{r.case} ({r.estimator}): chain {r.chain_error:+.2f} %, segregated flow "
                f"{r.baseline_error:+.2f} %" for r in worse) + ".")
        else:
            parts.append("In none is the baseline closer.")
    from cfbmarkov.analysis.kinetics_compare import exit_mean_agreement

    agreement = {"inside": 0, "not told apart": 0, "missed": 0}
    noise_only = with_flow = 0
    widths = []          # the intervals that hold the reference: their half-width, relative
    for r in rows:
        interval = r.side("model").get("exit_mean_interval")
        said = exit_mean_agreement(r.side("reference").get("exit_mean"), interval,
                                   r.side("reference").get("exit_mean_interval"))
        if said is None:
            continue
        if not str(r.side("model").get("interval_method") or "").startswith("block bootstrap"):
            noise_only += 1   # the Monte Carlo noise alone: no verdict, as compare says
            continue
        agreement[said] += 1
        with_flow += r.side("model").get("flow_sd") is not None
        centre = r.side("model").get("exit_mean")
        if said == "inside" and centre:
            widths.append(100 * (interval[1] - interval[0]) / 2 / abs(centre))
    known = sum(agreement.values())
    if known:
        parts.append(
            f"The reference's exit mean lies inside the chain's interval (the fitting "
            f"window's bootstrap and the Monte Carlo noise"
            + ("" if not with_flow else
               ", with the flow's variability between windows as a stretch of every "
               "residence" + ("" if with_flow == known else f" in {with_flow} of them"))
            + f", around the Monte Carlo's exit mean) in {agreement['inside']} of "
            f"{known} comparisons"
            + (": there the chain is consistent with it within its uncertainty, as compare "
               "says" + (f", which is no closer than those intervals' half-widths, "
                         f"{_range_text(widths)} % of the chain's exit mean" if widths else "")
               if agreement["inside"] else "")
            + (f"; in {agreement['not told apart']} it lies outside but the reference's own "
               "interval overlaps the chain's (not told apart)"
               if agreement["not told apart"] else "")
            + (f"; in {agreement['missed']} the chain misses it beyond its uncertainty"
               if agreement["missed"] else "") + ".")
    if noise_only:
        parts.append(f"In {noise_only} comparison{'' if noise_only == 1 else 's'} the chain's "
                     "interval holds the Monte Carlo noise alone (no bootstrap of the fitting "
                     "window: a carried property, or none asked), which leaves out most of its "
                     "uncertainty: no verdict is drawn from it.")
    return " ".join(parts)


def _range_text(values: list[float]) -> str:
    """``a-b`` (or ``a`` where they round alike) to two significant figures, written out
    (120, not 1.2e+02, which a dash beside it would garble)."""
    def text(value: float) -> str:
        return np.format_float_positional(float(f"{value:.2g}"), trim="-")

    lo, hi = text(min(values)), text(max(values))
    return lo if lo == hi else f"{lo} to {hi}"


def _table(rows: list[KineticsRow]) -> Table:
    header = ["case", "model", "reference exits", "reference", "chain (Monte Carlo)",
              "chain (exact, window)", "chain (exact)", "segregated flow", "chain error, %",
              "segregated flow error, %", "MD chain", "MD segregated flow"]
    body = []
    steady = False
    for r in rows:
        ref, mod, seg = r.side("reference"), r.side("model"), r.side("segregated_flow")
        exact = mod.get("exact") if isinstance(mod.get("exact"), dict) else {}
        plain = _value(exact.get("exit_mean"))
        if exact.get("note") and plain != "n/a":
            plain += " (long run)"        # a carried property's steady state: no window's
            steady = True
        body.append([r.case, r.estimator, str(ref.get("exit_count", "n/a")), _with_interval(ref),
                     _with_interval(mod), _value(exact.get("windowed_exit_mean")),
                     plain,
                     _with_interval(seg) if seg else "n/a", _pd(r.chain_error),
                     _pd(r.baseline_error), _value(mod.get("md_exit")),
                     _value(seg.get("md_exit")) if seg else "n/a"])
    notes = ["Exit means per residence with their intervals in brackets (the reference's and "
             "the baseline's from their standard errors, the chain's from the block bootstrap "
             "of its fitting window and the Monte Carlo noise). The chain's exact answer "
             "'window' is its exit mean as a window of the comparison's length sees it (short "
             "residences more often than long ones, as the reference's exits); the plain one "
             "is per residence of the chain. Errors are 100 (side - reference) / reference, "
             "the chain's from its exact answer as the window sees it where there is one, "
             "else from its exact answer, else from its Monte Carlo; MD: Minkowski distance "
             "of the exit distributions to the reference's on bins shared by the row's three "
             "sides (the range of the reference's, the chain's and the segregated flow's exit "
             "values), so a row's two MDs compare with each other, and the segregated flow's "
             "MD differs from row to row with the chain's range."]
    if steady:
        notes.append("'(long run)': a carried property's exact answer is the circulating "
                     "inventory's long-run steady state, after many passes; the window's "
                     "particles carry what they gathered since its start, so it is not "
                     "comparable with the window's figures and no error is taken from it.")
    return Table(header, body, notes)


def _copy_figure(c, name: str, figures_dir: Path, written: list[str]) -> tuple[str, str] | None:
    """Copy the case's kinetics figure of ``name`` into the figures; (file, estimator)."""
    want = f"kinetics-{name}.png"
    for e in c.finished:
        figures = e.summary.get("figures") or []
        block = e.summary.get("kinetics")
        png = e.compare_dir / want
        if not (isinstance(block, dict) and name in block and want in figures
                and png.is_file()):
            continue
        if png.read_bytes()[:8] != PNG_SIGNATURE:
            raise input_error(png, "not a PNG image")
        file = f"kinetics-{c.name}-{e.name}-{safe_name(name)}.png"
        with atomic_path(figures_dir / file, suffix=".png") as tmp:
            shutil.copyfile(png, tmp)
        written.append(file)
        return file, e.name
    return None


def source_text(source, rows: dict[str, list[KineticsRow]]) -> str:
    """The paragraph naming the kinetics file the comparisons integrated, its digest, each
    property's law, start and initial value, and, where the file is still there with the
    same definition, its settings line by line.

    Parameters
    ----------
    source : dict or None
        ``reproduce.json``'s ``kinetics`` entry (``{"file", "digest"}``).
    rows : dict of str to list of KineticsRow
        The properties' rows (:func:`collect_rows`).

    Returns
    -------
    str
    """
    laws = "; ".join(
        f"{name}: {r[0].entry.get('law', 'n/a')}, start {r[0].entry.get('start', 'n/a')}"
        + (f", initial {r[0].entry['initial']:g}" if isinstance(r[0].entry.get("initial"),
                                                              (int, float)) else "")
        for name, r in rows.items())
    units = ("Values are in the kinetics file's units (a temperature in those of its "
             "temperatures and initial value), rates in 1/s.")
    if not (isinstance(source, dict) and isinstance(source.get("file"), str)):
        return f"The properties: {laws}. {units}"
    file, digest = source["file"], str(source.get("digest", ""))
    text = f"The kinetics file {file} ({digest or 'no digest recorded'}): {laws}."
    path = Path(file)
    try:
        from cfbmarkov.kinetics import load_kinetics
        from cfbmarkov.kinetics.fingerprint import kinetics_digest

        same = path.is_file() and kinetics_digest(load_kinetics(path)) == digest
    except Exception:       # a file changed since into one that no longer reads
        same = False
    if same:
        lines = [ln.strip() for ln in path.read_text(encoding="utf-8").splitlines()
                 if ln.strip() and not ln.strip().startswith("#")]
        if len(lines) <= 40:
            text += " It holds: " + "; ".join(lines) + "."
    else:
        text += (" The file is no longer there or its definition has changed since (its "
                 "digest differs): the figures are of the definition of that digest.")
    return f"{text} {units}"


def kinetics_blocks(done, figures_dir: Path, written: list[str], source=None) -> list:
    """The section on properties along particle paths (empty where no comparison has a
    ``kinetics`` block).

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    figures_dir : pathlib.Path
        Folder the figures are copied into.
    written : list of str
        Receives the file names of the PNGs copied.
    source : dict, optional
        ``reproduce.json``'s ``kinetics`` entry: the file is named (:func:`source_text`).

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`).

    Raises
    ------
    InputError
        Where a comparison's kinetics figure is not a PNG image.
    """
    by_name = collect_rows(done)
    if not by_name:
        return []
    blocks: list = [Heading(2, HEADING), Para(
        "Each property of the kinetics file integrated along three sets of paths over the "
        "comparison window: the reference's (the CFD-DEM trajectories on the model's states "
        "at its lag), the chain's (its prediction, and its exact answer by the "
        "absorbing-chain algebra), and the segregated-flow baseline (the bed-averaged law "
        "over the fitting window's observed residence times). The chain is worth its name "
        "where it is closer to the reference than the baseline."),
        Para(source_text(source, by_name))]
    warnings = []
    for c in done:
        for e in c.finished:
            for w in e.summary.get("warnings") or []:
                if isinstance(w, str) and w.startswith("kinetics:"):
                    line = f"{c.label} ({e.name}): {w[len('kinetics:'):].strip()}"
                    if line not in warnings:
                        warnings.append(line)
    if warnings:
        blocks.append(Bullets(warnings))
    for name, rows in by_name.items():
        law = rows[0].entry.get("law", "")
        blocks.append(Heading(3, f"{name} ({law})" if law else name))
        blocks.append(_table(rows))
        blocks.append(Para(verdict_sentence(name, rows)))
        for c in done:
            copied = _copy_figure(c, name, figures_dir, written)
            if copied is None:
                continue
            file, est = copied
            blocks.append(FigureBlock(
                file, f"{name} along particle paths, {c.label} ({est})",
                "Left: the bed's mean of the property per cell over the comparison window "
                "(reference, the chain's prediction and, where known, its exact steady "
                "state), on one colour scale. Right: the distribution of the value at the "
                "exit (reference, chain, segregated flow) with each side's mean."))
    return blocks


__all__ = ["HEADING", "KineticsRow", "collect_rows", "kinetics_blocks", "safe_name", "source_text",
           "verdict_sentence"]
