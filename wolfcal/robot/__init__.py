"""Robot model: URDF kinematics, corrections, free-parameter sets, calibrated-URDF writer."""
