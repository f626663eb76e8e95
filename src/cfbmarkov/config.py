"""Case configuration: TOML files validated by pydantic models.

Every parameter of the paper's Table 1 (and the contact law of Table 2) has a named field;
units are given in each field's description. Defaults are the paper's values
(docs/definitions.md, Riser), except two numerical settings that change the speed only: the
DEM's neighbour-list skin (not in the paper) and its search grid (``"auto"``; the paper's
30 x 351 can be set).
"""

from __future__ import annotations

import json
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal, get_args, get_origin

from pydantic import (BaseModel, ConfigDict, Field, ValidationError, field_validator,
                      model_validator)

from cfbmarkov.errors import InputError

Positive = Annotated[float, Field(gt=0)]
#: the physical range of a length of the riser (m), beyond which no simulation is meant
Length = Annotated[float, Field(gt=0, le=100.0)]
#: a count of cells along one axis
Cells = Annotated[int, Field(gt=0, le=100_000)]
#: most particles a case may hold (the simulation also checks its memory before allocating)
MAX_PARTICLES = 10_000_000


def _numeric(annotation) -> bool:
    """Whether a field holds a number, or a tuple of numbers (its annotation)."""
    origin = get_origin(annotation)
    if origin is Annotated:
        return _numeric(get_args(annotation)[0])
    if origin is tuple:
        return all(_numeric(a) for a in get_args(annotation) if a is not Ellipsis)
    return annotation in (int, float)


class _Model(BaseModel):
    # every number finite (no inf or nan): a case value out of range is refused in one line
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _a_number_is_written_as_one(cls, value, info):
        """true/false or text where a number is meant is refused (pydantic would read true
        as 1 particle and "0.03" as 0.03 m)."""
        field = cls.model_fields.get(info.field_name)
        if field is None or not _numeric(field.annotation):
            return value
        items = value if isinstance(value, (list, tuple)) else [value]
        if any(isinstance(v, (bool, str, bytes)) for v in items):
            written = json.dumps(list(value) if isinstance(value, tuple) else value,
                                 default=str)
            raise ValueError(f"a number is meant, not {written} (write the number itself, "
                             "without quotes)")
        return value


class RiserConfig(_Model):
    """Geometry of the 2D riser: x across (walls at 0 and W), y up (periodic, 0 <= y < H)."""

    width: Length = Field(0.09, description="riser width W, m (Table 1: bed size 0.09 m)")
    height: Length = Field(0.95, description="riser height H, m (Table 1: bed size 0.95 m)")
    gravity: float = Field(9.81, ge=0, le=1000.0, description="gravitational acceleration, m/s^2, acting in -y")
    distributor_pressure_drop: float = Field(
        0.0, ge=0, description="pressure drop of the gas distributor under a bed standing on a "
        "floor (verification beds only; the periodic riser has none), Pa at the superficial "
        "velocity, linear in each column's gas flux; 0: no distributor resistance")


class ParticleConfig(_Model):
    number: int = Field(27000, gt=0, le=MAX_PARTICLES, description="number of particles (Table 1: 27000)")
    diameter: float = Field(0.001, gt=1e-7, le=0.1, description="particle diameter d, m (Table 1: 0.001 m)")
    density: float = Field(2600.0, ge=1.0, le=1e5, description="particle density, kg/m^3 (Table 1: 2600)")

    @property
    def mass(self) -> float:
        """Sphere mass, kg."""
        return self.density * math.pi * self.diameter**3 / 6.0

    @property
    def moment_of_inertia(self) -> float:
        """Sphere moment of inertia 2/5 m r^2, kg m^2."""
        return 0.1 * self.mass * self.diameter**2


