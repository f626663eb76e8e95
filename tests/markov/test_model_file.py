"""The model file: compressed [S, S] datasets that round-trip exactly and that any HDF5 reader
reads as plain dense arrays, in a model file and attached to a prediction."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from cfbmarkov._hdf5 import create_array_dataset
from cfbmarkov.markov import CellGrid, MarkovModel, SecondOrderCells
from cfbmarkov.markov.model_file import model_datasets_and_attrs, write_model
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import TrajectoryWriter

SQUARE = ("transition_matrix", "counts", "counts_up", "counts_down", "pass_up_fraction",
          "pass_down_fraction")


def sparse_model(space, nnz: int = 7, seed: int = 0) -> MarkovModel:
    """A fitted-looking model: ``nnz`` random non-zeros per row of the counts, P = counts
    normalised by row, a few of the transitions passing the boundary."""
    s = space.n_states
    rng = np.random.default_rng(seed)
    counts = np.zeros((s, s), np.int64)
    cols = np.stack([rng.choice(s, nnz, replace=False) for _ in range(s)])
    counts[np.repeat(np.arange(s), nnz), cols.ravel()] = rng.integers(1, 400, s * nnz)
    up = np.where(rng.random((s, s)) < 0.02, counts // 3, 0)
    down = np.where(rng.random((s, s)) < 0.02, counts // 4, 0)
    p = counts / counts.sum(axis=1, keepdims=True)
    return MarkovModel(p, counts, up, down, space, 0.025, "mle", (10.0, 15.0), "run.h5", 5000)


@pytest.fixture(scope="session")
def big_model():
    """1596 states: the second-order chain on the paper's 6 x 38 cells."""
    return sparse_model(SecondOrderCells(6, 38))


def expected_arrays(model: MarkovModel) -> dict[str, np.ndarray]:
    datasets, _ = model_datasets_and_attrs(model)
    return datasets


