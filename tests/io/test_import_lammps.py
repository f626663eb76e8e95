"""LAMMPS/LIGGGHTS dump import: round trips of generated dumps, the real engine files in
shared/data, and every kind of bad input through the Python API and ``cfbmarkov import``."""

from __future__ import annotations

import gzip
import itertools
import re

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.io import import_file, import_lammps
from cfbmarkov.trajectories import Trajectories

SHUFFLED = ("vy", "x", "radius", "id", "y", "z", "vx", "type")


def read_back(path):
    with Trajectories(path) as t:
        return {"times": t.times, "ids": t.ids, "positions": t.positions(),
                "velocities": t.velocities(), "laps": t.laps(), "source": t.source,
                "parameters": t.parameters, "domain": (t.width, t.height)}


# -- round trips of generated dumps -------------------------------------------------------------
@pytest.mark.parametrize("with_time", [True, False])
@pytest.mark.parametrize("gz", [False, True])
def test_round_trip_shuffled_columns_unsorted_ids(tmp_path, run, make_dump, save, with_time, gz):
    text = make_dump(run, columns=SHUFFLED, with_time=with_time)
    source = save(tmp_path / ("run.dump.gz" if gz else "run.dump"), text, gz=gz)
    out = import_file(source, "lammps", tmp_path / "run.h5",
                      time_step=None if with_time else 5e-6)
    got = read_back(out)
    np.testing.assert_array_equal(got["ids"], run.ids)
    if with_time:
        np.testing.assert_array_equal(got["times"], run.times)
    else:
        np.testing.assert_allclose(got["times"], run.times, rtol=1e-12)
    np.testing.assert_array_equal(got["positions"], run.positions)
    np.testing.assert_array_equal(got["velocities"], run.velocities)
    np.testing.assert_array_equal(got["laps"], run.laps)
    assert got["source"] == "import:lammps"
    assert got["domain"] == (0.09, 0.95)
    params = got["parameters"]
    assert params["columns"] == list(SHUFFLED)
    assert params["position_columns"] == ["x", "y"] and params["velocity_columns"] == ["vx", "vy"]
    assert params["format"] == "lammps" and params["source_file"] == source.name
    assert params["time_from"] == ("ITEM: TIME" if with_time else "timestep x time_step")
    assert params["time_step"] == (None if with_time else 5e-6)
    assert params["units"] == "si"
    assert params["box"] == [[0.0, 0.09], [0.0, 0.95], [-0.0005, 0.0005]]


@pytest.mark.parametrize("kind", [("x", "y"), ("xs", "ys"), ("xu", "yu")])
def test_position_columns_and_shifted_box(tmp_path, run, make_dump, save, kind):
    box = ((-0.045, 0.045), (0.2, 1.15), (-0.0005, 0.0005))
    text = make_dump(run, columns=("id",) + kind + ("vx", "vy"), box=box, units=None)
    out = import_lammps(save(tmp_path / "run.dump", text), tmp_path / "run.h5")
    got = read_back(out)
    np.testing.assert_allclose(got["positions"], run.positions, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got["laps"], run.laps)
    assert got["domain"] == pytest.approx((0.09, 0.95))
    assert got["parameters"]["origin_shift"] == [-0.045, 0.2]
    assert got["parameters"]["position_columns"] == list(kind)
    assert got["parameters"]["units"] is None


def test_unwrapped_heights_are_wrapped_into_the_box(tmp_path, run, make_dump, save):
    assert run.unwrapped_y.max() > run.height and run.unwrapped_y.min() < 0
    text = make_dump(run, columns=("id", "xu", "yu"))
    got = read_back(import_lammps(save(tmp_path / "run.dump", text), tmp_path / "run.h5"))
    assert got["velocities"] is None
    assert got["positions"][..., 1].min() >= 0 and got["positions"][..., 1].max() < run.height
    np.testing.assert_array_equal(got["laps"], run.laps)


