"""Gas phase of the CFD-DEM riser: staggered-grid solver, drag law, grid-particle transfers.

Modules: :mod:`.grid` (the staggered grid), :mod:`.solver` (the gas step), :mod:`.momentum`
(advection, viscous term, stability), :mod:`.pressure` (the projection), :mod:`.state`
(:class:`GasState`), :mod:`.drag` (drag law), :mod:`.coupling` (grid <-> particles).

Typical use (the coupling calls ``step`` once per gas step)::

    from cfbmarkov.simulate.cfd import GasGrid, GasSolver
    grid = GasGrid(nx=9, ny=95, width=0.09, height=0.95)
    solver = GasSolver(grid, density=1.205, viscosity=1.8e-5, superficial_velocity=6.0,
                       gravity=9.81, time_step=5e-5)
    state = solver.initial_state(void_fraction)
    state = solver.step(state, new_void_fraction, drag_u, drag_v)   # returns a new state
"""

import cfbmarkov  # noqa: F401  (sets the numba threading layer before anything compiles)
from cfbmarkov.simulate.cfd.coupling import (
    VOID_FRACTION_FLOOR,
    deposit_drag,
    deposit_drag_jacobian,
    deposit_drag_reaction,
    deposit_solid_volume,
    gas_velocity_at,
    interpolate_gas_velocity,
    void_fraction_field,
)
from cfbmarkov.simulate.cfd.drag import (
    drag_coefficient,
    interphase_momentum_coefficient,
    minimum_fluidization_velocity,
    particle_drag_force,
    particle_drag_jacobian,
    particle_reynolds_number,
    terminal_velocity,
)
from cfbmarkov.simulate.cfd.grid import GasGrid
from cfbmarkov.simulate.cfd.momentum import gas_stability_limit, momentum_tendency
from cfbmarkov.simulate.cfd.solver import GasSolver, PressureSolveError
from cfbmarkov.simulate.cfd.state import GasState, continuity_residual, cross_section_flux

__all__ = [
    "GasGrid",
    "GasSolver",
    "GasState",
    "PressureSolveError",
    "VOID_FRACTION_FLOOR",
    "continuity_residual",
    "cross_section_flux",
    "deposit_drag",
    "deposit_drag_jacobian",
    "deposit_drag_reaction",
    "deposit_solid_volume",
    "drag_coefficient",
    "gas_stability_limit",
    "gas_velocity_at",
    "interphase_momentum_coefficient",
    "interpolate_gas_velocity",
    "minimum_fluidization_velocity",
    "momentum_tendency",
    "particle_drag_force",
    "particle_drag_jacobian",
    "particle_reynolds_number",
    "terminal_velocity",
    "void_fraction_field",
]
