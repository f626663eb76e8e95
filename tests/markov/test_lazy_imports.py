"""Start-up of the model verbs: loading a model and asking for its RTD, or predicting,
imports only what they call (``cfbmarkov rtd`` and ``predict`` pay their imports on every
call)."""

import json
import os
import subprocess
import sys

import pytest

import cfbmarkov.markov


def loaded_after(code: str) -> set[str]:
    """The modules of interest loaded by ``code`` in a fresh interpreter."""
    probe = (code + "\nimport json, sys\nprint(json.dumps(sorted(m for m in sys.modules if "
             "m.startswith(('cfbmarkov.markov', 'scipy.sparse', 'scipy.stats')))))")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         env=env, check=True).stdout
    return set(json.loads(out.strip().splitlines()[-1]))


def test_the_model_class_loads_neither_estimators_nor_scipy_sparse():
    loaded = loaded_after("from cfbmarkov.markov import MarkovModel\n"
                          "import cfbmarkov.markov.model_file")
    assert "cfbmarkov.markov.model" in loaded
    for module in ("cfbmarkov.markov.estimate", "cfbmarkov.markov.counting",
                   "cfbmarkov.markov.discrete", "cfbmarkov.markov.select",
                   "cfbmarkov.markov.first_passage", "cfbmarkov.markov.prediction",
                   "scipy.sparse"):
        assert module not in loaded, module


def test_a_prediction_loads_no_scipy_sparse():
    loaded = loaded_after("from cfbmarkov.markov import MarkovModel\n"
                          "import cfbmarkov.markov.prediction")
    assert "cfbmarkov.markov.prediction" in loaded and "scipy.sparse" not in loaded


def test_intervals_and_the_verdict_load_no_scipy_stats():
    """The normal quantile of the intervals comes from scipy.special (ndtri): scipy.stats
    costs 0.8 s of every fit, rtd and compare's start-up."""
    loaded = loaded_after("import cfbmarkov.analysis.intervals, cfbmarkov.analysis.adequacy,"
                          " cfbmarkov.analysis.kinetics_compare, cfbmarkov.analysis.fit_checks")
    assert not any(m.startswith("scipy.stats") for m in loaded), sorted(loaded)


@pytest.mark.parametrize("name", cfbmarkov.markov.__all__)
def test_every_public_name_still_resolves(name):
    assert getattr(cfbmarkov.markov, name) is not None
    assert name in dir(cfbmarkov.markov)
