"""``--states auto``: choose the state space and lag from the fitting window alone.

The fitting window [A, B] is split in time: the models are fitted on its first part
[A, A + (1 - h)(B - A)] and judged on the held-out rest (h = ``holdout``, default 1/3) by
how well they predict what matters downstream, the residence-time distribution seen in a
window of the held-out length. For every candidate (state space x lag) the exact windowed
RTD of the model (:meth:`MarkovModel.rtd`, no Monte Carlo noise) is set against the
residence times observed in the held-out frames (SPEC section 3):

    score = |PD E(RT)| / 2 % + |PD SD(RT)| / 10 % + MD / MD(cells)

i.e. the errors in units of the project's goal for them (2 % and 10 %) plus the Minkowski
distance relative to that of the paper's state space on the same data, so that every term
is about 1 at the edge of what is acceptable. The candidate with the lowest score wins and
is refitted on the whole window; the model records every candidate's numbers and why it
was chosen (``model.selection``, saved with it).

Nothing outside the fitting window is used, so the choice can be checked on the prediction
window afterwards without fooling oneself.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from cfbmarkov.analysis.metrics import minkowski_distance, percentage_difference
from cfbmarkov.analysis.rtd import residence_times, rtd_histogram
from cfbmarkov.errors import CfbmarkovError, InputError
from cfbmarkov.markov.estimate import estimator_from_name
from cfbmarkov.markov.states import state_space_from_name
from cfbmarkov.trajectories import Trajectories

#: state spaces tried by default (names of :func:`state_space_from_name`)
DEFAULT_STATES = ("cells", "cells-direction", "cells-velocity", "cells-previous")
#: lags tried, in multiples of the base lag
DEFAULT_LAG_MULTIPLES = (1, 2)
#: fewer residence times than this in the held-out part: keep the paper's cells
MIN_RESIDENCES = 30


@dataclass(frozen=True)
class CandidateScore:
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

    def as_dict(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in self.__dict__.items()}


def _exact_histogram(rtd, bin_width: float, n_bins: int) -> np.ndarray:
    index = np.floor(rtd.times / bin_width + 1e-6).astype(np.int64)
    keep = (index >= 0) & (index < n_bins)
    counts = np.bincount(index[keep], weights=rtd.probability[keep], minlength=n_bins)
    total = counts.sum()
    return counts / total if total > 0 else counts


def select_model(data, *, window: tuple[float, float], columns: int, rows: int, lag: float,
                 states: Sequence[str] = DEFAULT_STATES,
                 lag_multiples: Sequence[int] = DEFAULT_LAG_MULTIPLES,
                 estimator: str = "mle", holdout: float = 1.0 / 3.0):
    """Choose, fit on ``window`` and return the best model (see the module doc); its
    ``selection`` attribute holds the candidates' scores and the reason."""
    if not 0.0 < holdout < 1.0:
        raise InputError(f"held-out fraction {holdout:g} must lie between 0 and 1")
    a, b = (float(v) for v in window)
    own = not isinstance(data, Trajectories)
    traj = Trajectories(data) if own else data
    try:
        step = lag * max(int(m) for m in lag_multiples)      # the split on a whole lag
        split = a + max(1, round((1.0 - holdout) * (b - a) / step)) * step
        if not split < b:
            raise InputError(f"auto: the fitting window {a:g}-{b:g} s is too short to hold "
                             "out a part of it")
        held = (float(split), b)
        observed = residence_times(traj, held)
        if observed.count < MIN_RESIDENCES:
            space = state_space_from_name("cells", columns, rows, traj.width, traj.height, lag)
            model = estimator_from_name(estimator, space, lag).fit(traj, window=(a, b))
            return model.with_selection({
                "method": "held-out RTD", "fit": [a, float(split)], "held_out": list(held),
                "estimator": estimator, "chosen": {"states": "cells", "lag": lag},
                "reason": f"the held-out part {held[0]:g}-{b:g} s holds {observed.count} "
                          f"residence times (fewer than {MIN_RESIDENCES}): too few to choose, "
                          "so the paper's cells were kept",
                "candidates": []})
        length = b - held[0]
        _, p_observed = rtd_histogram(observed.samples, lag, window_length=length)
        n_bins = p_observed.size
        scores: list[CandidateScore] = []
        md_cells = math.nan
        for name in states:
            for multiple in lag_multiples:
                tau = lag * int(multiple)
                space = state_space_from_name(name, columns, rows, traj.width, traj.height, tau)
                try:
                    model = estimator_from_name(estimator, space, tau).fit(
                        traj, window=(a, float(split)))
                    rtd = model.rtd(window=length)
                except (InputError, CfbmarkovError) as exc:
                    scores.append(CandidateScore(name, tau, space.n_states, math.nan, math.nan,
                                                 math.nan, math.nan, math.nan, math.inf,
                                                 str(exc)))
                    continue
                md = minkowski_distance(p_observed, _exact_histogram(rtd, lag, n_bins), 2.0)
                if name == "cells" and multiple == 1:
                    md_cells = md
                scores.append(CandidateScore(
                    name, tau, space.n_states, rtd.mean, rtd.sd,
                    percentage_difference(rtd.mean, observed.mean),
                    percentage_difference(rtd.sd, observed.sd), md, math.nan))
        reference_md = md_cells if math.isfinite(md_cells) and md_cells > 0 else 1.0
        final = []
        for s in scores:
            if s.error:
                final.append(s)
                continue
            value = abs(s.pd_rt_mean) / 2.0 + abs(s.pd_rt_sd) / 10.0 + s.md_rtd / reference_md
            final.append(CandidateScore(**{**s.__dict__, "score": float(value)}))
        usable = [s for s in final if math.isfinite(s.score)]
        if not usable:
            raise InputError("auto: no candidate state space could be fitted: "
                             + "; ".join(f"{s.states} lag {s.lag:g}: {s.error}" for s in final))
        best = min(usable, key=lambda s: s.score)
        space = state_space_from_name(best.states, columns, rows, traj.width, traj.height,
                                      best.lag)
        model = estimator_from_name(estimator, space, best.lag).fit(traj, window=(a, b))
    finally:
        if own:
            traj.close()
    cells = next((s for s in usable if s.states == "cells" and s.lag == lag), None)
    reason = (f"{best.states} at lag {best.lag:g} s had the lowest score {best.score:.3g} on "
              f"the held-out {held[0]:g}-{b:g} s (E(RT) {best.pd_rt_mean:+.1f} %, SD(RT) "
              f"{best.pd_rt_sd:+.1f} %, MD {best.md_rtd:.3g}")
    reason += (f"; cells: {cells.pd_rt_mean:+.1f} %, {cells.pd_rt_sd:+.1f} %, MD "
               f"{cells.md_rtd:.3g}, score {cells.score:.3g})" if cells is not None else ")")
    selection = {"method": "held-out RTD", "fit": [a, float(split)], "held_out": list(held),
                 "observed": {"rt_mean": observed.mean, "rt_sd": observed.sd,
                              "rt_count": observed.count},
                 "estimator": estimator, "chosen": {"states": best.states, "lag": best.lag},
                 "reason": reason, "candidates": [s.as_dict() for s in final]}
    return model.with_selection(selection)


