"""The trajectory store: round trips through TrajectoryWriter / write_trajectories and
Trajectories, validation on write, and damaged or foreign HDF5 files on read."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import FORMAT, PassEvents, lap_increments
from cfbmarkov.trajectory_writer import TrajectoryWriter, write_trajectories


def write_run(path, run, **kwargs):
    return write_trajectories(path, run.times, run.positions, width=run.width, height=run.height,
                              ids=run.ids, velocities=run.velocities, **kwargs)


# -- round trips ----------------------------------------------------------------------------------
def test_write_and_read_back_whole_arrays(tmp_path, run):
    events = PassEvents(np.array([0.61, 0.55]), np.array([0, 2]), np.array([1, -1]))
    path = write_run(tmp_path / "run.h5", run, source="test", parameters={"seed": 7, "u": 4.0},
                     events=events)
    with Trajectories(path) as t:
        np.testing.assert_array_equal(t.ids, run.ids)
        np.testing.assert_array_equal(t.times, run.times)
        np.testing.assert_array_equal(t.positions(), run.positions)
        np.testing.assert_array_equal(t.velocities(), run.velocities)
        np.testing.assert_array_equal(t.laps(), run.laps)
        np.testing.assert_array_equal(t.positions(3), run.positions[3])
        np.testing.assert_array_equal(t.laps(slice(2, 5)), run.laps[2:5])
        assert (t.width, t.height) == (run.width, run.height)
        assert t.source == "test" and t.parameters == {"seed": 7, "u": 4.0}
        assert t.frame_interval == pytest.approx(0.025)
        assert t.attrs["format"] == FORMAT and t.attrs["length_unit"] == "m"
        assert t.attrs["time_unit"] == "s"
        got = t.events()
        np.testing.assert_array_equal(got.time, [0.55, 0.61])  # sorted by time
        np.testing.assert_array_equal(got.particle, [2, 0])
        np.testing.assert_array_equal(got.direction, [-1, 1])
        assert "6 particles x 16 frames" in repr(t)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5"]


def test_frame_by_frame_equals_whole_arrays(tmp_path, run):
    write_run(tmp_path / "whole.h5", run)
    with TrajectoryWriter(tmp_path / "frames.h5", run.ids, width=run.width, height=run.height,
                          source="test", with_velocity=True) as w:
        w.append(run.times[0], run.positions[0], run.velocities[0])
        w.append_frames(run.times[1:4], run.positions[1:4], run.velocities[1:4])
        for k in range(4, run.times.size):
            w.append(run.times[k], run.positions[k], run.velocities[k])
    with Trajectories(tmp_path / "whole.h5") as a, Trajectories(tmp_path / "frames.h5") as b:
        np.testing.assert_array_equal(a.positions(), b.positions())
        np.testing.assert_array_equal(a.laps(), b.laps())
        np.testing.assert_array_equal(a.times, b.times)
        blocks = list(b.iter_frames(block=5))
        assert [len(times) for times, _, _ in blocks] == [5, 5, 5, 1]
        np.testing.assert_array_equal(np.concatenate([p for _, p, _ in blocks]), a.positions())


def test_frames_located_by_time(tmp_path, run):
    with Trajectories(write_run(tmp_path / "run.h5", run)) as t:
        assert t.frame_index(0.6) == 4
        assert t.window(0.55, 0.65) == slice(2, 7)
        assert t.lag_frames(0.05) == 2
        with pytest.raises(InputError, match=r"no frame at t = 0.61 s"):
            t.frame_index(0.61)
        # partly inside: the part inside and a window of the same length that fits
        with pytest.raises(InputError, match=r"lies partly outside the data .*\(0.5 to 0.875 s\); "
                                             r"only 0.5:0.6 s lies inside: choose one within "
                                             r"it, e.g. 0.5:0.7 \(the same length\)"):
            t.window(0.4, 0.6)
        with pytest.raises(InputError, match=r"lies outside the data .*e.g. 0.675:0.875"):
            t.window(1.0, 1.2)
        with pytest.raises(InputError, match=r"e.g. 0.5:0.875 \(all of it\)"):
            t.window(0.0, 2.0)
        with pytest.raises(InputError, match=r"not a whole multiple"):
            t.lag_frames(0.03)


def test_window_suggestions_have_few_digits_and_are_accepted(tmp_path):
    """Frames off the round numbers (0.000459185 + k * 0.005 s): the suggested window is
    written with the fewest digits that select the same frames, and it is accepted."""
    times = 0.000459185 + 0.005 * np.arange(157)
    pos = np.tile([0.045, 0.4], (157, 1, 1))
    path = write_trajectories(tmp_path / "p.h5", times, pos, width=0.09, height=0.95)
    with Trajectories(path) as t:
        with pytest.raises(InputError, match=r"only 0\.00046:0\.29 s lies inside: .*"
                                             r"e\.g\. 0\.00046:0\.29046 \(the same length\)$"):
            t.window(0.0, 0.29)
        assert t.window(0.00046, 0.29046) == t.window(times[0], times[0] + 0.29) == slice(0, 59)
        with pytest.raises(InputError, match=r"e\.g\. 0\.00046:0\.78046 \(all of it\)$"):
            t.window(0.0, 2.0)
        assert t.window(0.00046, 0.78046) == slice(0, 157)
        with pytest.raises(InputError, match=r"e\.g\. 0\.38046:0\.78046 \(the same length\)$"):
            t.window(0.5, 0.9)


def test_lap_increments_minimal_image():
    np.testing.assert_array_equal(
        lap_increments(np.array([0.9, 0.05, 0.5, 0.2]), np.array([0.05, 0.9, 0.6, 0.1]), 0.95),
        [1, -1, 0, 0])


# -- validation on write ----------------------------------------------------------------------------
@pytest.mark.parametrize("change, match", [
    (lambda t, p: (t, np.where(p == p[2, 1, 0], np.nan, p)),
     r"position of particle .* finite number \(a particle out of view is left out of its "
     r"frame: present False\)"),
    (lambda t, p: (t, p + np.array([0.1, 0.0])), r"lies outside the domain"),
    (lambda t, p: (t[::-1], p), r"time goes back from t ="),
    (lambda t, p: (t ** 1.5, p), r"frames unevenly spaced"),
])
def test_writer_refuses_bad_frames_and_leaves_no_file(tmp_path, run, change, match):
    times, positions = change(run.times.copy(), run.positions.copy())
    with pytest.raises(InputError, match=match):
        write_trajectories(tmp_path / "bad.h5", times, positions, width=run.width,
                           height=run.height)
    assert list(tmp_path.iterdir()) == []


def test_present_and_laps_laid_out_otherwise_are_refused_not_reshaped(tmp_path, run):
    """(T, N) is the layout: a present mask or lap counters given (N, T), or flat, were
    reshaped into another frame and particle (particle 3's absence became frames' of 10
    particles)."""
    t, n = run.times.size, run.positions.shape[1]
    assert t != n
    present = np.ones((t, n), bool)
    present[1:3, 3] = False
    for layout in (present.T, present.ravel()):
        with pytest.raises(InputError, match=rf"expected present of shape \({t}, {n}\)"):
            write_trajectories(tmp_path / "bad.h5", run.times, run.positions, width=run.width,
                               height=run.height, present=layout)
        assert list(tmp_path.iterdir()) == []
    laps = np.zeros((t, n), np.int64)
    for layout in (laps.T, laps.ravel()):
        with pytest.raises(InputError, match=rf"laps: whole numbers of shape \({t}, {n}\)"):
            write_trajectories(tmp_path / "bad.h5", run.times, run.positions, width=run.width,
                               height=run.height, laps=layout)
        assert list(tmp_path.iterdir()) == []


def test_writer_without_frames_or_with_bad_ids(tmp_path):
    writer = TrajectoryWriter(tmp_path / "empty.h5", [1, 2], width=0.09, height=0.95,
                              source="test")
    with pytest.raises(InputError, match=r"no frames to write"):
        writer.close()
    with pytest.raises(InputError, match=r"particle ids are not unique"):
        TrajectoryWriter(tmp_path / "dup.h5", [1, 1], width=0.09, height=0.95, source="test")
    with pytest.raises(InputError, match=r"positive size"):
        TrajectoryWriter(tmp_path / "flat.h5", [1], width=0.09, height=0.0, source="test")
    assert list(tmp_path.iterdir()) == []


def test_interrupted_writer_leaves_no_file(tmp_path, run):
    writer = TrajectoryWriter(tmp_path / "run.h5", run.ids, width=run.width, height=run.height,
                              source="test")
    with pytest.raises(KeyboardInterrupt), writer as w:
        w.append(run.times[0], run.positions[0])
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


# -- bad files on read --------------------------------------------------------------------------------
def truncated(tmp_path, run):
    data = write_run(tmp_path / "good.h5", run).read_bytes()
    path = tmp_path / "truncated.h5"
    path.write_bytes(data[: len(data) // 2])
    return path


def foreign(tmp_path, run):
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("frames/position", data=run.positions)
        f.attrs["creator"] = "someone else"
    return path


def model_file(tmp_path, run):
    path = tmp_path / "model.h5"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "cfbmarkov.model"
        f.create_dataset("transition_matrix", data=np.eye(2))
    return path


def other_format(tmp_path, run):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "h5md"
    return path


def damaged(tmp_path, run):
    path = write_run(tmp_path / "damaged.h5", run)
    with h5py.File(path, "a") as f:
        del f["frames/lap"]
    return path


def mismatched(tmp_path, run):
    path = write_run(tmp_path / "mismatched.h5", run)
    with h5py.File(path, "a") as f:
        del f["particles/id"]
        f["particles/id"] = np.arange(3)
    return path


def no_width(tmp_path, run):
    path = write_run(tmp_path / "nowidth.h5", run)
    with h5py.File(path, "a") as f:
        del f.attrs["width"]
    return path


def bad_parameters(tmp_path, run):
    path = write_run(tmp_path / "params.h5", run)
    with h5py.File(path, "a") as f:
        f.attrs["parameters"] = "{not json"
    return path


def text_file(tmp_path, run):
    path = tmp_path / "run.csv"
    path.write_text("t,id,x,y\n0,1,0.01,0.1\n")
    return path


def empty_file(tmp_path, run):
    path = tmp_path / "empty.h5"
    path.write_bytes(b"")
    return path


def missing_file(tmp_path, run):
    return tmp_path / "missing.h5"


BAD_STORES = {
    "truncated": (truncated,
                  r"truncated.h5: not a readable HDF5 file: truncated \(copy it or write it again"),
    "foreign": (foreign, r"not a cfbmarkov trajectory file \(no 'format' attribute\)"),
    "model": (model_file, r"a cfbmarkov model file, not a trajectory file"),
    "other-format": (other_format,
                     r"not a cfbmarkov trajectory file \(format attribute is 'h5md'\)"),
    "damaged": (damaged, r"damaged trajectory file \(no 'frames/lap' dataset\)"),
    "mismatched": (mismatched, r"frame arrays do not match 16 times x 3 particles"),
    "no-width": (no_width, r"damaged trajectory file"),
    "bad-parameters": (bad_parameters, r"damaged trajectory file"),
    "text": (text_file, r"run.csv: not a readable HDF5 file"),
    "empty": (empty_file, r"empty.h5: empty file"),
    "missing": (missing_file, r"missing.h5: no such file"),
}


@pytest.mark.parametrize("case", sorted(BAD_STORES))
def test_bad_store_raises_input_error(tmp_path, run, case):
    make, match = BAD_STORES[case]
    path = make(tmp_path, run)
    with pytest.raises(InputError, match=match):
        Trajectories(path)


@pytest.mark.parametrize("case", ["truncated", "foreign", "other-format", "damaged", "text",
                                  "empty", "missing"])
def test_bad_store_through_cli_info(tmp_path, run, cli, case):
    code, out, err = cli("info", BAD_STORES[case][0](tmp_path, run))
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].startswith("cfbmarkov info: error: ")


def test_model_file_is_named_as_such(tmp_path, run):
    with pytest.raises(InputError) as info:
        Trajectories(model_file(tmp_path, run))
    assert "not a cfbmarkov model file" not in str(info.value)
    assert "a cfbmarkov model file, not a trajectory file" in str(info.value)


def test_parameters_are_json(tmp_path, run):
    path = write_run(tmp_path / "run.h5", run,
                     parameters={"array": np.arange(3), "value": np.float32(0.5),
                                 "path": tmp_path})
    with h5py.File(path) as f:
        stored = json.loads(f.attrs["parameters"])
    assert stored == {"array": [0, 1, 2], "value": 0.5, "path": str(tmp_path)}


@pytest.mark.parametrize("stage", ["open", "create"])
def test_writer_interrupted_while_it_opens_leaves_no_file(tmp_path, run, monkeypatch, stage):
    # Ctrl-C can land while the constructor opens the file or creates its datasets, before
    # the caller holds the writer to abort it: the constructor itself must clean up
    import cfbmarkov.trajectory_writer as tw

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    if stage == "open":
        monkeypatch.setattr(tw.h5py, "File", interrupted)
    else:
        monkeypatch.setattr(tw.TrajectoryWriter, "_create", interrupted)
    with pytest.raises(KeyboardInterrupt):
        TrajectoryWriter(tmp_path / "run.h5", run.ids, width=run.width, height=run.height,
                         source="test")
    assert list(tmp_path.iterdir()) == []


def test_an_open_files_times_and_ids_are_read_only(tmp_path, run):
    """Every later answer reads an open file's times and ids (windows, frames, a fit's
    provenance): shifting them in place (``t.times[:] -= 10``) made a fit on 10-15 s say it
    was of 0-5 s; they are now read-only."""
    path = write_run(tmp_path / "r.h5", run)
    with Trajectories(path) as t:
        for name in ("times", "ids"):
            with pytest.raises(ValueError, match="read-only"):
                getattr(t, name)[:] = 0
        assert t.times[0] == run.times[0]


def test_write_trajectories_replaces_a_run_but_not_a_file_of_another_kind(tmp_path):
    """As `cfbmarkov import` replaces a model file only with --force: writing arrays over a
    model or a text file is refused unless force=True (it had replaced a model silently)."""
    from cfbmarkov.errors import InputError
    from cfbmarkov.trajectory_writer import write_trajectories

    times = np.array([0.0, 0.1])
    positions = np.full((2, 3, 2), 0.5)
    target = tmp_path / "run.h5"
    write_trajectories(target, times, positions, width=1.0, height=1.0)
    write_trajectories(target, times, positions, width=1.0, height=1.0)     # a run: replaced
    text = tmp_path / "notes.h5"
    text.write_text("my notes")
    with pytest.raises(InputError, match=r"notes.h5: exists and is .*force=True"):
        write_trajectories(text, times, positions, width=1.0, height=1.0)
    assert text.read_text() == "my notes"
    write_trajectories(text, times, positions, width=1.0, height=1.0, force=True)
    with Trajectories(text) as t:
        assert t.n_frames == 2
