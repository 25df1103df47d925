"""Fit speed: the leg preset (both sides) with the head camera on 25, 100, 400 and 1000 synthetic samples, and with an
external camera on 30 and 120 samples.

Run: python bench/bench_fit.py. Prints the solve's wall and CPU time (median of 3; reading and tag detection
excluded: observations are projected without images) and the number of linearisations. BLAS runs on one thread,
as in the `wolfcal` command.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from wolfcal.camera.camera_info import load_camera_info  # noqa: E402
from wolfcal.camera.model import CameraModel  # noqa: E402
from wolfcal.fit.pipeline import FitOptions, fit_observations  # noqa: E402
from wolfcal.robot.robot import load_robot  # noqa: E402
from wolfcal.sim.scenario import synthetic_external_scenario, synthetic_scenario  # noqa: E402

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
TRIPOD = CameraModel(1920, 1080, np.array([[1400.0, 0, 959.5], [0, 1400.0, 539.5], [0, 0, 1]]), np.zeros(5))


def timed(robot, obs, options: FitOptions) -> tuple[float, float, object]:
    wall, cpu, fit = [], [], None
    for _ in range(3):
        w, c = time.perf_counter(), time.process_time()
        fit = fit_observations(robot, obs, options)
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
    return float(np.median(wall)), float(np.median(cpu)), fit


def main() -> None:
    robot = load_robot(CONFIG)
    camera = load_camera_info(CONFIG / "basler_acA2040.yaml")
    for n in (25, 100, 400, 1000):
        scenario = synthetic_scenario(robot, camera, n=n, seed=n, offsets="all")
        wall, cpu, fit = timed(robot, scenario.obs, FitOptions(free="leg", side="both"))
        print(f"head camera, leg preset, {n:4d} samples, {len(scenario.obs.uv):5d} corners, {len(fit.params)} "
              f"unknowns: solve {wall:.3f} s wall, {cpu:.3f} s CPU (median of 3), {fit.solution.evaluations} "
              "linearisations")
    for n, moving in ((30, False), (120, False), (120, True)):
        scenario = synthetic_external_scenario(robot, TRIPOD, n=n, seed=n)
        wall, cpu, fit = timed(robot, scenario.obs, FitOptions(free="leg", external_moving=moving))
        print(f"external camera{' (moving)' if moving else ''}, leg preset, {n:4d} samples, {len(scenario.obs.uv):5d}"
              f" corners, {len(fit.params)} unknowns: solve {wall:.3f} s wall, {cpu:.3f} s CPU (median of 3), "
              f"{fit.solution.evaluations} linearisations")


if __name__ == "__main__":
    main()
