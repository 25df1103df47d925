"""What every command promises a new user (docs/cli.md): exit codes, `--version`, sizes in metres, defaults that
agree across commands, nothing left behind by a failed run, no OpenCV log lines, and messages that say what to do."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import typer
import yaml
from conftest import default_sigint
from typer.testing import CliRunner

import wolfcal
from wolfcal.atomic import atomic_output, make_folder, output_set, write_text_atomic
from wolfcal.capture.cameras import plan_cameras
from wolfcal.capture.options import CaptureOptions
from wolfcal.capture.poses import find_poses
from wolfcal.cli import app
from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.fit.options import FitOptions
from wolfcal.plan.pipeline import PlanOptions
from wolfcal.robot.presets import DEFAULT_PRESET
from wolfcal.robot.robot import load_robot
from wolfcal.vision.target_size import check_printed_edge

ROOT = Path(__file__).resolve().parents[2]
WOLFGANG = ROOT / "configs" / "wolfgang"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def cli(*args: object) -> tuple[int, str]:
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, result.output


def process(*args: object, cwd: Path) -> subprocess.Popen:
    command = [sys.executable, "-m", "wolfcal.cli", *map(str, args)]
    return subprocess.Popen(command, cwd=cwd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)  # fmt: skip


def test_version_is_the_package_version():
    code, output = cli("--version")
    assert code == 0 and output == f"wolfcal {wolfcal.__version__}\n"
    code, output = cli("--help")
    assert code == 0 and "Exit codes: 0 done, 1 refused to deploy, 2 bad usage or input" in " ".join(output.split())
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert 'dynamic = ["version"]' in pyproject and 'version = {attr = "wolfcal.__version__"}' in pyproject


@pytest.mark.parametrize("args, option, meant", [
    (("tags", "--size", 80), "--size 80", "0.08 for 80 mm"),
    (("tags", "--ids", "42", "--size", 0.8), "--size 0.8", "0.0008 for 0.8 mm"),
    (("board", "--board", "9x6", "--square", 25), "--square 25", "0.025 for 25 mm"),
    (("board", "--board", "9x6", "--square", 0.02, "--charuco", "5X5_100", "--marker", 15), "--marker 15",
     "0.015 for 15 mm"),
])  # fmt: skip
def test_target_sizes_in_millimetres_are_refused_before_any_work(tmp_path, args, option, meant):
    code, output = cli(*args, "--out", tmp_path / "sheet")
    text = " ".join(output.split())
    assert code == 2 and f"{option}:" in text and "did you mean millimetres?" in text and meant in text, output
    assert "Traceback" not in output and list(tmp_path.iterdir()) == []


def test_intrinsics_refuses_a_square_in_millimetres_before_reading_images(tmp_path):
    code, output = cli("intrinsics", tmp_path / "none", "--board", "9x6", "--square", 25, "--out", tmp_path / "c.yaml")
    assert code == 2 and "--square 25:" in output and "did you mean millimetres?" in output


def test_printed_edges_up_to_half_a_metre_are_accepted_and_config_sizes_checked_alike(tmp_path):
    assert check_printed_edge(0.5, "--size") == 0.5 and check_printed_edge(0.004, "--size") == 0.004
    for bad in (0.0, -0.08, float("nan")):
        with pytest.raises(WolfcalError, match="must be a positive length in metres"):
            check_printed_edge(bad, "--size")
    shutil.copytree(WOLFGANG, tmp_path / "robot")
    config = tmp_path / "robot" / "robot.yaml"
    text = config.read_text()
    config.write_text(text.replace("{id: 43, family: tag36h11, size: 0.08,", "{id: 43, family: tag36h11, size: 80,"))
    with pytest.raises(WolfcalError, match=r"'tags\[0\].size' 80: .*did you mean millimetres\? .* 0.08 for 80 mm"):
        load_robot_config(config)


def test_usage_errors_and_bad_input_exit_2_with_what_to_do(tmp_path):
    code, output = cli("fit", "--no-such-option")
    assert code == 2 and "No such option" in output
    capture = tmp_path / "game3.mcap"
    capture.write_bytes(b"\x89MCAP0\r\n")  # evaluate reads no capture given in place of the fit folder
    code, output = cli("evaluate", capture, "--out", tmp_path / "report")
    text = " ".join(output.split())
    assert code == 2 and f"{capture}: a capture file, not a fit folder" in text, output
    assert "the --out folder of `wolfcal fit`" in text and "wolfcal fit CAPTURE.mcap --out FIT" in text
    assert not (tmp_path / "report").exists()


@pytest.mark.slow
def test_a_refusal_to_deploy_exits_1_and_says_it_once(tmp_path):
    legs = ROOT / "captures" / "legs_demo.mcap"  # leg encoders off: a camera fit must not be deployed
    assert cli("fit", legs, "--robot", WOLFGANG, "--free", "camera", "--out", tmp_path / "fit")[0] == 0
    result = CliRunner().invoke(app, ["evaluate", str(tmp_path / "fit"), "--out", str(tmp_path / "report")])
    assert result.exit_code == 1, result.output
    assert result.output.count("the legs need calibration") == 1  # the verdict, not repeated as the error
    assert "not deployed: the verdict above withholds the deploy files" in result.output
    assert (tmp_path / "report" / "report.md").is_file() and not (tmp_path / "report" / "calibrated.urdf").exists()


@pytest.mark.slow
def test_ctrl_c_exits_130_and_leaves_no_output(tmp_path):
    fit = process("fit", ROOT / "captures" / "demo.mcap", "--no-cache", "--out", "fit", cwd=tmp_path)
    assert fit.stdout is not None and "detecting tags" in fit.stdout.readline()  # at work: Ctrl-C now
    fit.send_signal(signal.SIGINT)
    _, stderr = fit.communicate(timeout=300)
    assert fit.returncode == 130 and stderr == "interrupted\n", stderr
    assert list(tmp_path.iterdir()) == []


def test_opencv_and_ffmpeg_keep_their_log_lines_to_themselves(tmp_path):
    (tmp_path / "broken.mp4").write_bytes(b"not a video")
    for source in (["broken.mp4"], ["--camera", "63"]):  # FFmpeg: "moov atom not found"; V4L: "[ WARN:0@...]"
        run = process("intrinsics", *source, "--board", "9x6", "--square", 0.025, "--out", "c.yaml", cwd=tmp_path)
        _, stderr = run.communicate(timeout=120)
        assert run.returncode in (2, 4) and stderr.startswith("error: ") and stderr.count("\n") == 1, stderr


def test_free_and_binning_defaults_agree_across_commands(tmp_path):
    commands = typer.main.get_command(app).commands.values()  # type: ignore[attr-defined]
    free = {c.name: p.default for c in commands for p in c.params if p.name == "free"}
    assert free == {"fit": DEFAULT_PRESET, "plan": DEFAULT_PRESET} and FitOptions().free == PlanOptions().free
    robot = load_robot(WOLFGANG)
    captured = plan_cameras(CaptureOptions(WOLFGANG, tmp_path / "c.mcap", camera="sim"), robot)["head"]
    code, output = cli("simulate", "--samples", 1, "--out", tmp_path / "s.mcap")
    assert code == 0, output
    simulated = yaml.safe_load((tmp_path / "s.truth.yaml").read_text())["binning"]
    assert simulated == captured.binning == 4 and captured.model.binned(4, "head").width == 512


def test_tags_prints_the_robot_configs_tags_at_their_sizes_by_default(tmp_path):
    config = load_robot_config(WOLFGANG)
    sizes = {t.id: t.size for t in config.tags} | {t.id: t.size for t in config.floor.tags}
    dpi = 50
    code, output = cli("tags", "--out", tmp_path / "tags", "--dpi", dpi)
    assert code == 0, output
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11))
    found: dict[int, float] = {}
    for png in sorted(tmp_path.glob("tags*.png")):
        corners, ids, _ = detector.detectMarkers(cv2.imread(str(png), cv2.IMREAD_GRAYSCALE))
        for c, i in zip(corners, ids.ravel()):
            found[int(i)] = float(np.linalg.norm(c[0, 1] - c[0, 0])) / dpi * 0.0254  # edge [m]
    assert sorted(found) == sorted(sizes) == [42, 43, 44, 50, 51, 52, 53, 54, 55]
    assert all(abs(found[i] - sizes[i]) < 2 * 0.0254 / dpi for i in sizes), found  # within 2 px
    code, output = cli("tags", "--ids", "7", "--out", tmp_path / "other")
    assert code == 2 and "does not list tag(s) 7; give their edge with --size" in " ".join(output.split())


def test_a_failed_output_set_removes_the_folders_it_made(tmp_path):
    (tmp_path / "kept").mkdir()
    with pytest.raises(KeyboardInterrupt), output_set():
        write_text_atomic(tmp_path / "report" / "figures" / "a.txt", "a")
        make_folder(tmp_path / "kept" / "sub")
        raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept"] and list((tmp_path / "kept").iterdir()) == []
    with pytest.raises(RuntimeError), atomic_output(tmp_path / "lone" / "deep" / "x.bin") as handle:
        handle.write(b"half a file")
        raise RuntimeError("a lone output is a set of one")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept"]
    with output_set():
        write_text_atomic(tmp_path / "report" / "a.txt", "a")
    assert (tmp_path / "report" / "a.txt").read_text() == "a"


def test_poses_by_name_are_the_robot_configs_own(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert find_poses("poses.yaml", WOLFGANG / "robot.yaml") == WOLFGANG / "poses.yaml"
    (tmp_path / "poses.yaml").write_text("poses: []\n")
    assert find_poses("poses.yaml", WOLFGANG) == Path("poses.yaml")  # a file here comes first
    with pytest.raises(WolfcalError, match=r"--poses nope.yaml: no such file here or beside the robot config"):
        find_poses("nope.yaml", WOLFGANG)
