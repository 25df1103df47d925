"""Which cameras a capture file or recording holds, checked against the robot config before anything is decoded.

Every configured topic present must carry its message type; the joint states and at least one configured camera's
images must be there. A capture written by wolfcal names its cameras (metadata `wolfcal.cameras`); there, and in any
file written by wolfcal, an image stream of a camera the config does not know is an error rather than silently left
out (in a plain recording other image topics are simply not read).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mcap.reader import McapReader

from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.io.mcapfile import recover_hint
from wolfcal.io.msgdefs import CAMERA_INFO, CAMERAS_METADATA, COMPRESSED_IMAGE, JOINT_STATE, LIBRARY


@dataclass(frozen=True)
class FileCameras:
    cameras: list[str]  # configured cameras with images in the file, in config order
    with_info: set[str]  # those of them whose camera-info topic has messages


def _same_type(a: str, b: str) -> bool:
    return a.replace("/msg/", "/") == b.replace("/msg/", "/")


def _present_topics(path: Path, reader: McapReader) -> dict[str, str]:
    """topic -> schema name of every channel with messages."""
    summary = reader.get_summary()
    if summary is None:
        raise WolfcalError(f"{path}: the MCAP file has no summary (no channel list); {recover_hint(path)}")
    counts = summary.statistics.channel_message_counts if summary.statistics else {}
    present: dict[str, str] = {}
    for channel in summary.channels.values():
        if counts.get(channel.id, 1):  # a channel without messages counts as missing
            schema = summary.schemas.get(channel.schema_id)
            present[channel.topic] = schema.name if schema else "(no schema)"
    return present


def _expected_topics(config: RobotConfig) -> str:
    parts = [f"joint states on {config.joint_states_topic}"]
    for name in config.camera_names:
        image, info = config.camera_topics(name)
        parts.append(f"camera '{name}': images on {image}, camera info on {info} (optional)")
    return "; ".join(parts)


def _check_unknown_cameras(path: Path, reader: McapReader, config: RobotConfig, present: dict[str, str]) -> None:
    """A wolfcal capture with images of a camera the robot config does not name: an error naming file and topic."""
    configured = {config.camera_topics(n)[0]: n for n in config.camera_names}
    recorded: dict[str, str] = {}  # image topic -> camera name, from the capture's metadata
    for record in reader.iter_metadata():
        if record.name == CAMERAS_METADATA:
            recorded.update({topic: name for name, topic in record.metadata.items()})
    header = reader.get_header()
    if not recorded and header.library != LIBRARY:
        return  # a plain recording: other image topics are not read
    for topic, schema in sorted(present.items()):
        if _same_type(schema, COMPRESSED_IMAGE) and topic not in configured:
            name = recorded.get(topic)
            what = f"external camera '{name}'" if name else "a camera"
            raise WolfcalError(
                f"{path}: topic {topic} holds images of {what} that the robot config {config.path} does not "
                f"name; add it under 'external_cameras:' (name, image_topic: {topic}, info_topic) or use the "
                "config the capture was made with"
            )


def check_topics(path: Path, reader: McapReader, config: RobotConfig) -> FileCameras:
    """Check the file's topics against the config; returns the cameras it holds."""
    present = _present_topics(path, reader)
    listing = ", ".join(f"{t} ({present[t]})" for t in sorted(present)) or "none"
    wanted = {config.joint_states_topic: JOINT_STATE}
    for name in config.camera_names:
        image, info = config.camera_topics(name)
        wanted.update({image: COMPRESSED_IMAGE, info: CAMERA_INFO})
    for topic, datatype in wanted.items():
        if topic in present and not _same_type(present[topic], datatype):
            raise WolfcalError(
                f"{path}: topic {topic} carries {present[topic]}, wolfcal reads {datatype} there; record the "
                "matching topic (images: image_transport's compressed topic) or fix the topics in the config"
            )
    cameras = [n for n in config.camera_names if config.camera_topics(n)[0] in present]
    if config.joint_states_topic not in present or not cameras:
        missing = [config.joint_states_topic] if config.joint_states_topic not in present else []
        missing += [] if cameras else [config.camera_topics(n)[0] for n in config.camera_names]
        raise WolfcalError(
            f"{path}: no messages on topic(s) {', '.join(missing)}. Topics in the file: {listing}. The robot "
            f"config {config.path} expects {_expected_topics(config)}; record these topics or set "
            "'joint_states_topic' / 'camera.topic' / 'external_cameras[].image_topic' (and the info topics) in "
            "the config"
        )
    _check_unknown_cameras(path, reader, config, present)
    with_info = {n for n in cameras if config.camera_topics(n)[1] in present}
    return FileCameras(cameras, with_info)
