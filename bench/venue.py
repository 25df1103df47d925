"""Robot time of the head camera's recalibration at a venue against the bus emulator (its default motion model) and
the simulated camera (binning 4), before and after `wolfcal venue`.

Before: the README's recipe as single commands, each capture at its default speed (the poses file's 0.5 rad/s,
`capture --floor`'s 0.5 rad/s): the feet poses (configs/wolfgang/poses.yaml), the floor views, three held-out
floor checks (`--floor --check`) and a held-out feet capture (the same poses again); the robot time of a capture
is the wall time of its `run_capture` (bus checks, moves, holds, samples). The fit and the evaluation do not move
the robot. After: one `wolfcal venue` session; its robot time runs from torque on to the last sample.
Truth: captures/floor_demo.truth.yaml (served by the emulator, rendered by the simulated camera).

The harness's `venue` part (`python bench/run.py --parts venue`).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console

from wolfcal.capture.pipeline import CaptureOptions, run_capture
from wolfcal.evaluate.accuracy import camera_pose_errors
from wolfcal.fit.result import load_result
from wolfcal.hardware.emulator import EmulatorProcess, load_truth, spec_from_config
from wolfcal.robot.robot import load_robot
from wolfcal.venue.options import VenueOptions
from wolfcal.venue.session import run_venue

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "configs" / "wolfgang"
TRUTH = ROOT / "captures" / "floor_demo.truth.yaml"


def before(port: str, folder: Path, say) -> dict[str, float]:
    """Robot time [s] of each capture of the README's recipe."""
    captures = {
        "feet": {"poses": ROBOT / "poses.yaml"},
        "floor": {"floor": True},
        "check_a": {"floor": True, "floor_check": True},
        "check_b": {"floor": True, "floor_check": True},
        "check_c": {"floor": True, "floor_check": True},
        "feet_heldout": {"poses": ROBOT / "poses.yaml"},
    }
    times = {}
    for name, kwargs in captures.items():
        options = CaptureOptions(robot=ROBOT, out=folder / f"{name}.mcap", camera="sim", port=port, **kwargs)
        start = time.monotonic()
        summary = run_capture(options, Console(quiet=True))
        times[name] = time.monotonic() - start
        say(f"venue: before: {name}: {summary.samples} samples, {times[name]:.1f} s")
    return times


def after(port: str, folder: Path, say) -> dict:
    """Robot and wall time [s] of one venue session, and its camera error against the truth [deg, mm]."""
    options = VenueOptions(robot=ROBOT, out=folder / "venue", camera="sim", port=port, yes=True)
    figures = run_venue(options, say=lambda line: None)
    robot = load_robot(ROBOT)
    rotation, translation = camera_pose_errors(robot, load_result(options.out / "fit").corrections, load_truth(TRUTH))
    result = {
        "robot_time_s": figures["robot_time_s"],
        "wall_time_s": figures["wall_time_s"],
        "samples": figures["samples"],
        "camera_rotation_deg": float(np.rad2deg(rotation.max())),
        "camera_translation_mm": float(translation.max() * 1000),
        "deployed": figures["deploy"]["written"],
    }
    say(f"venue: after: robot time {result['robot_time_s']:.1f} s, wall time {result['wall_time_s']:.1f} s, samples "
        f"{result['samples']}, camera within {result['camera_rotation_deg']:.4f} deg and "
        f"{result['camera_translation_mm']:.3f} mm of the truth")  # fmt: skip
    return result


def venue(say) -> dict:
    """Robot time of the single-command recipe (`before`, per capture [s], and their sum) and of one venue session
    (`after`), each on a fresh emulated robot."""
    robot = load_robot(ROBOT)
    results: dict = {}
    with tempfile.TemporaryDirectory() as scratch:
        for side, measure in (("before", before), ("after", after)):
            spec = spec_from_config(robot.config, load_truth(TRUTH), truth_path=str(TRUTH))
            with EmulatorProcess(spec) as emu:  # a fresh robot for each side
                folder = Path(scratch) / side
                folder.mkdir()
                results[side] = measure(emu.port, folder, say)
    results["before_total_s"] = sum(results["before"].values())
    return results
