"""`wolfcal compare`: calibrations of three measurement systems side by side on held-out captures of all of them,
and bad input. The session: one simulated truth (encoder offsets, camera mount, tag mounts), a head-camera (with
floor samples), an external-camera and a motion-capture session of it, each fitted on its own captures and compared
on held-out captures of every system."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mocap_recordings import write_markers_recording
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.evaluate.compare import BEFORE_LABEL

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
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
    """Head-camera (with held-out floor samples), external-camera and motion-capture captures of one truth; a fit of
    each system on its own captures."""
    d = tmp_path_factory.mktemp("compare")
    robot = ["--robot", str(WOLFGANG)]
    truth = ["--truth", str(d / "head_fit.truth.yaml")]
    steps = [
        ["simulate", *robot, "--out", str(d / "head_fit.mcap"), "--samples", "16", "--binning", "2", "--seed", "1",
         "--offsets", "all"],
        ["simulate", *robot, "--out", str(d / "head_test.mcap"), "--samples", "10", "--binning", "2", "--seed", "2",
         *truth],
        ["simulate", *robot, "--out", str(d / "floor_test.mcap"), "--samples", "20", "--binning", "2", "--seed", "3",
         "--floor", *truth],
        ["simulate", *robot, "--out", str(d / "external_fit.mcap"), "--system", "external", "--samples", "20",
         "--binning", "1", "--seed", "4", *truth],
        ["simulate", *robot, "--out", str(d / "external_test.mcap"), "--system", "external", "--samples", "10",
         "--binning", "1", "--seed", "5", *truth],
        ["simulate", *robot, "--out", str(d / "mocap_fit.mcap"), "--system", "mocap", "--samples", "20", "--seed",
         "6", *truth],
        ["simulate", *robot, "--out", str(d / "mocap_test.mcap"), "--system", "mocap", "--samples", "12", "--seed",
         "7", *truth],
        ["fit", str(d / "head_fit.mcap"), *robot, "--out", str(d / "fit_head")],
        ["fit", str(d / "external_fit.mcap"), *robot, "--system", "external", "--free", "leg", "--out",
         str(d / "fit_external")],
        ["fit", str(d / "mocap_fit.mcap"), *robot, "--system", "mocap", "--free", "leg", "--out", str(d / "fit_mocap")],
    ]  # fmt: skip
    for step in steps:
        result = _run(*step)
        assert result.exit_code == 0, (step, result.output)
    return d


@pytest.mark.slow
def test_each_calibration_improves_the_columns_it_can_measure(session):
    """The study's table: a row per calibration and "before", a column per held-out measurement system in its unit,
    the ground error measured on held-out floor views."""
    d = session
    out = d / "report"
    fits = ["fit_head", "fit_external", "fit_mocap"]
    captures = ["head_test.mcap", "floor_test.mcap", "external_test.mcap", "mocap_test.mcap"]
    args = ["compare", *(str(d / f) for f in fits), *(a for c in captures for a in ("--capture", str(d / c))),
            "--out", str(out)]  # fmt: skip
    result = _run(*args)
    assert result.exit_code == 0, result.output
    metrics = json.loads((out / "metrics.json").read_text())
    table = metrics["table"]
    assert [c["key"] for c in metrics["columns"]] == ["head_px", "head_tag_grid_mm", "ground_cm",
                                                      "external_tripod_mm", "mocap_mm"]  # fmt: skip
    assert [c["unit"] for c in metrics["columns"]] == ["px", "mm", "cm", "mm", "mm"]
    assert set(table) == {BEFORE_LABEL, *fits} and metrics["not_measured"] == []
    before = {k: v["mean"] for k, v in table[BEFORE_LABEL].items()}
    # each calibration on the columns of its own measurement system
    assert table["fit_head"]["head_px"]["mean"] < 0.2 * before["head_px"]
    assert table["fit_head"]["head_tag_grid_mm"]["mean"] < 0.5 * before["head_tag_grid_mm"]
    assert table["fit_head"]["ground_cm"]["mean"] < 0.5 * before["ground_cm"]
    assert table["fit_external"]["external_tripod_mm"]["mean"] < 0.7 * before["external_tripod_mm"]
    assert table["fit_mocap"]["mocap_mm"]["mean"] < 0.5 * before["mocap_mm"]
    for label, row in table.items():
        for key, cell in row.items():
            assert cell["std"] is not None and cell["std"] >= 0, (label, key)
            assert cell["n"] >= (1 if key == "ground_cm" else 5), (label, key)
    # the leg calibrations cannot see the camera mount: the head camera's columns stay near before's
    assert table["fit_mocap"]["head_px"]["mean"] > 0.8 * before["head_px"]
    decision = metrics["decision"]
    assert decision["calibrations"]["fit_head"]["worse_columns"] == []
    for name in ("report.md", "report.html", *(f"figures/{c['key']}.png" for c in metrics["columns"]
                                               if c["key"] != "ground_cm")):  # fmt: skip
        assert (out / name).stat().st_size > 0
    report = (out / "report.md").read_text()
    assert "fit_head" in report and "ground error at 4.5 m" in report
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
