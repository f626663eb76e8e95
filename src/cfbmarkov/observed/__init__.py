"""Quantities observed directly in trajectory files, below any model: residence times from
lap counters or pass events, the comparison metrics (percentage difference, Minkowski
distance, mixing RMS) and the cluster index of particle snapshots.

Both the Markov layer (:mod:`cfbmarkov.markov`, e.g. the automatic choice of a state space
by the fitting window's own RTD) and the analysis layer (:mod:`cfbmarkov.analysis`) use
them; nothing here imports either (see ``docs/definitions.md``, Residence time, Metrics,
Cluster index).
"""

from cfbmarkov.observed.metrics import minkowski_distance, mixing_rms, percentage_difference
from cfbmarkov.observed.residence import (
    ResidenceTimes,
    flux_residence_time,
    residence_times,
    residence_times_from_events,
    residence_times_from_laps,
    rtd_histogram,
)

__all__ = [
    "ResidenceTimes", "flux_residence_time", "minkowski_distance", "mixing_rms", "percentage_difference",
    "residence_times", "residence_times_from_events", "residence_times_from_laps",
    "rtd_histogram",
]
