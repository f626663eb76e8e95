"""Residences counted in the direction of the fitting window's net solids flow: a generated
periodic riser whose chain drifts down (a Markov run mirrored top to bottom) against the
same run flowing up."""

import json

import h5py
import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.markov import CellGrid, MarkovModel, fit_model
from cfbmarkov.markov.model_summary import DOWNWARD_LINE
from cfbmarkov.observed.residence import residence_times
from cfbmarkov.synthetic import RiserFlow, sample_run
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

FLOW = RiserFlow(persistence=False)      # a Markov chain on the cells: the model is exact
STOP = 10.0                              # 401 frames, 0.025 s apart


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    """(up, down) trajectory files of one run and its mirror image (net flow down)."""
    folder = tmp_path_factory.mktemp("flow-direction")
    times, _, pos, laps = sample_run(FLOW, 200, 401, seed=4)
    up = write_trajectories(folder / "up.h5", times, pos, width=FLOW.width,
                            height=FLOW.height, laps=laps)
    mirrored = pos.copy()
    mirrored[..., 1] = np.nextafter(FLOW.height, 0) - pos[..., 1]
    down = write_trajectories(folder / "down.h5", times, mirrored, width=FLOW.width,
                              height=FLOW.height, laps=-laps)
    return up, down


def grid():
    return CellGrid(FLOW.columns, FLOW.rows, FLOW.width, FLOW.height)


def test_the_model_of_a_net_downflow_counts_residences_downward(runs):
    """The model knows its window's net flow runs down; its default E(RT) is the downward
    one and equals the observed downward E(RT) within its sampling error, while the upward
    count (what a fixed upward count would print) lies far off it."""
    up, down = runs
    m_down = fit_model(down, grid(), FLOW.lag, (0.0, STOP), "mle")
    m_up = fit_model(up, grid(), FLOW.lag, (0.0, STOP), "mle")
    assert m_down.flow_direction == "down" and m_up.flow_direction == "up"
    assert m_down.counts_down.sum() > m_down.counts_up.sum()
    assert m_down.rtd().mean == m_down.rtd(direction="down").mean
    assert m_down.rtd().mean == pytest.approx(m_up.rtd().mean, rel=1e-6)
    with Trajectories(down) as t:
        observed = residence_times(t, (0.0, STOP), use_events=False, direction="down")
    error = observed.sd / np.sqrt(observed.count)
    assert observed.count > 1000
    assert abs(m_down.rtd(window=STOP).mean - observed.mean) < 3 * error
    assert abs(m_down.rtd(window=STOP, direction="up").mean - observed.mean) > 30 * error
    # the up-flowing riser's chain unchanged: its default is the upward count
    with Trajectories(up) as t:
        observed_up = residence_times(t, (0.0, STOP), use_events=False)
    assert m_up.rtd().mean == m_up.rtd(direction="up").mean
    assert abs(m_up.rtd(window=STOP).mean - observed_up.mean) < 3 * error
    assert "flow_direction" not in m_up.describe()
    assert m_down.describe()["flow_direction"] == "down"


def test_the_direction_is_stored_and_old_files_read_as_up(runs, tmp_path):
    """The model file records the direction; a file without it (an older one) reads as up;
    a bad one is refused in one line."""
    _, down = runs
    path = fit_model(down, grid(), FLOW.lag, (0.0, STOP), "mle").save(tmp_path / "m.h5")
    assert MarkovModel.load(path).flow_direction == "down"
    with h5py.File(path, "r+") as f:
        del f.attrs["flow_direction"]
    assert MarkovModel.load(path).flow_direction == "up"
    with h5py.File(path, "r+") as f:
        f.attrs["flow_direction"] = "sideways"
    with pytest.raises(Exception, match="flow direction 'sideways'"):
        MarkovModel.load(path)


def test_intervals_and_verdict_follow_the_direction(runs):
    """The model's interval is of the downward E(RT) and rides on the default RTD; the
    verdict's E(RT) is the downward one too."""
    from cfbmarkov.analysis.adequacy import assess_adequacy
    from cfbmarkov.analysis.intervals import model_intervals

    _, down = runs
    model = fit_model(down, grid(), FLOW.lag, (0.0, STOP), "mle")
    band = model_intervals(model, level=0.9, resamples=20)
    exact = model.rtd().mean
    assert band.rt_mean_interval[0] <= exact <= band.rt_mean_interval[1]
    from cfbmarkov.errors import UnresolvedWarning

    with pytest.warns(UnresolvedWarning, match="counted upward"):    # against the net flow
        assert band.rt_mean_interval[1] < model.rtd(direction="up").mean
    model = model.with_uncertainty(band)
    assert model.rtd().uncertainty is band
    assert model.rtd(direction="up").uncertainty is None
    verdict = assess_adequacy(model, [down], [(0.0, STOP)])
    assert verdict.rt_mean == pytest.approx(exact)
    assert all(abs(m / exact - 1.0) < 0.3 for _, _, m, _ in verdict.parts)


