"""Robot config YAML (`configs/<robot>/robot.yaml`) -> typed objects.

Every error names the file, the key and what to do; unknown keys are errors, not silently ignored.
Lengths in metres, angles in radians.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from wolfcal.encoders import QUANTISATION_NOISE
from wolfcal.errors import WolfcalError
from wolfcal.field.model import FieldDimensions, field_dimensions
from wolfcal.fit.systems import config_sections, sampling_systems  # the registry: plain data
from wolfcal.observations import HEAD_CAMERA
from wolfcal.vision.target_size import check_printed_edge
from wolfcal.yamlfile import read_yaml

TAG_FAMILIES = ("tag36h11", "tag25h9", "tag16h5", "tag36h10")
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
# a marker as motion-capture software labels it ('r_foot_fl', 'Marker 001'), optionally with its 'Subject:' prefix
_MARKER_NAME = re.compile(r"([A-Za-z0-9_][A-Za-z0-9_ -]*:)?[A-Za-z]([A-Za-z0-9_ ]*[A-Za-z0-9_])?")


@dataclass(frozen=True)
class TagConfig:
    """One fiducial: `T_link_tag` places the tag frame (aruco convention, centre of the tag) in `link`."""

    id: int
    family: str
    size: float  # edge of the black square [m]
    link: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    side: str | None = None  # 'right' / 'left' (config `side`): the leg it is on, for the leg preset; None: no leg


@dataclass(frozen=True)
class CameraConfig:
    """The head camera. `frame` is its optical frame in the robot's model (z forward, x right, y down): the config's
    `camera.frame` itself when `axes` is 'optical'; when 'body' (ROS REP 103: x forward, y left, z up), a frame
    `<camera.frame>_optical` that the robot adds below the URDF link (`wolfcal.robot.robot.load_robot`)."""

    frame: str
    topic: str
    info_topic: str
    intrinsics: Path | None = None  # camera_info YAML used when a capture carries none (and by the simulator)
    name: str = "camera"  # in the names of its pose correction's parameters (`camera.x ... camera.rz`)
    axes: str = "optical"  # config `camera.axes`: how the URDF link `urdf_frame` is oriented, 'optical' | 'body'
    urdf_frame: str = ""  # config `camera.frame`: the URDF link the camera is

    def __post_init__(self) -> None:
        if not self.urdf_frame:
            object.__setattr__(self, "urdf_frame", self.frame)


@dataclass(frozen=True)
class ExternalCameraConfig:
    """A camera not on the robot (e.g. on a tripod); its name appears in parameter names (`<name>.x`) and the CLI."""

    name: str
    image_topic: str  # sensor_msgs/msg/CompressedImage
    info_topic: str  # sensor_msgs/msg/CameraInfo
    intrinsics: Path | None = None  # camera_info YAML used when a capture carries none (and by the simulator)


@dataclass(frozen=True)
class ServoConfig:
    port: str  # the first (or only) bus device
    baudrate: int
    protocol: float
    ids: dict[str, int]
    models: dict[str, int] = field(default_factory=dict)  # expected model number per joint (optional)
    # bus device -> servo ids on it (config `servos.ports`, or `servos.port` with every id); empty: `port` has all
    ports: dict[str, tuple[int, ...]] = field(default_factory=dict)

    @property
    def buses(self) -> dict[str, tuple[int, ...]]:
        """Bus device -> the servo ids on it, every configured id on exactly one."""
        return self.ports or {self.port: tuple(self.ids.values())}


@dataclass(frozen=True)
class PriorConfig:
    """Standard deviations of the Gaussian priors on free parameters (deviations from the nominal model)."""

    offset: float = 0.05  # joint encoder offset [rad]
    camera_translation: float = 0.01  # [m]
    camera_rotation: float = 0.1  # [rad]
    tag_translation: float = 0.005  # [m]
    tag_rotation: float = 0.05  # [rad]
    encoder_noise: float = float(QUANTISATION_NOISE)  # joint reading noise [rad]: tick / sqrt(12) = 0.44 mrad
    pixel_noise: float = 0.2  # corner detection noise per axis [px], the starting value before it is estimated


@dataclass(frozen=True)
class RobotConfig:
    path: Path
    name: str
    urdf: Path
    base_link: str
    camera: CameraConfig | None  # the head camera; None for a robot config used with external cameras only
    joint_states_topic: str
    tags: tuple[TagConfig, ...]
    servos: ServoConfig | None = None
    priors: PriorConfig = PriorConfig()
    external_cameras: tuple[ExternalCameraConfig, ...] = ()
    markers: MarkersConfig | None = None  # motion-capture markers on the robot (`markers:`), None when absent
    floor: FloorConfig | None = None  # the venue ground check (`floor:`), None when not configured
    playing_field: FieldConfig | None = None  # the RoboCup field whose lines the head camera sees (`field:`)
    # system ('head' | 'external') -> joint -> (lo, hi) true angles [rad] for simulated poses (`wolfcal.robot.ranges`)
    sampling_ranges: dict[str, dict[str, tuple[float, float]]] = field(default_factory=dict)
    planning: PlanningConfig = field(default_factory=lambda: PlanningConfig())
    # registered measurement systems' own sections (`System.config`: key -> its parsed, typed section)
    sections: dict[str, Any] = field(default_factory=dict)

    def section(self, key: str, why: str) -> Any:
        """A measurement system's section (e.g. `imu:`); a WolfcalError naming the file when the config has none."""
        if key not in self.sections:
            raise WolfcalError(f"the robot config {self.path} has no '{key}:'; {why}")
        return self.sections[key]

    def head_camera(self, why: str = "the head-camera system needs one") -> CameraConfig:
        """The head camera's config; a WolfcalError naming the file when the config has none."""
        if self.camera is None:
            raise WolfcalError(f"the robot config {self.path} has no 'camera:'; {why}")
        return self.camera

    def marker_config(self, why: str = "motion capture needs them") -> MarkersConfig:
        """The motion-capture markers' config; a WolfcalError naming the file when the config has none."""
        if self.markers is None:
            raise WolfcalError(f"the robot config {self.path} has no 'markers:'; {why}")
        return self.markers

    def floor_config(self, why: str = "floor samples need it") -> FloorConfig:
        """The venue ground check's config; a WolfcalError naming the file when the config has none."""
        if self.floor is None:
            raise WolfcalError(f"the robot config {self.path} has no 'floor:'; {why}")
        return self.floor

    def field_config(self, why: str = "field views need it") -> FieldConfig:
        """The field's config; a WolfcalError naming the file when the config has none."""
        if self.playing_field is None:
            raise WolfcalError(f"the robot config {self.path} has no 'field:'; {why}")
        return self.playing_field

    def external_camera(self, name: str) -> ExternalCameraConfig:
        """The external camera called `name`; a WolfcalError listing the configured ones otherwise."""
        for camera in self.external_cameras:
            if camera.name == name:
                return camera
        known = ", ".join(c.name for c in self.external_cameras) or "none"
        raise WolfcalError(
            f"{self.path}: no external camera named {name!r} (configured: {known}); add it under "
            "'external_cameras:' with its name, image_topic and info_topic"
        )

    def camera_topics(self, name: str) -> tuple[str, str]:
        """(image topic, camera-info topic) of the camera called `name` ('head' or an external camera)."""
        if name == HEAD_CAMERA:
            camera = self.head_camera()
            return camera.topic, camera.info_topic
        external = self.external_camera(name)
        return external.image_topic, external.info_topic

    def camera_intrinsics(self, name: str) -> tuple[Path | None, str]:
        """The configured camera_info YAML of a camera (or None) and the config key that sets it."""
        if name == HEAD_CAMERA:
            return self.head_camera().intrinsics, "camera.intrinsics"
        index = [c.name for c in self.external_cameras].index(self.external_camera(name).name)
        return self.external_cameras[index].intrinsics, f"external_cameras[{index}].intrinsics"

    def intrinsics_file(self, name: str, purpose: str, alternative: str = "") -> Path:
        """The configured camera_info YAML of camera `name`; a WolfcalError naming the key to set when there is none
        (`purpose`: what needs it, e.g. 'simulating'; `alternative`: another way to give it, e.g. a command option)."""
        path, key = self.camera_intrinsics(name)
        if path is None:
            raise WolfcalError(
                f"{self.path}: {purpose} needs the intrinsics of camera '{name}': set '{key}' to its camera_info YAML "
                f"(`wolfcal intrinsics` makes one){f' or {alternative}' if alternative else ''}"
            )
        return path

    @property
    def camera_names(self) -> list[str]:
        """'head' (when the config has a head camera) and the names of the external cameras, in config order."""
        return ([HEAD_CAMERA] if self.camera is not None else []) + [c.name for c in self.external_cameras]

    def tag(self, tag_id: int) -> TagConfig:
        return _by_id(self.tags, tag_id)

    @property
    def tag_ids(self) -> list[int]:
        return [t.id for t in self.tags]


