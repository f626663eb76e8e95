"""Counting the transitions of discrete trajectories: what every estimator gathers from the
data before it forms P (``docs/definitions.md``, States and transitions).

:func:`count_transitions` counts every pair of frames (t, t + lag) with A <= t and
t + lag <= B for every particle (sliding window) and records the direction of each
transition through the periodic boundary by the minimal-image rule on y; for an open riser
it also counts what crossed the inlet and outlet faces (:class:`FaceCounts`). The result,
a :class:`TransitionCounts`, is what the estimators of :mod:`cfbmarkov.markov.estimate`
turn into a model. The counting kernels are Numba functions on the window's arrays.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numba as nb
import numpy as np
import scipy.sparse as sp

from cfbmarkov import _interrupt
from cfbmarkov.boundary import Boundary
from cfbmarkov.errors import InputError
from cfbmarkov.markov.discrete import as_discrete_list
from cfbmarkov.markov.states import StateSpace

@nb.njit(cache=True)
def _frame_occupancy(states, t, lag_frames, occupancy):
    """occupancy[i] = N_i(t), the particles in state i at frame t whose frame t + lag is
    present too (Numba; ``occupancy`` [S] is overwritten)."""
    occupancy[:] = 0
    for p in range(states.shape[1]):
        i = states[t, p]
        if i >= 0 and states[t + lag_frames, p] >= 0:
            occupancy[i] += 1


@nb.njit(cache=True)
def _count_kernel(states, vertical, lag_frames, height, n_states, counts, counts_up,
                  counts_down, frame_average, occupied_frames, with_frame_average):
    """Accumulate the transition counts of discrete trajectories (Numba kernel).

    ``states`` int32 [T, N] (-1: absent), ``vertical`` float64 [T, N] heights (m). For
    every frame pair (t, t + lag) whose two ends are present, adds to ``counts[i, j]``
    (pooled), ``counts_up`` / ``counts_down`` (passes up through the top / down through the
    bottom: the height dropped / rose by more than H/2, the minimal-image rule),
    ``frame_average[i, j] += N_ij(t) / N_i(t)`` (the sum of the per-frame matrices P'(t)
    of the paper's Eq. 2; skipped unless ``with_frame_average``) and
    ``occupied_frames[i] += 1`` where N_i(t) > 0. Returns the number of frame pairs.
    """
    n_frames, n_particles = states.shape
    half = 0.5 * height
    occupancy = np.zeros(n_states, dtype=np.int64)
    pairs = 0
    for t in range(n_frames - lag_frames):
        _frame_occupancy(states, t, lag_frames, occupancy)
        for i in range(n_states):
            if occupancy[i] > 0:
                occupied_frames[i] += 1
        for p in range(n_particles):
            i = states[t, p]
            j = states[t + lag_frames, p]
            if i < 0 or j < 0:
                continue
            counts[i, j] += 1
            if with_frame_average:
                frame_average[i, j] += 1.0 / occupancy[i]
            dy = vertical[t + lag_frames, p] - vertical[t, p]
            if dy < -half:
                counts_up[i, j] += 1
            elif dy > half:
                counts_down[i, j] += 1
        pairs += 1
    return pairs


@nb.njit(cache=True, parallel=True)
def _sparse_count_kernel(states, vertical, lag_frames, height, n_states, with_frame_average,
                         occupied_frames, chunks):
    """The counts of :func:`_count_kernel` in compressed sparse rows (Numba kernel, parallel).

    Each transition is first placed in the row of its start state (a counting sort by i,
    frames in time order), then each row is gathered with a scratch marker over the
    destinations, so the work and memory are O(transitions + S + non-zeros), never S x S;
    the per-frame sums of the paper's Eq. 2 run in the same (time) order as the dense
    kernel's. The threads share the frames in consecutive chunks (a row's slots for chunk c
    follow those of chunks before it, so every row keeps the time order) and then the rows;
    the result is the same for any thread count and any ``chunks`` (the number of frame and
    row chunks, the caller's thread count: asking Numba for it here would make the kernel
    uncacheable). Returns ``indptr`` [S + 1], ``indices``
    int32, the values of ``counts``, ``counts_up``, ``counts_down`` (int64) and of the
    frame-average sum (float64; empty unless ``with_frame_average``) on that one pattern
    (explicit zeros kept in up and down, destinations of a row unsorted), and the number of
    frame pairs; ``occupied_frames`` [S] is updated."""
    n_frames, n_particles = states.shape
    half = 0.5 * height
    pairs = max(n_frames - lag_frames, 0)
    chunks = max(1, min(chunks, pairs))
    first_frame = np.empty(chunks + 1, np.int64)
    for c in range(chunks + 1):
        first_frame[c] = pairs * c // chunks
    histogram = np.zeros((chunks, n_states), np.int64)     # transitions from i per chunk
    for c in nb.prange(chunks):
        for t in range(first_frame[c], first_frame[c + 1]):
            for p in range(n_particles):
                i = states[t, p]
                if i >= 0 and states[t + lag_frames, p] >= 0:
                    histogram[c, i] += 1
    start = np.zeros(n_states + 1, np.int64)
    slot = np.empty((chunks, n_states), np.int64)   # next free slot of row i for chunk c
    total = 0
    for i in range(n_states):
        start[i] = total
        for c in range(chunks):
            slot[c, i] = total
            total += histogram[c, i]
    start[n_states] = total
    destination = np.empty(total, np.int32)
    kind = np.empty(total, np.int8)             # 0: stays, 1: up through the top, 2: down
    weight = np.empty(total if with_frame_average else 0, np.float64)
    occupied = np.zeros((chunks, n_states), np.int64)
    for c in nb.prange(chunks):
        occupancy = np.zeros(n_states, np.int64)
        last_frame = -np.ones(n_states, np.int64)   # the last frame state i was occupied in
        for t in range(first_frame[c], first_frame[c + 1]):
            if with_frame_average:      # N_i(t) first: the weights 1 / N_i(t) of Eq. 2
                _frame_occupancy(states, t, lag_frames, occupancy)
            for p in range(n_particles):
                i = states[t, p]
                j = states[t + lag_frames, p]
                if i < 0 or j < 0:
                    continue
                if last_frame[i] != t:
                    last_frame[i] = t
                    occupied[c, i] += 1
                q = slot[c, i]
                slot[c, i] += 1
                destination[q] = j
                dy = vertical[t + lag_frames, p] - vertical[t, p]
                kind[q] = 1 if dy < -half else (2 if dy > half else 0)
                if with_frame_average:
                    weight[q] = 1.0 / occupancy[i]
    for c in range(chunks):
        for i in range(n_states):
            occupied_frames[i] += occupied[c, i]
    # gather each row in place at its own slots (a row has at most as many non-zeros as
    # transitions), the rows shared in consecutive chunks, then compact
    indices = np.empty(total, np.int32)
    counts = np.zeros(total, np.int64)
    up = np.zeros(total, np.int64)
    down = np.zeros(total, np.int64)
    average = np.zeros(total if with_frame_average else 0, np.float64)
    row_nonzeros = np.zeros(n_states, np.int64)
    for c in nb.prange(chunks):
        where = -np.ones(n_states, np.int64)        # position of destination j in its row
        for i in range(n_states * c // chunks, n_states * (c + 1) // chunks):
            row_start = start[i]
            nnz = row_start
            for q in range(start[i], start[i + 1]):
                j = destination[q]
                k = where[j]
                if k < row_start:
                    k = nnz
                    where[j] = k
                    indices[k] = j
                    nnz += 1
                counts[k] += 1
                if kind[q] == 1:
                    up[k] += 1
                elif kind[q] == 2:
                    down[k] += 1
                if with_frame_average:
                    average[k] += weight[q]
            row_nonzeros[i] = nnz - row_start
    indptr = np.zeros(n_states + 1, np.int64)
    for i in range(n_states):
        k = indptr[i]
        for q in range(start[i], start[i] + row_nonzeros[i]):   # k <= q: a forward move
            indices[k] = indices[q]
            counts[k] = counts[q]
            up[k] = up[q]
            down[k] = down[q]
            if with_frame_average:
                average[k] = average[q]
            k += 1
        indptr[i + 1] = k
    nnz = indptr[n_states]
    return (indptr, indices[:nnz], counts[:nnz], up[:nnz], down[:nnz],
            average[:nnz] if with_frame_average else average, pairs)


@nb.njit(cache=True, nogil=True)
def _residence_begun(vertical, p, t, lag_frames, band, height):
    """The frame where particle ``p``'s residence in progress at frame ``t`` began (``t``
    before the appearance judged, the particle absent there), read on the frames t,
    t - lag, ... as the residence times read them
    (:func:`cfbmarkov.observed.residence.residence_times`): the first entry through the
    inlet (first seen within ``band`` of 0) after the last exit through the outlet (last
    seen within ``band`` of H) before ``t``, or 0 for a particle present at the window's
    first frame (a residence begun before it) that has not left through the outlet since;
    appearances and disappearances elsewhere change nothing. -1 where none (Numba
    kernel)."""
    begun = -1
    u = t
    while u >= lag_frames:
        a = u - lag_frames
        was, now = not np.isnan(vertical[a, p]), not np.isnan(vertical[u, p])
        if was and not now:
            last = a
            for f in range(a + 1, u):
                if not np.isnan(vertical[f, p]):
                    last = f
            if vertical[last, p] >= height - band:
                return begun                               # left through the outlet
        elif now and not was:
            first = u
            for f in range(u - 1, a, -1):
                if not np.isnan(vertical[f, p]):
                    first = f
            if vertical[first, p] <= band:
                begun = first                              # entered through the inlet
        u = a
    # the sequence's first frame u < lag: present there, the particle was seen first at
    # the window's first frame (inside at its start) or came into view after it
    if np.isnan(vertical[u, p]):
        return begun
    first = u                       # first seen: the first frame present up to u
    for f in range(u - 1, -1, -1):
        if not np.isnan(vertical[f, p]):
            first = f
    if first == 0:
        return 0                                           # inside at the window's start
    return first if vertical[first, p] <= band else begun


@nb.njit(cache=True)
def _open_kernel(states, vertical, lag_frames, band, height, exits, entries, vanished,
                 appeared, returns, returned_frames, first_pair, stop_pair):
    """Count what crosses the faces of an open riser (Numba kernel).

    For every frame pair (t, t + lag) of a particle: present then absent is an exit
    (``exits[i] += 1``) when its height where it was last seen (the last frame present in
    [t, t + lag)) lies within ``band`` (one cell) of the outlet face at H, else a
    disappearance (``vanished[i]``); absent then present is an entry (``entries[j] += 1``)
    when its height where it was first seen (the first frame present in (t, t + lag], and
    back through a presence that began before it) lies within ``band`` of the inlet face
    at 0, else an appearance (``appeared[j]``); a gap shorter than the lag between them
    does not move these frames (:func:`cfbmarkov.observed.residence.lag_face_heights`
    reads the residences so). With a lag of several frames, the frames within it are where the
    particle crossed the face, not t or t + lag; a state space with memory defines a
    particle's state only from a lag after it is first seen (its history), so its entry is
    judged where it was first seen too (present frames hold a finite height, absent ones
    NaN). A particle that comes back through the inlet within a residence (it fell back
    out through the inlet, or left the view: :func:`_residence_begun` on the pair's
    sequence of lag frames t, t - lag, ...), in which that sequence's chain had it in a
    state, makes no entry but a return (``returns[j] += 1``; ``returned_frames[j]`` += the
    frames from its last frame in a state on the sequence, g, to t + lag, which no
    transition counts): its residence goes on, as a residence observed does. Where the
    sequence's chain never had it in a state in that residence (a stay before the fall
    shorter than a state with memory's history), it is the chain's entry (the time before
    it is the chain's to miss, as at any entry delay). Only the pairs whose first frame t
    lies in [``first_pair``, ``stop_pair``) are counted, each read with all the frames
    before it (a block of the window counts its returns as the whole window does).
    Returns nothing; arrays are updated.
    """
    n_frames, n_particles = states.shape
    for t in range(max(first_pair, 0), min(stop_pair, n_frames - lag_frames)):
        for p in range(n_particles):
            i = states[t, p]
            j = states[t + lag_frames, p]
            if i >= 0 and j < 0:
                last = t          # where it was last seen: the last frame present before
                for f in range(t + 1, t + lag_frames):              # t + lag (a gap
                    if not np.isnan(vertical[f, p]):                # shorter than the lag
                        last = f                                    # does not end it)
                if vertical[last, p] >= height - band:
                    exits[i] += 1
                else:
                    vanished[i] += 1
            elif i < 0 and j >= 0:
                # where it was first seen: back over the sequence's lag frames it is present
                # at (a state with memory has none before its history), then the first frame
                # present within the lag before the earliest, as lag_face_heights reads it
                g = t + lag_frames
                while g >= lag_frames and not np.isnan(vertical[g - lag_frames, p]):
                    g -= lag_frames
                first = g
                for f in range(g - 1, max(g - lag_frames, -1), -1):
                    if not np.isnan(vertical[f, p]):
                        first = f
                if vertical[first, p] <= band:
                    # a return: in a residence on this pair's sequence of lag frames (t,
                    # t - lag, ...: entered through the inlet, or inside at its first
                    # frame, and not gone through the outlet since), in which the
                    # sequence's chain had it in a state (frame g, its last before)
                    u = t                         # the sequence's last frame before it
                    while u >= first:
                        u -= lag_frames
                    begun = (_residence_begun(vertical, p, u, lag_frames, band, height)
                             if u >= 0 else -1)
                    g = u
                    while g >= 0 and g >= begun and (g >= first or states[g, p] < 0):
                        g -= lag_frames
                    if begun >= 0 and g >= begun:
                        returns[j] += 1           # its residence goes on; no transition
                        returned_frames[j] += t + lag_frames - g      # counts g .. t + lag
                    else:
                        entries[j] += 1
                else:
                    appeared[j] += 1


@dataclass(frozen=True)
class FaceCounts:
    """What crossed the faces of an open riser (``docs/definitions.md``, Open risers).

    Attributes
    ----------
    exits : ndarray of int64, shape (S,)
        Transitions from each state to the outside through the outlet face (present, then
        absent one lag later, within one cell of the outlet).
    entries : ndarray of int64, shape (S,)
        Entries through the inlet face into each state (absent, then present within one
        cell of the inlet).
    vanished, appeared : ndarray of int64, shape (S,)
        Tracks that ended or began elsewhere (out of a camera's view, a gap): not counted
        as transitions, exits or entries (censored).
    returns : ndarray of int64, shape (S,)
        Returns through the inlet into each state, not among ``entries``: the particle
        comes back within a residence (it fell back out through the inlet, or left the
        view, after an entry or from the window's start, and did not leave through the
        outlet since): its residence goes on.
    returned_time : ndarray of float64, shape (S,)
        The residence time (s) around the returns that no transition counts: from a
        returning particle's last state before its fall to its first after it, summed.
    """

    exits: np.ndarray
    entries: np.ndarray
    vanished: np.ndarray
    appeared: np.ndarray
    returns: np.ndarray
    returned_time: np.ndarray

    def __add__(self, other: "FaceCounts") -> "FaceCounts":
        return FaceCounts(self.exits + other.exits, self.entries + other.entries,
                          self.vanished + other.vanished, self.appeared + other.appeared,
                          self.returns + other.returns, self.returned_time + other.returned_time)


@dataclass(frozen=True)
class TransitionCounts:
    """Everything an estimator gathers from the data before it forms P.

    Attributes
    ----------
    counts : ndarray of int64, shape (S, S)
        Pooled transition counts C_ij. With ``count_transitions(..., sparse=True)`` this and
        the other [S, S] fields are ``scipy.sparse.csr_array`` instead.
    counts_up, counts_down : ndarray of int64, shape (S, S)
        The transitions among them that passed up through the top / down through the
        bottom of the periodic riser.
    frame_average_sum : ndarray of float64, shape (S, S), or None
        Sum over the frame pairs of the per-frame row-normalised matrices P'(t) (paper
        Eq. 2-4); None where it was not gathered (only the paper's estimator needs it).
    occupied_frames : ndarray of int64, shape (S,)
        Frame pairs in which each state was occupied.
    frame_pairs : int
        Number of frame pairs (t, t + lag) counted.
    faces : FaceCounts or None
        Exits and entries of an open riser; None for a periodic one.
    """

    counts: np.ndarray
    counts_up: np.ndarray
    counts_down: np.ndarray
    frame_average_sum: np.ndarray | None
    occupied_frames: np.ndarray
    frame_pairs: int
    faces: FaceCounts | None = None

    @property
    def n_transitions(self) -> int:
        """Total number of transitions counted, sum of C_ij."""
        return int(self.counts.sum())

    def dense(self) -> "TransitionCounts":
        """These counts with dense [S, S] arrays: copies of sparse ones, dense counts as they
        are (``self``).

        Returns
        -------
        TransitionCounts
        """
        if not sp.issparse(self.counts):
            return self
        dense = lambda m: None if m is None else m.toarray()  # noqa: E731
        return TransitionCounts(dense(self.counts), dense(self.counts_up),
                                dense(self.counts_down), dense(self.frame_average_sum),
                                self.occupied_frames, self.frame_pairs, self.faces)

    def __add__(self, other: "TransitionCounts") -> "TransitionCounts":
        """The counts of two sets of data together (e.g. the training blocks of a fold)."""
        averages = (None if self.frame_average_sum is None or other.frame_average_sum is None
                    else self.frame_average_sum + other.frame_average_sum)
        faces = (None if self.faces is None or other.faces is None
                 else self.faces + other.faces)
        return TransitionCounts(self.counts + other.counts, self.counts_up + other.counts_up,
                                self.counts_down + other.counts_down, averages,
                                self.occupied_frames + other.occupied_frames,
                                self.frame_pairs + other.frame_pairs, faces)


def count_transitions(data, frame_average: bool = True, sparse: bool = False
                      ) -> TransitionCounts:
    """Count the transitions of discrete trajectories.

    Parameters
    ----------
    data : DiscreteTrajectories or sequence of them
        The windows to count (all in one state space, at one lag).
    frame_average : bool
        Also sum the per-frame matrices P'(t) that only the paper's estimator needs
        (``frame_average_sum`` is None otherwise).
    sparse : bool, optional
        Hold the [S, S] arrays as ``scipy.sparse.csr_array`` (memory and work grow with the
        transitions and non-zeros, never with S x S; what cross-validation over large state
        spaces uses, with :meth:`~cfbmarkov.markov.estimate.TransitionEstimator.split_chain`). Models are fitted from
        dense counts.

    Returns
    -------
    TransitionCounts

    Raises
    ------
    InputError
        If ``data`` is empty or not discrete trajectories, or the windows differ in state
        space or lag.

    Notes
    -----
    Every frame pair (t, t + lag) of every particle is counted (sliding window); a pair
    with an absent end is skipped. A pass through the periodic boundary is told by the
    minimal-image rule on y (``docs/definitions.md``, Pass direction).
    """
    windows = as_discrete_list(data)
    s = windows[0].state_space.n_states
    if sparse:
        with _interrupt.deferred():     # Ctrl-C held until the kernels return
            return _count_sparse(windows, frame_average)
    counts = np.zeros((s, s), np.int64)
    up = np.zeros((s, s), np.int64)
    down = np.zeros((s, s), np.int64)
    frame_sum = np.zeros((s, s) if frame_average else (1, 1), np.float64)
    occupied = np.zeros(s, np.int64)
    pairs = 0
    faces = _new_faces(windows)
    with _interrupt.deferred():         # Ctrl-C held until the kernels return
        for window, states, vertical in _window_arrays(windows, faces):
            pairs += _count_kernel(states, vertical, int(window.lag_frames),
                                   float(window.height), s, counts, up, down, frame_sum,
                                   occupied, bool(frame_average))
    return TransitionCounts(counts, up, down, frame_sum if frame_average else None, occupied,
                            pairs, faces)


def block_face_counts(window, cuts) -> list[FaceCounts]:
    """An open riser's face counts of each block of a window, the blocks' frame pairs
    starting at frames ``cuts[k]`` .. ``cuts[k + 1] - 1``, each pair read with the whole
    window's frames before it (:func:`_open_kernel`): a return through the inlet whose fall
    began in an earlier block is a return, as in the whole window, not an entry, and the
    blocks' counts sum to the window's.

    Parameters
    ----------
    window : DiscreteTrajectories
        An open riser's window.
    cuts : array_like of int, shape (B + 1,)
        The blocks' first pair frames, ascending, and the end.

    Returns
    -------
    list of FaceCounts
        One per block.
    """
    faces_of = []
    states = np.ascontiguousarray(window.states, dtype=np.int32)
    vertical = np.ascontiguousarray(window.vertical, dtype=np.float64)
    space = window.state_space
    for a, b in zip(cuts[:-1], cuts[1:]):
        faces = _new_faces([window])
        frames = np.zeros(space.n_states, np.int64)
        _open_kernel(states, vertical, int(window.lag_frames), face_band(space),
                     float(window.height), faces.exits, faces.entries, faces.vanished,
                     faces.appeared, faces.returns, frames, int(a), int(b))
        faces.returned_time[:] += frames * float(window.frame_interval)
        faces_of.append(faces)
    return faces_of


def _new_faces(windows) -> FaceCounts | None:
    """Empty face counts for windows of an open riser; None for a periodic one."""
    s = windows[0].state_space.n_states
    return (FaceCounts(*(np.zeros(s, np.int64) for _ in range(5)), np.zeros(s))
            if Boundary(windows[0].boundary).is_open else None)


def _window_arrays(windows, faces: FaceCounts | None):
    """Each window with its states (int32) and heights (float64) as contiguous arrays, after
    checking that it shares the first one's state space, lag and boundary; an open riser's
    face crossings are added to ``faces`` on the way."""
    space = windows[0].state_space
    open_riser = Boundary(windows[0].boundary).is_open
    for window in windows:
        if window.state_space != space or not window.matches_lag(windows[0].lag):
            raise InputError("discrete trajectories counted together must share the state "
                             "space and the lag")
        if Boundary(window.boundary).is_open != open_riser:
            raise InputError("discrete trajectories counted together must share the boundary "
                             "(periodic or open)")
        states = np.ascontiguousarray(window.states, dtype=np.int32)
        vertical = np.ascontiguousarray(window.vertical, dtype=np.float64)
        if open_riser:
            frames = np.zeros(space.n_states, np.int64)
            _open_kernel(states, vertical, int(window.lag_frames), face_band(space),
                         float(window.height), faces.exits, faces.entries, faces.vanished,
                         faces.appeared, faces.returns, frames, 0, states.shape[0])
            faces.returned_time[:] += frames * float(window.frame_interval)
        yield window, states, vertical


def _count_sparse(windows, frame_average: bool) -> TransitionCounts:
    """:func:`count_transitions` with scipy.sparse CSR arrays (one window at a time)."""
    s = windows[0].state_space.n_states
    faces = _new_faces(windows)
    total = None
    for window, states, vertical in _window_arrays(windows, faces):
        occupied = np.zeros(s, np.int64)
        indptr, indices, counts, up, down, average, pairs = _sparse_count_kernel(
            states, vertical, int(window.lag_frames), float(window.height), s,
            bool(frame_average), occupied, nb.get_num_threads())
        # sort each row's destinations once; the four value arrays follow the same order
        order = sp.csr_array((np.arange(indices.size, dtype=np.int64), indices, indptr),
                             shape=(s, s))
        order.sort_indices()
        permutation, sorted_indices, sorted_indptr = order.data, order.indices, order.indptr

        matrices = [sp.csr_array((values[permutation], sorted_indices.copy(),
                                  sorted_indptr.copy()), shape=(s, s))
                    for values in ((counts, up, down, average) if frame_average
                                   else (counts, up, down))]
        part = TransitionCounts(*matrices[:3], matrices[3] if frame_average else None,
                                occupied, int(pairs))
        total = part if total is None else total + part
    return dataclasses.replace(total, faces=faces)     # the faces of every window, once


def face_band(space: StateSpace) -> float:
    """How close to a face (m) a particle must vanish or appear to have crossed it: one
    cell height, H / rows (``docs/definitions.md``, Open risers).

    Parameters
    ----------
    space : StateSpace
        A cell-based state space (with ``height`` and ``rows``).

    Returns
    -------
    float
    """
    return float(space.height) / int(space.rows)
