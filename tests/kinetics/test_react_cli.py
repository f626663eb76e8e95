"""``cfbmarkov react`` on a small generated run, and bad kinetics files."""

import json
import warnings

import h5py
import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.kinetics import load_kinetics
from cfbmarkov.markov.states import CellGrid
from cfbmarkov.synthetic import RiserFlow, write_run


@pytest.fixture(scope="session")
def fitted(tmp_path_factory):
    folder = tmp_path_factory.mktemp("react")
    run = write_run(folder / "run.h5", RiserFlow(columns=3, rows=6), 60, 2.0, seed=1)
    model = folder / "model.h5"
    assert main(["fit", str(run), "--cells", "3x6", "--window", "0:2", "-o", str(model)]) == 0
    return folder, run, model


def _write(folder, text, rates=None):
    path = folder / "kin.toml"
    path.write_text(text)
    if rates is not None:
        (folder / "rates.csv").write_text(rates)
    return path


GOOD = """
[[property]]
name = "X"
law = "first-order"
rate_by_cell = "rates.csv"

[[property]]
name = "T"
law = "heat-exchange"
coefficient = 2.0
temperature = 800.0
wall_temperature = 600.0
initial = 300.0
"""
RATES = "col,row,rate\n" + "".join(f"{c},{r},{0.2 if c != 1 else 2.0}\n"
                                     for r in range(6) for c in range(3))


def test_react_table_says_the_computing_time_is_one(fitted, tmp_path, capsys):
    """The time under the table is the computation's, not a physical time; the values are
    in the kinetics file's units."""
    import re

    folder, run, model = fitted
    kin = _write(tmp_path, GOOD, RATES)
    assert main(["react", str(model), "--kinetics", str(kin)]) == 0
    lines = capsys.readouterr().out.splitlines()
    last = lines[-2]
    assert re.fullmatch(r"exact, per residence at the exit and over the bed in steady state, "
                        r"in the units of the kinetics file's values; computed in "
                        r"[0-9.e-]+ s", last), last
    # and that these are the fitted chain's, without its sampling uncertainty
    assert lines[-1].startswith("  exact for the fitted chain, without its sampling "
                                "uncertainty: --resamples 100")


def test_react_resamples_give_the_exit_means_intervals(fitted, tmp_path, capsys):
    """--resamples N: each property's exit mean with an interval from the fitting window's
    block bootstrap (each resample solved exactly), around the exact value, the same on a
    second call; wider at a higher level; fewer than 10 resamples refused in one line."""
    folder, run, model = fitted
    kin = _write(tmp_path, GOOD, RATES)
    argv = ["react", str(model), "--kinetics", str(kin), "--json", "--resamples", "20"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["level"] == 0.9 and out["interval_resamples"] == 20
    intervals = {}
    for name in ("X", "T"):
        value = out["properties"][name]
        lo, hi = intervals[name] = value["exit_mean_interval"]
        assert lo < value["exit_mean"] < hi
    assert main(argv) == 0                      # seeded: the same interval again
    again = json.loads(capsys.readouterr().out)["properties"]
    assert {name: again[name]["exit_mean_interval"] for name in intervals} == intervals
    # the same from Python, which had no call for it (a review rebuilt it by hand)
    from cfbmarkov.analysis.kinetics_compare import exit_mean_intervals
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.markov import MarkovModel

    formed = exit_mean_intervals(MarkovModel.load(model), load_kinetics(kin), resamples=20)
    assert formed["exit_mean"] == intervals and formed["resamples"] == 20
    assert main(argv + ["--level", "0.99"]) == 2        # 20 resamples reach 95 %, not 99 %
    assert "a 99 % interval needs at least 100 bootstrap resamples" in capsys.readouterr().err
    assert main(argv + ["--level", "0.95"]) == 0
    wide = json.loads(capsys.readouterr().out)["properties"]["T"]["exit_mean_interval"]
    assert wide[0] <= intervals["T"][0] and wide[1] >= intervals["T"][1]
    assert wide[1] - wide[0] > intervals["T"][1] - intervals["T"][0]
    assert main(["react", str(model), "--kinetics", str(kin), "--resamples", "20"]) == 0
    assert "90 % interval of X's exit mean: " in capsys.readouterr().out
    assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["properties"]["X"]["exit_mean_interval"] is None
    assert main(["react", str(model), "--kinetics", str(kin), "--resamples", "5"]) == 2
    assert "at least 10" in capsys.readouterr().err
    # a level without resamples sets nothing: refused in one line, not ignored
    assert main(["react", str(model), "--kinetics", str(kin), "--level", "0.5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--level 0.5" in err and "--resamples" in err


def test_react_resamples_give_the_activity_after_passes_its_intervals(fitted, tmp_path,
                                                                      capsys):
    """A carried deactivation, whose steady state is 0: its mean after each number of
    passes gets an interval from the same resamples, around the exact value, each later
    pass's below the earlier's, in the text and in --json."""
    _, _, model = fitted
    kin = _write(tmp_path, '[[property]]\nname = "a"\nlaw = "deactivation"\nrate = 0.8\n'
                           'start = "carried"\n')
    argv = ["react", str(model), "--kinetics", str(kin), "--resamples", "20",
            "--passes", "1", "3"]
    assert main(argv + ["--json"]) == 0
    after = json.loads(capsys.readouterr().out)["properties"]["a"]["after_passes"]
    bounds = []
    for n in ("1", "3"):
        lo, hi = after[n]["mean_interval"]
        assert lo < after[n]["mean"] < hi
        bounds.append((lo, hi))
    assert bounds[1][1] < bounds[0][0]                # three passes leave less than one
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert (f"90 % intervals of a's mean after 1 / 3 passes: {bounds[0][0]:.6g}-"
            f"{bounds[0][1]:.6g} / {bounds[1][0]:.6g}-{bounds[1][1]:.6g}") in text
    assert main(["react", str(model), "--kinetics", str(kin), "--json", "--passes", "1",
                 "1000000"]) == 0
    after = json.loads(capsys.readouterr().out)["properties"]["a"]["after_passes"]
    assert after["1"]["mean_interval"] is None
    # far below the normal floats: 0, not the round-off of an underflow (5.9e-323)
    assert after["1000000"]["mean"] == 0.0 and after["1000000"]["sd"] == 0.0


def test_an_interval_beyond_the_laws_range_is_cut_there(fitted, tmp_path, capsys,
                                                        monkeypatch):
    """An activity cannot be negative nor a conversion exceed 1: where the bootstrap's
    widened spread reaches beyond (after many passes a carried activity's mean nears 0;
    a real model gave -5.6e-11 to 2.5e-7), the interval is cut at the law's range, and
    the text says so (a minus beside the dash could not be read)."""
    import cfbmarkov.analysis.bootstrap as bootstrap

    _, _, model = fitted
    monkeypatch.setattr(bootstrap, "interval_bounds",
                        lambda point, *args, **kwargs: (point - 2.0, point + 2.0))
    kin = _write(tmp_path, '[[property]]\nname = "a"\nlaw = "deactivation"\nrate = 0.8\n'
                           'start = "carried"\n[[property]]\nname = "X"\n'
                           'law = "first-order"\nrate = 0.4\n')
    argv = ["react", str(model), "--kinetics", str(kin), "--resamples", "20", "--passes", "5"]
    assert main(argv + ["--json"]) == 0
    out = json.loads(capsys.readouterr().out)["properties"]
    lo, hi = out["a"]["after_passes"]["5"]["mean_interval"]
    assert lo == 0.0 and hi == pytest.approx(out["a"]["after_passes"]["5"]["mean"] + 2.0)
    assert out["X"]["exit_mean_interval"] == [0.0, 1.0]
    assert main(argv) == 0
    assert "(cut at the least value its law allows)" in capsys.readouterr().out


def test_react_json_and_monte_carlo(fitted, tmp_path, capsys):
    folder, run, model = fitted
    kin = _write(tmp_path, GOOD, RATES)
    assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    x = out["properties"]["X"]["exit_mean"]
    assert 0 < x < 1
    assert 300 < out["properties"]["T"]["exit_mean"] < 800
    pred = tmp_path / "pred.h5"
    assert main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "1", "-o", str(pred), "-q"]) == 0
    capsys.readouterr()
    again = tmp_path / "pred-json.h5"
    assert main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "1", "-o", str(again), "-q", "--json"]) == 0
    carlo = json.loads(capsys.readouterr().out)["monte_carlo"]
    assert out["monte_carlo"] is None and set(carlo) == {"X", "T"}
    with h5py.File(pred) as f:
        values = f["properties/X"][()]
        assert f["properties/X"].attrs["start"] == "entry"
        # a periodic riser: every particle present, the bed mean over all of them
        assert carlo["X"]["bed_mean"][1] == pytest.approx(float(np.mean(values[-1])), rel=1e-12)
        assert carlo["X"]["bed_mean"][0] == 0.0 and carlo["X"]["times"] == [0.5, 1.5]
        assert values.shape == f["frames/lap"].shape
        assert np.all((values >= 0) & (values <= 1))
        assert np.all(np.diff(values, axis=0)[np.diff(f["frames/lap"][()], axis=0) == 0]
                      >= -1e-15)      # conversion only grows between passes