_Tag = TypeVar("_Tag", "TagConfig", "FloorTagConfig")


def _by_id(tags: tuple[_Tag, ...], tag_id: int) -> _Tag:
    """The tag with id `tag_id`; KeyError when none has it."""
    for tag in tags:
        if tag.id == tag_id:
            return tag
    raise KeyError(tag_id)


class _Reader:
    """Checks one mapping of the config and builds error messages that name file and key."""

    def __init__(self, path: Path, data, where: str):
        self.path, self.where = path, where
        if not isinstance(data, dict):
            self.fail(f"must be a mapping, found {type(data).__name__}")
        self.data = data

    def fail(self, message: str):
        key = f" '{self.where}'" if self.where else ""
        raise WolfcalError(f"{self.path}:{key} {message}")

    def check_keys(self, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> None:
        unknown = sorted(set(self.data) - set(required) - set(optional))
        if unknown:
            allowed = ", ".join(required + optional)
            self.fail(f"unknown key(s) {', '.join(map(str, unknown))}; allowed keys: {allowed}")
        missing = [k for k in required if k not in self.data]
        if missing:
            self.fail(f"missing key(s) {', '.join(missing)}")

    def sub(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def string(self, key: str, default: str | None = None) -> str:
        value = self.data.get(key, default)
        if not isinstance(value, str) or not value:
            raise WolfcalError(f"{self.path}: '{self.sub(key)}' must be a non-empty string")
        return value

    def number(self, key: str, default: float | None = None, positive: bool = False) -> float:
        value = self.data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise WolfcalError(f"{self.path}: '{self.sub(key)}' must be a number, found {value!r}")
        if positive and value <= 0:
            raise WolfcalError(f"{self.path}: '{self.sub(key)}' must be positive, found {value!r}")
        return float(value)

    def vector3(self, key: str) -> tuple[float, float, float]:
        value = self.data.get(key, [0.0, 0.0, 0.0])
        ok = isinstance(value, (list, tuple)) and len(value) == 3
        ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        if not ok:
            raise WolfcalError(f"{self.path}: '{self.sub(key)}' must be a list of 3 numbers, found {value!r}")
        return (float(value[0]), float(value[1]), float(value[2]))


def _resolve(base: Path, value: str) -> Path:
    p = Path(value).expanduser()
    return p if p.is_absolute() else (base / p)


def _tag(path: Path, index: int, data) -> TagConfig:
    r = _Reader(path, data, f"tags[{index}]")
    r.check_keys(("id", "size", "link"), ("family", "xyz", "rpy", "side"))
    tag_id = r.data["id"]
    if isinstance(tag_id, bool) or not isinstance(tag_id, int) or tag_id < 0:
        r.fail(f"'id' must be a non-negative integer, found {tag_id!r}")
    family = r.string("family", "tag36h11")
    if family not in TAG_FAMILIES:
        r.fail(f"'family' {family!r} is not supported; use one of {', '.join(TAG_FAMILIES)}")
    side = r.data.get("side")
    if side is not None and side not in ("right", "left"):
        r.fail(f"'side' must be 'right' or 'left', found {side!r}")
    return TagConfig(
        id=tag_id,
        family=family,
        size=check_printed_edge(r.number("size", positive=True), f"{path}: '{r.sub('size')}'"),
        link=r.string("link"),
        xyz=r.vector3("xyz"),
        rpy=r.vector3("rpy"),
        side=side,
    )


def _servos(path: Path, data) -> ServoConfig:
    r = _Reader(path, data, "servos")
    r.check_keys(("ids",), ("port", "ports", "baudrate", "protocol", "models"))
    ids = r.data["ids"]
    if not isinstance(ids, dict) or not ids:
        r.fail("'ids' must map joint names to servo ids")
    for joint, sid in ids.items():
        if isinstance(sid, bool) or not isinstance(sid, int) or not 0 <= sid <= 252:
            raise WolfcalError(f"{path}: 'servos.ids.{joint}' must be a servo id 0-252, found {sid!r}")
    if len(set(ids.values())) != len(ids):
        r.fail("'ids' has the same servo id for two joints")
    models = r.data.get("models", {}) or {}
    if not isinstance(models, dict):
        r.fail("'models' must map joint names to model numbers")
    protocol = r.number("protocol", 2.0)
    if protocol != 2.0:
        r.fail(f"'protocol' must be 2 (Dynamixel Protocol 2.0), found {protocol!r}")
    ports = _ports(r, set(ids.values()))
    return ServoConfig(
        port=next(iter(ports)) if ports else r.string("port", "/dev/ttyUSB0"),
        baudrate=int(r.number("baudrate", 1_000_000, positive=True)),
        protocol=protocol,
        ids={str(k): int(v) for k, v in ids.items()},
        models={str(k): int(v) for k, v in models.items()},
        ports=ports,
    )


def _ports(r: _Reader, ids: set[int]) -> dict[str, tuple[int, ...]]:
    """`servos.ports: {device: [ids]}` (several buses): every id of `servos.ids` on exactly one device; {} without."""
    if "ports" not in r.data:
        return {}
    if "port" in r.data:
        r.fail("has both 'port' and 'ports'; give 'port' for one bus or 'ports' for several")
    data = r.data["ports"]
    if not isinstance(data, dict) or not data:
        r.fail("'ports' must map bus devices to the servo ids on them, e.g. {/dev/ttyUSB0: [1, 2], /dev/ttyUSB1: [3]}")
    ports: dict[str, tuple[int, ...]] = {}
    seen: set[int] = set()
    for device, listed in data.items():
        ok = isinstance(device, str) and device and isinstance(listed, list) and listed
        if not ok or not all(isinstance(i, int) and not isinstance(i, bool) for i in listed):
            r.fail(f"'ports.{device}' must be a non-empty list of servo ids")
        twice = sorted(seen & set(listed))
        unknown = sorted(set(listed) - ids)
        if twice or unknown or len(set(listed)) != len(listed):
            what = f"id(s) {twice or listed} listed twice" if twice or not unknown else f"id(s) {unknown} not in 'ids'"
            r.fail(f"'ports.{device}': {what}; each servo of 'ids' belongs on exactly one port")
        seen |= set(listed)
        ports[device] = tuple(listed)
    if seen != ids:
        r.fail(f"'ports' leaves servo id(s) {sorted(ids - seen)} of 'ids' on no port; list each on its bus")
    return ports


def _priors(path: Path, data) -> PriorConfig:
    r = _Reader(path, data, "priors")
    names = tuple(PriorConfig.__dataclass_fields__)
    r.check_keys((), names)
    return PriorConfig(**{k: r.number(k, positive=True) for k in names if k in r.data})


def _intrinsics_path(r: _Reader, base: Path) -> Path | None:
    """The optional `intrinsics` camera_info YAML of a camera mapping, resolved and checked to exist."""
    if "intrinsics" not in r.data:
        return None
    intrinsics = _resolve(base, r.string("intrinsics"))
    if not intrinsics.is_file():
        raise WolfcalError(f"{r.path}: '{r.sub('intrinsics')}' file {intrinsics} not found")
    return intrinsics


CAMERA_AXES = ("optical", "body")


def _camera(path: Path, data) -> CameraConfig:
    cam = _Reader(path, data, "camera")
    cam.check_keys(("frame",), ("name", "topic", "info_topic", "intrinsics", "axes"))
    name = _parameter_name(cam, "camera")
    axes = cam.string("axes", "optical")
    if axes not in CAMERA_AXES:
        cam.fail(
            f"'axes' must be 'optical' (z forward, x right, y down) or 'body' (x forward, y left, z up), found {axes!r}"
        )
    link = cam.string("frame")
    return CameraConfig(
        axes=axes,
        urdf_frame=link,
        name=name,
        frame=link if axes == "optical" else f"{link}_optical",
        topic=cam.string("topic", "/camera/image_raw/compressed"),
        info_topic=cam.string("info_topic", "/camera/camera_info"),
        intrinsics=_intrinsics_path(cam, path.parent),
    )


def _parameter_name(r: _Reader, default: str | None = None) -> str:
    """A camera's `name`, used in parameter names (`<name>.x`): a letter, then letters, digits and '_', and not
    `tag<id>` (the tag mounts' names)."""
    name = r.string("name", default)
    if not _NAME.fullmatch(name) or re.fullmatch(r"tag\d+", name):
        r.fail(
            f"'name' {name!r} must start with a letter, hold only letters, digits and '_' and not be tag<id> "
            f"(it is used in parameter names such as {name}.x)"
        )
    return name


def _sampling_ranges(path: Path, data) -> dict[str, dict[str, tuple[float, float]]]:
    """`sampling_ranges: {head|external|mocap: {<joint>: [lo, hi]}}` [rad, true angles]; joints: load_robot."""
    r = _Reader(path, data, "sampling_ranges")
    r.check_keys((), sampling_systems())
    out = {}
    for system, joints in r.data.items():
        if not isinstance(joints, dict) or not joints:
            r.fail(f"'{system}' must map joint names to [lower, upper] in rad")
        ranges = {}
        for joint, value in joints.items():
            ok = isinstance(value, (list, tuple)) and len(value) == 2
            ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in value)
            if not ok or value[0] > value[1]:
                raise WolfcalError(
                    f"{path}: 'sampling_ranges.{system}.{joint}' must be [lower, upper] in rad with lower <= upper, "
                    f"found {value!r}"
                )
            ranges[str(joint)] = (float(value[0]), float(value[1]))
        out[system] = ranges
    return out


def _external_cameras(path: Path, data) -> tuple[ExternalCameraConfig, ...]:
    if not isinstance(data, list):
        raise WolfcalError(f"{path}: 'external_cameras' must be a list of cameras ({{name, image_topic, info_topic}})")
    cameras: list[ExternalCameraConfig] = []
    for i, item in enumerate(data):
        r = _Reader(path, item, f"external_cameras[{i}]")
        r.check_keys(("name", "image_topic", "info_topic"), ("intrinsics",))
        name = _parameter_name(r)
        if name == HEAD_CAMERA:
            r.fail(f"'name' must not be {HEAD_CAMERA!r}: that name means the robot's own camera ('camera:')")
        if name in {c.name for c in cameras}:
            r.fail(f"'name' {name!r} is used by another external camera; names must be unique")
        cameras.append(
            ExternalCameraConfig(
                name=name,
                image_topic=r.string("image_topic"),
                info_topic=r.string("info_topic"),
                intrinsics=_intrinsics_path(r, path.parent),
            )
        )
    return tuple(cameras)


REPOSITORY_ROBOT = Path("configs/wolfgang")  # the default robot when run from the repository root


def packaged_robot() -> Path:
    """The default robot (Wolfgang) shipped in the package as wolfcal/data/robots/wolfgang (a copy of the
    repository's configs/wolfgang made when the package is built), or configs/wolfgang itself in a source tree."""
    here = Path(__file__).resolve().parent
    for folder in (here / "data" / "robots" / "wolfgang", here.parent / "configs" / "wolfgang"):
        if (folder / "robot.yaml").is_file():
            return folder
    raise WolfcalError("this wolfcal install lacks its default robot (wolfcal/data/robots/wolfgang); pass --robot")


def default_robot(robot: str | Path | None = None) -> Path:
    """`robot` if given; else configs/wolfgang in the current folder if there is one, else the packaged robot."""
    if robot is not None:
        return Path(robot)
    return REPOSITORY_ROBOT if (REPOSITORY_ROBOT / "robot.yaml").is_file() else packaged_robot()


def load_robot_config(path: str | Path) -> RobotConfig:
    """Read and check a robot config; the URDF's existence is checked, its content by `wolfcal.robot`."""
    path = Path(path)
    if path.is_dir():
        path = path / "robot.yaml"
    data = read_yaml(path, "robot config", "give --robot a robot.yaml or a folder holding one")
    r = _Reader(path, data, "")
    r.check_keys(
        ("name", "urdf", "base_link"),
        (
            "tags",
            "camera",
            "external_cameras",
            "joint_states_topic",
            "servos",
            "priors",
            "markers",
            "floor",
            "field",
            "sampling_ranges",
            *PLANNING_KEYS,
            *config_sections(),
        ),
    )
    urdf = _resolve(path.parent, r.string("urdf"))
    if not urdf.is_file():
        raise WolfcalError(f"{path}: 'urdf' file {urdf} not found")
    camera = _camera(path, r.data["camera"]) if r.data.get("camera") is not None else None
    external = _external_cameras(path, r.data["external_cameras"]) if r.data.get("external_cameras") else ()
    markers = _markers(path, r.data["markers"]) if r.data.get("markers") is not None else None
    sections = {key: parse(path, r.data[key]) for key, parse in config_sections().items()
                if r.data.get(key) is not None}  # fmt: skip
    if camera is None and not external and markers is None and not sections:
        r.fail(
            "needs a head camera ('camera:'), a camera under 'external_cameras:', motion-capture 'markers:' or "
            f"a measurement system's section ({', '.join(config_sections()) or 'none registered'})"
        )
    _check_topics_distinct(path, camera, external)
    if camera is not None and camera.name in {c.name for c in external}:
        r.fail(f"'camera.name' {camera.name!r} is also an external camera's name; each camera needs its own name")
    tags_data = r.data.get("tags", [] if camera is None and not external else None)
    if not isinstance(tags_data, list) or (not tags_data and (camera is not None or external)):
        r.fail("'tags' must be a non-empty list of tags (a config with cameras needs the tags they see)")
    tags = tuple(_tag(path, i, t) for i, t in enumerate(tags_data))
    if len({t.id for t in tags}) != len(tags):
        r.fail("'tags' lists the same tag id twice")
    return RobotConfig(
        path=path,
        name=r.string("name"),
        urdf=urdf,
        base_link=r.string("base_link"),
        camera=camera,
        joint_states_topic=r.string("joint_states_topic", "/joint_states"),
        tags=tags,
        servos=_servos(path, r.data["servos"]) if r.data.get("servos") is not None else None,
        priors=_priors(path, r.data["priors"]) if r.data.get("priors") is not None else PriorConfig(),
        external_cameras=external,
        markers=markers,
        floor=_floor(path, r.data["floor"], tags) if r.data.get("floor") is not None else None,
        playing_field=_field(path, r.data["field"]) if r.data.get("field") is not None else None,
        sampling_ranges=_sampling_ranges(path, r.data["sampling_ranges"]) if "sampling_ranges" in r.data else {},
        planning=_planning(path, r.data),
        sections=sections,
    )


def _check_topics_distinct(path: Path, camera: CameraConfig | None, external: tuple[ExternalCameraConfig, ...]) -> None:
    """Two cameras on one topic could not be told apart in a capture."""
    owners: dict[str, str] = {}
    topics = [] if camera is None else [(camera.topic, "camera.topic"), (camera.info_topic, "camera.info_topic")]
    for i, c in enumerate(external):
        topics += [(c.image_topic, f"external_cameras[{i}].image_topic"),
                   (c.info_topic, f"external_cameras[{i}].info_topic")]  # fmt: skip
    for topic, key in topics:
        if topic in owners:
            raise WolfcalError(f"{path}: '{key}' {topic} is also '{owners[topic]}'; each camera needs its own topics")
        owners[topic] = key


@dataclass(frozen=True)
class MarkerConfig:
    """One motion-capture marker: `xyz` [m] places it in `link` (nominal: the fit estimates its mount)."""

    name: str  # as the motion-capture system labels it
    link: str
    xyz: tuple[float, float, float]
    side: str | None = None  # 'right' / 'left': the leg it is on (`side:`, for the leg preset's --side), else None


@dataclass(frozen=True)
class MarkersConfig:
    """`markers:`: the mocap4r2_msgs/msg/Markers topic of ROS 2 recordings and the markers on the robot."""

    topic: str
    entries: tuple[MarkerConfig, ...]  # the `list:` of the config, in its order

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.entries]

    def marker(self, name: str) -> MarkerConfig:
        return self.entries[self.names.index(name)]


