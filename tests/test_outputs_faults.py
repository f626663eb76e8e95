"""Outputs under faults (issue 16): locks, inputs never overwritten, outputs of another kind,
full disk, kills at random points, Ctrl-C, stale temporaries, umask."""

import os
import random
import resource
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cfbmarkov._outputs import claim_output
from cfbmarkov.cli import main
from cfbmarkov.synthetic import RiserFlow, write_run

SRC = str(Path(__file__).resolve().parents[1] / "src")
SMALL_CASE = """
name = "small"
seed = 3
[riser]
width = 0.09
height = 0.2
[particles]
number = 200
[gas]
superficial_velocity = 6.0
[numerics]
cfd_cells = [9, 20]
dem_cells = [30, 74]
[output]
end_time = {end}
"""


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONWARNINGS"] = "ignore"
    env["PYTHONDONTWRITEBYTECODE"] = "1"     # no .pyc cut short by a file size limit
    if os.environ.get("PYTEST_XDIST_WORKER"):   # beside another worker (tests/conftest.py)
        env["NUMBA_NUM_THREADS"] = "1"
    return env


def cli(*args, cwd, preexec_fn=None, **kw):
    return subprocess.Popen([sys.executable, "-m", "cfbmarkov", *map(str, args)], cwd=cwd,
                            env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=preexec_fn, **kw)


def run_cli(*args, cwd, preexec_fn=None, timeout=120):
    p = cli(*args, cwd=cwd, preexec_fn=preexec_fn)
    out, err = p.communicate(timeout=timeout)
    return p.returncode, out, err


