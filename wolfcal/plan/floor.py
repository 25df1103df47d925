"""Planning floor samples (`--system floor`): head pan/tilt while the robot stands, and the fit's floor blocks.

The robot stands at the config's `floor.standing` readings (other joints 0, as `capture --floor` and the ground error
take it) and only the joints that aim the head camera move (`wolfcal.robot.aim.aim_joints`: pan and tilt),
drawn uniform within their URDF limits shrunk by the margin. The floor tags' places are unknowns of the fit, so a
plan assumes a layout and prints it: tag k of `floor.tags` lies face up (yaw 0) at the k-th of K distances evenly
from the nearest to the farthest point `capture --floor` aims at, at bearings spread over its bearing range
(`expected_places`). A candidate keeps CLEARANCE_M between the robot's bodies (the standing legs checked once) and
shows at least one floor tag whole, IMAGE_EDGE_MARGIN of the width inside the image, each edge at least
MIN_EDGE_PX long (the simulator's floor rule; no angle limit: a tag on the floor is seen at a grazing angle, and the
fit weights small views by their apparent size), the line from the camera to every corner missing the robot's body.
Information: noise-free corners of the floor tags under the nominal model handed to the fit's own `FloorBlock`
(each pose its own noise group, the tags' places and the corner inset its nuisance unknowns) and, for the chosen n
poses, the fit's `SoleClosure` (the same standing legs in every sample, counted as the fit counts it: once per
sample). The fit shares the standing legs' reading error between all floor samples (`FloorBlock.
joint_reading_groups`); the selection counts it per pose (`PosewiseFloorBlock`), so that a pose's information adds
up, while the std the plan reports comes from the fit's own floor blocks on the chosen poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block
from wolfcal.fit.floor_block import FloorBlock, SoleClosure
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import block_sigmas, floor_blocks
from wolfcal.fit.problem import Problem
from wolfcal.geometry import invert_transform, tag_corners
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.plan.candidates import (
    BATCH,
    CLEARANCE_M,
    IMAGE_EDGE_MARGIN,
    Candidates,
    PlanCamera,
    draw_until,
    joint_bounds,
)
from wolfcal.plan.information import plan_problem
from wolfcal.projection import tag_corner_pixels, visible_in_view
from wolfcal.robot.aim import AIM_BEARINGS_DEG, AIM_DISTANCES_M, aim_joints
from wolfcal.robot.collision import CollisionModel
from wolfcal.robot.floor import floor_frames, floor_tag_poses, standing_pose
from wolfcal.robot.parameters import ParameterSet, build_parameter_set
from wolfcal.robot.robot import Robot

MIN_EDGE_PX = 12.0  # shortest edge of a floor tag view [px] (as `wolfcal.sim.floor.floor_views`)
GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0  # spreads the bearings of successive tags


def expected_places(robot: Robot) -> dict[int, np.ndarray]:
    """(x, y, yaw) [m, rad] in the floor frame of each floor tag as a plan assumes them (see the module docstring);
    a clear error without floor tags."""
    floor = robot.config.floor_config(
        "--system floor plans the head's views of tags lying on the floor: add floor: {soles, standing, tags}"
    )
    if not floor.tags:
        raise WolfcalError(f"{robot.config.path}: 'floor.tags' lists no floor tag; --system floor plans the head's "
                           "views of the tags lying on the floor: add them ({id, family, size})")  # fmt: skip
    K = len(floor.tag_ids)
    near, far = min(AIM_DISTANCES_M), max(AIM_DISTANCES_M)
    distance = np.linspace(near, far, K) if K > 1 else np.array([0.5 * (near + far)])
    spread = (np.arange(K) * GOLDEN) % 1.0 if K > 1 else np.array([0.5])
    bearing = np.deg2rad(min(AIM_BEARINGS_DEG) + (max(AIM_BEARINGS_DEG) - min(AIM_BEARINGS_DEG)) * spread)
    return {t: np.array([distance[k] * np.cos(bearing[k]), distance[k] * np.sin(bearing[k]), 0.0])
            for k, t in enumerate(floor.tag_ids)}  # fmt: skip


def places_text(places: dict[int, np.ndarray]) -> str:
    """One line for the poses file and the table: where the plan assumes each floor tag."""
    return "; ".join(f"tag {t} at x {p[0]:.2f} m, y {p[1]:+.2f} m" for t, p in places.items())


def _camera_and_floor(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """T_root_camera and T_root_floor (N, 4, 4) under the nominal model at readings q (N, J) [m]."""
    frame, soles = robot.config.head_camera().frame, list(robot.config.floor_config().soles)
    poses = robot.model.link_poses(q, [frame, *soles])
    return poses[frame], floor_frames(np.stack([poses[s] for s in soles]))


def _floor_tags_seen(robot: Robot, q: np.ndarray, places: dict[int, np.ndarray]) -> tuple[np.ndarray, ...]:
    """T_root_camera (N, 4, 4), T_root_tag and T_camera_tag (N, T, 4, 4) of the floor tags (floor.tag_ids) at their
    places, under the nominal model at readings q (N, J)."""
    T_root_camera, T_root_floor = _camera_and_floor(robot, q)
    tag_poses = floor_tag_poses(robot, places)
    T_floor_tag = np.stack([tag_poses[t] for t in robot.config.floor_config().tag_ids])  # (T, 4, 4)
    T_root_tag = T_root_floor[:, None] @ T_floor_tag[None]
    return T_root_camera, T_root_tag, invert_transform(T_root_camera)[:, None] @ T_root_tag


def floor_views(robot: Robot, camera: PlanCamera, q: np.ndarray, places: dict[int, np.ndarray],
                collisions: CollisionModel | None = None) -> np.ndarray:  # fmt: skip
    """(N, T) bool over floor.tag_ids: tag whole in view, large enough and (with `collisions`) not hidden by the
    robot's body (see the module docstring)."""
    floor = robot.config.floor_config()
    T_root_camera, T_root_tag, T_camera_tag = _floor_tags_seen(robot, q, places)
    sizes = np.array([floor.tag(t).size for t in floor.tag_ids])
    width = camera.model.width
    visible = visible_in_view(camera.model, T_camera_tag, sizes, IMAGE_EDGE_MARGIN * width, MIN_EDGE_PX, np.pi / 2)
    if collisions is None or not visible.any():
        return visible
    corners = np.stack([tag_corners(s) for s in sizes])  # (T, 4, 3)
    points = np.einsum("ntij,tcj->ntci", T_root_tag[..., :3, :3], corners) + T_root_tag[:, :, None, :3, 3]
    viewer = collisions.body_of_link[robot.config.head_camera().frame]
    skip = np.tile([[viewer, -1]], (points.shape[1] * 4, 1))
    hidden = collisions.blocked(q, T_root_camera[:, :3, 3], points.reshape(len(q), -1, 3), skip)
    return visible & ~hidden.reshape(len(q), len(sizes), 4).any(axis=2)