def _markers(path: Path, data) -> MarkersConfig:
    r = _Reader(path, data, "markers")
    r.check_keys(("list",), ("topic",))
    items = r.data["list"]
    if not isinstance(items, list) or not items:
        r.fail("'list' must be a non-empty list of markers ({name, link, xyz})")
    markers: list[MarkerConfig] = []
    for i, item in enumerate(items):
        m = _Reader(path, item, f"markers.list[{i}]")
        m.check_keys(("name", "link", "xyz"), ("side",))
        name = m.string("name")
        if not _MARKER_NAME.fullmatch(name):
            m.fail(
                f"'name' {name!r} must start with a letter and hold only letters, digits, '_' and inner spaces, "
                "after an optional 'Subject:' prefix (it is used in parameter names such as marker.r_foot_fl.x)"
            )
        if name in {k.name for k in markers}:
            m.fail(f"'name' {name!r} is used by another marker; names must be unique")
        side = m.data.get("side")
        if side is not None and side not in ("right", "left"):
            m.fail(f"'side' must be 'right' or 'left' (the leg the marker is on), found {side!r}")
        markers.append(MarkerConfig(name=name, link=m.string("link"), xyz=m.vector3("xyz"), side=side))
    return MarkersConfig(topic=r.string("topic", "/mocap/markers"), entries=tuple(markers))


