"""`wolfcal simulate`: a capture file of a simulated robot with known ground truth.

Writes FILE.mcap (the capture format of DESIGN.md), FILE.truth.yaml (true corrections, camera, settings) and
FILE.truth.urdf (the robot as it really is: frame corrections folded into the origins, encoder offsets as
`<calibration rising>`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import yaml

from wolfcal.atomic import output_set, write_text_atomic
from wolfcal.camera.camera_info import camera_info_dict, load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.encoders import encoder_readings
from wolfcal.errors import WolfcalError
from wolfcal.io.writer import CaptureWriter
from wolfcal.outputs import check_outputs
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.sim.poses import random_visible_poses
from wolfcal.sim.scene import SimScene
from wolfcal.sim.truth import TruthSpec, random_truth
from wolfcal.vision.render import motion_blur

OFFSET_SETS = ("none", "head", "legs", "all")
START_NS = 1_700_000_000_000_000_000


@dataclass
class SimOptions:
    samples: int = 24
    seed: int = 0
    binning: int = 1
    noise_sigma: float = 2.0  # image noise [gray levels]
    outlier_fraction: float = 0.0  # share of samples made outliers (motion blur or stale joint reading)
    offsets: str = "none"  # which joints get a true encoder offset: none | head | legs | all (head and legs)
    truth: TruthSpec = field(default_factory=TruthSpec)
    truth_file: Path | None = None  # reuse the truth of an earlier simulation (e.g. for a held-out capture)


def truth_paths(out: Path) -> tuple[Path, Path]:
    stem = out.with_suffix("")
    return Path(f"{stem}.truth.yaml"), Path(f"{stem}.truth.urdf")


def offset_joints(robot: Robot, which: str) -> tuple[str, ...]:
    """The joints that get a true encoder offset: none, head (base -> camera), legs (base -> foot tags), all."""
    if which not in OFFSET_SETS:
        raise WolfcalError(f"--offsets {which!r} must be one of {', '.join(OFFSET_SETS)}")
    head = robot.camera_and_leg_joints(sides=())
    everything = robot.camera_and_leg_joints()
    legs = tuple(j for j in everything if j not in head)
    return {"none": (), "head": head, "legs": legs, "all": everything}[which]


def simulate_capture(
    robot_path: Path,
    out: Path,
    options: SimOptions,
    camera: CameraModel | None = None,
    say: Callable[[str], None] = print,
    force: bool = False,
) -> Corrections:
    """Simulate a capture; returns the true corrections (also written to FILE.truth.yaml). The three files are
    written as one set; existing ones are replaced only with `force`."""
    if out.suffix != ".mcap":
        raise WolfcalError(f"{out}: the capture file name must end in .mcap")
    if options.samples < 1:
        raise WolfcalError("--samples must be at least 1")
    robot = load_robot(robot_path)
    inputs = [robot.config.path, robot.config.urdf] + ([options.truth_file] if options.truth_file else [])
    check_outputs([out, *truth_paths(out)], force, inputs)
    with output_set():
        return _simulate(robot, out, options, camera, say)


def _simulate(
    robot: Robot, out: Path, options: SimOptions, camera: CameraModel | None, say: Callable[[str], None]
) -> Corrections:
    if camera is None:
        if robot.config.camera.intrinsics is None:
            raise WolfcalError(f"{robot.config.path}: set 'camera.intrinsics' or pass --intrinsics FILE")
        camera = load_camera_info(robot.config.camera.intrinsics)
    b = options.binning
    image_camera = camera if b == 1 else camera.scaled(1 / b, 1 / b, camera.width // b, camera.height // b)
    rng = np.random.default_rng(options.seed)
    spec = TruthSpec(**{**asdict(options.truth), "offset_joints": offset_joints(robot, options.offsets)})
    truth = random_truth(robot, spec, rng)
    if options.truth_file is not None:
        truth = load_corrections(options.truth_file, key="truth")
    q_true, visible = random_visible_poses(robot, image_camera, truth, options.samples, rng)
    offsets = truth.offset_vector(robot.joint_names)
    q_measured = encoder_readings(q_true, offsets)
    n_out = int(round(options.outlier_fraction * options.samples))
    outlier_index = rng.choice(options.samples, size=n_out, replace=False) if n_out else np.array([], int)
    kinds = {int(i): ("motion_blur" if k % 2 == 0 else "stale_joints") for k, i in enumerate(outlier_index)}
    moving = [robot.model.column(j) for j in robot.camera_and_leg_joints()]
    scene = SimScene(robot, truth, image_camera, seed=options.seed + 1, noise_sigma=options.noise_sigma)
    with CaptureWriter(out, robot.config, camera, binning=(b, b)) as writer:
        for i in range(options.samples):
            image = scene.render_true(q_true[i])
            reading = q_measured[i].copy()
            if kinds.get(i) == "motion_blur":
                image = motion_blur(image, length_px=rng.uniform(0.008, 0.015) * image_camera.width,
                                    angle_rad=rng.uniform(0, np.pi))
            elif kinds.get(i) == "stale_joints":
                reading[moving] += rng.normal(0.0, 0.04, len(moving))
            stamp = START_NS + i * 2_000_000_000
            writer.add_sample(stamp, robot.joint_names, reading, np.zeros_like(reading), image)
            seen = ", ".join(str(t) for t, v in zip(robot.config.tag_ids, visible[i]) if v)
            say(f"sample {i + 1}/{options.samples}: tags {seen}" + (f" ({kinds[i]})" if i in kinds else ""))
    truth_yaml, truth_urdf = truth_paths(out)
    write_text_atomic(
        truth_yaml,
        yaml.safe_dump(
            {
                "truth": truth.to_dict(),
                "camera": camera_info_dict(camera),
                "binning": b,
                "samples": options.samples,
                "seed": options.seed,
                "noise_sigma": options.noise_sigma,
                "outliers": {int(k): v for k, v in sorted(kinds.items())},
                "meaning": "offsets: q_true = q_measured + offset [rad]; frames/tags: origin_new = origin * "
                "Trans(x,y,z) * Exp(rx,ry,rz) [m, rad]",
            },
            sort_keys=False,
        ),
    )
    write_calibrated_urdf(robot.config.urdf, robot.model, truth, truth_urdf)
    say(f"wrote {out}, {truth_yaml}, {truth_urdf}")
    return truth
