"""A region narrower than a dump's periodic box: particles outside it are absent on every
axis (across, vertical, depth), never folded into it at shifted positions."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.io import import_lammps
from cfbmarkov.trajectories import Trajectories


def _dump(path, frames, box, flags="pp pp pp"):
    lines = []
    for t, atoms in enumerate(frames):
        lines += ["ITEM: TIMESTEP", str(t), "ITEM: TIME", repr(0.01 * t),
                  "ITEM: NUMBER OF ATOMS", str(len(atoms)), f"ITEM: BOX BOUNDS {flags}"]
        lines += [f"{lo!r} {hi!r}" for lo, hi in box]
        lines.append("ITEM: ATOMS id x y z")
        lines += [" ".join([str(i + 1)] + [repr(v) for v in p]) for i, p in enumerate(atoms)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _read(path):
    with Trajectories(path) as t:
        return t.positions(), t.present(), t.laps()


BOX_2D = ((0.0, 0.09), (0.0, 0.95), (-0.0005, 0.0005))
FRAMES_2D = [[(0.01, 0.3, 0.0), (0.07, 0.5, 0.0)], [(0.02, 0.31, 0.0), (0.08, 0.52, 0.0)]]


@pytest.mark.parametrize("options", [{"region": ((0.0, 0.045), (0.0, 0.95))},
                                     {"width": 0.045}])
def test_particle_across_a_periodic_box_outside_the_region_is_absent(tmp_path, options):
    source = _dump(tmp_path / "wide.dump", FRAMES_2D, BOX_2D)
    positions, present, _ = _read(import_lammps(source, tmp_path / "w.h5", **options))
    np.testing.assert_array_equal(present, [[True, False], [True, False]])
    np.testing.assert_allclose(positions[:, 0], [[0.01, 0.3], [0.02, 0.31]])
    assert np.isnan(positions[:, 1]).all()


def test_particle_outside_a_depth_sub_range_is_absent(tmp_path):
    frames = [[(0.01, 0.3, 0.005), (0.02, 0.5, 0.03)], [(0.02, 0.31, 0.006), (0.03, 0.52, 0.031)]]
    source = _dump(tmp_path / "d3.dump", frames, ((0.0, 0.09), (0.0, 0.95), (0.0, 0.04)))
    positions, present, _ = _read(import_lammps(
        source, tmp_path / "d.h5", vertical_axis="y",
        region=((0.0, 0.09), (0.0, 0.95), (0.0, 0.01))))
    np.testing.assert_array_equal(present, [[True, False], [True, False]])
    np.testing.assert_allclose(positions[:, 0], [[0.01, 0.3, 0.005], [0.02, 0.31, 0.006]])


def test_region_offset_in_a_periodic_box_wraps_by_the_box(tmp_path):
    """A particle just across the periodic box's edge is folded by the box's period, then
    measured from the region (here the region lies in the box's right half)."""
    frames = [[(0.08, 0.3, 0.0), (0.091, 0.5, 0.0)]]       # 0.091 is 0.001 past the box
    source = _dump(tmp_path / "edge.dump", frames, BOX_2D)
    positions, present, _ = _read(import_lammps(source, tmp_path / "e.h5",
                                                region=((0.045, 0.09), (0.0, 0.95))))
    np.testing.assert_array_equal(present, [[True, False]])     # 0.001 wrapped: outside
    np.testing.assert_allclose(positions[0, 0], [0.035, 0.3])


def test_periodic_riser_shorter_than_the_box_is_refused(tmp_path):
    source = _dump(tmp_path / "tall.dump", FRAMES_2D, BOX_2D)
    with pytest.raises(InputError, match="not the periodic box's 0..0.95 m.*--boundary open"):
        import_lammps(source, tmp_path / "t.h5", region=((0.0, 0.09), (0.0, 0.4)))
    assert not (tmp_path / "t.h5").exists()


def test_open_section_of_a_periodic_box(tmp_path):
    source = _dump(tmp_path / "tall.dump", FRAMES_2D, BOX_2D)
    _, present, _ = _read(import_lammps(source, tmp_path / "o.h5", boundary="open",
                                        region=((0.0, 0.09), (0.0, 0.4))))
    np.testing.assert_array_equal(present, [[True, False], [True, False]])


def _notes(path):
    with Trajectories(path) as t:
        return t.parameters.get("import_notes", [])


def test_rows_outside_the_region_and_a_region_beyond_the_box_are_noted(tmp_path):
    """A dump's particles left out by the region are counted in the import's notes, as a
    CSV file's rows are, and a region reaching past a fixed box is named; a region inside
    the box that holds every particle, and a shrink-wrapped box, give no note."""
    source = _dump(tmp_path / "wide.dump", FRAMES_2D, BOX_2D)
    notes = _notes(import_lammps(source, tmp_path / "w.h5",
                                 region=((-0.045, 0.045), (0.0, 0.95))))
    assert len(notes) == 2
    assert notes[0].startswith("2 of 4 particle rows (50 %) lie outside the riser's region")
    assert "the region's x -0.045..0.045 reaches beyond the source's box 0..0.09" in notes[1]
    assert _notes(import_lammps(source, tmp_path / "all.h5")) == []
    shrunk = _dump(tmp_path / "m.dump", FRAMES_2D, ((0.01, 0.08), (0.3, 0.52), (-0.0005, 0.0005)),
                   flags="mm mm mm")
    assert _notes(import_lammps(shrunk, tmp_path / "m.h5", region=((0.0, 0.09), (0.0, 0.95)),
                                boundary="open")) == []


def test_particles_outside_the_region_in_every_frame_warn_on_import(tmp_path, capsys):
    """A region that cuts the riser leaves particles out of every frame: `import` warns
    (a particle leaving an open view is present in some frames and is not counted)."""
    from cfbmarkov.cli import main

    source = _dump(tmp_path / "wide.dump", FRAMES_2D, BOX_2D)
    assert main(["import", str(source), "--region", "0:0.045,0:0.95", "-o",
                 str(tmp_path / "cut.h5")]) == 0
    err = capsys.readouterr().err
    assert "warning: 1 of the 2 particles lies outside the riser's region in every frame" in err
    assert main(["import", str(source), "-o", str(tmp_path / "whole.h5")]) == 0
    assert "warning" not in capsys.readouterr().err