class GasConfig(_Model):
    density: float = Field(1.205, ge=1e-3, le=1e4, description="gas density, kg/m^3 (air)")
    viscosity: float = Field(1.8e-5, ge=1e-7, le=10.0, description="gas dynamic viscosity, Pa s (air)")
    superficial_velocity: float = Field(
        6.0, gt=0, le=1000.0, description="inlet air velocity U: cross-section mean of void_fraction*v_gas, m/s "
        "(Table 1: 3, 4, 6 or 8 m/s)")
    minimum_fluidization_velocity: Positive = Field(
        0.44, description="minimum fluidization velocity, m/s (Table 1: 0.44; reported only)")


class ContactConfig(_Model):
    """Linear spring-dashpot contact with tangential history and Coulomb cap (Table 2)."""

    normal_stiffness: Positive = Field(10000.0, description="kn, N/m (Table 1: 10000)")
    tangential_stiffness: Positive = Field(2857.0, description="kt, N/m (Table 1: 2857)")
    normal_restitution: float = Field(0.97, gt=0, le=1, description="en, - (Table 1: 0.97)")
    tangential_restitution: float = Field(0.33, gt=0, le=1, description="et, - (Table 1: 0.33)")
    friction_coefficient: float = Field(0.1, ge=0, description="Coulomb friction mu_f, - (Table 1: 0.1)")


class NumericsConfig(_Model):
    cfd_cells: tuple[Cells, Cells] = Field(
        (9, 95), description="gas grid cells [across, up], - (Table 1: 9 x 95)")
    dem_cells: tuple[Cells, Cells] | Literal["auto"] = Field(
        "auto", description="DEM neighbour-search cells [across, up], or \"auto\": the finest "
        "grid whose cells are at least the search cutoff 2 R_max + skin (Table 1: 30 x 351; "
        "the grid changes the speed and the round-off, not the physics)")
    dem_skin: Positive = Field(
        4e-4, description="Verlet neighbour-list skin, m (not in the paper; affects speed only)")
    cfd_time_step: float = Field(5e-5, gt=0, le=1.0, description="gas time step, s (Table 1: 5e-5)")
    dem_time_step: float = Field(5e-6, gt=0, le=1.0, description="particle time step, s (Table 1: 5e-6)")

    @model_validator(mode="after")
    def _steps_commensurate(self):
        ratio = self.cfd_time_step / self.dem_time_step
        if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
            nearest = max(1, round(ratio)) * self.dem_time_step
            raise ValueError(
                f"cfd_time_step {self.cfd_time_step:g} s must be a whole multiple of "
                f"dem_time_step {self.dem_time_step:g} s (e.g. {nearest:.10g} s, "
                f"{max(1, round(ratio))} DEM steps per gas step)")
        return self

    @property
    def dem_steps_per_cfd_step(self) -> int:
        return int(round(self.cfd_time_step / self.dem_time_step))


class OutputConfig(_Model):
    end_time: float = Field(20.0, gt=0, le=1e6, description="simulated time to reach, s (paper: 20)")
    frame_interval: Positive = Field(0.025, description="time between stored frames, s")


