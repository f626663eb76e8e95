"""Property-based fuzzing of the CSV and LAMMPS dump readers: a small mutated text either
imports to the data it holds or is refused with InputError, never another exception."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cfbmarkov.errors import InputError
from cfbmarkov.io import import_file
from cfbmarkov.trajectories import Trajectories

IDS = [3, 2 ** 53, 2 ** 53 + 1]
FUZZ = settings(max_examples=100, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def csv_text():
    rows = ["t,id,x,y"]
    for k in range(4):
        for j, pid in enumerate(IDS):
            rows.append(f"{k * 0.025:.3f},{pid},{0.01 + 0.02 * j:.4f},{0.10 + 0.01 * k:.4f}")
    return "\n".join(rows) + "\n"


def dump_text():
    text = []
    for k in range(4):
        text += ["ITEM: TIMESTEP", str(100 * k), "ITEM: TIME", f"{k * 0.025:g}",
                 "ITEM: NUMBER OF ATOMS", str(len(IDS)), "ITEM: BOX BOUNDS ff pp pp",
                 "0 0.09", "0 0.95", "-0.01 0.01", "ITEM: ATOMS id x y z"]
        text += [f"{pid} {0.01 + 0.02 * j:.4f} {0.1 + 0.01 * k:.4f} 0" for j, pid in enumerate(IDS)]
    return "\n".join(text) + "\n"


PIECES = ["", "0", "-1", "1e308", "nan", "inf", ",", " ", "\n", ".", "e", "#", "9" * 25,
          "ITEM: ATOMS", "ITEM: NUMBER OF ATOMS\n-1", str(2 ** 63), "1.5", "x"]


@st.composite
def mutated(draw, base):
    text = base
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["cut", "delete", "insert", "replace"]))
        at = draw(st.integers(0, len(text)))
        if kind == "cut":
            text = text[:at]
        elif kind == "delete":
            text = text[:at] + text[at + draw(st.integers(1, 8)):]
        else:
            piece = draw(st.sampled_from(PIECES) | st.text("0123456789.-e,\n ", max_size=6))
            end = at + (draw(st.integers(1, 6)) if kind == "replace" else 0)
            text = text[:at] + piece + text[end:]
    return text


def _import(tmp_path, text, fmt):
    src = tmp_path / "src.txt"
    out = tmp_path / "out.h5"
    out.unlink(missing_ok=True)
    src.write_text(text)
    try:
        import_file(src, fmt, out, **({"width": 0.09, "height": 0.95} if fmt == "csv" else {}))
    except InputError:
        assert not out.exists()
        return None
    with Trajectories(out) as t:
        return t.ids.copy(), t.times.copy(), t.positions()


def _check_data(result):
    if result is None:
        return
    ids, times, pos = result
    assert ids.dtype == np.int64 and np.unique(ids).size == ids.size
    assert np.all(np.isfinite(times)) and np.all(np.diff(times) > 0)
    assert pos.shape[:2] == (times.size, ids.size)


def test_unmutated_texts_read_exactly(tmp_path):
    for text, fmt in ((csv_text(), "csv"), (dump_text(), "lammps")):
        ids, times, pos = _import(tmp_path, text, fmt)
        assert sorted(ids.tolist()) == IDS
        np.testing.assert_allclose(times, 0.025 * np.arange(4))


@FUZZ
@given(text=mutated(csv_text()))
def test_fuzzed_csv_clean_error_or_data(tmp_path, text):
    _check_data(_import(tmp_path, text, "csv"))


@FUZZ
@given(text=mutated(dump_text()))
def test_fuzzed_dump_clean_error_or_data(tmp_path, text):
    _check_data(_import(tmp_path, text, "lammps"))
