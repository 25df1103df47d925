"""wolfcal on a capture it did not make: another robot, other tag ids and sizes, another camera model, custom
topics, and a plain continuous ROS 2 recording written with mcap_ros2 directly (not wolfcal's writer)."""

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from mcap_ros2.writer import Writer as Ros2Writer
from typer.testing import CliRunner

from wolfcal.camera.model import CameraModel
from wolfcal.cli import app
from wolfcal.encoders import encoder_readings
from wolfcal.errors import WolfcalError
from wolfcal.geometry import invert_transform, rotation_angle
from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import load_robot
from wolfcal.sim.poses import tag_visibility
from wolfcal.sim.scene import SimScene

URDF = """<?xml version="1.0"?>
<robot name="pantilt">
  <link name="base"/><link name="pan_link"/><link name="tilt_link"/><link name="cam"/><link name="arm_link"/>
  <joint name="pan" type="revolute"><parent link="base"/><child link="pan_link"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="tilt" type="revolute"><parent link="pan_link"/><child link="tilt_link"/>
    <origin xyz="0.02 0 0.05" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-0.2" upper="1.5" effort="1" velocity="1"/>
  </joint>
  <joint name="cam_mount" type="fixed"><parent link="tilt_link"/><child link="cam"/>
    <origin xyz="0.03 0 0" rpy="-1.5708 0 -1.5708"/></joint>
  <joint name="arm" type="revolute"><parent link="base"/><child link="arm_link"/>
    <origin xyz="0.45 0 0.1" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>
"""

CONFIG = """name: pantilt
urdf: pantilt.urdf
base_link: base
camera: {frame: cam, topic: /pt/cam/image/compressed, info_topic: /pt/cam/info}
joint_states_topic: /pt/joints
tags:
  - {id: 7, family: tag36h11, size: 0.05, link: arm_link, xyz: [0.0, 0.0, 0.0], rpy: [0, 0, 0]}
  - {id: 9, family: tag36h11, size: 0.06, link: arm_link, xyz: [0.1, 0.0, 0.0], rpy: [0, 0, 0.3]}
"""

CAMERA = CameraModel(
    640, 480, [[330.0, 0, 319.5], [0, 331.0, 239.5], [0, 0, 1]], [0.05, -0.01, 0.002, 0.0], "equidistant", "pt"
)
TRUTH = Corrections(frames={"cam_mount": np.array([0.002, -0.001, 0.003, 0.03, -0.02, 0.01])})


def still_poses(robot, rng, n):
    """n true configurations (pan, tilt, arm) in which both tags are well visible."""
    found = []
    while len(found) < n:
        q = np.column_stack([rng.uniform(-0.3, 0.3, 500), rng.uniform(0.4, 1.1, 500), rng.uniform(-0.5, 0.5, 500)])
        visible = tag_visibility(robot, CAMERA, q, TRUTH, [7, 9], margin_px=15, min_size_px=15)
        found.extend(q[np.all(visible, axis=1)])
    return np.array(found[:n])


