"""Suite-wide settings.

The suite runs in two pytest-xdist workers (``-n auto --maxprocesses 2`` in pyproject.toml):
Numba compiles kernels on one core, so two workers keep both cores busy while the other
compiles. Each worker runs its Numba kernels and its BLAS (OpenBLAS, through threadpoolctl;
``OPENBLAS_NUM_THREADS=1`` for the processes it starts) on one thread, and the command lines
that the tests of outputs and faults start get ``NUMBA_NUM_THREADS=1`` (their ``_env``), so
that two workers do not oversubscribe the cores (OpenMP barriers and OpenBLAS's threads spin
waiting for descheduled threads; measured 2026-12-05: 452 s of CPU for the suite with two
BLAS threads a worker, 377 s with one). The
worker's own Numba still knows every core (``numba.config.NUMBA_NUM_THREADS``; it cannot
change once its threads run), so tests of the thread count can set two.
"""

import os

import pytest


@pytest.fixture(autouse=True)
def _no_heartbeat_lines(monkeypatch):
    """No "still working" lines from commands run in-process: on a busy machine a step may
    pass 5 s, and a line of progress would break the tests that count a refusal's lines
    (the heartbeat's own tests set its period)."""
    from cfbmarkov import _console

    monkeypatch.setattr(_console, "HEARTBEAT_EVERY", 1e6)


def pytest_configure(config):
    if os.environ.get("PYTEST_XDIST_WORKER"):
        import cfbmarkov  # noqa: F401  (selects the OpenMP threading layer first)
        import numba

        numba.set_num_threads(1)
        from threadpoolctl import threadpool_limits

        threadpool_limits(1, user_api="blas")
        os.environ["OPENBLAS_NUM_THREADS"] = "1"    # and in the processes the tests start


#: the two longest tests (about 35 s each on 2 cores), run first, one per worker, so that
#: neither is left running alone at the end while the other worker idles
FIRST = ("tests/simulate/test_coupled_physics.py::"
         "test_fluidized_bed_pressure_drop_carries_its_weight",
         "tests/test_docs.py::test_tutorial_commands_run")


def pytest_collection_modifyitems(config, items):
    first = [item for item in items if item.nodeid in FIRST]
    items[:] = first + [item for item in items if item.nodeid not in FIRST]

