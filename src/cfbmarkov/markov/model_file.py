"""The model file: a fitted :class:`~cfbmarkov.markov.model.MarkovModel` as HDF5.

Any HDF5 reader can use the file (``docs/definitions.md``, Model files). S is the number of
states:

- datasets ``transition_matrix`` [S, S] float64; ``counts``, ``counts_up``, ``counts_down``
  [S, S] int64; ``pass_up_fraction``, ``pass_down_fraction`` [S, S] float64;
  ``unvisited_states`` [U] int64;
- attributes ``format = "cfbmarkov.model"``, ``version``, ``state_space`` (JSON), ``columns``,
  ``rows``, ``lag`` (s), ``window`` (s, NaN for none), ``estimator``, ``source`` (JSON),
  ``frame_pairs``, ``n_transitions``, ``n_unvisited_states``, ``created``,
  ``cfbmarkov_version``; for a model fitted on several runs, ``run_windows`` (JSON, the
  window of each run of ``source``); ``flow_direction`` ("up" or "down", the direction
  residences are counted in; a file without it reads as "up"); for a model chosen by
  ``--states auto``,
  ``selection`` (JSON); for a model fitted on the largest strongly connected set, ``connected = 1``; where the
  fitting sample was judged, ``adequacy`` (JSON, :class:`~cfbmarkov.markov.adequacy.Adequacy`;
  optional, files without it read as models without a verdict);
- optionally the group ``uncertainty`` (the intervals of the exact E(RT), SD(RT) and RTD
  per bin, :class:`~cfbmarkov.markov.uncertainty.ModelUncertainty`): datasets ``level``,
  ``rt_mean_interval`` [2], ``rt_sd_interval`` [2] (s), ``rtd_edges`` [B + 1] (s),
  ``rtd_interval`` [2, B], ``resamples``, ``blocks``, ``block_length`` (s), ``flow_sd`` [2]
  (NaN where not measured), optionally ``requested``, ``flow_degrees_of_freedom`` (the
  flow term's, for Student's t; a file without it: the normal quantile) and
  ``bootstrap_widening`` (the factor the bootstrap part was widened by for its blocks; a
  file without it holds an interval formed without, which its warnings name). A file
  without the group loads as a model without intervals;
- optionally the fitting window's time-averaged cell fields
  (:class:`~cfbmarkov.kinetics.CellFields`, for kinetics whose rates depend on them):
  datasets ``cell_solids_fraction``, ``cell_wall_distance`` (m) and
  ``cell_vertical_velocity`` (m/s, NaN in a cell never visited), [C] float64 each (C cells
  of the grid), and the attribute ``cell_fields_relative`` (1: the solids fraction is a
  count relative to the bed's mean). A file without them loads as a model without fields.

The [S, S] datasets are stored chunked (blocks of whole rows, about 1 MiB) and compressed
with gzip (deflate, level 1; :func:`~cfbmarkov._hdf5.create_array_dataset`): the
matrices are sparse, so a 1596-state model takes under 1 MB instead of 122 MB, and it loads
in about a tenth of a second. Deflate is built into every HDF5 library, so any HDF5 reader
(h5py, h5dump, MATLAB, ...) still reads them as plain dense arrays; the layout and its
``version`` are unchanged, and files written before compression read the same.

A prediction carries the same group, stored the same way, as ``/provenance/model``. The model
class itself never opens a file; this module does it for it, and builds the model it reads
with the class it is given (:meth:`MarkovModel.load
<cfbmarkov.markov.model.MarkovModel.load>` passes its own).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import h5py
import numpy as np

from cfbmarkov._atomic import atomic_path, h5_file
from cfbmarkov._json import jsonable
from cfbmarkov._hdf5 import create_array_dataset, open_h5
from cfbmarkov.boundary import BOUNDARIES, Boundary
from cfbmarkov.errors import InputError
from cfbmarkov.kinetics.fields import FIELDS as CELL_FIELDS
from cfbmarkov.kinetics.fields import CellFields
from cfbmarkov.markov.adequacy import Adequacy
from cfbmarkov.markov.model_arrays import SQUARE_ARRAYS
from cfbmarkov.markov.open_flow import OpenFlow
from cfbmarkov.markov.spaces import state_space_from_attrs
from cfbmarkov.markov.uncertainty import ModelUncertainty

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel

#: the ``format`` attribute of a model file
#: the model cache's key of the ``created`` time read from a model file
CREATED = "created"
MODEL_FORMAT = "cfbmarkov.model"


def model_datasets_and_attrs(model: "MarkovModel") -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The datasets and attributes that store ``model`` (the layout in the module docstring).

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    datasets : dict of str to ndarray
    attrs : dict of str to value
    """
    datasets = {name: getattr(model, name) for name in SQUARE_ARRAYS}
    datasets["unvisited_states"] = model.unvisited_states
    datasets["pass_up_fraction"] = model.up_fraction
    datasets["pass_down_fraction"] = model.down_fraction
    attrs = {
        "format": MODEL_FORMAT, "version": 1,
        "state_space": json.dumps(model.state_space.to_attrs()),
        "columns": model.state_space.columns, "rows": model.state_space.rows,
        "lag": model.lag, "estimator": model.estimator,
        "window": np.asarray(model.window if model.window else [np.nan, np.nan], dtype=float),
        "source": json.dumps(model.source), "frame_pairs": int(model.frame_pairs),
        "n_transitions": model.n_transitions,
        "n_unvisited_states": int(model.unvisited_states.size),
        # when the model was first written: a copy (a prediction's provenance) keeps it
        "created": model._cache.get(CREATED)
        or _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "cfbmarkov_version": _version(),
        "flow_direction": model.flow_direction,
    }
    if model.run_windows is not None:
        attrs["run_windows"] = json.dumps([list(w) for w in model.run_windows])
    if model.source_identity:
        attrs["source_identity"] = str(model.source_identity)
    if model.selection:
        # strict JSON (undefined figures as null, not NaN): jq and JSON.parse read it
        attrs["selection"] = json.dumps(jsonable(model.selection), allow_nan=False)
    if model.connected:
        attrs["connected"] = 1
    if model.coherence:
        attrs["coherence"] = float(model.coherence)
    if model.adequacy is not None:
        attrs["adequacy"] = model.adequacy.to_attr()
    if model.uncertainty is not None:
        datasets.update(model.uncertainty.file_fields())
    if model.cell_fields is not None:
        for name in CELL_FIELDS:
            datasets[f"cell_{name}"] = model.cell_fields.field(name)
        attrs["cell_fields_relative"] = int(model.cell_fields.relative)
    if model.open_flow is not None:
        open_datasets, open_attrs = model.open_flow.file_fields()
        attrs.update(open_attrs)
        datasets.update(open_datasets)
    return datasets, attrs


