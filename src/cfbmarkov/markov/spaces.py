"""State spaces by name and from a saved description: the one lookup of a ``kind``.

Every :class:`~cfbmarkov.markov.states.StateSpace` subclass that sets ``kind`` registers
itself when its module is imported (:meth:`StateSpace.registered_kinds
<cfbmarkov.markov.states.StateSpace.registered_kinds>`). This module imports all of them,
so that :func:`state_space_from_name` (``--states``) and :func:`state_space_from_attrs` (a
model file's ``state_space`` attribute) know every kind.
"""

from __future__ import annotations

import json
from typing import Any

# the modules of the state spaces besides the grid: imported for their spaces' registration
import cfbmarkov.markov.memory_states  # noqa: F401
import cfbmarkov.markov.regimes  # noqa: F401
import cfbmarkov.markov.velocity_states  # noqa: F401
from cfbmarkov.errors import InputError
from cfbmarkov.markov.states import StateSpace

#: names accepted by :func:`state_space_from_name`
STATE_SPACES = ("cells", "cells-direction", "cells-velocity", "cells-velocity-fine",
                "cells-previous", "cells-regime", "cells-direction-regime")


def state_space_from_name(name: str, columns: int, rows: int, width: float | None = None,
                          height: float | None = None, depth_columns: int | None = None,
                          depth: float | None = None) -> StateSpace:
    """A state space by name with its defaults.

    Parameters
    ----------
    name : {"cells", "cells-direction", "cells-velocity", "cells-velocity-fine", \
            "cells-previous", "cells-regime", "cells-direction-regime"}
        ``cells`` (the paper's), ``cells-direction`` (direction from the displacement),
        ``cells-velocity`` (8 v_y bins from the displacement over the model's lag, edges at
        the quantiles of the fitting window's velocities), ``cells-velocity-fine`` (and each
        row split into sub-rows no taller than the median move in a lag, fitted on the
        fitting window),
        ``cells-previous`` (the second-order chain: previous cell within 3 rows),
        ``cells-regime`` (cells x 2 regimes of the solids flux, edges fitted on the fitting
        window), ``cells-direction-regime`` (and the direction).
    columns, rows : int
        The cell grid m x n.
    width, height : float, optional
        The riser W x H (m); None: the size of the file the space is used on.
    depth_columns : int, optional
        Cells along the depth, d: a 3D grid (needs ``depth``; only ``cells`` has depth
        columns yet). None: a 2D grid, which projects 3D positions.
    depth : float, optional
        The riser's depth (m), for a 3D grid.

    Returns
    -------
    StateSpace

    Raises
    ------
    InputError
        For an unknown name, a bad grid, depth columns without a depth, or depth columns
        for a state space with memory.

    Notes
    -----
    See ``docs/definitions.md`` (States and transitions).
    """
    if name not in STATE_SPACES:
        raise InputError(f"unknown state space '{name}' (choose from {', '.join(STATE_SPACES)})")
    space = StateSpace.registered_kinds()[name]
    if depth_columns is None:
        return space.with_defaults(columns, rows, width, height)
    if not space.has_depth_columns:
        raise InputError(f"state space {name} has no depth columns yet: use --states cells "
                         "with COLUMNSxDEPTHxROWS, or COLUMNSxROWS (the projection)")
    if depth is None:
        raise InputError(f"{depth_columns} depth column(s) need 3D data (the riser's depth): "
                         "give a 3D file, or cells as COLUMNSxROWS")
    return space(columns, rows, width, height, depth_columns=depth_columns, depth=depth)


def state_space_from_attrs(attrs: dict[str, Any] | str) -> StateSpace:
    """Rebuild a state space from its :meth:`~cfbmarkov.markov.states.StateSpace.to_attrs`
    (as a dict or as JSON text).

    Parameters
    ----------
    attrs : dict or str
        The description, e.g. a model file's ``state_space`` attribute.

    Returns
    -------
    StateSpace

    Raises
    ------
    InputError
        If the kind is unknown, or the arguments make no valid state space (e.g. a bad
        grid).
    """
    if isinstance(attrs, (str, bytes)):
        attrs = json.loads(attrs)
    attrs = dict(attrs)
    kind = attrs.pop("kind", None)
    kinds = StateSpace.registered_kinds()
    if kind not in kinds:
        raise InputError(f"unknown state space kind {kind!r}")
    return kinds[kind](**attrs)


__all__ = ["STATE_SPACES", "state_space_from_attrs", "state_space_from_name"]
