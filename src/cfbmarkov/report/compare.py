"""``cfbmarkov compare``: a model's trajectories against a reference (the paper's §3).

Both sides are trajectory files (or open :class:`~cfbmarkov.trajectories.Trajectories`).
Within the analysis window the report gives, per side, the residence-time samples (SPEC
section 3; exact pass events where the file logged them), their RTD on shared bins and the
Minkowski distance of the two RTDs (Eq. 9), the percentage differences of E(RT) and SD(RT)
(Table 3), and the radial mixing curves (SPEC section 4, Fig. 11) with the RMS of their
difference on the model's frames. ``output/summary.json`` holds the numbers (written last
and atomically); with ``figures`` the PNGs of Fig. 8-11 are drawn, and, when the prediction
carries its model (``/provenance/model``), those of Fig. 3-7 too.
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from cfbmarkov._atomic import write_text_atomic
from cfbmarkov.analysis.metrics import minkowski_distance, mixing_rms, percentage_difference
from cfbmarkov.analysis.mixing import mixing_curve_of
from cfbmarkov.analysis.rtd import ResidenceTimes, residence_times, rtd_histogram
from cfbmarkov.errors import InputError
from cfbmarkov.trajectories import Trajectories

SUMMARY = "summary.json"
#: snapshot offsets from the window start (s), as in the paper's Fig. 10
SNAPSHOT_OFFSETS = tuple(round(0.1 * k, 10) for k in range(8))


def _open(source, stack: contextlib.ExitStack) -> Trajectories:
    if isinstance(source, Trajectories):
        return source
    return stack.enter_context(Trajectories(source))


def _check_window(window) -> tuple[float, float]:
    try:
        start, stop = (float(v) for v in window)
    except (TypeError, ValueError):
        raise InputError(f"window {window!r} is not (start, stop) in seconds") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise InputError(f"window {start:g}:{stop:g} s is not finite")
    if not stop > start:
        raise InputError(f"window {start:g}:{stop:g} s is empty (the end must follow the start)")
    return start, stop


def model_columns(traj: Trajectories) -> int | None:
    """Number of cell columns of the model behind a prediction, or None if it has none:
    the ``columns`` attribute of ``/provenance/model`` (or of its ``state_space`` JSON),
    else ``parameters["columns"]`` of the file."""
    group = traj.group("model")
    if group is not None:
        if "columns" in group.attrs:
            return int(group.attrs["columns"])
        space = group.attrs.get("state_space")
        if space is not None:
            with contextlib.suppress(ValueError, TypeError, KeyError):
                return int(json.loads(space)["columns"])
    columns = traj.parameters.get("columns") if isinstance(traj.parameters, dict) else None
    return None if columns is None else int(columns)


def _side(rt: ResidenceTimes, traj: Trajectories, frames: slice, purple_fraction: float
          ) -> dict[str, Any]:
    return {"rt_mean": rt.mean, "rt_sd": rt.sd, "rt_count": rt.count, "exact_events": rt.exact,
            "path": str(traj.path), "source": traj.source, "n_particles": traj.n_particles,
            "frames": frames.stop - frames.start, "frame_interval": traj.frame_interval,
            "purple_fraction": purple_fraction}


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def _map_times(reference_mean: float, lag: float) -> list[float]:
    """Times of the batch-injection maps: about E(RT)/4, /2, 3/4 in whole lags (the paper's
    choice of 0.05-0.15 s or 0.25-0.75 s), else 2, 4 and 6 lags."""
    if math.isfinite(reference_mean) and reference_mean > 0:
        steps = sorted({max(1, round(f * reference_mean / lag)) for f in (0.25, 0.5, 0.75)})
        if len(steps) == 3:
            return [k * lag for k in steps]
    return [k * lag for k in (2, 4, 6)]


def _model_figures(pred: Trajectories, out: Path, reference_mean: float, warnings: list[str]
                   ) -> list[str]:
    """Fig. 3-7 from the model attached to a prediction; [] (with a warning) when there is
    none or the model API is unavailable."""
    group = pred.group("model")
    if group is None:
        return []
    try:
        from cfbmarkov.markov import MarkovModel
    except ImportError as exc:
        warnings.append(f"model figures skipped: cfbmarkov.markov cannot be imported ({exc})")
        return []
    from cfbmarkov.report import figures as fg

    try:
        model = MarkovModel.from_group(group)
        P = np.asarray(model.transition_matrix, dtype=np.float64)
        columns, rows = int(model.state_space.columns), int(model.state_space.rows)
        lag = float(getattr(model, "lag", pred.frame_interval))
        times = _map_times(reference_mean, lag)
        maps = np.asarray(model.batch_injection_maps(times), dtype=np.float64)
    except (InputError, AttributeError, KeyError, TypeError, ValueError) as exc:
        warnings.append(f"model figures skipped: the model of {pred.path} cannot be used "
                        f"({type(exc).__name__}: {exc})")
        return []
    fg.plot_transition_matrix(P, columns, rows, out / "transition_matrix.png")
    fg.plot_transition_bars(P, out / "transition_bars.png")
    fg.plot_probability_maps(maps, times, pred.width, pred.height, out / "probability_maps.png",
                             title=f"Batch fed over the inlet at t = 0 (model, {columns} x {rows} "
                                   f"cells, lag {lag:g} s)")
    return ["transition_matrix.png", "transition_bars.png", "probability_maps.png"]


def _snapshot_indices(ref: Trajectories, pred: Trajectories, start: float, stop: float
                      ) -> list[tuple[float, int, int]]:
    chosen = []
    for offset in SNAPSHOT_OFFSETS:
        t = start + offset
        if t > stop + 1e-9 * max(1.0, abs(stop)):
            break
        try:
            chosen.append((t, ref.frame_index(t), pred.frame_index(t)))
        except InputError:
            continue
    return chosen


def compare(reference, prediction, *, window, output, bin_width: float = 0.025,
            md_order: float = 2.0, figures: bool = True) -> dict[str, Any]:
    """Compare ``prediction`` (the model) with ``reference`` on ``window`` = (start, stop) s.

    Writes ``output/summary.json`` (SPEC section 5 keys, plus details per side, the bins,
    warnings and the figures written) and, with ``figures``, ``rtd.png``, ``snapshots.png``,
    ``mixing.png`` and, when the prediction carries its model, ``transition_matrix.png``,
    ``transition_bars.png`` and ``probability_maps.png``. Returns the summary as a dict
    (undefined values as NaN there, null in the JSON file).
    """
    start, stop = _check_window(window)
    if not (math.isfinite(bin_width) and bin_width > 0):
        raise InputError(f"RTD bin width {bin_width:g} s must be positive")
    if not md_order > 0:
        raise InputError(f"Minkowski order {md_order:g} must be positive")
    out = Path(output)
    if out.exists() and not out.is_dir():
        raise InputError(f"output {out} exists and is not a directory")
    warnings: list[str] = []
    with contextlib.ExitStack() as stack:
        ref = _open(reference, stack)
        pred = _open(prediction, stack)
        ref_frames = ref.window(start, stop)
        pred_frames = pred.window(start, stop)
        columns = model_columns(pred)
        if columns is not None and columns % 2:
            raise InputError(f"{pred.path}: the model's state space has an odd column count "
                             f"({columns}): mixing by halves (x < W/2) is undefined")
        if not (np.isclose(ref.width, pred.width) and np.isclose(ref.height, pred.height)):
            raise InputError(f"domains differ: {ref.path} is {ref.width:g} x {ref.height:g} m, "
                             f"{pred.path} is {pred.width:g} x {pred.height:g} m")
        if ref.n_particles != pred.n_particles or not np.array_equal(np.sort(ref.ids),
                                                                      np.sort(pred.ids)):
            raise InputError(f"{ref.path} ({ref.n_particles} particles) and {pred.path} "
                             f"({pred.n_particles}) do not hold the same particle ids; mixing "
                             "needs the same particles on both sides")

        # residence times (SPEC section 3)
        rt_ref = residence_times(ref, (start, stop))
        rt_mod = residence_times(pred, (start, stop))
        length = stop - start
        edges, p_ref = rtd_histogram(rt_ref.samples, bin_width, window_length=length)
        _, p_mod = rtd_histogram(rt_mod.samples, bin_width, window_length=length)
        for name, rt in (("reference", rt_ref), ("model", rt_mod)):
            if rt.count < 2:
                warnings.append(f"{name}: {rt.count} residence-time sample(s) in the window; "
                                "E(RT), SD(RT) or the RTD are undefined (a longer window helps)")
        if p_ref.sum() > 0 and p_mod.sum() > 0:
            md = minkowski_distance(p_ref, p_mod, md_order)
        else:
            md = float("nan")
        if rt_ref.exact != rt_mod.exact:
            warnings.append("residence times use exact pass events on one side and frame times "
                            "on the other")

        # mixing (SPEC section 4)
        t_ref, f_ref = mixing_curve_of(ref, (start, stop))
        t_mod, f_mod = mixing_curve_of(pred, (start, stop))
        rms = mixing_rms(t_ref, f_ref, t_mod, f_mod)
        x_ref = ref.positions(ref_frames.start)[:, 0]
        x_mod = pred.positions(pred_frames.start)[:, 0]
        purple_ref, purple_mod = x_ref < 0.5 * ref.width, x_mod < 0.5 * pred.width
        same_purple = np.array_equal(purple_ref[np.argsort(ref.ids)],
                                     purple_mod[np.argsort(pred.ids)])
        if not same_purple:
            warnings.append("the two files' first frames of the window disagree on which "
                            "particles are purple (x < W/2): the prediction did not start from "
                            "the reference's state at the window start")

        summary: dict[str, Any] = {
            "window": [start, stop],
            "reference": _side(rt_ref, ref, ref_frames, float(f_ref[0])),
            "model": _side(rt_mod, pred, pred_frames, float(f_mod[0])),
            "pd_rt_mean": percentage_difference(rt_mod.mean, rt_ref.mean),
            "pd_rt_sd": percentage_difference(rt_mod.sd, rt_ref.sd),
            "md_rtd": md,
            "md_order": float(md_order),
            "mixing_rms": rms,
            "bin_width": float(bin_width),
            "rtd_bins": {"from": 0.0, "to": float(edges[-1]), "count": int(edges.size - 1)},
            "exact_events": {"reference": rt_ref.exact, "model": rt_mod.exact},
            "mixing_frames": int(t_mod.size),
            "same_purple_particles": bool(same_purple),
            "model_columns": columns,
            "units": {"time": "s", "pd": "%", "mixing_rms": "fraction of all particles"},
        }

        out.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(FileNotFoundError):   # never leave a stale summary beside
            (out / SUMMARY).unlink()                     # figures of this run
        written: list[str] = []
        if figures:
            from cfbmarkov.report import figures as fg

            labels = (f"{ref.source} (reference)", f"{pred.source} (model)")
            fg.plot_rtd(edges, p_ref, p_mod, {"mean": rt_ref.mean, "sd": rt_ref.sd,
                                              "count": rt_ref.count},
                        {"mean": rt_mod.mean, "sd": rt_mod.sd, "count": rt_mod.count},
                        out / "rtd.png", labels=labels,
                        title=f"Residence-time distribution, window {start:g}-{stop:g} s "
                              f"(bins {bin_width:g} s; MD = {md:.3g}, order {md_order:g})")
            written.append("rtd.png")
            snaps = _snapshot_indices(ref, pred, start, stop)
            if snaps:
                fg.plot_snapshots(np.stack([ref.positions(i) for _, i, _ in snaps]),
                                  np.stack([pred.positions(j) for _, _, j in snaps]),
                                  purple_ref, purple_mod, [t for t, _, _ in snaps],
                                  ref.width, ref.height, out / "snapshots.png", labels=labels)
                written.append("snapshots.png")
            else:
                warnings.append("snapshots skipped: no frame at the window start + 0, 0.1, ... "
                                "0.7 s on both sides")
            fg.plot_mixing(t_ref, f_ref, t_mod, f_mod, out / "mixing.png", labels=labels,
                           well_mixed=float(f_ref[0]) ** 2,
                           title=f"Radial mixing from {start:g} s (RMS difference {rms:.3g})")
            written.append("mixing.png")
            written += _model_figures(pred, out, rt_ref.mean, warnings)
        summary["figures"] = written
        summary["warnings"] = warnings
    write_text_atomic(out / SUMMARY, json.dumps(_jsonable(summary), indent=2, allow_nan=False)
                      + "\n")
    return summary


__all__ = ["compare", "model_columns"]
