"""The verdict on a model's fitting sample: whether the window (or the pooled windows) could
carry the model (``docs/definitions.md``, Sample adequacy).

The verdict is computed by :func:`cfbmarkov.analysis.adequacy.assess_adequacy` (it fits
models on parts of the window and reads the trajectories); the model holds it as its
``adequacy`` attribute, stores it in its file as the JSON attribute ``adequacy`` and
repeats its lines among :meth:`~cfbmarkov.markov.model.MarkovModel.warnings`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from cfbmarkov.errors import InputError


#: the largest |PD| of E(RT) or SD(RT) of a chain on its own fitting window without a
#: warning (:meth:`Adequacy.on_window_warning`): a chain on the cells of a flow that is a
#: chain on those cells misses its window by about 1 % (tests/analysis/test_adequacy.py),
#: the paper's cells on the synthetic and the paper-scale 3 m/s flows miss SD(RT) by
#: 47-48 %, the tutorial's automatic choice by 3 %
ON_WINDOW_LIMIT = 0.25

#: how :meth:`Adequacy.on_window_warning` ends for a state space the user named
CARRY_ADVICE = ("a state space with memory may carry it (`fit --states auto` compares them on "
                "this window)")

#: ... and for one chosen among others on this window (``fit --states auto``,
#: ``select_model``), which the same choice would give again: what is left is the grid and
#: the amount of flow
CHOSEN_CARRY_ADVICE = ("its state space was chosen among others on this window (`fit "
                       "--states auto`, select_model): finer --cells (more columns keep a "
                       "downflowing wall layer apart from the rising core) or more flow (a "
                       "longer window, several runs pooled) may carry it")

#: the keys of the verdict's ``on_fitting_window`` (JSON), in :attr:`Adequacy.on_window`'s order
ON_WINDOW_KEYS = ("window_length", "rt_mean", "rt_sd", "observed_rt_mean", "observed_rt_sd",
                  "residences")


@dataclass(frozen=True)
class Adequacy:
    """Whether a model's fitting sample can carry it, in numbers.

    Attributes
    ----------
    warnings : tuple of str
        One line per problem found (empty: none), each with its numbers and what to do.
    parts : tuple of (float, float, float, str)
        Per part of the fitting window (its halves, or its quarters where they hold enough
        residences): start (s), stop (s), the E(RT) (s) of the model fitted on it with the
        same estimator and states (NaN where none could be), and the net solids flow
        direction over it ("up" or "down"). Several runs: the parts of each in turn.
    rt_mean : float
        The fitted model's exact E(RT) (s; NaN where it has none).
    spread : float
        (largest - smallest) E(RT) of the parts over ``rt_mean`` (-; NaN with fewer than two
        parts that have one).
    limit : float
        The relative width of the model's E(RT) interval where one was given, else the
        default tolerance (-): what :attr:`part_limit`, the spread the parts are judged
        against, is formed from (the name kept for the files that store it).
    window_length : float
        Length of the fitting window (s; the shortest where several runs were pooled).
    tail_share : float
        The model's exact RTD mass beyond ``window_length``: the share of residences a
        window of this length cannot contain (-; NaN without an RTD).
    runs : tuple of (str, float)
        A pooled fit's runs and the E(RT) (s; NaN where none) of the model fitted on each
        alone; empty for one run.
    window_rt_mean : float
        The fitting window's own E(RT) from its net solids flux (particle-time over net
        passes, several runs' summed; s): NaN for an open riser, a file with absent
        particles, or a verdict stored without it.
    part_limit : float
        The spread (-) beyond which one run's parts (as judged: halves or quarters) disagree,
        the limit the warning compares with
        (:func:`cfbmarkov.analysis.adequacy.parts_limit`); NaN for a pooled fit or a
        verdict stored without it.
    on_window : tuple of float
        The chain against its own fitting window (a periodic riser; several runs' windows
        of one length pooled; empty otherwise, or for a verdict stored without it): (window
        length W s, the chain's E(RT) and SD(RT) as a W s window sees it from the window's
        first frame, s, the E(RT) and SD(RT) of the residences the window holds whole, s,
        and their count). The sample's verdict does not judge it; beyond
        :data:`ON_WINDOW_LIMIT` it is the model's warning (:meth:`on_window_warning`;
        ``docs/definitions.md``, Sample adequacy).
    runs_limit : float
        A pooled fit's limit (-): the distance of a run's own model's E(RT) from the pooled
        model's, relative, beyond which the run is named (NaN for one run, or a verdict
        stored without it).
    runs_interval : bool
        Whether :attr:`runs_limit` came from the model's interval (the runs' own
        uncertainty); False where it is the default tolerance, with no interval to tell
        the runs' differences from their sampling (``--resamples 0``).
    throughput_limit : float
        The relative distance from :attr:`window_rt_mean` beyond which the model's E(RT)
        was warned of (-): 10 %, or more for a window whose cut through the particles'
        laps makes its net passes uncertain
        (:func:`cfbmarkov.analysis.adequacy.throughput_limit`); NaN without a throughput
        or for a verdict stored without it (then 10 %).
    """

    warnings: tuple[str, ...] = ()
    parts: tuple[tuple[float, float, float, str], ...] = ()
    rt_mean: float = math.nan
    spread: float = math.nan
    limit: float = math.nan
    window_length: float = math.nan
    tail_share: float = math.nan
    runs: tuple[tuple[str, float], ...] = ()
    window_rt_mean: float = math.nan
    part_limit: float = math.nan
    on_window: tuple[float, ...] = ()
    runs_limit: float = math.nan
    runs_interval: bool = True
    throughput_limit: float = math.nan

    def on_window_line(self) -> str | None:
        """The chain against its fitting window, one line of numbers (None without it):
        PD = 100 (chain - observed) / observed (Eq. 8 of the paper, as ``compare`` gives
        it) of its RTD as the window sees it against the residences the window holds
        whole."""
        if len(self.on_window) != 6:
            return None
        length, mean, sd, seen_mean, seen_sd, count = self.on_window
        if not (seen_mean > 0 and seen_sd > 0 and all(map(math.isfinite, (mean, sd)))):
            return None
        pd_mean = 100.0 * (mean - seen_mean) / seen_mean
        pd_sd = 100.0 * (sd - seen_sd) / seen_sd
        held = "the runs' windows hold" if self.runs else "the window holds"
        return (f"on its fitting window: the chain's E(RT) {mean:.3g} s (PD {pd_mean:+.1f} %), "
                f"SD(RT) {sd:.3g} s (PD {pd_sd:+.1f} %) as a {length:g} s window sees it, "
                f"against the {int(count)} residences {held} whole (E(RT) "
                f"{seen_mean:.3g} s, SD(RT) {seen_sd:.3g} s): how well the chain carries the "
                "data it was fitted on")

    def on_window_warning(self, limit: float = ON_WINDOW_LIMIT,
                          advice: str = CARRY_ADVICE) -> str | None:
        """One warning line where the chain misses its own fitting window (:attr:`on_window`)
        by more than ``limit`` (relative) in E(RT) or SD(RT), else None.

        A chain that cannot carry the data it was fitted on misses other windows of the
        flow at least as much, whatever the sample's verdict; its interval is the chain's
        sampling alone and does not cover that miss. The line is the model's, not the
        sample's: it is not among :attr:`warnings` and leaves :attr:`adequate` as it is.

        Parameters
        ----------
        limit : float, optional
            Relative, default :data:`ON_WINDOW_LIMIT`.
        advice : str, optional
            What the line ends with: what may carry the window (:data:`CARRY_ADVICE`; for a
            state space ``fit --states auto`` chose, :data:`CHOSEN_CARRY_ADVICE`, as
            :func:`~cfbmarkov.markov.model_summary.on_window_warning` picks it).

        Returns
        -------
        str or None
        """
        if len(self.on_window) != 6:
            return None
        length, mean, sd, seen_mean, seen_sd, count = self.on_window
        misses = []
        for name, chain, seen in (("E(RT)", mean, seen_mean), ("SD(RT)", sd, seen_sd)):
            if seen > 0 and math.isfinite(chain) and abs(chain - seen) > limit * seen:
                side = "above" if chain > seen else "below"
                misses.append(f"its {name} {chain:.3g} s lies {100 * abs(chain - seen) / seen:.0f} "
                              f"% {side} the window's {seen:.3g} s")
        if not misses:
            return None
        held = (f"the {int(count)} residences the {len(self.runs)} runs' windows hold whole"
                if self.runs else f"its {int(count)} residences held whole")
        return (f"the chain does not carry its own fitting window: as a {length:g} s window "
                f"sees it, {' and '.join(misses)} ({held}; "
                f"limit {100 * limit:g} %): the model's figures and their interval are the "
                f"chain's, and the flow's may lie far from them; {advice}")

    @property
    def adequate(self) -> bool:
        """True where no warning was raised."""
        return not self.warnings

    def passed_line(self) -> str | None:
        """Where the verdict raised no warning, one line with the numbers it judged (one
        run's parts' spread against its limit, times sqrt(2) for quarters; the chain's E(RT)
        against the window's throughput; the residences longer than the window), so that a
        passed verdict reads as such and not as one that was not run; None where it warned.

        Returns
        -------
        str or None
        """
        if self.warnings:
            return None
        said = []
        if math.isfinite(self.spread) and math.isfinite(self.limit) and not self.runs:
            # one run: the limit its parts were judged against (a verdict stored without
            # it: quarters against the limit times sqrt(2), as they were judged then)
            quarters = len(self.parts) == 4
            limit = (self.part_limit if math.isfinite(self.part_limit)
                     else self.limit * (math.sqrt(2.0) if quarters else 1.0))
            said.append(f"the window's {'quarters' if quarters else 'halves'} agree (E(RT) "
                        f"spread {100 * self.spread:.2g} %, limit {100 * limit:.2g} %)")
        alone = [m for _, m in self.runs if math.isfinite(m)]
        if alone and math.isfinite(self.rt_mean) and self.rt_mean > 0:
            # a pooled fit: each run's model against the pool's, and the parts' spread
            furthest = max(abs(m / self.rt_mean - 1.0) for m in alone)
            within = (f"; each within {100 * furthest:.2g} % of the pooled model's, limit "
                      f"{100 * self.runs_limit:.2g} %" if math.isfinite(self.runs_limit)
                      else "")
            figures = (f"E(RT) fitted on each alone {', '.join(f'{m:#.3g}' for m in alone)} "
                       f"s, pooled {self.rt_mean:#.3g} s{within}"
                       + (f"; their parts' spread {100 * self.spread:.2g} %"
                          if math.isfinite(self.spread) else ""))
            if self.runs_interval:
                said.append(f"the {len(self.runs)} runs agree ({figures})")
            else:
                said.append(f"the {len(self.runs)} runs are not judged against their own "
                            f"uncertainty ({figures}: without an interval, the default "
                            "tolerance alone, which cannot tell the runs' differences from "
                            "their sampling; give --resamples to judge them)")
        if math.isfinite(self.window_rt_mean) and math.isfinite(self.rt_mean):
            gap = abs(self.rt_mean / self.window_rt_mean - 1.0)
            said.append(f"the chain carries the window's throughput (within {100 * gap:.2g} %)")
        if math.isfinite(self.tail_share):
            share = 100 * self.tail_share
            said.append(f"{f'{share:.2g} %' if share >= 0.1 else 'under 0.1 %'} of its "
                        "residences outlast the window")
        # `stationarity` reads no periodic file with absent particles, whose window has no
        # throughput figure (NaN, as an open riser's and an older verdict's): not named there
        shown_by = ("`cfbmarkov stationarity` on a longer run, or runs pooled, show"
                    if math.isfinite(self.window_rt_mean) else "a longer run, or runs pooled, show")
        alone_note = ("" if self.runs else
                      " (judged on this window alone: a flow that changes over longer times "
                      f"than it can lie elsewhere, which {shown_by})")
        return ("the fitting sample's verdict: no warning" +
                (f": {'; '.join(said)}" if said else "") + alone_note)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as None): the attributes, ``parts`` as a list of objects.

        Returns
        -------
        dict
        """
        def number(v):
            return float(v) if v is not None and math.isfinite(v) else None
        return {"warnings": list(self.warnings),
                "parts": [{"window": [float(a), float(b)], "rt_mean": number(m),
                           "direction": d} for a, b, m, d in self.parts],
                "rt_mean": number(self.rt_mean), "spread": number(self.spread),
                "limit": number(self.limit), "window_length": number(self.window_length),
                "tail_share": number(self.tail_share),
                "runs": [{"run": r, "rt_mean": number(m)} for r, m in self.runs],
                "window_rt_mean": number(self.window_rt_mean),
                "part_limit": number(self.part_limit),
                "on_fitting_window": (None if len(self.on_window) != 6 else dict(zip(
                    ON_WINDOW_KEYS, (number(v) for v in self.on_window)))),
                "runs_limit": number(self.runs_limit), "runs_interval": bool(self.runs_interval),
                "throughput_limit": number(self.throughput_limit)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "Adequacy":
        """The verdict from :meth:`to_dict`'s form.

        Parameters
        ----------
        data : dict

        Returns
        -------
        Adequacy

        Raises
        ------
        InputError
            If ``data`` does not have that form.
        """
        def number(v):
            return math.nan if v is None else float(v)
        try:
            return cls(tuple(str(w) for w in data.get("warnings", [])),
                       tuple((float(p["window"][0]), float(p["window"][1]),
                              number(p.get("rt_mean")), str(p.get("direction", "up")))
                             for p in data.get("parts", [])),
                       number(data.get("rt_mean")), number(data.get("spread")),
                       number(data.get("limit")), number(data.get("window_length")),
                       number(data.get("tail_share")),
                       tuple((str(r["run"]), number(r.get("rt_mean")))
                             for r in data.get("runs", [])),
                       number(data.get("window_rt_mean")), number(data.get("part_limit")),
                       tuple(number(data["on_fitting_window"][k]) for k in ON_WINDOW_KEYS)
                       if data.get("on_fitting_window") else (),
                       number(data.get("runs_limit")), bool(data.get("runs_interval", True)),
                       number(data.get("throughput_limit")))
        except (TypeError, ValueError, KeyError, IndexError, AttributeError) as exc:
            raise InputError(f"adequacy attribute is not a verdict ({exc})") from None

    def to_attr(self) -> str:
        """The verdict as the model file's JSON attribute ``adequacy``."""
        return json.dumps(self.to_dict(), allow_nan=False)

    @classmethod
    def from_attr(cls, text: str | bytes) -> "Adequacy":
        """The verdict from the model file's attribute (:meth:`to_attr`).

        Raises
        ------
        InputError
            If the attribute is not such JSON.
        """
        if isinstance(text, bytes):
            text = text.decode(errors="replace")
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"adequacy attribute is not JSON ({exc.msg})") from None
        if not isinstance(data, dict):
            raise InputError("adequacy attribute is not a JSON object")
        return cls.from_dict(data)
