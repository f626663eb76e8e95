"""--states auto on several runs (markov.select.pooled): the choice scored on the pooled
windows picks what one run of the same flow with their particles together picks."""

import contextlib

import pytest

from cfbmarkov import synthetic
from cfbmarkov.cli import main
from cfbmarkov.markov import MarkovModel
from cfbmarkov.markov.select import DEFAULT_STATES, select_model, select_pooled
from cfbmarkov.trajectories import Trajectories

#: a flow with memory of the direction of motion: cells-previous describes it best
FLOW = synthetic.RiserFlow(columns=3, rows=8, rise_velocity=1.2, fall_velocity=-0.6,
                           vertical_spread=0.5, persistence=True)
WINDOW = (0.5, 4.0)


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("select-pooled")
    return {"a": synthetic.write_run(folder / "a.h5", FLOW, 300, 4.0, seed=21),
            "b": synthetic.write_run(folder / "b.h5", FLOW, 300, 4.0, seed=22),
            "both": synthetic.write_run(folder / "both.h5", FLOW, 600, 4.0, seed=23)}


def test_pooled_choice_is_the_one_run_choice(runs):
    """Two runs of 300 particles pooled against one run of 600 (the concatenated flow):
    the same state space chosen (cells-previous, the flow has memory), every candidate's
    score within 0.03 of the single run's."""
    one = select_model(runs["both"], window=WINDOW, columns=3, rows=8, lag=FLOW.lag,
                       estimator="mle")
    with contextlib.ExitStack() as stack:
        opened = [stack.enter_context(Trajectories(runs[k])) for k in ("a", "b")]
        pooled = select_pooled(opened, windows=[WINDOW], columns=3, rows=8, lag=FLOW.lag,
                               states=DEFAULT_STATES, lag_multiples=(1,), estimator="mle")
    assert one.selection["chosen"] == pooled.selection["chosen"]
    assert pooled.selection["chosen"]["states"] == "cells-previous"
    for a, b in zip(one.selection["candidates"], pooled.selection["candidates"]):
        assert a["states"] == b["states"] and abs(a["score"] - b["score"]) < 0.03, (a, b)
    assert pooled.run_windows == (WINDOW, WINDOW)
    assert "2 runs pooled" in pooled.selection["reason"]
    assert len(pooled.selection["blocks"]) == 2          # the window criterion: one per run


def test_fit_states_auto_on_several_runs(runs, tmp_path, capsys):
    out = tmp_path / "auto.h5"
    assert main(["fit", str(runs["a"]), str(runs["b"]), "--states", "auto", "--cells", "3x8",
                 "--window", "0.5:4", "--estimator", "mle", "--resamples", "10", "-q",
                 "-o", str(out)]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "chosen automatically" in printed and "fitting windows of 2 runs" in printed
    assert ("closest to the one observed over the fitting windows of 2 runs (0.5-4 s, "
            "0.5-4 s); the percentages set the chain's RTD as seen in each run's window") \
        in printed
    model = MarkovModel.load(out)
    assert model.selection["runs"][1][0] == str(runs["b"])
    # the states visited in any run's window, as one run's table gives them
    assert all(isinstance(c["visited"], int) and 0 < c["visited"] <= c["n_states"]
               for c in model.selection["candidates"]), model.selection["candidates"]
    assert model.source == [str(runs["a"]), str(runs["b"])]
    assert main(["fit", str(runs["a"]), str(runs["a"]), "--states", "auto", "--cells", "3x8",
                 "--window", "0.5:4", "-o", str(tmp_path / "x.h5")]) == 2
    assert "same data" in capsys.readouterr().err


def test_reproduction_ensemble_auto_is_chosen_on_all_members(runs):
    """A reproduction's ensemble (markov.select.fit_pooled_by_name) chooses ``auto`` on all
    the members' windows pooled, as ``fit a b --states auto`` does: the same record and
    transition matrix."""
    from cfbmarkov.markov.select.choice import fit_pooled_by_name

    with contextlib.ExitStack() as stack:
        opened = [stack.enter_context(Trajectories(runs[k])) for k in ("a", "b")]
        by_name = fit_pooled_by_name("auto", opened, window=WINDOW, columns=3, rows=8,
                                     lag=FLOW.lag)
        direct = select_pooled(opened, windows=[WINDOW, WINDOW], columns=3, rows=8,
                               lag=FLOW.lag, states=DEFAULT_STATES, lag_multiples=(1,),
                               estimator="mle")
    assert by_name.selection["chosen"] == direct.selection["chosen"]
    assert by_name.run_windows == (WINDOW, WINDOW)
    assert (by_name.transition_matrix == direct.transition_matrix).all()
