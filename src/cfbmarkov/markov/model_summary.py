"""The text that describes a fitted :class:`~cfbmarkov.markov.model.MarkovModel`: its
summary for ``fit`` and ``info`` and its warnings (traps; an open riser's censored tracks).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from cfbmarkov.markov.selection_table import UNVISITED_LIMIT

if TYPE_CHECKING:
    from cfbmarkov.markov.model import MarkovModel


#: the line ``fit``, ``rtd`` and ``info`` print for a model of a net downflow
DOWNWARD_LINE = ("residences counted downward: the fitting window's net solids flow runs "
                 "down")


#: what a reducible chain's lines advise: coarser cells join its closed classes, but they
#: mix columns the window's particles kept apart, so the coarser model is kept only where
#: it carries its own fitting window; where it does not, the classes are the flow's own
CLOSED_CLASSES_ADVICE = ("coarser --cells (fewer columns) join the classes but mix columns "
                         "whose particles did not cross in the window: keep the coarser "
                         "model only where fit prints no 'does not carry its own fitting "
                         "window' line for it; where it does, the classes are the flow's "
                         "own, and the finer cells' figures describe those that flow through")

#: unresolved mass of an exact RTD above which its E(RT) and SD(RT) are warned about
#: (``docs/definitions.md``, Exact RTD of a model)
UNRESOLVED_LIMIT = 0.01


#: an RTD as a window sees it: a warning where more than this share of the residences
#: begun in the window outlast it (a window short for the flow's residences); below it the
#: share, about E(RT) over the window's length, is what any window of data cuts, and the
#: RTD's line states it
WINDOW_UNRESOLVED_LIMIT = 0.5


def unresolved_warning(rtd, direction: str | None = None,
                       flow_direction: str | None = None) -> str | None:
    """The line that says an exact RTD's E(RT) and SD(RT) describe only its resolved
    residences, where its unresolved mass exceeds :data:`UNRESOLVED_LIMIT` (an RTD as a
    window sees it: :data:`WINDOW_UNRESOLVED_LIMIT`, the window short for the flow); else
    None.

    Parameters
    ----------
    rtd : ResidenceTimeDistribution
        An exact RTD (:meth:`MarkovModel.rtd <cfbmarkov.markov.model.MarkovModel.rtd>`).
    direction, flow_direction : {"up", "down"}, optional
        The direction its residences were counted in, and the chain's net flow direction
        (the model's ``flow_direction``): counted against the net flow, most residences
        drift away from their end, and the line says so and names the direction to count in.

    Returns
    -------
    str or None
    """
    u = float(rtd.unresolved)
    drift = getattr(rtd, "drift_mean", None)
    fallen = float(getattr(rtd, "deficit_unresolved", 0.0))
    if (direction is not None and flow_direction is not None and direction != flow_direction
            and u > UNRESOLVED_LIMIT and fallen > 0.5 * u and rtd.window is None):
        ends = "up through the top" if direction == "up" else "down through the bottom"
        resolved = float(np.sum(rtd.probability))
        return (f"unresolved mass {u:.2g}: counted {direction}ward (residences that end "
                f"{ends}), {fallen:.2g} of them drift more than {rtd.deficit_levels} laps "
                f"the other way before one ends, since the chain's net flow runs "
                f"{flow_direction}ward; E(RT) and SD(RT) describe the resolved "
                f"{100 * resolved:.2g} % alone and are not the flow's residence time: count "
                f"residences in the net flow's direction (direction=\"{flow_direction}\", "
                "the model's flow_direction, as fit and rtd do; docs/definitions.md, Net "
                "downflow)")
    if drift is not None and abs(rtd.mean - drift) > UNRESOLVED_LIMIT * drift:
        return (f"{fallen:.2g} of the residences fall more than {rtd.deficit_levels} laps "
                "below their entry, deeper than the exact RTD follows them: E(RT) and SD(RT) "
                "describe the others and are too short; the chain's E(RT) from its net lap "
                f"drift, which counts them, is {drift:.3g} s (docs/definitions.md, Exact RTD "
                "of a model); such a chain spends long stretches falling (a state space "
                "with memory on a window of a sluggish flow): fit on a longer window or "
                "another --states")
    if not u > UNRESOLVED_LIMIT:
        return None
    if rtd.window is not None and not u > WINDOW_UNRESOLVED_LIMIT:
        return None        # a window cuts about E(RT) / W of its residences: said, no warning
    if rtd.window is not None:
        # an RTD as a window sees it: the residences begun in the window that do not end in
        # it, about E(RT) / W of them from those begun late in it, besides the longer ones
        return (f"unresolved mass {u:.2g} in the {rtd.window:g} s window: the share of the "
                "residences begun in the window that do not end in it (those begun too late "
                "in it to end, about E(RT) over the window's length, as well as any longer "
                "than the window or that never reach the top), as a window of observed data "
                "cuts them; E(RT) and SD(RT) describe those that end in it, as a window of "
                "this length sees them; leave out --window-length for the intrinsic RTD, "
                "whose unresolved mass says whether the chain reaches the top from every "
                "state")
    window = ""
    return (f"unresolved mass {u:.2g} (above {100 * UNRESOLVED_LIMIT:g} %): E(RT) and SD(RT) "
            f"describe only the resolved {100 * (1.0 - u):.3g} % of the residences; the rest "
            "never reach the top in the chain (they stay in states where the fitting data "
            "saw particles only stay, as where a track ends or vanishes), fall deeper than "
            "the lap deficits computed or last longer than the lags computed "
            "(docs/definitions.md, Exact RTD of a model); fit on a coarser grid (--cells) "
            "or a longer window, so that the chain reaches the top from every state it "
            f"enters, and see its states never visited{window}")


def model_warnings(model: "MarkovModel") -> list[str]:
    """Lines about states entered but never left (traps), for an open riser about many
    tracks that ended or began away from the faces, the fitting sample's verdict
    (``model.adequacy``) and a chain that misses its own fitting window
    (:meth:`~cfbmarkov.markov.adequacy.Adequacy.on_window_warning`), more than
    :data:`UNVISITED_LIMIT` of the states never visited, an
    exact RTD whose unresolved mass exceeds :data:`UNRESOLVED_LIMIT`
    (:func:`unresolved_warning`), closed classes the exact answers leave out
    (:func:`left_out_classes_warning`), an open riser's hold-up
    (:func:`hold_up_warning`), a one-sided interval
    (:func:`one_sided_interval_warnings`) and an interval whose lower end is cut at 0
    (:meth:`~cfbmarkov.markov.uncertainty.ModelUncertainty.warnings`).

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
        missed = on_window_warning(model)
        if missed:
            lines.append(f"  {missed}")
    never = np.setdiff1d(model.unvisited_states, model.entered_never_left).size
    if never > UNVISITED_LIMIT * model.n_states:
        split = model.n_states > model.state_space.n_cells     # states that split cells
        lines.append(f"  {never} of {model.n_states} states never visited (more than "
                     f"{100 * UNVISITED_LIMIT:g} %): the "
                     + ("state space is" if split else "grid is")
                     + " too fine for the data, and the chain rests on the few states seen; "
                     "fit with a coarser --cells (fewer columns or rows)"
                     + (" or a state space with fewer states per cell" if split else "")
                     + " or on more data")
    try:
        unresolved = unresolved_warning(model.rtd())
    except Exception:  # a model without residence times says so in its summary
        unresolved = None
    if unresolved is not None:
        lines.append(f"  {unresolved}")
    if model.uncertainty is not None:
        lines += [f"  {line}" for line in model.uncertainty.warnings(fitting_run_count(model))]
        lines += [f"  {line}" for line in one_sided_interval_warnings(model)]
    left_out = left_out_classes_warning(model)
    if left_out is not None:
        lines.append(f"  {left_out}")
    hold_up = hold_up_warning(model)
    if hold_up is not None:
        lines.append(f"  {hold_up}")
    trapped = trap_warning(model)
    return lines if trapped is None else lines + [f"  {trapped}"]


def monte_carlo_warnings(model: "MarkovModel") -> list[str]:
    """The model's lines that a run of its chain (``predict``, ``react --init``, ``maps``)
    repeats: states entered but never left that keep their particles
    (:func:`trap_warning`: the run piles particles up there), and an open riser's inflow
    and censored tracks (:meth:`~cfbmarkov.markov.open_flow.OpenFlow.warnings`) and its
    hold-up (:func:`hold_up_warning`).

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    list of str
        One line each, without indentation; empty where none applies.
    """
    trapped = trap_warning(model)
    lines = [] if trapped is None else [trapped]
    if model.open_flow is None:
        return lines
    lines += [line.strip() for line in model.open_flow.warnings()]
    hold_up = hold_up_warning(model)
    return lines if hold_up is None else lines + [hold_up]


#: an interval whose one side is below this share of the other is called one-sided
ONE_SIDED_SHARE = 0.05


def one_sided_interval_warnings(model: "MarkovModel", rtd=None, uncertainty=None
                                ) -> list[str]:
    """Lines for an E(RT) or SD(RT) interval with (almost) no room on one side of the
    figure: the bootstrap's resamples of the fitting window lie almost all on the other
    side of the fitted chain's value (each half-width is the distance from the figure to
    a quantile of the resamples, none where the quantile lies beyond it), so the fitted
    value sits at the edge of what the window's blocks give, and the interval is no
    two-sided statement. Side below :data:`ONE_SIDED_SHARE` of the other.

    Parameters
    ----------
    model : MarkovModel
    rtd : ResidenceTimeDistribution, optional
        The intrinsic RTD the interval is of (default ``model.rtd()``).
    uncertainty : ModelUncertainty, optional
        The interval (default ``model.uncertainty``; one formed apart, by ``rtd
        --resamples``, may be given).

    Returns
    -------
    list of str
        Empty where the model has no interval, both intervals have room on both sides, or
        a lower end was cut at 0 (its own line, :meth:`ModelUncertainty.cut_at_zero
        <cfbmarkov.markov.uncertainty.ModelUncertainty.cut_at_zero>`, says why).
    """
    from cfbmarkov.markov.uncertainty import outward_bounds

    u = model.uncertainty if uncertainty is None else uncertainty
    if u is None:
        return []
    if rtd is None:
        try:
            rtd = model.rtd()
        except Exception:        # no residence: the summary says why
            return []
    lines = []
    for name, value, (lower, upper) in (("E(RT)", rtd.mean, u.rt_mean_interval),
                                        ("SD(RT)", rtd.sd, u.rt_sd_interval)):
        below, above = value - lower, upper - value
        if (not (np.isfinite(below) and np.isfinite(above)) or below + above <= 0
                or lower <= 0.0):
            continue
        if below < ONE_SIDED_SHARE * above or above < ONE_SIDED_SHARE * below:
            side, other = ("lower", "above") if below < above else ("upper", "below")
            lo, hi = outward_bounds(lower, upper, digits=4)
            lines.append(
                f"the {name} interval {lo}-{hi} s has almost no {side} side on the figure "
                f"{value:.4g} s: the bootstrap's resamples of the fitting window lie nearly "
                f"all {other} the fitted chain's, so the figure sits at the edge of what the "
                "window's blocks give (a short or unsteady sample, or one a few blocks "
                "dominate) and the interval says nothing of the other side; a longer window "
                "or several runs (fit A.h5 B.h5 ...) give a two-sided one")
    return lines


#: an open riser's chain whose steady hold-up lies farther than this share from its
#: fitting window's mean hold-up is warned of (its Monte Carlo drains or fills the riser)
HOLD_UP_LIMIT = 0.2


#: an open chain whose exact RTD leaves more than this share of its entries unresolved
#: (particles that reach a trap) has no steady hold-up
TRAPPED_SHARE = 1e-6


def hold_up_warning(model: "MarkovModel") -> str | None:
    """The line for an open riser's chain whose steady hold-up differs from the data's.

    In a steady state the riser holds inflow x the mean time a particle spends in its
    states (Little's law): the chain's hold-up is ``inflow_per_lag * e (I - Q)^-1 1`` (its
    E(RT) in lags, less :func:`~cfbmarkov.markov.model_rtd.entry_delay`), the
    fitting window's the particles in a state at the start of its frame pairs, averaged
    over them. Where the two differ by more than :data:`HOLD_UP_LIMIT`, the model's Monte
    Carlo (``predict``, ``react --init``) drains or fills the riser toward the chain's,
    and its bed means are of that riser (censored tracks, which the chain does not count
    as entries or exits, are a common cause).

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    str or None
        The line; None for a periodic riser, a model without frame pairs, or hold-ups that
        agree. A chain whose exact RTD leaves more than :data:`TRAPPED_SHARE` of its
        entries unresolved (a trap) has no steady hold-up: the line says its Monte Carlo
        fills the riser.

    References
    ----------
    J. D. C. Little, "A proof for the queuing formula L = lambda W", Operations Research
    9(3), 383-387 (1961).
    """
    flow = model.open_flow
    if flow is None or not model.frame_pairs:
        return None
    seen = (float(model.counts.sum()) + float(flow.exit_counts.sum())) / model.frame_pairs
    from cfbmarkov.markov.model_rtd import entry_delay

    try:
        rtd = model.rtd()
    except Exception:            # no residence: the model's other lines say why
        return None
    if rtd.unresolved > TRAPPED_SHARE:
        # particles that never leave: no steady hold-up, the riser fills for as long as
        # the Monte Carlo runs
        return (f"{100 * rtd.unresolved:.3g} % of the chain's entering particles never "
                "leave (a trap, or residences longer than the RTD follows), so it has no "
                "steady hold-up: its Monte Carlo (predict, react --init) fills the riser for "
                "as long as it runs, and its bed means are of that riser; fit with "
                "--connected or on a longer window")
    # E(RT) in lags, less the lags before a state with memory's first state
    lags = rtd.mean / model.lag - entry_delay(model)
    chain = flow.inflow_per_lag * lags
    if not seen > 0 or abs(chain - seen) <= HOLD_UP_LIMIT * seen:
        return None
    way = "drains" if chain < seen else "fills"
    return (f"the chain holds {chain:.4g} particles in a steady state (its inflow "
            f"{flow.inflow_per_lag:.4g} a lag x {lags:.4g} lags in the riser per particle), "
            f"{100 * abs(chain - seen) / seen:.0f} % {'below' if chain < seen else 'above'} "
            f"the fitting window's mean of {seen:.4g}: its Monte Carlo (predict, react "
            f"--init) {way} the riser toward that hold-up, and its bed means are of that "
            "riser (the RTD and the exit means are not affected); tracks left out as "
            "censored, or a window of unsteady flow, are the usual causes: import the riser "
            "from its inlet to its outlet, use taller cells or a shorter lag where tracks "
            "end or begin a row short of a face, or fit on a window of steady flow")


def left_out_classes(model: "MarkovModel") -> list[np.ndarray]:
    """The closed classes of a reducible periodic chain that its exact answers leave out:
    those with no net entry flux in the residences' direction
    (:func:`~cfbmarkov.markov.model_rtd.net_entry_flux`), whose particles never end a
    residence.

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    list of ndarray of int64
        The states of each class left out; empty for an open riser, an irreducible chain,
        or where every class has a net entry flux.
    """
    classes = model.closed_classes
    if model.open_flow is not None or len(classes) < 2:
        return []
    from cfbmarkov.markov.model_rtd import net_entry_flux

    flux = net_entry_flux(model, model.flow_direction)
    if flux is None:
        return []
    return [c for c in classes if not flux[c].sum() > 0]


def left_out_classes_warning(model: "MarkovModel") -> str | None:
    """The line for a reducible periodic chain whose exact answers leave classes out: the
    exact RTD weights each closed class by its observed net entry flux
    (:func:`~cfbmarkov.markov.model_rtd.net_entry_flux`), so a class whose net flow runs
    against the residences' direction (or is zero) gets no weight, and its particles are
    in neither the exact RTD nor the kinetics' exact answers.

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    str or None
        The line, naming how many classes, their states and share of the fitting window's
        particle-frames; None where no class is left out.
    """
    classes = model.closed_classes
    out = left_out_classes(model)
    if not out:
        return None
    direction = model.flow_direction
    frames = np.asarray(model.counts.sum(axis=1), dtype=np.float64)
    states = np.concatenate(out)
    share = frames[states].sum() / frames.sum() if frames.sum() > 0 else float("nan")
    return (f"{len(out)} of the chain's {len(classes)} closed classes ({states.size} states, "
            f"{100 * share:.3g} % of the fitting window's particle-frames) have no net "
            f"{direction}ward flow through the boundary, so the exact RTD and the kinetics' "
            "exact answers, which weight each class by its net entry flux, leave their "
            "particles out and describe the other classes alone; " + CLOSED_CLASSES_ADVICE)


def maps_left_out_warning(model: "MarkovModel", times, outflow: bool,
                          direction: str = "up") -> str | None:
    """The line for a batch of Eq. (8) (``maps``) partly fed into closed classes that the
    exact answers leave out (:func:`left_out_classes`): the chain keeps that share there,
    where the fitting window's particles stayed, instead of carrying it through the riser;
    with ``outflow`` the fraction in the riser levels off at what is still there.

    Parameters
    ----------
    model : MarkovModel
    times : sequence of float
        The maps' times after the injection (s), whole multiples of the lag.
    outflow : bool
        Whether the maps take out what leaves (:func:`~cfbmarkov.markov.propagation.
        propagate`).
    direction : {"up", "down"}, optional
        The row the batch is fed over (:func:`~cfbmarkov.markov.propagation.inlet_batch`).

    Returns
    -------
    str or None
        The line, naming the share fed into those classes and the share still in them at
        the last time; None where no class is left out or none of the batch is fed there.
    """
    out = left_out_classes(model)
    if not out:
        return None
    from cfbmarkov.markov.propagation import inlet_batch, propagate

    states = np.concatenate(out)
    batch = inlet_batch(model, direction)
    fed = float(batch[states].sum())
    if not fed > 0:
        return None
    last = max(times)
    held = float(propagate(model, batch, model.steps_for(last), outflow)[-1][states].sum())
    flow = model.flow_direction
    return (f"{fed:.3g} of the batch is fed into {len(out)} closed "
            f"{'class' if len(out) == 1 else 'classes'} of the chain with no net {flow}ward "
            f"flow through the boundary ({states.size} states; the fitting window's "
            "particles in them never moved into the other cells), where the chain keeps it: "
            f"{held:.3g} of the batch is still there at {last:g} s"
            + (" and counted in the fraction in riser" if outflow else "")
            + ", while the exact RTD leaves those particles out; " + CLOSED_CLASSES_ADVICE)


def on_window_warning(model: "MarkovModel", adequacy=None) -> str | None:
    """The model's line where its chain misses its own fitting window
    (:meth:`~cfbmarkov.markov.adequacy.Adequacy.on_window_warning`), ending with the advice
    that fits how its state space was chosen: a state space ``fit --states auto`` chose on
    this window is not sent to ``--states auto`` again.

    Parameters
    ----------
    model : MarkovModel
    adequacy : Adequacy, optional
        The verdict to read (default: the model's own, ``model.adequacy``).

    Returns
    -------
    str or None
        None where there is no verdict or the chain carries its window.
    """
    from cfbmarkov.markov.adequacy import CARRY_ADVICE, CHOSEN_CARRY_ADVICE

    adequacy = model.adequacy if adequacy is None else adequacy
    if adequacy is None:
        return None
    return adequacy.on_window_warning(
        advice=CHOSEN_CARRY_ADVICE if model.selection is not None else CARRY_ADVICE)


def trap_warning(model: "MarkovModel") -> str | None:
    """The line about states entered but never left, where particle-frames can reach them
    (None otherwise).

    Parameters
    ----------
    model : MarkovModel

    Returns
    -------
    str or None
    """
    trapped = model.entered_never_left
    if not trapped.size or model.trap_share == 0.0:
        return None
    return (f"states entered but never left: {state_set_text(model.state_space, trapped)}: "
            f"they keep their particles (P_ii = 1) or move as their cell; "
            f"{100 * model.trap_share:.1f} % of the particle-frames are in states that "
            "can reach a trap (fit --connected leaves them out; in Python "
            "connected=True)")


def _sources_text(source) -> str:
    """The file or files a model was fitted on, names joined by ``, `` (a pooled fit's)."""
    if isinstance(source, (list, tuple)):
        return ", ".join(str(s) for s in source)
    return str(source)


def _windows_text(model: "MarkovModel") -> str:
    """``window 10:15 s``, ``windows 10:15, 12:17 s`` (a pooled fit's, one per run) or
    ``window all``."""
    from cfbmarkov.trajectory_format import time_text      # 3600.005, not 3600.01

    if model.run_windows is not None and len({tuple(w) for w in model.run_windows}) > 1:
        return "windows " + ", ".join(f"{time_text(a)}:{time_text(b)}"
                                      for a, b in model.run_windows) + " s"
    return 'window ' + ('all' if model.window is None
                        else f'{time_text(model.window[0])}:{time_text(model.window[1])} s')


def _throughput_limit_text(adequacy) -> str:
    """``10 %``, or the wider limit a verdict applied for its window's cut through the
    particles' laps (:attr:`~cfbmarkov.markov.adequacy.Adequacy.throughput_limit`)."""
    limit = getattr(adequacy, "throughput_limit", math.nan)
    if not math.isfinite(limit) or limit <= 0.1 + 1e-12:
        return "10 %"
    return (f"{100 * limit:.2g} %, widened from 10 % for the few net passes that the "
            "window's cut through the particles' laps makes uncertain")


def model_summary(model: "MarkovModel", warnings: bool = True) -> str:
    """A few lines of text: state space, lag, fitting data, passes (or an open riser's exits
    and entries), unvisited states, warnings, regimes, coherence, closed classes, the
    selection, the direction residences are counted in where it is down
    (:data:`DOWNWARD_LINE`) and the exact E(RT) and SD(RT).

    Parameters
    ----------
    model : MarkovModel
    warnings : bool, optional
        Include the model's warnings (:func:`model_warnings`); ``fit`` leaves them out, having
        printed them as ``warning:`` lines on stderr.

    Returns
    -------
    str
        Lines separated by newlines; a model whose exact RTD cannot be computed says why on
        its last line.
    """
    lines = [
        f"Markov chain model: {model.state_space.describe()}, lag {model.lag:g} s, "
        f"estimator '{model.estimator}'",
        f"  fitted on {_sources_text(model.source)} {_windows_text(model)}: "
        f"{model.n_transitions} transitions over {model.frame_pairs} frame pairs",
        f"  passes through the periodic boundary: {int(model.counts_up.sum())} up, "
        f"{int(model.counts_down.sum())} down (in the transitions counted: a pass lies in "
        "every pair of frames one lag apart that spans it, so with frames closer than the lag "
        "it counts several times)" if model.open_flow is None else
        model.open_flow.summary_line(),
    ]
    never = np.setdiff1d(model.unvisited_states, model.entered_never_left)
    lines.append(f"  states never visited: {state_set_text(model.state_space, never)}")
    if warnings:
        lines.extend(f"  {line}" for line in model.warnings())
    if model.entered_never_left.size and model.trap_share == 0.0:
        keeps = any(model.transition_matrix[i, i] == 1.0 for i in model.entered_never_left)
        lines.append("  states entered but never left: "
                     f"{state_set_text(model.state_space, model.entered_never_left)}: "
                     + ("no state that holds particles in the window leads to those that "
                        "keep their particles" if keeps else
                        "their rows lead on (none keeps its particles), so they trap "
                        "nothing"))
    if model.connected:
        lines.append("  fitted on the largest strongly connected set of the counts")
    if model.regime_chain is not None:
        g = model.regime_chain
        stay = ", ".join(f"{g[r, r]:.3f}" for r in range(g.shape[0]))
        lines.append(f"  regime chain: stays per lag {stay} (mean durations "
                     + ", ".join(_regime_duration_text(model, g, r)
                                 for r in range(g.shape[0])) + ")")
    if model.coherence:
        lines.append(f"  coherent moves (the cluster model): coherence {model.coherence:.3f} "
                     "(share of a state's particles that move together each lag)")
    classes = model.closed_classes
    if len(classes) > 1:
        lines.append(f"  closed classes: {len(classes)} (sizes "
                     f"{', '.join(str(c.size) for c in classes[:6])}"
                     f"{', ...' if len(classes) > 6 else ''}): a reducible chain; "
                     + ("its particles enter by the observed entries"
                        if model.open_flow is not None else
                        "the exact RTD weights each class by its observed net entry "
                        "flux"))
    if model.selection:
        from cfbmarkov.markov.selection_table import candidate_table

        lines.append(f"  chosen automatically: {model.selection.get('reason', '')}")
        lines.extend(f"    {line}" for line in candidate_table(model.selection))
    if model.flow_direction == "down":
        lines.append(f"  {DOWNWARD_LINE}")
    try:
        r = model.rtd()
        if r.uncertainty is not None:
            u = r.uncertainty
            pooled_runs = len(model.run_windows) if model.run_windows else 1
            over = (f", already over sqrt({pooled_runs}) runs" if pooled_runs > 1 else "")
            sd_term = ("" if u.flow_sd is None or len(u.flow_sd) < 2 else
                       "; of SD(RT) taken as 0" if u.flow_sd[1] == 0.0 else
                       f"; {100 * u.flow_sd[1]:.3g} % of SD(RT)")
            short = ("fewer than two of the runs' windows hold a block of three mean "
                     "residence times" if pooled_runs > 1 else "the window is shorter than "
                     "two blocks of three mean residence times")
            flow = (f"; the flow's variability left out ({short})" if u.flow_sd is None else
                    "; the flow's variability of E(RT) between its blocks taken as 0 (their "
                    "E(RT) differ no more than their own sampling, which the bootstrap "
                    f"holds; an estimate on {u.flow_degrees_of_freedom} degree(s) of "
                    "freedom, itself uncertain: a longer window or more runs pin it down)"
                    + (f"; plus that of SD(RT) ({100 * u.flow_sd[1]:.3g} %{over}, times "
                       f"{u.flow_multiplier_text()})" if len(u.flow_sd) > 1
                       and u.flow_sd[1] > 0.0 else "")
                    if u.flow_sd[0] == 0.0 else
                    f"; plus the flow's variability between its blocks "
                    f"({100 * u.flow_sd[0]:.3g} % of E(RT){sd_term}{over}, times "
                    f"{u.flow_multiplier_text()})")
            lines.append(f"  exact residence time: {u.describe(r.mean, r.sd)}")
            runs = len(model.run_windows) if model.run_windows is not None else 1
            widened = ("" if u.bootstrap_widening is None else
                       f" (their spread widened {u.bootstrap_widening:.3g} times, for its "
                       f"{u.blocks - runs} degrees of freedom)")
            if runs > 1:        # each run's window cut into as many blocks
                spans = [(b - a) / max(u.blocks // runs, 1) for a, b in model.run_windows]
                long_ = (f"about {u.block_length:.3g} s long"
                         if max(spans) - min(spans) <= 1e-9 * max(spans) else
                         f"{min(spans):.3g} to {max(spans):.3g} s long by run")
            where = (f"the fitting windows of {runs} runs: {u.resamples} bootstrap "
                     f"resamples of {u.blocks // runs} blocks of each run, "
                     f"{long_}{widened}" if runs > 1 else
                     f"the fitting window alone: {u.resamples} bootstrap resamples of "
                     f"{u.blocks} blocks of {u.block_length:.3g} s{widened}")
            lines.append(f"    interval from {where}{flow}")
        else:
            lines.append(f"  exact residence time: E(RT) = {r.mean:.4g} s, "
                         f"SD(RT) = {r.sd:.4g} s (no interval: the model carries none; `fit` "
                         "without --resamples 0 adds one, and the verdict's limits with it; in "
                         "Python assess_fit(model))")
    except Exception as exc:  # a model without exits still has a summary
        lines.append(f"  exact residence time: none ({exc})")
    own = None if model.adequacy is None else model.adequacy.window_rt_mean
    if own is not None and np.isfinite(own):
        carry = ("a reducible chain, which weights its classes by their net entry flux, need "
                 "not carry it" if len(model.closed_classes) > 1 else
                 "the throughput the chain should carry; the verdict warns beyond "
                 f"{_throughput_limit_text(model.adequacy)}")
        lines.append(f"    the fitting window's own E(RT): {own:.4g} s (its particle-time over "
                     f"its net passes, {carry})")
    on_window = None if model.adequacy is None else model.adequacy.on_window_line()
    if on_window:
        lines.append(f"    {on_window}")
    passed = None if model.adequacy is None else model.adequacy.passed_line()
    if passed:
        others = len(model_warnings(model))
        if others:          # said beside "no warning", which is the sample's verdict alone
            where = ("the lines above" if warnings else "printed as `warning:` lines; "
                     "`cfbmarkov info MODEL` repeats them")
            passed += (f"; {others} warning{'' if others == 1 else 's'} about the model "
                       f"({where})")
        lines.append(f"  {passed}")
    elif model.adequacy is not None and not warnings:
        # the warnings went to stderr: the summary still says there are some, so that a
        # reader of standard output alone (a log) does not take silence for no warning
        count = len(model.adequacy.warnings)
        # the model's other lines (an interval cut at 0, states never visited, ...) are
        # printed beside the verdict's: counted apart, so that the lines add up
        others = len(model_warnings(model)) - count
        beside = (f", beside {others} more about the model" if others > 0 else "")
        lines.append(f"  the fitting sample's verdict: {count} warning"
                     f"{'' if count == 1 else 's'} (printed as `warning:` lines{beside}; "
                     "`cfbmarkov info MODEL` repeats them): the figures above may lie far "
                     "from the flow's long run")
    return "\n".join(lines)


def state_set_text(space, states: np.ndarray, limit: int = 8) -> str:
    """A set of states as a count and where they lie, never a long list of numbers.

    ``"0"``; ``"12 of 336 (rows 36-37; cells (0,3), (1,3) as column,row)"`` for a space
    whose states are its cells; ``"134 of 1596 (in 57 of 228 cells; all the states of 2 of
    them: cells (0,3), (1,3) as column,row)"`` for a space with memory, whose states split
    each cell.

    Parameters
    ----------
    space : StateSpace
        The state space the states belong to.
    states : ndarray of int
        State numbers, [K].
    limit : int, optional
        At most this many single cells are named (whole rows are named as row ranges).

    Returns
    -------
    str
        Cells as (column,row), or (column,depth column,row) in 3D, counted from the bottom
        left (``docs/definitions.md``, Cells and state numbers).
    """
    states = np.unique(np.asarray(states, dtype=np.int64))
    if not states.size:
        return "0"
    head = f"{states.size} of {space.n_states}"
    cell_of = np.asarray(space.cell_of_state)
    if space.n_states == space.n_cells and np.array_equal(cell_of,
                                                          np.arange(space.n_cells)):
        return f"{head} ({cells_text(space, states, limit)})"
    touched = np.unique(cell_of[states])
    per_cell = np.bincount(cell_of, minlength=space.n_cells)
    inside = np.bincount(cell_of[states], minlength=space.n_cells)
    whole = np.flatnonzero((inside == per_cell) & (per_cell > 0))
    text = f"{head} (in {touched.size} of {space.n_cells} cells"
    if whole.size:
        return text + (f"; all the states of {whole.size} of them: "
                       f"{cells_text(space, whole, limit)})")
    return text + ", none of them with all its states)"


def cells_text(space, cells: np.ndarray, limit: int = 8) -> str:
    """Cells by their rows and positions: whole rows as ranges (``rows 36-37``), the other
    cells as (column,row) counted from the bottom left, at most ``limit`` of them named
    (``"rows 36-37; cells (0,3), (1,3) as column,row"``).

    Parameters
    ----------
    space : StateSpace
        The state space whose grid numbers the cells (``(row*d + k)*m + col``).
    cells : ndarray of int
        Cell numbers, [K].
    limit : int, optional
        At most this many single cells are named; the rest are counted.

    Returns
    -------
    str
    """
    cells = np.unique(np.asarray(cells, dtype=np.int64))
    per_row = space.cells_per_row
    rows, within = np.divmod(cells, per_row)
    counts = np.bincount(rows, minlength=space.rows)
    full = np.flatnonzero(counts == per_row)
    parts = []
    start = None
    for k, r in enumerate(full):           # consecutive whole rows as one range
        if start is None:
            start = r
        if k + 1 == full.size or full[k + 1] != r + 1:
            parts.append(f"row {r}" if start == r else f"rows {start}-{r}")
            start = None
    single = ~np.isin(rows, full)
    named = []
    for r, w in zip(rows[single], within[single]):
        k, col = divmod(int(w), space.columns)
        named.append(f"({col},{k},{r})" if space.depth_columns > 1 else f"({col},{r})")
    if named:
        shown = ", ".join(named[:limit]) + (f", ... ({len(named) - limit} more)"
                                            if len(named) > limit else "")
        axes = "column,depth column,row" if space.depth_columns > 1 else "column,row"
        parts.append(f"cell{'s' if len(named) > 1 else ''} {shown} as {axes}")
    return "; ".join(parts)


def fitting_run_count(model) -> int:
    """The runs a model was fitted on: those of a pooled fit (``source`` a list), else 1."""
    source = getattr(model, "source", None)
    return len(source) if isinstance(source, (list, tuple)) and source else 1


def _regime_duration_text(model: "MarkovModel", g: np.ndarray, regime: int) -> str:
    """The mean duration of one regime of a regime model's chain G (lag / (1 - G_rr)), or
    why it has none: a regime whose states no counted transition leaves was never visited
    in the fitting window, or entered but never left where transitions led into it (its
    G_rr = 1 is a convention of :func:`~cfbmarkov.markov.regime_chain.regime_matrix`); one
    whose transitions all stay in it was never left."""
    if g[regime, regime] < 1.0:
        return f"{model.lag / (1.0 - g[regime, regime]):.3g} s"
    if model.n_transitions:
        states = model.state_space.regime_of(np.arange(model.state_space.n_states)) == regime
        if not model.counts[states].any():      # no transition out of the regime
            return ("entered but never left in the fitting window"
                    if model.counts[:, states].any() else "never visited in the fitting window")
    return "never left in the fitting window"