def stray(folder: Path, expected) -> list[str]:
    """Names under ``folder`` other than ``expected`` (temporaries, locks, parts)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")
                  if not any(p.relative_to(folder).parts[0] == e for e in expected))


@pytest.fixture(scope="session")
def data(tmp_path_factory):
    folder = tmp_path_factory.mktemp("outputs")
    run = write_run(folder / "run.h5", RiserFlow(), 120, 1.5, seed=1)
    assert main(["fit", str(run), "--window", "0:1", "-o", str(folder / "model.h5")]) == 0
    assert main(["predict", str(folder / "model.h5"), "--init", str(run), "--start", "0.5",
                 "--duration", "1", "-q", "-o", str(folder / "pred.h5")]) == 0
    return folder


def _fit(data, out, *more):
    return main(["fit", str(data / "run.h5"), "--window", "0:1", "-q", "-o", str(out), *more])


# -- 1. locks -------------------------------------------------------------------------------
def test_second_writer_refused_naming_the_holder(data, tmp_path):
    out = tmp_path / "model.h5"
    with claim_output(out, "simulate", "model"):
        assert (tmp_path / ".model.h5.lock").exists()
        rc, _, err = run_cli("fit", data / "run.h5", "--window", "0:1", "-o", out, cwd=tmp_path)
    assert rc == 2
    assert err.count("\n") == 1 and "being written by" in err
    assert f"pid {os.getpid()}" in err and "cfbmarkov simulate since" in err
    assert not out.exists() and stray(tmp_path, []) == []      # the lock file went with it


def test_lock_released_by_a_killed_writer(data, tmp_path):
    """kill -9 of a lock holder leaves no lock: the next writer goes ahead."""
    out = tmp_path / "model.h5"
    code = ("import sys, time; from cfbmarkov._outputs import claim_output\n"
            f"with claim_output({str(out)!r}, 'fit', 'model'):\n"
            "    print('locked', flush=True); time.sleep(60)\n")
    p = subprocess.Popen([sys.executable, "-c", code], env=_env(), stdout=subprocess.PIPE,
                         text=True)
    assert p.stdout.readline().strip() == "locked"
    assert _fit(data, out) == 2
    p.kill()
    p.wait()
    assert _fit(data, out) == 0
    assert stray(tmp_path, ["model.h5"]) == []


# -- 2. inputs and outputs of another kind --------------------------------------------------
def test_fit_and_predict_refuse_to_overwrite_an_input(data, tmp_path, capsys):
    run, model = data / "run.h5", data / "model.h5"
    before = run.stat().st_mtime_ns, model.stat().st_mtime_ns
    assert _fit(data, run) == 2
    (tmp_path / "link.h5").symlink_to(run)
    os.link(model, tmp_path / "hard.h5")
    assert _fit(data, tmp_path / "link.h5") == 2
    for out in (model, run, tmp_path / "hard.h5"):
        assert main(["predict", str(model), "--init", str(run), "--start", "1", "--duration",
                     "0.2", "-q", "-o", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 5 and all("is one of the inputs" in line for line in err)
    assert (run.stat().st_mtime_ns, model.stat().st_mtime_ns) == before


def test_output_of_another_kind_needs_force(data, tmp_path, capsys):
    traj = tmp_path / "traj.h5"
    write_run(traj, RiserFlow(), 10, 0.1)
    assert _fit(data, traj) == 2                       # a trajectory where a model goes
    assert "is a trajectory file, not a model file; add --force" in capsys.readouterr().err
    assert _fit(data, traj, "--force") == 0            # asked for: replaced
    assert _fit(data, traj) == 0                       # same kind: replaced as before
    text = tmp_path / "notes"                          # a text file without a suffix
    text.write_text("keep me")
    assert _fit(data, text) == 2 and text.read_text() == "keep me"
    os.mkfifo(tmp_path / "fifo")
    assert _fit(data, tmp_path / "fifo") == 2
    assert _fit(data, tmp_path / "fifo", "--force") == 2       # never replaced: /dev/null too
    assert stat.S_ISFIFO((tmp_path / "fifo").stat().st_mode)
    (tmp_path / "dir.h5").mkdir()
    assert _fit(data, tmp_path / "dir.h5") == 2
    assert _fit(data, tmp_path / "dir.h5", "--force") == 0    # an empty folder
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    assert _fit(data, tmp_path / "full", "--force") == 2      # never a folder with files
    assert main(["compare", str(data / "run.h5"), str(data / "pred.h5"), "--window", "0.5:1.5",
                 "--no-figures", "-o", str(text)]) == 2      # a file where a folder goes
    err = [line for line in capsys.readouterr().err.splitlines()
           if not line.startswith("warning:")]     # the fitting sample's, on the tiny window
    assert len(err) == 6, err
    assert "another format" in err[0] and "FIFO" in err[1] and "is a folder" in err[3]
    assert "never replaces a device, pipe or socket" in err[2]


# -- 3. full disk ---------------------------------------------------------------------------
def _file_size_limit(limit):
    def preexec():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


def test_full_disk_import_one_line_no_temporary(tmp_path):
    csv = tmp_path / "in.csv"
    rng = random.Random(0)
    with open(csv, "w") as f:
        f.write("t,id,x,y\n")
        for k in range(300):
            for i in range(100):
                f.write(f"{k * 0.01:.2f},{i},{rng.uniform(0.001, 0.089):.5f},"
                        f"{rng.uniform(0.001, 0.949):.5f}\n")
    # random heights each frame: an open riser (no laps from them), as the writes are tested
    rc, _, err = run_cli("import", csv, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "--boundary", "open", "-o", "out.h5", cwd=tmp_path,
                         preexec_fn=_file_size_limit(150_000))
    assert rc == 2, err
    assert err.splitlines() == ["cfbmarkov import: error: out.h5: cannot write (File too large)"]
    assert stray(tmp_path, ["in.csv"]) == []


@pytest.mark.parametrize("verb", ["fit", "predict", "compare"])
def test_full_disk_markov_verbs(data, tmp_path, verb):
    args = {"fit": ["fit", data / "run.h5", "--window", "0:1", "-q", "-o", "out.h5"],
            "predict": ["predict", data / "model.h5", "--init", data / "run.h5", "--start",
                        "0.5", "--duration", "1", "-q", "-o", "out.h5"],
            "compare": ["compare", data / "run.h5", data / "pred.h5", "--window", "0.5:1.5",
                        "-q", "-o", "out"]}[verb]
    rc, _, err = run_cli(*args, cwd=tmp_path, preexec_fn=_file_size_limit(2000))
    assert rc == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and "cannot write (File too large)" in lines[0], err
    assert stray(tmp_path, []) == []


# -- 4. kills at random points, stale temporaries --------------------------------------------
def test_kill_at_random_points_then_rerun_is_clean(data, tmp_path):
    """kill -9 of import, fit, predict, compare (with figures), maps and export-vtk at random
    moments: the rerun succeeds and leaves nothing but its output."""
    rng = random.Random(16)
    csv = tmp_path / "in.csv"
    with open(csv, "w") as f:
        f.write("t,id,x,y\n")
        for k in range(200):
            for i in range(50):
                f.write(f"{k * 0.01:.2f},{i},{rng.uniform(0.001, 0.089):.5f},"
                        f"{rng.uniform(0.001, 0.949):.5f}\n")
    jobs = [("imp.h5", ["import", csv, "--format", "csv", "--width", "0.09", "--height", "0.95",
                         "--boundary", "open", "-o", "imp.h5"]),    # random heights: no laps
            ("fit.h5", ["fit", data / "run.h5", "--window", "0:1", "-o", "fit.h5"]),
            ("pred.h5", ["predict", data / "model.h5", "--init", data / "run.h5", "--start",
                         "0.5", "--duration", "1", "-q", "-o", "pred.h5"]),
            ("cmp", ["compare", data / "run.h5", data / "pred.h5", "--window", "0.5:1.5",
                     "-o", "cmp"]),
            ("maps.png", ["maps", data / "model.h5", "--times", "0.05,0.1", "-o", "maps.png"]),
            ("vtk", ["export-vtk", data / "run.h5", "-o", "vtk"])]
    for name, args in jobs:
        p = cli(*args, cwd=tmp_path)
        time.sleep(rng.uniform(0.3, 1.5))
        p.kill()
        p.communicate()
        rc, _, err = run_cli(*args, cwd=tmp_path)
        assert rc == 0, err
        assert stray(tmp_path, ["in.csv", "imp.h5", "fit.h5", "pred.h5", "cmp", "maps.png",
                                "vtk"]) == [], name
    assert (tmp_path / "cmp" / "summary.json").exists()


def test_rerun_removes_stale_temporaries_of_its_output_only(data, tmp_path):
    out = tmp_path / "model.h5"
    stale = [tmp_path / ".model.h5.abc12_xy.tmp", tmp_path / ".model.h5.0123abcd.tmp.png"]
    for path in stale:
        path.write_bytes(b"half")
    (tmp_path / "model.h5.tmp-0123abcd").mkdir()
    other = tmp_path / ".other.h5.abc12_xy.tmp"
    other.write_bytes(b"someone else's")
    assert _fit(data, out) == 0
    assert stray(tmp_path, ["model.h5", other.name]) == []


def test_refused_reproduce_creates_no_folder(tmp_path):
    out = tmp_path / "new" / "run"
    assert main(["reproduce", "-o", str(out), "--jobs", "0", "-q"]) == 2
    assert not (tmp_path / "new").exists()


# -- 5. Ctrl-C ------------------------------------------------------------------------------
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_ctrl_c_exit_130_one_line_no_temporary(data, tmp_path, signum):
    """Ctrl-C, or SIGTERM (kill, a batch scheduler), while the prediction is being written
    (its temporary exists): exit 130, one line, the temporary and the lock removed."""
    p = cli("predict", data / "model.h5", "--init", data / "run.h5", "--start", "0.5",
            "--duration", "3000", "-q", "-o", "pred.h5", cwd=tmp_path)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".pred.h5.*.tmp")):
        assert p.poll() is None, "the prediction ended before its file was being written"
        assert time.monotonic() < deadline
        time.sleep(0.05)
    time.sleep(0.2)
    p.send_signal(signum)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert err.splitlines() == ["cfbmarkov predict: interrupted"]
    assert stray(tmp_path, []) == []


@pytest.mark.parametrize("replacing", [False, True], ids=["new", "replacing"])
def test_ctrl_c_after_the_model_is_saved_says_it_is_whole(data, tmp_path, capsys,
                                                          monkeypatch, replacing):
    """Ctrl-C while `fit` prints its summary, after the model was renamed into place: exit
    130 and one line that says the file is complete (it loads); where nothing was written
    (Ctrl-C before the save), no such claim, and a file replaced is the earlier one."""
    from cfbmarkov.markov import MarkovModel

    out = tmp_path / "model.h5"
    if replacing:
        assert _fit(data, out) == 0
    before = out.read_bytes() if replacing else None
    capsys.readouterr()

    def cut_short(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(MarkovModel, "summary", cut_short)
    assert _fit(data, out, "--resamples", "0") == 130
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == (f"cfbmarkov fit: interrupted after {out} was written whole (the file is "
                       "complete; only the lines printed after it were cut short)")
    assert MarkovModel.load(out).n_states > 0 and out.read_bytes() != before
    assert stray(tmp_path, ["model.h5"]) == []
    monkeypatch.setattr(MarkovModel, "save", cut_short)    # cut short before it is saved
    assert _fit(data, out, "--resamples", "0") == 130
    assert capsys.readouterr().err.splitlines()[-1] == "cfbmarkov fit: interrupted"


def test_ctrl_c_after_reacts_prediction_is_written_says_it_is_whole(data, tmp_path, capsys,
                                                                    monkeypatch):
    """react --init writes its prediction, then computes the exit means' intervals: a
    Ctrl-C there says the file is whole, as fit's does (it said only "interrupted")."""
    from cfbmarkov.cli import kinetics as cli_kinetics

    kinetics = tmp_path / "kin.toml"
    kinetics.write_text('[[property]]\nname = "X"\nlaw = "first-order"\nrate = 1.0\n')
    out = tmp_path / "ri.h5"

    def cut_short(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli_kinetics, "_exit_mean_intervals", cut_short)
    assert main(["react", str(data / "model.h5"), "--kinetics", str(kinetics), "--init",
                 str(data / "run.h5"), "--start", "0.5", "--duration", "0.5", "-q", "-o",
                 str(out)]) == 130
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"cfbmarkov react: interrupted after {out} was written whole (the file is complete; "
        "only the lines printed after it were cut short)")
    assert stray(tmp_path, ["ri.h5", "kin.toml"]) == []


