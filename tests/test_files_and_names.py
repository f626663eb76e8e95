"""Inputs that are not files, output names near the length limit, one-line errors for
damaged files and names with a line break, and the segments of a run carrying its identity.
Each bad input ends in one line on stderr and exit code 2."""

import os
from pathlib import Path

import h5py
import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov._atomic import is_write_failure
from cfbmarkov._names import NAME_MAX, helper_stem, one_line, parts_folder
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.segmented import SegmentedTrajectoryWriter

FLOW = synthetic.RiserFlow(columns=3, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)
SMALL_CASE = """
name = "small"
seed = 3
[riser]
width = 0.09
height = 0.2
[particles]
number = 200
[gas]
superficial_velocity = 6.0
[numerics]
cfd_cells = [9, 20]
dem_cells = [30, 74]
[output]
end_time = 0.05
"""


@pytest.fixture(scope="session")
def good(tmp_path_factory):
    folder = tmp_path_factory.mktemp("files")
    run = synthetic.write_run(folder / "run.h5", FLOW, 40, 2.0, seed=2)
    model = folder / "model.h5"
    assert main(["fit", str(run), "--cells", "4x8", "--window", "0:1.5", "--resamples", "0",
                 "-q", "-o", str(model)]) == 0
    return run, model


def one_line_error(capsys, argv, output=None):
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 2
    err = "\n".join(line for line in capsys.readouterr().err.splitlines()
                     if not line.startswith("note: "))       # the DEM time-step advisory
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    if output is not None:
        assert not Path(output).exists()
    return err


def stray(folder: Path, expected) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name not in expected)


# -- pipes ------------------------------------------------------------------------------------
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes")
@pytest.mark.parametrize("verb", ["import", "fit", "info"])
def test_a_pipe_is_refused_as_a_pipe_not_as_empty(good, tmp_path, capsys, verb):
    fifo = tmp_path / "data.csv"
    os.mkfifo(fifo)
    argv = {"import": ["import", fifo, "--width", "0.045", "--height", "1", "-o",
                       tmp_path / "o.h5"],
            "fit": ["fit", fifo, "--cells", "4x8", "-o", tmp_path / "o.h5"],
            "info": ["info", fifo]}[verb]
    err = one_line_error(capsys, argv, tmp_path / "o.h5")
    assert "is a pipe" in err and "save it to a file first" in err
    assert "empty" not in err


# -- output names near the limit ----------------------------------------------------------------
def test_helper_names_of_a_long_name_stay_within_the_limit():
    for length in (10, 235, 236, 245, 255):
        name = "a" * (length - 3) + ".h5"
        stem = helper_stem(name)
        assert len(os.fsencode(f".{stem}.abcdefgh.tmp.json")) <= NAME_MAX
        assert (stem == name) == (length <= 235)
    assert helper_stem("a" * 250 + "1") != helper_stem("a" * 250 + "2")
    assert len(os.fsencode(helper_stem("é" * 127))) <= NAME_MAX - 20      # 254 bytes
    assert parts_folder(Path("x") / ("b" * 252)).name.endswith(".parts")
    assert len(parts_folder("b" * 252).name) <= NAME_MAX


@pytest.mark.parametrize("length", [245, 255])
def test_legal_long_output_names_are_written(good, tmp_path, capsys, length):
    run, model = good
    out = tmp_path / ("m" * (length - 3) + ".h5")
    assert main(["fit", str(run), "--cells", "4x8", "--window", "0:1.5", "--resamples", "0",
                 "-q", "-o", str(out)]) == 0
    pred = tmp_path / ("p" * (length - 3) + ".h5")
    assert main(["predict", str(model), "--init", str(run), "--start", "0.5", "--duration",
                 "0.5", "-q", "-o", str(pred)]) == 0
    assert out.is_file() and pred.is_file()
    assert stray(tmp_path, [out.name, pred.name]) == []      # no lock or temporary left