def test_positions_just_outside_a_periodic_box_are_wrapped(tmp_path):
    """LAMMPS writes atoms a little outside a periodic box between re-neighbourings."""
    frames = [(0, ["1 0.01 0.9499", "2 0.02 0.0001"]), (1000, ["1 0.01 0.95003", "2 0.02 -0.00002"]),
              (2000, ["1 0.01 0.0002", "2 0.02 0.9498"])]
    text = "".join(f"ITEM: TIMESTEP\n{ts}\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS ff pp pp\n"
                   "0 0.09\n0 0.95\n-0.0005 0.0005\nITEM: ATOMS id x y\n" + "\n".join(rows) + "\n"
                   for ts, rows in frames)
    source = tmp_path / "edge.dump"
    source.write_text(text)
    got = read_back(import_lammps(source, tmp_path / "edge.h5", time_step=1e-5))
    np.testing.assert_allclose(got["positions"][1, :, 1], [0.00003, 0.95 - 0.00002], atol=1e-12)
    np.testing.assert_array_equal(got["laps"], [[0, 0], [1, -1], [1, -1]])
    np.testing.assert_allclose(got["times"], [0.0, 0.01, 0.02])


def test_two_line_box_trailing_spaces_and_domain_override(tmp_path, run, make_dump, save):
    text = make_dump(run, box=((0.0, 0.09), (0.0, 0.95)), boundary="ff pp", trailing_space=True,
                     columns=("id", "x", "y"))
    source = save(tmp_path / "run.dump", text)
    got = read_back(import_lammps(source, tmp_path / "a.h5"))
    np.testing.assert_array_equal(got["positions"], run.positions)
    got = read_back(import_lammps(source, tmp_path / "b.h5", width=0.1, height=0.95))
    assert got["domain"] == (0.1, 0.95)
    np.testing.assert_array_equal(got["laps"], run.laps)


def test_box_bounds_without_flags(tmp_path, run, make_dump, save):
    text = make_dump(run, boundary="", columns=("id", "x", "y")).replace("BOX BOUNDS \n",
                                                                         "BOX BOUNDS\n")
    got = read_back(import_lammps(save(tmp_path / "run.dump", text), tmp_path / "run.h5"))
    np.testing.assert_array_equal(got["positions"], run.positions)
    assert got["parameters"]["boundary"] == []


def test_cli_import_of_a_dump(tmp_path, run, make_dump, save, cli):
    source = save(tmp_path / "run.dump.gz", make_dump(run, with_time=False), gz=True)
    output = tmp_path / "o" / "run.h5"
    code, out, err = cli("import", source, "--format", "lammps", "-o", output,
                         "--time-step", "5e-6")
    assert code == 0, err
    assert out == f"{output}\n"
    assert err.startswith("cfbmarkov import: read 16 frames of 6 particles as LAMMPS/LIGGGHTS "
                          "text dump (--format)") and err.count("\n") == 1, err
    code, out, err = cli("info", output)
    assert code == 0 and "6 particles x 16 frames" in out and "import:lammps" in out


# -- the real engine files ------------------------------------------------------------------------
def raw_dump_heights(path):
    """y of every atom per frame, by id, read with plain string handling: {time: {id: y}}."""
    frames, lines = {}, path.read_text().splitlines()
    k = 0
    while k < len(lines):
        if lines[k] == "ITEM: TIME":
            time = float(lines[k + 1])
        if lines[k] == "ITEM: NUMBER OF ATOMS":
            count = int(lines[k + 1])
        if lines[k].startswith("ITEM: ATOMS"):
            names = lines[k].split()[2:]
            rows = [line.split() for line in lines[k + 1:k + 1 + count]]
            frames[time] = {int(r[names.index("id")]): float(r[names.index("y")]) for r in rows}
            k += count
        k += 1
    return frames


def test_real_lammps_riser_dump(tmp_path, shared_data):
    source = shared_data / "lammps-riser-300.dump"
    got = read_back(import_lammps(source, tmp_path / "riser.h5"))
    assert got["positions"].shape == (81, 300, 2)
    np.testing.assert_array_equal(got["ids"], np.arange(1, 301))
    np.testing.assert_allclose(got["times"], 0.5 + 0.025 * np.arange(81), rtol=0, atol=1e-12)
    assert got["domain"] == pytest.approx((0.09, 0.95))
    assert got["velocities"] is not None
    y = got["positions"][..., 1]
    assert y.min() >= 0 and y.max() <= 0.95
    np.testing.assert_array_equal(got["laps"][0], 0)
    steps = np.diff(got["laps"], axis=0)
    up, down = int((steps == 1).sum()), int((steps == -1).sum())
    assert np.abs(steps).max() <= 1

    raw = raw_dump_heights(source)
    times = sorted(raw)
    assert len(times) == 81
    raw_up = raw_down = 0
    for a, b in itertools.pairwise(times):
        dy = np.array([raw[b][i] - raw[a][i] for i in range(1, 301)])
        raw_up += int((dy < -0.475).sum())
        raw_down += int((dy > 0.475).sum())
    assert (up, down) == (raw_up, raw_down)
    assert abs(up - 1130) <= 60 and abs(down - 180) <= 20, (up, down)
    np.testing.assert_array_equal(got["laps"][-1], got["laps"][-1].astype(int))
    assert got["laps"][-1].sum() == up - down


