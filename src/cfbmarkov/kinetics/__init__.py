"""Kinetics of particle properties carried along particle paths: rate laws, their
parameters per cell and per state (``docs/definitions.md``, Properties along particle
paths). No I/O but reading a kinetics file; the chain's exact answers are
:mod:`cfbmarkov.markov.kinetics_exact`, the Monte Carlo :mod:`cfbmarkov.markov.kinetics_mc`.
"""

from cfbmarkov.kinetics.fields import (FIELDS, ByCell, CellFields, CellParameter, Constant,
                                       FromField, wall_cells)
from cfbmarkov.kinetics.laws import (LAWS, Custom, Deactivation, FirstOrder, HeatExchange, Law,
                                     affine_map)
from cfbmarkov.kinetics.spec import STARTS, Kinetics, Property, StateKinetics, load_kinetics

__all__ = ["FIELDS", "LAWS", "STARTS", "ByCell", "CellFields", "CellParameter", "Constant",
           "Custom", "Deactivation", "FirstOrder", "FromField", "HeatExchange", "Kinetics",
           "Law", "Property", "StateKinetics", "affine_map", "load_kinetics", "wall_cells"]
