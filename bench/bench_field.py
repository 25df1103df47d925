"""Field-line calibration against simulated truth: rendered field captures (goals, robots, ball, shadows, people,
uneven light, noise, motion blur) of a standing Wolfgang placed near `field.robot_at`, fitted with
`--system field --free camera`; prints per seed the camera's rotation and translation error, the ground error at
4.5 m, the field pose error, (estimate - truth) / std of every estimate, and the CPU and wall time of detection and
fit with the load average; `--tags`: the same figures from a fit of the feet tags (same true camera and seed).

    python bench/bench_field.py --seeds 5 --views 20 --tags
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.evaluate.ground import ground_errors
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import run_fit
from wolfcal.geometry import exp_so3, log_so3
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import load_robot
from wolfcal.sim.simulate import SimOptions, simulate_capture

ROOT = Path(__file__).resolve().parents[1]
KIDSIZE = {"length": 9.0, "width": 6.0, "line_width": 0.05, "center_circle_diameter": 1.5,
           "penalty_mark_distance": 1.5, "penalty_mark_size": 0.1, "goal_area_length": 1.0, "goal_area_width": 3.0,
           "penalty_area_length": 2.0, "penalty_area_width": 5.0}  # fmt: skip


def field_robot(folder: Path) -> Path:
    """The shipped Wolfgang config with a KidSize field, the robot placed at (-3, 0, 0)."""
    source = ROOT / "configs" / "wolfgang"
    data = yaml.safe_load((source / "robot.yaml").read_text())
    data["urdf"] = str(source / data["urdf"])
    data["camera"]["intrinsics"] = str(source / data["camera"]["intrinsics"])
    data.pop("external_cameras", None)
    data["field"] = {"dimensions": KIDSIZE, "robot_at": {"x": -3.0, "y": 0.0, "yaw": 0.0}}
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    return folder / "robot.yaml"


NAMES = ("x", "y", "z", "rx", "ry", "rz")


def camera_figures(robot_path: Path, truth: Corrections, params: dict) -> dict:
    """Rotation [deg] and translation [mm] error of the fitted camera, its |z| per component, the ground error at
    4.5 m [cm] of the fitted model against the truth."""
    robot = load_robot(robot_path)
    true_camera = np.asarray(truth.frames[robot.camera_joint])
    fitted = np.array([params[f"camera.{c}"]["value"] for c in NAMES])
    model = Corrections(frames={robot.camera_joint: fitted})
    camera = load_camera_info(robot.config.intrinsics_file(HEAD_CAMERA, "bench", "")).binned(4, HEAD_CAMERA)
    ground = ground_errors(robot, camera, truth, {"fit": model}, (4.5,))[0]["models"]["fit"]["error_m"]
    return {
        "rotation_deg": np.rad2deg(np.linalg.norm(log_so3(exp_so3(fitted[3:]).T @ exp_so3(true_camera[3:])))),
        "translation_mm": 1000 * np.linalg.norm(fitted[:3] - true_camera[:3]),
        "ground_cm": 100 * ground,
        "z": {c: (fitted[i] - true_camera[i]) / params[f"camera.{c}"]["std"] for i, c in enumerate(NAMES)},
    }


def fitted_params(folder: Path) -> dict:
    return {p["name"]: p for p in yaml.safe_load((folder / "result.yaml").read_text())["parameters"]}


def one_seed(seed: int, views: int, folder: Path, tags: bool) -> dict:
    robot_path = field_robot(folder)
    capture = folder / f"field{seed}.mcap"
    simulate_capture(robot_path, capture, SimOptions(samples=views, seed=seed, binning=4, system="field"),
                     say=lambda _: None)  # fmt: skip
    truth_file = folder / f"field{seed}.truth.yaml"
    truth = load_corrections(truth_file, key="truth")
    start, wall = time.process_time(), time.perf_counter()
    run_fit([capture], robot_path, folder / f"fit{seed}", FitOptions(free="camera", system="field"), None,
            say=lambda _: None, force=True)  # fmt: skip
    cpu, wall = time.process_time() - start, time.perf_counter() - wall
    params = fitted_params(folder / f"fit{seed}")
    out = {"seed": seed, "cpu_s": cpu, "wall_s": wall, "load": os.getloadavg()[0],
           **camera_figures(robot_path, truth, params)}  # fmt: skip
    pose = yaml.safe_load(truth_file.read_text())["field_pose"]
    out["z"].update({f"field_{c}": (params[f"field_pose.{c}"]["value"] - pose[c]) / params[f"field_pose.{c}"]["std"]
                     for c in pose})  # fmt: skip
    out["pose_mm"] = 1000 * np.hypot(params["field_pose.x"]["value"] - pose["x"],
                                     params["field_pose.y"]["value"] - pose["y"])  # fmt: skip
    out["yaw_deg"] = np.rad2deg(abs(params["field_pose.yaw"]["value"] - pose["yaw"]))
    if tags:  # the same true camera seen through the feet tags, as `simulate --system head` renders them
        feet = folder / f"feet{seed}.mcap"
        simulate_capture(robot_path, feet, SimOptions(samples=views, seed=seed, binning=4, system="head",
                                                      truth_file=truth_file), say=lambda _: None)  # fmt: skip
        run_fit([feet], robot_path, folder / f"tags{seed}", FitOptions(free="camera"), None, say=lambda _: None,
                force=True)  # fmt: skip
        out["tags"] = camera_figures(robot_path, truth, fitted_params(folder / f"tags{seed}"))
    return out


def line(label: str, r: dict) -> str:
    z = " ".join(f"{k} {v:+.2f}" for k, v in r["z"].items())
    return (f"  {label}: camera rotation {r['rotation_deg']:.3f} deg, translation {r['translation_mm']:.1f} mm, "
            f"ground error at 4.5 m {r['ground_cm']:.2f} cm; z: {z}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--views", type=int, default=16)
    parser.add_argument("--only", type=int, nargs="*", help="these seeds only")
    parser.add_argument("--tags", action="store_true", help="also fit the feet tags of the same true camera")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.only or range(args.seeds):
            r = one_seed(seed, args.views, Path(tmp), args.tags)
            print(f"seed {seed}: field pose {r['pose_mm']:.1f} mm, {r['yaw_deg']:.3f} deg; max |z| "
                  f"{max(abs(v) for v in r['z'].values()):.2f}; detection + fit {r['cpu_s']:.1f} s CPU, "
                  f"{r['wall_s']:.1f} s wall at load {r['load']:.1f}", flush=True)  # fmt: skip
            print(line("field", r), flush=True)
            if args.tags:
                print(line("tags ", r["tags"]), flush=True)


if __name__ == "__main__":
    main()
