"""How sets of states and the automatic choice's candidates are written: counts, rows and
cells, one table of every candidate; never a long list of state numbers."""

import math

import numpy as np

from cfbmarkov.markov import CellGrid, DirectionCells
from cfbmarkov.markov.model_summary import cells_text, state_set_text
from cfbmarkov.markov.select.record import CandidateScore
from cfbmarkov.markov.selection_table import candidate_columns, candidate_table


def test_cells_by_whole_rows_and_single_cells():
    grid = CellGrid(6, 56, 0.04, 0.3)                      # 336 states
    top = np.arange(54 * 6, 56 * 6)                        # rows 54-55 whole
    states = np.concatenate([[3 * 6 + 0, 3 * 6 + 1], top])
    text = state_set_text(grid, states)
    assert text == "14 of 336 (rows 54-55; cells (0,3), (1,3) as column,row)"
    assert state_set_text(grid, np.array([], dtype=np.int64)) == "0"
    # many single cells: a few named and the rest counted, no long list of numbers
    scattered = np.arange(0, 336, 7)                       # 48 cells, no whole row
    text = state_set_text(grid, scattered)
    assert text.startswith("48 of 336 (cells (0,0), (1,1),")
    assert "(40 more) as column,row)" in text
    assert text.count("(") <= 8 + 2
    assert "224" not in text and "329" not in text          # state numbers are not listed


def test_states_with_memory_are_counted_by_cell():
    space = DirectionCells(2, 3, 1.0, 3.0)                 # 12 states, 2 per cell
    cell_of = space.cell_of_state
    of_cell = lambda c: np.flatnonzero(cell_of == c)       # noqa: E731
    one_each = np.array([of_cell(0)[0], of_cell(5)[0]])
    assert state_set_text(space, one_each) == \
        "2 of 12 (in 2 of 6 cells, none of them with all its states)"
    whole = np.concatenate([of_cell(4), of_cell(5), of_cell(0)[:1]])
    assert state_set_text(space, whole) == \
        "5 of 12 (in 3 of 6 cells; all the states of 2 of them: row 2)"
    assert cells_text(space, np.array([1])) == "cell (1,0) as column,row"


def _record(method="the RTD over the fitting window"):
    def cand(states, n, visited, md, pd_e, pd_sd, score, error=""):
        return CandidateScore(states, 0.025, n, 0.8, 0.5, pd_e, pd_sd, md, score, error,
                              visited=visited).as_dict()
    return {"method": method, "chosen": {"states": "cells-previous", "lag": 0.025},
            "units": {"pd_rt_mean": 2.0, "pd_rt_sd": 10.0},
            "reason": "cells-previous at lag 0.025 s had the exact RTD closest ...",
            "candidates": [
                cand("cells", 228, 228, 0.206, 13.6, -47.0, 1.0),
                cand("cells-direction", 456, 456, 0.107, 8.1, -18.3, 0.521),
                cand("cells-velocity", 1824, 1810, 0.053, 4.4, -8.4, 0.257),
                cand("cells-previous", 1596, 1462, 0.0155, 0.5, -3.4, 0.0754),
                cand("cells-regime", 456, 456, math.nan, math.nan, math.nan, math.inf,
                     "the same states as cells-direction on this window")]}


def test_candidate_table_lists_every_candidate_with_the_winner_marked():
    lines = candidate_table(_record())
    header, rows = lines[0].split(), lines[1:6]
    assert header == ["states", "lag", "(s)", "S", "visited", "MD", "PD", "E(RT)", "%", "PD",
                      "SD(RT)", "%", "score"]
    # lowest score first, the winner marked, the one not judged last with a note
    assert [r.split()[0] for r in rows] == ["*", "cells-velocity", "cells-direction", "cells",
                                            "cells-regime"]
    assert rows[0].split() == ["*", "cells-previous", "0.025", "1596", "1462", "0.0155",
                               "+0.5", "-3.4", "0.0754"]
    assert rows[1].split()[:5] == ["cells-velocity", "0.025", "1824", "1810", "0.053"]
    assert rows[4].split()[-1] == "-"
    assert lines[6].startswith("score = MD / MD(cells)")
    assert lines[7] == ("cells-regime at lag 0.025 s not judged: the same states as "
                        "cells-direction on this window")
    assert len(lines) == 8
    # every column lines up
    assert len({len(line) for line in lines[:5]}) <= 2


def test_candidate_table_of_the_other_criteria():
    headers, rows, notes = candidate_columns(
        _record("3-fold blocked cross-validation of the RTD"))
    assert headers[5:] == ["PD E(RT) %", "PD SD(RT) %", "MD", "score"]
    assert notes[0].startswith("score = |PD E(RT)| / 2 + |PD SD(RT)| / 10 + MD / MD(cells)")
    record = _record("3-fold blocked cross-validation of the Chapman-Kolmogorov test")
    for c in record["candidates"]:
        c["ck_error"] = 0.01
    headers, rows, notes = candidate_columns(record)
    assert headers[5:] == ["CK error", "score"] and rows[0][5] == "0.0100"
    # none judged (the blocks too short): one note per reason, no score formula
    for c in record["candidates"]:
        c.update(score=None, error="no held-out comparison")
    headers, rows, notes = candidate_columns(record)
    assert len(rows) == 5 and notes == [
        "cells at lag 0.025 s, cells-direction at lag 0.025 s, cells-velocity at lag 0.025 s, "
        "cells-previous at lag 0.025 s, cells-regime at lag 0.025 s not judged: no held-out "
        "comparison"]
    # a record without the visited count: "-" in its place
    for c in record["candidates"]:
        del c["visited"]
    assert candidate_columns(record)[1][0][4] == "-"
