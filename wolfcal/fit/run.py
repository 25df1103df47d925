"""`wolfcal fit` as one job: read the captures, detect the tags, solve, write the outputs.

The solver's modules (`wolfcal.fit.pipeline`: the blocks, the problem, the noise model, SciPy's sparse matrices;
about 0.25 s of CPU on their own, a third of the command's imports) are imported by a background thread while the
captures are read and their images detected, instead of before: detection runs on threads that release the
interpreter lock most of the time, so the import shares the cores with it instead of delaying the start. This
module therefore imports nothing of the solver at its top.
"""

from __future__ import annotations

import importlib
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from wolfcal.atomic import output_set
from wolfcal.fit.inputs import in_system, load_samples, repeat_warnings
from wolfcal.fit.options import FitOptions
from wolfcal.io.mocap_load import load_marker_observations
from wolfcal.markers import MarkerObservations
from wolfcal.memory import large_blocks_mapped, release_freed_memory
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.outputs import check_output_folder
from wolfcal.progress import Progress
from wolfcal.robot.config_writer import write_calibrated_config
from wolfcal.robot.robot import load_robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.vision.cache import digest_ahead
from wolfcal.vision.observe import detect_observations

if TYPE_CHECKING:
    from wolfcal.fit.result import FitResult

SOLVER_MODULES = ("wolfcal.fit.pipeline", "wolfcal.fit.result")
FIT_OUTPUTS = ("result.yaml", "calibrated.urdf", "calibrated_robot.yaml")


def _load_in_background(modules: Sequence[str]) -> threading.Thread:
    """A started daemon thread importing `modules`; an import that fails there is left to fail again, with its
    error, where the module is imported for use."""

    def load() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001, S112 (imported again where it is used: that import raises)
                continue

    thread = threading.Thread(target=load, name="wolfcal-load-solver", daemon=True)
    thread.start()
    return thread


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
    Existing outputs in out_dir are replaced only with `force`; both files are written as one set. Motion capture
    (--system mocap or all, or --mocap files): markers from the captures' Markers topic, or from the `mocap` files
    (one per capture, clock offsets `mocap_offsets` or estimated)."""
    solver = _load_in_background(SOLVER_MODULES)
    robot = load_robot(robot_path)
    inputs = [*captures, *mocap, robot.config.path, robot.config.urdf] + ([intrinsics] if intrinsics else [])
    check_output_folder(out_dir, FIT_OUTPUTS, force, inputs)
    markers: MarkerObservations | None = None
    warnings: list[str] = []
    observations: dict[str, Observations] = {}
    if options.system == "mocap" or mocap:
        markers = load_marker_observations(robot.config, robot.joint_names, captures, list(mocap), list(mocap_offsets))
        say(f"motion capture: {markers.n_samples} still sample(s), {len(markers.xyz)} marker positions"
            + "".join(f"; {Path(k).name}: clock offset {v:.4f} s" for k, v in markers.clock_offsets_s.items()))
        warnings += [f"marker labels not in the robot config, ignored: {', '.join(markers.unknown_names)}"
                     ] if markers.unknown_names else []  # fmt: skip
    if options.system != "mocap":
        required = (HEAD_CAMERA,) if options.system == "head" else ()
        digest_ahead(captures)  # the detection cache's key, hashed while the captures are read
        samples, read_warnings = load_samples(robot, captures, intrinsics, cameras=required, say=say)
        release_freed_memory()  # the reader's heap between image buffers: detection starts from the samples
        warnings += read_warnings
        say(f"read {len(samples)} sample(s) from {len(captures)} capture file(s); detecting tags ...")
        names = dict.fromkeys([HEAD_CAMERA, *robot.config.camera_names])
        wanted = None if options.system in (None, "all") else [n for n in names if in_system(n, options.system)]
        observations, detect_warnings = detect_observations(
            samples, robot, progress=Progress(say, "detecting tags", "samples"), cameras=wanted
        )
        warnings += detect_warnings + repeat_warnings(observations, options.noise_floor_px)
        release_freed_memory()  # the detection threads' image buffers: the fit starts from the corners
    for name, obs in observations.items():
        say(f"{name} camera: {obs.n_samples} sample(s) with tags, {len(obs.uv)} corners")
    say(f"fitting --free {options.free} ...")
    solver.join()  # the solver's modules, loaded while the captures were read and detected
    from wolfcal.fit.pipeline import check_solution_left_out, fit_observations
    from wolfcal.fit.result import explain, fit_result, summary_lines, write_result

    # the solve's large transient arrays do not stay on the heap (wolfcal/memory.py); not while reading and detecting,
    # whose image buffers would then be mapped afresh each time (8 s more system time per 600 frames)
    with large_blocks_mapped():
        fit = fit_observations(robot, observations, options, say, markers)
        check_solution_left_out(fit, captures)
        result = fit_result(fit, options, captures, intrinsics, warnings)
        with output_set():
            write_result(out_dir / "result.yaml", result)
            write_calibrated_urdf(robot.config.urdf, robot.model, fit.corrections, out_dir / "calibrated.urdf")
            write_calibrated_config(robot, fit.corrections, out_dir / "calibrated_robot.yaml")
    for line in summary_lines(result):
        say(line)
    for line in explain(fit.params, fit.solution):
        say(f"note: {line}")
    for line in warnings:
        say(f"warning: {line}")
    say(f"wrote {out_dir / 'result.yaml'}, {out_dir / 'calibrated.urdf'} and {out_dir / 'calibrated_robot.yaml'}")
    return result
