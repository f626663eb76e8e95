"""``cfbmarkov reproduce`` in miniature: every stage a file, skip and resume, the report, the
local and Dask executors, and the scales' claims (hold-up, contact resolution, windows)."""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import signal
import subprocess
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.config import load_case
from cfbmarkov.errors import InputError
from cfbmarkov.reproduce import SCALES, reproduce, scale_cases
from cfbmarkov.simulate.dem import ContactLaw
from cfbmarkov.trajectories import Trajectories
from tests.shared_builds import built_once, worker_copy

TINY = """
[riser]
width = 0.03
height = 0.12
[particles]
number = 240
[numerics]
cfd_cells = [3, 12]
dem_cells = [10, 40]
[output]
end_time = 0.8
frame_interval = 0.01
[markov]
columns = 2
rows = 6
lag = 0.01
fit_window = [0.2, 0.5]
predict_window = [0.5, 0.8]
interval_resamples = 20
"""
STAGES = ["case.json", "cfd-dem.h5", "model-paper.h5", "model-mle.h5", "model-auto.h5",
          "prediction-paper.h5", "prediction-mle.h5", "prediction-auto.h5",
          "compare-paper/summary.json", "compare-mle/summary.json", "compare-auto/summary.json",
          "timings.json"]


def tiny(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def run_arrays(path):
    with Trajectories(path) as t:
        out = [t.times, t.positions(), t.laps()]
        if t.has_velocity:
            out.append(t.velocities())
        ev = t.events()
        if ev is not None:
            out += [ev.time, ev.particle, ev.direction]
        return out


def assert_same_files(a: Path, b: Path, names=("cfd-dem.h5", "prediction-paper.h5",
                                                "prediction-mle.h5")):
    for name in names:
        for x, y in zip(run_arrays(a / name), run_arrays(b / name)):
            np.testing.assert_array_equal(x, y)


#: what the reference reproduction printed on stderr
STDERR: dict[str, str] = {}
STDOUT: dict[str, str] = {}


def _build_reference(folder: Path) -> None:
    overrides = tiny(folder)
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        assert main(["reproduce", "--scale", "quick", "--overrides", str(overrides),
                     "--velocities", "8", "-o", str(folder / "ref"), "--jobs", "1"]) == 0
    (folder / "stderr.txt").write_text(err.getvalue())
    (folder / "stdout.txt").write_text(out.getvalue())


@pytest.fixture(scope="session")
def reference(tmp_path_factory):
    """An uninterrupted miniature reproduction at 8 m/s (inline executor), with progress:
    built once per test run, this worker's own copy."""
    shared = built_once(tmp_path_factory, "reproduce-reference", _build_reference)
    folder = worker_copy(tmp_path_factory, shared, "reproduce-reference")
    STDERR["reference"] = (folder / "stderr.txt").read_text()
    STDOUT["reference"] = (folder / "stdout.txt").read_text()
    return folder / "ref", folder / "tiny.toml"


def test_each_models_line_says_where_the_reference_lies_and_its_warnings(reference):
    """The terminal's line of each model's figures says where the CFD-DEM's E(RT) lies
    against the model's interval and how many warnings its comparison carries (its
    summary.json's), and the run ends with the report's verdict line, links as text."""
    out, _ = reference
    printed = STDOUT["reference"].splitlines()
    names = [p.name[len("compare-"):] for p in sorted((out / "u8").glob("compare-*"))]
    assert names
    for name in names:
        summary_path = out / "u8" / f"compare-{name}" / "summary.json"
        summary = json.loads(summary_path.read_text())
        line = next(x for x in printed if x.startswith(f"u8 {name:>5}: PD E(RT) "))
        lo, hi = summary["model"]["rt_mean_interval"]
        ref = summary["reference"]["rt_mean"]
        place = "inside" if lo <= ref <= hi else "below" if ref < lo else "above"
        assert (f"; the CFD-DEM's E(RT) {ref:.4g} s lies {place} the model's 90 % interval "
                f"{lo:.4g}-{hi:.4g} s") in line, line
        warned = len(summary["warnings"])
        assert (f"; {warned} warning" in line) == (warned > 0), line
    verdict = [x for x in printed if x.startswith("verdict: ")]
    assert len(verdict) == 1 and verdict[0].startswith("verdict: Verdict at the quick scale: ")
    assert "](#" not in verdict[0] and "Next step: " in verdict[0]
    assert printed[-1].endswith("report.html")     # the path last, as scripts read it


def check_case_lines(err: str, cases) -> None:
    """Every line on stderr is whole: progress lines naming their case, from start to end,
    then one advisory for the run that finished, the quick scale's step (``note:``, no
    Python warning format)."""
    lines = err.splitlines()
    assert lines and not any("Warning" in line or "warn(" in line for line in lines), lines
    notes = [x for x in lines if x.startswith("note: ")]
    assert len(notes) == 1 and notes == lines[-1:], lines
    assert notes[0].startswith("note: DEM time step 1e-05 s resolves a contact in 5.18 steps")
    assert notes[0].endswith("(the quick scale's step; the paper's settings give 5.18 steps)"
                             if len(cases) == 1 else "(the quick scale's step, the same in "
                             "every case; the paper's settings give 5.18 steps)")
    for case in cases:
        progress = [x for x in lines if x.startswith(f"{case}: CFD-DEM ")]
        assert progress[0].startswith(f"{case}: CFD-DEM starting at 0/")
        assert " s simulated in " in progress[-1] and len(progress) >= 3
    named = tuple(f"{c}: CFD-DEM " for c in cases)
    assert all(line.startswith(named) and "\r" not in line for line in lines[:-1]), lines


def test_progress_and_advisory_are_whole_lines_naming_the_case(reference):
    check_case_lines(STDERR["reference"], ["u8"])


def test_every_stage_is_a_file_and_the_report_has_every_section(reference, capsys):
    out, _ = reference
    manifest = json.loads((out / "reproduce.json").read_text())
    assert manifest["scale"] == "quick" and manifest["cases"] == ["u8"]
    # the scale's description and reductions say that the overrides changed them
    assert manifest["description"].endswith(
        "every case then changed by the overrides of riser.width, riser.height, "
        "particles.number, numerics.cfd_cells, numerics.dem_cells, output.end_time, "
        "output.frame_interval, markov.columns, markov.rows, markov.lag, markov.fit_window, "
        "markov.predict_window, markov.interval_resamples")
    assert manifest["reductions"][-1].startswith(
        "then the overrides, which replace what the lines above say of the same settings: "
        "riser.width = 0.03, riser.height = 0.12, particles.number = 240")
    for name in STAGES:
        assert (out / "u8" / name).exists(), name
    timings = json.loads((out / "u8" / "timings.json").read_text())
    cfd = timings["cfd_dem"]
    # the wall time of the prediction window comes from the checkpoint history, not pro rata
    assert cfd["predict_window_estimated"] is False
    assert 0 < cfd["predict_window_wall_s"] < cfd["wall_s"]
    for stage in ("fit-paper", "predict-paper", "fit-mle", "predict-mle", "compare-paper"):
        assert timings[stage]["wall_s"] > 0 and timings[stage]["cpu_s"] > 0
    assert cfd["cpu_s"] > 0      # the CPU time of the process that ran it
    summary = json.loads((out / "u8" / "compare-paper" / "summary.json").read_text())
    assert summary["window"] == [0.5, 0.8] and summary["same_tracer_groups"]
    assert summary["basis"] == "frames" and summary["exact_reference"]["rt_count"] > 0
    html = (out / "report.html").read_text()
    for heading in ("Table 3", "Computing time", "Fig. 3", "Fig. 8", "Fig. 9", "Fig. 11",
                    "Beyond the paper", "Implied timescales", "Chapman-Kolmogorov"):
        assert heading in html, heading
    # the three models of a reproduction, the automatic one with its reason
    for model in ("paper", "mle", "auto"):
        assert (out / "u8" / f"compare-{model}" / "summary.json").exists()
    assert "Chosen: " in (out / "report.md").read_text()
    assert "data:image/png;base64," in html and 'src="figures/' not in html
    assert (out / "report.md").exists()


def test_rerun_skips_what_is_done(reference, capsys):
    out, overrides = reference
    before = {n: (out / "u8" / n).stat().st_mtime_ns for n in STAGES if n != "timings.json"}
    # what a worker stopped mid-comparison leaves: removed, and no estimator of the report
    stale = out / "u8" / "compare-mle.tmp-1a2b3c4d"
    stale.mkdir()
    (stale / ".snapshots.png.abcd1234.tmp.png").write_bytes(b"half")
    capsys.readouterr()
    assert main(["reproduce", "--scale", "quick", "--overrides", str(overrides), "--velocities",
                 "8", "-o", str(out), "--jobs", "1", "-q"]) == 0
    log = capsys.readouterr().out
    assert not stale.exists() and "tmp-1a2b3c4d" not in (out / "report.md").read_text()
    assert "cfd-dem skipped" in log and "fit-paper skipped" in log and "compare-mle skipped" in log
    # how finely the RTDs are resolved, per side: bins spanned and residences
    summary = json.loads((out / "u8" / "compare-paper" / "summary.json").read_text())
    spanned = summary["rtd_bins_spanned"]
    assert spanned["reference"] >= 1 and spanned["model"] >= 1
    assert (f"u8 RTD (bins of 0.01 s spanned, residences): CFD-DEM {spanned['reference']}, "
            f"{summary['reference']['rt_count']}; paper {spanned['model']}, ") in log
    after = {n: (out / "u8" / n).stat().st_mtime_ns for n in before}
    assert before == after


def test_other_configuration_in_the_same_folder_is_refused(reference, tmp_path, capsys):
    out, _ = reference
    other = tmp_path / "other.toml"
    other.write_text(TINY.replace("number = 240", "number = 200"))
    capsys.readouterr()
    assert main(["reproduce", "--scale", "quick", "--overrides", str(other), "--velocities", "8",
                 "-o", str(out), "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another configuration" in err[0]


def test_other_markov_settings_are_refused_with_the_way_to_refit_the_same_cfd_dem(
        reference, tmp_path, capsys):
    """Overrides that differ in [markov] alone are refused in the earlier folder, naming the
    way to fit them on the same CFD-DEM: a new folder with the case's cfd-dem.h5 linked in,
    where only the Markov stages run. The case folder's own check says the same; a change of
    physics does not get the hint."""
    from cfbmarkov.errors import InputError
    from cfbmarkov.reproduce_case import check_case_folder

    out, _ = reference
    other = tmp_path / "other.toml"
    other.write_text(TINY.replace("fit_window = [0.2, 0.5]", "fit_window = [0.3, 0.5]"))
    capsys.readouterr()
    assert main(["reproduce", "--scale", "quick", "--overrides", str(other), "--velocities", "8",
                 "-o", str(out), "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "differ in [markov] alone" in err[0], err
    assert f"link {out / 'u8' / 'cfd-dem.h5'} into the new folder's u8/" in err[0]
    # the way it names is open: the linked file passes the checks made before any stage
    from cfbmarkov.cases.scales import load_overrides, scale_cases
    from cfbmarkov.reproduce import check_run_folder

    new = tmp_path / "refit"
    (new / "u8").mkdir(parents=True)
    (new / "u8" / "cfd-dem.h5").symlink_to(out / "u8" / "cfd-dem.h5")
    saved = scale_cases("quick", [8.0], load_overrides(other))[0]
    assert saved.markov.fit_window == (0.3, 0.5)
    check_run_folder(new, [saved], ["u8"], 1)
    with pytest.raises(InputError, match=r"differ in \[markov\] alone: to fit them"):
        check_case_folder(out / "u8", saved)
    # cases of other velocities in that folder: the manifest's overrides say the same
    assert main(["reproduce", "--scale", "quick", "--overrides", str(other), "--velocities", "9",
                 "-o", str(out), "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another --overrides" in err[0], err
    assert f"link each case's cfd-dem.h5, {out / '<case>' / 'cfd-dem.h5'}" in err[0]
    physics = saved.model_copy(update={"seed": saved.seed + 1})
    with pytest.raises(InputError, match="another configuration") as refused:
        check_case_folder(out / "u8", physics)
    assert "[markov]" not in str(refused.value)


@pytest.mark.slow
def test_resume_after_kill_mid_simulation_equals_uninterrupted(reference, tmp_path):
    ref, overrides = reference
    out = tmp_path / "killed"
    # the models whose files are compared with the reference's (not auto)
    cmd = [sys.executable, "-m", "cfbmarkov", "reproduce", "--scale", "quick", "--overrides",
           str(overrides), "--velocities", "8", "-o", str(out), "--jobs", "1", "-q",
           "--models", "paper,mle"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    checkpoint = out / "u8" / "cfd-dem.h5.parts" / "checkpoint.h5"
    deadline = time.time() + 180
    while not checkpoint.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.005)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert checkpoint.exists() and not (out / "u8" / "cfd-dem.h5").exists()
    assert main(cmd[3:]) == 0
    assert_same_files(ref / "u8", out / "u8")
    a = json.loads((ref / "u8" / "compare-paper" / "summary.json").read_text())
    b = json.loads((out / "u8" / "compare-paper" / "summary.json").read_text())
    assert a["pd_rt_mean"] == b["pd_rt_mean"] and a["mixing_rms"] == b["mixing_rms"]
    # the resumed run's CPU time is the run's own record, the killed process's included
    timing = json.loads((out / "u8" / "timings.json").read_text())["cfd_dem"]
    with Trajectories(out / "u8" / "cfd-dem.h5") as t:
        assert timing["cpu_s"] == t.group("run").attrs["cpu_time_s"]


def test_cases_added_to_a_reproduction_join_its_report_and_another_scale_is_refused(
        reference, tmp_path, capsys):
    """A folder's earlier cases stay listed when a rerun adds others (its report covers
    them all); a reproduction of another scale or overrides into it is refused in one line
    before anything is written."""
    from cfbmarkov.reproduce import load_overrides

    ref, overrides = reference
    out = tmp_path / "grown"
    shutil.copytree(ref, out)
    earlier = json.loads((out / "reproduce.json").read_text())
    (out / "u3").mkdir()                           # a case of the earlier reproduction
    (out / "reproduce.json").write_text(json.dumps({**earlier, "cases": ["u3"]}))
    reproduce(out, "quick", [8.0], overrides=load_overrides(overrides), models=("paper", "mle"),
              jobs=1, progress=False, report=False, log=lambda line: None)
    assert json.loads((out / "reproduce.json").read_text())["cases"] == ["u3", "u8"]
    before = (out / "reproduce.json").read_bytes()
    capsys.readouterr()
    for argv, what in ((["--scale", "paper", "--velocities", "6"], "another scale"),
                       (["--scale", "quick", "--velocities", "6"], "another --overrides")):
        assert main(["reproduce", *argv, "-o", str(out), "-q"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and what in err[0], err
    assert (out / "reproduce.json").read_bytes() == before and not (out / "u6").exists()


@pytest.mark.slow
def test_dask_cluster_gives_the_same_result(reference, tmp_path):
    from dask import distributed

    ref, overrides = reference
    from cfbmarkov.reproduce import load_overrides

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        # the models whose files are compared with the reference's (not auto)
        out = reproduce(tmp_path / "dask", "quick", [8.0], overrides=load_overrides(overrides),
                        models=("paper", "mle"), scheduler=cluster.scheduler_address,
                        progress=False, report=False, log=lambda line: None)
        with distributed.Client(cluster.scheduler_address) as client:
            # the cluster ran the case: its worker holds the task's record
            assert any("run_case" in str(k) for k in client.run_on_scheduler(
                lambda dask_scheduler: list(dask_scheduler.task_prefixes)))
    assert_same_files(ref / "u8", out / "u8")


@pytest.mark.slow
def test_process_pool_runs_cases_in_parallel(tmp_path, capfd):
    overrides = tiny(tmp_path)
    text = overrides.read_text().replace("end_time = 0.8", "end_time = 0.3").replace(
        "fit_window = [0.2, 0.5]", "fit_window = [0.05, 0.2]").replace(
        "predict_window = [0.5, 0.8]", "predict_window = [0.2, 0.3]")
    overrides.write_text(text)
    from cfbmarkov.reproduce import load_overrides

    from cfbmarkov._console import one_line_notes

    capfd.readouterr()
    with one_line_notes():          # as the command line prints the run's advisory
        # one model, the one whose comparison is checked: the other models' stages run the
        # same way in a worker (the reference runs all three)
        out = reproduce(tmp_path / "pool", "quick", [4.0, 6.0], models=("mle",),
                        overrides=load_overrides(overrides), jobs=2, progress=True,
                        report=False, log=lambda line: None)
    # the workers' progress and advice: whole lines, each naming its case
    check_case_lines(capfd.readouterr().err, ["u4", "u6"])
    for case in ("u4", "u6"):
        assert (out / case / "compare-mle" / "summary.json").exists()
        saved = json.loads((out / case / "case.json").read_text())
        assert saved["gas"]["superficial_velocity"] == float(case[1:])


@pytest.mark.parametrize("argv, message", [
    (["--velocities", "3,-4"], "must be positive"),
    (["--models", "paper,best"], "unknown model 'best'"),
    (["--models", "paper,paper"], "names 'paper,paper' repeat a name: give each once"),
    (["--velocities", "4,,6"], "velocities '4,,6' hold an empty entry between commas"),
    (["--overrides", "missing.toml"], "cannot read overrides file missing.toml"),
    # a model given as overrides, or a file that sets nothing
    (["--overrides", "binary.h5"], "overrides file binary.h5 is not text (an HDF5 file"),
    (["--overrides", "empty.toml"], "overrides file empty.toml is empty (it sets nothing)"),
    (["--jobs", "0"], "must be at least 1"),
    (["--scheduler", "localhost"], "--scheduler 'localhost' is not a scheduler's address"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, message, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "binary.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(100))
    (tmp_path / "empty.toml").write_text("# nothing set\n")
    assert main(["reproduce", "-o", str(tmp_path / "x"), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_bad_override_value_names_the_field(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text("[particles]\nnumber = -5\n")
    assert main(["reproduce", "--overrides", str(path), "-o", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert "particles.number" in err and "\n" not in err


@pytest.mark.parametrize("markov, named", [
    ("columns = 3", "columns 3: an even count"),
    ("interval_resamples = 5", "interval_resamples 5: at least 10"),
    ("interval_level = 0.99\ninterval_resamples = 20", "a 99 % interval needs 100 or more")])
def test_markov_settings_that_would_fail_after_the_cfd_dem_are_refused_first(
        tmp_path, capsys, markov, named):
    """An odd column count (the mixing's halves) or too few resamples for the intervals'
    level would fail at the comparison stage, after the CFD-DEM, leaving a folder whose
    configuration a corrected rerun is refused for: refused before anything runs."""
    path = tmp_path / "bad.toml"
    path.write_text(f"[markov]\n{markov}\n")
    assert main(["reproduce", "--overrides", str(path), "-o", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert named in err and "\n" not in err
    assert not (tmp_path / "x").exists()


# -- the scales' claims ------------------------------------------------------------------
def _holdup(case) -> float:
    d = case.particles.diameter
    return case.particles.number * math.pi * d**3 / 6 / (case.riser.width * case.riser.height * d)


@pytest.mark.parametrize("scale", ["paper", "quick"])
def test_scales_keep_the_papers_physics(scale):
    paper = load_case("paper-u6")
    for u, case in zip((3, 4, 6, 8), scale_cases(scale)):
        assert case.gas.superficial_velocity == u
        assert case.particles.diameter == paper.particles.diameter
        assert case.particles.density == paper.particles.density
        assert _holdup(case) == pytest.approx(_holdup(paper), rel=2e-3)
        law = ContactLaw.from_config(case.contact, case.particles.diameter, case.particles.density)
        steps = law.contact_times()[0] / case.numerics.dem_time_step
        assert steps >= 5.0
        c = case.contact
        assert (c.normal_restitution, c.friction_coefficient) == (0.97, 0.1)
        assert c.tangential_stiffness / c.normal_stiffness == pytest.approx(0.2857, rel=1e-3)
        nx, ny = case.numerics.cfd_cells
        assert case.riser.width / nx == pytest.approx(0.01, rel=0.12)
        assert case.riser.height / ny == pytest.approx(0.01, rel=0.12)
        m = case.markov
        assert 0 < m.fit_window[0] < m.fit_window[1] <= m.predict_window[0]
        assert m.predict_window[1] <= case.output.end_time
        assert m.columns % 2 == 0
        assert case.output.frame_interval <= m.lag
    if scale == "paper":
        assert [c.output.end_time for c in scale_cases(scale)] == [20.0] * 4
        assert SCALES["paper"].overrides == {}


def test_export_vtk_of_a_cfd_dem_stage(reference, tmp_path, capsys):
    """The CLI exports the reproduction's CFD-DEM run (particles and gas) for ParaView."""
    out, _ = reference
    run = out / "u8" / "cfd-dem.h5"
    with Trajectories(run) as t:
        n_frames = t.n_frames
        assert t.has_fields
    vtk = tmp_path / "vtk"
    capsys.readouterr()
    assert main(["export-vtk", str(run), "-o", str(vtk), "--every", "2", "-q"]) == 0
    assert f"{(n_frames + 1) // 2} particle frames" in capsys.readouterr().out
    assert len(list(vtk.glob("particles_*.vtu"))) == (n_frames + 1) // 2
    assert len(list(vtk.glob("gas_*.vtr"))) == (n_frames + 1) // 2
    assert (vtk / "particles.pvd").exists() and (vtk / "gas.pvd").exists()
    assert main(["export-vtk", str(run), "-o", str(tmp_path / "bad"), "--start", "50"]) == 2
    assert not (tmp_path / "bad").exists()


def test_a_dropped_in_cfd_dem_file_must_match_the_case(reference, tmp_path, capsys):
    """A CFD-DEM file put in place (e.g. made by 'cfbmarkov simulate') is used only if its
    physics is the case's and it covers the prediction window."""
    import shutil

    ref, overrides = reference
    (tmp_path / "d" / "u6").mkdir(parents=True)
    shutil.copy(ref / "u8" / "cfd-dem.h5", tmp_path / "d" / "u6" / "cfd-dem.h5")
    capsys.readouterr()
    assert main(["reproduce", "--scale", "quick", "--overrides", str(overrides), "--velocities",
                 "6", "-o", str(tmp_path / "d"), "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert "simulated with other seed, gas" in err and "\n" not in err
    # refused before anything is written: the folder holds the linked file alone
    assert sorted(p.name for p in (tmp_path / "d").rglob("*")) == ["cfd-dem.h5", "u6"]
    # a file of another source (no case in it) with another particle count: the report
    # would state the case's 240 particles for it
    from cfbmarkov.synthetic import RiserFlow, write_run

    (tmp_path / "f" / "u8").mkdir(parents=True)
    write_run(tmp_path / "f" / "u8" / "cfd-dem.h5", RiserFlow(width=0.03, height=0.12), 100,
              0.9, seed=1)
    assert main(["reproduce", "--scale", "quick", "--overrides", str(overrides), "--velocities",
                 "8", "-o", str(tmp_path / "f"), "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("f/u8/cfd-dem.h5 holds 100 particles in a 0.03 m x 0.12 m riser, case "
                        "quick-u8 240 in 0.03 m x 0.12 m: give overrides that match the file "
                        "(particles.number, riser.width, riser.height), or move it away"), err
    assert not (tmp_path / "f" / "reproduce.json").exists()
    longer = tmp_path / "longer.toml"
    longer.write_text(TINY.replace("predict_window = [0.5, 0.8]", "predict_window = [0.5, 0.9]")
                      .replace("end_time = 0.8", "end_time = 0.9"))
    (tmp_path / "e" / "u8").mkdir(parents=True)
    shutil.copy(ref / "u8" / "cfd-dem.h5", tmp_path / "e" / "u8" / "cfd-dem.h5")
    assert main(["reproduce", "--scale", "quick", "--overrides", str(longer), "--velocities",
                 "8", "-o", str(tmp_path / "e"), "--jobs", "1", "-q"]) == 2
    assert "before the end of the prediction window" in capsys.readouterr().err
    # the search grid and the skin change the speed only: a file made with others serves
    from cfbmarkov.cases.scales import load_overrides
    from cfbmarkov.reproduce_case import check_reference

    changed = load_overrides(overrides)
    changed["numerics"] = {**changed["numerics"], "dem_cells": "auto", "dem_skin": 6e-4}
    case = scale_cases("quick", [8.0], overrides=changed)[0]
    with Trajectories(ref / "u8" / "cfd-dem.h5") as t:
        assert t.parameters["numerics"]["dem_cells"] != "auto"
    check_reference(ref / "u8" / "cfd-dem.h5", case)
    changed["numerics"]["dem_time_step"] = 0.5 * case.numerics.dem_time_step
    with pytest.raises(InputError, match="simulated with other numerics"):
        check_reference(ref / "u8" / "cfd-dem.h5", scale_cases("quick", [8.0],
                                                               overrides=changed)[0])


def test_compile_kernels_warms_both_halves_and_leaves_the_step_alone(tmp_path, monkeypatch):
    """The warm-up of a process pool (each worker compiles one half of a gas step's kernels):
    both parts run on a tiny copy of the case and write nothing where they run; a gas step
    split into its gas half and the DEM steps is the step, bit for bit."""
    import numpy as np

    from cfbmarkov.reproduce_case import compile_kernels
    from cfbmarkov.simulate.riser import CoupledRiser

    monkeypatch.chdir(tmp_path)
    case = scale_cases("quick", [8.0])[0]
    for part in ("dem", "gas"):
        assert compile_kernels(case.model_dump_json(), part) >= 0.0
    assert list(tmp_path.iterdir()) == []
    small = case.model_copy(update={"particles": case.particles.model_copy(update={"number": 80})})
    whole, halves = CoupledRiser.initial(small), CoupledRiser.initial(small)
    for _ in range(3):
        whole.step()
        halves._gas_step()
        halves.dem.step(halves.dem_steps_per_cfd, external_force=halves._force)
    np.testing.assert_array_equal(whole.dem.positions, halves.dem.positions)
    np.testing.assert_array_equal(whole.gas.u, halves.gas.u)


# -- what reproduce refuses before it writes anything ----------------------------------------
def _quick_case_folder(out: Path) -> dict:
    """A folder as a quick-scale reproduce at 3 m/s leaves it once its case has started:
    reproduce.json and u3/case.json; returns each file's bytes."""
    (out / "u3").mkdir(parents=True)
    case = scale_cases("quick", [3.0])[0]
    (out / "u3" / "case.json").write_text(case.model_dump_json(indent=2) + "\n")
    (out / "reproduce.json").write_text(json.dumps({"scale": "quick", "cases": ["u3"]}) + "\n")
    return {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}


def test_another_scale_in_the_folder_is_refused_before_the_manifest_is_written(
        tmp_path, capsys):
    out = tmp_path / "rp"
    before = _quick_case_folder(out)
    capsys.readouterr()
    assert main(["reproduce", "-o", str(out), "--velocities", "3", "--scale", "paper"]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert captured.out == "" and len(err) == 1, captured
    assert f"{out / 'u3'} holds a run of another configuration" in err[0]
    assert "failed" not in err[0] and "use another output directory" in err[0]
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before          # the quick scale's manifest intact, nothing added


@pytest.mark.parametrize("foreign, named", [
    (["notes.txt"], "'notes.txt', which is not part"),
    (["a.txt", "b.dat", "c.csv", "d.h5"], "'a.txt', 'b.dat' and 'c.csv' (and 1 more), which "
                                          "are not part"),
])
def test_a_folder_of_other_files_is_refused_naming_them(tmp_path, capsys, foreign, named):
    out = tmp_path / "k3"
    out.mkdir()
    for name in foreign:
        (out / name).write_text("mine")
    assert main(["reproduce", "-o", str(out), "--velocities", "3", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    assert f"{out}: folder holds {named} of a reproduction" in err[0]
    assert "give a new or empty folder with -o" in err[0]
    assert sorted(p.name for p in out.iterdir()) == sorted(foreign)


def test_the_synthetic_demo_folder_is_refused_and_stays_the_demos(tmp_path, capsys,
                                                                   monkeypatch):
    import cfbmarkov.demo

    out = tmp_path / "synth"
    out.mkdir()
    for name in ("reference.h5", "demo.json", "model-paper.h5"):
        (out / name).write_text("{}")
    assert main(["reproduce", "-o", str(out), "--velocities", "3", "-q"]) == 2
    err = capsys.readouterr().err
    assert "which are not part of a reproduction" in err and "'demo.json'" in err
    assert sorted(p.name for p in out.iterdir()) == ["demo.json", "model-paper.h5",
                                                     "reference.h5"]
    # still the synthetic demo's folder: the CFD-DEM demo refuses it as such
    monkeypatch.setattr(cfbmarkov.demo, "run_demo", lambda *a, **k: None)
    assert main(["demo", "-o", str(out)]) == 2
    assert "holds the synthetic demo" in capsys.readouterr().err


def test_a_reproductions_own_entries_are_not_foreign(tmp_path):
    from cfbmarkov.reproduce import check_run_folder, is_reproduce_entry

    out = tmp_path / "run"
    for folder in ("u3", "u4.5", "figures"):
        (out / folder).mkdir(parents=True)
    for name in ("reproduce.json", "report.html", "report.md", ".reproduce.json.abcd_123.tmp",
                 "u4.5.tmp-0123abcd"):
        (out / name).write_text("")
    assert all(is_reproduce_entry(p) for p in out.iterdir())
    check_run_folder(out, scale_cases("quick", [6.0]), ["u6"])
    (out / "u7.txt").write_text("")
    (out / "uu").mkdir()
    assert not is_reproduce_entry(out / "u7.txt") and not is_reproduce_entry(out / "uu")
    with pytest.raises(InputError, match="'u7.txt' and 'uu', which are not part of"):
        check_run_folder(out, scale_cases("quick", [6.0]), ["u6"])


def test_the_models_record_their_fitting_data(reference, tmp_path):
    """As fit does: each model records its fitting window's identity (and cell fields), by
    which a copy of its fitting file is recognised wherever it lies."""
    import shutil

    from cfbmarkov.analysis.cell_fields import check_fitting_file
    from cfbmarkov.markov import MarkovModel

    out, _ = reference
    copy = tmp_path / "copy.h5"
    shutil.copy(out / "u8" / "cfd-dem.h5", copy)
    for name in ("paper", "mle", "auto"):
        model = MarkovModel.load(out / "u8" / f"model-{name}.h5")
        assert model.source_identity and model.cell_fields is not None, name
        assert check_fitting_file(model, copy) == tuple(model.window)


# -- a kinetics file ---------------------------------------------------------------------
def _kinetics_file(folder: Path, name: str, body: str) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(f'[[property]]\nname = "X"\nlaw = "first-order"\n{body}\n')
    return path


def test_a_kinetics_table_of_another_grid_is_refused_before_the_cfd_dem(tmp_path, capsys):
    """The table is checked on each case's grid (here 2 x 6) before any CFD-DEM runs."""
    rows = "\n".join(f"{c},{r},1.0" for r in range(12) for c in range(4))
    (tmp_path / "rates.csv").write_text("col,row,rate\n" + rows + "\n")
    kin = _kinetics_file(tmp_path, "grid", 'rate_by_cell = "rates.csv"')
    assert main(["reproduce", "--overrides", str(tiny(tmp_path)), "--velocities", "8",
                 "--kinetics", str(kin), "-o", str(tmp_path / "x"), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert "outside the grid 2x6" in err and "\n" not in err
    assert not (tmp_path / "x").exists()


def test_a_rerun_with_another_kinetics_file_is_refused_and_the_same_one_skips(
        reference, tmp_path, capsys):
    """The comparisons record the kinetics they integrated: a rerun with another definition
    (or none) in the folder is refused in one line, the same file skips every stage."""
    import shutil

    out, overrides = reference
    out = Path(shutil.copytree(out, tmp_path / "ref"))
    first = _kinetics_file(tmp_path, "first", "rate = 5.0")
    argv = ["reproduce", "--scale", "quick", "--overrides", str(overrides), "--velocities", "8",
            "-o", str(out), "--jobs", "1", "--models", "paper"]
    assert main([*argv, "--kinetics", str(first)]) == 0
    log = capsys.readouterr().out
    assert "cfd-dem skipped" in log and "compare-paper done" in log
    summary = json.loads((out / "u8" / "compare-paper" / "summary.json").read_text())
    assert summary["kinetics_source"]["digest"].startswith("sha256:")
    assert json.loads((out / "reproduce.json").read_text())["kinetics"]["file"] == str(first)
    first.write_text(first.read_text().replace("rate = 5.0", "rate = 50.0"))
    for extra in (["--kinetics", str(first)], ["--kinetics", str(_kinetics_file(
            tmp_path, "second", "rate = 7.0"))], []):
        assert main([*argv, *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert "would mix two kinetics" in err and "\n" not in err
    first.write_text(first.read_text().replace("rate = 50.0", "rate = 5.0"))
    assert main([*argv, "--kinetics", str(first)]) == 0
    assert "compare-paper skipped" in capsys.readouterr().out


def test_a_comparison_is_formed_again_unless_it_holds_the_kinetics_asked_for(tmp_path):
    from cfbmarkov.kinetics import load_kinetics
    from cfbmarkov.kinetics.fingerprint import kinetics_digest
    from cfbmarkov.reproduce_case import _same_kinetics

    a = kinetics_digest(load_kinetics(_kinetics_file(tmp_path, "a", "rate = 1.0")))
    assert a == kinetics_digest(load_kinetics(_kinetics_file(tmp_path, "b", "rate = 1.0")))
    assert a != kinetics_digest(load_kinetics(_kinetics_file(tmp_path, "c", "rate = 1.5")))
    block = {"X": {}}
    assert _same_kinetics({}, None)
    assert not _same_kinetics({"kinetics": block}, None)
    assert not _same_kinetics({"kinetics": block}, a)          # recorded by no digest
    assert _same_kinetics({"kinetics": block, "kinetics_source": {"digest": a}}, a)
    assert not _same_kinetics({"kinetics": block, "kinetics_source": {"digest": "x"}}, a)


def test_stopped_workers_leave_no_empty_checkpoint_folder(tmp_path):
    """A Ctrl-C to `reproduce --jobs 2` before the cases' first checkpoints left their empty
    `cfd-dem.h5.parts/` folders; a case's folder with a checkpoint is kept (it resumes)."""
    from cfbmarkov.reproduce import _stop_workers

    (tmp_path / "u6" / "cfd-dem.h5.parts").mkdir(parents=True)
    kept = tmp_path / "u8" / "cfd-dem.h5.parts"
    kept.mkdir(parents=True)
    (kept / "checkpoint.h5").write_bytes(b"state")
    _stop_workers(object(), tmp_path)
    assert not (tmp_path / "u6" / "cfd-dem.h5.parts").exists()
    assert (kept / "checkpoint.h5").exists()


def test_a_models_line_gives_no_place_for_a_reference_without_residences():
    """A reference window without residences (E(RT) NaN in the summary compare returns, null
    in its summary.json) and an interval of NaN are not placed against each other."""
    from cfbmarkov.reproduce import _judged

    summary = {"model": {"rt_mean_interval": [1.0, 2.0]}, "reference": {"rt_mean": float("nan")},
               "level": 0.9, "warnings": []}
    assert _judged(summary, "mle") == ""
    summary["reference"]["rt_mean"], summary["model"]["rt_mean_interval"] = 1.5, [float("nan")] * 2
    assert _judged(summary, "mle") == ""
    summary["model"]["rt_mean_interval"] = [None, None]      # NaN read back from JSON
    assert _judged(summary, "mle") == ""
    summary["model"]["rt_mean_interval"] = [1.0, 2.0]
    assert _judged(summary, "mle") == ("; the CFD-DEM's E(RT) 1.5 s lies inside the model's "
                                       "90 % interval 1-2 s")
