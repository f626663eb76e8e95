"""The LAMMPS deck of the worked example ``docs/example-open-riser.md`` parses and runs.

Runs ``examples/open-riser/riser.in`` for 200 steps (``-var steps 200``, well under a
second) in a temporary directory; skipped where LAMMPS is not installed (CI).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from cfbmarkov.simulate.dem.lammps import find_lammps

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "open-riser"


def test_open_riser_deck_runs(tmp_path):
    lmp = find_lammps()
    if lmp is None:
        pytest.skip("LAMMPS is not installed")
    out = tmp_path / "out"
    out.mkdir()
    cmd = [lmp, "-in", str(EXAMPLE / "riser.in"), "-log", str(tmp_path / "log.lammps"),
           "-screen", "none", "-var", "steps", "200", "-var", "out", str(out),
           "-var", "mol", str(EXAMPLE / "grain.mol")]
    done = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=60,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    log = (tmp_path / "log.lammps").read_text()
    assert done.returncode == 0, log[-2000:] or done.stderr
    assert "Loop time" in log and "for 200 steps" in log
    # one grain deposited every 100 steps; dumps at step 0 only (every 1000 steps)
    assert "with 2 atoms" in log
    assert sorted(p.name for p in out.iterdir()) == ["dump.0.lammpstrj"]
