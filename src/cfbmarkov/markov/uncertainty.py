"""The uncertainty of a fitted model's residence-time figures, as the model carries it.

A :class:`ModelUncertainty` holds the intervals at a stated level of the model's exact
E(RT), SD(RT) and RTD per bin, from its fitting window alone: a block bootstrap over time
blocks of the window plus the flow's variability between its blocks
(``docs/definitions.md``, The model's interval). It is computed in the analysis layer
(:func:`cfbmarkov.analysis.intervals.model_intervals`), held by the model
(:meth:`MarkovModel.with_uncertainty <cfbmarkov.markov.model.MarkovModel.with_uncertainty>`),
stored in the model file as the optional group ``uncertainty`` and shown beside the point
values by ``fit``, ``rtd`` and ``info``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfbmarkov._repr import compact_repr
from cfbmarkov.errors import InputError

#: the group of a model file that holds the uncertainty
GROUP = "uncertainty"


def bootstrap_widening(level: float, blocks: int, runs: int = 1) -> float:
    """The factor by which an interval's block-bootstrap half-widths are widened: the
    bootstrap's spread estimated from B blocks of each of R runs is a small-sample estimate
    of the standard error, with R (B - 1) degrees of freedom, and biased low.

    The block bootstrap's variance of a sum of B blocks drawn with replacement is
    (B - 1) / B times the unbiased estimate of the sum's variance from its B blocks, and
    that estimate has R (B - 1) degrees of freedom: an interval built on it takes Student's
    t quantile, not the normal one, as the batch-means method of simulation output
    analysis does. The factor is sqrt(B / (B - 1)) t_{R (B - 1)}(q) / z(q) at
    q = (1 + level) / 2: 1.175 for 10 blocks of one run at 90 %, 1.45 for 5 blocks.
    Measured on 200 independent runs of a known stationary chain
    (``benchmarks/interval_scatter.py --independent``): 90 % intervals from 10 blocks held
    the chain's E(RT) in 81.5 % (12 s runs) and 83.0 % (4 s) of the runs unwidened, 87.5 %
    in both widened; from 5 blocks 76.0 and 80.0 % unwidened, 91.0 and 90.5 % widened.

    Parameters
    ----------
    level : float
        The interval's level, in (0, 1).
    blocks : int
        Time blocks B of each run's fitting window (at least 2).
    runs : int, optional
        Runs R whose blocks are resampled within each (a pooled fit's stratified bootstrap).

    Returns
    -------
    float
        The factor (> 1).

    Raises
    ------
    InputError
        For fewer than 2 blocks or 1 run.

    References
    ----------
    B. Efron and R. J. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall (1993),
    Ch. 5.3 (the bootstrap standard error of a mean is sqrt((n - 1) / n) times the usual
    one); B. Schmeiser, "Batch size effects in the analysis of simulation output",
    Oper. Res. 30, 556 (1982) (Student's t with B - 1 degrees of freedom for B batch means).
    """
    blocks, runs = int(blocks), int(runs)
    if blocks < 2 or runs < 1:
        raise InputError(f"the bootstrap's widening needs at least 2 blocks and 1 run "
                         f"({blocks}, {runs})")
    from scipy.special import ndtri, stdtrit

    q = 0.5 * (1.0 + float(level))
    return float(np.sqrt(blocks / (blocks - 1.0)) * stdtrit(runs * (blocks - 1), q)
                 / ndtri(q))


def outward_bounds(lower: float, upper: float, digits: int = 3) -> tuple[str, str]:
    """An interval's bounds as text of ``digits`` significant digits, rounded outwards (the
    lower bound down, the upper up), so that the printed interval holds every value the
    stored one holds: [2.3593, 2.3940] prints as 2.35-2.40, not 2.36-2.39.

    Parameters
    ----------
    lower, upper : float
        The bounds, lower first.
    digits : int, optional
        Significant digits of each.

    Returns
    -------
    (str, str)
        The two bounds in ``g`` format with trailing zeros kept (``2.40``; ``0`` for a
        bound of 0).
    """
    def rounded(value: float, up: bool) -> str:
        if value == 0.0 or not np.isfinite(value):
            return f"{abs(value) if value == 0.0 else value:.{digits}g}"     # no "-0"
        exponent = digits - 1 - int(np.floor(np.log10(abs(value))))
        if abs(exponent) > 290:        # a scale that overflows (below ~1e-290): as it is
            return f"{value:.{digits}g}"
        scale = 10.0 ** exponent
        scaled = value * scale
        # a value already on the grid stays where it is: the product's round-off, a few
        # units in the last place of ``scaled``, never a unit of the last digit printed
        slack = min(16.0 * np.finfo(np.float64).eps * abs(scaled), 0.1)
        whole = np.ceil(scaled - slack) if up else np.floor(scaled + slack)
        return f"{whole / scale:#.{digits}g}".rstrip(".")   # trailing zeros kept: 2.40

    return rounded(float(lower), False), rounded(float(upper), True)


@dataclass(frozen=True, eq=False)     # == is identity, as for a MarkovModel (array fields)
class ModelUncertainty:
    """Intervals of a model's exact E(RT), SD(RT) and RTD per bin at ``level``.

    Attributes
    ----------
    level : float
        Coverage of the intervals, in (0, 1) (e.g. 0.9).
    rt_mean_interval, rt_sd_interval : (float, float)
        Lower and upper bound of E(RT) and SD(RT) (s).
    rtd_edges : ndarray of float64, shape (B + 1,)
        Edges of the RTD's bins (s).
    rtd_interval : ndarray of float64, shape (2, B)
        Lower and upper probability per bin.
    resamples : int
        Bootstrap resamples that gave a model with residences.
    blocks : int
        Time blocks of the fitting window in the bootstrap (a pooled fit's: of all its
        runs' windows, the same number in each).
    block_length : float
        Length of one block (s; a pooled fit's: mean over its runs).
    flow_sd : (float, float) or None
        The flow's relative standard deviations of E(RT) and SD(RT) between blocks of the
        window (fractions) added to the bootstrap's spread (a pooled fit's: between the
        blocks of all its runs, over sqrt(runs)); None where the window is too short to
        measure them (the intervals are then the bootstrap's alone).
    requested : int or None, optional
        Bootstrap resamples drawn (``resamples`` of them gave a model with residences);
        None where not recorded.
    flow_degrees_of_freedom : int or None, optional
        The degrees of freedom of ``flow_sd`` (the blocks compared less one): the interval
        multiplies it by Student's t quantile with them
        (:func:`cfbmarkov.analysis.bootstrap.flow_quantile`); None without ``flow_sd``, or
        where not recorded (the normal quantile).
    bootstrap_widening : float or None, optional
        The factor the bootstrap's distances to its quantiles were multiplied by for its
        blocks (:func:`bootstrap_widening`); None for an
        interval formed without it (a model file of an earlier cfbmarkov: its bootstrap
        part is that much too narrow, and :meth:`warnings` says so).

    Raises
    ------
    InputError
        If the level is not in (0, 1), a bound is not finite or lower above upper, or the
        RTD's arrays do not fit together.
    """

    __repr__ = compact_repr

    level: float
    rt_mean_interval: tuple[float, float]
    rt_sd_interval: tuple[float, float]
    rtd_edges: np.ndarray
    rtd_interval: np.ndarray
    resamples: int
    blocks: int
    block_length: float
    flow_sd: tuple[float, float] | None = None
    requested: int | None = None
    flow_degrees_of_freedom: int | None = None
    bootstrap_widening: float | None = None

    def __post_init__(self):
        if not 0.0 < float(self.level) < 1.0:
            raise InputError(f"interval level {self.level!r} must lie strictly between 0 and 1")
        for name in ("rt_mean_interval", "rt_sd_interval"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
                raise InputError(f"{name} ({lo}, {hi}) is not two finite bounds, lower first")
            object.__setattr__(self, name, (lo, hi))
        edges = np.array(self.rtd_edges, dtype=np.float64)
        band = np.array(self.rtd_interval, dtype=np.float64)
        if edges.ndim != 1 or edges.size < 2 or band.shape != (2, edges.size - 1):
            raise InputError(f"RTD interval of shape {band.shape} does not fit {edges.size} "
                             "bin edges")
        edges.setflags(write=False)
        band.setflags(write=False)
        object.__setattr__(self, "rtd_edges", edges)
        object.__setattr__(self, "rtd_interval", band)
        object.__setattr__(self, "level", float(self.level))
        if self.flow_sd is not None:
            object.__setattr__(self, "flow_sd", tuple(float(v) for v in self.flow_sd))
        if self.flow_degrees_of_freedom is not None:
            dof = int(self.flow_degrees_of_freedom)
            if dof < 1 or self.flow_sd is None:
                raise InputError(f"flow_degrees_of_freedom {self.flow_degrees_of_freedom!r}: "
                                 "a whole number >= 1, with flow_sd")
            object.__setattr__(self, "flow_degrees_of_freedom", dof)
        if self.bootstrap_widening is not None:
            widening = float(self.bootstrap_widening)
            if not (np.isfinite(widening) and widening >= 1.0):
                raise InputError(f"bootstrap_widening {self.bootstrap_widening!r}: a finite "
                                 "factor >= 1")
            object.__setattr__(self, "bootstrap_widening", widening)

    @property
    def percent(self) -> str:
        """The level as a percentage, e.g. ``'90'``."""
        return f"{100 * self.level:g}"

    def describe(self, mean: float, sd: float) -> str:
        """``E(RT) = 0.591 s (90 % interval 0.4102-0.8301 s), SD(RT) = ...`` for the point
        values ``mean`` and ``sd`` (s)."""
        (a, b), (c, d) = self.rt_mean_interval, self.rt_sd_interval
        return (f"E(RT) = {mean:.4g} s ({self.percent} % interval {self._bounds(a, b)}), "
                f"SD(RT) = {sd:.4g} s ({self.percent} % interval {self._bounds(c, d)})")

    @staticmethod
    def _bounds(lower: float, upper: float) -> str:
        """``0.4102-0.8301 s`` (4 significant digits like the point values, rounded
        outwards, :func:`outward_bounds`), or for a lower bound cut at 0
        (:meth:`cut_at_zero`) ``up to 0.8301 s, its lower end cut at 0``."""
        lo, hi = outward_bounds(lower, upper, digits=4)
        if lower > 0.0:
            return f"{lo}-{hi} s"
        return f"up to {hi} s, its lower end cut at 0"

    def cut_at_zero(self) -> list[str]:
        """Lines saying which interval's lower end fell to zero or below and was cut at 0,
        and why: the flow's variability between the fitting window's blocks, its quantile
        times it more than the figure itself (``flow_sd``), or else the bootstrap's spread
        below the figure (widened by ``bootstrap_widening``, the flow's term added), skewed
        resamples far below it or at 0 (``docs/definitions.md``, The model's interval).

        Returns
        -------
        list of str
            Empty where both lower bounds are above 0.
        """
        lines = []
        for k, (name, (lower, _)) in enumerate((("E(RT)", self.rt_mean_interval),
                                                ("SD(RT)", self.rt_sd_interval))):
            if lower > 0.0:
                continue
            flow = (self.flow_sd[k] * self.flow_multiplier()
                    if self.flow_sd is not None and self.flow_sd[k] > 0 else 0.0)
            if flow >= 1.0:
                why = (f"the flow's variability between the fitting window's blocks is "
                       f"{100 * self.flow_sd[k]:.3g} % of {name}, times "
                       f"{self.flow_multiplier_text()}: {100 * flow:.3g} %, so the "
                       "interval's lower half-width exceeds the figure itself")
            else:
                # the bootstrap's lower spread (widened), with any flow term in quadrature,
                # reaches the figure: a skewed bootstrap (a few resamples far below it, or at
                # 0); which it is, the quantiles alone would tell
                widened = (f", widened {self.bootstrap_widening:.3g} times for the few "
                           "blocks drawn," if self.bootstrap_widening
                           and self.bootstrap_widening > 1.0 else "")
                flow_text = (f" with the flow's variability between its blocks "
                             f"({100 * flow:.3g} % of {name} with its quantile) added"
                             if flow > 0 else "")
                why = (f"the spread of the bootstrap resamples' {name} below the figure"
                       f"{widened}{flow_text} exceeds the figure itself: the resamples are "
                       f"skewed, a few of them far below {name} (or at 0)")
            lines.append(f"the {self.percent} % interval of {name} reaches 0 and is cut "
                         f"there ({name} cannot be negative): {why}; the interval says only "
                         "that the figure lies below its upper end; a longer fitting "
                         "window narrows it where the flow is steady (more residences per "
                         "block), not where its blocks see different flows")
        return lines

    def flow_multiplier(self) -> float:
        """The quantile the flow's standard deviation is multiplied by in the interval:
        Student's t with :attr:`flow_degrees_of_freedom` at (1 + level) / 2, the normal one
        where they are not recorded (:func:`cfbmarkov.analysis.bootstrap.flow_quantile`)."""
        from scipy.special import ndtri, stdtrit

        p = 0.5 * (1.0 + self.level)
        dof = self.flow_degrees_of_freedom
        return float(ndtri(p)) if dof is None else float(stdtrit(dof, p))

    def flow_multiplier_text(self) -> str:
        """``Student's t = 6.31 with 1 degree of freedom`` or ``z = 1.64``:
        :meth:`flow_multiplier` as the lines about the interval name it."""
        dof = self.flow_degrees_of_freedom
        if dof is None:
            return f"z = {self.flow_multiplier():.3g}"
        return (f"Student's t = {self.flow_multiplier():.3g} with {dof} degree"
                f"{'' if dof == 1 else 's'} of freedom")

    def short_of_resamples(self) -> list[str]:
        """A line where fewer resamples than drawn gave a model with residences: the
        interval rests on those (the others' chains never pass the boundary), empty where
        all did or the count drawn was not recorded."""
        if self.requested is None or self.resamples >= self.requested:
            return []
        return [f"the {self.percent} % interval rests on {self.resamples} of the "
                f"{self.requested} bootstrap resamples drawn: the others' chains have no "
                "residence (their blocks hold too few passes through the boundary), so it "
                "describes the resamples that circulate and may be too narrow; a longer "
                "fitting window or pooled runs give more"]

    def not_widened(self, runs: int = 1) -> list[str]:
        """A line where the interval was formed without the bootstrap's widening for its
        blocks (:attr:`bootstrap_widening` None: a model file of an earlier cfbmarkov),
        naming the factor its bootstrap part lacks (:func:`bootstrap_widening` of its
        blocks per run, ``blocks`` being those of all ``runs`` runs of a pooled fit); empty
        otherwise."""
        runs = max(int(runs), 1)
        per_run = int(self.blocks) // runs
        if self.bootstrap_widening is not None or per_run < 2:
            return []
        factor = bootstrap_widening(self.level, per_run, runs)
        blocks = (f"{per_run} blocks" if runs == 1 else
                  f"{per_run} blocks in each of {runs} runs")
        return [f"the {self.percent} % interval was formed without the bootstrap's widening "
                f"for its {blocks} (a model file of an earlier cfbmarkov): its bootstrap "
                f"part is about {factor:.2f} times too narrow, so it holds the figure less "
                "often than stated; fit again, or form the interval anew with `cfbmarkov "
                f"rtd MODEL --level {self.level:g} --resamples {self.requested or self.resamples}`"]

    def warnings(self, runs: int = 1) -> list[str]:
        """Every line on the interval: :meth:`cut_at_zero`, :meth:`short_of_resamples` and
        :meth:`not_widened` (``runs``: the runs of a pooled fit)."""
        return self.cut_at_zero() + self.short_of_resamples() + self.not_widened(runs)

    def to_dict(self) -> dict:
        """JSON-serialisable: level, the intervals, the RTD's edges and bounds, resamples,
        blocks, block length, the flow's relative SDs and their degrees of freedom (null
        where none), the bootstrap's widening (null where the interval was formed without
        it)."""
        return {"level": self.level, "rt_mean_interval": list(self.rt_mean_interval),
                "rt_sd_interval": list(self.rt_sd_interval),
                "rtd_edges": self.rtd_edges.tolist(),
                "rtd_interval": self.rtd_interval.tolist(), "resamples": int(self.resamples),
                "blocks": int(self.blocks), "block_length": float(self.block_length),
                "flow_sd": None if self.flow_sd is None else list(self.flow_sd),
                "flow_degrees_of_freedom": self.flow_degrees_of_freedom,
                "requested": self.requested, "bootstrap_widening": self.bootstrap_widening}

    def file_fields(self) -> dict[str, np.ndarray]:
        """The datasets that store it, named ``uncertainty/<field>``."""
        flow = (np.nan, np.nan) if self.flow_sd is None else self.flow_sd
        fields = {"level": self.level, "rt_mean_interval": self.rt_mean_interval,
                  "rt_sd_interval": self.rt_sd_interval, "rtd_edges": self.rtd_edges,
                  "rtd_interval": self.rtd_interval, "resamples": int(self.resamples),
                  "blocks": int(self.blocks), "block_length": float(self.block_length),
                  "flow_sd": flow}
        if self.requested is not None:
            fields["requested"] = int(self.requested)
        if self.flow_degrees_of_freedom is not None:
            fields["flow_degrees_of_freedom"] = int(self.flow_degrees_of_freedom)
        if self.bootstrap_widening is not None:
            fields["bootstrap_widening"] = float(self.bootstrap_widening)
        return {f"{GROUP}/{name}": np.asarray(value) for name, value in fields.items()}

    @classmethod
    def from_group(cls, group) -> "ModelUncertainty | None":
        """The uncertainty stored in a model group (None where the group has none).

        Raises
        ------
        KeyError, InputError
            If the group is there but incomplete or invalid (the model file reader reports
            it as a damaged file).
        """
        if GROUP not in group:
            return None
        g = group[GROUP]
        flow = np.asarray(g["flow_sd"][()], dtype=np.float64)
        return cls(float(g["level"][()]), tuple(g["rt_mean_interval"][()]),
                   tuple(g["rt_sd_interval"][()]), g["rtd_edges"][()], g["rtd_interval"][()],
                   int(g["resamples"][()]), int(g["blocks"][()]), float(g["block_length"][()]),
                   None if np.isnan(flow).any() else (float(flow[0]), float(flow[1])),
                   int(g["requested"][()]) if "requested" in g else None,
                   int(g["flow_degrees_of_freedom"][()]) if "flow_degrees_of_freedom" in g
                   else None,
                   float(g["bootstrap_widening"][()]) if "bootstrap_widening" in g else None)
