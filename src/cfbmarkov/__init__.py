"""cfbmarkov: Markov chain models of particle motion in circulating fluidized bed risers.

The pipeline, data flowing one way::

    config -> simulate (CFD-DEM) -> trajectories (HDF5) <- io (CSV, LAMMPS dumps)
    trajectories -> markov (states, estimate, model, Monte Carlo) -> trajectories
    trajectories x2 -> analysis (RTD, mixing, metrics) -> report (figures)
"""

import os as _os

# Numba's default threading layer (tbb) gives almost no speed-up for the short parallel
# loops of this package; OpenMP gives about 1.9x on 2 cores (see docs/performance.md).
# It must be chosen before numba compiles anything; a user's explicit choice wins.
_os.environ.setdefault("NUMBA_THREADING_LAYER", "omp")

from cfbmarkov._version import __version__  # noqa: E402
from cfbmarkov.errors import CfbmarkovError, InputError  # noqa: E402

#: the names loaded on first use (h5py and Numba take seconds to import: ``cfbmarkov
#: --help`` and the verbs that do not read files need neither)
_LAZY = {"Trajectories": "cfbmarkov.trajectories",
         "TrajectoryWriter": "cfbmarkov.trajectory_writer",
         "write_trajectories": "cfbmarkov.trajectory_writer"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'cfbmarkov' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_LAZY])


__all__ = [
    "CfbmarkovError",
    "InputError",
    "Trajectories",
    "TrajectoryWriter",
    "write_trajectories",
    "__version__",
]