class MarkovConfig(_Model):
    columns: int = Field(6, gt=0, le=100_000, description="cell columns m across the riser, - (paper: 6)")
    rows: int = Field(38, gt=0, le=100_000, description="cell rows n up the riser, - (paper: 38)")
    lag: Positive = Field(0.025, description="transition time step, s (paper: 0.025)")
    fit_window: tuple[float, float] = Field(
        (10.0, 15.0), description="fitting window [start, stop], s (paper: [10, 15])")
    predict_window: tuple[float, float] = Field(
        (15.0, 20.0),
        description="prediction and comparison window [start, stop], s (paper: [15, 20])")
    interval_level: float = Field(0.9, gt=0.0, lt=1.0,
                                  description="coverage of the prediction's intervals, -")
    interval_resamples: int = Field(100, ge=0, description="bootstrap resamples of the fitting "
                                    "window for the intervals (0: none), -")
    coherent_auto: bool = Field(True, description="fit the automatically chosen model with "
                                "coherent moves (the cluster model), -")

    @field_validator("fit_window", "predict_window")
    @classmethod
    def _window_in_order(cls, window: tuple[float, float]) -> tuple[float, float]:
        start, stop = window
        if not (math.isfinite(start) and math.isfinite(stop) and 0.0 <= start < stop):
            raise ValueError(f"[{start:g}, {stop:g}] s is not [start, stop] with "
                             "0 <= start < stop" + (f" (e.g. [{stop:g}, {start:g}])"
                                                    if 0.0 <= stop < start else ""))
        return window

    def comparison_problem(self) -> str | None:
        """What keeps a reproduction's Markov stages from running on these settings, found
        before its CFD-DEM rather than at its comparison (None where nothing does): an odd
        column count (the comparison's mixing follows the left half, which the middle column
        of an odd count straddles), or too few interval resamples for the level (1-9, or
        fewer than 1 / (1 - level): the tails must hold a resample each). A case that is
        only simulated is not judged by them."""
        if self.columns % 2:
            return (f"columns {self.columns}: an even count (the comparison's mixing follows "
                    "the particles of the left half, x < W/2, which the middle column of an "
                    f"odd count straddles; e.g. {self.columns + 1})")
        if 0 < self.interval_resamples < 10:
            return (f"interval_resamples {self.interval_resamples}: at least 10 (0 leaves the "
                    "intervals out)")
        needed = math.ceil(1.0 / (1.0 - self.interval_level) - 1e-9)
        if self.interval_resamples and self.interval_resamples < needed:
            return (f"interval_resamples {self.interval_resamples}: a "
                    f"{100 * self.interval_level:g} % interval needs {needed} or more (its "
                    "tails must hold a resample each), or a lower interval_level")
        return None


class CaseConfig(_Model):
    name: str = Field("custom", description="case name")
    seed: int = Field(0, ge=0, le=2**64 - 1, description="random seed (initial placement, Monte Carlo)")
    riser: RiserConfig = RiserConfig()
    particles: ParticleConfig = ParticleConfig()
    gas: GasConfig = GasConfig()
    contact: ContactConfig = ContactConfig()
    numerics: NumericsConfig = NumericsConfig()
    output: OutputConfig = OutputConfig()
    markov: MarkovConfig = MarkovConfig()

    def reproduction_problem(self) -> str | None:
        """What keeps a reproduction's Markov stages from running on this case, found before
        its CFD-DEM (None where nothing does).

        Besides :meth:`MarkovConfig.comparison_problem`: a fitting or predict window that
        ends after ``output.end_time`` or is shorter than one lag, a predict window that
        starts before the fitting window ends, and a lag that is not a whole multiple of
        ``output.frame_interval`` (the frames the CFD-DEM stores). Each would otherwise stop
        the case after its CFD-DEM has run.

        Returns
        -------
        str or None
            The problem, naming the setting and a value that works.
        """
        markov, output = self.markov, self.output
        problem = markov.comparison_problem()
        if problem is not None:
            return problem
        frames = markov.lag / output.frame_interval
        if round(frames) < 1 or abs(frames - round(frames)) > 1e-9 * frames:
            nearest = max(1, round(frames)) * output.frame_interval
            return (f"lag {markov.lag:g} s: a whole multiple of output.frame_interval "
                    f"{output.frame_interval:g} s (the frames the CFD-DEM stores), e.g. "
                    f"{nearest:g}")
        for key in ("fit_window", "predict_window"):
            a, b = getattr(markov, key)       # in order (MarkovConfig checks it)
            if b > output.end_time * (1 + 1e-12):
                return (f"{key} [{a:g}, {b:g}] s ends after the CFD-DEM's output.end_time "
                        f"{output.end_time:g} s: a window within 0-{output.end_time:g} s, or a "
                        "later end_time")
            if b - a < markov.lag * (1 - 1e-9):
                return (f"{key} [{a:g}, {b:g}] s is shorter than one lag ({markov.lag:g} s): a "
                        "longer window or a shorter lag")
        (fa, fb), (pa, pb) = markov.fit_window, markov.predict_window
        if pa < fb * (1 - 1e-12):
            return (f"predict_window [{pa:g}, {pb:g}] s starts inside fit_window [{fa:g}, "
                    f"{fb:g}] s: a reproduction compares the model on the window after the one "
                    f"it was fitted on (predict_window from {fb:g} s on; `cfbmarkov compare` "
                    "judges any window)")
        return None


