"""RoboCup field lines: the field model, rendered views for simulation, and line detection in camera images."""
