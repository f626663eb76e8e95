"""The kinetics section of a comparison: per property, maps of the bed's mean per cell
(reference, model, and the chain's exact steady state where known) and the cumulative
distribution of the value at the exit (reference, model, segregated flow);
``kinetics-NAME.png`` in the output of ``cfbmarkov compare --kinetics``.

References
----------
``docs/definitions.md``, Properties along observed paths; the segregated-flow baseline.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure


def _grid(values, space) -> np.ndarray:
    """Per-cell values as a (rows, columns) map, averaged over the depth of a 3D grid."""
    v = np.asarray(values, dtype=np.float64).reshape(space.rows, space.depth_columns,
                                                       space.columns)
    with np.errstate(invalid="ignore"):
        return np.nanmean(v, axis=1) if space.depth_columns > 1 else v[:, 0, :]


def plot_kinetics(drawn: dict, name: str, path, *, window) -> Path:
    """One property of a comparison: maps of the bed's mean per cell and its exit
    distribution, drawn cumulative (the share of exits at or below each bin's upper edge).

    Parameters
    ----------
    drawn : dict
        The figure inputs of :func:`cfbmarkov.analysis.kinetics_compare.compare_kinetics`
        for the property: ``edges`` (B + 1), the exit distributions ``reference``,
        ``model``, ``segregated_flow`` (B, or None), the per-cell means ``cell_reference``,
        ``cell_model``, ``cell_exact`` (C, or None), the model's ``space`` and the exit
        ``means`` (reference, model, segregated flow or None).
    name : str
        The property.
    path : str or os.PathLike
        Output PNG file.
    window : (float, float)
        The analysis window (s), for the title.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    space = drawn["space"]
    maps = [("reference", drawn["cell_reference"]), ("model", drawn["cell_model"])]
    if drawn.get("cell_exact") is not None:
        maps.append(("chain, exact steady state", drawn["cell_exact"]))
    grids = [(label, _grid(v, space)) for label, v in maps]
    finite = np.concatenate([g[np.isfinite(g)] for _, g in grids] + [np.zeros(0)])
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if not hi > lo:
        hi = lo + 1e-9
    panel_h = 5.0
    panel_w = max(1.2, panel_h * space.width / space.height)
    fig = Figure(figsize=(len(grids) * (panel_w + 0.7) + 5.5, panel_h + 1.4),
                 layout="constrained")
    axes = fig.subplots(1, len(grids) + 1,
                        width_ratios=[panel_w] * len(grids) + [panel_w * 3.5])
    image = None
    for n, (ax, (label, grid)) in enumerate(zip(axes, grids)):
        image = ax.imshow(grid, origin="lower", extent=(0.0, space.width, 0.0, space.height),
                          cmap="viridis", vmin=lo, vmax=hi, interpolation="nearest",
                          aspect="auto")
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("x (m)")
        if n == 0:
            ax.set_ylabel("height (m)")
    if image is not None:
        fig.colorbar(image, ax=list(axes[:len(grids)]), label=f"{name}: bed mean per cell",
                     shrink=0.8)
    ax = axes[-1]
    edges = np.asarray(drawn["edges"], dtype=np.float64)
    means = drawn["means"]
    for key, label, style, mean in (("reference", "reference", "-", means[0]),
                                    ("model", "model", "--", means[1]),
                                    ("segregated_flow", "segregated flow", ":", means[2])):
        dist = drawn.get(key)
        if dist is None:
            continue
        text = f"{label} (mean {mean:.4g})" if mean is not None and np.isfinite(mean) else label
        # cumulative: the exit values of a chain are discrete (one a whole number of lags),
        # which equal bins alias into a comb of full and empty bins
        ax.step(edges, np.concatenate([[0.0], np.cumsum(dist)]), where="post",
                linestyle=style, label=text)
    ax.set_xlabel(f"{name} at the exit")
    ax.set_ylabel("share of the exits at or below")
    ax.legend(fontsize=8)
    fig.suptitle(f"{name} along particle paths, window {window[0]:g}-{window[1]:g} s")
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


__all__ = ["plot_kinetics"]
