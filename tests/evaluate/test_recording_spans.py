"""`wolfcal evaluate` and `wolfcal compare` on plain ROS 2 recordings (written with mcap_ros2, not wolfcal's capture
writer): a sample is one still span, as the fit takes it. Cross-validation refits the fit's spans (their count and
frames the fit's own), a held-out recording is judged per span (its stamp the span's first frame's, the figures
drawn on that frame), and compare's head-camera column holds one value per held-out span."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.evaluate.compare import run_compare
from wolfcal.evaluate.pipeline import run_evaluate
from wolfcal.fit.pipeline import FitOptions, run_fit
from wolfcal.io.reader import read_capture
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.robot import load_robot
from wolfcal.sim.poses import random_visible_poses
from wolfcal.sim.recording import RecordingOptions, simulate_recording, write_recording

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
FIT_POSES, HELD_POSES = 8, 5
OPTIONS = RecordingOptions(move_s=0.5, hold_s=1.0, seed=3)  # 5-10 still frames per pose at 10 Hz
BINNING = 4  # 512 x 384 images


def quiet(_text: str) -> None:
    pass


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """A fit (--free camera) on one recording and a held-out recording of other poses of the same robot."""
    root = tmp_path_factory.mktemp("recording_spans")
    robot = load_robot(CONFIG)
    truth = simulate_recording(robot, root / "fit.mcap", FIT_POSES, binning=BINNING, options=OPTIONS)
    camera = load_camera_info(robot.config.intrinsics_file(HEAD_CAMERA, "simulating")).binned(BINNING, HEAD_CAMERA)
    poses = random_visible_poses(robot, camera, truth, HELD_POSES, np.random.default_rng(11))[0]
    write_recording(root / "held.mcap", robot, truth, camera, poses, RecordingOptions(move_s=0.5, hold_s=1.0, seed=4))
    run_fit([root / "fit.mcap"], CONFIG, root / "fit", FitOptions(free="camera"), say=quiet)
    return root


def first_frames(path: Path) -> tuple[list[int], int]:
    """The first stamp of each still span of a recording with a head image (the reader's spans), and the number of
    still frames."""
    samples = read_capture(path, load_robot(CONFIG).config).samples
    first: dict[int, int] = {}
    for s in samples:
        span = s.images[HEAD_CAMERA].span
        first[span] = min(first.get(span, s.stamp_ns), s.stamp_ns)
    return sorted(first.values()), len(samples)


def test_cross_validation_refits_the_fits_still_spans(recorded):
    fit = yaml.safe_load((recorded / "fit" / "result.yaml").read_text())
    head = fit["blocks"][0]
    said: list[str] = []
    metrics = run_evaluate(recorded / "fit", [], recorded / "cv", say=said.append)
    assert fit["n_samples"] == FIT_POSES and head["n_frames"] >= 4 * FIT_POSES  # one sample per pose
    assert metrics["mode"] == "cross-validation"
    assert metrics["n_samples"] == fit["n_samples"] and metrics["n_frames"] == head["n_frames"]
    assert [s["frames"] for s in metrics["samples"]] == [s["frames"] for s in head["samples"]]
    folds = [line for line in said if line.startswith("fold ")]
    assert len(folds) == metrics["folds"]
    for line in folds:  # every fold refits spans, never frames
        fitted, held = (int(w) for w in line.split() if w.isdigit())
        assert fitted + held == FIT_POSES
    assert "still span" in metrics["mode_note"] and "samples" in metrics["meanings"]
    assert metrics["after"]["rms_px"] < metrics["before"]["rms_px"]  # the camera's true mount error is corrected


def test_a_held_out_recording_is_judged_per_still_span(recorded):
    metrics = run_evaluate(recorded / "fit", [recorded / "held.mcap"], recorded / "held", say=quiet)
    spans, frames = first_frames(recorded / "held.mcap")
    assert metrics["mode"] == "held-out" and metrics["n_samples"] == len(spans) == HELD_POSES
    assert metrics["n_frames"] == sum(s["frames"] for s in metrics["samples"]) <= frames
    assert sorted(s["stamp_ns"] for s in metrics["samples"]) == spans  # a span's stamp: its first frame's
    overlays = [f["caption"] for f in metrics["figures"] if "overlay" in f["file"]]
    assert overlays and all("drawn on its first frame" in c for c in overlays)
    assert metrics["verdict"]["deploy"]  # the true camera mount error corrected; its pixel figures say what they are
    assert f"(of still-span means: {HELD_POSES} spans of {metrics['n_frames']} frames)" in metrics["verdict"]["message"]
    report = (recorded / "held" / "report.md").read_text()
    assert f"still spans of {metrics['n_frames']} frames" in report


def test_compare_measures_one_value_per_held_out_still_span(recorded):
    metrics = run_compare([recorded / "fit"], [recorded / "held.mcap"], recorded / "compare", say=quiet)
    spans, _ = first_frames(recorded / "held.mcap")
    column = next(c for c in metrics["columns"] if c["key"] == "head_px")
    assert "still-span means" in column["title"]
    for row in metrics["table"].values():
        assert row["head_px"]["n"] == len(spans)  # no outlier in a simulation: every span
    saved = json.loads((recorded / "compare" / "metrics.json").read_text())
    assert saved["decision"]["deploy"] == "fit"  # the fit corrects the simulated camera mount
