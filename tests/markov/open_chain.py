"""A known open chain on a cell grid, and trajectories drawn from it: particles enter
through the bottom row (new ids), move by the chain, leave through the top (test helper)."""

from __future__ import annotations

import numpy as np

W, H = 0.09, 0.95


def open_chain(columns: int = 6, rows: int = 38, up: float = 0.55, stay: float = 0.3,
               side: float = 0.05):
    """(Q [S, S] sub-stochastic, r [S] exit probabilities, e [S] entry distribution).

    From cell (row, col): up a row with ``up``, stay with ``stay``, down with the rest less
    the sideways moves (``side`` each way, reflected at the walls); down from the bottom row
    stays; up from the top row leaves through the outlet."""
    s = columns * rows
    q = np.zeros((s, s))
    r = np.zeros(s)
    down = 1.0 - up - stay - 2 * side
    for row in range(rows):
        for col in range(columns):
            i = row * columns + col
            if row + 1 < rows:
                q[i, i + columns] += up
            else:
                r[i] += up
            q[i, i] += stay
            q[i, (row - 1) * columns + col if row > 0 else i] += down
            for dc in (-1, 1):
                c = min(max(col + dc, 0), columns - 1)
                q[i, row * columns + c] += side
    e = np.zeros(s)
    e[:columns] = 1.0 / columns
    return q, r, e


def draw(q, r, e, *, n_steps: int, inflow: float, n_start: int, seed: int, columns: int = 6,
         rows: int = 38):
    """Frames of the open chain: (states [T, N] with -1 absent, ids [N]). Particles present
    at the start are spread over the riser; each step a Poisson(``inflow``) number enters
    with a state drawn from ``e``."""
    rng = np.random.default_rng(seed)
    s = q.shape[0]
    cumulative = np.cumsum(np.concatenate([q, r[:, None]], axis=1), axis=1)
    entries = rng.poisson(inflow, size=n_steps)
    n = n_start + int(entries[1:].sum())
    states = np.full((n_steps, n), -1, dtype=np.int64)
    states[0, :n_start] = rng.integers(0, s, n_start)
    born = np.concatenate([np.zeros(n_start, int), np.repeat(np.arange(1, n_steps), entries[1:])])
    for k in range(1, n_steps):
        prev = states[k - 1]
        alive = prev >= 0
        u = rng.random(alive.sum())
        nxt = (u[:, None] > cumulative[prev[alive]]).sum(axis=1)
        nxt[nxt == s] = -1                      # through the outlet
        states[k, alive] = nxt
        new = born == k
        states[k, new] = rng.choice(s, size=new.sum(), p=e)
    return states, np.arange(1, n + 1)


def positions_of(states, seed: int, columns: int = 6, rows: int = 38):
    """Positions uniform in each state's cell, NaN where absent [T, N, 2] (m)."""
    rng = np.random.default_rng(seed)
    col, row = states % columns, states // columns
    x = (col + rng.random(states.shape)) * (W / columns)
    y = (row + rng.random(states.shape)) * (H / rows)
    pos = np.stack([x, y], axis=-1)
    pos[states < 0] = np.nan
    return pos


def lammps_dump(times, ids, positions, step: float) -> str:
    """A LAMMPS text dump with `ff ff pp` bounds (open y), one frame per time, absent atoms
    left out (deleted at the outlet, not yet inserted)."""
    out = []
    for k, t in enumerate(times):
        here = np.flatnonzero(np.isfinite(positions[k, :, 0]))
        out.append(f"ITEM: TIMESTEP\n{int(round(t / step))}\nITEM: NUMBER OF ATOMS\n{here.size}\n"
                   f"ITEM: BOX BOUNDS ff ff pp\n0 {W}\n0 {H}\n-0.0005 0.0005\n"
                   "ITEM: ATOMS id type x y z\n")
        out.append("".join(f"{ids[p]} 1 {float(positions[k, p, 0])!r} {float(positions[k, p, 1])!r} 0\n"
                           for p in here))
    return "".join(out)
