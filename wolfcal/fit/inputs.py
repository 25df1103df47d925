"""What `wolfcal fit` reads before it solves: the captures' samples (robot checked), the cameras of a --system, and
warnings on repeated images. No solver here: `wolfcal.fit.run` reads and detects with this while the solver's
modules load (`wolfcal.fit.pipeline`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import yaml

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.errors import WolfcalError
from wolfcal.io.reader import read_capture, require_cameras
from wolfcal.io.samples import Capture, Sample
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.progress import Progress
from wolfcal.robot.robot import Robot
from wolfcal.yamlfile import load_yaml


def in_system(camera: str, system: str | None) -> bool:
    """Whether a camera belongs to a --system: head -> the head camera, external -> any other; all (or no
    choice) -> every camera."""
    return system in (None, "all") or (system == "head") == (camera == HEAD_CAMERA)


def load_captures(
    robot: Robot, captures: list[Path], intrinsics: Path | None, say: Callable[[str], None] | None = None
) -> list[Capture]:
    """The captures read; one whose attached robot config names another robot is refused. `say` gets progress
    lines while long files are read."""
    camera = load_camera_info(intrinsics) if intrinsics else None
    progress = (lambda path: Progress(say, f"reading {Path(path).name}", "messages")) if say else (lambda path: None)
    loaded = [read_capture(path, robot.config, camera, progress(path)) for path in captures]
    for capture in loaded:
        name = attached_robot_name(capture.robot_config_text)
        if name is not None and name != robot.config.name:
            raise WolfcalError(
                f"{capture.path}: captured with robot '{name}', but --robot is '{robot.config.name}' "
                f"({robot.config.path}); use the config of the robot that was captured"
            )
    return loaded


def samples_of(
    loaded: list[Capture], robot: Robot, cameras: tuple[str, ...] = (HEAD_CAMERA,)
) -> tuple[list[Sample], list[str]]:
    """All samples of read captures, and notes on frames a recording skipped; a capture without images of each of
    `cameras` is refused."""
    require_cameras(loaded, cameras, robot.config)
    samples = [s for c in loaded for s in c.samples]
    notes = [f"{c.path.name}: {len(c.skipped)} frame(s) skipped ({c.skipped[0]} ...)" for c in loaded if c.skipped]
    return samples, notes


def load_samples(
    robot: Robot, captures: list[Path], intrinsics: Path | None, cameras: tuple[str, ...] = (HEAD_CAMERA,),
    say: Callable[[str], None] | None = None,
) -> tuple[list[Sample], list[str]]:
    """`samples_of` the captures read by `load_captures`."""
    return samples_of(load_captures(robot, captures, intrinsics, say), robot, cameras)


def attached_robot_name(config_text: str | None) -> str | None:
    """The `name` of a robot config attached to a capture (None when absent or unreadable)."""
    try:
        data = load_yaml(config_text) if config_text else None
    except yaml.YAMLError:
        return None
    return data.get("name") if isinstance(data, dict) else None


def repeat_warnings(observations: dict[str, Observations], noise_floor_px: float) -> list[str]:
    """A warning per camera whose samples repeat the image before them exactly (`Observations.repeated_samples`)."""
    warnings = []
    for name, obs in observations.items():
        repeated = obs.repeated_samples()
        if repeated:
            warnings.append(
                f"{name} camera: {repeated} of {obs.n_samples} sample(s) show exactly the tag corners of the sample "
                "before them (the same image again: a camera driver repeating its last frame, or a copied stream); "
                "they add no information, and the pixel noise estimate, which reads the scatter between the frames "
                "of a pose, stays at its floor "
                f"({noise_floor_px} px)"
            )
    return warnings
