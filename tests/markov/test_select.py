"""``--states auto``: the state space and lag chosen on the fitting window alone.

On the synthetic core-annulus flow (hidden direction of motion) the paper's cells miss the
spread of residence times by about 40 %; the automatic choice must find a space with
memory, from the fitting window alone, that predicts the RTD of a *later* window.
"""

import contextlib
import json

import numpy as np
import pytest

from cfbmarkov import synthetic
from cfbmarkov.observed.residence import residence_times
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.markov import MarkovModel
from cfbmarkov.markov.select import DEFAULT_STATES, fit_by_name, parse_model_name, select_model
from cfbmarkov.trajectories import Trajectories

try:
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover
    threadpool_limits = None

FLOW = synthetic.RiserFlow()
FIT, LATER = (0.5, 4.5), (4.5, 8.5)


@pytest.fixture(scope="session")
def run(tmp_path_factory):
    path = tmp_path_factory.mktemp("select") / "run.h5"
    with (threadpool_limits(1) if threadpool_limits else contextlib.nullcontext()):
        synthetic.write_run(path, FLOW, 2000, LATER[1], seed=4)
    return path


def _later_errors(model, run):
    with Trajectories(run) as traj:
        observed = residence_times(traj, LATER)
    exact = model.rtd(window=LATER[1] - LATER[0])
    return 100 * (exact.mean / observed.mean - 1), 100 * (exact.sd / observed.sd - 1)


def test_auto_chooses_memory_and_predicts_the_later_spread(run, tmp_path):
    model = select_model(run, window=FIT, columns=FLOW.columns, rows=FLOW.rows, lag=FLOW.lag)
    chosen = model.selection["chosen"]
    assert chosen["states"] != "cells" and model.state_space.kind == chosen["states"]
    assert model.lag == pytest.approx(chosen["lag"]) and model.window == FIT
    # only the fitting window was used, judged whole: score = MD / MD(cells)
    assert model.selection["blocks"] == [list(FIT)]
    assert model.selection["method"] == "the RTD over the fitting window"
    candidates = model.selection["candidates"]
    assert {c["states"] for c in candidates} == set(DEFAULT_STATES)
    assert "cells-regime" in DEFAULT_STATES
    cells_md = next(c["md_rtd"] for c in candidates if c["states"] == "cells")
    for c in candidates:
        assert c["score"] == pytest.approx(c["md_rtd"] / cells_md)
    assert min(c["score"] for c in candidates) == pytest.approx(
        next(c["score"] for c in candidates if c["states"] == chosen["states"]
             and c["lag"] == chosen["lag"]))
    cells = fit_by_name("mle", run, window=FIT, columns=FLOW.columns, rows=FLOW.rows,
                        lag=FLOW.lag)
    cells_mean, cells_sd = _later_errors(cells, run)
    auto_mean, auto_sd = _later_errors(model, run)
    assert cells_sd < -25.0                                     # the paper's weakness
    assert abs(auto_mean) < 3.0 and abs(auto_sd) < 10.0, (auto_mean, auto_sd)
    # the choice is saved with the model and explained
    model.save(tmp_path / "auto.h5")
    loaded = MarkovModel.load(tmp_path / "auto.h5")
    assert loaded.selection == json.loads(json.dumps(model.selection))
    assert chosen["states"] in loaded.summary() and "fitting window" in loaded.summary()
    # the chosen model, formed from the counts of the cached frames, is the model that
    # fitting its state space on the window gives
    direct = fit_by_name(chosen["states"], run, window=FIT, columns=FLOW.columns,
                         rows=FLOW.rows, lag=chosen["lag"])
    np.testing.assert_array_equal(model.counts, direct.counts)
    np.testing.assert_allclose(model.transition_matrix, direct.transition_matrix, atol=0)


