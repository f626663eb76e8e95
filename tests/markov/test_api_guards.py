"""What the Python interface refuses or protects, so that a slip in a notebook gives one
clear error and never a wrong number: kinetics resolved on another state space, laps and
steps that do not fit the particles, cached arrays written into, and a block wider than
the window it is cut from."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.kinetics import Kinetics, Property
from cfbmarkov.kinetics.fields import Constant
from cfbmarkov.kinetics.laws import FirstOrder
from cfbmarkov.markov import CellGrid, discretize, fit_model
from cfbmarkov.markov.kinetics_exact import exact_kinetics


@pytest.fixture(scope="session")
def model(markov_flow, markov_run):
    return fit_model(markov_run, markov_flow.grid, markov_flow.lag, (2.0, 6.0), "mle")


def _kinetics():
    return Kinetics((Property("X", FirstOrder(), {"rate": Constant(1.1)}),))


def test_kinetics_resolved_on_another_grid_are_refused(model, markov_flow, markov_run):
    """Kinetics resolved on a grid of more states, of fewer, and of the same count
    (another arrangement) are refused by the exact answers and the Monte Carlo alike; the
    model's own resolution, or the Kinetics itself, gives the same exit mean."""
    flow = markov_flow
    own = _kinetics().per_state(model.state_space)
    mean = exact_kinetics(model, own)["X"].exit_mean
    assert exact_kinetics(model, _kinetics())["X"].exit_mean == mean
    for columns, rows in ((8, 16), (2, 16), (16, 4)):
        other = _kinetics().per_state(CellGrid(columns, rows, flow.width, flow.height))
        with pytest.raises(InputError, match="kinetics resolved on .*not on the model's"):
            exact_kinetics(model, other)
        with pytest.raises(InputError, match="kinetics resolved on .*not on the model's"):
            model.predict(markov_run, start=6.0, duration=0.5, seed=1, kinetics=other)
    # the same cells on a riser of another size: the refusal names what differs (a
    # review read "cells 6x38 (228 states), not on the model's cells 6x38 (228 states)")
    space = model.state_space
    taller = _kinetics().per_state(CellGrid(space.columns, space.rows, flow.width,
                                            2 * flow.height))
    with pytest.raises(InputError, match=rf"kinetics resolved on .* \(height "
                       rf"{2 * flow.height!r} against {flow.height!r}\), not on the model's"):
        exact_kinetics(model, taller)
    with pytest.raises(InputError, match="a Kinetics .* not Property"):
        exact_kinetics(model, _kinetics().properties[0])


def test_monte_carlo_checks_its_particles_laps_and_steps(model):
    start = np.array([0, 1, 2])
    states, laps = model.monte_carlo(start, 4, seed=1, initial_laps=[5, 6, 7])
    np.testing.assert_array_equal(laps[0], [5, 6, 7])
    for kwargs, message in (({"initial_laps": [5]}, "1 laps for 3 particles"),
                            ({"initial_laps": [1.5, 2, 3]}, "whole numbers"),
                            ({"initial_laps": [2**40, 0, 0]}, "32-bit integer"),
                            ({"n_steps": 5.5}, "n_steps 5.5"),
                            ({"n_steps": -3}, "n_steps -3")):
        options = {"n_steps": 4, **kwargs}
        with pytest.raises(InputError, match=message):
            model.monte_carlo(start, seed=1, **options)
    for states in (np.zeros((2, 3), int), np.array([0.9, 2.0])):
        with pytest.raises(InputError, match="initial_states"):
            model.monte_carlo(states, 4)
    # initial_states' -1 of a particle absent from the frame: named, with the fix
    with pytest.raises(InputError, match=r"from -1 to 2 \(-1 marks a particle absent .* "
                                         r"states\[states >= 0\]\)"):
        model.monte_carlo(np.array([-1, 0, 2]), 4)
    with pytest.raises(InputError, match=rf"0 \.\. {model.n_states - 1}: from 0 to "
                                         rf"{model.n_states}$"):
        model.monte_carlo(np.array([0, model.n_states]), 4)