@dataclass(frozen=True)
class FloorTagConfig:
    """A tag lying flat on the floor, face up, at a place the fit finds (DESIGN.md `floor.tags`)."""

    id: int
    family: str
    size: float  # edge of the black square [m]
    thickness: float = 0.0  # height of the tag's face above the floor [m]


@dataclass(frozen=True)
class GroundCheck:
    """The deploy verdict's ground error (`floor.ground_check`): a ball seen `distance` [m] away must land within
    `limit` [m] of where it lies. Defaults suit a KidSize field (9 x 6 m: 4.5 m is half its length); an AdultSize
    field (14 x 9 m) sees balls farther away (7 m is half its length)."""

    distance: float = 4.5  # [m]
    limit: float = 0.05  # [m]


@dataclass(frozen=True)
class SoleConfig:
    """A sole given as `{link, xyz}`: the frame `frame` [m] at `xyz` in `link`, axes as the link's, which the robot
    adds to its model (for URDFs without sole frames)."""

    frame: str  # `<link>_sole`
    link: str
    xyz: tuple[float, float, float]


@dataclass(frozen=True)
class FloorConfig:
    """The venue ground check (DESIGN.md `floor:`): the floor is the plane of the standing soles."""

    soles: tuple[str, ...]  # frames that lie on the floor (z up) when the robot stands: URDF links or `added_soles`
    standing: dict[str, float]  # joint readings of the standing pose [rad] (joints not named: 0)
    tags: tuple[FloorTagConfig, ...] = ()
    stances: tuple[dict[str, float], ...] = ()  # standing poses of the floor samples (`floor.stances`); () = standing
    # standing poses of the held-out floor capture that checks a fit (`floor.check_stances`, `capture --floor
    # --check`), none of the fit's: a stance the fit saw reads the ticks whose rounding the fit took in
    check_stances: tuple[dict[str, float], ...] = ()
    ground_check: GroundCheck = GroundCheck()  # the verdict's ground error distance and limit (`floor.ground_check`)
    added_soles: tuple[SoleConfig, ...] = ()  # soles given as {link, xyz}: frames the robot adds to its model
    aim: tuple[str, ...] = ()  # `floor.aim`: the joints that aim the camera (pan, tilt); () = the default

    @property
    def floor_stances(self) -> tuple[dict[str, float], ...]:
        """The standing poses floor samples are taken in: `floor.stances`, else just `floor.standing`."""
        return self.stances or (self.standing,)

    def named_stances(self) -> list[tuple[str, dict[str, float]]]:
        """Every standing pose the config gives, with its key: `floor.standing`, `floor.stances[i]`,
        `floor.check_stances[i]`."""
        return [
            ("floor.standing", self.standing),
            *((f"floor.stances[{i}]", s) for i, s in enumerate(self.stances)),
            *((f"floor.check_stances[{i}]", s) for i, s in enumerate(self.check_stances)),
        ]

    def capture_stances(self, check: bool = False) -> tuple[dict[str, float], ...]:
        """The stances a floor capture goes through: `floor_stances`, or with `check` `floor.check_stances` (() when
        there are none)."""
        return self.check_stances if check else self.floor_stances

    def tag(self, tag_id: int) -> FloorTagConfig:
        return _by_id(self.tags, tag_id)

    @property
    def tag_ids(self) -> list[int]:
        return [t.id for t in self.tags]