#: keys a user may look for in a case that the 2D periodic CFD-DEM has not, and where
#: such a riser comes from instead
NOT_SIMULATED = {"depth": "a 3D riser", "boundary": "an open riser",
                 "dimensions": "a 3D riser"}


def _fields_along(loc: tuple) -> tuple[list[str], type[BaseModel] | None, object]:
    """The case's settings named along an error's location: (their names, the model that
    holds the last, the last one's field info or None)."""
    model: type[BaseModel] | None = CaseConfig
    names: list[str] = []
    field = None
    for part in loc:
        if not (isinstance(part, str) and model is not None and part in model.model_fields):
            break
        names.append(part)
        field = model.model_fields[part]
        annotation = field.annotation
        holder = model
        model = annotation if isinstance(annotation, type) and issubclass(annotation,
                                                                          BaseModel) else None
        if model is None:
            return names, holder, field
    return names, model, field


def describe_validation_error(err: ValidationError) -> tuple[str, str]:
    """Where a case's first fault lies and what it is, in the case file's words.

    An unknown key names the keys its table takes (and the nearest, for a typing slip; for
    ``depth`` or ``boundary``, that the CFD-DEM is 2D and periodic); a value of the wrong
    shape (a pair given three values, ``"Auto"`` for ``"auto"``) names what the setting
    takes, from its description.

    Parameters
    ----------
    err : pydantic.ValidationError
        The error of :meth:`CaseConfig.model_validate`.

    Returns
    -------
    (str, str)
        The setting's dotted name (``(top level)`` for the case itself) and the message
        (with the value given, where it is a number or text).
    """
    import difflib

    first = err.errors()[0]
    loc = tuple(first["loc"])
    names, model, field = _fields_along(loc)
    given = first.get("input")
    value = (f" (given {given!r})" if isinstance(given, (int, float, str)) and
             not isinstance(given, bool) else "")
    message = str(first["msg"]).removeprefix("Value error, ")
    if first["type"] == "extra_forbidden" and model is not None and len(names) == len(loc) - 1:
        key = str(loc[-1])
        table = f"[{'.'.join(names)}]" if names else "the top level"
        keys = list(model.model_fields)
        near = difflib.get_close_matches(key, keys, n=1, cutoff=0.75)
        message = f"unknown key '{key}' in {table}"
        elsewhere = [name for name, f in CaseConfig.model_fields.items()
                     if isinstance(f.annotation, type) and issubclass(f.annotation, BaseModel)
                     and key in f.annotation.model_fields]
        if near:
            message += f"; did you mean '{near[0]}'?"
        elif elsewhere:
            message += f"; it belongs in [{elsewhere[0]}]"
        elif key in NOT_SIMULATED:
            message += (f": the CFD-DEM simulates a 2D periodic riser; {NOT_SIMULATED[key]} "
                        "comes from imported data (cfbmarkov import)")
        message += f" ({table} takes: {', '.join(keys)})"
        where = ".".join([*names, key])
        return where, message
    rest = loc[len(names):]
    items = [str(p) for p in rest if isinstance(p, int)]
    where = ".".join([*names, *items]) or ".".join(str(p) for p in loc) or "(top level)"
    # a union's branch named in the location ("tuple[...]", "literal['auto']") or a value
    # of the wrong shape (three items for a pair, one for a window): say what it takes
    branch = any(isinstance(p, str) for p in rest)
    shape = first["type"] in ("too_long", "too_short", "tuple_type", "list_type", "missing",
                              "literal_error")
    if field is not None and field.description and (branch or shape):
        message = f"expected {field.description}"
        where = ".".join(names)
    # a number out of range: say the setting's unit and the paper's value, where a slip of
    # units (a diameter of 1 for 1 mm) is the likely cause
    bounded = first["type"] in ("greater_than", "greater_than_equal", "less_than",
                                "less_than_equal")
    if bounded and field is not None and field.description:
        return where, f"{message}{value}; it is the {field.description}"
    return where, message if first["type"] == "value_error" else message + value


