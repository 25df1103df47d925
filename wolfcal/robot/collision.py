"""The robot's body as capsules: self-collision and line of sight, vectorised over configurations.

Geometry, in this order of preference:
- the URDF's `<collision>` geometry, each shape bounded by a capsule (cylinder: its axis and radius; sphere: a point;
  box: its longest edge, radius half the diagonal of the other two; mesh: that of its oriented bounding box; see
  `wolfcal.robot.collision_urdf`);
- otherwise `collision_radii: {link: m}` of the robot config: per listed link, capsules from the link's origin to
  the origin of each of its child joints (a sphere at the origin for a link without children).
Capsules of links joined by fixed joints form one body. Pairs never checked (as in MoveIt's allowed-collision
matrix): bodies joined by one joint, and bodies touching in the rest pose (`rest_pose:`, others 0), where the robot
stands without harm. Joint values are readings of the nominal model [rad]; lengths in metres, in the root frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.robot.collision_urdf import urdf_collision_segments
from wolfcal.robot.robot import Robot

REST_CLEARANCE_M = 0.005  # bodies closer than this in the rest pose are never checked against each other
PAIR_CHUNK = 16  # capsule pairs checked at a time by `CollisionModel.collision_free`
EXACT_BELOW_M = 0.05  # capsule pairs whose bounding spheres are further apart need no exact distance [m]


@dataclass(frozen=True)
class Capsule:
    link: str
    body: int  # index of the rigid body (links joined by fixed joints)
    a_link: np.ndarray  # (3,) segment start in the link frame [m]
    b_link: np.ndarray  # (3,) segment end in the link frame [m]
    radius: float  # [m]


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """(...) shortest distance between segments p0-p1 and q0-q1 ((..., 3) each, broadcast) [m] (closest points of
    two segments, Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e = np.sum(d1 * d1, -1), np.sum(d2 * d2, -1)
    b, c, f = np.sum(d1 * d2, -1), np.sum(d1 * r, -1), np.sum(d2 * r, -1)
    tiny = 1e-18
    denom = a * e - b * b
    s = np.where(denom > tiny, np.clip((b * f - c * e) / np.maximum(denom, tiny), 0.0, 1.0), 0.0)
    t = np.where(e > tiny, (b * s + f) / np.maximum(e, tiny), 0.0)
    s = np.where(t < 0.0, np.where(a > tiny, np.clip(-c / np.maximum(a, tiny), 0.0, 1.0), 0.0), s)
    s = np.where(t > 1.0, np.where(a > tiny, np.clip((b - c) / np.maximum(a, tiny), 0.0, 1.0), 0.0), s)
    t = np.clip(t, 0.0, 1.0)
    gap = (p0 + d1 * s[..., None]) - (q0 + d2 * t[..., None])
    return np.linalg.norm(gap, axis=-1)


class CollisionModel:
    """Capsules of a robot's links and the body pairs to check; see the module docstring."""

    def __init__(self, robot: Robot, capsules: list[Capsule], source: str, rest: np.ndarray) -> None:
        self.robot, self.capsules, self.source = robot, capsules, source
        self.links = sorted({c.link for c in capsules})
        self.radius = np.array([c.radius for c in capsules])
        self.body = np.array([c.body for c in capsules])
        i, j = np.triu_indices(len(capsules), k=1)
        keep = self.body[i] != self.body[j]
        adjacent = _adjacent_bodies(robot, self.body_of_link)
        keep &= ~np.array([(self.body[a], self.body[b]) in adjacent for a, b in zip(i, j)], dtype=bool)
        self.pairs = np.stack([i[keep], j[keep]], axis=1)
        rest_distance = self._pair_clearance(np.atleast_2d(rest))[0]
        touching = rest_distance < REST_CLEARANCE_M
        self.pairs, self.rest_distance = self.pairs[~touching], rest_distance[~touching]

    @property
    def body_of_link(self) -> dict[str, int]:
        return _bodies(self.robot)

    def segments(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Capsule segment ends (N, C, 3) each, in the root frame, for joint readings q (N, J)."""
        poses = self.robot.model.link_poses(np.atleast_2d(q), self.links)
        a = np.stack([poses[c.link][:, :3, :3] @ c.a_link + poses[c.link][:, :3, 3] for c in self.capsules], 1)
        b = np.stack([poses[c.link][:, :3, :3] @ c.b_link + poses[c.link][:, :3, 3] for c in self.capsules], 1)
        return a, b

    def pairs_moved_by(self, joints: list[str]) -> np.ndarray:
        """(pairs,) bool over the checked pairs: some of `joints` lies on the chain between the pair's two links, so
        their distance changes with it (the other pairs keep theirs whatever these joints do)."""
        names, model = set(joints), self.robot.model
        return np.array([any(joint.name in names for joint in model.joints_between(self.capsules[i].link,
                                                                                   self.capsules[j].link))
                         for i, j in self.pairs], dtype=bool)  # fmt: skip

    def _pair_clearance(self, q: np.ndarray, which: np.ndarray | None = None) -> np.ndarray:
        """(N, pairs) surface distance of each checked capsule pair (negative: overlap) [m]: exact below EXACT_BELOW_M,
        above it a lower bound (from the distance of the segments' midpoints), enough for every threshold used;
        `which` ((pairs,) bool) keeps some pairs only."""
        a, b = self.segments(q)
        return self._distances(a, b, self.pairs if which is None else self.pairs[which])

    def _distances(self, a: np.ndarray, b: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """(N, len(pairs)) surface distances of capsule pairs (K, 2) with segment ends a, b (N, C, 3) [m]; see
        `_pair_clearance`."""
        i, j = pairs[:, 0], pairs[:, 1]
        mid, half = 0.5 * (a + b), 0.5 * np.linalg.norm(b - a, axis=2)
        d = np.linalg.norm(mid[:, i] - mid[:, j], axis=2) - half[:, i] - half[:, j] - self.radius[i] - self.radius[j]
        n, k = np.nonzero(d < EXACT_BELOW_M)
        ik, jk = i[k], j[k]
        d[n, k] = segment_distance(a[n, ik], b[n, ik], a[n, jk], b[n, jk]) - self.radius[ik] - self.radius[jk]
        return d

    def clearance(self, q: np.ndarray, which: np.ndarray | None = None) -> np.ndarray:
        """(N,) smallest surface distance between checked bodies [m] (negative: they overlap), over the pairs
        `which` ((pairs,) bool, e.g. from `pairs_moved_by`) or all."""
        d = self._pair_clearance(q, which)
        return d.min(axis=1) if d.shape[1] else np.full(len(d), np.inf)

    def collision_free(self, q: np.ndarray, clearance_m: float, which: np.ndarray | None = None) -> np.ndarray:
        """(N,) bool: `clearance(q, which) >= clearance_m`, found faster: the pairs closest in the rest pose (most
        often in contact) are checked first, PAIR_CHUNK at a time, and a configuration is dropped at its first pair
        that is too close."""
        a, b = self.segments(q)
        order = np.flatnonzero(np.ones(len(self.pairs), bool) if which is None else which)
        order = order[np.argsort(self.rest_distance[order], kind="stable")]
        free, rows = np.ones(len(a), dtype=bool), np.arange(len(a))
        for start in range(0, len(order), PAIR_CHUNK):
            if not len(rows):
                break
            close = self._distances(a[rows], b[rows], self.pairs[order[start : start + PAIR_CHUNK]]).min(axis=1)
            free[rows[close < clearance_m]] = False
            rows = rows[close >= clearance_m]
        return free

    def colliding_pair(self, q: np.ndarray) -> tuple[str, str] | None:
        """The links of the closest overlapping pair at one configuration q (J,), or None."""
        d = self._pair_clearance(np.atleast_2d(q))[0]
        if not len(d) or d.min() >= 0:
            return None
        i, j = self.pairs[int(np.argmin(d))]
        return self.capsules[i].link, self.capsules[j].link

    def blocked(self, q: np.ndarray, origin: np.ndarray, points: np.ndarray, skip_bodies: np.ndarray) -> np.ndarray:
        """(N, K) bool: the straight line from `origin` (N, 3) to `points` (N, K, 3) (root frame [m]) passes
        through a capsule; capsules of the bodies in skip_bodies (K, B) (-1: none) are ignored."""
        a, b = self.segments(q)
        d = segment_distance(origin[:, None, None, :], points[:, :, None, :], a[:, None], b[:, None])  # (N, K, C)
        hit = d < self.radius
        skip = np.any(self.body[None, :, None] == skip_bodies[:, None, :], axis=2)  # (K, C)
        return np.any(hit & ~skip[None], axis=2)


def _bodies(robot: Robot) -> dict[str, int]:
    """Rigid body index of every link: links joined by fixed joints share one."""
    model = robot.model
    body: dict[str, int] = {}
    for link in sorted(model.links, key=lambda name: len(model.path_from_root(name))):
        joint = model.joint_to_child.get(link)
        if joint is not None and joint.type == "fixed":
            body[link] = body[joint.parent]
        else:
            body[link] = len(set(body.values()))
    return body


def _adjacent_bodies(robot: Robot, body: dict[str, int]) -> set[tuple[int, int]]:
    """Pairs of bodies joined by one moving joint (both orders)."""
    out = set()
    for joint in robot.model.joints.values():
        a, b = body[joint.parent], body[joint.child]
        out |= {(a, b), (b, a)}
    return out


def rest_configuration(robot: Robot) -> np.ndarray:
    """(J,) the rest pose of the robot config (`rest_pose:`, others 0) [rad]; unknown joints are refused."""
    rest = robot.config.planning.rest_pose
    unknown = sorted(set(rest) - set(robot.joint_names))
    if unknown:
        raise WolfcalError(
            f"{robot.config.path}: 'rest_pose' names {', '.join(unknown)}, not movable joints of {robot.config.urdf}"
        )
    return np.array([rest.get(j, 0.0) for j in robot.joint_names])


def _urdf_capsules(robot: Robot, body: dict[str, int]) -> list[Capsule]:
    """Capsules bounding the URDF's <collision> geometry (empty when it has none; `wolfcal.robot.collision_urdf`)."""
    segments = urdf_collision_segments(robot.config.urdf)
    unknown = sorted({link for link, *_ in segments} - robot.model.links)
    if unknown:
        raise WolfcalError(f"{robot.config.urdf}: <collision> of {', '.join(unknown)}, links the model does not have")
    return [Capsule(link, body[link], a, b, radius) for link, a, b, radius in segments]


def _config_capsules(robot: Robot, body: dict[str, int]) -> list[Capsule]:
    """Capsules from `collision_radii:` (see the module docstring)."""
    radii = robot.config.planning.collision_radii
    unknown = sorted(set(radii) - robot.model.links)
    if unknown:
        raise WolfcalError(
            f"{robot.config.path}: 'collision_radii' names {', '.join(unknown)}, not links of {robot.config.urdf}"
        )
    capsules = []
    for link, radius in radii.items():
        children = [j for j in robot.model.joints.values() if j.parent == link]
        ends = [j.T_parent_origin[:3, 3] for j in children] or [np.zeros(3)]
        capsules += [Capsule(link, body[link], np.zeros(3), np.asarray(end, float), radius) for end in ends]
    return capsules


def optional_collision_model(robot: Robot) -> CollisionModel | None:
    """The robot's capsules (URDF <collision> if any, else `collision_radii:`); None without either."""
    body = _bodies(robot)
    capsules, source = _urdf_capsules(robot, body), f"<collision> of {robot.config.urdf}"
    if not capsules:
        capsules, source = _config_capsules(robot, body), f"'collision_radii' of {robot.config.path}"
    return CollisionModel(robot, capsules, source, rest_configuration(robot)) if capsules else None


def collision_model(robot: Robot) -> CollisionModel:
    """The robot's capsules (`optional_collision_model`); a clear error when it has none."""
    model = optional_collision_model(robot)
    if model is None:
        raise WolfcalError(
            f"{robot.config.urdf} has no <collision> geometry and {robot.config.path} no 'collision_radii:', so "
            "poses cannot be checked for self-collision; add 'collision_radii: {link: metres}' (capsules between "
            "joint origins) for the links of the body, e.g. collision_radii: {r_lower_leg: 0.04}"
        )
    return model
