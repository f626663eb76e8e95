"""Kinetics built in Python: wrong kinds of arguments are refused in one line naming the
form expected (InputError), as a kinetics file's are, before any work."""

from __future__ import annotations

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.kinetics import ByCell, Constant, FirstOrder, HeatExchange, Property, load_kinetics


@pytest.mark.parametrize("value", ["fast", "0.4", None, np.ones(3), float("nan"), True])
def test_a_constant_takes_one_finite_number(value):
    with pytest.raises(InputError, match=r"Constant\(.*\): a constant takes one finite number"):
        Constant(value)


def test_a_constant_of_a_number_stands():
    assert Constant(0.4).value == 0.4 and Constant(np.float32(2)).describe() == 2.0


def test_a_table_is_an_array_not_a_file_name(tmp_path):
    with pytest.raises(InputError, match=r"not a file name; a CSV file is read by "
                                         r"load_kinetics"):
        ByCell("rates.csv")
    with pytest.raises(InputError, match="not a file name"):
        ByCell(tmp_path / "rates.csv")


@pytest.mark.parametrize("wall", [float("nan"), "hot", float("inf")])
def test_a_wall_temperature_is_a_finite_number(wall):
    with pytest.raises(InputError, match=r"wall_temperature = .* must be a finite number"):
        HeatExchange(wall_temperature=wall)


def test_a_wall_temperature_beside_a_temperature_table_is_refused_as_in_a_file():
    table = np.array([[c, r, 700.0] for r in range(2) for c in range(2)])
    with pytest.raises(InputError, match="wall_temperature would replace the wall cells' "
                                         "values of the temperature table"):
        Property("T", HeatExchange(wall_temperature=600.0),
                 {"coefficient": 1.0, "temperature": ByCell(table)}, initial=300.0)
    # a constant temperature beside it stands
    Property("T", HeatExchange(wall_temperature=600.0),
             {"coefficient": 1.0, "temperature": 800.0}, initial=300.0)


@pytest.mark.parametrize("initial", ["0.5", "abc", float("nan")])
def test_a_start_value_is_a_finite_number(initial):
    with pytest.raises(InputError, match="give its finite start value as a number"):
        Property("X", FirstOrder(), {"rate": 1.0}, initial=initial)


def test_load_kinetics_takes_a_path():
    with pytest.raises(InputError, match=r"load_kinetics\(3\): give the path of a kinetics "
                                         r"file"):
        load_kinetics(3)


def test_exact_kinetics_checks_its_model_and_depth():
    from cfbmarkov.kinetics import Kinetics
    from cfbmarkov.markov.kinetics_exact import exact_kinetics
    from cfbmarkov.markov.model import MarkovModel
    from cfbmarkov.markov.states import CellGrid

    kinetics = Kinetics((Property("X", FirstOrder(), {"rate": 1.0}),))
    with pytest.raises(InputError, match="is not a fitted model; give one"):
        exact_kinetics("model.h5", kinetics)
    p = np.array([[0.0, 1.0], [0.0, 0.0]])
    up = np.array([[0.0, 0.0], [1.0, 0.0]])
    p[1, 0] = 1.0
    zeros = np.zeros((2, 2), np.int64)
    model = MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 2, 0.1, 1.0), 0.1,
                        estimator="given", pass_fractions=(up, np.zeros((2, 2))))
    for levels in (-1, 1.5, "2", True):
        with pytest.raises(InputError, match=r"deficit_levels = .*: a whole number of lap "
                                             r"deficits >= 0"):
            exact_kinetics(model, kinetics, deficit_levels=levels)
    answer = exact_kinetics(model, kinetics)["X"]
    assert answer.exit_mean == pytest.approx(1.0 - np.exp(-0.2), rel=1e-12)   # two lags


def test_a_negative_rate_is_refused_when_the_property_is_made_as_in_a_file():
    """A rate or coefficient below 0 is refused by Property itself (as load_kinetics
    refuses it in a file), not first when an answer is asked; a signed parameter (a
    temperature) keeps its sign."""
    with pytest.raises(InputError, match=r"property X: rate -1 < 0; rates and coefficients "
                                         r"must be >= 0"):
        Property("X", FirstOrder(), {"rate": -1.0})
    table = np.array([[c, r, 0.4 if r else -0.2] for r in range(2) for c in range(2)])
    with pytest.raises(InputError, match=r"property X: rate -0.2 < 0"):
        Property("X", FirstOrder(), {"rate": ByCell(table)})
    Property("T", HeatExchange(), {"coefficient": 1.0, "temperature": -20.0}, initial=300.0)


