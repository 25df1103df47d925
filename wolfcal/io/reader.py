"""Read capture files and plain ROS 2 recordings (MCAP) into `Capture`s of still samples.

A capture file (written by `CaptureWriter`) holds one JointState per image, with the image's stamp: every
image is a sample. Any other file is read as a recording: each image is paired with the joint states around
it and kept only when the robot was still (see `wolfcal.io.recording`). Images stay encoded;
`Sample.image()` decodes on demand.

Intrinsics of a sample, at its image's resolution, come from (first that applies): the `intrinsics`
argument (`--intrinsics FILE`), the CameraInfo stamped nearest to the image (binning applied, ROS
convention; an uncalibrated one, K all zero, counts as none), the robot config's `camera.intrinsics`.
Any of them at another resolution than the image is scaled to it (same aspect ratio only).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import IO

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import McapReader, make_reader
from mcap_ros2.decoder import DecoderFactory

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.camera.validate import MESSAGE_FIELDS, YAML_FIELDS, check_image_size, checked_camera
from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.io.images import image_kind, image_size
from wolfcal.io.mcapfile import check_mcap, is_finished, message_count, recover_hint, torn_error
from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, header_stamp_ns
from wolfcal.io.recording import JointStates, Paired, pair_frame
from wolfcal.io.samples import Capture, Sample
from wolfcal.io.validate import drop_damaged_images, finite_joint_states
from wolfcal.io.writer import CONFIG_ATTACHMENT, URDF_ATTACHMENT


def read_captures(
    paths: Iterable[str | Path], robot_config: RobotConfig, intrinsics: CameraModel | None = None
) -> list[Capture]:
    """`read_capture` of each file, in order."""
    return [read_capture(p, robot_config, intrinsics) for p in paths]


def read_capture(
    path: str | Path,
    robot_config: RobotConfig,
    intrinsics: CameraModel | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Capture:
    """Read one capture file or ROS 2 recording; WolfcalError naming the file when it gives no samples.
    `progress(messages read, messages in the file)` is called now and then while reading."""
    path = Path(path)
    check_mcap(path)
    if not is_finished(path):
        raise torn_error(path)
    try:
        with path.open("rb") as handle:
            return _read(path, handle, robot_config, intrinsics, progress)
    except McapError as exc:
        raise WolfcalError(f"{path}: damaged MCAP file ({exc}); {recover_hint(path)}") from None


def _check_topics(path: Path, reader: McapReader, config: RobotConfig) -> bool:
    """Check the config's topics are present with the right types; returns whether camera info is."""
    summary = reader.get_summary()
    if summary is None:
        raise WolfcalError(f"{path}: the MCAP file has no summary (no channel list); {recover_hint(path)}")
    counts = summary.statistics.channel_message_counts if summary.statistics else {}
    present: dict[str, str] = {}
    for channel in summary.channels.values():
        if counts.get(channel.id, 1):  # a channel without messages counts as missing
            schema = summary.schemas.get(channel.schema_id)
            present[channel.topic] = schema.name if schema else "(no schema)"
    wanted = {
        config.joint_states_topic: JOINT_STATE,
        config.camera.topic: COMPRESSED_IMAGE,
        config.camera.info_topic: CAMERA_INFO,
    }
    missing = [t for t in (config.joint_states_topic, config.camera.topic) if t not in present]
    if missing:
        listing = ", ".join(f"{t} ({present[t]})" for t in sorted(present)) or "none"
        raise WolfcalError(
            f"{path}: no messages on topic(s) {', '.join(missing)}. Topics in the file: {listing}. "
            f"The robot config {config.path} expects joint states on {config.joint_states_topic}, images on "
            f"{config.camera.topic} and camera info on {config.camera.info_topic} (optional); record these "
            "topics or set 'joint_states_topic' / 'camera.topic' / 'camera.info_topic' in the config"
        )
    for topic, datatype in wanted.items():
        if topic in present and present[topic].replace("/msg/", "/") != datatype.replace("/msg/", "/"):
            raise WolfcalError(
                f"{path}: topic {topic} carries {present[topic]}, wolfcal reads {datatype} there; record the "
                "matching topic (images: image_transport's compressed topic) or fix the topics in the config"
            )
    return config.camera.info_topic in present


def _camera_info_model(where: str, message) -> tuple[CameraModel, tuple[int, int]] | None:
    """(full-resolution model, binning) of a CameraInfo; None for an uncalibrated one (K all zero)."""
    if not np.any(np.asarray(message.k, dtype=float)) or message.width == 0 or message.height == 0:
        return None
    model = message.distortion_model or "plumb_bob"
    camera = checked_camera(where, message.width, message.height, message.k, message.d, model, MESSAGE_FIELDS)
    return camera, (max(int(message.binning_x), 1), max(int(message.binning_y), 1))


