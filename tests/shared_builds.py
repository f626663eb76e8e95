"""Outputs that a test run builds once and its pytest-xdist workers share.

A module-scoped fixture is built again each time a worker comes back to its module after
tests of another (pytest tears module fixtures down when the module changes), and once in
each worker that runs a test of the module. The expensive outputs (a miniature reproduction,
the report's template folder, the documentation's first commands) are built here once per
test run instead: the first worker that asks builds the folder under a file lock in the
run's base folder, which the workers share; another waits for it, then reads it. Tests that
write into such a folder work on their own copy (:func:`worker_copy`).
"""

from __future__ import annotations

import fcntl
import os
import shutil
from pathlib import Path
from typing import Callable


def shared_base(tmp_path_factory) -> Path:
    """The folder shared by this run's workers (this process's base folder without xdist)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def built_once(tmp_path_factory, name: str, build: Callable[[Path], None]) -> Path:
    """The folder ``name`` in :func:`shared_base`, filled by ``build(folder)`` once per test
    run (a build that raised is tried again by the next worker that asks)."""
    base = shared_base(tmp_path_factory)
    folder, done = base / name, base / f"{name}.done"
    with open(base / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir(parents=True)
            build(folder)
            done.touch()
    return folder


def worker_copy(tmp_path_factory, folder: Path, name: str) -> Path:
    """A copy of ``folder`` of this worker's own, at ``<new temporary folder>/name``."""
    copy = tmp_path_factory.mktemp(name) / name
    shutil.copytree(folder, copy)
    return copy
