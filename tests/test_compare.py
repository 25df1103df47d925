"""`wolfcal compare`: calibrations of two measurement systems side by side on held-out captures of both, and bad
input. The session: one simulated truth (leg encoder offsets, camera mount), a head-camera and a motion-capture
session of it, each fitted on its own captures and compared on held-out captures of both systems."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_mocap_io import write_markers_recording
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.evaluate.compare import BEFORE_LABEL

WOLFGANG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
runner = CliRunner()


def _run(*args: str):
    return runner.invoke(app, [*args])


def test_fit_folder_without_result_is_refused(tmp_path):
    (tmp_path / "fit").mkdir()
    (tmp_path / "c.mcap").write_bytes(b"")
    result = _run("compare", str(tmp_path / "fit"), "--capture", str(tmp_path / "c.mcap"), "--out",
                  str(tmp_path / "out"))  # fmt: skip
    assert result.exit_code != 0
    assert "no result.yaml" in result.output and str(tmp_path / "fit") in result.output
    assert "Traceback" not in result.output and not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """Head-camera and motion-capture captures of one truth; a fit of each on its own captures."""
    d = tmp_path_factory.mktemp("compare")
    robot = ["--robot", str(WOLFGANG)]
    steps = [
        ["simulate", *robot, "--out", str(d / "head_fit.mcap"), "--samples", "16", "--binning", "4", "--seed", "1",
         "--offsets", "legs"],
        ["simulate", *robot, "--out", str(d / "head_test.mcap"), "--samples", "10", "--binning", "4", "--seed", "2",
         "--truth", str(d / "head_fit.truth.yaml")],
        ["simulate", *robot, "--out", str(d / "mocap_fit.mcap"), "--system", "mocap", "--samples", "20", "--seed",
         "3", "--truth", str(d / "head_fit.truth.yaml")],
        ["simulate", *robot, "--out", str(d / "mocap_test.mcap"), "--system", "mocap", "--samples", "12", "--seed",
         "4", "--truth", str(d / "head_fit.truth.yaml")],
        ["fit", str(d / "head_fit.mcap"), *robot, "--out", str(d / "fit_head")],
        ["fit", str(d / "mocap_fit.mcap"), *robot, "--system", "mocap", "--free", "leg", "--out", str(d / "fit_mocap")],
    ]  # fmt: skip
    for step in steps:
        result = _run(*step)
        assert result.exit_code == 0, (step, result.output)
    return d


@pytest.mark.slow
def test_each_calibration_improves_the_columns_it_can_measure(session):
    d = session
    out = d / "report"
    args = ["compare", str(d / "fit_head"), str(d / "fit_mocap"), "--capture", str(d / "head_test.mcap"),
            "--capture", str(d / "mocap_test.mcap"), "--out", str(out)]  # fmt: skip
    result = _run(*args)
    assert result.exit_code == 0, result.output
    metrics = json.loads((out / "metrics.json").read_text())
    table = metrics["table"]
    assert [c["key"] for c in metrics["columns"]] == ["head_px", "head_tag_grid_mm", "mocap_mm"]
    assert set(table) == {BEFORE_LABEL, "fit_head", "fit_mocap"}
    before = {k: v["mean"] for k, v in table[BEFORE_LABEL].items()}
    # the head-camera calibration on the head camera's columns, the leg calibration on the markers
    assert table["fit_head"]["head_px"]["mean"] < 0.2 * before["head_px"]
    assert table["fit_head"]["head_tag_grid_mm"]["mean"] < 0.5 * before["head_tag_grid_mm"]
    assert table["fit_mocap"]["mocap_mm"]["mean"] < 0.5 * before["mocap_mm"]
    for row in table.values():
        for cell in row.values():
            assert cell["n"] > 5 and cell["std"] >= 0
    # the leg calibration cannot see the camera mount: the head camera's columns are no better with it, so the
    # decision is the head-camera calibration, and the report says why the other is not deployable
    assert table["fit_mocap"]["head_px"]["mean"] > 0.9 * before["head_px"]
    decision = metrics["decision"]
    assert decision["deploy"] == "fit_head"
    assert decision["calibrations"]["fit_head"]["worse_columns"] == []
    for name in ("report.md", "report.html", *(f"figures/{c['key']}.png" for c in metrics["columns"])):
        assert (out / name).stat().st_size > 0
    assert "fit_head" in (out / "report.md").read_text()
    again = _run(*args)
    assert again.exit_code != 0 and "--force" in again.output
    assert _run(*args, "--force").exit_code == 0


@pytest.mark.slow
def test_bad_captures_are_refused(session):
    d = session
    t = np.arange(200) / 100.0
    write_markers_recording(d / "joints_only.mcap", t, {"head_pan": np.zeros_like(t)}, [], None)
    fits = [str(d / "fit_head"), str(d / "fit_mocap")]
    result = _run("compare", *fits, "--capture", str(d / "joints_only.mcap"), "--out", str(d / "bad"))
    assert result.exit_code != 0
    assert "joints_only.mcap" in result.output and "neither camera images" in result.output
    result = _run("compare", *fits, "--capture", str(d / "head_fit.mcap"), "--out", str(d / "bad"))
    assert result.exit_code != 0 and "not held out" in result.output
    assert not (d / "bad").exists()
