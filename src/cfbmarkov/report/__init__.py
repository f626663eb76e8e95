"""Reports: the ``compare`` verb (summary.json and the paper's figures) and the figure
functions (:mod:`cfbmarkov.report.figures`, imported on demand: it loads matplotlib)."""

from cfbmarkov.report.compare import compare

__all__ = ["compare"]
