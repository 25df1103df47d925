"""Bad input and data safety (issue 12): each test gives wolfcal one thing a team meets at a venue or in the lab and
checks the outcome against what is known to be wrong with it: the file, field or device named, nothing overwritten,
no traceback. Faulty captures are real MCAP files rewritten from a simulated one (`wolfcal.sim.faulty`)."""

from __future__ import annotations

import hashlib
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from wolfcal.atomic import atomic_output, output_set, write_text_atomic
from wolfcal.camera.camera_info import load_camera_info
from wolfcal.capture.pipeline import CaptureOptions, run_capture
from wolfcal.cli import app
from wolfcal.config import default_robot, load_robot_config, packaged_robot
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.pipeline import run_evaluate
from wolfcal.fit import pipeline as fit_pipeline
from wolfcal.fit.pipeline import FitOptions, run_fit
from wolfcal.io.reader import read_capture
from wolfcal.progress import Progress
from wolfcal.robot.robot import load_robot
from wolfcal.sim.faulty import rewrite_capture, with_camera_info, with_damaged_image, with_joint_values
from wolfcal.sim.simulate import SimOptions, simulate_capture
from wolfcal.vision.printing import parse_ids, sheet_paths, tag_sheets, write_sheet

ROOT = Path(__file__).resolve().parents[2]
ROBOT = ROOT / "configs" / "wolfgang"
JOINTS_TOPIC, IMAGE_TOPIC, INFO_TOPIC = "/joint_states", "/camera/image_proc/compressed", "/camera/camera_info"
N = 16  # samples of the simulated capture


def quiet(_: str) -> None:
    pass


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def cli(*args) -> tuple[int, str]:
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.output
    return result.exit_code, result.output


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    """16 samples, 512x384 images (binned 4x), with its truth beside it."""
    path = tmp_path_factory.mktemp("good") / "good.mcap"
    simulate_capture(ROBOT, path, SimOptions(samples=N, seed=4, binning=4), say=quiet)
    return path


