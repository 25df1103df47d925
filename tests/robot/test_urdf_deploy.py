"""The deployed URDF is the fitted model on URDFs as people write them: joints named inside <transmission>, gazebo
blocks, commented-out joints, single quotes, joints without <origin>, mimic joints, CRLF line ends; and the robot
facts a config states instead of URDF edits (camera.axes, soles as {link, xyz}, floor.aim)."""

from __future__ import annotations

import difflib
from pathlib import Path

import numpy as np
import pytest
from deployed_urdf import deployed_error
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.errors import WolfcalError
from wolfcal.geometry import rotation_angle
from wolfcal.robot.aim import aim_joints
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import build_parameter_set
from wolfcal.robot.robot import load_robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf

ROBOTS = Path(__file__).resolve().parents[1] / "data" / "robots"
REPOSITORY_WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang" / "robot.yaml"

URDF = """<?xml version="1.0"?>
<!-- a hand-written robot: <joint name="r_hip" type="fixed"> in a comment is not a joint -->
<robot name="walker">
  <link name="base"/><link name="neck"/><link name="head"/><link name="cam"/>
  <link name="r_leg"/><link name="r_foot"/><link name="l_leg"/><link name="l_foot"/>
  <joint name="pan" type="revolute"><parent link="base"/><child link="neck"/>
    <origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name='tilt' type='revolute'>
    <parent link='neck'/><child link='head'/>
    <origin xyz='0.01 0 0.05' rpy='0 0 0'/>
    <axis xyz='0 1 0'/><limit lower='-0.2' upper='1.5' effort='1' velocity='1'/>
  </joint>
  <joint name="cam_mount" type="fixed"><parent link="head"/><child link="cam"/>
    <origin xyz="0.04 0 0.02" rpy="0 0.1 0"/></joint>
  <joint name="r_hip" type="revolute">
    <parent link="base"/>
    <child link="r_leg"/>
    <origin xyz="0 -0.05 0" rpy="0 0 0"/>
    <axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>
  </joint>
  <joint name="r_knee" type="revolute">
    <parent link="r_leg"/>
    <child link="r_foot"/>
    <axis xyz="0 1 0"/>
    <limit lower="-2" upper="0" effort="1" velocity="1"/>
  </joint>
  <joint name="l_hip" type="revolute">
    <parent link="base"/>
    <child link="l_leg"/>
    <origin xyz="0 0.05 0" rpy="0 0 0"/>
    <axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>
    <mimic joint="r_hip" multiplier="-0.8" offset="0.1"/>
  </joint>
  <joint name="l_knee" type="prismatic">
    <parent link="l_leg"/>
    <child link="l_foot"/>
    <origin xyz="0 0 0" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-0.1" upper="0.1" effort="1" velocity="1"/>
  </joint>
  <transmission name="r_hip_tran">
    <type>transmission_interface/SimpleTransmission</type>
    <joint name="r_hip"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
    <actuator name="r_hip_motor"><mechanicalReduction>1</mechanicalReduction></actuator>
  </transmission>
  <transmission name="l_knee_tran">
    <joint name="l_knee"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
  </transmission>
  <gazebo reference="r_foot"><mu1>0.9</mu1></gazebo>
  <gazebo><plugin name="mimic" filename="libmimic.so"><joint>l_hip</joint><mimicJoint>r_hip</mimicJoint></plugin>
  </gazebo>
</robot>
"""

CONFIG = """name: walker
urdf: walker.urdf
base_link: base
camera: {frame: cam, axes: body}
tags:
  - {id: 1, size: 0.05, link: r_foot, xyz: [0.1, 0, -0.02], side: right}
  - {id: 2, size: 0.05, link: l_foot, xyz: [0.1, 0, -0.02], side: left}
floor:
  soles: [{link: r_foot, xyz: [0.02, 0, -0.03]}, {link: l_foot, xyz: [0.02, 0, -0.03]}]
  standing: {}
"""
KEPT = ("<transmission", "<gazebo", "<!--", "<mimic", "'tilt'", "<joint>l_hip</joint>")


