"""`wolfcal capture --floor`: floor samples. The robot stands on the floor among the config's floor tags (`floor:`);
its legs hold a standing pose (`floor.stances`, default `floor.standing`: encoder readings, other leg joints 0) with
torque on, and its head looks at the floor: scripted, in each stance in turn (the legs moved there at the capture
velocity) the head aims at points on the floor `AIM_DISTANCES_M` from the robot at bearings `AIM_BEARINGS_DEG` (a
pan/tilt grid found through the robot's own nominal model in that stance, within its URDF limits); manual, the legs
hold the stances in turn while the operator turns the head by hand (its torque off).

Each sample is an ordinary capture sample; the fit and evaluation tell floor samples by the floor tags they see.
"""

from __future__ import annotations

import math

import numpy as np

from wolfcal.capture.manual import joint_groups
from wolfcal.capture.poses import Pose, PoseScript, check_collisions, colliding_poses
from wolfcal.capture.scripted import torque_on, wait_arrival
from wolfcal.capture.session import CaptureSession
from wolfcal.errors import WolfcalError
from wolfcal.hardware.bus import rad_to_ticks
from wolfcal.robot.aim import AIM_BEARINGS_DEG, AIM_DISTANCES_M, aim_head, aim_joints, ball_position
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import CHECK_VIEWS_PER_STANCE, stance_poses, standing_pose
from wolfcal.robot.robot import Robot

FLOOR_NEEDED_CAPTURE = "capture --floor needs the standing soles, the standing readings and the floor tags"


def floor_joints(robot: Robot) -> tuple[list[str], list[str]]:
    """(standing joints, head joints) of the servo bus: the legs hold the standing pose, the head looks around."""
    groups = joint_groups(robot)
    return groups["legs"], groups["head"]


def stance_targets(robot: Robot, check: bool = False) -> list[dict[str, float]]:
    """`standing_targets` of each stance (`floor.stances`, default `floor.standing`; with `check`
    `floor.check_stances` where given)."""
    floor = robot.config.floor_config(FLOOR_NEEDED_CAPTURE)
    if not floor.tags:
        raise WolfcalError(f"{robot.config.path}: 'floor.tags' lists no floor tag; {FLOOR_NEEDED_CAPTURE}")
    return [standing_targets(robot, q, k, check) for k, q in enumerate(stance_poses(robot, check))]


def stance_name(robot: Robot, k: int, check: bool = False) -> str:
    """How the config names stance k: 'floor.standing', 'floor.stances[k]' or (`check`) 'floor.check_stances[k]'."""
    if check:
        return f"floor.check_stances[{k}]"
    return f"floor.stances[{k}]" if robot.config.floor_config().stances else "floor.standing"


def standing_targets(robot: Robot, q: np.ndarray | None = None, k: int = 0, check: bool = False) -> dict[str, float]:
    """Readings [rad] of a standing pose q (J,) (default `floor.standing`; else stance k of the capture (`check`),
    for messages) for the leg and head servo joints, checked against the URDF limits."""
    name = "floor.standing" if q is None else stance_name(robot, k, check)
    q = standing_pose(robot) if q is None else q
    legs, head = floor_joints(robot)
    targets = {j: float(q[robot.model.column(j)]) for j in legs + head}
    outside = [f"{j} = {v:.4f} rad (limits [{robot.model.joints[j].lower:.4f}, {robot.model.joints[j].upper:.4f}])"
               for j, v in targets.items()
               if not robot.model.joints[j].lower <= v <= robot.model.joints[j].upper]  # fmt: skip
    if outside:
        raise WolfcalError(f"{robot.config.path}: '{name}' puts joints outside their URDF "
                           "limits: "
                           + "; ".join(outside))  # fmt: skip
    return targets