def test_real_liggghts_sample(tmp_path, shared_data, assert_clean_failure):
    source = shared_data / "liggghts-3.8.0-sample.dump"
    output = tmp_path / "out" / "sample.h5"
    with pytest.raises(InputError, match=r"no ITEM: TIME; give .* --time-step"):
        import_lammps(source, output)
    assert_clean_failure("import", source, "--format", "lammps", "-o", output, output=output,
                         match=r"--time-step")
    got = read_back(import_lammps(source, output, time_step=1e-5))
    np.testing.assert_array_equal(got["ids"], [1, 2, 3])
    np.testing.assert_array_equal(got["times"], [0.0])
    np.testing.assert_array_equal(got["positions"], [[[0.02, 0.05], [0.05, 0.06], [0.07, 0.08]]])
    np.testing.assert_array_equal(got["velocities"], np.zeros((1, 3, 2)))
    assert got["domain"] == (0.09, 0.2)
    assert got["parameters"]["boundary"] == ["ff", "ff", "pp"]


# -- bad input ------------------------------------------------------------------------------------
BOX = "0 0.09\n0 0.95\n-0.0005 0.0005\n"
ATOMS = [["1 1 0.01 0.10 0 1", "2 1 0.02 0.20 0 1", "3 1 0.03 0.30 0 1"],
         ["3 1 0.03 0.31 0 1", "1 1 0.01 0.11 0 1", "2 1 0.02 0.21 0 1"],
         ["1 1 0.01 0.12 0 1", "2 1 0.02 0.22 0 1", "3 1 0.03 0.32 0 1"]]


def frame(k: int, rows=None, *, time: float | None = None, natoms: int | None = None,
          box: str = BOX, flags: str = "ff pp pp", columns: str = "id type x y vx vy") -> str:
    rows = ATOMS[k] if rows is None else rows
    time = 0.5 + 0.025 * k if time is None else time
    head = "" if time is False else f"ITEM: TIME\n{time}\n"
    return (f"{head}ITEM: TIMESTEP\n{5000 * k}\nITEM: NUMBER OF ATOMS\n"
            f"{len(rows) if natoms is None else natoms}\nITEM: BOX BOUNDS {flags}\n{box}"
            f"ITEM: ATOMS {columns}\n" + "".join(row + "\n" for row in rows))


def dump(*frames: str) -> str:
    return "".join(frames) if frames else frame(0) + frame(1) + frame(2)


