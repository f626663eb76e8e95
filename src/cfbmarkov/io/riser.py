"""Where the riser lies in a source's coordinates, and how a frame of source positions
becomes a frame of the trajectory store: shared by every importer.

A source (a dump, a CSV file) has axes x, y (and z). The riser is a region of them: one
axis is vertical (heights), one across, and in 3D the third is its depth. Stored positions
are (across, vertical[, depth]) measured from the region's lower corner, so a box larger
than the riser shifts nothing. A particle outside the region is absent from that frame,
not an error; ``cfbmarkov info`` shows how many are present per frame. On a periodic
vertical axis the height is wrapped into the region and the lap counter counts the wraps
(``docs/definitions.md``, Axes and region; Presence). A periodic source axis wraps by its
box's period, never by the region's extent: a region narrower than a periodic box keeps
the particles outside it absent, not folded in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import InputError
from cfbmarkov.trajectory_format import POSITION_TOLERANCE
from cfbmarkov.trajectory_writer import TrajectoryWriter

AXES = "xyz"


@dataclass(frozen=True)
class RiserFrame:
    """How a source's coordinates map onto the riser.

    Attributes
    ----------
    axes : tuple of int
        Source axis (0, 1, 2 for x, y, z) of each stored axis: (across, vertical) in 2D,
        (across, vertical, depth) in 3D.
    region : numpy.ndarray, shape (D, 2)
        [lo, hi] of each stored axis in the source's coordinates (m).
    from_box : bool
        Whether the region is a dump's box (then the box must not change).
    periodic : tuple of bool
        Whether each stored axis is periodic in the source; the vertical one is the riser's
        boundary (``boundary``).
    boundary : Boundary
        The vertical boundary stored.
    dropped : int or None
        A source axis dropped by projection (``--drop-depth``), or None.
    wrap : numpy.ndarray, shape (D, 2), or None
        [lo, period] (m, source coordinates) of each stored axis that wraps: a periodic box
        axis wraps by the box, a periodic riser without a periodic box by the region; period
        NaN where the axis does not wrap. None: every axis wraps by the region where
        periodic (a source without a box).
    """

    axes: tuple[int, ...]
    region: np.ndarray
    from_box: bool
    periodic: tuple[bool, ...]
    boundary: Boundary
    dropped: int | None = None
    wrap: np.ndarray | None = None

    @property
    def across(self) -> int:
        """Source axis of the across direction."""
        return self.axes[0]

    @property
    def vertical(self) -> int:
        """Source axis of the vertical direction."""
        return self.axes[1]

    @property
    def depth(self) -> int | None:
        """Source axis of the depth (3D), else None."""
        return self.axes[2] if len(self.axes) == 3 else None

    @property
    def width(self) -> float:
        """Extent across (m)."""
        return float(self.region[0, 1] - self.region[0, 0])

    @property
    def height(self) -> float:
        """Extent vertically (m)."""
        return float(self.region[1, 1] - self.region[1, 0])

    @property
    def depth_extent(self) -> float | None:
        """Extent in depth (m) of a 3D riser, else None."""
        return float(self.region[2, 1] - self.region[2, 0]) if len(self.axes) == 3 else None

    def region_text(self) -> str:
        """The region in the source's axis order, as ``--region`` takes it, each range
        named by its axis and role: ``x -0.045:0.045 (across), z 0:0.95 (vertical) m``."""
        roles = ("across", "vertical", "depth")
        ranges = sorted((a, k) for k, a in enumerate(self.axes))
        return ", ".join(f"{AXES[a]} {self.region[k, 0]:g}:{self.region[k, 1]:g} ({roles[k]})"
                         for a, k in ranges) + " m"

    def writer_options(self) -> dict:
        """The geometry options of :class:`~cfbmarkov.trajectory_writer.TrajectoryWriter`."""
        names = ("across", "vertical", "depth")
        return {"width": self.width, "height": self.height, "depth": self.depth_extent,
                "boundary": self.boundary, "region_origin": self.region[:, 0].copy(),
                "axes": {names[k]: AXES[a] for k, a in enumerate(self.axes)}}

    def provenance(self) -> dict:
        """What the import recorded about the axes and the region (JSON-ready)."""
        return {"vertical_axis": AXES[self.vertical], "across_axis": AXES[self.across],
                "depth_axis": None if self.depth is None else AXES[self.depth],
                "depth_axis_dropped": None if self.dropped is None else AXES[self.dropped],
                "region": self.region.tolist(), "boundary_stored": self.boundary.value}


def box_text(box) -> str:
    """A source's box as ``--region`` would give it: ``x 0:0.1, y 0:0.15, z 0:0.95 m``."""
    return ", ".join(f"{AXES[a]} {lo:g}:{hi:g}" for a, (lo, hi) in enumerate(np.asarray(box))) \
        + " m"


