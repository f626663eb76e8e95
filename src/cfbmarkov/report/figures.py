"""Figures of the comparison report, one function per figure (the paper's Fig. 3-11).

Every function takes plain arrays and an output path and writes one PNG atomically (a
temporary name in the same folder, then a rename). Figures are drawn on bare
:class:`matplotlib.figure.Figure` objects rendered by Agg, so no GUI backend is touched and
pyplot's global state is never used (safe in scripts, servers and tests).
"""

from __future__ import annotations

import os
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.colors import LogNorm, Normalize, to_rgba
from matplotlib.figure import Figure

from cfbmarkov._atomic import atomic_path
from cfbmarkov.errors import InputError

DPI = 120
PURPLE = "#6c2a91"
GREEN = "#1a9641"
REFERENCE_COLOUR = "#1f4e79"
MODEL_COLOUR = "#d35400"


def _save(fig: Figure, path: str | os.PathLike) -> Path:
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    return path


def _riser_axes(ax, width: float, height: float, *, xlabel: bool = True, ylabel: bool = True):
    ax.set_xlim(0.0, width)
    ax.set_ylim(0.0, height)
    ax.set_aspect("equal")
    ax.set_xticks([0.0, width])
    ax.set_xticklabels(["0", f"{width:g}"], fontsize=8)
    for label, align in zip(ax.get_xticklabels(), ("left", "right")):
        label.set_horizontalalignment(align)  # keep both labels inside a narrow panel
    if xlabel:
        ax.set_xlabel("x (m)")
    if ylabel:
        ax.set_ylabel("y (m)")
    else:
        ax.tick_params(labelleft=False)


# -- transition matrix (Fig. 3) --------------------------------------------------------------
def row_ticks(row_of_state, rows: int) -> tuple[np.ndarray, list[str]] | None:
    """Tick positions and labels of the riser rows along a matrix axis, where the states are
    ordered by row.

    Parameters
    ----------
    row_of_state : numpy.ndarray of int, shape (S,)
        The riser row (0 = bottom) of each state's cell.
    rows : int
        Rows of the grid.

    Returns
    -------
    (numpy.ndarray, list of str) or None
        The first state of every k-th row (at most about ten ticks) and the row numbers;
        None when the states are not ordered by row.
    """
    r = np.asarray(row_of_state)
    if r.size == 0 or np.any(np.diff(r) < 0) or rows < 2:
        return None
    step = max(1, int(np.ceil(rows / 10)))
    ticks = [int(np.searchsorted(r, k)) for k in range(0, rows, step) if np.any(r == k)]
    return np.asarray(ticks, dtype=float) - 0.5, [str(int(r[t])) for t in ticks]


#: the most cells a heat map draws along each side: a larger matrix is drawn by the largest
#: entry of each block of k x k (:func:`pooled_max`), about the pixels a panel has
HEATMAP_PIXELS = 600


