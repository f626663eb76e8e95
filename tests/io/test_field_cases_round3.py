"""Field cases of real tools' output (excerpts copied into tests/io/field/), each against
its right result:

- ``dump-atom-2d-image.dump``: LAMMPS 2D ``dump atom`` with ``dump_modify image yes``
  (``id type xs ys zs ix iy iz``, zs = 0.5, box centred on the origin, some scaled values
  just outside 0..1); right positions and laps in ``.truth.json`` beside it.
- ``liggghts-centred-box.dump``: a riser centred on x = 0, imported with the documented
  ``--region -0.045:0.045,-0.0005:0.0005,0:0.95``; particle 5 lies outside the walls.
- ``pept-two-tracers-noise.csv``: pept output of two tracers (``# t x y z error label``,
  mm and ms, label -1 = noise), its first 80 rows: tracer 0 near x = 30 mm, tracer 1 near
  x = 68 mm, one noise row.
- ``trackmate-spots.csv``: a TrackMate 7 spots export (four header rows; ``ID`` numbers
  detections, ``TRACK_ID`` the tracks): 3 tracks x 20 frames 5 ms apart and one spot in
  no track; positions in mm.
- ``excel-unicode-text-utf16.txt`` (UTF-16 LE with BOM, tabs, CR LF),
  ``excel-tab-utf8-title.txt`` (a title row above the header), ``excel-csv-bom-ghost-row.csv``
  (UTF-8 BOM, empty trailing columns and a row of only commas): 3 particles, x = 0.02, 0.04,
  0.06 m, y = 0.1, 0.35, 0.6 m + 0.025 m per frame, frames 0.025 s apart;
  ``excel-tab-cp1252-title.txt`` is the title file in cp1252 (a '°' on line 1).
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.trajectories import Trajectories

FIELD = Path(__file__).parent / "field"


def _truth(name):
    return json.loads((FIELD / f"{name}.truth.json").read_text())


def test_lammps_2d_dump_atom_with_image_flags(tmp_path, capsys):
    truth = _truth("dump-atom-2d-image")
    code = main(["import", str(FIELD / "dump-atom-2d-image.dump"), "--format", "lammps",
                 "--time-step", "5e-6", "-o", str(tmp_path / "r.h5")])
    assert code == 0, capsys.readouterr().err
    with Trajectories(tmp_path / "r.h5") as t:
        assert t.dimensions == 2 and (t.width, t.height) == pytest.approx((0.09, 0.95))
        np.testing.assert_array_equal(t.ids, truth["ids"])
        np.testing.assert_allclose(t.times, truth["times"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(t.positions(), truth["positions"], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(t.laps(), truth["laps"])
        assert t.parameters["laps_from"] == "image flags"


def test_liggghts_centred_box_with_the_documented_negative_region(tmp_path, capsys):
    truth = _truth("liggghts-centred-box")
    code = main(["import", str(FIELD / "liggghts-centred-box.dump"), "--format", "lammps",
                 "-o", str(tmp_path / "r.h5"), "--vertical-axis", "z", "--time-step", "1e-5",
                 "--region", "-0.045:0.045,-0.0005:0.0005,0:0.95"])
    assert code == 0, capsys.readouterr().err
    present = np.asarray(truth["present"])
    with Trajectories(tmp_path / "r.h5") as t:
        np.testing.assert_array_equal(t.present(), present)
        assert not present[:, 4].any()                      # particle 5: outside the walls
        np.testing.assert_allclose(t.positions()[present],
                                   np.asarray(truth["positions"])[present], rtol=0, atol=1e-9)


def test_pept_tracers_are_told_apart_by_label_and_noise_is_dropped(tmp_path, capsys):
    code = main(["import", str(FIELD / "pept-two-tracers-noise.csv"), "--format", "csv", "--width", "0.09", "--height", "0.95",
                 "-o", str(tmp_path / "p.h5"), "--vertical-axis", "y", "--drop-depth",
                 "--length-unit", "mm", "--time-unit", "ms", "--resample", "0.005",
                 "--max-gap", "0.01"])
    out = capsys.readouterr().err                 # the notes go to stderr, after the summary
    assert code == 0
    assert "particle ids from column 'label'" in out and "1 row with label -1" in out
    with Trajectories(tmp_path / "p.h5") as t:
        assert t.ids.tolist() == [0, 1]
        x = t.positions()[..., 0]
        present = t.present()
        rows = np.loadtxt(FIELD / "pept-two-tracers-noise.csv")
        for k in (0, 1):                 # each tracer follows its own rows: no zig-zag
            own = rows[rows[:, 5] == k]
            assert present[:, k].sum() > 5
            expected = np.interp(t.times[present[:, k]] * 1000, own[:, 0], own[:, 1]) / 1000
            np.testing.assert_allclose(x[present[:, k], k], expected, rtol=0, atol=1e-9)
        assert abs(x[present[:, 0], 0].mean() - x[present[:, 1], 1].mean()) > 0.02
        assert t.parameters["noise_rows_dropped"] == 1
    assert main(["info", str(tmp_path / "p.h5")]) == 0
    assert "import: 1 row with label -1" in capsys.readouterr().out


PEPT_OPTIONS = ["--format", "csv", "--width", "0.09", "--height", "0.95", "--vertical-axis",
                "y", "--drop-depth", "--length-unit", "mm", "--time-unit", "ms", "--resample",
                "0.005", "--max-gap", "0.01"]


@pytest.mark.parametrize("name", ["tracer", "track", "trackid", "trajectory"])
def test_pept_tracers_under_other_id_names_are_told_apart(tmp_path, capsys, name):
    """The pept file's label column renamed as other tools name a tracer's id: still two
    tracers (the noise row, label -1, is then tracer -1: the file says so)."""
    text = (FIELD / "pept-two-tracers-noise.csv").read_text()
    rows = [line for line in text.splitlines() if not line.startswith("#")
            and float(line.split()[5]) != -1]
    path = tmp_path / "t.csv"
    path.write_text(f"# t x y z error {name}\n" + "\n".join(rows) + "\n")
    assert main(["import", str(path), *PEPT_OPTIONS, "-o", str(tmp_path / "p.h5")]) == 0
    assert f"ids from column {name!r}" in capsys.readouterr().err
    with Trajectories(tmp_path / "p.h5") as t:
        assert t.ids.tolist() == [0, 1]


def test_a_file_read_as_one_tracer_names_the_columns_it_did_not_use(tmp_path, capsys):
    """Two tracers numbered in a column of no id name: read as one tracer, which jumps
    between them; the refusal names the column, whose values split the jumps away."""
    text = (FIELD / "pept-two-tracers-noise.csv").read_text()
    rows = [line for line in text.splitlines() if not line.startswith("#")
            and float(line.split()[5]) != -1]
    far = [" ".join(f[:2] + [str(float(f[2]) + (400 if float(f[5]) == 1 else 0))] + f[3:])
           for f in (r.split() for r in rows)]
    path = tmp_path / "t.csv"
    path.write_text("# t x y z error mark\n" + "\n".join(far) + "\n")
    assert main(["import", str(path), *PEPT_OPTIONS, "-o", str(tmp_path / "p.h5")]) == 2
    err = capsys.readouterr().err
    assert "column 'mark' seems to number the tracers (2 whole values): read as one " \
           "tracer, the samples jump" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "p.h5").exists()
    one = tmp_path / "one.csv"              # one tracer: imported, its unused columns named
    one.write_text("# t x y z error mark\n" + "\n".join(
        r for r, f in zip(far, rows) if float(f.split()[5]) == 0) + "\n")
    assert main(["import", str(one), *PEPT_OPTIONS, "-o", str(tmp_path / "o.h5")]) == 0
    assert "no id column, so the file is read as one tracer; not used: 'error', 'mark'" in \
        capsys.readouterr().err


def test_trackmate_spots_use_track_id(tmp_path, capsys):
    code = main(["import", str(FIELD / "trackmate-spots.csv"), "--format", "csv", "--width", "0.09", "--height", "0.95", "-o",
                 str(tmp_path / "s.h5"), "--vertical-axis", "y", "--drop-depth",
                 "--boundary", "open"])
    out = capsys.readouterr().err
    assert code == 0
    assert "particle ids from column 'TRACK_ID'; not from 'LABEL', 'ID'" in out
    assert "1 row with TRACK_ID -1 or empty" in out
    rows = [line.split(",") for line in
            (FIELD / "trackmate-spots.csv").read_text().splitlines()[4:]]
    rows = [r for r in rows if r[2]]
    with Trajectories(tmp_path / "s.h5") as t:
        assert t.ids.tolist() == [0, 1, 2] and t.n_frames == 20 and t.present().all()
        np.testing.assert_allclose(t.times, np.arange(20) * 0.005, atol=1e-12)
        pos = t.positions()
        assert t.parameters["units"]["x"] == "mm"                     # from the units row
        for r in rows:
            frame, track = int(r[8]), int(r[2])
            np.testing.assert_allclose(pos[frame, track], [float(r[4]) / 1000,
                                                           float(r[5]) / 1000], atol=1e-12)


def test_spots_without_tracks_are_refused_naming_the_columns(tmp_path, capsys):
    """A TrackMate export whose spots are in no track (TRACK_ID empty everywhere) and one
    without a TRACK_ID column (its text LABEL would be the id): each refused in one line
    naming the file's own column, nothing written."""
    lines = (FIELD / "trackmate-spots.csv").read_text().splitlines()
    rows = [line.split(",") for line in lines]
    untracked = [r if k < 4 else r[:2] + [""] + r[3:] for k, r in enumerate(rows)]
    no_track = [r[:2] + r[3:] for r in rows]
    # the next step a user takes: the text LABEL column dropped too, so that the spots' ID
    # (one per detection) is the only id left: each id in one frame, no particle followed
    spot_ids = [r[1:2] + r[3:] for r in rows]
    for name, table, match in (
            ("untracked.csv", untracked, r"all 61 data rows have an empty 'TRACK_ID'"),
            ("no-track.csv", no_track, r"'ID0' in column 'LABEL' \(read as 'id'\) is not a "
                                       r"number; the particle id must be a whole number"),
            ("spot-ids.csv", spot_ids, r"each of the 61 ids in column 'ID' occurs in one "
                                       r"frame only \(over 20 frames\).*TRACK_ID")):
        source = tmp_path / name
        source.write_text("\n".join(",".join(r) for r in table) + "\n")
        code = main(["import", str(source), "--width", "0.09", "--height", "0.95", "-o",
                     str(tmp_path / "s.h5"), "--vertical-axis", "y", "--drop-depth"])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1, err
        assert re.search(match, err), err
        assert not (tmp_path / "s.h5").exists()


