"""Beyond the paper: the report's section on memory states and lag diagnostics (implied
timescales against lag, Chapman-Kolmogorov tests, and why the automatic model chose its
state space and lag). The diagnostics are computed by :mod:`cfbmarkov.markov.diagnostics`
on the fitting window; this module draws them and writes their blocks.

References
----------
docs/definitions.md, section "states and transitions".
"""

from __future__ import annotations

from pathlib import Path

from cfbmarkov.analysis.reproduction import reading_errors
from cfbmarkov.errors import InputError
from cfbmarkov.report.document import FigureBlock, Heading, Para, Table, number_text


def diagnostics_blocks(done, figures_dir: Path, written: list[str]) -> list:
    """Beyond the paper: memory states and lag diagnostics of each finished case.

    Why the automatic model chose its state space and lag, implied timescales against lag,
    and the Chapman-Kolmogorov test of each model on height thirds and core/annulus, all on
    the fitting window.

    Parameters
    ----------
    done : list of cfbmarkov.report.run_folder.Case
        The finished cases, sorted by U.
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
        When a model file cannot be read (named in the message).
    """
    from cfbmarkov.markov import MarkovModel, discretize
    from cfbmarkov.markov.diagnostics import (core_annulus, ck_test, height_bands,
                                              implied_timescales)
    from cfbmarkov.markov.states import CellGrid
    from cfbmarkov.markov.selection_table import candidate_columns
    from cfbmarkov.report.diagnostics import plot_ck_test, plot_implied_timescales
    from cfbmarkov.trajectories import Trajectories

    blocks: list = [Heading(2, "Beyond the paper: memory states and lag diagnostics"),
                    Para("The paper's chain on cells forgets how a particle was moving; the "
                          "'auto' model chooses a state space with memory (direction, "
                          "velocity bins, previous cell or flow regime) on the fitting "
                          "window alone: the one whose exact RTD is closest to the window's "
                          "own or, where the window holds too few residences, by the "
                          "Chapman-Kolmogorov test on held-out blocks (docs/method.md). "
                          "Implied timescales that "
                          "change with the lag, and Chapman-Kolmogorov errors, show the memory "
                          "a chain on cells misses.")]
    ck_rows = []
    formulas: set[str] = set()
    for c in done:
        m = c.config.markov
        window = tuple(float(v) for v in m.fit_window)
        auto_path = c.path / "model-auto.h5"
        models = {}
        for e in c.finished:
            with reading_errors(e.model):
                models[e.name] = MarkovModel.load(e.model)
        if auto_path.is_file() and "auto" in models and models["auto"].selection:
            sel = models["auto"].selection
            blocks.append(Heading(3, f"{c.label}: the automatic choice"))
            blocks.append(Para(f"Chosen: {sel.get('reason', 'n/a')}."))
            headers, rows, notes = candidate_columns(sel)
            if rows:
                parts = ", ".join(f"{x:g}-{y:g} s" for x, y in sel.get("blocks", []))
                fitted = (f"Each candidate fitted on the fitting window {window[0]:g}-"
                          f"{window[1]:g} s" if sel.get("method") ==
                          "the RTD over the fitting window" else
                          f"{sel.get('method', 'cross-validation')} over the blocks {parts}")
                headers[0] = "chosen"
                # the score's definition once, under the first table that uses it
                formula = notes[0] if notes and notes[0].startswith("score =") else ""
                said = formula in formulas
                formulas.add(formula)
                blocks.append(Table(headers, rows,
                                    [f"{fitted}; " + ("the columns and score as above." if said
                                                      else "S: states; visited: states "
                                                      "occupied in the fitting window"
                                                      + (f"; {formula}." if formula else ".")),
                                     *notes[1 if formula else 0:]]))
        with reading_errors(c.reference), Trajectories(c.reference) as ref:
            lags = [m.lag * k for k in (1, 2, 4)]
            grid = CellGrid(m.columns, m.rows, ref.width, ref.height)
            try:
                its = implied_timescales(ref, grid, lags, window=window, k=4)
            except (InputError, ValueError) as exc:
                blocks.append(Para(f"{c.label}: implied timescales not computed ({exc})."))
                its = None
            if its is not None:
                name = f"its-{c.name}.png"
                plot_implied_timescales(its, figures_dir / name,
                                        title=f"Implied timescales, cells, {c.label}")
                written.append(name)
                slow = its.timescales[:, 0]
                trend = " → ".join(f"{t:.3g} s" for t in slow)
                blocks.append(FigureBlock(name, f"Implied timescales against lag, {c.label}",
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
                                f"{model.lag:g}", number_text(b["max_abs_error"], ".3f"),
                                number_text(r["max_abs_error"], ".3f")])
                if name_m == ("auto" if "auto" in models else "paper"):
                    fig = f"ck-{c.name}.png"
                    plot_ck_test(bands, figures_dir / fig,
                                 title=f"Chapman-Kolmogorov test, {name_m} model, {c.label}")
                    written.append(fig)
                    blocks.append(FigureBlock(fig, f"Chapman-Kolmogorov test on height thirds, "
                                            f"{name_m} model, {c.label}",
                                       f"Probability to be in each third of the riser k lags "
                                       f"after being in it: data of the fitting window "
                                       f"(points) against P^k of the {name_m} model (lines); "
                                       f"largest difference {b['max_abs_error']:.2g}."))
    if ck_rows:
        blocks.append(Heading(3, "Chapman-Kolmogorov errors"))
        blocks.append(Table(["case", "model", "states", "lag (s)",
                              "max |error|, height thirds", "max |error|, core/annulus"],
                             ck_rows,
                             ["Max over 1-4 lags and all group pairs of |P_model(A→B, kτ) − "
                              "P_data(A→B, kτ)|, on the fitting window."]))
    return blocks


__all__ = ["diagnostics_blocks"]
