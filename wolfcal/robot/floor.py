"""The floor a robot stands on: the plane of its standing soles (config `floor.soles`), and the standing robot
(config `floor.standing`) in it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.geometry import exp_so3, invert_transform, log_so3
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.derivatives import cross
from wolfcal.robot.robot import Robot
from wolfcal.robot.stances import stance_readings

# why `floor:` is needed, for the error that names the robot config when it is missing
FLOOR_NEEDED = "the ground error needs its soles and standing pose: add floor: {soles: [...], standing: {...}}"
# The held-out floor capture that checks a fit (`capture --floor --check`; docs/workflows/floor-check.md, "The held-out
# check"): head views per check stance (the standing legs' tick rounding averages over stances, not over views in one
# stance) and how many times it is taken, the floor tags moved between (a tag's corner bias averages over the places it
# lies in)
CHECK_VIEWS_PER_STANCE = 1
CHECK_LAYOUTS = 3


def floor_frames(sole_poses: np.ndarray) -> np.ndarray:
    """T_base_floor (N, 4, 4) from the poses of the soles (K, N, 4, 4) in the base frame: origin midway between
    the soles, z along their mean z axis, x along their mean x axis made orthogonal to z."""
    origin = sole_poses[:, :, :3, 3].mean(axis=0)
    z = sole_poses[:, :, :3, 2].mean(axis=0)
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = sole_poses[:, :, :3, 0].mean(axis=0)
    x -= np.einsum("ni,ni->n", x, z)[:, None] * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    T = np.tile(np.eye(4), (len(origin), 1, 1))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2], T[:, :3, 3] = x, np.cross(z, x), z, origin
    return T


def floor_tag_poses(robot: Robot, places: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """T_floor_tag (4, 4) of each floor tag lying face up at its place (x, y, yaw) [m, rad]."""
    out = {}
    for tag_id, (x, y, yaw) in places.items():
        T = np.eye(4)
        T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
        T[:3, 3] = x, y, robot.config.floor_config().tag(tag_id).thickness
        out[tag_id] = T
    return out


def floor_frame_twists(sole_poses: np.ndarray, sole_twists: np.ndarray) -> np.ndarray:
    """(N, C, 6) spatial twists (v0, w) of the floor frame (`floor_frames`) from the sole poses (K, N, 4, 4) and the
    soles' twists (K, N, C, 6) per column (joint reading or parameter), all in one root frame. The floor frame is
    rigid, so its motion is a twist: the origin moves with the mean of the soles' origins; the rotation's angular
    velocity is w = 1/2 sum_i e_i x de_i over its axes e_i, each differentiated through the means and
    normalisations of `floor_frames`."""
    T = floor_frames(sole_poses)  # (N, 4, 4)
    o_k, z_k, x_k = sole_poses[..., None, :3, 3], sole_poses[..., None, :3, 2], sole_poses[..., None, :3, 0]
    v0_k, w_k = sole_twists[..., :3], sole_twists[..., 3:]
    d_origin = (v0_k + cross(w_k, o_k)).mean(axis=0)  # (N, C, 3)
    z_raw, x_raw = sole_poses[:, :, :3, 2].mean(axis=0), sole_poses[:, :, :3, 0].mean(axis=0)  # (N, 3)
    dz_raw, dx_raw = cross(w_k, z_k).mean(axis=0), cross(w_k, x_k).mean(axis=0)  # (N, C, 3)
    x, y, z, origin = T[:, None, :3, 0], T[:, None, :3, 1], T[:, None, :3, 2], T[:, None, :3, 3]
    dz = (dz_raw - np.sum(dz_raw * z, axis=-1, keepdims=True) * z) / np.linalg.norm(z_raw, axis=-1)[:, None, None]
    xz = np.sum(x_raw[:, None] * z, axis=-1, keepdims=True)  # (N, 1, 1)
    x_perp = x_raw[:, None] - xz * z
    dx_perp = (
        dx_raw
        - (np.sum(dx_raw * z, axis=-1, keepdims=True) + np.sum(x_raw[:, None] * dz, axis=-1, keepdims=True)) * z
        - xz * dz
    )
    dx = (dx_perp - np.sum(dx_perp * x, axis=-1, keepdims=True) * x) / np.linalg.norm(x_perp, axis=-1, keepdims=True)
    dy = cross(dz, x) + cross(z, dx)
    w = 0.5 * (cross(x, dx) + cross(y, dy) + cross(z, dz))
    return np.concatenate([d_origin - cross(w, origin), w], axis=-1)


def standing_pose(robot: Robot) -> np.ndarray:
    """(J,) encoder readings of the standing robot: the config's `floor.standing`, other joints 0 [rad]."""
    return stance_readings([robot.config.floor_config(FLOOR_NEEDED).standing], robot.model)[0]


