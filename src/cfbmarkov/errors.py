"""Errors that reach the user as one line and exit code 2."""


class CfbmarkovError(Exception):
    """Base class of every error that the command line reports as one line (exit code 2)."""


class InputError(CfbmarkovError, ValueError):
    """Bad input: a file, an option or an argument that cannot be used as given."""



class LagError(InputError):
    """A lag that is not a whole multiple of a trajectory file's frame interval.

    The message advises ``--lag`` (the option of ``fit`` and ``stationarity``);
    :meth:`for_model` is the message where the lag is a fitted model's, which only a refit
    changes.

    Parameters
    ----------
    lag : float
        The lag, s.
    interval, nearest : str
        The file's frame interval and the multiple of it nearest the lag, s, as printed.
    path : str
        The file.
    """

    def __init__(self, lag: float, interval: str, nearest: str, path: str):
        self.lag, self.interval, self.nearest, self.path = lag, interval, nearest, path
        super().__init__(f"lag {lag:g} s is not a whole multiple of the frame interval of "
                         f"{path}: its frames are {interval} s apart: use --lag {interval} or "
                         f"a multiple (lag={interval} from Python; the nearest: {nearest})")

    def for_model(self) -> str:
        """The message where the lag is a fitted model's.

        Returns
        -------
        str
            Advice to refit the model with ``cfbmarkov fit ... --lag`` or to give a file
            whose frames divide the model's lag.
        """
        return (f"the model's lag {self.lag:g} s is not a whole multiple of the frame "
                f"interval of {self.path}: its frames are {self.interval} s apart: refit the "
                f"model with `cfbmarkov fit ... --lag {self.interval}` (or a multiple; the "
                f"nearest: {self.nearest}), or give a file whose frames divide {self.lag:g} s")


class HistoryError(InputError):
    """A window that starts too early for a state space with memory: the frames of history
    before its start are missing.

    The message advises ``--window`` (the option of ``fit``) where a window was given;
    :meth:`advice` words it for a verb with another option, or none.

    Parameters
    ----------
    message : str
        The error, up to the earliest start (without an option).
    earliest : float or None
        The earliest start with the history, s; None where the file has none.
    stop : float or None
        The end of the window given, s; None where no window was given.
    """

    def __init__(self, message: str, earliest: float | None = None,
                 stop: float | None = None):
        self.message, self.earliest, self.stop = message, earliest, stop
        hint = (f" (--window {earliest:g}:{stop:g})" if earliest is not None
                and stop is not None else "")
        super().__init__(message + hint)

    def advice(self, option: str | None) -> str:
        """The message with the option a verb has.

        Parameters
        ----------
        option : {"--window", "--start"} or None
            The verb's option that sets the window's start; None: no option named.

        Returns
        -------
        str
        """
        if self.earliest is None:
            return self.message
        if option == "--window":
            return str(self)
        if option == "--start":
            return f"{self.message} (--start {self.earliest:g})"
        return self.message

class CfbmarkovWarning(UserWarning):
    """Base class of cfbmarkov's warnings: advice that does not stop the work.

    From Python they are ordinary warnings (``warnings.catch_warnings``, ``pytest.warns``,
    ``-W error::cfbmarkov.errors.CfbmarkovWarning``); the command line and the worker
    processes of ``cfbmarkov reproduce`` print each as one line on stderr, ``note: MESSAGE``,
    without the Python source line (:func:`cfbmarkov._console.one_line_notes`); a
    category whose ``prefix`` is ``"warning: "`` (a figure that may be far off) as
    ``warning: MESSAGE``, as the verbs print the same lines.
    """

    #: how the command line starts the warning's line
    prefix = "note: "


class TimeStepAdvisory(CfbmarkovWarning):
    """The DEM time step resolves a contact in fewer than the recommended 10 steps (but in
    5 or more, below which the run is refused)."""


class UnresolvedWarning(CfbmarkovWarning):
    """A model's exact RTD leaves more than 1 % of its residences unresolved (they never
    reach the boundary in the chain, fall deeper than the lap deficits followed, or outlast
    the lags computed): its E(RT) and SD(RT) describe the others
    (:meth:`cfbmarkov.markov.MarkovModel.rtd`; the command line prints the same line as a
    ``warning:``)."""

    prefix = "warning: "


class IntervalWarning(CfbmarkovWarning):
    """No interval could be formed for a model's E(RT) and SD(RT) (the message says why);
    the model is returned without one
    (:func:`cfbmarkov.analysis.fit_checks.assess_fit`)."""

    prefix = "warning: "


class SampleWarning(CfbmarkovWarning):
    """A model used for a prediction carries a warning of its fitting sample's verdict
    (:attr:`cfbmarkov.markov.MarkovModel.adequacy`): the message repeats it, as the command
    line's ``warning: the model's fitting sample: ...`` line does."""

    prefix = "warning: "
