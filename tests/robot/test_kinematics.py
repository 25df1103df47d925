"""Forward kinematics against yourdfpy's own, corrections, and config errors that name file and key."""

from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from wolfcal.errors import WolfcalError
from wolfcal.geometry import exp_so3, log_so3, matrix_to_rpy, rpy_to_matrix, transform_from_twist_params
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import load_robot

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang" / "robot.yaml"


def random_q(model, n, rng):
    lo = np.array([model.joints[j].lower for j in model.actuated_joint_names])
    hi = np.array([model.joints[j].upper for j in model.actuated_joint_names])
    return rng.uniform(lo, hi, size=(n, len(lo)))


def test_fk_matches_yourdfpy_on_random_configurations(robot):
    rng = np.random.default_rng(1)
    model = robot.model
    urdf = yourdfpy.URDF.load(str(robot.config.urdf), load_meshes=False)
    links = ["camera_optical_frame", "r_sole", "l_sole", "r_lower_arm", "l_toe", "head"]
    q = random_q(model, 12, rng)
    poses = model.link_poses(q, links, base="base_link")
    for i in range(len(q)):
        urdf.update_cfg(dict(zip(model.actuated_joint_names, q[i])))
        for link in links:
            np.testing.assert_allclose(poses[link][i], urdf.get_transform(link, "base_link"), atol=1e-9)


def test_urdf_joints_read_as_yourdfpy_reads_them(robot):
    urdf = yourdfpy.URDF.load(str(robot.config.urdf), load_meshes=False, build_scene_graph=False)
    assert robot.model.name == urdf.robot.name and len(robot.model.joints) == len(urdf.robot.joints)
    for j in urdf.robot.joints:
        ours = robot.model.joints[j.name]
        assert (ours.type, ours.parent, ours.child) == (j.type, j.parent, j.child)
        np.testing.assert_allclose(ours.T_parent_origin, np.eye(4) if j.origin is None else j.origin, atol=1e-12)
        if j.axis is not None:
            np.testing.assert_allclose(ours.axis, j.axis / np.linalg.norm(j.axis), atol=1e-12)
        if j.type in ("revolute", "prismatic") and j.limit is not None:
            assert (ours.lower, ours.upper) == (j.limit.lower, j.limit.upper)
        assert (ours.mimic is None) == (j.mimic is None)


def test_published_straight_leg_check(robot):
    q = np.zeros((1, len(robot.joint_names)))
    q[0, robot.model.column("RKnee")] = -0.2618
    q[0, robot.model.column("LKnee")] = 0.2618
    poses = robot.model.link_poses(q, ["camera_optical_frame", "r_sole", "l_sole"], base="base_link")
    np.testing.assert_allclose(poses["camera_optical_frame"][0, :3, 3], [0.0697, 0.0, 0.3385], atol=2e-4)
    for sole in ("r_sole", "l_sole"):
        np.testing.assert_allclose(poses[sole][0, 2, 3], -0.4333, atol=3e-4)
        np.testing.assert_allclose(poses[sole][0, 0, 3], 0.040, atol=1e-3)


def test_offset_equals_shifted_joint_value(robot):
    rng = np.random.default_rng(2)
    model = robot.model
    q = random_q(model, 5, rng)
    corr = Corrections(offsets={"RKnee": 0.03, "HeadTilt": -0.02})
    shifted = q.copy()
    shifted[:, model.column("RKnee")] += 0.03
    shifted[:, model.column("HeadTilt")] -= 0.02
    a = model.link_poses(q, ["r_sole", "camera_optical_frame"], corr)
    b = model.link_poses(shifted, ["r_sole", "camera_optical_frame"])
    for link in a:
        np.testing.assert_allclose(a[link], b[link], atol=1e-12)


def test_frame_correction_applies_in_child_frame(robot):
    q = np.zeros((1, len(robot.joint_names)))
    delta = np.array([0.01, -0.02, 0.003, 0.05, -0.01, 0.02])
    joint = robot.camera_joint
    nominal = robot.model.link_poses(q, ["camera_optical_frame", "head"])
    corrected = robot.model.link_poses(q, ["camera_optical_frame"], Corrections(frames={joint: delta}))
    expected = nominal["camera_optical_frame"][0] @ transform_from_twist_params(delta)
    np.testing.assert_allclose(corrected["camera_optical_frame"][0], expected, atol=1e-12)


