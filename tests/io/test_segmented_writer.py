"""Crash-safe segmented output: segments, resume after a crash, merge."""

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.segmented import SegmentedTrajectoryWriter
from cfbmarkov.trajectories import Trajectories

W, H = 0.09, 0.95


def frames(n_frames, n=5, seed=0):
    rng = np.random.default_rng(seed)
    y = (np.linspace(0.1, 0.9, n)[None] + 0.3 * np.arange(n_frames)[:, None]) % H
    x = rng.uniform(0, W, (n_frames, n))
    return 0.025 * np.arange(n_frames), np.stack([x, y], axis=-1)


def options():
    return dict(ids=np.arange(5), width=W, height=H, source="test", with_velocity=False,
                frame_interval=0.025)


def test_segments_merge_into_one_file(tmp_path):
    times, pos = frames(10)
    # laps consistent with the positions (a pass up where the height drops), as read checks
    laps = np.concatenate([np.zeros((1, 5), int),
                           np.cumsum(np.diff(pos[..., 1], axis=0) < -H / 2, axis=0)])
    out = tmp_path / "run.h5"
    w = SegmentedTrajectoryWriter(out, **options())
    for k in range(10):
        w.append(times[k], pos[k], lap=laps[k])
        if k % 4 == 3:
            assert w.close_segment() == (k + 1) // 4
    w.add_events([0.11, 0.01], [1, 2], [1, -1])
    assert not out.exists()
    w.finish()
    assert not (tmp_path / "run.h5.parts").exists()
    with Trajectories(out) as t:
        np.testing.assert_array_equal(t.positions(), pos)
        np.testing.assert_allclose(t.times, times)
        assert t.laps()[:, 0].tolist() == laps[:, 0].tolist()
        np.testing.assert_allclose(t.events().time, [0.01, 0.11])


def test_resume_discards_what_followed_the_checkpoint(tmp_path):
    times, pos = frames(12)
    out = tmp_path / "run.h5"
    w = SegmentedTrajectoryWriter(out, **options())
    for k in range(6):
        w.append(times[k], pos[k])
    checkpoint = w.close_segment()
    for k in range(6, 9):          # written after the checkpoint, then the run dies
        w.append(times[k], pos[k])
    w.close_segment()
    w2 = SegmentedTrajectoryWriter.resume(out, checkpoint, **options())
    assert w2.n_segments == 1
    for k in range(6, 12):
        w2.append(times[k], pos[k])
    w2.finish()
    with Trajectories(out) as t:
        np.testing.assert_array_equal(t.positions(), pos)
        assert t.n_frames == 12
        # laps are continued across the resume from the positions
        assert t.laps()[-1].max() >= 1
    with pytest.raises(InputError, match="segment segment-00000.h5 is missing"):
        SegmentedTrajectoryWriter.resume(tmp_path / "other.h5", 1, **options())


def test_abort_removes_a_segment_whose_writer_never_finished_opening(tmp_path):
    # an interrupt between the temporary file's creation and the writer's return leaves a
    # temporary segment the segmented writer does not hold: abort still removes it
    times, pos = frames(4)
    out = tmp_path / "run.h5"
    w = SegmentedTrajectoryWriter(out, **options())
    w.append(times[0], pos[0])
    w.close_segment()
    stray = w.parts / ".segment-00001.h5.abc123.tmp"
    stray.write_bytes(b"half")
    other = w.parts / ".segment-00007.h5.zzz.tmp.keep"
    other.write_bytes(b"not ours")
    w.abort()
    assert not stray.exists() and other.exists()
    assert (w.parts / "segment-00000.h5").exists()
