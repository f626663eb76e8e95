"""``compare``'s refusals: one line, before any output, naming its own options."""

from __future__ import annotations

import pytest

from cfbmarkov.cli import main


def refused(capsys, argv, out):
    """Run ``cfbmarkov compare`` with ``argv`` into ``out``; the one line it says on stderr
    after checking it exits 2 and prints nothing on stdout."""
    code = main(["compare", *map(str, argv), "-o", str(out), "--resamples", "0",
                 "--no-figures"])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and captured.out == "", captured
    assert "Traceback" not in captured.err
    return lines[0]


# -- 4. messages naming compare's own options -------------------------------------------------

def test_a_long_run_span_outside_the_reference_names_compares_option(pair, tmp_path, capsys):
    ref, pred = pair
    err = refused(capsys, [ref, pred, "--window", "0.5:3", "--long-run-span", "0:40", "-q"],
                  tmp_path / "c")
    assert "give --long-run-span inside them, e.g. --long-run-span 0:3" in err
    assert "--span" not in err.replace("--long-run-span", "")
    err = refused(capsys, [ref, pred, "--window", "0.5:3", "--long-run-span", "0:3", "-q"],
                  tmp_path / "c")
    assert "(give a longer --long-run-span)" in err
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("order, text", [
    ("nan", "'nan' is not a number: give a finite number >= 1 (or inf"),
    ("0.5", "'0.5' must be a finite number >= 1 (or inf"),
    ("-inf", "'-inf' must be a finite number >= 1 (or inf")])
def test_md_order_refusals_say_what_is_wanted(pair, tmp_path, capsys, order, text):
    ref, pred = pair
    err = refused(capsys, [ref, pred, "--window", "0.5:3", f"--md-order={order}", "-q"],
                  tmp_path / "c")
    assert "argument --md-order: " + text in err
    assert not (tmp_path / "c").exists()