@dataclass(frozen=True)
class FieldConfig:
    """The RoboCup field (DESIGN.md `field:`): its markings and where the robot is placed for field views."""

    dimensions: FieldDimensions
    robot_at: tuple[float, float, float]  # x, y [m], yaw [rad] of the standing robot's floor frame on the field
    # `field.sweep`: the head's pan and tilt readings [rad] a field capture goes through (a grid, pan x tilt);
    # a key left out: the default of `wolfcal.capture.field`
    sweep: dict[str, tuple[float, ...]] = field(default_factory=dict)
    # where the robot stands for the held-out field views that check a fit (another place), as robot_at; None: not set
    check_at: tuple[float, float, float] | None = None


def _field(path: Path, data) -> FieldConfig:
    """`field:` with the field's `dimensions` [m], the robot's place `robot_at: {x, y, yaw}` [m, m, rad] and,
    optionally, the head sweep of a field capture `sweep: {pan, tilt}` [rad] and the held-out check's place `check_at`
    (the keys of robot_at)."""
    r = _Reader(path, data, "field")
    r.check_keys(("dimensions", "robot_at"), ("sweep", "check_at"))
    dimensions = r.data["dimensions"]
    if not isinstance(dimensions, dict):
        r.fail("'dimensions' must be a mapping of the field's sizes [m] (see the robot config reference)")
    places = []
    for key in ("robot_at", "check_at"):
        if key not in r.data:
            continue
        at = _Reader(path, r.data[key], f"field.{key}")
        at.check_keys(("x", "y", "yaw"))
        places.append((at.number("x"), at.number("y"), at.number("yaw")))
    sweep = _Reader(path, r.data.get("sweep") or {}, "field.sweep")
    sweep.check_keys((), ("pan", "tilt"))
    angles = {}
    for key, values in sweep.data.items():
        ok = isinstance(values, list) and values and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                         and np.isfinite(v) for v in values)  # fmt: skip
        if not ok:
            raise WolfcalError(f"{path}: 'field.sweep.{key}' must be a non-empty list of angles [rad], found "
                               f"{values!r}")  # fmt: skip
        angles[key] = tuple(float(v) for v in values)
    return FieldConfig(field_dimensions(dimensions, f"{path}: 'field.dimensions'"), places[0],
                       sweep=angles, check_at=places[1] if len(places) > 1 else None)  # fmt: skip


