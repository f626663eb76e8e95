"""Fluidized bed on a floor: time-averaged gas pressure drop against the bed weight.

    python benchmarks/fluidized_bed.py [PARTICLES] [U m/s] [SECONDS] [HEIGHT m] [CELL m] [WIDTH m]
                                       [DISTRIBUTOR]

DISTRIBUTOR is the distributor's pressure drop at U as a fraction of the bed weight per unit
cross-section (default 0.3; 0: none); the bed's pressure drop excludes it.

Prints, every 0.1 s of simulated time, the pressure drop over the period divided by the
bed weight per unit cross-section (block mean and running mean from 0.3 s), and the share
of the weight the floor and the side walls carried in the block (their impulse on the
particles over the block's weight impulse). A fluidized bed should carry its weight (ratio
1); without a distributor plate the gas channels through one loose column and the floor
carries 5-20 % (``docs/simulation.md`` has the measured table). With the plate at 0.3:
8000 particles, 1.6 m/s, 4 s, 0.3 m: dp / weight 0.985, floor 2.0 %; 4000 particles, 1.3 m/s,
2 s, 0.25 m, 1 cm cells, 6 cm wide (the pytest case): 0.985, floor 2.4 %.
"""

import argparse
import time
import warnings

import numpy as np

from cfbmarkov.config import CaseConfig
from cfbmarkov.simulate.coupling import hexagonal_bed
from cfbmarkov.simulate.riser import CoupledRiser


def main(n: int = 8000, u: float = 1.6, duration: float = 1.6, height: float = 0.3,
         cell: float = 0.01, width: float = 0.09, distributor: float = 0.3) -> None:
    d = 1e-3
    weight = n * 2600.0 * np.pi * d**3 / 6 * 9.81 / (width * d)
    case = CaseConfig.model_validate({
        "riser": {"width": width, "height": height,
                  "distributor_pressure_drop": distributor * weight},
        "particles": {"number": n},
        "gas": {"superficial_velocity": u},
        "numerics": {"cfd_cells": [int(round(width / cell)), int(round(height / cell))],
                     "dem_cells": [int(width / 0.003), int(height / 0.0027)]}})
    pos = hexagonal_bed(n, d, width)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        riser = CoupledRiser.from_particles(case, pos, np.zeros_like(pos), bottom_wall=True)
    weight = n * case.particles.mass * case.riser.gravity / (width * d)
    rho_g_g = case.gas.density * case.riser.gravity
    ratios = []
    block = int(round(0.1 / case.numerics.cfd_time_step))
    block_weight_impulse = n * case.particles.mass * case.riser.gravity * 0.1
    riser.dem.reset_wall_impulse()
    start = time.perf_counter()
    for k in range(int(round(duration / case.numerics.cfd_time_step))):
        riser.step()
        gas = riser.gas
        ratios.append(((gas.driving_pressure_gradient - rho_g_g * gas.void_fraction.mean())
                       * height - gas.distributor_pressure_drop) / weight)
        if (k + 1) % block == 0:
            settled = ratios[3 * block:]
            running = np.mean(settled) if settled else float("nan")
            walls, floor = riser.dem.wall_impulse
            riser.dem.reset_wall_impulse()
            print(f"t = {riser.time:.2f} s: dp/weight {np.mean(ratios[-block:]):.3f} "
                  f"(mean from 0.3 s {running:.3f}), floor {floor / block_weight_impulse:.3f}, "
                  f"walls {walls / block_weight_impulse:.3f}, "
                  f"wall time {time.perf_counter() - start:.0f} s", flush=True)


def _arguments(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    for name, kind, default, text in (
            ("particles", int, 8000, "particles"), ("u", float, 1.6, "gas velocity, m/s"),
            ("seconds", float, 1.6, "simulated time, s"), ("height", float, 0.3, "bed box, m"),
            ("cell", float, 0.01, "gas cell, m"), ("width", float, 0.09, "bed width, m"),
            ("distributor", float, 0.3, "distributor drop / bed weight")):
        p.add_argument(name, type=kind, nargs="?", default=default,
                       help=f"{text} (default {default:g})")
    return p.parse_args(argv)


if __name__ == "__main__":
    a = _arguments()
    main(a.particles, a.u, a.seconds, a.height, a.cell, a.width, a.distributor)
