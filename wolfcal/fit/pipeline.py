"""The fit: observations -> measurement blocks -> problem -> solution (`wolfcal.fit.run` reads, detects and writes)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block
from wolfcal.fit.camera_block import CameraBlock, placements
from wolfcal.fit.floor_block import FloorBlock, SoleClosure, check_floor_samples
from wolfcal.fit.inputs import in_system
from wolfcal.fit.mocap_block import MOCAP_NOISE_START_M, MocapBlock
from wolfcal.fit.options import FitOptions
from wolfcal.fit.problem import Problem
from wolfcal.fit.solver import MIN_SIGMA, Solution, solve
from wolfcal.leftout import check_left_out
from wolfcal.markers import MarkerObservations
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet, build_parameter_set, tags_for_preset
from wolfcal.robot.robot import Robot

SOLE_NOISE_M = 1e-3  # starting noise of the sole closure [m], before it is estimated


@dataclass
class Fit:
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
        return sorted({t for b in self.blocks if b.system != "floor" for t in getattr(b, "tag_ids", ())})

    @property
    def corrections(self) -> Corrections:
        return self.chain.corrections(self.solution.values[: len(self.chain)])



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


def check_solution_left_out(fit: Fit, captures: list[Path]) -> None:
    """The outlier rule must not absorb unusable data: WolfcalError when more than MAX_LEFT_OUT of a measurement
    system's samples or tag views were left out as outliers."""
    counts = {}
    for block, result in zip(fit.blocks, fit.solution.blocks):
        counts[f"{block.name} samples"] = (int(result.outlier_samples.sum()), len(block.q_measured))
        counts[f"{block.name} tag views"] = (len(result.outlier_views), block.n_views)
    check_left_out(
        counts,
        ", ".join(map(str, captures)),
        "the data do not fit the model: check the joint readings, the tags' ids, sizes and links in the robot "
        "config, and the camera intrinsics (--intrinsics)",
    )


