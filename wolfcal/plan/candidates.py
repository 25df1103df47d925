"""Candidate calibration poses: random joint readings inside the URDF limits that show the tags and do not collide.

The joints a plan moves are those between the base and the viewer and between the base and each tag used; each is
drawn uniformly within its URDF limits shrunk by `margin` [rad] at both ends, the others stand at the rest pose.
Joint values are readings of the nominal model [rad] (what the servos are commanded to). A configuration is kept
when the camera sees the tags it needs in full (head camera: at least one used tag; external camera: the tags fixed
to the base and one other, as the simulator asks, `wolfcal.sim`), none of them hidden by the robot's own body (the
line from the camera centre to each corner misses every capsule but those of the tag's and the viewer's bodies),
and no two bodies come closer than CLEARANCE_M (`wolfcal.robot.collision`).

How they are drawn (a fair sample: every candidate is a uniform draw over the joint box, kept by exact tests, so the
candidates are uniform over the valid poses): the joints that move the tags (the legs) are drawn first and checked
against the capsule pairs the head joints do not move (their distance is the same for every head configuration);
for each leg configuration that passes, VIEWS_PER_BODY head configurations are drawn, each uniform over the head's
range, and every (legs, head) pair is tested in full: tags in view (tag poses from the legs' pass, camera pose from
the head's), the pairs the head moves, line of sight. Rejecting the legs before drawing the head rejects exactly the
pairs the full test would; what it saves is the legs' forward kinematics and most collision checks, which plain
rejection repeats for every pose drawn (only about 1 in 400 uniform poses shows a foot tag without colliding).
Candidates that share a leg configuration (on average about one per leg configuration) are not independent draws;
each one is uniform over the valid poses. An external camera has no head joints: each configuration is drawn whole.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.external_view import external_pose_ok, external_visibility
from wolfcal.geometry import invert_transform, tag_corners
from wolfcal.observations import HEAD_CAMERA
from wolfcal.placement import expected_placement, placement_from_text
from wolfcal.projection import visible_in_view
from wolfcal.robot.collision import CollisionModel
from wolfcal.robot.collision_sources import rest_configuration
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

BATCH = 4000  # configurations of the joints that move the tags drawn at a time
VIEWS_PER_BODY = 128  # head camera: configurations of the head drawn for each of them
VIEWS_AT_A_TIME = 16_384  # configurations judged at once (bounds the memory of a batch's link poses)
MAX_DRAWN = 1_000_000  # configurations drawn at most
HOPELESS_DRAWN = 100_000  # give up after this many configurations without a single candidate
CLEARANCE_M = 0.005  # smallest distance kept between two bodies of a candidate pose [m]
SELF_COLLISION_SHARE = 0.9  # a draw that finds nothing blames the collision model when it rejected this share
HINT_POSES = 500  # random poses that tell which link pair the collision model rejects most


@dataclass(frozen=True)
class PlanCamera:
    """The camera a plan is made for: the head camera or an external camera at an expected placement."""

    name: str  # 'head' or the external camera's name in the robot config
    model: CameraModel
    T_base_camera: np.ndarray | None = None  # (4, 4) external cameras only [m]

    @property
    def external(self) -> bool:
        return self.name != HEAD_CAMERA

    def pose(self) -> np.ndarray:
        """T_base_camera (4, 4) of an external camera [m]; a clear error for the head camera (it moves)."""
        if self.T_base_camera is None:
            raise WolfcalError(f"camera {self.name!r} has no fixed placement (the head camera moves with the head)")
        return self.T_base_camera


@dataclass
class Candidates:
    q: np.ndarray  # (N, J) joint readings [rad], model order
    visible: np.ndarray  # (N, T) bool over robot.config.tag_ids: tag used and well in view
    joints: list[str]  # the joints the plan moves
    drawn: int  # configurations drawn to find them
    rejected: dict[str, int]  # configurations left out, by reason


def plan_camera(robot: Robot, system: str, external: str | None = None, placement: str | None = None) -> PlanCamera:
    """The camera of a --system (head | external), its intrinsics from the robot config; an external camera at
    `placement` ('x,y,z,roll,pitch,yaw', see `wolfcal.placement`) or the simulator's expected placement."""
    if system == "head":
        name = HEAD_CAMERA
        robot.config.head_camera("--system head plans for it")
    else:
        if not robot.config.external_cameras:
            raise WolfcalError(f"{robot.config.path}: --system external needs a camera under 'external_cameras:'")
        name = external or robot.config.external_cameras[0].name
    intrinsics = robot.config.intrinsics_file(name, "the plan")
    T = None if name == HEAD_CAMERA else (placement_from_text(placement) if placement else expected_placement())
    return PlanCamera(name, load_camera_info(intrinsics), T)


def plan_joints(robot: Robot, camera: PlanCamera, tag_ids: list[int]) -> list[str]:
    """The joints that move the used tags relative to the camera, in model order."""
    links = [robot.config.tag(t).link for t in tag_ids]
    if not camera.external:
        links.append(robot.config.head_camera().frame)
    moved = set(robot.actuated_joints_to(links))
    return [j for j in robot.joint_names if j in moved]


