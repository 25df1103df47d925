"""Synthetic calibration scenarios without images: truth, poses, observations (for tests and benchmarks)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.sim.observations import synthetic_observations
from wolfcal.sim.poses import random_visible_poses
from wolfcal.sim.simulate import offset_joints
from wolfcal.sim.truth import TruthSpec, random_truth


@dataclass
class Scenario:
    obs: Observations
    truth: Corrections
    q_true: np.ndarray  # (S, J) [rad]
    outliers: np.ndarray  # (S,) bool: samples given a stale joint reading


def synthetic_scenario(
    robot: Robot, camera: CameraModel, n: int, seed: int, offsets: str = "none", noise_px: float = 0.15,
    outlier_fraction: float = 0.0, tag_ids: list[int] | None = None,
) -> Scenario:
    """n samples of the foot tags; outlier samples get joint readings off by ~0.04 rad (a stale reading)."""
    rng = np.random.default_rng(seed)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, offsets)), rng)
    tag_ids = tag_ids or [t.id for t in robot.config.tags if t.side is not None]
    q_true, visible = random_visible_poses(robot, camera, truth, n, rng, tag_ids=tag_ids)
    all_visible = np.zeros((n, len(robot.config.tag_ids)), dtype=bool)
    for k, tag_id in enumerate(tag_ids):
        all_visible[:, robot.config.tag_ids.index(tag_id)] = visible[:, k]
    obs = synthetic_observations(robot, camera, truth, q_true, all_visible, noise_px, rng)
    outliers = np.zeros(n, dtype=bool)
    outliers[rng.choice(n, size=int(round(outlier_fraction * n)), replace=False)] = True
    obs.q_measured[outliers] += rng.normal(0.0, 0.04, size=(int(outliers.sum()), obs.q_measured.shape[1]))
    return Scenario(obs, truth, q_true, outliers)
