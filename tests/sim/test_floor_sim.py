"""`wolfcal simulate --floor`: rendered floor samples that `wolfcal fit feet.mcap floor.mcap --free leg` fits end to
end (detection on the rendered images, floor block, sole closure), against the simulator's truth."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.ground import ground_errors
from wolfcal.evaluate.pipeline import run_evaluate
from wolfcal.fit.pipeline import FitOptions, run_fit
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import load_robot
from wolfcal.sim.simulate import SimOptions, simulate_capture

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"


def test_floor_simulation_needs_the_head_camera(tmp_path):
    with pytest.raises(WolfcalError, match="--floor simulates the head camera"):
        simulate_capture(WOLFGANG, tmp_path / "floor.mcap", SimOptions(floor=True, system="external"), say=lambda s: 0)


@pytest.mark.slow
def test_fit_on_rendered_feet_and_floor_captures(tmp_path):
    feet, floor = tmp_path / "feet.mcap", tmp_path / "floor.mcap"
    say = lambda s: None  # noqa: E731
    truth = simulate_capture(WOLFGANG, feet, SimOptions(samples=24, seed=3, binning=2, offsets="all"), say=say)
    simulate_capture(WOLFGANG, floor, SimOptions(samples=20, seed=4, binning=2, floor=True,
                                                 truth_file=tmp_path / "feet.truth.yaml"), say=say)  # fmt: skip
    data = yaml.safe_load((tmp_path / "floor.truth.yaml").read_text())
    assert load_corrections(tmp_path / "floor.truth.yaml", key="truth").to_dict() == truth.to_dict()
    places = data["floor_tags"]
    assert all(0.5 <= np.hypot(p["x"], p["y"]) <= 5.0 for p in places.values())
    result = run_fit([feet, floor], WOLFGANG, tmp_path / "fit", FitOptions(free="leg"), say=say)
    robot = load_robot(WOLFGANG)
    values = {p.name: p.value for p in result.parameters}
    fitted = {int(name.split(".")[1][3:]) for name in values if name.startswith("floor.tag")}
    assert len(fitted) >= 3  # floor tags found on the rendered images
    for tag_id in fitted:  # the fitted places agree with the true ones (true floor frame vs fitted floor frame)
        true = places[tag_id]
        assert np.hypot(values[f"floor.tag{tag_id}.x"] - true["x"], values[f"floor.tag{tag_id}.y"] - true["y"]) < 0.05
    model = load_camera_info(robot.config.head_camera().intrinsics)
    rows = ground_errors(robot, model, truth, {"before": Corrections(), "after": result.corrections}, (4.5,))
    before, after = (rows[0]["models"][k]["error_m"] for k in ("before", "after"))
    assert before > 1.0 and after < 0.1, (before, after)  # measured: 6.0 m -> 7.8 cm (binned 640x480 images)
    # held out: feet and floor samples of the same robot; the measured ground error (no truth used) in metrics.json
    held_feet, held_floor = tmp_path / "held_feet.mcap", tmp_path / "held_floor.mcap"
    truth_file = tmp_path / "feet.truth.yaml"
    simulate_capture(WOLFGANG, held_feet, SimOptions(samples=12, seed=13, binning=2, truth_file=truth_file), say=say)
    simulate_capture(WOLFGANG, held_floor, SimOptions(samples=16, seed=14, binning=2, floor=True,
                                                      truth_file=truth_file), say=say)  # fmt: skip
    metrics = run_evaluate(tmp_path / "fit", [held_feet, held_floor], tmp_path / "eval", say=say)
    k = [r["distance_m"] for r in metrics["ground"]["rows"]].index(4.5)
    true_before = metrics["ground"]["rows"][k]["models"]["before"]["error_m"]
    measured = metrics["ground"]["measured"]["models"]
    measured_before, measured_after = measured["before"]["rows"][k]["error_m"], measured["after"]["rows"][k]["error_m"]
    assert abs(measured_before - true_before) < 0.2 * true_before, (measured_before, true_before)
    assert measured_after < 0.1 * measured_before
    assert (tmp_path / "eval" / "report.md").read_text().count("Measured ground error") == 1
