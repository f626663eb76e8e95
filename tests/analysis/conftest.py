"""Fixtures of the analysis tests: the generated riser runs of the observed-quantity tests
(:mod:`tests.observed.conftest`), shared."""

from ..observed.conftest import events_of, make_run, pair, write_run  # noqa: F401
