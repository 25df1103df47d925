"""Which pairs of a robot's rigid bodies a self-collision check never looks at, from the kinematics alone.

A body is a set of links joined by fixed joints. Never checked against each other (as URDF tools do, e.g. MoveIt's
setup assistant writing `disable_collisions reason="Adjacent"` into the SRDF):
- bodies joined by one moving joint; a body without collision geometry is passed through, so a body and its
  nearest ancestor with geometry count as joined;
- the two outer bodies of a two-axis joint: two moving joints in a row whose axes meet (within AXES_MEET_M, in the
  rest pose), as a hip's roll and pitch or an ankle's pitch and roll. The cross piece between them is built to let
  them turn about each other within the joint limits, and bounding shapes around such compact parts overlap
  where the parts do not.
Pairs that touch in the rest pose are the collision model's own rule (`wolfcal.robot.collision`).
"""

from __future__ import annotations

import numpy as np

from wolfcal.robot.kinematics import JointModel
from wolfcal.robot.robot import Robot

AXES_MEET_M = 0.01  # two joint axes closer than this form one two-axis joint [m]


def bodies(robot: Robot) -> dict[str, int]:
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


def _axes_meet(robot: Robot, a: JointModel, b: JointModel, rest: np.ndarray) -> bool:
    """Whether the axes of two moving joints pass within AXES_MEET_M of each other in the rest pose (lines)."""
    poses = robot.model.link_poses(rest[None], [a.parent, b.parent])
    lines = []
    for joint in (a, b):
        T = poses[joint.parent][0] @ joint.T_parent_origin
        lines.append((T[:3, 3], T[:3, :3] @ joint.axis))
    (p, u), (r, v) = lines
    normal = np.cross(u, v)
    if np.linalg.norm(normal) < 1e-9:  # parallel axes meet only if they coincide
        gap = np.linalg.norm(np.cross(r - p, u)) / np.linalg.norm(u)
    else:
        gap = abs(float(np.dot(r - p, normal))) / np.linalg.norm(normal)
    return bool(gap < AXES_MEET_M)


def adjacent_bodies(robot: Robot, body: dict[str, int], solid: set[int], rest: np.ndarray) -> set[tuple[int, int]]:
    """Pairs of bodies never checked against each other by their kinematics (both orders):
    - bodies joined by one moving joint, bodies without capsules (not in `solid`) passed through as MoveIt's setup
      assistant does (a body and its nearest ancestor with capsules are adjacent);
    - the two outer bodies of a two-axis joint: two moving joints in a row whose axes meet (within AXES_MEET_M, in
      the rest pose), as a hip's roll and pitch or an ankle's pitch and roll; the cross piece between them is built
      to let them turn about each other within the joint limits."""
    up: dict[int, tuple[int, JointModel]] = {}  # body -> (its parent body, the moving joint between them)
    for joint in robot.model.joints.values():
        if body[joint.parent] != body[joint.child]:
            up[body[joint.child]] = (body[joint.parent], joint)
    out = set()
    for child, (parent, joint) in up.items():
        ancestor = parent
        while ancestor not in solid and ancestor in up:
            ancestor = up[ancestor][0]
        out |= {(child, ancestor), (ancestor, child)}
        if parent in up and _axes_meet(robot, up[parent][1], joint, rest):
            grandparent = up[parent][0]
            out |= {(child, grandparent), (grandparent, child)}
    return out