@pytest.fixture(scope="module")
def good_fit(good, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fit") / "fit"
    run_fit([good], ROBOT, out, FitOptions(free="camera"), say=quiet)
    return out


def faulty(good: Path, tmp_path: Path, edit, name: str = "bad.mcap") -> Path:
    path = tmp_path / name
    rewrite_capture(good, path, edit)
    return path


# --- 1. NaN / infinite joint readings, and the 20 % rule --------------------------------------------------------
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_unusable_joint_readings_in_many_samples_are_refused(good, tmp_path, robot, value):
    bad = faulty(good, tmp_path, with_joint_values(JOINTS_TOPIC, range(0, N, 2), "HeadTilt", value))
    with pytest.raises(WolfcalError) as info:
        read_capture(bad, robot.config)
    assert f"{bad}: 8 of 16 joint state(s) on /joint_states hold NaN or infinite positions (HeadTilt 8x)" in str(
        info.value
    )


def test_a_few_nan_readings_leave_out_those_samples_with_a_warning(good, tmp_path, robot):
    bad = faulty(good, tmp_path, with_joint_values(JOINTS_TOPIC, [3], "HeadTilt", math.nan))
    capture = read_capture(bad, robot.config)
    assert len(capture.samples) == N - 1
    assert all(np.all(np.isfinite(s.positions)) for s in capture.samples)
    assert "1 of 16 joint state(s) on /joint_states hold NaN" in capture.skipped[0]
    assert "left out" in capture.skipped[0]
    lines: list[str] = []
    run_fit([bad], ROBOT, tmp_path / "fit", FitOptions(free="camera"), say=lines.append)
    assert any(line.startswith("warning: ") and "HeadTilt 1x" in line for line in lines)


@pytest.mark.slow
def test_more_than_a_fifth_left_out_as_outliers_fails_the_fit_and_is_refused_by_evaluate(good, good_fit, tmp_path):
    many = tmp_path / "outliers.mcap"  # half the samples blurred or with stale joint readings
    simulate_capture(ROBOT, many, SimOptions(samples=N, seed=4, binning=4, outlier_fraction=0.5), say=quiet)
    with pytest.raises(WolfcalError, match=r"samples \(\d+%\).* left out as outliers, more than the 20%"):
        run_fit([many], ROBOT, tmp_path / "fit", FitOptions(free="camera"), say=quiet)
    assert not (tmp_path / "fit" / "result.yaml").exists()
    held = tmp_path / "held.mcap"
    truth = good.with_name("good.truth.yaml")
    simulate_capture(
        ROBOT, held, SimOptions(samples=12, seed=9, binning=4, outlier_fraction=0.6, truth_file=truth), say=quiet
    )
    with pytest.raises(WolfcalError, match=r"of 12 samples .* evaluation refuses"):
        run_evaluate(good_fit, [held], tmp_path / "report", say=quiet)
    assert not (tmp_path / "report" / "metrics.json").exists()


# --- 2. camera_info validation ---------------------------------------------------------------------------------
CAMERA_INFO = yaml.safe_load((ROBOT / "basler_acA2040.yaml").read_text())


@pytest.mark.parametrize(
    "change, field",
    [
        ({"camera_matrix": {"rows": 3, "cols": 3, "data": [0, 0, 1015.8, 0, 1334.4, 727, 0, 0, 1]}},
         r"'camera_matrix.data\[0\]' \(fx\) is 0"),
        ({"camera_matrix": {"rows": 3, "cols": 3, "data": [1336.2, 0, 1015.8, 0, -1334.4, 727, 0, 0, 1]}},
         r"'camera_matrix.data\[4\]' \(fy\) is -1334.4"),
        ({"camera_matrix": {"rows": 3, "cols": 3, "data": [math.nan, 0, 1015.8, 0, 1334.4, 727, 0, 0, 1]}},
         r"'camera_matrix.data\[0\]' is nan"),
        ({"camera_matrix": {"rows": 3, "cols": 3, "data": [1336.2, 0, 1015.8, 0, 1334.4, 727, 0, 0]}},
         r"'camera_matrix.data' must have 9 numbers"),
        ({"camera_matrix": {"rows": 2, "cols": 3, "data": [1336.2, 0, 1015.8, 0, 1334.4, 727, 0, 0, 1]}},
         r"'camera_matrix.rows' is 2"),
        ({"camera_matrix": {"rows": 3, "cols": 3, "data": [1336.2, 0, 4000.0, 0, 1334.4, 727, 0, 0, 1]}},
         r"'camera_matrix.data\[2\]' \(cx\) = 4000 px lies outside the 2048x1536 image"),
        ({"image_width": 0}, r"'image_width' must be a positive whole number"),
        ({"distortion_coefficients": {"rows": 1, "cols": 6, "data": [0.1, 0, 0, 0, 0, 0.3]}},
         r"'distortion_coefficients.data' has 6 coefficients, the plumb_bob model has 5"),
    ],
)  # fmt: skip
def test_camera_info_yaml_errors_name_the_file_and_field(tmp_path, change, field):
    path = tmp_path / "camera.yaml"
    path.write_text(yaml.safe_dump({**CAMERA_INFO, **change}))
    with pytest.raises(WolfcalError, match=rf"^{re.escape(str(path))}: {field}"):
        load_camera_info(path)


def test_camera_info_message_with_zero_focal_length_names_file_topic_and_field(good, tmp_path, robot):
    bad = faulty(good, tmp_path, with_camera_info(INFO_TOPIC, k=[0.0, 0, 1015.8, 0, 1334.4, 727.0, 0, 0, 1]))
    with pytest.raises(WolfcalError, match=rf"{re.escape(str(bad))}: CameraInfo on {INFO_TOPIC}: 'k\[0\]' \(fx\)"):
        read_capture(bad, robot.config)


def test_intrinsics_for_another_image_size_are_refused(good, tmp_path, robot):
    path = tmp_path / "vga.yaml"  # 640x480: same aspect ratio as the 512x384 images, but no whole binning factor
    path.write_text(yaml.safe_dump({**CAMERA_INFO, "image_width": 640, "image_height": 480, "camera_matrix": {
        "rows": 3, "cols": 3, "data": [500.0, 0, 320, 0, 500, 240, 0, 0, 1]}}))  # fmt: skip
    with pytest.raises(WolfcalError, match=r"'image_width'/'image_height' say 640x480 px, the images are 512x384 px"):
        read_capture(good, robot.config, load_camera_info(path))


# --- 3./4. outputs: never an input, existing ones only with --force, checked first, written as a set ----------------
def test_recover_never_replaces_an_existing_capture_without_force(good, tmp_path):
    existing = tmp_path / "precious.mcap"
    shutil.copy(good, existing)
    before = digest(existing)
    torn = tmp_path / "torn.mcap.partial"
    torn.write_bytes(good.read_bytes()[: good.stat().st_size // 3])
    code, output = cli("recover", torn, "--out", existing)
    assert code == 2 and "exists; pass --force" in output and digest(existing) == before
    code, output = cli("recover", torn, "--out", torn, "--force")
    assert code == 2 and "never overwrites the torn file" in output
    code, output = cli("recover", torn, "--out", existing, "--force")
    assert code == 0 and digest(existing) != before


def test_simulate_and_capture_refuse_an_existing_file_before_any_work(good, tmp_path):
    existing = tmp_path / "x.mcap"
    shutil.copy(good, existing)
    before = digest(existing)
    code, output = cli("simulate", "--robot", ROBOT, "--out", existing, "--samples", 1)
    assert code == 2 and "pass --force" in output and digest(existing) == before
    with pytest.raises(WolfcalError, match="exists; pass --force"):  # before the (absent) bus is opened
        run_capture(CaptureOptions(robot=ROBOT, out=existing, camera="sim", port="/dev/ttyNOPE", manual=True))
    assert digest(existing) == before


@pytest.mark.parametrize("where", ["a file", "below a file", "an earlier fit"])
def test_fit_output_problems_are_found_before_the_work(good, good_fit, tmp_path, where):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a folder")
    out = {"a file": blocker, "below a file": blocker / "fit", "an earlier fit": good_fit}[where]
    before = {p: digest(p) for p in [blocker, *good_fit.iterdir()]}
    missing = tmp_path / "missing.mcap"  # read only after the outputs were checked
    code, output = cli("fit", missing, "--robot", ROBOT, "--out", out)
    assert code == 2 and "missing.mcap" not in output
    assert {"a file": "is a file, not a folder", "below a file": "is a file, not a folder",
            "an earlier fit": "pass --force"}[where] in output  # fmt: skip
    assert before == {p: digest(p) for p in before}


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda text: text.replace('<link name="base_link"/>', '<link name="base_link"/>&nbsp;', 1),
         "Entity 'nbsp' not defined"),
        (lambda text: text.replace("</robot>", ""), "Premature end of data"),
    ],
    ids=["undefined entity", "missing </robot>"],
)  # fmt: skip
def test_a_broken_urdf_is_refused_up_front_and_leaves_no_result(good, tmp_path, edit, message):
    robot = tmp_path / "robot"
    shutil.copytree(ROBOT, robot)
    urdf = robot / "wolfgang.urdf"
    urdf.write_text(edit(urdf.read_text()))
    with pytest.raises(WolfcalError, match=rf"{re.escape(str(urdf))}: not a well-formed URDF: {message}"):
        load_robot(robot)
    code, output = cli("fit", good, "--robot", robot, "--out", tmp_path / "fit")
    assert code == 2 and "not a well-formed URDF" in output and not (tmp_path / "fit").exists()


