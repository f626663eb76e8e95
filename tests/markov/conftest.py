import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.trajectory_writer import write_trajectories


@pytest.fixture(scope="session")
def markov_flow():
    """A small riser-like chain on cells (no hidden state): 4 columns x 16 rows."""
    return synthetic.RiserFlow(columns=4, rows=16, rise_velocity=1.2, fall_velocity=-0.6,
                               vertical_spread=0.5, persistence=False)


@pytest.fixture(scope="session")
def markov_run(tmp_path_factory, markov_flow):
    """2000 particles x 8 s sampled from ``markov_flow``."""
    path = tmp_path_factory.mktemp("markov") / "run.h5"
    synthetic.write_run(path, markov_flow, 2000, 8.0, seed=11)
    return path


@pytest.fixture
def write_states():
    return _write_states


def _write_states(path, states, columns, rows, width=1.0, height=2.0, dt=1.0):
    """Trajectory file whose particles sit at the centres of the given cells [T, N]."""
    states = np.asarray(states)
    col = states % columns
    row = states // columns
    pos = np.stack([(col + 0.5) * width / columns, (row + 0.5) * height / rows], axis=-1)
    times = dt * np.arange(states.shape[0])
    return write_trajectories(path, times, pos, width=width, height=height)
