"""`wolfcal fit`: captures -> observations -> problem -> solution -> result.yaml + calibrated.urdf."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import yaml

from wolfcal.atomic import output_set
from wolfcal.camera.camera_info import load_camera_info
from wolfcal.errors import WolfcalError
from wolfcal.fit.problem import Problem
from wolfcal.fit.result import explain, result_dict, summary_lines, write_result
from wolfcal.fit.solver import Solution, solve
from wolfcal.io.reader import read_capture
from wolfcal.io.samples import Sample
from wolfcal.leftout import check_left_out
from wolfcal.observations import Observations
from wolfcal.outputs import check_output_folder
from wolfcal.progress import Progress
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet, build_parameter_set, check_preset, tags_for_preset
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.vision.observe import detect_observations


@dataclass(frozen=True)
class FitOptions:
    free: str = "camera"
    side: str = "both"
    fix_tags: bool = False
    huber_k: float = 3.0  # robust threshold [standard deviations of the noise model]
    outlier_floor_px: float = 0.5

    def __post_init__(self) -> None:
        check_preset(self.free, self.side)  # before any file is read


@dataclass
class Fit:
    robot: Robot
    obs: Observations
    tag_ids: list[int]
    params: ParameterSet
    problem: Problem
    solution: Solution

    @property
    def corrections(self) -> Corrections:
        return self.params.corrections(self.solution.values)


def minimum_samples(n_params: int) -> int:
    """Samples needed for a free-parameter set: each tag view gives 8 numbers; ask for twice the unknowns."""
    return max(3, -(-2 * n_params // 8))


def fit_observations(
    robot: Robot, obs: Observations, options: FitOptions, say: Callable[[str], None] | None = None
) -> Fit:
    """Choose the free parameters for the observed tags, check there is enough data, solve."""
    tag_ids = tags_for_preset(robot, options.free, obs.observed_tag_ids, options.side)
    if not tag_ids:
        raise WolfcalError(
            f"no tag of the {options.side} side was detected; the leg preset with --side {options.side} needs one"
        )
    if set(tag_ids) != set(obs.observed_tag_ids):
        obs = obs.only_tags(tag_ids)
    params = build_parameter_set(robot, options.free, tag_ids, options.side, options.fix_tags)
    needed = minimum_samples(len(params))
    if obs.n_samples < needed:
        raise WolfcalError(
            f"too few samples for the free parameters: {obs.n_samples} sample(s) with tags for {len(params)} free "
            f"parameters (--free {options.free}); capture at least {needed}, or free fewer parameters"
        )
    priors = robot.config.priors
    problem = Problem(
        robot, obs, params, tag_ids, priors.pixel_noise, priors.encoder_noise, options.huber_k
    )
    solution = solve(problem, outlier_floor_px=options.outlier_floor_px, progress=say)
    return Fit(robot, obs, tag_ids, params, problem, solution)


def load_samples(
    robot: Robot, captures: list[Path], intrinsics: Path | None, say: Callable[[str], None] | None = None
) -> tuple[list[Sample], list[str]]:
    """All samples of the captures, and notes on frames a recording skipped. A capture whose attached robot
    config names another robot is refused. `say` gets progress lines while long files are read."""
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
    samples = [s for c in loaded for s in c.samples]
    notes = [f"{c.path.name}: {len(c.skipped)} frame(s) skipped ({c.skipped[0]} ...)" for c in loaded if c.skipped]
    return samples, notes


def attached_robot_name(config_text: str | None) -> str | None:
    """The `name` of a robot config attached to a capture (None when absent or unreadable)."""
    try:
        data = yaml.safe_load(config_text) if config_text else None
    except yaml.YAMLError:
        return None
    return data.get("name") if isinstance(data, dict) else None


FIT_OUTPUTS = ("result.yaml", "calibrated.urdf")


def check_solution_left_out(fit: Fit, captures: list[Path]) -> None:
    """The outlier rule must not absorb unusable data: WolfcalError when more than MAX_LEFT_OUT of the samples
    or tag views were left out as outliers."""
    n_views = len({(int(s), int(t)) for s, t in zip(fit.obs.sample_index, fit.obs.tag_ids)})
    check_left_out(
        {
            "samples": (int(fit.solution.outlier_samples.sum()), fit.obs.n_samples),
            "tag views": (len(fit.solution.outlier_views), n_views),
        },
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
) -> dict:
    """The whole `wolfcal fit` job; returns the result dict that was written to out_dir/result.yaml.
    Existing outputs in out_dir are replaced only with `force`; both files are written as one set."""
    robot = load_robot(robot_path)
    inputs = [*captures, robot.config.path, robot.config.urdf] + ([intrinsics] if intrinsics else [])
    check_output_folder(out_dir, FIT_OUTPUTS, force, inputs)
    samples, warnings = load_samples(robot, captures, intrinsics, say)
    say(f"read {len(samples)} sample(s) from {len(captures)} capture file(s); detecting tags ...")
    obs, detect_warnings = detect_observations(samples, robot, progress=Progress(say, "detecting tags", "samples"))
    warnings += detect_warnings
    say(f"{obs.n_samples} sample(s) with tags, {len(obs.uv)} corners; fitting --free {options.free} ...")
    fit = fit_observations(robot, obs, options, say)
    check_solution_left_out(fit, captures)
    data = result_dict(
        robot_path=robot.config.path,
        urdf_path=robot.config.urdf,
        captures=captures,
        intrinsics=intrinsics,
        preset=options.free,
        side=options.side,
        fix_tags=options.fix_tags,
        tag_ids=fit.tag_ids,
        params=fit.params,
        solution=fit.solution,
        obs=fit.obs,
        corrections=fit.corrections,
        huber_k=options.huber_k,
        warnings=warnings,
    )
    with output_set():
        write_result(out_dir / "result.yaml", data)
        write_calibrated_urdf(robot.config.urdf, robot.model, fit.corrections, out_dir / "calibrated.urdf")
    for line in summary_lines(data):
        say(line)
    for line in explain(fit.params, fit.solution):
        say(f"note: {line}")
    for line in warnings:
        say(f"warning: {line}")
    say(f"wrote {out_dir / 'result.yaml'} and {out_dir / 'calibrated.urdf'}")
    return data
