"""The synthetic riser's parameters and a run's arguments: what gives no chain or no run is
refused naming the parameter (InputError), not met as a numpy error or a silently wrong
file."""

from __future__ import annotations

import pytest

from cfbmarkov import synthetic
from cfbmarkov.errors import InputError


@pytest.mark.parametrize("options, message", [
    ({"lateral_probability": 0.8}, "RiserFlow lateral_probability 0.8 must be at most 0.5 "
                                   "(the probability of staying would be negative)"),
    ({"switch_probability": 0.7}, "RiserFlow switch_probability 0.7 must be at most 0.5882"),
    ({"lateral_probability": -0.1}, "RiserFlow lateral_probability -0.1 must be >= 0"),
    ({"lag": -0.025}, "RiserFlow lag -0.025 must be positive"),
    ({"vertical_spread": float("nan")}, "RiserFlow vertical_spread nan is not a finite number"),
    ({"rise_velocity": float("inf")}, "RiserFlow rise_velocity inf is not a finite number"),
    ({"rows": 3}, "RiserFlow rows 3: a whole number >= 4"),
    ({"columns": 2.5}, "RiserFlow columns 2.5: a whole number >= 1")])
def test_a_flow_that_gives_no_chain_is_refused(options, message):
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        synthetic.RiserFlow(**options)


@pytest.mark.parametrize("arguments, message", [
    ((-5, 1.0), "n_particles -5: a whole number >= 1"),
    ((10, float("nan")), "duration nan s is not a finite number"),
    ((10, -1.0), "duration -1 s must be positive"),
    ((10, 1.0, -1), "seed -1 must lie in 0 .. 2"),
    ((10, 1.0, 0, float("nan")), "start_time nan s is not a finite number")])
def test_a_run_that_cannot_be_written_is_refused_before_the_file(tmp_path, arguments, message):
    path = tmp_path / "run.h5"
    with pytest.raises(InputError, match=message):
        synthetic.write_run(path, synthetic.RiserFlow(columns=3, rows=8), *arguments)
    assert not path.exists()
