"""External cameras on the data path: robot config, capture files with several cameras (wolfcal's writer and a plain
ROS 2 recording written with mcap_ros2 directly), bad input, recovery, and the simulated tripod camera."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from mcap_ros2.writer import Writer as Ros2Writer
from typer.testing import CliRunner

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.cli import app
from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.external_view import external_tag_poses
from wolfcal.geometry import tag_corners
from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS, stamp_dict
from wolfcal.io.reader import read_capture, require_cameras
from wolfcal.io.recording import SAMPLE_TOLERANCE_NS, group_by_stamp
from wolfcal.io.recover import recover_capture
from wolfcal.io.truth import load_external_truth, truth_paths
from wolfcal.io.writer import CaptureWriter, camera_info_message
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import load_robot
from wolfcal.sim.faulty import rewrite_capture, with_camera_info, with_damaged_image
from wolfcal.vision.observe import detect_observations

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
T0 = 1_700_000_000_000_000_000  # [ns]
JOINTS = ["HeadPan", "HeadTilt", "RKnee", "LKnee"]


def write_config(tmp_path: Path, name: str = "robot.yaml", **changes) -> Path:
    """The Wolfgang config with absolute paths and top-level keys replaced (None removes a key)."""
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str(WOLFGANG / "wolfgang.urdf")
    data["camera"]["intrinsics"] = str(WOLFGANG / "basler_acA2040.yaml")
    for camera in data["external_cameras"]:
        camera["intrinsics"] = str(WOLFGANG / camera["intrinsics"])
    for key, value in changes.items():
        if value is None:
            data.pop(key, None)
        else:
            data[key] = value
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


TRIPOD = {"name": "tripod", "image_topic": "/tripod/image/compressed", "info_topic": "/tripod/camera_info",
          "intrinsics": str(WOLFGANG / "tripod_webcam.yaml")}  # fmt: skip


# --- robot config ---------------------------------------------------------------------------------------------
def test_config_reads_external_cameras_and_a_missing_head_camera(tmp_path):
    config = load_robot_config(WOLFGANG)
    (tripod,) = config.external_cameras
    assert (tripod.name, tripod.image_topic, tripod.info_topic) == (
        "tripod",
        "/tripod/image/compressed",
        "/tripod/camera_info",
    )
    assert tripod.intrinsics == WOLFGANG / "tripod_webcam.yaml" and config.camera_names == ["head", "tripod"]
    headless = load_robot(write_config(tmp_path, camera=None))
    assert headless.config.camera is None and headless.config.camera_names == ["tripod"]
    with pytest.raises(WolfcalError, match=r"robot\.yaml has no 'camera:'; the head-camera system needs one"):
        headless.config.head_camera()
    with pytest.raises(WolfcalError, match="no 'camera:'"):
        headless.camera_joint  # noqa: B018


@pytest.mark.parametrize(
    "cameras, message",
    [
        ([{**TRIPOD, "zoom": 2}], r"'external_cameras\[0\]' unknown key\(s\) zoom"),
        ([TRIPOD, {**TRIPOD, "image_topic": "/b/image", "info_topic": "/b/info"}], "used by another external camera"),
        ([{**TRIPOD, "name": "head"}], "must not be 'head'"),
        ([{**TRIPOD, "name": "tri pod"}], "letters, digits and '_'"),
        ([{**TRIPOD, "intrinsics": "nowhere.yaml"}], r"'external_cameras\[0\]\.intrinsics' file .*nowhere\.yaml"),
        ([{**TRIPOD, "image_topic": "/camera/image_proc/compressed"}], "each camera needs its own topics"),
        ([{"name": "tripod", "image_topic": "/t"}], r"missing key\(s\) info_topic"),
    ],
)
def test_config_refuses_bad_external_cameras(tmp_path, cameras, message):
    with pytest.raises(WolfcalError, match=message):
        load_robot_config(write_config(tmp_path, external_cameras=cameras))


def test_config_needs_some_camera(tmp_path):
    with pytest.raises(WolfcalError, match="needs a head camera"):
        load_robot_config(write_config(tmp_path, camera=None, external_cameras=None, markers=None, imu=None))


# --- own capture files with several cameras ------------------------------------------------------------------
def sample_images(i: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(i)
    head, tripod = rng.integers(0, 256, (192, 256), np.uint8), rng.integers(0, 256, (135, 240), np.uint8)
    return {HEAD_CAMERA: head, "tripod": tripod}


def write_two_camera_capture(path: Path, config, n: int, tripod_only: tuple[int, ...] = ()) -> None:
    head, tripod = load_camera_info(WOLFGANG / "basler_acA2040.yaml"), load_camera_info(WOLFGANG / "tripod_webcam.yaml")
    with CaptureWriter(path, config, {HEAD_CAMERA: (head, (8, 8)), "tripod": (tripod, (8, 8))}) as writer:
        for i in range(n):
            images = sample_images(i)
            if i in tripod_only:
                images.pop(HEAD_CAMERA)
            writer.add_sample(T0 + i * 10**9, JOINTS, np.full(4, 0.1 * i), None, images)


def test_two_camera_round_trip_keeps_each_camera_with_its_own_intrinsics(tmp_path):
    config = load_robot_config(WOLFGANG)
    path = tmp_path / "both.mcap"
    write_two_camera_capture(path, config, 4, tripod_only=(2,))
    capture = read_capture(path, config)
    assert capture.cameras == ["head", "tripod"] and len(capture.samples) == 4
    for i, sample in enumerate(capture.samples):
        expected = sample_images(i)
        assert set(sample.images) == ({"tripod"} if i == 2 else {"head", "tripod"})
        for name, image in sample.images.items():
            assert np.array_equal(image.decode(), expected[name])
        assert sample.images["tripod"].camera.width == 240 and sample.images["tripod"].camera.fx == 1400 / 8
    assert capture.samples[0].images["head"].camera.width == 256
    assert len(capture.samples_of("head")) == 3


def test_capture_of_an_external_camera_the_config_does_not_name_is_refused(tmp_path):
    config = load_robot_config(WOLFGANG)
    path = tmp_path / "both.mcap"
    write_two_camera_capture(path, config, 2)
    other = load_robot_config(write_config(tmp_path, external_cameras=None))
    with pytest.raises(WolfcalError, match=r"both\.mcap: topic /tripod/image/compressed holds images of external "
                       r"camera 'tripod' that the robot config .* does not name"):  # fmt: skip
        read_capture(path, other)
    result = CliRunner().invoke(app, ["fit", str(path), "--robot", str(tmp_path / "robot.yaml"), "--out",
                                      str(tmp_path / "fit")])  # fmt: skip
    assert result.exit_code != 0 and "/tripod/image/compressed" in result.output and "Traceback" not in result.output


def test_a_fit_of_the_head_camera_names_a_capture_without_head_images(tmp_path):
    config = load_robot_config(WOLFGANG)
    path = tmp_path / "tripod.mcap"
    tripod = load_camera_info(WOLFGANG / "tripod_webcam.yaml")
    with CaptureWriter(path, config, {"tripod": (tripod, (8, 8))}) as writer:
        writer.add_sample(T0, JOINTS, np.zeros(4), None, {"tripod": sample_images(0)["tripod"]})
    capture = read_capture(path, config)
    require_cameras([capture], ["tripod"], config)
    with pytest.raises(WolfcalError, match=r"tripod\.mcap: no images of camera 'head' \(topic "
                       r"/camera/image_proc/compressed\); the file holds images of 'tripod'"):  # fmt: skip
        require_cameras([capture], [HEAD_CAMERA], config)
    result = CliRunner().invoke(app, ["fit", str(path), "--system", "head", "--out", str(tmp_path / "fit")])
    assert result.exit_code != 0 and "no images of camera 'head'" in result.output


def test_recover_rescues_two_camera_samples(tmp_path):
    config = load_robot_config(WOLFGANG)
    path = tmp_path / "c.mcap"
    write_two_camera_capture(path, config, 3)
    data = path.read_bytes()
    torn = tmp_path / "torn.mcap.partial"
    torn.write_bytes(data[: int(len(data) * 0.8)])  # the summary and part of the last sample are lost
    count = recover_capture(torn, tmp_path / "rescued.mcap")
    samples = read_capture(tmp_path / "rescued.mcap", config).samples
    assert count == len(samples) >= 2 and all(set(s.images) == {"head", "tripod"} for s in samples)


def test_a_damaged_external_image_is_left_out_and_named_by_camera_index_and_time(tmp_path):
    config = load_robot_config(WOLFGANG)
    good, bad = tmp_path / "good.mcap", tmp_path / "bad.mcap"
    write_two_camera_capture(good, config, 6)
    rewrite_capture(good, bad, with_damaged_image("/tripod/image/compressed", 2))
    calls: list[tuple[int, int]] = []
    capture = read_capture(bad, config, progress=lambda done, total: calls.append((done, total)))
    assert calls[0] == (0, 30) and calls[-1] == (30, 30)  # joint states, and images and infos of both cameras
    assert capture.skipped == ["'tripod' image 3 of 6 (2.000 s after the first): png checksum error in its IDAT chunk"]
    assert [set(s.images) for s in capture.samples] == [{"head", "tripod"}] * 2 + [{"head"}] + [{"head", "tripod"}] * 3
    rewrite_capture(good, bad, lambda topic, i, m: with_damaged_image("/tripod/image/compressed", i)(topic, i, m))
    with pytest.raises(WolfcalError, match=r"bad\.mcap: 'tripod' image 1 of 6 .* \(and 5 more damaged\): 6 of 6 im"):
        read_capture(bad, config)


def test_external_camera_info_is_validated_naming_file_topic_and_field(tmp_path):
    config = load_robot_config(WOLFGANG)
    good, bad = tmp_path / "good.mcap", tmp_path / "bad.mcap"
    write_two_camera_capture(good, config, 2)
    nan_fy = [1400.0, 0, 960, 0, float("nan"), 540, 0, 0, 1]
    rewrite_capture(good, bad, with_camera_info("/tripod/camera_info", k=nan_fy))
    with pytest.raises(WolfcalError, match=r"bad\.mcap: CameraInfo on /tripod/camera_info: 'k\[4\]' is nan"):
        read_capture(bad, config)
    rewrite_capture(good, bad, with_camera_info("/tripod/camera_info", width=1000, height=1000))
    with pytest.raises(WolfcalError, match=r"bad\.mcap: CameraInfo on /tripod/camera_info: 'width'/'height' say "
                       r"125x125 px, the images are 240x135 px \(another aspect ratio\); record the camera_info of "
                       r"the images of camera 'tripod'"):  # fmt: skip
        read_capture(bad, config)


# --- a plain ROS 2 recording with two image streams, written by mcap_ros2 directly ----------------------------
RATE_HZ = 100
HEAD_TIMES = 0.105 + 0.25 * np.arange(16)  # [s] 4 Hz
TRIPOD_TIMES = HEAD_TIMES + np.where(np.arange(16) % 4 == 3, 0.06, 0.008)  # 8 ms after, every 4th 60 ms after
MOVE = (1.65, 2.2)  # [s] the joints move; still before and after


def write_recording(path: Path, config, nan_at: float | None = None, nan_span: float = 0.03) -> None:
    t = np.arange(int(4.2 * RATE_HZ)) / RATE_HZ
    q = np.outer(np.clip((t - MOVE[0]) / (MOVE[1] - MOVE[0]), 0, 1), [0.3, -0.2, 0.5, 0.4])
    head_info = camera_info_message(load_camera_info(WOLFGANG / "basler_acA2040.yaml"), (8, 8), 0, "cam")
    tripod_info = camera_info_message(load_camera_info(WOLFGANG / "tripod_webcam.yaml"), (8, 8), 0, "tripod")
    with path.open("wb") as handle:
        writer = Ros2Writer(handle)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        events = [(s, "joints", i) for i, s in enumerate(t)]
        events += [(s, "head", i) for i, s in enumerate(HEAD_TIMES)]
        events += [(s, "tripod", i) for i, s in enumerate(TRIPOD_TIMES)]
        for s, kind, i in sorted(events):
            stamp = T0 + int(round(s * 1e9))
            header = {"stamp": stamp_dict(stamp), "frame_id": ""}
            if kind == "joints":
                position = q[i].tolist()
                if nan_at is not None and abs(s - nan_at) < nan_span:
                    position[2] = float("nan")
                message = {"header": header, "name": JOINTS, "position": position, "velocity": [], "effort": []}
                writer.write_message(config.joint_states_topic, schemas[JOINT_STATE], message, log_time=stamp)
                continue
            image_topic, info_topic = config.camera_topics(kind)
            shape = (192, 256) if kind == "head" else (135, 240)
            data = cv2.imencode(".png", np.random.default_rng(i).integers(0, 256, shape, np.uint8))[1].tobytes()
            writer.write_message(image_topic, schemas[COMPRESSED_IMAGE], {"header": header, "format": "png",
                                                                           "data": data}, log_time=stamp)  # fmt: skip
            info = dict(head_info if kind == "head" else tripod_info, header=header)
            writer.write_message(info_topic, schemas[CAMERA_INFO], info, log_time=stamp)
        writer.finish()


def test_recording_pairs_each_stream_and_groups_frames_within_20_ms(tmp_path):
    config = load_robot_config(WOLFGANG)
    path = tmp_path / "rosbag.mcap"
    write_recording(path, config)
    capture = read_capture(path, config)

    def still(s: float) -> bool:  # no motion within +-0.25 s
        return s + 0.25 < MOVE[0] or s - 0.25 > MOVE[1]

    together = [k for k in range(16) if still(HEAD_TIMES[k]) and still(TRIPOD_TIMES[k]) and k % 4 != 3]
    apart = [k for k in range(16) if still(HEAD_TIMES[k]) and still(TRIPOD_TIMES[k]) and k % 4 == 3]
    alone = [k for k in range(16) if still(HEAD_TIMES[k]) != still(TRIPOD_TIMES[k])]
    assert len(together) >= 8 and len(apart) >= 2
    assert len(capture.samples) == len(together) + 2 * len(apart) + len(alone)
    stamps = {round((s.stamp_ns - T0) / 1e9, 3): s for s in capture.samples}
    for k in together:
        sample = stamps[round(HEAD_TIMES[k], 3)]
        assert set(sample.images) == {"head", "tripod"}
        assert sample.images["tripod"].stamp_ns - sample.stamp_ns == 8_000_000
    for k in apart:
        assert set(stamps[round(HEAD_TIMES[k], 3)].images) == {"head"}
        assert set(stamps[round(TRIPOD_TIMES[k], 3)].images) == {"tripod"}
    sample = capture.samples[0]
    assert sample.images["tripod"].camera.width == 240 and sample.images["head"].camera.width == 256
    assert np.array_equal(sample.images["tripod"].decode().shape, (135, 240))
    assert any("'tripod' image" in reason and "not still" in reason for reason in capture.skipped)


def test_recording_with_a_few_nan_joint_readings_leaves_them_out_with_a_warning(tmp_path):
    config = load_robot_config(WOLFGANG)
    clean, path = tmp_path / "clean.mcap", tmp_path / "rosbag.mcap"
    write_recording(clean, config)
    write_recording(path, config, nan_at=1.0)
    capture = read_capture(path, config)
    assert capture.skipped[0].startswith(
        f"{path}: 5 of 420 joint state(s) on /joint_states hold NaN or infinite positions (RKnee 5x)"
    )
    assert "left out" in capture.skipped[0]
    assert all(np.all(np.isfinite(s.positions)) for s in capture.samples)
    assert [s.stamp_ns for s in capture.samples] == [s.stamp_ns for s in read_capture(clean, config).samples]


def test_recording_with_many_nan_joint_readings_is_refused(tmp_path):
    config = load_robot_config(WOLFGANG)
    path = tmp_path / "rosbag.mcap"
    write_recording(path, config, nan_at=1.0, nan_span=0.6)  # 120 of 420 joint states
    with pytest.raises(WolfcalError, match=r"rosbag\.mcap: 1\d\d of 420 joint state\(s\) on /joint_states hold NaN "
                       r"or infinite positions \(RKnee 1\d\dx\): more than 20%"):  # fmt: skip
        read_capture(path, config)


def test_group_by_stamp_takes_one_frame_per_camera():
    ms = 1_000_000
    groups = group_by_stamp([0, 5 * ms, 10 * ms, 30 * ms, 31 * ms], ["a", "b", "a", "b", "a"], SAMPLE_TOLERANCE_NS)
    assert groups == [[0, 1], [2, 3], [4]]


# --- the simulated tripod camera -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tripod_capture(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "ext.mcap"
    result = CliRunner().invoke(app, ["simulate", "--robot", str(WOLFGANG), "--out", str(out), "--system",
                                      "external", "--samples", "5", "--offsets", "legs", "--binning", "2", "--seed",
                                      "3"])  # fmt: skip
    assert result.exit_code == 0, result.output
    return out


def test_simulated_tripod_images_show_the_tags_where_the_truth_puts_them(tripod_capture):
    robot = load_robot(WOLFGANG)
    truth = load_corrections(truth_paths(tripod_capture)[0], key="truth")
    assert set(truth.offsets) == set(robot.camera_and_leg_joints()) - {"HeadPan", "HeadTilt"}
    assert all(np.linalg.norm(v[:3]) < 0.01 for v in truth.tags.values())  # tag mounts off by about 1 mm
    T_base_camera = load_external_truth(truth_paths(tripod_capture)[0])["tripod"]
    distance = np.linalg.norm(T_base_camera[:2, 3])
    assert 1.0 <= distance <= 2.0 and T_base_camera[0, 2] < 0  # in front, looking back at the robot
    capture = read_capture(tripod_capture, robot.config)
    observations, _ = detect_observations(capture.samples, robot)
    tripod = observations["tripod"]
    assert set(observations) == {"tripod"} and tripod.n_samples == 5
    frames = Corrections(frames=truth.frames, tags=truth.tags)
    q_true = tripod.q_measured + truth.offset_vector(robot.joint_names)
    for s in range(tripod.n_samples):
        tags = tripod.tags_in_sample(s)
        assert 42 in tags and ({43, 44} & set(tags))
        T_camera_tag = external_tag_poses(robot, T_base_camera, q_true[s : s + 1], frames, tags)[0]
        for k, tag in enumerate(tags):
            corners = tag_corners(robot.config.tag(tag).size) @ T_camera_tag[k, :3, :3].T + T_camera_tag[k, :3, 3]
            rows = (tripod.sample_index == s) & (tripod.tag_ids == tag)
            error = np.linalg.norm(tripod.camera.project(corners) - tripod.uv[rows], axis=1)
            assert error.max() < 0.6, (s, tag, error)  # quantisation moves a foot tag by < 0.1 px here


def test_simulate_with_a_config_without_head_camera_and_a_given_placement(tmp_path):
    config = write_config(tmp_path, camera=None)
    out = tmp_path / "headless.mcap"
    placement = "1.4,0.1,0.3,0,0.2,3.1416"
    args = ["--system", "external", "--samples", "2", "--binning", "4", "--placement", placement]
    result = CliRunner().invoke(app, ["simulate", "--robot", str(config), "--out", str(out), *args])
    assert result.exit_code == 0, result.output
    T_base_camera = load_external_truth(truth_paths(out)[0])["tripod"]
    np.testing.assert_allclose(T_base_camera[:3, 3], [1.4, 0.1, 0.3])
    np.testing.assert_allclose(T_base_camera[:3, 2], [-np.cos(0.2), 0, -np.sin(0.2)], atol=1e-4)  # looks back, down
    result = CliRunner().invoke(app, ["simulate", "--robot", str(config), "--out", str(tmp_path / "h.mcap")])
    assert result.exit_code != 0 and "has no 'camera:'; the head-camera system needs one" in result.output
    result = CliRunner().invoke(app, ["fit", str(out), "--robot", str(config), "--out", str(tmp_path / "fit")])
    assert result.exit_code != 0 and "has no 'camera:'" in result.output and "Traceback" not in result.output
    shutil.rmtree(tmp_path / "fit", ignore_errors=True)