def test_fit_outputs_are_written_as_a_set(good, good_fit, tmp_path, monkeypatch):
    out = tmp_path / "fit"
    shutil.copytree(good_fit, out)
    before = {p.name: digest(p) for p in out.iterdir()}

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(fit_pipeline, "write_calibrated_urdf", disk_full)
    with pytest.raises(OSError, match="No space left"):
        run_fit([good], ROBOT, out, FitOptions(free="camera", fix_tags=True), say=quiet, force=True)
    assert {p.name: digest(p) for p in out.iterdir()} == before  # the new result.yaml did not land alone


def test_an_output_set_lands_whole_or_not_at_all(tmp_path):
    (tmp_path / "a.txt").write_text("old a")
    with pytest.raises(RuntimeError), output_set():
        write_text_atomic(tmp_path / "a.txt", "new a")
        write_text_atomic(tmp_path / "b.txt", "new b")
        raise RuntimeError("failed before the set was complete")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"] and (tmp_path / "a.txt").read_text() == "old a"
    with output_set():
        write_text_atomic(tmp_path / "a.txt", "new a")
        assert (tmp_path / "a.txt").read_text() == "old a"  # not before the set is complete
    assert (tmp_path / "a.txt").read_text() == "new a"


def test_a_scratch_file_is_no_output_of_the_set(tmp_path, monkeypatch):
    """A cache file (scratch) lands at once, even inside an output set that then fails, and waits for no fsync."""
    synced: list[int] = []
    real_fsync = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: synced.append(fd) or real_fsync(fd))
    with pytest.raises(RuntimeError), output_set():
        write_text_atomic(tmp_path / "result.txt", "output")
        with atomic_output(tmp_path / "entry.bin", scratch=True) as handle:
            handle.write(b"cached")
        assert (tmp_path / "entry.bin").read_bytes() == b"cached"
        raise RuntimeError("failed before the set was complete")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["entry.bin"]
    assert len(synced) == 1  # the output's own fsync, none for the scratch file


