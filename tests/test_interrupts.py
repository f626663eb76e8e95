"""Ctrl-C at any moment: while the command line's modules load, while Numba kernels count
transitions, during `fit --states auto`: one line and exit code 130, never a traceback or
a crash."""

import builtins
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cfbmarkov import _interrupt, synthetic
from cfbmarkov.cli import main
from cfbmarkov.markov import MarkovModel

SRC = str(Path(__file__).resolve().parents[1] / "src")


@pytest.fixture
def default_sigint():
    """SIGINT as in a program started from a shell (the default handler): a test worker
    process may have it ignored, and then no Ctrl-C arrives at all."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_deferred_holds_ctrl_c_until_the_block_ends(default_sigint):
    reached = False
    with pytest.raises(KeyboardInterrupt):
        with _interrupt.deferred():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)            # the handler runs here and must not raise
            reached = True
    assert reached
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_counting_holds_ctrl_c_until_its_kernels_return(monkeypatch, default_sigint):
    from cfbmarkov.markov import counting

    seen = []
    real = counting._count_kernel

    def kernel(*args):
        os.kill(os.getpid(), signal.SIGINT)      # Ctrl-C while the kernel "runs"
        time.sleep(0.02)
        seen.append(real(*args))
        return seen[-1]

    monkeypatch.setattr(counting, "_count_kernel", kernel)
    from cfbmarkov.markov import CellGrid
    from cfbmarkov.markov.discrete import DiscreteTrajectories

    states = np.array([[0, 0, 1], [1, 1, 1], [1, 0, 0]], np.int32)
    data = DiscreteTrajectories(states=states, vertical=states + 0.5, times=np.arange(3.0),
                                lag_frames=1, frame_interval=1.0, height=2.0,
                                state_space=CellGrid(1, 2, 1.0, 2.0))
    with pytest.raises(KeyboardInterrupt):
        counting.count_transitions(data)
    assert seen                                  # the kernel ran to its end first


def test_ctrl_c_while_the_modules_load_is_one_line(monkeypatch, capsys):
    real = builtins.__import__

    def slow_import(name, *args, **kwargs):
        if name == "cfbmarkov.cli.command":
            raise KeyboardInterrupt              # as a Ctrl-C in the middle of the import
        return real(name, *args, **kwargs)

    monkeypatch.delitem(sys.modules, "cfbmarkov.cli.command", raising=False)
    monkeypatch.setattr(builtins, "__import__", slow_import)
    assert main(["info", "x.h5"]) == 130
    assert capsys.readouterr().err == "cfbmarkov: interrupted\n"


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONWARNINGS"] = "ignore"
    env["NUMBA_NUM_THREADS"] = "2"
    return env


@pytest.mark.parametrize("delay", [0.4, 1.5, 4.0])
def test_ctrl_c_during_fit_states_auto_is_clean(tmp_path, delay):
    """SIGINT at a few moments of `fit --states auto` (the modules loading, the counting
    kernels, the candidates): exit code 130 with one line, or a finished fit; never a
    traceback or a crash. The moment each signal lands depends on the machine, so only the
    outcome is asserted."""
    synthetic.write_run(tmp_path / "run.h5", synthetic.RiserFlow(), 80, 3.0, seed=3)
    p = subprocess.Popen([sys.executable, "-m", "cfbmarkov", "fit", "run.h5", "--states", "auto",
                          "--window", "0:2.5", "--resamples", "0", "-o", "m.h5"],
                         cwd=tmp_path, env=_env(), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=300)
    assert "Traceback" not in err and "Fatal Python error" not in err, err
    # 130 from the handler, or ended by the signal itself (-2: the shell shows 130 too)
    assert p.returncode in (0, 130, -signal.SIGINT), (p.returncode, err)
    if p.returncode != 0 and (tmp_path / "m.h5").exists():   # after the save: said so
        assert err.splitlines()[-1] == ("cfbmarkov fit: interrupted after m.h5 was written "
                                        "whole (the file is complete; only the lines "
                                        "printed after it were cut short)"), err
        assert MarkovModel.load(tmp_path / "m.h5").n_states > 0
        assert sorted(x.name for x in tmp_path.iterdir()) == ["m.h5", "run.h5"]
    elif p.returncode != 0:
        assert err.splitlines()[-1].endswith("interrupted"), err
        assert sorted(x.name for x in tmp_path.iterdir()) == ["run.h5"]



LATE_CTRL_C = """
import os, signal, sys, time, types


class LastWord:                 # freed as the interpreter tears its modules down
    def __del__(self):
        os.kill(os.getpid(), getattr(signal, sys.argv[2]))
        time.sleep(0.2)