def test_an_output_name_past_the_limit_is_refused_naming_it(good, tmp_path, capsys):
    run, _ = good
    out = tmp_path / ("m" * 254 + ".h5")
    err = one_line_error(capsys, ["fit", run, "--cells", "4x8", "-o", out])
    assert "257 bytes" in err and "limit of 255" in err
    assert stray(tmp_path, []) == []


def test_an_output_inside_a_file_names_the_file(good, tmp_path, capsys):
    """-o model.h5/o.h5 where model.h5 is a file: said as such ("cannot create its folder
    model.h5 (File exists)" read as if a folder were in the way)."""
    run, _ = good
    (tmp_path / "model.h5").write_bytes(b"x")
    err = one_line_error(capsys, ["fit", run, "--cells", "4x8", "-o",
                                  tmp_path / "model.h5" / "a" / "o.h5"])
    assert f"{tmp_path / 'model.h5'} is a file, not a folder" in err
    assert (tmp_path / "model.h5").read_bytes() == b"x"


def test_segments_of_a_long_output_name(tmp_path):
    out = tmp_path / ("s" * 250 + ".h5")
    writer = SegmentedTrajectoryWriter(out, np.arange(3), width=0.1, height=1.0,
                                       source="test", run_id="r1")
    writer.append(0.0, np.full((3, 2), 0.05))
    writer.append(0.1, np.full((3, 2), 0.06))
    writer.close_segment()
    assert writer.parts.is_dir() and len(writer.parts.name) <= NAME_MAX
    writer.finish()
    assert out.is_file() and not writer.parts.exists()


