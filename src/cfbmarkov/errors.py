"""Errors that reach the user as one line and exit code 2."""


class CfbmarkovError(Exception):
    """Base class of every error that the command line reports as one line (exit code 2)."""


class InputError(CfbmarkovError, ValueError):
    """Bad input: a file, an option or an argument that cannot be used as given."""
