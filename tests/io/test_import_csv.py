"""CSV import: round trips, lap counters, compression, and every kind of bad input through the
Python API and through ``cfbmarkov import``."""

from __future__ import annotations

import gzip
import re

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.io import import_csv, import_file
from cfbmarkov.trajectories import Trajectories


def read_back(path):
    with Trajectories(path) as t:
        return (t.times, t.ids, t.positions(), t.velocities(), t.laps(), t.source, t.parameters,
                (t.width, t.height), t.frame_interval)


# -- round trips ----------------------------------------------------------------------------
@pytest.mark.parametrize("columns", [("t", "id", "x", "y", "vx", "vy"),
                                     ("vy", "x", "id", "vx", "t", "y")])
def test_round_trip_with_velocities(tmp_path, run, make_csv, save, columns):
    source = save(tmp_path / "run.csv", make_csv(run, columns))
    out = import_file(source, "csv", tmp_path / "run.h5", width=0.09, height=0.95)
    assert out == tmp_path / "run.h5"
    times, ids, pos, vel, laps, src, params, domain, interval = read_back(out)
    np.testing.assert_array_equal(ids, run.ids)
    np.testing.assert_array_equal(times, run.times)
    np.testing.assert_array_equal(pos, run.positions)
    np.testing.assert_array_equal(vel, run.velocities)
    np.testing.assert_array_equal(laps, run.laps)
    assert src == "import:csv"
    assert params["format"] == "csv" and params["source_file"] == "run.csv"
    assert params["columns"] == list(columns)
    assert domain == (0.09, 0.95)
    assert interval == pytest.approx(0.025)


def test_laps_of_a_particle_crossing_top_and_bottom(tmp_path, run, make_csv, save):
    out = import_csv(save(tmp_path / "run.csv", make_csv(run)), tmp_path / "run.h5", width=0.09, height=0.95)
    laps = read_back(out)[4][:, 0]
    steps = np.diff(laps)
    assert (steps == 1).sum() == 1 and (steps == -1).sum() == 2
    assert laps.max() == 1 and laps[-1] == -1
    crossing_up = int(np.argmax(steps == 1)) + 1
    assert run.positions[crossing_up, 0, 1] < run.positions[crossing_up - 1, 0, 1]


def test_round_trip_without_velocities_and_sorted_rows(tmp_path, run, make_csv, save):
    text = make_csv(run, ("t", "id", "x", "y"), shuffle=False)
    out = import_csv(save(tmp_path / "run.csv", text), tmp_path / "run.h5", width=0.09, height=0.95)
    times, ids, pos, vel, laps, *_ = read_back(out)
    np.testing.assert_array_equal(times, run.times)
    np.testing.assert_array_equal(ids, run.ids)
    assert vel is None
    np.testing.assert_array_equal(pos, run.positions)
    np.testing.assert_array_equal(laps, run.laps)


@pytest.mark.parametrize("name", ["run.csv.gz", "run.csv"])
def test_gzip_detected_by_magic_bytes(tmp_path, run, make_csv, save, name):
    source = save(tmp_path / name, make_csv(run), gz=True)
    out = import_csv(source, tmp_path / "run.h5", width=0.09, height=0.95)
    np.testing.assert_array_equal(read_back(out)[2], run.positions)


def test_domain_from_options(tmp_path, make_run, make_csv, save):
    run = make_run(width=0.2, height=2.0)
    out = import_file(save(tmp_path / "run.csv", make_csv(run)), "csv", tmp_path / "run.h5",
                      width=0.2, height=2.0)
    *_, domain, _ = read_back(out)
    assert domain == (0.2, 2.0)
    np.testing.assert_array_equal(read_back(out)[4], run.laps)


def test_windows_line_ends_spaces_and_comments(tmp_path):
    text = ("\ufeff# made by hand\r\n t , id , x , y \r\n0.0, 2, 0.01, 0.5\r\n0.0, 1, 0.02, 0.6\r\n"
            "\r\n0.1, 1, 0.03, 0.7\r\n0.1, 2, 0.04, 0.7\r\n")
    source = tmp_path / "hand.csv"
    source.write_bytes(text.encode())
    times, ids, pos, *_ = read_back(import_csv(source, tmp_path / "hand.h5", width=0.09, height=0.95))
    np.testing.assert_array_equal(ids, [1, 2])
    np.testing.assert_array_equal(times, [0.0, 0.1])
    np.testing.assert_array_equal(pos, [[[0.02, 0.6], [0.01, 0.5]], [[0.03, 0.7], [0.04, 0.7]]])


@pytest.mark.parametrize("order", ["frames-shuffled", "by-particle"])
def test_rows_in_any_order_are_sorted_by_time_then_id(tmp_path, make_run, make_csv, save,
                                                      monkeypatch, order):
    """Frames out of time order, or rows grouped by particle: read whole, sorted, stored right
    (also when the disorder first shows in a later read block)."""
    import cfbmarkov.io.csv_rows as csv_rows

    monkeypatch.setattr(csv_rows, "CHUNK_CHARS", 300)
    run = make_run(n_particles=5, n_frames=12)
    header, *rows = make_csv(run).splitlines()
    if order == "by-particle":
        rows.sort(key=lambda r: (int(r.split(",")[1]), float(r.split(",")[0])))
    else:
        frames = [rows[k:k + 5] for k in range(0, len(rows), 5)]
        rows = [r for k in (0, 1, 2, 3, 7, 4, 11, 5, 6, 8, 10, 9) for r in frames[k]]
    out = import_csv(save(tmp_path / "run.csv", "\n".join([header, *rows]) + "\n"),
                     tmp_path / "run.h5", width=0.09, height=0.95)
    times, ids, pos, vel, laps, _, params, *_ = read_back(out)
    np.testing.assert_array_equal(times, run.times)
    np.testing.assert_array_equal(ids, run.ids)
    np.testing.assert_array_equal(pos, run.positions)
    np.testing.assert_array_equal(vel, run.velocities)
    np.testing.assert_array_equal(laps, run.laps)
    assert params["row_order"].startswith("sorted by time and id")


