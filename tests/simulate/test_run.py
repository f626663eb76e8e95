"""The coupled CFD-DEM run end to end: output, exact events, checkpoint/resume bit for bit
(also after kill -9), configuration errors."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.config import CaseConfig
from cfbmarkov.errors import InputError
from cfbmarkov.simulate.run import simulate
from cfbmarkov.trajectories import Trajectories

SMALL = """
name = "small"
seed = 3
[riser]
width = 0.09
height = 0.2
[particles]
number = {n}
[gas]
superficial_velocity = 6.0
[numerics]
cfd_cells = [9, 20]
dem_cells = [30, 74]
[output]
end_time = {end}
"""


def small_case(tmp_path, n=600, end=0.1):
    path = tmp_path / "small.toml"
    path.write_text(SMALL.format(n=n, end=end))
    return path


def load(path):
    from cfbmarkov.config import load_case

    return load_case(path)


def arrays(path):
    with Trajectories(path) as t:
        ev = t.events()
        return (t.times, t.positions(), t.velocities(), t.laps(), ev.time, ev.particle,
                ev.direction, t.field_times, *(t.field(name) for name in t.field_names))


@pytest.fixture(scope="session")
def reference(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sim")
    case = load(small_case(tmp))
    out = simulate(case, tmp / "ref.h5", checkpoint_every=0.025, progress=False)
    return case, out


def test_small_riser_end_to_end(reference):
    case, out = reference
    assert not out.with_name(out.name + ".parts").exists()
    with Trajectories(out) as t:
        assert t.n_frames == 5 and t.n_particles == case.particles.number
        assert t.source == "cfd-dem" and t.has_velocity and t.has_events
        assert t.parameters["gas"]["superficial_velocity"] == 6.0
        pos = t.positions()
        assert np.all((pos[..., 0] >= 0) & (pos[..., 0] <= case.riser.width))
        # exact events account for every change of the lap counters
        ev = t.events()
        net = np.zeros(t.n_particles, int)
        np.add.at(net, ev.particle, ev.direction)
        np.testing.assert_array_equal(net, t.laps(-1) - t.laps(0))
        assert len(ev) > 0 and np.all(np.diff(ev.time) >= 0)
        assert t.group("run").attrs["particle_steps_per_s"] > 0
        history = t.group("run")["wall_history"][()]
        np.testing.assert_allclose(history[:, 0], t.times)          # a checkpoint per frame
        assert np.all(np.diff(history[:, 1]) > 0)
        # gas fields with every frame, cell-centred [ny, nx]
        assert t.field_names == ["gas_velocity", "pressure", "void_fraction"]
        np.testing.assert_array_equal(t.field_times, t.times)
        nx, ny = case.numerics.cfd_cells
        assert t.field("void_fraction").shape == (t.n_frames, ny, nx)
        assert t.field("gas_velocity", 0).shape == (ny, nx, 2)
        eps = t.field("void_fraction")
        assert np.all((eps > 0.2) & (eps <= 1.0))
        # the stored void fraction is that of the particles in the frame: the solids volume
        # it accounts for equals the particles' volume (pseudo-2D cells dx dy d)
        d = case.particles.diameter
        dx, dy = t.field_spacing
        solids = ((1.0 - eps[-1].astype(float)) * dx * dy * d).sum()
        assert solids == pytest.approx(case.particles.number * np.pi * d**3 / 6, rel=1e-4)
        # cross-section mean of eps * v_gas is U (float32 storage, face-to-centre averaging)
        vg = t.field("gas_velocity", -1)[..., 1].astype(float)
        flux = (eps[-1] * vg).mean()
        assert flux == pytest.approx(case.gas.superficial_velocity, rel=0.03)


def test_resume_equals_uninterrupted_run(tmp_path, reference):
    case, ref = reference
    out = tmp_path / "b.h5"
    simulate(case, out, checkpoint_every=0.025, progress=False, stop_after_frames=3)
    assert not out.exists() and (tmp_path / "b.h5.parts" / "checkpoint.h5").exists()
    with pytest.raises(Exception, match="add --resume"):
        simulate(case, out, progress=False)
    from cfbmarkov.simulate.checkpoint import checkpoint_cpu_time
    from cfbmarkov.trajectories import Trajectories

    before = checkpoint_cpu_time(tmp_path / "b.h5.parts" / "checkpoint.h5")
    assert before > 0
    simulate(case, out, checkpoint_every=0.025, progress=False, resume=True)
    for a, b in zip(arrays(ref), arrays(out)):
        np.testing.assert_array_equal(a, b)
    # the run's CPU time counts the interrupted process's as well as the resumed one's
    with Trajectories(out) as t:
        assert t.group("run").attrs["cpu_time_s"] > before


def test_resume_with_another_search_grid_names_it(tmp_path, reference):
    """A checkpoint is resumed only with the case it was made with; the refusal names the
    setting that differs (here the DEM search grid, which changes the round-off only)."""
    case, _ = reference
    out = tmp_path / "c.h5"
    simulate(case, out, checkpoint_every=0.025, progress=False, stop_after_frames=2)
    auto = case.model_copy(update={"numerics": case.numerics.model_copy(
        update={"dem_cells": "auto"})})
    with pytest.raises(Exception, match=r"numerics\.dem_cells: saved \[30, 74\], now 'auto'\); "
                                        r"resume with the saved value, or delete .*c\.h5\.parts "
                                        "and run without --resume"):
        simulate(auto, out, progress=False, resume=True)
    # the fix it names is taken: a plain run is refused while the checkpoint waits
    with pytest.raises(InputError, match="holds an interrupted run: add --resume"):
        simulate(auto, out, progress=False)


def test_automatic_search_grid(tmp_path):
    """dem_cells = "auto" (the default) gives the finest grid of cells no smaller than the
    search cutoff; anything but two positive integers or "auto" is refused in one line."""
    from cfbmarkov.simulate.riser import CoupledRiser

    assert CaseConfig().numerics.dem_cells == "auto"
    case = load(small_case(tmp_path, n=300)).model_copy()
    case = case.model_copy(update={"numerics": case.numerics.model_copy(
        update={"dem_cells": "auto"})})
    dem = CoupledRiser.initial(case).dem
    ncx, ncy = dem.search_cells
    cut = case.particles.diameter + case.numerics.dem_skin
    assert case.riser.width / ncx >= cut and case.riser.height / ncy >= cut
    assert case.riser.width / (ncx + 1) < cut and case.riser.height / (ncy + 1) < cut
    bad = tmp_path / "bad.toml"
    bad.write_text(SMALL.format(n=100, end=0.05).replace("dem_cells = [30, 74]",
                                                         'dem_cells = "fine"'))
    assert main(["simulate", str(bad), "-o", str(tmp_path / "x.h5"), "-q"]) == 2


def test_resume_after_kill_9(tmp_path, reference):
    case, ref = reference
    toml = small_case(tmp_path)
    out = tmp_path / "k.h5"
    cmd = [sys.executable, "-m", "cfbmarkov", "simulate", str(toml), "-o", str(out),
           "--checkpoint-every", "0.025", "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    checkpoint = tmp_path / "k.h5.parts" / "checkpoint.h5"
    deadline = time.time() + 120
    while not checkpoint.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGKILL)       # at once: the run is between checkpoints
    proc.wait()
    assert proc.returncode == -signal.SIGKILL and not out.exists()
    assert main(["simulate", str(toml), "-o", str(out), "--checkpoint-every", "0.025",
                 "--resume", "-q"]) == 0
    for a, b in zip(arrays(ref), arrays(out)):
        np.testing.assert_array_equal(a, b)


def test_a_blow_up_is_one_line_naming_its_step_time_and_checkpoint(tmp_path, capsys,
                                                                    monkeypatch):
    """A DEM blow-up after a checkpoint: one line, exit 2, the engine's message with the
    time and the checkpoint kept; the error keeps its type and attributes (re-raising it as
    a new one of its class needed the step, particle and reason: a TypeError traceback)."""
    from cfbmarkov.simulate.dem import SimulationBlowUp
    from cfbmarkov.simulate.riser import CoupledRiser

    toml = small_case(tmp_path, n=100, end=0.1)
    original, calls = CoupledRiser.step, []

    def failing(self, *args, **kwargs):
        calls.append(1)
        if len(calls) > 1100:           # 0.055 s of gas steps: after two checkpoints
            raise SimulationBlowUp("DEM blow-up in step 7: particle 3 overlaps", 7, 3,
                                   "overlap")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(CoupledRiser, "step", failing)
    out = tmp_path / "run.h5"
    assert main(["simulate", str(toml), "-o", str(out), "--checkpoint-every", "0.025",
                 "-q"]) == 2
    err = capsys.readouterr().err.strip()
    errors = [line for line in err.splitlines() if not line.startswith("note: ")]
    assert len(errors) == 1 and "Traceback" not in err, err
    assert re.search(r"error: DEM blow-up in step 7: particle 3 overlaps \(at t = 0\.05\d* s\); "
                     r"the last good checkpoint is in \S+", errors[0]), errors[0]
    with pytest.raises(SimulationBlowUp) as raised:
        simulate(CaseConfig.model_validate_json(CaseConfig.model_validate(
            __import__("tomllib").loads(toml.read_text())).model_dump_json()),
            tmp_path / "again.h5", progress=False)
    assert (raised.value.step, raised.value.particle, raised.value.reason) == (7, 3, "overlap")


def test_configuration_errors(tmp_path, capsys):
    bad = tmp_path / "bad.toml"     # 2e-5 s resolves a contact in 1.3 steps: refused
    bad.write_text(SMALL.format(n=100, end=0.05).replace(
        "[numerics]", "[numerics]\ndem_time_step = 2e-5\ncfd_time_step = 4e-5"))
    assert main(["simulate", str(bad), "-o", str(tmp_path / "x.h5"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "steps" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.h5").exists()
    unknown = tmp_path / "u.toml"
    unknown.write_text("[gas]\nvelocity = 3\n")
    assert main(["simulate", str(unknown), "-o", str(tmp_path / "x.h5")]) == 2
    assert "gas.velocity" in capsys.readouterr().err
    assert CaseConfig().particles.number == 27000
    # an end between frames (0.025 s apart): the run would step on to the next frame and
    # record the end asked for; refused, naming the two whole-frame ends
    between = tmp_path / "between.toml"
    between.write_text(SMALL.format(n=100, end=0.06))
    for argv, where in (([], "output.end_time in the case file"), (["--until", "0.03"],
                                                                    "--until")):
        assert main(["simulate", str(between), "-o", str(tmp_path / "y.h5"), "-q",
                     *argv]) == 2
        err = capsys.readouterr().err.strip()
        end = argv[1] if argv else "0.06"
        low, high = ("0.025", "0.05") if argv else ("0.05", "0.075")
        assert err.endswith(f"end time {end} s is not a whole number of frames (0.025 s "
                            f"apart): give {low} or {high} s ({where})"), err
        assert not (tmp_path / "y.h5").exists()


def test_time_step_advisory_is_one_line_and_progress_whole_lines(tmp_path, capsys):
    """The CLI says the DEM step's advice once, as one line without Python's warning format;
    off a terminal the progress is whole lines. From Python the advice is a warning."""
    from cfbmarkov.errors import TimeStepAdvisory

    case = small_case(tmp_path, n=100, end=0.05)     # the paper's step: 5.18 steps a contact
    assert main(["simulate", str(case), "-o", str(tmp_path / "a.h5")]) == 0
    err = capsys.readouterr().err.splitlines()
    notes = [line for line in err if line.startswith("note: ")]
    assert len(notes) == 1 and "DEM time step 5e-06 s resolves a contact in 5.18" in notes[0]
    assert notes[0].endswith("10 or more are recommended")
    assert not any("UserWarning" in line or "Warning:" in line for line in err)
    progress = [line for line in err if not line.startswith("note: ")]
    assert progress[0].startswith("CFD-DEM starting at 0/0.05 s simulated, 100 particles")
    assert progress[-1].startswith("CFD-DEM 0.05/0.05 s simulated in ")
    assert all(line.startswith("CFD-DEM ") for line in progress) and len(progress) >= 3
    with pytest.warns(TimeStepAdvisory, match=r"^u6: DEM time step 5e-06 s") as caught:
        simulate(load(case), tmp_path / "b.h5", until=0.025, progress=False, label="u6")
    assert len([w for w in caught if w.category is TimeStepAdvisory]) == 1


def test_resume_to_an_end_before_the_checkpoint_is_refused(tmp_path, reference):
    case, _ = reference
    out = tmp_path / "c.h5"
    simulate(case, out, checkpoint_every=0.025, progress=False, stop_after_frames=3)
    with pytest.raises(InputError, match="past the end asked for"):
        simulate(case, out, until=0.025, progress=False, resume=True)
    assert not out.exists() and (tmp_path / "c.h5.parts" / "checkpoint.h5").exists()


def test_resume_of_a_finished_run_says_it_is_finished(tmp_path, reference):
    """--resume on a finished output of another case or end says the file is a finished
    run, which keeps no checkpoint (not that the run stopped before its first one); the
    same case and end is resumed as done, saying so (it said nothing)."""
    case, ref = reference
    out = tmp_path / "done.h5"
    shutil.copyfile(ref, out)
    before = out.read_bytes()
    other = case.model_copy(update={"seed": case.seed + 1})
    with pytest.raises(InputError, match=r"done\.h5 is a finished run of another case \(its "
                                         r"settings differ from these\), and a finished run "
                                         "keeps no checkpoint"):
        simulate(other, out, progress=False, resume=True)
    end = case.output.end_time
    with pytest.raises(InputError, match=rf"done\.h5 is this case's finished run, which ends "
                                         rf"at {end:g} s, and a finished run keeps no"):
        simulate(case, out, until=2 * end, progress=False, resume=True)
    from cfbmarkov.errors import CfbmarkovWarning

    with pytest.warns(CfbmarkovWarning, match=rf"nothing left to resume: .*done\.h5 already "
                                              rf"holds this run to {end:g} s, finished"):
        assert simulate(case, out, progress=False, resume=True) == out
    assert out.read_bytes() == before and not (tmp_path / "done.h5.parts").exists()


def test_info_of_a_run_names_its_case(reference, capsys):
    """``info`` of a CFD-DEM run says which case it was simulated from: name, seed, gas
    velocity, particles, steps, end time (an imported file has no such line)."""
    case, ref = reference
    assert main(["info", str(ref)]) == 0
    out = capsys.readouterr().out
    line = next(line for line in out.splitlines() if line.startswith("  case "))
    assert line.startswith(f"  case {case.name} (seed {case.seed}): superficial gas velocity "
                           f"{case.gas.superficial_velocity:g} m/s; {case.particles.number} "
                           f"particles of {1e3 * case.particles.diameter:g} mm, "
                           f"{case.particles.density:g} kg/m3; DEM step ")
    assert line.endswith(f"; end time {case.output.end_time:g} s")


def test_info_of_a_run_with_an_interrupted_rerun_beside_it_says_so(tmp_path, reference,
                                                                   capsys):
    """A rerun into a finished output, interrupted, leaves the earlier run in place and its
    checkpoint in OUTPUT.parts: ``info`` says which one the file is."""
    case, ref = reference
    out = tmp_path / "done.h5"
    shutil.copyfile(ref, out)
    assert main(["info", str(out)]) == 0
    assert "note:" not in capsys.readouterr().err
    other = case.model_copy(update={"seed": case.seed + 1})
    before = out.read_bytes()
    with pytest.raises(InputError, match="holds a finished run of another case .*a finished "
                       "run is not replaced without --force"):
        simulate(other, out, checkpoint_every=0.025, progress=False)
    with pytest.raises(InputError, match="holds this case's finished run, which ends at"):
        simulate(case, out, until=0.025, progress=False)
    assert out.read_bytes() == before and not (tmp_path / "done.h5.parts").exists()
    simulate(other, out, checkpoint_every=0.025, progress=False, stop_after_frames=3,
             force=True)
    assert (tmp_path / "done.h5.parts" / "checkpoint.h5").is_file() and out.is_file()
    assert main(["info", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f"note: {tmp_path / 'done.h5.parts'} holds an interrupted simulate "
                          "run to this file; until it is resumed")


@pytest.mark.parametrize("content, message", [
    (b"", "case file {p} is empty (it sets nothing): give a TOML file of the case's tables"),
    (b"# only a comment\n", "case file {p} is empty"),
    (b"\x89HDF\r\n\x1a\n" + bytes(64), "case file {p} is not text (an HDF5 file: a model or "
                                       "trajectory file?)"),
    (b"\xff\xfe[\x00", "case file {p} is text in UTF-16; save it as UTF-8"),
])
def test_a_case_file_that_is_empty_or_not_text_is_one_line(tmp_path, capsys, content,
                                                          message):
    """An empty case file is refused (not run as the paper's 20 s, 27000-particle case); a
    model given as the case is named as such (no UnicodeDecodeError)."""
    path = tmp_path / "case.toml"
    path.write_bytes(content)
    assert main(["simulate", str(path), "-o", str(tmp_path / "x.h5"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message.format(p=path) in err[0], err
    assert not (tmp_path / "x.h5").exists()


def test_a_case_file_with_old_mac_line_ends_reads():
    """Line ends of a lone carriage return, as text mode reads them."""
    from cfbmarkov.config import load_case

    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "case.toml"
        path.write_bytes(b'name = "cr"\r[particles]\rnumber = 200\r')
        case = load_case(path)
    assert case.name == "cr" and case.particles.number == 200


def test_info_counts_a_runs_passes_from_its_exact_events(tmp_path, reference, capsys):
    """A CFD-DEM run stores every pass: ``info`` counts those (977 up, 127 down in a review's
    run), and says the lap counters' frame-to-frame count beside them (960 and 110: a pass
    undone within a frame interval nets out); a file without events keeps that count."""
    import h5py

    _, out = reference
    with h5py.File(out, "r") as f:
        direction = f["events/direction"][()]
        times = f["events/time"][()]
        frame_times = f["frames/time"][()]
    inside = (times > frame_times[0]) & (times <= frame_times[-1])
    up, down = int((direction[inside] > 0).sum()), int((direction[inside] < 0).sum())
    assert up + down > 0
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"passes through the periodic boundary: {up} up, {down} down (the exact pass " \
        "events; " in text
    # the stored pressure is the periodic part, said with the weight G carries (the drop
    # over the height is in no stored field: a review read a 1 Pa drop for a 229 Pa one)
    said = re.search(r"pressure is its periodic part \(zero mean\): the full pressure adds "
                     r"-G y, with G the driving gradient that carries the riser's weight, "
                     r"about ([0-9.]+) Pa/m here \(the weight per volume at the mean void "
                     r"fraction ([0-9.]+)\)", text)
    assert said, text
    with h5py.File(out, "r") as f:
        eps = float(np.mean(f["fields/void_fraction"][()]))
        case = json.loads(f.attrs["parameters"])
    weight = ((1 - eps) * (case["particles"]["density"] - case["gas"]["density"])
              + case["gas"]["density"]) * case["riser"]["gravity"]
    assert float(said.group(1)) == pytest.approx(weight, rel=1e-3)
    bare = tmp_path / "bare.h5"
    shutil.copyfile(out, bare)
    with h5py.File(bare, "a") as f:
        del f["events"]
    assert main(["info", str(bare)]) == 0
    text = capsys.readouterr().out
    assert "passes through the periodic boundary: " in text and "exact pass events" not in text
