"""`wolfcal fit`: captures -> observations -> problem -> solution -> result.yaml + calibrated.urdf."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from wolfcal.atomic import output_set
from wolfcal.camera.camera_info import load_camera_info
from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block
from wolfcal.fit.camera_block import CameraBlock, placements
from wolfcal.fit.floor_block import FloorBlock, SoleClosure, check_floor_samples
from wolfcal.fit.mocap_block import MOCAP_NOISE_START_M, MocapBlock
from wolfcal.fit.options import FitOptions
from wolfcal.fit.problem import Problem
from wolfcal.fit.result import FitResult, explain, fit_result, summary_lines, write_result
from wolfcal.fit.solver import MIN_SIGMA, Solution, solve
from wolfcal.io.reader import read_capture, require_cameras
from wolfcal.io.samples import Capture, Sample
from wolfcal.leftout import check_left_out
from wolfcal.markers import MarkerObservations
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.outputs import check_output_folder
from wolfcal.progress import Progress
from wolfcal.robot.config_writer import write_calibrated_config
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet, build_parameter_set, tags_for_preset
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.vision.observe import detect_observations
from wolfcal.yamlfile import load_yaml

SOLE_NOISE_M = 1e-3  # starting noise of the sole closure [m], before it is estimated


@dataclass
class Fit:
    """A solved fit: the measurement blocks and their observations, the unknowns and the solution."""

    robot: Robot
    observations: dict[str, Observations]  # per camera, only the tags used
    blocks: list[Block]  # the measurement blocks (camera, floor, sole closure, motion capture)
    chain: ParameterSet  # the robot-model parameters (the first len(chain) unknowns)
    problem: Problem
    solution: Solution

    @property
    def params(self) -> ParameterSet:
        """Every unknown: the chain parameters, then each block's own (e.g. external camera poses)."""
        return self.problem.params

    @property
    def tag_ids(self) -> list[int]:
        """The ids of the tags on links that the fit's blocks observe (floor tags not included)."""
        return sorted({t for b in self.blocks if b.system != "floor" for t in getattr(b, "tag_ids", ())})

    @property
    def corrections(self) -> Corrections:
        """The fitted corrections of the robot model (offsets [rad], frame and tag-mount vectors [m, rad])."""
        return self.chain.corrections(self.solution.values[: len(self.chain)])


def in_system(camera: str, system: str | None) -> bool:
    """Whether a camera belongs to a --system: head -> the head camera, external -> any other; all (or no
    choice) -> every camera."""
    return system in (None, "all") or (system == "head") == (camera == HEAD_CAMERA)


def _systems(robot: Robot, observations: dict[str, Observations], options: FitOptions) -> dict[str, Observations]:
    """The cameras the fit uses, by --system (default: every one the captures contain)."""
    system = options.system or "all"
    chosen = {name: obs for name, obs in observations.items() if in_system(name, system)}
    if not chosen:
        found = ", ".join(sorted(observations)) or "none"
        raise WolfcalError(f"--system {system}: the captures hold no such camera's tag views (cameras found: {found})")
    if options.free in ("camera", "head_camera"):
        robot.config.head_camera()  # a clear error when the robot config has no head camera
    if options.free in ("camera", "head_camera") and HEAD_CAMERA not in chosen:
        raise WolfcalError(
            f"--free {options.free} estimates the head camera, but the captures used (--system {system}) hold no "
            "head-camera images; use --free leg for an external camera, or add a head-camera capture"
        )
    return chosen


def fit_observations(
    robot: Robot,
    observations: dict[str, Observations] | Observations,
    options: FitOptions,
    say: Callable[[str], None] | None = None,
    markers: MarkerObservations | None = None,
) -> Fit:
    """Choose the free parameters for the observed tags of each camera and the measured markers, check there is
    enough data, solve."""
    if isinstance(observations, Observations):
        observations = {observations.camera_name: observations}
    mocap = mocap_block(robot, markers, options)
    if options.system == "mocap" or (mocap is not None and not observations):
        observations = {}
    else:
        observations = _systems(robot, observations, options)
    observations, floor = split_floor(robot, observations)
    used = _tags_used(robot, observations, options)
    if not used and mocap is None and floor is None:
        raise WolfcalError(
            f"no tag of the {options.side} side was detected; the leg preset with --side {options.side} needs one"
        )
    camera_blocks = _camera_blocks(robot, used, options)
    blocks: list[Block] = [*camera_blocks]
    tags_by_camera = {b.camera_name: b.tag_ids for b in camera_blocks}
    if floor is not None:
        tags_by_camera.setdefault(HEAD_CAMERA, [])
        blocks += floor_blocks(robot, floor, options)
    chain = build_parameter_set(
        robot, options.free, tags_by_camera, options.side, options.fix_tags,
        tuple(mocap.links) if mocap is not None else (),
    )
    blocks += [mocap] if mocap is not None else []
    _check_enough_data(blocks, len(chain), options.free)
    problem = Problem(chain, blocks, block_sigmas(robot, blocks), robot.config.priors.encoder_noise, options.huber_k)
    solution = solve(problem, progress=say, min_sigma={**MIN_SIGMA, "px": options.noise_floor_px})
    return Fit(robot, used, blocks, chain, problem, solution)