def walker(tmp_path: Path, newline: str = "\n", urdf: str = URDF) -> Path:
    (tmp_path / "walker.urdf").write_bytes(urdf.replace("\n", newline).encode())
    (tmp_path / "robot.yaml").write_text(CONFIG)
    return tmp_path / "robot.yaml"


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_deployed_urdfs_are_the_model_and_nothing_else_changes(tmp_path, newline):
    robot = load_robot(walker(tmp_path, newline))
    rng = np.random.default_rng(4)
    corrections = Corrections(
        offsets={j: float(rng.normal(0, 0.05)) for j in robot.joint_names},
        frames={robot.camera_joint: rng.normal(0, 0.01, 6), "r_hip": rng.normal(0, 0.01, 6)},
    )
    assert robot.camera_joint == "cam_optical" and robot.model.urdf_joint_of(robot.camera_joint) == "cam_mount"
    source = (tmp_path / "walker.urdf").read_bytes().decode()
    q = rng.uniform(-0.5, 0.5, size=(6, len(robot.joint_names)))
    for folded in (False, True):
        out = tmp_path / f"deployed_{folded}.urdf"
        write_calibrated_urdf(robot.config.urdf, robot.model, corrections, out, fold_offsets=folded)
        assert deployed_error(robot, corrections, out, folded, q) < 1e-9
        text = out.read_bytes().decode()
        for kept in KEPT:
            assert text.count(kept) == source.count(kept), kept
        assert text.count("\n") == text.count(newline), "line ends"
        a, b = source.splitlines(keepends=True), text.splitlines(keepends=True)
        for tag, _, _, j1, j2 in difflib.SequenceMatcher(None, a, b, autojunk=False).get_opcodes():
            if tag != "equal":  # only origins and calibrations of the robot's own joints
                assert all("<origin" in line or "<calibration" in line for line in b[j1:j2]), b[j1:j2]
        assert "<calibration" not in text.split("<transmission", 1)[1]
        assert ("<calibration" in text) != folded


def test_mimic_joint_moves_with_its_master_and_frees_it(tmp_path):
    """l_hip follows r_hip (-0.8 x + 0.1): the left leg preset frees r_hip's offset, and the model moves l_leg by
    -0.8 x r_hip's offset."""
    robot = load_robot(walker(tmp_path))
    assert robot.joint_names == ["pan", "tilt", "r_hip", "r_knee", "l_knee"]
    params = build_parameter_set(robot, "leg", {"head": [2]}, side="left")
    assert {"r_hip.offset", "l_knee.offset", "pan.offset", "tilt.offset"} <= set(params.names)
    assert "r_knee.offset" not in params.names
    q = np.zeros((1, 5))
    q[0, 2] = 0.3
    offset = Corrections(offsets={"r_hip": 0.05})
    T = robot.model.link_poses(q, ["l_leg"], offset, base="base")["l_leg"][0]
    angle = -0.8 * (0.3 + 0.05) + 0.1  # about +y
    np.testing.assert_allclose(T[:3, :3], [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                                           [-np.sin(angle), 0, np.cos(angle)]], atol=1e-12)  # fmt: skip


def test_a_mimic_joint_without_its_master_is_named(tmp_path):
    config = walker(tmp_path, urdf=URDF.replace('<mimic joint="r_hip"', '<mimic joint="r_hipp"'))
    with pytest.raises(WolfcalError, match=r"walker.urdf: joint 'l_hip' mimics joint 'r_hipp', which is not in"):
        load_robot(config)
    result = CliRunner().invoke(app, ["simulate", "--robot", str(config), "--out", str(tmp_path / "x.mcap")])
    assert result.exit_code == 2 and "'r_hipp'" in result.output and "Traceback" not in result.output


def test_body_axes_camera_link_is_the_optical_frame_it_once_had():
    """The published Wolfgang's `camera` link (body axes) with `camera.axes: body` gives the optical frame of the
    repository's hand-edited URDF (camera_optical_frame: rpy 3.14159 -1.5708 0 at 0.0432 0.08 -0.0235 in head,
    0.7 mm from the published link's origin)."""
    published, edited = load_robot(ROBOTS / "wolfgang" / "robot.yaml"), load_robot(REPOSITORY_WOLFGANG)
    q = np.random.default_rng(0).uniform(-0.5, 0.5, size=(5, len(published.joint_names)))
    q_edited = q[:, [published.joint_names.index(j) for j in edited.joint_names]]  # the same readings by name
    ours = published.model.link_poses(q, [published.config.head_camera().frame], base="base_link")
    theirs = edited.model.link_poses(q_edited, [edited.config.head_camera().frame], base="base_link")
    (T1,), (T2,) = ours.values(), theirs.values()
    assert np.max(rotation_angle(np.swapaxes(T1[:, :3, :3], 1, 2) @ T2[:, :3, :3])) < 1e-4
    assert np.max(np.linalg.norm(T1[:, :3, 3] - T2[:, :3, 3], axis=1)) < 0.001