class _Intrinsics:
    """Chooses and scales the intrinsics of each image, caching one model per source and image size."""

    def __init__(self, path: Path, config: RobotConfig, override: CameraModel | None) -> None:
        self.path, self.config, self.override = path, config, override
        self.cache: dict[tuple, CameraModel] = {}
        self.fallback: CameraModel | None = None

    def for_image(
        self, size: tuple[int, int], info: tuple[CameraModel, tuple[int, int]] | None
    ) -> CameraModel:
        """Intrinsics for an image of `size` (width, height) given the CameraInfo nearest to it (or None)."""
        if self.override is not None:
            base, binning, what = self.override, (1, 1), (f"{self.path}: the --intrinsics", YAML_FIELDS)
        elif info is not None:
            where = f"{self.path}: CameraInfo on {self.config.camera.info_topic}"
            base, binning, what = info[0], info[1], (where, MESSAGE_FIELDS)
        else:
            where = f"{self.config.camera.intrinsics} (intrinsics for {self.path})"
            base, binning, what = self._config_intrinsics(), (1, 1), (where, YAML_FIELDS)
        key = (id(base), binning, size)
        if key not in self.cache:
            self.cache[key] = self._at_size(base, binning, size, what)
        return self.cache[key]

    def _config_intrinsics(self) -> CameraModel:
        if self.fallback is None:
            if self.config.camera.intrinsics is None:
                raise WolfcalError(
                    f"{self.path}: no CameraInfo on {self.config.camera.info_topic} and no intrinsics "
                    f"given; pass --intrinsics FILE or set 'camera.intrinsics' in {self.config.path}"
                )
            self.fallback = load_camera_info(self.config.camera.intrinsics)
        return self.fallback

    def _at_size(
        self, base: CameraModel, binning: tuple[int, int], size: tuple[int, int], what: tuple[str, dict]
    ) -> CameraModel:
        if binning != (1, 1):
            bx, by = binning
            base = base.scaled(1 / bx, 1 / by, base.width // bx, base.height // by)
        width, height = size
        if (base.width, base.height) == (width, height):
            return base
        check_image_size(*what, base, size)
        return base.scaled(width / base.width, height / base.height, width, height)


def _read(
    path: Path,
    handle: IO[bytes],
    config: RobotConfig,
    intrinsics: CameraModel | None,
    progress: Callable[[int, int], None] | None = None,
) -> Capture:
    """Both passes over an open file: pair and select frames, then fetch the kept frames' bytes."""
    reader = make_reader(handle, decoder_factories=[DecoderFactory()])
    use_info = _check_topics(path, reader, config) and intrinsics is None
    joint_messages, images, infos = [], [], []  # images: (stamp, kind, size) - the bytes come in pass 2
    info_models: dict[tuple, tuple[CameraModel, tuple[int, int]] | None] = {}
    topics = [config.joint_states_topic, config.camera.topic] + (
        [config.camera.info_topic] if use_info else []
    )
    total = message_count(reader, topics)
    for count, (_, channel, message, decoded) in enumerate(reader.iter_decoded_messages(topics=topics)):
        if progress is not None and count % 200 == 0:
            progress(count, total)
        stamp = header_stamp_ns(decoded.header, message.log_time)
        if channel.topic == config.joint_states_topic:
            joint_messages.append((stamp, decoded.name, decoded.position, decoded.velocity))
        elif channel.topic == config.camera.topic:
            images.append((stamp, image_kind(decoded.data), image_size(decoded.data)))
        else:
            key = (
                decoded.width,
                decoded.height,
                decoded.distortion_model,
                tuple(decoded.k),
                tuple(decoded.d),
            )
            key += (decoded.binning_x, decoded.binning_y)
            if key not in info_models:  # one model per distinct CameraInfo
                info_models[key] = _camera_info_model(f"{path}: CameraInfo on {channel.topic}", decoded)
            infos.append((stamp, info_models[key]))
    attachments = {a.name: a.data.decode("utf-8", errors="replace") for a in reader.iter_attachments()}

    if progress is not None:
        progress(total, total)
    # a capture file: one joint state per image, with the image's stamp
    exact = len(joint_messages) == len(images) and {i[0] for i in images} <= {m[0] for m in joint_messages}
    joint_messages, bad_stamps, skipped = finite_joint_states(path, config.joint_states_topic, joint_messages)
    states = JointStates.from_messages(joint_messages)
    info_stamps = np.asarray([s for s, _ in infos], dtype=np.int64)
    chooser = _Intrinsics(path, config, intrinsics)
    images.sort(key=lambda item: item[0])
    start = images[0][0] if images else 0
    kept: dict[int, Sample] = {}
    for stamp, kind, size in images:
        where = f"image {(stamp - start) / 1e9:.3f} s after the first (stamp {stamp} ns)"
        if kind is None or size is None:
            skipped.append(f"{where}: not a png or jpeg image")
            continue
        if stamp in bad_stamps:  # its joint reading is not a number: said in `skipped` already
            continue
        paired = pair_frame(states, stamp, exact)
        if not isinstance(paired, Paired):
            skipped.append(f"{where}: {paired}")
            continue
        if stamp in kept:
            skipped.append(f"{where}: a second image with the same stamp")
            continue
        info = infos[int(np.argmin(np.abs(info_stamps - stamp)))][1] if len(infos) else None
        kept[stamp] = Sample(
            stamp_ns=stamp,
            joint_names=list(states.names),
            positions=paired.positions,
            image_data=b"",
            image_format=kind,
            camera=chooser.for_image(size, info),
            velocities=paired.velocities,
            source=str(path),
        )
    if not kept:
        why = f"; e.g. {skipped[0]}" if skipped else ""
        raise WolfcalError(
            f"{path}: no usable samples ({len(images)} image(s) on {config.camera.topic}, "
            f"{len(joint_messages)} joint state(s) on {config.joint_states_topic}{why}); record the robot "
            "holding still poses with the camera running"
        )
    # pass 2: the encoded bytes of the kept frames only (a long recording's images need not fit in memory)
    for _, _, message, decoded in reader.iter_decoded_messages(topics=[config.camera.topic]):
        sample = kept.get(header_stamp_ns(decoded.header, message.log_time))
        if sample is not None and not sample.image_data:
            sample.image_data = bytes(decoded.data)
    skipped += drop_damaged_images(path, kept, [stamp for stamp, _, _ in images])
    return Capture(
        path=path,
        samples=list(kept.values()),
        urdf_text=attachments.get(URDF_ATTACHMENT),
        robot_config_text=attachments.get(CONFIG_ATTACHMENT),
        skipped=skipped,
    )

