"""Where an external camera stands: a pose T_base_camera of its optical frame (z forward, x right, y down) in the
robot's base frame [m, rad].

The simulator's random placements (`wolfcal.sim.placement.random_placement`), whose middle a plan expects
(`expected_placement`): a tripod in front of the robot on its stand, at a horizontal distance of `DISTANCE_M` from
base_link's origin, within `AZIMUTH_RAD` of straight ahead (+x of base_link), at a height of
`HEIGHT_M` relative to base_link, looking at `TARGET_BASE` (between the torso tag and the feet, so both are in view)
give or take `TARGET_JITTER_M` per axis, rolled about its viewing axis by up to `ROLL_RAD`.

Given placements (`placement_from_text`, `--placement x,y,z,roll,pitch,yaw`): the position [m] and the URDF
roll-pitch-yaw [rad] of the camera's body frame (x along the viewing direction, y left, z up) in base_link, e.g.
`1.5,0,0,0,0,3.1416`: 1.5 m in front at base height, looking back at the robot.
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.geometry import axis_angle_matrix, transform_from_xyz_rpy

DISTANCE_M = (1.0, 2.0)
AZIMUTH_RAD = (-0.5, 0.5)  # about +-29 deg
HEIGHT_M = (-0.3, 0.4)
TARGET_BASE = np.array([0.1, 0.0, -0.15])  # [m] in base_link
TARGET_JITTER_M = 0.05
ROLL_RAD = 0.05
# optical frame (z forward, x right, y down) in the body frame (x forward, y left, z up)
T_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def look_at(position_base: np.ndarray, target_base: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """(4, 4) T_base_camera of an optical frame at `position_base` whose z axis points at `target_base`, its x axis
    level (horizontal) before `roll` [rad] about the viewing axis."""
    z = np.asarray(target_base, float) - np.asarray(position_base, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-9:
        raise WolfcalError("an external camera looking straight up or down has no level direction; move it")
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z]) @ axis_angle_matrix(np.array([0.0, 0.0, 1.0]), np.array(roll))
    T_base_camera = np.eye(4)
    T_base_camera[:3, :3] = R
    T_base_camera[:3, 3] = position_base
    return T_base_camera


def placement_from_text(text: str) -> np.ndarray:
    """(4, 4) T_base_camera from 'x,y,z,roll,pitch,yaw' (body frame of the camera, see the module docstring)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 6 or not np.all(np.isfinite(values)):
        raise WolfcalError(
            f"--placement {text!r}: give x,y,z,roll,pitch,yaw (metres, radians) of the camera in base_link, "
            "e.g. 1.5,0,0,0,0,3.1416 for a camera 1.5 m in front looking back at the robot"
        )
    return transform_from_xyz_rpy(values[:3], values[3:]) @ T_BODY_OPTICAL


def expected_placement() -> np.ndarray:
    """(4, 4) T_base_camera at the middle of the random placements' ranges: straight ahead, level roll."""
    position_base = np.array([np.mean(DISTANCE_M), 0.0, np.mean(HEIGHT_M)])
    return look_at(position_base, TARGET_BASE)