def test_intrinsics_board_and_tags_refuse_existing_outputs(tmp_path):
    (tmp_path / "camera.yaml").write_text("earlier calibration")
    code, output = cli("intrinsics", tmp_path / "imgs", "--board", "9x6", "--square", 0.025, "--out",
                       tmp_path / "camera.yaml")  # fmt: skip
    assert code == 2 and "camera.yaml exists; pass --force" in output
    (tmp_path / "tags.png").write_text("earlier sheet")
    code, output = cli("tags", "--ids", "1", "--size", 0.05, "--out", tmp_path / "tags")
    assert code == 2 and "tags.png exists" in output and not (tmp_path / "tags.pdf").exists()
    assert (tmp_path / "tags.png").read_text() == "earlier sheet"


# --- 7. the smaller ones ------------------------------------------------------------------------------------------
def test_a_damaged_image_is_skipped_and_named_by_index_and_time(good, tmp_path, robot):
    bad = faulty(good, tmp_path, with_damaged_image(IMAGE_TOPIC, 5))
    capture = read_capture(bad, robot.config)
    assert len(capture.samples) == N - 1
    damaged = "'head' image 6 of 16 (10.000 s after the first): png checksum error"
    assert any(n.startswith(damaged) for n in capture.skipped)
    result = subprocess.run([sys.executable, "-m", "wolfcal.cli", "fit", str(bad), "--robot", str(ROBOT), "--out",
                             str(tmp_path / "fit")], capture_output=True, text=True, timeout=300)  # fmt: skip
    assert result.returncode == 0 and "libpng" not in result.stderr + result.stdout
    assert "image 6 of 16" in result.stdout


def test_emulate_refuses_a_fault_on_a_servo_that_is_not_configured():
    result = subprocess.run([sys.executable, "-m", "wolfcal.cli", "emulate", "--robot", str(ROBOT), "--fault",
                             "no-answer:99"], capture_output=True, text=True, timeout=60)  # fmt: skip
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "--fault no-answer:99: no servo with this id" in result.stderr and "HeadTilt 20" in result.stderr


def test_backwards_id_range_says_so():
    with pytest.raises(WolfcalError, match="the range 5-2 runs backwards; write 2-5"):
        parse_ids("5-2")


def test_a_folder_given_as_capture_says_it_is_a_folder(good, robot):
    with pytest.raises(WolfcalError, match=rf"{re.escape(str(good.parent))}: is a folder, not a capture file; give"):
        read_capture(good.parent, robot.config)


def test_evaluate_refuses_a_fit_folder_without_its_calibrated_urdf(good, good_fit, tmp_path):
    partial = tmp_path / "partial_fit"
    partial.mkdir()
    shutil.copy(good_fit / "result.yaml", partial / "result.yaml")
    code, output = cli("evaluate", partial, "--out", tmp_path / "report")
    assert code == 2 and "not a complete fit folder (calibrated.urdf, calibrated_robot.yaml missing)" in output


