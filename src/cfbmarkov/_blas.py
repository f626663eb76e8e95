"""One BLAS thread for small dense linear algebra.

A small dense LU or eigenproblem is microseconds of arithmetic; BLAS threads only contend
over it (100 times slower on a busy 2-core machine), and a thread count that changes the
order of a sum changes its last bits. threadpoolctl finds the BLAS libraries once per
controller, which costs milliseconds: the controller is made once, on first use.
"""

from __future__ import annotations

from threadpoolctl import ThreadpoolController

_controller: ThreadpoolController | None = None


def one_blas_thread():
    """A context manager that limits the BLAS libraries to one thread while it is open
    (``threadpoolctl.ThreadpoolController.limit``)."""
    global _controller
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")
