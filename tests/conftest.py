"""Suite-wide settings.

The suite runs in two pytest-xdist workers (``-n auto --maxprocesses 2`` in pyproject.toml):
Numba compiles kernels on one core, so two workers keep both cores busy while the other
compiles. Each worker runs its Numba kernels on one thread, and the command lines that the
tests of outputs and faults start get ``NUMBA_NUM_THREADS=1`` (their ``_env``), so that two
workers do not oversubscribe the cores (OpenMP barriers wait for descheduled threads). The
worker's own Numba still knows every core (``numba.config.NUMBA_NUM_THREADS``; it cannot
change once its threads run), so tests of the thread count can set two.

The workers take the tests one by one, except the modules of :data:`GROUPS`, whose module-
or session-scoped fixture is costly (a reproduction, the simulated GPU checks): each group
runs whole on one worker, so that its fixture is made once per run instead of once per
worker (``--dist loadgroup`` in pyproject.toml and :func:`pytest_xdist_make_scheduler`
here; the groups, most tests first, go out before the single tests, which fill in around
them). The groups are named here by module, not with ``pytest.mark.xdist_group`` in the
modules: pytest 9.2 builds a test's id from ``Node._id``, which pytest-xdist 3.8 does not
change, so the marks reach no scheduler.
"""

import os

#: test module -> group: the modules that run whole on one worker (their costly fixture)
GROUPS = {
    "tests/test_reproduce.py": "reproduce",                # reference (a reproduction)
    "tests/test_reproduce_ensemble.py": "reproduce-ensemble",   # ensemble (a reproduction)
    "tests/test_gpu.py": "gpu-checks",                     # checks (the simulated GPU)
    "tests/markov/test_open_riser.py": "open-riser",       # open_run
    # reproduction_template and report_of_template of tests/report/conftest.py
    "tests/report/test_reproduction.py": "report-template",
    "tests/report/test_kinetics_section.py": "report-template",
    "tests/report/test_run_folder.py": "report-template",
}


def pytest_xdist_make_scheduler(config, log):
    """With ``--dist loadgroup``: tests grouped by :data:`GROUPS` (and by any
    ``xdist_group`` mark that reaches the scheduler), every other test on its own."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    class ModuleGroups(LoadGroupScheduling):
        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            if scope != nodeid:
                return scope
            return GROUPS.get(nodeid.split("::", 1)[0], nodeid)

    return ModuleGroups(config, log)


def pytest_configure(config):
    if os.environ.get("PYTEST_XDIST_WORKER"):
        import cfbmarkov  # noqa: F401  (selects the OpenMP threading layer first)
        import numba

        numba.set_num_threads(1)
