"""The cameras of one `wolfcal capture`: the head camera (`--camera SOURCE`) and external cameras
(`--external NAME=SOURCE`, repeatable), each with its intrinsics, binning and open image source.

Sources: a V4L index or /dev/video path, a video file, an image folder, or `sim` (renders the robot served by
`wolfcal emulate`; an external camera from its placement, see `sim_camera`). Intrinsics: the head camera's from
`--intrinsics` or the config's `camera.intrinsics`; an external camera's from its `intrinsics` in the config.
Binning: `--binning` for every camera; by default a simulated camera's (`sim.scene.sim_binning`, as `wolfcal
simulate`), 1 for real cameras.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.capture.options import CaptureOptions, parse_external
from wolfcal.capture.sim_camera import SimCamera
from wolfcal.hardware.camera import CameraSource, open_camera
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.robot import Robot
from wolfcal.sim.scene import sim_binning


@dataclass
class CaptureCamera:
    model: CameraModel  # full-resolution intrinsics (written to CameraInfo)
    image_model: CameraModel  # intrinsics of the binned images
    binning: int
    source_text: str
    source: CameraSource | None = None  # opened by `open_sources`


def plan_cameras(options: CaptureOptions, robot: Robot) -> dict[str, CaptureCamera]:
    """The cameras to record by name ('head' first), checked against the config; nothing opened yet."""
    sources: dict[str, str] = {}
    if options.camera is not None:
        robot.config.head_camera("--camera records the head camera, which needs one")
        sources[HEAD_CAMERA] = options.camera
    for text in options.external:
        name, source = parse_external(text)
        robot.config.external_camera(name)  # a clear error for a name the config does not have
        sources[name] = source
    cameras = {}
    for name, source in sources.items():
        head = name == HEAD_CAMERA
        path = (
            Path(options.intrinsics)
            if head and options.intrinsics
            else robot.config.intrinsics_file(name, "capturing", "pass --intrinsics FILE" if head else "")
        )
        model = load_camera_info(path)
        binning = options.binning or (sim_binning(name) if source == "sim" else 1)
        cameras[name] = CaptureCamera(model, model.binned(binning, name), binning, source)
    return cameras


def open_sources(
    cameras: dict[str, CaptureCamera], robot: Robot, ports: list[str], field: bool = False, check: bool = False
) -> None:
    """Open every camera's source (a `sim` one reads the emulators on the servo buses `ports`; with `field` the
    head camera sees the field the robot stands on, at `field.check_at` with `check`); on failure the ones already
    open are closed again."""
    try:
        for name, camera in cameras.items():
            if camera.source_text == "sim":
                external = None if name == HEAD_CAMERA else name
                camera.source = SimCamera(
                    robot, ports, camera.image_model, external=external, field=field, field_check=check
                )
            else:
                camera.source = open_camera(camera.source_text, camera.image_model)
    except BaseException:
        close_sources(cameras)
        raise


def close_sources(cameras: dict[str, CaptureCamera]) -> None:
    for camera in cameras.values():
        if camera.source is not None:
            camera.source.close()
            camera.source = None