def write_model(model: "MarkovModel", path: str | os.PathLike) -> Path:
    """Write ``model`` as an HDF5 file, atomically (no partial file on failure).

    Parameters
    ----------
    model : MarkovModel
    path : str or os.PathLike
        The model file; its folder is created if needed.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    InputError
        If the file cannot be put in place.
    """
    datasets, attrs = model_datasets_and_attrs(model)
    with atomic_path(path) as tmp:
        with h5_file(tmp, path) as f:
            for name, value in datasets.items():
                create_array_dataset(f, name, value)
            f.attrs.update(attrs)
    return Path(path)


def read_model_group(group: h5py.Group | h5py.File, model_class: Callable[..., "MarkovModel"],
                     label: str = "") -> "MarkovModel":
    """Rebuild a model from an HDF5 group written by :func:`write_model`.

    Parameters
    ----------
    group : h5py.Group or h5py.File
        The model file, or the group attached to a prediction as ``/provenance/model``.
    model_class : callable
        Makes the model from its fields as keywords
        (:class:`~cfbmarkov.markov.model.MarkovModel`).
    label : str, optional
        Names the source in error messages (default: the file's name).

    Returns
    -------
    MarkovModel

    Raises
    ------
    InputError
        If the group is not a cfbmarkov model, misses a dataset or attribute, or holds an
        invalid model.
    """
    label = label or getattr(group.file, "filename", "")
    fmt = group.attrs.get("format")
    if isinstance(fmt, bytes):
        fmt = fmt.decode(errors="replace")
    if fmt == "cfbmarkov.trajectories":
        if "provenance/model" in group:      # a prediction: it carries the model it ran
            raise InputError(f"{label} is a prediction (a trajectory file), not a cfbmarkov "
                             "model file: give the model file it was predicted with (in "
                             "Python, MarkovModel.from_trajectories(Trajectories(path)) is "
                             "the model it carries)")
        raise InputError(f"{label} is a trajectory file, not a cfbmarkov model file: fit a "
                         f"model on it first (cfbmarkov fit {label} -o model.h5) and give "
                         "that model")
    if fmt != MODEL_FORMAT:
        raise InputError(f"{label}: not a cfbmarkov model file ("
                         + ("an HDF5 file without cfbmarkov's 'format' attribute" if fmt is None
                            else f"its format attribute is {fmt!r}")
                         + "): give a model that cfbmarkov fit wrote (cfbmarkov fit RUN -o "
                           "model.h5)")
    try:
        version = _attr_number(group.attrs.get("version", 1), "version")
    except InputError as exc:
        raise InputError(f"{label}: damaged model file ({exc})") from None
    if np.isfinite(version) and version == round(version) and version > 1:
        raise InputError(f"{label}: model file layout version {version:g}, written by a newer "
                         "cfbmarkov (this one reads version 1); upgrade cfbmarkov")
    if version != 1:
        raise InputError(f"{label}: damaged model file (layout version {version:g}: this "
                         "cfbmarkov writes and reads version 1)")
    try:
        model = _read_model_group(group, model_class)
        created = group.attrs.get("created")
        if created is not None:     # kept, so that a copy (a prediction's) keeps the fit's
            model._cache[CREATED] = created.decode() if isinstance(created, bytes) \
                else str(created)
        return model
    except KeyError as exc:
        raise InputError(f"{label}: damaged model file (missing {_missing(exc)})") from None
    except InputError as exc:
        raise InputError(f"{label}: damaged model file ({exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{label}: damaged model file (an attribute that should be JSON is "
                         f"not: {exc.msg})") from None
    except (ValueError, TypeError, OSError, AttributeError) as exc:
        raise InputError(f"{label}: damaged model file ({type(exc).__name__}: {exc})") from None


