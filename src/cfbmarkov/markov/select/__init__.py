"""``--states auto``: choose the state space and lag from the fitting window alone.

Every candidate (state space x lag) is fitted on the fitting window [A, B] and judged by
what matters downstream, the residence-time distribution: its exact windowed RTD
(:func:`~cfbmarkov.markov.first_passage.exact_rtd`, no Monte Carlo noise), started from the entry
states observed in the window (the landing states of its passes; this spares the chain's
own stationary entry distribution, a sparse LU and an eigenvector per fit), against the
residence times observed over the same window, from frames at the lag
(``docs/definitions.md``, Residence time). The score is the Minkowski distance (Eq. 9,
k = 2) between the two RTD histograms, relative to that of the paper's state space,

    score = MD / MD(cells)

and the candidate with the lowest score wins. Its E(RT) and SD(RT) are recorded but do not
judge. This is the Chapman-Kolmogorov idea applied to the quantity the model is for: the
estimator fits one-lag transitions, never the RTD, so how far the chain's many-lag RTD is
from the data's is a test of the memory the state space misses, not a measure of how well
it was fitted (Prinz et al. 2011 run the CK test on the estimation data for the same
reason). With 10^5 to 10^7 transitions per window and at most a few thousand states the
estimation noise is small against the differences between the candidates.

Blocked cross-validation is available as ``criterion="rtd"``: the window cut into
``folds`` (3) blocks of whole lags, each candidate fitted on the other blocks and judged on
the held-out block's RTD by

    score = |mean PD E(RT)| / u_E + |mean PD SD(RT)| / u_SD + mean MD / mean MD(cells)

with the units u the project's goals (2 %, 10 %) or the blocks' own variability where that
is larger. On sliding 5 s windows of the 3, 4, 6 and 8 m/s paper-scale runs
(``docs/method.md``, Choosing the state space and lag) the choice by the whole window's RTD
was the candidate with the lowest MD on the *next* window in 8, 3, 6 and 8 of 8 windows
each, the cross-validation's in 5, 4, 4 and 5, and lost less MD against the best candidate
in total (0.30 against 0.85 over the 32 windows): held-out blocks of 1.7 s see RTDs cut at 1.7 s, and the
bias terms of one block against the others followed the flow's surges more than the
models' errors. Neither is an oracle.

When the window holds fewer than ``MIN_RESIDENCES`` (30) complete residences (at low gas
velocity a residence can outlast the window), the RTD cannot judge, and the candidates are
judged instead by the Chapman-Kolmogorov test on held-out blocks: fitted on the other
blocks, each predicts where the particles of each coarse group (height thirds x core /
annulus) are found after t = 2, 4, ..., 20 base lags, from the occupancy of its states at
the start frames; the score is the mean absolute difference from the fractions observed in
the block, relative to that of the paper's cells.

Nothing outside the fitting window is used, so the choice can be checked on the prediction
window afterwards without fooling oneself. The window's frames are read once, every
candidate is discretised once and counted from memory, and the chosen model is formed from
those counts: the same model as fitting its state space on the window. The model records
every candidate's numbers and why it was chosen (``model.selection``, saved with it).

The steps, one module each: :mod:`.blocks` (the judged blocks of the fitting window and
their observed residence times), :mod:`.criteria` (the three criteria behind one
interface), :mod:`.candidates` (every candidate fitted, judged and scored), :mod:`.record`
(the selection record stored in the model) and :mod:`.choice` (:func:`select_model`, which
runs them, and the models named in a reproduction); :mod:`.pooled` (:func:`select_pooled`)
runs them on several runs of one case, their windows pooled. The record's candidates as the
table ``fit`` and the report print: :mod:`cfbmarkov.markov.selection_table`.
"""

from cfbmarkov.markov.select.choice import (DEFAULT_LAG_MULTIPLES, DEFAULT_STATES, fit_by_name,
                                            parse_model_name, select_model)
from cfbmarkov.markov.select.pooled import select_pooled
from cfbmarkov.markov.select.record import CandidateScore

__all__ = ["DEFAULT_LAG_MULTIPLES", "DEFAULT_STATES", "CandidateScore", "fit_by_name",
           "parse_model_name", "select_model", "select_pooled"]
