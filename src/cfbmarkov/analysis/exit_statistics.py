"""The statistics of a property's values at the exit, shared by the reference side
(:mod:`cfbmarkov.analysis.kinetics_reference`) and the segregated-flow baseline
(:mod:`cfbmarkov.analysis.segregated_flow`)."""

from __future__ import annotations

import numpy as np


class ExitStatistics:
    """Mean, SD and standard error of ``exit_values`` (an attribute of the class that mixes
    this in: ndarray of float64, shape (E,), one value per exit or residence-time sample)."""

    exit_values: np.ndarray

    @property
    def count(self) -> int:
        """Number of values at exit."""
        return int(self.exit_values.size)

    @property
    def exit_mean(self) -> float:
        """The mean value at exit (NaN without values)."""
        return float(self.exit_values.mean()) if self.count else float("nan")

    @property
    def exit_sd(self) -> float:
        """The SD of the values at exit, ddof = 1 (NaN with fewer than two)."""
        return float(self.exit_values.std(ddof=1)) if self.count > 1 else float("nan")

    @property
    def exit_se(self) -> float:
        """Standard error of :attr:`exit_mean` (the values taken as independent)."""
        return self.exit_sd / np.sqrt(self.count) if self.count > 1 else float("nan")