def test_pept_points_all_noise_are_refused_as_such(tmp_path, capsys):
    rows = np.loadtxt(FIELD / "pept-two-tracers-noise.csv")
    rows[:, 5] = -1
    source = tmp_path / "noise.csv"
    np.savetxt(source, rows, header="t x y z error label")
    code = main(["import", str(source), "--width", "0.09", "--height", "0.95", "-o",
                 str(tmp_path / "p.h5"), "--vertical-axis", "y", "--drop-depth",
                 "--length-unit", "mm", "--time-unit", "ms", "--resample", "0.005"])
    err = capsys.readouterr().err
    assert code == 2 and f"all {rows.shape[0]} data rows have -1 (noise) in 'label'" in err
    assert not (tmp_path / "p.h5").exists()


def _spreadsheet_truth():
    k = np.arange(11)[:, None]
    return (np.arange(11) * 0.025,
            np.stack([np.broadcast_to([0.02, 0.04, 0.06], (11, 3)),
                      np.array([0.1, 0.35, 0.6]) + 0.025 * k], axis=-1))


@pytest.mark.parametrize("name, note", [("excel-unicode-text-utf16.txt", None),
                                        ("excel-tab-utf8-title.txt", "title line"),
                                        ("excel-csv-bom-ghost-row.csv", None)])
