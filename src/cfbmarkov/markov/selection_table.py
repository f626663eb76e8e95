"""The automatic choice's candidates as a table: every candidate scored, the winner marked.

:func:`candidate_columns` forms the table from a selection record
(:func:`~cfbmarkov.markov.select.record.selection_record`, as stored in a model) for any
renderer (the report draws it as HTML); :func:`candidate_table` writes it as fixed-width
text lines for ``fit`` and ``info``.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

#: share of a model's states never visited above which its grid is warned about as too fine
#: (:func:`cfbmarkov.markov.model_summary.model_warnings`) and `--states auto` passes a
#: candidate over (:func:`cfbmarkov.markov.select.candidates.best_candidate`)
UNVISITED_LIMIT = 0.5


def too_sparse(candidate, limit: float) -> bool:
    """Whether more than ``limit`` (a fraction) of a candidate's states (a
    :class:`~cfbmarkov.markov.select.record.CandidateScore`) are never visited in the
    fitting window."""
    return (candidate.visited is not None
            and candidate.n_states - candidate.visited > limit * candidate.n_states)


def _number(value, spec: str) -> str:
    """``value`` formatted by ``spec``; "-" where it is missing or not finite."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, spec)


def _kind(selection: Mapping[str, Any]) -> str:
    """The criterion of a record: ``window``, ``rtd`` or ``ck``."""
    method = str(selection.get("method", ""))
    if "Chapman-Kolmogorov" in method or "reason" in selection and \
            "too short to judge" in str(selection.get("reason", "")):
        return "ck"
    if method == "the RTD over the fitting window":
        return "window"
    return "rtd"


def candidate_columns(selection: Mapping[str, Any]
                      ) -> tuple[list[str], list[list[str]], list[str]]:
    """The candidates of a selection record as a table.

    Parameters
    ----------
    selection : mapping
        A selection record (``model.selection``): ``method``, ``chosen``, ``units`` and
        ``candidates`` (:meth:`~cfbmarkov.markov.select.record.CandidateScore.as_dict`).

    Returns
    -------
    headers : list of str
        The first column is the mark (``*`` on the chosen candidate's row); then the state
        space, lag (s), states S, states visited in the fitting window, the score's parts
        (the criterion's: MD and the PD terms of the RTD criteria, the CK error), the score.
    rows : list of list of str
        One per candidate, lowest score first, those not judged last; "-" where a number
        is missing.
    notes : list of str
        What the score is (where a candidate was scored), and why the candidates not judged
        were not, once per reason.
    """
    kind = _kind(selection)
    chosen = selection.get("chosen", {})
    candidates = list(selection.get("candidates", []))
    scored = [c for c in candidates if c.get("score") is not None
              and math.isfinite(c["score"])]
    rest = [c for c in candidates if c not in scored]
    scored.sort(key=lambda c: c["score"])
    if kind == "ck":
        parts = ["CK error"]
        formula = ("score = CK error / CK error(cells), the lowest chosen; CK error = mean "
                   "|P_model(A -> B, t) - P_observed| over height thirds x core/annulus at "
                   "t = 2 to 20 lags, each block predicted by the model fitted on the others")
    elif kind == "window":
        parts = ["MD", "PD E(RT) %", "PD SD(RT) %"]
        formula = ("score = MD / MD(cells), the lowest chosen: the candidate's exact RTD "
                   "against the fitting window's; PD E(RT) and PD SD(RT) shown, not judged")
    else:
        units = selection.get("units", {})
        parts = ["PD E(RT) %", "PD SD(RT) %", "MD"]
        formula = (f"score = |PD E(RT)| / {_number(units.get('pd_rt_mean'), '.3g')} + "
                   f"|PD SD(RT)| / {_number(units.get('pd_rt_sd'), '.3g')} + MD / MD(cells), "
                   "the lowest chosen; each the mean over the held-out blocks")
    headers = ["", "states", "lag (s)", "S", "visited", *parts, "score"]
    rows, notes = [], [formula] if scored else []
    unjudged: dict[str, list[str]] = {}           # why -> the candidates, said once each
    for c in scored + rest:
        mark = "*" if (c.get("states"), c.get("lag")) == (chosen.get("states"),
                                                          chosen.get("lag")) else ""
        if kind == "ck":
            values = [_number(c.get("ck_error"), ".4f")]
        elif kind == "window":
            values = [_number(c.get("md_rtd"), ".3g"), _number(c.get("pd_rt_mean"), "+.1f"),
                      _number(c.get("pd_rt_sd"), "+.1f")]
        else:
            values = [_number(c.get("pd_rt_mean"), "+.1f"), _number(c.get("pd_rt_sd"), "+.1f"),
                      _number(c.get("md_rtd"), ".3g")]
        rows.append([mark, str(c.get("states", "")), _number(c.get("lag"), "g"),
                     _number(c.get("n_states"), "d"), _number(c.get("visited"), "d"),
                     *values, _number(c.get("score"), ".3g")])
        if c in rest:
            unjudged.setdefault(c.get("error") or "no held-out comparison", []).append(
                f"{c.get('states')} at lag {_number(c.get('lag'), 'g')} s")
    notes += [f"{', '.join(names)} not judged: {why}" for why, names in unjudged.items()]
    notes += _passed_over(scored, chosen)
    return headers, rows, notes


def _passed_over(scored: list, chosen: Mapping[str, Any]) -> list[str]:
    """Notes on the candidates that scored lower than the chosen one but were not chosen,
    more than half of their states never visited in the window
    (:func:`~cfbmarkov.markov.select.candidates.best_candidate`)."""
    best = next((c for c in scored if (c.get("states"), c.get("lag"))
                 == (chosen.get("states"), chosen.get("lag"))), None)
    if best is None:
        return []
    notes = []
    for c in scored:
        n, visited = c.get("n_states"), c.get("visited")
        if (c["score"] < best["score"] and n and visited is not None
                and n - visited > UNVISITED_LIMIT * n):
            notes.append(f"{c.get('states')} at lag {_number(c.get('lag'), 'g')} s not chosen "
                         f"despite its lower score: {n - visited} of its {n} states never "
                         f"visited in the window (more than {100 * UNVISITED_LIMIT:g} %), so "
                         "its chain rests on the few states seen")
    return notes


def candidate_table(selection: Mapping[str, Any]) -> list[str]:
    """The candidates of a selection record as fixed-width text lines (:func:`candidate_columns`).

    Parameters
    ----------
    selection : mapping
        A selection record (``model.selection``).

    Returns
    -------
    list of str
        The header, one line per candidate (``*`` marks the chosen one), then the notes;
        no lines for a record without candidates.
    """
    headers, rows, notes = candidate_columns(selection)
    if not rows:
        return []
    widths = [max(len(r[k]) for r in [headers, *rows]) for k in range(len(headers))]
    # names to the left, numbers to the right
    def line(cells):
        return "  ".join(cell.ljust(w) if k < 2 else cell.rjust(w)
                         for k, (cell, w) in enumerate(zip(cells, widths))).rstrip()
    return [line(headers), *(line(r) for r in rows), *notes]


__all__ = ["candidate_columns", "candidate_table"]
