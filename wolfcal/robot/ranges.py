"""Joint ranges [rad, true angles] from which simulated and planned calibration poses are drawn.

From the robot config's `sampling_ranges: {<system>: {<joint>: [lo, hi]}}` (system `head`: poses in which the head
camera sees the foot tags; `external`: poses in which an external camera sees the torso and foot tags; `mocap`:
poses on a stand seen by motion capture, the `external` ranges when not given: the robot stands alike), intersected
with the URDF limits; joints a listed system leaves out stay at 0 (or the limit nearest to it). A robot config
without ranges for a system samples every actuated joint within its URDF limits shrunk by `LIMIT_MARGIN` of the
range at each end (limits wider than +-pi taken as +-pi).
"""

from __future__ import annotations

import numpy as np

from wolfcal.robot.robot import Robot

LIMIT_MARGIN = 0.1  # share of a joint's URDF range kept free at each end when the config gives no ranges


def sampling_bounds(robot: Robot, system: str = "head") -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) per actuated joint [rad] for poses of `system` ('head' | 'external' | 'mocap'); see the module."""
    configured = robot.config.sampling_ranges
    ranges = configured.get(system, configured.get("external") if system == "mocap" else None)
    lo, hi = [], []
    for name in robot.joint_names:
        joint = robot.model.joints[name]
        if ranges is None:
            a, b = max(joint.lower, -np.pi), min(joint.upper, np.pi)
            margin = LIMIT_MARGIN * (b - a)
            a, b = a + margin, b - margin
        else:
            a, b = ranges.get(name, (0.0, 0.0))
            a, b = max(a, joint.lower), min(b, joint.upper)
        if a > b:  # range and limits disjoint: sit at the limit nearest to 0
            a = b = float(np.clip(0.0, joint.lower, joint.upper))
        lo.append(a)
        hi.append(b)
    return np.array(lo), np.array(hi)


def range_grid(robot: Robot, frame: str, grid: int) -> np.ndarray:
    """(grid^K, J) readings [rad] spanning the whole range of each of the K actuated joints between base and
    `frame` (limits wider than +-pi taken as +-pi), the others 0."""
    joints = [j for j in robot.model.joints_between(robot.config.base_link, frame) if j.actuated]
    axes = [np.linspace(max(j.lower, -np.pi), min(j.upper, np.pi), grid) for j in joints]
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(joints))
    q = np.zeros((len(mesh), len(robot.joint_names)))
    for k, joint in enumerate(joints):
        q[:, robot.model.column(joint.name)] = mesh[:, k]
    return q
