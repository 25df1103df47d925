"""`wolfcal fit` and `wolfcal evaluate` on the shipped external-camera captures (rendered tripod images with truth)."""

import json
from pathlib import Path

import numpy as np
import yaml
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.evaluate.accuracy import link_position_errors
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import load_robot

ROOT = Path(__file__).resolve().parents[2]
CAPTURE = ROOT / "captures" / "external_demo.mcap"
HELD_OUT = ROOT / "captures" / "external_demo_heldout.mcap"


def test_external_leg_fit_and_held_out_evaluation(tmp_path):
    fit_dir = tmp_path / "fit"
    result = CliRunner().invoke(app, ["fit", str(CAPTURE), "--robot", str(ROOT / "configs" / "wolfgang"),
                                      "--free", "leg", "--system", "external", "--out", str(fit_dir)])  # fmt: skip
    assert result.exit_code == 0, result.output
    data = yaml.safe_load((fit_dir / "result.yaml").read_text())
    assert [b["system"] for b in data["blocks"]] == ["external"]
    assert "tripod" in data["external_cameras"]
    truth = load_corrections(CAPTURE.with_suffix("").as_posix() + ".truth.yaml", key="truth")
    robot = load_robot(ROOT / "configs" / "wolfgang")
    fitted = Corrections.from_dict(data["corrections"])
    rng = np.random.default_rng(1)
    for sole in ("r_sole", "l_sole"):
        assert link_position_errors(robot, sole, fitted, truth, 300, rng).max() < 0.002, sole
    offsets = {p["name"][: -len(".offset")]: p for p in data["parameters"] if p["name"].endswith(".offset")}
    for joint, p in offsets.items():
        assert abs(p["value"] - truth.offsets.get(joint, 0.0)) < 3 * p["std"], joint
    # the calibrated config holds the fitted tag mounts and loads as a robot config
    calibrated = load_robot(fit_dir / "calibrated_robot.yaml")
    np.testing.assert_allclose(calibrated.T_link_tag(43), robot.T_link_tag(43, fitted), atol=1e-6)

    report = tmp_path / "eval"
    result = CliRunner().invoke(app, ["evaluate", str(fit_dir), "--capture", str(HELD_OUT), "--out", str(report)])
    assert result.exit_code == 0, result.output
    metrics = json.loads((report / "metrics.json").read_text())
    tripod = metrics["external"]["cameras"]["tripod"]
    assert tripod["after"]["rms_px"] < tripod["before"]["rms_px"]
    soles = metrics["external"]["sole_error_mm"]
    assert max(soles["after"].values()) < 0.25 * max(soles["before"].values())
    assert metrics["deploy"]["written"] and (report / "calibrated.urdf").is_file()
