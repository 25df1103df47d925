"""Motion-capture markers in the robot config: the Wolfgang layout, a config for motion capture alone (no camera, no
tags), and bad marker entries."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.robot.robot import load_robot

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"


def mocap_only_config(tmp_path: Path, **changes) -> Path:
    """The Wolfgang robot with only its markers (no camera, no tags); top-level keys replaced by `changes`."""
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    for key in ("camera", "external_cameras", "tags", "imu"):
        data.pop(key)
    data["urdf"] = str(WOLFGANG / "wolfgang.urdf")
    data.update(changes)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_wolfgang_layout_has_the_studys_markers_on_the_foot_plates_and_torso():
    robot = load_robot(WOLFGANG)
    markers = robot.config.markers
    assert markers.topic == "/mocap/markers"
    by_link = {}
    for m in markers.entries:
        by_link.setdefault(m.link, []).append(m)
    assert {k: len(v) for k, v in by_link.items()} == {"r_foot": 4, "l_foot": 4, "torso": 6}
    assert [m.side for m in by_link["r_foot"]] == ["right"] * 4 and by_link["torso"][0].side is None
    # straight legs: foot markers lie 1 cm above the sole plane, at the plate corners (0.19 m x 0.11 m)
    q = np.zeros((1, len(robot.joint_names)))
    q[0, robot.model.column("RKnee")], q[0, robot.model.column("LKnee")] = -0.2618, 0.2618
    poses = robot.model.link_poses(q, ["r_foot", "r_sole"], None, base="base_link")
    corners = np.array([poses["r_foot"][0][:3, :3] @ m.xyz + poses["r_foot"][0][:3, 3] for m in by_link["r_foot"]])
    sole = poses["r_sole"][0][:3, 3]
    assert np.allclose(corners[:, 2], sole[2] + 0.01, atol=1e-3)
    assert np.ptp(corners[:, 0]) == pytest.approx(0.1877, abs=1e-3) and np.ptp(corners[:, 1]) == pytest.approx(0.11)
    # the upper four are 52 mm apart vertically (the study's weakly measured rotation), two more at the bottom
    z = sorted({m.xyz[2] for m in by_link["torso"]})
    assert z[2] - z[1] == pytest.approx(0.052) and z[0] < 0.0


def test_a_config_for_motion_capture_alone_needs_no_camera_and_no_tags(tmp_path):
    config = load_robot_config(mocap_only_config(tmp_path))
    assert config.camera is None and config.tags == () and len(config.markers.entries) == 14
    with pytest.raises(WolfcalError, match="has no 'camera:'"):
        config.head_camera()


@pytest.mark.parametrize(
    "markers, message",
    [
        ({"topic": "/m"}, r"'markers' missing key\(s\) list"),
        ({"list": []}, "must be a non-empty list of markers"),
        ({"list": [{"name": "a", "link": "torso"}]}, r"missing key\(s\) xyz"),
        ({"list": [{"name": "a.b", "link": "torso", "xyz": [0, 0, 0]}]}, "must start with a letter"),
        ({"list": [{"name": "a", "link": "torso", "xyz": [0, 0, 0]}] * 2}, "used by another marker"),
        ({"list": [{"name": "a", "link": "torso", "xyz": [0, 0]}]}, "list of 3 numbers"),
        ({"list": [{"name": "a", "link": "torso", "xyz": [0, 0, 0], "id": 3}]}, r"unknown key\(s\) id"),
    ],
)
def test_config_refuses_bad_markers(tmp_path, markers, message):
    with pytest.raises(WolfcalError, match=message):
        load_robot_config(mocap_only_config(tmp_path, markers=markers))


def test_a_marker_on_a_link_the_urdf_lacks_is_refused(tmp_path):
    path = mocap_only_config(tmp_path, markers={"list": [{"name": "a", "link": "wing", "xyz": [0, 0, 0]}]})
    with pytest.raises(WolfcalError, match=r"'markers.list\[0\].link' 'wing' \(marker a\) is not a link"):
        load_robot(path)


def test_no_camera_no_markers_is_refused(tmp_path):
    path = mocap_only_config(tmp_path)
    data = yaml.safe_load(path.read_text())
    data.pop("markers")
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(WolfcalError, match="needs a head camera"):
        load_robot_config(path)
