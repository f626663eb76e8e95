"""Rate laws of particle properties (``docs/definitions.md``, Properties along particle paths).

Every built-in law is a linear relaxation toward a per-state value,

    dv/dt = k_s (v_inf,s - v),

with k_s and v_inf,s the rate and the limit of the state s the particle is in. Rates are
piecewise constant (over each lag the rate of the state at the lag's start), so one lag
maps the value exactly by an affine map v' = a_s v + b_s with a_s = exp(-k_s lag) and
b_s = v_inf,s (1 - a_s):

- :class:`FirstOrder`, a first-order solid reaction dX/dt = k_s (1 - X) (conversion X);
- :class:`Deactivation`, catalyst deactivation da/dt = -k_s a (activity a);
- :class:`HeatExchange`, dT/dt = h_s (T_s - T) (a particle temperature relaxing toward the
  state's temperature; the wall cells toward the wall temperature where one is given).

:class:`Custom` takes a user-supplied Numba-compiled rate function for coupled and
non-linear laws (an Arrhenius rate depending on a temperature, an n-th order reaction);
the Monte Carlo integrates it with a fixed number of classical Runge-Kutta (RK4) sub-steps
per lag, and no exact answer exists for it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.limits import check_finite


class Law(ABC):
    """A rate law of one particle property.

    Attributes
    ----------
    key : str
        The law's name in a kinetics file (``first-order``, ...), a class attribute.
    linear : bool
        Whether the law is a linear relaxation with an exact per-lag affine map (and exact
        answers from the chain).
    """

    key: ClassVar[str]
    linear: ClassVar[bool] = True
    #: the value a property of this law takes at entry unless the file gives ``initial``
    default_initial: ClassVar[float | None] = None
    #: the range (lowest, highest; None: unbounded) of a start value, and what it is
    initial_range: ClassVar[tuple[float | None, float | None]] = (None, None)
    quantity: ClassVar[str] = "value"

    @property
    @abstractmethod
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the law's per-state parameters (``rate``; ``coefficient``,
        ``temperature``; a custom law's own)."""

    def signed_parameters(self) -> tuple[str, ...]:
        """The parameters that may be negative (all others must be >= 0)."""
        return ()

    def relaxation(self, parameters: dict[str, np.ndarray], wall: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Rate k and limit v_inf of the relaxation dv/dt = k (v_inf - v) per cell.

        Parameters
        ----------
        parameters : dict of str to ndarray of float64, shape (C,)
            Each of :attr:`parameter_names` per cell.
        wall : ndarray of bool, shape (C,)
            Whether a cell touches a wall (its column is the first or last across, or in
            the depth).

        Returns
        -------
        k, v_inf : ndarray of float64, shape (C,)
            Rate (1/s) and limit (the property's unit).

        Raises
        ------
        InputError
            For a law with no linear relaxation (:class:`Custom`).
        """
        raise InputError(f"law {self.key} is not a linear relaxation: it has no exact "
                         "answer (use the Monte Carlo, react --init)")

    def describe(self) -> dict[str, Any]:
        """The law as JSON-serialisable text (its key and settings)."""
        return {"law": self.key}


@dataclass(frozen=True)
class FirstOrder(Law):
    """First-order solid reaction dX/dt = k_s (1 - X): parameter ``rate`` (1/s); X starts
    at 0 unless given."""

    key: ClassVar[str] = "first-order"
    default_initial: ClassVar[float | None] = 0.0
    initial_range: ClassVar[tuple[float | None, float | None]] = (0.0, 1.0)
    quantity: ClassVar[str] = "a conversion"

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("rate",)

    def relaxation(self, parameters, wall):
        k = np.asarray(parameters["rate"], dtype=np.float64)
        return k, np.ones_like(k)


@dataclass(frozen=True)
class Deactivation(Law):
    """Catalyst deactivation da/dt = -k_s a: parameter ``rate`` (1/s); a starts at 1
    unless given."""

    key: ClassVar[str] = "deactivation"
    default_initial: ClassVar[float | None] = 1.0
    initial_range: ClassVar[tuple[float | None, float | None]] = (0.0, None)
    quantity: ClassVar[str] = "an activity"

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("rate",)

    def relaxation(self, parameters, wall):
        k = np.asarray(parameters["rate"], dtype=np.float64)
        return k, np.zeros_like(k)


@dataclass(frozen=True)
class HeatExchange(Law):
    """Heat exchange dT/dt = h_s (T_s - T): parameters ``coefficient`` h (1/s, the heat
    transfer coefficient times area over the particle's heat capacity) and ``temperature``
    T_s; where ``wall_temperature`` is given, the wall cells relax toward it instead of
    their T_s. The start value (``initial``, the feed temperature) must be given.

    Attributes
    ----------
    wall_temperature : float or None
        T_wall, the limit in the cells that touch a wall; None: every cell its own T_s.
    """

    key: ClassVar[str] = "heat-exchange"
    wall_temperature: float | None = None

    def __post_init__(self):
        if self.wall_temperature is None:
            return
        try:
            check_finite(self.wall_temperature, "wall_temperature")
        except InputError:
            raise InputError(f"wall_temperature = {self.wall_temperature!r} must be a finite "
                             "number (the wall's temperature, in the units of temperature and "
                             "initial), or None") from None

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("coefficient", "temperature")

    def signed_parameters(self) -> tuple[str, ...]:
        return ("temperature",)

    def relaxation(self, parameters, wall):
        k = np.asarray(parameters["coefficient"], dtype=np.float64)
        target = np.array(parameters["temperature"], dtype=np.float64)
        if self.wall_temperature is not None:
            target[np.asarray(wall, dtype=bool)] = self.wall_temperature
        return k, target

    def describe(self):
        return {"law": self.key, "wall_temperature": self.wall_temperature}


@dataclass(frozen=True)
class Custom(Law):
    """A law given by a Numba-compiled rate function, for the Monte Carlo only.

    ``function(v, parameters, values) -> dv/dt`` (all float64): ``v`` the property's value,
    ``parameters`` the state's row of this law's parameters (float64 [q], in the order of
    ``parameters``), ``values`` the particle's properties at the lag's start (float64 [P],
    in the order of the kinetics; the linear properties and the custom ones declared before
    this one are filled, the others NaN, so a coupled custom law, e.g. an Arrhenius rate of
    a custom temperature, comes after the property it reads; a function that raises or
    gives no finite rate at its start value is refused before the run). Each lag is integrated with ``substeps`` classical RK4 steps with the state and
    the other properties held at the lag's start.

    Attributes
    ----------
    function : numba dispatcher
        The rate function, compiled with ``numba.njit``.
    parameters : tuple of str
        Names of its per-state parameters.
    substeps : int
        RK4 sub-steps per lag (default 8).
    initial : float
        Default start value (0).
    signed : tuple of str
        Parameters that may be negative.
    """

    function: Any
    parameters: tuple[str, ...] = ()
    substeps: int = 8
    initial: float = 0.0
    signed: tuple[str, ...] = ()
    key: ClassVar[str] = "custom"
    linear: ClassVar[bool] = False

    def __post_init__(self):
        if not hasattr(self.function, "py_func"):
            raise InputError("a custom law's rate function must be compiled with numba.njit")
        if not (isinstance(self.substeps, (int, np.integer)) and self.substeps >= 1):
            raise InputError(f"a custom law's substeps {self.substeps!r} must be an integer >= 1")
        object.__setattr__(self, "parameters", tuple(self.parameters))

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.parameters

    def signed_parameters(self) -> tuple[str, ...]:
        return tuple(self.signed)

    def describe(self):
        return {"law": self.key, "function": getattr(self.function, "__name__", "?"),
                "substeps": int(self.substeps)}


#: the laws a kinetics file may name, by key
LAWS: dict[str, type[Law]] = {law.key: law for law in (FirstOrder, Deactivation, HeatExchange)}


def affine_map(rate: np.ndarray, target: np.ndarray, lag: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """The exact map of one lag of dv/dt = k (v_inf - v) with k held: v' = a v + b.

    Parameters
    ----------
    rate, target : ndarray of float64
        k (1/s) and v_inf, of the same shape.
    lag : float
        The lag (s).

    Returns
    -------
    a, b : ndarray of float64
        a = exp(-k lag), b = v_inf (1 - a) (computed as -expm1(-k lag) for small k lag).
    """
    rate = np.asarray(rate, dtype=np.float64)
    a = np.exp(-rate * lag)
    b = np.asarray(target, dtype=np.float64) * -np.expm1(-rate * lag)
    return a, b
