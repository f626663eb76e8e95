"""An open riser's trajectory file stores compactly the particles absent from most frames
(chunks of frames x particles, deflated for a prediction, blocks holding only absent
particles never written), and reads back exactly what was written; a periodic riser's
layout is unchanged."""

import h5py
import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.cli import main
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import TrajectoryWriter

FLOW = synthetic.RiserFlow(columns=4, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=False)


def _few_present(n_particles=3000, n_frames=400, seed=1):
    """Frames where each particle is present for 20 frames, about 8 at a time, in id order
    (as an open riser's prediction: newcomers enter one after the other)."""
    rng = np.random.default_rng(seed)
    present = np.zeros((n_frames, n_particles), bool)
    for j in range(n_particles):
        start = j * n_frames // n_particles
        present[start:start + 20, j] = True
    positions = np.stack([rng.uniform(0.001, 0.089, (n_frames, n_particles)),
                          rng.uniform(0.001, 0.949, (n_frames, n_particles))], axis=-1)
    return present, positions


@pytest.mark.parametrize("source, deflated, share", [("markov-prediction", True, 20),
                                                      ("test", False, 4)])
def test_open_file_is_compact_and_reads_back_exactly(tmp_path, source, deflated, share):
    """A prediction's chunks are deflated (a twentieth of the dense size here); a run's are
    not (fitting reads it as fast as a periodic run), its blocks of absent particles still
    unwritten (a quarter)."""
    present, positions = _few_present()
    n_frames, n = present.shape
    times = 0.025 * np.arange(n_frames)
    path = tmp_path / "open.h5"
    with TrajectoryWriter(path, np.arange(n), width=0.09, height=0.95, source=source,
                          boundary="open", frame_interval=0.025, max_step=1.0) as w:
        for i in range(0, n_frames, 37):          # blocks not aligned with the chunks
            k = slice(i, min(i + 37, n_frames))
            w.append_frames(times[k], positions[k], present=present[k])
    dense = n_frames * n * (2 * 8 + 4 + 1)        # positions, laps, presence uncompressed
    assert path.stat().st_size < dense / share, (path.stat().st_size, dense)
    with Trajectories(path) as t:
        np.testing.assert_array_equal(t.present(slice(None)), present)
        expected = np.where(present[..., None], positions, np.nan)
        np.testing.assert_array_equal(t.positions(slice(None)), expected)
        np.testing.assert_array_equal(t.laps(slice(None)), 0)
    with h5py.File(path) as f:
        assert f["frames/position"].chunks == (16, 256, 2)
        assert f["frames/position"].compression == ("gzip" if deflated else None)


def test_periodic_file_layout_is_unchanged(tmp_path):
    """A periodic file: one frame of its particles per chunk, uncompressed; with fewer than
    256 particles, as many frames of them as make about 256 values (no padding)."""
    path = synthetic.write_run(tmp_path / "run.h5", FLOW, 300, 0.5, seed=1)
    with h5py.File(path) as f:
        assert f["frames/position"].chunks == (1, 300, 2)
        assert f["frames/position"].compression is None
        assert f["frames/lap"].chunks == (1, 300)
    few = synthetic.write_run(tmp_path / "few.h5", FLOW, 30, 0.5, seed=1)
    with h5py.File(few) as f:
        assert f["frames/position"].chunks == (8, 30, 2)
        assert f["frames/lap"].chunks == (8, 30)


def test_open_riser_prediction_is_small_and_reads_the_same(tmp_path, capsys):
    run = synthetic.write_open_run(tmp_path / "open.h5", FLOW, 60, 6.0, seed=4)
    model, pred = tmp_path / "m.h5", tmp_path / "p.h5"
    assert main(["fit", str(run), "--cells", "4x8", "--window", "0:6", "--resamples", "0",
                 "-q", "-o", str(model)]) == 0
    assert main(["predict", str(model), "--init", str(run), "--start", "1", "--duration", "20",
                 "-q", "-o", str(pred)]) == 0
    with Trajectories(pred) as t:
        n, frames = t.n_particles, t.n_frames
        present = t.present(slice(None))
        assert 0 < present.sum(axis=1).max() < n / 4        # few present per frame
        assert np.isnan(t.positions(slice(None))[~present]).all()
    # every particle a column in every frame would be 21 bytes per entry
    assert pred.stat().st_size < frames * n * 21 / 5, (pred.stat().st_size, frames * n * 21)
    capsys.readouterr()
    assert main(["info", str(pred)]) == 0
    assert "particles present per frame" in capsys.readouterr().out
