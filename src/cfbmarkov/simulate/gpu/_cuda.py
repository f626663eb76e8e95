"""The one module that imports ``numba.cuda`` (imported lazily, only by the GPU backend).

numba-cuda 0.30 uses ``numpy.row_stack``, which numpy 2.5 removed: it is aliased to
``numpy.vstack`` here, before the import. ``NUMBA_ENABLE_CUDASIM=1`` in the environment
(read by numba when ``numba.cuda`` is first imported) runs the kernels under the CUDA
simulator, in Python, without a GPU.
"""

from __future__ import annotations

import numpy as np

if not hasattr(np, "row_stack"):
    np.row_stack = np.vstack

from numba import cuda  # noqa: E402

__all__ = ["cuda"]
