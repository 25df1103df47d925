"""wolfcal.vision: tag geometry and detection (`tags`), rendering of planar targets for simulation (`render`)."""
