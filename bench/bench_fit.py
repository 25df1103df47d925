"""Fit speed: leg preset (both sides) on 25, 100 and 400 synthetic samples of the Wolfgang robot.

Run: python bench/bench_fit.py. Prints wall time per fit (median of 3) and the number of residual evaluations.
Observations are projected without images, so this measures the estimator alone.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.robot.robot import load_robot
from wolfcal.sim.scenario import synthetic_scenario

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


def main() -> None:
    robot = load_robot(CONFIG)
    camera = load_camera_info(CONFIG / "basler_acA2040.yaml")
    for n in (25, 100, 400):
        scenario = synthetic_scenario(robot, camera, n=n, seed=n, offsets="all")
        times, fit = [], None
        for _ in range(3):
            start = time.perf_counter()
            fit = fit_observations(robot, scenario.obs, FitOptions(free="leg", side="both"))
            times.append(time.perf_counter() - start)
        print(
            f"leg preset, {n:4d} samples, {len(scenario.obs.uv):5d} corners, {len(fit.params)} parameters: "
            f"{np.median(times):.2f} s (median of 3), {fit.solution.evaluations} residual evaluations"
        )


if __name__ == "__main__":
    main()