def _floor(path: Path, data, link_tags: tuple[TagConfig, ...]) -> FloorConfig:
    """`floor:` with its soles, standing readings and floor tags; a floor tag must not also be a tag on a link."""
    r = _Reader(path, data, "floor")
    r.check_keys(("soles", "standing"), ("tags", "stances", "check_stances", "ground_check", "aim"))
    soles, added_soles = _soles(path, r.data["soles"])
    aim = r.data.get("aim", [])
    if not isinstance(aim, list) or len(aim) > 2 or not all(isinstance(j, str) and j for j in aim):
        r.fail("'aim' must list the one or two joints that aim the camera, e.g. [HeadPan, HeadTilt]")
    standing = _readings(r, r.data["standing"], "standing")
    stances, check_stances = (_stances(r, key) for key in ("stances", "check_stances"))
    tags_data = r.data.get("tags") or []
    if not isinstance(tags_data, list):
        r.fail("'tags' must be a list of floor tags ({id, family, size, thickness})")
    tags: list[FloorTagConfig] = []
    on_links = {t.id for t in link_tags}
    for i, item in enumerate(tags_data):
        t = _Reader(path, item, f"floor.tags[{i}]")
        t.check_keys(("id", "size"), ("family", "thickness"))
        tag_id = t.data["id"]
        if isinstance(tag_id, bool) or not isinstance(tag_id, int) or tag_id < 0:
            t.fail(f"'id' must be a non-negative integer, found {tag_id!r}")
        if tag_id in on_links:
            t.fail(
                f"tag {tag_id} is also configured on a link under 'tags:'; a floor tag lies on the floor, "
                "so give it an id no tag on the robot uses"
            )
        if tag_id in {x.id for x in tags}:
            t.fail(f"tag {tag_id} is listed twice")
        family = t.string("family", "tag36h11")
        if family not in TAG_FAMILIES:
            t.fail(f"'family' {family!r} is not supported; use one of {', '.join(TAG_FAMILIES)}")
        thickness = t.number("thickness", 0.0)
        if thickness < 0:
            t.fail(f"'thickness' must not be negative, found {thickness!r}")
        size = check_printed_edge(t.number("size", positive=True), f"{path}: '{t.sub('size')}'")
        tags.append(FloorTagConfig(tag_id, family, size, thickness))
    return FloorConfig(soles, standing, tuple(tags), stances, check_stances, _ground_check(path, r.data),
                       added_soles, tuple(aim))  # fmt: skip


