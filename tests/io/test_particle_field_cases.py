"""Field cases of particle files (copied into tests/io/field/ from the shared field data, each
with its ``truth.json``):

- ``liggghts-custom-vtk/post/dump*.vtk``: LIGGGHTS ``dump custom/vtk`` every 5000 steps of
  1e-5 s, with ``*_boundingBox.vtk`` (0..0.09 x 0..0.003 x 0..0.95 m, z vertical), point
  arrays id, type, v, radius.
- ``mfix-des-vtp/RISER_DES.pvd`` + ``RISER_DES_*.vtp``: MFiX-DEM 2D output (Position, ID,
  Velocity; times in the .pvd and in a comment of each file).
- ``lammps-h5md/dump_h5md.h5``: LAMMPS ``dump h5md`` of position, image, velocity, species;
  no id element (ids implicit 1..4), box 0.09 x 0.95 x 0.001 m, periodic in y.
- ``paraview-csv-export/particles.csv``: ParaView "Save Data" (``Points:0``, ``v:0``,
  ``Time``), 3D with z vertical.

The truth gives the times (and for the CSV positions, laps and velocities); positions of
the other three are read back from the files with plain string handling or h5py.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.io import import_file
from cfbmarkov.trajectories import Trajectories

FIELD = Path(__file__).parent / "field"
H = 0.95


def _truth(case: str) -> dict:
    return json.loads((FIELD / case / "truth.json").read_text())


def _read(path):
    with Trajectories(path) as t:
        return t.times, t.ids, t.positions(), t.velocities(), t.laps(), t.parameters


def _liggghts_points():
    """(x, z) of each file's POINTS, in step order, by plain string handling."""
    frames = []
    files = sorted((FIELD / "liggghts-custom-vtk" / "post").glob("dump*.vtk"),
                   key=lambda p: int(re.sub(r"\D", "", p.stem) or 0))
    for path in files:
        if "boundingBox" in path.name:
            continue
        lines = path.read_text().splitlines()
        k = next(i for i, line in enumerate(lines) if line.startswith("POINTS"))
        n = int(lines[k].split()[1])
        frames.append([[float(v) for v in row.split()] for row in lines[k + 1:k + 1 + n]])
    return np.asarray(frames)


def test_liggghts_custom_vtk(tmp_path, capsys):
    truth = _truth("liggghts-custom-vtk")
    post = FIELD / "liggghts-custom-vtk" / "post"
    code = main(["import", str(post / "dump*.vtk"), "--time-step", "1e-5", "--vertical-axis",
                 "z", "--drop-depth", "-o", str(tmp_path / "l.h5")])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "legacy VTK (detected from the content" in captured.err
    times, ids, pos, vel, laps, params = _read(tmp_path / "l.h5")
    np.testing.assert_allclose(times, truth["times"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ids, [1, 2, 3, 4])
    points = _liggghts_points()
    np.testing.assert_allclose(pos, points[..., [0, 2]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(vel[..., 1], 1.5)
    # vz = 1.5 m/s over 0.5 s: 0.75 m up, through the top once for the particles starting
    # above 0.2 m
    np.testing.assert_array_equal(laps[-1] - laps[0], [0, 1, 1, 1])
    assert params["box"] == [[0.0, 0.09], [0.0, 0.003], [0.0, 0.95]]
    # the folder itself, and a missing time step named
    code = main(["import", str(post), "--vertical-axis", "z", "-o", str(tmp_path / "m.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--time-step" in err


def _vtp_positions():
    frames = []
    for path in sorted((FIELD / "mfix-des-vtp").glob("RISER_DES_*.vtp")):
        text = path.read_text()
        block = re.search(r'Name="Position"[^>]*>(.*?)</DataArray>', text, re.S).group(1)
        frames.append(np.array(block.split(), dtype=float).reshape(-1, 3))
    return np.asarray(frames)


@pytest.mark.parametrize("source", ["RISER_DES.pvd", "", "RISER_DES_*.vtp"],
                         ids=["pvd", "folder", "vtp-pattern"])
def test_mfix_des_vtp(tmp_path, capsys, source):
    truth = _truth("mfix-des-vtp")
    out = tmp_path / "m.h5"
    code = main(["import", str(FIELD / "mfix-des-vtp" / source), "--width", "0.09",
                 "--height", "0.95", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    times, ids, pos, vel, laps, params = _read(out)
    np.testing.assert_allclose(times, truth["times"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ids, [1, 2, 3, 4])
    np.testing.assert_allclose(pos, _vtp_positions()[..., :2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(vel[..., 1], 1.2)


def test_pieces_of_one_frame_without_their_pvd_are_named_as_such(tmp_path, capsys):
    """Files of one time (pieces written in parallel, or copies) given without the .pvd
    that groups them: refused in one line naming them as pieces and the .pvd as the cure."""
    import shutil

    folder = tmp_path / "pieces"
    folder.mkdir()
    for name in ("RISER_DES_0000.vtp", "RISER_DES_0001.vtp"):
        shutil.copy(FIELD / "mfix-des-vtp" / name, folder / name)
    shutil.copy(FIELD / "mfix-des-vtp" / "RISER_DES_0000.vtp", folder / "RISER_DES_0000_p1.vtp")
    code = main(["import", str(folder), "--width", "0.09", "--height", "0.95", "-o",
                 str(tmp_path / "m.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "the files are pieces of one frame" in err and "import the .pvd" in err
    assert not (tmp_path / "m.h5").exists()


def test_mfix_des_vtp_without_geometry_is_refused(tmp_path, capsys):
    code = main(["import", str(FIELD / "mfix-des-vtp" / "RISER_DES.pvd"), "-o",
                 str(tmp_path / "m.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--width and --height" in err
    assert not (tmp_path / "m.h5").exists()


def test_lammps_h5md(tmp_path, capsys):
    truth = _truth("lammps-h5md")
    source = FIELD / "lammps-h5md" / "dump_h5md.h5"
    code = main(["import", str(source), "-o", str(tmp_path / "h.h5")])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "H5MD (detected from the content" in captured.err and "laps from image" in captured.err
    times, ids, pos, vel, laps, params = _read(tmp_path / "h.h5")
    np.testing.assert_allclose(times, truth["times"], rtol=0, atol=0)
    np.testing.assert_array_equal(ids, truth["ids_implicit"])
    with h5py.File(source, "r") as f:
        raw = f["particles/all/position/value"][()]
        image = f["particles/all/image/value"][()]
    np.testing.assert_allclose(pos, raw[..., :2], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(laps, image[..., 1])
    assert params["laps_from"] == "image flags" and params["boundary_stored"] == "periodic"


def test_paraview_csv_export(tmp_path):
    truth = _truth("paraview-csv-export")
    out = import_file(FIELD / "paraview-csv-export" / "particles.csv", "csv", tmp_path / "p.h5",
                      vertical_axis="z", drop_depth=True, width=0.09, height=0.95)
    times, ids, pos, vel, laps, _ = _read(out)
    np.testing.assert_allclose(times, truth["times"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ids, truth["ids"])
    np.testing.assert_allclose(pos, truth["positions"], rtol=0, atol=truth["tolerance_m"])
    np.testing.assert_array_equal(laps, truth["laps"])
    np.testing.assert_allclose(vel, truth["velocities"], rtol=0, atol=1e-12)