def floor_blocks(robot: Robot, floor: Observations, options: FitOptions) -> list[Block]:
    """The blocks of the floor samples, checked (`check_floor_samples`): the floor tags' corners and, with two
    soles, the sole closure."""
    check_floor_samples(robot, floor)
    floor_block = FloorBlock(robot, floor)
    floor_block.outlier_rule = options.outlier
    return [floor_block, SoleClosure(robot, floor)] if len(robot.config.floor_config().soles) == 2 else [floor_block]


def block_sigmas(robot: Robot, blocks: Sequence[Block]) -> list[float]:
    """The noise level each block starts from before the solver estimates it (px: the config's pixel noise; motion
    capture and the sole closure [m]): the fit's and pose planning's whitening."""
    pixel = robot.config.priors.pixel_noise
    return [pixel if b.unit == "px" else MOCAP_NOISE_START_M if b.system == "mocap" else SOLE_NOISE_M for b in blocks]


def _tags_used(
    robot: Robot, observations: dict[str, Observations], options: FitOptions
) -> dict[str, Observations]:
    """Per camera, the observations of the tags the preset uses (cameras without one left out); an external camera
    also keeps the tags fixed to the base, on which its pose rests."""
    used: dict[str, Observations] = {}
    for name, obs in observations.items():
        tag_ids = tags_for_preset(robot, options.free, obs.observed_tag_ids, options.side)
        if name != HEAD_CAMERA:
            tag_ids = sorted(set(tag_ids) | {t for t in obs.observed_tag_ids
                                             if robot.fixed_to_base(robot.config.tag(t).link)})
        if tag_ids:
            used[name] = obs if set(tag_ids) == set(obs.observed_tag_ids) else obs.only_tags(tag_ids)
    return used


def _camera_blocks(robot: Robot, used: dict[str, Observations], options: FitOptions) -> list[CameraBlock]:
    """One camera block per camera: the head camera's, or an external camera's with its placement unknowns."""
    camera_blocks: list[CameraBlock] = []
    for name, obs in used.items():
        if name == HEAD_CAMERA:
            block = CameraBlock(robot, obs, obs.observed_tag_ids)
        else:
            placement, names = placements(obs, options.external_moving)
            block = CameraBlock(robot, obs, obs.observed_tag_ids, True, placement, names)
        block.outlier_rule = options.outlier
        camera_blocks.append(block)
    return camera_blocks


def _check_enough_data(blocks: list[Block], n_chain: int, preset: str) -> None:
    """Refuse a fit with fewer than twice as many measured numbers as unknowns (chain and nuisance)."""
    n_params = n_chain + sum(len(b.nuisance) for b in blocks)
    n_numbers = sum(b.n_units * b.dim for b in blocks)
    if n_numbers < 2 * n_params:
        n_samples = sum(len(b.q_measured) for b in blocks)
        needed = max(3, int(np.ceil(n_samples * 2 * n_params / max(n_numbers, 1))))
        raise WolfcalError(
            f"too few samples for the free parameters: {n_samples} sample(s) with tags or markers give {n_numbers} "
            f"measured numbers for {n_params} unknowns (--free {preset}); capture at least {needed}, or free "
            "fewer parameters"
        )