def test_cached_answers_cannot_be_written_into(model):
    """The model is immutable: the arrays it caches and returns are read-only, so a later
    question gets the same answer whatever was done to an earlier one's arrays."""
    rtd = model.rtd()
    mean = rtd.mean
    for array in (rtd.probability, rtd.entry_distribution, model.stationary_distribution,
                  model.up_fraction, model.down_fraction):
        with pytest.raises(ValueError, match="read-only"):
            array[:1] = 0.0
    assert model.rtd().mean == mean
    entry = np.full(model.n_states, 1.0 / model.n_states)
    from cfbmarkov.markov.first_passage import ResidenceTimeDistribution

    ResidenceTimeDistribution(model.lag, np.array([0.5, 0.5]), 0.0, entry)
    entry[0] = 0.0                      # the caller's own array stays writable


def test_a_block_reaching_outside_its_window_records_what_it_holds(markov_flow, markov_run):
    window = discretize(markov_run, markov_flow.grid, markov_flow.lag, (4.0, 6.0))
    block = window.block(2.0, 5.0)
    assert block.window == (4.0, 5.0) and block.times[0] >= 4.0 - 1e-9
    assert window.block(4.5, 5.5).window == (4.5, 5.5)


def test_kinetics_built_wrongly_in_python_say_how_to_build_them(model):
    """A law class or name where an instance belongs, one Property where a tuple belongs
    and a flat array of per-cell values each give one InputError naming the fix; an array
    laid out as the grid is ``ByCell.from_grid``, equal to the table of the same values."""
    from cfbmarkov.kinetics.fields import ByCell

    with pytest.raises(InputError, match="the class FirstOrder is not a law"):
        Property("X", FirstOrder, {"rate": Constant(1.0)})
    with pytest.raises(InputError, match="'first-order' is not a law"):
        Property("X", "first-order", {"rate": Constant(1.0)})
    one = Property("X", FirstOrder(), {"rate": Constant(1.0)})
    with pytest.raises(InputError, match=r"as a tuple, Kinetics\(\(Property"):
        Kinetics(one)
    space = model.state_space
    values = np.arange(space.rows * space.columns, dtype=float).reshape(space.rows,
                                                                         space.columns) / 10
    flat = Kinetics((Property("X", FirstOrder(), {"rate": ByCell(values.ravel())}),))
    with pytest.raises(InputError, match=r"ByCell.from_grid\(values\)"):
        flat.per_state(space)
    grid = Kinetics((Property("X", FirstOrder(), {"rate": ByCell.from_grid(values)}),))
    table = np.array([[c, r, values[r, c]] for r in range(space.rows)
                      for c in range(space.columns)])
    by_table = Kinetics((Property("X", FirstOrder(), {"rate": ByCell(table)}),))
    np.testing.assert_array_equal(grid.per_state(space).rate, by_table.per_state(space).rate)
    np.testing.assert_array_equal(grid.per_state(space).rate[0], values.ravel())
    # the table is the parameter's own: the caller's later write changes no answer (a
    # review saw a frozen Kinetics' exit mean go from 0.559 to 0.972 when its table did)
    before = by_table.per_state(space).rate.copy()
    table[:, 2] = 5.0
    np.testing.assert_array_equal(by_table.per_state(space).rate, before)
    with pytest.raises(ValueError):
        by_table.properties[0].parameters["rate"].table[0, 2] = 1.0
    with pytest.raises(InputError, match=r"t \(rate\): a table of numbers"):
        ByCell([["a", "b", "c"]], "t", "rate")


def test_compare_runs_takes_paths_as_open_files(model, markov_run, tmp_path):
    from cfbmarkov.analysis.compare import compare_runs
    from cfbmarkov.trajectories import Trajectories

    prediction = tmp_path / "pred.h5"
    model.predict(markov_run, start=6.0, duration=2.0, seed=3, output=prediction)
    by_path = compare_runs(markov_run, prediction, (6.0, 8.0))
    with Trajectories(markov_run) as ref, Trajectories(prediction) as pred:
        opened = compare_runs(ref, pred, (6.0, 8.0))
    assert by_path.md_rtd == opened.md_rtd and by_path.mixing_rms == opened.mixing_rms