def write_recording(path: Path, robot, poses: np.ndarray) -> int:
    """50 Hz joint states, 4 Hz images, 1 Hz camera info; 0.5 s moving then 1 s still per pose. Returns the
    number of images with no motion within +-0.25 s (what the reader must keep)."""
    scene = SimScene(robot, TRUTH, CAMERA, seed=3, noise_sigma=1.5)
    ros = Ros2Writer(path.open("wb"))
    schemas = {name: ros.register_msgdef(name, MSGDEFS[name]) for name in (JOINT_STATE, COMPRESSED_IMAGE, CAMERA_INFO)}

    def header(t_ns):
        return {"stamp": {"sec": t_ns // 10**9, "nanosec": t_ns % 10**9}, "frame_id": "cam"}

    def q_at(t):  # piecewise: move 0.5 s from the previous pose, then hold 1 s
        k, phase = int(t // 1.5), t % 1.5
        previous = poses[max(k - 1, 0)]
        return previous + (poses[k] - previous) * min(phase / 0.5, 1.0)

    still_images = 0
    total = 1.5 * len(poses)
    for step in range(int(total * 50)):
        t = step / 50
        t_ns = 10**9 + int(round(t * 1e9))
        q = q_at(t)
        reading = encoder_readings(q[None], np.zeros(3))[0]
        ros.write_message(
            "/pt/joints",
            schemas[JOINT_STATE],
            {
                "header": header(t_ns),
                "name": robot.joint_names,
                "position": reading.tolist(),
                "velocity": [],
                "effort": [],
            },
            log_time=t_ns,
            publish_time=t_ns,
        )
        if step % 50 == 0:
            K = CAMERA.K.ravel().tolist()
            ros.write_message(
                "/pt/cam/info",
                schemas[CAMERA_INFO],
                {
                    "header": header(t_ns),
                    "height": 480,
                    "width": 640,
                    "distortion_model": "equidistant",
                    "d": CAMERA.D.tolist(),
                    "k": K,
                    "r": np.eye(3).ravel().tolist(),
                    "p": K[:3] + [0] + K[3:6] + [0] + K[6:] + [0],
                    "binning_x": 0,
                    "binning_y": 0,
                    "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
                },
                log_time=t_ns,
                publish_time=t_ns,
            )
        if step % 12 == 6:  # 4 Hz, between joint-state stamps
            t_image = t + 0.01
            image = scene.render_true(q_at(t_image))
            ok, png = cv2.imencode(".png", image)
            stamp = 10**9 + int(round(t_image * 1e9))
            ros.write_message(
                "/pt/cam/image/compressed",
                schemas[COMPRESSED_IMAGE],
                {"header": header(stamp), "format": "png", "data": png.tobytes()},
                log_time=stamp,
                publish_time=stamp,
            )
            phase, first, last = t_image % 1.5, t_image < 1.5, t_image >= total - 1.5
            still_images += (phase >= 0.75 or first) and (phase <= 1.25 or last)
    ros.finish()
    return still_images


def test_fit_on_a_plain_recording_of_another_robot(tmp_path):
    (tmp_path / "pantilt.urdf").write_text(URDF)
    (tmp_path / "robot.yaml").write_text(CONFIG)
    robot = load_robot(tmp_path / "robot.yaml")
    rng = np.random.default_rng(5)
    recording = tmp_path / "recording.mcap"
    still = write_recording(recording, robot, still_poses(robot, rng, 12))
    result = CliRunner().invoke(
        app,
        [
            "fit",
            str(recording),
            "--robot",
            str(tmp_path / "robot.yaml"),
            "--free",
            "camera",
            "--out",
            str(tmp_path / "fit"),
        ],
    )
    assert result.exit_code == 0, result.output
    data = yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())
    assert data["tags_used"] == [7, 9]
    head = data["blocks"][0]
    assert still - 2 <= head["n_frames"] <= still  # only frames taken while every joint was still
    assert head["n_samples"] == 12  # one sample per still pose: its frames averaged
    estimate = Corrections.from_dict(data["corrections"])
    q = np.zeros((1, 3))
    base = robot.model.link_poses(q, ["cam"], TRUTH, base="base")["cam"]
    fitted = robot.model.link_poses(q, ["cam"], estimate, base="base")["cam"]
    error = invert_transform(base) @ fitted
    # 640x480 camera, tags of 25-40 px: corner detection errors of a few hundredths of a pixel repeat across poses
    # and the tag mounts absorb them; the camera pose stays within a quarter degree and within 3 reported std.
    assert np.rad2deg(rotation_angle(error[:, :3, :3])[0]) < 0.25
    assert np.linalg.norm(error[0, :3, 3]) < 0.003
    for p in data["parameters"]:
        if p["name"].startswith("camera."):  # the correction of the URDF joint cam_mount
            assert p["urdf_joint"] == "cam_mount"
            true = TRUTH.frames["cam_mount"]["x y z rx ry rz".split().index(p["name"].split(".")[1])]
            assert abs(p["value"] - true) < 3 * p["std"], p["name"]


def test_simulation_ranges_come_from_the_config_alone(tmp_path):
    """Without `sampling_ranges` every joint is drawn within its URDF limits shrunk by 10 % at each end; with them,
    the listed joints within their ranges and the others at 0; simulated poses respect them."""
    from wolfcal.robot.ranges import sampling_bounds
    from wolfcal.sim.poses import random_visible_poses

    (tmp_path / "pantilt.urdf").write_text(URDF)
    (tmp_path / "robot.yaml").write_text(CONFIG)
    robot = load_robot(tmp_path / "robot.yaml")
    lo, hi = sampling_bounds(robot, "head")
    assert robot.joint_names == ["pan", "tilt", "arm"]
    np.testing.assert_allclose(lo, [-0.8, -0.03, -0.8])
    np.testing.assert_allclose(hi, [0.8, 1.33, 0.8])
    (tmp_path / "robot.yaml").write_text(CONFIG + "sampling_ranges:\n  head: {pan: [-0.3, 0.3], tilt: [0.4, 2.0]}\n")
    robot = load_robot(tmp_path / "robot.yaml")
    lo, hi = sampling_bounds(robot, "head")
    np.testing.assert_allclose(lo, [-0.3, 0.4, 0.0])
    np.testing.assert_allclose(hi, [0.3, 1.5, 0.0])  # tilt's URDF limit is 1.5
    q, visible = random_visible_poses(robot, CAMERA, TRUTH, 5, np.random.default_rng(0), margin_px=15, min_size_px=15)
    assert np.all((q >= lo) & (q <= hi)) and visible.any(axis=1).all()
    (tmp_path / "robot.yaml").write_text(CONFIG + "sampling_ranges:\n  head: {wrist: [-0.3, 0.3]}\n")
    with pytest.raises(WolfcalError, match=r"sampling_ranges.head.*wrist"):
        load_robot(tmp_path / "robot.yaml")