def test_rotation_helpers_round_trip():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(50, 3))
    v *= (rng.uniform(0, 3.1, size=50) / np.linalg.norm(v, axis=1))[:, None]
    np.testing.assert_allclose(log_so3(exp_so3(v)), v, atol=1e-9)
    rpy = rng.uniform([-3, -1.5, -3], [3, 1.5, 3], size=(50, 3))
    np.testing.assert_allclose(rpy_to_matrix(matrix_to_rpy(rpy_to_matrix(rpy))), rpy_to_matrix(rpy), atol=1e-12)


def write_config(tmp_path, text):
    (tmp_path / "robot.urdf").write_text(Path(CONFIG.parent / "wolfgang.urdf").read_text())
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    return path


BASE = """name: t
urdf: robot.urdf
base_link: base_link
camera: {frame: camera_optical_frame}
tags:
  - {id: 43, size: 0.08, link: r_foot}
"""


@pytest.mark.parametrize(
    "text, words",
    [
        (BASE + "colour: red\n", ["robot.yaml", "unknown key", "colour"]),
        (BASE.replace("robot.urdf", "missing.urdf"), ["'urdf'", "missing.urdf", "not found"]),
        (BASE.replace("r_foot", "r_hoof"), ["tags[0].link", "r_hoof"]),
        (BASE.replace("frame: camera_optical_frame", "frame: eye"), ["camera.frame", "eye"]),
        (BASE.replace("size: 0.08", "size: -1"), ["tags[0].size", "positive"]),
        (BASE + "servos: {ids: {Tail: 3}}\n", ["servos.ids", "Tail"]),
        (
            BASE.replace("frame: camera_optical_frame", "frame: camera_optical_frame, name: tag43"),
            ["'camera'", "tag43", "tag<id>"],
        ),
        (
            BASE + "external_cameras: [{name: camera, image_topic: /t/i, info_topic: /t/c}]\n",
            ["camera.name", "external camera's name"],
        ),
    ],
)
def test_config_errors_name_file_and_key(tmp_path, text, words):
    path = write_config(tmp_path, text)
    with pytest.raises(WolfcalError) as info:
        load_robot(path)
    for word in words:
        assert word in str(info.value)


@pytest.mark.parametrize("fold_offsets", [False, True])
def test_calibrated_urdf_round_trip(robot, tmp_path, fold_offsets):
    """A calibrated URDF read back by an independent reader (yourdfpy, which takes `<calibration rising>` as the
    encoder offset q_model = q_measured + rising) gives the corrected model's kinematics to 1e-9."""
    from wolfcal.robot.urdf_writer import write_calibrated_urdf

    rng = np.random.default_rng(5)
    model = robot.model
    truth = Corrections(
        offsets={"RKnee": 0.031, "HeadTilt": -0.017, "LAnklePitch": 0.009},
        frames={
            robot.camera_joint: np.array([0.004, -0.002, 0.003, 0.02, -0.05, 0.01]),
            "RKnee": np.array([0.001, 0.0, -0.002, 0.0, 0.01, 0.0]),
        },
    )
    out = tmp_path / "calibrated.urdf"
    write_calibrated_urdf(robot.config.urdf, model, truth, out, fold_offsets=fold_offsets)
    urdf = yourdfpy.URDF.load(str(out), load_meshes=False)
    rising = {j.name: j.calibration.rising for j in urdf.robot.joints if j.calibration is not None}
    assert rising == ({} if fold_offsets else truth.offsets)
    links = ["camera_optical_frame", "r_sole", "l_sole", "head"]
    q = random_q(model, 8, rng)
    expected = model.link_poses(q, links, truth, base="base_link")
    for i in range(len(q)):
        urdf.update_cfg({j: q[i, model.column(j)] + rising.get(j, 0.0) for j in model.actuated_joint_names})
        for link in links:
            np.testing.assert_allclose(urdf.get_transform(link, "base_link"), expected[link][i], atol=1e-9)


def test_camera_parameters_take_the_configured_name(tmp_path):
    """The head camera's pose parameters are named after `camera.name` (default `camera`); they still correct the
    fixed joint above the optical frame."""
    from wolfcal.robot.parameters import build_parameter_set

    named = BASE.replace("frame: camera_optical_frame", "frame: camera_optical_frame, name: eye")
    for text, prefix in ((BASE, "camera"), (named, "eye")):
        robot = load_robot(write_config(tmp_path, text))
        params = build_parameter_set(robot, "camera", {"head": [43]})
        frames = [p for p in params.parameters if p.kind == "frame"]
        assert [p.name for p in frames] == [f"{prefix}.{c}" for c in ("x", "y", "z", "rx", "ry", "rz")]
        assert {p.target for p in frames} == {"camera_optical_frame_uncalibrated_frame"}
