"""The `field` part: the head camera from the lines of a RoboCup field against simulated truth, and from the feet
tags of the same true camera for comparison.

Per seed: a rendered field capture (`simulate --system field`: 512x384 colour views with goals, two other robots,
a ball, shadows, people and walls, uneven light, noise and up to 2 px of motion blur) of a standing Wolfgang placed
within 0.3 m and 10 deg of `field.robot_at` (-3, 0, 0) on a KidSize field, `views` views, fitted with `--system
field --free camera` in this process (BLAS on one thread, as the `wolfcal` command). Reported per seed:
  rotation_deg, translation_mm   the fitted camera's rotation and translation error against the truth
  ground_cm                      the fitted model's ground error at 4.5 m against the truth (`evaluate.ground`)
  place_mm, yaw_deg              the fitted field pose's error
  z                              (estimate - truth) / reported std of camera x y z rx ry rz and field x y yaw
  cpu_s, wall_s, load            detection + fit (reading the capture included), the load average after it
  tags                           rotation, translation, ground and z of `--free camera` on 20 feet-tag samples
                                 rendered at the same truth and seed (`simulate --system head`)
"""

from __future__ import annotations

import os
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import yaml

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.evaluate.ground import ground_errors
from wolfcal.field.model import KIDSIZE
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import run_fit
from wolfcal.geometry import exp_so3, log_so3
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import load_robot
from wolfcal.sim.simulate import SimOptions, simulate_capture

WOLFGANG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
NAMES = ("x", "y", "z", "rx", "ry", "rz")
TAG_SAMPLES = 20
QUIET = lambda _: None  # noqa: E731


def field_robot(folder: Path, check_at: dict | None = None) -> Path:
    """The shipped Wolfgang config with a KidSize field, the robot placed at (-3, 0, 0) (and `check_at` for the
    held-out check)."""
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str(WOLFGANG / data["urdf"])
    data["camera"]["intrinsics"] = str(WOLFGANG / data["camera"]["intrinsics"])
    data.pop("external_cameras", None)
    data["field"] = {"dimensions": asdict(KIDSIZE), "robot_at": {"x": -3.0, "y": 0.0, "yaw": 0.0}}
    if check_at is not None:
        data["field"]["check_at"] = check_at
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    return folder / "robot.yaml"


def fitted_params(folder: Path) -> dict:
    return {p["name"]: p for p in yaml.safe_load((folder / "result.yaml").read_text())["parameters"]}


def camera_figures(robot_path: Path, truth: Corrections, params: dict) -> dict:
    """Rotation [deg] and translation [mm] error of the fitted camera, its z per component, the ground error at
    4.5 m [cm] of the fitted model against the truth."""
    robot = load_robot(robot_path)
    true_camera = np.asarray(truth.frames[robot.camera_joint])
    fitted = np.array([params[f"camera.{c}"]["value"] for c in NAMES])
    model = Corrections(frames={robot.camera_joint: fitted})
    camera = load_camera_info(robot.config.intrinsics_file(HEAD_CAMERA, "bench", "")).binned(4, HEAD_CAMERA)
    ground = ground_errors(robot, camera, truth, {"fit": model}, (4.5,))[0]["models"]["fit"]["error_m"]
    return {
        "rotation_deg": float(np.rad2deg(np.linalg.norm(log_so3(exp_so3(fitted[3:]).T @ exp_so3(true_camera[3:]))))),
        "translation_mm": float(1000 * np.linalg.norm(fitted[:3] - true_camera[:3])),
        "ground_cm": float(100 * ground),
        "z": {c: float((fitted[i] - true_camera[i]) / params[f"camera.{c}"]["std"]) for i, c in enumerate(NAMES)},
    }


def one_seed(seed: int, views: int, folder: Path) -> dict:
    """The figures of the module docstring for one seed."""
    robot_path = field_robot(folder)
    capture = folder / f"field{seed}.mcap"
    simulate_capture(robot_path, capture, SimOptions(samples=views, seed=seed, binning=4, system="field"),
                     say=QUIET)  # fmt: skip
    truth_file = folder / f"field{seed}.truth.yaml"
    truth = load_corrections(truth_file, key="truth")
    cpu, wall = time.process_time(), time.perf_counter()
    run_fit([capture], robot_path, folder / f"fit{seed}", FitOptions(free="camera", system="field"), None,
            say=QUIET, force=True)  # fmt: skip
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    params = fitted_params(folder / f"fit{seed}")
    out = {"seed": seed, "cpu_s": cpu, "wall_s": wall, "load": os.getloadavg()[0],
           **camera_figures(robot_path, truth, params)}  # fmt: skip
    pose = yaml.safe_load(truth_file.read_text())["field_pose"]
    estimate = {c: params[f"field_pose.{c}"] for c in ("x", "y", "yaw")}
    out["z"].update({f"field_{c}": (estimate[c]["value"] - pose[c]) / estimate[c]["std"] for c in estimate})
    out["place_mm"] = float(1000 * np.hypot(estimate["x"]["value"] - pose["x"], estimate["y"]["value"] - pose["y"]))
    out["yaw_deg"] = float(np.rad2deg(abs(estimate["yaw"]["value"] - pose["yaw"])))
    out["max_z"] = max(abs(v) for v in out["z"].values())
    feet = folder / f"feet{seed}.mcap"
    simulate_capture(robot_path, feet, SimOptions(samples=TAG_SAMPLES, seed=seed, binning=4, system="head",
                                                  truth_file=truth_file), say=QUIET)  # fmt: skip
    run_fit([feet], robot_path, folder / f"tags{seed}", FitOptions(free="camera"), None, say=QUIET, force=True)
    tags = camera_figures(robot_path, truth, fitted_params(folder / f"tags{seed}"))
    out["tags"] = {**tags, "max_z": max(abs(v) for v in tags["z"].values())}
    return out


def field(seeds: int, views: int, say) -> dict:
    """Per seed 0 .. seeds-1 the figures of `one_seed`; the worst of each over the seeds."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            r = one_seed(seed, views, Path(tmp))
            rows.append(r)
            say(f"field seed {seed}: rotation {r['rotation_deg']:.3f} deg, ground {r['ground_cm']:.2f} cm, max |z| "
                f"{r['max_z']:.2f}; tags {r['tags']['rotation_deg']:.3f} deg; {r['cpu_s']:.1f} s CPU, "
                f"{r['wall_s']:.1f} s wall at load {r['load']:.1f}")  # fmt: skip
    keys = ("rotation_deg", "translation_mm", "ground_cm", "place_mm", "yaw_deg", "max_z", "cpu_s", "wall_s")
    worst = {k: max(r[k] for r in rows) for k in keys}
    worst_tags = {k: max(r["tags"][k] for r in rows) for k in ("rotation_deg", "translation_mm", "ground_cm", "max_z")}
    return {"seeds": seeds, "views": views, "tag_samples": TAG_SAMPLES, "rows": rows, "worst": worst,
            "worst_tags": worst_tags}  # fmt: skip