def test_a_heat_exchange_without_a_start_value_says_none_is_given():
    """A temperature has no default start value: the refusal says none is given (it said
    "not None", Python's word)."""
    with pytest.raises(InputError, match=r"initial = \.\.\. \(the feed's value\), none is "
                                         r"given$"):
        Property("T", HeatExchange(), {"coefficient": 1.0, "temperature": 800.0})


@pytest.mark.parametrize("args, message", [
    (("porosity", 0.2, 2.0, 0.1), "FromField: 'porosity' is not a cell field; use one of "
                                  "solids_fraction, wall_distance, vertical_velocity"),
    (("solids_fraction", 0.2, 2.0, float("nan")), "FromField('solids_fraction') threshold nan "
                                                   "is not a finite number"),
    (("solids_fraction", 0.2, 2.0, float("inf")), "threshold inf is not a finite number"),
    (("wall_distance", float("nan"), 2.0, 0.01), "dense nan is not a finite number"),
    (("wall_distance", 0.2, "2", 0.01), "dilute '2' is not a number")])
def test_a_parameter_from_a_cell_field_takes_a_known_field_and_finite_numbers(args, message):
    """A NaN threshold would put every cell on the dilute side silently; an unknown field
    would fail only where the fields are read: both refused when built."""
    from cfbmarkov.kinetics import FromField

    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        FromField(*args)


def test_a_negative_value_from_a_cell_field_is_refused_as_a_negative_rate():
    from cfbmarkov.kinetics import FromField

    with pytest.raises(InputError, match="property X: rate -0.2 < 0; rates and coefficients "
                                         "must be >= 0"):
        Property("X", FirstOrder(), {"rate": FromField("solids_fraction", -0.2, 2.0, 0.1)})


def test_a_setting_of_the_law_given_as_a_parameter_is_sent_to_the_law():
    """A kinetics file gives wall_temperature beside the parameters; in Python it is the
    law's own (HeatExchange(wall_temperature=...)), and the refusal says so."""
    with pytest.raises(InputError, match=r"takes no wall_temperature as a parameter; give it "
                                         r"to the law: HeatExchange\(wall_temperature=\.\.\.\)"):
        Property("T", HeatExchange(), {"coefficient": 2.0, "temperature": 800.0,
                                       "wall_temperature": 600.0}, initial=300.0)
    with pytest.raises(InputError, match=r"takes no bogus as a parameter$"):
        Property("X", FirstOrder(), {"rate": 1.0, "bogus": 1.0})
    # a class constant of the law is no setting of it: no hint to pass it
    for constant in ("key", "quantity", "initial_range"):
        with pytest.raises(InputError, match=rf"takes no {constant} as a parameter$"):
            Property("X", FirstOrder(), {"rate": 1.0, constant: 1.0})


def test_a_non_finite_value_in_a_table_is_named_by_its_row_and_cell():
    table = np.array([[c, r, 1.0] for r in range(3) for c in range(2)])
    table[3, 2] = np.nan
    with pytest.raises(InputError, match=r"data row 4 \(col 1, row 1\) gives the value nan; "
                                         "give a finite number for every cell"):
        ByCell(table)


def test_a_grid_array_of_the_wrong_shape_is_named_by_its_shape():
    """ByCell.from_grid(values) takes values[row, col]; an array laid out (columns, rows)
    is named as transposed, with the shape the grid needs and the parameter's name."""
    from cfbmarkov.markov import CellGrid

    grid = CellGrid(2, 5, 0.04, 0.3)
    rate = ByCell.from_grid(np.ones((2, 5)))
    prop = Property("X", FirstOrder(), {"rate": rate})
    with pytest.raises(InputError, match=r"array \(rate\): values of shape \(2, 5\) "
                                         r"\(transposed: values\[row, col\], row 0 at the "
                                         r"bottom\); the model's grid 2x5 needs shape "
                                         r"\(rows, columns\) = \(5, 2\)"):
        prop.per_cell(grid)
    good = Property("X", FirstOrder(), {"rate": ByCell.from_grid(np.arange(10.0).reshape(5, 2))})
    np.testing.assert_array_equal(good.per_cell(grid)["rate"], np.arange(10.0))
    # a depth axis of one on a grid of one depth is the same layout
    deep = Property("X", FirstOrder(),
                    {"rate": ByCell.from_grid(np.arange(10.0).reshape(5, 1, 2))})
    np.testing.assert_array_equal(deep.per_cell(grid)["rate"], np.arange(10.0))
