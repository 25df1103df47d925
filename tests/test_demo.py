"""`wolfcal demo` on the shipped captures: what it prints is true (the simulator's truth beside each capture)."""

from pathlib import Path

import pytest

from wolfcal.demo import run_demo

ROOT = Path(__file__).resolve().parents[1]


def at(rows: list[dict], distance: float) -> dict:
    return next(r for r in rows if r["distance_m"] == distance)


@pytest.mark.slow
def test_demo_deploys_the_venue_fit_and_refuses_the_camera_fit_on_legs_that_are_off(tmp_path):
    lines: list[str] = []
    metrics = run_demo(ROOT, tmp_path / "demo", say=lines.append)
    venue, legs = metrics["venue"], metrics["legs"]
    assert venue["deploy"]["written"] and venue["after"]["rms_px"] < 0.3 < 20 < venue["before"]["rms_px"]
    true_after = at(venue["ground"]["rows"], 4.5)["models"]["after"]["error_m"]
    measured = at(venue["ground"]["measured"]["models"]["after"]["rows"], 4.5)
    assert true_after < 0.03 and measured["error_m"] < 0.05  # below the deploy limit
    assert abs(measured["error_m"] - true_after) < 2 * measured["std_m"]  # the measurement's 1 sigma, 2x
    before = at(venue["ground"]["measured"]["models"]["before"]["rows"], 4.5)["error_m"]
    assert before == pytest.approx(at(venue["ground"]["rows"], 4.5)["models"]["before"]["error_m"], rel=0.2)
    assert not legs["deploy"]["written"] and "the legs need calibration" in legs["deploy"]["reason"]
    assert at(legs["ground"]["rows"], 4.5)["models"]["after"]["error_m"] > 0.3  # what a deploy would have cost
    text = "\n".join(lines)
    assert "measured ground error (floor views), ball at 4.5 m" in text and "Do not deploy: the legs need" in text
