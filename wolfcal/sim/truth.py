"""Random ground truth for simulations: the corrections a real robot would hide from its nominal model."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot


@dataclass(frozen=True)
class TruthSpec:
    """Standard deviations of the simulated errors (SI units); the camera also gets a systematic tilt."""

    offset_rms: float = 0.025  # encoder offsets of the joints in `offset_joints` [rad]
    offset_joints: tuple[str, ...] = ()  # which joints get an offset (empty: none)
    camera_rotation: float = 0.03  # per axis [rad], on top of `camera_tilt`
    camera_tilt: float = -0.065  # rotation about the optical x axis [rad] (hand-tuned values: -0.06 to -0.075)
    camera_translation: float = 0.003  # per axis [m]
    tag_translation: float = 0.001  # per axis [m]
    tag_rotation: float = 0.01  # per axis [rad]


def random_truth(robot: Robot, spec: TruthSpec, rng: np.random.Generator) -> Corrections:
    """Random true corrections drawn by `spec` (normal, zero mean, its sigmas [m, rad]): encoder offsets of its
    joints [rad], the head camera's mount (with the tilt `spec.camera_tilt` [rad] added) and every tag's mount."""
    camera = np.concatenate([rng.normal(0.0, spec.camera_translation, 3), rng.normal(0.0, spec.camera_rotation, 3)])
    camera[3] += spec.camera_tilt
    return Corrections(
        offsets={j: float(rng.normal(0.0, spec.offset_rms)) for j in spec.offset_joints},
        frames={robot.camera_joint: camera} if robot.config.camera is not None else {},
        tags={
            t.id: np.concatenate([rng.normal(0.0, spec.tag_translation, 3), rng.normal(0.0, spec.tag_rotation, 3)])
            for t in robot.config.tags
        },
    )
