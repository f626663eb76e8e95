"""The demo runs the whole Markov pipeline and reproduces the paper's known weakness
(a first-order chain on cells underestimates the spread of residence times)."""

import json

from cfbmarkov.cli import main


def test_demo_end_to_end(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--synthetic", "-o", str(out), "--particles", "1500"]) == 0
    rows = json.loads((out / "demo.json").read_text())
    for name in ("paper", "mle"):
        summary = json.loads((out / f"compare-{name}" / "summary.json").read_text())
        assert summary["reference"]["rt_count"] > 1000
        # the prediction's sample mean agrees with the model's exact windowed RTD
        assert abs(summary["model"]["rt_mean"] - rows[name]["exact_model_rt_mean"]) < 0.05
        assert summary["pd_rt_sd"] < -20          # the hidden direction is lost
        for png in ("rtd", "snapshots", "mixing", "transition_matrix", "probability_maps"):
            assert (out / f"compare-{name}" / f"{png}.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert str(out) in printed
    # the exact E(RT) is labelled as the window sees it, not as fit's intrinsic one
    assert "exact, as a 5 s window sees it:" in printed
    # the prediction's E(RT) with its interval, the summary's
    for name in ("paper", "mle"):
        lo, hi = json.loads((out / f"compare-{name}" / "summary.json").read_text())[
            "model"]["rt_mean_interval"]
        from cfbmarkov.markov.uncertainty import outward_bounds

        shown = "-".join(outward_bounds(lo, hi, digits=4))     # rounded outwards
        assert f"(its Monte Carlo sample, 90 % interval with the flow's variability {shown} s;" \
            in printed
    # a closing verdict in the report's words, against the persistence baseline
    from cfbmarkov.report.table3 import baseline_clause, baseline_outcomes

    verdict = [line for line in printed.splitlines() if line.startswith("verdict: ")]
    assert len(verdict) == 1
    clause = baseline_clause(baseline_outcomes(rows.values()), unit="estimator",
                             reference="the reference")
    assert verdict[0].startswith(f"verdict: {clause} (") and "Next step: " in verdict[0]
    # the tutorial quotes these lines as printed (numbers and the folder aside)
    assert _masked(printed.splitlines()[:-1]) == _masked(_tutorial_quote()[:-1])


def _masked(lines):
    import re

    return [re.sub(r"[-+]?\d+(\.\d+)?(e-?\d+)?", "#", line) for line in lines]


def _tutorial_quote():
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "tutorial" / "index.md").read_text()
    after = text.split("cfbmarkov demo --synthetic --particles 2000 -o synth\n```", 1)[1]
    return after.split("```text\n", 1)[1].split("```", 1)[0].splitlines()


# --- what the demo does with a folder that holds files (small references, no full run) ---

import pytest

from cfbmarkov import demo as demo_module
from cfbmarkov import synthetic
from cfbmarkov.errors import InputError


def _reference(folder, particles, seed):
    folder.mkdir(parents=True, exist_ok=True)
    synthetic.write_run(folder / "reference.h5", synthetic.RiserFlow(), particles, 20.0,
                        seed=seed)


def _listing(folder):
    return sorted((p.name, p.stat().st_mtime_ns) for p in folder.iterdir())


def _stop_at_fit(monkeypatch):
    def stop(*args, **kwargs):
        raise InputError("stopped at the fit (test)")
    monkeypatch.setattr(demo_module, "fit_model", stop)


def test_demo_refuses_a_reference_of_other_parameters(tmp_path, capsys):
    out = tmp_path / "d"
    _reference(out, 12, seed=2)
    before = _listing(out)
    assert main(["demo", "--synthetic", "-o", str(out), "--particles", "10"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "reference.h5: a synthetic reference of 12 particles, seed 2, not this demo's " \
           "10 particles, seed 1" in err
    assert "--force" in err and "-o" in err
    assert _listing(out) == before


def test_demo_refuses_a_reference_it_did_not_write(tmp_path, capsys):
    out = tmp_path / "d"
    out.mkdir()
    synthetic.write_open_run(out / "reference.h5", synthetic.RiserFlow(), 10, 20.0, seed=1)
    before = _listing(out)
    assert main(["demo", "--synthetic", "-o", str(out), "--particles", "10"]) == 2
    err = capsys.readouterr().err
    assert "source 'synthetic-open', which the demo did not write" in err
    assert _listing(out) == before


@pytest.mark.parametrize("foreign", ["notes.txt", "summary.json"])
def test_demo_refuses_a_folder_of_other_files(tmp_path, capsys, foreign):
    out = tmp_path / "d"
    out.mkdir()
    (out / foreign).write_text("mine")
    assert main(["demo", "--synthetic", "-o", str(out), "--particles", "10"]) == 2
    err = capsys.readouterr().err
    assert f"folder holds '{foreign}', which is not part of a synthetic demo" in err
    assert "--force" in err
    assert [p.name for p in out.iterdir()] == [foreign]


def test_demo_refuses_a_model_it_did_not_fit(tmp_path, capsys):
    out = tmp_path / "d"
    _reference(out, 10, seed=1)
    (out / "model-paper.h5").write_text("not a model")
    assert main(["demo", "--synthetic", "-o", str(out), "--particles", "10"]) == 2
    assert "model-paper.h5: a model the demo did not fit" in capsys.readouterr().err


def test_demo_reuses_its_own_reference_and_says_so(tmp_path, capsys, monkeypatch):
    out = tmp_path / "d"
    _reference(out, 10, seed=3)
    assert demo_module.check_demo_folder(out, 10, 3) is True
    with pytest.raises(InputError, match="not this demo's 11 particles"):
        demo_module.check_demo_folder(out, 11, 3)
    _stop_at_fit(monkeypatch)
    before = (out / "reference.h5").stat().st_mtime_ns
    assert main(["demo", "--synthetic", "-o", str(out), "--particles", "10", "--seed", "3"]) == 2
    err = capsys.readouterr().err
    assert f"reusing {out / 'reference.h5'} (same parameters" in err
    assert "[1/6]" in err and "synthetic reference" not in err
    assert (out / "reference.h5").stat().st_mtime_ns == before


def test_demo_force_makes_the_reference_again(tmp_path, capsys, monkeypatch):
    from cfbmarkov.trajectories import Trajectories

    out = tmp_path / "d"
    _reference(out, 12, seed=2)
    (out / "notes.txt").write_text("mine")
    (out / "demo.json").write_text('{"paper": {"rt_mean": 1.0}}')     # the earlier set's
    _stop_at_fit(monkeypatch)
    assert main(["demo", "--synthetic", "-o", str(out), "--particles", "10", "--force"]) == 2
    assert "stopped at the fit" in capsys.readouterr().err
    with Trajectories(out / "reference.h5") as run:
        assert run.n_particles == 10 and run.parameters["seed"] == 1
    assert (out / "notes.txt").read_text() == "mine"
    # cut short with a new reference: no summary of the earlier set's files is left
    assert not (out / "demo.json").exists()


def _summary(md, md_base, md_halves=0.01):
    return {"md_rtd": md, "baseline": {"md_rtd": md_base, "windows": [[10, 15], [15, 20]]},
            "natural_variability": {"md_rtd": md_halves}}


def test_demo_verdict_follows_the_baseline_rule():
    loses = demo_module.demo_verdict({"paper": _summary(0.2, 0.03), "mle": _summary(0.2, 0.03)})
    assert loses.startswith("verdict: reusing the fitting window's RTD (the persistence "
                            "baseline) predicts better than the models in both estimators")
    assert "paper MD 0.2 against the baseline's 0.03" in loses
    assert "10-15 s as the prediction of 15-20 s" in loses
    assert "Next step: a state space with memory (fit --states auto)" in loses
    beats = demo_module.demo_verdict({"paper": _summary(0.02, 0.2), "mle": _summary(0.3, 0.2)})
    assert "the models beat the persistence baseline in 1 of 2 estimators" in beats


def test_demo_models_find_their_reference_from_inside_the_folder(tmp_path, capsys,
                                                                 monkeypatch):
    """The demo's models record their fitting data as fit does (its identity): run from
    inside the demo's folder, rtd's interval and react --run find or accept reference.h5
    (and a byte-identical copy), though the models name it from the folder above."""
    import importlib
    import shutil

    def stop(*args, **kwargs):
        raise InputError("stopped at the comparison (test)")

    monkeypatch.setattr(importlib.import_module("cfbmarkov.report.compare"), "compare", stop)
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--synthetic", "-o", "synth", "--particles", "300", "-q"]) == 2
    monkeypatch.chdir(tmp_path / "synth")
    from cfbmarkov.markov import MarkovModel

    model = MarkovModel.load("model-paper.h5")
    assert model.source == "synth/reference.h5" and model.source_identity
    capsys.readouterr()
    assert main(["rtd", "model-paper.h5", "--resamples", "20"]) == 0
    captured = capsys.readouterr()
    # the reference found: no warning but the paper's chain's own (its SD(RT) misses its
    # fitting window, a line of the model's)
    others = [line for line in captured.err.splitlines() if "warning" in line
              and "the chain does not carry its own fitting window" not in line]
    assert "90 % interval" in captured.out and not others, captured.err
    (tmp_path / "kin.toml").write_text('[[property]]\nname = "T"\nlaw = "heat-exchange"\n'
                                       "coefficient = 2.0\ntemperature = 800.0\n"
                                       "wall_temperature = 600.0\ninitial = 300.0\n")
    shutil.copy("reference.h5", tmp_path / "copy.h5")
    for run in ("reference.h5", str(tmp_path / "copy.h5")):
        assert main(["react", "model-paper.h5", "--kinetics", str(tmp_path / "kin.toml"),
                     "--run", run]) == 0, capsys.readouterr().err


def test_demo_refuses_synthetic_options_without_synthetic(tmp_path, capsys, monkeypatch):
    """--particles and --seed belong to the synthetic demo: without --synthetic they are
    refused in one line before anything starts, not dropped."""
    import cfbmarkov.reproduce

    def no_run(*args, **kwargs):            # were it not refused: fail at once, not run
        raise AssertionError("the CFD-DEM demo started")

    monkeypatch.setattr(cfbmarkov.reproduce, "reproduce", no_run)
    for argv, named in ((["--particles", "100"], "--particles applies only with --synthetic"),
                        (["--particles", "100", "--seed", "2"],
                         "--particles and --seed apply only with --synthetic")):
        assert main(["demo", "-o", str(tmp_path / "d"), *argv]) == 2
        captured = capsys.readouterr()
        err = captured.err.strip().splitlines()
        assert len(err) == 1 and captured.out == "" and named in err[0]
        assert "add --synthetic" in err[0]
        assert not (tmp_path / "d").exists()


def test_a_comparison_left_half_written_by_a_killed_demo_is_removed(tmp_path, capsys,
                                                                    monkeypatch):
    """A demo killed while drawing a comparison leaves ``compare-paper.tmp-XXXXXXXX`` with
    partial figures; the next demo in the folder removes it (it had stayed beside the
    results through reruns, --force included)."""
    out = tmp_path / "d"
    _reference(out, 10, seed=3)
    left = out / "compare-paper.tmp-0123abcd"
    left.mkdir()
    (left / "rtd.png").write_bytes(b"partial")
    _stop_at_fit(monkeypatch)
    assert main(["demo", "--synthetic", "-o", str(out), "--particles", "10", "--seed", "3"]) == 2
    capsys.readouterr()
    assert not left.exists() and (out / "reference.h5").exists()