def riser_frame(*, n_axes: int, spread: bool, vertical_axis: str | None, flags: tuple[str, ...],
                box: np.ndarray | None, region, width: float | None, height: float | None,
                boundary: str | None, drop_depth: bool, where: str, default_boundary: str
                ) -> RiserFrame:
    """The riser in a source with ``n_axes`` position axes.

    Parameters
    ----------
    n_axes : int
        2 or 3 position axes in the source.
    spread : bool
        Whether positions vary along all three axes (a genuinely 3D source).
    vertical_axis : {"x", "y", "z"} or None
        The vertical axis; required when ``spread`` (never guessed).
    flags : tuple of str
        Periodicity flags per source axis (``'pp'`` periodic, as LAMMPS writes them); empty
        where the source has none.
    box : numpy.ndarray of shape (n_axes, 2), or None
        The source's box (m), the default region.
    region : sequence of (lo, hi) or None
        The riser in source coordinates, one range per source axis x, y (, z).
    width, height : float or None
        Without a region: the riser is 0..width across and 0..height vertically.
    boundary : {"periodic", "open"} or None
        The vertical boundary; by default from ``flags`` on the vertical axis, else
        ``default_boundary``.
    drop_depth : bool
        Project a 3D source on (across, vertical).
    where : str
        Starts an error message.
    default_boundary : str
        The boundary when neither ``boundary`` nor flags say.

    Returns
    -------
    RiserFrame

    Raises
    ------
    InputError
        For a 3D source without ``vertical_axis`` (the message lists the extents and the
        axis a guess would take), an unknown axis or boundary, ``drop_depth`` on a 2D
        source, a region that does not fit the source's axes, or a riser of no size.
    """
    if boundary is not None:
        boundary = Boundary.parse(boundary, "--boundary")
    if vertical_axis is not None and vertical_axis not in AXES:
        raise InputError(f"--vertical-axis {vertical_axis!r}: choose x, y or z")
    if vertical_axis is None:
        if spread:
            extents = (", ".join(f"{AXES[k]} {lo:g}..{hi:g}" for k, (lo, hi) in enumerate(box))
                       if box is not None else "x, y and z")
            guess = (f"a guess would take the box's longest, "
                     f"{AXES[int(np.argmax(np.diff(box[:3], axis=1)))]}; " if box is not None
                     else "")
            raise InputError(
                f"{where}: 3D positions ({extents} m): say which axis is vertical with "
                f"--vertical-axis x|y|z ({guess}LIGGGHTS puts gravity along -z, "
                "cfbmarkov export-vtk writes y)")
        vertical_axis = "y"
    vertical = AXES.index(vertical_axis)
    if vertical >= n_axes:
        raise InputError(f"{where}: --vertical-axis {vertical_axis} but the source has no "
                         f"{vertical_axis} positions")
    others = [k for k in range(3 if spread else 2) if k != vertical and k < n_axes]
    axes = (others[0], vertical) + ((others[1],) if len(others) > 1 and not drop_depth else ())
    dropped = others[1] if len(others) > 1 and drop_depth else None
    periodic = tuple(len(flags) > k and str(flags[k]).startswith("p") for k in axes)
    if boundary is None:
        boundary = Boundary.parse(("periodic" if periodic[1] else "open") if len(flags) > vertical
                                  else default_boundary)
    if drop_depth and not spread and n_axes == 2:
        raise InputError(f"{where}: --drop-depth drops a third axis, but the source has two "
                         "(x and y): leave --drop-depth out")
    if region is not None:
        ranges = [tuple(float(v) for v in r) for r in region]
        if len(ranges) > 2 and n_axes == 2 and not spread:
            raise InputError(f"{where}: --region gives a z range, but the source's positions "
                             "are 2D (x and y), which it would leave unused: give two "
                             "ranges, --region XMIN:XMAX,YMIN:YMAX")
        if max(axes) >= len(ranges):
            raise InputError(f"--region gives {len(ranges)} ranges but the riser uses the "
                             f"{AXES[max(axes)]} axis: give x, y and z ranges")
        bounds = np.array([ranges[k] for k in axes], dtype=np.float64)
        from_box = False
    else:
        if box is None:
            box = np.array([(0.0, np.nan)] * n_axes)
        bounds = np.array([box[k] for k in axes], dtype=np.float64)
        if width is not None:
            bounds[0] = (0.0, float(width))
        if height is not None:
            bounds[1] = (0.0, float(height))
        from_box = width is None and height is None
    unknown = [k for k in range(len(axes)) if not np.all(np.isfinite(bounds[k]))]
    if unknown == [2] and region is None:
        raise InputError(f"{where}: the riser's depth along {AXES[axes[2]]} is unknown (the "
                         "files carry no box, and --width and --height set the other two): "
                         "give all three ranges with --region XMIN:XMAX,YMIN:YMAX,ZMIN:ZMAX, "
                         "or --drop-depth for a 2D projection")
    if not np.all(np.isfinite(bounds)) or np.any(bounds[:, 1] <= bounds[:, 0]):
        raise InputError(f"{where}: the riser region {bounds.tolist()} m has no size; give it "
                         "with --region")
    if boundary.is_open and periodic[1] and box is not None and vertical < len(box) and (
            np.all(np.isfinite(box[vertical]))):
        lo, hi = (float(v) for v in box[vertical])
        tol = POSITION_TOLERANCE + 1e-9 * max(abs(lo), abs(hi))
        if bounds[1, 0] <= lo + tol and bounds[1, 1] >= hi - tol:
            raise InputError(
                f"{where}: --boundary open, but the box is periodic along {vertical_axis} and "
                f"the riser spans all of it ({lo:g}..{hi:g} m): its particles leave through "
                "the top and come back at the bottom, which an open riser would read as "
                "jumps inside it; leave out --boundary (a periodic riser), or give --region "
                "a section of the height to import it open")
    wrap = _wrap(axes, bounds, periodic, boundary, box, where)
    return RiserFrame(axes, bounds, from_box, periodic, boundary, dropped, wrap)


