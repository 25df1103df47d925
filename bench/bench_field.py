"""Field-line calibration against simulated truth: rendered field captures (goals, robots, ball, shadows, people,
uneven light, noise, motion blur) of a standing Wolfgang placed near `field.robot_at`, fitted with
`--system field --free camera`; prints per seed the camera's rotation and translation error, the field pose error,
the largest |estimate - truth| / std, and the CPU time of detection and fit.

    python bench/bench_field.py --seeds 5 --views 16
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import run_fit
from wolfcal.geometry import exp_so3, log_so3
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


def one_seed(seed: int, views: int, folder: Path) -> dict:
    robot_path = field_robot(folder)
    capture = folder / f"field{seed}.mcap"
    simulate_capture(robot_path, capture, SimOptions(samples=views, seed=seed, binning=4, system="field"),
                     say=lambda _: None)  # fmt: skip
    truth = yaml.safe_load((folder / f"field{seed}.truth.yaml").read_text())
    start = time.process_time()
    run_fit([capture], robot_path, folder / f"fit{seed}", FitOptions(free="camera", system="field"), None,
            say=lambda _: None, force=True)  # fmt: skip
    cpu = time.process_time() - start
    result = yaml.safe_load((folder / f"fit{seed}" / "result.yaml").read_text())
    params = {p["name"]: p for p in result["parameters"]}
    robot = load_robot(robot_path)
    true_camera = np.array(truth["truth"]["frames"][robot.camera_joint])
    fitted = np.array([params[f"camera.{c}"]["value"] for c in ("x", "y", "z", "rx", "ry", "rz")])
    rotation = np.rad2deg(np.linalg.norm(log_so3(exp_so3(fitted[3:]).T @ exp_so3(true_camera[3:]))))
    pose = truth["field_pose"]
    z = [
        abs(fitted[i] - true_camera[i]) / params[f"camera.{c}"]["std"]
        for i, c in enumerate(("x", "y", "z", "rx", "ry", "rz"))
    ]
    z += [abs(params[f"field_pose.{c}"]["value"] - pose[c]) / params[f"field_pose.{c}"]["std"] for c in pose]
    return {
        "seed": seed,
        "rotation_deg": rotation,
        "translation_mm": 1000 * np.linalg.norm(fitted[:3] - true_camera[:3]),
        "pose_mm": 1000
        * np.hypot(params["field_pose.x"]["value"] - pose["x"], params["field_pose.y"]["value"] - pose["y"]),
        "yaw_deg": np.rad2deg(abs(params["field_pose.yaw"]["value"] - pose["yaw"])),
        "max_z": max(z),
        "cpu_s": cpu,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--views", type=int, default=16)
    parser.add_argument("--only", type=int, nargs="*", help="these seeds only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.only or range(args.seeds):
            r = one_seed(seed, args.views, Path(tmp))
            print(
                f"seed {r['seed']}: camera rotation {r['rotation_deg']:.3f} deg, "
                f"translation {r['translation_mm']:.1f} mm; "
                f"field pose {r['pose_mm']:.1f} mm, {r['yaw_deg']:.3f} deg; max |z| {r['max_z']:.2f}; "
                f"detection + fit {r['cpu_s']:.1f} s CPU",
                flush=True,
            )


if __name__ == "__main__":
    main()
