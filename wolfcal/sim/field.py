"""Simulated field views: the robot stands on a RoboCup field at a true place and sweeps its head over the field.

The robot stands at the true joint angles of `floor.standing` (its soles on the field); its encoders report them
minus the true offsets. The head's pan and tilt (the aiming joints, `robot.aim.aim_joints`) are drawn so that each
view sees at least `min_points` points of the field's lines within `max_distance` m. `synthetic_field` gives the
line points themselves (projected exactly, plus pixel noise), for tests that need no images; `field_views` gives
the true camera poses for rendering (`wolfcal.field.render`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from wolfcal.atomic import output_set, write_text_atomic
from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.encoders import encoder_readings
from wolfcal.errors import WolfcalError
from wolfcal.field.ground import camera_on_field
from wolfcal.field.model import FieldDimensions, FieldLines, field_lines
from wolfcal.field.observations import FieldObservations, spread
from wolfcal.field.render import pixel_rays, render_field_view
from wolfcal.field.scene import cluttered_scene
from wolfcal.io.truth import truth_paths
from wolfcal.io.writer import CaptureWriter
from wolfcal.observations import HEAD_CAMERA
from wolfcal.outputs import check_outputs
from wolfcal.robot.aim import aim_joints
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.floor import camera_in_floor, standing_pose
from wolfcal.robot.robot import Robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.sim.scene import sim_binning
from wolfcal.sim.simulate import SimOptions, offset_joints
from wolfcal.sim.truth import TruthSpec, random_truth
from wolfcal.yamlfile import dump_yaml

SAMPLE_SPACING_M = 0.05  # line points along the lines for synthetic views [m]


@dataclass(frozen=True)
class FieldViews:
    """True field views of a standing robot."""

    q_true: np.ndarray  # (S, J) true joint angles [rad]
    T_field_camera: np.ndarray  # (S, 4, 4) true camera poses on the field


def line_samples(lines: FieldLines, spacing: float = SAMPLE_SPACING_M) -> np.ndarray:
    """(N, 2) points along every line of the field, `spacing` apart [m]."""
    points = []
    for start, end in lines.segments:
        n = max(2, int(np.ceil(np.linalg.norm(end - start) / spacing)) + 1)
        points.append(start + np.linspace(0.0, 1.0, n)[:, None] * (end - start))
    angles = np.linspace(0.0, 2 * np.pi, int(np.ceil(2 * np.pi * lines.circle_radius / spacing)), endpoint=False)
    points.append(lines.circle_radius * np.column_stack([np.cos(angles), np.sin(angles)]))
    return np.vstack(points)


def visible_line_points(camera: CameraModel, T_field_camera: np.ndarray, points: np.ndarray,
                        max_distance: float, margin_px: float = 2.0) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Pixels (K, 2) of the field points (N, 2) a camera sees within `max_distance` [m] of it, and their indices."""
    p = np.column_stack([points, np.zeros(len(points))])
    T = np.linalg.inv(T_field_camera)
    p_camera = p @ T[:3, :3].T + T[:3, 3]
    near = (p_camera[:, 2] > 0.1) & (np.linalg.norm(p_camera, axis=1) < max_distance)
    uv = camera.project(p_camera)
    keep = near & camera.in_image(uv, margin_px)
    return uv[keep], np.flatnonzero(keep)


def field_views(
    robot: Robot,
    camera: CameraModel,
    truth: Corrections,
    pose: np.ndarray,
    dims: FieldDimensions,
    n: int,
    rng: np.random.Generator,
    min_points: int = 60,
    max_distance: float = 7.0,
) -> FieldViews:
    """n standing views from a robot at the true field pose (x, y, yaw) whose head sees the lines (module
    docstring)."""
    joints = [robot.model.joints[j] for j in aim_joints(robot)]
    q = np.tile(standing_pose(robot), (40 * n, 1))
    for j in joints:
        q[:, robot.model.column(j.name)] = rng.uniform(max(j.lower, -1.5), min(j.upper, 1.5), len(q))
    true_model = Corrections(frames=truth.frames, tags=truth.tags)  # q are true angles: no offsets
    T_field_camera = camera_on_field(camera_in_floor(robot, q, true_model)[0], pose)
    samples = line_samples(field_lines(dims))
    seen = np.array([len(visible_line_points(camera, T, samples, max_distance)[1]) for T in T_field_camera])
    good = np.flatnonzero(seen >= min_points)
    if len(good) < n:
        raise WolfcalError(
            f"{robot.config.path}: only {len(good)} of {len(q)} head poses see at least {min_points} "
            f"line points within {max_distance} m from {tuple(np.round(pose, 2))}; asked for {n}"
        )
    chosen = rng.choice(good, n, replace=False)
    return FieldViews(q[chosen], T_field_camera[chosen])