def _wrap(axes, bounds: np.ndarray, periodic, boundary: Boundary, box, where: str) -> np.ndarray:
    """[lo, period] of each stored axis that wraps (period NaN where none): a periodic box
    axis by its box; the vertical axis of a periodic riser without a periodic box by the
    region. A periodic riser whose height is not the box's period is refused (its laps and
    heights would disagree)."""
    wrap = np.full((len(axes), 2), np.nan)
    for k, a in enumerate(axes):
        if k == 1 and boundary.is_open:
            continue
        box_periodic = (periodic[k] and box is not None and a < len(box)
                        and np.all(np.isfinite(box[a])) and box[a][1] > box[a][0])
        if box_periodic:
            wrap[k] = (box[a][0], box[a][1] - box[a][0])
            if k == 1 and np.abs(bounds[1] - np.asarray(box[a])).max() > (
                    POSITION_TOLERANCE + 1e-9 * float(np.abs(box[a]).max())):
                raise InputError(
                    f"{where}: the riser's vertical range {bounds[1, 0]:g}..{bounds[1, 1]:g} m "
                    f"is not the periodic box's {box[a][0]:g}..{box[a][1]:g} m: a periodic "
                    f"riser is the whole period; give {AXES[a]} as {box[a][0]:g}:{box[a][1]:g} "
                    + ("(--region)" if box[a][0] != 0 else
                       f"(--region, or --height {box[a][1]:g})")
                    + ", or --boundary open to import the section")
        elif k == 1:
            wrap[k] = (bounds[1, 0], bounds[1, 1] - bounds[1, 0])
    return wrap


