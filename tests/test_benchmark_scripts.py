"""Every script in ``benchmarks/`` starts as the docs show it (``python benchmarks/X.py``):
its folder comes first on ``sys.path`` then, so a script named like a package that the
project's imports load (``coverage``, which Numba imports) would stand in for it and break
every other script in the folder."""

import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(BENCHMARKS.glob("*.py"))


def test_the_folder_holds_scripts():
    assert len(SCRIPTS) >= 3


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_script_help_runs_from_its_folder(script):
    done = subprocess.run([sys.executable, str(script), "--help"], capture_output=True,
                          text=True, timeout=120, cwd=BENCHMARKS.parent)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "usage" in done.stdout.lower()
    assert "Traceback" not in done.stderr
