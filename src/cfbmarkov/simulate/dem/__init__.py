"""2D DEM engine (discs with sphere mass, linear spring-dashpot contacts with tangential
history, walls at x = 0 and W, periodic in y); see :mod:`.system` (kernels in
:mod:`.contact`, :mod:`.neighbours`, :mod:`.integrate`, :mod:`.stepping`, :mod:`.order`; data
layout in :mod:`~cfbmarkov.simulate.dem.layout`)."""

from cfbmarkov.simulate.dem.law import ContactLaw, ContactTimes, damping_ratio
from cfbmarkov.simulate.dem.system import DEMSystem, SimulationBlowUp

__all__ = ["ContactLaw", "ContactTimes", "DEMSystem", "SimulationBlowUp", "damping_ratio"]