def test_propagate_refuses_negative_mass_and_broken_steps(model):
    s0 = np.zeros(model.n_states)
    s0[0] = 1.0
    assert model.propagate(s0, 3).shape == (4, model.n_states)
    for initial, steps, message in ((-s0, 3, "non-negative"), (s0 * np.nan, 3, "finite"),
                                    (s0, -1, "steps -1"), (s0, 5.9, "steps 5.9")):
        with pytest.raises(InputError, match=message):
            model.propagate(initial, steps)


def test_select_model_of_several_runs_names_select_pooled(markov_flow, markov_run):
    from cfbmarkov.markov.select import select_model

    with pytest.raises(InputError, match=r"select_pooled\(runs, windows="):
        select_model([markov_run, markov_run], window=(2.0, 4.0), columns=4, rows=16,
                     lag=markov_flow.lag)


def test_a_cell_grid_of_fractional_or_boolean_cells_is_refused():
    """As `--cells 6.5x38` is refused: 6.9 columns are not truncated to 6, True is not 1."""
    from cfbmarkov.markov import CellGrid

    for columns, rows in ((6.9, 38), (True, 38), ("6", 38), (6, 37.99), (float("nan"), 38),
                          (float("inf"), 38)):
        with pytest.raises(InputError, match="a whole number of cells"):
            CellGrid(columns, rows, 0.09, 0.95)
    assert CellGrid(6.0, np.int64(38), 0.09, 0.95).n_states == 228
    assert CellGrid(np.array(6), np.uint8(38), 0.09, 0.95).n_states == 228


def test_values_of_the_wrong_kind_are_refused_in_one_line(model):
    """Text, booleans and scalars where numbers or sequences go: one InputError naming the
    argument in the API's words (not a command-line option), never a numpy TypeError or a
    silently converted string; a negative time is named as negative."""
    calls = {
        "initial distribution 'abc'": lambda: model.propagate("abc", steps=2),
        r"initial distribution \['0', ": lambda: model.propagate(
            ["0"] * model.n_states, steps=2),
        r"times 0\.05: a sequence": lambda: model.batch_injection_maps(0.05),
        r"times '0\.05': a sequence": lambda: model.batch_injection_maps("0.05"),
        r"window length '5' is not a number": lambda: model.rtd(window="5"),
        r"window length True is not a number": lambda: model.rtd(window=True),
        r"window length 0 s must be positive": lambda: model.rtd(window=0),
        r"time -0\.05 s is negative": lambda: model.batch_injection_maps([-0.05]),
    }
    for message, call in calls.items():
        with pytest.raises(InputError, match=message):
            call()
    assert model.batch_injection_maps([model.lag]).shape == (1, model.state_space.rows,
                                                             model.state_space.columns)


def test_a_closed_file_or_a_model_where_trajectories_go_is_named_in_one_line(
        model, markov_run, tmp_path, monkeypatch):
    """A file read after its `with` block (h5py's KeyError about an invalid identifier), a
    model given where a run's file goes (pathlib's TypeError): one InputError line each;
    an open file pickles by its path (for worker processes)."""
    import pickle

    from cfbmarkov.trajectories import Trajectories

    with Trajectories(markov_run) as traj:
        first = traj.positions(0)
    assert traj.closed and repr(traj).endswith(", closed)")
    for read in (lambda: traj.positions(0), lambda: traj.laps(0),
                 lambda: discretize(traj, CellGrid(6, 38), 0.025, (0.5, 1.5))):
        with pytest.raises(InputError, match="the trajectory file is closed .* open it again"):
            read()
    for call in (lambda: discretize(model, CellGrid(6, 38), 0.025, (0.5, 1.5)),
                 lambda: model.predict(model, 0.5, 0.5)):
        with pytest.raises(InputError, match="got a MarkovModel; a model is no trajectories"):
            call()
    # opened by a relative path, unpickled in another working folder (a worker's)
    from pathlib import Path

    monkeypatch.chdir(Path(markov_run).parent)
    with Trajectories(Path(markov_run).name) as traj:
        pickled = pickle.dumps(traj)
        with Trajectories(traj) as handle:          # another handle on the same file
            np.testing.assert_array_equal(handle.positions(0), first)
    monkeypatch.chdir(tmp_path)
    again = pickle.loads(pickled)
    np.testing.assert_array_equal(again.positions(0), first)
    again.close()