# -- one line: damaged checkpoints, names with a line break, damaged models -----------------------
def _damaged(data: bytes, how: str) -> bytes:
    n = len(data)
    if how == "truncated":
        return data[:n // 2]
    if how == "zeroed":
        return data[:n // 2] + bytes(n - n // 2)
    if how == "random":
        return data[:512] + np.random.default_rng(1).bytes(n - 512)
    return bytes(n)


@pytest.mark.parametrize("how", ["truncated", "zeroed", "random", "all-zero"])
def test_a_damaged_checkpoint_is_one_line(tmp_path, capsys, how):
    case = tmp_path / "small.toml"
    case.write_text(SMALL_CASE)
    parts = tmp_path / "s.h5.parts"
    parts.mkdir()
    good = tmp_path / "good.h5"
    with h5py.File(good, "w") as f:     # a checkpoint's attributes and groups, then damaged
        from cfbmarkov.config import load_case

        f.attrs["case"] = load_case(case).model_dump_json()
        for key in ("version", "n_segments", "frames", "wall_time", "cfd_steps"):
            f.attrs[key] = 1
        f.create_group("dem").create_dataset("positions", data=np.zeros((200, 2)))
        f.create_group("gas").create_dataset("pressure", data=np.zeros((20, 9)))
    (parts / "checkpoint.h5").write_bytes(_damaged(good.read_bytes(), how))
    err = one_line_error(capsys, ["simulate", case, "-o", tmp_path / "s.h5", "--resume", "-q"],
                         tmp_path / "s.h5")
    assert "checkpoint" in err and ("damaged" in err or "not a readable" in err), err


def test_names_with_a_line_break_are_one_line(good, tmp_path, capsys):
    err = one_line_error(capsys, ["info", tmp_path / "no\nsuch.h5"])
    assert "no\\nsuch.h5" in err
    run, _ = good
    odd = tmp_path / "r\nun.h5"
    odd.write_bytes(run.read_bytes())
    capsys.readouterr()
    assert main(["fit", str(odd), "--cells", "4x8", "--window", "0:1.5", "--resamples", "0",
                 "-q", "-o", str(tmp_path / "m.h5")]) == 0
    for line in capsys.readouterr().err.splitlines():
        assert line.startswith(("warning: ", "note: ")), line
    assert one_line("a\nb\tc\x00") == "a\\nb c\\x00"


@pytest.mark.parametrize("verb", ["info", "predict", "rtd"])
def test_a_damaged_model_is_named_as_damaged(good, tmp_path, capsys, verb):
    run, model = good
    data = model.read_bytes()
    bad = tmp_path / "bad.h5"
    bad.write_bytes(data[:len(data) // 2] + bytes(len(data) - len(data) // 2))
    out = tmp_path / "p.h5"
    argv = {"info": ["info", bad], "rtd": ["rtd", bad],
            "predict": ["predict", bad, "--init", run, "--start", "0.5", "--duration", "0.5",
                        "-o", out]}[verb]
    err = one_line_error(capsys, argv, out)
    assert "bad.h5" in err and ("damaged" in err or "not a readable" in err), err
    assert "cannot write" not in err


def test_an_hdf5_read_error_is_not_a_write_failure():
    assert not is_write_failure(OSError("Unable to synchronously read data (inflate() failed)"))
    assert not is_write_failure(OSError("Unable to synchronously open object (unable to "
                                        "determine object type)"))
    assert is_write_failure(OSError(28, "No space left on device"))
    assert is_write_failure(OSError("Can't write data (file write failed: errno = 27)"))


# -- a run's segments carry its identity ---------------------------------------------------------
def _segments(output: Path, run_id: str, n: int, start: float = 0.0):
    writer = SegmentedTrajectoryWriter(output, np.arange(3), width=0.1, height=1.0,
                                       source="test", run_id=run_id)
    t = start
    for _ in range(n):
        for _ in range(2):
            writer.append(t, np.full((3, 2), 0.05 + t / 100))
            t += 0.1
        writer.close_segment()
    return writer


def test_resume_refuses_a_segment_of_another_run(tmp_path):
    _segments(tmp_path / "a.h5", "run-a", 2)
    _segments(tmp_path / "b.h5", "run-b", 2)
    options = dict(ids=np.arange(3), width=0.1, height=1.0, source="test")
    resumed = SegmentedTrajectoryWriter.resume(tmp_path / "a.h5", 2, run_id="run-a", **options)
    assert resumed.n_segments == 2
    (tmp_path / "a.h5.parts" / "segment-00001.h5").write_bytes(
        (tmp_path / "b.h5.parts" / "segment-00001.h5").read_bytes())
    with pytest.raises(InputError, match="not a segment of this run"):
        SegmentedTrajectoryWriter.resume(tmp_path / "a.h5", 2, run_id="run-a", **options)


def test_a_failed_start_of_simulate_leaves_no_parts_folder(tmp_path, monkeypatch):
    from cfbmarkov.config import load_case
    from cfbmarkov.simulate.run import simulate

    case = tmp_path / "small.toml"
    case.write_text(SMALL_CASE)

    def full(self, *args, **kwargs):
        raise InputError(f"{self.parts}/segment-00000.h5: cannot write (No space left on device)")

    monkeypatch.setattr(SegmentedTrajectoryWriter, "append", full)
    with pytest.raises(InputError, match="No space left"):
        simulate(load_case(case), tmp_path / "s.h5", progress=False)
    assert stray(tmp_path, ["small.toml"]) == []


# -- simulate's memory and disk, estimated before anything is allocated --------------------------
def test_simulate_refuses_a_run_that_does_not_fit_in_memory(tmp_path, capsys, monkeypatch):
    case = tmp_path / "small.toml"
    case.write_text(SMALL_CASE)
    monkeypatch.setenv("CFBMARKOV_MEMORY_LIMIT", "20000000")
    err = one_line_error(capsys, ["simulate", case, "-o", tmp_path / "s.h5", "-q"],
                         tmp_path / "s.h5")
    assert "CFD-DEM run of 200 particles" in err and "of memory" in err
    assert stray(tmp_path, ["small.toml"]) == []


def test_simulate_refuses_an_output_larger_than_the_free_disk(tmp_path, capsys, monkeypatch):
    from cfbmarkov import limits

    case = tmp_path / "small.toml"
    case.write_text(SMALL_CASE.replace("end_time = 0.05", "end_time = 2000"))
    monkeypatch.setattr(limits, "free_disk", lambda folder: 50e6)
    err = one_line_error(capsys, ["simulate", case, "-o", tmp_path / "s.h5", "-q"],
                         tmp_path / "s.h5")
    assert "on disk" in err and "200 particles" in err and "--until" in err
    assert stray(tmp_path, ["small.toml"]) == []


def test_a_read_error_inside_h5py_names_the_damaged_file(tmp_path):
    from cfbmarkov.cli.command import _damaged_input

    path = tmp_path / "d.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("x", data=np.arange(4096.0).reshape(64, 64), chunks=(64, 64),
                         compression="gzip")
    with h5py.File(path, "r") as f:
        offset = f["x"].id.get_chunk_info(0).byte_offset
    data = bytearray(path.read_bytes())
    data[offset:offset + 64] = bytes(64)
    path.write_bytes(bytes(data))

    def read(handle):
        return handle["x"][()]

    with h5py.File(path, "r") as f:
        with pytest.raises(OSError) as caught:
            read(f)
        message = _damaged_input(caught.value)
    assert message.startswith(f"{path}: damaged file, cannot be read (")
    assert "\n" not in message
    assert _damaged_input(KeyError("not from h5py")) is None


def test_the_current_folder_as_an_output_is_refused_in_one_line(good, tmp_path, capsys,
                                                                 monkeypatch):
    """``-o .`` (and ``./``, ``dir/..``, ``/``) for a verb that writes a folder, and a
    folder above the current one (replaced whole, it would leave the shell in a deleted
    folder): one line each, no traceback, nothing written."""
    run, _ = good
    work = tmp_path / "work"
    (work / "sub").mkdir(parents=True)
    monkeypatch.chdir(work / "sub")
    for output in (".", "./", "..", "sub/..", "/", ""):
        err = one_line_error(capsys, ["export-vtk", run, "-o", output, "-q"])
        assert ("names no file or folder of its own" if output else "an empty output name"
                ) in err, (output, err)
    for output in (str(work), "../../work", "../sub/../../work"):
        err = one_line_error(capsys, ["export-vtk", run, "-o", output, "-q"])
        assert "holds the current folder" in err, output
    (tmp_path / "link").symlink_to(work)
    err = one_line_error(capsys, ["export-vtk", run, "-o", str(tmp_path / "link"), "-q"])
    assert "holds the current folder" in err
    (tmp_path / "link").unlink()
    assert sorted(p.name for p in work.rglob("*")) == ["sub"]
    with pytest.raises(InputError, match="names no file or folder of its own"):
        parts_folder(".")


def test_free_lock_files_are_removed_and_held_ones_kept(tmp_path):
    import fcntl

    from cfbmarkov._outputs import remove_free_locks

    (tmp_path / "u4").mkdir()
    free, held = tmp_path / "u4" / ".cfd-dem.h5.lock", tmp_path / ".report.html.lock"
    free.write_text('{"pid": 1}')
    held.write_text("{}")
    fd = os.open(held, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        assert remove_free_locks(tmp_path) == [free]
        assert not free.exists() and held.exists()
    finally:
        os.close(fd)
    assert remove_free_locks(tmp_path) == [held] and not held.exists()


def test_a_run_of_another_riser_given_to_a_model_names_the_fix(good, tmp_path, capsys):
    """The message names the command line's fix, not only the Python API's."""
    from dataclasses import replace

    _, model = good
    wide = synthetic.write_run(tmp_path / "wide.h5", replace(FLOW, width=0.2), 40, 2.0, seed=2)
    err = one_line_error(capsys, ["predict", model, "--init", wide, "--start", 1.0,
                                  "--duration", 0.5, "-q", "-o", tmp_path / "p.h5"],
                         tmp_path / "p.h5")
    assert "but" in err and "0.2 x 0.95 m" in err
    assert "give a run of that riser, or fit a model on this one" in err


def test_a_folders_name_given_where_a_file_is_written(good, tmp_path, capsys):
    run, _ = good
    err = one_line_error(capsys, ["fit", run, "--cells", "4x8", "--window", "0:1.5", "-o",
                                  f"{tmp_path}/newdir/"])
    assert "a folder's name, where this verb writes one file; give the file's name (e.g. " \
        f"{tmp_path}/newdir/model.h5: the folder is created)" in err
    assert not (tmp_path / "newdir").exists()