def test_soles_aim_and_legs_come_from_the_config():
    g1 = load_robot(ROBOTS / "unitree_g1" / "robot.yaml")
    assert g1.feet == ("left_ankle_roll_link_sole", "right_ankle_roll_link_sole")
    sole, link = "left_ankle_roll_link_sole", "left_ankle_roll_link"
    T = g1.model.link_poses(np.zeros((1, len(g1.joint_names))), [sole, link])
    expected = [[1, 0, 0, 0.035], [0, 1, 0, 0], [0, 0, 1, -0.035], [0, 0, 0, 1]]
    np.testing.assert_allclose(np.linalg.inv(T[link][0]) @ T[sole][0], expected, atol=1e-12)
    assert aim_joints(g1) == ["waist_yaw_joint", "waist_pitch_joint"]  # floor.aim, not waist roll and pitch
    assert not g1.fixed_to_base("torso_link") and g1.off_the_legs("torso_link")  # behind the waist joints
    assert not g1.off_the_legs("left_ankle_roll_link")
    h1 = load_robot(ROBOTS / "unitree_h1" / "robot.yaml")
    assert aim_joints(h1) == ["torso_joint"]  # the default: the movable joints before the camera, here one


@pytest.mark.parametrize("name, wrong, right", [("wolfgang", "optical", "body"), ("nao", "body", "optical")])
def test_camera_axes_the_data_contradict_are_named(tmp_path, name, wrong, right):
    """A capture of the robot as it is, fitted with the camera's axes configured the other way: most tags project
    behind the camera, and the error says which convention the data fit."""
    folder = ROBOTS / name
    config = (folder / "robot.yaml").read_text()
    config = (
        config.replace("  axes: body\n", "")
        if wrong == "optical"
        else config.replace("  frame: CameraBottom_optical_frame", "  axes: body\n  frame: CameraBottom_optical_frame")
    )
    for item in folder.iterdir():
        if item.name != "robot.yaml":
            (tmp_path / item.name).symlink_to(item)
    (tmp_path / "robot.yaml").write_text(config)
    capture = tmp_path / "capture.mcap"
    result = CliRunner().invoke(
        app,
        [
            "simulate",
            "--robot",
            str(folder / "robot.yaml"),
            "--out",
            str(capture),
            "--samples",
            "4",
            "--binning",
            "4" if name == "wolfgang" else "1",
        ],
    )
    assert result.exit_code == 0, result.output
    result = CliRunner().invoke(
        app, ["fit", str(capture), "--robot", str(tmp_path / "robot.yaml"), "--out", str(tmp_path / "fit")]
    )
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert f"'camera.axes' is '{wrong}' but " in result.output and f"the data fit '{right}'" in result.output
    assert not (tmp_path / "fit").exists()


def test_config_naming_a_mimic_joint_is_told_its_master(tmp_path):
    config = walker(tmp_path)
    config.write_text(CONFIG + "sampling_ranges: {head: {l_hip: [-0.1, 0.1]}}\n")
    with pytest.raises(WolfcalError, match=r"'sampling_ranges.head' names mimic joint\(s\) \(l_hip follows r_hip"):
        load_robot(config)


def test_without_legs_named_only_links_fixed_to_the_base_are_off_the_legs(tmp_path):
    config = walker(tmp_path)
    config.write_text(CONFIG.replace(", side: right", "").replace(", side: left", "").split("floor:")[0])
    robot = load_robot(config)
    assert robot.leg_joints == () and robot.feet == ()
    assert robot.off_the_legs("base") and not robot.off_the_legs("r_foot") and not robot.off_the_legs("head")
