"""The reproduction report: the paper's §3 (Table 3, computing time, Fig. 3-11) from a
reproduction directory.

:func:`write_report` reads a directory written by the reproduction pipeline::

    DIR/reproduce.json                      {"scale", "cases": ["u3", ...], "version"}
    DIR/<case>/case.json                    CaseConfig JSON
    DIR/<case>/cfd-dem.h5                   reference trajectories
    DIR/<case>/model-<est>.h5               fitted models (paper, mle, then others)
    DIR/<case>/prediction-<est>.h5          Monte Carlo predictions over the predict window
    DIR/<case>/compare-<est>/summary.json   output of cfbmarkov.report.compare.compare
    DIR/<case>/timings.json                 wall times of the stages (keys may be missing)

and writes ``DIR/report.html`` (self-contained: PNGs embedded as base64 ``data:`` URIs,
inline CSS), ``DIR/report.md`` (the same content, images linked as ``figures/NAME.png``)
and the PNGs in ``DIR/figures/``, each atomically; report.html is written last.

Choices (where the brief leaves room):

- A case is *finished* when its case.json and cfd-dem.h5 exist and at least one estimator
  has its model, prediction and compare summary. Missing files of a case or an estimator are
  reported as "not finished"; files that exist but cannot be read are an
  :class:`~cfbmarkov.errors.InputError` naming the file, as is a directory without any
  finished case.
- Estimators are those with any file in any case (``model-*``, ``prediction-*``, ``compare-*``), ordered
  paper, mle, then the rest alphabetically; an estimator missing from a case makes that
  case's row "not finished".
- Figures 4-7 are numbered by the position of the case among all cases sorted by U (4, 5,
  6, 7) when there are at most four cases; with more cases a case at one of the paper's U
  (3, 4, 6, 8 m/s) takes the paper's number and any other case the number of the paper's
  nearest U (the file name always carries the case name).
- Fig. 3 and Fig. 4-7 use the ``paper`` estimator's model (else the first finished one, and
  the caption says so). Batch-injection times that are not whole multiples of the model's
  lag are rounded to the nearest whole lag (at least one) and the caption says so.
- RTDs (Fig. 8-9), mixing curves (Fig. 11) and the solids profile are recomputed from the
  trajectory files over the case's predict window, with the bin width of the compare
  summaries; Table 3 quotes the summaries.
"""

from __future__ import annotations

import base64
import contextlib
import html
import json
import math
import os
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from cfbmarkov._atomic import atomic_path
from cfbmarkov.errors import InputError

REPORT_HTML = "report.html"
REPORT_MD = "report.md"
FIGURES = "figures"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

#: the paper's Table 3 as printed: U (m/s) -> (PD of E(RT) %, PD of SD(RT) %, MD of RTD)
PAPER_TABLE3: dict[float, tuple[str, str, str]] = {
    3.0: ("11.89", "-50.55", "0.0185"),
    4.0: ("1.57", "-37.84", "0.238"),
    6.0: ("2.45", "-41.67", "0.380"),
    8.0: ("0.54", "-45.16", "0.328"),
}
#: the paper's batch-injection figure of each of its velocities (Fig. 4-7)
PAPER_MAP_FIGURE: dict[float, int] = {3.0: 4, 4.0: 5, 6.0: 6, 8.0: 7}
#: the paper's §3.1: CFD-DEM of the 5 s predict window about 50 h, the MCM about 30 min
PAPER_CFD_DEM_S = 50 * 3600.0
PAPER_MCM_S = 30 * 60.0
PAPER_SPEEDUP = 100.0
#: Fig. 10 is drawn at this velocity (m/s), or the case nearest to it
SNAPSHOT_VELOCITY = 6.0
#: snapshots span window start + 0 ... 0.7 s
SNAPSHOT_SPAN = 0.7
ESTIMATOR_ORDER = ("paper", "mle")
DEFAULT_BIN_WIDTH = 0.025

_CFD_DEM_COLOUR = "#1f4e79"
_ESTIMATOR_COLOURS = {"paper": "#d35400", "mle": "#7b3294"}
_OTHER_COLOURS = ("#1a9641", "#c51b7d", "#4d4d4d", "#b8860b", "#2c7fb8")
_STALE_FIGURE = re.compile(r"^(fig\d\d-.*|plausibility|its-.*|ck-.*)\.png$")


# -- reading the directory -------------------------------------------------------------------
def _error(path: Path, what: str) -> InputError:
    """A one-line InputError naming ``path``."""
    return InputError(f"{path}: {' '.join(str(what).split())}")


@contextlib.contextmanager
def _reading(path: Path):
    """Turn low-level read failures of ``path`` (HDF5 errors, missing datasets) into a
    one-line InputError naming it; InputErrors pass unchanged."""
    try:
        yield
    except InputError:
        raise
    except (OSError, KeyError) as exc:
        raise _error(path, f"cannot be used ({type(exc).__name__}: {exc})") from None


