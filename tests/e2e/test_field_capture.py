"""`wolfcal capture --field` then `wolfcal fit --system field` against the bus emulator (real dynamixel-sdk on a
pty, in its own process) and the simulated camera, which renders the field from the emulator's true robot.

Known truth: the camera's true mount (turned by a few degrees) and the robot's true place on the field, 0.25 m and
8 deg away from the configured `field.robot_at`, both in the emulator's truth file. Checks: the capture's samples
hold the legs standing and the head on the sweep's grid; the fit recovers the camera's rotation within 0.1 deg and
the robot's place within 5 cm and 0.5 deg (the tolerances of the rendered field fit).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import wolfgang_on_a_field

from wolfcal.capture.field import field_script
from wolfcal.geometry import exp_so3, log_so3
from wolfcal.hardware.bus import rad_to_ticks
from wolfcal.hardware.emulator import EmulatorProcess, spec_from_config
from wolfcal.io.reader import read_capture
from wolfcal.robot.robot import load_robot
from wolfcal.sim.truth import TruthSpec, random_truth

ROOT = Path(__file__).resolve().parents[2]
TRUE_PLACE = {"x": -2.75, "y": -0.2, "yaw": float(np.deg2rad(8.0))}  # robot_at is (-3, 0, 0)
SWEEP = {"pan": [-0.4, 0.1, 0.6, 1.1], "tilt": [-0.5, -0.36, -0.22]}  # 12 views, none touching the shoulders


def wolfcal(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "wolfcal.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=900)  # fmt: skip


@pytest.mark.slow
def test_a_field_capture_from_the_emulator_calibrates_the_camera(tmp_path):
    config = wolfgang_on_a_field(tmp_path)
    data = yaml.safe_load(config.read_text())
    data["field"]["sweep"] = SWEEP
    config.write_text(yaml.safe_dump(data))
    robot = load_robot(config)
    truth = random_truth(robot, TruthSpec(), np.random.default_rng(4))
    truth_file = tmp_path / "truth.yaml"
    truth_file.write_text(yaml.safe_dump({"truth": truth.to_dict(), "field_pose": TRUE_PLACE}))
    capture = tmp_path / "field.mcap"
    with EmulatorProcess(spec_from_config(robot.config, truth, truth_path=str(truth_file))) as emu:
        taken = wolfcal("capture", "--field", "--robot", str(config), "--port", emu.port, "--camera", "sim",
                        "--velocity", "4", "--out", str(capture))  # fmt: skip
    assert taken.returncode == 0, taken.stderr
    assert "Traceback" not in taken.stderr and "12 sample(s) saved" in taken.stderr and "field-line" in taken.stderr
    grid = {tuple(rad_to_ticks(p.joints[j]) for j in ("HeadPan", "HeadTilt")) for p in field_script(robot, 4).poses}
    samples = read_capture(capture, robot.config).samples
    assert len(samples) == 12
    for sample in samples:
        values = dict(zip(sample.joint_names, sample.positions, strict=True))
        assert tuple(rad_to_ticks(values[j]) for j in ("HeadPan", "HeadTilt")) in grid
        assert rad_to_ticks(values["RKnee"]) == rad_to_ticks(-0.2618)  # floor.standing
    fitted = wolfcal("fit", str(capture), "--robot", str(config), "--system", "field", "--free", "camera", "--out",
                     str(tmp_path / "fit"))  # fmt: skip
    assert fitted.returncode == 0, fitted.stderr
    params = {p["name"]: p for p in yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())["parameters"]}
    true_camera = truth.frames[robot.camera_joint]
    rotation = np.array([params[f"camera.{c}"]["value"] for c in ("rx", "ry", "rz")])
    error_deg = np.rad2deg(np.linalg.norm(log_so3(exp_so3(rotation).T @ exp_so3(true_camera[3:]))))
    place_error = np.hypot(params["field_pose.x"]["value"] - TRUE_PLACE["x"],
                           params["field_pose.y"]["value"] - TRUE_PLACE["y"])  # fmt: skip
    yaw_error = np.rad2deg(params["field_pose.yaw"]["value"] - TRUE_PLACE["yaw"])
    assert error_deg < 0.1 and place_error < 0.05 and abs(yaw_error) < 0.5, (error_deg, place_error, yaw_error)