def _ground_check(path: Path, floor: dict) -> GroundCheck:
    """`floor.ground_check: {distance, limit}` [m, m], each optional (defaults: `GroundCheck`)."""
    if floor.get("ground_check") is None:
        return GroundCheck()
    r = _Reader(path, floor["ground_check"], "floor.ground_check")
    r.check_keys((), ("distance", "limit"))
    default = GroundCheck()
    return GroundCheck(r.number("distance", default.distance, positive=True),
                       r.number("limit", default.limit, positive=True))  # fmt: skip


def _soles(path: Path, data) -> tuple[tuple[str, ...], tuple[SoleConfig, ...]]:
    """`floor.soles`: each a link name, or {link, xyz} for a sole frame at xyz [m] in the link (axes as the link's).
    Returns the sole frames' names and the frames to add."""
    if not isinstance(data, list) or not data:
        raise WolfcalError(
            f"{path}: 'floor.soles' must be a non-empty list of links (or {{link, xyz}}) whose frames lie on the floor"
        )
    names: list[str] = []
    added: list[SoleConfig] = []
    for i, item in enumerate(data):
        if isinstance(item, str) and item:
            names.append(item)
            continue
        r = _Reader(path, item, f"floor.soles[{i}]")
        r.check_keys(("link", "xyz"))
        sole = SoleConfig(f"{r.string('link')}_sole", r.string("link"), r.vector3("xyz"))
        if sole.frame in names:
            r.fail(f"a second sole on link {sole.link!r}; give each sole its own link")
        names.append(sole.frame)
        added.append(sole)
    return tuple(names), tuple(added)