def _read_json(path: Path) -> Any:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise _error(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise _error(path, f"cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise _error(path, f"not valid JSON ({exc.msg} at line {exc.lineno})") from None


def _read_config(path: Path):
    from pydantic import ValidationError

    from cfbmarkov.config import CaseConfig

    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise _error(path, f"cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        return CaseConfig.model_validate_json(text)
    except ValidationError as exc:
        first = exc.errors()[0]
        loc = ".".join(str(p) for p in first["loc"]) or "(top level)"
        raise _error(path, f"not a usable case configuration (at '{loc}': {first['msg']})") from None


def _finite(value) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _velocity_of_name(name: str) -> float:
    match = re.fullmatch(r"u(\d+(?:\.\d+)?)", name)
    return float(match.group(1)) if match else math.inf


def _estimator_names(case_dirs: Sequence[Path]) -> list[str]:
    """Estimators with any file in any of ``case_dirs``: paper, mle, then the rest sorted."""
    names: set[str] = set()
    for d in case_dirs:
        if not d.is_dir():
            continue
        for p in d.iterdir():
            match = (re.fullmatch(r"(?:model|prediction)-(.+)\.h5", p.name) if p.is_file()
                     else re.fullmatch(r"compare-(.+)", p.name) if p.is_dir() else None)
            if match:
                names.add(match.group(1))
    return ([n for n in ESTIMATOR_ORDER if n in names]
            + sorted(n for n in names if n not in ESTIMATOR_ORDER))


@dataclass
class _Estimator:
    name: str
    model: Path
    prediction: Path
    summary_path: Path
    summary: dict | None = None

    @property
    def compare_dir(self) -> Path:
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
class _Case:
    name: str
    path: Path
    velocity: float
    config: Any = None
    estimators: list[_Estimator] = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)   # case-level reasons (not finished)

    @property
    def reference(self) -> Path:
        return self.path / "cfd-dem.h5"

    @property
    def finished(self) -> list[_Estimator]:
        return [e for e in self.estimators if e.summary is not None]

    @property
    def complete(self) -> bool:
        return not self.problems and bool(self.finished)

    @property
    def reasons(self) -> list[str]:
        return self.problems + [m for e in self.estimators if (m := e.missing)]

    @property
    def label(self) -> str:
        return f"U = {self.velocity:g} m/s" if math.isfinite(self.velocity) else self.name


def _load_case(root: Path, name: str, estimators: Sequence[str]) -> _Case:
    path = root / name
    case = _Case(name, path, _velocity_of_name(name))
    if not path.is_dir():
        case.problems.append("not started (no directory)")
        return case
    config_path = path / "case.json"
    if config_path.is_file():
        case.config = _read_config(config_path)
        case.velocity = float(case.config.gas.superficial_velocity)
    else:
        case.problems.append("no case.json")
    if not case.reference.is_file():
        case.problems.append("no cfd-dem.h5")
    for est in estimators:
        e = _Estimator(est, path / f"model-{est}.h5", path / f"prediction-{est}.h5",
                       path / f"compare-{est}" / "summary.json")
        if e.missing is None:
            summary = _read_json(e.summary_path)
            if not (isinstance(summary, dict) and isinstance(summary.get("reference"), dict)
                    and isinstance(summary.get("model"), dict)):
                raise _error(e.summary_path, "not a compare summary (no 'reference' and "
                                             "'model' sections)")
            e.summary = summary
        case.estimators.append(e)
    if not case.estimators:
        case.problems.append("not fitted (no model-*.h5)")
    timings_path = path / "timings.json"
    if timings_path.is_file():
        timings = _read_json(timings_path)
        if not isinstance(timings, dict):
            raise _error(timings_path, "not a JSON object of stage timings")
        case.timings = timings
    return case


def _load_directory(root: Path) -> tuple[dict, list[_Case]]:
    if not root.is_dir():
        raise _error(root, "not a reproduction directory (no such directory)")
    meta_path = root / "reproduce.json"
    meta = _read_json(meta_path)
    if not isinstance(meta, dict):
        raise _error(meta_path, "not a JSON object")
    names = meta.get("cases")
    if names is None:          # not listed: every folder with a case.json
        names = sorted(p.name for p in root.iterdir() if (p / "case.json").is_file())
    if not (isinstance(names, list) and all(isinstance(n, str) and n and "/" not in n
                                            and n not in (".", "..") for n in names)):
        raise _error(meta_path, "'cases' is not a list of case folder names")
    names = list(dict.fromkeys(names))
    if not names:
        raise _error(meta_path, "lists no case")
    estimators = _estimator_names([root / n for n in names])
    cases = sorted((_load_case(root, n, estimators) for n in names),
                   key=lambda c: (c.velocity, c.name))
    if not any(c.complete for c in cases):
        detail = "; ".join(f"{c.name}: {', '.join(c.reasons) or 'no estimator'}" for c in cases)
        raise _error(root, f"no finished case to report ({detail})")
    return meta, cases


# -- analysis of the finished cases ------------------------------------------------------------
@dataclass
class _Side:
    rt: Any                       # ResidenceTimes
    prob: np.ndarray              # RTD per bin
    mix_t: np.ndarray
    mix_f: np.ndarray


@dataclass
class _Analysis:
    window: tuple[float, float]
    bin_width: float
    edges: np.ndarray
    reference: _Side
    models: dict[str, _Side]
    band_positions: np.ndarray    # bin centres across the riser, x (m)
    solids_fraction: np.ndarray   # time-averaged solids volume fraction per bin
    solids_velocity: np.ndarray   # mean vertical solids velocity per bin (m/s)
    model_name: str | None = None
    model: Any = None             # MarkovModel used for Fig. 3-7


def _side(traj, window, bin_width) -> _Side:
    from cfbmarkov.analysis.mixing import mixing_curve_of
    from cfbmarkov.analysis.rtd import residence_times, rtd_histogram

    rt = residence_times(traj, window)
    _, prob = rtd_histogram(rt.samples, bin_width, window_length=window[1] - window[0])
    t, f = mixing_curve_of(traj, window)
    return _Side(rt, prob, t, f)


def _solids_profile(traj, window, config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Radial (across the riser) profiles over the window: bin centres x (m), time-averaged
    solids volume fraction (pseudo-2D as in SPEC §1: N pi d^3/6 over H dx d) and the
    solids' mean vertical velocity (m/s; NaN where no particle passed, or without
    velocities). Two bins per gas cell across."""
    bins = 2 * int(config.numerics.cfd_cells[0])
    edges = np.linspace(0.0, traj.width, bins + 1)
    counts = np.zeros(bins)
    momentum = np.zeros(bins)
    frames = traj.window(*window)
    n_frames = 0
    for k0 in range(frames.start, frames.stop, 32):
        block = slice(k0, min(k0 + 32, frames.stop))
        positions = traj.positions(block)
        x = positions[..., 0].ravel()
        counts += np.histogram(x, bins=edges)[0]
        velocities = traj.velocities(block)
        if velocities is not None:
            momentum += np.histogram(x, bins=edges, weights=velocities[..., 1].ravel())[0]
        n_frames += positions.shape[0]
    d = float(config.particles.diameter)
    fraction = counts / max(n_frames, 1) * (math.pi * d * d / 6.0) / (traj.height * np.diff(edges))
    velocity = np.divide(momentum, counts, out=np.full(bins, np.nan), where=counts > 0)
    if not traj.has_velocity:
        velocity[:] = np.nan
    return 0.5 * (edges[:-1] + edges[1:]), fraction, velocity


def _analyse(case: _Case, notes: list[str]) -> _Analysis:
    from cfbmarkov.analysis.rtd import rtd_histogram
    from cfbmarkov.markov import MarkovModel
    from cfbmarkov.trajectories import Trajectories

    window = tuple(float(v) for v in case.config.markov.predict_window)
    widths = {_finite(e.summary.get("bin_width")) for e in case.finished} - {None}
    bin_width = min(widths) if widths else DEFAULT_BIN_WIDTH
    for e in case.finished:
        w = e.summary.get("window")
        if isinstance(w, list) and len(w) == 2 and not np.allclose(w, window, atol=1e-9):
            notes.append(f"{case.name} / {e.name}: compare window {w[0]:g}-{w[1]:g} s differs "
                         f"from the case's predict window {window[0]:g}-{window[1]:g} s")
    with _reading(case.reference), Trajectories(case.reference) as ref:
        reference = _side(ref, window, bin_width)
        across, solids, solids_velocity = _solids_profile(ref, window, case.config)
    edges, _ = rtd_histogram(np.zeros(0), bin_width, window_length=window[1] - window[0])
    models = {}
    for e in case.finished:
        with _reading(e.prediction), Trajectories(e.prediction) as pred:
            models[e.name] = _side(pred, window, bin_width)
    analysis = _Analysis(window, bin_width, edges, reference, models, across, solids,
                         solids_velocity)
    chosen = case.finished[0]
    analysis.model_name = chosen.name
    with _reading(chosen.model):
        analysis.model = MarkovModel.load(chosen.model)
    return analysis


# -- figures ---------------------------------------------------------------------------------
def _grid(n: int) -> tuple[int, int]:
    cols = max(1, math.ceil(math.sqrt(n)))
    return math.ceil(n / cols), cols


def _panel_axes(n: int, panel_width: float, panel_height: float):
    """A constrained figure of ``n`` 2D panels on the :func:`_grid` layout, unused slots
    hidden: (figure, the first ``n`` axes)."""
    from matplotlib.figure import Figure

    nrows, ncols = _grid(n)
    fig = Figure(figsize=(0.6 + panel_width * ncols, 0.7 + panel_height * nrows),
                 layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:n]


def _letter(k: int) -> str:
    return f"({chr(ord('a') + k)})" if k < 26 else f"({k + 1})"


def _estimator_colour(name: str, names: Sequence[str]) -> str:
    if name in _ESTIMATOR_COLOURS:
        return _ESTIMATOR_COLOURS[name]
    others = [n for n in names if n not in _ESTIMATOR_COLOURS]
    return _OTHER_COLOURS[others.index(name) % len(_OTHER_COLOURS)] if name in others \
        else _OTHER_COLOURS[0]


def _plot_transition_bars_grid(panels: Sequence[tuple[str, np.ndarray]], path, title: str
                               ) -> Path:
    """Fig. 3: one 3D bar (stem) panel per velocity, P_ij at (state i, state j), on one
    shared colour scale (the style of figures.plot_transition_bars)."""
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    from cfbmarkov.report.figures import _save, draw_stems

    nrows, ncols = _grid(len(panels))
    vmax = max((float(P.max()) for _, P in panels), default=1.0)
    norm = Normalize(vmin=0.0, vmax=max(vmax, 1e-12))
    fig = Figure(figsize=(0.6 + 5.4 * ncols, 0.9 + 4.8 * nrows), layout="constrained")
    axes, stems = [], None
    for k, (label, P) in enumerate(panels):
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        s = P.shape[0]
        i, j = np.nonzero(P > 0)
        p = P[i, j]
        draw_stems(ax, i, j, p, s, norm, linewidth=0.7)
        ax.set_xlabel("state number i, from (-)", fontsize=8)
        ax.set_ylabel("transition number j, to (-)", fontsize=8)
        ax.set_zlabel("$P_{ij}$ (-)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.view_init(elev=52, azim=-60)
        ax.set_box_aspect(None, zoom=0.86)      # room for the axis labels
        ax.set_title(f"{_letter(k)} {label}: {p.size} nonzero of {s} x {s}", fontsize=9)
        axes.append(ax)
    if stems is not None:
        bar = fig.colorbar(stems, ax=axes, shrink=0.6, pad=0.04)
        bar.set_label("transition probability $P_{ij}$ (-)")
    fig.suptitle(title, fontsize=11)
    return _save(fig, path)


def _plot_rtd_grid(panels, path, title: str) -> Path:
    """Fig. 8/9: one RTD panel per velocity. ``panels``: (label, edges, series) with series
    (name, probability, ResidenceTimes, colour, filled)."""
    from cfbmarkov.report.figures import _save

    fig, axes = _panel_axes(len(panels), 5.6, 3.9)
    for k, (ax, (label, edges, series)) in enumerate(zip(axes, panels)):
        top, right = 1e-3, 0.0
        for name, prob, rt, colour, filled in series:
            text = (f"{name}: E(RT) = {_num(rt.mean, '.3f')} s, SD(RT) = {_num(rt.sd, '.3f')} s, "
                    f"n = {rt.count}")
            if filled:
                ax.stairs(prob, edges, fill=True, color=colour, alpha=0.3, label=text)
                ax.stairs(prob, edges, color=colour, lw=0.8)
            else:
                ax.stairs(prob, edges, color=colour, lw=1.4, label=text)
            if math.isfinite(rt.mean):
                ax.axvline(rt.mean, color=colour, ls="--", lw=0.9)
            top = max(top, float(prob.max(initial=0)))
            support = np.flatnonzero(prob > 0)
            if support.size:
                right = max(right, float(edges[support[-1] + 1]))
        ax.set_xlim(0.0, min(float(edges[-1]), right * 1.08) if right > 0 else float(edges[-1]))
        ax.set_ylim(0.0, top * 1.45)
        ax.set_xlabel("residence time (s)")
        ax.set_ylabel(f"probability per bin ({edges[1] - edges[0]:g} s)")
        ax.legend(loc="upper right", fontsize=7.5, framealpha=0.9, edgecolor="none",
                  title="dashed lines: E(RT)", title_fontsize=7)
        ax.set_title(f"{_letter(k)} {label}", fontsize=10)
    fig.suptitle(title, fontsize=11)
    return _save(fig, path)


def _plot_mixing_grid(panels, path, title: str) -> Path:
    """Fig. 11: one mixing panel per velocity. ``panels``: (label, series, well_mixed) with
    series (name, times, fraction, colour, line width)."""
    from cfbmarkov.report.figures import _save

    fig, axes = _panel_axes(len(panels), 5.4, 3.7)
    for k, (ax, (label, series, well_mixed)) in enumerate(zip(axes, panels)):
        top, lo, hi = 0.05, math.inf, -math.inf
        for name, t, f, colour, lw in series:
            ax.plot(t, f, color=colour, lw=lw, label=name)
            top = max(top, float(np.nanmax(f, initial=0)))
            if t.size:
                lo, hi = min(lo, float(t[0])), max(hi, float(t[-1]))
        if well_mixed is not None and math.isfinite(well_mixed):
            ax.axhline(well_mixed, color="0.35", ls="--", lw=1.0,
                       label=f"well mixed: $f_0^2$ = {well_mixed:.3f}")
        ax.set_ylim(0.0, min(1.0, 1.2 * top))
        if hi > lo:
            ax.set_xlim(lo, hi)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("purple in left half / all (-)")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8, frameon=False)
        ax.set_title(f"{_letter(k)} {label}", fontsize=10)
    fig.suptitle(title, fontsize=11)
    return _save(fig, path)


def _plot_plausibility(velocities, means, sds, model_means, profiles, path, title: str) -> Path:
    """(a) E(RT) and SD(RT) of the CFD-DEM (and E(RT) of each estimator) against U; (b)
    solids volume fraction and (c) mean vertical solids velocity across the riser, one line
    per U (the core-annulus structure)."""
    from matplotlib.figure import Figure

    from cfbmarkov.report.figures import _save

    fig = Figure(figsize=(15.0, 4.6), layout="constrained")
    ax, bx, cx = fig.subplots(1, 3)
    u = np.asarray(velocities, float)
    ax.plot(u, means, "o-", color=_CFD_DEM_COLOUR, label="E(RT), CFD-DEM")
    ax.plot(u, sds, "s--", color=_CFD_DEM_COLOUR, mfc="white", label="SD(RT), CFD-DEM")
    names = list(model_means)
    for name, values in model_means.items():
        ax.plot(u, values, "^", color=_estimator_colour(name, names), mfc="none", ms=8,
                label=f"E(RT), MCM ({name})")
    ax.set_xlabel("superficial gas velocity U (m/s)")
    ax.set_ylabel("residence time (s)")
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, frameon=False)
    ax.set_title("(a) residence time against U", fontsize=10)
    colours = ("#1f4e79", "#d35400", "#1a9641", "#7b3294", "#c51b7d", "#4d4d4d",
               "#b8860b", "#2c7fb8") * 4
    for (label, across, fraction, velocity), colour in zip(profiles, colours):
        bx.plot(1e3 * across, fraction, "-", color=colour, lw=1.4, label=label)
        cx.plot(1e3 * across, velocity, "-", color=colour, lw=1.4, label=label)
    bx.set_xlabel("distance from the left wall x (mm)")
    bx.set_ylabel("solids volume fraction (-), window average")
    bx.set_ylim(bottom=0.0)
    bx.grid(alpha=0.3)
    bx.legend(fontsize=8, frameon=False)
    bx.set_title("(b) radial solids profile, CFD-DEM", fontsize=10)
    cx.axhline(0.0, color="0.4", lw=0.8)
    cx.set_xlabel("distance from the left wall x (mm)")
    cx.set_ylabel("mean vertical solids velocity (m/s)")
    cx.grid(alpha=0.3)
    cx.set_title("(c) radial solids velocity, CFD-DEM (< 0: falling)", fontsize=10)
    fig.suptitle(title, fontsize=11)
    return _save(fig, path)


# -- the document ----------------------------------------------------------------------------
@dataclass
class _Heading:
    level: int
    text: str


@dataclass
class _Para:
    text: str
    css: str = ""


@dataclass
class _Bullets:
    items: list[str]


@dataclass
class _Table:
    header: list[str]
    rows: list[list[str]]
    notes: list[str] = field(default_factory=list)


@dataclass
class _Fig:
    file: str
    title: str
    sentence: str


def _num(value, spec: str, unit: str = "") -> str:
    v = _finite(value)
    return "n/a" if v is None else f"{v:{spec}}{unit}"


def _duration(seconds) -> str:
    s = _finite(seconds)
    if s is None:
        return "n/a"
    if s < 120:
        return f"{s:.3g} s"
    if s < 7200:
        return f"{s / 60:.3g} min"
    return f"{s / 3600:.3g} h"


def _md_cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _render_md(title: str, blocks) -> str:
    out = [f"# {title}", ""]
    for b in blocks:
        if isinstance(b, _Heading):
            out += ["#" * b.level + " " + b.text, ""]
        elif isinstance(b, _Para):
            out += [b.text, ""]
        elif isinstance(b, _Bullets):
            out += [f"- {item}" for item in b.items] + [""]
        elif isinstance(b, _Table):
            out.append("| " + " | ".join(_md_cell(h) for h in b.header) + " |")
            out.append("|" + "|".join("---" for _ in b.header) + "|")
            out += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in b.rows]
            out.append("")
            if b.notes:
                out += [f"{k + 1}. {note}" for k, note in enumerate(b.notes)] + [""]
        elif isinstance(b, _Fig):
            out += [f"![{b.title}]({FIGURES}/{b.file})", "", f"**{b.title}.** {b.sentence}", ""]
    return "\n".join(out).rstrip() + "\n"


_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; color: #222;
       max-width: 1180px; margin: 2em auto; padding: 0 1.2em; line-height: 1.45; }
h1 { font-size: 1.7em; border-bottom: 2px solid #1f4e79; padding-bottom: .2em; }
h2 { font-size: 1.3em; margin-top: 2em; color: #1f4e79; border-bottom: 1px solid #ccd; }
h3 { font-size: 1.08em; margin-top: 1.4em; }
div.wide { overflow-x: auto; }
table { border-collapse: collapse; margin: .8em 0; font-size: .88em; }
th, td { border: 1px solid #bbc; padding: .25em .55em; text-align: right; }
th { background: #eef2f7; text-align: center; }
td:first-child, td:nth-child(2) { text-align: left; }
tr:nth-child(even) td { background: #fafbfd; }
ol.notes { font-size: .85em; color: #444; }
figure { margin: 1em 0 1.6em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #e3e3e3; }
figcaption { font-size: .92em; margin-top: .3em; }
p.warn { color: #8a4b00; }
"""


def _render_html(title: str, blocks, figures_dir: Path) -> str:
    e = html.escape
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           f"<title>{e(title)}</title>", f"<style>{_CSS}</style>", "</head>", "<body>",
           f"<h1>{e(title)}</h1>"]
    for b in blocks:
        if isinstance(b, _Heading):
            out.append(f"<h{b.level}>{e(b.text)}</h{b.level}>")
        elif isinstance(b, _Para):
            out.append(f'<p class="{b.css}">{e(b.text)}</p>' if b.css else f"<p>{e(b.text)}</p>")
        elif isinstance(b, _Bullets):
            out.append("<ul>" + "".join(f"<li>{e(i)}</li>" for i in b.items) + "</ul>")
        elif isinstance(b, _Table):
            out.append('<div class="wide"><table><thead><tr>' + "".join(f"<th>{e(h)}</th>" for h in b.header)
                       + "</tr></thead><tbody>")
            out += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in b.rows]
            out.append("</tbody></table></div>")
            if b.notes:
                out.append('<ol class="notes">' + "".join(f"<li>{e(n)}</li>" for n in b.notes)
                           + "</ol>")
        elif isinstance(b, _Fig):
            data = base64.b64encode((figures_dir / b.file).read_bytes()).decode("ascii")
            out.append(f'<figure><img src="data:image/png;base64,{data}" alt="{e(b.title)}">'
                       f"<figcaption><b>{e(b.title)}.</b> {e(b.sentence)}</figcaption></figure>")
    out += ["</body>", "</html>", ""]
    return "\n".join(out)