def test_1596_state_model_is_small_and_round_trips_exactly(tmp_path, big_model):
    path = write_model(big_model, tmp_path / "model.h5")
    # 6 dense [1596, 1596] arrays of 8 bytes were 122 MB; 7 non-zeros per row compress to < 1 MB
    assert big_model.n_states == 1596
    assert path.stat().st_size < 3e6
    back = MarkovModel.load(path)
    for name in ("transition_matrix", "counts", "counts_up", "counts_down", "up_fraction",
                 "down_fraction", "unvisited_states"):
        a, b = getattr(big_model, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert (back.lag, back.window, back.estimator, back.source, back.frame_pairs) == \
        (0.025, (10.0, 15.0), "mle", "run.h5", 5000)
    assert back.state_space.describe() == big_model.state_space.describe()


def test_any_hdf5_reader_reads_dense_arrays(tmp_path, big_model):
    path = write_model(big_model, tmp_path / "model.h5")
    expected = expected_arrays(big_model)
    with h5py.File(path, "r") as f:        # plain h5py, no cfbmarkov
        p = f["transition_matrix"][()]
        assert isinstance(p, np.ndarray) and p.shape == (1596, 1596) and p.dtype == np.float64
        np.testing.assert_array_equal(p, big_model.transition_matrix)
        np.testing.assert_allclose(p.sum(axis=1), 1.0)
        c = f["counts"][()]
        assert c.shape == (1596, 1596) and c.dtype == np.int64
        np.testing.assert_array_equal(c, big_model.counts)
        for name in SQUARE:
            d = f[name]
            assert d.compression == "gzip" and d.chunks[1] == 1596 and not d.shuffle, name
            np.testing.assert_array_equal(d[()], expected[name])
        assert f["transition_matrix"][5, 7] == big_model.transition_matrix[5, 7]   # one element
        assert f.attrs["format"] == "cfbmarkov.model" and f.attrs["version"] == 1


def test_prediction_carries_the_same_compressed_group(tmp_path, big_model):
    path = tmp_path / "pred.h5"
    with TrajectoryWriter(path, [1, 2], width=0.09, height=0.95, source="markov-prediction",
                          frame_interval=0.025) as w:
        w.attach("model", *model_datasets_and_attrs(big_model))
        w.append_frames([0.0, 0.025], np.full((2, 2, 2), 0.05))
    assert path.stat().st_size < 3e6
    with Trajectories(path) as t:
        assert t.group("model")["transition_matrix"].compression == "gzip"
        back = MarkovModel.from_trajectories(t)
    for name in ("transition_matrix", "counts", "counts_up", "counts_down", "up_fraction",
                 "down_fraction"):
        assert np.array_equal(getattr(big_model, name), getattr(back, name)), name


def test_small_model_round_trips(tmp_path):
    model = sparse_model(CellGrid(2, 3), nnz=2, seed=4)         # 6 states: stored plain
    back = MarkovModel.load(model.save(tmp_path / "small.h5"))
    assert np.array_equal(back.transition_matrix, model.transition_matrix)
    assert np.array_equal(back.counts, model.counts)
    with h5py.File(tmp_path / "small.h5") as f:
        assert f["counts"].compression is None


def test_files_written_without_compression_still_read(tmp_path, big_model):
    datasets, attrs = model_datasets_and_attrs(big_model)
    with h5py.File(tmp_path / "plain.h5", "w") as f:
        for name, value in datasets.items():
            f.create_dataset(name, data=value)
        f.attrs.update(attrs)
    back = MarkovModel.load(tmp_path / "plain.h5")
    assert np.array_equal(back.transition_matrix, big_model.transition_matrix)


@pytest.mark.parametrize("shape, dtype, compressed", [
    ((64, 64), np.float64, True),           # 4096 elements
    ((63, 64), np.float64, False),
    ((5000,), np.int64, False),             # 1-D: plain
    ((0, 0), np.float64, False),
    ((300, 5000), np.float64, True),        # rows of 40 kB: 26 rows per chunk of ~1 MiB
    ((300, 5000), np.dtype(">i4"), True),   # big-endian, a partial last chunk
    ((40, 30, 9), np.int8, True),           # three dimensions in one chunk
])
def test_create_array_dataset(tmp_path, shape, dtype, compressed):
    value = np.arange(int(np.prod(shape)), dtype=dtype).reshape(shape)
    with h5py.File(tmp_path / "a.h5", "w") as f:
        d = create_array_dataset(f, "a", value)
        assert (d.compression == "gzip") == compressed
        if compressed:
            row = int(np.prod(shape[1:])) * np.dtype(dtype).itemsize
            assert d.chunks[1:] == shape[1:] and d.chunks[0] * row <= 1 << 20
        assert d.dtype == dtype and np.array_equal(d[()], value)
        if compressed:      # deflated chunks that HDF5's own filter reads back
            assert np.array_equal(d[3:7], value[3:7])


def test_a_predictions_copy_of_the_model_keeps_the_models_created_time(tmp_path):
    """The model a prediction carries (/provenance/model) keeps the time the model file was
    written, not the prediction's."""
    import h5py

    from cfbmarkov.markov import MarkovModel, fit_model
    from cfbmarkov.markov.states import CellGrid
    from cfbmarkov.synthetic import RiserFlow, write_run

    run = write_run(tmp_path / "r.h5", RiserFlow(), 60, 3.0, seed=1)
    path = fit_model(run, CellGrid(6, 38, 0.09, 0.95), 0.025, (0.5, 2.5)).save(tmp_path / "m.h5")
    with h5py.File(path, "r+") as f:            # as if fitted an hour before
        f.attrs["created"] = "2026-01-01T00:00:00+00:00"
    pred = MarkovModel.load(path).predict(run, 2.5, 0.2, seed=1, output=tmp_path / "p.h5")
    with h5py.File(pred) as f:
        assert f["provenance/model"].attrs["created"] == "2026-01-01T00:00:00+00:00"
        assert f.attrs["created"] != "2026-01-01T00:00:00+00:00"
