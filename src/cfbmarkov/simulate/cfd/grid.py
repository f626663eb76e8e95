"""The staggered (MAC) gas grid of the 2D riser.

Layout (``i`` counts across, ``j`` counts up; arrays are indexed ``[i, j]``)::

    cell centre (i, j):  x = (i + 1/2) dx,  y = (j + 1/2) dy     eps, p     shape (nx, ny)
    x-face      (i, j):  x = i dx,          y = (j + 1/2) dy     u          shape (nx + 1, ny)
    y-face      (i, j):  x = (i + 1/2) dx,  y = j dy             v          shape (nx, ny)

``u[0, :]`` and ``u[nx, :]`` lie on the walls x = 0 and x = W and are always zero (no
penetration). The y-direction is periodic: y-face ``j = 0`` lies at y = 0 = H, between
cell row ``ny - 1`` (below, through the periodic boundary) and cell row 0. The no-slip
condition for ``v`` at the walls is imposed through a ghost value ``v_ghost = -v`` half a
cell outside the wall, i.e. v = 0 on the wall by linear interpolation.

A y-face's void fraction (which turns the mass flux eps v into the interstitial velocity v)
is the mean of the two cells beside it. On a grid with ``distributor=True`` (a bed standing
on a floor at y = 0, through which the gas enters as through a distributor plate) the face
j = 0 takes the void fraction of the cell above it instead: the gas leaves the distributor
into the bed at U / eps_bed, not at U over the mean of the bed and the empty freeboard
across the periodic seam.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfbmarkov.errors import InputError


@dataclass(frozen=True)
class GasGrid:
    """A uniform staggered grid of ``nx`` x ``ny`` cells over [0, width] x [0, height)
    (``distributor``: the face at y = 0 is a distributor under a bed, see the module)."""

    nx: int
    ny: int
    width: float
    height: float
    distributor: bool = False

    def __post_init__(self) -> None:
        if int(self.nx) != self.nx or int(self.ny) != self.ny:
            raise InputError(f"gas grid cell counts must be integers, got {self.nx} x {self.ny}")
        if self.nx < 2 or self.ny < 3:
            raise InputError(
                f"gas grid needs at least 2 cells across and 3 up, got {self.nx} x {self.ny}")
        if not (np.isfinite(self.width) and np.isfinite(self.height)
                and self.width > 0 and self.height > 0):
            raise InputError(
                f"gas grid size must be positive and finite, got {self.width} x {self.height} m")
        object.__setattr__(self, "nx", int(self.nx))
        object.__setattr__(self, "ny", int(self.ny))
        object.__setattr__(self, "width", float(self.width))
        object.__setattr__(self, "height", float(self.height))
        object.__setattr__(self, "distributor", bool(self.distributor))

    @classmethod
    def from_config(cls, case, distributor: bool = False) -> "GasGrid":
        """The grid of a :class:`cfbmarkov.config.CaseConfig` (riser size, ``numerics.cfd_cells``)."""
        nx, ny = case.numerics.cfd_cells
        return cls(nx=nx, ny=ny, width=case.riser.width, height=case.riser.height,
                   distributor=distributor)

    @property
    def dx(self) -> float:
        """Cell width, m."""
        return self.width / self.nx

    @property
    def dy(self) -> float:
        """Cell height, m."""
        return self.height / self.ny

    @property
    def cell_shape(self) -> tuple[int, int]:
        return (self.nx, self.ny)

    @property
    def u_shape(self) -> tuple[int, int]:
        return (self.nx + 1, self.ny)

    @property
    def v_shape(self) -> tuple[int, int]:
        return (self.nx, self.ny)

    @property
    def x_centres(self) -> np.ndarray:
        """x of the cell centres (and of the y-faces), m, shape (nx,)."""
        return (np.arange(self.nx) + 0.5) * self.dx

    @property
    def y_centres(self) -> np.ndarray:
        """y of the cell centres (and of the x-faces), m, shape (ny,)."""
        return (np.arange(self.ny) + 0.5) * self.dy

    @property
    def x_faces(self) -> np.ndarray:
        """x of the x-faces (u points), m, shape (nx + 1,)."""
        return np.arange(self.nx + 1) * self.dx

    @property
    def y_faces(self) -> np.ndarray:
        """y of the y-faces (v points), m, shape (ny,)."""
        return np.arange(self.ny) * self.dy

    def y_face_void_fraction(self, void_fraction) -> np.ndarray:
        """:func:`y_face_void_fraction` on this grid."""
        return y_face_void_fraction(void_fraction, self.distributor)

    def cell_volume(self, thickness: float) -> float:
        """Volume of one cell of the pseudo-2D grid, dx*dy*thickness (``docs/definitions.md``, riser), m^3."""
        return self.dx * self.dy * thickness


def y_face_void_fraction(void_fraction, distributor: bool = False) -> np.ndarray:
    """Void fraction on the y-faces (nx, ny) from the cells' (nx, ny): the mean of the cells
    below and above (across the periodic seam at j = 0), or with a ``distributor`` the cell
    above at j = 0."""
    e = np.asarray(void_fraction, dtype=np.float64)
    face = 0.5 * (np.roll(e, 1, axis=1) + e)
    if distributor:
        face[:, 0] = e[:, 0]
    return face
