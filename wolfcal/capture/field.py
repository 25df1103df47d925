"""`wolfcal capture --field`: field views. The robot stands on a RoboCup field at `field.robot_at`, its legs holding
`floor.standing` (torque on, soles from `floor.soles`), and its head sweeps a pan/tilt grid over the field: one
sample per still view, taken as floor views are taken (`capture.floor`: the standing legs' targets and their
limits, the views the robot cannot take without touching itself left out).

The grid is `field.sweep: {pan: [...], tilt: [...]}` [rad, joint readings] in the robot config, pan the first and
tilt the second of the joints that aim the camera (`robot.aim.aim_joints`). A key left out takes its default:
pan `DEFAULT_PANS` readings evenly over +-`DEFAULT_PAN_SPAN_RAD` within the pan joint's URDF limits; tilt the
readings at which the nominal model's optical axis, the head turned straight ahead, meets the floor
`DEFAULT_TILT_AIM_M` in front of the robot (within the tilt joint's limits). Every reading is checked against its
joint's URDF limits before anything moves.
"""

from __future__ import annotations

import numpy as np

from wolfcal.capture.floor import standing_targets
from wolfcal.capture.poses import Pose, PoseScript
from wolfcal.errors import WolfcalError
from wolfcal.robot.aim import aim_head, aim_joints, ball_position
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

FIELD_NEEDED_CAPTURE = (
    "field views need the field's dimensions and where the robot stands: add field: {dimensions, robot_at}"
)
STANDING_NEEDED_CAPTURE = "field views need the standing soles and readings: add floor: {soles, standing}"
DEFAULT_PANS = 7
DEFAULT_PAN_SPAN_RAD = 1.2  # about 70 deg to either side: the touch lines and the penalty area from beside it
DEFAULT_TILT_AIM_M = (1.5, 3.5)  # floor points ahead of the robot the default tilts aim at [m]
# a sweep whose views all lie on one side of straight ahead (beyond this pan [rad]) lets the camera's yaw and the
# robot's place on the field trade against each other: said before anything moves
ONE_SIDE_PAN_RAD = 0.2


def sweep_joints(robot: Robot) -> dict[str, str]:
    """`field.sweep` key -> the joint it moves: pan and tilt, or tilt alone for a camera aimed by one joint."""
    joints = aim_joints(robot)
    return dict(zip(("pan", "tilt")[-len(joints) :], joints))


def sweep_readings(robot: Robot) -> dict[str, tuple[float, ...]]:
    """The readings [rad] of each `field.sweep` key (the config's, else the defaults of the module docstring),
    checked against the URDF limits of its joint (WolfcalError naming the key)."""
    config = robot.config.field_config(FIELD_NEEDED_CAPTURE)
    robot.config.floor_config(STANDING_NEEDED_CAPTURE)
    joints = sweep_joints(robot)
    unknown = sorted(set(config.sweep) - set(joints))
    if unknown:
        raise WolfcalError(f"{robot.config.path}: 'field.sweep.{unknown[0]}': the camera is aimed by "
                           f"{' and '.join(joints.values())} alone; give {', '.join(joints)}")  # fmt: skip
    readings = {}
    for key, joint in joints.items():
        lo, hi = robot.model.joints[joint].lower, robot.model.joints[joint].upper
        values = config.sweep.get(key) or default_readings(robot, key, joint)
        outside = [f"{v:.4f}" for v in values if not lo <= v <= hi]
        if outside:
            raise WolfcalError(f"{robot.config.path}: 'field.sweep.{key}' has {', '.join(outside)} rad outside the "
                               f"URDF limits of {joint} [{lo:.4f}, {hi:.4f}]; nothing was moved")  # fmt: skip
        readings[key] = values
    return readings


def default_readings(robot: Robot, key: str, joint: str) -> tuple[float, ...]:
    """The default readings [rad] of `field.sweep.<key>` for its joint (module docstring)."""
    lo, hi = robot.model.joints[joint].lower, robot.model.joints[joint].upper
    if key == "pan":
        return tuple(float(v) for v in np.linspace(max(lo, -DEFAULT_PAN_SPAN_RAD), min(hi, DEFAULT_PAN_SPAN_RAD),
                                                   DEFAULT_PANS))  # fmt: skip
    column = robot.model.column(joint)
    nominal = Corrections()
    tilts = [aim_head(robot, nominal, ball_position(robot, nominal, d, 0.0))[column] for d in DEFAULT_TILT_AIM_M]
    return tuple(float(np.clip(t, lo, hi)) for t in tilts)


def field_place(robot: Robot, check: bool) -> tuple[float, float, float]:
    """Where the robot stands for a field capture (x, y [m], yaw [rad] on the field): `field.robot_at`, or with
    `check` (the held-out views that check a fit) `field.check_at`; WolfcalError naming the key when it is missing."""
    config = robot.config.field_config(FIELD_NEEDED_CAPTURE)
    if not check:
        return config.robot_at
    if config.check_at is None:
        raise WolfcalError(
            f"{robot.config.path}: --field --check stands the robot at 'field.check_at', which the config does not "
            "give: add check_at: {x, y, yaw} [m, m, rad], another place than robot_at"
        )
    return config.check_at


def field_standing(robot: Robot) -> dict[str, float]:
    """The standing readings [rad] of the leg and head servos (`floor.standing`, checked against the URDF limits)
    of a robot config that has a field; WolfcalError naming the missing section otherwise."""
    robot.config.field_config(FIELD_NEEDED_CAPTURE)
    robot.config.floor_config(STANDING_NEEDED_CAPTURE)
    return standing_targets(robot)


def field_script(robot: Robot, velocity: float) -> PoseScript:
    """The scripted field capture at `velocity` [rad/s]: the legs standing (`floor.standing`), the head through the
    sweep's grid, row by row of tilt and to and fro along pan (short moves)."""
    standing = field_standing(robot)
    readings = sweep_readings(robot)
    joints = sweep_joints(robot)
    missing = [j for j in joints.values() if j not in standing]
    if missing:
        raise WolfcalError(f"{robot.config.path}: {', '.join(missing)} (aiming the camera) is not a servo of "
                           "'servos.ids'; a field capture turns the head with it")  # fmt: skip
    pans: tuple[float | None, ...] = readings.get("pan", (None,))
    poses = []
    for row, tilt in enumerate(readings["tilt"]):
        for pan in pans[:: -1 if row % 2 else 1]:
            head = {joints["tilt"]: tilt}
            name = f"tilt {np.rad2deg(tilt):+.0f} deg"
            if pan is not None:
                head[joints["pan"]] = pan
                name = f"pan {np.rad2deg(pan):+.0f} deg, {name}"
            poses.append(Pose(f"field {name}", {**standing, **head}))
    return PoseScript(poses, velocity)


def one_sided_note(robot: Robot, script: PoseScript) -> str | None:
    """A note when the views of a field script (after any left out) do not look to both sides: no pan reading
    below -ONE_SIDE_PAN_RAD or none above it; None when they do (or the camera has no pan joint)."""
    pan = sweep_joints(robot).get("pan")
    if pan is None or not script.poses:
        return None
    pans = [pose.joints[pan] for pose in script.poses]
    if min(pans) < -ONE_SIDE_PAN_RAD and max(pans) > ONE_SIDE_PAN_RAD:
        return None
    return (
        f"--field: every view turns {pan} to one side ({np.rad2deg(min(pans)):+.0f} to {np.rad2deg(max(pans)):+.0f}"
        " deg): the camera's yaw and the robot's place on the field then trade against each other and the fit can "
        "settle far off; give 'field.sweep.pan' readings on both sides of straight ahead"
    )
