"""`wolfcal fit`: captures -> observations -> problem -> solution -> result.yaml + calibrated.urdf."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

from wolfcal.atomic import output_set
from wolfcal.camera.camera_info import load_camera_info
from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block
from wolfcal.fit.camera_axes import check_camera_axes
from wolfcal.fit.camera_block import CameraBlock, placements
from wolfcal.fit.floor_block import FloorBlock, SoleClosure, check_floor_samples
from wolfcal.fit.jackknife import spread_checked
from wolfcal.fit.mocap_block import MocapBlock
from wolfcal.fit.options import FitOptions
from wolfcal.fit.problem import Problem
from wolfcal.fit.result import FitResult, explain, fit_result, summary_lines, write_result
from wolfcal.fit.solved import Fit
from wolfcal.fit.solver import solve
from wolfcal.fit.systems import ALL, load_attribute, own_file_systems, system_presets
from wolfcal.io.current import current_files, load_current
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
from wolfcal.spans import sample_count, still_span_observations
from wolfcal.vision.observe import detect_observations
from wolfcal.yamlfile import load_yaml

CAMERA_SYSTEMS = (None, ALL, "head", "external")  # --system choices whose fit uses the cameras' tag views


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
    if options.chain_preset in ("camera", "head_camera"):
        robot.config.head_camera()  # a clear error when the robot config has no head camera
    if options.chain_preset in ("camera", "head_camera") and HEAD_CAMERA not in chosen:
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
    own_blocks: Sequence[Block] = (),
) -> Fit:
    """Choose the free parameters for the observed tags of each camera, the measured markers and the blocks of
    systems that read their own files (`own_file_blocks`), check there is enough data, solve."""
    if isinstance(observations, Observations):
        observations = {observations.camera_name: observations}
    mocap = mocap_block(robot, markers, options) if options.chain_preset is not None else None
    if (
        options.system not in CAMERA_SYSTEMS
        or options.chain_preset is None
        or (not observations and (mocap is not None or own_blocks))
    ):
        observations = {}  # no camera in the fit: --system names another, or no camera parameter is free
    else:
        observations = _systems(robot, observations, options)
    observations, floor = split_floor(robot, observations)
    if HEAD_CAMERA in observations:
        check_camera_axes(robot, observations[HEAD_CAMERA])
    used = _tags_used(robot, observations, options)
    if not used and mocap is None and floor is None and not own_blocks:
        raise WolfcalError(
            f"no tag of the {options.side} side was detected; the leg preset with --side {options.side} needs one"
        )
    tags_by_camera = {name: list(obs.observed_tag_ids) for name, obs in used.items()}
    if floor is not None:
        tags_by_camera.setdefault(HEAD_CAMERA, [])
    for own in own_blocks:  # a system of its own that sees with a camera (field lines) frees that camera's mount
        camera_name = getattr(own, "camera_name", None)
        if camera_name:
            tags_by_camera.setdefault(camera_name, [])
    chain = chain_parameters(robot, options, tags_by_camera, tuple(mocap.links) if mocap is not None else ())
    current = options.current or Corrections()
    chain, held = chain.centred_on(current), chain.held(current)
    blocks: list[Block] = [*_camera_blocks(robot, used, options, held)]
    if floor is not None:
        blocks += floor_blocks(robot, floor, options, held)
    if mocap is not None:
        mocap.fixed = held  # its starting base poses came from the nominal model
        blocks.append(mocap)
    blocks += list(own_blocks)
    _check_enough_data(blocks, len(chain), options.free)
    sigmas = block_sigmas(robot, blocks)
    problem = Problem(chain, blocks, sigmas, robot.config.priors.encoder_noise, options.huber_k)
    solution, _ = spread_checked(problem, solve(problem, progress=say), sigmas, say)  # blocks that ask for it
    return Fit(robot, used, blocks, chain, problem, solution, held)


def chain_parameters(
    robot: Robot, options: FitOptions, tags_by_camera: dict[str, list[int]], marker_links: tuple[str, ...] = ()
) -> ParameterSet:
    """The free robot-model parameters of the --free presets: the robot model's preset (camera | head_camera |
    leg, `build_parameter_set`) for the tags each camera uses and the markers' links, then each measurement
    system's preset (`System.presets`, e.g. imu: the IMU's mount)."""
    chain = ParameterSet([])
    if options.chain_preset is not None:
        chain = build_parameter_set(robot, options.chain_preset, tags_by_camera, options.side, options.fix_tags,
                                    marker_links)  # fmt: skip
    extra = system_presets()
    for preset in options.presets:
        if preset in extra:
            chain = chain + ParameterSet(load_attribute(extra[preset], f"--free {preset} parameters")(robot))
    return chain


def own_file_blocks(
    robot: Robot, captures: Sequence[Path], options: FitOptions, say: Callable[[str], None]
) -> tuple[list[Block], set[Path]]:
    """The blocks of the registered systems that read their own files (`System.fit_blocks`) and --system takes,
    and the captures they used alone (no camera reads those)."""
    blocks: list[Block] = []
    used: set[Path] = set()
    for entry in own_file_systems():
        if options.system in (None, ALL, entry.name):
            built, paths = entry.load("fit_blocks")(robot, list(captures), options, say)
            blocks += built
            used |= {Path(p) for p in paths}
    return blocks, used


def floor_blocks(
    robot: Robot, floor: Observations, options: FitOptions, held: Corrections | None = None
) -> list[Block]:
    """The blocks of the floor samples, checked (`check_floor_samples`): the floor tags' corners and, with two
    soles, the sole closure; `held`: corrections held fixed under the free parameters."""
    check_floor_samples(robot, floor)
    floor_block = FloorBlock(robot, floor, held)
    floor_block.outlier_rule, floor_block.noise_min = options.outlier, options.noise_floor_px
    two_soles = len(robot.config.floor_config().soles) == 2
    return [floor_block, SoleClosure(robot, floor, held)] if two_soles else [floor_block]


def block_sigmas(robot: Robot, blocks: Sequence[Block]) -> list[float]:
    """The noise level each block starts from before the solver estimates it (`Block.start_noise`): the fit's and
    pose planning's whitening."""
    return [b.start_noise(robot.config.priors) for b in blocks]


