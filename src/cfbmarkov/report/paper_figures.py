"""Figures of the reproduction report (matplotlib, no pyplot): one panel per case for the
paper's Fig. 3, 8-9 and 11, and the plausibility figure. The data come ready from
:mod:`cfbmarkov.analysis.reproduction`; these functions only draw and save."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from cfbmarkov.report.document import number_text

CFD_DEM_COLOUR = "#1f4e79"
ESTIMATOR_COLOURS = {"paper": "#d35400", "mle": "#7b3294"}
OTHER_COLOURS = ("#1a9641", "#c51b7d", "#4d4d4d", "#b8860b", "#2c7fb8")

def _grid(n: int) -> tuple[int, int]:
    """(rows, columns) of a near-square layout of ``n`` panels."""
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
    """Panel letter: (a), (b), ..."""
    return f"({chr(ord('a') + k)})" if k < 26 else f"({k + 1})"


def estimator_colour(name: str, names: Sequence[str]) -> str:
    """Line colour of an estimator.

    Parameters
    ----------
    name : str
        The estimator.
    names : sequence of str
        All estimators of the report; estimators other than ``paper`` and ``mle`` take
        their colour by position among the others.

    Returns
    -------
    str
        A matplotlib colour (hex), fixed for ``paper`` and ``mle``.
    """
    if name in ESTIMATOR_COLOURS:
        return ESTIMATOR_COLOURS[name]
    others = [n for n in names if n not in ESTIMATOR_COLOURS]
    return OTHER_COLOURS[others.index(name) % len(OTHER_COLOURS)] if name in others \
        else OTHER_COLOURS[0]


def plot_transition_heatmaps_grid(panels, path, title: str) -> Path:
    """Fig. 3: one heat map of the transition matrix per velocity, written as a PNG.

    P_ij on one logarithmic colour scale shared by all panels, zeros blank; where the states
    are ordered by riser row, the top and right axes give the row of each state's cell.

    Parameters
    ----------
    panels : sequence of (str, numpy.ndarray, numpy.ndarray or None, int)
        Per panel its label (naming the state space), transition matrix (S, S), the riser
        row of each state's cell (S,) or None, and the grid's rows.
    path : str or os.PathLike
        Output PNG file.
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 3 (drawn there
    as 3D bars).
    """
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    from cfbmarkov.report.figures import _save, draw_heatmap

    nrows, ncols = _grid(len(panels))
    positive = [float(P[P > 0].min()) for _, P, _, _ in panels if np.any(P > 0)]
    vmin = max(min(positive, default=1e-3), 1e-6)
    vmax = max(max((float(P.max()) for _, P, _, _ in panels), default=1.0), vmin * 10)
    norm = LogNorm(vmin=vmin, vmax=vmax)
    fig = Figure(figsize=(0.8 + 5.0 * ncols, 1.0 + 5.0 * nrows), layout="constrained")
    axes, image = [], None
    for k, (label, P, row_of_state, rows) in enumerate(panels):
        ax = fig.add_subplot(nrows, ncols, k + 1)
        image = draw_heatmap(ax, np.asarray(P, dtype=np.float64), norm,
                             row_of_state=row_of_state, rows=rows, fontsize=8)
        ax.tick_params(labelsize=7)
        s = P.shape[0]
        ax.set_title(f"{_letter(k)} {label}\n{int(np.count_nonzero(P))} nonzero of {s} x {s}",
                     fontsize=9)
        axes.append(ax)
    if image is not None:
        bar = fig.colorbar(image, ax=axes, shrink=0.6, pad=0.04)
        bar.set_label("transition probability $P_{ij}$ (log scale; blank = 0)")
    fig.suptitle(title, fontsize=11)
    return _save(fig, path)


def plot_rtd_grid(panels, path, title: str) -> Path:
    """Fig. 8/9: one RTD panel per velocity, written as a PNG.

    Parameters
    ----------
    panels : sequence of (str, numpy.ndarray, sequence)
        Per panel (label, edges, series): bin edges shape (B + 1,) in s, and series of
        (name, probability per bin shape (B,), :class:`~cfbmarkov.observed.residence.ResidenceTimes`,
        colour, filled).
    path : str or os.PathLike
        Output PNG file.
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 8-9.
    """
    from cfbmarkov.report.figures import _save

    fig, axes = _panel_axes(len(panels), 5.6, 3.9)
    for k, (ax, (label, edges, series)) in enumerate(zip(axes, panels)):
        top, right = 1e-3, 0.0
        for name, prob, rt, colour, filled in series:
            text = (f"{name}: E(RT) = {number_text(rt.mean, '.3f')} s, "
                    f"SD(RT) = {number_text(rt.sd, '.3f')} s, n = {rt.count}")
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


def plot_mixing_grid(panels, path, title: str) -> Path:
    """Fig. 11: one mixing panel per velocity, written as a PNG.

    Parameters
    ----------
    panels : sequence of (str, sequence, float or None)
        Per panel (label, series, well_mixed): series of (name, frame times shape (T,) in s,
        mixing curve shape (T,) (-), colour, line width); ``well_mixed`` (-) is drawn as a
        dashed line when given and finite.
    path : str or os.PathLike
        Output PNG file.
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 11; ``docs/definitions.md`` (Mixing).
    """
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


def plot_plausibility(velocities, means, sds, model_means, profiles, path, title: str,
                      flux_means=None) -> Path:
    """The plausibility figure of the CFD-DEM, written as a PNG.

    (a) E(RT) and SD(RT) of the CFD-DEM (and E(RT) of each estimator) against U; (b)
    solids volume fraction and (c) mean vertical solids velocity across the riser, one line
    per U (the core-annulus structure).

    Parameters
    ----------
    velocities : sequence of float, length C
        Superficial gas velocity U of each case, m/s.
    means, sds : sequence of float, length C
        E(RT) and SD(RT) of the CFD-DEM, s.
    model_means : dict of str to sequence of float
        E(RT) of each estimator's prediction per case, s (NaN where missing).
    profiles : sequence of (str, numpy.ndarray, numpy.ndarray, numpy.ndarray)
        Per case (label, bin centres x in m, solids volume fraction (-), mean vertical
        solids velocity in m/s), each array of shape (K,).
    path : str or os.PathLike
        Output PNG file.
    title : str
        Figure title.
    flux_means : sequence of float, length C, optional
        E(RT) of the CFD-DEM from the net solids flux over each window (particle-time over
        net passes, which the window's length does not censor; the physics check's), s,
        drawn beside ``means`` (the residences the window holds whole), which can rise
        where it falls.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.
    """
    from matplotlib.figure import Figure

    from cfbmarkov.report.figures import _save

    fig = Figure(figsize=(15.0, 4.6), layout="constrained")
    ax, bx, cx = fig.subplots(1, 3)
    u = np.asarray(velocities, float)
    ax.plot(u, means, "o-", color=CFD_DEM_COLOUR,
            label="E(RT), CFD-DEM (residences held whole, as Table 3)")
    if flux_means is not None:
        ax.plot(u, flux_means, "D:", color=CFD_DEM_COLOUR, mfc="white",
                label="E(RT), CFD-DEM, from the net solids flux (the physics check's)")
    ax.plot(u, sds, "s--", color=CFD_DEM_COLOUR, mfc="white", label="SD(RT), CFD-DEM")
    names = list(model_means)
    for name, values in model_means.items():
        ax.plot(u, values, "^", color=estimator_colour(name, names), mfc="none", ms=8,
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


__all__ = ["CFD_DEM_COLOUR", "estimator_colour", "plot_mixing_grid", "plot_plausibility",
           "plot_rtd_grid", "plot_transition_heatmaps_grid"]
