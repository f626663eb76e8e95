"""CFD-DEM of the 2D periodic riser: DEM engine (:mod:`.dem`), gas phase (:mod:`.cfd`), the
coupling kernels (:mod:`.coupling`), the coupled riser (:mod:`.riser`) and the run loop
(:mod:`.run`, with :mod:`.checkpoint` and :mod:`.progress`)."""