def _tags_used(robot: Robot, observations: dict[str, Observations], options: FitOptions) -> dict[str, Observations]:
    """Per camera, the observations of the tags the preset uses (cameras without one left out); an external camera
    also keeps the tags on links the legs do not move, on which its pose rests."""
    used: dict[str, Observations] = {}
    for name, obs in observations.items():
        tag_ids = tags_for_preset(robot, options.chain_preset or "camera", obs.observed_tag_ids, options.side)
        if name != HEAD_CAMERA:
            tag_ids = sorted(
                set(tag_ids) | {t for t in obs.observed_tag_ids if robot.off_the_legs(robot.config.tag(t).link)}
            )
        if tag_ids:
            used[name] = obs if set(tag_ids) == set(obs.observed_tag_ids) else obs.only_tags(tag_ids)
    return used


def _camera_blocks(
    robot: Robot, used: dict[str, Observations], options: FitOptions, held: Corrections
) -> list[CameraBlock]:
    """One camera block per camera: the head camera's, or an external camera's with its placement unknowns;
    `held`: corrections held fixed under the free parameters."""
    camera_blocks: list[CameraBlock] = []
    for name, obs in used.items():
        if name == HEAD_CAMERA:
            block = CameraBlock(robot, obs, obs.observed_tag_ids, fixed=held)
        else:
            placement, names = placements(obs, options.external_moving)
            block = CameraBlock(robot, obs, obs.observed_tag_ids, True, placement, names, held)
        block.outlier_rule, block.noise_min = options.outlier, options.noise_floor_px
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
            raise WolfcalError(
                "--system mocap: no marker data; give a ROS 2 recording with the robot config's "
                "markers topic, or a motion-capture file with --mocap FILE"
            )
        return None
    if options.chain_preset in ("camera", "head_camera") and options.system == "mocap":
        raise WolfcalError(
            f"--free {options.free} estimates the head camera, which motion capture cannot see "
            "(no marker on the camera's optical frame); use --free leg with --system mocap"
        )
    if options.chain_preset == "leg" and options.side != "both":
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
    robot: Robot,
    captures: list[Path],
    intrinsics: Path | None,
    cameras: tuple[str, ...] = (HEAD_CAMERA,),
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
    current: Sequence[Path] = (),
) -> FitResult:
    """The whole `wolfcal fit` job; returns the result that was written to out_dir/result.yaml.
    Existing outputs in out_dir are replaced only with `force`; the outputs are written as one set. Motion capture
    (--system mocap or all, or --mocap files): markers from the captures' Markers topic, or from the `mocap` files
    (one per capture, clock offsets `mocap_offsets` [s] or estimated). `current`: the robot's present calibration
    (`io.current.load_current`): the fit starts from it and its result holds the new totals."""
    robot = load_robot(robot_path)
    inputs = fit_inputs(robot, captures, mocap, intrinsics) + current_files(list(current))
    check_output_folder(out_dir, FIT_OUTPUTS, force, inputs)
    present = load_current(list(current), robot) if current else None
    if present is not None:
        options = replace(options, current=present.corrections)
        say(f"starting from the present calibration in {', '.join(present.sources)}")
    markers: MarkerObservations | None = None
    warnings: list[str] = []
    if options.system == "mocap" or mocap:
        markers, warnings = read_markers(robot, captures, mocap, mocap_offsets, say)
    own, own_captures = own_file_blocks(robot, captures, options, say)
    camera_captures = [c for c in captures if Path(c) not in own_captures]
    observations: dict[str, Observations] = {}
    if options.system in CAMERA_SYSTEMS and options.chain_preset is not None and camera_captures:
        observations, camera_warnings = detect_captures(robot, camera_captures, intrinsics, options, say)
        warnings += camera_warnings
    for name, obs in observations.items():
        say(f"{name} camera: {sample_count(obs)} with tags, {len(obs.uv)} corners")
    say(f"fitting --free {options.free} ...")
    fit = fit_observations(robot, observations, options, say, markers, own)
    check_solution_left_out(fit, captures)
    result = fit_result(fit, options, captures, intrinsics, warnings, present)
    write_fit(out_dir, fit, result)
    report_fit(result, fit, warnings, out_dir, say)
    return result