def test_blocked_cross_validation_still_chooses_memory(run):
    """The criterion of sessions 4-17 (held-out blocks, bias and shape) stays available."""
    model = select_model(run, window=FIT, columns=FLOW.columns, rows=FLOW.rows,
                         lag=FLOW.lag, criterion="rtd")
    blocks = model.selection["blocks"]
    assert len(blocks) == 3 and blocks[0][0] == FIT[0] and blocks[-1][1] == FIT[1]
    assert all(x[1] == y[0] for x, y in zip(blocks, blocks[1:]))
    assert "cross-validation" in model.selection["method"]
    assert model.state_space.kind != "cells"
    auto_mean, auto_sd = _later_errors(model, run)
    assert abs(auto_mean) < 3.0 and abs(auto_sd) < 10.0, (auto_mean, auto_sd)


def test_too_short_blocks_keep_the_papers_cells(run):
    model = select_model(run, window=(0.5, 0.8), columns=FLOW.columns, rows=FLOW.rows,
                         lag=FLOW.lag)
    assert model.state_space.kind == "cells" and "too short" in model.selection["reason"]
    with pytest.raises(InputError, match="too few"):
        select_model(run, window=(0.5, 0.8), columns=FLOW.columns, rows=FLOW.rows,
                     lag=FLOW.lag, criterion="rtd")


def test_held_out_ck_test_finds_the_hidden_direction(run):
    """Where blocks hold too few complete residences (at low gas velocity) the held-out
    Chapman-Kolmogorov test judges instead; on the synthetic flow it too prefers memory."""
    model = select_model(run, window=FIT, columns=FLOW.columns, rows=FLOW.rows,
                         lag=FLOW.lag, criterion="ck")
    selection = model.selection
    assert "Chapman-Kolmogorov" in selection["method"]
    assert "Chapman-Kolmogorov error" in selection["reason"]
    scores = {(c["states"], c["lag"]): c for c in selection["candidates"]}
    cells = scores[("cells", FLOW.lag)]
    assert cells["score"] == pytest.approx(1.0) and cells["ck_error"] > 0
    assert model.state_space.kind != "cells"
    chosen = scores[(selection["chosen"]["states"], selection["chosen"]["lag"])]
    assert chosen["ck_error"] < 0.8 * cells["ck_error"]


