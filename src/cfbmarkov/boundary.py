"""The riser's vertical boundary, one type for every layer (``docs/definitions.md``, Open
risers).

A trajectory file, an importer's option and a fitted model name their boundary by a
:class:`Boundary`; code asks it (:attr:`Boundary.is_open`) instead of comparing strings. The
value is what files store (the ``boundary`` attribute of trajectory and model files).
"""

from __future__ import annotations

import enum

from cfbmarkov.errors import InputError


class Boundary(enum.StrEnum):
    """The vertical boundary of a riser.

    ``PERIODIC`` (the paper's riser): what leaves through the top re-enters at the bottom,
    each particle carrying a lap counter. ``OPEN``: particles enter through the inlet and
    leave through the outlet for good; the Markov chain is absorbing.

    A :class:`Boundary` is a ``str`` (its value), so it compares equal to ``"periodic"`` /
    ``"open"`` and is written to files as that text.
    """

    PERIODIC = "periodic"
    OPEN = "open"

    @property
    def is_open(self) -> bool:
        """True for an open riser (absorbing chain, inlet and outlet)."""
        return self is Boundary.OPEN

    @classmethod
    def parse(cls, value, what: str = "boundary") -> "Boundary":
        """The boundary named by ``value`` (a :class:`Boundary`, ``str`` or ``bytes``).

        Parameters
        ----------
        value : Boundary, str or bytes
            ``"periodic"`` or ``"open"``.
        what : str, optional
            What the value is, for the error message (e.g. a file's name).

        Returns
        -------
        Boundary

        Raises
        ------
        InputError
            If ``value`` names no boundary.
        """
        if isinstance(value, bytes):
            value = value.decode(errors="replace")
        try:
            return cls(str(value))
        except ValueError:
            raise InputError(f"{what} {value!r}: choose periodic or open") from None


#: the boundaries' names, as files store them
BOUNDARIES = tuple(b.value for b in Boundary)