def pooled_max(P: np.ndarray, pixels: int) -> np.ndarray:
    """``P`` reduced to at most ``pixels`` cells a side by the largest entry of each block of
    k x k, k = ceil(S / pixels) (the last blocks padded with zeros); ``P`` itself where
    S <= ``pixels``.

    A heat map of more states than its panel has pixels drops all but one entry of each
    pixel's block, whichever the renderer samples; the block's largest keeps every non-zero
    visible and costs the renderer k^2 times fewer cells.

    Parameters
    ----------
    P : numpy.ndarray, shape (S, S)
    pixels : int

    Returns
    -------
    numpy.ndarray, shape (ceil(S / k), ceil(S / k))
    """
    s = P.shape[0]
    k = -(-s // pixels)
    if k <= 1:
        return P
    n = -(-s // k)
    padded = np.zeros((n * k, n * k), dtype=P.dtype)
    padded[:s, :s] = P
    return padded.reshape(n, k, n, k).max(axis=(1, 3))


def draw_heatmap(ax, P, norm, *, row_of_state=None, rows: int = 0, fontsize: float = 9):
    """A transition matrix as a heat map on log colours, zeros blank, on given axes; a
    matrix of more than :data:`HEATMAP_PIXELS` states drawn by its blocks' largest entries
    (:func:`pooled_max`), on the same state axes.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    P : numpy.ndarray, shape (S, S)
        Transition matrix, from state i (rows, top to bottom) to state j.
    norm : matplotlib.colors.Normalize
        Colour normalisation (e.g. shared by several panels).
    row_of_state : numpy.ndarray of int, shape (S,), optional
        The riser row of each state's cell: ticks on the top and right axes give it where
        the states are ordered by row (:func:`row_ticks`).
    rows : int, optional
        Rows of the grid.
    fontsize : float, optional
        Size of the axis labels, points.

    Returns
    -------
    matplotlib.image.AxesImage
    """
    s = P.shape[0]
    image = ax.imshow(np.ma.masked_less_equal(pooled_max(P, HEATMAP_PIXELS), 0.0),
                      origin="upper", interpolation="nearest", norm=norm, cmap="viridis",
                      extent=(-0.5, s - 0.5, s - 0.5, -0.5))
    ax.set_facecolor("white")
    ax.set_xlabel("to state j (0-based)", fontsize=fontsize)
    ax.set_ylabel("from state i (0-based)", fontsize=fontsize)
    ticks = row_ticks(row_of_state, rows) if row_of_state is not None else None
    if ticks is not None:
        top = ax.secondary_xaxis("top")
        top.set_xticks(ticks[0])
        top.set_xticklabels(ticks[1], fontsize=fontsize - 1)
        top.set_xlabel("riser row of state j's cell (0 = bottom)", fontsize=fontsize)
        right = ax.secondary_yaxis("right")
        right.set_yticks(ticks[0])
        right.set_yticklabels(ticks[1], fontsize=fontsize - 1)
        right.set_ylabel("riser row of state i's cell", fontsize=fontsize)
    return image


def plot_transition_matrix(P, columns: int, rows: int, path, *, title: str | None = None,
                           grid: bool = False, states: str | None = None,
                           row_of_state=None) -> Path:
    """Heatmap of the S x S transition matrix, written as a PNG.

    From state i (rows, top to bottom) to state j (columns), nonzero entries on a log colour
    scale, zeros blank. The top axis gives the riser row of the states' cells where the
    states are ordered by row (for cells, s = row*m + col).

    Parameters
    ----------
    P : array_like, shape (S, S)
        Transition matrix, P_ij the probability to go from state i to state j in one lag.
    columns, rows : int
        Cells across (m) and along the riser.
    path : str or os.PathLike
        Output PNG file.
    title : str, optional
        Figure title; by default one naming the state space, its states and the nonzero
        entries.
    grid : bool, optional
        Draw a line between every row of cells.
    states : str, optional
        The state space's description (e.g. ``velocity 4x12 (336 states)``,
        :meth:`cfbmarkov.markov.states.StateSpace.describe`); default: cells of
        ``columns`` x ``rows``.
    row_of_state : array_like of int, shape (S,), optional
        The riser row of each state's cell; default: row*m + col order when S = columns x
        rows.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    Raises
    ------
    InputError
        When ``P`` is not a non-empty square matrix.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 3.
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[0] != P.shape[1] or P.shape[0] == 0:
        raise InputError(f"transition matrix must be square, got shape {P.shape}")
    s = P.shape[0]
    positive = P[P > 0]
    vmin = max(float(positive.min()) if positive.size else 1e-3, 1e-6)
    vmax = max(float(positive.max()) if positive.size else 1.0, vmin * 10)
    if row_of_state is None and columns * rows == s:
        row_of_state = np.arange(s) // columns
    fig = Figure(figsize=(7.6, 6.8), layout="constrained")
    ax = fig.add_subplot()
    image = draw_heatmap(ax, P, LogNorm(vmin=vmin, vmax=vmax), row_of_state=row_of_state,
                         rows=rows, fontsize=10)
    bar = fig.colorbar(image, ax=ax, shrink=0.85, pad=0.08)
    bar.set_label("transition probability $P_{ij}$ (log scale; blank = 0)")
    if grid and row_of_state is not None:
        r = np.asarray(row_of_state)
        for t in (np.nonzero(np.diff(r))[0] + 0.5 if np.all(np.diff(r) >= 0) else []):
            ax.axhline(t, color="0.85", lw=0.3, zorder=0)
            ax.axvline(t, color="0.85", lw=0.3, zorder=0)
    nonzero = int(np.count_nonzero(P))
    described = states or f"cells {columns}x{rows} ({s} states)"
    # a long state-space description on lines of its own, so that no title is cut
    lines = ["Transition probability matrix", *textwrap.wrap(described, 60),
             f"{nonzero} nonzero of {s} x {s}"]
    ax.set_title(title or "\n".join(lines), fontsize=11)
    return _save(fig, path)


def draw_stems(ax, i, j, p, n_states: int, norm, linewidth: float = 0.8):
    """Vertical stems of height p at (i, j) on 3D axes, coloured by p (tallest drawn last).

    Parameters
    ----------
    ax : mpl_toolkits.mplot3d.axes3d.Axes3D
        The 3D axes; their limits are set to span the n_states x n_states matrix.
    i, j : numpy.ndarray of int, shape (K,)
        From-state and to-state of each stem.
    p : numpy.ndarray, shape (K,)
        Stem heights (transition probabilities, -).
    n_states : int
        Number of states S.
    norm : matplotlib.colors.Normalize
        Colour normalisation; its ``vmax`` is also the height of the z axis.
    linewidth : float, optional
        Stem line width, points.

    Returns
    -------
    mpl_toolkits.mplot3d.art3d.Line3DCollection
        The stems (for a colour bar).
    """
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    order = np.argsort(p)
    segments = np.stack([np.c_[i, j, np.zeros_like(p)], np.c_[i, j, p]], axis=1)[order]
    stems = Line3DCollection(segments, cmap="viridis", norm=norm, linewidths=linewidth)
    stems.set_array(p[order])
    ax.add_collection3d(stems)
    ax.set_xlim(0, n_states - 1)
    ax.set_ylim(0, n_states - 1)
    ax.set_zlim(0, norm.vmax)
    return stems


def plot_transition_bars(P, path, *, title: str | None = None, min_probability: float = 0.0
                         ) -> Path:
    """The paper's Fig. 3 bar view of a transition matrix, written as a PNG.

    A vertical stem of height P_ij at (state i, state j) for every entry above
    ``min_probability``, coloured by its value.

    Parameters
    ----------
    P : array_like, shape (S, S)
        Transition matrix.
    path : str or os.PathLike
        Output PNG file.
    title : str, optional
        Figure title.
    min_probability : float, optional
        Entries at or below this probability are not drawn.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    Raises
    ------
    InputError
        When ``P`` is not a non-empty square matrix.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 3.
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[0] != P.shape[1] or P.shape[0] == 0:
        raise InputError(f"transition matrix must be square, got shape {P.shape}")
    s = P.shape[0]
    i, j = np.nonzero(P > min_probability)
    p = P[i, j]
    fig = Figure(figsize=(8.0, 6.6), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    norm = Normalize(vmin=0.0, vmax=max(float(p.max()) if p.size else 1.0, 1e-12))
    stems = draw_stems(ax, i, j, p, s, norm, linewidth=0.8)
    ax.set_xlabel("state number i (from)")
    ax.set_ylabel("transition number j (to)")
    ax.set_zlabel("$P_{ij}$")
    ax.view_init(elev=52, azim=-60)   # all three regions of Fig. 3 in view
    bar = fig.colorbar(stems, ax=ax, shrink=0.6, pad=0.08)
    bar.set_label("transition probability $P_{ij}$")
    ax.set_title(title or f"Transition probabilities as bars ({p.size} nonzero of {s} x {s})",
                 fontsize=11)
    return _save(fig, path)


# -- batch injection maps (Fig. 4-7) ---------------------------------------------------------
def plot_probability_maps(maps, times: Sequence[float], width: float, height: float, path,
                          title: str | None = None) -> Path:
    """Batch-injection maps: panels side by side of the probability per cell over the riser.

    One panel per time, on one shared colour scale; a panel whose total differs from 1
    gives the share still in the riser.

    Parameters
    ----------
    maps : array_like, shape (K, rows, columns) or (rows, columns)
        Probability per cell (-), row 0 at the bottom.
    times : sequence of float, length K
        Time of each map, s.
    width, height : float
        Riser width W and height H, m.
    path : str or os.PathLike
        Output PNG file.
    title : str, optional
        Figure title.
    band : (ndarray of shape (2, B), float), optional
        The model's interval per bin (lower, upper) and its level, drawn as a band.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    Raises
    ------
    InputError
        When ``maps`` is not of shape (K, rows, columns) with K >= 1, or ``times`` does not
        have K entries.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 4-7.
    """
    maps = np.asarray(maps, dtype=np.float64)
    if maps.ndim == 2:
        maps = maps[None]
    if maps.ndim != 3 or maps.shape[0] == 0:
        raise InputError(f"probability maps must have shape (k, rows, columns), got {maps.shape}")
    k = maps.shape[0]
    if len(times) != k:
        raise InputError(f"{k} probability maps but {len(times)} times")
    vmax = float(maps.max()) if maps.size and maps.max() > 0 else 1.0
    panel_h = 6.2
    panel_w = panel_h * width / height
    title = title or "Batch fed over the inlet at t = 0"
    lines = title.splitlines() or [""]
    # wide enough for the longest line of the title (about 0.085 in per character at 11 pt)
    # and tall enough for all of its lines: a title is never cut
    fig_w = max(2.2 + k * (panel_w + 0.5), 0.6 + 0.085 * max(len(t) for t in lines))
    fig = Figure(figsize=(fig_w, panel_h + 1.0 + 0.22 * len(lines)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, k, sharey=True, squeeze=False)[0])
    image = None
    for n, (ax, m, t) in enumerate(zip(axes, maps, times)):
        image = ax.imshow(m, origin="lower", extent=(0.0, width, 0.0, height), cmap="YlOrRd",
                          vmin=0.0, vmax=vmax, interpolation="nearest")
        _riser_axes(ax, width, height, ylabel=n == 0)
        total = float(m.sum())
        ax.set_title(f"t = {t:g} s" + (f"\nin riser: {total:.2f}" if abs(total - 1) > 5e-4
                                       else ""), fontsize=9)
    bar = fig.colorbar(image, ax=list(axes), shrink=0.8, pad=0.04)
    bar.set_label("probability per cell")
    fig.suptitle(title, fontsize=11)
    return _save(fig, path)


# -- residence-time distributions (Fig. 8-9) ----------------------------------------------------
def _stats(stats) -> tuple[float, float, int | None]:
    if isinstance(stats, Mapping):
        mean = stats.get("mean", stats.get("rt_mean"))
        sd = stats.get("sd", stats.get("rt_sd"))
        count = stats.get("count", stats.get("rt_count"))
    else:
        mean, sd, *rest = tuple(stats)
        count = rest[0] if rest else None
    mean = float("nan") if mean is None else float(mean)
    sd = float("nan") if sd is None else float(sd)
    return mean, sd, None if count is None else int(count)


def plot_rtd(edges, prob_reference, prob_model, stats_ref, stats_model, path, *,
             labels: tuple[str, str] = ("reference", "model"), title: str | None = None,
             band=None) -> Path:
    """Both RTDs as probability per bin on shared bins, written as a PNG.

    The legend gives E(RT) and SD(RT); dashed lines mark the means.

    Parameters
    ----------
    edges : array_like, shape (B + 1,)
        Bin edges, s.
    prob_reference, prob_model : array_like, shape (B,)
        Probability per bin (-) of the reference and the model.
    stats_ref, stats_model : mapping or tuple
        E(RT), SD(RT) (s) and optionally the sample count: a mapping with ``mean``, ``sd``
        [, ``count``] (or ``rt_mean``, ``rt_sd``, ``rt_count``), or a tuple
        (mean, sd[, count]).
    path : str or os.PathLike
        Output PNG file.
    labels : (str, str), optional
        Legend names of the reference and the model.
    title : str, optional
        Figure title.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    Raises
    ------
    InputError
        When ``edges`` is not 1D or the probabilities do not have B = ``edges.size - 1``
        entries each.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 8-9.
    """
    edges = np.asarray(edges, dtype=np.float64)
    pr = np.asarray(prob_reference, dtype=np.float64)
    pm = np.asarray(prob_model, dtype=np.float64)
    if edges.ndim != 1 or pr.shape != (edges.size - 1,) or pm.shape != pr.shape:
        raise InputError(f"RTD arrays do not match {edges.size - 1} bins")
    fig = Figure(figsize=(8.0, 4.8), layout="constrained")
    ax = fig.add_subplot()
    for prob, stats, label, colour, filled in ((pr, stats_ref, labels[0], REFERENCE_COLOUR, True),
                                               (pm, stats_model, labels[1], MODEL_COLOUR, False)):
        mean, sd, count = _stats(stats)
        text = f"{label}: E(RT) = {mean:.3f} s, SD(RT) = {sd:.3f} s"
        if count is not None:
            text += f", n = {count}"
        if filled:
            ax.stairs(prob, edges, fill=True, color=colour, alpha=0.35, label=text)
            ax.stairs(prob, edges, color=colour, lw=0.8)
        else:
            ax.stairs(prob, edges, color=colour, lw=1.6, label=text)
        if np.isfinite(mean):
            ax.axvline(mean, color=colour, ls="--", lw=1.0)
    if band is not None:
        (lower, upper), level = np.asarray(band[0], dtype=np.float64), float(band[1])
        if lower.shape == pm.shape:
            ax.stairs(upper, edges, baseline=lower, fill=True, color=MODEL_COLOUR, alpha=0.2,
                      label=f"model, {100 * level:g} % interval per bin")
    support = np.flatnonzero((pr > 0) | (pm > 0))
    right = edges[-1] if support.size == 0 else min(edges[-1], edges[support[-1] + 1] * 1.08)
    ax.set_xlim(0.0, right)
    ax.set_ylim(0.0, max(float(pr.max(initial=0)), float(pm.max(initial=0)), 1e-3) * 1.4)
    width = edges[1] - edges[0] if edges.size > 1 else float("nan")
    ax.set_xlabel("residence time (s)")
    ax.set_ylabel(f"probability per bin ({width:g} s)")
    ax.legend(loc="upper right", fontsize=8.5, framealpha=0.9, edgecolor="none",
              title="dashed lines: E(RT)", title_fontsize=8)
    ax.set_title(title or "Residence-time distribution", fontsize=11)
    return _save(fig, path)


# -- snapshots (Fig. 10) -----------------------------------------------------------------------
def plot_snapshots(positions_ref, positions_model, left_group_ref, left_group_model,
                   times: Sequence[float], width: float, height: float, path, *,
                   labels: tuple[str, str] = ("reference", "model"), title: str | None = None
                   ) -> Path:
    """K snapshot pairs like the paper's Fig. 10, written as a PNG.

    Top row reference, bottom row model; particles of the left tracer group (x < W/2 at the
    window start) are drawn purple, the others green.

    Parameters
    ----------
    positions_ref, positions_model : array_like, shape (K, N, 2) or (N, 2)
        Particle positions (x, y), m, of the reference and the model at each time.
    left_group_ref, left_group_model : array_like of bool, shape (N,)
        Left tracer group of each side.
    times : sequence of float, length K
        Snapshot times, s.
    width, height : float
        Riser width W and height H, m.
    path : str or os.PathLike
        Output PNG file.
    labels : (str, str), optional
        Row names of the reference and the model.
    title : str, optional
        Figure title.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    Raises
    ------
    InputError
        When the positions are not of shape (K, N, 2) with K the number of ``times``, or a
        tracer-group mask does not have one entry per particle of its side.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 10; ``docs/definitions.md`` (Mixing).
    """
    pref = np.asarray(positions_ref, dtype=np.float64)
    pmod = np.asarray(positions_model, dtype=np.float64)
    if pref.ndim == 2:
        pref, pmod = pref[None], pmod[None]
    k = len(times)
    if pref.ndim != 3 or pmod.ndim != 3 or pref.shape[0] != k or pmod.shape[0] != k:
        raise InputError(f"snapshot positions must have shape ({k}, N, 2)")
    masks = (np.asarray(left_group_ref, dtype=bool), np.asarray(left_group_model, dtype=bool))
    if masks[0].shape != (pref.shape[1],) or masks[1].shape != (pmod.shape[1],):
        raise InputError("tracer group masks do not match the particles of the snapshots")
    panel_h = 5.0
    panel_w = panel_h * width / height
    fig = Figure(figsize=(1.1 + k * (panel_w + 0.32), 2 * panel_h + 1.4), layout="constrained")
    area = (72 * panel_w) * (72 * panel_h)      # panel area in points squared
    # not shared: every panel gets the same limits and ticks below, and the inner panels'
    # tick labels are hidden as sharing would (label_outer); shared axes would be kept in
    # step on every draw (a third of the figure's time)
    axes = fig.subplots(2, k, squeeze=False)
    rng = np.random.default_rng(0)     # interleave colours so neither is drawn on top
    for r, (pos, mask, label) in enumerate(((pref, masks[0], labels[0]),
                                            (pmod, masks[1], labels[1]))):
        n = pos.shape[1]
        order = rng.permutation(n)
        # RGBA rows, not colour names: one conversion, not one per particle and panel
        colours = np.where(mask[:, None], to_rgba(PURPLE), to_rgba(GREEN))[order]
        size = float(np.clip(0.4 * area / max(n, 1), 0.1, 8.0))   # ~40 % of the area inked
        for c in range(k):
            ax = axes[r, c]
            ax.scatter(pos[c, order, 0], pos[c, order, 1], s=size, c=colours, linewidths=0,
                       rasterized=True)
            _riser_axes(ax, width, height, xlabel=r == 1, ylabel=c == 0)
            if r == 0:
                ax.set_title(f"t = {times[c]:g} s", fontsize=9)
            if c == 0:
                ax.set_ylabel(f"{label}\ny (m)", fontsize=9)
            ax.label_outer()
    fig.suptitle(title or "Particle snapshots: purple = left half (x < W/2) at the window start, "
                 "green = right half", fontsize=10)
    return _save(fig, path)


# -- mixing curves (Fig. 11) -------------------------------------------------------------------
def plot_mixing(times_ref, frac_ref, times_model, frac_model, path, *,
                labels: tuple[str, str] = ("reference", "model"), title: str | None = None,
                well_mixed: float | None = None, band=None, open_riser: bool = False
                ) -> Path:
    """Mixing curves of both sides against time, written as a PNG.

    The fraction of all particles that are in the left tracer group (drawn purple) and in
    the left half (x < W/2); of an open riser, the fraction of the tracers still present
    (``docs/definitions.md``, Mixing in an open riser).

    Parameters
    ----------
    times_ref, frac_ref : array_like, shape (T_ref,)
        Frame times (s) and mixing curve (-) of the reference.
    times_model, frac_model : array_like, shape (T,)
        Frame times (s) and mixing curve (-) of the model.
    path : str or os.PathLike
        Output PNG file.
    labels : (str, str), optional
        Legend names of the reference and the model.
    title : str, optional
        Figure title.
    well_mixed : float, optional
        Level of a fully mixed bed (-), drawn as a dotted line when given and finite.
    band : (array_like of shape (T_b,), array_like of shape (2, T_b), float), optional
        The model's interval: frame times (s), lower and upper bounds (-) and its level,
        drawn as a band (``docs/definitions.md``, Intervals).
    open_riser : bool, optional
        The curves are an open riser's (their denominator the tracers still present).

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 11; ``docs/definitions.md`` (Mixing).
    """
    fig = Figure(figsize=(8.0, 4.6), layout="constrained")
    ax = fig.add_subplot()
    tr, fr = np.asarray(times_ref, float), np.asarray(frac_ref, float)
    tm, fm = np.asarray(times_model, float), np.asarray(frac_model, float)
    ax.plot(tr, fr, color=REFERENCE_COLOUR, lw=1.2, label=labels[0])
    ax.plot(tm, fm, color=MODEL_COLOUR, lw=1.6, label=labels[1])
    if band is not None:
        tb, (lower, upper) = np.asarray(band[0], float), np.asarray(band[1], float)
        if tb.shape == lower.shape == upper.shape:
            ax.fill_between(tb, lower, upper, color=MODEL_COLOUR, alpha=0.2, lw=0,
                            label=f"model's own {100 * float(band[2]):g} % band (the reference's "
                                  "sampling left out)")
    if well_mixed is not None and np.isfinite(well_mixed):
        ax.axhline(well_mixed, color="0.4", ls=":", lw=1.0,
                   label=f"fully mixed, the left half's share as at the start: "
                         f"(purple fraction)² = {well_mixed:.3f}")
    top = max(float(np.nanmax(fr, initial=0)), float(np.nanmax(fm, initial=0)), 0.05)
    ax.set_ylim(0.0, min(1.0, 1.15 * top))
    lo = min(tr.min(initial=np.inf), tm.min(initial=np.inf))
    hi = max(tr.max(initial=-np.inf), tm.max(initial=-np.inf))
    if np.isfinite(lo) and hi > lo:
        ax.set_xlim(lo, hi)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("purple tracers in left half / tracers still present" if open_riser
                  else "purple particles in left half / all particles")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=9, frameon=False)
    ax.set_title(title or "Radial mixing: purple = left half (x < W/2) at the window start",
                 fontsize=11)
    return _save(fig, path)


__all__ = ["plot_mixing", "plot_probability_maps", "plot_rtd", "plot_snapshots",
           "plot_transition_bars", "plot_transition_matrix", "draw_heatmap", "pooled_max",
           "row_ticks"]