GOOD = dump()
LONG = "".join(frame(k, ATOMS[k % 3], time=0.5 + 0.025 * k) for k in range(300))
BAD_DUMPS = {
    "triclinic-flags": (dump(frame(0, flags="xy xz yz ff pp pp",
                                   box="0 0.09 0\n0 0.95 0.02\n0 1 0\n")),
                        r"line 9: box bounds with a tilt factor 0.02: a tilted \(triclinic\) box"),
    "triclinic-bounds": (dump(frame(0, box="0 0.09 0.01\n0 0.95 0\n0 1 0\n")),
                         r"line 8: box bounds with a tilt factor 0.01: a tilted \(triclinic\)"),
    "non-si-units": ("ITEM: UNITS\nlj\n" + GOOD, r"line 2: units are 'lj', not SI"),
    "no-time": (dump(*(frame(k, time=False) for k in range(3))),
                (r"timestep 0 \(line 9\): the dump has no ITEM: TIME; give the simulation "
                 r"time step with --time-step \(s\)")),
    "time-in-first-frame-only": (dump(frame(0), frame(1, time=False)),
                                 r"timestep 5000 \(line 23\): the dump has no ITEM: TIME"),
    "truncated-mid-frame": (GOOD[: GOOD.rindex("3 1 0.03 0.32")],
                            (r"file ends inside the atoms of timestep 10000: 2 of 3 atom "
                             r"lines \(truncated\?\)")),
    "truncated-mid-line": (GOOD[:-11], (r"line 42: 3 values, ITEM: ATOMS names 6 columns "
                                        r"\(the file ends inside this line: truncated\?\)")),
    "truncated-in-header": (GOOD[: GOOD.rindex("ITEM: BOX")],
                            r"file ends inside the header of a frame at line 34 \(truncated\?\)"),
    "truncated-after-item": (GOOD[: GOOD.rindex("ITEM: BOX") - 2],
                             r"no value after 'ITEM: NUMBER OF ATOMS' \(truncated\?\)"),
    "truncated-gzip": (gzip.compress(LONG.encode())[: len(gzip.compress(LONG.encode())) // 2],
                       r"file is truncated \(the compressed stream ends early\)"),
    "no-id-column": (dump(frame(0, [r[2:] for r in ATOMS[0]], columns="type x y vx vy")),
                     r"ITEM: ATOMS has no 'id' column \(type x y vx vy\), so the frames' "
                     r"particles cannot be matched; write the dump with id first"),
    "no-position-columns": (dump(frame(0, columns="id type a b vx vy")),
                            r"no position columns \(xu yu, xsu ysu, x y or xs ys\)"),
    "unknown-item": (GOOD.replace("ITEM: TIMESTEP\n5000", "ITEM: ENTRIES c_1\n5000"),
                     r"line 17: unknown item 'ITEM: ENTRIES c_1'"),
    "atoms-without-count": (GOOD.replace("ITEM: NUMBER OF ATOMS\n3\n", "", 1),
                            r"line 9: ITEM: ATOMS without a preceding ITEM: NUMBER OF ATOMS"),
    "box-changes": (dump(frame(0), frame(1, box="0 0.09\n0 1.0\n-0.0005 0.0005\n"), frame(2)),
                    r"timestep 5000 \(line 25\): the box changes"),
    "columns-change": (dump(frame(0), frame(1, [r[:-4] for r in ATOMS[1]], columns="id type x y")),
                       r"ITEM: ATOMS columns change \(id type x y\)"),
    "non-numeric": (dump(frame(0), frame(1, ["3 1 0.03 0.31 0 1", "1 1 abc 0.11 0 1",
                                             "2 1 0.02 0.21 0 1"])),
                    r"line 27: 'abc' in column 'x' is not a number"),
    "bad-timestep": (GOOD.replace("TIMESTEP\n5000", "TIMESTEP\n5e3"),
                     r"line 18: ITEM: TIMESTEP value '5e3' is not a whole number"),
    "fewer-atoms-than-declared": (dump(frame(0, natoms=4), frame(1)),
                                  (r"line 15: 'ITEM: TIME' inside the atoms of timestep 0: "
                                   r"fewer atom lines \(3\) than NUMBER OF ATOMS \(4\)")),
    "more-atoms-than-declared": (dump(frame(0, natoms=2), frame(1)),
                                 r"line 14: expected an 'ITEM:' line, found '3 1 0.03 0.30 0 1'"),
    "duplicate-id": (dump(frame(0), frame(1, ATOMS[1][:2] + ["1 1 0.02 0.21 0 1"])),
                     r"particle id 1 appears more than once"),
    "fractional-id": (dump(frame(0), frame(1, ATOMS[1][:2] + ["2.5 1 0.02 0.21 0 1"])),
                      r"particle id 2.5 is not a whole number"),
    "time-not-increasing": (dump(frame(0), frame(1, time=0.55), frame(2, time=0.525)),
                            r"time goes back from t = 0.55 to 0.525 s \(frames out of order"),
    "frame-repeated": (dump(frame(0), frame(1), frame(1)),
                       r"the frame at t = 0.525 s comes twice \(a dump appended to after a "
                       r"restart repeats the restart's step"),
    "uneven-frames": (dump(frame(0), frame(1), frame(2, time=0.56)),
                      r"frames unevenly spaced: 0.035 s between t = 0.525 and 0.56 s"),
    "nan-position": (dump(frame(0), frame(1, ["3 1 0.03 0.31 0 1", "1 1 nan 0.11 0 1",
                                              "2 1 0.02 0.21 0 1"])),
                     (r"position of particle 1 at t = 0.525 s is not a finite number \(the "
                      r"simulation had diverged by this frame: keep only the frames written")),
    "inf-velocity": (dump(frame(0), frame(1, ["3 1 0.03 0.31 0 inf", "1 1 0.01 0.11 0 1",
                                              "2 1 0.02 0.21 0 1"])),
                     r"velocity of particle 3 at t = 0.525 s is not a finite number"),
    # the reader names the line; the command line, which checks --format first, the CSV
    "not-a-dump": ("t,id,x,y\n0,1,0.01,0.1\n",
                   r"line 1: expected an 'ITEM:' line, found 't,id,x,y'|"
                   r"\(read as CSV\), not lammps; import it with --format csv"),
    "not-a-dump-nor-a-table": ("hello world\n",
                               r"line 1: expected an 'ITEM:' line, found 'hello world'"),
    "no-frames": ("ITEM: UNITS\nsi\n", r"no frames with atoms \(no 'ITEM: ATOMS' block\)"),
    "empty-file": ("", r"empty file"),
    "binary-file": (b"\x00\x01\x02\xff\xfe\x80", r"not a text file"),
}


def write_case(tmp_path, content):
    source = tmp_path / "bad.dump"
    if isinstance(content, bytes):
        source.write_bytes(content)
    else:
        source.write_text(content)
    return source


@pytest.mark.parametrize("case", sorted(BAD_DUMPS))
def test_bad_dump_raises_input_error(tmp_path, case):
    content, match = BAD_DUMPS[case]
    output = tmp_path / "out" / "run.h5"
    with pytest.raises(InputError, match=match):
        import_lammps(write_case(tmp_path, content), output)
    assert not output.exists() and not output.parent.exists()


@pytest.mark.parametrize("case", sorted(BAD_DUMPS))
def test_bad_dump_through_cli(tmp_path, assert_clean_failure, case):
    content, match = BAD_DUMPS[case]
    output = tmp_path / "out" / "run.h5"
    line = assert_clean_failure("import", write_case(tmp_path, content), "--format", "lammps",
                                "-o", output, output=output, match=match)
    assert line.startswith("cfbmarkov import: error: ")


def test_good_reference_dump_imports(tmp_path):
    """The text that the bad cases alter is itself valid."""
    got = read_back(import_lammps(write_case(tmp_path, GOOD), tmp_path / "good.h5"))
    np.testing.assert_array_equal(got["positions"][1], [[0.01, 0.11], [0.02, 0.21], [0.03, 0.31]])
    got = read_back(import_lammps(write_case(tmp_path, LONG), tmp_path / "long.h5"))
    assert got["times"].size == 300


def test_missing_dump(tmp_path, assert_clean_failure):
    output = tmp_path / "out" / "run.h5"
    with pytest.raises(InputError, match=r"none.dump: no such file"):
        import_lammps(tmp_path / "none.dump", output)
    assert_clean_failure("import", tmp_path / "none.dump", "--format", "lammps", "-o", output,
                         output=output, match=r"no such file")


def test_a_dump_cut_inside_a_frame_names_the_lines_to_keep(tmp_path):
    """A dump cut inside its third frame's atoms (a run still writing it): the refusal gives
    the head command that keeps the two whole frames, and that file imports them."""
    import subprocess

    from cfbmarkov.errors import InputError
    from cfbmarkov.io import import_file

    frame = ("ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS pp pp pp\n"
             "0 0.09\n0 0.95\n0 0.001\nITEM: ATOMS id x y z\n1 0.01 {y} 0.0005\n"
             "2 0.05 0.4 0.0005\n")
    text = "".join(frame.format(step=1000 * k, y=0.2 + 0.01 * k) for k in range(3))
    cut = tmp_path / "run.dump"
    cut.write_text(text[:text.rindex("2 0.05")])           # the third frame's last atom missing
    with pytest.raises(InputError, match=r"2 atom lines \(truncated\?\); the frames before "
                                         r"line 23 are whole: keep them with head -n 22 ") as err:
        import_file(cut, "lammps", tmp_path / "a.h5", time_step=1e-5)
    command = str(err.value).split("keep them with ")[1]
    subprocess.run(command, shell=True, cwd=tmp_path, check=True)
    import_file(tmp_path / "whole.dump", "lammps", tmp_path / "b.h5", time_step=1e-5)
    with Trajectories(tmp_path / "b.h5") as t:
        assert t.n_frames == 2


def test_a_pattern_beside_a_file_and_the_same_timestep_twice(tmp_path, cli, assert_clean_failure):
    """A quoted pattern given with another dump file reads all their files as one series
    (in timestep order); a file that starts at a timestep another starts at (a copy, a
    restart's dump) is refused naming both files; sources the shell cannot make one
    pattern of (files in two folders) are refused with the folder as the cure."""
    series = tmp_path / "post"
    series.mkdir()
    for k in range(3):
        (series / f"dump{5000 * k}.riser").write_text(frame(k, time=False))
    extra = tmp_path / "later" / "dump15000.riser"
    extra.parent.mkdir()
    extra.write_text(frame(0, time=False).replace("TIMESTEP\n0\n", "TIMESTEP\n15000\n"))
    output = tmp_path / "run.h5"
    code, _, err = cli("import", str(series / "dump*.riser"), str(extra), "--time-step",
                       "1e-5", "-o", output, "--width", "0.09", "--height", "0.95")
    assert code == 0, err
    with Trajectories(output) as t:
        np.testing.assert_allclose(t.times, [0.0, 0.05, 0.1, 0.15])
    copy = tmp_path / "later" / "dump5000.riser"
    copy.write_text((series / "dump5000.riser").read_text())
    assert_clean_failure("import", str(series / "dump*.riser"), str(copy), "--time-step",
                         "1e-5", "-o", tmp_path / "out" / "dup.h5", output=tmp_path / "out" / "dup.h5",
                         match=r"dump5000.riser and .*dump5000.riser both start at timestep "
                               r"5000 with the same atoms: the same frames given twice .* "
                               r"leave one of them out")
    # a restart with reset_timestep 0: the same first timestep, but ITEM: TIME carries on
    reset = tmp_path / "reset"
    reset.mkdir()
    (reset / "a.dump").write_text(frame(0, time=0.0) + frame(1, time=0.05))
    (reset / "b.dump").write_text((frame(0, time=0.1) + frame(1, time=0.15)).replace(
        "TIMESTEP\n5000\n", "TIMESTEP\n10000\n"))
    code, _, err = cli("import", str(reset / "b.dump"), str(reset / "a.dump"), "-o",
                       tmp_path / "reset.h5", "--width", "0.09", "--height", "0.95")
    assert code == 0, err
    with Trajectories(tmp_path / "reset.h5") as t:
        np.testing.assert_allclose(t.times, [0.0, 0.05, 0.1, 0.15])
    notes = tmp_path / "notes.txt"
    notes.write_text("not a dump\n")
    assert_clean_failure("import", str(series / "dump*.riser"), str(notes), "-o",
                         tmp_path / "out" / "mixed.h5", output=tmp_path / "out" / "mixed.h5",
                         match=r"put the files of one series in one folder")


def test_a_2d_dump_read_with_z_as_the_vertical_is_refused_and_nothing_kept(
        tmp_path, assert_clean_failure):
    """A 2D dump (z the same for every atom) imported with --vertical-axis z put every
    particle at one height of a riser 1 mm high, and wrote it with warnings (exit 0): no
    pass, residence or model could come of it. It is refused in one line naming the
    option, and nothing is written; without the option the same dump imports."""
    frames = [(k * 1000, [f"{i} {0.01 + 0.02 * i} {0.1 + 0.05 * k + 0.2 * i} 0.0"
                          for i in range(1, 4)]) for k in range(6)]
    text = "".join(f"ITEM: TIMESTEP\n{ts}\nITEM: NUMBER OF ATOMS\n3\nITEM: BOX BOUNDS pp pp pp\n"
                   "0 0.09\n0 0.95\n-0.0005 0.0005\nITEM: ATOMS id x y z\n" + "\n".join(rows) + "\n"
                   for ts, rows in frames)
    source = tmp_path / "flat.dump"
    source.write_text(text)
    output = tmp_path / "out" / "run.h5"
    assert_clean_failure("import", source, "--format", "lammps", "-o", output, "--time-step",
                         "1e-5", "--vertical-axis", "z", output=output,
                         match=r"every particle lies at the height [0-9.e-]+ m in every frame read "
                               r"\(the vertical axis z\).*leave --vertical-axis out")
    got = read_back(import_lammps(source, tmp_path / "flat.h5", time_step=1e-5))
    assert got["positions"].shape == (6, 3, 2)


CENTRED_BOX = """ITEM: TIMESTEP
{step}
ITEM: NUMBER OF ATOMS
2
ITEM: BOX BOUNDS pp pp pp
-0.045 0.045
{lo} {hi}
-0.001 0.001
ITEM: ATOMS id type x y z
1 1 0.01 {y1} 0
2 1 -0.02 {y2} 0
"""


@pytest.mark.parametrize("lo, hi, fix", [(-0.475, 0.475, "give y as -0.475:0.475 (--region), or"),
                                         (0.0, 0.95, "give y as 0:0.95 (--region, or --height "
                                                     "0.95), or")])
def test_a_riser_that_is_not_the_periodic_box_names_the_options_that_can_give_it(
        tmp_path, lo, hi, fix):
    """A periodic riser other than the box's period: the fix names --height only where the
    box starts at 0 (--height sets 0..H; a centred box needs --region)."""
    source = tmp_path / "box.dump"
    y = (lo + 0.1, lo + 0.2)
    source.write_text("".join(CENTRED_BOX.format(step=s, lo=lo, hi=hi, y1=y[0] + d, y2=y[1] + d)
                              for s, d in ((0, 0.0), (1000, 0.01))))
    with pytest.raises(InputError, match=re.escape(fix)):
        import_lammps(source, tmp_path / "box.h5", time_step=1e-5, region=((-0.045, 0.045),
                                                                           (lo + 0.05, hi - 0.05)))
    import_lammps(source, tmp_path / "box.h5", time_step=1e-5,
                  region=((-0.045, 0.045), (lo, hi)))
    with Trajectories(tmp_path / "box.h5") as t:
        assert t.height == pytest.approx(0.95) and t.n_frames == 2
        assert repr(t).endswith("2 particles x 2 frames, 0..0.01 s, every 0.01 s, "
                                "source='import:lammps')")


def test_the_pieces_of_a_dump_written_per_processor_are_joined(tmp_path, make_run, make_dump,
                                                                assert_clean_failure):
    """A LAMMPS dump named with % writes one file per processor, each holding other atoms of
    every frame: given together (a pattern), their frames are joined, and the file equals
    the import of the whole dump. They were refused. Pieces of different timesteps are
    refused naming the pieces."""
    import dataclasses

    run = make_run(n_particles=8)
    whole = tmp_path / "whole.dump"
    whole.write_text(make_dump(run))
    folder = tmp_path / "pieces"
    folder.mkdir()
    for k, part in enumerate((np.arange(0, 8, 2), np.arange(1, 8, 2), np.arange(0))):
        piece = dataclasses.replace(run, ids=run.ids[part], positions=run.positions[:, part],
                                    velocities=run.velocities[:, part], laps=run.laps[:, part],
                                    unwrapped_y=run.unwrapped_y[:, part])
        (folder / f"dump.{k}.txt").write_text(make_dump(piece))   # processor 2 holds none
    options = dict(vertical_axis="y", drop_depth=True, width=run.width, height=run.height)
    import_file(whole, "lammps", tmp_path / "whole.h5", **options)
    import_file(str(folder / "dump.*.txt"), "lammps", tmp_path / "joined.h5", **options)
    with Trajectories(tmp_path / "whole.h5") as a, Trajectories(tmp_path / "joined.h5") as b:
        assert np.array_equal(a.ids, b.ids) and np.array_equal(a.times, b.times)
        assert np.array_equal(a.positions(slice(None)), b.positions(slice(None)))
        assert np.array_equal(a.laps(slice(None)), b.laps(slice(None)))
    text = (folder / "dump.1.txt").read_text()
    (folder / "dump.1.txt").write_text(text[:text.rindex("ITEM: TIME\n")])   # a frame short
    with pytest.raises(InputError, match=r"the pieces of one dump \(files starting at one "
                                         r"timestep\) hold other timesteps here"):
        import_file(str(folder / "dump.*.txt"), "lammps", tmp_path / "bad.h5", **options)
    assert not (tmp_path / "bad.h5").exists()
