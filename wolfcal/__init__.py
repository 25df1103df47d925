"""wolfcal: kinematic calibration of humanoid robots (camera intrinsics, pose capture, fitting, evaluation)."""

__version__ = "0.1.0"