def test_spreadsheet_text_exports(tmp_path, capsys, name, note):
    code = main(["import", str(FIELD / name), "--format", "csv", "--width", "0.09", "--height", "0.95", "-o", str(tmp_path / "e.h5")])
    out, err = capsys.readouterr()
    assert code == 0 and out == f"{tmp_path / 'e.h5'}\n"
    assert (note in err) if note else err.count("\n") == 1
    times, positions = _spreadsheet_truth()
    with Trajectories(tmp_path / "e.h5") as t:
        assert t.ids.tolist() == [1, 2, 3]
        np.testing.assert_allclose(t.times, times, rtol=0, atol=1e-12)
        np.testing.assert_allclose(t.positions(), positions, rtol=0, atol=1e-12)


def test_cp1252_text_is_refused_naming_the_line_and_the_encoding(tmp_path, capsys):
    code = main(["import", str(FIELD / "excel-tab-cp1252-title.txt"), "--format", "csv", "--width", "0.09", "--height", "0.95", "-o",
                 str(tmp_path / "e.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "line 1: byte 0xb0 is not UTF-8" in err and "cp1252" in err and "'°'" in err
    assert not (tmp_path / "e.h5").exists()


def test_a_fit_without_transitions_is_an_error(tmp_path, capsys):
    """Every particle in one frame only (spot ids taken for particle ids): nothing to count."""
    rows = ["t,id,x,y"] + [f"{0.005 * f:.3f},{3 * f + i},{0.01 + 0.02 * i:.3f},{0.1 + 0.01 * f:.3f}"
                           for f in range(20) for i in range(3)]
    (tmp_path / "spots.csv").write_text("\n".join(rows) + "\n")
    # the import itself refuses such ids (each in one frame: detections, not particles)
    assert main(["import", str(tmp_path / "spots.csv"), "--format", "csv", "--width", "0.09",
                 "--height", "0.95", "-o", str(tmp_path / "s.h5")]) == 2
    assert "occurs in one frame only" in capsys.readouterr().err
    # a trajectory file written so in Python: fit finds no transition to count
    from cfbmarkov.trajectory_writer import write_trajectories

    n = 60
    present = np.zeros((20, n), dtype=bool)
    present[np.arange(n) // 3, np.arange(n)] = True
    positions = np.full((20, n, 2), 0.05)
    positions[..., 1] = 0.1 + 0.01 * np.arange(20)[:, None]
    write_trajectories(tmp_path / "s.h5", 0.005 * np.arange(20), positions, width=0.09,
                       height=0.95, present=present)
    code = main(["fit", str(tmp_path / "s.h5"), "--cells", "3x10", "--lag", "0.005",
                 "--window", "0:0.095", "-o", str(tmp_path / "m.h5")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no transitions to fit" in err
    assert not (tmp_path / "m.h5").exists()


def test_pept_rows_at_one_printed_time_are_merged(tmp_path, capsys):
    """Times printed at 0.01 ms: two locations of the tracer share t = 3.77 ms."""
    t = [1.00, 2.40, 3.77, 3.77, 5.10, 6.55, 8.00, 9.30, 10.70]
    y = [100.0, 110.0, 120.0, 122.0, 131.0, 140.0, 150.0, 160.0, 170.0]
    (tmp_path / "p.csv").write_text("# t x y z error\n" + "".join(
        f"{a:.2f} 45.0 {b:.1f} 0.5 1.0\n" for a, b in zip(t, y)))
    code = main(["import", str(tmp_path / "p.csv"), "--format", "csv", "--width", "0.09", "--height", "0.95", "-o",
                 str(tmp_path / "p.h5"), "--vertical-axis", "y", "--drop-depth",
                 "--length-unit", "mm", "--time-unit", "ms", "--resample", "0.001",
                 "--max-gap", "0.002"])
    out = capsys.readouterr().err
    assert code == 0 and "1 row at the same time" in out
    with Trajectories(tmp_path / "p.h5") as p:
        k = int(np.argmin(np.abs(p.times - 0.00377)))
        if abs(p.times[k] - 0.00377) < 1e-9:
            assert p.positions()[k, 0, 1] == pytest.approx(0.121)
        assert p.parameters["rows_merged"] == 1
        y_stored = p.positions()[p.present()[:, 0], 0, 1]
        assert np.all(np.diff(y_stored) > 0)               # the mean, not either row
