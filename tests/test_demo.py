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
    assert str(out) in capsys.readouterr().out
