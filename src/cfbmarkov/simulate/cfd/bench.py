"""Timing of the gas phase at the paper's scale: ``python -m cfbmarkov.simulate.cfd.bench``.

Prints one ``name: value unit`` line per figure (the format of ``cfbmarkov bench``).
"""

from __future__ import annotations

import time

import numpy as np

from cfbmarkov.simulate.cfd.coupling import (
    deposit_drag_reaction,
    interpolate_gas_velocity,
    void_fraction_field,
)
from cfbmarkov.simulate.cfd.grid import GasGrid
from cfbmarkov.simulate.cfd.solver import GasSolver


def _median_seconds(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def gas_benchmarks(steps: int = 3000, particles: int = 27000, seed: int = 0) -> dict[str, float]:
    """Median seconds per call on the paper's 9 x 95 grid at U = 6 m/s.

    ``gas_step``: a step whose void fraction changed (re-factorisation every step, as in
    a coupled run); ``gas_step_fixed_void``: the same with an unchanged void fraction;
    ``void_fraction``, ``interpolate``, ``drag_reaction``: the transfers for ``particles``.
    """
    rng = np.random.default_rng(seed)
    grid = GasGrid(nx=9, ny=95, width=0.09, height=0.95)
    solver = GasSolver(grid, superficial_velocity=6.0)
    d = 1e-3
    x = rng.uniform(d / 2, grid.width - d / 2, particles)
    y = rng.uniform(0, grid.height, particles)
    eps = void_fraction_field(grid, x, y, d)
    fu = np.zeros(grid.u_shape)
    fv = 50.0 * (1 - eps)
    state = solver.initial_state(eps)
    for _ in range(100):
        state = solver.step(state, eps, fu, fv)
    eps_b = eps * (1 - 1e-6) + 1e-6
    cur = {"s": state, "k": 0}

    def step_changing():
        cur["k"] += 1
        cur["s"] = solver.step(cur["s"], eps_b if cur["k"] % 2 else eps, fu, fv)

    def step_fixed():
        cur["s"] = solver.step(cur["s"], cur["s"].void_fraction, fu, fv)

    fx = rng.normal(0, 1e-5, particles)
    fy = rng.normal(1e-5, 1e-5, particles)
    return {
        "gas_step": _median_seconds(step_changing, steps),
        "gas_step_fixed_void": _median_seconds(step_fixed, steps),
        "void_fraction": _median_seconds(lambda: void_fraction_field(grid, x, y, d), 200),
        "interpolate": _median_seconds(
            lambda: interpolate_gas_velocity(grid, cur["s"].u, cur["s"].v, x, y), 200),
        "drag_reaction": _median_seconds(
            lambda: deposit_drag_reaction(grid, x, y, fx, fy, d), 200),
    }


def main() -> None:
    for name, seconds in gas_benchmarks().items():
        print(f"{name}: {seconds * 1e6:.1f} us")


if __name__ == "__main__":
    main()
