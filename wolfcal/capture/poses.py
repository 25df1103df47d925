"""Scripted capture poses: a YAML list of named joint targets, checked against the URDF limits up front.

Format (angles in radians, the robot's joint convention (ticks - 2048) * 2 pi / 4096, velocity in rad/s):

    velocity: 0.5            # optional, profile velocity of every move (default 0.5 rad/s)
    poses:
      - name: look_at_right_foot
        joints: {HeadPan: -0.3, HeadTilt: -1.2, RHipPitch: -0.4, RKnee: -0.8}
      - name: ...

A joint not named in a pose keeps its previous target (at the start: where it stands).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.robot.collision_sources import optional_collision_model
from wolfcal.robot.robot import Robot
from wolfcal.yamlfile import read_yaml

DEFAULT_VELOCITY = 0.5  # rad/s


@dataclass(frozen=True)
class Pose:
    name: str
    joints: dict[str, float]  # joint -> target [rad]


@dataclass(frozen=True)
class PoseScript:
    poses: list[Pose]
    velocity: float  # rad/s

    @property
    def joints(self) -> list[str]:
        """Every joint some pose moves, in first-seen order."""
        seen: dict[str, None] = {}
        for pose in self.poses:
            seen.update(dict.fromkeys(pose.joints))
        return list(seen)

    def readings(self, joint_names: list[str], start: Mapping[str, float]) -> np.ndarray:
        """(S, J) the readings [rad] of `joint_names` at each pose as the script drives them: each joint at its
        latest target, a joint no pose has named yet at `start` (others 0)."""
        targets = dict(start)
        rows = []
        for pose in self.poses:
            targets.update(pose.joints)
            rows.append([targets.get(j, 0.0) for j in joint_names])
        return np.array(rows)


def joint_limits(robot: Robot, joints: Iterable[str]) -> dict[str, tuple[float, float]]:
    """URDF (lower, upper) limits [rad] of `joints`, as `load_poses` takes them."""
    return {j: (robot.model.joints[j].lower, robot.model.joints[j].upper) for j in joints}


def find_poses(path: str | Path, robot_config: str | Path) -> Path:
    """The poses file `--poses` names: `path` where it exists; else a bare file name is taken from the robot
    config's folder, so that a robot's own poses (the packaged Wolfgang's `poses.yaml`) are found from any folder
    as `--poses poses.yaml`. WolfcalError naming both places when neither holds it."""
    path, folder = Path(path), Path(robot_config)
    folder = folder if folder.is_dir() else folder.parent
    if path.exists() or path.parent != Path("."):
        return path
    beside = folder / path
    if beside.is_file():
        return beside
    raise WolfcalError(f"--poses {path}: no such file here or beside the robot config ({folder}); give its path, or "
                       "make one with `wolfcal plan --out POSES.yaml`")  # fmt: skip


def load_poses(path: str | Path, limits: dict[str, tuple[float, float]]) -> PoseScript:
    """Read and check a poses file; `limits` maps each servo joint to its URDF (lower, upper) [rad].

    Every problem (unknown joint, target outside the limits, bad value) is listed in one WolfcalError.
    """
    path = Path(path)
    data = read_yaml(path, "poses file")
    if not isinstance(data, dict) or not isinstance(data.get("poses"), list) or not data["poses"]:
        raise WolfcalError(f"{path}: expected a mapping with 'poses': a non-empty list of {{name, joints}}")
    unknown = sorted(set(data) - {"poses", "velocity"})
    if unknown:
        raise WolfcalError(f"{path}: unknown key(s) {', '.join(unknown)}; allowed: poses, velocity")
    velocity = data.get("velocity", DEFAULT_VELOCITY)
    if isinstance(velocity, bool) or not isinstance(velocity, (int, float)) or not 0 < velocity <= 6:
        raise WolfcalError(f"{path}: 'velocity' must be a speed in rad/s in (0, 6], found {velocity!r}")
    problems, poses, names = [], [], set()
    for i, entry in enumerate(data["poses"]):
        where = f"poses[{i}]"
        if not isinstance(entry, dict) or set(entry) - {"name", "joints"} or not isinstance(entry.get("joints"), dict):
            problems.append(f"{where}: must be a mapping with 'name' and 'joints' (joint: rad)")
            continue
        name = str(entry.get("name", f"pose{i + 1}"))
        where = f"{where} ({name})"
        if name in names:
            problems.append(f"{where}: the name is used twice")
        names.add(name)
        joints = {}
        for joint, value in entry["joints"].items():
            if joint not in limits:
                problems.append(f"{where}: unknown joint {joint!r} (not in the robot config's servos)")
            elif isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                problems.append(f"{where}: {joint} must be a number of radians, found {value!r}")
            elif not limits[joint][0] <= value <= limits[joint][1]:
                lo, hi = limits[joint]
                problems.append(f"{where}: {joint} = {value:.4f} rad is outside the URDF limits [{lo:.4f}, {hi:.4f}]")
            else:
                joints[str(joint)] = float(value)
        poses.append(Pose(name, joints))
    if problems:
        raise WolfcalError(f"{path}: {len(problems)} problem(s), nothing was moved:\n  " + "\n  ".join(problems))
    return PoseScript(poses, float(velocity))


def check_collisions(robot: Robot, script: PoseScript, path: str | Path, start: dict[str, float]) -> str | None:
    """Refuse a script in which the robot would touch itself (`wolfcal.robot.collision`): each pose with every
    joint at its latest target, joints never named where they stand at the start (`start`: joint -> rad; others
    at the rest pose). Returns a note when the robot config has no collision geometry (nothing checked)."""
    colliding = colliding_poses(robot, script, start)
    if colliding is None:
        return (f"{robot.config.path} has no collision geometry ('collision_radii:'): poses not checked for "
                "self-collision")  # fmt: skip
    if colliding:
        problems = [f"{name}: {' and '.join(pair)} would touch" for name, pair in colliding.items()]
        raise WolfcalError(f"{path}: {len(problems)} pose(s) collide, nothing was moved:\n  " + "\n  ".join(problems))
    return None


def colliding_poses(robot: Robot, script: PoseScript, start: dict[str, float]) -> dict[str, tuple[str, str]] | None:
    """Pose name -> the two links that would touch, of the poses of `script` in which the robot would touch itself
    (as `check_collisions` poses it); None when the robot config has no collision geometry."""
    model = optional_collision_model(robot)
    if model is None:
        return None
    q = script.readings(robot.joint_names, {**robot.config.planning.rest_pose, **start})
    clearance = model.clearance(q)
    return {pose.name: model.colliding_pair(row) or ("?", "?")
            for pose, row, c in zip(script.poses, q, clearance) if c < 0}  # fmt: skip