def joint_bounds(robot: Robot, joints: list[str], margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) readings (J,) [rad]: `joints` within their limits shrunk by margin, the others at rest."""
    lo, hi = rest_configuration(robot), rest_configuration(robot)
    for name in joints:
        joint, k = robot.model.joints[name], robot.model.column(name)
        a, b = max(joint.lower, -np.pi) + margin, min(joint.upper, np.pi) - margin
        if a > b:
            raise WolfcalError(f"{robot.config.urdf}: joint {name} has a range narrower than twice the margin")
        lo[k], hi[k] = a, b
    return lo, hi


# A head-camera tag must lie this share of the image width inside every edge under the nominal model: before
# calibration the head joints and the camera may be several degrees off (0.15 of a 60 deg wide image is 9 deg), and
# a plan whose tags leave the image on the real robot is no plan (margins of 3 % and 10 % each lost a tag on a robot
# with a 3.5 deg camera error and 2 deg head offsets).
IMAGE_EDGE_MARGIN = 0.15


def base_tag_poses(robot: Robot, q: np.ndarray, tag_ids: list[int]) -> np.ndarray:
    """T_base_tag (N, T, 4, 4) of `tag_ids` at readings q (N, J) under the nominal model [m]."""
    config = robot.config
    poses = robot.model.link_poses(q, [config.tag(t).link for t in tag_ids], base=config.base_link)
    return np.stack([poses[config.tag(t).link] @ robot.T_link_tag(t) for t in tag_ids], axis=1)


def tag_views(
    robot: Robot, camera: PlanCamera, q: np.ndarray, tag_ids: list[int], T_base_tag: np.ndarray | None = None
) -> np.ndarray:
    """(N, T) bool over config.tag_ids: tag in `tag_ids`, fully in the image with a margin, large and facing the
    camera (the simulator's rules, `wolfcal.projection.visible_in_view`, nominal model); line of sight is checked by
    `line_of_sight`.
    Head camera: T_base_tag (N, len(used), 4, 4) of the used tags in config order, when known, saves their FK."""
    nominal = Corrections()
    used = np.isin(robot.config.tag_ids, tag_ids)
    if camera.external:
        return external_visibility(robot, camera.model, camera.pose(), q, nominal) & used
    width = camera.model.width
    out = np.zeros((len(q), len(used)), dtype=bool)
    ids = [t for t in robot.config.tag_ids if t in tag_ids]  # only the used tags are projected
    if T_base_tag is None:
        T_base_tag = base_tag_poses(robot, q, ids)
    frame = robot.config.head_camera().frame
    T_base_camera = robot.model.link_poses(q, [frame], base=robot.config.base_link)[frame]
    T_camera_tag = invert_transform(T_base_camera)[:, None] @ T_base_tag
    sizes = np.array([robot.config.tag(t).size for t in ids])
    out[:, used] = visible_in_view(camera.model, T_camera_tag, sizes, IMAGE_EDGE_MARGIN * width, 0.02 * width)
    return out


def line_of_sight(robot: Robot, camera: PlanCamera, q: np.ndarray, collisions: CollisionModel) -> np.ndarray:
    """(N, T) bool over config.tag_ids: no capsule (but the tag's and the viewer's bodies) between the camera centre
    and any corner of the tag."""
    config = robot.config
    links = [config.tag(t).link for t in config.tag_ids]
    viewer = config.base_link if camera.external else config.head_camera().frame
    poses = robot.model.link_poses(q, links + [viewer])
    T_root_camera = poses[viewer] @ (camera.T_base_camera if camera.external else np.eye(4))
    corners = []
    for t in config.tag_ids:
        T_root_tag = poses[config.tag(t).link] @ robot.T_link_tag(t)
        corners.append(np.einsum("nij,cj->nci", T_root_tag[:, :3, :3], tag_corners(config.tag(t).size))
                       + T_root_tag[:, None, :3, 3])  # fmt: skip
    points = np.concatenate(corners, axis=1)  # (N, 4T, 3)
    body = collisions.body_of_link
    viewer_body = -1 if camera.external else body[viewer]
    skip = np.repeat([[body[config.tag(t).link], viewer_body] for t in config.tag_ids], 4, axis=0)
    blocked = collisions.blocked(q, T_root_camera[:, :3, 3], points, skip)
    return np.asarray(~blocked.reshape(len(q), len(config.tag_ids), 4).any(axis=2), dtype=bool)


def pose_ok(robot: Robot, camera: PlanCamera, visible: np.ndarray) -> np.ndarray:
    """(N,) bool: the camera sees what it needs (see the module docstring)."""
    if camera.external:
        return np.asarray(external_pose_ok(robot, visible), dtype=bool)
    return np.asarray(visible.any(axis=1), dtype=bool)


def viewer_joints(robot: Robot, camera: PlanCamera, joints: list[str]) -> list[str]:
    """Those of the plan's `joints` that move the camera (the head camera's chain; none for an external camera)."""
    if camera.external:
        return []
    moving = set(robot.actuated_joints_to([robot.config.head_camera().frame]))
    return [j for j in joints if j in moving]


def draw_until(n: int, batch: Callable[[], tuple[np.ndarray, np.ndarray, int]]) -> tuple[np.ndarray, np.ndarray, int]:
    """Calls `batch` (the candidates it keeps (k, J), what each shows (k, ...), how many it drew) until n are kept,
    MAX_DRAWN are drawn, or HOPELESS_DRAWN are drawn without one kept; returns the first n kept, what they show and
    the number drawn."""
    kept_q, kept_v, drawn = [], [], 0
    while drawn < MAX_DRAWN:
        q, visible, count = batch()
        kept_q.append(q)
        kept_v.append(visible)
        drawn += count
        found = sum(len(k) for k in kept_q)
        if found >= n or (not found and drawn >= HOPELESS_DRAWN):
            break
    return np.concatenate(kept_q)[:n], np.concatenate(kept_v)[:n], drawn


def draw_candidates(
    robot: Robot,
    camera: PlanCamera,
    tag_ids: list[int],
    n: int,
    rng: np.random.Generator,
    collisions: CollisionModel,
    margin: float = 0.1,
) -> Candidates:
    """Up to n candidate poses (see the module docstring), the joints drawn within their limits shrunk by `margin`
    [rad]; a clear error when none shows the tags."""
    if not tag_ids:
        raise WolfcalError(f"{robot.config.path}: no tag of 'tags:' is one the {camera.name} camera's plan can use")
    joints = plan_joints(robot, camera, tag_ids)
    lo, hi = joint_bounds(robot, joints, margin)
    aim = [robot.model.column(j) for j in viewer_joints(robot, camera, joints)]
    per_body = VIEWS_PER_BODY if aim else 1
    moved = collisions.pairs_moved_by([robot.joint_names[k] for k in aim])
    ids = [t for t in robot.config.tag_ids if t in tag_ids]
    tag_joints = robot.actuated_joints_to([robot.config.tag(t).link for t in ids])
    factored = bool(aim) and not {robot.joint_names[k] for k in aim} & set(tag_joints)  # tags don't move with the head
    rejected = {"tags not in view": 0, "self-collision": 0, "tags hidden by the body": 0}

    def keep(q: np.ndarray, T_base_tag: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The configurations q (m, J) that show the tags, with what each shows."""
        visible = tag_views(robot, camera, q, tag_ids, T_base_tag)
        ok = pose_ok(robot, camera, visible)
        rejected["tags not in view"] += int((~ok).sum())
        q, visible = q[ok], visible[ok]
        free = collisions.collision_free(q, CLEARANCE_M, moved)
        rejected["self-collision"] += int((~free).sum())
        q, visible = q[free], visible[free]
        if len(q):
            visible &= line_of_sight(robot, camera, q, collisions)
        ok = pose_ok(robot, camera, visible)
        rejected["tags hidden by the body"] += int((~ok).sum())
        return q[ok], visible[ok]

    def batch() -> tuple[np.ndarray, np.ndarray, int]:
        q = rng.uniform(lo, hi, size=(BATCH, len(lo)))
        free = collisions.collision_free(q, CLEARANCE_M, ~moved)  # the pairs the viewer's joints do not move
        rejected["self-collision"] += int((~free).sum()) * per_body
        q_body = q[free]
        q = np.repeat(q_body, per_body, axis=0)
        q[:, aim] = rng.uniform(lo[aim], hi[aim], size=(len(q), len(aim)))  # the viewer's joints, drawn anew
        bodies = max(1, VIEWS_AT_A_TIME // per_body)  # the views of this many bodies are judged at a time
        kept = []
        for start in range(0, len(q_body), bodies):
            part = q[start * per_body : (start + bodies) * per_body]
            body_part = q_body[start : start + bodies]
            kept.append(keep(part, np.repeat(base_tag_poses(robot, body_part, ids), per_body, 0) if factored else None))
        if not kept:
            return q[:0], np.zeros((0, len(robot.config.tag_ids)), dtype=bool), BATCH * per_body
        return np.concatenate([k[0] for k in kept]), np.concatenate([k[1] for k in kept]), BATCH * per_body

    q, visible, drawn = draw_until(n, batch)
    if not len(q):
        what = "the tags fixed to the base and another tag" if camera.external else "a tag"
        message = (f"none of {drawn} random poses within the joint limits shows the {camera.name} camera {what} "
                   f"(tags {', '.join(map(str, tag_ids))}; left out: "
                   + ", ".join(f"{k} {v}" for k, v in rejected.items()) + ")")  # fmt: skip
        if rejected["self-collision"] >= SELF_COLLISION_SHARE * drawn:
            sample = rng.uniform(lo, hi, size=(HINT_POSES, len(lo)))
            raise WolfcalError(f"{message}: {collisions.rejection_hint(sample, CLEARANCE_M)}")
        raise WolfcalError(f"{message}; check the tags' links and poses in the robot config, the camera's intrinsics "
                           "and placement")  # fmt: skip
    return Candidates(q, visible, joints, drawn, rejected)
