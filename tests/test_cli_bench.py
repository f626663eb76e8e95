"""``cfbmarkov bench --only``: names are checked and listed, and a figure's name runs that
figure alone."""

from __future__ import annotations

from cfbmarkov.bench import MCM_NAMES, selects
from cfbmarkov.cli import build_parser, main


def test_an_unknown_name_is_refused_listing_the_valid_ones(capsys):
    assert main(["bench", "--only", "nope"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert "unknown benchmark 'nope'" in captured.err and "mcm-exact-rtd" in captured.err


def test_help_lists_the_names():
    text = " ".join(build_parser()._subparsers._group_actions[0].choices["bench"]
                    .format_help().split())
    for name in ("mcm", "cfd-dem", "mcm-exact-rtd", "mcm-fit-regime"):
        assert name in text


def test_a_figures_name_selects_that_figure_alone():
    assert [n for n in MCM_NAMES if selects(["mcm-fit"], n)] == ["mcm-fit"]
    assert [n for n in MCM_NAMES if selects(["mcm"], n)] == list(MCM_NAMES)
    assert selects(["mcm-fit-chosen"], "mcm-fit-chosen-cells-direction")
    assert selects(["dem-throughput"], "dem-throughput-lammps-2ranks")
    assert not selects(["dem-throughput"], "dem-throughput-dense")


def test_only_the_named_figure_is_measured(capsys):
    assert main(["bench", "--only", "mcm-exact-rtd", "--repeat", "1", "--particles",
                 "200"]) == 0
    captured = capsys.readouterr()
    assert [line.split(":")[0] for line in captured.out.splitlines()] == ["mcm-exact-rtd"]
    assert "bench: mcm-exact-rtd done" in captured.err and "\r" not in captured.err


def test_a_simulation_figure_alone_runs_nothing_else(monkeypatch):
    """``--only dem-throughput`` measures the dilute DEM alone: neither the dense DEM nor
    the coupled riser (half a second of the paper's riser to develop) runs."""
    from cfbmarkov.simulate import bench as simulation

    ran = []
    monkeypatch.setattr(simulation, "_dem_rate",
                        lambda state, particles, repeat: ran.append(state) or 1.0)
    monkeypatch.setattr(simulation, "_lammps_lines", lambda *args: iter(()))
    monkeypatch.setattr(simulation, "fluidized_riser",
                        lambda particles: ran.append("coupled") or None)
    rows = list(simulation.simulation_benchmarks(
        repeat=1, particles=10, wanted=lambda name: selects(["dem-throughput"], name)))
    assert [row[0] for row in rows] == ["dem-throughput"] and ran == ["dilute"]
    ran.clear()
    rows = list(simulation.simulation_benchmarks(
        repeat=1, particles=10, wanted=lambda name: selects(["dem"], name)))
    assert [row[0] for row in rows] == ["dem-throughput", "dem-throughput-dense"]
    assert ran == ["dilute", "dense"]