def mocap_block(robot: Robot, markers: MarkerObservations | None, options: FitOptions) -> MocapBlock | None:
    """The motion-capture block when --system takes it (mocap, all, or none given) and markers were measured;
    with the leg preset and one --side, the markers of the other leg are left out."""
    if options.system not in (None, "all", "mocap"):
        return None
    if markers is None:
        if options.system == "mocap":
            raise WolfcalError("--system mocap: no marker data; give a ROS 2 recording with the robot config's "
                               "markers topic, or a motion-capture file with --mocap FILE")
        return None
    if options.free in ("camera", "head_camera") and options.system == "mocap":
        raise WolfcalError(f"--free {options.free} estimates the head camera, which motion capture cannot see "
                           "(no marker on the camera's optical frame); use --free leg with --system mocap")
    if options.free == "leg" and options.side != "both":
        config = robot.config.marker_config()
        markers = markers.only_markers([n for n in markers.marker_names
                                        if config.marker(n).side in (options.side, None)])  # fmt: skip
    return MocapBlock(robot, markers, options.mocap_moving)


def split_floor(
    robot: Robot, observations: dict[str, Observations]
) -> tuple[dict[str, Observations], Observations | None]:
    """The head camera's views of floor tags (config `floor.tags`) apart from its views of tags on links."""
    head = observations.get(HEAD_CAMERA)
    if head is None or robot.config.floor is None:
        return observations, None
    floor_ids = [t for t in head.observed_tag_ids if t in robot.config.floor.tag_ids]
    if not floor_ids:
        return observations, None
    rest = {k: v for k, v in observations.items() if k != HEAD_CAMERA}
    link_ids = [t for t in head.observed_tag_ids if t not in floor_ids]
    if link_ids:
        rest[HEAD_CAMERA] = head.only_tags(link_ids)
    return rest, head.only_tags(floor_ids)


def load_captures(
    robot: Robot, captures: list[Path], intrinsics: Path | None, say: Callable[[str], None] | None = None
) -> list[Capture]:
    """The captures read; one whose attached robot config names another robot is refused. `say` gets progress
    lines while long files are read."""
    camera = load_camera_info(intrinsics) if intrinsics else None
    progress = (lambda path: Progress(say, f"reading {Path(path).name}", "messages")) if say else (lambda path: None)
    loaded = [read_capture(path, robot.config, camera, progress(path)) for path in captures]
    try:
        own_text: str | None = robot.config.path.read_text(encoding="utf-8", errors="replace")  # as attachments
    except OSError:
        own_text = None
    for capture in loaded:
        # the robot's own config attached (a capture of this robot with this config): its name, without parsing
        same = own_text is not None and capture.robot_config_text == own_text
        name = robot.config.name if same else attached_robot_name(capture.robot_config_text)
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


FIT_OUTPUTS = ("result.yaml", "calibrated.urdf", "calibrated_robot.yaml")


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


def check_solution_left_out(fit: Fit, captures: list[Path]) -> None:
    """The outlier rule must not absorb unusable data: WolfcalError when more than MAX_LEFT_OUT of a measurement
    system's samples or tag views, or of the single units of a block with a unit rule (the floor's corners), were
    left out as outliers."""
    counts = {}
    for block, result, state in zip(fit.blocks, fit.solution.blocks, fit.problem.states):
        counts[f"{block.name} samples"] = (int(result.outlier_samples.sum()), len(block.q_measured))
        counts[f"{block.name} tag views"] = (len(result.outlier_views), block.n_views)
        if block.unit_rule is not None:
            counts[f"{block.name} single corners"] = (int(state.excluded_units.sum()), block.n_units)
    check_left_out(
        counts,
        ", ".join(map(str, captures)),
        "the data do not fit the model: check the joint readings, the tags' ids, sizes and links in the robot "
        "config, and the camera intrinsics (--intrinsics)",
    )


def run_fit(
    captures: list[Path],
    robot_path: Path,
    out_dir: Path,
    options: FitOptions,
    intrinsics: Path | None = None,
    say: Callable[[str], None] = print,
    force: bool = False,
    mocap: Sequence[Path] = (),
    mocap_offsets: Sequence[float] = (),
) -> FitResult:
    """The whole `wolfcal fit` job; returns the result that was written to out_dir/result.yaml.
    Existing outputs in out_dir are replaced only with `force`; the outputs are written as one set. Motion capture
    (--system mocap or all, or --mocap files): markers from the captures' Markers topic, or from the `mocap` files
    (one per capture, clock offsets `mocap_offsets` [s] or estimated)."""
    robot = load_robot(robot_path)
    check_output_folder(out_dir, FIT_OUTPUTS, force, fit_inputs(robot, captures, mocap, intrinsics))
    markers: MarkerObservations | None = None
    warnings: list[str] = []
    if options.system == "mocap" or mocap:
        markers, warnings = read_markers(robot, captures, mocap, mocap_offsets, say)
    observations: dict[str, Observations] = {}
    if options.system != "mocap":
        observations, camera_warnings = detect_captures(robot, captures, intrinsics, options, say)
        warnings += camera_warnings
    for name, obs in observations.items():
        say(f"{name} camera: {obs.n_samples} sample(s) with tags, {len(obs.uv)} corners")
    say(f"fitting --free {options.free} ...")
    fit = fit_observations(robot, observations, options, say, markers)
    check_solution_left_out(fit, captures)
    result = fit_result(fit, options, captures, intrinsics, warnings)
    write_fit(out_dir, fit, result)
    report_fit(result, fit, warnings, out_dir, say)
    return result