# --- 8.-11. what a new user reads ------------------------------------------------------------------------------------
def test_help_shows_units_in_square_brackets():
    code, output = cli("intrinsics", "--help")
    assert code == 0 and "Square edge [m]." in output and "ChArUco marker edge [m]" in output


def test_tags_of_the_readme_fit_on_a4_pages(tmp_path):
    sheets = tag_sheets("36h11", parse_ids("42-44"), 0.08, "a4")
    assert len(sheets) == 2 and all(s.width <= 0.2971 and s.height <= 0.2971 for s in sheets)
    code, output = cli("tags", "--ids", "42-44", "--size", 0.08, "--out", tmp_path / "tags")
    assert code == 0, output
    pdf, *pngs = sheet_paths(tmp_path / "tags", 2)
    assert pdf.read_bytes().count(b"/Type /Page ") == 2 and b"/Count 2" in pdf.read_bytes()
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11))
    found = []
    for png in pngs:
        _, ids, _ = detector.detectMarkers(cv2.imread(str(png), cv2.IMREAD_GRAYSCALE))
        found += ids.ravel().tolist()
    assert sorted(found) == [42, 43, 44]
    assert write_sheet(sheets, tmp_path / "again", 50) == sheet_paths(tmp_path / "again", 2)


def test_default_robot_is_the_packaged_one_outside_the_repository(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert default_robot() == packaged_robot()
    assert load_robot_config(default_robot()).name == "wolfgang"
    monkeypatch.chdir(ROOT)
    assert default_robot() == Path("configs/wolfgang")
    assert default_robot("elsewhere/robot.yaml") == Path("elsewhere/robot.yaml")


def test_progress_says_how_far_how_fast_and_how_long_is_left():
    now = [0.0]
    lines: list[str] = []
    progress = Progress(lines.append, "detecting tags", "samples", interval_s=2.0, clock=lambda: now[0])
    for done in range(1, 101):
        now[0] = done * 0.1  # 10 samples per second
        progress(done, 100)
    assert lines[0] == "detecting tags: 20/100 samples, 10.0 samples/s, about 8 s left"
    assert lines[-1] == "detecting tags: 100/100 samples in 10 s, 10.0 samples/s"
    silent: list[str] = []
    quick = Progress(silent.append, "reading", "messages", clock=lambda: 0.0)
    quick(5, 10), quick(10, 10)
    assert silent == []


def test_reading_reports_progress_over_the_messages_of_the_file(good, robot):
    calls: list[tuple[int, int]] = []
    read_capture(good, robot.config, progress=lambda done, total: calls.append((done, total)))
    assert calls[0] == (0, 3 * N) and calls[-1] == (3 * N, 3 * N)


@pytest.mark.slow
def test_the_bad_inputs_script_passes_every_case():
    """bad_input_cases.py: every bad input above through the real command line, one line per case."""
    script = Path(__file__).resolve().parent / "bad_input_cases.py"
    result = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True,
                            text=True, timeout=1800)  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert re.search(r"(\d+) of \1 cases pass", result.stdout)


def test_a_missing_camera_intrinsics_key_is_named_with_what_needs_it(tmp_path):
    """A robot config whose head camera has no intrinsics: simulate, capture and plan name the file, the key to set
    and their other way to give it (`RobotConfig.intrinsics_file`), before any output is written."""
    robot = tmp_path / "robot"
    shutil.copytree(ROBOT, robot)
    config = robot / "robot.yaml"
    config.write_text("".join(line for line in config.read_text().splitlines(keepends=True)
                              if not line.startswith("  intrinsics:")))  # fmt: skip
    key = "needs the intrinsics of camera 'head': set 'camera.intrinsics' to its camera_info YAML "
    key += "(`wolfcal intrinsics` makes one)"
    for args, out, needs in (
        (("simulate", "--samples", 2), "s.mcap", f"simulating {key} or pass --intrinsics FILE"),
        (("capture", "--camera", "sim", "--manual"), "c.mcap", f"capturing {key} or pass --intrinsics FILE"),
        (("plan",), "plan.yaml", f"the plan {key}"),
    ):
        code, output = cli(*args, "--robot", robot, "--out", tmp_path / out)
        assert code != 0 and f"{config}: {needs}" in " ".join(output.split()), output
        assert not (tmp_path / out).exists()
