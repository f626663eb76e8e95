"""The selection record: how every candidate fared and why one was chosen.

:class:`CandidateScore` holds one candidate's numbers; :func:`selection_record` and
:func:`kept_cells_record` form the dict stored in the chosen model
(:meth:`~cfbmarkov.markov.model.MarkovModel.with_selection`, saved with it as JSON).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from cfbmarkov.markov.select.blocks import MIN_RESIDENCES

if TYPE_CHECKING:
    from cfbmarkov.markov.select.criteria import Criterion, HeldOutCK


@dataclass(frozen=True)
class CandidateScore:
    """How one candidate (state space x lag) fared in the cross-validation.

    Attributes
    ----------
    states : str
        Name of the state space (:func:`~cfbmarkov.markov.spaces.state_space_from_name`).
    lag : float
        The lag (s).
    n_states : int
        Number of states S.
    rt_mean, rt_sd : float
        The model's windowed E(RT) and SD(RT) (s), averaged over the blocks (NaN under
        the CK criterion).
    pd_rt_mean, pd_rt_sd : float
        Percentage differences (%) of E(RT) and SD(RT) from the held-out blocks, averaged
        with their signs.
    md_rtd : float
        Mean Minkowski distance (p = 2) between the model's and the held-out RTD
        histograms.
    score : float
        The criterion (lower is better; inf where the candidate failed).
    error : str
        Why the candidate could not be judged ("" if it could).
    ck_error : float
        Held-out Chapman-Kolmogorov error (the criterion when residences are too few).
    visited : int or None
        States occupied in some frame of the fitting window (at the candidate's lag); None
        where the candidate could not be discretised.
    """

    states: str
    lag: float
    n_states: int
    rt_mean: float
    rt_sd: float
    pd_rt_mean: float
    pd_rt_sd: float
    md_rtd: float
    score: float
    error: str = ""
    # held-out Chapman-Kolmogorov error (the criterion when residences are too few)
    ck_error: float = math.nan
    visited: int | None = None

    def as_dict(self) -> dict[str, Any]:
        """The fields as a JSON-serialisable dict (non-finite numbers as None)."""
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in self.__dict__.items()}


def selection_record(criterion: Criterion, estimator: str, best: CandidateScore,
                     candidates: list[CandidateScore], lag: float) -> dict[str, Any]:
    """The record of a choice: the criterion, the judged blocks, every candidate, the reason.

    Parameters
    ----------
    criterion : Criterion
        The criterion that judged, with its judged blocks.
    estimator : str
        The estimator of every candidate.
    best : CandidateScore
        The chosen candidate.
    candidates : list of CandidateScore
        Every candidate, in the order tried.
    lag : float
        The base lag, s (the paper's cells at this lag are quoted beside the choice).

    Returns
    -------
    dict
        ``method``, ``blocks`` ([start, stop] s), ``observed`` (``rt_mean``, ``rt_sd`` s and
        ``rt_count`` of each judged block), ``direction``, ``estimator``, ``chosen``
        (``states``, ``lag``), ``units`` (of the PD terms, %), ``reason`` and
        ``candidates`` (:meth:`CandidateScore.as_dict`).
    """
    fitting = criterion.fitting
    cells = next((c for c in candidates if math.isfinite(c.score) and c.states == "cells"
                  and c.lag == lag), None)
    unit_mean, unit_sd = criterion.units
    return {"method": criterion.method(),
            "blocks": [list(x) for x in fitting.judged],
            "observed": [{"rt_mean": o.mean, "rt_sd": o.sd, "rt_count": o.count}
                         for o in fitting.observed],
            "direction": fitting.direction,
            "estimator": estimator, "chosen": {"states": best.states, "lag": best.lag},
            # undefined units (a criterion on the window judges no PD) as None, not NaN:
            # the record is stored as strict JSON and reads back the same
            "units": {"pd_rt_mean": _defined(unit_mean), "pd_rt_sd": _defined(unit_sd)},
            "reason": criterion.reason(best, cells) + _passed_over(best, candidates),
            "candidates": [c.as_dict() for c in candidates]}


def _defined(value):
    """``value``, or None where it is a non-finite float."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


def _passed_over(best: CandidateScore, candidates) -> str:
    """The words that qualify a choice where a lower-scored candidate was passed over for
    leaving too many of its states never visited (:func:`~cfbmarkov.markov.select.
    candidates.best_candidate`); empty where the chosen one scored lowest."""
    from cfbmarkov.markov.selection_table import UNVISITED_LIMIT, too_sparse

    lower = [c for c in candidates if math.isfinite(c.score) and c.score < best.score
             and too_sparse(c, UNVISITED_LIMIT)]
    if not lower:
        return ""
    names = ", ".join(f"{c.states} (score {c.score:.3g}, {c.n_states - c.visited} of "
                      f"{c.n_states} states never visited)" for c in lower)
    return (f"; closest among the candidates whose states the window visits: {names} "
            f"scored lower but leaves more than {100 * UNVISITED_LIMIT:g} % of its states "
            "never visited")


def kept_cells_record(criterion: HeldOutCK, estimator: str, candidates: list[CandidateScore],
                      lag: float) -> dict[str, Any]:
    """The record where the held-out CK test could judge no candidate: the paper's cells kept.

    Parameters
    ----------
    criterion : HeldOutCK
        The held-out Chapman-Kolmogorov criterion, with its judged blocks.
    estimator : str
        The estimator.
    candidates : list of CandidateScore
        Every candidate, none judged.
    lag : float
        The base lag, s.

    Returns
    -------
    dict
        ``method``, ``blocks``, ``estimator``, ``chosen``, ``reason`` and ``candidates``.
    """
    fitting = criterion.fitting
    if fitting.fewest < MIN_RESIDENCES:
        why = (f"the blocks of the fitting window are too short to judge: a block holds only "
               f"{fitting.fewest} residence times (fewer than {MIN_RESIDENCES}) and is "
               f"shorter than the CK test's {criterion.times.max():g} s")
    else:       # the blocks were long enough: every candidate failed for its own reason
        errors = list(dict.fromkeys(f"{c.states}: {c.error}" for c in candidates if c.error))
        why = ("no candidate could be judged by the CK test on the fitting window's blocks ("
               + "; ".join(errors[:3]) + ("; ..." if len(errors) > 3 else "") + ")")
    return {"method": f"{fitting.folds}-fold blocked cross-validation",
            "blocks": [list(x) for x in fitting.blocks], "estimator": estimator,
            "chosen": {"states": "cells", "lag": lag},
            "reason": f"{why}, so the paper's cells were kept",
            "candidates": [c.as_dict() for c in candidates]}
