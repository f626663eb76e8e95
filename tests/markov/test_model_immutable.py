"""What a caller does with a model's copies and containers cannot change its answers:
dataclasses.replace gives a model with its own results (not the original's RTD cache),
unpickled and deep-copied models keep their arrays read-only beside their cached RTD, and
selection records, sources and closed classes refuse changes."""

from __future__ import annotations

import copy
import dataclasses
import json
import pickle

import numpy as np
import pytest

from cfbmarkov.markov.model import MarkovModel
from cfbmarkov.markov.states import CellGrid


def _model(**fields) -> MarkovModel:
    """A column of three cells: up one cell a lag with probability 0.5, a pass up through
    the top back to the bottom."""
    p = np.array([[0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]])
    up = np.zeros((3, 3))
    up[2, 0] = 1.0
    zeros = np.zeros((3, 3), np.int64)
    return MarkovModel(p, zeros, zeros, zeros, CellGrid(1, 3, 0.1, 1.0), 0.1,
                       estimator="given", pass_fractions=(up, np.zeros((3, 3))), **fields)


def test_replace_gives_a_model_with_its_own_results():
    model = _model()
    slower = dataclasses.replace(model, lag=0.2)
    assert slower.rtd().mean == pytest.approx(2 * model.rtd().mean, rel=1e-12)
    assert model.rtd().mean == pytest.approx(0.6, rel=1e-9)      # 6 lags of 0.1 s
    other = _model()
    twice = dataclasses.replace(other, lag=0.2)
    assert twice.rtd().mean == pytest.approx(1.2, rel=1e-9)      # asked first, then:
    assert other.rtd().mean == pytest.approx(0.6, rel=1e-9)


@pytest.mark.parametrize("clone", [copy.deepcopy, lambda m: pickle.loads(pickle.dumps(m))])
def test_copies_keep_their_arrays_read_only(clone):
    model = _model()
    model.rtd()
    twin = clone(model)
    assert twin.rtd().mean == pytest.approx(model.rtd().mean, rel=1e-15)
    for array in (twin.transition_matrix, twin.counts, twin.rtd().probability,
                  *twin.pass_fractions):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 0.0


def test_selection_source_and_classes_are_read_only():
    selection = {"reason": "chosen", "candidates": [{"name": "cells", "score": 1.0}]}
    source = ["a.h5", "b.h5"]
    model = _model(selection=selection, source=source)
    selection["reason"] = "changed by the caller afterwards"
    source.append("c.h5")
    assert model.selection["reason"] == "chosen" and list(model.source) == ["a.h5", "b.h5"]
    with pytest.raises(TypeError, match="belongs to an immutable object"):
        model.selection["reason"] = "rewritten"
    with pytest.raises(TypeError, match="belongs to an immutable object"):
        model.selection["candidates"].append({})
    with pytest.raises(TypeError, match="belongs to an immutable object"):
        model.source.append("d.h5")
    described = model.describe()        # a copy the caller may change, not the model's
    described["selection"]["reason"] = "mine"
    described["source"].append("e.h5")
    assert model.selection["reason"] == "chosen" and len(model.source) == 2
    assert json.loads(json.dumps(model.describe()))["selection"] == {
        "reason": "chosen", "candidates": [{"name": "cells", "score": 1.0}]}
    classes = model.closed_classes
    assert isinstance(classes, tuple) and len(classes) == 1
    with pytest.raises(ValueError, match="read-only"):
        classes[0][0] = 5


def test_a_window_rtd_says_the_window_asked_for():
    """Window RTDs are of whole lags, cached by them; each says the length it used (the
    nearest whole number of lags to the one asked for), not the length asked for."""
    model = _model()
    first, second = model.rtd(window=5.01), model.rtd(window=4.99)
    assert first.window == pytest.approx(5.0, abs=1e-12) and second.window == first.window
    assert second.probability is first.probability      # the same numbers, computed once


def test_a_selection_given_afterwards_is_read_only_too():
    """with_selection (the automatic choice's models) and a source set by _derived."""
    model = _model().with_selection({"reason": "chosen", "candidates": [{"name": "cells"}]})
    with pytest.raises(TypeError, match="belongs to an immutable object"):
        model.selection["candidates"].append({})
    runs = ["a.h5"]
    other = model._derived(source=runs)
    runs.append("b.h5")
    assert list(other.source) == ["a.h5"]


def test_the_repr_tells_models_apart_by_window_and_coherence():
    model = _model(window=(10.0, 15.0))
    assert repr(model) == ("MarkovModel(cells 1x3 (3 states), lag=0.1 s, estimator='given', "
                           "window=10-15 s, transitions=0)")
    assert repr(model.with_coherence(0.6)).endswith(", transitions=0, coherence=0.6)")
