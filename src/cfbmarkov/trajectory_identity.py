"""The identity of a trajectory file's window by its content: what a model records of the
data it was fitted on, so that a later re-read (a comparison's intervals, ``react --run``,
a pooled fit's runs) can tell the same data from another file of the same name, a file
replaced in place, or one edited in some of its frames.

The identity (version 2) is a SHA-256 digest of the window's frame times, the particle ids,
the riser's size and boundary, and a 64-bit fold of every frame's positions, lap counters
and presence: each value's bits times an odd multiplier of its place, summed modulo 2^64,
so that a change of any one value, in any frame, changes the fold (an odd multiplier is
invertible modulo 2^64). The fold is numpy arithmetic over the frames as they are read, in
blocks of a fixed number of values, so the identity costs one read of the window and
does not depend on how it is read. Version 1 (``window-sha256-1:``)
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
#: particle-frame values read per block while folding (the identity does not depend on it)
_BLOCK_VALUES = 2 ** 21


def _multipliers(n: int) -> np.ndarray:
    """Odd 64-bit multipliers, one per place of a frame's values (a Weyl sequence)."""
    with np.errstate(over="ignore"):
        return (np.arange(1, n + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)) \
            | np.uint64(1)


def _fold(values: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
    """Per frame (axis 0): sum of each value's 64 bits times its place's multiplier,
    modulo 2^64."""
    bits = np.ascontiguousarray(values).reshape(values.shape[0], -1)
    bits = bits.astype("<i8" if bits.dtype.kind in "iub" else "<f8", copy=False).view("<u8")
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
    values = n * max(int(traj.dimensions), 1)
    multipliers = _multipliers(values)
    block = max(1, _BLOCK_VALUES // max(values, 1))
    streams = ([], [], [])                  # per frame: positions, laps, presence
    for start in range(i0, i1, block):
        rows = slice(start, min(start + block, i1))
        positions = np.nan_to_num(np.asarray(traj.positions(rows), dtype="<f8"), nan=-1.0)
        streams[0].append(_fold(positions, multipliers))
        streams[1].append(_fold(np.asarray(traj.laps(rows), dtype="<i8"), multipliers))
        streams[2].append(_fold(np.asarray(traj.present(rows), dtype="<i8"), multipliers))
    for stream in streams:                  # each whole, so the blocks read do not show
        digest.update(np.concatenate(stream).astype("<u8").tobytes())
    return IDENTITY_PREFIX + digest.hexdigest()[:32]


def identity_version(identity: str) -> int:
    """The rule an identity was recorded with: 1 (``window-sha256-1:``) or 2 (this
    version's, and the one used for a new identity where ``identity`` is empty).

    Raises
    ------
    InputError
        For an identity of another rule (a newer cfbmarkov's): upgrade to compare it.
    """
    from cfbmarkov.errors import InputError

    identity = str(identity or "")
    if not identity or identity.startswith(IDENTITY_PREFIX):
        return 2
    if identity.startswith(IDENTITY_PREFIX_V1):
        return 1
    raise InputError(f"a fitting-window identity of an unknown rule ({identity.split(':')[0]}"
                     "): recorded by a newer cfbmarkov; upgrade cfbmarkov to compare it")


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
        As :func:`window_identity`, and for an identity of an unknown rule
        (:func:`identity_version`).
    """
    return window_identity(traj, window, identity_version(recorded)) == recorded


__all__ = ["IDENTITY_PREFIX", "IDENTITY_PREFIX_V1", "identity_version", "same_window",
           "window_identity"]
