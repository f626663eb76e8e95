"""The identity of a trajectory file's window by its content: what a model records of the
data it was fitted on, so that a later re-read (a comparison's intervals) can tell the
same data from another file of the same name or a file replaced in place.

The identity is a SHA-256 digest of the window's frame times, the particle ids, the riser's
size and boundary, and the positions and presence of three of the window's frames (first,
middle, last): a small part of the data, read in a few frames whatever the window's
length, that any other run or import differs in.
"""

from __future__ import annotations

import hashlib

import numpy as np

#: the digest's version and kind, its prefix
IDENTITY_PREFIX = "window-sha256-1:"


def window_identity(traj, window: tuple[float, float] | None) -> str:
    """The content identity of ``window`` of an open trajectory file.

    Parameters
    ----------
    traj : Trajectories
        The open file.
    window : (float, float) or None
        The window (s); None: every frame.

    Returns
    -------
    str
        ``IDENTITY_PREFIX`` and 32 hexadecimal digits.

    Raises
    ------
    InputError
        If the window holds no frame of the file, or a frame read fails its checks.
    """
    frames = slice(0, traj.n_frames) if window is None else traj.window(*window)
    i0, i1 = frames.start, frames.stop
    digest = hashlib.sha256(IDENTITY_PREFIX.encode())
    digest.update(np.ascontiguousarray(traj.times[i0:i1], dtype="<f8").tobytes())
    digest.update(np.ascontiguousarray(traj.ids, dtype="<i8").tobytes())
    digest.update(repr((float(traj.width), float(traj.height), str(getattr(traj.boundary, 'value', traj.boundary)))).encode())
    for k in sorted({i0, (i0 + i1 - 1) // 2, i1 - 1}):
        positions = np.nan_to_num(np.asarray(traj.positions(k), dtype="<f8"), nan=-1.0)
        digest.update(np.ascontiguousarray(positions).tobytes())
        digest.update(np.ascontiguousarray(traj.present(k), dtype=np.uint8).tobytes())
    return IDENTITY_PREFIX + digest.hexdigest()[:32]


__all__ = ["IDENTITY_PREFIX", "window_identity"]
