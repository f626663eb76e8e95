"""Read-only containers for what an immutable object holds: a record (``dict`` and
``list`` as JSON gives them) that compares, prints and serialises as a dict and a list but
refuses changes, and the read-only flag put back on numpy arrays that pickling and copying
make writable again."""

from __future__ import annotations

from typing import Any

import numpy as np


def _refuse(self, *args, **kwargs):
    what = "record" if isinstance(self, dict) else "list"
    raise TypeError(f"this {what} belongs to an immutable object and cannot be changed; "
                    "change a copy (copy.deepcopy, or dict(...) / list(...))")


class ReadOnlyDict(dict):
    """A dict that refuses changes (a JSON record held by an immutable object)."""

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = _refuse
    __ior__ = _refuse

    def __reduce__(self):                  # pickle and copy without __setitem__
        return (type(self), (dict(self),))


class ReadOnlyList(list):
    """A list that refuses changes (a JSON array held by an immutable object)."""

    __setitem__ = __delitem__ = append = extend = insert = pop = remove = clear = _refuse
    sort = reverse = __iadd__ = __imul__ = _refuse

    def __reduce__(self):
        return (type(self), (list(self),))


def frozen_record(value: Any) -> Any:
    """``value`` with every dict and list in it (at any depth) made read-only
    (:class:`ReadOnlyDict`, :class:`ReadOnlyList`); other values as they are."""
    if isinstance(value, dict):
        return ReadOnlyDict({k: frozen_record(v) for k, v in value.items()})
    if isinstance(value, list):
        return ReadOnlyList(frozen_record(v) for v in value)
    if isinstance(value, tuple):
        return tuple(frozen_record(v) for v in value)
    return value


def thawed_record(value: Any) -> Any:
    """A plain copy of a (frozen) record: dicts and lists the caller may change."""
    if isinstance(value, dict):
        return {k: thawed_record(v) for k, v in value.items()}
    if isinstance(value, list):
        return [thawed_record(v) for v in value]
    if isinstance(value, tuple):
        return tuple(thawed_record(v) for v in value)
    return value


def read_only_copy(value, dtype=None):
    """A read-only copy of an array (a view of a read-only base, which cannot be made
    writeable again): what an immutable object keeps of an array it is given, so that the
    caller's later writes to theirs change nothing.

    Parameters
    ----------
    value : array_like
    dtype : numpy dtype, optional
        Converted to it (numpy's rules: ``ValueError`` or ``TypeError`` where it cannot).

    Returns
    -------
    numpy.ndarray
    """
    import numpy as np

    owned = np.array(value, dtype=dtype)
    owned.setflags(write=False)
    view = owned.view()
    view.setflags(write=False)
    return view


def freeze_arrays(value: Any, seen: set | None = None) -> None:
    """Set every numpy array reachable from ``value`` (through objects' attributes,
    tuples, lists and dicts) read-only: what an unpickled or deep-copied immutable object
    holds (pickle does not keep the flag)."""
    seen = set() if seen is None else seen
    if id(value) in seen:
        return
    seen.add(id(value))
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif isinstance(value, dict):
        for v in value.values():
            freeze_arrays(v, seen)
    elif isinstance(value, (list, tuple, set, frozenset)):
        for v in value:
            freeze_arrays(v, seen)
    elif hasattr(value, "__dict__") and not isinstance(value, type):
        for v in vars(value).values():
            freeze_arrays(v, seen)


__all__ = ["ReadOnlyDict", "ReadOnlyList", "freeze_arrays", "frozen_record", "read_only_copy",
           "thawed_record"]