def test_cli_fit_with_auto_and_named_states(run, tmp_path, capsys):
    out = tmp_path / "m.h5"
    # (a short window and no interval: the CLI path of the choice, not the choice or the
    # interval, is under test here)
    # (no --estimator: auto fits with mle by default)
    assert main(["fit", str(run), "--cells", "6x38", "--window", "0.5:1.5", "--states", "auto",
                 "--resamples", "0", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "chosen automatically" in text
    assert MarkovModel.load(out).estimator == "mle"
    selection = MarkovModel.load(out).selection
    assert selection is not None
    # every candidate scored in one table, the winner marked, visited states counted
    assert "visited" in text and "score" in text
    marked = [line.split() for line in text.splitlines() if line.strip().startswith("* ")]
    assert len(marked) == 1 and marked[0][1] == selection["chosen"]["states"]
    for c in selection["candidates"]:
        assert any(line.split()[:1] == [c["states"]] or line.split()[1:2] == [c["states"]]
                   for line in text.splitlines() if line.strip())
        assert 0 < c["visited"] <= c["n_states"]
    # a space with memory: mle by default, the paper's estimator only when named, and warned
    fit = ["fit", str(run), "--window", "0.5:4.5", "--resamples", "0", "--no-adequacy",
           "-o", str(out)]
    capsys.readouterr()
    assert main(fit + ["--states", "cells-direction"]) == 0
    model = MarkovModel.load(out)
    assert model.state_space.kind == "cells-direction" and model.estimator == "mle"
    assert "warning: the paper's estimator" not in capsys.readouterr().err
    assert main(fit + ["--states", "cells-direction", "--estimator", "paper"]) == 0
    assert MarkovModel.load(out).estimator == "paper"
    assert "warning: the paper's estimator (Eq. 2-4)" in capsys.readouterr().err
    assert main(fit) == 0       # the paper's cells: its estimator, without a warning
    assert MarkovModel.load(out).estimator == "paper"
    assert "warning: the paper's estimator" not in capsys.readouterr().err
    assert main(["fit", str(run), "--states", "cells-best", "-o", str(out)]) == 2


def test_model_names():
    assert parse_model_name("paper") == ("cells", "paper")
    assert parse_model_name("mle") == ("cells", "mle")
    assert parse_model_name("auto") == ("auto", "mle")
    assert parse_model_name("cells-velocity") == ("cells-velocity", "mle")
    assert parse_model_name("cells-previous:paper") == ("cells-previous", "paper")
    for bad in ("best", "cells:bayes", "cells-sideways"):
        with pytest.raises(InputError, match="unknown model"):
            parse_model_name(bad)


def test_memory_candidates_work_when_the_window_starts_at_the_first_frame(tmp_path):
    """Spaces with memory need one lag before the window: at the file's first frame they
    start one lag later instead of failing (and so are still candidates)."""
    path = tmp_path / "early.h5"
    synthetic.write_run(path, FLOW, 1500, 4.0, seed=5)
    model = select_model(path, window=(0.0, 4.0), columns=FLOW.columns, rows=FLOW.rows,
                         lag=FLOW.lag, lag_multiples=(1,))
    errors = {c["states"]: c["error"] for c in model.selection["candidates"]}
    assert errors == {name: "" for name in errors} and len(errors) == len(DEFAULT_STATES)


def test_a_candidate_with_an_earlier_ones_states_is_not_judged_twice(tmp_path):
    """The fine velocity space fits one sub-row on a flow that moves a row or more per lag:
    the states of cells-velocity, listed as such and not judged again."""
    path = tmp_path / "fast.h5"
    synthetic.write_run(path, FLOW, 1500, 4.0, seed=5)
    model = select_model(path, window=(0.0, 4.0), columns=FLOW.columns, rows=FLOW.rows,
                         lag=FLOW.lag, states=("cells", "cells-velocity", "cells-velocity-fine"))
    scores = {c["states"]: c for c in model.selection["candidates"]}
    assert scores["cells-velocity-fine"]["error"] == ("the same states as cells-velocity on "
                                                     "this window")
    assert scores["cells-velocity-fine"]["score"] is None
    assert scores["cells-velocity"]["score"] is not None and scores["cells-velocity"]["error"] == ""


def test_score_units_are_the_goals_on_a_steady_flow_and_the_flows_variability_otherwise():
    """The PD terms' units: 2 % / 10 % where blocks agree, the blocks' own spread where not."""
    from cfbmarkov.observed.residence import ResidenceTimes
    from cfbmarkov.markov.select.criteria import GOAL_PD_MEAN, GOAL_PD_SD, _natural_tolerances

    rng = np.random.default_rng(3)
    steady = [ResidenceTimes(rng.exponential(0.3, 20000), False, (k, k + 1)) for k in range(3)]
    assert _natural_tolerances(steady) == (GOAL_PD_MEAN, GOAL_PD_SD)
    # the middle block's residences are half as long: each block differs from the others
    scales = (0.36, 0.18, 0.36)
    varying = [ResidenceTimes(rng.exponential(s, 20000), False, (k, k + 1))
               for k, s in enumerate(scales)]
    unit_mean, unit_sd = _natural_tolerances(varying)
    # blocks 1 + 3 (0.36 s) as the prediction of block 2 (0.18 s): +100 % in E; blocks 2 + 3
    # pooled (0.27 s) as that of block 1 or 3 (0.36 s): -25 %
    expected = np.sqrt((2 * 25 ** 2 + 100 ** 2) / 3)
    assert unit_mean == pytest.approx(expected, rel=0.02)
    assert unit_sd > GOAL_PD_SD


def test_net_downflow_is_judged_downward(tmp_path):
    """Where the fitting window's net flow runs down, the held-out residences and the
    candidates' RTDs are counted downward: exactly the upward judgement of the same run
    mirrored top to bottom (y -> H - y, laps -> -laps)."""
    from cfbmarkov.trajectory_writer import TrajectoryWriter

    flow = synthetic.RiserFlow(rise_velocity=0.8, fall_velocity=-2.0)
    path, mirrored = tmp_path / "down.h5", tmp_path / "mirrored.h5"
    with (threadpool_limits(1) if threadpool_limits else contextlib.nullcontext()):
        synthetic.write_run(path, flow, 1500, FIT[1], seed=5)
    with Trajectories(path) as traj:
        positions, laps = traj.positions(slice(None)).copy(), traj.laps(slice(None))
        times, height = traj.times[:], traj.height
        with TrajectoryWriter(mirrored, traj.ids, width=traj.width, height=height,
                              source="synthetic", frame_interval=traj.frame_interval) as out:
            positions[..., 1] = np.where(positions[..., 1] > 0, height - positions[..., 1], 0.0)
            out.append_frames(times, positions, None, -laps)
    chosen = {}
    for name in (path, mirrored):
        chosen[name] = select_model(name, window=FIT, columns=6, rows=38, lag=0.025,
                                    states=("cells", "cells-direction")).selection
    down, up = chosen[path], chosen[mirrored]
    assert down["direction"] == "down" and "counted downward" in down["reason"]
    assert up["direction"] == "up" and "counted downward" not in up["reason"]
    assert min(o["rt_count"] for o in down["observed"]) >= 30          # judged by the RTD
    assert [o["rt_count"] for o in down["observed"]] == [o["rt_count"] for o in up["observed"]]
    for a, b in zip(down["candidates"], up["candidates"]):
        for key in ("pd_rt_mean", "pd_rt_sd", "md_rtd", "score"):
            assert a[key] == pytest.approx(b[key], rel=1e-9, abs=1e-12), (a["states"], key)


def test_auto_fit_at_the_file_start_keeps_its_verdict_and_interval(tmp_path, capsys):
    """A window starting at the file's first frame: the choice judges memory spaces with
    the window's first frames as their history, and the verdict's halves and the interval's
    bootstrap re-read the window the same way (they refused "needs 1 frame(s) of history"
    whenever a space with memory won)."""
    run = tmp_path / "run.h5"
    synthetic.write_run(run, synthetic.RiserFlow(), 80, 3.0, seed=3)
    out = tmp_path / "m.h5"
    code = main(["fit", str(run), "--states", "auto", "--window", "0:2.5", "--resamples", "20",
                 "-q", "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    model = MarkovModel.load(out)
    assert model.state_space.memory_lags >= 1        # a space with memory won here
    assert model.uncertainty is not None and model.adequacy is not None
    # and the window it was fitted on, after the history's first frames, is said
    start = model.window[0]
    assert start > 0.0 and (f"note: the window starts at {start:g} s, the first frame with "
                            f"the history that {model.state_space.kind} needs (the file "
                            f"starts at 0 s): the model is fitted on {start:g}:2.5 s"
                            in captured.err), captured.err


def test_a_space_whose_window_leaves_most_states_unvisited_is_not_chosen():
    """The lowest score wins unless more than half of its states were never visited in the
    window (the chosen model would warn that its space is too fine); the table says why it
    was passed over. Where every candidate is that sparse, the lowest score still wins."""
    import math

    from cfbmarkov.markov.select.candidates import best_candidate
    from cfbmarkov.markov.select.record import CandidateScore
    from cfbmarkov.markov.selection_table import candidate_table

    def score(states, n, visited, value):
        return CandidateScore(states, 0.025, n, 1.0, 1.0, 0.0, 0.0, 0.1, value,
                              visited=visited)

    cells = score("cells", 228, 228, 1.0)
    sparse = score("cells-velocity", 1824, 644, 0.4)       # 1180 of 1824 never visited
    filled = score("cells-direction", 456, 300, 0.7)       # 156 of 456: kept
    failed = CandidateScore("cells-previous", 0.025, 1596, *[math.nan] * 5, math.inf, "x")
    assert best_candidate([cells, sparse, filled, failed]) is filled
    assert best_candidate([cells, sparse]) is cells
    lone = score("cells", 228, 100, 1.0)                   # every candidate sparse
    assert best_candidate([lone, sparse]) is sparse
    assert best_candidate([failed]) is None
    record = {"method": "window RTD", "chosen": {"states": "cells-direction", "lag": 0.025},
              "candidates": [c.as_dict() for c in (cells, sparse, filled)]}
    notes = [line for line in candidate_table(record) if "not chosen" in line]
    assert len(notes) == 1 and notes[0].startswith("cells-velocity at lag 0.025 s not chosen")
    assert "1180 of its 1824 states never visited" in notes[0]


def test_a_choice_that_passed_over_a_lower_score_says_so():
    """A candidate that scored lower but left most of its states never visited is passed
    over: the reason says the chosen one is the closest among the others, naming it (it
    said "had the exact RTD closest" beside a table whose closer row was that candidate)."""
    from types import SimpleNamespace

    from cfbmarkov.markov.select.record import _passed_over

    chosen = SimpleNamespace(states="cells", score=1.0, n_states=228, visited=228)
    sparse = SimpleNamespace(states="cells-previous", score=0.442, n_states=336, visited=96)
    filled = SimpleNamespace(states="cells-direction", score=1.3, n_states=456, visited=450)
    said = _passed_over(chosen, [chosen, sparse, filled])
    assert said == ("; closest among the candidates whose states the window visits: "
                    "cells-previous (score 0.442, 240 of 336 states never visited) scored "
                    "lower but leaves more than 50 % of its states never visited")
    assert _passed_over(chosen, [chosen, filled]) == ""


def test_the_stored_selection_is_strict_json(run, tmp_path):
    """The choice over the fitting window has no PD units (NaN in memory): the model file
    stores them as null, JSON that strict parsers read (json.loads with no NaN allowed)."""
    import h5py

    out = tmp_path / "auto.h5"
    assert main(["fit", str(run), "--window", "0.5:3", "--states", "auto", "--estimator",
                 "mle", "--resamples", "0", "--no-adequacy", "-q", "-o", str(out)]) == 0
    with h5py.File(out, "r") as f:
        text = next(g.attrs["selection"] for g in [f, *f.values()]
                    if isinstance(g, h5py.Group) and "selection" in g.attrs)

    def refuse(constant):
        raise ValueError(constant)

    record = json.loads(text, parse_constant=refuse)
    assert record["units"] == {"pd_rt_mean": None, "pd_rt_sd": None}
    assert MarkovModel.load(out).selection["chosen"] == record["chosen"]


def test_a_window_started_late_by_its_history_is_judged_as_fitted(run, tmp_path, capsys):
    """A state space with memory on a window from the file's first frame starts it a lag
    late; the verdict and the window's own E(RT) were of the window as given (a review
    found 0.5792 s printed for a model fitted on 0.525:1.5, whose own is 0.5758 s), now
    of the frames the model was fitted on."""
    out = tmp_path / "m.h5"
    with Trajectories(run) as traj:
        first = float(traj.times[0])
    assert main(["fit", str(run), "--cells", "6x38", "--window", f"{first:g}:{first + 2:g}",
                 "--states", "auto", "--resamples", "0", "-o", str(out)]) == 0
    capsys.readouterr()
    model = MarkovModel.load(out)
    assert model.window[0] > first
    assert model.adequacy.window_length == pytest.approx(model.window[1] - model.window[0])


def test_auto_judges_a_window_between_frames_on_the_frames_it_holds(tmp_path):
    """A window typed between frames (1.01:4.99 on frames every 0.025 s): the candidates
    are judged on the frames it holds, 1.025-4.975 s, seen as a 3.95 s window, as the
    chosen model is fitted and stored."""
    from cfbmarkov.markov.select import select_model
    from cfbmarkov.synthetic import RiserFlow, write_run

    run = write_run(tmp_path / "a.h5", RiserFlow(columns=4, rows=8, lag=0.025,
                                                 persistence=False, rise_velocity=4.0,
                                                 fall_velocity=-1.0), 100, 5.0, seed=1)
    model = select_model(run, window=(1.01, 4.99), columns=4, rows=8, lag=0.025,
                         states=("cells", "cells-direction"), lag_multiples=(1,))
    assert model.window == pytest.approx((1.025, 4.975))
    text = model.summary()
    assert "the fitting window 1.025-4.975 s" in text and "a 3.95 s window" in text
    assert "1.01" not in text and "3.98 s" not in text