def fit_inputs(
    robot: Robot, captures: Sequence[Path], mocap: Sequence[Path], intrinsics: Path | None
) -> list[Path]:
    """Every file a fit reads (captures, motion-capture files, robot config and URDF, intrinsics): none of them may
    be an output (`check_output_folder`)."""
    return [*captures, *mocap, robot.config.path, robot.config.urdf] + ([intrinsics] if intrinsics else [])


def read_markers(
    robot: Robot, captures: list[Path], mocap: Sequence[Path], mocap_offsets: Sequence[float],
    say: Callable[[str], None],
) -> tuple[MarkerObservations, list[str]]:
    """The still samples' marker positions (motion-capture frame [m]) from the captures' Markers topic or the
    `mocap` files (clock offsets `mocap_offsets` [s], or estimated), and a warning for marker labels the robot
    config does not list."""
    from wolfcal.io.mocap_load import load_marker_observations  # here: a camera fit does not load the mocap readers

    markers = load_marker_observations(robot.config, robot.joint_names, captures, list(mocap), list(mocap_offsets))
    say(f"motion capture: {markers.n_samples} still sample(s), {len(markers.xyz)} marker positions"
        + "".join(f"; {Path(k).name}: clock offset {v:.4f} s" for k, v in markers.clock_offsets_s.items()))
    warnings = [f"marker labels not in the robot config, ignored: {', '.join(markers.unknown_names)}"
                ] if markers.unknown_names else []  # fmt: skip
    return markers, warnings


def detect_captures(
    robot: Robot, captures: list[Path], intrinsics: Path | None, options: FitOptions, say: Callable[[str], None]
) -> tuple[dict[str, Observations], list[str]]:
    """The captures read and their tags detected in the images of the cameras --system takes: per camera, the
    detected tag corners [px] with the joint readings of their samples; and the warnings of reading and detection
    (frames skipped, repeated images)."""
    required = (HEAD_CAMERA,) if options.system == "head" else ()
    samples, warnings = load_samples(robot, captures, intrinsics, cameras=required, say=say)
    say(f"read {len(samples)} sample(s) from {len(captures)} capture file(s); detecting tags ...")
    names = dict.fromkeys([HEAD_CAMERA, *robot.config.camera_names])
    wanted = None if options.system in (None, "all") else [n for n in names if in_system(n, options.system)]
    observations, detect_warnings = detect_observations(
        samples, robot, progress=Progress(say, "detecting tags", "samples"), cameras=wanted
    )
    warnings += detect_warnings + repeat_warnings(observations, options.noise_floor_px)
    return observations, warnings


def write_fit(out_dir: Path, fit: Fit, result: FitResult) -> None:
    """The fit's outputs (FIT_OUTPUTS), written as one set: result.yaml, the URDF with the fitted corrections
    (`Corrections`: encoder offsets [rad], joint-frame corrections [m, rad]) and the robot config with the fitted
    tag mounts (T_link_tag [m, rad])."""
    urdf = fit.robot.config.urdf
    with output_set():
        write_result(out_dir / "result.yaml", result)
        write_calibrated_urdf(urdf, fit.robot.model, fit.corrections, out_dir / "calibrated.urdf")
        write_calibrated_config(fit.robot, fit.corrections, out_dir / "calibrated_robot.yaml")


def report_fit(
    result: FitResult, fit: Fit, warnings: list[str], out_dir: Path, say: Callable[[str], None]
) -> None:
    """Tell the user what was fitted: the summary, notes on what the data cannot tell apart, the warnings, and
    where the outputs are."""
    for line in summary_lines(result):
        say(line)
    for line in explain(fit.params, fit.solution):
        say(f"note: {line}")
    for line in warnings:
        say(f"warning: {line}")
    say(f"wrote {out_dir / 'result.yaml'}, {out_dir / 'calibrated.urdf'} and {out_dir / 'calibrated_robot.yaml'}")
