"""The `floor:` config: the standing pose and soles that the ground error uses, for any robot, and its bad inputs."""

import numpy as np
import pytest
import yaml
from test_other_robot import CAMERA, CONFIG, URDF
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.ground import ground_errors
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor, standing_pose
from wolfcal.robot.robot import load_robot

FLOOR = "floor: {soles: [base], standing: {arm: 0.2}, tags: [{id: 30, size: 0.15}, {id: 31, size: 0.12}]}\n"


def write_robot(folder, extra=FLOOR):
    (folder / "pantilt.urdf").write_text(URDF)
    (folder / "robot.yaml").write_text(CONFIG + extra)
    return folder / "robot.yaml"


def test_other_robot_gets_ground_errors_from_its_config(tmp_path):
    robot = load_robot(write_robot(tmp_path))
    assert robot.config.floor.tag_ids == [30, 31] and robot.config.floor.tag(31).size == 0.12
    assert standing_pose(robot)[robot.model.column("arm")] == 0.2
    truth = Corrections(frames={robot.camera_joint: np.array([0, 0, 0, -0.06, 0, 0])})  # looks 0.06 rad lower
    rows = {r["distance_m"]: r for r in ground_errors(robot, CAMERA, truth, {"before": Corrections(), "truth": truth})}
    for d in (1.0, 2.0, 4.5):
        assert rows[d]["models"]["truth"]["error_m"] < 1e-6
    # Straight ahead, closed form: the nominal model sees the ray 0.06 rad less steep from the same camera position.
    from wolfcal.robot.aim import aim_head, ball_position

    ball = ball_position(robot, truth, 2.0, 0.0)
    T_floor_camera, _ = camera_in_floor(robot, aim_head(robot, truth, ball)[None], truth)
    x_c, h = T_floor_camera[0, 0, 3], T_floor_camera[0, 2, 3]
    expected = x_c + h / np.tan(np.arctan2(h, ball[0] - x_c) - 0.06) - ball[0]
    errors = [ground_errors(robot, CAMERA, truth, {"before": Corrections()}, (2.0,))[0]["models"]["before"]]
    assert errors[0]["error_m"] >= expected - 1e-6  # the worst bearing is at least the straight-ahead error
    assert abs(errors[0]["error_m"] - expected) / expected < 0.15


@pytest.mark.parametrize(
    "extra, words",
    [
        ("floor: {soles: [base], standing: {}, tags: [{id: 7, size: 0.1}]}\n", "also configured on a link"),
        ("floor: {soles: [nowhere], standing: {}}\n", "'floor.soles[0]'"),
        ("floor: {soles: [base], standing: {nojoint: 0.1}}\n", "'floor.standing'"),
        ("floor: {soles: [], standing: {}}\n", "'floor.soles' must be a non-empty list"),
        ("floor: {soles: [{link: nowhere, xyz: [0, 0, 0]}], standing: {}}\n", "'floor.soles' link 'nowhere'"),
        ("floor: {soles: [{link: base, xyz: [0, 0]}], standing: {}}\n", "'floor.soles[0].xyz' must be a list of 3"),
        ("floor: {soles: [{link: base, rpy: [0, 0, 0]}], standing: {}}\n", "'floor.soles[0]' unknown key(s) rpy"),
        ("floor: {soles: [base], standing: {}, aim: [nojoint]}\n", "'floor.aim' names nojoint"),
        ("floor: {soles: [base], standing: {}, tags: [{id: 30, size: -1}]}\n", "must be positive"),
    ],
)
def test_bad_floor_config_is_named(tmp_path, extra, words):
    path = write_robot(tmp_path, extra)
    with pytest.raises(WolfcalError, match="robot.yaml") as info:
        load_robot(path)
    assert words in str(info.value)
    result = CliRunner().invoke(app, ["simulate", "--robot", str(path), "--out", str(tmp_path / "x.mcap")])
    assert result.exit_code != 0 and words in result.output and "Traceback" not in result.output


def test_wolfgang_standing_pose_comes_from_its_config():
    from pathlib import Path

    robot = load_robot(Path(__file__).resolve().parents[2] / "configs" / "wolfgang")
    data = yaml.safe_load((Path(robot.config.path)).read_text())["floor"]
    q = standing_pose(robot)
    assert q[robot.model.column("RKnee")] == data["standing"]["RKnee"]
    assert robot.config.floor.soles == ("l_sole", "r_sole")
