"""The names of the free-parameter presets (`--free`), and the one every command takes when none is given.

camera: the head camera's frame and the tag mounts (a venue's calibration); head_camera: also the head joints'
encoder offsets; leg: also the legs' encoder offsets (`wolfcal.robot.parameters` builds each set). `fit`, `plan`
and the pipelines that chain them default to DEFAULT_PRESET, so a plan is made for the fit that follows it.
"""

PRESETS = ("camera", "head_camera", "leg")
DEFAULT_PRESET = "camera"