def floor_script(robot: Robot, velocity: float, check: bool = False) -> PoseScript:
    """The scripted floor capture, driven at `velocity` [rad/s]: in each stance in turn, standing legs and the head
    aimed at each grid point of the floor (poses that round to the same ticks, where a limit stops the head, are
    kept once per stance); with `check` in the stances of the held-out capture that checks a fit
    (`floor.check_stances`; `check_views` then picks its views)."""
    all_targets = stance_targets(robot, check)
    stances = stance_poses(robot, check)
    poses = []
    for k, targets in enumerate(all_targets):
        pan_tilt = [j for j in aim_joints(robot) if j in targets]
        if not pan_tilt:
            raise WolfcalError(f"{robot.config.path}: the joints that aim the camera are not servos; use --manual")
        prefix = f"stance {k}, " if len(stances) > 1 else ""
        seen: set[tuple[int, ...]] = set()
        nominal = Corrections()
        for row, distance in enumerate(AIM_DISTANCES_M):
            for bearing in AIM_BEARINGS_DEG[:: -1 if row % 2 else 1]:  # to and fro: short moves
                ball = ball_position(robot, nominal, distance, math.radians(bearing))
                q = aim_head(robot, nominal, ball, stances[k])
                joints = {**targets, **{j: float(q[robot.model.column(j)]) for j in pan_tilt}}
                key = tuple(int(rad_to_ticks(joints[j])) for j in pan_tilt)
                if key not in seen:
                    seen.add(key)
                    poses.append(Pose(f"{prefix}floor {distance:g} m, {bearing:+g} deg", joints))
    return PoseScript(poses, velocity)


def check_views(robot: Robot, script: PoseScript) -> PoseScript:
    """The held-out check's views of a floor script (`floor_script(check=True)`, less any left out for
    collisions): CHECK_VIEWS_PER_STANCE (`robot.floor`) per stance, each stance's remaining grid views taken in turn
    over the stances, so that the check sees the whole grid. A stance is the standing legs' targets, in ticks."""
    legs, _ = floor_joints(robot)
    by_stance: dict[tuple[int, ...], list[Pose]] = {}
    for pose in script.poses:
        by_stance.setdefault(tuple(int(rad_to_ticks(pose.joints[j])) for j in legs), []).append(pose)
    picked = [views[(k * CHECK_VIEWS_PER_STANCE + i) % len(views)] for k, views in enumerate(by_stance.values())
              for i in range(min(CHECK_VIEWS_PER_STANCE, len(views)))]  # fmt: skip
    return PoseScript(picked, script.velocity)


def without_collisions(robot: Robot, script: PoseScript, start: dict[str, float],
                       mode: str = "--floor") -> tuple[PoseScript, str | None]:  # fmt: skip
    """The script of standing views (`mode`: --floor or --field, for messages) less the views in which the robot
    would touch itself (`capture.poses.colliding_poses`, `start`: joint -> rad where the robot stands), and a note
    on what was left out or not checked; WolfcalError when no view is left."""
    colliding = colliding_poses(robot, script, start)
    if colliding is None:
        return script, check_collisions(robot, script, mode, start)  # the note: nothing checked
    if not colliding:
        return script, None
    kept = [pose for pose in script.poses if pose.name not in colliding]
    if not kept:
        left_out = "; ".join(f"{name} ({' and '.join(pair)} would touch)" for name, pair in colliding.items())
        raise WolfcalError(f"{mode}: every {mode[2:]} view would make the robot touch itself, nothing was moved: "
                           f"{left_out}")  # fmt: skip
    pairs = sorted({" and ".join(pair) for pair in colliding.values()})  # a few link pairs, not every view
    return PoseScript(kept, script.velocity), (f"{mode}: {len(colliding)} of {len(script.poses)} view(s) left out "
                                               f"(there {', '.join(pairs)} would touch)")  # fmt: skip


def check_floor_limp(robot: Robot, limp: list[str], mode: str = "--floor") -> None:
    """Refuse a manual capture of standing views (`mode`: --floor or --field) that would switch off a joint of the
    standing legs."""
    legs, _ = floor_joints(robot)
    standing = [j for j in limp if j in legs]
    if standing:
        raise WolfcalError(f"{mode} keeps the legs standing with torque on; --limp names {', '.join(standing)}: "
                           f"give head joints only (the default with {mode} is 'head')")  # fmt: skip


def stand(session: CaptureSession, targets: dict[str, float], velocity: float) -> None:
    """Manual floor capture: torque on for the legs, moved to the standing readings `targets` [rad] at `velocity`
    [rad/s] (a standing robot barely moves); WolfcalError when they do not get there."""
    goals = torque_on(session, list(targets), velocity)
    goals.update(targets)
    session.bus.set_goal_positions(goals)
    index = {j: k for k, j in enumerate(session.bus.joints)}
    reason = wait_arrival(session, goals, index, velocity)
    if reason is not None:
        raise WolfcalError(f"the legs did not reach the standing pose (floor.standing): {reason}")
