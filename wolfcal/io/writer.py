"""Write capture files: one still sample = a JointState plus, for each camera that took part, a CompressedImage (a png
stored without compression or filters, quick to decode, or a jpeg: `wolfcal.io.images.encode_image`) and a
CameraInfo, all with one header stamp. Cameras are the head camera (`HEAD_CAMERA`, topics `camera.topic` /
`camera.info_topic`) and external cameras (their `image_topic` / `info_topic`); the file's metadata record
`wolfcal.cameras` maps each recorded camera name to its image topic, so a reader can tell a camera the robot config
does not know.

The file is an MCAP file with ROS 2 messages (CDR, `ros2msg` schemas, profile `ros2`), so `ros2 bag` and
Foxglove open it. Durability: every sample is its own chunk, written, flushed and fsynced into
`<path>.partial` before `add_sample` returns; `close()` writes the summary (indexes, Statistics) and renames
the file to `<path>`. A process killed mid-capture leaves `<path>.partial`, from which `wolfcal recover`
rescues every sample that was added.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

import numpy as np
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2._dynamic import serialize_dynamic

from wolfcal.atomic import make_folder, replace_file
from wolfcal.camera.model import CameraModel
from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.io.images import encode_image
from wolfcal.io.mcapfile import partial_path
from wolfcal.io.msgdefs import (
    CAMERA_INFO,
    CAMERAS_METADATA,
    COMPRESSED_IMAGE,
    CONFIG_ATTACHMENT,
    JOINT_STATE,
    LIBRARY,
    MSGDEFS,
    URDF_ATTACHMENT,
    stamp_dict,
)
from wolfcal.observations import HEAD_CAMERA

CameraStreams = dict[str, tuple[CameraModel, tuple[int, int]]]  # camera name -> (full-resolution model, binning)
# Chunks close only when a sample is complete (flush), never inside one: a torn file holds whole samples.
_NEVER = 2**62


def camera_info_message(camera: CameraModel, binning: tuple[int, int], stamp_ns: int, frame_id: str) -> dict:
    """sensor_msgs/CameraInfo of a full-resolution camera with images binned by `binning` (ROS convention)."""
    P = np.zeros((3, 4))
    P[:, :3] = camera.K
    return {
        "header": {"stamp": stamp_dict(stamp_ns), "frame_id": frame_id},
        "height": int(camera.height),
        "width": int(camera.width),
        "distortion_model": camera.distortion_model,
        "d": [float(v) for v in camera.D],
        "k": [float(v) for v in camera.K.ravel()],
        "r": [float(v) for v in np.eye(3).ravel()],
        "p": [float(v) for v in P.ravel()],
        "binning_x": int(binning[0]),
        "binning_y": int(binning[1]),
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def start_file(
    file: BinaryIO, config: RobotConfig, topics: list[tuple[str, str]], metadata: dict[str, dict[str, str]]
) -> tuple[McapWriter, dict[str, int], dict[str, Callable]]:
    """Start a capture file in `file`: header (profile ros2), a schema per message type and a channel per
    (topic, type), the metadata records, the URDF and robot config attached; flushed and fsynced. Returns the
    writer, the channel id by topic and the CDR encoder by message type."""
    mcap = McapWriter(file, chunk_size=_NEVER, compression=CompressionType.NONE)
    mcap.start(profile="ros2", library=LIBRARY)
    schema_ids, channels, encoders = {}, {}, {}
    for topic, datatype in topics:
        if datatype not in schema_ids:
            schema_ids[datatype] = mcap.register_schema(datatype, "ros2msg", MSGDEFS[datatype].encode())
            encoders[datatype] = serialize_dynamic(datatype, MSGDEFS[datatype])[datatype]
        channels[topic] = mcap.register_channel(topic, "cdr", schema_ids[datatype])
    for name, record in metadata.items():
        mcap.add_metadata(name, record)
    now = time.time_ns()
    for name, media_type, source in (
        (URDF_ATTACHMENT, "application/xml", config.urdf),
        (CONFIG_ATTACHMENT, "application/yaml", config.path),
    ):
        mcap.add_attachment(now, now, name, media_type, Path(source).read_bytes())
    mcap.flush()
    os.fsync(file.fileno())
    return mcap, channels, encoders


def finish_file(mcap: McapWriter, file: BinaryIO, partial: Path, path: Path, written: bool) -> Path | None:
    """Finish a capture file started by `start_file` in `file` (open on `partial`): summary and footer, fsynced,
    closed, then renamed to `path` (inside an output set: when the whole set is written). Without `written`
    messages the partial file is removed instead, so an empty capture never replaces an earlier one; returns
    `path` or None."""
    mcap.finish()
    file.flush()
    os.fsync(file.fileno())
    file.close()
    if not written:
        partial.unlink()
        return None
    replace_file(partial, path)
    return path


class CaptureWriter:
    """Context manager writing one capture file; see the module docstring for the guarantees.

    `cameras` maps each camera to record ('head' or an external camera of the config) to its full-resolution model
    and binning; images given to `add_sample` must have the binned size
    (camera.width // binning[0], camera.height // binning[1]).
    """

    def __init__(
        self,
        path: str | Path,
        robot_config: RobotConfig,
        cameras: CameraStreams,
        image_format: str = "png",
    ) -> None:
        self.path = Path(path)
        self.partial = partial_path(self.path)
        if image_format not in ("png", "jpeg"):
            raise WolfcalError(f"{self.path}: unknown image format {image_format!r}; use 'png' or 'jpeg'")
        if not cameras:
            raise WolfcalError(f"{self.path}: no camera to record; a capture needs at least one")
        for name, (_, binning) in cameras.items():
            if len(binning) != 2 or any(int(b) != b or b < 1 for b in binning):
                raise WolfcalError(
                    f"{self.path}: binning of camera {name!r} must be two positive integers, found {binning!r}"
                )
        self.topics = {name: robot_config.camera_topics(name) for name in cameras}  # checks the names
        if self.partial.exists():
            raise WolfcalError(
                f"{self.partial} exists: an earlier capture did not finish; rescue its samples with "
                f"`wolfcal recover {self.partial}` or delete it, then capture again"
            )
        self.config = robot_config
        self.cameras = {name: (camera, (int(b[0]), int(b[1]))) for name, (camera, b) in cameras.items()}
        self.image_sizes = {
            name: (camera.width // b[0], camera.height // b[1]) for name, (camera, b) in self.cameras.items()
        }
        self.frame_ids = {name: self._frame_id(name) for name in cameras}
        self.image_format = image_format
        self.count = 0
        self._closed = False
        make_folder(self.path.parent)  # removed again if the output set it belongs to fails
        self._file = open(self.partial, "xb")  # closed in close()
        try:
            self._mcap, self._channels, self._encoders = self._start(robot_config)
        except BaseException:  # e.g. an unreadable URDF: leave no .partial that blocks the next capture
            self._file.close()
            self.partial.unlink()
            raise

    def _frame_id(self, name: str) -> str:
        """header.frame_id of a camera's messages: the head camera's optical frame, `<name>_optical_frame` else."""
        return self.config.head_camera().frame if name == HEAD_CAMERA else f"{name}_optical_frame"

    def _start(self, config: RobotConfig) -> tuple[McapWriter, dict[str, int], dict[str, Callable]]:
        """Header, schemas, channels (by topic), camera metadata and attachments; durable on return."""
        topics = [(config.joint_states_topic, JOINT_STATE)]
        for image_topic, info_topic in self.topics.values():
            topics += [(image_topic, COMPRESSED_IMAGE), (info_topic, CAMERA_INFO)]
        metadata = {CAMERAS_METADATA: {name: image for name, (image, _) in self.topics.items()}}
        return start_file(self._file, config, topics, metadata)

    def add_sample(
        self,
        stamp_ns: int,
        joint_names: list[str],
        positions: np.ndarray,
        velocities: np.ndarray | None,
        images: dict[str, np.ndarray],
    ) -> None:
        """Append one still sample (positions [rad], velocities [rad/s] or None, one image per camera that took
        part: a subset of the writer's cameras, at least one); durable on return."""
        if self._closed:
            raise WolfcalError(f"{self.path}: the capture is closed; open a new CaptureWriter")
        positions = np.asarray(positions, dtype=float).ravel()
        velocities = None if velocities is None else np.asarray(velocities, dtype=float).ravel()
        if len(positions) != len(joint_names) or (velocities is not None and len(velocities) != len(joint_names)):
            raise WolfcalError(f"{self.path}: {len(joint_names)} joint names but positions/velocities differ")
        unknown = sorted(set(images) - set(self.cameras))
        if unknown or not images:
            raise WolfcalError(
                f"{self.path}: a sample needs images of the writer's cameras ({', '.join(self.cameras)}), "
                f"got {', '.join(unknown) if unknown else 'none'}"
            )
        for name, image in images.items():
            self._check_size(name, image)
        stamp = stamp_dict(stamp_ns)
        messages: list[tuple[str, str, dict[str, object]]] = [
            (
                self.config.joint_states_topic,
                JOINT_STATE,
                {
                    "header": {"stamp": stamp, "frame_id": ""},
                    "name": list(joint_names),
                    "position": positions.tolist(),
                    "velocity": [] if velocities is None else velocities.tolist(),
                    "effort": [],
                },
            )
        ]
        for name, image in images.items():  # encode every image before anything is written
            data, image_format = encode_image(image, self.image_format)
            image_topic, info_topic = self.topics[name]
            camera, binning = self.cameras[name]
            header = {"stamp": stamp, "frame_id": self.frame_ids[name]}
            messages.append((image_topic, COMPRESSED_IMAGE, {"header": header, "format": image_format, "data": data}))
            messages.append(
                (info_topic, CAMERA_INFO, camera_info_message(camera, binning, stamp_ns, self.frame_ids[name]))
            )
        for topic, datatype, message in messages:
            self._mcap.add_message(
                self._channels[topic],
                log_time=int(stamp_ns),
                data=self._encoders[datatype](message),
                publish_time=int(stamp_ns),
                sequence=self.count,
            )
        self._sync()
        self.count += 1

    def _check_size(self, name: str, image: np.ndarray) -> None:
        height, width = image.shape[:2]
        if (width, height) != self.image_sizes[name]:
            camera, binning = self.cameras[name]
            size = self.image_sizes[name]
            raise WolfcalError(
                f"{self.path}: image of camera {name!r} is {width}x{height} px, but camera "
                f"{camera.width}x{camera.height} with binning {binning[0]}x{binning[1]} gives {size[0]}x{size[1]}"
            )

    def close(self) -> Path | None:
        """Finish the file and rename it to `path`; returns `path`, or None if no sample was added."""
        if self._closed:
            return self.path if self.count else None
        self._closed = True
        return finish_file(self._mcap, self._file, self.partial, self.path, bool(self.count))

    def _sync(self) -> None:
        self._mcap.flush()
        os.fsync(self._file.fileno())

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