def test_residence_times_are_the_lags_decimal_multiples():
    """An RTD's times are k * lag rounded to the lag's own decimals (0.075, not
    0.07500000000000001, in a JSON file or a comparison); a lag without a short decimal
    form keeps the plain product."""
    from cfbmarkov.markov.first_passage import ResidenceTimeDistribution, lag_multiples

    rtd = ResidenceTimeDistribution(0.025, np.full(400, 1 / 400), 0.0, np.ones(1))
    assert rtd.times.tolist() == [float(f"{0.025 * k:.6f}") for k in range(1, 401)]
    assert np.abs(rtd.times - 0.025 * np.arange(1, 401)).max() < 1e-13
    third = lag_multiples(1 / 30, np.arange(1, 50))
    assert np.array_equal(third, np.arange(1, 50) * (1 / 30))


def test_a_lag_that_is_not_a_positive_finite_number_and_a_window_outside_are_named(
        markov_flow, markov_run):
    """discretize with a NaN or infinite lag said "lag of 0 frames"; select_model with a
    window outside the data named its first block (30:31.675 s), not the window given."""
    from cfbmarkov.markov.select import select_model

    for lag in (float("nan"), float("inf"), -0.025):
        with pytest.raises(InputError, match=r"lag (nan|inf|-0.025) s must be a positive "
                                             r"finite number"):
            discretize(markov_run, CellGrid(markov_flow.columns, markov_flow.rows), lag,
                       (0.5, 1.0))
    with pytest.raises(InputError, match=r"window 30:35 s lies outside the data"):
        select_model(markov_run, window=(30.0, 35.0), columns=markov_flow.columns,
                     rows=markov_flow.rows, lag=markov_flow.lag)


def test_an_occupancy_without_a_window_and_one_run_given_alone(model, markov_run):
    """rtd(occupancy=...) without a window ignored the occupancy; assess_fit(runs="x.h5")
    read the name letter by letter ("s: no such file")."""
    from cfbmarkov.analysis.fit_checks import assess_fit

    with pytest.raises(InputError, match=r"occupancy= says where a window's particles start: "
                                         r"give the window's length with it"):
        model.rtd(occupancy=np.ones(model.n_states))
    assert model.rtd(window=1.0, occupancy=np.ones(model.n_states)).mean > 0
    alone = assess_fit(model, runs=str(markov_run), resamples=0, verdict=False)
    listed = assess_fit(model, runs=[str(markov_run)], resamples=0, verdict=False)
    assert alone.source_identity is not None
    assert alone.source_identity == listed.source_identity


def test_an_rtd_and_an_interval_compare_by_identity_as_the_model_does(model):
    """`==` on two RTDs raised numpy's "truth value of an array is ambiguous"; as for a
    MarkovModel it is identity (their contents compared field by field where wanted)."""
    rtd, again = model.rtd(), model.rtd(window=1.0)
    assert rtd == rtd and (rtd == again) is False and rtd != again
    assert (model == model) and rtd.uncertainty == rtd.uncertainty


def test_a_model_loaded_or_saved_with_no_path_is_refused_in_one_line(tmp_path):
    """None (a variable never set in a notebook) as a path: an InputError naming it, not a
    TypeError from pathlib."""
    from cfbmarkov.errors import InputError
    from cfbmarkov.markov import MarkovModel
    from tests.markov.test_model import ladder_model

    with pytest.raises(InputError, match=r"None is no file name: give the path"):
        MarkovModel.load(None)
    with pytest.raises(InputError, match=r"None is no file name: give the output's path"):
        ladder_model(4, 0.5).save(None)


def test_a_misspelt_parameter_of_a_law_is_named_beside_the_one_missing():
    from cfbmarkov.kinetics import Constant, FirstOrder

    with pytest.raises(InputError, match=r"law first-order needs rate \(given rat, which it "
                       r"takes no: a misspelt name\?\)"):
        Property("X", FirstOrder(), {"rat": Constant(1.0)})