def fit_inputs(robot: Robot, captures: Sequence[Path], mocap: Sequence[Path], intrinsics: Path | None) -> list[Path]:
    """Every file a fit reads (captures, motion-capture files, robot config and URDF, intrinsics): none of them may
    be an output (`check_output_folder`)."""
    return [*captures, *mocap, robot.config.path, robot.config.urdf] + ([intrinsics] if intrinsics else [])


def read_markers(
    robot: Robot,
    captures: list[Path],
    mocap: Sequence[Path],
    mocap_offsets: Sequence[float],
    say: Callable[[str], None],
) -> tuple[MarkerObservations, list[str]]:
    """The still samples' marker positions (motion-capture frame [m]) from the captures' Markers topic or the
    `mocap` files (clock offsets `mocap_offsets` [s], or estimated), and a warning for marker labels the robot
    config does not list."""
    from wolfcal.io.mocap_load import load_marker_observations  # here: a camera fit does not load the mocap readers

    markers = load_marker_observations(robot.config, robot.joint_names, captures, list(mocap), list(mocap_offsets))
    say(
        f"motion capture: {markers.n_samples} still sample(s), {len(markers.xyz)} marker positions"
        + "".join(f"; {Path(k).name}: clock offset {v:.4f} s" for k, v in markers.clock_offsets_s.items())
    )
    warnings = [f"marker labels not in the robot config, ignored: {', '.join(markers.unknown_names)}"
                ] if markers.unknown_names else []  # fmt: skip
    return markers, warnings


def detect_captures(
    robot: Robot, captures: list[Path], intrinsics: Path | None, options: FitOptions, say: Callable[[str], None]
) -> tuple[dict[str, Observations], list[str]]:
    """The captures read and their tags detected in the images of the cameras --system takes: per camera, the
    detected tag corners [px] with the joint readings of their samples, a recording's frames averaged per still span
    (`still_span_observations`); and the warnings of reading and detection (frames skipped, repeated images)."""
    required = (HEAD_CAMERA,) if options.system == "head" else ()
    samples, warnings = load_samples(robot, captures, intrinsics, cameras=required, say=say)
    say(f"read {len(samples)} sample(s) from {len(captures)} capture file(s); detecting tags ...")
    names = dict.fromkeys([HEAD_CAMERA, *robot.config.camera_names])
    wanted = None if options.system in (None, "all") else [n for n in names if in_system(n, options.system)]
    observations, detect_warnings = detect_observations(
        samples, robot, progress=Progress(say, "detecting tags", "samples"), cameras=wanted
    )
    warnings += detect_warnings + repeat_warnings(observations, options.noise_floor_px)
    return still_span_observations(robot.config, observations, options.external_moving), warnings


def write_fit(out_dir: Path, fit: Fit, result: FitResult) -> None:
    """The fit's outputs (FIT_OUTPUTS), written as one set: result.yaml, the URDF with the fitted corrections
    (`Corrections`: encoder offsets [rad], joint-frame corrections [m, rad]) and the robot config with the fitted
    tag mounts (T_link_tag [m, rad])."""
    urdf = fit.robot.config.urdf
    with output_set():
        write_result(out_dir / "result.yaml", result)
        write_calibrated_urdf(urdf, fit.robot.model, fit.corrections, out_dir / "calibrated.urdf")
        write_calibrated_config(fit.robot, fit.corrections, out_dir / "calibrated_robot.yaml")


def report_fit(result: FitResult, fit: Fit, warnings: list[str], out_dir: Path, say: Callable[[str], None]) -> None:
    """Tell the user what was fitted: the summary, notes on what the data cannot tell apart, the warnings, and
    where the outputs are."""
    for line in summary_lines(result):
        say(line)
    for line in explain(fit.params, fit.solution):
        say(f"note: {line}")
    for line in warnings:
        say(f"warning: {line}")
    say(f"wrote {out_dir / 'result.yaml'}, {out_dir / 'calibrated.urdf'} and {out_dir / 'calibrated_robot.yaml'}")