def synthetic_field(robot: Robot, camera: CameraModel, truth: Corrections, pose: np.ndarray, start: np.ndarray,
                    dims: FieldDimensions, n: int, rng: np.random.Generator, noise_px: float = 0.3,
                    source: str = "field.mcap") -> FieldObservations:  # fmt: skip
    """Line points of n views (module docstring) with Gaussian pixel noise [px]; `start` is the field pose the
    fit starts from (where the robot was meant to stand)."""
    views = field_views(robot, camera, truth, pose, dims, n, rng)
    samples = line_samples(field_lines(dims))
    uv, index = [], []
    for s, T in enumerate(views.T_field_camera):
        seen, _ = visible_line_points(camera, T, samples, 7.0)
        seen = seen[spread(seen)]
        uv.append(seen + rng.normal(0.0, noise_px, seen.shape))
        index.append(np.full(len(seen), s))
    q_read = encoder_readings(views.q_true, truth.offset_vector(robot.joint_names))
    return FieldObservations(list(robot.joint_names), q_read, np.arange(n, dtype=np.int64) + 10**6, [source] * n,
                             np.zeros(n, dtype=int), np.asarray(start, float)[None], camera, np.concatenate(index),
                             np.vstack(uv))  # fmt: skip


def simulate_field_capture(robot: Robot, out: Path, options: SimOptions, camera: CameraModel | None,
                           say: Callable[[str], None], force: bool, inputs: list[Path]) -> Corrections:  # fmt: skip
    """The field system's simulator (`wolfcal.fit.systems`): the robot stands on the config's field within 0.3 m
    and 10 deg of `field.robot_at` (`field.check_at` for the held-out check, `options.floor_check`) and its head
    camera sweeps over the lines; colour images rendered with goals, two
    other robots, a ball, shadows, people and walls (`wolfcal.field.scene`), noise and up to 2 px of motion blur.
    Writes FILE.mcap, FILE.truth.yaml (the true corrections and `field_pose`) and FILE.truth.urdf."""
    config = robot.config.field_config("simulated field views need the field")
    check_outputs([out, *truth_paths(out)], force, inputs)
    rng = np.random.default_rng(options.seed)
    spec = TruthSpec(**{**asdict(options.truth), "offset_joints": offset_joints(robot, options.offsets)})
    truth = random_truth(robot, spec, rng)
    if options.truth_file is not None:
        truth = load_corrections(options.truth_file, key="truth")
    full = camera or load_camera_info(robot.config.intrinsics_file(HEAD_CAMERA, "simulating", "pass --intrinsics"))
    binning = options.binning or sim_binning(HEAD_CAMERA)
    image_camera = full.binned(binning, HEAD_CAMERA)
    if options.floor_check and config.check_at is None:
        raise WolfcalError(f"{robot.config.path}: --check places the robot at field.check_at: add it to 'field:' "
                           "(x, y [m], yaw [rad]; another place than robot_at)")  # fmt: skip
    at = config.check_at if options.floor_check else config.robot_at
    pose = np.asarray(at) + rng.uniform([-0.3, -0.3, -0.17], [0.3, 0.3, 0.17])
    views = field_views(robot, image_camera, truth, pose, config.dimensions, options.samples, rng)
    scene = cluttered_scene(config.dimensions, rng)
    rays = pixel_rays(image_camera)
    readings = encoder_readings(views.q_true, truth.offset_vector(robot.joint_names))
    with output_set(), CaptureWriter(out, robot.config, {HEAD_CAMERA: (full, (binning, binning))}) as w:
        for i, T in enumerate(views.T_field_camera):
            view = render_field_view(image_camera, T, config.dimensions, scene, rng, options.noise_sigma,
                                     float(rng.uniform(0.0, 2.0)), rays)  # fmt: skip
            w.add_sample(10**18 + i * 10**9, robot.joint_names, readings[i], np.zeros(len(readings[i])),
                         {HEAD_CAMERA: view.image})  # fmt: skip
            say(f"rendered field view {i + 1} of {len(views.T_field_camera)}")
        truth_yaml, truth_urdf = truth_paths(out)
        data = {"truth": truth.to_dict(), "field_pose": {"x": float(pose[0]), "y": float(pose[1]),
                                                         "yaw": float(pose[2])}}  # fmt: skip
        write_text_atomic(truth_yaml, dump_yaml(data, sort_keys=False))
        write_calibrated_urdf(robot.config.urdf, robot.model, truth, truth_urdf)
    say(f"wrote {out}, {truth_yaml}, {truth_urdf}")
    return truth