def test_a_folder_moved_aside_by_a_dead_writer_is_put_back(tmp_path):
    """A writer killed between moving the previous output folder aside and renaming the new
    one into place leaves NAME.old-XXXXXXXX and no NAME: the next writer's cleanup puts it
    back, never deletes it; beside a NAME that exists, it is removed as a leftover."""
    from cfbmarkov._outputs import remove_stale_temporaries

    out = tmp_path / "compare"
    aside = tmp_path / "compare.old-1a2b3c4d"
    aside.mkdir()
    (aside / "summary.json").write_text("{}")
    remove_stale_temporaries(out)
    assert (out / "summary.json").read_text() == "{}" and not aside.exists()
    aside.mkdir()
    remove_stale_temporaries(out)
    assert not aside.exists() and (out / "summary.json").exists()


# -- 6. umask -------------------------------------------------------------------------------
def test_umask_022_gives_0644_files(data, tmp_path):
    old = os.umask(0o022)
    try:
        assert _fit(data, tmp_path / "m.h5") == 0
        assert main(["maps", str(data / "model.h5"), "--times", "0.05", "-o",
                     str(tmp_path / "maps.png")]) == 0
    finally:
        os.umask(old)
    for name in ("m.h5", "maps.png"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644


# -- simulate: kills, full disk, Ctrl-C, the final rename ------------------------------------
def _case(tmp_path, end=0.1):
    path = tmp_path / "small.toml"
    path.write_text(SMALL_CASE.format(end=end))
    return path


@pytest.mark.slow
def test_simulate_killed_at_random_points_resumes_or_reruns_clean(tmp_path):
    case = _case(tmp_path, end=0.1)
    rng = random.Random(7)
    # --force: the second round reruns over the first's finished run
    args = ["simulate", case, "-o", "s.h5", "-q", "--checkpoint-every", "0.01", "--force"]
    for _ in range(2):
        p = cli(*args, cwd=tmp_path)
        time.sleep(rng.uniform(1.0, 3.5))
        p.kill()
        p.communicate()
        resume = (tmp_path / "s.h5.parts" / "checkpoint.h5").exists()
        rc, _, err = run_cli(*args, *(["--resume"] if resume else []), cwd=tmp_path,
                             timeout=300)
        assert rc == 0, err
        assert stray(tmp_path, ["small.toml", "s.h5"]) == []


@pytest.mark.slow
def test_simulate_full_disk_keeps_last_checkpoint_and_ctrl_c(tmp_path):
    case = _case(tmp_path, end=0.2)     # an output of about 290 kB against a 150 kB limit
    args = ["simulate", case, "-o", "s.h5", "-q", "--checkpoint-every", "0.01"]
    rc, _, err = run_cli(*args, cwd=tmp_path, preexec_fn=_file_size_limit(150_000),
                         timeout=300)
    assert rc == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and "cannot write (File too large)" in lines[0], err
    assert lines[0].endswith("its last checkpoint is kept: once it can write there again, "
                             "rerun with --resume")
    assert not [p for p in tmp_path.rglob(".*.tmp*")]
    rc, _, err = run_cli(*args, "--resume", cwd=tmp_path, timeout=300)
    assert rc == 0, err
    assert stray(tmp_path, ["small.toml", "s.h5"]) == []
    p = cli("simulate", case, "-o", "t.h5", "-q", "--checkpoint-every", "0.01", "--until",
            "2", cwd=tmp_path)
    deadline = time.time() + 120
    while not (tmp_path / "t.h5.parts" / "checkpoint.h5").exists() and time.time() < deadline:
        time.sleep(0.2)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130
    assert err.splitlines() == ["cfbmarkov simulate: interrupted; the run can be resumed "
                                "with --resume (from its last checkpoint)"]
    assert not [p for p in tmp_path.rglob(".*.tmp*")]


@pytest.mark.slow
@pytest.mark.parametrize("kill_at", ["checkpoint.h5", "segment-00000.h5"])
def test_simulate_killed_during_final_cleanup_is_accepted(tmp_path, monkeypatch, kill_at):
    """A kill after the final rename, while the checkpoint folder is removed: --resume ends
    with the same output, and a plain rerun is accepted too."""
    from cfbmarkov.config import load_case
    from cfbmarkov.simulate.run import simulate

    case = load_case(_case(tmp_path, end=0.05))
    real_unlink = Path.unlink

    def unlink(self, missing_ok=False):
        if self.name == kill_at and self.parent.name == "s.h5.parts":
            raise SystemExit("killed")
        return real_unlink(self, missing_ok=missing_ok)

    monkeypatch.setattr(Path, "unlink", unlink)
    with pytest.raises(SystemExit):
        simulate(case, tmp_path / "s.h5", checkpoint_every=0.01, progress=False)
    monkeypatch.setattr(Path, "unlink", real_unlink)
    assert (tmp_path / "s.h5").exists() and (tmp_path / "s.h5.parts").exists()
    first = (tmp_path / "s.h5").read_bytes()
    simulate(case, tmp_path / "s.h5", checkpoint_every=0.01, progress=False, resume=True)
    assert not (tmp_path / "s.h5.parts").exists()
    assert stray(tmp_path, ["small.toml", "s.h5"]) == []
    assert len((tmp_path / "s.h5").read_bytes()) == len(first)


@pytest.mark.slow
def test_ctrl_c_of_a_reproduce_with_two_workers_is_one_line(tmp_path):
    """Ctrl-C while two worker processes simulate: the workers are stopped (no traceback of
    theirs), the parent says so in one line and exits with 130."""
    tiny = Path(__file__).parent / "test_reproduce.py"
    text = tiny.read_text().split('TINY = """', 1)[1].split('"""', 1)[0]
    (tmp_path / "tiny.toml").write_text(text.replace("end_time = 0.8", "end_time = 3.0"))
    p = cli("reproduce", "--scale", "quick", "--overrides", "tiny.toml", "--velocities", "6,8",
            "-o", "out", "--jobs", "2", "-q", cwd=tmp_path)
    # the signal comes once both workers hold their CFD-DEM's lock (a fixed wait came
    # before the workers started on a busy machine)
    deadline = time.monotonic() + 120.0
    while (len(list((tmp_path / "out").glob("u*/.cfd-dem.h5.lock"))) < 2
           and time.monotonic() < deadline and p.poll() is None):
        time.sleep(0.2)
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    lines = [line for line in err.strip().splitlines()    # the workers' advice, if given
             if not line.startswith("note: ")]
    assert lines == ["cfbmarkov reproduce: interrupted; rerun the same command to resume"]
    # the workers, terminated, could not remove their outputs' lock files: the parent does
    assert (tmp_path / "out").is_dir()
    assert not list((tmp_path / "out").rglob(".*.lock")), list((tmp_path / "out").rglob("*"))


def test_the_temporaries_of_terminated_workers_are_removed(tmp_path):
    """What a reproduction's terminated workers leave (a comparison's folder under way, a
    report figure's and a model's temporaries; a comparison moved aside before its
    replacement took its place) is cleared once they are gone: temporaries removed, the
    moved-aside output put back, every finished file left."""
    from cfbmarkov._outputs import remove_dead_temporaries

    case = tmp_path / "u8"
    (case / "compare-mle.tmp-dc88b590").mkdir(parents=True)
    (case / "compare-mle.tmp-dc88b590" / ".snapshots.png.7v1db4e2.tmp.png").write_bytes(b"")
    (case / ".model-paper.h5.ab12cd34.tmp").write_bytes(b"x")
    (case / "compare-paper.old-0123abcd").mkdir()
    (case / "compare-paper.old-0123abcd" / "summary.json").write_text("{}")
    (case / "model-mle.h5").write_bytes(b"done")
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / ".fig11-mixing.png.dn5ml9e9.tmp.png").write_bytes(b"y")
    (tmp_path / "figures" / "fig10.png").write_bytes(b"z")
    remove_dead_temporaries(tmp_path)
    left = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert left == ["figures", "figures/fig10.png", "u8", "u8/compare-paper",
                    "u8/compare-paper/summary.json", "u8/model-mle.h5"], left
