"""Render what a camera sees of a simulated robot: the robot's tags at the true kinematics.

The head camera by default, or an external camera fixed in the base frame at `T_base_camera` (its optical frame).
`true angle = measured + true offset`; tag and camera frames include the true corrections. With `floor_places`
(floor tag id -> x, y, yaw [m, rad]) the head camera also sees the config's floor tags lying there, on the floor of
the true soles wherever they are (`wolfcal.robot.floor`: the robot is taken to stand).
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.external_view import external_tag_poses
from wolfcal.geometry import invert_transform
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor
from wolfcal.robot.robot import Robot
from wolfcal.sim.floor import floor_targets
from wolfcal.vision.render import PlanarTarget, render_targets
from wolfcal.vision.tags import tag_texture, tag_texture_width

# Binning of a simulated camera's images when none is given: 4 for the head camera (a 2048x1536 sensor gives
# 512x384, quick to render, the foot tags still about 40 px across), 2 for an external camera (it sees the tags
# from further away). `wolfcal simulate` and `wolfcal capture --camera sim` both use it.
SIM_BINNING = {HEAD_CAMERA: 4}
SIM_BINNING_EXTERNAL = 2


def sim_binning(camera: str) -> int:
    """The default binning of the simulated camera named `camera` ('head' or an external camera's name)."""
    return SIM_BINNING.get(camera, SIM_BINNING_EXTERNAL)


class SimScene:
    """The simulated robot's view; `render` takes measured joint angles like the real capture does."""

    def __init__(
        self,
        robot: Robot,
        truth: Corrections,
        camera: CameraModel,
        seed: int = 0,
        noise_sigma: float = 2.0,
        T_base_camera: np.ndarray | None = None,
        floor_places: dict[int, np.ndarray] | None = None,
    ):
        self.robot, self.truth, self.camera = robot, truth, camera
        self.T_base_camera = T_base_camera  # (4, 4) external camera; None: the head camera
        self.noise_sigma = noise_sigma
        self.floor_places = floor_places or {}
        self.rng = np.random.default_rng(seed)
        self.textures = {t.id: tag_texture(t.family, t.id) for t in robot.config.tags}

    def true_angles(self, q_measured: np.ndarray) -> np.ndarray:
        """(N, J) true joint angles from encoder readings (N, J) [rad]."""
        return np.atleast_2d(q_measured) + self.truth.offset_vector(self.robot.joint_names)

    def render_true(self, q_true: np.ndarray) -> np.ndarray:
        """Gray uint8 image at true joint angles (J,) [rad]."""
        frames = Corrections(frames=self.truth.frames, tags=self.truth.tags)
        tag_ids = self.robot.config.tag_ids
        if self.T_base_camera is None:
            _, T_camera_tag = self.robot.camera_and_tag_poses(np.atleast_2d(q_true), tag_ids, frames)
        else:
            T_camera_tag = external_tag_poses(self.robot, self.T_base_camera, q_true, frames, tag_ids)
        targets = []
        for k, tag_id in enumerate(tag_ids):
            tag = self.robot.config.tag(tag_id)
            width = tag_texture_width(tag.family, tag.size, self.textures[tag_id])
            targets.append(PlanarTarget(T_camera_tag[0, k], self.textures[tag_id], width, width))
        if self.floor_places and self.T_base_camera is None:
            T_floor_camera, _ = camera_in_floor(self.robot, np.atleast_2d(q_true), frames)
            targets += floor_targets(self.robot, self.floor_places, invert_transform(T_floor_camera[0]))
        return render_targets(self.camera, targets, noise_sigma=self.noise_sigma, rng=self.rng)

    def render(self, q_measured: dict[str, float] | np.ndarray) -> np.ndarray:
        """Gray uint8 image for encoder readings (a joint -> rad mapping or a (J,) array in model order)."""
        if isinstance(q_measured, dict):
            q_measured = np.array([q_measured.get(n, 0.0) for n in self.robot.joint_names])
        return self.render_true(self.true_angles(q_measured)[0])
