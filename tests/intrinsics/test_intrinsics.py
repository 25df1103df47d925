"""wolfcal intrinsics / board / tags against rendered views of a known camera."""

from __future__ import annotations

import re
import struct
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.cli import app
from wolfcal.errors import WolfcalError
from wolfcal.intrinsics.calibrate import calibrate_views
from wolfcal.intrinsics.coverage import ViewSelector, empty_regions
from wolfcal.intrinsics.detect import Detection, detect_board
from wolfcal.intrinsics.live import collect_views
from wolfcal.intrinsics.synthetic import example_camera, random_board_poses, render_view, true_corners
from wolfcal.vision.board import Board, make_board
from wolfcal.vision.printing import PT_PER_M, board_sheet, parse_ids, sheet_pdf, sheet_png, tag_sheets

CAMERA = example_camera(640, 480)
BOARD = Board(9, 6, 0.025)
N_VIEWS = 16


def render_views(camera: CameraModel, board: Board, poses: list[np.ndarray], seed: int, blur: float = 1.0):
    """Rendered views (noise 2 grey levels, motion blur `blur` px), each with its own seeded generator."""
    rngs = [np.random.default_rng([seed, i]) for i in range(len(poses))]
    with ThreadPoolExecutor(2) as pool:
        return list(pool.map(lambda a: render_view(camera, board, a[0], a[1], 2.0, blur), zip(poses, rngs)))


@pytest.fixture(scope="module")
def views() -> tuple[list[np.ndarray], list[np.ndarray]]:
    poses = random_board_poses(CAMERA, BOARD, N_VIEWS, np.random.default_rng(7))
    return poses, render_views(CAMERA, BOARD, poses, seed=7)


@pytest.fixture(scope="module")
def image_folder(tmp_path_factory, views) -> Path:
    folder = tmp_path_factory.mktemp("views")
    for i, image in enumerate(views[1]):
        cv2.imwrite(str(folder / f"view_{i:02d}.png"), image)
    return folder


def _errors(camera: CameraModel) -> dict[str, float]:
    return {k: getattr(camera, k) - getattr(CAMERA, k) for k in ("fx", "fy", "cx", "cy")}


def test_detected_corners_match_rendered_truth(views):
    poses, images = views
    errors = []
    for T, image in zip(poses, images, strict=True):
        found = detect_board(image, BOARD)
        assert isinstance(found, Detection)
        truth = true_corners(CAMERA, BOARD, T)
        e1 = np.linalg.norm(found.corners - truth, axis=1)
        e2 = np.linalg.norm(found.corners[::-1] - truth, axis=1)  # a symmetric board may be read from either end
        errors.append(e1 if e1.mean() < e2.mean() else e2)
    rms = np.sqrt(np.mean(np.concatenate(errors) ** 2))
    assert rms < 0.12, f"corner RMS {rms:.3f} px"


def test_calibration_recovers_known_camera_within_its_uncertainty(views):
    detections = [detect_board(image, BOARD, str(i)) for i, image in enumerate(views[1])]
    result = calibrate_views([d for d in detections if isinstance(d, Detection)], BOARD, "plumb_bob", min_views=10)
    errors = _errors(result.camera)
    assert abs(errors["fx"]) / CAMERA.fx < 0.002 and abs(errors["fy"]) / CAMERA.fy < 0.002
    assert abs(errors["cx"]) < 1.0 and abs(errors["cy"]) < 1.0
    for name, error in errors.items():  # the reported 1-sigma covers the true error (3-sigma bound)
        assert abs(error) < 3 * result.std[name], f"{name}: error {error:.3f} vs 1-sigma {result.std[name]:.3f}"
        assert result.std[name] < 1.0
    assert result.rms_per_axis == pytest.approx(result.rms_per_point / np.sqrt(2))
    assert result.rms_per_point < 0.2 and not result.rejected


