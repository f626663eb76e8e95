"""Field cases: small dumps with the quirks of real data (copied into tests/io/field/) that
used to be stored wrong without a word. Right values from the cases' descriptions:

- ``unwrapped-coarse.dump`` / ``unwrapped-fine.dump``: unwrapped ``xu yu zu`` on a periodic
  y, frames 0.1 s / 0.025 s apart; laps = floor(yu / H) (the ``.laps.npy`` beside them),
  wrapped y = yu mod 0.95. In the coarse one two particles move more than H/2 between
  frames, where the minimal-image rule gave laps -3 instead of 7 and 0 instead of 10.
- ``box-wider-than-riser.dump``: the box is -0.001..0.091 m across, the riser 0..0.09 m;
  positions = ``box-wider-than-riser.xy.npy`` exactly (``--width`` shifted them by 1 mm).
- ``liggghts-dump800.newModels``: a LIGGGHTS 3D dump, gravity along -z, box -0.05..0.05 x
  -0.05..0.05 x 0..0.15 m (was stored as an x-y riser 0.1 m high with z dropped).
"""

from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.io import import_file
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_info import describe

FIELD = Path(__file__).parent / "field"
H = 0.95


def _read(path):
    with Trajectories(path) as t:
        return t.times, t.positions(), t.laps(), t.width, t.height, t.parameters


def _unwrapped_heights(path):
    """yu of every atom per frame, read with plain string handling, sorted by id."""
    frames, lines = [], Path(path).read_text().splitlines()
    for k, line in enumerate(lines):
        if line.startswith("ITEM: ATOMS"):
            names = line.split()[2:]
            n = int(lines[k - 5])
            rows = sorted((int(r.split()[names.index("id")]), float(r.split()[names.index("yu")]))
                          for r in lines[k + 1:k + 1 + n])
            frames.append([y for _, y in rows])
    return np.asarray(frames)


@pytest.mark.parametrize("name", ["unwrapped-coarse", "unwrapped-fine"])
def test_unwrapped_coordinates_give_exact_laps(tmp_path, name):
    out = import_file(FIELD / f"{name}.dump", "lammps", tmp_path / "u.h5", time_step=5e-6)
    _, pos, laps, width, height, params = _read(out)
    expected = np.load(FIELD / f"{name}.laps.npy")
    np.testing.assert_array_equal(laps, expected)
    yu = _unwrapped_heights(FIELD / f"{name}.dump")
    np.testing.assert_allclose(pos[..., 1], np.mod(yu, H), rtol=0, atol=1e-12)
    assert (width, height) == (0.09, 0.95)
    assert params["laps_from"] == "unwrapped coordinates"


