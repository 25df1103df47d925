"""`wolfcal demo` on the captures it simulates: what it prints is true (the simulator's truth beside each capture),
it runs from any folder, and it warns about nothing a user would have to act on."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from wolfcal.demo import SIMULATIONS

ROOT = Path(__file__).resolve().parents[2]


def at(rows: list[dict], distance: float) -> dict:
    return next(r for r in rows if r["distance_m"] == distance)


@pytest.mark.slow
def test_demo_deploys_the_venue_fit_and_refuses_the_camera_fit_on_legs_that_are_off(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, "-m", "wolfcal.cli", "demo", "--out", "demo"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=1200)  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr  # a folder without captures/ or configs/: it simulates them
    assert sorted(p.name for p in (tmp_path / "demo" / "captures").glob("*.mcap")) == sorted(SIMULATIONS)
    venue = json.loads((tmp_path / "demo" / "report" / "metrics.json").read_text())
    legs = json.loads((tmp_path / "demo" / "legs_report" / "metrics.json").read_text())
    assert venue["deploy"]["written"] and venue["after"]["rms_px"] < 0.3 and 20 < venue["before"]["rms_px"]
    true_after = at(venue["ground"]["rows"], 4.5)["models"]["after"]["error_m"]
    measured = at(venue["ground"]["measured"]["models"]["after"]["rows"], 4.5)
    assert true_after < 0.03 and measured["error_m"] < 0.05  # below the deploy limit
    assert abs(measured["error_m"] - true_after) < 2 * measured["std_m"]  # the measurement's 1 sigma, 2x
    before = at(venue["ground"]["measured"]["models"]["before"]["rows"], 4.5)["error_m"]
    assert before == pytest.approx(at(venue["ground"]["rows"], 4.5)["models"]["before"]["error_m"], rel=0.2)
    assert not legs["deploy"]["written"] and "the legs need calibration" in legs["deploy"]["reason"]
    assert at(legs["ground"]["rows"], 4.5)["models"]["after"]["error_m"] > 0.3  # what a deploy would have cost
    text = run.stdout
    assert "measured ground error (floor views), ball at 4.5 m" in text and "Do not deploy: the legs need" in text
    # nothing to act on: the camera's 5 deg correction is checked by the floor views, the floor tags' places are
    # the floor check's own unknowns, and OpenCV keeps its log lines to itself
    assert "more than a camera mount moves" not in text and "note: floor.tag" not in text
    assert "warning:" not in text and "[ WARN" not in run.stderr and run.stderr == ""
