"""GPU backend of the CFD-DEM (numba-cuda): ensembles of independent risers side by side.

:class:`~.ensemble.GpuEnsembleDEM` holds M members of N particles each on the device and
advances them with the kernels of :mod:`.kernels`; :class:`~.riser.GpuEnsembleRiser` couples
each member to its own gas (:class:`~cfbmarkov.simulate.cfd.GasSolver` on the host). The
backend is optional: ``numba.cuda`` is imported only when a GPU object is made
(:mod:`._cuda`), so the package imports where CUDA is absent; :func:`gpu_available` says
whether a CUDA device (or the CUDA simulator, ``NUMBA_ENABLE_CUDASIM=1``) is usable.
"""

from __future__ import annotations

import os

from cfbmarkov.errors import CfbmarkovError


class GpuUnavailable(CfbmarkovError):
    """No usable CUDA device (and the CUDA simulator is not switched on)."""


def simulator() -> bool:
    """Whether ``numba.cuda`` runs (or will run) the CUDA simulator: ``NUMBA_ENABLE_CUDASIM``
    set to a non-zero value in the environment, read when ``numba.cuda`` is first imported."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0").strip() not in ("", "0")


def gpu_available() -> tuple[bool, str]:
    """Whether the GPU backend can run here.

    Returns
    -------
    ok : bool
        A CUDA device (or the CUDA simulator) is usable.
    reason : str
        Why not (empty when ``ok``).
    """
    try:
        from cfbmarkov.simulate.gpu._cuda import cuda
    except Exception as exc:  # numba-cuda missing or broken
        return False, f"numba.cuda cannot be imported ({type(exc).__name__}: {exc})"
    try:
        if not cuda.is_available():
            return False, "no CUDA device or driver found"
    except Exception as exc:
        return False, f"CUDA is not usable ({type(exc).__name__}: {exc})"
    return True, ""


def require_gpu() -> None:
    """Raise :class:`GpuUnavailable` (one line naming the problem and the fix) where
    :func:`gpu_available` says no."""
    ok, reason = gpu_available()
    if not ok:
        raise GpuUnavailable(f"--device gpu: {reason}; run with --device cpu, or on a machine "
                             f"with an NVIDIA GPU and numba-cuda")


__all__ = ["GpuUnavailable", "gpu_available", "require_gpu", "simulator"]
