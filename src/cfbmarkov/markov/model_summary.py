"""The text that describes a fitted :class:`~cfbmarkov.markov.model.MarkovModel`: its
summary for ``fit`` and ``info`` and its warnings (traps; an open riser's censored tracks).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel


#: the line ``fit``, ``rtd`` and ``info`` print for a model of a net downflow
DOWNWARD_LINE = ("residences counted downward: the fitting window's net solids flow runs "
                 "down")


def model_warnings(model: "MarkovModel") -> list[str]:
    """Lines about states entered but never left (traps), for an open riser about many
    tracks that ended or began away from the faces, and the fitting sample's verdict
    (``model.adequacy``).

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    list of str
    """
    lines = [] if model.open_flow is None else model.open_flow.warnings()
    if model.adequacy is not None:
        lines += [f"  {line}" for line in model.adequacy.warnings]
    trapped = model.entered_never_left
    if not trapped.size or model.trap_share == 0.0:
        return lines
    return lines + [f"  states entered but never left: {trapped.size} ({_short_list(trapped)}): "
            f"they keep their particles (P_ii = 1) or move as their cell; "
            f"{100 * model.trap_share:.1f} % of the particle-frames are in states that "
            "can reach a trap (fit --connected leaves them out)"]


def _windows_text(model: "MarkovModel") -> str:
    """``window 10:15 s``, ``windows 10:15, 12:17 s`` (a pooled fit's, one per run) or
    ``window all``."""
    if model.run_windows is not None and len({tuple(w) for w in model.run_windows}) > 1:
        return "windows " + ", ".join(f"{a:g}:{b:g}" for a, b in model.run_windows) + " s"
    return 'window ' + ('all' if model.window is None
                        else f'{model.window[0]:g}:{model.window[1]:g} s')


def model_summary(model: "MarkovModel") -> str:
    """A few lines of text: state space, lag, fitting data, passes (or an open riser's exits
    and entries), unvisited states, warnings, regimes, coherence, closed classes, the
    selection, the direction residences are counted in where it is down
    (:data:`DOWNWARD_LINE`) and the exact E(RT) and SD(RT).

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    str
        Lines separated by newlines; a model whose exact RTD cannot be computed says why on
        its last line.
    """
    lines = [
        f"Markov chain model: {model.state_space.describe()}, lag {model.lag:g} s, "
        f"estimator '{model.estimator}'",
        f"  fitted on {model.source} {_windows_text(model)}: "
        f"{model.n_transitions} transitions over {model.frame_pairs} frame pairs",
        f"  passes through the periodic boundary: {int(model.counts_up.sum())} up, "
        f"{int(model.counts_down.sum())} down" if model.open_flow is None else
        model.open_flow.summary_line(),
    ]
    never = np.setdiff1d(model.unvisited_states, model.entered_never_left)
    lines.append(f"  states never visited: {never.size}"
                 + (f" ({_short_list(never)})" if never.size else ""))
    lines.extend(model.warnings())
    if model.entered_never_left.size and model.trap_share == 0.0:
        lines.append(f"  states entered but never left: {model.entered_never_left.size} "
                     f"({_short_list(model.entered_never_left)}): no state leads to them")
    if model.connected:
        lines.append("  fitted on the largest strongly connected set of the counts")
    if model.regime_chain is not None:
        g = model.regime_chain
        stay = ", ".join(f"{g[r, r]:.3f}" for r in range(g.shape[0]))
        lines.append(f"  regime chain: stays per lag {stay} (mean durations "
                     + ", ".join(f"{model.lag / max(1.0 - g[r, r], 1e-12):.3g}"
                                 for r in range(g.shape[0])) + " s)")
    if model.coherence:
        lines.append(f"  coherent moves (the cluster model): coherence {model.coherence:.3f} "
                     "(share of a state's particles that move together each lag)")
    classes = model.closed_classes
    if len(classes) > 1:
        lines.append(f"  closed classes: {len(classes)} (sizes "
                     f"{', '.join(str(c.size) for c in classes[:6])}"
                     f"{', ...' if len(classes) > 6 else ''}): a reducible chain; the "
                     "exact RTD weights each class by its observed entry flux")
    if model.selection:
        lines.append(f"  chosen automatically: {model.selection.get('reason', '')}")
    if model.flow_direction == "down":
        lines.append(f"  {DOWNWARD_LINE}")
    try:
        r = model.rtd()
        if r.uncertainty is not None:
            u = r.uncertainty
            flow = ("; the flow's variability left out (the window is shorter than two "
                    "blocks of three mean residence times)" if u.flow_sd is None else
                    f" and the flow's variability between its blocks ({100 * u.flow_sd[0]:.3g} "
                    "% of E(RT)" + (", over sqrt(runs)" if model.run_windows else "") + ")")
            lines.append(f"  exact residence time: {u.describe(r.mean, r.sd)}")
            runs = len(model.run_windows) if model.run_windows is not None else 1
            where = (f"the fitting windows of {runs} runs: {u.resamples} bootstrap "
                     f"resamples of {u.blocks // runs} blocks of each run, about "
                     f"{u.block_length:.3g} s long" if runs > 1 else
                     f"the fitting window alone: {u.resamples} bootstrap resamples of "
                     f"{u.blocks} blocks of {u.block_length:.3g} s")
            lines.append(f"    interval from {where}{flow}")
        else:
            lines.append(f"  exact residence time: E(RT) = {r.mean:.4g} s, "
                         f"SD(RT) = {r.sd:.4g} s")
    except Exception as exc:  # a model without exits still has a summary
        lines.append(f"  exact residence time: none ({exc})")
    return "\n".join(lines)


def _short_list(values: np.ndarray, limit: int = 12) -> str:
    text = ", ".join(str(v) for v in values[:limit])
    return text + (", ..." if values.size > limit else "")
