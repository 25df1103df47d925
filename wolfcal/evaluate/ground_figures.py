"""The ground-error figures an evaluation reports and its verdict judges.

- the distances [m]: `ground.DISTANCES_M` and the verdict's (`floor.ground_check.distance` of the robot config);
- the verdict's limits (`verdict_limits`: the config's `floor.ground_check`, its limit overridden on the command
  line);
- the rows of the standing robot against the simulator's truth (`ground_rows`; without a truth the model after is
  its own reference, so its error is not given: 'n/a (no truth)');
- the error measured on held-out floor views (`floor_ground`), and the one the fit's covariance predicts;
- the camera's turn between the models before and after [rad].
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from wolfcal.camera.model import CameraModel
from wolfcal.config import GroundCheck
from wolfcal.evaluate.floor_ground import measured_ground_errors
from wolfcal.evaluate.ground import DISTANCES_M, ground_errors, predicted_ground_std
from wolfcal.evaluate.verdict import VerdictLimits
from wolfcal.fit.result import FitResult
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet, build_parameter_set
from wolfcal.robot.robot import Robot


def measured_ground(robot: Robot, floor: Observations | None, models: dict[str, Corrections], held_out: bool,
                    say: Callable[[str], None], corner_inset: tuple[float, float],
                    distances: tuple[float, ...]) -> dict | None:  # fmt: skip
    """`floor_ground.measured_ground_errors` of the held-out floor views, before and after (None: not measured)."""
    if floor is None or not held_out:
        return None
    say("measuring the ground error on the held-out floor views ...")
    return measured_ground_errors(robot, floor, models, distances, corner_inset)


def ground_distances(limits: VerdictLimits) -> tuple[float, ...]:
    """The distances ground errors are given at [m]: DISTANCES_M and the verdict's."""
    return tuple(sorted({*DISTANCES_M, limits.ground_distance_m}))


def ground_check(robot: Robot) -> GroundCheck:
    """The robot config's `floor.ground_check` (its defaults without `floor:`)."""
    return robot.config.floor.ground_check if robot.config.floor is not None else GroundCheck()


def verdict_limits(robot: Robot, ground_limit_m: float | None, mount_limit_rad: float) -> VerdictLimits:
    """The verdict's limits: distance and limit from `ground_check`, the limit overridden by `ground_limit_m` when
    given."""
    check = ground_check(robot)
    return VerdictLimits(check.limit if ground_limit_m is None else ground_limit_m, mount_limit_rad, check.distance)


def verdict_ground(measured: dict | None, distances: tuple[float, ...], distance: float) -> dict | None:
    """The verdict's {'before_m', 'after_m', 'after_std_m'} at `distance` (inf: the ball lies above the horizon)."""
    if measured is None:
        return None
    k = distances.index(distance)
    before, after = (measured["models"][m]["rows"][k] for m in ("before", "after"))
    inf = float("inf")
    return {
        "before_m": inf if before["error_m"] is None else before["error_m"],
        "after_m": inf if after["error_m"] is None else after["error_m"],
        "after_std_m": after["std_m"],
        "before_std_m": before["std_m"] or 0.0,
        "capture": measured.get("capture"),
        "check": measured.get("check"),
    }


def ground_rows(
    robot: Robot,
    camera: CameraModel,
    truth: Corrections | None,
    models: dict[str, Corrections],
    say: Callable[[str], None],
    distances: tuple[float, ...],
) -> tuple[list[dict], str | None]:
    """`ground_errors` rows of the models before and after [m] against the simulator's truth, or none and why (no
    `floor:` config). Without a truth the reference is the model after, whose error is then not measured: None,
    with 'no_truth' set (it would read 0 by definition)."""
    if robot.config.floor is None:
        return [], (f"{robot.config.path} has no 'floor:' (standing soles and pose): the ground error was not computed")
    say("computing the ground error ...")
    rows = ground_errors(robot, camera, truth if truth is not None else models["after"], models, distances)
    if truth is None:
        for row in rows:
            row["models"]["after"].update(error_m=None, no_truth=True)
    return rows, None


def predicted_ground(
    robot: Robot, camera: CameraModel, result: FitResult, tags: list[int], fitted: Corrections, distance: float
) -> float | None:
    """1-sigma ground error at `distance` [m] from the fit's covariance of its chain parameters (None without
    floor)."""
    covariance = result.covariance
    if robot.config.floor is None or not covariance:
        return None
    chain = build_parameter_set(robot, result.free, {HEAD_CAMERA: tags}, result.side, result.fix_tags)
    index = {name: i for i, name in enumerate(covariance["names"])}
    keep = [k for k, name in enumerate(chain.names) if name in index]
    cols = [index[chain.names[k]] for k in keep]
    sub = ParameterSet([chain.parameters[k] for k in keep])
    matrix = np.asarray(covariance["matrix"], dtype=float)[np.ix_(cols, cols)]
    return predicted_ground_std(robot, camera, sub, sub.values_from(fitted), matrix, distance)


def camera_turn(robot: Robot, fitted: Corrections, before: Corrections) -> float:
    """Rotation angle [rad] between the camera frame corrections of the model before and the fitted one (0
    without a head camera)."""
    if robot.config.camera is None:
        return 0.0
    turn = [Rotation.from_rotvec(c.frames.get(robot.camera_joint, np.zeros(6))[3:]) for c in (before, fitted)]
    return float((turn[0].inv() * turn[1]).magnitude())


def ground_section(robot: Robot, from_truth: bool, rows: list[dict], measured: dict | None) -> dict:
    """metrics['ground']: the ground error rows of the standing robot and the one measured on floor views."""
    floor = robot.config.floor
    return {
        "reference": "simulator truth" if from_truth else "calibrated model",
        "standing_pose_rad": dict(floor.standing) if floor else {},
        "soles": list(floor.soles) if floor else [],
        "rows": rows,
        "measured": measured,
    }
