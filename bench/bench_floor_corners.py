"""The floor block on synthetic corners (no images), the setting of `tests/fit/test_floor_fit.py`: true ground error at
4.5 m (worst of the bearings -30, 0, +30 deg) before, after a fit on feet samples only, and after one on feet + floor
samples.

Wolfgang's URDF with other tag ids and sizes (feet 7 and 8, torso 3), floor tags 60-65 of 0.12-0.2 m lying 1-4 m
away, a 1280x960 camera with k1 = -0.12, 30 feet + 30 floor samples, 0.15 px corner noise, 0.025 rad rms encoder
offsets on the head and legs (`legs calibrated`: none) and the camera ~4 deg off.
Run: python bench/bench_floor_corners.py [--seeds 1 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: BLAS threads spinning on 2 busy cores cost 50x

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from conftest import OTHER_CAMERA, joined, robot_with_floor_tags  # noqa: E402

from wolfcal.evaluate.ground import ground_errors  # noqa: E402
from wolfcal.fit.pipeline import FitOptions, fit_observations  # noqa: E402
from wolfcal.robot.corrections import Corrections  # noqa: E402
from wolfcal.sim.floor import simulate_floor  # noqa: E402
from wolfcal.sim.scenario import synthetic_scenario  # noqa: E402

CASES = (("--free leg", "leg", "all"), ("--free camera, legs off", "camera", "all"),
         ("--free camera, legs calibrated", "camera", "none"))  # fmt: skip


def ground_4_5_cm(robot, truth: Corrections, model: Corrections) -> float:
    """True ground error at 4.5 m [cm], worst of the three bearings."""
    return 100.0 * ground_errors(robot, OTHER_CAMERA, truth, {"m": model}, (4.5,))[0]["models"]["m"]["error_m"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        robot = robot_with_floor_tags(Path(folder))
    print("| fit | seed | before | feet only | feet + floor |\n|---|---|---|---|---|")
    for label, free, offsets in CASES:
        for seed in args.seeds:
            feet = synthetic_scenario(robot, OTHER_CAMERA, 30, seed, offsets=offsets)
            floor = simulate_floor(robot, OTHER_CAMERA, feet.truth, 30, np.random.default_rng(seed + 100))
            cells = [ground_4_5_cm(robot, feet.truth, Corrections())]
            for obs in (feet.obs, joined(feet.obs, floor.obs)):
                fit = fit_observations(robot, {"head": obs}, FitOptions(free=free))
                cells.append(ground_4_5_cm(robot, feet.truth, fit.corrections))
            print(f"| `{label}` | {seed} | " + " | ".join(f"{c:.1f} cm" for c in cells) + " |", flush=True)


if __name__ == "__main__":
    main()
