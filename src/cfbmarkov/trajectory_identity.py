"""The identity of a trajectory file's window by its content: what a model records of the
data it was fitted on, so that a later re-read (a comparison's intervals, ``react --run``,
a pooled fit's runs) can tell the same data from another file of the same name, a file
replaced in place, or one edited in some of its frames.

The identity (version 2) is a SHA-256 digest of the window's frame times, the particle ids,
the riser's size and boundary, and a 64-bit fold of every frame's positions, lap counters
and presence: each value's bits times an odd multiplier of its place, summed modulo 2^64,
so that a change of any one value, in any frame, changes the fold (an odd multiplier is
invertible modulo 2^64). The fold is numpy arithmetic over the frames as they are read, in
blocks, so the identity costs one read of the window. Version 1 (``window-sha256-1:``)
digested three frames only (first, middle, last); an identity recorded so is still
compared by its own rule (:func:`same_window`).
"""

from __future__ import annotations

import hashlib

import numpy as np

#: the digest's version and kind, its prefix
IDENTITY_PREFIX = "window-sha256-2:"
#: the prefix of identities recorded by the earlier rule (three frames)
IDENTITY_PREFIX_V1 = "window-sha256-1:"
#: frames read per block while folding
_BLOCK = 64


def _multipliers(n: int) -> np.ndarray:
    """Odd 64-bit multipliers, one per place of a frame's values (a Weyl sequence)."""
    with np.errstate(over="ignore"):
        return (np.arange(1, n + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)) \
            | np.uint64(1)


def _fold(values: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
    """Per frame (axis 0): sum of each value's 64 bits times its place's multiplier,
    modulo 2^64."""
    bits = np.ascontiguousarray(values).reshape(values.shape[0], -1)
    if bits.dtype.itemsize != 8:
        bits = bits.astype(np.int64)
    bits = bits.view(np.uint64)
    with np.errstate(over="ignore"):
        return (bits * multipliers[:bits.shape[1]]).sum(axis=1, dtype=np.uint64)


def _identity_v1(traj, i0: int, i1: int) -> str:
    digest = hashlib.sha256(IDENTITY_PREFIX_V1.encode())
    _header(digest, traj, i0, i1)
    for k in sorted({i0, (i0 + i1 - 1) // 2, i1 - 1}):
        positions = np.nan_to_num(np.asarray(traj.positions(k), dtype="<f8"), nan=-1.0)
        digest.update(np.ascontiguousarray(positions).tobytes())
        digest.update(np.ascontiguousarray(traj.present(k), dtype=np.uint8).tobytes())
    return IDENTITY_PREFIX_V1 + digest.hexdigest()[:32]


def _header(digest, traj, i0: int, i1: int) -> None:
    digest.update(np.ascontiguousarray(traj.times[i0:i1], dtype="<f8").tobytes())
    digest.update(np.ascontiguousarray(traj.ids, dtype="<i8").tobytes())
    digest.update(repr((float(traj.width), float(traj.height),
                        str(getattr(traj.boundary, 'value', traj.boundary)))).encode())


def window_identity(traj, window: tuple[float, float] | None, version: int = 2) -> str:
    """The content identity of ``window`` of an open trajectory file.

    Parameters
    ----------
    traj : Trajectories
        The open file.
    window : (float, float) or None
        The window (s); None: every frame.
    version : {2, 1}, optional
        The rule: 2 (every frame folded, the default) or 1 (three frames, the earlier
        rule, for an identity recorded by it).

    Returns
    -------
    str
        The version's prefix and 32 hexadecimal digits.

    Raises
    ------
    InputError
        If the window holds no frame of the file, or a frame read fails its checks.
    """
    frames = slice(0, traj.n_frames) if window is None else traj.window(*window)
    i0, i1 = frames.start, frames.stop
    if version == 1:
        return _identity_v1(traj, i0, i1)
    digest = hashlib.sha256(IDENTITY_PREFIX.encode())
    _header(digest, traj, i0, i1)
    n = traj.n_particles
    multipliers = _multipliers(n * max(int(traj.dimensions), 1))
    folds = []
    for start in range(i0, i1, _BLOCK):
        rows = slice(start, min(start + _BLOCK, i1))
        positions = np.nan_to_num(np.asarray(traj.positions(rows), dtype="<f8"), nan=-1.0)
        folds.append(_fold(positions, multipliers))
        folds.append(_fold(np.asarray(traj.laps(rows), dtype=np.int64), multipliers))
        folds.append(_fold(np.asarray(traj.present(rows), dtype=np.int64), multipliers))
    for fold in folds:
        digest.update(np.ascontiguousarray(fold, dtype="<u8").tobytes())
    return IDENTITY_PREFIX + digest.hexdigest()[:32]


def same_window(traj, window: tuple[float, float] | None, recorded: str) -> bool:
    """Whether ``window`` of an open file holds the data an identity was recorded of, by
    the rule the identity was recorded with (its prefix).

    Parameters
    ----------
    traj : Trajectories
    window : (float, float) or None
    recorded : str
        An identity from :func:`window_identity`.

    Returns
    -------
    bool

    Raises
    ------
    InputError
        As :func:`window_identity`.
    """
    version = 1 if str(recorded).startswith(IDENTITY_PREFIX_V1) else 2
    return window_identity(traj, window, version) == recorded


__all__ = ["IDENTITY_PREFIX", "IDENTITY_PREFIX_V1", "same_window", "window_identity"]
