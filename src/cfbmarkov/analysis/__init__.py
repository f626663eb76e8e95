"""Analysis of trajectory files: residence times (SPEC section 3), radial mixing (section 4)
and the comparison metrics of the paper (PD, Minkowski distance, mixing RMS)."""

from cfbmarkov.analysis.metrics import minkowski_distance, mixing_rms, percentage_difference
from cfbmarkov.analysis.mixing import mixing_curve, mixing_curve_of, purple_mask
from cfbmarkov.analysis.rtd import (
    ResidenceTimes,
    residence_times,
    residence_times_from_events,
    residence_times_from_laps,
    rtd_histogram,
)

__all__ = [
    "ResidenceTimes", "minkowski_distance", "mixing_curve", "mixing_curve_of", "mixing_rms",
    "percentage_difference", "purple_mask", "residence_times", "residence_times_from_events",
    "residence_times_from_laps", "rtd_histogram",
]
