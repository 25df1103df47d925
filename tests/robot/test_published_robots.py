"""Five robot descriptions as their makers publish them (tests/data/robots, SOURCES.md in each folder): simulate,
fit the legs, evaluate on held-out samples, and read the deployed URDFs back with an independent reader (yourdfpy):
they must put the camera, the tag links and the soles where the fitted model does. The Wolfgang's camera link has
ROS body axes and H1, OP3 and G1 have no sole frames: config keys alone (`camera.axes`, `floor.soles` as
{link, xyz}) make them work."""

from __future__ import annotations

import difflib
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from deployed_urdf import deployed_error
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.evaluate.undetermined import deployable_model
from wolfcal.fit.result import FitResult
from wolfcal.io.current import CurrentCalibration
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import load_robot

ROBOTS = Path(__file__).resolve().parents[1] / "data" / "robots"
# robot -> (simulate options, what the URDF holds that a writer must leave alone)
PUBLISHED = {
    "wolfgang": (["--binning", "2"], ["<transmission", "<gazebo", "<!--"]),
    "op3": ([], ["<transmission", "<gazebo", "<!--"]),
    "nao": ([], ["<transmission", "<gazebo", "<mimic", "<!--"]),
    "unitree_g1": ([], ["<!--"]),
    "unitree_h1": ([], ["<mujoco", "<!--"]),
}
DEPLOYED = ("calibrated.urdf", "calibrated_folded.urdf")


def run(*args: str) -> None:
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output


def changed_lines(before: str, after: str) -> list[str]:
    """The lines of `after` that are not in `before` (line ends kept)."""
    a, b = before.splitlines(keepends=True), after.splitlines(keepends=True)
    out = []
    for tag, _, _, j1, j2 in difflib.SequenceMatcher(None, a, b, autojunk=False).get_opcodes():
        if tag != "equal":
            out += b[j1:j2]
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", list(PUBLISHED))
def test_published_robot_deploys_the_fitted_model(tmp_path, name):
    config = ROBOTS / name / "robot.yaml"
    sim_options, kept = PUBLISHED[name]
    fit_capture, held_capture = tmp_path / "fit.mcap", tmp_path / "held.mcap"
    run("simulate", "--robot", str(config), "--out", str(fit_capture), "--samples", "16", "--offsets", "legs",
        "--seed", "1", *sim_options)  # fmt: skip
    run("simulate", "--robot", str(config), "--out", str(held_capture), "--samples", "6", "--seed", "2",
        "--truth", str(tmp_path / "fit.truth.yaml"), *sim_options)  # fmt: skip
    run("fit", str(fit_capture), "--robot", str(config), "--free", "leg", "--out", str(tmp_path / "fit"))
    run("evaluate", str(tmp_path / "fit"), "--capture", str(held_capture), "--out", str(tmp_path / "report"),
        "--deploy-worse")  # fmt: skip
    robot = load_robot(config)
    fitted = Corrections.from_dict(yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())["corrections"])
    truth = load_corrections(tmp_path / "fit.truth.yaml", key="truth")
    assert fitted.offsets and set(truth.offsets) <= set(robot.joint_names)
    q = np.random.default_rng(0).uniform(-0.5, 0.5, size=(4, len(robot.joint_names)))
    source = robot.config.urdf.read_bytes().decode("utf-8")
    result_file = tmp_path / "fit" / "result.yaml"
    fit_result = FitResult.from_dict(yaml.safe_load(result_file.read_text()), result_file)
    deployed, _ = deployable_model(fit_result, CurrentCalibration(), robot)  # undetermined parameters held
    for urdf, model in [(tmp_path / "fit" / "calibrated.urdf", fitted)] + [
        (tmp_path / "report" / f, deployed) for f in DEPLOYED
    ]:
        error = deployed_error(robot, model, urdf, folded="folded" in urdf.name, q=q)
        assert error < 1e-6, f"{name}: {urdf.parent.name}/{urdf.name} is {error:.2e} m off the model it holds"
        text = urdf.read_bytes().decode("utf-8")
        for marker in kept:
            assert text.count(marker) == source.count(marker), f"{name}: {urdf.name} changed the {marker!r}"
        changed = changed_lines(source, text)
        assert changed and all(line.lstrip().startswith(("<origin", "<calibration")) for line in changed), changed[:3]
        if "\r\n" in source:
            assert text.count("\n") == text.count("\r\n"), f"{name}: {urdf.name} mixes line ends"


@pytest.mark.slow
def test_external_camera_rests_on_the_torso_tag_behind_waist_joints(tmp_path):
    """G1: the torso tag hangs behind three waist joints, not fixed to the pelvis; the tripod's pose rests on it, the
    leg fit frees the waist offsets too, and the held-out foot error is that of the config's soles ({link, xyz})."""
    config = str(ROBOTS / "unitree_g1" / "robot.yaml")
    run("simulate", "--robot", config, "--system", "external", "--out", str(tmp_path / "ext.mcap"), "--samples", "16",
        "--offsets", "legs", "--seed", "3")  # fmt: skip
    run("simulate", "--robot", config, "--system", "external", "--out", str(tmp_path / "held.mcap"), "--samples",
        "8", "--truth", str(tmp_path / "ext.truth.yaml"), "--seed", "4")  # fmt: skip
    run("fit", str(tmp_path / "ext.mcap"), "--robot", config, "--free", "leg", "--out", str(tmp_path / "fit"))
    names = [p["name"] for p in yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())["parameters"]]
    assert {"waist_yaw_joint.offset", "tripod.x", "tag42.x"} <= set(names)
    run("evaluate", str(tmp_path / "fit"), "--capture", str(tmp_path / "held.mcap"), "--out", str(tmp_path / "rep"))
    soles = json.loads((tmp_path / "rep" / "metrics.json").read_text())["external"]["sole_error_mm"]
    assert set(soles["before"]) == {"left_ankle_roll_link_sole", "right_ankle_roll_link_sole"}
    for sole, before in soles["before"].items():  # truth: leg offsets of a few degrees
        assert soles["after"][sole] < 0.3 * before, sole


@pytest.mark.slow
def test_floor_views_aim_with_the_configured_joints_and_stand_on_configured_soles(tmp_path):
    """G1: floor samples aimed with `floor.aim` (waist yaw and pitch), the floor the plane of the {link, xyz} soles;
    a camera fit from them finds the simulated camera rotation to a few mrad."""
    config = str(ROBOTS / "unitree_g1" / "robot.yaml")
    run(
        "simulate",
        "--robot",
        config,
        "--floor",
        "--out",
        str(tmp_path / "floor.mcap"),
        "--samples",
        "6",
        "--binning",
        "1",
    )
    run("fit", str(tmp_path / "floor.mcap"), "--robot", config, "--free", "camera", "--out", str(tmp_path / "fit"))
    truth = load_corrections(tmp_path / "floor.truth.yaml", key="truth").frames["d435_link_optical"]
    result = yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())
    fitted = Corrections.from_dict(result["corrections"]).frames["d435_link_optical"]
    assert np.max(np.abs(fitted[3:] - truth[3:])) < 0.003
    camera = [p for p in result["parameters"] if p["name"].startswith("camera.")]
    assert len(camera) == 6 and all(p["urdf_joint"] == "d435_joint" for p in camera)
