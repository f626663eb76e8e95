"""Errors that reach the user as one line and exit code 2."""


class CfbmarkovError(Exception):
    """Base class of every error that the command line reports as one line (exit code 2)."""


class InputError(CfbmarkovError, ValueError):
    """Bad input: a file, an option or an argument that cannot be used as given."""


class CfbmarkovWarning(UserWarning):
    """Base class of cfbmarkov's warnings: advice that does not stop the work.

    From Python they are ordinary warnings (``warnings.catch_warnings``, ``pytest.warns``,
    ``-W error::cfbmarkov.errors.CfbmarkovWarning``); the command line and the worker
    processes of ``cfbmarkov reproduce`` print each as one line on stderr, ``note: MESSAGE``,
    without the Python source line (:func:`cfbmarkov._console.one_line_notes`).
    """


class TimeStepAdvisory(CfbmarkovWarning):
    """The DEM time step resolves a contact in fewer than the recommended 10 steps (but in
    5 or more, below which the run is refused)."""
