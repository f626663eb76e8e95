"""Settings that the periodic riser's CFD-DEM or a reproduction's Markov stages cannot run
are refused before anything runs or is written: in one line, exit 2, naming the setting,
with no note about the time step printed first."""

import pytest

from cfbmarkov.cases.scales import scale_cases
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError

#: a small case of the paper's particles whose DEM step draws the time-step note
CASE = """
[riser]
width = 0.02
height = 0.10
{riser}
[particles]
number = 300
[numerics]
cfd_cells = [2, 10]
dem_time_step = 1e-5
cfd_time_step = 1e-4
{numerics}
[output]
end_time = 0.2
frame_interval = 0.01
"""


@pytest.mark.parametrize("riser, numerics, said", [
    ("distributor_pressure_drop = 500.0", "",
     "riser.distributor_pressure_drop 500 Pa: the periodic riser has no distributor"),
    ("", "dem_cells = [1, 1]", "search cells 1 x 1: a periodic height needs at least 3 rows "
     "of search cells; use 3 to 71 rows, or the automatic grid"),
    ("", "dem_skin = 0.05", "the neighbour cutoff 2*R_max + skin = 51 mm exceeds the width W "
     "= 20 mm: a smaller numerics.dem_skin"),
    ("", "dem_cells = [100, 1000]", "search cells 100 x 1000 are 0.2 x 0.1 mm, smaller than "
     "the neighbour cutoff"),
])
def test_simulate_refuses_before_the_note(tmp_path, capsys, riser, numerics, said):
    case = tmp_path / "c.toml"
    case.write_text(CASE.format(riser=riser, numerics=numerics))
    assert main(["simulate", str(case), "-o", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err and "note:" not in err, err
    assert list(tmp_path.iterdir()) == [case]


OVERRIDES = {"riser": {"width": 0.02, "height": 0.10}, "particles": {"number": 300},
             "numerics": {"cfd_cells": [2, 10], "dem_cells": "auto"},
             "output": {"end_time": 0.6, "frame_interval": 0.01},
             "markov": {"columns": 2, "rows": 4, "lag": 0.01, "fit_window": [0.2, 0.4],
                        "predict_window": [0.4, 0.6]}}


def _with(section, **values):
    changed = {k: dict(v) if isinstance(v, dict) else v for k, v in OVERRIDES.items()}
    changed.setdefault(section, {}).update(values)
    return changed


@pytest.mark.parametrize("overrides, said", [
    (_with("gas", superficial_velocity=3.0), "overrides may not set gas.superficial_velocity: "
     "a reproduction sets it per case (--velocities)"),
    ({**OVERRIDES, "name": "mine"}, "overrides may not set name"),
    (_with("markov", fit_window=[0.4, 0.2]), "at 'markov.fit_window' for U = 5 m/s: [0.4, 0.2] "
     "s is not [start, stop] with 0 <= start < stop (e.g. [0.2, 0.4])"),
    (_with("markov", predict_window=[0.4, 0.8]), "predict_window [0.4, 0.8] s ends after the "
     "CFD-DEM's output.end_time 0.6 s"),
    (_with("markov", lag=0.015), "lag 0.015 s: a whole multiple of output.frame_interval "
     "0.01 s (the frames the CFD-DEM stores), e.g. 0.02"),
    (_with("markov", fit_window=[0.2, 0.205]), "fit_window [0.2, 0.205] s is shorter than one "
     "lag"),
    (_with("numerics", dem_cells=[13, 100]), "search cells 13 x 100 are 1.538 x 1 mm"),
])
def test_reproduction_settings_are_checked_before_its_cfd_dem(overrides, said):
    with pytest.raises(InputError) as caught:
        scale_cases("quick", [5.0], overrides)
    assert said in str(caught.value), str(caught.value)


def test_simulate_refuses_a_reversed_window_in_its_case_file(tmp_path, capsys):
    case = tmp_path / "c.toml"
    case.write_text(CASE.format(riser="", numerics="") + "[markov]\nfit_window = [0.4, 0.2]\n")
    assert main(["simulate", str(case), "-o", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "markov.fit_window" in err and "(e.g. [0.2, 0.4])" in err


def test_the_same_overrides_without_the_fault_pass():
    (case,) = scale_cases("quick", [5.0], OVERRIDES)
    assert case.gas.superficial_velocity == 5.0 and case.markov.fit_window == (0.2, 0.4)


def test_reproduce_writes_nothing_for_a_fault_of_its_markov_settings(tmp_path, capsys):
    overrides = tmp_path / "o.toml"
    overrides.write_text("[output]\nend_time = 0.6\n")        # the fit window 1-2 s: beyond
    out = tmp_path / "run"
    assert main(["reproduce", "--scale", "quick", "--velocities", "5", "--models", "paper",
                 "--overrides", str(overrides), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "ends after the CFD-DEM's output.end_time 0.6 s" in err
    assert not out.exists()