@pytest.mark.parametrize("text, rates, message", [
    ('[[property]]\nname = "X"\nlaw = "second-order"\nrate = 1.0\n', None, "unknown law"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = -1.0\n', None, "rate = -1.0"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = nan\n', None, "finite"),
    # values whose squares overflow the exit SD's moments
    ('[[property]]\nname = "T"\nlaw = "heat-exchange"\ncoefficient = 2.0\n'
     'temperature = 1e155\ninitial = 300.0\n', None,
     "property T: a value of 1e+155 (its initial value or a cell's limit) lies beyond 1e+100"),
    # TOML reads 1e400 as inf: the message says so, not "rate = inf" alone
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1e400\n', None,
     "rate = inf (a number beyond 1.8e308 reads as inf) must be a finite number"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\nspeed = 2\n', None,
     "unknown key 'speed'"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n0,0,1.0\n", "misses 17 cell"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n" + "".join(f"{c},{r},1\n" for r in range(6) for c in range(3))
     + "7,0,1\n", "outside the grid"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,rate\n0,1\n", "columns col,rate"),
    ('[[property]]\nname = "X"\nlaw = "heat-exchange"\ncoefficient = 1.0\n'
     'temperature = 800\n', None, "initial"),
    ('[[property]\nname = "X"\n', None, "not valid TOML"),
    # a TOML error names the fix, not the parser's words alone
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\nrate = 2.0\n', None,
     "(at line 5, column 11); correct the file there: each setting `key = value` on its own "
     "line, text in double quotes, a key once in each table"),
    # a table's non-finite value or bad cell index is named as such
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n0,0,nan\n", "line 2: rate is nan, not a finite number; give col,row,rate"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n-1,0,1.0\n", "line 2: col -1 is not a cell index (a whole number >= 0, "
                                  "counted from 0)"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n0,inf,1.0\n", "line 2: row is inf, not a finite number"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\ninitial = 1.5\n', None,
     "initial = 1.5 is outside [0, 1]"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\ninitial = -0.1\n', None,
     "outside [0, 1]"),
    ('[[property]]\nname = "X"\nlaw = "deactivation"\nrate = 1.0\ninitial = -0.5\n', None,
     "initial = -0.5 is outside [0, inf)"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n" + "".join(f"{c},{r},1\n" for r in range(6) for c in range(3))
     + "2,4,1\n", "cell col 2, row 4 more than once"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 0.0\nstart = "carried"\n', None,
     "no steady state"),
    # a misspelt parameter is named as an unknown key, not as a missing one
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrat = 1.0\n', None,
     "unknown key 'rat'"),
    # a name that is not text: said so, not read as "the third property"
    ('[[property]]\nname = 3\nlaw = "first-order"\nrate = 1.0\n', None,
     "[[property]] 1: give name = \"...\" (a text in quotes: name = 3 is not)"),
    # a misspelt law key: the laws listed and the stray key named
    ('[[property]]\nname = "X"\nlwa = "first-order"\nrate = 1.0\n', None,
     "give law = \"...\" (one of first-order, deactivation, heat-exchange); unknown key 'lwa'"),
    # file lines as an editor numbers them, blank lines counted: the cell (col 2, row 4) on
    # line 16 (header on 1, cell k = 3 row + col on line k + 2) and again on line 21, after
    # a blank line 20
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n" + "".join(f"{c},{r},1\n" for r in range(6) for c in range(3))
     + "\n2,4,1\n", "(lines 16, 21)"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n\n0,0,x\n", "line 3 ('0,0,x') is not 3 numbers; give col,row,rate"),
    # keys of a field-dependent rate left beside a constant rate are refused, not ignored
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 0.4\nrate_dense = 5.0\n', None,
     "rate_dense applies only with rate_from"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 0.4\nthreshold = 0.1\n', None,
     "threshold applies only to a parameter given as a function of a cell field"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 0.4\nunits = "1/min"\n', None,
     "rates and heat-exchange coefficients are read in 1/s"),
    ('[property]\nname = "X"\nlaw = "first-order"\nrate = 0.4\n', None,
     "a single [property] table; write it [[property]]"),
    # the cells a table misses are named (the first three)
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n" + "".join(f"{c},{r},1\n" for r in range(6) for c in range(3)
                                if (c, r) != (2, 4)), "misses 1 cell(s) of the grid 3x6 (col 2, row 4)"),
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,rate\n0,0,1.0\n", "(col 1, row 0; col 2, row 0; col 0, row 1; and 14 more)"),
    # a field-dependent parameter's bad value is named as such, not as a missing key
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_from = "solids_fraction"\n'
     'rate_dense = -0.2\nrate_dilute = 1.0\nthreshold = 0.1\n', None,
     "rate_dense = -0.2 must be a finite number >= 0"),
    # a wall temperature beside a per-cell table would replace the table's wall cells
    ('[[property]]\nname = "T"\nlaw = "heat-exchange"\ncoefficient = 1.0\n'
     'temperature_by_cell = "rates.csv"\nwall_temperature = 600.0\ninitial = 300.0\n',
     "col,row,temperature\n" + "".join(f"{c},{r},700\n" for r in range(6) for c in range(3)),
     "wall_temperature would replace the wall cells' values of temperature_by_cell"),
    # a depth column on a 2D grid: only its one depth, 0, and the line that gives another
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "rates.csv"\n',
     "col,row,depth,rate\n" + "".join(f"{c},{r},{int((c, r) == (1, 2))},1\n"
                                      for r in range(6) for c in range(3)),
     "line 9 gives depth 1, but the grid 3x6 has the one depth 0: for values that differ in "
     "depth fit the model on COLUMNSxDEPTHxROWS cells of a 3D run; else give col,row,VALUE"),
    # a table that is not there: where its path is read from
    ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_by_cell = "missing.csv"\n', None,
     "a table's path is relative to the kinetics file's folder"),
    # a name the particle files' arrays carry would replace that array in export-vtk
    ('[[property]]\nname = "id"\nlaw = "first-order"\nrate = 0.4\n', None,
     "property name 'id' is the name of an array the particle files carry"),
])
def test_bad_kinetics_files_one_line_exit_2(fitted, tmp_path, capsys, text, rates, message):
    _, _, model = fitted
    kin = _write(tmp_path, text, rates)
    assert main(["react", str(model), "--kinetics", str(kin)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and str(kin) in err


def test_rate_tables_from_excel_read_or_refused_by_encoding(fitted, tmp_path, capsys):
    """Excel's "CSV UTF-8" (a byte-order mark before the header) reads as plain UTF-8; its
    "Unicode Text" (UTF-16) and other encodings are refused in one line naming the file
    and how to save it (not a traceback); a kinetics TOML with a byte-order mark reads, one
    in UTF-16 or cp1252 is named as text in that encoding (not as a binary file)."""
    _, _, model = fitted
    kin = _write(tmp_path, GOOD)
    (tmp_path / "rates.csv").write_bytes(b"\xef\xbb\xbf" + RATES.encode())
    kin.write_bytes(b"\xef\xbb\xbf" + kin.read_bytes())
    assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0
    with_bom = json.loads(capsys.readouterr().out)["properties"]["X"]["exit_mean"]
    (tmp_path / "rates.csv").write_text(RATES)
    assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["properties"]["X"]["exit_mean"] == with_bom
    for text, says in ((GOOD.encode("utf-16"), "is text in UTF-16; save it as UTF-8"),
                       (("# caf\u00e9\n" + GOOD).encode("cp1252"),
                        "is text in another encoding than UTF-8; save it as UTF-8")):
        other = tmp_path / "other.toml"
        other.write_bytes(text)
        assert main(["react", str(model), "--kinetics", str(other)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err
    for data, says in ((RATES.encode("utf-16"), "is UTF-16 (Excel's 'Unicode Text')"),
                       (RATES.replace("rate", "rate \u00b0").encode("cp1252"), "not UTF-8")):
        (tmp_path / "rates.csv").write_bytes(data)
        assert main(["react", str(model), "--kinetics", str(kin)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err and "save it as CSV in UTF-8" in err


def test_rate_tables_with_comments_quotes_or_capitals_read_as_the_plain_table(
        fitted, tmp_path, capsys):
    """A '#' comment line, quoted fields and a capitalised header, as spreadsheets and
    scripts write them, and a depth column of zeros on a 2D grid, give the same exit mean
    as the plain table."""
    _, _, model = fitted
    kin = _write(tmp_path, GOOD)
    (tmp_path / "rates.csv").write_text(RATES)
    assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)["properties"]["X"]["exit_mean"]
    header, *rows = RATES.strip().splitlines()
    quoted = "\n".join(",".join(f'"{x}"' for x in line.split(",")) for line in rows)
    with_depth = "col,row,depth,rate\n" + "".join(
        f"{c},{r},0,{v}\n" for c, r, v in (line.split(",") for line in rows))
    for text in ("# rates from the zone map\n" + RATES,
                 with_depth,                 # a 2D grid's one depth, 0, on every row
                 header.title() + "\n" + "\n".join(rows) + "\n",
                 ",".join(f'"{x}"' for x in header.split(",")) + "\n" + quoted + "\n"):
        (tmp_path / "rates.csv").write_text(text)
        assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0, \
            capsys.readouterr().err
        assert json.loads(capsys.readouterr().out)["properties"]["X"]["exit_mean"] == plain



def test_rate_from_a_cell_field():
    from cfbmarkov.kinetics import CellFields

    space = CellGrid(3, 2, 0.09, 1.0)
    path = _tmp_toml('[[property]]\nname = "X"\nlaw = "first-order"\n'
                     'rate_from = "solids_fraction"\nrate_dense = 0.1\nrate_dilute = 1.0\n'
                     'threshold = 0.05\n')
    kin = load_kinetics(path)
    fields = CellFields(np.array([0.2, 0.01, 0.2, 0.1, 0.02, 0.1]), np.zeros(6), np.zeros(6))
    np.testing.assert_array_equal(kin.per_state(space, fields).rate[0],
                                  [0.1, 1.0, 0.1, 0.1, 1.0, 0.1])


def test_two_fields_of_one_property_take_a_threshold_each():
    """coefficient from the wall distance (m) and temperature from the solids fraction (-)
    need thresholds of different scales: coefficient_threshold and temperature_threshold,
    each before the shared threshold."""
    from cfbmarkov.kinetics import CellFields

    space = CellGrid(3, 2, 0.09, 1.0)
    path = _tmp_toml('[[property]]\nname = "T"\nlaw = "heat-exchange"\ninitial = 300\n'
                     'coefficient_from = "wall_distance"\ncoefficient_dense = 5.0\n'
                     'coefficient_dilute = 1.0\ncoefficient_threshold = 0.02\n'
                     'temperature_from = "solids_fraction"\ntemperature_dense = 600\n'
                     'temperature_dilute = 800\nthreshold = 0.05\n')
    fields = CellFields(np.array([0.2, 0.01, 0.2, 0.1, 0.02, 0.1]),
                        np.array([0.015, 0.045, 0.015, 0.015, 0.045, 0.015]), np.zeros(6))
    resolved = load_kinetics(path).per_state(space, fields)
    np.testing.assert_array_equal(resolved.rate[0], [5.0, 1.0, 5.0, 5.0, 1.0, 5.0])
    np.testing.assert_array_equal(resolved.target[0], [600, 800, 600, 600, 800, 600])


def _tmp_toml(text):
    import tempfile
    from pathlib import Path

    path = Path(tempfile.mkdtemp()) / "kin.toml"
    path.write_text(text)
    return path


ZONES = ('[[property]]\nname = "X"\nlaw = "first-order"\nrate_from = "wall_distance"\n'
         'rate_dense = 0.2\nrate_dilute = 2.0\nthreshold = 0.02\n')


def _exit_mean(capsys, argv):
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    return out["properties"]["X"]["exit_mean"], out["cell_fields_from"]


def test_react_rate_from_uses_the_fields_fit_stored(fitted, tmp_path, capsys):
    from cfbmarkov.markov import MarkovModel

    folder, run, model = fitted
    stored = MarkovModel.load(model).cell_fields
    assert stored is not None and stored.n_cells == 18
    assert np.all(stored.solids_fraction > 0)
    dense = stored.wall_distance <= 0.02       # the wall columns, not the core
    assert dense.any() and not dense.all()
    kin = _write(tmp_path, ZONES)
    x_fields, source = _exit_mean(capsys, ["react", str(model), "--kinetics", str(kin),
                                           "--json"])
    assert source == "model"
    # the same answer as a rate table of the same values per cell
    table = "col,row,rate\n" + "".join(f"{c},{r},{0.2 if dense[r * 3 + c] else 2.0}\n"
                                       for r in range(6) for c in range(3))
    (tmp_path / "t").mkdir()
    by_cell = _write(tmp_path / "t", '[[property]]\nname = "X"\nlaw = "first-order"\n'
                     'rate_by_cell = "rates.csv"\n', table)
    x_table, source = _exit_mean(capsys, ["react", str(model), "--kinetics", str(by_cell),
                                          "--json"])
    assert source is None
    assert x_fields == pytest.approx(x_table, rel=1e-12)
    assert 0 < x_fields < 1


def test_react_rate_from_with_run_and_the_refusal(fitted, tmp_path, capsys):
    from cfbmarkov.markov import MarkovModel

    folder, run, model = fitted
    bare = tmp_path / "bare.h5"
    MarkovModel.load(model).with_cell_fields(None).save(bare)
    kin = _write(tmp_path, ZONES)
    # no fields in the model and no run: one line naming the fix, exit 2
    assert main(["react", str(bare), "--kinetics", str(kin)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--run" in err and "stores none" in err
    # with the fitting file: the fields computed there, the same answer as the stored ones
    x_run, source = _exit_mean(capsys, ["react", str(bare), "--kinetics", str(kin), "--run",
                                        str(run), "--json"])
    assert source == str(run)
    x_model, _ = _exit_mean(capsys, ["react", str(model), "--kinetics", str(kin), "--json"])
    assert x_run == pytest.approx(x_model, rel=1e-12)
    # another file than the one fitted on: refused
    other = write_run(tmp_path / "other.h5", RiserFlow(columns=3, rows=6), 60, 2.0, seed=2)
    assert main(["react", str(bare), "--kinetics", str(kin), "--run", str(other)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not the model's fitting file" in err


def test_react_run_must_be_the_fitting_file(fitted, tmp_path, capsys):
    """--run is checked against the model's recorded identity even where the model stores
    its fields: another file is refused in one line naming both files and the fix."""
    folder, run, model = fitted
    kin = _write(tmp_path, ZONES)
    other = write_run(tmp_path / "other.h5", RiserFlow(columns=3, rows=6), 60, 2.0, seed=2)
    for text in (ZONES, GOOD):
        kin = _write(tmp_path, text, RATES)
        assert main(["react", str(model), "--kinetics", str(kin), "--run", str(other)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err
        assert str(other) in err and str(run) in err and "--run" in err
    kin = _write(tmp_path, ZONES)
    x, source = _exit_mean(capsys, ["react", str(model), "--kinetics", str(kin), "--run",
                                    str(run), "--json"])
    assert 0 < x < 1 and source == "model"


def test_pooled_model_stores_pooled_cell_fields(tmp_path, capsys):
    """A pooled fit stores the cell fields of all its runs' windows together (particle-frames
    summed, the velocity weighted by particle-frames per cell); react uses them, accepts
    --run of any one of the pooled runs and refuses another file."""
    from cfbmarkov.analysis.cell_fields import window_cell_fields
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.trajectories import Trajectories

    flow = RiserFlow(columns=3, rows=6)
    a = write_run(tmp_path / "a.h5", flow, 60, 2.0, seed=1)
    b = write_run(tmp_path / "b.h5", flow, 90, 2.0, seed=2)
    other = write_run(tmp_path / "c.h5", flow, 60, 2.0, seed=3)
    pooled = tmp_path / "pooled.h5"
    assert main(["fit", str(a), str(b), "--cells", "3x6", "--window", "0:2,0.5:1.5",
                 "--resamples", "0", "-q", "-o", str(pooled)]) == 0
    capsys.readouterr()
    model = MarkovModel.load(pooled)
    assert model.cell_fields is not None
    with Trajectories(a) as ta, Trajectories(b) as tb:
        fa = window_cell_fields(ta, model.state_space, (0.0, 2.0))
        fb = window_cell_fields(tb, model.state_space, (0.5, 1.5))
        ca = fa["solids_fraction"] * fa["frames"]          # relative: no diameter in files
        # counts per cell: relative fraction times the mean count over cells
        na = ca / ca.mean() * 60 * fa["frames"] / 18
        nb = fb["solids_fraction"] * fb["frames"] / fb["solids_fraction"].mean() * 90 / 18
    expected = (na + nb) / (fa["frames"] + fb["frames"])
    np.testing.assert_allclose(model.cell_fields.solids_fraction, expected / expected.mean(),
                               rtol=1e-9)
    kin = _write(tmp_path, ZONES)
    x, source = _exit_mean(capsys, ["react", str(pooled), "--kinetics", str(kin), "--json"])
    assert 0 < x < 1 and source == "model"
    assert _exit_mean(capsys, ["react", str(pooled), "--kinetics", str(kin), "--run", str(b),
                               "--json"])[0] == x
    assert main(["react", str(pooled), "--kinetics", str(kin), "--run", str(other)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(other) in err and str(a) in err
    # a pooled model without fields: the message says to refit on the runs, not --run
    bare = tmp_path / "bare.h5"
    model.with_cell_fields(None).save(bare)
    assert main(["react", str(bare), "--kinetics", str(kin), "--run", str(a)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pooled" in err and "cfbmarkov fit RUN1.h5" in err


def test_unknown_key_lists_only_the_laws_keys(fitted, tmp_path, capsys):
    """The keys the message offers for first-order exclude wall_temperature (heat-exchange
    only); heat-exchange's include it."""
    _, _, model = fitted
    kin = _write(tmp_path, '[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\n'
                 'speed = 2\n')
    assert main(["react", str(model), "--kinetics", str(kin)]) == 2
    err = capsys.readouterr().err
    assert "unknown key 'speed'" in err and "wall_temperature" not in err
    assert "rate_by_cell" in err
    kin = _write(tmp_path, '[[property]]\nname = "T"\nlaw = "heat-exchange"\n'
                 'coefficient = 1.0\ntemperature = 800\ninitial = 300\nspeed = 2\n')
    assert main(["react", str(model), "--kinetics", str(kin)]) == 2
    assert "wall_temperature" in capsys.readouterr().err


def test_react_says_exits_are_counted_downward_and_repeats_the_verdict(tmp_path, capsys):
    """A model of a net downflow (a run mirrored top to bottom): the table and --json say
    the exits are counted downward; --init repeats the model's fitting-sample warnings as
    predict does."""
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.adequacy import Adequacy
    from cfbmarkov.markov.model_summary import DOWNWARD_LINE
    from cfbmarkov.synthetic import sample_run
    from cfbmarkov.trajectory_writer import write_trajectories

    flow = RiserFlow(columns=3, rows=6, persistence=False)
    times, _, pos, laps = sample_run(flow, 60, 81, seed=4)
    pos[..., 1] = np.nextafter(flow.height, 0) - pos[..., 1]
    down = write_trajectories(tmp_path / "down.h5", times, pos, width=flow.width,
                              height=flow.height, laps=-laps)
    model = tmp_path / "down-model.h5"
    assert main(["fit", str(down), "--cells", "3x6", "--window", "0:2", "--resamples", "0",
                 "-q", "-o", str(model)]) == 0
    capsys.readouterr()
    kin = _write(tmp_path, GOOD, RATES)
    assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["direction"] == "down"
    assert main(["react", str(model), "--kinetics", str(kin)]) == 0
    out = capsys.readouterr().out
    assert "downward" in out and DOWNWARD_LINE in out
    warned = tmp_path / "warned.h5"
    MarkovModel.load(model).with_adequacy(Adequacy(("the halves disagree: test",))).save(warned)
    assert main(["react", str(warned), "--kinetics", str(kin), "--init", str(down), "--start",
                 "0.5", "--duration", "0.5", "-o", str(tmp_path / "p.h5"), "-q"]) == 0
    err = capsys.readouterr().err
    assert "warning: the model's fitting sample: the halves disagree: test" in err


def test_react_warns_where_a_cell_field_cannot_tell_the_zones(fitted, tmp_path, capsys):
    """A solids fraction read as a relative count (the generated file stores no particle
    diameter) and a threshold that puts every cell on one side are said on stderr as
    `warning:` lines naming the property, the range and the fix; the answer is that of the
    one rate it then is everywhere."""
    from cfbmarkov.markov import MarkovModel

    folder, run, model = fitted
    fraction = MarkovModel.load(model).cell_fields.solids_fraction
    assert MarkovModel.load(model).cell_fields.relative
    kin = _write(tmp_path, '[[property]]\nname = "X"\nlaw = "first-order"\n'
                 'rate_from = "solids_fraction"\nrate_dense = 0.2\nrate_dilute = 2.0\n'
                 'threshold = 0.1\n')
    assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0
    captured = capsys.readouterr()
    x = json.loads(captured.out)["properties"]["X"]["exit_mean"]
    lines = [line for line in captured.err.splitlines()
             if not line.startswith("warning: the model's fitting sample: ")]
    assert len(lines) == 2 and all(line.startswith("warning: property X: rate_from = "
                                                   "'solids_fraction'") for line in lines)
    assert "relative to the bed's mean" in lines[0]
    assert f"{fraction.min():.3g}-{fraction.max():.3g}" in lines[0]
    assert "every cell on the dense side" in lines[1] and "rate is 0.2 everywhere" in lines[1]
    (tmp_path / "uniform").mkdir()
    uniform = _write(tmp_path / "uniform",
                     '[[property]]\nname = "X"\nlaw = "first-order"\nrate = 0.2\n')
    assert _exit_mean(capsys, ["react", str(model), "--kinetics", str(uniform), "--json"])[0] \
        == pytest.approx(x, rel=1e-12)
    # a threshold inside the range: only the relative-count line
    middle = float(np.median(fraction))
    kin.write_text(kin.read_text().replace("threshold = 0.1", f"threshold = {middle!r}"))
    assert main(["react", str(model), "--kinetics", str(kin)]) == 0
    err = [line for line in capsys.readouterr().err.splitlines()
           if not line.startswith("warning: the model's fitting sample: ")]
    assert len(err) == 1 and "relative to the bed's mean" in err[0]


def test_react_carried_and_reference_starts_are_said(fitted, tmp_path, capsys):
    """A carried value relaxing to one temperature everywhere leaves the exit at exactly that
    value: its SD is printed 0, not the round-off of E[v^2] - E[v]^2; the table says that a
    carried row is the inventory's steady state and that a reference start without --init
    is answered as a fresh feed."""
    folder, run, model = fitted
    kin = _write(tmp_path, '[[property]]\nname = "T"\nlaw = "heat-exchange"\n'
                 'coefficient = 2.0\ntemperature = 650.0\ninitial = 300.0\n'
                 'start = "carried"\n\n[[property]]\nname = "X"\nlaw = "first-order"\n'
                 'rate = 1.0\nstart = "reference"\n')
    assert main(["react", str(model), "--kinetics", str(kin), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)["properties"]
    assert out["T"]["exit_mean"] == pytest.approx(650.0, rel=1e-12)
    assert out["T"]["exit_sd"] == 0.0
    assert out["X"]["exit_sd"] > 0.01
    assert main(["react", str(model), "--kinetics", str(kin)]) == 0
    text = capsys.readouterr().out
    assert "T (carried): the circulating inventory's steady state" in text
    assert "X (start = reference): the exact answers are those of a fresh feed entering at 0" \
        in text


def test_info_lists_a_predictions_properties(fitted, tmp_path, capsys):
    folder, run, model = fitted
    kin = _write(tmp_path, GOOD, RATES)
    pred = tmp_path / "pred.h5"
    assert main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "0.5", "-o", str(pred), "-q"]) == 0
    capsys.readouterr()
    assert main(["info", str(pred)]) == 0
    out = capsys.readouterr().out
    assert "particle property T (law heat-exchange, start entry) per frame" in out
    assert "particle property X (law first-order, start entry) per frame" in out
    assert main(["info", str(run)]) == 0
    assert "particle property" not in capsys.readouterr().out


def test_react_follows_a_carried_activity_pass_by_pass(fitted, tmp_path, capsys):
    """A carried deactivation's steady state is 0, and react says so and gives the
    activity after 1, 10, 100 passes (or --passes): after one pass the entry start's exit
    mean, after N those of the Python API (each pass entering where the last one landed,
    not the first pass's mean to the power N); --json carries them with the grid's cell
    order and the warnings."""
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.markov.kinetics_exact import exact_kinetics
    from cfbmarkov.markov.model import MarkovModel

    folder, run, model = fitted
    kin = _write(tmp_path, '[[property]]\nname = "a"\nlaw = "deactivation"\nrate = 0.5\n'
                 'start = "carried"\ninitial = 1.0\n\n[[property]]\nname = "fresh"\n'
                 'law = "deactivation"\nrate = 0.5\ninitial = 1.0\n')
    assert main(["react", str(model), "--kinetics", str(kin), "--json", "--passes", "3"]) == 0
    out = json.loads(capsys.readouterr().out)
    one = out["properties"]["fresh"]["exit_mean"]
    carried = out["properties"]["a"]
    assert carried["exit_mean"] == 0 and carried["initial"] == 1.0
    assert main(["react", str(model), "--kinetics", str(kin), "--json", "--passes", "1",
                 "3"]) == 0
    carried = json.loads(capsys.readouterr().out)["properties"]["a"]
    assert carried["after_passes"]["1"]["mean"] == pytest.approx(one, rel=1e-12)
    answer = exact_kinetics(MarkovModel.load(model), load_kinetics(kin))["a"]
    assert carried["after_passes"]["3"]["mean"] == pytest.approx(answer.after_passes(3)[0],
                                                                 rel=1e-12)
    assert "after_passes" not in out["properties"]["fresh"]
    # a number of passes given twice is refused in one line, as maps --times refuses it
    assert main(["react", str(model), "--kinetics", str(kin), "--passes", "5", "3", "5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--passes gives 5 more than once" in err
    assert out["grid"]["columns"] == 3 and out["grid"]["rows"] == 6
    # the model's verdict (a short fitting window here) travels with the answers
    assert out["warnings"] and all(w.startswith("the model's fitting sample: ")
                                   for w in out["warnings"])
    assert main(["react", str(model), "--kinetics", str(kin)]) == 0
    text = capsys.readouterr().out
    assert "(nothing brings it back: it tends to 0)" in text
    after = [answer.after_passes(n)[0] for n in (1, 10, 100)]
    assert (f"a after 1 / 10 / 100 passes from 1: exit mean {after[0]:.6g} / {after[1]:.6g} / "
            f"{after[2]:.6g}") in text


def test_react_refuses_a_reference_start_before_the_monte_carlo(fitted, tmp_path, capsys):
    folder, run, model = fitted
    kin = _write(tmp_path, '[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\n'
                 'start = "reference"\n')
    out = tmp_path / "p.h5"
    assert main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "0.5", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "starts from the reference" in err and "Monte Carlo done" not in err
    assert not out.exists()


def test_reference_values_of_another_law_or_range_are_refused(fitted, tmp_path, capsys):
    """A ``reference`` start takes the stored values of the property of that name: stored
    for another law, or outside the law's range, they are another quantity, refused in one
    line before the Monte Carlo."""
    import h5py

    _, run, model = fitted
    heat = _write(tmp_path, '[[property]]\nname = "T"\nlaw = "heat-exchange"\n'
                  'coefficient = 2.0\ntemperature = 800.0\ninitial = 300.0\n')
    first = tmp_path / "first.h5"
    assert main(["react", str(model), "--kinetics", str(heat), "--init", str(run), "--start",
                 "0.5", "--duration", "0.5", "-o", str(first)]) == 0
    capsys.readouterr()
    conversion = _write(tmp_path, '[[property]]\nname = "T"\nlaw = "first-order"\n'
                        'rate = 1.0\nstart = "reference"\n')
    out = tmp_path / "second.h5"
    argv = ["react", str(model), "--kinetics", str(conversion), "--init", str(first),
            "--start", "0.75", "--duration", "0.25", "-o", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "stores T of law heat-exchange, not first-order" in err
    assert not out.exists()
    with h5py.File(first, "a") as f:         # a file that does not say its law: the range
        del f["properties/T"].attrs["law"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "outside [0, 1], the range of" in err
    assert not out.exists()


def test_a_value_beyond_an_interval_prints_apart_from_its_end():
    """The reference just above the interval's upper end is printed with the digits that
    put it beyond the end as the interval prints it (rounded outwards at those digits),
    never "0.8855 lies above 0.8835-0.8855" nor "0.8854 lies above 0.8801-0.8855"."""
    from cfbmarkov.cli.analysis import _digits, _interval_text, interval_verdict

    line = interval_verdict(0.885512, 0.3, (0.88351, 0.885504), (0.2, 0.4))
    assert "E(RT) 0.885512 s lies above" in line   # the end prints 0.8856, 0.88551 at 4, 5
    assert _interval_text((0.88351, 0.885504), _digits(0.885512, (0.88351, 0.885504))) \
        == "0.883510-0.885504"
    for value, interval in ((0.88546, (0.8801, 0.88541)), (0.74575, (0.74576, 0.9))):
        d = _digits(value, interval)
        lo, hi = (float(v) for v in _interval_text(interval, d).split("-"))
        shown = float(f"{value:.{d}g}")
        assert shown > hi if value > interval[1] else shown < lo, (value, d)
    assert "E(RT) 0.85 s lies below" in interval_verdict(0.85, 0.3, (0.88351, 0.885504),
                                                         (0.2, 0.4))


def test_a_kinetics_miss_within_the_references_own_sampling_is_not_told_apart():
    """The model's exit-mean interval misses the reference's value, but the reference's own
    interval overlaps it: not a miss."""
    from cfbmarkov.cli.analysis import kinetics_verdict

    model = {"exit_mean_interval": [0.8613, 0.8643],
             "interval_method": "block bootstrap of the fitting window (exact exit means) "
                                "and Monte Carlo noise, in quadrature"}
    line = kinetics_verdict("activity", 0.8648, model, 0.9, [0.8634, 0.8663])
    assert line.endswith("overlaps it: the two are not told apart")
    assert kinetics_verdict("activity", 0.8648, model, 0.9, [0.8646, 0.8663]).endswith(
        "the model misses the reference's activity beyond its uncertainty")
    # an interval of the Monte Carlo noise alone (compare --resamples 0, a carried
    # property) leaves out the fitting sample's uncertainty: no verdict from it
    noise = {"exit_mean_interval": [0.8613, 0.8643], "interval_method": "Monte Carlo noise"}
    line = kinetics_verdict("activity", 0.8648, noise, 0.9, [0.8646, 0.8663])
    assert "beyond the Monte Carlo noise; the fitting sample's uncertainty, the larger part, " \
        "is not in this interval (`--resamples 100` forms it), so no verdict" in line
    assert "misses" not in line
    assert "within the Monte Carlo noise" in kinetics_verdict("activity", 0.8620, noise, 0.9)


def test_react_options_that_would_be_ignored_are_refused(fitted, tmp_path, capsys):
    """A Monte Carlo option given alone names the missing ones; --seed without a Monte
    Carlo, and a model file given as the kinetics file, are refused in one line."""
    folder, run, model = fitted
    kin = _write(tmp_path, "[[property]]\nname = \"X\"\nlaw = \"first-order\"\nrate = 0.4\n")
    for argv, message in (
            (["--init", str(run)], "add --start T --duration D -o OUT"),
            (["--init", str(run), "--start", "0", "-o", str(tmp_path / "p.h5")],
             "add --duration D"),
            (["--seed", "3"], "--seed seeds the Monte Carlo"),
            (["--kinetics", str(model)], "is not text (an HDF5 file: a model or trajectory")):
        kinetics = [] if "--kinetics" in argv else ["--kinetics", str(kin)]
        assert main(["react", str(model), *kinetics, *argv]) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "p.h5").exists()


def test_rtd_at_another_level_of_a_model_without_an_interval_is_refused(fitted, tmp_path,
                                                                         capsys):
    _, run, _ = fitted
    bare = tmp_path / "bare.h5"
    assert main(["fit", str(run), "--cells", "3x6", "--window", "0:2", "--resamples", "0",
                 "-o", str(bare)]) == 0
    capsys.readouterr()
    assert main(["rtd", str(bare), "--level", "0.5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds no interval" in err and "--resamples 100" in err
    assert main(["rtd", str(bare)]) == 0
    capsys.readouterr()
    assert main(["predict", str(bare), "--init", str(run), "--start", "0", "--duration",
                 "0.11", "-q", "-o", str(tmp_path / "p.h5")]) == 2
    err = capsys.readouterr().err
    assert "duration 0.11 s is not a whole multiple of the model's lag 0.025 s (e.g. 0.1 or 0.125 s)" in err


def test_react_monte_carlo_prints_its_bed_means(fitted, tmp_path, capsys):
    """The Monte Carlo's line: the bed mean over the particles present at the first and last
    frames, the first the properties' start value (0 for a fresh feed)."""
    import h5py as _h5py

    folder, run, model = fitted
    kin = _write(tmp_path, "[[property]]\nname = \"X\"\nlaw = \"first-order\"\nrate = 2.0\n")
    out = tmp_path / "p.h5"
    assert main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "1", "-q", "-o", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    line = next(x for x in lines if x.startswith("Monte Carlo, bed mean"))
    with _h5py.File(out, "r") as f:
        last = f["properties"]["X"][-1]
    assert "X 0 at 0.5 s" in line and f"{np.nanmean(last):.6g} at 1.5 s" in line
    present = last[np.isfinite(last)]
    se = present.std(ddof=1) / np.sqrt(present.size)
    assert f"(standard error {se:.2g} over its {present.size} particles)" in line
    assert lines[-1] == str(out)


def test_react_repeats_the_residences_the_chain_never_ends(tmp_path, capsys):
    """A chain where a third of the residences fall into a state that is never left: fit,
    rtd and info warn of the unresolved mass, and react, whose exit values average only the
    residences that end, repeats it (on stderr and in --json's warnings)."""
    import numpy as np

    from cfbmarkov.markov.model import MarkovModel
    from cfbmarkov.markov.states import CellGrid

    p = np.zeros((6, 6))            # state = row x 2 + column, one row up a lag
    p[0, 2] = p[2, 4] = 1.0         # column 0 rises to the top
    p[1, 3] = p[1, 5] = 0.5         # column 1: half skip to the top row, half fall into
    p[3, 3] = 1.0                   # a state that is never left (a trap)
    up = np.zeros((6, 6))
    p[4, :2] = p[5, :2] = up[4, :2] = up[5, :2] = 0.5     # the top passes up, landing anywhere
    zeros = np.zeros((6, 6), np.int64)
    model = MarkovModel(p, zeros, zeros, zeros, CellGrid(2, 3, 0.2, 1.0), 0.1,
                        estimator="given", pass_fractions=(up, np.zeros((6, 6))))
    # in Python, a warning says so, once per model and direction (the object kept no word)
    from cfbmarkov.errors import UnresolvedWarning

    with pytest.warns(UnresolvedWarning, match="unresolved mass 0.4 .* describe only the "
                      "resolved 60 % of the residences"):
        assert model.rtd().unresolved > 0.01
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.rtd()
    path = tmp_path / "trap.h5"
    model.save(path)
    kin = _write(tmp_path, '[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\n')
    assert main(["react", str(path), "--kinetics", str(kin), "--json"]) == 0
    out, err = capsys.readouterr()
    warned = json.loads(out)["warnings"]
    assert any(w.startswith("the model: unresolved mass") and "average only the residences "
               "that end" in w for w in warned)
    assert "warning: the model: unresolved mass" in err
    assert "note: unresolved mass" not in err      # the command line's own warning only


def test_the_memory_check_of_a_monte_carlo_counts_its_properties(fitted, tmp_path, capsys,
                                                                  monkeypatch):
    """react --init carries a float64 of each property for every particle at every lag: its
    memory check counts them (with two properties a run needs twice what predict needs),
    so a run that fits without them is refused with them, naming them."""
    import math

    from cfbmarkov.markov.model import MarkovModel
    from cfbmarkov.trajectories import Trajectories

    folder, run, model = fitted
    kin = _write(tmp_path, GOOD, RATES)
    with Trajectories(run) as t:
        particles, dims = t.n_particles, t.dimensions
    lag = MarkovModel.load(model).lag
    steps = round(1.0 / lag)
    plain = (steps + 1) * particles * 8 + 8 * particles * dims
    monkeypatch.setenv("CFBMARKOV_MEMORY_LIMIT", str(math.ceil(1.5 * plain)))
    assert main(["predict", str(model), "--init", str(run), "--start", "0.5", "--duration", "1",
                 "-q", "-o", str(tmp_path / "p.h5")]) == 0
    capsys.readouterr()
    assert main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "1", "-q", "-o", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "particles with 2 properties) would need about" in err
    assert not (tmp_path / "r.h5").exists()


def test_react_monte_carlo_shows_its_progress_while_it_runs(fitted, tmp_path, capsys,
                                                           monkeypatch):
    """Off a terminal, `react --init` prints a line while the Monte Carlo runs and while
    its properties are carried (pieces of one lag here, a line at each), before the frames
    are written; the prediction is the same as one made quietly in one piece."""
    from cfbmarkov.markov import montecarlo, prediction

    folder, run, model = fitted
    kin = _write(tmp_path, GOOD, RATES)
    quiet = tmp_path / "quiet.h5"
    assert main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "1", "-o", str(quiet), "-q"]) == 0
    capsys.readouterr()
    monkeypatch.setattr(prediction, "LINE_INTERVAL", 0.0)
    monkeypatch.setattr(montecarlo, "PIECE_PARTICLE_STEPS", 1)
    shown = tmp_path / "shown.h5"
    assert main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "1", "-o", str(shown)]) == 0
    lines = capsys.readouterr().err.splitlines()
    run_lines = [k for k, line in enumerate(lines) if line.startswith("predict: Monte Carlo ")
                 and " s run, " in line]
    carried = [k for k, line in enumerate(lines) if line.startswith("predict: properties ")]
    done = [k for k, line in enumerate(lines) if line.startswith("predict: Monte Carlo done")]
    assert run_lines and carried and done, lines
    assert max(run_lines) < min(carried) and max(carried) < done[0]
    assert "% carried" in lines[carried[0]] and lines[carried[0]].endswith(" left")
    with h5py.File(quiet) as a, h5py.File(shown) as b:
        for name in ("frames/position", "frames/lap", "properties/X", "properties/T"):
            np.testing.assert_array_equal(a[name][()], b[name][()])


def test_a_missing_kinetics_file_says_what_to_give(fitted, capsys):
    _, _, model = fitted
    assert main(["react", str(model), "--kinetics", "no-such-kinetics.toml"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot read kinetics file no-such-kinetics.toml: No such " \
        "file or directory (give the path of a TOML file of [[property]] tables" in err


def test_react_claims_its_output_before_any_work(fitted, tmp_path, capsys, monkeypatch):
    """The Monte Carlo's output is claimed (locked and checked) first, as every writing
    verb's: an output that is the model itself is refused before the exact solve (it came
    after, and a second writer of the same output was not refused at all)."""
    from cfbmarkov.markov import kinetics_exact

    folder, run, model = fitted
    kin = _write(tmp_path, GOOD, RATES)

    def no_work(*args, **kwargs):
        raise AssertionError("the exact solve ran before the output was claimed")

    monkeypatch.setattr(kinetics_exact, "exact_kinetics", no_work)
    code = main(["react", str(model), "--kinetics", str(kin), "--init", str(run), "--start",
                 "0.5", "--duration", "1", "-o", str(model)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "input" in err, err


def test_a_stretch_of_every_residence_moves_the_exit_mean_by_its_derivative(fitted):
    """stretch_sensitivity: for a uniform first-order rate k the exit conversion of a
    residence of n lags is 1 - exp(-k n lag), so d(exit mean)/d(ln s) is the RTD's mean of
    k t exp(-k t), which the central difference in the rates gives to O(step^2)."""
    from cfbmarkov.analysis.kinetics_compare import stretch_sensitivity
    from cfbmarkov.kinetics import FirstOrder, Kinetics, Property
    from cfbmarkov.markov import MarkovModel

    _, _, path = fitted
    model = MarkovModel.load(path)
    k = 1.5
    sk = Kinetics((Property("X", FirstOrder(), {"rate": k}),)).per_state(model.state_space)
    rtd = model.rtd()
    w = rtd.probability / rtd.probability.sum()
    expected = float(np.sum(w * k * rtd.times * np.exp(-k * rtd.times)))
    got = stretch_sensitivity(model, sk, model.flow_direction)["X"]
    assert got == pytest.approx(expected, rel=1e-3)


def test_the_exit_means_interval_carries_the_models_flow_term(fitted, tmp_path):
    """A model whose E(RT) interval carries the flow's variability between windows (a
    relative SD of E(RT) on some degrees of freedom) gives its exit means' intervals that
    term too, as a stretch of every residence: |d(exit mean)/d(ln s)| times it, with
    Student's t on its degrees of freedom; without it the bootstrap alone."""
    import dataclasses

    from cfbmarkov.analysis.kinetics_compare import exit_mean_intervals, stretch_sensitivity
    from cfbmarkov.markov import MarkovModel

    folder, _, path = fitted
    kin = load_kinetics(_write(tmp_path, GOOD, RATES))
    model = MarkovModel.load(path)
    plain = model.with_uncertainty(dataclasses.replace(
        model.uncertainty, flow_sd=None, flow_degrees_of_freedom=None))
    flowing = model.with_uncertainty(dataclasses.replace(
        model.uncertainty, flow_sd=(0.1, 0.05), flow_degrees_of_freedom=3))
    measured_zero = model.with_uncertainty(dataclasses.replace(
        model.uncertainty, flow_sd=(0.0, 0.0), flow_degrees_of_freedom=2))
    zero = exit_mean_intervals(measured_zero, kin, resamples=20,
                               candidates=[folder / "run.h5"])
    # a flow term measured as 0 is carried (as 0), as compare carries it: not "left out"
    assert zero["flow_sd"]["X"]["exit_mean"] == 0.0
    assert zero["flow_sd"]["X"]["degrees_of_freedom"] == 2
    without = exit_mean_intervals(plain, kin, resamples=20, candidates=[folder / "run.h5"])
    with_flow = exit_mean_intervals(flowing, kin, resamples=20,
                                    candidates=[folder / "run.h5"])
    assert without["flow_sd"] == {}
    slope = stretch_sensitivity(model, kin.per_state(model.state_space, model.cell_fields),
                                model.flow_direction)
    for name in ("X", "T"):
        term = with_flow["flow_sd"][name]
        assert term["exit_mean"] == pytest.approx(abs(slope[name]) * 0.1, rel=1e-12)
        assert term["rt_mean_relative"] == 0.1 and term["degrees_of_freedom"] == 3
        (a, b), (c, d) = without["exit_mean"][name], with_flow["exit_mean"][name]
        assert c < a and d > b


def test_react_repeats_an_open_risers_returns_and_its_intervals_lines(tmp_path, capsys):
    """The exit means rest on the exits the chain was fitted on: react repeats the open
    riser's lines (returns through the inlet, as predict does) and, with --resamples, the
    model's lines on its interval (the same bootstrap)."""
    from tests.analysis.test_model_intervals import _returning_riser_csv

    csv = _returning_riser_csv(tmp_path / "r.csv")
    run, model = tmp_path / "r.h5", tmp_path / "m.h5"
    assert main(["import", str(csv), "--format", "csv", "--width", "0.1", "--height", "1",
                 "--boundary", "open", "-o", str(run)]) == 0
    assert main(["fit", str(run), "--cells", "2x10", "--lag", "0.1", "--window", "2:7.5",
                 "--resamples", "20", "-q", "-o", str(model)]) == 0
    capsys.readouterr()
    kin = _write(tmp_path, '[[property]]\nname = "X"\nlaw = "first-order"\nrate = 0.7\n')
    assert main(["react", str(model), "--kinetics", str(kin), "--resamples", "20"]) == 0
    err = capsys.readouterr().err
    assert "warning: the model: " in err and " returns through the inlet against " in err
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.model_summary import fitting_run_count, one_sided_interval_warnings

    m = MarkovModel.load(model)
    for line in (m.uncertainty.warnings(fitting_run_count(m))
                 + one_sided_interval_warnings(m)):
        assert line in err


def test_a_reducible_chains_exit_interval_has_the_rtd_intervals_definition(tmp_path):
    """Columns whose particles never cross (closed classes of different E(RT)): the
    resamples of an exit mean start from the fitted model's entry distribution, as the
    RTD's do, so a slow first-order conversion (X ~ k E(RT)) has the relative interval of
    E(RT), where each resample's own entry distribution re-weighted the classes and spread
    it several times as far."""
    from cfbmarkov.analysis.intervals import model_intervals
    from cfbmarkov.analysis.kinetics_compare import exit_mean_intervals
    from cfbmarkov.kinetics import FirstOrder, Kinetics, Property
    from cfbmarkov.markov import MarkovModel, fit_model

    flow = RiserFlow(columns=4, rows=8, lag=0.025, persistence=False, rise_velocity=2.0,
                     fall_velocity=-1.0, lateral_probability=0.0)
    run = write_run(tmp_path / "run.h5", flow, 200, 4.0, seed=3)
    model = fit_model(run, CellGrid(4, 8), 0.025, (0.0, 4.0), "mle")
    assert len(model.closed_classes) > 1
    path = model.save(tmp_path / "m.h5")
    model = MarkovModel.load(path)
    rt = model_intervals(model, resamples=40)
    k = 0.01
    kin = Kinetics((Property("X", FirstOrder(), {"rate": k}),))
    formed = exit_mean_intervals(model, kin, resamples=40, candidates=[run])
    lo, hi = formed["exit_mean"]["X"]
    mean = model.rtd().mean
    width_rt = (rt.rt_mean_interval[1] - rt.rt_mean_interval[0]) / mean
    width_x = (hi - lo) / (k * mean)
    assert width_x == pytest.approx(width_rt, rel=0.3)


def test_a_carried_propertys_resamples_keep_their_own_circulation(fitted):
    """A carried property's steady state closes each resample's own circulation (its
    landings fed back as its entries): with a uniform target every chain's steady exit mean
    is the target, and so is every resample's, so the interval is that one value (a
    foreign entry distribution gave 348.75-350.93 around 350)."""
    from cfbmarkov.analysis.kinetics_compare import exit_mean_intervals
    from cfbmarkov.kinetics import HeatExchange, Kinetics, Property
    from cfbmarkov.markov import MarkovModel

    folder, _, path = fitted
    kin = Kinetics((Property("T", HeatExchange(), {"coefficient": 2.0, "temperature": 350.0},
                             initial=300.0, start="carried"),
                    Property("X", HeatExchange(), {"coefficient": 2.0,
                                                   "temperature": 350.0}, initial=300.0)))
    formed = exit_mean_intervals(MarkovModel.load(path), kin, resamples=20,
                                 candidates=[folder / "run.h5"])
    lo, hi = formed["exit_mean"]["T"]
    assert lo == pytest.approx(350.0, abs=1e-9) and hi == pytest.approx(350.0, abs=1e-9)
    lo, hi = formed["exit_mean"]["X"]              # entering at 300: below, with a spread
    assert lo < hi < 350.0


@pytest.mark.parametrize("rate", [1e-3, 1e-7])
def test_the_spread_after_passes_keeps_its_digits_at_slow_rates(fitted, rate):
    """A slowly deactivating carried catalyst: after one pass a = exp(-k RT) ~ 1 - k RT, so
    its SD is k SD(RT) to O(k); formed from E[a^2] - E[a]^2 around 0 it lost every digit
    (printed 0 at 1e-6 1/s). The moments of a - mean keep them; 1000 passes spread it about
    sqrt(1000) times as far (the passes correlated a little)."""
    from cfbmarkov.kinetics import Deactivation, Kinetics, Property
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.markov.kinetics_exact import exact_kinetics

    _, _, path = fitted
    model = MarkovModel.load(path)
    answer = exact_kinetics(model, Kinetics((Property("a", Deactivation(), {"rate": rate},
                                                      start="carried"),)))["a"]
    mean, sd = answer.after_passes(1)
    rtd = model.rtd()
    assert mean == pytest.approx(1.0 - rate * rtd.mean, rel=10 * rate)
    assert sd == pytest.approx(rate * rtd.sd, rel=10 * rate + 1e-6)
    many = answer.after_passes(1000)[1]
    assert 10 * sd < many < 100 * sd


def test_a_passes_note_without_a_carried_property_is_in_the_json_warnings(fitted, tmp_path,
                                                                           capsys):
    """--passes on a kinetics file with no carried property is noted on stderr and, with
    --json, among the warnings a script reads."""
    _, _, model = fitted
    kin = _write(tmp_path, '[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\n')
    assert main(["react", str(model), "--kinetics", str(kin), "--passes", "5", "--json"]) == 0
    captured = capsys.readouterr()
    assert "note: --passes follows carried properties" in captured.err
    assert any(w.startswith("--passes follows carried properties")
               for w in json.loads(captured.out)["warnings"])