late = types.ModuleType("late_finalizer")
late.keep = LastWord()
sys.modules["late_finalizer"] = late
del late
from cfbmarkov.cli import program

sys.argv = ["cfbmarkov", "info", sys.argv[1]]
program()
"""


@pytest.mark.parametrize("signal_name", ["SIGINT", "SIGTERM"])
def test_ctrl_c_while_the_interpreter_shuts_down_after_a_complete_verb_is_ignored(
        tmp_path, signal_name):
    """A Ctrl-C (or a SIGTERM) after the verb has returned (its output published), while the
    interpreter tears down its modules, where Python has put the default handler back: the
    run ends with the verb's code, not killed by the signal with nothing said."""
    synthetic.write_run(tmp_path / "run.h5", synthetic.RiserFlow(), 8, 0.5, seed=3)
    script = tmp_path / "late.py"
    script.write_text(LATE_CTRL_C)
    done = subprocess.run([sys.executable, str(script), "run.h5", signal_name], cwd=tmp_path,
                          env=_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, (done.returncode, done.stderr)
    assert "trajectories" in done.stdout.lower() and "interrupted" not in done.stderr


def test_program_after_an_interrupt_past_the_verb_says_one_line(monkeypatch, capsys):
    from cfbmarkov import cli

    def interrupted_on_return(argv=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "main", interrupted_on_return)
    previous = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    try:
        with pytest.raises(SystemExit) as exited:
            cli.program()
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous[0])
        signal.signal(signal.SIGTERM, previous[1])
    assert exited.value.code == 130
    assert capsys.readouterr().err == "cfbmarkov: interrupted\n"


HALF_BUILT = """
import sys
from cfbmarkov.cli import main
from cfbmarkov.cli import markov as verbs


class HalfBuilt:  # construction cut short by Ctrl-C; its finalizer then fails
    def __init__(self):
        raise KeyboardInterrupt

    def __del__(self):
        self.handle


verbs.cmd_info = lambda args: HalfBuilt()
hook = sys.unraisablehook
code = main(["info", sys.argv[1]])
assert sys.unraisablehook is hook, "the unraisable hook is not restored"
sys.exit(code)
"""


def _run_script(script: Path, text: str) -> subprocess.CompletedProcess:
    """``text`` written to ``script`` and run as a program with this checkout's package,
    its own path as the argument (a file that exists, for `cfbmarkov info`)."""
    script.write_text(text)
    env = dict(os.environ)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, str(script), str(script)], capture_output=True,
                          text=True, env=env, timeout=120)


def test_failing_finalizers_of_what_the_interrupt_cut_short_stay_quiet(tmp_path):
    """An object the interrupt left half built, whose finalizer fails as it is freed (as
    llvmlite's ``ObjectRef`` does when Numba is interrupted while it loads its cache): the
    one line and exit code 130, no "Exception ignored" traceback after it, and the
    unraisable hook restored."""

    done = _run_script(tmp_path / "half_built.py", HALF_BUILT)
    assert done.returncode == 130, done.stderr
    assert done.stderr == "cfbmarkov info: interrupted\n", done.stderr


PRINTED_BY_C = """
import sys
from cfbmarkov import _interrupt
from cfbmarkov.cli import main
from cfbmarkov.cli import markov as verbs


def verb(args):
    try:
        _interrupt.handler(2, None)     # the handler, raising inside an import that C code
    except KeyboardInterrupt as exc:    # made, which prints it (PyErr_Print) and carries on
        sys.excepthook(type(exc), exc, exc.__traceback__)
    sys.excepthook(ValueError, ValueError("kept"), None)   # other errors still printed
    _interrupt.check()                  # the next check raises it again
    return 0


verbs.cmd_info = verb
hook = sys.excepthook
code = main(["info", sys.argv[1]])
assert sys.excepthook is hook, "the except hook is not restored"
sys.exit(code)
"""


def test_an_interrupt_printed_by_c_code_is_not_a_traceback(tmp_path):
    """Ctrl-C raised inside an import made by C code, which prints it through
    sys.excepthook and carries on (seen once at SIGINT 0.4 s of `fit --states auto`: a
    traceback of importlib's _find_and_load before the one line): not printed while the
    verb runs, raised again at the next check: the one line, exit 130, other errors still
    printed, and the hook restored."""
    done = _run_script(tmp_path / "printed_by_c.py", PRINTED_BY_C)
    assert done.returncode == 130, done.stderr
    assert "KeyboardInterrupt" not in done.stderr and "ValueError: kept" in done.stderr
    assert done.stderr.endswith("cfbmarkov info: interrupted\n"), done.stderr