def draw_floor_candidates(
    robot: Robot,
    camera: PlanCamera,
    places: dict[int, np.ndarray],
    n: int,
    rng: np.random.Generator,
    collisions: CollisionModel,
    margin: float = 0.1,
) -> Candidates:
    """Up to n standing poses with the head aimed at random (pan/tilt within their limits shrunk by `margin` [rad]),
    each showing a floor tag (module docstring)."""
    joints = aim_joints(robot)
    lo, hi = joint_bounds(robot, joints, margin)
    standing = standing_pose(robot)
    aim = [robot.model.column(j) for j in joints]
    others = ~np.isin(np.arange(len(lo)), aim)
    lo[others] = hi[others] = standing[others]
    moved = collisions.pairs_moved_by(joints)
    if not collisions.collision_free(standing[None], CLEARANCE_M, ~moved)[0]:
        raise WolfcalError(f"{robot.config.path}: the standing pose 'floor.standing' makes the robot touch itself "
                           "(collision model); check its readings")  # fmt: skip
    rejected = {"self-collision": 0, "no floor tag in view": 0}

    def batch() -> tuple[np.ndarray, np.ndarray, int]:
        q = rng.uniform(lo, hi, size=(BATCH, len(lo)))
        free = collisions.collision_free(q, CLEARANCE_M, moved)
        rejected["self-collision"] += int((~free).sum())
        q = q[free]
        visible = floor_views(robot, camera, q, places, collisions)
        ok = visible.any(axis=1)
        rejected["no floor tag in view"] += int((~ok).sum())
        return q[ok], visible[ok], BATCH

    q, visible, drawn = draw_until(n, batch)
    if not len(q):
        raise WolfcalError(
            f"none of {drawn} head poses ({', '.join(joints)} within their limits, legs standing) shows a floor tag "
            f"whole and at least {MIN_EDGE_PX:.0f} px wide at the places the plan assumes ({places_text(places)}); "
            "check the floor tags' sizes, the camera's intrinsics and 'floor.standing'"
        )
    written = set(joints) | set(robot.actuated_joints_to(list(robot.config.floor_config().soles)))
    return Candidates(q, visible, [j for j in robot.joint_names if j in written], drawn, rejected)


