"""Discrete trajectories: the one step from trajectory frames to Markov states.

Everything in :mod:`cfbmarkov.markov` that learns from data (the estimators, the automatic
choice of the state space, the lag diagnostics, the initial states of a prediction) works
on a :class:`DiscreteTrajectories`: the states of every particle in every frame of one
analysis window, held in memory, with the lag in frames and the frame interval it was made
with. This module is the only code that turns frames into states, and so the only code
that knows about *history frames*: a state space with memory (``memory_lags > 0``, e.g.
the direction of motion over the previous lag) needs ``memory_lags * lag_frames`` frames
before the window's first frame; they are read, used to discretise and dropped.

The lag exists once, in frames (``lag_frames``); seconds appear only at the edge
(``lag = lag_frames * frame_interval``), and a state space that needs a time (velocity bins
from displacements) takes the frame interval from here, so the lag it uses cannot
disagree with the model's.

Absent particles: a state of ``-1`` (:data:`ABSENT`) marks a particle that is not present
in a frame; counting skips every transition with an absent end. Files written today hold
every particle in every frame, so no state is ``-1`` yet; the layout is ready for data in
which particles come and go.

Layout of the arrays (T frames of the window, N particles)::

    states    int32   [T, N]   state of each particle in each frame (-1: absent)
    vertical  float64 [T, N]   height of each particle (m), for the boundary passes
    times     float64 [T]      frame times (s)

See ``docs/definitions.md`` (States and transitions) for the definitions.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from cfbmarkov.errors import HistoryError, InputError
from cfbmarkov.markov.frame_quantities import FrameQuantities
from cfbmarkov.markov.states import StateSpace
from cfbmarkov.observed.lag_resolution import PassReading
from cfbmarkov.trajectories import Trajectories, opened
from cfbmarkov.trajectory_format import FRAME_SPACING_TOLERANCE, POSITION_TOLERANCE, time_text

#: the state of a particle that is absent in a frame
ABSENT = -1


@dataclass(frozen=True, eq=False)
class DiscreteTrajectories:
    """The discrete trajectories of one analysis window, in memory.

    Parameters
    ----------
    states : ndarray of int32, shape (T, N)
        State of particle p in frame t of the window (``ABSENT`` = -1 where absent).
    vertical : ndarray of float64, shape (T, N)
        Height y (m) of each particle in each frame; the pass through the periodic
        boundary of a transition is taken from it by the minimal-image rule.
    times : ndarray of float64, shape (T,)
        Times (s) of the frames.
    lag_frames : int
        The lag, in frames (>= 1).
    frame_interval : float
        Time between frames (s).
    height : float
        Height H of the riser (m), the period of the vertical axis.
    state_space : StateSpace
        The state space the states belong to.
    window : tuple of float or None
        The analysis window (A, B) in s as asked for (None: all frames).
    source : str
        Where the frames came from (a file path, or a description).
    positions : ndarray of float64, shape (T, N, D), optional
        Positions (m; D = 3 in a 3D file), kept only where asked for (e.g. to place a
        prediction's first frame).
    laps : ndarray of int64, shape (T, N), optional
        Lap counters, kept only where asked for.
    boundary : {"periodic", "open"}, optional
        The riser's vertical boundary: on an open one, a particle that vanishes within one
        cell of the outlet face has left, one that appears within one cell of the inlet
        face has entered (``docs/definitions.md``, Open risers).
    pass_reading : PassReading, optional
        How the heights one lag apart read the periodic boundary's passes against the file's
        laps (:func:`cfbmarkov.observed.lag_resolution.read_passes`); the estimators refuse
        a lag that misreads them. None: not read (an open riser, or arrays made by hand).

    Raises
    ------
    InputError
        If ``states`` is not 2-D or not whole numbers in -1 .. S-1, ``vertical`` has
        another shape or a height that is not finite or lies outside 0 .. ``height`` where
        a particle is present, ``times`` does not hold one time per frame,
        ``lag_frames`` is not a whole number >= 1, ``frame_interval`` is not a positive
        finite number, the times are not spaced by it, ``state_space`` is no state space,
        or (arrays given by a caller) ``positions`` or ``laps`` do not match the states'
        shape, ``height`` is not the state space's, or ``window`` holds none of the frames.

    See Also
    --------
    discretize : makes them from a trajectory file.

    Notes
    -----
    The arrays are held read-only; an array given writeable (a caller's buffer) is copied
    first, so that writing to it afterwards cannot change the trajectories. The checks of
    states, heights and times run on arrays given that way (or as lists); the read-only
    arrays :func:`discretize` makes were checked where they were read. See
    ``docs/definitions.md`` (Discrete trajectories).
    """

    states: np.ndarray
    vertical: np.ndarray
    times: np.ndarray
    lag_frames: int
    frame_interval: float
    height: float
    state_space: StateSpace
    window: tuple[float, float] | None = None
    source: str = ""
    positions: np.ndarray | None = field(default=None, repr=False)
    laps: np.ndarray | None = field(default=None, repr=False)
    boundary: str = "periodic"
    pass_reading: PassReading | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        if self.boundary not in ("periodic", "open"):
            raise InputError(f"boundary {self.boundary!r}: choose periodic or open")
        # made by discretize or a block of it: read-only arrays, checked where they were
        # made; a caller's arrays (writeable, or not arrays) are checked here
        given = any(not isinstance(getattr(self, name), np.ndarray)
                    or getattr(self, name).flags.writeable
                    for name in ("states", "vertical", "times"))
        for name in ("states", "vertical", "times", "positions", "laps"):
            if getattr(self, name) is not None and not isinstance(getattr(self, name),
                                                                  np.ndarray):
                try:
                    object.__setattr__(self, name, np.asarray(getattr(self, name)))
                except (TypeError, ValueError) as error:
                    raise InputError(f"discrete trajectories: {name} is not an array "
                                     f"({error}); give a numpy array") from None
        if self.states.ndim != 2 or self.vertical.shape != self.states.shape:
            raise InputError(f"discrete trajectories: states {self.states.shape} and heights "
                             f"{self.vertical.shape} must both be [T, N]")
        if self.times.shape != (self.states.shape[0],):
            raise InputError(f"discrete trajectories: {self.times.size} times for "
                             f"{self.states.shape[0]} frames")
        whole = (not isinstance(self.lag_frames, bool)
                 and isinstance(self.lag_frames, (int, np.integer, float, np.floating))
                 and np.isfinite(self.lag_frames)
                 and abs(self.lag_frames - round(self.lag_frames)) <= 1e-9 * abs(
                     self.lag_frames))
        if not whole:
            # a fractional lag counts transitions of whole frames labelled with its length
            raise InputError(f"lag of {self.lag_frames!r} frames: a whole number of frames "
                             "(round(lag / frame_interval))")
        object.__setattr__(self, "lag_frames", int(round(self.lag_frames)))
        if int(self.lag_frames) < 1:
            raise InputError(f"lag of {self.lag_frames} frames: must be at least 1")
        if not (np.isfinite(self.frame_interval) and self.frame_interval > 0):
            raise InputError(f"frame interval {self.frame_interval!r} s must be positive")
        if not hasattr(self.state_space, "n_states"):
            raise InputError(f"discrete trajectories: state_space {self.state_space!r} is no "
                             "state space; give one (e.g. CellGrid(6, 38, 0.09, 0.95))")
        if given:
            self._check_times()
            self._check_states()
            self._check_heights()
            self._check_others()
        for name in ("states", "vertical", "times", "positions", "laps"):
            values = getattr(self, name)
            # as immutable as a model: a writeable array (a caller's buffer) is copied, so
            # that writing to it later cannot change these trajectories
            if isinstance(values, np.ndarray) and values.flags.writeable:
                object.__setattr__(self, name, _frozen(values.copy()))

    def _check_others(self):
        """Refuse positions or laps of another shape than the states', a height other than
        the state space's, and a window that holds none of the frames."""
        shape = self.states.shape
        if self.positions is not None and (self.positions.ndim != 3
                                           or self.positions.shape[:2] != shape):
            raise InputError(f"discrete trajectories: positions {self.positions.shape} for "
                             f"states {shape}: give them [T, N, D]")
        if self.laps is not None and (self.laps.shape != shape
                                      or self.laps.dtype.kind not in "iu"):
            raise InputError(f"discrete trajectories: laps {self.laps.shape} of type "
                             f"{self.laps.dtype} for states {shape}: give whole numbers [T, N]")
        space_height = getattr(self.state_space, "height", None)
        if space_height is not None and not np.isclose(float(space_height),
                                                       float(self.height)):
            # the tolerance of discretize's domain check (check_domain)
            raise InputError(f"discrete trajectories: height {self.height:.10g} m, but the "
                             f"state space's grid is {float(space_height):.10g} m high; give "
                             "the riser's height in m, as the grid has it")
        if self.window is not None and self.times.size:
            a, b = (float(v) for v in self.window)
            tol = self._tolerance()
            if not (a <= b and a <= float(self.times[-1]) + tol
                    and b >= float(self.times[0]) - tol):
                raise InputError(f"discrete trajectories: window {a:g}:{b:g} s holds none of "
                                 f"the frames ({float(self.times[0]):g} to "
                                 f"{float(self.times[-1]):g} s); give the window they are of")

    def _check_times(self):
        """Refuse times not evenly spaced by the frame interval (as a trajectory file's
        writer judges them: every step within 1 % of their median, and the median within
        1 % of the frame interval)."""
        steps = np.diff(self.times)
        if not steps.size:
            return
        median = float(np.median(steps))
        tolerance = FRAME_SPACING_TOLERANCE * self.frame_interval
        if not (abs(median - self.frame_interval) <= tolerance
                and np.all(np.abs(steps - median) <= tolerance)):
            raise InputError(f"discrete trajectories: the times are not spaced by the frame "
                             f"interval {self.frame_interval:g} s (steps {steps.min():g} .. "
                             f"{steps.max():g} s); give frames evenly spaced by it")

    def _check_states(self):
        """Refuse states that are not whole numbers in -1 .. S-1 (the counting kernels
        index arrays with them)."""
        states = self.states
        if states.dtype.kind not in "iu":
            raise InputError(f"discrete trajectories: states of type {states.dtype} must be "
                             "integers (the state index, -1 where a particle is absent); "
                             "give an int32 array")
        if states.size:
            low, high = int(states.min()), int(states.max())
            n = self.state_space.n_states
            if low < ABSENT or high >= n:
                raise InputError(f"discrete trajectories: states run {low} .. {high}, outside "
                                 f"the state space's 0 .. {n - 1} (and {ABSENT} for an absent "
                                 "particle); number the states from 0 "
                                 "(state_space.discretize gives them)")
        if states.dtype != np.int32:
            object.__setattr__(self, "states", states.astype(np.int32))

    def _check_heights(self):
        """Refuse heights that are not finite, or outside 0 .. H, where a particle is
        present (the boundary's passes are read from them)."""
        present = self.states != ABSENT
        if not present.any():
            return
        heights = self.vertical if present.all() else self.vertical[present]
        if not np.all(np.isfinite(heights)):
            raise InputError("discrete trajectories: a height is NaN or infinite where its "
                             "particle is present; give every present particle its height "
                             "(m), or the state -1")
        low, high = float(heights.min()), float(heights.max())
        if low < -POSITION_TOLERANCE or high > self.height + POSITION_TOLERANCE:
            raise InputError(f"discrete trajectories: heights run {low:g} .. {high:g} m, "
                             f"outside the riser's 0 .. {self.height:g} m; give the heights "
                             "in m within the riser")

    @property
    def lag(self) -> float:
        """The lag in s (``lag_frames * frame_interval``)."""
        return self.lag_frames * self.frame_interval

    @property
    def n_frames(self) -> int:
        """Number of frames T of the window."""
        return int(self.states.shape[0])

    @property
    def n_particles(self) -> int:
        """Number of particles N."""
        return int(self.states.shape[1])

    def _tolerance(self) -> float:
        # as Trajectories.window (half the frame-spacing tolerance of an interval), so that
        # a block selects the frames the file would
        return 0.5 * FRAME_SPACING_TOLERANCE * self.frame_interval

    def matches_lag(self, lag: float) -> bool:
        """Whether ``lag`` (s) is this window's lag, to the frame-time tolerance."""
        return abs(self.lag - float(lag)) <= self._tolerance()

    def block(self, start: float, stop: float) -> "DiscreteTrajectories":
        """The frames with ``start <= t <= stop`` (s), e.g. one fold of a cross-validation.

        Parameters
        ----------
        start, stop : float
            The block's first and last time (s), matched to frames within the tolerance
            of :meth:`cfbmarkov.trajectories.Trajectories.window`.

        Returns
        -------
        DiscreteTrajectories
            The same trajectories restricted to those frames (views, no copy), with
            ``window = (start, stop)`` clipped to the window these were discretized on
            (a block reaching outside it holds only the frames inside).

        Raises
        ------
        InputError
            If the block holds fewer than two frames one lag apart.
        """
        tol = self._tolerance()
        i0 = int(np.searchsorted(self.times, start - tol, side="left"))
        i1 = int(np.searchsorted(self.times, stop + tol, side="right"))
        if i1 - i0 <= self.lag_frames:
            raise InputError(f"window {start:g}:{stop:g} s holds fewer than two frames one "
                             f"lag ({self.lag:g} s) apart")
        if self.window is not None:      # what it holds: no wider than the window discretized
            start, stop = max(start, self.window[0]), min(stop, self.window[1])
        rows = slice(i0, i1)
        return replace(self, states=self.states[rows], vertical=self.vertical[rows],
                       times=self.times[rows], window=(float(start), float(stop)),
                       positions=None if self.positions is None else self.positions[rows],
                       laps=None if self.laps is None else self.laps[rows])

    def trajectories(self) -> list[np.ndarray]:
        """Per-particle state sequences, the layout deeptime's estimators take.

        Returns
        -------
        list of ndarray of int32, shape (T,)
            One array per particle (N in all), one entry per frame of the file (not per
            lag).

        Notes
        -----
        Three things differ from this package's own estimators: deeptime's ``lagtime`` is
        in frames, so give it :attr:`lag_frames` (a lag of 0.05 s on frames 0.025 s apart
        is 2); the entries are ``-1`` (:data:`ABSENT`) where a particle is absent (an open
        riser, a tracked particle out of view), which deeptime's counting does not take,
        so split the sequences there first; and the passes through a periodic riser's top
        and bottom are not in the states, so a chain counted by deeptime has no RTD (the
        passes come from :attr:`vertical` and :attr:`laps`).
        """
        return list(np.ascontiguousarray(self.states.T))

    def __repr__(self) -> str:
        span = (f"{time_text(self.times[0])}..{time_text(self.times[-1])} s" if self.n_frames
                else "no frames")
        frames = "frame" if self.lag_frames == 1 else "frames"
        return (f"DiscreteTrajectories({self.state_space.describe()}, {self.n_particles} "
                f"particles x {self.n_frames} frames, {span}, lag {self.lag_frames} {frames} = "
                f"{self.lag:g} s)")


@dataclass(frozen=True, eq=False)
class WindowFrames:
    """The frames of one window and the history before it, read from a file once.

    Several state spaces (the candidates of ``--states auto``) are then discretised on the
    same frames without going back to the file, sharing what they derive from them: the
    frames own one :class:`~cfbmarkov.markov.frame_quantities.FrameQuantities` memo per
    array of positions they hand to the spaces. The arrays cover the frames
    ``first .. stop - 1`` of the file; the window's own frames start at row ``history``
    (``first + history`` in the file). Made by :func:`read_frames`.

    Parameters
    ----------
    positions : ndarray of float64, shape (F, N, D)
        Positions (m) of the frames read, D = 2, or 3 in a 3D file.
    velocities : ndarray of float64, shape (F, N, D), or None
        Velocities (m/s), or None where they were not read.
    times : ndarray of float64, shape (F,)
        Times (s) of the frames read.
    laps : ndarray of int32, shape (F, N), or None
        Lap counters, or None where they were not read.
    history : int
        Number of history rows before the window's first frame.
    frame_interval : float
        Time between frames (s).
    width, height : float
        The riser W x H (m).
    window : tuple of float or None
        The analysis window (A, B) in s as asked for (None: all frames).
    source : str
        The file the frames came from.
    present : ndarray of bool, shape (F, N), or None
        Which particles are in each frame read; None: every particle in every frame.
    boundary : {"periodic", "open"}
        The riser's vertical boundary.
    depth : float or None, optional
        The riser's depth (m) of a 3D file; None in 2D.
    """

    positions: np.ndarray
    velocities: np.ndarray | None
    times: np.ndarray
    laps: np.ndarray | None
    history: int
    frame_interval: float
    width: float
    height: float
    window: tuple[float, float] | None
    source: str
    present: np.ndarray | None = None
    boundary: str = "periodic"
    depth: float | None = None
    # per first row: the memo of the positions given to the spaces (the view and what they
    # derive from it: cells, displacements); per window start: the window's contiguous
    # heights. Shared by every state space discretised on these frames.
    _memos: dict[int, FrameQuantities] = field(default_factory=dict, repr=False,
                                               compare=False)
    _heights: dict[int, np.ndarray] = field(default_factory=dict, repr=False, compare=False)
    # per lag (in frames): how the heights one lag apart read the periodic boundary's passes
    _pass_readings: dict = field(default_factory=dict, repr=False, compare=False)

    def _pass_reading(self, lag_frames: int):
        """How the heights one lag apart read a periodic riser's passes against the file's
        laps (:func:`cfbmarkov.observed.lag_resolution.read_passes`), once per lag; None on
        an open riser or where no laps were read."""
        if self.laps is None or self.boundary == "open":
            return None
        if lag_frames not in self._pass_readings:
            from cfbmarkov.observed.lag_resolution import read_passes

            self._pass_readings[lag_frames] = read_passes(
                self.positions[:, :, 1], self.laps, lag_frames, self.height,
                self.frame_interval, self.source)
        return self._pass_readings[lag_frames]

    def discretize(self, state_space: StateSpace, lag_frames: int, *,
                   keep_positions: bool = False) -> DiscreteTrajectories:
        """The discrete trajectories of the window for ``state_space`` at ``lag_frames``.

        Where the frames read hold less history than the state space needs, the window's
        start moves past it (only :func:`read_frames` with ``short_history="skip"`` reads
        such frames).

        Parameters
        ----------
        state_space : StateSpace
            How positions (and motion) become states; it needs
            ``state_space.memory_lags * lag_frames`` frames of history.
        lag_frames : int
            The lag, in frames.
        keep_positions : bool, optional
            Keep the positions (and laps, where read) of the window's frames.

        Returns
        -------
        DiscreteTrajectories

        Raises
        ------
        InputError
            If the state space does not cover the frames' domain, needs velocities the
            frames lack, or the window holds fewer than two frames one lag apart.
        """
        state_space = check_domain(state_space, self.width, self.height, self.source,
                                   self.depth)
        lag_frames = int(lag_frames)
        reading = self._pass_reading(lag_frames)
        if state_space.needs_velocity and self.velocities is None:
            raise InputError(f"state space {state_space.kind} needs velocities; {self.source} "
                             "has none")
        need = state_space.memory_lags * lag_frames
        first = self.history - need
        window = self.window
        if first < 0:              # too little history: the window starts where it has it
            first, start = 0, need
            if window is not None and start < self.times.size:
                window = (max(window[0], float(self.times[start])), window[1])
        else:
            start = self.history
        frames = slice(first, None)
        if first not in self._memos:
            self._memos[first] = FrameQuantities(self.positions[frames],
                                                 periodic=self.boundary != "open")
        memo = self._memos[first]
        positions = memo.positions
        velocities = None if self.velocities is None else self.velocities[frames]
        # a space that learns from the fitting window (regime edges) learns it here
        state_space = state_space.fit_to_frames(positions, lag_frames, self.frame_interval,
                                                memo=memo)
        # absent particles (NaN) get some state, masked here with those whose history is
        # incomplete
        states = state_space.discretize(positions, velocities, lag_frames, self.frame_interval,
                                        memo=memo)
        if self.present is not None:
            states[~_known(self.present[frames], need, lag_frames)] = ABSENT
        offset = start - first
        rows = slice(start, None)
        if start not in self._heights:
            self._heights[start] = np.ascontiguousarray(self.positions[rows, :, 1])
            self._heights[start].setflags(write=False)
        # read-only views of arrays these frames own: not copied by DiscreteTrajectories
        return DiscreteTrajectories(
            states=_frozen(np.ascontiguousarray(states[offset:])),
            vertical=self._heights[start],
            times=_read_only(self.times[rows]), lag_frames=lag_frames,
            frame_interval=self.frame_interval,
            height=self.height, state_space=state_space, window=window, source=self.source,
            positions=_read_only(self.positions[rows]) if keep_positions else None,
            laps=None if (self.laps is None or not keep_positions)
            else _read_only(self.laps[rows]),
            boundary=self.boundary, pass_reading=reading)


def _read_only(values: np.ndarray) -> np.ndarray:
    """A read-only view of ``values``, whose owner keeps it."""
    view = values.view()
    view.setflags(write=False)
    return view


def _frozen(values: np.ndarray) -> np.ndarray:
    """A read-only view of ``values`` (which this code owns from here on)."""
    values.setflags(write=False)
    view = values.view()
    view.setflags(write=False)
    return view


def _known(present: np.ndarray, history: int, lag_frames: int) -> np.ndarray:
    """Where a state is defined: the particle is present in the frame and in every frame
    its state looks back to (t - lag, t - 2 lag, ... within ``history`` frames)."""
    known = present.copy()
    for back in range(lag_frames, history + 1, lag_frames):
        known[back:] &= present[:-back]
        known[:back] = False
    return known


def _describe(window) -> str:
    return "(all)" if window is None else f"{window[0]:g}:{window[1]:g} s"


def check_domain(state_space: StateSpace, width: float, height: float, source: str = "",
                 depth: float | None = None) -> StateSpace:
    """Check that ``state_space`` covers a riser of W x H = ``width`` x ``height`` (m)
    [x ``depth``]; a space made without a size takes this one.

    A 2D state space fits 3D data (it uses the projection on across x vertical); a 3D one
    (with depth columns) needs 3D data of its depth.

    Parameters
    ----------
    state_space : StateSpace
        The state space to check.
    width, height : float
        The riser's width W and height H (m), e.g. those of a trajectory file.
    source : str, optional
        Named in the error message (e.g. the file's path).
    depth : float, optional
        The riser's depth (m) of 3D data; None for 2D data.

    Returns
    -------
    StateSpace
        ``state_space``, or, made without a size, a copy of it with this size
        (:meth:`~cfbmarkov.markov.states.StateSpace.with_size`).

    Raises
    ------
    InputError
        If the state space's width or height differ from ``width`` or ``height``
        (beyond :func:`numpy.isclose`), or it has a depth and the data have none or
        another one.
    """
    if not state_space.sized:
        state_space = state_space.with_size(width, height)
    if not (np.isclose(state_space.width, width) and np.isclose(state_space.height, height)):
        raise InputError(f"state space covers {state_space.width:g} x {state_space.height:g} m "
                         f"but {source} is {width:g} x {height:g} m: a model's states are of "
                         "the riser it was fitted on (give a run of that riser, or fit a model "
                         "on this one; in Python, a state space made without a size takes the "
                         "file's)")
    if state_space.depth is not None:
        if depth is None:
            raise InputError(f"state space {state_space.describe()} has depth columns but "
                             f"{source} is 2D: give a 3D file, or fit with COLUMNSxROWS cells")
        if not np.isclose(state_space.depth, depth):
            raise InputError(f"state space covers a depth of {state_space.depth:g} m but "
                             f"{source} is {depth:g} m deep: give a run of the riser the "
                             "model was fitted on, or fit a model on this one")
    return state_space


def _read_rows(trajectories: Trajectories, start: int, stop: int, history: int,
               window: tuple[float, float] | None, velocities: bool, laps: bool,
               short_history: str) -> WindowFrames:
    """Frames ``start .. stop - 1`` of the file and ``history`` frames before them."""
    first = start - int(history)
    if first < 0:
        if short_history != "skip":
            where = (f"the start of the window {_describe(window)}" if window is not None
                     else f"t = {trajectories.times[start]:g} s")
            fix, earliest = "", None
            if int(history) < trajectories.n_frames:
                earliest = float(trajectories.times[int(history)])
                what = "start the window" if window is not None else "start"
                fix = f": {what} at {earliest:g} s or later"
            raise HistoryError(f"the state space needs {history} frame(s) of history before "
                               f"{where}; {trajectories.path} has {start}{fix}", earliest,
                               None if window is None else float(window[1]))
        first = 0
    rows = slice(first, stop)
    if window is not None and stop > start:
        # a window whose ends fall between frames is the frames it holds: its length is
        # what the model's figures "as the window sees it" are of (4.975 s of frames for
        # 10.01:15 on frames every 0.025 s, not 4.99 s)
        held = float(trajectories.times[start]), float(trajectories.times[stop - 1])
        tol = trajectories.time_tolerance
        window = tuple(float(w) if abs(w - h) <= tol else h for w, h in zip(window, held))
    return WindowFrames(
        positions=trajectories.positions(rows),
        velocities=trajectories.velocities(rows) if velocities else None,
        # a periodic riser's laps always: they check that the lag resolves its passes
        times=trajectories.times[rows],
        laps=(trajectories.laps(rows) if laps or not trajectories.boundary.is_open
              else None),
        history=start - first, frame_interval=trajectories.frame_interval,
        width=trajectories.width, height=trajectories.height,
        window=None if window is None else (float(window[0]), float(window[1])),
        source=str(trajectories.path),
        present=trajectories.present(rows) if trajectories.has_absences else None,
        boundary=trajectories.boundary, depth=trajectories.depth)


def held_window(run, window: tuple[float, float]) -> tuple[float, float]:
    """``window`` as the frames of ``run`` it holds (:meth:`Trajectories.held
    <cfbmarkov.frame_times.FrameTimes.held>`): what a model fitted on it stores, whatever
    the window typed (a file written before models stored the frames held keeps the typed
    one); the window as given where it does not lie in the run's frames.

    Parameters
    ----------
    run : str, os.PathLike or Trajectories
    window : (float, float)
        Start and end (s).

    Returns
    -------
    (float, float)
    """
    try:
        with opened(run) as traj:
            return traj.held(float(window[0]), float(window[1]))
    except (InputError, OSError):
        return float(window[0]), float(window[1])


def read_frames(trajectories: Trajectories, window: tuple[float, float] | None,
                history: int = 0, *, velocities: bool = False, laps: bool = False,
                short_history: str = "error") -> WindowFrames:
    """Read the frames of ``window`` and ``history`` frames before it.

    Parameters
    ----------
    trajectories : Trajectories
        An open trajectory file.
    window : tuple of float or None
        (A, B) in s: the frames with A <= t <= B. None: every frame of the file after the
        history.
    history : int
        Frames needed before the window's first frame (``memory_lags * lag_frames``).
    velocities, laps : bool
        Also read velocities / lap counters.
    short_history : {"error", "skip"}
        What to do when the file holds fewer than ``history`` frames before the window:
        raise, or move the window's start later (the window then starts at the first frame
        that has its history).

    Returns
    -------
    WindowFrames

    Raises
    ------
    InputError
        If the window is empty, lies outside the data or holds no frame, or
        (``short_history="error"``) the history is missing.
    """
    if window is None:
        start, stop = min(int(history), trajectories.n_frames), trajectories.n_frames
    else:
        start, stop, _ = trajectories.window(*window).indices(trajectories.n_frames)
    return _read_rows(trajectories, start, stop, history, window, velocities, laps,
                      short_history)


def check_arguments(state_space, lag, window=None) -> None:
    """Refuse, in one line naming the expected form, arguments of the wrong kind (a state
    space given as a tuple, a lag or window as text) before they reach numpy.

    Parameters
    ----------
    state_space : StateSpace
    lag : float
        The lag (s).
    window : (float, float) or None, optional
        A fitting window (s).

    Raises
    ------
    InputError
        Naming the argument, what was given and an example of the right form.
    """
    import numbers

    if not isinstance(state_space, StateSpace):
        raise InputError(f"state space {state_space!r} is a {type(state_space).__name__}, not "
                         "a state space: give e.g. CellGrid(6, 38) (cfbmarkov.markov), or "
                         "state_space_from_name('cells-previous', 6, 38)")
    if isinstance(lag, bool) or not isinstance(lag, numbers.Real):
        raise InputError(f"lag {lag!r} is a {type(lag).__name__}, not a number of seconds: "
                         "give e.g. lag=0.025")
    if not (np.isfinite(float(lag)) and float(lag) > 0):
        raise InputError(f"lag {float(lag):g} s must be a positive finite number (a whole "
                         "number of frame intervals): give e.g. lag=0.025")
    if window is None:
        return
    ok = (isinstance(window, (tuple, list, np.ndarray)) and len(window) == 2 and all(
        isinstance(v, numbers.Real) and not isinstance(v, bool) for v in window))
    if not ok or not float(window[0]) < float(window[1]):
        raise InputError(f"window {window!r} is not (start, stop) in s with start < stop: "
                         "give e.g. window=(10.0, 15.0)")


def _prepare(traj: Trajectories, state_space: StateSpace, lag: float) -> int:
    """Check that ``state_space`` fits the file and return the lag in frames (NaN as the
    lag: check the fit only, return 0)."""
    traj.require_supported("a Markov model", three_d=True, absent=True,
                           open_boundary=True)   # a 2D grid projects 3D data
    check_domain(state_space, traj.width, traj.height, str(traj.path), traj.depth)
    lag_frames = traj.lag_frames(lag) if np.isfinite(lag) else 0
    if state_space.needs_velocity and not traj.has_velocity:
        raise InputError(f"state space {state_space.kind} needs velocities; {traj.path} "
                         "has none")
    return lag_frames


def discretize(source, state_space: StateSpace, lag: float,
               window: tuple[float, float] | None = None, *, keep_positions: bool = False,
               short_history: str = "error") -> DiscreteTrajectories:
    """Turn the frames of ``window`` into discrete trajectories (the convenience wrapper
    that opens files).

    Parameters
    ----------
    source : str, os.PathLike or Trajectories
        A trajectory file, by path or open.
    state_space : StateSpace
        How positions (and motion) become states.
    lag : float
        The lag (s); a whole multiple of the file's frame interval.
    window : tuple of float or None
        (A, B) in s; None: all frames that have the history the state space needs.
    keep_positions : bool
        Keep positions and laps of the window's frames.
    short_history : {"error", "skip"}
        See :func:`read_frames` (None as the window always skips).

    Returns
    -------
    DiscreteTrajectories

    Raises
    ------
    InputError
        If the file cannot be read, the lag is not a whole number of frames, the window
        lies outside the data, lacks history or holds fewer than two frames one lag apart,
        or the state space does not fit the file (domain, or velocities it needs and the
        file lacks).

    Notes
    -----
    See ``docs/definitions.md`` (Discrete trajectories; Lag and fitting window).
    """
    check_arguments(state_space, lag, window)
    with opened(source) as traj:
        lag_frames = _prepare(traj, state_space, lag)
        frames = read_frames(traj, window, state_space.memory_lags * lag_frames,
                             velocities=state_space.needs_velocity, laps=keep_positions,
                             short_history="skip" if window is None else short_history)
        discrete = frames.discretize(state_space, lag_frames, keep_positions=keep_positions)
    if discrete.n_frames <= lag_frames:
        raise InputError(f"window {_describe(window)} of {discrete.source} holds fewer than "
                         f"two frames one lag ({lag:g} s) apart; give a lag shorter than the "
                         "window, or a longer window")
    return discrete


def discretize_frame(source, state_space: StateSpace, lag: float, time: float
                     ) -> DiscreteTrajectories:
    """The one frame at ``time`` (s), discretised with the history its state space needs.

    Positions and laps are kept: these are the initial states of a prediction.

    Parameters
    ----------
    source : str, os.PathLike or Trajectories
        A trajectory file, by path or open.
    state_space : StateSpace
        How positions (and motion) become states.
    lag : float
        The lag (s); a whole multiple of the file's frame interval.
    time : float
        Time of the frame (s).

    Returns
    -------
    DiscreteTrajectories
        One frame (T = 1) with ``positions`` and ``laps``.

    Raises
    ------
    InputError
        If the file cannot be read, the state space does not fit it, the lag is not a
        whole number of frames, no frame lies at ``time`` or the history before it is
        missing.
    """
    with opened(source) as traj:
        if state_space.memory_lags == 0 and traj.n_frames == 1:
            # a one-frame file has no frame interval, and a state without memory needs none
            _prepare(traj, state_space, float("nan"))
            lag_frames, interval = 1, float(lag)
        else:
            lag_frames, interval = _prepare(traj, state_space, lag), None
        i = traj.frame_index(time)
        frames = _read_rows(traj, i, i + 1, state_space.memory_lags * lag_frames, None,
                            state_space.needs_velocity, True, "error")
    if interval is not None:
        frames = replace(frames, frame_interval=interval)
    return frames.discretize(state_space, lag_frames, keep_positions=True)


def as_discrete_list(data) -> list[DiscreteTrajectories]:
    """``data`` (one :class:`DiscreteTrajectories` or a sequence of them) as a list.

    Parameters
    ----------
    data : DiscreteTrajectories or list or tuple of them
        The discrete trajectories.

    Returns
    -------
    list of DiscreteTrajectories

    Raises
    ------
    InputError
        If the sequence is empty, or anything else is given (a path or an open file:
        discretise it first).
    """
    items = list(data) if isinstance(data, (list, tuple)) else [data]
    if not items:
        raise InputError("no discrete trajectories given")
    for item in items:
        if not isinstance(item, DiscreteTrajectories):
            raise InputError(
                f"expected discrete trajectories, got {type(item).__name__}: make them with "
                "cfbmarkov.markov.discretize(trajectories, state_space, lag, window) or fit "
                "from a file with cfbmarkov.markov.fit_model(...)")
    return items


def check_distinct_windows(windows: list[DiscreteTrajectories]) -> None:
    """Refuse to pool discrete trajectories with themselves: the same object twice, two
    windows of one file whose times overlap, or two with equal times and states (a copy).
    Pooled twice, a window counts its transitions twice and its interval narrows as if it
    were independent flow (``cfbmarkov fit a.h5 a.h5`` is refused alike,
    :func:`cfbmarkov.markov.pooling.check_runs_distinct`).

    Parameters
    ----------
    windows : list of DiscreteTrajectories

    Raises
    ------
    InputError
        Where two of them hold the same data, or overlap in one file.
    """
    import os

    for k, window in enumerate(windows):
        for j, other in enumerate(windows[:k]):
            same_file = (bool(window.source) and bool(other.source)
                         and os.path.realpath(window.source) == os.path.realpath(other.source)
                         and window.times[0] < other.times[-1]
                         and other.times[0] < window.times[-1])
            if other is window or same_file or (
                    other.states.shape == window.states.shape
                    and np.array_equal(other.times, window.times)
                    and np.array_equal(other.states, window.states)):
                names = [w.source or "discrete trajectories" for w in (other, window)]
                name = names[0] if names[0] == names[1] else " and ".join(names)
                what = "hold the same data" if other is window or not same_file or (
                    np.array_equal(other.times, window.times)) else "overlap"
                raise InputError(
                    f"windows {j} and {k} ({name}, {other.times[0]:g}-{other.times[-1]:g} s "
                    f"and {window.times[0]:g}-{window.times[-1]:g} s) {what}: "
                    "pooling a window with itself counts its transitions twice and narrows "
                    "the interval falsely (pool windows of independent runs, or windows of "
                    "one run that do not overlap)")


__all__ = ["ABSENT", "DiscreteTrajectories", "WindowFrames", "as_discrete_list",
           "check_arguments", "check_distinct_windows",
           "check_domain", "discretize", "discretize_frame", "read_frames"]
