"""Synthetic calibration scenarios without images: truth, poses, observations (for tests and benchmarks)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.external_view import external_pose_ok, external_tag_poses, external_visibility
from wolfcal.observations import Observations
from wolfcal.projection import observations_from_poses
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.ranges import sampling_bounds
from wolfcal.robot.robot import Robot
from wolfcal.sim.observations import synthetic_observations
from wolfcal.sim.placement import random_placement
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
    robot: Robot,
    camera: CameraModel,
    n: int,
    seed: int,
    offsets: str = "none",
    noise_px: float = 0.15,
    outlier_fraction: float = 0.0,
    tag_ids: list[int] | None = None,
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


@dataclass
class ExternalScenario:
    obs: Observations  # the external camera's corners, samples of every placement in order
    truth: Corrections
    q_true: np.ndarray  # (S, J) [rad]
    T_base_camera: list[np.ndarray]  # true pose of each placement (4, 4)


def synthetic_external_scenario(
    robot: Robot,
    camera: CameraModel,
    n: int,
    seed: int,
    offsets: str = "legs",
    noise_px: float = 0.15,
    placements: int = 1,
    camera_name: str = "tripod",
) -> ExternalScenario:
    """n samples (split evenly over `placements` tripod placements, one capture file each) in which an external
    camera sees a tag fixed to the base and at least one other tag; legs move, the base stays fixed."""
    rng = np.random.default_rng(seed)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, offsets)), rng)
    lo, hi = sampling_bounds(robot, "external")
    qs, poses, visibility, sources, cameras = [], [], [], [], []
    for k in range(placements):
        count = n // placements + (1 if k < n % placements else 0)
        for _ in range(50):
            T_base_camera = random_placement(rng)
            kept_q, kept_v = [], []
            for _ in range(20):
                q = rng.uniform(lo, hi, size=(2000, len(lo)))
                vis = external_visibility(robot, camera, T_base_camera, q, truth)
                good = external_pose_ok(robot, vis)
                kept_q.append(q[good])
                kept_v.append(vis[good])
                if sum(len(x) for x in kept_q) >= count:
                    break
            if sum(len(x) for x in kept_q) >= count:
                break
        else:
            raise WolfcalError(f"no tripod placement sees the torso tag and a foot tag of {robot.config.path}")
        q_k = np.concatenate(kept_q)[:count]
        qs.append(q_k)
        visibility.append(np.concatenate(kept_v)[:count])
        poses.append(external_tag_poses(robot, T_base_camera, q_k, truth, robot.config.tag_ids))
        sources += [f"placement{k + 1}.mcap"] * count
        cameras.append(T_base_camera)
    q_true = np.concatenate(qs)
    obs = observations_from_poses(robot, camera, truth, q_true, np.concatenate(poses), np.concatenate(visibility),
                                  noise_px, rng, camera_name, sources)  # fmt: skip
    return ExternalScenario(obs, truth, q_true, cameras)
