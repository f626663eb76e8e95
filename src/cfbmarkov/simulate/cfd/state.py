"""The gas state (:class:`GasState`) and diagnostics computed from states (numpy)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cfbmarkov.errors import InputError
from cfbmarkov.simulate.cfd.grid import GasGrid, y_face_void_fraction


@dataclass(eq=False)
class GasState:
    """The gas at one time (all arrays float64, indexed [i, j]; see :mod:`.grid`).

    ``u`` (nx+1, ny) and ``v`` (nx, ny) are interstitial gas velocities (m/s) on the faces,
    ``p`` (nx, ny) the periodic part of the pressure (Pa, zero mean; the full pressure is
    ``p - G y``), ``void_fraction`` (nx, ny) the eps these velocities belong to,
    ``driving_pressure_gradient`` G (Pa/m), ``distributor_pressure_drop`` the mean pressure
    drop across a distributor (Pa; 0 without one), ``pressure_residual`` the relative continuity
    residual of the last projection (-), ``continuity_defect`` the mean deps/dt removed
    before it (1/s), ``time`` (s) and ``steps`` since the initial state.
    """

    u: np.ndarray
    v: np.ndarray
    p: np.ndarray
    void_fraction: np.ndarray
    driving_pressure_gradient: float = 0.0
    pressure_residual: float = 0.0
    continuity_defect: float = 0.0
    time: float = 0.0
    distributor_pressure_drop: float = 0.0
    steps: int = 0
    diagnostics: dict[str, float] = field(default_factory=dict, compare=False)

    _ARRAYS = ("u", "v", "p", "void_fraction")
    _SCALARS = ("driving_pressure_gradient", "pressure_residual", "continuity_defect", "time")

    def state_dict(self) -> dict[str, Any]:
        """Arrays (copied) and scalars for a checkpoint; :meth:`from_state_dict` restores it."""
        d: dict[str, Any] = {k: np.array(getattr(self, k), dtype=np.float64, copy=True)
                             for k in self._ARRAYS}
        for k in self._SCALARS + ("distributor_pressure_drop",):
            d[k] = float(getattr(self, k))
        d["steps"] = int(self.steps)
        return d

    @classmethod
    def from_state_dict(cls, d: dict[str, Any]) -> "GasState":
        try:
            arrays = {k: np.array(d[k], dtype=np.float64, copy=True, order="C") for k in cls._ARRAYS}
            scalars = {k: float(d[k]) for k in cls._SCALARS}
            # absent from checkpoints written before distributors existed
            scalars["distributor_pressure_drop"] = float(d.get("distributor_pressure_drop", 0.0))
            steps = int(d["steps"])
        except KeyError as exc:
            raise InputError(f"gas state checkpoint lacks '{exc.args[0]}'") from None
        return cls(**arrays, **scalars, steps=steps)

    def mean_gas_flux(self, grid: GasGrid | None = None) -> float:
        """Domain mean of eps_face * v over all y-faces (m/s): U after every step. Pass the
        solver's ``grid`` where it has a ``distributor`` (its face void fraction differs)."""
        return float(np.mean(cross_section_flux(self, grid)))


def cross_section_flux(state: GasState, grid: GasGrid | None = None) -> np.ndarray:
    """Mean of eps_face * v over each row of y-faces (shape (ny,), m/s).

    Row j lies at y = j dy. These differ from each other by the rate of change of the gas
    volume between the rows; their mean is U. Pass the solver's ``grid`` where it has a
    ``distributor`` (the face void fraction at j = 0 differs there).
    """
    faces = y_face_void_fraction(state.void_fraction, grid is not None and grid.distributor)
    return np.mean(faces * state.v, axis=0)


def continuity_residual(grid: GasGrid, old: GasState, new: GasState, time_step: float) -> np.ndarray:
    """div(eps u) + deps/dt - continuity_defect per cell (1/s), recomputed with numpy."""
    e0, e1 = old.void_fraction, new.void_fraction
    eu = np.zeros(grid.u_shape)
    eu[1:-1] = 0.5 * (e1[1:] + e1[:-1]) * new.u[1:-1]
    ev = grid.y_face_void_fraction(e1) * new.v
    div = (eu[1:] - eu[:-1]) / grid.dx + (np.roll(ev, -1, axis=1) - ev) / grid.dy
    return div + (e1 - e0) / time_step - new.continuity_defect
