"""Reading a reproduction run folder: the one place that knows its layout.

A run folder written by :func:`cfbmarkov.reproduce.reproduce` holds::

    DIR/reproduce.json                      {"scale", "cases": [folder, ...], "version", ...}
    DIR/<case>/case.json                    the case's CaseConfig (JSON): U, riser, windows ...
    DIR/<case>/cfd-dem.h5                   reference trajectories
    DIR/<case>/model-<est>.h5               fitted models (paper, mle, then others)
    DIR/<case>/prediction-<est>.h5          Monte Carlo predictions over the predict window
    DIR/<case>/compare-<est>/summary.json   output of cfbmarkov.report.compare.compare
    DIR/<case>/timings.json                 wall times of the stages (keys may be missing)

:func:`read_run_folder` returns its cases, each with its superficial gas velocity U (m/s),
configuration, estimators ("models") and paths. U comes from ``case.json``, never from the
folder name. A case folder made by an older version without ``case.json`` takes its
configuration from the case stored in its ``cfd-dem.h5`` (the ``parameters`` of a CFD-DEM
run); without either, reading fails with one :class:`~cfbmarkov.errors.InputError` line
that asks to rerun ``cfbmarkov reproduce`` on the folder (which resumes and writes
``case.json``).

Choices:

- A case is *finished* when its configuration and cfd-dem.h5 exist and at least one
  estimator has its model, prediction and compare summary. Missing files of a case or an
  estimator are reported as "not finished"; files that exist but cannot be read are an
  InputError naming the file, as is a folder without any finished case.
- Estimators are those with any file in any case (``model-*``, ``prediction-*``, ``compare-*``),
  ordered paper, mle, then the rest alphabetically; an estimator missing from a case makes
  that case's row "not finished".

References
----------
docs/definitions.md, section "file formats".
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from cfbmarkov.analysis.reproduction import reading_errors
from cfbmarkov.errors import InputError

ESTIMATOR_ORDER = ("paper", "mle")
CASE_FILE = "case.json"
MANIFEST = "reproduce.json"
REFERENCE = "cfd-dem.h5"
#: an ensemble's member 0 (``reproduce --ensemble``), the reference where REFERENCE is absent
MEMBER_REFERENCE = "cfd-dem-m0.h5"


def input_error(path: Path, what: str) -> InputError:
    """A one-line InputError naming a file.

    Parameters
    ----------
    path : pathlib.Path
        The file or folder at fault.
    what : str
        What is wrong with it (whitespace runs become single spaces).

    Returns
    -------
    InputError
        ``InputError("PATH: WHAT")``, to be raised by the caller.
    """
    return InputError(f"{path}: {' '.join(str(what).split())}")


def read_json(path: Path) -> Any:
    """The JSON value of a file.

    Parameters
    ----------
    path : pathlib.Path
        A UTF-8 JSON file.

    Returns
    -------
    object
        The decoded value.

    Raises
    ------
    InputError
        One line naming ``path`` when it is missing, unreadable or not JSON.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise input_error(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise input_error(path, f"cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise input_error(path, f"not valid JSON ({exc.msg} at line {exc.lineno})") from None


def _config_error(path: Path, exc) -> InputError:
    first = exc.errors()[0]
    loc = ".".join(str(p) for p in first["loc"]) or "(top level)"
    return input_error(path, f"not a usable case configuration (at '{loc}': {first['msg']})")


def read_config(path: Path):
    """The :class:`~cfbmarkov.config.CaseConfig` of a ``case.json``.

    Parameters
    ----------
    path : pathlib.Path
        The ``case.json`` file.

    Returns
    -------
    CaseConfig
        The validated case.

    Raises
    ------
    InputError
        One line naming ``path`` when it is unreadable or not a valid case.
    """
    from pydantic import ValidationError

    from cfbmarkov.config import CaseConfig

    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise input_error(path, f"cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        return CaseConfig.model_validate_json(text)
    except ValidationError as exc:
        raise _config_error(path, exc) from None


def config_of_reference(path: Path):
    """The case configuration stored in a CFD-DEM trajectory file, or None.

    Parameters
    ----------
    path : pathlib.Path
        A trajectory file (``cfd-dem.h5``).

    Returns
    -------
    CaseConfig or None
        Its ``parameters`` as a case, None when the file is missing or stores no usable
        case (e.g. trajectories from another source).

    Raises
    ------
    InputError
        When the file exists but cannot be read.
    """
    from pydantic import ValidationError

    from cfbmarkov.config import CaseConfig
    from cfbmarkov.trajectories import Trajectories

    if not path.is_file():
        return None
    with reading_errors(path), Trajectories(path) as traj:
        parameters = traj.parameters
    if not isinstance(parameters, dict) or not parameters:
        return None
    try:
        return CaseConfig.model_validate(parameters)
    except ValidationError:
        return None


#: the name ending of a folder a writer had not finished (``compare-mle.tmp-1a2b3c4d``)
_TEMPORARY = re.compile(r"\.(?:tmp|old)-[0-9a-f]{8}$")


def estimator_names(case_dirs: Sequence[Path]) -> list[str]:
    """Estimators with any file in any of the case folders.

    Parameters
    ----------
    case_dirs : sequence of pathlib.Path
        Case folders; those that do not exist are skipped.

    Returns
    -------
    list of str
        Names from ``model-*.h5``, ``prediction-*.h5`` and ``compare-*/``: paper, mle, then
        the rest sorted.
    """
    names: set[str] = set()
    for d in case_dirs:
        if not d.is_dir():
            continue
        for p in d.iterdir():
            match = (re.fullmatch(r"(?:model|prediction)-(.+)\.h5", p.name) if p.is_file()
                     else re.fullmatch(r"compare-(.+)", p.name) if p.is_dir() else None)
            if match and not _TEMPORARY.search(p.name):     # a dead writer's leftover
                names.add(match.group(1))
    return ([n for n in ESTIMATOR_ORDER if n in names]
            + sorted(n for n in names if n not in ESTIMATOR_ORDER))


@dataclass
class EstimatorRun:
    """The files of one estimator ("model") in one case, and its compare summary once read.

    Attributes
    ----------
    name : str
        The estimator.
    model : pathlib.Path
        ``model-<name>.h5``.
    prediction : pathlib.Path
        ``prediction-<name>.h5``.
    summary_path : pathlib.Path
        ``compare-<name>/summary.json``.
    summary : dict or None
        The compare summary once read (None: not finished).
    """

    name: str
    model: Path
    prediction: Path
    summary_path: Path
    summary: dict | None = None

    @property
    def compare_dir(self) -> Path:
        """The folder ``compare-<name>`` of the compare output."""
        return self.summary_path.parent

    @property
    def missing(self) -> str | None:
        """Why this estimator is not finished, or None when it is."""
        case = self.model.parent
        for path, stage in ((self.model, "not fitted"), (self.prediction, "not predicted"),
                            (self.summary_path, "not compared")):
            if not path.is_file():
                return f"{self.name} {stage} (no {path.relative_to(case).as_posix()})"
        return None


@dataclass
class Case:
    """One case folder of a run.

    Attributes
    ----------
    name : str
        The folder name (any name: U is not read from it).
    path : pathlib.Path
        The folder.
    velocity : float
        Superficial gas velocity U, m/s, from the configuration; ``inf`` when unknown (a
        case not started).
    config : CaseConfig or None
        The configuration (case.json, else the one stored in cfd-dem.h5).
    estimators : list of EstimatorRun
        The estimators of the run, in report order.
    timings : dict
        timings.json (stage -> values), empty when absent.
    problems : list of str
        Case-level reasons why it is not finished.
    """

    name: str
    path: Path
    velocity: float = math.inf
    config: Any = None
    estimators: list[EstimatorRun] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    @property
    def reference(self) -> Path:
        """The CFD-DEM trajectory file ``cfd-dem.h5`` of the case (of an ensemble
        (``reproduce --ensemble``), member 0's ``cfd-dem-m0.h5``)."""
        single = self.path / REFERENCE
        member = self.path / MEMBER_REFERENCE
        return member if not single.exists() and member.exists() else single

    @property
    def finished(self) -> list[EstimatorRun]:
        """The estimators whose compare summary has been read."""
        return [e for e in self.estimators if e.summary is not None]

    @property
    def complete(self) -> bool:
        """Whether the case has no case-level problem and at least one finished estimator."""
        return not self.problems and bool(self.finished)

    @property
    def reasons(self) -> list[str]:
        """Why the case or any of its estimators is not finished (empty when all are)."""
        return self.problems + [m for e in self.estimators if (m := e.missing)]

    @property
    def label(self) -> str:
        """"U = ... m/s" for the report, or the folder name when U is unknown."""
        return f"U = {self.velocity:g} m/s" if math.isfinite(self.velocity) else self.name


@dataclass
class RunFolder:
    """A reproduction run folder as read by :func:`read_run_folder`.

    Attributes
    ----------
    root : pathlib.Path
        The run folder.
    manifest : dict
        reproduce.json.
    cases : list of Case
        Sorted by U, then name.
    estimators : list of str
        Estimator names, in report order.
    """

    root: Path
    manifest: dict
    cases: list[Case]
    estimators: list[str]

    @property
    def finished(self) -> list[Case]:
        """The complete cases (:attr:`Case.complete`), sorted by U."""
        return [c for c in self.cases if c.complete]


def _read_case(root: Path, name: str, estimators: Sequence[str]) -> Case:
    path = root / name
    case = Case(name, path)
    if not path.is_dir():
        case.problems.append("not started (no directory)")
        return case
    config_path = path / CASE_FILE
    if config_path.is_file():
        case.config = read_config(config_path)
    else:
        case.config = config_of_reference(case.reference)
        if case.config is None:
            raise input_error(path, f"no {CASE_FILE} and no case stored in {REFERENCE} to read "
                                    f"U from (a run folder of an older version): rerun "
                                    f"'cfbmarkov reproduce -o {root}' with the same options to "
                                    f"resume it; it writes {CASE_FILE}")
    case.velocity = float(case.config.gas.superficial_velocity)
    if not case.reference.is_file():
        case.problems.append(f"no {REFERENCE}")
    for est in estimators:
        e = EstimatorRun(est, path / f"model-{est}.h5", path / f"prediction-{est}.h5",
                         path / f"compare-{est}" / "summary.json")
        if e.missing is None:
            summary = read_json(e.summary_path)
            if not (isinstance(summary, dict) and isinstance(summary.get("reference"), dict)
                    and isinstance(summary.get("model"), dict)):
                raise input_error(e.summary_path, "not a compare summary (no 'reference' and "
                                                  "'model' sections)")
            e.summary = summary
        case.estimators.append(e)
    if not case.estimators:
        case.problems.append("not fitted (no model-*.h5)")
    timings_path = path / "timings.json"
    if timings_path.is_file():
        timings = read_json(timings_path)
        if not isinstance(timings, dict):
            raise input_error(timings_path, "not a JSON object of stage timings")
        case.timings = timings
    return case


def read_run_folder(directory: str | os.PathLike) -> RunFolder:
    """Read a reproduction run folder.

    Parameters
    ----------
    directory : str or os.PathLike
        The folder written by ``cfbmarkov reproduce``.

    Returns
    -------
    RunFolder
        Its manifest, its cases (U, configuration, estimators, paths), sorted by U.

    Raises
    ------
    InputError
        One line naming the file: no folder or reproduce.json, an unusable reproduce.json,
        case.json, summary or timings, a case folder with neither case.json nor a case
        stored in its cfd-dem.h5, or no finished case.
    """
    root = Path(directory)
    if not root.is_dir():
        raise input_error(root, "not a reproduction directory (no such directory)")
    meta_path = root / MANIFEST
    meta = read_json(meta_path)
    if not isinstance(meta, dict):
        raise input_error(meta_path, "not a JSON object")
    names = meta.get("cases")
    if names is None:          # not listed: every folder with a case.json
        names = sorted(p.name for p in root.iterdir() if (p / CASE_FILE).is_file())
    if not (isinstance(names, list) and all(isinstance(n, str) and n and "/" not in n
                                            and n not in (".", "..") for n in names)):
        raise input_error(meta_path, "'cases' is not a list of case folder names")
    names = list(dict.fromkeys(names))
    if not names:
        raise input_error(meta_path, "lists no case")
    estimators = estimator_names([root / n for n in names])
    cases = sorted((_read_case(root, n, estimators) for n in names),
                   key=lambda c: (c.velocity, c.name))
    if not any(c.complete for c in cases):
        detail = "; ".join(f"{c.name}: {', '.join(c.reasons) or 'no estimator'}" for c in cases)
        raise input_error(root, f"no finished case to report ({detail})")
    return RunFolder(root, meta, cases, estimators)


__all__ = ["Case", "EstimatorRun", "RunFolder", "config_of_reference", "estimator_names",
           "input_error", "read_config", "read_json", "read_run_folder"]
