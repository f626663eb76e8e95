"""The scales and cases of a reproduction (``cfbmarkov reproduce``): the paper's riser and
times (``paper``), and a reduced riser that keeps the paper's particles, gas, hold-up, cell
size and contact-time resolution (``quick``, see :data:`QUICK_REDUCTIONS`).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, Iterable

from pydantic import ValidationError

from cfbmarkov.config import CaseConfig, describe_validation_error, load_case
from cfbmarkov.errors import InputError


VELOCITIES = (3.0, 4.0, 6.0, 8.0)
#: the models of a reproduction: the paper's (cells, Eq. 2-4), cells with the pooled MLE, and
#: the state space and lag chosen from the fitting window (cfbmarkov.markov.select)
MODELS = ("paper", "mle", "auto")


@dataclass(frozen=True)
class Scale:
    """A set of changes applied to the paper's cases (nested dict, as in a case TOML).

    Attributes
    ----------
    name : str
        The scale's name (``paper``, ``quick``).
    description : str
        One line for the manifest and the report.
    overrides : dict
        Changes to every case, as nested tables of a case file.
    reductions : tuple of str
        What the scale reduces against the paper, and why.
    by_velocity : tuple of (float, dict)
        Further changes to the cases at and above a velocity (m/s), applied in order after
        ``overrides``.
    """

    name: str
    description: str
    overrides: dict[str, Any] = field(default_factory=dict)
    reductions: tuple[str, ...] = ()
    by_velocity: tuple[tuple[float, dict[str, Any]], ...] = ()

    def overrides_at(self, velocity: float) -> dict[str, Any]:
        """The changes to the paper's case at ``velocity`` (m/s).

        Parameters
        ----------
        velocity : float
            Superficial gas velocity U, m/s.

        Returns
        -------
        dict
            ``overrides``, then each entry of ``by_velocity`` whose velocity U reaches.
        """
        out = self.overrides
        for threshold, changes in self.by_velocity:
            if velocity >= threshold:
                out = _merge(out, changes)
        return out


#: The quick scale's reductions and their reasons (shown in the docs and the report).
QUICK_REDUCTIONS = (
    "riser 0.04 m x 0.30 m instead of 0.09 m x 0.95 m, with 3789 particles instead of 27000: "
    "the same solids hold-up (16.5 % by volume in the pseudo-2D cells), so the drag on a "
    "particle in the suspension (Wen & Yu's voidage factor) is the paper's and at 3 and "
    "4 m/s the solids are carried only where they gather, with back-mixing along the walls; "
    "40 particle diameters across still leave a core and two wall layers",
    "gas cells of 10 mm x 10 mm as in the paper (4 x 30 cells)",
    "contact springs 4 times softer (kn 2500 N/m, kt 714 N/m) and a DEM step twice as long "
    "(1e-5 s): a contact still takes 5.2 DEM steps as in the paper, and restitution and "
    "friction are unchanged; overlaps at a given impact velocity are twice the paper's "
    "(1.7 % of d at 1 m/s instead of 0.8 %)",
    "from 5 m/s 0-3 s of CFD-DEM, the model fitted on 1-2 s and compared on 2-3 s: in the "
    "shorter riser the flow develops within a second (the solids' mean velocity is steady "
    "from 0.5 s at 6 m/s and from 0.75 s at 8 m/s) and residence times are a third of the "
    "paper's or less; at 3 m/s 0-4.5 s, fitted on 2.5-3.5 s and compared on 3.5-4.5 s: from "
    "rest the gas first lifts the solids for about 2.5 s, after which they fall, so both "
    "windows must lie in that developed flow; at 4 m/s 0-7 s, fitted on 4-5.5 s and compared "
    "on 5.5-7 s: there the net flow of the solids is small against their up and down passes "
    "(a dense layer falls along one wall while the other side rises) and turns now and then "
    "for up to 1.5 s (at 3-4.5 s and 2.5-3 s in two of four runs from different seeds), so "
    "1 s windows at 2.5-4.5 s could see opposite flows, which no model fitted on the first "
    "can predict; over both 1.5 s windows from 4 s on it rose in every run",
    "4 x 12 cells of 10 mm x 25 mm (the paper's row height); below 5 m/s frames, lag and "
    "RTD bins of 0.01 s (a mean residence time of 0.2-0.5 s spans 20-50 lags, the paper's "
    "56 at 3 m/s), from 5 m/s of 0.002 s, from 7 m/s of 0.001 s: at 8 m/s the solids cross "
    "the 0.30 m in about 0.056 s, nearly as a plug, so the RTD must be binned this finely to "
    "span ten bins or more (at 0.01 s it spanned four, at 0.002 s 13 for the CFD-DEM and "
    "10 for the automatic model in one run, at 0.001 s 27 for the CFD-DEM and 63-66 for "
    "the models), and a "
    "mean residence time spans about 56 lags instead of the paper's 9",
    "from 5 m/s a neighbour-list skin of 0.8 mm instead of 0.4 mm: the fast solids cross the "
    "0.4 mm skin's half in a few DEM steps and the list was rebuilt that often (the skin "
    "changes which pairs are listed, never which touch: the speed only, and the round-off)",
)

#: from this velocity (m/s) the quick scale runs 0-7 s, fitted on 4-5.5 s, compared on 5.5-7 s
#: (below :data:`QUICK_FINE_FROM`; see :data:`QUICK_REDUCTIONS`)
QUICK_LONG_FROM = 4.0
#: from this velocity (m/s) the quick scale's frames, lag and RTD bins are 0.002 s
QUICK_FINE_FROM = 5.0
#: from this velocity (m/s) the quick scale's frames, lag and RTD bins are 0.001 s
QUICK_FINEST_FROM = 7.0

SCALES: dict[str, Scale] = {
    "paper": Scale("paper", "the paper's riser: 27000 particles, 0.09 m x 0.95 m, 0-20 s, "
                   "fitted on 10-15 s, compared on 15-20 s, 6 x 38 cells, lag 0.025 s"),
    "quick": Scale(
        "quick", "a reduced riser (3789 particles, 0.04 m x 0.30 m; at 3 m/s 0-4.5 s, at 4 m/s "
        "0-7 s, both with lag 0.01 s; from 5 m/s 0-3 s and lag 0.002 s, from 7 m/s 0.001 s) "
        "that runs the whole pipeline in minutes on 2 cores",
        {"riser": {"width": 0.04, "height": 0.30},
         "particles": {"number": 3789},
         "contact": {"normal_stiffness": 2500.0, "tangential_stiffness": 714.25},
         "numerics": {"cfd_cells": [4, 30], "dem_cells": [13, 100], "dem_time_step": 1e-5},
         "output": {"end_time": 4.5, "frame_interval": 0.01},
         "markov": {"columns": 4, "rows": 12, "lag": 0.01, "fit_window": [2.5, 3.5],
                    "predict_window": [3.5, 4.5]}},
        QUICK_REDUCTIONS,
        ((QUICK_LONG_FROM, {"output": {"end_time": 7.0},
                            "markov": {"fit_window": [4.0, 5.5], "predict_window": [5.5, 7.0]}}),
         (QUICK_FINE_FROM, {"output": {"end_time": 3.0, "frame_interval": 0.002},
                            "numerics": {"dem_skin": 8e-4},
                            "markov": {"lag": 0.002, "fit_window": [1.0, 2.0],
                                       "predict_window": [2.0, 3.0]}}),
         (QUICK_FINEST_FROM, {"output": {"frame_interval": 0.001}, "markov": {"lag": 0.001}}))),
}


# -- cases -------------------------------------------------------------------------------------
def case_name(velocity: float) -> str:
    """Folder name of a velocity: 6.0 -> 'u6', 2.5 -> 'u2.5'.

    Parameters
    ----------
    velocity : float
        Superficial gas velocity U, m/s.

    Returns
    -------
    str
    """
    return f"u{velocity:g}"


def _merge(base: dict, changes: dict) -> dict:
    out = dict(base)
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def as_scale(scale: str | Scale) -> Scale:
    """The :class:`Scale` named ``scale`` (``paper`` or ``quick``), or ``scale`` itself.

    Raises
    ------
    InputError
        For an unknown name.
    """
    if isinstance(scale, Scale):
        return scale
    if scale not in SCALES:
        raise InputError(f"unknown scale '{scale}': choose one of {', '.join(SCALES)}")
    return SCALES[scale]


def scale_cases(scale: str | Scale = "quick", velocities: Iterable[float] = VELOCITIES,
                overrides: dict[str, Any] | None = None) -> list[CaseConfig]:
    """The cases of a scale at the given velocities.

    The paper's case at each velocity (``paper-u<U>``, or ``paper-u6`` with U replaced),
    changed by the scale and then by ``overrides``.

    Parameters
    ----------
    scale : str or Scale, optional
        A name in :data:`SCALES` or a scale.
    velocities : iterable of float, optional
        Superficial gas velocities U, m/s.
    overrides : dict, optional
        Changes to every case (nested tables of a case file).

    Returns
    -------
    list of CaseConfig
        One case per velocity, named ``<scale>-u<U>``.

    Raises
    ------
    InputError
        For an unknown scale name, no velocities, a velocity that is not finite and
        positive, or changes that make an invalid configuration.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Section 2.
    """
    scale = as_scale(scale)
    cases = []
    velocities = [float(u) for u in velocities]
    if not velocities:
        raise InputError("no velocities given")
    for key, option in ((("gas", "superficial_velocity"), "--velocities"),
                        (("name",), "the case names, <scale>-u<U>")):
        table = overrides or {}
        for part in key[:-1]:
            table = table.get(part, {}) if isinstance(table, dict) else {}
        if isinstance(table, dict) and key[-1] in table:
            raise InputError(f"overrides may not set {'.'.join(key)}: a reproduction sets it "
                             f"per case ({option}); leave it out of the overrides file")
    for u in velocities:
        if not (math.isfinite(u) and u > 0):
            raise InputError(f"velocity {u:g} m/s must be positive")
        name = f"paper-u{u:g}"
        try:
            base = load_case(name)
        except InputError:
            base = load_case("paper-u6")
        data = _merge(json.loads(base.model_dump_json()), {
            "name": f"{scale.name}-{case_name(u)}", "gas": {"superficial_velocity": u}})
        data = _merge(_merge(data, scale.overrides_at(u)), overrides or {})
        try:
            cases.append(CaseConfig.model_validate(data))
        except ValidationError as exc:   # one line
            where, message = describe_validation_error(exc)
            raise InputError(f"invalid configuration at '{where}' for U = {u:g} m/s: "
                             f"{message}") from None
        problem = cases[-1].reproduction_problem()
        if problem is not None:
            raise InputError(f"invalid configuration at 'markov' for U = {u:g} m/s: {problem}")
        from cfbmarkov.simulate.run import check_periodic_case

        try:
            check_periodic_case(cases[-1])
        except InputError as exc:
            raise InputError(f"invalid configuration for U = {u:g} m/s: "
                             f"{exc}") from None
    return cases


def load_overrides(path: str | os.PathLike) -> dict[str, Any]:
    """A TOML file of changes to apply to every case (same tables as a case file).

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file.

    Returns
    -------
    dict
        The nested tables.

    Raises
    ------
    InputError
        When the file cannot be read, is not UTF-8 text or valid TOML, or sets nothing.
    """
    from cfbmarkov._toml import read_toml

    return read_toml(path, "overrides file", "a TOML file with the tables of a case file "
                     "to change, e.g. [output] end_time = 10.0")
