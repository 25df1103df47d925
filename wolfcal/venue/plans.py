"""The feet views of a venue session: the fewest poses that pin the head camera, planned once per robot config.

`wolfcal plan`'s own planner (`wolfcal.plan.pipeline.make_plan`, the camera preset with the head camera) chooses
them; the poses file it writes is kept in the cache folder under a key made of the robot config's and URDF's
content, the planner's settings and wolfcal's version, so a venue does not wait for planning twice. A robot whose
poses cannot be planned (the planner refuses: no collision geometry, tags never in view) falls back to the poses
file beside its config (`poses.yaml`), and the session says so.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import wolfcal
from wolfcal.atomic import write_text_atomic
from wolfcal.capture.poses import PoseScript, joint_limits, load_poses
from wolfcal.errors import WolfcalError
from wolfcal.io.filememo import cache_dir
from wolfcal.plan.pipeline import PlanOptions, make_plan, poses_text
from wolfcal.robot.robot import Robot

FALLBACK_POSES = "poses.yaml"  # beside robot.yaml: the poses used when none can be planned
PLAN_SEED = 1
PLAN_CANDIDATES = 2000


@dataclass(frozen=True)
class FeetPlan:
    script: PoseScript
    source: str  # where the poses come from, in words: "planned", "cached plan <path>", "fallback <path>"
    key: str  # the plan's cache key (content hash)


def plan_key(robot: Robot, n_poses: int, velocity: float) -> str:
    """Hex SHA-256 of the robot config and URDF contents, the planner's settings and wolfcal's version."""
    digest = hashlib.sha256()
    for path in (robot.config.path, robot.config.urdf):
        digest.update(Path(path).read_bytes())
    digest.update(f"camera head {n_poses} {velocity:.6g} {PLAN_SEED} {PLAN_CANDIDATES} {wolfcal.__version__}".encode())
    return digest.hexdigest()


def plan_cache_path(key: str) -> Path:
    return cache_dir() / "plans" / f"{key[:32]}.yaml"


def feet_plan(robot: Robot, n_poses: int, velocity: float, say: Callable[[str], None]) -> FeetPlan:
    """The feet views' poses at `velocity` [rad/s]: from the cache, else planned (and cached), else the config's
    fallback poses file; checked against the URDF limits of the servo joints (`load_poses`)."""
    if robot.config.servos is None:
        raise WolfcalError(f"{robot.config.path}: no 'servos' section (port, ids): the session needs the servo bus")
    limits = joint_limits(robot, robot.config.servos.ids)
    key = plan_key(robot, n_poses, velocity)
    cached = plan_cache_path(key)
    if cached.is_file():
        return FeetPlan(load_poses(cached, limits), f"cached plan {cached}", key)
    say(f"planning {n_poses} feet views for {robot.config.name} (once per robot config; cached) ...")
    options = PlanOptions(free="camera", system="head", poses=n_poses, candidates=PLAN_CANDIDATES,
                          velocity=velocity, seed=PLAN_SEED)  # fmt: skip
    try:
        plan = make_plan(robot, options, say=lambda line: None)
    except WolfcalError as exc:
        fallback = robot.config.path.parent / FALLBACK_POSES
        if not fallback.is_file():
            raise WolfcalError(
                f"{robot.config.path}: the feet views cannot be planned ({exc}), and there is no "
                f"{fallback} to fall back to: fix the config or write that poses file"
            ) from None
        say(f"note: the feet views cannot be planned ({exc}); using {fallback} instead")
        return FeetPlan(load_poses(fallback, limits), f"fallback {fallback}", key)
    cached.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(cached, poses_text(robot, plan, options))
    return FeetPlan(load_poses(cached, limits), f"planned now, cached in {cached}", key)
