"""Kinetics of particle properties: what each particle carries and how it changes
(``docs/definitions.md``, Properties along particle paths; ``docs/how-to/kinetics.md``).

A :class:`Kinetics` is a tuple of :class:`Property` (a name, a rate law, its parameters per
cell, where the property starts and its start value). :meth:`Kinetics.per_state` resolves
the parameters on a model's state space into a :class:`StateKinetics`: per state the rate
k and limit v_inf of every linear law and, over a lag, the exact affine maps.
:func:`load_kinetics` reads a kinetics file (TOML).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from cfbmarkov._repr import compact_repr
from cfbmarkov.errors import InputError
from cfbmarkov.limits import check_finite
from cfbmarkov.kinetics.fields import (FIELDS, ByCell, CellFields, CellParameter, Constant,
                                       FromField, wall_cells)
from cfbmarkov.kinetics.laws import LAWS, Custom, HeatExchange, Law, affine_map

#: where a property starts: reset at each entry through the inlet (a fresh feed), carried
#: across passes (a circulating inventory), or the reference's values at the start
STARTS = ("entry", "carried", "reference")


#: names a property cannot take: the arrays ``export-vtk`` writes beside the properties
RESERVED_NAMES = ("id", "lap", "colour_group", "speed", "velocity", "points")


@dataclass(frozen=True)
class Property:
    """One scalar carried by every particle.

    Attributes
    ----------
    name : str
        Its name (a dataset name in prediction files: letters, digits, ``_``, ``-``).
    law : Law
        Its rate law.
    parameters : Mapping of str to CellParameter
        Each of ``law.parameter_names``, per cell.
    start : {"entry", "carried", "reference"}
        ``entry``: the value resets to ``initial`` at each entry through the inlet (open
        riser) or pass up through the top that starts a residence (periodic riser);
        ``carried``: a particle keeps its value across passes (a circulating inventory);
        ``reference``: the particles present at the start take the reference's values, the
        entering ones ``initial``.
    initial : float
        The value at entry (and of every particle at the start of a Monte Carlo run without
        reference values).

    Raises
    ------
    InputError
        For a bad name, start, a parameter missing or unknown, a constant or per-cell table
        value below 0 where the law needs it >= 0 (a value from a cell field is checked
        when the fields are known), or a start value that is not finite or lies outside the
        law's range (a conversion in [0, 1], an activity >= 0).
    """

    name: str
    law: Law
    parameters: Mapping[str, CellParameter]
    start: str = "entry"
    initial: float | None = None

    def __post_init__(self):
        if not (isinstance(self.name, str) and self.name
                and all(c.isalnum() or c in "_-" for c in self.name)):
            raise InputError(f"property name {self.name!r}: use letters, digits, _ and -")
        if self.name.lower() in RESERVED_NAMES:
            raise InputError(f"property name {self.name!r} is the name of an array the "
                             f"particle files carry ({', '.join(RESERVED_NAMES)}); choose "
                             "another")
        if self.start not in STARTS:
            raise InputError(f"property {self.name}: start {self.start!r} is not one of "
                             f"{', '.join(STARTS)}")
        if not isinstance(self.law, Law):
            what = (f"the class {self.law.__name__}" if isinstance(self.law, type)
                    else repr(self.law))
            raise InputError(f"property {self.name}: law {what} is not a law; give one, such "
                             f"as FirstOrder() or LAWS['first-order']() (laws: "
                             f"{', '.join(LAWS)}, or Custom(...))")
        if not isinstance(self.parameters, Mapping):
            raise InputError(f"property {self.name}: parameters as a dict of name to "
                             "Constant(...), ByCell(...) or FromField(...)")
        names = set(self.law.parameter_names)
        given = set(self.parameters)
        if names - given:
            unknown = sorted(given - names)
            raise InputError(f"property {self.name}: law {self.law.key} needs "
                             f"{', '.join(sorted(names - given))}"
                             + (f" (given {', '.join(unknown)}, which it takes no: a misspelt "
                                "name?)" if unknown else ""))
        if given - names:
            extra = sorted(given - names)
            # a setting of the law itself (HeatExchange(wall_temperature=...)), which a
            # kinetics file gives beside the parameters
            settings = ({f.name for f in dataclasses.fields(self.law)}
                        if dataclasses.is_dataclass(self.law) else set())
            own = [k for k in extra if k in settings]
            raise InputError(f"property {self.name}: law {self.law.key} takes no "
                             f"{', '.join(extra)} as a parameter"
                             + (f"; give it to the law: {type(self.law).__name__}("
                                + ", ".join(f"{k}=..." for k in own) + ")" if own else ""))
        initial = self.initial
        if initial is None:
            initial = (self.law.initial if isinstance(self.law, Custom)
                       else self.law.default_initial)
        try:
            if initial is None:
                raise InputError("no start value")
            check_finite(initial, "initial")
        except InputError:
            raise InputError(f"property {self.name}: give its finite start value as a number, "
                             "initial = ... (the feed's value), "
                             + ("none is given" if initial is None else f"not {initial!r}")
                             ) from None
        low, high = getattr(self.law, "initial_range", (None, None))
        if (low is not None and float(initial) < low) or (high is not None
                                                          and float(initial) > high):
            span = f"[{low:g}, {high:g}]" if high is not None else f"[{low:g}, inf)"
            raise InputError(f"property {self.name}: initial = {float(initial):g} is outside "
                             f"{span}, the range of {self.law.quantity} (law {self.law.key}); "
                             f"give a start value in {span}")
        object.__setattr__(self, "initial", float(initial))
        parameters = {}
        for key, value in self.parameters.items():     # a plain number: a constant
            if isinstance(value, numbers.Real) and not isinstance(value, bool):
                value = Constant(float(value))
            if not isinstance(value, CellParameter):
                raise InputError(f"property {self.name}: parameter {key} = {value!r} is a "
                                 f"{type(value).__name__}; give a number, Constant(...), "
                                 "ByCell(...) or FromField(...) (cfbmarkov.kinetics)")
            if isinstance(value, ByCell) and value.key == "value_by_cell":
                value = dataclasses.replace(value, key=key)     # messages name the parameter
            table = np.asarray(value.table) if isinstance(value, ByCell) else None
            low = (value.value if isinstance(value, Constant) else
                   min(value.dense, value.dilute) if isinstance(value, FromField) else
                   float(np.nanmin(table[:, -1])) if table is not None and table.ndim == 2
                   and table.shape[1] in (3, 4) and table.shape[0] else None)
            if low is not None and low < 0 and key not in self.law.signed_parameters():
                raise InputError(f"property {self.name}: {key} {low:g} < 0; rates and "
                                 "coefficients must be >= 0")
            parameters[key] = value
        object.__setattr__(self, "parameters", parameters)
        wall = getattr(self.law, "wall_temperature", None)
        if wall is not None and isinstance(parameters.get("temperature"), ByCell):
            raise InputError(f"property {self.name}: wall_temperature would replace the wall "
                             "cells' values of the temperature table; give the wall cells' "
                             "own in the table, or a constant temperature beside "
                             "wall_temperature")

    def per_cell(self, space, fields: CellFields | None = None,
                 without_fields: bool = False) -> dict[str, np.ndarray]:
        """Each parameter per cell of ``space``'s grid, checked (float64 [C] each).

        ``without_fields`` leaves out the parameters given as a function of a cell field
        (a check of the others against a grid before any cell field exists).

        Raises
        ------
        InputError
            If a value is not finite, or negative where the law needs it >= 0.
        """
        out = {}
        signed = self.law.signed_parameters()
        for name in self.law.parameter_names:
            if without_fields and isinstance(self.parameters[name], FromField):
                continue
            value = self.parameters[name].per_cell(space, fields)
            if not np.all(np.isfinite(value)):
                cell = int(np.flatnonzero(~np.isfinite(value))[0])
                m, d = space.columns, space.depth_columns
                at = (f"col {cell % m}, row {cell // (m * d)}"
                      + (f", depth {cell // m % d}" if d > 1 else ""))
                raise InputError(f"property {self.name}: {name} is {value[cell]:g} in the cell "
                                 f"{at}; give a finite value in every cell")
            if name not in signed and value.min() < 0:
                raise InputError(f"property {self.name}: {name} {value.min():g} < 0; rates "
                                 "and coefficients must be >= 0")
            out[name] = value
        return out

    def describe(self) -> dict:
        """The property as JSON-serialisable text."""
        return {"name": self.name, **self.law.describe(), "start": self.start,
                "initial": self.initial,
                "parameters": {k: v.describe() for k, v in self.parameters.items()}}


@dataclass(frozen=True)
class StateKinetics:
    """The kinetics resolved on a state space: per property and state.

    Attributes
    ----------
    names : tuple of str
        The properties' names (P).
    starts : tuple of str
        Their start rules.
    initial : ndarray of float64, shape (P,)
        Their values at entry.
    linear : ndarray of bool, shape (P,)
        Whether each law is a linear relaxation.
    rate, target : ndarray of float64, shape (P, S)
        k_s (1/s) and v_inf,s of the linear laws (NaN rows for a custom law).
    parameters : tuple of ndarray of float64, shape (S, q)
        Each property's parameters per state (columns in the law's order).
    laws : tuple of Law
        The laws.
    source : str, optional
        The kinetics file they came from, for messages.
    state_space : StateSpace, optional
        The state space they were resolved on (:meth:`Kinetics.per_state` records it);
        :meth:`on` refuses them on another.
    """

    __repr__ = compact_repr

    names: tuple
    starts: tuple
    initial: np.ndarray
    linear: np.ndarray
    rate: np.ndarray
    target: np.ndarray
    parameters: tuple
    laws: tuple
    source: str = ""
    state_space: object = None

    def on(self, state_space) -> "StateKinetics":
        """These kinetics, checked to be resolved on ``state_space`` (a model's).

        Parameters
        ----------
        state_space : StateSpace

        Returns
        -------
        StateKinetics
            ``self``.

        Raises
        ------
        InputError
            If they were resolved on another state space, or hold another number of
            states.
        """
        n = int(state_space.n_states)
        if self.state_space is not None and self.state_space != state_space:
            raise InputError(f"kinetics resolved on "
                             f"{self.state_space.describe_against(state_space)}, not on the "
                             f"model's {state_space.describe()}: resolve them with "
                             "kinetics.per_state(model.state_space, model.cell_fields), or pass "
                             "the Kinetics itself")
        if self.rate.shape[-1] != n or any(np.shape(q)[0] != n for q in self.parameters):
            raise InputError(f"kinetics resolved on {self.rate.shape[-1]} states, not on the "
                             f"model's {n}: resolve them with kinetics.per_state("
                             "model.state_space, model.cell_fields), or pass the Kinetics "
                             "itself")
        return self

    @property
    def n_properties(self) -> int:
        """Number of properties P."""
        return len(self.names)

    def over(self, lag: float) -> tuple[np.ndarray, np.ndarray]:
        """The exact affine maps of one lag, v' = a_s v + b_s, of every linear law.

        Parameters
        ----------
        lag : float
            The lag (s).

        Returns
        -------
        a, b : ndarray of float64, shape (P, S)
            a = exp(-k_s lag), b = v_inf,s (1 - a) (NaN rows for a custom law).
        """
        return affine_map(self.rate, self.target, lag)

    def index(self, name: str) -> int:
        """Position of the property ``name``.

        Raises
        ------
        InputError
            If there is none of that name.
        """
        if name not in self.names:
            raise InputError(f"no property {name!r} (the kinetics has "
                             f"{', '.join(self.names)})")
        return self.names.index(name)


@dataclass(frozen=True)
class Kinetics:
    """The properties every particle carries, in order.

    Attributes
    ----------
    properties : tuple of Property
        At least one, with distinct names.
    source : str
        Where it came from (a file name), for messages.

    Raises
    ------
    InputError
        If there is no property or two share a name.
    """

    properties: tuple
    source: str = ""

    def __post_init__(self):
        if isinstance(self.properties, Property):
            raise InputError("kinetics: give the properties as a tuple, "
                             "Kinetics((Property(...),)), not one Property")
        props = tuple(self.properties)
        if any(not isinstance(p, Property) for p in props):
            raise InputError("kinetics: every item must be a Property(name, law, parameters)")
        if not props:
            raise InputError(f"{self.source or 'kinetics'}: no property; add a [[property]] "
                             "table")
        names = [p.name for p in props]
        if len(set(names)) != len(names):
            raise InputError(f"{self.source or 'kinetics'}: two properties are named "
                             f"{next(n for n in names if names.count(n) > 1)!r}; give each "
                             "[[property]] a name of its own")
        object.__setattr__(self, "properties", props)

    @property
    def names(self) -> tuple[str, ...]:
        """The properties' names."""
        return tuple(p.name for p in self.properties)

    @property
    def linear(self) -> bool:
        """Whether every law is a linear relaxation (exact answers exist)."""
        return all(p.law.linear for p in self.properties)

    def check_cells(self, state_space) -> None:
        """Check the parameters given as constants or per-cell tables against a grid, before
        any run: a table of another grid, a missing or repeated cell, a value that is not
        finite or negative where it must not be. Parameters given as a function of a cell
        field are checked where :meth:`per_state` resolves them.

        Parameters
        ----------
        state_space : StateSpace
            A state space on the grid the kinetics will be resolved on.

        Raises
        ------
        InputError
            One line naming the file, the property and the fix.
        """
        for prop in self.properties:
            try:
                prop.per_cell(state_space, None, without_fields=True)
            except InputError as exc:
                raise InputError(f"{self.source}: {exc}" if self.source else str(exc)) from None

    def per_state(self, state_space, cell_fields: CellFields | None = None) -> StateKinetics:
        """Resolve the parameters on a state space (cells to states through
        ``state_space.cell_of_state``).

        Parameters
        ----------
        state_space : StateSpace
            The model's states.
        cell_fields : CellFields, optional
            The fitting window's time-averaged cell fields, for parameters given as a
            function of them.

        Returns
        -------
        StateKinetics

        Raises
        ------
        InputError
            If a table does not fit the grid, a parameter is negative or not finite, or
            cell fields are needed but not given.
        """
        cell = np.asarray(state_space.cell_of_state, dtype=np.int64)
        wall = wall_cells(state_space)
        s = cell.size
        p = len(self.properties)
        rate = np.full((p, s), np.nan)
        target = np.full((p, s), np.nan)
        params = []
        for i, prop in enumerate(self.properties):
            try:
                values = prop.per_cell(state_space, cell_fields)
            except InputError as exc:
                raise InputError(f"{self.source}: {exc}" if self.source else str(exc)) from None
            params.append(np.stack([values[n][cell] for n in prop.law.parameter_names], axis=1)
                          if values else np.zeros((s, 0)))
            if prop.law.linear:
                k, v_inf = prop.law.relaxation(values, wall)
                rate[i], target[i] = k[cell], v_inf[cell]
                largest = max(float(np.max(np.abs(target[i]), initial=0.0)),
                              abs(float(prop.initial)))
                if largest > MAX_VALUE:
                    where = f"{self.source}: " if self.source else ""
                    raise InputError(
                        f"{where}property {prop.name}: a value of {largest:.3g} (its "
                        f"initial value or a cell's limit) lies beyond {MAX_VALUE:g}, where "
                        "the exit SD's squares overflow; give the values in other units")
        for arr in (rate, target):
            arr.setflags(write=False)
        return StateKinetics(self.names, tuple(pr.start for pr in self.properties),
                             np.array([pr.initial for pr in self.properties]),
                             np.array([pr.law.linear for pr in self.properties]),
                             rate, target, tuple(params),
                             tuple(pr.law for pr in self.properties), self.source,
                             state_space)

    def grid_notes(self, state_space) -> tuple[str, ...]:
        """Warnings on a heat exchange's ``wall_temperature`` where every cell of the grid
        touches a wall (a 3D grid of one or two depth columns: its front and back walls
        take every cell), so that ``temperature`` is used nowhere.

        Parameters
        ----------
        state_space : StateSpace
            The model's states (their grid's cells).

        Returns
        -------
        tuple of str
            One line each, naming the property and what to do.
        """
        wall = wall_cells(state_space)
        if not wall.all():
            return ()
        depth = int(getattr(state_space, "depth_columns", 1) or 1)
        why = (f"its {depth} depth column{'s put' if depth > 1 else ' puts'} every cell at "
               "the front or back wall" if getattr(state_space, "depth", None) is not None
               else f"its {state_space.columns} columns put every cell at a side wall")
        return tuple(
            f"property {prop.name}: every cell of the grid touches a wall ({why}), so "
            "wall_temperature applies everywhere and temperature nowhere; fit on a grid "
            "with cells away from the walls (more columns or depth columns, or COLUMNSxROWS)"
            for prop in self.properties
            if isinstance(prop.law, HeatExchange) and prop.law.wall_temperature is not None)

    def field_notes(self, cell_fields: CellFields | None) -> tuple[str, ...]:
        """Warnings on the parameters given as a function of a cell field: where the solids
        fraction is a relative count (a fitting file without the particle diameter), and
        where the threshold puts every cell seen on one side (the parameter is then one
        value everywhere).

        Parameters
        ----------
        cell_fields : CellFields or None
            The fitting window's cell fields (None: no notes).

        Returns
        -------
        tuple of str
            One line each, naming the property, the key and what to do.
        """
        if cell_fields is None:
            return ()
        notes = []
        for prop in self.properties:
            for name, parameter in prop.parameters.items():
                if not isinstance(parameter, FromField):
                    continue
                value = cell_fields.field(parameter.field)
                seen = value[np.isfinite(value)]
                if not seen.size:
                    continue
                span = f"{seen.min():.3g}-{seen.max():.3g}"
                what = f"property {prop.name}: {parameter.key} = {parameter.field!r}"
                if parameter.field == "solids_fraction" and cell_fields.relative:
                    notes.append(f"{what} reads each cell's particle count relative to the "
                                 f"bed's mean (here {span}; 1 the mean), the fitting file "
                                 "giving no particle diameter: give the threshold on that "
                                 "scale, or fit on a file that stores the particle diameter")
                above = FIELDS[parameter.field] == "above"
                dense = seen >= parameter.threshold if above else seen <= parameter.threshold
                if dense.all() or not dense.any():
                    side, used = (("dense", parameter.dense) if dense.all()
                                  else ("dilute", parameter.dilute))
                    notes.append(f"{what}: threshold {parameter.threshold:g} puts every cell "
                                 f"on the {side} side ({parameter.field} {span} over the cells "
                                 f"seen), so {name} is {used:g} everywhere; give a threshold "
                                 f"({name}_threshold for this parameter alone) inside that "
                                 "range to tell the zones apart")
        return tuple(notes)

    def describe(self) -> list[dict]:
        """The properties as JSON-serialisable text."""
        return [p.describe() for p in self.properties]


_PROPERTY_KEYS = {"name", "law", "start", "initial", "threshold"}


def on_states(kinetics, state_space, cell_fields: CellFields | None = None) -> StateKinetics:
    """Kinetics resolved on a model's state space: a :class:`Kinetics` resolved
    (:meth:`Kinetics.per_state`), a :class:`StateKinetics` checked (:meth:`StateKinetics.on`).

    Parameters
    ----------
    kinetics : Kinetics or StateKinetics
    state_space : StateSpace
        The model's states.
    cell_fields : CellFields, optional
        The fitting window's cell fields, for parameters given as a function of them.

    Returns
    -------
    StateKinetics

    Raises
    ------
    InputError
        If ``kinetics`` is neither, was resolved on another state space, or does not resolve
        (:meth:`Kinetics.per_state`).
    """
    if isinstance(kinetics, Kinetics):
        return kinetics.per_state(state_space, cell_fields)
    if isinstance(kinetics, StateKinetics):
        return kinetics.on(state_space)
    raise InputError(f"kinetics: a Kinetics (load_kinetics(path), or Kinetics((Property(...), "
                     f"...))) or its StateKinetics, not {type(kinetics).__name__}")


def load_kinetics(path: str | os.PathLike) -> Kinetics:
    """Read a kinetics file (TOML; ``docs/how-to/kinetics.md``).

    One ``[[property]]`` table per scalar: ``name``, ``law`` (``first-order``,
    ``deactivation``, ``heat-exchange``), each parameter of the law (``rate``; for heat
    exchange ``coefficient`` and ``temperature``, and optionally ``wall_temperature``) as a
    constant (``rate = 0.4``), a per-cell table (``rate_by_cell = "rates.csv"``, columns
    ``col,row[,depth],rate`` -- or ``value`` -- relative to the kinetics file) or a
    function of a cell field (``rate_from = "solids_fraction"``, ``rate_dense``,
    ``rate_dilute`` and ``threshold``, or ``rate_threshold`` where two parameters of one
    property need different thresholds), ``start`` (``entry``, ``carried``, ``reference``;
    default ``entry``) and ``initial`` (the value at entry).

    Parameters
    ----------
    path : str or os.PathLike
        The kinetics file.

    Returns
    -------
    Kinetics

    Raises
    ------
    InputError
        One line naming the file, the key and the fix: a file that cannot be read or
        parsed, an unknown law or key, a missing parameter, a negative or non-finite value,
        a bad table.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(f"load_kinetics({path!r}): give the path of a kinetics file (TOML); "
                         "a Kinetics built in Python needs no loading")
    path = Path(path)
    name = str(path)
    try:
        data = tomllib.loads(path.read_bytes().decode("utf-8-sig"))   # an editor's BOM too
    except OSError as exc:
        raise InputError(f"cannot read kinetics file {name}: {exc.strerror or exc} (give the "
                         "path of a TOML file of [[property]] tables, relative to the folder "
                         "the command runs in)") from None
    except UnicodeDecodeError:
        from cfbmarkov._toml import binary_kind

        what = binary_kind(path)
        if what.startswith("text"):
            raise InputError(f"kinetics file {name} is {what}; save it as UTF-8 (a TOML file "
                             "of [[property]] tables)") from None
        raise InputError(f"kinetics file {name} is not text ({what}): give the TOML file of "
                         "[[property]] tables (--kinetics kin.toml)") from None
    except tomllib.TOMLDecodeError as exc:
        from cfbmarkov._toml import SYNTAX_FIX

        raise InputError(f"kinetics file {name} is not valid TOML: {exc}; {SYNTAX_FIX}") \
            from None
    unknown = set(data) - {"property"}
    if unknown:
        raise InputError(f"{name}: unknown key {sorted(unknown)[0]!r}; a kinetics file holds "
                         "[[property]] tables only")
    tables = data.get("property")
    if isinstance(tables, dict):
        raise InputError(f"{name}: a single [property] table; write it [[property]] (double "
                         "brackets: an array of tables, one per property)")
    if not isinstance(tables, list) or not tables:
        raise InputError(f"{name}: no [[property]] table; add one per property")
    props = [_property(t, i, path) for i, t in enumerate(tables)]
    return Kinetics(tuple(props), name)


def _property(table, index: int, path: Path) -> Property:
    where = f"{path} [[property]] {index + 1}"
    if not isinstance(table, dict):
        raise InputError(f"{where}: not a table")
    if isinstance(table.get("name"), str):
        where = f"{path} property {table['name']!r}"
    for key in ("name", "law"):
        if not isinstance(table.get(key), str):
            choices = f" (one of {', '.join(LAWS)})" if key == "law" else ""
            # a misspelt key names itself: the keys no law takes
            known = set(_PROPERTY_KEYS) | {"wall_temperature"} | {
                f"{p}{suffix}" for law in LAWS.values() for p in law().parameter_names
                for suffix in ("", "_by_cell", "_from", "_dense", "_dilute", "_threshold")}
            stray = sorted(k for k in table if k not in known)
            also = f"; unknown key {', '.join(map(repr, stray))}" if stray else ""
            given = (f" (a text in quotes: {key} = {table[key]!r} is not)" if key in table
                     else "")
            raise InputError(f"{where}: give {key} = \"...\"{given}{choices}{also}")
    law_key = table["law"]
    if law_key not in LAWS:
        raise InputError(f"{where}: unknown law {law_key!r}; use one of {', '.join(LAWS)}")
    law_cls = LAWS[law_key]
    if law_cls is HeatExchange:
        wall = table.get("wall_temperature")
        if wall is not None and not _finite(wall):
            raise InputError(f"{where}: wall_temperature must be a finite number")
        law = HeatExchange(None if wall is None else float(wall))
    else:
        if "wall_temperature" in table:
            raise InputError(f"{where}: wall_temperature is for law heat-exchange only")
        law = law_cls()
    allowed = set(_PROPERTY_KEYS) | ({"wall_temperature"} if law_cls is HeatExchange else set())
    for p in law.parameter_names:
        allowed.update((p, f"{p}_by_cell", f"{p}_from", f"{p}_dense", f"{p}_dilute",
                        f"{p}_threshold"))
    # an unknown key first: a misspelt parameter is named as such, not as a missing one
    unknown = sorted(set(table) - allowed)
    if unknown:
        if "unit" in unknown[0].lower():
            raise InputError(f"{where}: unknown key {unknown[0]!r}: a kinetics file has no "
                             "units to set; rates and heat-exchange coefficients are read in "
                             "1/s (convert: a rate in 1/min divided by 60), values in the "
                             "units you give initial and temperature in")
        raise InputError(f"{where}: unknown key {unknown[0]!r} for law {law_key}; it takes "
                         f"{', '.join(sorted(allowed))} (rates in 1/s)")
    params = {p: _parameter(table, p, where, path, law) for p in law.parameter_names}
    if law_cls is HeatExchange and "wall_temperature" in table and \
            "temperature_by_cell" in table:
        raise InputError(f"{where}: wall_temperature would replace the wall cells' values of "
                         "temperature_by_cell; give the wall cells' temperature in the table "
                         "and remove wall_temperature (or give temperature = NUMBER beside it)")
    if "threshold" in table and not any(
            isinstance(v, FromField) and f"{p}_threshold" not in table
            for p, v in params.items()):
        raise InputError(f"{where}: threshold applies only to a parameter given as a function "
                         f"of a cell field ({law.parameter_names[0]}_from = \"FIELD\") "
                         "without a threshold of its own (PARAMETER_threshold); no parameter "
                         "uses it here: remove it")
    initial = table.get("initial")
    if initial is not None and not _finite(initial):
        raise InputError(f"{where}: initial must be a finite number")
    start = table.get("start", "entry")
    try:
        return Property(table["name"], law, params, start, initial)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None


#: the largest magnitude of a property's values (its initial value, the limit it relaxes
#: to): their squares, which the exit SD is formed from, stay below 1.8e308
MAX_VALUE = 1e100


def _toml_text(value) -> str:
    """A value as the TOML file spells it (``true``, ``"text"``), for messages."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float) and math.isinf(value):     # as TOML reads 1e400 too
        return f"{'-' if value < 0 else ''}inf (a number beyond 1.8e308 reads as inf)"
    return repr(value)


def _finite(value) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def _parameter(table, p: str, where: str, path: Path, law: Law) -> CellParameter:
    forms = [k for k in (p, f"{p}_by_cell", f"{p}_from") if k in table]
    if len(forms) != 1:
        raise InputError(f"{where}: give {p} exactly once, as {p} = NUMBER, {p}_by_cell = "
                         f"\"FILE.csv\" or {p}_from = \"FIELD\""
                         + (f" (found {', '.join(forms)})" if forms else ""))
    key = forms[0]
    signed = p in law.signed_parameters()
    value = table[key]
    stray = [k for k in (f"{p}_dense", f"{p}_dilute", f"{p}_threshold") if k in table]
    if stray and key != f"{p}_from":
        raise InputError(f"{where}: {stray[0]} applies only with {p}_from = \"FIELD\", and "
                         f"{p} is given as {key}; remove {', '.join(stray)} (or give "
                         f"{p}_from instead of {key})")
    if key == p:
        if not _finite(value) or (not signed and value < 0):
            raise InputError(f"{where}: {p} = {_toml_text(value)} must be a finite number"
                             + ("" if signed else " >= 0"))
        return Constant(float(value))
    if key.endswith("_by_cell"):
        if not isinstance(value, str):
            raise InputError(f"{where}: {key} must be a file name (CSV, relative to "
                             f"{path.name})")
        rows, lines = _read_table(path.parent / value, p, f"{where}: {key}", signed)
        return ByCell(rows, str(path.parent / value), key, lines)
    if value not in FIELDS:
        raise InputError(f"{where}: {key} = {value!r} is not a cell field; use one of "
                         f"{', '.join(FIELDS)}")
    numbers = {}
    # a threshold of this parameter's own (p_threshold) before the property's shared one:
    # two parameters of different fields need two thresholds
    threshold = f"{p}_threshold" if f"{p}_threshold" in table else "threshold"
    for k in (f"{p}_dense", f"{p}_dilute", threshold):
        v = table.get(k)
        if k in table and (not _finite(v) or (k != threshold and not signed and v < 0)):
            raise InputError(f"{where}: {k} = {_toml_text(v)} must be a finite number"
                             + ("" if k == threshold or signed else " >= 0"))
        if not _finite(v) or (k != threshold and not signed and v < 0):
            raise InputError(f"{where}: {key} needs {k} = NUMBER (finite"
                             + (")" if k == threshold or signed else ", >= 0)")
                             + (f" (or {p}_threshold)" if k == "threshold" else ""))
        numbers[k] = float(v)
    return FromField(value, numbers[f"{p}_dense"], numbers[f"{p}_dilute"], numbers[threshold],
                     key)


def _read_table(file: Path, p: str, where: str, signed: bool) -> tuple[np.ndarray, np.ndarray]:
    """The rows of a per-cell CSV table and the file line (from 1) of each; blank and ``#``
    lines are skipped but counted, so that every message names the line an editor shows;
    quotes around fields and the header's case do not matter."""
    try:
        raw = file.read_bytes()
    except OSError as exc:
        raise InputError(f"{where}: cannot read {file}: {exc.strerror or exc}; a table's path "
                         "is relative to the kinetics file's folder: check the name and the "
                         "folder, or give an absolute path") from None
    try:                                 # Excel's "CSV UTF-8" starts with a byte-order mark
        text = raw.decode("utf-8-sig").splitlines()
    except UnicodeDecodeError:
        kind = ("UTF-16 (Excel's 'Unicode Text')" if raw[:2] in (b"\xff\xfe", b"\xfe\xff")
                else "not UTF-8")
        raise InputError(f"{where}: {file} is {kind}; save it as CSV in UTF-8 (plain "
                         "numbers and a header col,row[,depth],"
                         f"{p})") from None
    # blank and '#' comment lines skipped; quotes around fields and the header's case, as
    # spreadsheets write them, do not matter
    numbered = [(n, ln.strip()) for n, ln in enumerate(text, start=1)
                if ln.strip() and not ln.lstrip().startswith("#")]
    if not numbered:
        raise InputError(f"{where}: {file} is empty; give a header col,row[,depth],{p}")
    header = [h.strip().strip('"').strip("'").strip().lower() for h in numbered[0][1].split(",")]
    if header not in (["col", "row", p], ["col", "row", "depth", p], ["col", "row", "value"],
                      ["col", "row", "depth", "value"]):
        raise InputError(f"{where}: {file} has columns {','.join(header)}; give "
                         f"col,row[,depth],{p}")
    width = len(header)
    example = "0,5,0.4" if width == 3 else "0,5,1,0.4"
    rows, lines = [], []
    for n, line in numbered[1:]:
        parts = [x.strip().strip('"').strip("'") for x in line.split(",")]
        try:
            values = [float(x) for x in parts]
        except ValueError:
            values = None
        if values is None or len(values) != width:
            raise InputError(f"{where}: {file} line {n} ({line!r}) is not {width} numbers; "
                             f"give {','.join(header)} on each line, such as {example}")
        for name, v in zip(header, values):
            if not math.isfinite(v):
                raise InputError(f"{where}: {file} line {n}: {name} is {v:g}, not a finite "
                                 f"number; give {','.join(header)}, such as {example}")
            if name != header[-1] and (v != int(v) or v < 0):
                raise InputError(f"{where}: {file} line {n}: {name} {v:g} is not a cell index "
                                 f"(a whole number >= 0, counted from 0); give "
                                 f"{','.join(header)}, such as {example}")
        if not signed and values[-1] < 0:
            raise InputError(f"{where}: {file} line {n}: {p} {values[-1]:g} < 0; rates and "
                             "coefficients must be >= 0")
        rows.append(values)
        lines.append(n)
    if not rows:
        raise InputError(f"{where}: {file} has no rows; give one per cell")
    return np.array(rows, dtype=np.float64), np.array(lines, dtype=np.int64)