def test_frames_spanning_read_blocks(tmp_path, make_run, make_csv, save, monkeypatch):
    import cfbmarkov.io.csv_rows as csv_rows

    monkeypatch.setattr(csv_rows, "CHUNK_CHARS", 300)  # a few rows per block
    run = make_run(n_particles=7, n_frames=9)
    out = import_csv(save(tmp_path / "run.csv", make_csv(run)), tmp_path / "run.h5", width=0.09, height=0.95)
    times, ids, pos, vel, laps, *_ = read_back(out)
    np.testing.assert_array_equal(times, run.times)
    np.testing.assert_array_equal(pos, run.positions)
    np.testing.assert_array_equal(vel, run.velocities)
    np.testing.assert_array_equal(ids, run.ids)
    np.testing.assert_array_equal(laps, run.laps)
    assert read_back(out)[6]["row_order"] == "as written"


def test_cli_import_prints_the_output(tmp_path, run, make_csv, save, cli):
    source = save(tmp_path / "run.csv", make_csv(run))
    code, out, err = cli("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "-o", tmp_path / "o" / "run.h5")
    assert code == 0, err
    assert out == f"{tmp_path / 'o' / 'run.h5'}\n"          # the path alone on stdout
    assert err == ("cfbmarkov import: read 16 frames of 6 particles as CSV (--format); "
                   "positions from x, y (m); ids from column 'id'; times in s; velocities "
                   "from vx, vy; periodic boundary; laps from minimal-image rule\n")
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["run.h5"]


# -- bad input ----------------------------------------------------------------------------------
HEADER = "t,id,x,y"
FRAMES = [[(0.0, 1, 0.01, 0.10), (0.0, 2, 0.02, 0.20), (0.0, 3, 0.03, 0.30)],
          [(0.025, 3, 0.03, 0.31), (0.025, 1, 0.01, 0.11), (0.025, 2, 0.02, 0.21)],
          [(0.05, 1, 0.01, 0.12), (0.05, 2, 0.02, 0.22), (0.05, 3, 0.03, 0.32)]]


def table(frames=FRAMES, header=HEADER) -> str:
    rows = (",".join(str(v) for v in row) for frame in frames for row in frame)
    return header + "\n" + "\n".join(rows) + "\n"


def changed(frame: int, row: int, **values) -> list:
    """FRAMES with some fields of one row replaced (t, id, x, y)."""
    frames = [list(f) for f in FRAMES]
    names = ("t", "id", "x", "y")
    old = dict(zip(names, frames[frame][row]))
    old.update(values)
    frames[frame][row] = tuple(old[n] for n in names)
    return frames


def with_unused_column(text: str, extra_at: int | None = None, delimiter: str = ",") -> str:
    """The table with a 'quality' column the reader leaves unused; the data row at index
    ``extra_at`` (or every row where None) carries one value more than the header names."""
    head, *rows = text.rstrip("\n").split("\n")
    rows = [r.replace(",", delimiter) + f"{delimiter}5"
            + (f"{delimiter}9" if extra_at in (None, k) else "") for k, r in enumerate(rows)]
    return "\n".join([head.replace(",", delimiter) + f"{delimiter}quality"] + rows) + "\n"


LONG = table([[(0.025 * k, i, 0.01 * i, 0.1 * i) for i in (1, 2, 3)] for k in range(400)])

BAD_CSV = {
    "missing-column": (table(header="t,id,x"), r"missing column 'y'"),
    "misnamed-column": (table(header="tijd,id,x,y"),
                        r"missing column 't' in the header 'tijd,id,x,y'; expected t, x, y"),
    "z-column-without-vertical-axis": (table(header="t,id,x,y,z"),
                                       r"has a z column.*--vertical-axis x\|y\|z.*a 2D export "
                                       r"whose z is all 0 \(TrackMate, PTV\): --vertical-axis "
                                       r"y --drop-depth$"),
    "duplicate-column": (table(header="t,id,x,y,x"), r"column 'x' appears twice"),
    "half-velocity": (table(header="t,id,x,y,vx"), r"only one of vx, vy"),
    "no-header": (table().split("\n", 1)[1], r"line 1 is not a header"),
    "non-numeric": (table(changed(1, 1, x="abc")), r"line 6: 'abc' in column 'x' is not a number"),
    "empty-value": (table(changed(1, 1, y="")), r"line 6: column 'y' is empty"),
    # a spreadsheet's missing value begins with the comment mark: named, not cut short
    "spreadsheet-na": (table(changed(1, 1, x="#N/A")),
                       r"line 6: '#N/A' in column 'x' is a spreadsheet's error or missing "
                       r"value, not a number"),
    "nan-position": (table(changed(1, 1, x="nan")),
                     (r"position of particle 1 at t = 0.025 s is not a finite number "
                      r"\(\[nan, [0-9.]+\]; a particle out of view is left out of its frame: "
                      r"drop the rows that hold such values\)")),
    "inf-position": (table(changed(2, 0, y="inf")),
                     r"position of particle 1 at t = 0.05 s is not a finite number \(\[[0-9.]+, inf\]"),
    "nan-time": (table(changed(1, 0, t="nan")), r"line 5: time t = nan is not a finite number"),
    "fractional-id": (table(changed(1, 0, id=2.5)), r"line 5: particle id 2.5 is not a whole"),
    "frame-repeated": (table([FRAMES[0], FRAMES[1], FRAMES[2], FRAMES[1]]),
                       (r"frame at t = 0.025 s: particle id 1 appears more than once \(two rows "
                        r"for one particle at one time\)")),
    "uneven-frames": (table(FRAMES[:2] + [[(0.06,) + r[1:] for r in FRAMES[2]]]),
                      r"frames unevenly spaced: 0.035 s between t = 0.025 and 0.06 s"),
    "duplicate-id": (table(changed(1, 0, id=2)), r"particle id 2 appears more than once \(two "
                     r"rows for one particle at one time\): remove one of them"),
    "duplicate-id-first-frame": (table(changed(0, 2, id=2)), r"id 2 appears more than once"),
    "outside-height": (table(changed(2, 2, y=-0.01)), r"particle 3 at t = 0.05 s lies outside"),
    # laps from wrapped heights: a step beyond a quarter of the height is refused, as a
    # dump's is (the minimal image would count a wrong pass silently up to a half); a CSV
    # has no unwrapped coordinates or image flags to name as the fix
    "step-too-large": (table(changed(2, 1, y=0.51)),
                       r"particle 2 moved 0.3 m \(more than 0.25 of the height 0.95 m\) "
                       r"between t = 0.025 and 0.05 s: the lap counter cannot be inferred "
                       r"from wrapped positions; write frames more often$"),
    "empty-file": ("", r"empty file \(0 bytes\): nothing to import; check the path"),
    "blank-file": ("\n \n", r"empty file \(no header line\): nothing to import"),
    "header-only": (HEADER + "\n", r"no data rows after the header: nothing to import"),
    "truncated-mid-row": (table()[:-9], (r"line 10: 3 values, the header names 4 columns "
                                         r"\(the file ends inside this row: truncated\?\)")),
    # np.loadtxt reads a longer row's first columns where one column is unused: refused
    "row-index-without-name": (with_unused_column(table()),
                               r"line 2: 6 values, the header names 5 columns in every row, so "
                               r"each value would be read from the wrong column; .*give it a "
                               r"name\)$"),
    # a text value holding the delimiter before a used column shifts that column
    "unquoted-delimiter-in-text": (
        "t,note,id,x,y\n" + "".join(
            ",".join([str(row[0]), "a, b" if (k, j) == (1, 0) else "ok"]
                     + [str(v) for v in row[1:]]) + "\n"
            for k, frame in enumerate(FRAMES) for j, row in enumerate(frame)),
        r"line 5: 6 values, the header names 5 columns: a value holds the delimiter ',' "
        r"unquoted"),
    "whitespace-row-index": (with_unused_column(table(), delimiter=" "),
                             r"line 2: 6 values, the header names 5 columns"),
    "binary-file": (b"\x89HDF\r\n\x1a\n\x00\x00\xff\xfe", r"not a text file"),
    "truncated-gzip": (gzip.compress(LONG.encode())[: len(gzip.compress(LONG.encode())) // 2],
                       r"file is truncated \(the compressed stream ends early\)"),
}


def write_case(tmp_path, content):
    source = tmp_path / "bad.csv"
    if isinstance(content, bytes):
        source.write_bytes(content)
    else:
        source.write_text(content)
    return source


@pytest.mark.parametrize("case", sorted(BAD_CSV))
def test_bad_csv_raises_input_error(tmp_path, case):
    content, match = BAD_CSV[case]
    source = write_case(tmp_path, content)
    output = tmp_path / "out" / "run.h5"
    with pytest.raises(InputError, match=match):
        import_csv(source, output, width=0.09, height=0.95)
    assert not output.exists() and not output.parent.exists()


@pytest.mark.parametrize("case", sorted(BAD_CSV))
def test_bad_csv_through_cli(tmp_path, assert_clean_failure, case):
    content, match = BAD_CSV[case]
    source = write_case(tmp_path, content)
    output = tmp_path / "out" / "run.h5"
    line = assert_clean_failure("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                                "-o", output, output=output,
                                match=match)
    assert line.startswith("cfbmarkov import: error: ")


def test_a_longer_row_whose_used_columns_come_first_is_read(tmp_path):
    """A free-text last column with an unquoted comma in one row: the used columns before
    it are read right, so the row is read (quoted, a value holding delimiters or spaces is
    one value)."""
    plain = import_csv(write_case(tmp_path, table()), tmp_path / "plain.h5", width=0.09,
                       height=0.95)
    head, *rows = table().rstrip("\n").split("\n")
    notes = [r + (",bad frame, see log" if k == 3 else ",ok") for k, r in enumerate(rows)]
    (tmp_path / "notes.csv").write_text("\n".join([head + ",note"] + notes) + "\n")
    spaced = [" ".join(r.split(",")) + (' "track 1"' if k % 2 else " ok")
              for k, r in enumerate(rows)]
    (tmp_path / "spaced.txt").write_text("\n".join([" ".join(head.split(",")) + " note"]
                                                    + spaced) + "\n")
    for name in ("notes.csv", "spaced.txt"):
        out = import_csv(tmp_path / name, tmp_path / f"{name}.h5", width=0.09, height=0.95)
        for a, b in zip(read_back(plain)[:5], read_back(out)[:5]):
            np.testing.assert_array_equal(a, b)


def test_empty_cells_after_the_named_columns_are_read_as_a_spreadsheets_ghost_cells(tmp_path):
    plain = import_csv(write_case(tmp_path, table()), tmp_path / "plain.h5", width=0.09,
                       height=0.95)
    head, *rows = table().rstrip("\n").split("\n")
    ghost = "\n".join([head + ",quality"] + [r + ",5,," for r in rows]) + "\n"
    (tmp_path / "ghost.csv").write_text(ghost)
    out = import_csv(tmp_path / "ghost.csv", tmp_path / "ghost.h5", width=0.09, height=0.95)
    for a, b in zip(read_back(plain)[:5], read_back(out)[:5]):
        np.testing.assert_array_equal(a, b)


def test_missing_input_file(tmp_path, assert_clean_failure):
    output = tmp_path / "out" / "run.h5"
    with pytest.raises(InputError, match=r"nowhere.csv: no such file"):
        import_file(tmp_path / "nowhere.csv", "csv", output, width=0.09, height=0.95)
    assert_clean_failure("import", tmp_path / "nowhere.csv", "--format", "csv",
                         "--width", "0.09", "--height", "0.95",
                         "-o", output,
                         output=output, match=r"no such file")


def test_options_that_do_not_apply(tmp_path, run, make_csv, save):
    source = save(tmp_path / "run.csv", make_csv(run))
    with pytest.raises(InputError, match=r"--time-step dates the steps of LAMMPS dumps, H5MD "
                                         r"and VTK series; a CSV file gives its times in"):
        import_file(source, "csv", tmp_path / "run.h5", time_step=1e-5, width=0.09, height=0.95)
    with pytest.raises(InputError, match=r"unknown import format 'xyz'"):
        import_file(source, "xyz", tmp_path / "run.h5")
    with pytest.raises(InputError, match=r"the content is text .*not vtk; .*--format csv"):
        import_file(source, "vtk", tmp_path / "run.h5")
    with pytest.raises(InputError, match=r"width -1 must be a positive number"):
        import_file(source, "csv", tmp_path / "run.h5", width=-1)
    with pytest.raises(InputError, match=r"is a folder"):
        import_file(source, "csv", tmp_path, width=0.09, height=0.95)
    with pytest.raises(InputError, match=r"would overwrite the input"):
        import_file(source, "csv", source, width=0.09, height=0.95)
    with pytest.raises(InputError, match=r"cannot write"):
        import_file(source, "csv", source / "run.h5", width=0.09, height=0.95)
    assert not (tmp_path / "run.h5").exists()


def test_domain_too_small_for_the_data(tmp_path, run, make_csv, save, assert_clean_failure):
    source = save(tmp_path / "run.csv", make_csv(run))
    output = tmp_path / "out" / "run.h5"
    assert_clean_failure("import", source, "--format", "csv", "--width", "0.09",
                         "-o", output, "--height", "0.5",
                         output=output, match=r"lies outside the domain 0..0.09 x 0..0.5 m.*"
                         r"a periodic riser holds every particle, so its vertical range must "
                         r"cover every height: give a taller --height")


def test_failed_import_keeps_an_existing_output(tmp_path, run, make_csv, save):
    output = tmp_path / "run.h5"
    import_csv(save(tmp_path / "good.csv", make_csv(run)), output, width=0.09, height=0.95)
    before = output.read_bytes()
    with pytest.raises(InputError):
        import_csv(write_case(tmp_path, BAD_CSV["duplicate-id"][0]), output, width=0.09, height=0.95)
    assert output.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv", "good.csv", "run.h5"]


def test_progress_bar_only_on_a_terminal(tmp_path, run, make_csv, save, capsys, monkeypatch):
    import sys

    source = save(tmp_path / "run.csv", make_csv(run))
    import_csv(source, tmp_path / "a.h5", width=0.09, height=0.95)
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    import_csv(source, tmp_path / "b.h5", width=0.09, height=0.95)
               # short: the bar waits a second before it shows
    assert capsys.readouterr().err == ""
    np.testing.assert_array_equal(read_back(tmp_path / "b.h5")[2], run.positions)


# -- the riser's size ------------------------------------------------------------------------
def test_a_csv_without_the_risers_size_is_refused_naming_the_datas_extent(tmp_path, make_run,
                                                                          make_csv, save, cli):
    """A CSV file does not give the riser's size: without --width/--height (or --region) the
    import is refused (exit 2, one line naming the data's extent and the options), not read
    as the paper's 0.09 x 0.95 m riser; with them it imports in the given riser."""
    run = make_run(width=0.04, height=0.3)
    source = save(tmp_path / "small.csv", make_csv(run))
    output = tmp_path / "small.h5"
    code, out, err = cli("import", source, "--format", "csv", "-o", output)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "--width" in err and "--height" in err and "--region" in err
    lo, hi = run.positions[..., 1].min(), run.positions[..., 1].max()
    assert f"y {lo:.4g}..{hi:.4g} m" in err
    assert not output.exists()
    with pytest.raises(InputError, match="riser's size"):
        import_csv(source, output, width=0.04)
    code, out, err = cli("import", source, "--format", "csv", "-o", output, "--width", "0.04",
                         "--height", "0.3")
    assert code == 0, err
    with Trajectories(output) as t:
        assert (t.width, t.height) == (0.04, 0.3)
        np.testing.assert_array_equal(t.laps(), run.laps)


def test_a_dump_given_as_csv_and_an_expanded_pattern_name_the_fix(tmp_path, capsys):
    """A LAMMPS dump given --format csv is named as a dump (not a CSV file missing column
    t); several dump files, the shell's expansion of an unquoted pattern in name order, are
    read in the order of their timesteps; several CSV files are refused naming why."""
    from cfbmarkov.cli import main

    dump = tmp_path / "run.dump"
    dump.write_text("ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS pp pp pp\n"
                    "0 0.09\n0 0.95\n0 0.001\nITEM: ATOMS id x y z\n1 0.01 0.2 0.0005\n")
    with pytest.raises(InputError, match=r"the content is a LAMMPS/LIGGGHTS dump .*not csv; "
                                         r"import it with --format lammps"):
        import_file(dump, "csv", tmp_path / "a.h5", width=0.09, height=0.95)
    table = tmp_path / "run.csv"       # and a CSV file given --format lammps: named as CSV
    table.write_text("t,id,x,y\n0,1,0.01,0.2\n0.01,1,0.01,0.21\n")
    with pytest.raises(InputError, match=r"\(read as CSV\), not lammps; import it with "
                                         r"--format csv"):
        import_file(table, "lammps", tmp_path / "b.h5", width=0.09, height=0.95)
    assert not (tmp_path / "b.h5").exists()
    steps = [tmp_path / f"dump{k}.liggghts" for k in (0, 2000, 4000)]
    for k, path in zip((0, 2000, 4000), steps):
        path.write_text(dump.read_text().replace("TIMESTEP\n0\n", f"TIMESTEP\n{k}\n")
                        .replace("0.2 0.0005", f"{0.2 + k * 1e-5} 0.0005"))
    by_name = sorted(map(str, steps))              # dump0, dump2000, dump4000 as the shell
    assert main(["import", *by_name[::-1], "--time-step", "1e-5", "-o",
                 str(tmp_path / "b.h5")]) == 0
    with Trajectories(tmp_path / "b.h5") as run:
        np.testing.assert_allclose(run.times, [0.0, 0.02, 0.04])
        np.testing.assert_allclose(run.positions()[:, 0, 1], [0.2, 0.22, 0.24])
    capsys.readouterr()
    tables = [tmp_path / f"t{k}.csv" for k in range(2)]
    for path in tables:
        path.write_text("t,x,y\n0,0.01,0.2\n0.01,0.01,0.21\n")
    assert main(["import", *map(str, tables), "--width", "0.09", "--height", "0.95", "-o",
                 str(tmp_path / "c.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "2 CSV files given" in err and "one CSV file at a time" in err
    assert not (tmp_path / "a.h5").exists() and not (tmp_path / "c.h5").exists()


def test_sizes_that_suggest_a_unit_mistake_warn(tmp_path, capsys):
    """Metre positions read as mm (a sliver of the riser), a riser given in mm (950 m high),
    times in s read as ms (frames 2 microseconds apart, particles at 25 km/s) and times in
    ms read as s (a 0.5 m/s flow moving at 5 mm/s) each import with `warning:` lines naming
    the option (the 950 m riser a second, on its particles' sliver of it); the same file in
    its right units, and a flow of 2.5 cm/s (above the 2 cm/s limit), warn of nothing."""
    from cfbmarkov.cli import main

    rows = ["t,id,x,y"] + [f"{0.002 * k:.3f},{i},{0.01 + 0.02 * i:.4f},{0.2 + 0.05 * k + 0.1 * i:.4f}"
                           for k in range(10) for i in range(3)]
    source = tmp_path / "run.csv"
    source.write_text("\n".join(rows) + "\n")
    slow = tmp_path / "ms.csv"          # the same flow with its times written in ms
    slow.write_text("\n".join(["t,id,x,y"] + [
        f"{2 * k},{i},{0.01 + 0.02 * i:.4f},{0.2 + 0.05 * k + 0.1 * i:.4f}"
        for k in range(10) for i in range(3)]) + "\n")
    cases = {(): (None, 0),
             ("--length-unit", "mm"): ("the particles' heights span 0.00065 m of the riser's "
                                       "0.95 m", 1),
             # the 950 m riser: its particles' span is a sliver of it too
             ("--width", "90", "--height", "950"): ("the riser is 950 m high and 90 m wide", 2),
             ("--time-unit", "ms"): ("frames 2e-06 s apart", 2),
             ("slow",): ("the particles move at a median 0.025 m/s", 0)}
    for k, (options, (expected, count)) in enumerate(cases.items()):
        size = [] if "--width" in options else ["--width", "0.09", "--height", "0.95"]
        given = [str(slow)] if options == ("slow",) else [str(source), *options]
        assert main(["import", *given, *size, "-o", str(tmp_path / f"{k}.h5")]) == 0
        warnings = [line for line in capsys.readouterr().err.splitlines()
                    if line.startswith("warning:")]
        if expected is None:
            assert warnings == []
        elif options == ("slow",):      # 2.5 cm/s: above the limit of 2 cm/s, no warning
            assert warnings == []
        else:
            assert expected in "\n".join(warnings) and len(warnings) == count, warnings
        if "--width" in options:         # the sizes typed in mm: the fix in metres
            assert "given in mm? --width 0.09 --height 0.95 (m)" in warnings[0]
        if options == ("--length-unit", "mm"):       # or a depth read as the heights
            assert ("or the heights come from another axis than the vertical one (3D "
                    "positions: --vertical-axis names the vertical)") in warnings[0]
    assert "the particles move at a median 2.5e+04 m/s" in "\n".join(
        [line for line in _import_err(main, capsys, source, tmp_path, "--time-unit", "ms")])
    slower = tmp_path / "slower.csv"    # a 0.5 m/s flow written in ms: 5 mm/s read as s
    slower.write_text("\n".join(["t,id,x,y"] + [
        f"{2 * k},{i},{0.01 + 0.02 * i:.4f},{0.2 + 0.001 * k + 0.1 * i:.4f}"
        for k in range(10) for i in range(3)]) + "\n")
    assert any("the particles move at a median 0.0005 m/s between frames: times in "
               "milliseconds read as seconds" in line
               for line in _import_err(main, capsys, slower, tmp_path))


def _import_err(main, capsys, source, tmp_path, *options):
    assert main(["import", str(source), "--width", "0.09", "--height", "0.95", *options,
                 "-o", str(tmp_path / "again.h5"), "--force"]) == 0
    return capsys.readouterr().err.splitlines()


def test_info_names_origin_and_region_by_the_sources_axes(tmp_path, capsys):
    """A 3D CSV file with z vertical: info gives the origin and the region in the source's
    x, y, z (not the stored across, vertical, depth order), so that the region it prints
    imports the file again."""
    from cfbmarkov.cli import main

    rows = ["t,id,x,y,z"] + [f"{0.01 * k:.2f},{i},{-0.03 + 0.02 * i:.3f},0.001,{0.2 + 0.01 * k:.3f}"
                             for k in range(5) for i in range(3)]
    source = tmp_path / "run.csv"
    source.write_text("\n".join(rows) + "\n")
    region = "-0.045:0.045,0:0.003,0.1:1.05"
    out = tmp_path / "a.h5"
    assert main(["import", str(source), "--vertical-axis", "z", "--region", region, "-o",
                 str(out)]) == 0
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert ("origin at x = -0.045, y = 0, z = 0.1 m in the source's coordinates; riser region "
            "x -0.045:0.045, y 0:0.003, z 0.1:1.05 m") in text
    printed = text.split("riser region ")[1].split(" m\n")[0]
    again = ",".join(part.split(" ")[1] for part in printed.split(", "))
    assert again == region


def test_a_height_beyond_a_periodic_risers_region_names_the_vertical_range(tmp_path):
    """A 3D file whose heights run past --region's vertical range on a periodic riser:
    refused naming the domain with its depth, and the fix (a taller vertical range, or an
    open riser), not --region to keep particles out, which a periodic riser cannot do."""
    rows = ["t,id,x,y,z"] + [f"{0.01 * k:.2f},{i},{0.02 + 0.02 * i:.3f},0.001,{0.2 + 0.2 * k:.3f}"
                             for k in range(5) for i in range(3)]
    source = tmp_path / "run.csv"
    source.write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError) as refused:
        import_file(source, "csv", tmp_path / "a.h5", vertical_axis="z",
                    region=[(0.0, 0.09), (0.0, 0.003), (0.0, 0.9)])
    message = str(refused.value)
    assert "lies outside the domain 0..0.09 x 0..0.9 x 0..0.003 m: 'z' = 1 m" in message
    assert "its vertical range must cover every height" in message
    assert "--boundary open" in message and "to keep only the particles" not in message
    assert not (tmp_path / "a.h5").exists()


def test_a_depth_range_for_2d_positions_is_refused(tmp_path):
    """--region with a z range on a file of x, y positions: the range was left unused with
    no word (as --drop-depth on such a file is refused); two ranges import it."""
    source = tmp_path / "run.csv"
    source.write_text("t,id,x,y\n0,1,0.01,0.2\n0.01,1,0.01,0.21\n")
    with pytest.raises(InputError, match=r"--region gives a z range, but the file's positions "
                                         r"are 2D \(x across, y vertical\)"):
        import_file(source, "csv", tmp_path / "a.h5",
                    region=[(0.0, 0.09), (0.0, 0.95), (0.0, 1.0)])
    assert not (tmp_path / "a.h5").exists()
    import_file(source, "csv", tmp_path / "b.h5", region=[(0.0, 0.09), (0.0, 0.95)])


def test_a_missing_option_and_a_folder_of_dumps_name_the_fix(tmp_path):
    """--width alone: the message asks for --height and says --width is given; a folder of
    dumps given as the source: the quoted pattern of its dumps, whatever --format."""
    source = tmp_path / "run.csv"
    source.write_text("t,id,x,y\n0,1,0.01,0.2\n0.01,1,0.01,0.21\n")
    with pytest.raises(InputError, match=r"give --height H \(--width is given\)"):
        import_file(source, "csv", tmp_path / "a.h5", width=0.09)
    folder = tmp_path / "post"
    folder.mkdir()
    for step in (0, 500, 1000):
        (folder / f"dump{step}.liggghts").write_text(
            "ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS pp pp pp\n"
            "0 0.09\n0 0.95\n0 0.001\nITEM: ATOMS id x y z\n1 0.01 0.2 0.0005\n")
    for fmt in ("auto", "lammps", "csv"):
        with pytest.raises(InputError, match=r"it holds 3 LAMMPS/LIGGGHTS dump\(s\): import them "
                                             rf"with the quoted pattern '{folder}/dump\*\.liggghts'"):
            import_file(folder, fmt, tmp_path / "b.h5", time_step=1e-5 if fmt != "csv" else None)
    assert not (tmp_path / "a.h5").exists() and not (tmp_path / "b.h5").exists()


def test_rows_outside_the_riser_are_counted_in_the_import_notes(tmp_path, capsys):
    """Positions measured from the riser's centre (x from -0.03) with --width 0.09: the rows
    left of x = 0 are absent, and the import says how many of how many."""
    from cfbmarkov.cli import main

    rows = ["t,id,x,y"] + [f"{0.01 * k:.2f},{i},{-0.03 + 0.02 * i:.3f},0.3"
                           for k in range(4) for i in range(4)]
    source = tmp_path / "centred.csv"
    source.write_text("\n".join(rows) + "\n")
    assert main(["import", str(source), "--width", "0.09", "--height", "0.95", "-o",
                 str(tmp_path / "a.h5")]) == 0
    err = capsys.readouterr().err
    assert "  8 of 16 rows (50 %) lie outside the riser's region and are absent there" in err
    inside = ["t,id,x,y"] + [f"{0.01 * k:.2f},{i},{0.01 + 0.02 * i:.3f},0.3"
                             for k in range(4) for i in range(4)]
    source.write_text("\n".join(inside) + "\n")
    assert main(["import", str(source), "--width", "0.09", "--height", "0.95", "-o",
                 str(tmp_path / "b.h5")]) == 0
    assert "outside the riser's region" not in capsys.readouterr().err


def test_a_stray_row_with_a_wrong_time_is_told_apart_from_a_gap(tmp_path, cli):
    """A row appended with t = -1 makes a first frame of its own 1 s before the others
    (0.025 s apart): the refusal says that two steps cannot tell which is wrong, not only
    that the good frames are "unevenly spaced"."""
    rows = ["id,t,x,y"] + [f"{i},{0.025 * k:.3f},0.02,{0.1 + 0.01 * k:.2f}"
                           for k in range(6) for i in range(3)] + ["0,-1,0.01,0.01"]
    (tmp_path / "stray.csv").write_text("\n".join(rows) + "\n")
    code, _, err = cli("import", tmp_path / "stray.csv", "--width", "0.09", "--height", "0.95",
                       "-o", tmp_path / "out" / "s.h5")
    assert code == 2 and err.count("\n") == 1
    assert "a row with a wrong time makes a first frame of its own" in err


@pytest.mark.parametrize("unit", ["um", "µm", "μm", "micron", "Microns"])
def test_micrometre_columns_in_any_spelling_are_read(tmp_path, unit):
    """TrackMate writes "(micron)", others µm (the micro sign or the Greek mu) or um: all
    are micrometres, converted to m, recorded as um."""
    source = tmp_path / "um.csv"
    source.write_text(f"t (sec),id,x ({unit}),y ({unit})\n0,1,20000,100000\n0,2,40000,350000\n"
                      "0.01,1,20000,110000\n0.01,2,40000,360000\n", encoding="utf-8")
    output = import_csv(source, tmp_path / "um.h5", width=0.09, height=0.95)
    with Trajectories(output) as t:
        np.testing.assert_allclose(t.positions()[1], [[0.02, 0.11], [0.04, 0.36]], rtol=1e-12)
        assert t.parameters["units"]["x"] == "um"


@pytest.mark.parametrize("header, fix", [
    ("t,id,x (pixel),y (pixel)", "convert it with the pixel size (m per pixel) to one of m, "
                                 "cm, mm, um and name that unit in the header"),
    ("t (frame),id,x,y", "convert it with the frame rate (frames per second) to one of s, ms "
                         "and name that unit in the header"),
    ("t,id,x (in),y (in)", "unit 'in' is not known; convert the column to one of m, cm, mm, "
                           "um and name that unit in the header (--length-unit sets the unit "
                           "of columns that name none)")])
def test_a_unit_with_no_scale_or_unknown_names_the_conversion_not_the_option(
        tmp_path, assert_clean_failure, header, fix):
    """A column counted in pixels or frames, or in a unit not read: one line naming the
    conversion to make in the file; --length-unit, which cannot override a header's unit,
    is not offered as the fix."""
    source = tmp_path / "px.csv"
    source.write_text(header + "\n0,1,2,3\n1,1,2,4\n")
    output = tmp_path / "out" / "px.h5"
    line = assert_clean_failure("import", source, "--width", "0.09", "--height", "0.95",
                                "--length-unit", "mm", "-o", output, output=output,
                                match=re.escape(fix))
    assert line.startswith("cfbmarkov import: error: ")


def test_vertical_bar_delimiter_and_columns_in_their_own_units(tmp_path, cli):
    """A '|'-separated file is read like a ';'-separated one; where the position columns
    name different units, the summary gives each column its own, in the columns' order."""
    source = tmp_path / "bar.csv"
    source.write_text("t (s)|id|x (mm)|y (m)\n0|1|20|0.1\n0|2|40|0.35\n0.01|1|20|0.11\n"
                      "0.01|2|40|0.36\n")
    code, out, err = cli("import", source, "--width", "0.09", "--height", "0.95", "-o",
                         tmp_path / "bar.h5")
    assert code == 0, err
    assert "positions from x (mm), y (m); ids from column 'id'" in err
    with Trajectories(tmp_path / "bar.h5") as t:
        np.testing.assert_allclose(t.positions()[1], [[0.02, 0.11], [0.04, 0.36]], rtol=1e-12)
        assert t.parameters["delimiter"] == "vertical bar"


@pytest.mark.parametrize("content, fault", [
    (b"", "empty file (0 bytes)"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "not a text file (it holds binary data"),
    (b"caf\xe9,id\n", "line 1: byte 0xe9 is not UTF-8 text")])
def test_time_step_given_for_a_file_told_csv_by_elimination_names_the_files_fault(
        tmp_path, assert_clean_failure, content, fault):
    """An empty or binary file is told to be CSV only because it is nothing else: with
    --time-step, its own fault is named, not that a CSV file takes no time step."""
    source = tmp_path / "in.dump"
    source.write_bytes(content)
    output = tmp_path / "out" / "x.h5"
    line = assert_clean_failure("import", source, "--time-step", "1e-5", "-o", output,
                                output=output)
    assert fault in line and "--time-step" not in line, line
    if "UTF-8 text" in fault:       # a dump is not a spreadsheet: no Excel advice for it
        assert "Excel" not in line and "iconv -f cp1252 -t utf-8" in line, line


def test_a_file_of_one_frame_is_said_in_the_singular(tmp_path):
    source = tmp_path / "one.csv"
    source.write_text("t,id,x,y\n0,1,0.02,0.1\n0,2,0.03,0.2\n")
    with Trajectories(import_csv(source, tmp_path / "one.h5", width=0.09, height=0.95)) as t:
        assert ": 2 particles x 1 frame, 0..0 s, source='import:csv')" in repr(t)


def test_a_unit_written_apart_from_its_name_in_a_whitespace_header_stays_with_it(tmp_path,
                                                                                   cli):
    """``x (m)`` under whitespace made "(m)" a column of its own and shifted every column
    after it by one: y was read from a later column, with exit 0."""
    rows = [(0.025 * k, i, 0.02 * i, 0.1 + 0.01 * k, 0.0005, 0.3) for k in range(4)
            for i in (1, 2)]
    source = tmp_path / "ws.csv"
    source.write_text("t id x (m) y [ m ] q r s\n"
                      + "".join("%g %g %g %g %g %g\n" % r for r in rows))
    code, out, err = cli("import", source, "--width", "0.09", "--height", "0.95", "-o",
                         tmp_path / "ws.h5")
    assert code == 0, err
    assert "positions from x, y (m)" in err
    with Trajectories(tmp_path / "ws.h5") as t:
        np.testing.assert_allclose(t.positions()[:, 0, 1], [0.1, 0.11, 0.12, 0.13])
        np.testing.assert_allclose(t.positions()[:, 1, 0], 0.04)


def test_two_far_apart_rows_of_one_tracer_at_one_time_are_refused_not_averaged(tmp_path):
    """With --resample, rows of one tracer sharing a time stamp are one sample printed
    twice and are averaged; two rows 0.3 m apart are not, and were averaged into a height
    0.15 m off the track."""
    lines = ["t x y"] + [f"{0.002 * k:.4f} 0.045 {0.1 + 0.005 * k:.4f}" for k in range(40)]
    near = lines[:11] + ["0.0200 0.0451 0.1501"] + lines[11:]
    far = lines[:11] + ["0.0200 0.045 0.4500"] + lines[11:]
    for name, text in (("near.csv", near), ("far.csv", far)):
        (tmp_path / name).write_text("\n".join(text) + "\n")
    out = import_csv(tmp_path / "near.csv", tmp_path / "near.h5", width=0.09, height=0.95,
                     resample=0.004)
    with Trajectories(out) as t:
        assert abs(t.positions()[5, 0, 1] - 0.15005) < 1e-9     # the two rows' mean
    with pytest.raises(InputError, match=r"two rows of particle 0 at t = 0\.02 s lie 0\.3 m "
                                         "apart .* not one sample of one track"):
        import_csv(tmp_path / "far.csv", tmp_path / "far.h5", width=0.09, height=0.95,
                   resample=0.004)
    assert not (tmp_path / "far.h5").exists()
    # a tracer at 5 m/s located every 0.5 ms, its times printed to 1 ms: rows of one stamp
    # lie up to 5 mm apart (more than 5 % of the width), a step of its own track: merged
    t = np.arange(0, 0.15, 0.0005)
    rows = [f"{a:.3f} {0.045 + 0.0005 * np.sin(k):.5f} {0.05 + 5.0 * a:.5f}"
            for k, a in enumerate(t)]
    (tmp_path / "fast.csv").write_text("t x y\n" + "\n".join(rows) + "\n")
    import_csv(tmp_path / "fast.csv", tmp_path / "fast.h5", width=0.09, height=0.95,
               resample=0.002)


@pytest.mark.parametrize("fmt", [None, "csv", "lammps"])
@pytest.mark.parametrize("content, match", [
    ('<?xml version="1.0" encoding="UTF-8"?>\n<TrackMate version="7.0">\n<Model>\n',
     r"TrackMate XML tracks: not read; export the tracks as CSV"),
    ('TITLE = "particles"\nVARIABLES = "X" "Y"\nZONE T="t0"\n0.1 0.2\n',
     r"Tecplot ASCII \(TITLE/VARIABLES/ZONE lines\): not read"),
    ("# a riser\nunits si\natom_style sphere\ndimension 2\nboundary f p p\n"
     "dump d1 all custom 100 post/Riser_Run3.dump id x y\nrun 1000\n",
     r"LAMMPS commands \(units, atom_style, dimension, boundary\): an input script or its "
     r"log, not a dump: import the file its dump command writes \(here: "
     r"post/Riser_Run3\.dump\)")])
def test_a_text_format_no_reader_reads_is_named_whatever_format_is_given(
        tmp_path, assert_clean_failure, fmt, content, match):
    source = tmp_path / "tracks.txt"
    source.write_text(content)
    output = tmp_path / "out" / "run.h5"
    line = assert_clean_failure("import", source, *(["--format", fmt] if fmt else []),
                                "--width", "0.09", "--height", "0.95", "-o", output,
                                output=output, match=match)
    assert "missing column" not in line and "ITEM" not in line


@pytest.mark.parametrize("fmt", [None, "csv"])
def test_a_csv_whose_first_column_is_named_zone_or_title_is_read(tmp_path, fmt):
    """Tecplot's ZONE and TITLE lines take '='; a table's column named so is no Tecplot
    file, and is read as the CSV it is."""
    for name in ("zone", "title"):
        source = tmp_path / f"{name}.csv"
        source.write_text(f"{name},t,id,x,y\n1,0.0,1,0.01,0.1\n1,0.025,1,0.01,0.12\n"
                          "1,0.05,1,0.01,0.14\n")
        out = import_file(source, fmt, tmp_path / f"{name}.h5", width=0.09, height=0.95)
        np.testing.assert_allclose(read_back(out)[2][:, 0, 1], [0.1, 0.12, 0.14])


def test_a_lone_longer_row_after_the_first_rows_and_ghost_cells_before_a_bad_value(tmp_path):
    """The rows a file begins with decide whether a column has no name: a longer row read
    in a later block alone (the sixth, after the five read ahead) is not taken for an
    unnamed index; and a bad value after rows of ghost cells is named where it is."""
    head, *rows = table().rstrip("\n").split("\n")
    notes = [r + (",bad frame, see log" if k == 5 else ",ok") for k, r in enumerate(rows)]
    (tmp_path / "late.csv").write_text("\n".join([head + ",note"] + notes) + "\n")
    out = import_csv(tmp_path / "late.csv", tmp_path / "late.h5", width=0.09, height=0.95)
    np.testing.assert_array_equal(read_back(out)[2], read_back(import_csv(
        write_case(tmp_path, table()), tmp_path / "plain.h5", width=0.09, height=0.95))[2])
    ghost = ["t,note,id,x,y"] + [f"{r.split(',')[0]},ok,{','.join(r.split(',')[1:])},"
                                 for r in rows]
    ghost[8] = ghost[8].replace(",0.02,", ",abc,")
    (tmp_path / "ghost.csv").write_text("\n".join(ghost) + "\n")
    with pytest.raises(InputError, match=r"line 9: 'abc' in column 'x' is not a number"):
        import_csv(tmp_path / "ghost.csv", tmp_path / "ghost.h5", width=0.09, height=0.95)


def test_import_does_not_replace_a_simulated_run_without_force(tmp_path, capsys):
    """A finished CFD-DEM or generated run is hours of work: import replaces an earlier
    import's file, not such a run, unless --force; the run is left as it was."""
    from cfbmarkov.cli import main
    from cfbmarkov.synthetic import RiserFlow, write_run

    run = write_run(tmp_path / "run.h5", RiserFlow(columns=2, rows=4), 5, 0.2, seed=1)
    before = run.read_bytes()
    csv = tmp_path / "t.csv"
    csv.write_text("t,id,x,y\n0,1,0.01,0.1\n0.025,1,0.01,0.12\n0.05,1,0.01,0.14\n")
    argv = ["import", str(csv), "--width", "0.09", "--height", "0.95", "-o", str(run)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not an earlier import" in err and "--force" in err
    assert run.read_bytes() == before
    again = tmp_path / "imported.h5"
    assert main(argv[:-1] + [str(again)]) == 0
    assert main(argv[:-1] + [str(again)]) == 0          # an import replaces an import
    assert main(argv + ["--force"]) == 0
    with Trajectories(run) as t:
        assert t.n_particles == 1
