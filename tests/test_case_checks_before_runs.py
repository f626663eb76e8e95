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
    (_with("markov", fit_window=[0.3, 0.5]), "predict_window [0.4, 0.6] s starts inside "
     "fit_window [0.3, 0.5] s: a reproduction compares the model on the window after the one "
     "it was fitted on (predict_window from 0.5 s on"),
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


#: the tables of a small case that runs, as TOML lines per table
TABLES = {"riser": ["width = 0.02", "height = 0.10"], "particles": ["number = 300"],
          "numerics": ["cfd_cells = [2, 10]", "dem_time_step = 1e-5", "cfd_time_step = 1e-4"],
          "output": ["end_time = 0.2", "frame_interval = 0.01"]}


def _case_text(table: str, line: str) -> str:
    """The small case with ``line`` in ``table`` (replacing a line of the same key)."""
    tables = {name: list(lines) for name, lines in TABLES.items()}
    key = line.split("=")[0].strip()
    tables[table] = [x for x in tables.get(table, []) if x.split("=")[0].strip() != key]
    tables[table].append(line)
    return "".join(f"[{name}]\n" + "".join(x + "\n" for x in lines)
                   for name, lines in tables.items())


@pytest.mark.parametrize("table, line, said", [
    ("contact", "friction_coeficient = 0.3", "at 'contact.friction_coeficient': unknown key "
     "'friction_coeficient' in [contact]; did you mean 'friction_coefficient'? ([contact] "
     "takes: normal_stiffness,"),
    ("output", "dem_time_step = 1e-5", "unknown key 'dem_time_step' in [output]; it belongs "
     "in [numerics]"),
    ("riser", "depth = 0.01", "unknown key 'depth' in [riser]: the CFD-DEM simulates a 2D "
     "periodic riser; a 3D riser comes from imported data (cfbmarkov import)"),
    ("riser", 'boundary = "open"', "an open riser comes from imported data"),
    ("numerics", 'dem_cells = "Auto"', "at 'numerics.dem_cells': expected DEM "
     "neighbour-search cells [across, up], or \"auto\""),
    ("numerics", "cfd_cells = [2, 10, 4]", "at 'numerics.cfd_cells': expected gas grid cells "
     "[across, up]"),
    ("markov", "fit_window = [0.2]", "at 'markov.fit_window': expected fitting window "
     "[start, stop], s"),
    ("numerics", "dem_time_step = 5e-5", "at least 5 are needed (10 or more recommended): "
     "numerics.dem_time_step at most 5.18e-06 s (2.59e-06 s recommended"),
    ("numerics", "cfd_cells = [200, 1000]", "numerics.cfd_time_step at most"),
])
def test_a_case_files_faults_name_the_setting_and_what_it_takes(tmp_path, capsys, table, line,
                                                                said):
    case = tmp_path / "c.toml"
    case.write_text(_case_text(table, line))
    assert main(["simulate", str(case), "-o", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err and "Traceback" not in err, err


def test_unlikely_units_are_noted():
    from cfbmarkov.config import CaseConfig
    from cfbmarkov.simulate.run import unlikely_units

    assert unlikely_units(CaseConfig()) == []
    slip = CaseConfig.model_validate({"riser": {"width": 20.0}, "particles": {"density": 2.5}})
    notes = unlikely_units(slip)
    assert notes == ["riser.width 20 m is 20000 particle diameters (d = 0.001 m): lengths are "
                     "in m (20 mm would be 0.02)",
                     "particles.density 2.5 kg/m^3 is below 100 kg/m^3: densities are in "
                     "kg/m^3 (2.5 g/cm^3 would be 2500)"]


def test_the_time_step_note_says_when_the_overrides_set_the_step():
    """The run's note names the scale's step, or the step the overrides made."""
    import warnings

    from cfbmarkov.errors import TimeStepAdvisory
    from cfbmarkov.reproduce import SCALES, _advise_time_step

    cases = scale_cases("quick", [5.0], OVERRIDES)
    for overridden, whose in ((False, "(the quick scale's step;"),
                              (True, "(the quick scale's step and contacts with the overrides;")):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            _advise_time_step(SCALES["quick"], cases, ["u5"], overridden)
        (note,) = [w for w in caught if w.category is TimeStepAdvisory]
        assert whose in str(note.message), str(note.message)


def test_an_item_out_of_range_keeps_its_index_and_pydantics_words(tmp_path, capsys):
    """A value constraint on one item of a pair is said as it is, at the item's location."""
    case = tmp_path / "c.toml"
    case.write_text(_case_text("numerics", "cfd_cells = [0, 5]"))
    assert main(["simulate", str(case), "-o", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert "at 'numerics.cfd_cells.0': Input should be greater than 0 (given 0)" in err


def test_a_number_out_of_range_says_the_settings_unit(tmp_path, capsys):
    """A diameter of 1 (1 mm written as 1) was refused as "Input should be less than or
    equal to 0.1" with no unit: the message now says what the setting is, in its unit."""
    case = tmp_path / "c.toml"
    case.write_text(_case_text("particles", "diameter = 1.0"))
    assert main(["simulate", str(case), "-o", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert ("at 'particles.diameter': Input should be less than or equal to 0.1 (given 1.0); "
            "it is the particle diameter d, m (Table 1: 0.001 m)") in err, err


def test_gas_cells_smaller_than_a_particle_are_refused_and_narrow_ones_noted(tmp_path, capsys):
    """Gas cells narrower than a particle (d = 15 mm in 10 mm cells) put a cell's void
    fraction at its floor from one particle: the run went on with no word; now refused
    before anything runs. Cells of 1-3 diameters are noted."""
    from cfbmarkov.config import load_case
    from cfbmarkov.simulate.run import doubtful_physics

    case = tmp_path / "c.toml"
    case.write_text(CASE.format(riser="", numerics="").replace("number = 300",
                                                               "number = 5\ndiameter = 0.015"))
    assert main(["simulate", str(case), "-o", str(tmp_path / "r.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gas cells 0.01 x 0.01 m are smaller than the particles" \
        in err, err
    assert list(tmp_path.iterdir()) == [case]
    case.write_text(CASE.format(riser="", numerics="").replace("number = 300",
                                                               "number = 20\ndiameter = 0.004"))
    notes = doubtful_physics(load_case(case))
    assert "are 2.5 particle diameters across" in notes[0]
    case.write_text(CASE.format(riser="", numerics=""))
    assert doubtful_physics(load_case(case)) == []


def test_a_gas_too_slow_to_fluidise_and_frames_too_far_apart_are_noted(tmp_path):
    """A superficial velocity below the case's minimum fluidization velocity (the solids fall
    as in a downer) and frames so far apart that a falling particle crosses the riser between
    two (the run stopped at its first checkpoint, its work lost) are said before the run."""
    from cfbmarkov.config import load_case
    from cfbmarkov.simulate.run import doubtful_physics

    case = tmp_path / "c.toml"
    case.write_text(CASE.format(riser="", numerics="") + "[gas]\nsuperficial_velocity = 0.1\n")
    notes = doubtful_physics(load_case(case))
    assert len(notes) == 1 and "0.1 m/s is below the case's minimum fluidization velocity " \
        "0.44 m/s" in notes[0]
    slow_frames = CASE.format(riser="", numerics="").replace("frame_interval = 0.01",
                                                             "frame_interval = 0.02")
    case.write_text(slow_frames + "[gas]\nsuperficial_velocity = 3.0\n")
    notes = doubtful_physics(load_case(case))
    assert len(notes) == 1 and "frames 0.02 s apart" in notes[0]
    assert "(6.99 m/s) crosses the riser's height 0.1 m" in notes[0]
    assert "output.frame_interval at most 0.014 s" in notes[0]
