"""The one module that imports ``numba.cuda`` (imported lazily, only by the GPU backend).

numba-cuda 0.30 uses ``numpy.row_stack``, which numpy 2.5 removed: it is aliased to
``numpy.vstack`` here, before the import. ``NUMBA_ENABLE_CUDASIM=1`` in the environment
(read by numba when ``numba.cuda`` is first imported) runs the kernels under the CUDA
simulator, in Python, without a GPU.

Under the simulator each thread of a block is a Python thread, and the simulator's block
manager polls them in a loop that holds the GIL until the interpreter's switch interval
(5 ms by default) hands it over: every ``cuda.syncthreads()`` then waits about that long.
With the simulator on, the switch interval is set to :data:`SIMULATOR_SWITCH_INTERVAL`
(``sys.setswitchinterval``), which leaves the results as they are and makes the DEM checks
of :mod:`.checks` 4 to 12 times faster there (measured 2026-12-04 with
``python -m cfbmarkov.simulate.gpu.checks --threads 4`` under the simulator).
"""

from __future__ import annotations

import sys

import numpy as np

from cfbmarkov.simulate.gpu import simulator

#: the interpreter's thread switch interval under the CUDA simulator, s
SIMULATOR_SWITCH_INTERVAL = 1e-4

if not hasattr(np, "row_stack"):
    np.row_stack = np.vstack

if simulator():
    sys.setswitchinterval(min(sys.getswitchinterval(), SIMULATOR_SWITCH_INTERVAL))

from numba import cuda  # noqa: E402

__all__ = ["cuda"]
