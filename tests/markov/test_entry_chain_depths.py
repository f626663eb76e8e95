"""The entry chain's block elimination shared by the depth search's tries
(entry_chain.DepthElimination): the same embedded chain, fall probabilities and decay, bit
for bit, as each depth eliminated on its own, with fewer steps, also where a
deeper try's levels keep other states (those steps are eliminated again)."""

import numpy as np
import pytest
import scipy.sparse as sp

import cfbmarkov.markov.entry_chain as entry_chain
from cfbmarkov.markov.first_passage import split_by_pass


def column_chain(states=40, seed=7):
    """A periodic column with passes both ways and random links (S = 40, 30 % filled)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 1, (states, states)) * (rng.uniform(0, 1, (states, states)) < 0.3)
    p += np.eye(states)
    p /= p.sum(axis=1, keepdims=True)
    up, down = np.zeros_like(p), np.zeros_like(p)
    up[-5:, :5] = 1.0                             # the top rows pass up into the bottom ones
    down[:5, -5:] = 1.0
    p[-5:, :5] += 0.2
    p[:5, -5:] += 0.15
    p /= p.sum(axis=1, keepdims=True)
    return split_by_pass(sp.csr_matrix(p), up, down)


def counting(monkeypatch):
    """Counts the levels' steps (each takes level g + 1's result down: D_g X)."""
    count = {"steps": 0}
    for algebra in (entry_chain._SparseBlocks, entry_chain._DenseBlocks):
        original = algebra.down_solved

        def down_solved(self, rows, below, x, original=original):
            count["steps"] += 1
            return original(self, rows, below, x)

        monkeypatch.setattr(algebra, "down_solved", down_solved)
    return count


@pytest.mark.parametrize("dense", [True, False])
def test_shared_depths_give_each_depths_own_elimination_bit_for_bit(monkeypatch, dense):
    if not dense:
        monkeypatch.setattr(entry_chain, "DENSE_STATES", 0)
    count = counting(monkeypatch)
    p_up, p_down, p_stay = column_chain()
    entries = np.flatnonzero(np.asarray(p_up.sum(axis=0)).ravel() > 0)
    s = p_up.shape[0]
    lives = [np.ones((9, s), bool), np.ones((17, s), bool), np.ones((25, s), bool)]
    lives[2][12, 3] = False       # a deeper try whose level 12 keeps other states (its
    #                               distance from the deepest, 12, the shallower ones have)
    own = []
    for live in lives:
        own.append(entry_chain.entry_matrix(p_up, p_down, p_stay, live, entries, True, True))
    alone = count["steps"]
    count["steps"] = 0
    shared = entry_chain.DepthElimination(p_up, p_down, p_stay)
    for live, expected in zip(lives, own):
        got = entry_chain.entry_matrix(p_up, p_down, p_stay, live, entries, True, True,
                                       elimination=shared)
        assert np.array_equal(got[0], expected[0]) and np.array_equal(got[1], expected[1])
        assert got[2] == expected[2] or (np.isnan(got[2]) and np.isnan(expected[2]))
    assert expected[1].max() > 1e-8                  # something falls below the levels
    assert count["steps"] < alone - 10               # the shared steps were not redone