def _read_model_group(group, model_class) -> "MarkovModel":
    """The model of a group whose format has been checked (errors raised as they come)."""
    window = np.asarray(group.attrs["window"], dtype=float)
    if window.shape != (2,):
        raise InputError(f"window attribute of shape {window.shape}, not 2 times")
    frame_pairs = _attr_number(group.attrs.get("frame_pairs", 0), "frame_pairs")
    if not (np.isfinite(frame_pairs) and frame_pairs >= 0 and frame_pairs == round(frame_pairs)):
        raise InputError(f"frame_pairs {frame_pairs:g} is not a count")
    model = model_class(
        **{name: group[name][()] for name in SQUARE_ARRAYS},
        state_space=state_space_from_attrs(group.attrs["state_space"]),
        lag=_attr_number(group.attrs["lag"], "lag"), estimator=str(group.attrs["estimator"]),
        window=None if np.isnan(window).any() else (float(window[0]), float(window[1])),
        source=json.loads(group.attrs.get("source", '""')),
        frame_pairs=int(frame_pairs),
        pass_fractions=(group["pass_up_fraction"][()], group["pass_down_fraction"][()])
        if "pass_up_fraction" in group else None,
        selection=_selection(json.loads(group.attrs["selection"]))
        if "selection" in group.attrs else None,
        connected=bool(group.attrs.get("connected", 0)),
        coherence=_attr_number(group.attrs.get("coherence", 0.0), "coherence"),
        open_flow=_open_flow(group), uncertainty=ModelUncertainty.from_group(group),
        adequacy=Adequacy.from_attr(group.attrs["adequacy"])
        if "adequacy" in group.attrs else None,
        source_identity=_text_attr(group.attrs["source_identity"])
        if "source_identity" in group.attrs else None,
        cell_fields=_cell_fields(group),
        run_windows=json.loads(_text_attr(group.attrs["run_windows"]))
        if "run_windows" in group.attrs else None,
        flow_direction=_text_attr(group.attrs.get("flow_direction", "up")))
    _check_cell_fields(model)
    return model