def test_fit_rtd_and_info_say_the_residences_are_counted_downward(runs, tmp_path, capsys):
    up, down = runs
    path = tmp_path / "down.h5"
    assert main(["fit", str(down), "--cells", f"{FLOW.columns}x{FLOW.rows}", "--lag",
                 str(FLOW.lag), "--window", f"0:{STOP:g}", "--estimator", "mle",
                 "--resamples", "0", "-o", str(path)]) == 0
    out = capsys.readouterr().out
    assert DOWNWARD_LINE in out
    model = MarkovModel.load(path)
    assert f"E(RT) = {model.rtd().mean:.4g} s" in out
    assert main(["rtd", str(path)]) == 0
    out = capsys.readouterr().out
    assert DOWNWARD_LINE in out and f"E(RT) = {model.rtd().mean:.4f} s" in out
    assert main(["rtd", str(path), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["direction"] == "down" and got["rt_mean"] == pytest.approx(model.rtd().mean)
    assert main(["info", str(path)]) == 0
    assert DOWNWARD_LINE in capsys.readouterr().out
    up_path = tmp_path / "up.h5"
    assert main(["fit", str(up), "--cells", f"{FLOW.columns}x{FLOW.rows}", "--lag",
                 str(FLOW.lag), "--window", f"0:{STOP:g}", "--estimator", "mle",
                 "--resamples", "0", "--no-adequacy", "-o", str(up_path)]) == 0
    assert DOWNWARD_LINE not in capsys.readouterr().out
    assert main(["rtd", str(up_path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["direction"] == "up"


def test_compare_counts_as_the_model_and_says_where_the_reference_differs(runs, tmp_path):
    """A prediction of the down model compared with the up-flowing run: both sides counted
    downward, as the model, with one warning line naming the two directions; against the
    down-flowing run itself no such line."""
    from cfbmarkov.report.compare import compare

    up, down = runs
    model = fit_model(down, grid(), FLOW.lag, (0.0, 5.0), "mle")
    pred = model.predict(down, start=5.0, duration=5.0, seed=3, output=tmp_path / "p.h5")
    same = compare(down, pred, window=(5.0, 10.0), output=tmp_path / "same", figures=False,
                   resamples=0)
    assert same["direction"] == "down"
    assert not any("the model counts residences" in w for w in same["warnings"])
    with pytest.raises(InputError, match="counted downward as the model counts, while the "
                                         "reference's net flow over the window runs up"):
        compare(up, pred, window=(5.0, 10.0), output=tmp_path / "other", figures=False,
                resamples=0)     # the up run holds no downward residence
    assert not (tmp_path / "other").exists()
    other = compare(up, pred, window=(5.0, 10.0), output=tmp_path / "other", figures=False,
                    resamples=0, allow_empty=True)
    assert other["direction"] == "down"
    lines = [w for w in other["warnings"] if "the model counts residences downward" in w]
    assert len(lines) == 1 and "runs up" in lines[0]


def test_residences_counted_against_the_net_flow_warn_that_they_drift_away(runs):
    """Counted against the chain's net flow, nearly every residence drifts away from its
    end: the warning says so, with the share that ends, and names the direction to count
    in, not a coarser grid; in the net flow's direction no warning."""
    import warnings

    from cfbmarkov.errors import UnresolvedWarning

    up, down = runs
    for path, flow, other in ((up, "up", "down"), (down, "down", "up")):
        model = fit_model(path, grid(), FLOW.lag, (0.0, STOP), "mle")
        with pytest.warns(UnresolvedWarning) as caught:
            against = model.rtd(direction=other)
        line = str(caught[0].message)
        assert against.unresolved > 0.5
        assert line.startswith(f"unresolved mass {against.unresolved:.2g}: counted {other}ward")
        assert f"since the chain's net flow runs {flow}ward" in line
        resolved = 100 * float(against.probability.sum())
        assert f"describe the resolved {resolved:.2g} % alone" in line
        assert f'(direction="{flow}", the model\'s flow_direction' in line
        assert "coarser grid" not in line
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            model.rtd()                   # the net flow's direction: no warning


def test_maps_with_outflow_of_a_net_downflow_are_the_mirror_image_of_the_upflows(runs, tmp_path,
                                                                                capsys):
    """A batch of a net downflow's model, with outflow, is fed over the top cells and
    leaves through the bottom as the model's downward residences end: its maps are the
    up-flowing run's maps turned upside down, and the mass left is the same (a batch fed
    at the bottom and taken out by passes up was not); the CLI says so in one note."""
    up, down = runs
    m_down = fit_model(down, grid(), FLOW.lag, (0.0, STOP), "mle")
    m_up = fit_model(up, grid(), FLOW.lag, (0.0, STOP), "mle")
    times = [0.0, 0.5, 2.0, 5.0]
    maps_down = m_down.batch_injection_maps(times, outflow=True)
    maps_up = m_up.batch_injection_maps(times, outflow=True)
    np.testing.assert_allclose(maps_down[:, ::-1, :], maps_up, rtol=0, atol=1e-12)
    left = maps_down.sum(axis=(1, 2))
    assert left[0] == pytest.approx(1.0) and left[-1] < 0.5
    # without outflow: Eq. (8)'s batch over the bottom cells, for either flow
    plain = m_down.batch_injection_maps([0.0], outflow=False)
    assert plain[0, 0].sum() == pytest.approx(1.0)
    model = tmp_path / "down-model.h5"
    m_down.save(model)
    assert main(["maps", str(model), "--times", "0,5", "--outflow", "-o",
                 str(tmp_path / "maps.png")]) == 0
    captured = capsys.readouterr()
    assert captured.err.count("note: the model's residences run downward") == 1
    assert f"t = 5 s: fraction in riser {left[-1]:.4f}" in captured.out
