"""CSV field cases: small exports with the quirks of real data (copied into tests/io/field/
from the shared field data), with their right values from the cases' descriptions:

- ``semicolon-decimal-comma.csv``: ``t;id;x;y``, ``0,000;1;0,020;0,100``: 3 frames (0, 0.025,
  0.05 s) x 3 particles, x = 0.02 id m, y = 0.1 + 0.05 frame m.
- ``spreadsheet-style-headers.csv``: ``Time (s),Particle ID,Position X (m),...`` with z and
  velocities: the same positions, velocity (0, 2) m/s; the z column needs --vertical-axis.
- ``pept-pointdata.csv``: ``# t x y z error``, space-delimited, mm and ms, one tracer,
  irregular times and a gap: refused (no resampling yet), never stored.
- ``ptv-enter-leave.csv``: particle 5 enters at the third frame, particle 2 leaves after the
  fourth: refused (no presence mask yet), naming the particle and the frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.cli import main as cli_main
from cfbmarkov.errors import InputError
from cfbmarkov.io import import_csv, import_file
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_info import describe

FIELD = Path(__file__).parent / "field"


def _read(path):
    with Trajectories(path) as t:
        return t.times, t.ids, t.positions(), t.velocities(), t.parameters


def _three_by_three(times, ids, pos):
    np.testing.assert_allclose(times, [0.0, 0.025, 0.05], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(ids, [1, 2, 3])
    np.testing.assert_allclose(pos[..., 0], np.tile(0.02 * ids, (3, 1)), rtol=0, atol=1e-15)
    np.testing.assert_allclose(pos[..., 1], np.repeat(0.1 + 0.05 * np.arange(3), 3).reshape(3, 3),
                               rtol=0, atol=1e-15)


# -- semicolon and decimal comma -------------------------------------------------------------------
def test_semicolon_and_decimal_comma(tmp_path, cli):
    code, out, err = cli("import", FIELD / "semicolon-decimal-comma.csv", "--format", "csv",
                         "--width", "0.09", "--height", "0.95",
                         "-o", tmp_path / "s.h5")
    assert code == 0, err
    times, ids, pos, vel, params = _read(tmp_path / "s.h5")
    _three_by_three(times, ids, pos)
    assert vel is None
    assert params["delimiter"] == "semicolon" and params["decimal_mark"] == "comma"
    assert params["columns"] == ["t", "id", "x", "y"] and params["ignored_columns"] == []


@pytest.mark.parametrize("delimiter", ["\t", "  ", ";"])
def test_other_delimiters_with_either_decimal_mark(tmp_path, delimiter):
    rows = [f"{0.025 * k:.3f}{delimiter}{i}{delimiter}{0.02 * i:.3f}{delimiter}{0.1 + 0.05 * k:.3f}"
            for k in range(3) for i in (3, 1, 2)]
    for comma in (False, True):
        text = "\n".join([delimiter.join(["t", "id", "x", "y"]), *rows]) + "\n"
        if comma:
            text = text.replace(".", ",")
        source = tmp_path / f"d{comma}.csv"
        source.write_text(text)
        times, ids, pos, _, params = _read(import_csv(source, tmp_path / f"d{comma}.h5",
                                                      width=0.09, height=0.95))
        _three_by_three(times, ids, pos)
        assert params["decimal_mark"] == ("comma" if comma else "point")


@pytest.mark.parametrize("delimiter", [",", ";"])
def test_every_field_quoted_reads_as_plain(tmp_path, delimiter):
    """Exports that quote every field (pandas with QUOTE_ALL, some loggers): the values
    inside the quotes, with either decimal mark; a quoted text column with the delimiter
    inside stays one column."""
    rows = [[f"{0.025 * k:.3f}", str(i), f"{0.02 * i:.3f}", f"{0.1 + 0.05 * k:.3f}",
             "a, b; c"] for k in range(3) for i in (3, 1, 2)]
    for comma in ((False, True) if delimiter == ";" else (False,)):
        lines = [delimiter.join(f'"{x}"' for x in ["t", "id", "x", "y", "note"])]
        lines += [delimiter.join(f'"{x.replace(".", ",") if comma else x}"' for x in row)
                  for row in rows]
        source = tmp_path / f"q{comma}.csv"
        source.write_text("\n".join(lines) + "\n")
        times, ids, pos, _, _ = _read(import_csv(source, tmp_path / f"q{comma}.h5",
                                                 width=0.09, height=0.95))
        _three_by_three(times, ids, pos)


def test_decimal_comma_with_a_comma_delimiter_is_refused_by_line(tmp_path, assert_clean_failure):
    source = tmp_path / "bad.csv"
    source.write_text("t,id,x,y\n0,1,0.02,0.1\n0.025,1,0,02,0.1\n")
    assert_clean_failure("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "-o", tmp_path / "o" / "b.h5",
                         output=tmp_path / "o" / "b.h5", match=r"line 3: 5 values, the header "
                                                               r"names 4 columns")


# -- spreadsheet-style headers -------------------------------------------------------------------
def test_spreadsheet_headers_need_the_vertical_axis_then_map(tmp_path, assert_clean_failure):
    source = FIELD / "spreadsheet-style-headers.csv"
    output = tmp_path / "o" / "e.h5"
    line = assert_clean_failure("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                                "-o", output, output=output,
                                match=r"has a z column \(3D positions\): say which axis is "
                                      r"vertical with --vertical-axis x\|y\|z")
    assert "nothing is guessed" in line
    assert_clean_failure("import", source, "--format", "csv", "--vertical-axis", "y", "-o", output,
                         output=output, match=r"3D positions \(x across, y vertical, z depth\): "
                                              r"give the riser with --region .* or --drop-depth")
    times, ids, pos, vel, params = _read(import_file(source, "csv", tmp_path / "e.h5",
                                                     vertical_axis="y", drop_depth=True,
                                                     width=0.09, height=0.95))
    _three_by_three(times, ids, pos)
    np.testing.assert_array_equal(vel, np.broadcast_to([0.0, 2.0], (3, 3, 2)))
    assert params["vertical_axis"] == "y" and params["across_axis"] == "x"
    assert params["depth_axis_dropped"] == "z"
    assert params["ignored_columns"] == ["Position Z (m) (depth axis)",
                                         "Velocity Z (m/s) (depth axis)"]
    assert params["units"] == {"t": "s", "x": "m", "y": "m", "vx": "m/s", "vy": "m/s"}


def test_header_units_are_honoured_and_not_contradicted(tmp_path, assert_clean_failure):
    source = tmp_path / "mm.csv"
    source.write_text("Time [ms],Particle_ID,Position X (mm),Position Y (mm),Velocity X (mm/s),"
                      "Velocity Y (mm/s),Mass (kg)\n"
                      + "".join(f"{25 * k},{i},{20 * i},{100 + 50 * k},{1000 * i},-500,1e-6\n"
                                for k in range(3) for i in (1, 2, 3)))
    times, ids, pos, vel, params = _read(import_csv(source, tmp_path / "mm.h5", width=0.09, height=0.95))
    _three_by_three(times, ids, pos)
    np.testing.assert_allclose(vel[..., 0], np.tile([1.0, 2.0, 3.0], (3, 1)), rtol=0, atol=1e-15)
    np.testing.assert_allclose(vel[..., 1], -0.5, rtol=0, atol=1e-15)
    assert params["units"]["x"] == "mm" and params["units"]["t"] == "ms"
    assert params["units"]["vx"] == "mm/s"
    assert params["ignored_columns"] == ["Mass (kg)"]
    output = tmp_path / "o" / "x.h5"
    assert_clean_failure("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "--length-unit", "cm", "-o", output,
                         output=output, match=r"'Position X \(mm\)' is in mm but --length-unit "
                                              r"cm was given")
    source.write_text(source.read_text().replace("(mm)", "(in)", 1))
    assert_clean_failure("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "-o", output, output=output,
                         match=r"'Position X \(in\)': unit 'in' is not known; convert the "
                               r"column to one of m, cm, mm, um and name that unit in the header")


def test_unknown_names_are_refused_naming_the_columns_expected(tmp_path, assert_clean_failure):
    source = tmp_path / "odd.csv"
    source.write_text("Zeit,Teilchen,PosX,PosY\n0,1,0.02,0.1\n")
    output = tmp_path / "o" / "x.h5"
    assert_clean_failure("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "-o", output, output=output,
                         match=r"missing column 't' in the header 'Zeit,Teilchen,PosX,PosY'; "
                               r"expected t, x, y and optionally id.*'Time \(s\)'")


# -- 3D files and the vertical axis ----------------------------------------------------------------
def test_vertical_axis_z_takes_heights_from_z(tmp_path):
    source = tmp_path / "z.csv"
    source.write_text("t,id,x,y,z,vx,vy,vz\n" + "".join(
        f"{0.025 * k},{i},{0.02 * i},0.004,{0.1 + 0.05 * k},0.5,9,-1.5\n"
        for k in range(3) for i in (1, 2, 3)))
    times, ids, pos, vel, params = _read(import_file(source, "csv", tmp_path / "z.h5",
                                                     vertical_axis="z", drop_depth=True,
                                                     width=0.09, height=0.95))
    _three_by_three(times, ids, pos)
    np.testing.assert_array_equal(vel, np.broadcast_to([0.5, -1.5], (3, 3, 2)))
    assert (params["vertical_axis"], params["across_axis"]) == ("z", "x")
    assert params["depth_axis_dropped"] == "y"
    assert params["velocity_columns"] == ["vx", "vz"]
    # kept in 3D with the riser's region (x, y, z ranges): depth y measured from its lower bound
    times, ids, pos3, vel3, params = _read(import_file(
        source, "csv", tmp_path / "z3.h5", vertical_axis="z",
        region=((0.0, 0.09), (0.0, 0.01), (0.0, 0.95))))
    np.testing.assert_array_equal(pos3[..., :2], pos)
    np.testing.assert_allclose(pos3[..., 2], 0.004, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(vel3, np.broadcast_to([0.5, -1.5, 9.0], (3, 3, 3)))
    with Trajectories(tmp_path / "z3.h5") as t:
        assert (t.dimensions, t.depth) == (3, 0.01)
        assert t.axes == {"across": "x", "vertical": "z", "depth": "y"}
    with pytest.raises(InputError, match=r"--vertical-axis z but the header 't;id;x;y' has no z"):
        import_file(FIELD / "semicolon-decimal-comma.csv", "csv", tmp_path / "n.h5",
                    vertical_axis="z", width=0.09, height=0.95)


# -- PEPT and PTV: resampling and presence ----------------------------------------------------
def test_pept_point_data_needs_resampling_and_then_gives_the_right_track(tmp_path,
                                                                         assert_clean_failure):
    """README: one tracer; y = (2.5 mm/ms t) mod 950 mm, x = 45 + 20 sin(t / 50 ms) mm;
    resampled onto 5 ms it is present on 0-300 ms and from 420 ms on, absent in the gap."""
    source = FIELD / "pept-pointdata.csv"
    output = tmp_path / "o" / "p.h5"
    base = ("import", source, "--format", "csv", "-o", output)
    assert_clean_failure(*base, output=output, match=r"header 't x y z error' has a z column.*"
                                                     r"--vertical-axis")
    units = ("--vertical-axis", "y", "--drop-depth")
    assert_clean_failure(*base, *units, output=output,
                         match=r"does not give the riser's size: give --width W and --height H "
                               r".*the data span x 25..65 m, y 1.148..949.6 m")
    assert_clean_failure(*base, *units, "--width", "0.09", "--height", "0.95", output=output,
                         match=r"particle 0 at t = 0.459185 s lies outside the domain .*'x' = "
                               r"45.1837 m.*give --length-unit cm\|mm")
    units += ("--length-unit", "mm", "--time-unit", "ms", "--width", "0.09", "--height", "0.95")
    line = assert_clean_failure(*base, *units, output=output,
                                match=r"frames unevenly spaced: 0.002244815 s between t = "
                                      r"0.001535799 and 0.003780614 s")
    assert "resample them with --resample DT --max-gap G" in line
    for bad, match in ((("--resample", "0"), r"argument --resample: '0' must be positive"),
                       (("--resample", "5"), r"--resample step 5 s is larger than the span"),
                       (("--max-gap", "0.1"), r"--max-gap applies with --resample only"),
                       (("--resample", "0.005", "--max-gap", "-1"), r"--max-gap: '-1' must be")):
        assert_clean_failure(*base, *units, *bad, output=output, match=match)
    out = tmp_path / "p.h5"
    assert cli_main(["import", str(source), "--format", "csv", "-o", str(out), *units,
                     "--resample", "0.005", "--max-gap", "0.1"]) == 0
    with Trajectories(out) as t:
        times, pos, present, laps = t.times, t.positions()[:, 0], t.present()[:, 0], t.laps()[:, 0]
        assert t.frame_interval == 0.005 and t.parameters["resample"] == 0.005
    ms = times * 1000
    assert ms[0] == pytest.approx(5.0, abs=1e-9) and ms[-1] == pytest.approx(780.0, abs=1e-9)
    gap = (ms > 297.2) & (ms < 420.4)
    np.testing.assert_array_equal(present, ~gap)
    assert np.isnan(pos[gap]).all()
    x, y = 45 + 20 * np.sin(ms / 50), np.mod(2.5 * ms, 950)
    np.testing.assert_allclose(pos[~gap, 0] * 1000, x[~gap], atol=0.5)
    dy = np.abs(pos[~gap, 1] * 1000 - y[~gap])
    assert np.minimum(dy, 950 - dy).max() < 0.5
    # the pass at 380 ms is inside the gap, unseen; the one at 760 ms is counted
    assert laps[ms < 750].max() == 0 and laps[-1] == 1


def test_pept_gaps_longer_than_the_default_max_gap_are_warned(tmp_path, capsys):
    """Resampled without --max-gap (default: the resample step), the irregular samples of
    the pept file leave the tracer absent many times, each gap a broken residence: a
    warning counts them and names --max-gap; with --max-gap given, none."""
    from tests.io.test_csv_field_cases import FIELD as field

    units = ["--format", "csv", "--vertical-axis", "y", "--drop-depth", "--length-unit", "mm",
             "--time-unit", "ms", "--width", "0.09", "--height", "0.95", "--resample", "0.005"]
    source = str(field / "pept-pointdata.csv")
    assert cli_main(["import", source, "-o", str(tmp_path / "d.h5"), *units]) == 0
    err = capsys.readouterr().err
    with Trajectories(tmp_path / "d.h5") as t:
        present = t.present()[:, 0]
    after = present[int(np.argmax(present)):]        # from the tracer's first sample on
    back = int(np.count_nonzero(~after[:-1] & after[1:]))       # absent, then present again
    assert back > 1
    assert (f"warning: the tracers are absent {back} time(s) between two of their samples "
            "further apart than --max-gap, by default the resample step 0.005 s") in err
    assert "give a larger --max-gap (such as 0.02)" in err
    assert cli_main(["import", source, "-o", str(tmp_path / "g.h5"), *units,
                     "--max-gap", "0.02"]) == 0
    assert "warning:" not in capsys.readouterr().err


def test_pept_style_file_at_even_times_reads_right(tmp_path):
    """The pept layout ('# t x y z error', spaces, mm and ms, no id) where the times are even."""
    t = np.arange(0.0, 50.0, 2.0)                       # ms
    x, y = 45 + 20 * np.sin(t / 50), np.mod(2.5 * t, 950)  # mm
    source = tmp_path / "pept.csv"
    source.write_text("# written by pept\n# t x y z error\n" + "".join(
        f"{a:.6e} {b:.6e} {c:.6e} 5.000000e-01 1.2\n" for a, b, c in zip(t, x, y)))
    times, ids, pos, vel, params = _read(import_file(
        source, "csv", tmp_path / "p.h5", length_unit="mm", time_unit="ms", vertical_axis="y",
        drop_depth=True, width=0.09, height=0.95))
    np.testing.assert_array_equal(ids, [0])
    np.testing.assert_allclose(times, t / 1000, rtol=1e-6)
    np.testing.assert_allclose(pos[:, 0, 0], x / 1000, rtol=1e-6)
    np.testing.assert_allclose(pos[:, 0, 1], y / 1000, rtol=1e-6)
    assert params["id_column"] is None and params["delimiter"] == "whitespace"
    assert params["ignored_columns"] == ["z (depth axis)", "error"]
    assert params["units"] == {"t": "ms", "x": "mm", "y": "mm"}


def test_two_rows_at_one_time_without_id(tmp_path, assert_clean_failure):
    source = tmp_path / "two.csv"
    source.write_text("t,x,y\n0,0.01,0.1\n0,0.02,0.2\n")
    output = tmp_path / "o" / "x.h5"
    assert_clean_failure("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "-o", output, output=output,
                         match=r"2 rows at this time, but the file has no id column, so it")
    # a column that numbers the tracers under another name is named, with the fix
    source.write_text("t,tag,x,y\n0,1,0.01,0.1\n0,2,0.02,0.2\n")
    assert_clean_failure("import", source, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "-o", output, output=output,
                         match=r"no id column \(not used: 'tag'\), so it is read as one tracer; "
                               r"name the column that numbers the particles id")


def test_ptv_particles_entering_and_leaving_are_present_as_in_the_file(tmp_path):
    """Particle 5 enters the view at the third frame, particle 2 leaves after the fourth."""
    source = FIELD / "ptv-enter-leave.csv"
    rows = np.loadtxt(source, delimiter=",", skiprows=1)
    out = import_file(source, "csv", tmp_path / "v.h5", width=0.09, height=0.95)
    with Trajectories(out) as t:
        ids, times, present, pos = t.ids, t.times, t.present(), t.positions()
        lines = describe(t)
    frame_times = np.unique(rows[:, 0])
    np.testing.assert_allclose(times, frame_times)
    for k, time in enumerate(frame_times):
        expected = set(rows[rows[:, 0] == time, 1].astype(int))
        assert set(ids[present[k]]) == expected
        for r in rows[rows[:, 0] == time]:
            np.testing.assert_array_equal(pos[k, list(ids).index(int(r[1]))], r[2:4])
    assert present[:2, list(ids).index(5)].tolist() == [False, False]
    assert present[4:, list(ids).index(2)].sum() == 0
    text = "\n".join(lines)
    assert "particles present per frame: min 4, max 5 of 5" in text
    assert "tracks begun 1, ended 1 (after the first frame, anywhere" in text


# -- the new options, given wrong ----------------------------------------------------------------
@pytest.mark.parametrize("args, match", [
    (("--length-unit", "km"), r"argument --length-unit: invalid choice: 'km'"),
    (("--time-unit", "h"), r"argument --time-unit: invalid choice: 'h'"),
    (("--vertical-axis", "w"), r"argument --vertical-axis: invalid choice: 'w'"),
    (("--region", "0:0.09"), r"argument --region"),
    (("--boundary", "closed"), r"argument --boundary: invalid choice: 'closed'"),
    (("--region", "0.5:0.9,0:0.95"), r"holds no particle in any frame"),
    (("--region", "0:0.09,0:0.95", "--width", "0.05"),
     r"--region sets the riser's size and place, so --width would be ignored"),
    (("--drop-depth", "--width", "0.09", "--height", "0.95"),
     r"--drop-depth drops a z column, but the file's positions are 2D"),
])
def test_wrong_option_values_give_one_line(tmp_path, assert_clean_failure, args, match):
    output = tmp_path / "o" / "x.h5"
    size = () if {"--region", "--width"} & set(args) else ("--width", "0.09", "--height", "0.95")
    assert_clean_failure("import", FIELD / "semicolon-decimal-comma.csv", "--format", "csv",
                         *size, *args, "-o", output, output=output, match=match)


def test_wrong_option_values_through_the_api(tmp_path):
    source = FIELD / "semicolon-decimal-comma.csv"
    for options, match in (({"length_unit": "km"}, r"--length-unit 'km': choose m, cm, mm or um"),
                           ({"time_unit": "min"}, r"--time-unit 'min': choose s or ms"),
                           ({"vertical_axis": "w"}, r"--vertical-axis 'w': choose x, y or z")):
        with pytest.raises(InputError, match=match):
            import_file(source, "csv", tmp_path / "x.h5", **options, width=0.09, height=0.95)
    with pytest.raises(InputError, match=r"--length-unit and --time-unit apply to CSV files only"):
        import_file(FIELD / "unwrapped-fine.dump", "lammps", tmp_path / "x.h5", length_unit="mm")
    assert not (tmp_path / "x.h5").exists()


def test_times_since_an_epoch_that_a_double_cannot_tell_apart_are_named(tmp_path, capsys):
    """Rows 1e-7 s apart at 1.7e9 s (seconds since 1970) read as one time in a double (held
    to 2.4e-7 s): the refusal said only "2 rows at this time, but the file has no id
    column"; it now names the times' size and the fix beside that advice, and the rows a
    resampling merges carry the same note. The same times with the first subtracted
    import; epoch times 1 ms apart import as they are."""
    def write(name, start, step, with_id, repeat=None):
        head = "t,id,x,y\n" if with_id else "t,x,y\n"
        rows = [f"{start + k * step:.7f}," + ("1," if with_id else "")
                + f"0.02,{0.1 + 0.004 * k:.4f}\n" for k in range(60)]
        if repeat is not None:
            rows.insert(repeat, rows[repeat])
        path = tmp_path / name
        path.write_text(head + "".join(rows))
        return path

    fix = ("where a double holds them only to 2.4e-07 s, so rows stamped closer than that read "
           "as one time: give the times from the run's start")
    for path, said in ((write("one.csv", 1.7e9, 1e-7, False), "or add one; or the times lie"),
                       (write("ids.csv", 1.7e9, 1e-7, True), "appears more than once")):
        code = cli_main(["import", str(path), "--width", "0.09", "--height", "0.95",
                         "-o", str(tmp_path / "x.h5")])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and fix in err and said in err, err
        assert not (tmp_path / "x.h5").exists()
    # resampled: a row given twice is merged, and the note names the times' size
    twice = write("twice.csv", 1.7e9, 1e-3, True, repeat=10)
    assert cli_main(["import", str(twice), "--width", "0.09", "--height", "0.95",
                     "--resample", "0.001", "-o", str(tmp_path / "t.h5")]) == 0
    with Trajectories(tmp_path / "t.h5") as t:
        [note] = [n for n in t.parameters["import_notes"] if "merged" in n]
    assert note.startswith("1 row at the same time as another row") and fix in note
    for path in (write("from0.csv", 0.0, 1e-7, True), write("ms.csv", 1.7e9, 1e-3, True)):
        assert cli_main(["import", str(path), "--width", "0.09", "--height", "0.95", "-o",
                         str(tmp_path / f"{path.stem}.h5")]) == 0
    capsys.readouterr()
