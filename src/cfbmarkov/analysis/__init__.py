"""Analysis of trajectory files: residence times (re-exported from
:mod:`cfbmarkov.observed`), radial mixing of the tracer groups, the
comparison metrics of the paper (PD, Minkowski distance, mixing RMS), the comparison of a
model with a reference (:mod:`cfbmarkov.analysis.compare`) and the measures of the
reproduction report (:mod:`cfbmarkov.analysis.reproduction`).

See docs/definitions.md, sections "residence time" and "mixing"."""

from cfbmarkov.observed.metrics import minkowski_distance, mixing_rms, percentage_difference
from cfbmarkov.analysis.mixing import (left_tracer_group, mixing_curve, mixing_curve_of,
                                       model_mixing_curve)
from cfbmarkov.observed.residence import (
    ResidenceTimes,
    residence_times,
    residence_times_from_events,
    residence_times_from_laps,
    rtd_histogram,
)

__all__ = [
    "ResidenceTimes", "left_tracer_group", "minkowski_distance", "mixing_curve",
    "mixing_curve_of", "mixing_rms", "model_mixing_curve", "percentage_difference",
    "residence_times",
    "residence_times_from_events", "residence_times_from_laps", "rtd_histogram",
]