def _format_validation_error(err: ValidationError, source: str) -> str:
    where, message = describe_validation_error(err)
    return f"{source}: invalid configuration at '{where}': {message}"


def load_case(source: str | Path) -> CaseConfig:
    """Load a case from a TOML file path or a shipped case name.

    Parameters
    ----------
    source : str or pathlib.Path
        A ``.toml`` file, or the name of a shipped case (:func:`case_names`).

    Returns
    -------
    CaseConfig
        The validated case; parameters not given keep the paper's values.

    Raises
    ------
    InputError
        When the file cannot be read, is not valid TOML, or fails validation (the message
        names the first offending field), or the name is unknown.
    """
    path = Path(source)
    if path.suffix == ".toml" or path.exists():
        from cfbmarkov._toml import read_toml

        data = read_toml(path, "case file", "a TOML file of the case's tables ([riser], "
                         "[particles], [gas], ...; a shipped case by name: "
                         + ", ".join(case_names()) + ")")
    elif str(source) in case_names():
        text = resources.files("cfbmarkov.cases").joinpath(f"{source}.toml").read_text()
        data = tomllib.loads(text)
    else:
        raise InputError(f"unknown case '{source}': not a file, and not one of {', '.join(case_names())}")
    try:
        return CaseConfig.model_validate(data)
    except ValidationError as exc:
        raise InputError(_format_validation_error(exc, str(source))) from None


def case_names() -> list[str]:
    """Names of the shipped cases.

    Returns
    -------
    list of str
        Sorted names (``paper-u3``, ``paper-u4``, ``paper-u6``, ``paper-u8``).
    """
    folder = resources.files("cfbmarkov.cases")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


#: settings that change a simulation's speed and round-off, not its physics: a CFD-DEM file
#: made with other values still serves the same case (cfbmarkov.reproduce)
SPEED_ONLY = ("numerics.dem_cells", "numerics.dem_skin")


def flat_tables(tables: dict, prefix: str = "") -> dict[str, object]:
    """Nested tables of a case file as ``{"section.name": value}``, in the tables' order.

    Parameters
    ----------
    tables : dict
        Nested tables (a case's, or an overrides file's).
    prefix : str, optional
        Put before every name.

    Returns
    -------
    dict
        Dotted names to the values.
    """
    out: dict[str, object] = {}
    for key, value in tables.items():
        if isinstance(value, dict):
            out.update(flat_tables(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def flat_settings(case: CaseConfig) -> dict[str, object]:
    """A case's settings as ``{"section.name": value}`` (JSON values: tuples as lists)."""
    return flat_tables(case.model_dump(mode="json"))


def case_difference(saved: CaseConfig, case: CaseConfig, limit: int = 3) -> str:
    """The settings in which two cases differ, for a message.

    Parameters
    ----------
    saved, case : CaseConfig
        The case a file was made with and the case asked for now.
    limit : int, optional
        How many differences to name (the rest are counted).

    Returns
    -------
    str
        ``"section.name: saved X, now Y; ..."``, or ``"settings differ"`` when none is found.
    """
    a, b = flat_settings(saved), flat_settings(case)
    diffs = [f"{k}: saved {a.get(k)!r}, now {b.get(k)!r}" for k in sorted(set(a) | set(b))
             if a.get(k) != b.get(k)]
    more = f", and {len(diffs) - limit} more" if len(diffs) > limit else ""
    return "; ".join(diffs[:limit]) + more if diffs else "settings differ"