def riser_positions(raw: np.ndarray, riser: RiserFrame, image: np.ndarray | None = None,
                    unwrapped: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Stored positions, presence and exact laps of one frame's source positions.

    Parameters
    ----------
    raw : numpy.ndarray, shape (N, n_axes)
        Source positions (m), x y (z).
    riser : RiserFrame
        The riser.
    image : numpy.ndarray of int, shape (N,), optional
        Image flags of the vertical axis (periodic sources).
    unwrapped : bool
        Whether ``raw`` is unwrapped (periodic images not folded back).

    Returns
    -------
    positions : numpy.ndarray, shape (N, D)
        (across, vertical[, depth]) from the region's lower corner (m).
    inside : numpy.ndarray of bool, shape (N,)
        Which particles lie in the region (the others are absent).
    laps : numpy.ndarray of int64, shape (N,), or None
        Exact laps on a periodic vertical boundary: floor(y / H) of unwrapped positions,
        or the image flag (plus any wrap of an atom written just outside the box); None
        where they must come from the minimal-image rule, or for an open riser.

    Notes
    -----
    On a periodic vertical boundary the height is wrapped into 0..H; a periodic across (or
    depth) axis is wrapped likewise. Positions within ``POSITION_TOLERANCE`` outside the
    region count as inside and are clipped to it (round-off).
    """
    pos = raw[:, list(riser.axes)] - riser.region[:, 0]
    extent = riser.region[:, 1] - riser.region[:, 0]
    laps = None
    for k, periodic in enumerate(riser.periodic):
        if riser.wrap is not None:
            lo, period = riser.wrap[k]
            if not np.isfinite(period):
                continue
        elif (k == 1 and riser.boundary.is_open) or not (periodic or k == 1):
            continue
        else:
            lo, period = riser.region[k, 0], extent[k]
        offset = lo - riser.region[k, 0]               # the period's start, from the region's
        wraps = np.floor((pos[:, k] - offset) / period)
        pos[:, k] -= wraps * period
        top = offset + period
        pos[pos[:, k] >= top, k] = offset              # round-off of a tiny negative value
        if k == 1:
            if unwrapped:
                laps = wraps.astype(np.int64)
            elif image is not None:
                laps = image.astype(np.int64) + wraps.astype(np.int64)
    tol = POSITION_TOLERANCE
    inside = np.all((pos >= -tol) & (pos <= extent + tol), axis=1)
    np.clip(pos, 0.0, extent, out=pos)
    return pos, inside, laps


def region_notes(riser, box, rows: int, outside: int, flags: tuple[str, ...] = ()
                 ) -> list[str]:
    """The import's notes on its region: the particle rows outside it (absent in the file)
    and the sides where it reaches beyond the source's box.

    Parameters
    ----------
    riser : RiserFrame
        The riser's region (source coordinates, m).
    box : ndarray of float64, shape (3, 2), or None
        The source's box (source coordinates), where it has one.
    rows, outside : int
        Particle rows read, and of them those outside the region.
    flags : tuple of str, optional
        The box's boundary flags per source axis (LAMMPS: ``pp``, ``ff``, ``ss``, ``mm``):
        a shrink-wrapped side (``s``, ``m``) follows the particles and is not compared.

    Returns
    -------
    list of str
    """
    notes = []
    if outside:
        notes.append(f"{outside} of {rows} particle rows ({100 * outside / max(rows, 1):.3g} %) "
                     "lie outside the riser's region and are absent there; if that is not "
                     "the particles leaving the riser, check --width/--height (from 0 in the "
                     "source's coordinates) or --region")
    if box is not None and not riser.from_box:
        letters = "xyz"
        for k, axis in enumerate(riser.axes):
            if len(flags) > axis and any(c in "sm" for c in str(flags[axis])):
                continue
            lo, hi = riser.region[k]
            b_lo, b_hi = box[axis]
            tol = 1e-9 * max(abs(b_hi - b_lo), 1.0)
            if lo < b_lo - tol or hi > b_hi + tol:
                notes.append(f"the region's {letters[axis]} {lo:g}..{hi:g} reaches beyond the "
                             f"source's box {b_lo:g}..{b_hi:g}: no particle can lie in the part "
                             "outside it")
    return notes


class FrameColumns:
    """Puts each frame's particles into the writer's columns, adding particles that appear
    for the first time (inserted, entering the view) as new columns.

    Parameters
    ----------
    writer : TrajectoryWriter
        The open writer (its ids are the columns so far).

    Attributes
    ----------
    rows, outside : int
        Particle rows placed so far, and of them those outside the region.
    """

    def __init__(self, writer: TrajectoryWriter):
        self.writer = writer
        self.rows = 0
        self.outside = 0
        self._refresh()

    def _refresh(self) -> None:
        self._order = np.argsort(self.writer.ids, kind="stable")
        self._sorted = self.writer.ids[self._order]

    def columns(self, ids: np.ndarray, where: str) -> np.ndarray:
        """The column of each of a frame's ids, adding new ids (sorted) to the writer.

        Parameters
        ----------
        ids : numpy.ndarray of int64, shape (M,)
            The frame's ids, in row order.
        where : str
            Starts an error message.

        Returns
        -------
        numpy.ndarray of int64, shape (M,)

        Raises
        ------
        InputError
            If an id appears twice in the frame.
        """
        unique = np.unique(ids)
        if unique.size != ids.size:
            srt = np.sort(ids)
            repeated = srt[1:][srt[1:] == srt[:-1]][0]
            raise InputError(f"{where}: particle id {repeated} appears more than once (two rows "
                             "for one particle at one time): remove one of them (a CSV "
                             "imported with --resample DT merges the rows of a particle at one "
                             "time)")
        pos = np.searchsorted(self._sorted, ids)
        known = (pos < self._sorted.size) & (self._sorted[np.minimum(pos, self._sorted.size - 1)]
                                             == ids) if self._sorted.size else np.zeros(ids.size, bool)
        if not known.all():
            self.writer.add_particles(np.sort(ids[~known]))
            self._refresh()
            pos = np.searchsorted(self._sorted, ids)
        return self._order[pos]

    def frame(self, ids: np.ndarray, positions: np.ndarray, inside: np.ndarray,
              velocities: np.ndarray | None, laps: np.ndarray | None, where: str):
        """Full-width arrays of one frame: every column, absent where the frame has no such
        particle or it lies outside the region.

        Parameters
        ----------
        ids : numpy.ndarray of int64, shape (M,)
            The frame's ids.
        positions : numpy.ndarray, shape (M, D)
            Stored positions (m).
        inside : numpy.ndarray of bool, shape (M,)
            Which lie in the region.
        velocities : numpy.ndarray, shape (M, D), or None
            Velocities (m/s).
        laps : numpy.ndarray of int, shape (M,), or None
            Exact laps, or None.
        where : str
            Starts an error message.

        Returns
        -------
        tuple
            (positions [N, D], velocities [N, D] or None, laps [N] or None, present [N]) for
            :meth:`TrajectoryWriter.append`.
        """
        cols = self.columns(ids, where)
        self.rows += int(inside.size)
        self.outside += int(inside.size - np.count_nonzero(inside))
        n, d = self.writer.ids.size, positions.shape[1]
        full = np.full((n, d), np.nan)
        full[cols] = positions
        present = np.zeros(n, dtype=bool)
        present[cols] = inside
        vel = None
        if velocities is not None:
            vel = np.full((n, d), np.nan)
            vel[cols] = velocities
        lap = None
        if laps is not None:
            lap = np.zeros(n, dtype=np.int64)
            lap[cols] = laps
        return full, vel, lap, present
