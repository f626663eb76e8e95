"""compare's window against both files' spans: suggestions inside their overlap, the
overlap as the default window, and a refusal naming both spans where they do not overlap."""

import pytest

from cfbmarkov import synthetic
from cfbmarkov.analysis.compare_inputs import check_common_window, common_span
from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("spans")
    flow = synthetic.RiserFlow()
    files = {}
    for name, start, duration in (("ref", 0.0, 20.0), ("late", 15.0, 10.0),
                                  ("apart", 21.0, 4.0)):
        files[name] = folder / f"{name}.h5"
        synthetic.write_run(files[name], flow, 20, duration, seed=1, start_time=start)
    return files


def test_suggestion_lies_in_both_files(runs):
    with Trajectories(runs["ref"]) as ref, Trajectories(runs["late"]) as pred:
        assert common_span(ref, pred) == pytest.approx((15.0, 20.0))
        with pytest.raises(InputError) as err:
            check_common_window(ref, pred, 15.0, 25.0)
        text = str(err.value)
        assert "e.g. 15:20 (all of it)" in text and "10:20" not in text
        assert "covers 0 to 20 s" in text and "15 to 25 s" in text
        with pytest.raises(InputError, match=r"e\.g\. 15:17 \(the same length\)"):
            check_common_window(ref, pred, 12.0, 14.0)
        check_common_window(ref, pred, 16.0, 20.0)        # inside: no error


def test_spans_that_do_not_overlap_are_named(runs):
    with Trajectories(runs["ref"]) as ref, Trajectories(runs["apart"]) as pred:
        assert common_span(ref, pred) is None
        with pytest.raises(InputError, match="do not overlap"):
            check_common_window(ref, pred, 21.0, 25.0)


def test_cli_refuses_then_defaults_to_the_overlap(runs, tmp_path, capsys):
    out = tmp_path / "c"
    base = ["compare", str(runs["ref"]), str(runs["late"]), "-o", str(out), "--no-figures",
            "--resamples", "0"]
    assert main(base + ["--window", "15:25"]) == 2
    err = capsys.readouterr().err
    assert "e.g. 15:20" in err and len(err.strip().splitlines()) == 1
    assert main(base) == 0
    err = capsys.readouterr().err
    assert "no --window given: comparing over 15:20 s, the span both files cover" in err
    assert (out / "summary.json").is_file()
    assert main(["compare", str(runs["ref"]), str(runs["apart"]), "-o", str(tmp_path / "d"),
                 "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert "covers 0 to 20 s" in err and "21 to 25 s" in err and "do not overlap" in err
    assert not (tmp_path / "d").exists()