def _stances(r: _Reader, key: str) -> tuple[dict[str, float], ...]:
    """`floor.<key>`: a list of standing poses, each like 'standing'."""
    data = r.data.get(key) or []
    if not isinstance(data, list):
        r.fail(f"'{key}' must be a list of standing poses, each like 'standing' (joint -> reading [rad])")
    return tuple(_readings(r, item, f"{key}[{i}]") for i, item in enumerate(data))


def _readings(r: _Reader, data, key: str) -> dict[str, float]:
    """`floor.<key>`: joint name -> encoder reading [rad] (joints not named are 0)."""
    data = data or {}
    if not isinstance(data, dict):
        r.fail(f"'{key}' must map joint names to readings [rad] (joints not named are 0)")
    for joint, value in data.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            r.fail(f"'{key}.{joint}' must be a number [rad], found {value!r}")
    return {str(k): float(v) for k, v in data.items()}


# --- pose planning: `rest_pose:`, `collision_radii:`, `collision_ignore:` (all optional) ----------------------------
PLANNING_KEYS = ("rest_pose", "collision_radii", "collision_ignore")


@dataclass(frozen=True)
class PlanningConfig:
    """Where joints a planned pose leaves alone stand, capsule radii that replace the URDF's <collision>, and link
    pairs never checked for self-collision (as `disable_collisions` in a MoveIt SRDF)."""

    rest_pose: dict[str, float] = field(default_factory=dict)  # joint -> reading [rad]; others 0
    collision_radii: dict[str, float] = field(default_factory=dict)  # link -> capsule radius [m]
    collision_ignore: tuple[tuple[str, str], ...] = ()  # link pairs never checked against each other


def _planning(path: Path, data: dict) -> PlanningConfig:
    """`rest_pose: {joint: rad}`, `collision_radii: {link: m}` and `collision_ignore: [[link, link], ...]` (names
    are checked against the URDF later)."""
    out: dict = {}
    for key, positive in (("rest_pose", False), ("collision_radii", True)):
        value = data.get(key) or {}
        if not isinstance(value, dict):
            raise WolfcalError(f"{path}: '{key}' must map names to numbers, e.g. {{RKnee: -0.26}}")
        r = _Reader(path, value, key)
        out[key] = {str(k): r.number(k, positive=positive) for k in value}
    pairs = data.get("collision_ignore") or []
    if not isinstance(pairs, list) or not all(isinstance(p, list) and len(p) == 2 and all(isinstance(n, str) for n in p)
                                              for p in pairs):  # fmt: skip
        raise WolfcalError(f"{path}: 'collision_ignore' must be a list of link pairs, e.g. [[r_hip_1, r_upper_leg]]")
    out["collision_ignore"] = tuple((a, b) for a, b in pairs)
    return PlanningConfig(**out)
