"""`wolfcal plan`: the few calibration poses that tell the most."""
