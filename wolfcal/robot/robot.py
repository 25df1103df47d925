"""A robot = its config + its kinematic model, cross-checked; tag and camera poses in the base frame."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wolfcal.config import RobotConfig, load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.geometry import invert_transform, transform_from_twist_params, transform_from_xyz_rpy
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.kinematics import KinematicModel
from wolfcal.robot.stances import check_stances

# The optical frame (z forward, x right, y down) in a camera link with ROS body axes (x forward, y left, z up):
# optical x = -body y, optical y = -body z, optical z = body x (URDF rpy -pi/2, 0, -pi/2).
T_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


@dataclass
class Robot:
    config: RobotConfig
    model: KinematicModel
    _mounts: dict[int, np.ndarray] = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def joint_names(self) -> list[str]:
        return self.model.actuated_joint_names

    @property
    def camera_joint(self) -> str:
        """The joint whose origin places the camera's optical frame: its frame correction is the camera extrinsic,
        in the optical frame. For `camera.axes: body` it is the fixed joint the robot adds below the camera link
        (`KinematicModel.urdf_joint_of` names the URDF joint the correction is written to)."""
        return self.model.parent_joint(self.config.head_camera().frame).name

    def actuated_joints_to(self, links: list[str]) -> tuple[str, ...]:
        """The actuated joints between the base and each of `links`, in chain order, each once; a mimic joint on
        the way stands for the joint it follows (whose offset moves it)."""
        joints: list[str] = []
        for link in links:
            for joint in self.model.joints_between(self.config.base_link, link):
                name = joint.mimic[0] if joint.mimic is not None else joint.name
                if self.model.joints[name].actuated and name not in joints:
                    joints.append(name)
        return tuple(joints)

    def fixed_to_base(self, link: str) -> bool:
        """Whether no actuated joint lies between the base link and `link` (e.g. the torso)."""
        return not self.actuated_joints_to([link])

    @property
    def leg_joints(self) -> tuple[str, ...]:
        """The actuated joints that move the legs: those between the base and the links of the tags and markers
        the config puts on a leg (`side`), and of the floor's soles."""
        links = [t.link for t in self.config.tags if t.side is not None]
        links += [m.link for m in (self.config.markers.entries if self.config.markers else ()) if m.side is not None]
        links += list(self.config.floor.soles) if self.config.floor is not None else []
        return self.actuated_joints_to(links)

    @property
    def feet(self) -> tuple[str, ...]:
        """The frames that stand for the feet in figures: the floor's soles (`floor.soles`), else the links of the
        tags on a leg (`side`), each once; () when the config names neither."""
        if self.config.floor is not None:
            return tuple(self.config.floor.soles)
        return tuple(dict.fromkeys(t.link for t in self.config.tags if t.side is not None))

    def off_the_legs(self, link: str) -> bool:
        """Whether no leg joint (`leg_joints`) moves `link` (e.g. the torso, also behind waist joints): a tag on it
        can place an external camera. A config that names no legs (no `side`, no soles): whether `link` is fixed to
        the base."""
        legs = self.leg_joints
        if not legs:
            return self.fixed_to_base(link)
        return not set(self.actuated_joints_to([link])) & set(legs)

    def camera_and_leg_joints(self, sides: tuple[str, ...] = ("right", "left")) -> tuple[str, ...]:
        """The actuated joints between base and camera (none without a head camera), then those between base and
        each tag of the given sides: the joints whose encoder offsets a camera-to-foot calibration can see."""
        camera = [self.config.camera.frame] if self.config.camera is not None else []
        return self.actuated_joints_to(camera + [t.link for t in self.config.tags if t.side in sides])

    def T_link_tag(self, tag_id: int, corrections: Corrections | None = None) -> np.ndarray:
        """(4, 4) mount of a tag in its link, with its correction applied."""
        if tag_id not in self._mounts:  # the nominal mount, once per tag (a fit asks for it at every step)
            tag = self.config.tag(tag_id)
            self._mounts[tag_id] = transform_from_xyz_rpy(tag.xyz, tag.rpy)
        T = self._mounts[tag_id].copy()
        if corrections is not None and tag_id in corrections.tags:
            T = T @ transform_from_twist_params(corrections.tags[tag_id])
        return T

    def camera_and_tag_poses(
        self, q: np.ndarray, tag_ids: list[int], corrections: Corrections | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """T_base_camera (N, 4, 4) and T_camera_tag (N, len(tag_ids), 4, 4) from measured q (N, J)."""
        frame = self.config.head_camera().frame
        links = [frame] + [self.config.tag(t).link for t in tag_ids]
        poses = self.model.link_poses(q, links, corrections, base=self.config.base_link)
        T_base_camera = poses[frame]
        T_camera_base = invert_transform(T_base_camera)
        T_camera_tag = (
            np.stack(
                [T_camera_base @ poses[self.config.tag(t).link] @ self.T_link_tag(t, corrections) for t in tag_ids],
                axis=1,
            )
            if tag_ids
            else np.zeros((len(T_base_camera), 0, 4, 4))
        )
        return T_base_camera, T_camera_tag


def load_robot(config_path: str | Path) -> Robot:
    """Load a robot config and its URDF; every link and joint the config names must exist in the URDF."""
    config = load_robot_config(config_path)
    model = KinematicModel.from_urdf(config.urdf)  # read strictly (`read_urdf_xml`): what loads also writes back
    where = str(config.path)
    if config.base_link not in model.links:
        raise WolfcalError(f"{where}: 'base_link' {config.base_link!r} is not a link of {config.urdf}")
    if config.camera is not None:
        if config.camera.urdf_frame not in model.links:
            raise WolfcalError(
                f"{where}: 'camera.frame' {config.camera.urdf_frame!r} is not a link/frame of {config.urdf}"
            )
        if config.camera.urdf_frame == model.root:
            raise WolfcalError(f"{where}: 'camera.frame' must not be the URDF's root link")
    model = _with_config_frames(config, model)
    for i, tag in enumerate(config.tags):
        if tag.link not in model.links:
            raise WolfcalError(f"{where}: 'tags[{i}].link' {tag.link!r} (tag {tag.id}) is not a link of {config.urdf}")
    for i, marker in enumerate(config.markers.entries if config.markers is not None else ()):
        if marker.link not in model.links:
            raise WolfcalError(
                f"{where}: 'markers.list[{i}].link' {marker.link!r} (marker {marker.name}) is not a link of "
                f"{config.urdf}"
            )
    for system, ranges in config.sampling_ranges.items():
        _check_movable(config, model, f"sampling_ranges.{system}", ranges)
    if config.servos is not None:
        _check_movable(config, model, "servos.ids", config.servos.ids)
    _check_floor(config, model)
    return Robot(config=config, model=model)


def _with_config_frames(config: RobotConfig, model: KinematicModel) -> KinematicModel:
    """The model with the frames the config adds: a body-axes camera's optical frame (rotated by T_BODY_OPTICAL
    from the camera link) and the soles given as {link, xyz}; a WolfcalError naming the key when a link is missing."""
    frames = []
    if config.camera is not None and config.camera.axes == "body":
        frames.append((config.camera.frame, config.camera.urdf_frame, T_BODY_OPTICAL))
    for sole in config.floor.added_soles if config.floor is not None else ():
        if sole.link not in model.links:
            raise WolfcalError(f"{config.path}: 'floor.soles' link {sole.link!r} is not a link of {config.urdf}")
        frames.append((sole.frame, sole.link, transform_from_xyz_rpy(sole.xyz, (0.0, 0.0, 0.0))))
    return model.with_frames(frames) if frames else model


def _check_movable(config: RobotConfig, model: KinematicModel, key: str, joints: Iterable[str]) -> None:
    """A WolfcalError naming the config's `key` when `joints` names joints that are not movable joints of the URDF."""
    unknown = [j for j in joints if j not in model.actuated_joint_names]
    followed = {j: model.joints[j].mimic for j in unknown if j in model.joints}
    mimics = [f"{j} follows {mimic[0]}" for j, mimic in followed.items() if mimic is not None]
    if mimics:
        raise WolfcalError(
            f"{config.path}: '{key}' names mimic joint(s) ({'; '.join(mimics)}, <mimic> in "
            f"{config.urdf}): name the joint each follows instead"
        )
    if unknown:
        raise WolfcalError(
            f"{config.path}: '{key}' names joint(s) {', '.join(unknown)} that are not movable joints of {config.urdf}"
        )


def _check_aim(config: RobotConfig, model: KinematicModel) -> None:
    """`floor.aim` must name movable joints between the base and the camera."""
    if config.floor is None or not config.floor.aim:
        return
    chain = [j.name for j in model.joints_between(config.base_link, config.head_camera("floor.aim needs it").frame)]
    wrong = [j for j in config.floor.aim if j not in chain or not model.joints[j].actuated]
    if wrong:
        raise WolfcalError(
            f"{config.path}: 'floor.aim' names {', '.join(wrong)}, not movable joint(s) between "
            f"{config.base_link} and the camera; name the pan and tilt joints of the camera"
        )


def _check_floor(config: RobotConfig, model: KinematicModel) -> None:
    """The floor's soles must be links, its standing readings and stances movable joints of the URDF that keep the
    soles on one plane (`robot.stances.check_stances`)."""
    if config.floor is None:
        return
    for i, sole in enumerate(config.floor.soles):
        if sole not in model.links:
            raise WolfcalError(f"{config.path}: 'floor.soles[{i}]' {sole!r} is not a link of {config.urdf}")
    for key, stance in config.floor.named_stances():
        _check_movable(config, model, key, stance)
    _check_aim(config, model)
    check_stances(config, model)
