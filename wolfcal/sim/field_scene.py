"""What the simulated head camera sees while the robot stands on a RoboCup field: the field's lines, goals, two
other robots, a ball, shadows, people and walls (`wolfcal.field.scene.cluttered_scene`), rendered through the
distorted camera (`wolfcal.field.render`) at the true kinematics.

The robot's floor frame (`wolfcal.robot.floor`: the plane of its true standing soles) lies on the field at the true
place `pose` (x, y, yaw) [m, m, rad]; the camera's pose follows from the true joint angles and the true frame
corrections. The scene and the image noise come from one seeded generator, so a run is reproducible.
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.field.ground import camera_on_field
from wolfcal.field.model import FieldDimensions
from wolfcal.field.render import pixel_rays, render_field_view
from wolfcal.field.scene import cluttered_scene
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor
from wolfcal.robot.robot import Robot

FIELD_NOISE_SIGMA = 3.0  # image noise of a rendered field view [grey levels], as `wolfcal simulate --system field`


class FieldSimScene:
    """The simulated head camera's view of the field from a robot standing at `pose` (module docstring)."""

    def __init__(self, robot: Robot, truth: Corrections, camera: CameraModel, dims: FieldDimensions,
                 pose: np.ndarray, seed: int = 0, noise_sigma: float = FIELD_NOISE_SIGMA):  # fmt: skip
        self.robot, self.camera, self.dims = robot, camera, dims
        self.frames = Corrections(frames=truth.frames, tags=truth.tags)  # true angles carry the offsets already
        self.pose = np.asarray(pose, float)  # (3,) x, y [m], yaw [rad]
        self.noise_sigma = noise_sigma
        self.rng = np.random.default_rng(seed)
        self.scene = cluttered_scene(dims, self.rng)
        self.rays = pixel_rays(camera)

    def camera_pose(self, q_true: np.ndarray) -> np.ndarray:
        """T_field_camera (4, 4) of the head camera's optical frame at true joint angles (J,) [rad]."""
        T_floor_camera, _ = camera_in_floor(self.robot, np.atleast_2d(q_true), self.frames)
        return camera_on_field(T_floor_camera[0], self.pose)

    def render_true(self, q_true: np.ndarray) -> np.ndarray:
        """BGR uint8 image (H, W, 3) at true joint angles (J,) [rad]."""
        view = render_field_view(self.camera, self.camera_pose(q_true), self.dims, self.scene, self.rng,
                                 self.noise_sigma, 0.0, self.rays)  # fmt: skip
        return view.image