def _readable_mode() -> int:
    """rw for everyone the umask allows (temporary files of atomic_path are 0600)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def _write_utf8(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
        os.chmod(tmp, _readable_mode())


# -- sections --------------------------------------------------------------------------------
def _shared(values: dict[str, str]) -> str:
    """One value when all cases agree, else 'case: value' for each."""
    distinct = list(dict.fromkeys(values.values()))
    if len(distinct) == 1:
        return distinct[0]
    return "; ".join(f"{case}: {value}" for case, value in values.items())


def _window_text(window) -> str:
    return f"{float(window[0]):g}–{float(window[1]):g} s"


def _header_blocks(meta: dict, cases: list[_Case], estimators: list[str]) -> list:
    from cfbmarkov import __version__

    configured = [c for c in cases if c.config is not None]
    done = [c for c in cases if c.complete]
    pending = [c for c in cases if not c.complete]
    cfg = {c.name: c.config for c in configured}
    items = [
        f"Scale: {meta.get('scale', 'n/a')}",
        "Cases: " + ", ".join(f"{c.name} ({c.label})" for c in cases)
        + f" — {len(done)} finished" + (f", {len(pending)} not finished ("
                                         + ", ".join(c.name for c in pending) + ")"
                                         if pending else ""),
        "Riser: " + _shared({n: f"{c.riser.width:g} m wide x {c.riser.height:g} m high"
                             for n, c in cfg.items()}),
        "Particles: " + _shared({n: f"{c.particles.number}" for n, c in cfg.items()}),
        "Windows: " + _shared({n: f"fit {_window_text(c.markov.fit_window)}, predict "
                                  f"{_window_text(c.markov.predict_window)}"
                               for n, c in cfg.items()}),
        "Lag: " + _shared({n: f"{c.markov.lag:g} s" for n, c in cfg.items()}),
        "Cells: " + _shared({n: f"{c.markov.columns} columns x {c.markov.rows} rows"
                             for n, c in cfg.items()}),
        "Estimators: " + (", ".join(estimators) or "none"),
        f"cfbmarkov version: {__version__}"
        + (f" (pipeline recorded {meta['version']})" if meta.get("version") not in (None, "")
           else ""),
    ]
    return [_Heading(2, "Reproduction"), _Bullets(items)]


def _not_finished_blocks(cases: list[_Case]) -> list:
    pending = [c for c in cases if not c.complete or c.reasons]
    if not pending:
        return []
    items = []
    for c in pending:
        state = "not finished" if not c.complete else "partly finished; not finished"
        items.append(f"{c.name} ({c.label}): {state}: " + "; ".join(c.reasons))
    return [_Heading(2, "Not finished"),
            _Para("These cases or estimators have not completed every stage of the pipeline; "
                  "they are left out of the figures and shown as 'not finished' in the "
                  "tables."),
            _Bullets(items)]


def _paper_row(u: float) -> tuple[str, str, str]:
    values = PAPER_TABLE3.get(round(u, 6)) if math.isfinite(u) else None
    return values if values is not None else ("—", "—", "—")


def _table3_blocks(cases: list[_Case], estimators: list[str]) -> list:
    header = ["U (m/s)", "Estimator", "E(RT) CFD-DEM (s)", "E(RT) MCM (s)", "PD of E(RT) (%)",
              "SD(RT) CFD-DEM (s)", "SD(RT) MCM (s)", "PD of SD(RT) (%)", "MD of RTD",
              "Mixing RMS", "Paper: PD of E(RT) (%)", "Paper: PD of SD(RT) (%)",
              "Paper: MD of RTD"]
    rows, pd_sd, pd_mean, orders, widths, exact = [], [], [], set(), set(), {}
    for c in cases:
        paper = _paper_row(c.velocity)
        u = f"{c.velocity:g}" if math.isfinite(c.velocity) else c.name
        for e in c.estimators if c.estimators else [None]:
            s = e.summary if e is not None and not c.problems else None
            if s is None:
                rows.append([u, e.name if e else "—"] + ["not finished"] * 8 + list(paper))
                continue
            ref, mod = s["reference"], s["model"]
            rows.append([u, e.name, _num(ref.get("rt_mean"), ".3f"), _num(mod.get("rt_mean"), ".3f"),
                         _num(s.get("pd_rt_mean"), ".2f"), _num(ref.get("rt_sd"), ".3f"),
                         _num(mod.get("rt_sd"), ".3f"), _num(s.get("pd_rt_sd"), ".2f"),
                         _num(s.get("md_rtd"), ".3g"), _num(s.get("mixing_rms"), ".3g")]
                        + list(paper))
            if (v := _finite(s.get("pd_rt_sd"))) is not None:
                pd_sd.append(v)
            if (v := _finite(s.get("pd_rt_mean"))) is not None:
                pd_mean.append(v)
            if (v := _finite(s.get("md_order"))) is not None:
                orders.add(v)
            if (v := _finite(s.get("bin_width"))) is not None:
                widths.add(v)
            ex = s.get("exact_events") or {}
            exact.setdefault("CFD-DEM: exact pass events" if ex.get("reference")
                             else "CFD-DEM: frame times", set()).add(c.name)
    order_text = ", ".join(f"{k:g}" for k in sorted(orders)) or "n/a"
    width_text = ", ".join(f"{w:g}" for w in sorted(widths)) or f"{DEFAULT_BIN_WIDTH:g}"
    notes = [
        "PD = 100 (MCM − CFD-DEM) / CFD-DEM, in % (SPEC §3); E(RT) and SD(RT) over the predict "
        "window, SD with ddof = 1. The paper's columns quote its Table 3; '—' where the paper "
        "has no case at this U.",
        "The paper reports MD under a '%' heading. Our MD is Eq. 9 of order k = "
        f"{order_text} (md_order of the compare summaries) on the RTD probabilities per "
        f"{width_text} s bin (bins from 0 to the window length), a dimensionless distance; "
        "compare its size with the paper's only loosely.",
        "Mixing RMS: root-mean-square difference of the MCM and CFD-DEM mixing curves on the "
        "model's frames, as a fraction of all particles (no paper value).",
    ]
    if exact:
        notes.append("Residence-time moments: " + "; ".join(
            f"{k} ({', '.join(sorted(v))})" for k, v in exact.items())
            + "; MCM predictions: frame times.")
    blocks = [_Heading(2, "Table 3: RTD of the CFD-DEM and the MCM"), _Table(header, rows, notes)]
    if pd_mean:
        under = sum(v < 0 for v in pd_sd)
        blocks.append(_Para(
            f"PD of E(RT) ranges from {min(pd_mean):.2f} to {max(pd_mean):.2f} % (paper: 0.54 to "
            f"11.89 %); the MCM's SD(RT) is smaller than the CFD-DEM's in {under} of "
            f"{len(pd_sd)} comparisons (paper: all four, by 38 to 51 %)."))
    return blocks


def _computing_blocks(cases: list[_Case]) -> list:
    header = ["U (m/s)", "CFD-DEM, predict window (wall)", "CFD-DEM run (wall / simulated)",
              "CFD-DEM particle-steps/s", "Estimator", "MCM fit (wall)", "MCM predict (wall)",
              "MCM fit + predict", "CFD-DEM / MCM"]
    rows, ratios = [], []
    for c in cases:
        if not c.complete:
            continue
        t = c.timings
        cfd = t.get("cfd_dem") if isinstance(t.get("cfd_dem"), dict) else {}
        window_wall = _finite(cfd.get("predict_window_wall_s"))
        window_text = _duration(window_wall)
        if window_wall is not None and cfd.get("predict_window_estimated"):
            window_text += " (estimated)"
        wall, simulated = _finite(cfd.get("wall_s")), _finite(cfd.get("simulated_s"))
        run_text = (f"{_duration(wall)} / {simulated:g} s" if wall is not None
                    and simulated is not None else "n/a")
        particles = _finite(cfd.get("particles"))
        rate = "n/a"
        if particles and simulated and wall and wall > 0:
            steps = simulated / float(c.config.numerics.dem_time_step)
            rate = f"{particles * steps / wall:.3g}"
        for e in c.finished:
            fit = _finite((t.get(f"fit-{e.name}") or {}).get("wall_s")
                          if isinstance(t.get(f"fit-{e.name}"), dict) else None)
            pred = _finite((t.get(f"predict-{e.name}") or {}).get("wall_s")
                           if isinstance(t.get(f"predict-{e.name}"), dict) else None)
            total = fit + pred if fit is not None and pred is not None else None
            ratio = window_wall / total if window_wall is not None and total else None
            if ratio is not None:
                ratios.append(ratio)
            rows.append([f"{c.velocity:g}", window_text, run_text, rate, e.name, _duration(fit),
                         _duration(pred), _duration(total), _num(ratio, ".3g")])
    rows.append(["paper (3–8)", f"about {_duration(PAPER_CFD_DEM_S)} (5 s, 27000 particles)",
                 "—", "—", "MCM", "—", "—", f"about {_duration(PAPER_MCM_S)}",
                 f"about {PAPER_SPEEDUP:g}"])
    notes = ["Wall times as recorded in each case's timings.json ('n/a' where not recorded); "
             "'estimated' marks a CFD-DEM time for the predict window extrapolated from a "
             "shorter run.",
             "Particle-steps/s = particles x (simulated time / DEM time step) / wall time of the "
             "CFD-DEM run."]
    blocks = [_Heading(2, "Computing time (paper §3.1)"), _Table(header, rows, notes)]
    if ratios:
        blocks.append(_Para(
            f"Over the predict window the MCM (fit + predict) is {min(ratios):.3g} to "
            f"{max(ratios):.3g} times faster than the CFD-DEM (paper: about "
            f"{PAPER_SPEEDUP:g} times, 50 h against 30 min)."))
    else:
        blocks.append(_Para("No speed-up can be given: the wall times of the CFD-DEM over the "
                            "predict window or of the MCM were not recorded."))
    return blocks


def _implied_velocity(model) -> float:
    """Mean vertical particle velocity (m/s) implied by P: the stationary average of the
    expected row displacement per lag, passes through the periodic boundary included."""
    space = model.state_space
    P = np.asarray(model.transition_matrix)
    row = space.cell_of_state // space.columns
    shift = (row[None, :] - row[:, None]) + space.rows * (model.up_fraction - model.down_fraction)
    per_state = (P * shift).sum(axis=1)
    return float(model.stationary_distribution @ per_state) * (space.height / space.rows) \
        / model.lag


def _fig3_blocks(done, analyses, figures_dir: Path, written: list[str]) -> list:
    name = "fig03-transition-matrices.png"
    panels, velocities = [], []
    for c in done:
        a = analyses[c.name]
        suffix = "" if a.model_name == "paper" else f", {a.model_name} estimator"
        panels.append((f"{c.label}{suffix}", np.asarray(a.model.transition_matrix)))
        velocities.append((c, _implied_velocity(a.model)))
    _plot_transition_bars_grid(panels, figures_dir / name,
                               "Fig. 3: transition probability matrices as bar graphs")
    written.append(name)
    vel = ", ".join(f"{v:+.2f} m/s at {c.label}" for c, v in velocities)
    sentence = (f"Each panel shows the nonzero P_ij of one velocity as a stem at (state i, "
                f"state j); the stationary mean vertical particle velocity implied by P is {vel}"
                + (", rising with U." if len(velocities) > 1 and all(
                    b[1] > a[1] for a, b in zip(velocities, velocities[1:])) else "."))
    return [_Heading(2, "Fig. 3: Transition probability matrices"),
            _Fig(name, "Fig. 3: transition probability matrices, paper estimator", sentence)]


def _map_numbers(cases: list[_Case]) -> dict[str, int]:
    if len(cases) <= 4:
        return {c.name: 4 + k for k, c in enumerate(cases)}
    papers = sorted(PAPER_MAP_FIGURE)
    out = {}
    for c in cases:
        if not math.isfinite(c.velocity):
            out[c.name] = 7
            continue
        nearest = min(papers, key=lambda u: (abs(u - c.velocity), u))
        out[c.name] = PAPER_MAP_FIGURE[nearest]
    return out


def _map_times(velocity: float, lag: float) -> tuple[list[float], list[float], bool]:
    """(paper's times, times in whole lags, whether any was rounded)."""
    wanted = [0.25, 0.5, 0.75] if velocity < 3.5 else [0.05, 0.10, 0.15]
    used = [max(1, math.floor(t / lag + 0.5 + 1e-9)) * lag for t in wanted]   # halves up
    rounded = any(abs(a - b) > 1e-9 * max(1.0, b) for a, b in zip(used, wanted))
    return wanted, used, rounded


def _maps_blocks(cases, done, analyses, figures_dir: Path, written: list[str]) -> list:
    from cfbmarkov.report import figures as fg

    numbers = _map_numbers(cases)
    blocks = [_Heading(2, "Fig. 4–7: Batch-injection probability maps"),
              _Para("A batch fed evenly over the inlet cells at t = 0 (Eq. 8), propagated by "
                    "S(t + lag) = S(t) P (Eq. 5-6); probability per cell at the paper's times "
                    "(0.25, 0.5, 0.75 s below 3.5 m/s, else 0.05, 0.10, 0.15 s).")]
    for c in done:
        a = analyses[c.name]
        model = a.model
        number = numbers[c.name]
        wanted, used, rounded = _map_times(c.velocity, model.lag)
        maps = np.asarray(model.batch_injection_maps(used), dtype=np.float64)
        # the same batch with what leaves through the top taken out (what is still inside)
        inside = np.asarray(model.batch_injection_maps(used, outflow=True), dtype=np.float64)
        left = 1.0 - float(inside[-1].sum())
        name = f"fig{number:02d}-maps-{c.name}.png"
        space = model.state_space
        fg.plot_probability_maps(
            maps, used, space.width, space.height, figures_dir / name,
            title=f"Fig. {number}: batch fed over the inlet\nat t = 0, {c.label}\n"
                  f"{a.model_name} estimator, {space.columns} x {space.rows} cells,\n"
                  f"lag {model.lag:g} s")
        written.append(name)
        centres = (np.arange(space.rows) + 0.5) * space.height / space.rows
        com = [float((m.sum(axis=1) * centres).sum() / max(m.sum(), 1e-300)) for m in inside]
        sentence = (f"At t = {', '.join(f'{t:g}' for t in used)} s the mean height of the part of "
                    f"the batch that has not yet left through the top is "
                    f"{', '.join(f'{h:.2f}' for h in com)} m (riser {space.height:g} m high); "
                    f"{100 * left:.1f} % of the batch has left through the top by {used[-1]:g} s "
                    "(the maps, like the paper's, keep it: it re-enters at the bottom).")
        if rounded:
            sentence += (f" The paper's times {', '.join(f'{t:g}' for t in wanted)} s are not "
                         f"whole multiples of the lag {model.lag:g} s and were rounded to the "
                         "nearest whole lag.")
        paper_u = [u for u, n in PAPER_MAP_FIGURE.items() if n == number]
        if paper_u and not math.isclose(paper_u[0], c.velocity):
            sentence += f" (The paper's Fig. {number} is at U = {paper_u[0]:g} m/s.)"
        blocks += [_Heading(3, f"Fig. {number}: {c.label} ({c.name})"),
                   _Fig(name, f"Fig. {number}: batch-injection maps, {c.label}", sentence)]
    return blocks


def _rtd_blocks(done, analyses, estimators, figures_dir: Path, written: list[str]) -> list:
    panels8, panels9 = [], []
    for c in done:
        a = analyses[c.name]
        panels8.append((c.label, a.edges,
                        [("CFD-DEM", a.reference.prob, a.reference.rt, _CFD_DEM_COLOUR, True)]))
        series = [("CFD-DEM (Fig. 8)", a.reference.prob, a.reference.rt, "0.7", True)]
        series += [(f"MCM, {n}", side.prob, side.rt, _estimator_colour(n, estimators), False)
                   for n, side in a.models.items()]
        panels9.append((c.label, a.edges, series))
    window_texts = _shared({c.name: _window_text(analyses[c.name].window) for c in done})
    _plot_rtd_grid(panels8, figures_dir / "fig08-rtd-cfd-dem.png",
                   f"Fig. 8: residence-time distributions of the CFD-DEM, window {window_texts}")
    _plot_rtd_grid(panels9, figures_dir / "fig09-rtd-mcm.png",
                   f"Fig. 9: residence-time distributions of the MCM, window {window_texts}")
    written += ["fig08-rtd-cfd-dem.png", "fig09-rtd-mcm.png"]

    sds = [(c, analyses[c.name].reference.rt.sd) for c in done
           if math.isfinite(analyses[c.name].reference.rt.sd)]
    means = ", ".join(f"{_num(analyses[c.name].reference.rt.mean, '.3f')} s at {c.label}"
                      for c in done)
    if len(sds) > 1:
        widest = max(sds, key=lambda x: x[1])
        narrowest = min(sds, key=lambda x: x[1])
        s8 = (f"The CFD-DEM RTD is widest at {widest[0].label} (SD(RT) = {widest[1]:.3f} s) and "
              f"narrowest at {narrowest[0].label} ({narrowest[1]:.3f} s); E(RT) is {means}.")
    else:
        s8 = f"The CFD-DEM RTD has E(RT) = {means}."
    narrower, total = 0, 0
    for c in done:
        a = analyses[c.name]
        for side in a.models.values():
            if math.isfinite(side.rt.sd) and math.isfinite(a.reference.rt.sd):
                total += 1
                narrower += side.rt.sd < a.reference.rt.sd
    s9 = (f"The MCM RTDs (grey: the CFD-DEM's) are narrower than the CFD-DEM's in {narrower} of "
          f"{total} velocity-estimator pairs; the paper found them narrower at all four "
          "velocities.")
    return [_Heading(2, "Fig. 8: RTD of the CFD-DEM"),
            _Fig("fig08-rtd-cfd-dem.png", "Fig. 8: CFD-DEM residence-time distributions", s8),
            _Heading(2, "Fig. 9: RTD of the MCM"),
            _Fig("fig09-rtd-mcm.png", "Fig. 9: MCM residence-time distributions", s9)]


def _snapshot_blocks(done, analyses, figures_dir: Path, written: list[str]) -> list:
    name = "fig10-snapshots.png"
    blocks: list = [_Heading(2, "Fig. 10: Particle snapshots")]
    candidates = []
    for c in done:
        for e in c.finished:
            png = e.compare_dir / "snapshots.png"
            if png.is_file():
                candidates.append((abs(c.velocity - SNAPSHOT_VELOCITY), c.velocity, c, e, png))
                break
    if not candidates:
        blocks.append(_Para("Not available: no finished case has a compare-*/snapshots.png.",
                            css="warn"))
        return blocks
    _, _, c, e, png = min(candidates, key=lambda x: (x[0], x[1]))
    data = png.read_bytes()
    if data[:8] != PNG_SIGNATURE:
        raise _error(png, "not a PNG image")
    with atomic_path(figures_dir / name, suffix=".png") as tmp:
        shutil.copyfile(png, tmp)
    written.append(name)
    a = analyses[c.name]
    t0 = a.window[0]
    at = t0 + SNAPSHOT_SPAN
    ref, mod = a.reference, a.models[e.name]

    def _at(side: _Side) -> str:
        if side.mix_t.size == 0 or at > side.mix_t[-1] + 1e-9:
            return "n/a"
        return f"{float(np.interp(at, side.mix_t, side.mix_f)):.3f}"

    sentence = (f"Snapshots at {c.label} (nearest to the paper's {SNAPSHOT_VELOCITY:g} m/s) from "
                f"{t0:g} to {at:g} s, CFD-DEM above and MCM ({e.name}) below, purple = x < W/2 at "
                f"{t0:g} s; the share of all particles that are purple and in the left half goes "
                f"from {_num(ref.mix_f[0] if ref.mix_f.size else None, '.3f')} to {_at(ref)} "
                f"(CFD-DEM) and {_at(mod)} (MCM) by {at:g} s.")
    blocks.append(_Fig(name, f"Fig. 10: particle snapshots, {c.label}", sentence))
    return blocks


def _mixing_blocks(done, analyses, estimators, figures_dir: Path, written: list[str]) -> list:
    name = "fig11-mixing.png"
    panels, parts = [], []
    for c in done:
        a = analyses[c.name]
        f0 = float(a.reference.mix_f[0]) if a.reference.mix_f.size else math.nan
        series = [("CFD-DEM", a.reference.mix_t, a.reference.mix_f, _CFD_DEM_COLOUR, 1.1)]
        series += [(f"MCM, {n}", s.mix_t, s.mix_f, _estimator_colour(n, estimators), 1.6)
                   for n, s in a.models.items()]
        panels.append((c.label, series, f0 * f0))
        end = float(a.reference.mix_f[-1]) if a.reference.mix_f.size else math.nan
        rms = [_num(e.summary.get("mixing_rms"), ".3g") for e in c.finished]
        parts.append(f"{c.label}: CFD-DEM ends at {end:.3f} against a well-mixed {f0 * f0:.3f}, "
                     f"RMS difference {', '.join(rms)} "
                     f"({', '.join(e.name for e in c.finished)})")
    _plot_mixing_grid(panels, figures_dir / name,
                      "Fig. 11: purple particles in the left half of the riser / all particles")
    written.append(name)
    return [_Heading(2, "Fig. 11: Radial mixing"),
            _Fig(name, "Fig. 11: radial mixing curves",
                 "Share of all particles that are purple (x < W/2 at the window start) and in the "
                 "left half, CFD-DEM against each estimator; " + "; ".join(parts) + ".")]


def _nanmean(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else math.nan


def _plausibility_blocks(done, analyses, estimators, figures_dir: Path,
                         written: list[str]) -> list:
    name = "plausibility.png"
    u = [c.velocity for c in done]
    means = [analyses[c.name].reference.rt.mean for c in done]
    sds = [analyses[c.name].reference.rt.sd for c in done]
    model_means = {n: [analyses[c.name].models[n].rt.mean if n in analyses[c.name].models
                       else math.nan for c in done] for n in estimators
                   if any(n in analyses[c.name].models for c in done)}
    profiles = [(c.label, analyses[c.name].band_positions, analyses[c.name].solids_fraction,
                 analyses[c.name].solids_velocity) for c in done]
    _plot_plausibility(u, means, sds, model_means, profiles, figures_dir / name,
                       "Plausibility of the CFD-DEM: residence time against U, core-annulus "
                       "profiles")
    written.append(name)
    finite = [(c, m) for c, m in zip(done, means) if math.isfinite(m)]
    trend = " → ".join(f"{m:.3f} s" for _, m in finite)
    span = f"{finite[0][0].velocity:g} → {finite[-1][0].velocity:g} m/s" if finite else ""
    if len(finite) < 2:
        verdict = "Only one finished case: no trend of E(RT) with U can be judged."
    elif all(b[1] < a[1] for a, b in zip(finite, finite[1:])):
        verdict = (f"E(RT) of the CFD-DEM falls as U rises ({span}: {trend}), as the paper "
                   "reports (Fig. 8).")
    else:
        verdict = (f"E(RT) of the CFD-DEM does NOT fall steadily as U rises ({span}: {trend}); "
                   "the paper reports a steady fall (Fig. 8).")
    ratios = []
    for c in done:
        a = analyses[c.name]
        k = max(1, a.solids_fraction.size // 6)
        wall = float(np.r_[a.solids_fraction[:k], a.solids_fraction[-k:]].mean())
        core = float(a.solids_fraction[k:-k].mean()) if a.solids_fraction.size > 2 * k else wall
        v_wall = _nanmean(np.r_[a.solids_velocity[:k], a.solids_velocity[-k:]])
        v_core = _nanmean(a.solids_velocity[k:-k]) if a.solids_velocity.size > 2 * k else v_wall
        ratios.append(f"{c.label}: solids fraction wall/core {wall:.3g}/{core:.3g}, velocity "
                      f"wall/core {v_wall:+.2f}/{v_core:+.2f} m/s")
    sentence = ("(a) E(RT) and SD(RT) of the CFD-DEM, and E(RT) of each MCM, against U; (b) "
                "solids volume fraction and (c) mean vertical solids velocity of the CFD-DEM "
                "across the riser (pseudo-2D, one particle diameter thick), averaged over the "
                f"predict window; a core-annulus flow has denser, slower or falling wall layers "
                f"({'; '.join(ratios)}).")
    return [_Heading(2, "Plausibility"),
            _Para(verdict),
            _Fig(name, "Plausibility: E(RT) and SD(RT) against U, radial solids profiles",
                 sentence)]


def _diagnostics_blocks(done, figures_dir: Path, written: list[str]) -> list:
    """Beyond the paper (issue 5): why the automatic model chose its state space and lag,
    implied timescales against lag, and the Chapman-Kolmogorov test of each model on height
    thirds and core/annulus, all on the fitting window."""
    from cfbmarkov.markov import MarkovModel, discretize
    from cfbmarkov.markov.diagnostics import (core_annulus, ck_test, height_bands,
                                              implied_timescales)
    from cfbmarkov.markov.states import CellGrid
    from cfbmarkov.report.diagnostics import plot_ck_test, plot_implied_timescales
    from cfbmarkov.trajectories import Trajectories

    blocks: list = [_Heading(2, "Beyond the paper: memory states and lag diagnostics"),
                    _Para("The paper's chain on cells forgets how a particle was moving; the "
                          "'auto' model chooses a state space with memory (direction, "
                          "velocity bins or previous cell) on held-out frames of the fitting "
                          "window alone, by the RTD or, where the blocks hold too few "
                          "residences, by the Chapman-Kolmogorov test (docs/method.md). "
                          "Implied timescales that "
                          "change with the lag, and Chapman-Kolmogorov errors, show the memory "
                          "a chain on cells misses.")]
    ck_rows = []
    for c in done:
        m = c.config.markov
        window = tuple(float(v) for v in m.fit_window)
        auto_path = c.path / "model-auto.h5"
        models = {}
        for e in c.finished:
            with _reading(e.model):
                models[e.name] = MarkovModel.load(e.model)
        if auto_path.is_file() and "auto" in models and models["auto"].selection:
            sel = models["auto"].selection
            blocks.append(_Heading(3, f"{c.label}: the automatic choice"))
            blocks.append(_Para(f"Chosen: {sel.get('reason', 'n/a')}."))
            by_ck = "Chapman-Kolmogorov" in sel.get("method", "")
            rows = [[cand["states"], f"{cand['lag']:g}", str(cand["n_states"]),
                     _num(cand.get("ck_error"), ".4f"), _num(cand.get("score"), ".3g")]
                    if by_ck else
                    [cand["states"], f"{cand['lag']:g}", str(cand["n_states"]),
                     _num(cand.get("pd_rt_mean"), "+.1f"), _num(cand.get("pd_rt_sd"), "+.1f"),
                     _num(cand.get("md_rtd"), ".3g"), _num(cand.get("score"), ".3g")]
                    for cand in sel.get("candidates", [])]
            if rows and by_ck:
                parts = ", ".join(f"{x:g}-{y:g} s" for x, y in sel.get("blocks", []))
                blocks.append(_Table(
                    ["states", "lag (s)", "states S", "mean CK error", "score"], rows,
                    [f"{sel.get('method')} over the blocks {parts}: each block predicted by "
                     "the model fitted on the others; CK error = mean |P_model(A -> B, t) - "
                     "P_observed| over height thirds x core/annulus at t = 2 to 20 lags; "
                     "score = CK error / CK error(cells)."]))
            elif rows:
                parts = ", ".join(f"{x:g}-{y:g} s" for x, y in sel.get("blocks", []))
                blocks.append(_Table(
                    ["states", "lag (s)", "states S", "mean PD E(RT) (%)",
                     "mean PD SD(RT) (%)", "mean MD", "score"], rows,
                    [f"{sel.get('method', 'cross-validation')} over the blocks {parts}: each "
                     "block predicted by the model fitted on the others; score = |mean PD E|/2 "
                     "+ |mean PD SD|/10 + mean MD / mean MD(cells)."]))
        with _reading(c.reference), Trajectories(c.reference) as ref:
            lags = [m.lag * k for k in (1, 2, 4)]
            grid = CellGrid(m.columns, m.rows, ref.width, ref.height)
            try:
                its = implied_timescales(ref, grid, lags, window=window, k=4)
            except (InputError, ValueError) as exc:
                blocks.append(_Para(f"{c.label}: implied timescales not computed ({exc})."))
                its = None
            if its is not None:
                name = f"its-{c.name}.png"
                plot_implied_timescales(its, figures_dir / name,
                                        title=f"Implied timescales, cells, {c.label}")
                written.append(name)
                slow = its.timescales[:, 0]
                trend = " → ".join(f"{t:.3g} s" for t in slow)
                blocks.append(_Fig(name, f"Implied timescales against lag, {c.label}",
                                   f"The slowest processes of the chain on cells at lags "
                                   f"{', '.join(f'{v:g}' for v in lags)} s (fitting window "
                                   f"{window[0]:g}-{window[1]:g} s); a Markov chain would give "
                                   f"the same timescales at every lag, here the slowest goes "
                                   f"{trend}."))
            for name_m, model in models.items():
                try:
                    discrete = discretize(ref, model.state_space, model.lag, window)
                    bands = ck_test(discrete, model, height_bands(model.state_space, 3), steps=4)
                    radial = ck_test(discrete, model, core_annulus(model.state_space), steps=4)
                except (InputError, ValueError) as exc:
                    ck_rows.append([c.label, name_m, f"not computed ({exc})", "", "", ""])
                    continue
                b, r = bands.summary(), radial.summary()
                ck_rows.append([c.label, name_m, model.state_space.describe(),
                                f"{model.lag:g}", _num(b["max_abs_error"], ".3f"),
                                _num(r["max_abs_error"], ".3f")])
                if name_m == ("auto" if "auto" in models else "paper"):
                    fig = f"ck-{c.name}.png"
                    plot_ck_test(bands, figures_dir / fig,
                                 title=f"Chapman-Kolmogorov test, {name_m} model, {c.label}")
                    written.append(fig)
                    blocks.append(_Fig(fig, f"Chapman-Kolmogorov test on height thirds, "
                                            f"{name_m} model, {c.label}",
                                       f"Probability to be in each third of the riser k lags "
                                       f"after being in it: data of the fitting window "
                                       f"(points) against P^k of the {name_m} model (lines); "
                                       f"largest difference {b['max_abs_error']:.3f}."))
    if ck_rows:
        blocks.append(_Heading(3, "Chapman-Kolmogorov errors"))
        blocks.append(_Table(["case", "model", "states", "lag (s)",
                              "max |error|, height thirds", "max |error|, core/annulus"],
                             ck_rows,
                             ["Max over 1-4 lags and all group pairs of |P_model(A→B, kτ) − "
                              "P_data(A→B, kτ)|, on the fitting window."]))
    return blocks


def _warning_blocks(cases: list[_Case], notes: list[str]) -> list:
    items = []
    for c in cases:
        for e in c.finished:
            for w in e.summary.get("warnings") or []:
                items.append(f"{c.name} / {e.name}: {w}")
    items += [f"report: {n}" for n in notes]
    return [_Heading(2, "Warnings"),
            _Bullets(items) if items else _Para("No warnings from the comparisons.")]


# -- entry point -----------------------------------------------------------------------------
def write_report(directory: str | os.PathLike, *, title: str | None = None) -> Path:
    """Write ``DIR/report.html``, ``DIR/report.md`` and ``DIR/figures/*.png`` for the
    reproduction directory ``directory``; return the path of report.html.

    Raises :class:`~cfbmarkov.errors.InputError` (one line, naming the file) when
    reproduce.json is missing or unusable, when a file that exists cannot be read, or when
    no case is finished. Unfinished cases are listed as "not finished".
    """
    root = Path(directory)
    meta, cases = _load_directory(root)
    estimators = _estimator_names([c.path for c in cases])
    done = [c for c in cases if c.complete]
    notes: list[str] = []
    analyses = {c.name: _analyse(c, notes) for c in done}
    for c in done:
        if analyses[c.name].model_name != "paper":
            notes.append(f"{c.name}: Fig. 3-7 use the {analyses[c.name].model_name} estimator "
                         "(no finished paper estimator)")
        if not c.timings:
            notes.append(f"{c.name}: no timings.json; computing times are n/a")

    figures_dir = root / FIGURES
    figures_dir.mkdir(parents=True, exist_ok=True)
    written: list[str] = []
    blocks: list = []
    blocks += _header_blocks(meta, cases, estimators)
    blocks += _not_finished_blocks(cases)
    blocks += _table3_blocks(cases, estimators)
    blocks += _computing_blocks(cases)
    blocks += _fig3_blocks(done, analyses, figures_dir, written)
    blocks += _maps_blocks(cases, done, analyses, figures_dir, written)
    blocks += _rtd_blocks(done, analyses, estimators, figures_dir, written)
    blocks += _snapshot_blocks(done, analyses, figures_dir, written)
    blocks += _mixing_blocks(done, analyses, estimators, figures_dir, written)
    blocks += _plausibility_blocks(done, analyses, estimators, figures_dir, written)
    blocks += _diagnostics_blocks(done, figures_dir, written)
    blocks += _warning_blocks(cases, notes)

    # figures of an earlier run that this run did not draw (e.g. a case since removed)
    for p in figures_dir.iterdir():
        if p.is_file() and _STALE_FIGURE.match(p.name) and p.name not in written:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
    mode = _readable_mode()
    for name in written:
        with contextlib.suppress(OSError):
            os.chmod(figures_dir / name, mode)

    title = title or ("cfbmarkov reproduction of the Markov chain riser paper "
                      f"({meta.get('scale', 'n/a')} scale)")
    _write_utf8(root / REPORT_MD, _render_md(title, blocks))
    html_path = root / REPORT_HTML
    _write_utf8(html_path, _render_html(title, blocks, figures_dir))
    return html_path


__all__ = ["write_report"]