class PosewiseFloorBlock(FloorBlock):
    """The fit's floor block with each pose's joint readings its own error (the selection's additive model)."""

    def joint_reading_groups(self) -> np.ndarray:
        return Block.joint_reading_groups(self)  # the still pose's, as every other block


@dataclass
class FloorPlanModel:
    """The floor fit a plan is made for (same interface as `wolfcal.plan.information.PlanModel`)."""

    robot: Robot
    camera: PlanCamera
    preset: str
    side: str
    places: dict[int, np.ndarray]

    def observations(self, q: np.ndarray, visible: np.ndarray) -> Observations:
        """Noise-free corners of the visible floor tags (visible: (N, T) over floor.tag_ids) at readings q (N, J)."""
        floor = self.robot.config.floor_config()
        T_camera_tag = _floor_tags_seen(self.robot, q, self.places)[2]
        s, t = np.nonzero(visible)
        corners = np.stack([tag_corners(floor.tag(i).size) for i in floor.tag_ids])[t]  # (V, 4, 3)
        return Observations.of_views(
            list(self.robot.joint_names), q, np.arange(len(q), dtype=np.int64), ["plan"] * len(q), self.camera.model,
            s, np.array(floor.tag_ids)[t], tag_corner_pixels(self.camera.model, T_camera_tag[s, t], corners),
        )  # fmt: skip

    def chain(self) -> ParameterSet:
        return build_parameter_set(self.robot, self.preset, {HEAD_CAMERA: []}, self.side)

    def problem(self, q: np.ndarray, visible: np.ndarray, independent: bool = False) -> Problem:
        """The fit's floor problem on these poses (`fit.pipeline.floor_blocks`; a tag seen once left out), or with
        `independent` the floor block alone, every pose its own noise group (the sole closure: `repeated_...`)."""
        if not independent:  # a floor tag seen once, which the fit refuses, left out as a user would remove it
            visible = visible & (visible.sum(axis=0) >= 2)
        obs = self.observations(q, visible)
        options = FitOptions(free=self.preset, side=self.side)
        blocks = [PosewiseFloorBlock(self.robot, obs)] if independent else floor_blocks(self.robot, obs, options)
        sigmas, encoder = block_sigmas(self.robot, blocks), self.robot.config.priors.encoder_noise
        return plan_problem(self.chain(), blocks, sigmas, encoder)

    def repeated_information(self, problem: Problem, q: np.ndarray, visible: np.ndarray, n: int) -> np.ndarray:
        """(P, P) the sole closure's information [z units] in n floor samples (the standing legs, the same in every
        pose): that of the fit's problem on n of the candidates less its floor block's."""
        P = len(problem.params)
        out = np.zeros((P, P))
        if len(self.robot.config.floor_config().soles) != 2:
            return out
        obs = self.observations(q[:n], visible[:n])
        blocks = [SoleClosure(self.robot, obs)]
        sigmas, encoder = block_sigmas(self.robot, blocks), self.robot.config.priors.encoder_noise
        closure = plan_problem(self.chain(), blocks, sigmas, encoder)
        c = len(closure.params)
        if closure.params.names != problem.params.names[:c]:
            raise RuntimeError("the sole closure's problem has other chain unknowns than the candidates'")
        J = np.asarray(closure.data_jacobian(np.zeros(c), robust=False))
        out[:c, :c] = J.T @ J
        return out
