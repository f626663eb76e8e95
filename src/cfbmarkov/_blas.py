"""One BLAS thread for small dense linear algebra.

A small dense LU or eigenproblem is microseconds of arithmetic: BLAS threads only contend
over it (on a busy 2-core machine, many times slower), and a thread count that changes the
order of a sum changes its last bits. The limit is the process's (BLAS keeps one thread
count), so it is taken and given back under a lock with a count of the Python threads
inside: the first in sets it, the last out restores it, and a thread leaving never lifts
it under another still inside (limits that each thread set and restored on its own left
one resample's RTD in 150 with other last bits than the serial run's, where the
bootstrap's resamples run in two threads: a paper-scale 6 m/s model's chain perturbed 150
times, OpenBLAS 0.3.30, 2026-12-06). A pool of threads that does such linear algebra also
holds the limit around the whole pool (:func:`cfbmarkov.analysis.bootstrap._in_threads`).
threadpoolctl finds the BLAS libraries once per controller, which costs
milliseconds; the controller is made when this module is imported, after NumPy's and
SciPy's linear algebra (and so their BLAS libraries) are loaded.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy.linalg  # noqa: F401  (loads NumPy's BLAS before the controller looks)
import scipy.linalg  # noqa: F401  (and SciPy's)
from threadpoolctl import ThreadpoolController

_controller = ThreadpoolController()
_lock = threading.Lock()
_inside = 0
_limiter = None


@contextmanager
def one_blas_thread():
    """Limit the BLAS libraries to one thread while any thread is inside this context
    (``threadpoolctl.ThreadpoolController.limit``; nested and concurrent uses share one
    limit, lifted when the last of them leaves)."""
    global _inside, _limiter
    with _lock:
        if _inside == 0:
            _limiter = _controller.limit(limits=1, user_api="blas")
        _inside += 1
    try:
        yield
    finally:
        with _lock:
            _inside -= 1
            if _inside == 0:
                _limiter.restore_original_limits()
                _limiter = None
