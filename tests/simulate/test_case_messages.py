"""Refusals of a case that name the case file's key to change, not a Python argument or a
fix that cannot help."""

import pytest
from pydantic import ValidationError

from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.simulate.coupling import place_without_overlap
from cfbmarkov.simulate.dem.neighbours import search_grid
from tests.test_reproduce import TINY

#: the miniature reproduction's case (240 particles in a 0.03 x 0.12 m riser), its frame
#: interval and end set here
CASE = (TINY.replace("frame_interval = 0.01", "frame_interval = {frame}")
        .replace("end_time = 0.8", "end_time = 0.05"))


def test_a_particle_wider_than_the_riser_asks_for_a_smaller_diameter():
    with pytest.raises(InputError, match=r"at most 0 on the starting lattice of 0 x 2 sites\); "
                                         r"give a particles.diameter smaller than the riser"):
        place_without_overlap(10, 0.05, 0.03, 0.12, seed=1)
    with pytest.raises(InputError, match=r"give fewer particles \(particles.number, or --particles\)"):
        place_without_overlap(10_000, 0.001, 0.03, 0.12, seed=1)


def test_search_cells_too_small_name_the_automatic_grid_of_a_case_file():
    with pytest.raises(InputError, match=r'numerics.dem_cells = "auto" in a case file'):
        search_grid(0.03, 0.12, 0.0014, (100, 400), True)


def test_a_frame_interval_between_gas_steps_names_the_keys(tmp_path, capsys):
    case = tmp_path / "case.toml"
    case.write_text(CASE.format(frame=0.00012))          # gas steps of 5e-5 s
    assert main(["simulate", str(case), "-o", str(tmp_path / "run.h5"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.endswith("frame interval 0.00012 s is not a whole number of gas steps (5e-05 "
                        "s): give an output.frame_interval that is (e.g. 0.0001 s), or "
                        "another numerics.cfd_time_step"), err
    assert not (tmp_path / "run.h5").exists()


@pytest.mark.parametrize("line, key, written", [
    ("number = true", "particles.number", "true"),
    ('width = "0.03"', "riser.width", '"0.03"'),
    ("cfd_cells = [true, 12]", "numerics.cfd_cells", "[true, 12]"),
])
def test_true_or_text_where_a_number_is_meant_is_refused(tmp_path, capsys, line, key,
                                                         written):
    """true read as 1 particle, "0.03" as 0.03 m: refused, naming the key and the value as
    the file writes it."""
    text = CASE.format(frame=0.01)
    old = {"particles.number": "number = 240", "riser.width": "width = 0.03",
           "numerics.cfd_cells": "cfd_cells = [3, 12]"}[key]
    case = tmp_path / "case.toml"
    case.write_text(text.replace(old, line))
    assert main(["simulate", str(case), "-o", str(tmp_path / "run.h5"), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert f"invalid configuration at '{key}'" in err
    assert f"a number is meant, not {written} (write the number itself, without quotes)" in err
    assert not (tmp_path / "run.h5").exists()


def test_a_gas_step_not_a_multiple_of_the_dem_step_names_one_that_is():
    """cfd_time_step 5.2e-5 s on a 5e-6 s DEM step: the refusal gives the nearest multiple."""
    from cfbmarkov.config import CaseConfig

    with pytest.raises(ValidationError, match=r"must be a whole multiple of dem_time_step "
                       r"5e-06 s \(e.g. 5e-05 s, 10 DEM steps per gas step\)"):
        CaseConfig.model_validate({"numerics": {"cfd_time_step": 5.2e-5}})