def test_outlier_view_is_rejected_and_named(views):
    detections = [detect_board(image, BOARD, f"v{i}") for i, image in enumerate(views[1])]
    good = [d for d in detections if isinstance(d, Detection)]
    bad_corners = good[3].corners + np.random.default_rng(0).normal(0, 2.0, good[3].corners.shape)
    bad = Detection("smeared.png", bad_corners, good[3].ids, good[3].image_size)
    result = calibrate_views(good[:3] + [bad] + good[4:], BOARD, min_views=10)
    assert [v.name for v, _ in result.rejected] == ["smeared.png"]
    assert abs(_errors(result.camera)["fx"]) / CAMERA.fx < 0.002


def test_too_few_views_is_a_clear_error(views):
    detections = [detect_board(image, BOARD) for image in views[1][:4]]
    with pytest.raises(WolfcalError, match="only 4 views.*at least 10"):
        calibrate_views(detections, BOARD, min_views=10)


def test_cli_calibrates_a_folder_lists_failures_and_writes_the_report(image_folder, tmp_path):
    inputs = tmp_path / "in"
    inputs.mkdir()
    for p in image_folder.iterdir():
        (inputs / p.name).write_bytes(p.read_bytes())
    (inputs / "broken.png").write_bytes(b"not an image")
    cv2.imwrite(str(inputs / "empty.png"), np.full((480, 640), 128, np.uint8))
    out = tmp_path / "camera_info.yaml"
    result = CliRunner().invoke(
        app, ["intrinsics", str(inputs), "--board", "9x6", "--square", "0.025", "--out", str(out), "--name", "head"]
    )
    assert result.exit_code == 0, result.output
    assert re.search(r"broken\.png: not a readable image", result.output)
    assert re.search(r"empty\.png: no 9x6 checkerboard found", result.output)
    assert "RMS per point" in result.output and "per axis" in result.output
    camera = load_camera_info(out)
    assert camera.name == "head" and (camera.width, camera.height) == (640, 480)
    assert abs(camera.fx - CAMERA.fx) / CAMERA.fx < 0.002 and abs(camera.cx - CAMERA.cx) < 1.0
    report = tmp_path / "camera_info_report"
    for name in ("summary.md", "intrinsics.yaml", "per_view.csv", "detections.yaml", "residual_histogram.png",
                 "per_view_errors.png", "corner_map.png", "distortion_field.png"):  # fmt: skip
        assert (report / name).is_file(), name
    summary = (report / "summary.md").read_text()
    assert "per point" in summary and "broken.png" in summary
    stds = yaml.safe_load((report / "intrinsics.yaml").read_text())["parameters"]
    assert set(stds) == {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"}


@pytest.mark.slow
def test_cli_wrong_board_size_names_the_size_found_and_leaves_nothing_behind(image_folder, tmp_path):
    out = tmp_path / "camera_info.yaml"
    args = ["intrinsics", str(image_folder / "view_0*.png"), "--board", "8x6", "--square", "0.025", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "found a 9x6 checkerboard" in result.output and "--board 9x6" in result.output
    assert sorted(tmp_path.iterdir()) == [], "a failed run leaves no camera_info and no report folder"
    assert result.output.count("no 8x6 checkerboard found") == 10  # each view's reason, on the terminal
    args[3] = "9x6"
    retried = CliRunner().invoke(app, args)  # the retry is not blocked by anything of the failed run
    assert retried.exit_code == 0, retried.output
    assert out.is_file() and (tmp_path / "camera_info_report" / "detections.yaml").is_file()


def test_cli_missing_input_and_bad_board_text(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["intrinsics", str(tmp_path / "nope"), "--board", "9x6", "--square", "0.025",
                                 "--out", str(tmp_path / "c.yaml")])  # fmt: skip
    assert result.exit_code != 0 and "no such file or folder" in result.output
    result = runner.invoke(app, ["intrinsics", "x", "--board", "9by6", "--square", "0.025", "--out", "c.yaml"])
    assert result.exit_code != 0 and "COLSxROWS" in result.output


def test_empty_image_regions_are_named():
    left_only = Detection("a", np.array([[10.0, 10.0], [100.0, 300.0], [50.0, 470.0]]), np.arange(3), (640, 480))
    assert set(empty_regions([left_only], (640, 480))) == {"top", "top-right", "centre", "right", "bottom",
                                                           "bottom-right"}  # fmt: skip


def _stream(poses: list[np.ndarray], images: list[np.ndarray]):
    """A board held still for 3 frames at each pose, with one frame in motion between poses."""
    for i, image in enumerate(images):
        shifted = np.roll(image, 12, axis=1)  # the board in motion
        yield f"f{i}m", shifted
        for k in range(3):
            yield f"f{i}s{k}", image


@pytest.mark.slow
def test_live_selection_keeps_still_distinct_views_and_stops_when_covered(tmp_path):
    rng = np.random.default_rng(3)
    poses = random_board_poses(CAMERA, BOARD, 30, rng, max_tilt_deg=50, fill=(0.3, 0.95))
    images = render_views(CAMERA, BOARD, poses, seed=3, blur=0.0)
    selector = ViewSelector(BOARD)
    seen = []
    frames = ((name, image) for name, image in _stream(poses, images) if not seen.append(name))
    complete = collect_views(frames, selector, min_views=10, save_dir=tmp_path / "kept")
    assert all("s" in v.name.split("_")[-1] or v.name.endswith(".png") for v in selector.kept)
    assert complete and len(selector.kept) >= 10 and len(seen) < 4 * len(images)
    assert len(list((tmp_path / "kept").glob("view_*.png"))) == len(selector.kept)
    params = np.array(selector.coverage.params)
    assert all(np.abs(p - q).sum() > 0.2 for i, p in enumerate(params) for q in params[:i])


def test_cli_video_input(views, tmp_path):
    video = tmp_path / "board.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (640, 480), False)
    for _, image in _stream(*views):
        writer.write(image)
    writer.release()
    out = tmp_path / "c.yaml"
    args = ["intrinsics", str(video), "--board", "9x6", "--square", "0.025", "--out", str(out), "--save-frames",
            str(tmp_path / "kept")]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert abs(load_camera_info(out).fx - CAMERA.fx) / CAMERA.fx < 0.005
    assert len(list((tmp_path / "kept").glob("*.png"))) >= 10


@pytest.mark.slow
@pytest.mark.parametrize("legacy", [False, True])
def test_charuco_views_calibrate(legacy):
    board = make_board("6x5", 0.03, "5X5_100", 0.022, legacy)  # 7x6 squares: even rows, the layouts differ
    poses = random_board_poses(CAMERA, board, 12, np.random.default_rng(11), max_tilt_deg=40)
    images = render_views(CAMERA, board, poses, seed=11)
    found = [detect_board(image, board, str(i)) for i, image in enumerate(images)]
    detections = [d for d in found if isinstance(d, Detection)]
    assert len(detections) >= 11
    errors = [d.corners - true_corners(CAMERA, board, T)[d.ids] for d, T in zip(found, poses, strict=True)
              if isinstance(d, Detection)]  # fmt: skip
    assert np.sqrt(np.mean(np.sum(np.concatenate(errors) ** 2, axis=1))) < 0.15
    other = make_board("6x5", 0.03, "5X5_100", 0.022, not legacy)
    assert not isinstance(detect_board(images[0], other), Detection)  # the wrong layout reads nothing
    result = calibrate_views(detections, board, min_views=10)
    assert abs(result.camera.fx - CAMERA.fx) / CAMERA.fx < 0.004


@pytest.mark.slow
def test_equidistant_model():
    fisheye = CameraModel(640, 480, [[300.0, 0, 322.0], [0, 300.5, 236.0], [0, 0, 1]], [0.05, -0.02, 0.01, 0.0],
                          "equidistant")  # fmt: skip
    poses = random_board_poses(fisheye, BOARD, 14, np.random.default_rng(5), fill=(0.45, 0.9))
    images = render_views(fisheye, BOARD, poses, seed=5, blur=0.0)
    detections = [d for d in (detect_board(im, BOARD) for im in images) if isinstance(d, Detection)]
    result = calibrate_views(detections, BOARD, "equidistant", min_views=10)
    assert abs(result.camera.fx - 300.0) / 300.0 < 0.005 and abs(result.camera.cx - 322.0) < 1.5
    assert set(result.std) == {"fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"}


def _pdf_objects(pdf: bytes) -> dict[int, bytes]:
    """Objects by number, checked against the xref table's offsets."""
    start = int(re.search(rb"startxref\n(\d+)", pdf)[1])
    table = pdf[start:].split(b"trailer")[0].split(b"\n")[3:]
    offsets = [int(line[:10]) for line in table if line.strip()]
    objects = {}
    for number, offset in enumerate(offsets, start=1):
        assert pdf[offset:].startswith(f"{number} 0 obj".encode())
        objects[number] = pdf[offset : pdf.index(b"endobj", offset)]
    return objects


def test_board_pdf_places_the_board_at_exact_size():
    board = Board(9, 6, 0.025)
    pdf = sheet_pdf(board_sheet(board, "a4"))
    objects = _pdf_objects(pdf)
    media = [float(x) for x in re.search(rb"MediaBox \[([^\]]+)\]", objects[3])[1].split()]
    assert media[2:] == pytest.approx([0.297 * PT_PER_M, 0.210 * PT_PER_M], abs=0.01)  # A4 landscape
    content = zlib.decompress(objects[4].split(b"stream\n", 1)[1].rsplit(b"\nendstream", 1)[0]).decode()
    w, h = (float(x) for x in re.search(r"q ([\d.]+) 0 0 ([\d.]+)", content).groups())
    assert (w, h) == pytest.approx((10 * 0.025 * PT_PER_M, 7 * 0.025 * PT_PER_M), abs=1e-3)
    assert "must measure 100 mm" in content


def test_board_png_has_its_density_and_a_readable_board(tmp_path):
    sheet = board_sheet(Board(9, 6, 0.02), "a4")
    png = sheet_png(sheet, dpi=150)
    assert png[12:16] == b"IHDR" and png[37:41] == b"pHYs"
    ppm_x, ppm_y, unit = struct.unpack(">IIB", png[41:50])
    assert unit == 1 and ppm_x == ppm_y == round(150 / 0.0254)
    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert image.shape == (round(0.210 * ppm_x), round(0.297 * ppm_x))
    found = detect_board(image, Board(9, 6, 0.02))
    assert isinstance(found, Detection)
    spacing = np.linalg.norm(np.diff(found.corners.reshape(6, 9, 2), axis=1), axis=2).mean()
    assert spacing == pytest.approx(0.02 * ppm_x, abs=0.3)


def test_tag_sheet_ids_read_back():
    assert parse_ids("0-3,7") == [0, 1, 2, 3, 7]
    (sheet,) = tag_sheets("36h11", [0, 5, 9], 0.05)
    image = cv2.imdecode(np.frombuffer(sheet_png(sheet, 100), np.uint8), 0)
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11))
    _, ids, _ = detector.detectMarkers(image)
    assert sorted(ids.ravel().tolist()) == [0, 5, 9]
    with pytest.raises(WolfcalError, match="do not exist"):
        tag_sheets("36h11", [600], 0.05)


def test_cli_board_and_tags_write_pdf_and_png(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["board", "--board", "4x6", "--square", "0.03", "--charuco", "5X5_100",
                                 "--out", str(tmp_path / "charuco")])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert (tmp_path / "charuco.pdf").read_bytes().startswith(b"%PDF-1.4")
    result = runner.invoke(app, ["tags", "--ids", "0-3", "--size", "0.06", "--out", str(tmp_path / "tags.pdf")])
    assert result.exit_code == 0 and (tmp_path / "tags.png").is_file()
    result = runner.invoke(app, ["board", "--board", "9x6", "--square", "0.05", "--out", str(tmp_path / "big")])
    assert result.exit_code != 0 and "does not fit on a4" in result.output
