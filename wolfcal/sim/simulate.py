"""`wolfcal simulate`: a capture file of a simulated robot with known ground truth.

Systems: `head` (the head camera sees the foot tags in random reachable poses), `external` (an external camera of the
robot config, on a tripod in front of the robot on its stand, sees the torso tag and the foot tags while the legs move:
`wolfcal.external_view`, placement `wolfcal.sim.placement`), `all` (both cameras in every sample). Writes FILE.mcap (the
capture format of DESIGN.md), FILE.truth.yaml (true corrections, cameras, settings, and the true pose of each external
camera under `external_cameras`) and FILE.truth.urdf (the robot as it really is: frame corrections folded into the
origins, encoder offsets as `<calibration rising>`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from wolfcal.atomic import output_set, write_text_atomic
from wolfcal.camera.camera_info import camera_info_dict, load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.capture.poses import find_poses, joint_limits, load_poses
from wolfcal.encoders import encoder_readings
from wolfcal.errors import WolfcalError
from wolfcal.external_view import external_pose_ok, external_visibility
from wolfcal.fit.systems import ALL, simulated_systems, system
from wolfcal.io.truth import external_truth_entry, truth_paths
from wolfcal.io.writer import CaptureWriter
from wolfcal.observations import HEAD_CAMERA
from wolfcal.outputs import check_outputs
from wolfcal.placement import placement_from_text
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.floor import FLOOR_NEEDED
from wolfcal.robot.ranges import sampling_bounds
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.sim.floor import floor_views, render_floor
from wolfcal.sim.mocap import simulate_mocap
from wolfcal.sim.placement import random_placement
from wolfcal.sim.poses import draw_accepted, random_visible_poses, tag_visibility
from wolfcal.sim.scene import SimScene, sim_binning
from wolfcal.sim.truth import TruthSpec, random_truth
from wolfcal.vision.render import motion_blur
from wolfcal.yamlfile import dump_yaml

OFFSET_SETS = ("none", "head", "legs", "all")
START_NS = 1_700_000_000_000_000_000
FLOOR_DISTANCE_M = (0.5, 5.0)  # floor tags lie this far from the robot (`--floor`)


@dataclass
class SimOptions:
    samples: int = 24
    seed: int = 0
    binning: int | None = 1  # of every camera's images; None: each simulated camera's default (`scene.sim_binning`)
    noise_sigma: float = 2.0  # image noise [gray levels]
    outlier_fraction: float = 0.0  # share of samples made outliers (motion blur or stale joint reading)
    offsets: str = "none"  # which joints get a true encoder offset: none | head | legs | all (head and legs)
    truth: TruthSpec = field(default_factory=TruthSpec)
    truth_file: Path | None = None  # reuse the truth of an earlier simulation (e.g. for a held-out capture)
    system: str = "head"  # head | external | all
    external: str | None = None  # which external camera of the config (default: the first)
    placement: str | None = None  # 'x,y,z,roll,pitch,yaw' of the external camera (default: random)
    poses: Path | None = None  # a poses file (`wolfcal plan`, `capture --poses`): its poses instead of random ones
    floor: bool = False  # floor samples: the robot stands and its head camera sees the config's floor tags
    floor_distance: tuple[float, float] = FLOOR_DISTANCE_M  # the floor tags lie this far from the robot [m]
    # the held-out capture: floor samples spread over `floor.check_stances`; field views from `field.check_at`
    floor_check: bool = False


@dataclass
class _SimCamera:
    model: CameraModel  # full resolution
    image: CameraModel  # binned
    binning: int  # sensor binning of the images (both axes)
    T_base_camera: np.ndarray | None = None  # external cameras only


def offset_joints(robot: Robot, which: str) -> tuple[str, ...]:
    """The joints that get a true encoder offset: none, head (base -> camera), legs (base -> foot tags), all."""
    if which not in OFFSET_SETS:
        raise WolfcalError(f"--offsets {which!r} must be one of {', '.join(OFFSET_SETS)}")
    head = robot.camera_and_leg_joints(sides=())
    everything = robot.camera_and_leg_joints()
    legs = tuple(j for j in everything if j not in head)
    return {"none": (), "head": head, "legs": legs, "all": everything}[which]


def _cameras(robot: Robot, options: SimOptions, head: CameraModel | None) -> dict[str, _SimCamera]:
    """The simulated cameras by name, without placements yet."""
    cameras: dict[str, _SimCamera] = {}
    if options.system in ("head", "all"):
        if head is None:
            head = load_camera_info(robot.config.intrinsics_file(HEAD_CAMERA, "simulating", "pass --intrinsics FILE"))
        binning = options.binning or sim_binning(HEAD_CAMERA)
        cameras[HEAD_CAMERA] = _SimCamera(head, head.binned(binning, HEAD_CAMERA), binning)
    if options.system in ("external", "all"):
        if not robot.config.external_cameras:
            raise WolfcalError(
                f"{robot.config.path}: --system {options.system} needs an external camera; add one under "
                "'external_cameras:' (name, image_topic, info_topic, intrinsics)"
            )
        name = options.external or robot.config.external_cameras[0].name
        model = load_camera_info(robot.config.intrinsics_file(name, "simulating"))
        binning = options.binning or sim_binning(name)
        cameras[name] = _SimCamera(model, model.binned(binning, name), binning)
    return cameras


def _poses(robot: Robot, options: SimOptions, cameras: dict[str, _SimCamera], truth: Corrections,
           rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """(S, J) true joint angles in which every simulated camera sees tags well (or those of the poses file)."""
    if options.poses is not None:  # the servos reach the commanded readings: true angle = reading + true offset
        return planned_readings(robot, options.poses) + truth.offset_vector(robot.joint_names)
    if options.system == "head":
        return random_visible_poses(robot, cameras[HEAD_CAMERA].image, truth, options.samples, rng)[0]
    name = next(n for n in cameras if n != HEAD_CAMERA)
    external = cameras[name]
    T_base_camera = external.T_base_camera
    if T_base_camera is None:
        raise WolfcalError(f"simulated external camera '{name}' has no placement")
    lo, hi = sampling_bounds(robot, "external")
    checks = [lambda q: external_pose_ok(robot, external_visibility(robot, external.image, T_base_camera,
                                                                    q, truth))]  # fmt: skip
    what = f"camera '{name}' sees the torso tag and a foot tag"
    if HEAD_CAMERA in cameras:
        head_lo, head_hi = sampling_bounds(robot, "head")
        for k, joint in enumerate(robot.joint_names):
            if joint in robot.camera_and_leg_joints(sides=()):  # the head camera's joints move as for head poses
                lo[k], hi[k] = head_lo[k], head_hi[k]
        head = cameras[HEAD_CAMERA].image
        margin, size = 0.03 * head.width, 0.02 * head.width
        checks.append(lambda q: np.any(tag_visibility(robot, head, q, truth, robot.config.tag_ids, margin, size), 1))
        what += " and the head camera sees a tag"
    return draw_accepted(lo, hi, options.samples, rng, lambda q: np.logical_and.reduce([c(q) for c in checks]), what)


def simulate_capture(
    robot_path: Path,
    out: Path,
    options: SimOptions,
    camera: CameraModel | None = None,
    say: Callable[[str], None] = print,
    force: bool = False,
) -> Corrections:
    """Simulate a capture; returns the true corrections (also written to FILE.truth.yaml). `camera` replaces the
    head camera's intrinsics (`--intrinsics`). The three files are written as one set; existing ones are replaced
    only with `force`."""
    if out.suffix != ".mcap":
        raise WolfcalError(f"{out}: the capture file name must end in .mcap")
    if options.samples < 1:
        raise WolfcalError("--samples must be at least 1")
    if options.system not in simulated_systems():
        raise WolfcalError(f"--system {options.system!r} must be one of {', '.join(simulated_systems())}")
    robot = load_robot(robot_path)
    if options.floor and (options.system != "head" or options.poses is not None):
        raise WolfcalError("--floor simulates the head camera's views of the floor tags: drop --system and --poses")
    if options.floor_check and not (options.floor or options.system == "field"):
        raise WolfcalError(
            "--check is the held-out floor capture: give it with --floor (or, for held-out field "
            "views at field.check_at, with --system field)"
        )
    if options.floor:
        if not robot.config.floor_config(FLOOR_NEEDED).tags:
            raise WolfcalError(f"{robot.config.path}: --floor needs floor tags: add 'floor.tags' (DESIGN.md)")
    if options.poses is not None:
        poses = find_poses(options.poses, robot_path)  # a bare name: the robot's own poses file
        options = replace(options, poses=poses, samples=len(planned_readings(robot, poses)))
    inputs = [robot.config.path, robot.config.urdf] + [p for p in (options.truth_file, options.poses) if p]
    simulator = simulate_cameras if options.system == ALL else system(options.system).load("simulator")
    return simulator(robot, out, options, camera, say, force, inputs)


def simulate_cameras(robot: Robot, out: Path, options: SimOptions, camera: CameraModel | None,
                     say: Callable[[str], None], force: bool, inputs: list[Path]) -> Corrections:  # fmt: skip
    """The head and external cameras' simulator (the registry's, `wolfcal.fit.systems`): a capture file of tag
    images; `inputs` may not be overwritten."""
    cameras = _cameras(robot, options, camera)
    check_outputs([out, *truth_paths(out)], force, inputs)
    with output_set():
        return _simulate(robot, out, options, cameras, say)


def simulate_mocap_session(robot: Robot, out: Path, options: SimOptions, camera: CameraModel | None,
                           say: Callable[[str], None], force: bool, inputs: list[Path]) -> Corrections:  # fmt: skip
    """The motion-capture simulator (`wolfcal.sim.mocap`): FILE.mcap with joint states and Markers, FILE.c3d."""
    check_outputs([out, out.with_suffix(".c3d"), *truth_paths(out)], force, inputs)
    spec = TruthSpec(**{**asdict(options.truth), "offset_joints": offset_joints(robot, options.offsets)})
    truth = random_truth(robot, spec, np.random.default_rng(options.seed))
    if options.truth_file is not None:
        truth = load_corrections(options.truth_file, key="truth")
    with output_set():
        simulate_mocap(robot, out, options.samples, options.seed + 1, truth, say=say)
    return truth


def _simulate(
    robot: Robot, out: Path, options: SimOptions, cameras: dict[str, _SimCamera], say: Callable[[str], None]
) -> Corrections:
    rng = np.random.default_rng(options.seed)
    spec = TruthSpec(**{**asdict(options.truth), "offset_joints": offset_joints(robot, options.offsets)})
    truth = random_truth(robot, spec, rng)
    if options.truth_file is not None:
        truth = load_corrections(options.truth_file, key="truth")
    for name, sim_camera in cameras.items():
        if name != HEAD_CAMERA:
            placement = options.placement
            sim_camera.T_base_camera = placement_from_text(placement) if placement else random_placement(rng)
    floor = None
    if options.floor:  # the robot stands; the floor tags lie 0.5-5 m away (options.floor_distance)
        head = cameras[HEAD_CAMERA].image
        floor = floor_views(robot, head, truth, options.samples, rng, options.floor_distance, 0.01 * head.width,
                            0.01 * head.width, options.floor_check)  # fmt: skip
        q_true = floor.q_true
    else:
        q_true = _poses(robot, options, cameras, truth, rng)
    offsets = truth.offset_vector(robot.joint_names)
    q_measured = encoder_readings(q_true, offsets)
    n_out = int(round(options.outlier_fraction * options.samples))
    outlier_index = rng.choice(options.samples, size=n_out, replace=False) if n_out else np.array([], int)
    kinds = {int(i): ("motion_blur" if k % 2 == 0 else "stale_joints") for k, i in enumerate(outlier_index)}
    moving = [robot.model.column(j) for j in robot.camera_and_leg_joints()]
    scenes = {
        name: SimScene(robot, truth, c.image, seed=options.seed + 1 + k, noise_sigma=options.noise_sigma,
                       T_base_camera=c.T_base_camera)
        for k, (name, c) in enumerate(cameras.items())
    }  # fmt: skip
    streams = {name: (c.model, (c.binning, c.binning)) for name, c in cameras.items()}
    with CaptureWriter(out, robot.config, streams) as writer:
        for i in range(options.samples):
            if floor is None:
                images = {name: scene.render_true(q_true[i]) for name, scene in scenes.items()}
            else:
                images = {HEAD_CAMERA: render_floor(robot, cameras[HEAD_CAMERA].image, floor, i, options.noise_sigma,
                                                    scenes[HEAD_CAMERA].rng)}  # fmt: skip
            reading = q_measured[i].copy()
            if kinds.get(i) == "motion_blur":
                length, angle = rng.uniform(0.008, 0.015), rng.uniform(0, np.pi)
                images = {n: motion_blur(im, length * im.shape[1], angle) for n, im in images.items()}
            elif kinds.get(i) == "stale_joints":
                reading[moving] += rng.normal(0.0, 0.04, len(moving))
            stamp = START_NS + i * 2_000_000_000
            writer.add_sample(stamp, robot.joint_names, reading, np.zeros_like(reading), images)
            floor_ids = robot.config.floor_config().tag_ids if floor is not None else []
            seen = (
                _seen(robot, scenes, q_true[i])
                if floor is None
                else ["floor tags " + ", ".join(str(t) for t, v in zip(floor_ids, floor.visible[i]) if v)]
            )
            say(f"sample {i + 1}/{options.samples}: " + "; ".join(seen)
                + (f" ({kinds[i]})" if i in kinds else ""))  # fmt: skip
    _write_truth(robot, out, options, truth, cameras, kinds, floor.places if floor is not None else None)
    say(f"wrote {out}, {truth_paths(out)[0]}, {truth_paths(out)[1]}")
    return truth


def _seen(robot: Robot, scenes: dict[str, SimScene], q_true: np.ndarray) -> list[str]:
    """'<camera>: tags a, b' per camera, the tags well in view at true angles q_true (J,)."""
    lines = []
    for name, scene in scenes.items():
        if scene.T_base_camera is None:
            visible = tag_visibility(robot, scene.camera, q_true[None], scene.truth, robot.config.tag_ids,
                                     0.03 * scene.camera.width, 0.02 * scene.camera.width)[0]  # fmt: skip
        else:
            visible = external_visibility(robot, scene.camera, scene.T_base_camera, q_true[None], scene.truth)[0]
        lines.append(f"{name}: tags " + (", ".join(str(t) for t, v in zip(robot.config.tag_ids, visible) if v)
                                         or "none"))  # fmt: skip
    return lines


def _write_truth(robot: Robot, out: Path, options: SimOptions, truth: Corrections, cameras: dict[str, _SimCamera],
                 kinds: dict[int, str], floor_places: dict[int, np.ndarray] | None = None) -> None:  # fmt: skip
    """FILE.truth.yaml and FILE.truth.urdf beside the capture (with `floor_tags`: each floor tag's true place
    x, y [m], yaw [rad] in the true floor frame)."""
    truth_yaml, truth_urdf = truth_paths(out)
    data: dict[str, object] = {"truth": truth.to_dict()}
    if HEAD_CAMERA in cameras:
        data["camera"] = camera_info_dict(cameras[HEAD_CAMERA].model)
    binnings = {name: c.binning for name, c in cameras.items()}
    data |= {
        "binning": next(iter(binnings.values())) if len(binnings) == 1 else binnings,
        "samples": options.samples,
        "seed": options.seed,
        "noise_sigma": options.noise_sigma,
        "outliers": {int(k): v for k, v in sorted(kinds.items())},
        "meaning": "offsets: q_true = q_measured + offset [rad]; frames/tags: origin_new = origin * "
        "Trans(x,y,z) * Exp(rx,ry,rz) [m, rad]",
        "system": options.system,
    }
    external = {n: (c.T_base_camera, c.model) for n, c in cameras.items() if c.T_base_camera is not None}
    if external:
        data["external_cameras"] = {
            n: {**external_truth_entry(T_base_camera), "camera": camera_info_dict(model)}
            for n, (T_base_camera, model) in external.items()
        }
    if floor_places is not None:
        data["floor_tags"] = {int(t): {"x": float(p[0]), "y": float(p[1]), "yaw": float(p[2])}
                              for t, p in floor_places.items()}  # fmt: skip
    write_text_atomic(truth_yaml, dump_yaml(data, sort_keys=False))
    write_calibrated_urdf(robot.config.urdf, robot.model, truth, truth_urdf)


def planned_readings(robot: Robot, path: Path) -> np.ndarray:
    """(S, J) joint readings [rad] of a poses file, checked as `capture --poses` checks it: each joint at its
    latest target, joints never named at the rest pose (`rest_pose:`, others 0)."""
    script = load_poses(path, joint_limits(robot, robot.joint_names))
    return script.readings(robot.joint_names, robot.config.planning.rest_pose)
