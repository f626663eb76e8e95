"""CFD-DEM of the 2D periodic riser: DEM engine (:mod:`.dem`), gas phase (:mod:`.cfd`), the
coupling kernels (:mod:`.coupling`) and the run loop (:mod:`.run`)."""
