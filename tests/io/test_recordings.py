"""Reported uncertainty on a continuous recording: a plain ROS 2 recording (written with mcap_ros2, not wolfcal's
capture format) of 14 still poses with about 20 frames each and motion in between, images rendered through the
distorted head camera with image noise of their own; `wolfcal fit --free head_camera` on it (one sample per still
pose, its frames averaged) must report standard deviations that cover the true error without being absurdly
conservative."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.robot.parameters import build_parameter_set
from wolfcal.robot.robot import load_robot
from wolfcal.sim.recording import RecordingOptions, simulate_recording

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 3])
def test_reported_std_covers_the_error_on_a_continuous_recording(tmp_path, seed):
    robot = load_robot(CONFIG)
    recording = tmp_path / "recording.mcap"
    truth = simulate_recording(robot, recording, 14, offsets="head", options=RecordingOptions(seed=seed))
    out = tmp_path / "fit"
    result = CliRunner().invoke(
        app, ["fit", str(recording), "--robot", str(CONFIG), "--free", "head_camera", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    data = yaml.safe_load((out / "result.yaml").read_text())
    head = data["blocks"][0]
    assert head["n_samples"] == data["n_samples"] <= 14  # one sample per still pose: its frames averaged
    assert 14 * 18 <= head["n_frames"] <= 14 * 22  # only the still frames: about 20 per pose
    assert sum(s["frames"] for s in head["samples"]) == head["n_frames"]
    params = build_parameter_set(robot, "head_camera", {"head": data["tags_used"]})
    truth_of = dict(zip(params.names, params.values_from(truth)))
    z = {p["name"]: abs(p["value"] - truth_of[p["name"]]) / p["std"] for p in data["parameters"]}
    assert set(z) == set(truth_of)
    assert max(z.values()) < 3.0, z  # frames of one still pose are not counted as independent evidence
    assert np.median(list(z.values())) > 0.2, z  # nor is the reported std absurdly conservative
