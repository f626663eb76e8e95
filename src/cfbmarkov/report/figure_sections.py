"""The report's sections with figures: the paper's Fig. 3-11 and the plausibility of the
CFD-DEM. Each builder draws its PNGs into the figures folder (appending their names to
``written``) and returns its document blocks; the numbers come from
:mod:`cfbmarkov.analysis.reproduction`.

Choices:

- Figures 4-7 are numbered by the position of the case among all cases sorted by U (4, 5,
  6, 7) when there are at most four cases; with more cases a case at one of the paper's U
  (3, 4, 6, 8 m/s) takes the paper's number and any other case the number of the paper's
  nearest U (the file name always carries the case name).
- Fig. 3 and Fig. 4-7 use the ``paper`` estimator's model (else the first finished one, and
  the caption says so). Batch-injection times that are not whole multiples of the model's
  lag are rounded to the nearest whole lag (at least one) and the caption says so.
- In Fig. 10-11 the left tracer group (x < W/2 at the window start) is drawn purple.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np

from cfbmarkov._atomic import atomic_path
from cfbmarkov.analysis.figure_inputs import SNAPSHOT_OFFSETS
from cfbmarkov.analysis.reproduction import (
    RunMeasures,
    batch_injection,
    implied_vertical_velocity,
    paper_map_times,
    wall_zone_weights,
    zone_mean,
)
from cfbmarkov.report.document import FigureBlock, Heading, Para, link, number_text
from cfbmarkov.report.figures import plot_probability_maps
from cfbmarkov.report.summary import CONDITIONS_HEADING
from cfbmarkov.report.paper_figures import (
    CFD_DEM_COLOUR,
    estimator_colour,
    plot_mixing_grid,
    plot_plausibility,
    plot_rtd_grid,
    plot_transition_heatmaps_grid,
)
from cfbmarkov.report.run_folder import Case, input_error
from cfbmarkov.report.sections import shared_text, window_text

#: the paper's batch-injection figure of each of its velocities (Fig. 4-7)
PAPER_MAP_FIGURE: dict[float, int] = {3.0: 4, 4.0: 5, 6.0: 6, 8.0: 7}
#: Fig. 10 is drawn at this velocity (m/s), or the case nearest to it
SNAPSHOT_VELOCITY = 6.0
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def fig3_blocks(done, measures, figures_dir: Path, written: list[str]) -> list:
    """Fig. 3: the transition matrices of all finished cases as heat maps.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.
    figures_dir : pathlib.Path
        Folder the PNGs are written into.
    written : list of str
        Receives the file names of the PNGs written.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`).

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 3.
    """
    name = "fig03-transition-matrices.png"
    panels, velocities = [], []
    for c in done:
        measured = measures[c.name]
        model = measured.model
        space = model.state_space
        suffix = "" if measured.model_name == "paper" else f", {measured.model_name} estimator"
        rows = np.asarray(space.cell_of_state) // space.cells_per_row
        panels.append((f"{c.label}{suffix}: {space.describe()}",
                       np.asarray(model.transition_matrix), rows, int(space.rows)))
        velocities.append((c, implied_vertical_velocity(model)))
    plot_transition_heatmaps_grid(panels, figures_dir / name,
                                  "Fig. 3: transition probability matrices")
    written.append(name)
    vel = ", ".join(f"{v:+.2f} m/s at {c.label}" for c, v in velocities)
    sentence = (f"Each panel shows the transition matrix of one velocity as a heat map, from "
                f"state i (down) to state j (across), zeros blank (the paper draws it as 3D "
                f"bars); the stationary mean vertical particle velocity implied by P is {vel}"
                + (", rising with U." if len(velocities) > 1 and all(
                    b[1] > a[1] for a, b in zip(velocities, velocities[1:])) else "."))
    return [Heading(2, "Fig. 3: Transition probability matrices"),
            FigureBlock(name, "Fig. 3: transition probability matrices", sentence)]


def map_numbers(cases: list[Case]) -> dict[str, int]:
    """Figure number (4-7) of each case's batch-injection maps.

    With at most four cases, by position among the cases sorted by U (4, 5, 6, 7); with
    more, the number of the paper's nearest U (3, 4, 6, 8 m/s; 7 when U is not finite).

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U.

    Returns
    -------
    dict of str to int
        Figure number by case name.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 4-7.
    """
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


def maps_blocks(cases, done, measures, figures_dir: Path, written: list[str]) -> list:
    """Fig. 4-7: batch-injection probability maps of each finished case.

    Parameters
    ----------
    cases : list of cfbmarkov.report.run_folder.Case
        All cases of the run, sorted by U (they number the figures, :func:`map_numbers`).
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.
    figures_dir : pathlib.Path
        Folder the PNGs are written into.
    written : list of str
        Receives the file names of the PNGs written.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`).

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Eqs. 5-6 and 8, Figs. 4-7.
    """

    numbers = map_numbers(cases)
    blocks = [Heading(2, "Fig. 4–7: Batch-injection probability maps"),
              Para("A batch fed evenly over the inlet cells at t = 0 (Eq. 8), propagated by "
                    "S(t + lag) = S(t) P (Eq. 5-6); probability per cell at the paper's times "
                    "(0.25, 0.5, 0.75 s below 3.5 m/s, else 0.05, 0.10, 0.15 s).")]
    for c in done:
        measured = measures[c.name]
        model = measured.model
        number = numbers[c.name]
        wanted, used, rounded = paper_map_times(c.velocity, model.lag)
        batch = batch_injection(model, used)
        name = f"fig{number:02d}-maps-{c.name}.png"
        space = model.state_space
        plot_probability_maps(
            batch.maps, used, space.width, space.height, figures_dir / name,
            title=f"Fig. {number}: batch fed over the inlet at t = 0, {c.label}\n"
                  f"{measured.model_name} estimator, {space.describe()}, lag {model.lag:g} s")
        written.append(name)
        down = any((e.summary or {}).get("direction") == "down" for e in c.finished)
        sentence = (f"At t = {', '.join(f'{t:g}' for t in used)} s the mean height of the part of "
                    f"the batch that has not yet passed up through the top is "
                    f"{', '.join(f'{h:.2f}' for h in batch.mean_heights)} m (riser {space.height:g} m high); "
                    f"{100 * batch.left_share:.1f} % of the batch has passed up through the top by "
                    f"{used[-1]:g} s"
                    + (f", and {100 * batch.fallen_share:.1f} % has fallen through the bottom "
                       "(the direction the solids' net flow takes here)"
                       if down and batch.fallen_share is not None else "")
                    + ". The riser is periodic, so nothing leaves it: the maps, like "
                    "the paper's, show what passes the top wrapped to the bottom"
                    + (", and what falls through the bottom wrapped to the top." if down
                       else "."))
        if rounded:
            sentence += (f" The paper's times {', '.join(f'{t:g}' for t in wanted)} s are not "
                         f"whole multiples of the lag {model.lag:g} s and were rounded to the "
                         "nearest whole lag.")
        paper_u = [u for u, n in PAPER_MAP_FIGURE.items() if n == number]
        if paper_u and not math.isclose(paper_u[0], c.velocity):
            sentence += f" (The paper's Fig. {number} is at U = {paper_u[0]:g} m/s.)"
        blocks += [Heading(3, f"Fig. {number}: {c.label} ({c.name})"),
                   FigureBlock(name, f"Fig. {number}: batch-injection maps, {c.label}", sentence)]
    return blocks


def rtd_blocks(done, measures, estimators, figures_dir: Path, written: list[str]) -> list:
    """Fig. 8-9: RTDs of the CFD-DEM and of each estimator's prediction.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.
    estimators : list of str
        The estimators of the run, in report order.
    figures_dir : pathlib.Path
        Folder the PNGs are written into.
    written : list of str
        Receives the file names of the PNGs written.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`).

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Figs. 8-9.
    """
    panels8, panels9 = [], []
    for c in done:
        measured = measures[c.name]
        panels8.append((c.label, measured.edges,
                        [("CFD-DEM", measured.reference.prob, measured.reference.rt, CFD_DEM_COLOUR, True)]))
        series = [("CFD-DEM (Fig. 8)", measured.reference.prob, measured.reference.rt, "0.7", True)]
        series += [(f"MCM, {n}", side.prob, side.rt, estimator_colour(n, estimators), False)
                   for n, side in measured.models.items()]
        panels9.append((c.label, measured.edges, series))
    window_texts = shared_text({c.name: window_text(measures[c.name].window) for c in done})
    plot_rtd_grid(panels8, figures_dir / "fig08-rtd-cfd-dem.png",
                   f"Fig. 8: residence-time distributions of the CFD-DEM, window {window_texts}")
    plot_rtd_grid(panels9, figures_dir / "fig09-rtd-mcm.png",
                   f"Fig. 9: residence-time distributions of the MCM, window {window_texts}")
    written += ["fig08-rtd-cfd-dem.png", "fig09-rtd-mcm.png"]

    sds = [(c, measures[c.name].reference.rt.sd) for c in done
           if math.isfinite(measures[c.name].reference.rt.sd)]
    means = ", ".join(f"{number_text(measures[c.name].reference.rt.mean, '.3f')} s at {c.label}"
                      for c in done)
    if len(sds) > 1:
        widest = max(sds, key=lambda x: x[1])
        narrowest = min(sds, key=lambda x: x[1])
        s8 = (f"The CFD-DEM RTD is widest at {widest[0].label} (SD(RT) = {widest[1]:.3f} s) and "
              f"narrowest at {narrowest[0].label} ({narrowest[1]:.3f} s); E(RT) is {means}.")
    else:
        s8 = f"The CFD-DEM RTD has E(RT) = {means}."
    s9 = ("The MCM RTDs against the CFD-DEM's (grey); their means and spreads, and the "
          "paper's, are in Table 3 and the summary.")
    return [Heading(2, "Fig. 8: RTD of the CFD-DEM"),
            FigureBlock("fig08-rtd-cfd-dem.png", "Fig. 8: CFD-DEM residence-time distributions", s8),
            Heading(2, "Fig. 9: RTD of the MCM"),
            FigureBlock("fig09-rtd-mcm.png", "Fig. 9: MCM residence-time distributions", s9)]


def snapshot_blocks(done, measures, figures_dir: Path, written: list[str]) -> list:
    """Fig. 10: the particle snapshots of the case nearest to U = 6 m/s.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.
    figures_dir : pathlib.Path
        Folder the PNGs are written into.
    written : list of str
        Receives the file names of the PNGs written.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`).

    Raises
    ------
    InputError
        When the copied ``compare-*/snapshots.png`` is not a PNG image.

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 10.
    """
    name = "fig10-snapshots.png"
    blocks: list = [Heading(2, "Fig. 10: Particle snapshots")]
    candidates = []
    for c in done:
        for e in c.finished:
            png = e.compare_dir / "snapshots.png"
            if png.is_file():
                candidates.append((abs(c.velocity - SNAPSHOT_VELOCITY), c.velocity, c, e, png))
                break
    if not candidates:
        blocks.append(Para("Not available: no finished case has a compare-*/snapshots.png.",
                            css="warn"))
        return blocks
    _, _, c, e, png = min(candidates, key=lambda x: (x[0], x[1]))
    if png.read_bytes()[:8] != PNG_SIGNATURE:
        raise input_error(png, "not a PNG image")
    with atomic_path(figures_dir / name, suffix=".png") as tmp:
        shutil.copyfile(png, tmp)
    written.append(name)
    measured = measures[c.name]
    t0, t1 = measured.window
    # the last snapshot compare drew: start + 0, 0.1, ... 0.7 s within the window
    at = t0 + max(o for o in SNAPSHOT_OFFSETS if t0 + o <= t1 + 1e-9 * max(1.0, abs(t1)))
    ref, mod = measured.reference, measured.models[e.name]

    def _at(side: RunMeasures) -> str:
        """The mixing curve of ``side`` at the end of the snapshots, or n/a."""
        if side.mix_t.size == 0 or at > side.mix_t[-1] + 1e-9:
            return "n/a"
        return f"{float(np.interp(at, side.mix_t, side.mix_f)):.3f}"

    sentence = (f"Snapshots at {c.label} (nearest to the paper's {SNAPSHOT_VELOCITY:g} m/s) from "
                f"{t0:g} to {at:g} s, CFD-DEM above and MCM ({e.name}) below, purple = x < W/2 at "
                f"{t0:g} s; the share of all particles that are purple and in the left half goes "
                f"from {number_text(ref.mix_f[0] if ref.mix_f.size else None, '.3f')} to {_at(ref)} "
                f"(CFD-DEM) and {_at(mod)} (MCM) by {at:g} s.")
    blocks.append(FigureBlock(name, f"Fig. 10: particle snapshots, {c.label}", sentence))
    return blocks


def mixing_blocks(done, measures, estimators, figures_dir: Path, written: list[str]) -> list:
    """Fig. 11: mixing curves of the CFD-DEM and of each estimator's prediction.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.
    estimators : list of str
        The estimators of the run, in report order.
    figures_dir : pathlib.Path
        Folder the PNGs are written into.
    written : list of str
        Receives the file names of the PNGs written.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`).

    References
    ----------
    Y. Zhuang, Processes 13(3), 614 (2025), doi:10.3390/pr13030614, Fig. 11.
    """
    name = "fig11-mixing.png"
    panels, parts = [], []
    for c in done:
        measured = measures[c.name]
        f0 = float(measured.reference.mix_f[0]) if measured.reference.mix_f.size else math.nan
        series = [("CFD-DEM", measured.reference.mix_t, measured.reference.mix_f, CFD_DEM_COLOUR, 1.1)]
        series += [(f"MCM, {n}", s.mix_t, s.mix_f, estimator_colour(n, estimators), 1.6)
                   for n, s in measured.models.items()]
        panels.append((c.label, series, f0 * f0))
        end = float(measured.reference.mix_f[-1]) if measured.reference.mix_f.size else math.nan
        rms = [number_text(e.summary.get("mixing_rms"), ".3g") for e in c.finished]
        level = ("" if not (math.isfinite(end) and math.isfinite(f0)) else
                 " (at it)" if abs(end - f0 * f0) <= 0.01 else
                 " (above it)" if end > f0 * f0 else " (below it)")
        parts.append(f"{c.label}: CFD-DEM starts at f0 = {f0:.3f} and ends at {end:.3f} against a "
                     f"well-mixed {f0 * f0:.3f}{level}, RMS difference {', '.join(rms)} "
                     f"({', '.join(e.name for e in c.finished)})")
    plot_mixing_grid(panels, figures_dir / name,
                      "Fig. 11: purple particles in the left half of the riser / all particles")
    written.append(name)
    return [Heading(2, "Fig. 11: Radial mixing"),
            FigureBlock(name, "Fig. 11: radial mixing curves",
                 "Share of all particles that are purple (x < W/2 at the window start) and in the "
                 "left half, CFD-DEM against each estimator; " + "; ".join(parts) + ". A curve "
                 "starts at f0, the share of all particles in the left half at the window "
                 "start (0.5 only where they are evenly split across the riser), and levels "
                 "off at f0^2 where the purple particles spread evenly and the left half keeps "
                 "its share. Above it, the purple particles are still gathered on their side "
                 "at the window's end (radial mixing incomplete) or the left half holds more "
                 "of all particles than at the start; below it, it holds fewer.")]


def _one_sided_text(done, measures) -> str:
    """The radial profiles' asymmetry, said as what it is: one wall layer denser than the
    other (the outer sixth of the riser on each side), where they differ by more than a
    fifth."""
    sides = []
    for c in done:
        fraction = np.asarray(measures[c.name].solids_fraction, dtype=float)
        left_layer, _, right_layer = wall_zone_weights(fraction.size)
        left, right = zone_mean(fraction, left_layer), zone_mean(fraction, right_layer)
        if (math.isfinite(left) and math.isfinite(right) and max(left, right) > 0
                and abs(left - right) > 0.2 * max(left, right)):
            sides.append(f"{c.label} {left:.3g} at the left wall, {right:.3g} at the right")
    if not sides:
        return ""
    return (" The profiles are one-sided where the solids gather at one wall (solids "
            "fraction " + "; ".join(sides) + "): over this window the flow keeps a "
            "dense layer along one wall. The wall/core figures average both walls; a longer "
            "window or more runs would tell a lasting side from a passing one.")


def plausibility_blocks(done, measures, estimators, figures_dir: Path,
                         written: list[str]) -> list:
    """Plausibility of the CFD-DEM: E(RT) and SD(RT) against U, and radial solids profiles.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
    measures : dict of str to cfbmarkov.analysis.reproduction.CaseMeasures
        The recomputed numbers of each finished case, by case name.
    estimators : list of str
        The estimators of the run, in report order.
    figures_dir : pathlib.Path
        Folder the PNGs are written into.
    written : list of str
        Receives the file names of the PNGs written.

    Returns
    -------
    list
        The section's document blocks (:mod:`cfbmarkov.report.document`).
    """
    name = "plausibility.png"
    u = [c.velocity for c in done]
    means = [measures[c.name].reference.rt.mean for c in done]
    sds = [measures[c.name].reference.rt.sd for c in done]
    model_means = {n: [measures[c.name].models[n].rt.mean if n in measures[c.name].models
                       else math.nan for c in done] for n in estimators
                   if any(n in measures[c.name].models for c in done)}
    profiles = [(c.label, measures[c.name].band_positions, measures[c.name].solids_fraction,
                 measures[c.name].solids_velocity) for c in done]
    flux = [getattr(measures[c.name], "flux_rt_mean", math.nan) for c in done]
    plot_plausibility(u, means, sds, model_means, profiles, figures_dir / name,
                       "Plausibility of the CFD-DEM: residence time against U, core-annulus "
                       "profiles", flux_means=flux)
    written.append(name)
    sentence = ("(a) E(RT) and SD(RT) of the CFD-DEM, and E(RT) of each MCM, against U: "
                "the E(RT) of the residences each predict window holds whole (Table 3's, "
                "which the window's length censors: it can rise where the flow's falls) "
                "and, dotted, the E(RT) from the window's net solids flux, which the physics "
                "check judges; (b) "
                "solids volume fraction and (c) mean vertical solids velocity of the CFD-DEM "
                "across the riser (pseudo-2D, one particle diameter thick), averaged over the "
                "predict window; a core-annulus flow has denser, slower or falling wall layers. "
                "What they show is judged, with the numbers, in the "
                + link("physics checks", CONDITIONS_HEADING) + ".")
    sentence += _one_sided_text(done, measures)
    return [Heading(2, "Plausibility"),
            FigureBlock(name, "Plausibility: E(RT) and SD(RT) against U, radial solids profiles",
                 sentence)]


__all__ = ["PAPER_MAP_FIGURE", "fig3_blocks", "map_numbers", "maps_blocks", "mixing_blocks",
           "plausibility_blocks", "rtd_blocks", "snapshot_blocks"]
