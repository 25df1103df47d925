"""Where a robot's collision capsules come from, and the model built from them.

In this order of preference:
- `collision_radii: {link: m}` of the robot config, when given (it replaces the URDF's <collision>): per listed
  link, capsules from the link's origin to the origin of each of its child joints (a sphere at the origin for a
  link without children);
- otherwise the URDF's `<collision>` geometry, bounded by capsules (`wolfcal.robot.collision_urdf`); collision
  meshes that are not found are skipped with one warning naming them.
The pairs checked are those of `wolfcal.robot.collision.CollisionModel`.
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.robot.collision import Capsule, CollisionModel
from wolfcal.robot.collision_pairs import bodies
from wolfcal.robot.collision_urdf import urdf_collision
from wolfcal.robot.robot import Robot


def rest_configuration(robot: Robot) -> np.ndarray:
    """(J,) the rest pose of the robot config (`rest_pose:`, others 0) [rad]; unknown joints are refused."""
    rest = robot.config.planning.rest_pose
    unknown = sorted(set(rest) - set(robot.joint_names))
    if unknown:
        raise WolfcalError(
            f"{robot.config.path}: 'rest_pose' names {', '.join(unknown)}, not movable joints of {robot.config.urdf}"
        )
    return np.array([rest.get(j, 0.0) for j in robot.joint_names])


def _urdf_capsules(robot: Robot, body: dict[str, int]) -> tuple[list[Capsule], list[str]]:
    """Capsules bounding the URDF's <collision> geometry (empty when it has none; `wolfcal.robot.collision_urdf`)
    and a note naming the collision meshes not found (skipped)."""
    urdf = urdf_collision(robot.config.urdf)
    unknown = sorted({link for link, *_ in urdf.segments} - robot.model.links)
    if unknown:
        raise WolfcalError(f"{robot.config.urdf}: <collision> of {', '.join(unknown)}, links the model does not have")
    notes = []
    if urdf.missing_meshes:
        shaped = {link for link, *_ in urdf.segments}
        bare = sorted({link for names in urdf.missing_meshes.values() for link in names} - shaped)
        unchecked = f"; left without collision geometry (never checked): {', '.join(bare)}" if bare else ""
        notes.append(f"{robot.config.urdf}: {len(urdf.missing_meshes)} collision meshes not found, skipped ("
                     + ", ".join(urdf.missing_meshes) + f"){unchecked}. Put the meshes where the URDF names them, "
                     "or give 'collision_radii:' in the robot config")  # fmt: skip
    return [Capsule(link, body[link], a, b, radius) for link, a, b, radius in urdf.segments], notes


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
    """The robot's capsules (`collision_radii:` when given, else the URDF's <collision>); None without either."""
    body = bodies(robot)
    capsules, warnings = _config_capsules(robot, body), list[str]()
    source = f"'collision_radii' of {robot.config.path}"
    if not capsules:
        (capsules, warnings), source = _urdf_capsules(robot, body), f"<collision> of {robot.config.urdf}"
    if not capsules:
        if warnings:  # every collision shape was a mesh not found
            raise WolfcalError(f"{warnings[0]}; without them the robot has no collision geometry to check poses with")
        return None
    unknown = sorted({link for pair in robot.config.planning.collision_ignore for link in pair} - robot.model.links)
    if unknown:
        raise WolfcalError(f"{robot.config.path}: 'collision_ignore' names {', '.join(unknown)}, not links of "
                           f"{robot.config.urdf}")  # fmt: skip
    return CollisionModel(robot, capsules, source, rest_configuration(robot), warnings)


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