def stance_poses(robot: Robot, check: bool = False) -> np.ndarray:
    """(K, J) encoder readings of the stances floor samples are taken in: the config's `floor.stances`, else
    `floor.standing` alone; with `check` (the held-out capture that checks a fit) `floor.check_stances`; other
    joints 0 [rad]. A WolfcalError for `check` without `floor.check_stances`."""
    stances = robot.config.floor_config(FLOOR_NEEDED).capture_stances(check)
    if not stances:
        raise WolfcalError(f"{robot.config.path}: --check takes the held-out floor capture in 'floor.check_stances', "
                           "which the config does not give: list standing poses there, none of the fit's "
                           "(see the floor-check workflow in the docs, \"The held-out check\")")  # fmt: skip
    return stance_readings(stances, robot.model)


def check_size(robot: Robot) -> dict[str, int] | None:
    """The check's samples, stances and tag layouts on this robot: its config's `floor.check_stances`,
    CHECK_VIEWS_PER_STANCE head views in each, taken CHECK_LAYOUTS times; None when the config lists no check
    stances."""
    stances = len(robot.config.floor_config(FLOOR_NEEDED).check_stances)
    if not stances:
        return None
    return {"samples": stances * CHECK_VIEWS_PER_STANCE * CHECK_LAYOUTS, "stances": stances, "layouts": CHECK_LAYOUTS}


def camera_in_floor(
    robot: Robot, q: np.ndarray, corrections: Corrections, camera_frame: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """T_floor_camera (N, 4, 4) and T_floor_base (N, 4, 4) for readings q (N, J) under a model."""
    frame = camera_frame or robot.config.head_camera("the ground error needs the head camera").frame
    soles = list(robot.config.floor_config(FLOOR_NEEDED).soles)
    poses = robot.model.link_poses(q, [frame, *soles], corrections, base=robot.config.base_link)
    T_floor_base = invert_transform(floor_frames(np.stack([poses[s] for s in soles])))
    return T_floor_base @ poses[frame], T_floor_base


def moved_stance(robot: Robot, stance: Mapping[str, float], shift: Sequence[float]) -> dict[str, float]:
    """Readings [rad] of a stance with the torso moved by `shift` (dx, dy, dz [m] along the floor's axes, yaw [rad]
    about the vertical through the base; or dx, dy, dz, then a rotation vector rx, ry, rz [rad] about the floor's
    axes through the base: a tilted torso) from `stance` (joint -> rad; not stretched legs, where a knee could bend
    either way), the soles (config `floor.soles`) kept where they stand, under the nominal model: the actuated
    joints between the base and the soles solved by least squares (each sole's position [m] and rotation [rad]),
    within their URDF limits, in ten steps along the move; other joints as in `stance`. Rounded to 0.1 mrad. A
    WolfcalError when the soles cannot be kept within 1 mm and 1 mrad (beyond the legs' reach)."""
    from scipy.optimize import least_squares  # a config-writing tool's, kept off the fit's import path

    model, base = robot.model, robot.config.base_link
    soles = list(robot.config.floor_config(FLOOR_NEEDED).soles)
    q0 = stance_readings([stance], model)
    T_base_sole = np.stack([model.link_poses(q0, soles, base=base)[s] for s in soles])  # (K, 1, 4, 4)
    T_floor_base = invert_transform(floor_frames(T_base_sole))[0]
    joints = robot.actuated_joints_to(soles)
    columns = [model.column(j) for j in joints]
    lower, upper = (np.array([getattr(model.joints[j], side) for j in joints]) for side in ("lower", "upper"))

    def residuals(x: np.ndarray, target: np.ndarray) -> np.ndarray:
        q = q0.copy()
        q[0, columns] = x
        poses = model.link_poses(q, soles, base=base)
        T = np.stack([poses[s][0] for s in soles])
        rotation = log_so3(np.swapaxes(target[:, :3, :3], 1, 2) @ T[:, :3, :3])
        return np.concatenate([(T[:, :3, 3] - target[:, :3, 3]).ravel(), rotation.ravel()])

    rotation = np.array([0.0, 0.0, shift[3]]) if len(shift) == 4 else np.asarray(shift[3:6], dtype=float)
    x = np.clip(q0[0, columns], lower, upper)
    for fraction in np.linspace(0.1, 1.0, 10):  # in steps from the standing pose: the legs stay on its branch
        T_new = T_floor_base.copy()
        T_new[:3, :3] = exp_so3(fraction * rotation) @ T_floor_base[:3, :3]
        T_new[:3, 3] += fraction * np.asarray(shift[:3])
        target = invert_transform(T_new) @ T_floor_base @ T_base_sole[:, 0]  # (K, 4, 4) the soles stay put
        x = least_squares(residuals, x, bounds=(lower, upper), xtol=1e-12, ftol=1e-12, args=(target,)).x
    r = np.abs(residuals(x, target))
    n = 3 * len(soles)
    if r[:n].max() > 1e-3 or r[n:].max() > 1e-3:
        raise WolfcalError(f"{robot.config.path}: the torso moved by {[float(v) for v in shift]} (dx, dy, dz [m], "
                           f"yaw [rad]) leaves the soles {r[:n].max() * 1000:.1f} mm and {r[n:].max() * 1000:.1f} "
                           "mrad from where they stand: take a smaller move")  # fmt: skip
    moved = dict(stance)
    moved.update({j: round(float(v), 4) for j, v in zip(joints, x)})
    return moved