def _check_cell_fields(model) -> None:
    """Refuse cell fields a fit cannot have written: a solids fraction or wall distance that
    is not finite, or a vertical velocity NaN (the mark of a cell never visited) in a cell
    whose states have transitions; a kinetics law on the field would take such a cell for
    another (a NaN compares false with every threshold)."""
    fields = model.cell_fields
    if fields is None:
        return
    space = model.state_space
    visited = np.zeros(space.n_cells, dtype=bool)
    moved = np.asarray(model.counts).sum(axis=1) > 0
    visited[np.asarray(space.cell_of_state)[moved]] = True
    for name, values, where in (
            ("solids_fraction", fields.solids_fraction, np.ones_like(visited)),
            ("wall_distance", fields.wall_distance, np.ones_like(visited)),
            ("vertical_velocity", fields.vertical_velocity, visited)):
        values = np.asarray(values, dtype=np.float64)
        if values.shape != (space.n_cells,):
            raise InputError(f"cell_{name} holds {values.size} values for the grid's "
                             f"{space.n_cells} cells")
        bad = where & ~np.isfinite(values)
        if bad.any():
            left = ", which the fit saw particles leave" if name == "vertical_velocity" else ""
            raise InputError(f"cell_{name} is not a number in cell "
                             f"{int(np.flatnonzero(bad)[0])}{left} (NaN marks only a cell "
                             "never visited)")


def _cell_fields(group) -> CellFields | None:
    """The fitting window's cell fields stored in a model group, or None."""
    names = [f"cell_{name}" for name in CELL_FIELDS]
    if not all(name in group for name in names):
        return None
    return CellFields(*(np.asarray(group[name][()], dtype=np.float64) for name in names),
                      relative=bool(group.attrs.get("cell_fields_relative", 0)))


def _text_attr(value) -> str:
    """A text attribute as str (h5py may give bytes)."""
    return value.decode() if isinstance(value, bytes) else str(value)


def _missing(exc: KeyError) -> str:
    """What a KeyError from h5py says is missing, in words (the attribute or dataset by
    name), or its text."""
    import re

    text = str(exc.args[0]) if exc.args else str(exc)
    found = re.search(r"can't locate attribute: '([^']+)'", text)
    if found:
        return f"the attribute {found.group(1)!r}"
    found = re.search(r"object '([^']+)' doesn't exist", text)
    if found:
        return f"the dataset {found.group(1)!r}"
    return text


def _attr_number(value, name: str) -> float:
    """A numeric attribute as a float; refused where it is not one number."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} attribute {value!r} is not a number") from None
    if array.size != 1:
        raise InputError(f"{name} attribute holds {array.size} values, not one number")
    return float(array.reshape(()))


def _selection(record):
    """The ``selection`` attribute, a record of the automatic choice: a dict, its
    ``candidates`` a list of dicts (a damaged file's other JSON is refused here, not met
    by a traceback where the record is read)."""
    candidates = record.get("candidates", []) if isinstance(record, dict) else None
    if not (isinstance(candidates, list) and all(isinstance(c, dict) for c in candidates)):
        raise InputError("selection is not a record of the automatic choice (a JSON object "
                         "with a list of candidates)")
    return record


def _open_flow(group) -> OpenFlow | None:
    """An open riser's flow from a model group (None for a periodic riser's)."""
    boundary = group.attrs.get("boundary", Boundary.PERIODIC.value)
    boundary = boundary.decode() if isinstance(boundary, bytes) else str(boundary)
    if boundary not in BOUNDARIES:
        raise InputError(f"model boundary {boundary!r}: periodic or open")
    return OpenFlow.from_group(group) if Boundary(boundary).is_open else None


def read_model(path: str | os.PathLike, model_class: Callable[..., "MarkovModel"]
               ) -> "MarkovModel":
    """Read a model file written by :func:`write_model`.

    Parameters
    ----------
    path : str or os.PathLike
    model_class : callable
        Makes the model from its fields as keywords
        (:class:`~cfbmarkov.markov.model.MarkovModel`).

    Returns
    -------
    MarkovModel

    Raises
    ------
    InputError
        If the file is missing, empty, not HDF5, not a model file, or damaged.
    """
    with open_h5(path) as f:
        model = read_model_group(f, model_class, str(path))
    # where it was read from: a fitting file named relative to the folder the model was
    # fitted (and usually saved) in is looked for beside it too
    # (cfbmarkov.analysis.intervals.resolve_source)
    model._cache["file"] = os.path.abspath(path)
    return model


def _version() -> str:
    from cfbmarkov import __version__

    return __version__
