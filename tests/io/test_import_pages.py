"""The import commands of docs/how-to/particle-files.md and docs/how-to/pept-ptv.md run as
printed, each on a small file of tests/io/field named as the page names it (the folder of
`cfbmarkov export-vtk`, on a generated run)."""

from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path

import pytest

from cfbmarkov.cli import main
from cfbmarkov.trajectories import Trajectories

ROOT = Path(__file__).resolve().parents[2]
FIELD = Path(__file__).resolve().parent / "field"
BLOCK = re.compile(r"^```(?:bash|sh|text)\s*$(.*?)^```", re.M | re.S)

#: the file each page's command names -> the field file or folder standing for it
SOURCES = {"post/dump*.vtk": ("liggghts-custom-vtk/post", "post"),
           "RISER_DES.pvd": ("mfix-des-vtp", "."),
           "dump_h5md.h5": ("lammps-h5md/dump_h5md.h5", "dump_h5md.h5"),
           "particles.csv": ("paraview-csv-export/particles.csv", "particles.csv"),
           "pept.csv": ("pept-pointdata.csv", "pept.csv"),
           "tracks.csv": ("ptv-enter-leave.csv", "tracks.csv"),
           "vtk": (None, "vtk")}


def _commands(page: str) -> list[str]:
    lines = []
    for block in BLOCK.findall((ROOT / "docs" / "how-to" / page).read_text(encoding="utf-8")):
        for line in re.sub(r"\\\n\s*", " ", block).splitlines():
            line = line.strip().removeprefix("$ ")
            if line.startswith("cfbmarkov import ") and " error:" not in line:
                lines.append(line)
    return lines


CASES = [(page, line) for page in ("particle-files.md", "pept-ptv.md")
         for line in _commands(page)]


def test_the_pages_show_their_commands():
    assert len(CASES) == 8
    assert {shlex.split(line)[2] for _, line in CASES} == set(SOURCES)


@pytest.mark.parametrize("page, line", CASES)
def test_import_command_of_the_page_runs(page, line, tmp_path, monkeypatch, capsys):
    argv = shlex.split(line)[1:]
    source, target = SOURCES[argv[1]]
    if source is None:                  # what export-vtk writes of a generated run
        from cfbmarkov.io.vtk import export_vtk
        from tests.io.test_vtk import make_run

        make_run(tmp_path / "generated.h5")
        export_vtk(tmp_path / "generated.h5", tmp_path / target)
    elif (FIELD / source).is_dir():
        shutil.copytree(FIELD / source, tmp_path / target, dirs_exist_ok=True)
    else:
        shutil.copy(FIELD / source, tmp_path / target)
    monkeypatch.chdir(tmp_path)
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 0, f"{page}: {line}: {err}"
    output = argv[argv.index("-o") + 1]
    assert out == f"{output}\n" and err.startswith("cfbmarkov import: read ")
    with Trajectories(tmp_path / output) as t:
        assert t.n_frames > 5 and t.n_particles >= 1
