"""Figures of the lag diagnostics (:mod:`cfbmarkov.markov.diagnostics`): implied timescales
against the lag, and the Chapman-Kolmogorov test on coarse groups of cells.

Like :mod:`cfbmarkov.report.figures`, every function draws on a bare
:class:`matplotlib.figure.Figure` rendered by Agg (pyplot's global state is never used) and
writes one PNG atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cfbmarkov.errors import InputError
from cfbmarkov.markov.diagnostics import CKTest, ImpliedTimescales
from cfbmarkov.report.figures import MODEL_COLOUR, REFERENCE_COLOUR, _save


def plot_implied_timescales(its: ImpliedTimescales, path, title: str | None = None) -> Path:
    """Implied timescales t_i (s, log scale) against the lag tau (s), one line per process.

    The region t <= tau is shaded: a process faster than the lag is not resolved by the
    model. Lines that level off with the lag show Markovian dynamics on the states; for a
    non-reversible chain the timescales may approach their limit from above or below.

    Parameters
    ----------
    its : cfbmarkov.markov.diagnostics.ImpliedTimescales
        Implied timescales: ``lags`` shape (L,) s, ``timescales`` and ``eigenvalues``
        shape (L, k).
    path : str or os.PathLike
        Output PNG file.
    title : str, optional
        Figure title; by default one naming the estimator and state space.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    Raises
    ------
    InputError
        When ``its.timescales`` is not of shape (L, k) for the L >= 1 lags.
    """
    lags = np.asarray(its.lags, dtype=np.float64)
    ts = np.asarray(its.timescales, dtype=np.float64)
    if lags.ndim != 1 or ts.ndim != 2 or ts.shape[0] != lags.size or lags.size == 0:
        raise InputError(f"implied timescales must be [L, k] for L lags, got {ts.shape} "
                         f"for {lags.size} lag(s)")
    order = np.argsort(lags)
    lags, ts, eig = lags[order], ts[order], np.asarray(its.eigenvalues)[order]
    fig = Figure(figsize=(7.6, 4.8), layout="constrained")
    ax = fig.add_subplot()
    finite = ts[np.isfinite(ts) & (ts > 0)]
    lo = min(float(finite.min()) if finite.size else lags.min(), lags.min()) / 2.0
    hi = max(float(finite.max()) if finite.size else lags.max(), lags.max()) * 2.0
    for i in range(ts.shape[1]):
        column = ts[:, i]
        shown = np.where(np.isfinite(column) & (column > 0), column, np.nan)
        line, = ax.plot(lags, shown, lw=1.4, label=f"$t_{{{i + 2}}}$")
        real = np.abs(np.imag(eig[:, i])) <= 1e-12
        ax.plot(lags[real], shown[real], ls="none", marker="o", ms=4.5, color=line.get_color())
        ax.plot(lags[~real], shown[~real], ls="none", marker="o", ms=5, mfc="white",
                color=line.get_color())
        if np.any(np.isinf(column)):
            ax.plot(lags[np.isinf(column)], np.full(int(np.isinf(column).sum()), hi / 1.5),
                    ls="none", marker="^", color=line.get_color())
    x = np.linspace(0.0, lags.max() * 1.05, 200)
    ax.fill_between(x, lo, np.maximum(x, lo), color="0.6", alpha=0.35, lw=0,
                    label="t ≤ τ (faster than the lag)")
    ax.plot(x, np.maximum(x, lo), color="0.35", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlim(0.0, lags.max() * 1.05)
    ax.set_ylim(lo, hi)
    ax.set_xlabel("lag τ (s)")
    ax.set_ylabel("implied timescale $t_i = -τ / \\ln|λ_i|$ (s)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="best", fontsize=8.5, frameon=False, ncol=2 if ts.shape[1] > 4 else 1,
              title="open markers: complex λ (conjugate pairs coincide);\n"
                    "triangles: |λ| = 1 (does not decay)", title_fontsize=7.5)
    space = f" — {its.state_space}" if its.state_space else ""
    ax.set_title(title or f"Implied timescales ({its.estimator or 'model'}{space})", fontsize=11)
    return _save(fig, path)


def plot_ck_test(ck: CKTest, path, title: str | None = None, full: bool = False) -> Path:
    """Chapman-Kolmogorov test, written as a PNG.

    Per group A the probability to be in A (``full``: in every group B) a time k·tau after
    being in A, from the data (points, ±1 standard error) and predicted by the model's P^k
    (line), against the time k·tau (s). At t = 0 both are 1 (A -> A) or 0.

    Parameters
    ----------
    ck : cfbmarkov.markov.diagnostics.CKTest
        The test: ``predicted``, ``estimated`` and ``stderr`` of shape (K, G, G) for K
        steps and G groups, ``times`` shape (K,) s.
    path : str or os.PathLike
        Output PNG file.
    title : str, optional
        Figure title; by default one naming the lag.
    full : bool, optional
        Draw every pair A -> B (a G x G grid) instead of A -> A only.

    Returns
    -------
    pathlib.Path
        ``path``, where the PNG was written.

    Raises
    ------
    InputError
        When ``ck.predicted`` or ``ck.estimated`` is not of shape (K, G, G).
    """
    g = len(ck.group_names)
    k = ck.steps.size
    if ck.predicted.shape != (k, g, g) or ck.estimated.shape != (k, g, g):
        raise InputError(f"CK arrays do not match {k} steps x {g} groups")
    times = np.concatenate([[0.0], ck.times])
    if full:
        nrows, ncols = g, g
        pairs = [(a, b) for a in range(g) for b in range(g)]
    else:
        ncols = min(g, 4)
        nrows = int(np.ceil(g / ncols))
        pairs = [(a, a) for a in range(g)]
    fig = Figure(figsize=(1.0 + 3.0 * ncols, 0.9 + 2.6 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True)
    for n, ax in enumerate(axes.ravel()):
        if n >= len(pairs):
            ax.set_visible(False)
            continue
        a, b = pairs[n]
        start = 1.0 if a == b else 0.0
        pred = np.concatenate([[start], ck.predicted[:, a, b]])
        est = ck.estimated[:, a, b]
        err = np.nan_to_num(ck.stderr[:, a, b])
        ax.plot(times, pred, color=MODEL_COLOUR, lw=1.6, label="model $(w_A P^k)_B$")
        ax.errorbar(ck.times, est, yerr=err, fmt="o", ms=3.5, color=REFERENCE_COLOUR,
                    ecolor=REFERENCE_COLOUR, elinewidth=1.0, capsize=2, label="data ± 1 s.e.")
        ax.plot([0.0], [start], "o", ms=3.5, color=REFERENCE_COLOUR)
        values = np.concatenate([pred, est + err, est - err])
        values = values[np.isfinite(values)]
        top = max(float(values.max()) if values.size else 1.0, 0.05)
        ax.set_ylim(0.0, min(1.02, top * 1.1 + 0.02) if a != b else 1.02)
        ax.set_xlim(0.0, times[-1] * 1.04)
        ax.set_title(f"{ck.group_names[a]} → {ck.group_names[b]}", fontsize=9)
        ax.grid(alpha=0.3)
        row, col = divmod(n, ncols)
        if col == 0:
            ax.set_ylabel("probability")
        if row == nrows - 1 or n + ncols >= len(pairs):
            ax.set_xlabel("time k·τ (s)")
            ax.tick_params(labelbottom=True)
        if n == 0:
            ax.legend(loc="best", fontsize=7.5, frameon=False)
    s = ck.summary()
    which = "all A→B" if full else "A→A"
    err_max = s["max_abs_error"] if full else s["max_abs_error_diagonal"]
    err_rms = s["rms_error"] if full else s["rms_error_diagonal"]
    fig.suptitle((title or f"Chapman–Kolmogorov test, lag τ = {ck.lag:g} s")
                 + f"\n|model − data| over {which}: max {err_max:.3g}, RMS {err_rms:.3g}",
                 fontsize=10)
    return _save(fig, path)


__all__ = ["plot_ck_test", "plot_implied_timescales"]
