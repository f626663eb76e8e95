"""Scaled, unwrapped and image-flag dump columns, in 2D and 3D, written the way LAMMPS writes
them: ``dump atom`` (``id type xs ys zs``, with ``ix iy iz`` under ``dump_modify image yes``)
and ``dump custom`` (``xsu ysu zsu``, ``x y z ix iy iz``, ``xu yu zu``), ``%g`` numbers,
atoms unsorted. A 2D LAMMPS run has a z box of -0.5..0.5 and every atom at z = 0, so
``zs = 0.5``. The right positions and laps are those the dumps were generated from.
"""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.io import import_file
from cfbmarkov.trajectories import Trajectories

W, H = 0.09, 0.95
#: the box lower corner (a riser centred across on x = 0, vertically on y = 0)
LO = np.array([-0.045, -0.475])
N, FRAMES, STEP, DT = 5, 24, 2000, 5e-6


def _motion():
    """Unwrapped positions [T, N, 2] relative to the box corner: upward at different speeds
    (several laps, at most 0.2 H per frame), a slow sway across."""
    t = np.arange(FRAMES)[:, None] * STEP * DT
    k = np.arange(N)[None, :]
    x = 0.01 + 0.015 * k + 0.004 * np.sin(3 * t + k)
    y = 0.05 + 0.17 * k + (1.0 + 0.6 * k) * 5 * t - (k == 4) * 2.5 * t
    return np.stack([x + 0 * t, y], axis=-1)


def _dump(columns: str, dims: int, z_box=(-0.5, 0.5), vertical: str = "y") -> str:
    """The dump text of :func:`_motion` with ``columns`` ('atom', 'atom-image', 'xsu',
    'x-image', 'xu'); in 3D the depth axis holds 0.0005 + 0.0001 k, and with ``vertical``
    'z' the riser's height is along z (box z = -H/2..H/2, y = the depth)."""
    pos = _motion()
    lap = np.floor(pos[..., 1] / H)
    wrapped = pos[..., 1] - lap * H
    rng = np.random.default_rng(3)
    out = []
    for f in range(FRAMES):
        order = rng.permutation(N)             # dump_modify sort is off by default
        names = {"atom": "xs ys zs", "atom-image": "xs ys zs ix iy iz", "xsu": "xsu ysu zsu",
                 "x-image": "x y z ix iy iz", "xu": "xu yu zu"}[columns]
        across_lo, across_hi = LO[0], LO[0] + W
        if vertical == "y":
            bounds = [(across_lo, across_hi), (LO[1], LO[1] + H), z_box]
            flags = "ff pp pp" if dims == 2 else "ff pp ff"
        else:
            bounds = [(across_lo, across_hi), z_box, (LO[1], LO[1] + H)]
            flags = "ff ff pp"
        lines = [f"ITEM: TIMESTEP\n{f * STEP}\nITEM: NUMBER OF ATOMS\n{N}\n"
                 f"ITEM: BOX BOUNDS {flags}\n"
                 + "".join(f"{lo:g} {hi:g}\n" for lo, hi in bounds)
                 + f"ITEM: ATOMS id type {names}\n"]
        for i in order:
            depth = (0.0 if dims == 2 else 0.0005 + 0.0001 * i)
            height_u = LO[1] + pos[f, i, 1]
            height_w = LO[1] + wrapped[f, i]
            across = LO[0] + pos[f, i, 0]
            vert_index = 1 if vertical == "y" else 2
            depth_index = 2 if vertical == "y" else 1
            unwrapped = [across, 0.0, 0.0]
            unwrapped[vert_index], unwrapped[depth_index] = height_u, depth
            plain = list(unwrapped)
            plain[vert_index] = height_w
            image = [0, 0, 0]
            image[vert_index] = int(lap[f, i])
            if columns in ("atom", "atom-image", "xsu"):
                source = unwrapped if columns == "xsu" else plain
                values = [(v - lo) / (hi - lo) for v, (lo, hi) in zip(source, bounds)]
            else:
                values = unwrapped if columns == "xu" else plain
            text = " ".join(f"{v:g}" for v in values)
            if columns.endswith("image"):
                text += " " + " ".join(str(m) for m in image)
            lines.append(f"{i + 1} 1 {text}\n")
        out.append("".join(lines))
    return "".join(out)


def _expected():
    pos = _motion()
    lap = np.floor(pos[..., 1] / H)
    return np.stack([pos[..., 0], pos[..., 1] - lap * H], axis=-1), lap


def _atol(columns):
    """%g keeps 6 significant digits: 1e-6 of a wrapped coordinate (m or box fraction); a
    scaled unwrapped one reaches 5 box heights, so 5e-6 of the height."""
    return 5e-6 if columns == "xsu" else 1.5e-6


@pytest.mark.parametrize("columns, laps_from", [
    ("atom-image", "image flags"), ("atom", "minimal-image rule"),
    ("xsu", "unwrapped coordinates"), ("x-image", "image flags"),
    ("xu", "unwrapped coordinates")])
@pytest.mark.parametrize("z_box", [(-0.5, 0.5), (-0.0005, 0.0005)])
def test_2d_dumps_of_every_column_kind_import(tmp_path, columns, laps_from, z_box):
    source = tmp_path / "dump.riser"
    source.write_text(_dump(columns, 2, z_box))
    out = import_file(source, "lammps", tmp_path / "r.h5", time_step=DT)
    positions, laps = _expected()
    with Trajectories(out) as t:
        assert t.dimensions == 2 and (t.width, t.height) == pytest.approx((W, H))
        np.testing.assert_allclose(t.positions(), positions, rtol=0, atol=_atol(columns))
        np.testing.assert_array_equal(t.laps(), laps)
        assert t.parameters["laps_from"] == laps_from
        assert laps.max() >= 3                     # the motion crosses the top several times


@pytest.mark.parametrize("columns", ["atom-image", "xsu", "x-image", "xu"])
@pytest.mark.parametrize("vertical", ["y", "z"])
def test_3d_dumps_of_every_column_kind_import(tmp_path, columns, vertical):
    source = tmp_path / "dump.riser"
    source.write_text(_dump(columns, 3, (-0.001, 0.001) if vertical == "y" else (-0.001, 0.001),
                            vertical))
    out = import_file(source, "lammps", tmp_path / "r.h5", time_step=DT, vertical_axis=vertical)
    positions, laps = _expected()
    with Trajectories(out) as t:
        assert t.dimensions == 3
        full = t.positions()
        np.testing.assert_allclose(full[..., :2], positions, rtol=0, atol=_atol(columns))
        np.testing.assert_array_equal(t.laps(), laps)
        depth = 0.0005 + 0.0001 * np.arange(N) + 0.001      # from the box's lower corner
        np.testing.assert_allclose(full[..., 2], np.broadcast_to(depth, full.shape[:2]),
                                   rtol=0, atol=_atol(columns))


def test_2d_dump_atom_through_the_command_line(tmp_path, capsys):
    source = tmp_path / "dump.riser"
    source.write_text(_dump("atom-image", 2))
    code = main(["import", str(source), "--format", "lammps", "--time-step", str(DT), "-o",
                 str(tmp_path / "r.h5")])
    assert code == 0, capsys.readouterr().err
    code = main(["info", str(tmp_path / "r.h5")])
    out = capsys.readouterr().out
    assert code == 0 and "image flags" in out