def test_coarse_wrapped_output_is_refused_and_image_flags_give_the_laps(tmp_path, capsys):
    """The same coarse motion written as wrapped y: the minimal-image rule cannot tell the
    laps (steps up to 0.95 m in 0.1 s), so import refuses, naming the particle, the step and
    the fix; written as wrapped y with image flags iy, the laps are exact again."""
    text = (FIELD / "unwrapped-coarse.dump").read_text()
    yu = _unwrapped_heights(FIELD / "unwrapped-coarse.dump")
    wrapped_lines, image_lines, frame = [], [], -1
    for line in text.splitlines():
        if line.startswith("ITEM: ATOMS"):
            frame += 1
            atom = 0
            wrapped_lines.append("ITEM: ATOMS id type x y z")
            image_lines.append("ITEM: ATOMS id type x y z ix iy iz")
            continue
        parts = line.split()
        if len(parts) == 5 and frame >= 0 and wrapped_lines[-1].startswith(("ITEM: ATOMS", "1 ",
                                                                            "2 ", "3 ", "4 ")):
            pid = int(parts[0])
            y = float(yu[frame, pid - 1])
            lap = int(np.floor(y / H))
            wrapped_lines.append(f"{pid} 1 {parts[2]} {y - lap * H!r} 0")
            image_lines.append(f"{pid} 1 {parts[2]} {y - lap * H!r} 0 0 {lap} 0")
            atom += 1
            continue
        wrapped_lines.append(line)
        image_lines.append(line)
    wrapped = tmp_path / "wrapped.dump"
    wrapped.write_text("\n".join(wrapped_lines) + "\n")
    with pytest.raises(InputError, match=r"particle \d moved 0\.\d+ m \(more than 0.25 of the "
                                         r"height 0.95 m\).*unwrapped coordinates \(xu yu\)"):
        import_file(wrapped, "lammps", tmp_path / "w.h5", time_step=5e-6)
    assert not (tmp_path / "w.h5").exists()
    assert main(["import", str(wrapped), "--format", "lammps", "--time-step", "5e-6", "-o",
                 str(tmp_path / "w.h5")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    flagged = tmp_path / "image.dump"
    flagged.write_text("\n".join(image_lines) + "\n")
    _, _, laps, *_, params = _read(import_file(flagged, "lammps", tmp_path / "i.h5",
                                               time_step=5e-6))
    np.testing.assert_array_equal(laps, np.load(FIELD / "unwrapped-coarse.laps.npy"))
    assert params["laps_from"] == "image flags"


@pytest.mark.parametrize("options", [
    {"region": ((0.0, 0.09), (0.0, 0.95))},
    {"width": 0.09, "height": 0.95},
], ids=["region", "width-height"])
def test_box_wider_than_the_riser_does_not_shift_positions(tmp_path, options):
    out = import_file(FIELD / "box-wider-than-riser.dump", "lammps", tmp_path / "b.h5",
                      time_step=5e-6, **options)
    _, pos, _, width, height, params = _read(out)
    # exact to the dump's 8 printed digits: no 1 mm shift
    np.testing.assert_allclose(pos, np.load(FIELD / "box-wider-than-riser.xy.npy"), rtol=0,
                               atol=5e-9)
    assert (width, height) == (0.09, 0.95)
    assert params["region"] == [[0.0, 0.09], [0.0, 0.95]]
    # without a region the box (lower corner at -0.001 m) is the domain, as the file says
    _, pos_box, _, width_box, *_ = _read(import_file(FIELD / "box-wider-than-riser.dump",
                                                     "lammps", tmp_path / "box.h5",
                                                     time_step=5e-6))
    assert width_box == pytest.approx(0.092)
    np.testing.assert_allclose(pos_box[..., 0], pos[..., 0] + 0.001, rtol=0, atol=1e-15)


def test_particles_outside_the_region_are_absent_and_an_empty_region_is_refused(tmp_path, capsys):
    """A region narrower than the riser keeps the particles inside it, measured from its own
    lower corner; the others are absent from the frames where they lie outside it."""
    out = import_file(FIELD / "box-wider-than-riser.dump", "lammps", tmp_path / "r.h5",
                      time_step=5e-6, region=((0.05, 0.09), (0.0, 0.95)))
    truth = np.load(FIELD / "box-wider-than-riser.xy.npy")
    inside = truth[..., 0] >= 0.05
    assert 0 < inside.sum() < inside.size
    with Trajectories(out) as t:
        present, pos = t.present(), t.positions()
        order = np.argsort(t.ids)
    np.testing.assert_array_equal(present[:, order], inside)
    np.testing.assert_allclose(pos[:, order][inside][:, 0], truth[inside][:, 0] - 0.05, atol=5e-9)
    assert np.isnan(pos[:, order][~inside]).all()
    code = main(["import", str(FIELD / "box-wider-than-riser.dump"), "--format", "lammps",
                 "--time-step", "5e-6", "--region", "0.5:0.9,0:0.95", "-o", str(tmp_path / "e.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "holds no particle" in err
    assert not (tmp_path / "e.h5").exists()


def test_3d_dump_needs_its_vertical_axis(tmp_path, capsys):
    source = FIELD / "liggghts-dump800.newModels"
    code = main(["import", str(source), "--format", "lammps", "--time-step", "1e-5", "-o",
                 str(tmp_path / "g.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "3D positions" in err and "--vertical-axis" in err and "z 0..0.15" in err
    assert "the box's longest, z" in err
    assert not (tmp_path / "g.h5").exists()
    out = import_file(source, "lammps", tmp_path / "g.h5", time_step=1e-5, vertical_axis="z")
    times, pos, laps, width, height, params = _read(out)
    assert (width, height) == pytest.approx((0.1, 0.15))
    assert times.tolist() == pytest.approx([0.008])
    raw = np.loadtxt(source, skiprows=9, usecols=(2, 3, 4))
    np.testing.assert_allclose(pos[0, :, 1], raw[:, 2], atol=1e-15)          # heights are z
    np.testing.assert_allclose(pos[0, :, 0], raw[:, 0] + 0.05, atol=1e-15)   # across is x
    np.testing.assert_allclose(pos[0, :, 2], raw[:, 1] + 0.05, atol=1e-15)   # depth is y
    with Trajectories(out) as t:
        assert (t.dimensions, t.depth, t.boundary) == (3, pytest.approx(0.1), "open")
        assert t.axes == {"across": "x", "vertical": "z", "depth": "y"}
        np.testing.assert_allclose(t.region_origin, [-0.05, 0.0, -0.05])
    assert params["vertical_axis"] == "z" and params["across_axis"] == "x"
    assert params["depth_axis"] == "y" and params["depth_axis_dropped"] is None
    assert params["laps_from"] == "none (open riser)" and laps.max() == 0
    # projected on (across, vertical) on request
    flat = import_file(source, "lammps", tmp_path / "f.h5", time_step=1e-5, vertical_axis="z",
                       drop_depth=True)
    _, pos2, *_, params2 = _read(flat)
    assert pos2.shape[-1] == 2 and params2["depth_axis_dropped"] == "y"
    np.testing.assert_array_equal(pos2, pos[..., :2])
    with pytest.raises(InputError, match="the z axis: give x, y and z ranges"):
        import_file(source, "lammps", tmp_path / "x.h5", time_step=1e-5, vertical_axis="z",
                    region=((-0.05, 0.05), (-0.05, 0.05)))
    with pytest.raises(InputError, match="choose x, y or z"):
        import_file(source, "lammps", tmp_path / "x.h5", time_step=1e-5, vertical_axis="w")


def test_region_option_is_checked(tmp_path, capsys):
    for bad in ("0:0.09", "0:0.09,0.95:0", "a:b,0:1", "0:1,0:1,0:1,0:1", "0:inf,0:1"):
        code = main(["import", str(FIELD / "box-wider-than-riser.dump"), "--format", "lammps",
                     "--region", bad, "-o", str(tmp_path / "x.h5")])
        err = capsys.readouterr().err
        assert code == 2 and "region" in err and err.count("\n") == 1, (bad, err)


def test_liggghts_one_file_per_timestep_by_glob_in_timestep_order(tmp_path, capsys):
    """13 files dump0 ... dump9600 (name order puts dump800 after dump7200); dump0 holds no
    atom; 3D with gravity along -z: 12 frames at t = 0.008 ... 0.096 s of 6 particles, the
    heights the files' z, across x (0.1 m wide box), depth y."""
    pattern = str(FIELD / "liggghts-per-timestep" / "post" / "dump*.newModels")
    out = tmp_path / "l.h5"
    code = main(["import", pattern, "--format", "lammps", "--time-step", "1e-5",
                 "--vertical-axis", "z", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    times, pos, laps, width, height, params = _read(out)
    np.testing.assert_allclose(times, 0.008 * np.arange(1, 13), rtol=1e-12)
    assert pos.shape == (12, 6, 3) and (width, height) == pytest.approx((0.1, 0.15))
    for k, timestep in enumerate(range(800, 9601, 800)):
        raw = np.loadtxt(FIELD / "liggghts-per-timestep" / "post" / f"dump{timestep}.newModels",
                         skiprows=9, usecols=(0, 2, 4))
        raw = raw[np.argsort(raw[:, 0])]
        np.testing.assert_allclose(pos[k, :, 1], raw[:, 2], atol=1e-15)
        np.testing.assert_allclose(pos[k, :, 0], raw[:, 1] + 0.05, atol=1e-15)
    assert params["frames_without_atoms_skipped"] == 1 and len(params["source_files"]) == 13
    assert params["source_files"][1] == "dump800.newModels"
    assert laps.max() == 0 and params["laps_from"] == "none (open riser)"
    assert main(["import", str(FIELD / "nothing*.dump"), "--format", "lammps", "-o",
                 str(tmp_path / "n.h5")]) == 2
    assert "no file matches" in capsys.readouterr().err


def test_triclinic_box_with_zero_tilt_reads_as_orthogonal(tmp_path):
    _, pos, _, width, height, _ = _read(import_file(FIELD / "triclinic-zero-tilt.dump", "lammps",
                                                    tmp_path / "t.h5", time_step=1e-5))
    assert (width, height) == (0.09, 0.95)
    np.testing.assert_allclose(pos[0], [[0.02, 0.3], [0.06, 0.7]], atol=1e-15)
    assert pos.shape == (3, 2, 2)


def test_shrink_wrapped_box_is_accepted_with_a_region(tmp_path):
    source = FIELD / "shrinkwrap-box.dump"
    with pytest.raises(InputError, match="the box changes"):
        import_file(source, "lammps", tmp_path / "s.h5", time_step=1e-5)
    out = import_file(source, "lammps", tmp_path / "s.h5", time_step=1e-5,
                      region=((0.0, 0.09), (0.0, 0.95)))
    _, pos, _, width, height, params = _read(out)
    assert (width, height) == (0.09, 0.95) and params["region"] == [[0.0, 0.09], [0.0, 0.95]]
    first = np.loadtxt(source, skiprows=9, max_rows=5, usecols=(0, 2, 3))
    np.testing.assert_allclose(pos[0], first[np.argsort(first[:, 0])][:, 1:], atol=1e-15)


def test_info_shows_a_wrong_import_at_a_glance(tmp_path, capsys):
    lig = tmp_path / "lig.h5"
    assert main(["import", str(FIELD / "liggghts-per-timestep" / "post" / "dump*.newModels"),
                 "--format", "lammps", "--time-step", "1e-5", "--vertical-axis", "z", "-o",
                 str(lig)]) == 0
    coarse = import_file(FIELD / "unwrapped-coarse.dump", "lammps", tmp_path / "uc.h5",
                         time_step=5e-6)
    capsys.readouterr()
    assert main(["info", str(lig)]) == 0
    text = capsys.readouterr().out
    assert "0.1 m across x 0.15 m high x 0.1 m deep (3D)" in text
    assert "vertical z, across x, depth y" in text and "vertical boundary open" in text
    assert "particles present per frame: min 6, max 6" in text
    assert main(["info", str(coarse)]) == 0
    text = capsys.readouterr().out
    laps = np.load(FIELD / "unwrapped-coarse.laps.npy")
    assert "laps from: unwrapped coordinates" in text
    assert f"passes through the periodic boundary: {laps[-1].sum()} up, 0 down" in text


# -- particles that come and go ----------------------------------------------------------------
def _ids_per_frame(path):
    with Trajectories(path) as t:
        return [set(t.ids[p].tolist()) for p in t.present()], t


def test_outlet_deletion_and_reinsertion_under_a_new_id(tmp_path):
    """`ff ff pp`: y is not periodic, so the riser is open; particle 3 leaves through the
    outlet and particle 6 is inserted: ids {1-5}, {1-5}, {1,2,4,5}, {1,2,4,5,6}."""
    out = import_file(FIELD / "outlet-delete-reinsert.dump", "lammps", tmp_path / "o.h5",
                      time_step=1e-5)
    present, _ = _ids_per_frame(out)
    assert present == [{1, 2, 3, 4, 5}, {1, 2, 3, 4, 5}, {1, 2, 4, 5}, {1, 2, 4, 5, 6}]
    with Trajectories(out) as t:
        assert t.boundary == "open" and t.laps().max() == 0
        np.testing.assert_array_equal(t.ids, [1, 2, 3, 4, 5, 6])
        np.testing.assert_allclose(t.positions(3)[5], [0.06, 0.2])
        text = "\n".join(describe(t))
    assert "tracks begun 1, ended 1 (after the first frame, anywhere" in text
    assert "min 4, max 5 of 6" in text
    assert "vertical boundary open" in text and "passes through" not in text
    # the same file declared periodic counts laps instead (particle 5: 0.9 -> 0 passes up)
    out = import_file(FIELD / "outlet-delete-reinsert.dump", "lammps", tmp_path / "p.h5",
                      time_step=1e-5, boundary="periodic")
    with Trajectories(out) as t:
        assert t.boundary == "periodic" and t.laps()[2:, 4].tolist() == [1, 1]


def test_an_open_riser_warns_of_a_particle_back_at_the_inlet_with_its_id(tmp_path, capsys):
    """Particle 5 goes from 0.9 m to 0 m between two frames of the open riser while present
    in both: an open riser reads it as a move inside, not an exit and an entry, so import
    warns and names the periodic boundary; declared periodic, no warning (a lap)."""
    dump = str(FIELD / "outlet-delete-reinsert.dump")
    code = main(["import", dump, "--time-step", "1e-5", "-o", str(tmp_path / "o.h5")])
    err = capsys.readouterr().err
    assert code == 0
    line = [w for w in err.splitlines() if w.startswith("warning:")]
    assert len(line) == 1 and "1 move(s) of half the riser's height" in line[0]
    assert "particle 5: 0.9 -> 0 m between 0.05 and 0.1 s" in line[0]
    assert "--boundary periodic" in line[0]
    code = main(["import", dump, "--time-step", "1e-5", "--boundary", "periodic", "-o",
                 str(tmp_path / "p.h5")])
    assert code == 0 and "warning:" not in capsys.readouterr().err
    # four frames hold no path from the inlet to the outlet: refused with the fix
    code = main(["fit", str(tmp_path / "o.h5"), "--cells", "1x4", "--lag", "0.05", "--window",
                 "0:0.15", "-o", str(tmp_path / "m.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "every residence is trapped" in err
    assert "fit on a longer window" in err and not (tmp_path / "m.h5").exists()


def test_an_open_riser_without_entries_is_refused_with_the_fix(tmp_path, capsys):
    """LIGGGHTS files of one timestep each, an open box whose 6 particles never leave nor
    enter: a fit has no entry distribution, refused in one line naming what to do."""
    source = str(FIELD / "liggghts-per-timestep" / "post" / "dump*.newModels")
    assert main(["import", source, "--vertical-axis", "z", "--time-step", "1e-5", "-o",
                 str(tmp_path / "lig.h5")]) == 0
    capsys.readouterr()
    assert main(["fit", str(tmp_path / "lig.h5"), "--cells", "2x3", "--lag", "0.008",
                 "--window", "0.008:0.096", "-o", str(tmp_path / "m.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "without any entry through the inlet" in err
    assert "fit on a window in which particles enter" in err and "--boundary periodic" in err


def test_insert_stream_growing_atom_count_with_image_flags(tmp_path):
    """LIGGGHTS insert/stream: the atom count grows; a duplicated `type` column; image flags.
    Every id is present from the frame where it first appears."""
    source = FIELD / "insert-stream-growing.dump"
    text = source.read_text().split("ITEM: TIMESTEP")[1:]
    expected = [{int(line.split()[0]) for line in frame.split("ITEM: ATOMS")[1].splitlines()[1:]
                 if line.strip()} for frame in text]
    assert len(expected[-1]) > len(expected[0])
    out = import_file(source, "lammps", tmp_path / "s.h5", time_step=1e-5)
    present, _ = _ids_per_frame(out)
    assert present == expected
    with Trajectories(out) as t:
        assert t.parameters["laps_from"] == "image flags" and t.boundary == "periodic"
        first = {int(i): k for k, i in enumerate(t.ids)}
        for k, frame in enumerate(text):
            for line in frame.split("ITEM: ATOMS")[1].splitlines()[1:]:
                if line.strip():
                    v = line.split()
                    np.testing.assert_allclose(t.positions(k)[first[int(v[0])]],
                                               [float(v[3]), float(v[4])], atol=1e-15)


def test_a_region_that_holds_no_particle_and_bad_new_options(tmp_path, capsys):
    dump = str(FIELD / "outlet-delete-reinsert.dump")
    # the region named axis by axis in the order --region takes, beside the dump's box
    for args, match in ((["--region", "0.5:0.6,0:0.95"],
                         "the riser region x 0.5:0.6 (across), y 0:0.95 (vertical) m holds no "
                         "particle in any frame; check --region (or --width/--height) against "
                         "the first frame's box, x 0:0.09, y 0:0.95, z -0.0005:0.0005 m"),
                        (["--boundary", "shut"], "argument --boundary: invalid choice"),
                        (["--resample", "0.01"], "--resample and --max-gap apply to CSV files"),
                        (["--region", "0:0.09,0.95:0"], "region")):
        code = main(["import", dump, "--format", "lammps", "--time-step", "1e-5", *args, "-o",
                     str(tmp_path / "x.h5")])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and match in err, (args, err)
    assert not (tmp_path / "x.h5").exists()
    # 3D, vertical z: the ranges in the order typed (x, y, z), not stored (across, vertical,
    # depth), so that the wrong one shows (a review read y and z swapped, unnamed)
    assert main(["import", str(FIELD / "liggghts-per-timestep" / "post" / "dump*.newModels"),
                 "--format", "lammps", "--time-step", "1e-5", "--vertical-axis", "z",
                 "--region", "-0.045:0.045,-0.0005:0.0005,0:0.95",
                 "-o", str(tmp_path / "x.h5")]) == 2
    assert ("the riser region x -0.045:0.045 (across), y -0.0005:0.0005 (depth), z 0:0.95 "
            "(vertical) m holds no particle in any frame; check --region (or --width/--height) "
            "against the first frame's box, x -0.05:0.05, y -0.05:0.05, z 0:0.15 m"
            ) in capsys.readouterr().err


def test_a_dump_flat_in_z_at_first_that_spreads_later_is_refused(tmp_path, capsys):
    """insert/stream from an inlet face at one height: the first frame's atoms all lie at one
    z, so the dump looks 2D; where atoms leave that z it is 3D, and import refuses instead
    of dropping z."""
    frames = []
    for k, zs in enumerate(([0.05, 0.05], [0.05, 0.04, 0.05])):
        atoms = "".join(f"{i + 1} 1 {0.01 * (i + 1)} 0.02 {z}\n" for i, z in enumerate(zs))
        frames.append(f"ITEM: TIMESTEP\n{1000 * k}\nITEM: NUMBER OF ATOMS\n{len(zs)}\n"
                      "ITEM: BOX BOUNDS ff ff ff\n0 0.05\n0 0.05\n0 0.06\n"
                      f"ITEM: ATOMS id type x y z\n{atoms}")
    source = tmp_path / "flat.dump"
    source.write_text("".join(frames))
    code = main(["import", str(source), "--format", "lammps", "--time-step", "1e-5", "-o",
                 str(tmp_path / "f.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "particle 2 at z = 0.04 m" in err and "--vertical-axis" in err
    assert not (tmp_path / "f.h5").exists()
    out = import_file(source, "lammps", tmp_path / "g.h5", time_step=1e-5, vertical_axis="z")
    with Trajectories(out) as t:
        assert t.dimensions == 3 and t.present().tolist() == [[True, True, False], [True] * 3]


def test_a_pair_of_frames_out_of_order_is_named_as_such(tmp_path, capsys):
    """Two frames swapped in a dump: the first gap (twice the interval) is refused with the
    way out for frames that come later in the file, not only for missing ones."""
    from cfbmarkov.cli import main

    frames = (FIELD / "unwrapped-fine.dump").read_text().split("ITEM: TIMESTEP")[1:]
    frames[2], frames[3] = frames[3], frames[2]
    swapped = tmp_path / "swap.dump"
    swapped.write_text("".join("ITEM: TIMESTEP" + f for f in frames))
    assert main(["import", str(swapped), "--time-step", "5e-6", "-o", str(tmp_path / "s.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "frames unevenly spaced" in err
    assert "missing frames come later in the file, out of order: put its frames in time " \
        "order" in err
    assert not (tmp_path / "s.h5").exists()
