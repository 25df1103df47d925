"""How far a deployed URDF, read by an independent reader (yourdfpy), puts the camera, the tag links and the soles
from where wolfcal's fitted model puts them.

The frames a robot config adds to the URDF (a body-axes camera's optical frame, soles given as {link, xyz}) are
placed here from the config's own words, not from wolfcal's model: the camera's optical frame is the link rotated by
the REP 103 body-to-optical rotation, a sole is the link moved by its xyz.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yourdfpy

from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

# optical x = -body y, optical y = -body z, optical z = body x
BODY_TO_OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def probes(reach: float) -> np.ndarray:
    """(4, 4) homogeneous points: a frame's origin and `reach` [m] along each axis; their distances measure position
    and rotation in metres."""
    return np.array([[0.0, 0.0, 0.0, 1.0], [reach, 0.0, 0.0, 1.0], [0.0, reach, 0.0, 1.0], [0.0, 0.0, reach, 1.0]]).T


def checked_frames(robot: Robot) -> dict[str, tuple[str, np.ndarray]]:
    """Per frame of the fitted model that the check compares: (URDF link, T_link_frame) from the config's words."""
    config = robot.config
    frames: dict[str, tuple[str, np.ndarray]] = {}
    if config.camera is not None:
        T = BODY_TO_OPTICAL if config.camera.axes == "body" else np.eye(4)
        frames[config.camera.frame] = (config.camera.urdf_frame, T)
    for tag in config.tags:
        frames[tag.link] = (tag.link, np.eye(4))
    added = {s.frame: s for s in config.floor.added_soles} if config.floor is not None else {}
    for sole in config.floor.soles if config.floor is not None else ():
        T = np.eye(4)
        if sole in added:
            T[:3, 3] = added[sole].xyz
            frames[sole] = (added[sole].link, T)
        else:
            frames[sole] = (sole, T)
    return frames


def deployed_error(
    robot: Robot, corrections: Corrections, urdf: Path, folded: bool, q: np.ndarray, reach: float = 1.0
) -> float:
    """Largest distance [m] between the deployed URDF's and the fitted model's frames (`checked_frames`: origins and
    points `reach` m along each axis) over the readings q (N, J) [rad]. `folded`: offsets are in the origins;
    otherwise they are read from each joint's <calibration rising>, q_model = q + rising, and mimic joints follow
    their master's value."""
    urdf_model = yourdfpy.URDF.load(str(urdf), load_meshes=False, build_collision_scene_graph=False)
    rising = {} if folded else {
        name: float(j.calibration.rising) for name, j in urdf_model.joint_map.items()
        if j.calibration is not None and j.calibration.rising is not None
    }  # fmt: skip
    base = robot.config.base_link
    frames = checked_frames(robot)
    worst = 0.0
    for qi in np.atleast_2d(q):
        cfg = {name: float(v) + rising.get(name, 0.0) for name, v in zip(robot.joint_names, qi)}
        urdf_model.update_cfg({n: v for n, v in cfg.items() if n in urdf_model.actuated_joint_names})
        ours = robot.model.link_poses(qi[None], list(frames), corrections, base=base)
        for frame, (link, T_link_frame) in frames.items():
            theirs = urdf_model.get_transform(link, base) @ T_link_frame
            d = np.linalg.norm((theirs @ probes(reach) - ours[frame][0] @ probes(reach))[:3], axis=0)
            worst = max(worst, float(d.max()))
    return worst
