"""An open riser's trajectory file stores compactly the particles absent from most frames
(chunks of frames x particles, deflated for a prediction, blocks holding only absent
particles never written), and reads back exactly what was written; a periodic riser's
layout is unchanged."""

import zlib

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


@pytest.mark.parametrize("kind", ["position", "lap", "present"])
def test_chunks_deflated_in_threads_are_those_of_hdf5s_own_filters(tmp_path, kind):
    """Frames written from a chunk's first frame are deflated by zlib in threads and written
    as they are; the stored chunks hold the bytes HDF5's own shuffle and deflate filters
    store for the same values (decompressed, byte for byte), chunks of fill values are not
    written, and a later block that starts inside a chunk (HDF5 writes it) reads back too."""
    from cfbmarkov.trajectory_groups import create_frames, write_frame_rows

    present, positions = _few_present(n_particles=700, n_frames=70)
    values = {"position": np.where(present[..., None], positions, np.nan),
              "lap": np.where(present, np.arange(700) % 5 - 2, 0).astype(np.int32),
              "present": present}[kind]
    paths = {}
    for how in ("threads", "hdf5"):
        paths[how] = tmp_path / f"{how}.h5"
        with h5py.File(paths[how], "w") as f:
            create_frames(f, np.arange(700), 2, False, compact=True, deflate=True)
            if kind == "present":
                f.create_dataset("frames/present", shape=(0, 700), maxshape=(None, None),
                                 dtype="?", fillvalue=False, chunks=(16, 256),
                                 compression="gzip", compression_opts=1, shuffle=True)
            ds = f[f"frames/{kind}"]
            for i0, i1 in ((0, 32), (32, 51), (51, 70)):   # aligned, aligned, inside a chunk
                ds.resize(i1, axis=0)
                if how == "threads":
                    write_frame_rows(ds, i0, values[i0:i1], compact=True)
                else:
                    ds[i0:i1] = values[i0:i1]
    with h5py.File(paths["threads"]) as a, h5py.File(paths["hdf5"]) as b:
        x, y = a[f"frames/{kind}"], b[f"frames/{kind}"]
        np.testing.assert_array_equal(x[:], values)
        np.testing.assert_array_equal(y[:], values)
        stored = 0
        for i0 in range(0, 64, 16):     # the chunks wholly written by the first two blocks
            for j0 in range(0, 700, 256):
                corner = (i0, j0) + (0,) * (x.ndim - 2)
                chunk = values[i0:i0 + 16, j0:j0 + 256]
                empty = (not chunk.any()) if kind != "position" else np.isnan(chunk).all()
                if i0 == 48:            # written again by the block that starts inside it
                    continue
                if empty:
                    assert x.id.get_chunk_info_by_coord(corner).byte_offset is None
                    continue
                stored += 1
                assert (zlib.decompress(x.id.read_direct_chunk(corner)[1])
                        == zlib.decompress(y.id.read_direct_chunk(corner)[1]))
        assert stored > 3