def parse_model_name(name: str) -> tuple[str, str]:
    """A model's name in a reproduction -> (state space, estimator): ``paper`` and ``mle``
    are the paper's cells with that estimator, ``auto`` is :func:`select_model`, and
    ``STATES`` or ``STATES:ESTIMATOR`` names a state space (estimator ``mle`` by default)."""
    from cfbmarkov.markov.estimate import ESTIMATORS
    from cfbmarkov.markov.states import STATE_SPACES

    if name in ESTIMATORS:
        return "cells", name
    if name == "auto":
        return "auto", "mle"
    states, _, estimator = name.partition(":")
    estimator = estimator or "mle"
    if states not in STATE_SPACES or estimator not in ESTIMATORS:
        raise InputError(f"unknown model '{name}': use paper, mle, auto, or STATES[:ESTIMATOR] "
                         f"with STATES in {', '.join(STATE_SPACES)} and ESTIMATOR in "
                         f"{', '.join(ESTIMATORS)}")
    return states, estimator


def fit_by_name(name: str, data, *, window: tuple[float, float], columns: int, rows: int,
                lag: float):
    """Fit the model ``name`` (see :func:`parse_model_name`) on ``window`` of ``data``."""
    states, estimator = parse_model_name(name)
    if states == "auto":
        return select_model(data, window=window, columns=columns, rows=rows, lag=lag,
                            estimator=estimator)
    own = not isinstance(data, Trajectories)
    traj = Trajectories(data) if own else data
    try:
        space = state_space_from_name(states, columns, rows, traj.width, traj.height, lag)
        return estimator_from_name(estimator, space, lag).fit(traj, window=window)
    finally:
        if own:
            traj.close()


def selection_json(model) -> str:
    return json.dumps(getattr(model, "selection", None) or {}, indent=2)


__all__ = ["DEFAULT_LAG_MULTIPLES", "DEFAULT_STATES", "CandidateScore", "fit_by_name",
           "parse_model_name", "select_model", "selection_json"]
