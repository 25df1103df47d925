"""End-to-end accuracy with images: simulate -> detect -> fit -> compare with the truth.

Scenarios of the foundation issue, on a 2048x1536 camera with strong barrel distortion (k1 = -0.286), encoder
quantisation (4096 ticks per turn) and image noise (sigma 2 gray levels):
  camera    24 samples, --free camera: camera pose error over the whole head range (target 0.05 deg, 2 mm)
  leg       24 samples, 0.025 rad rms offsets on both legs and the head, --free leg --side both: sole error
            over random leg configurations (target 3 mm)
  outliers  24 samples of which 10 % motion-blurred or with stale joint readings, --free camera (target 0.1 deg)
Every scenario also reports the largest |estimate - truth| / reported std (target below 3).
Run: python bench/bench_accuracy.py [--seeds 3] [--binning 1]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from wolfcal.evaluate.accuracy import camera_pose_errors, link_position_errors
from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples
from wolfcal.io.truth import truth_paths
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import load_corrections
from wolfcal.robot.robot import load_robot
from wolfcal.sim.simulate import SimOptions, simulate_capture
from wolfcal.vision.observe import detect_observations

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
SCENARIOS = {
    "camera": (SimOptions(samples=24, offsets="none"), FitOptions(free="camera")),
    "leg": (SimOptions(samples=24, offsets="all"), FitOptions(free="leg", side="both")),
    "outliers": (SimOptions(samples=24, offsets="none", outlier_fraction=0.1), FitOptions(free="camera")),
}


def run(name: str, seed: int, binning: int, folder: Path) -> str:
    sim, options = SCENARIOS[name]
    sim = SimOptions(**{**sim.__dict__, "seed": seed, "binning": binning})
    capture = folder / f"{name}_{seed}.mcap"
    start = time.perf_counter()
    simulate_capture(CONFIG, capture, sim, say=lambda _m: None)
    simulated = time.perf_counter() - start
    robot = load_robot(CONFIG)
    truth = load_corrections(truth_paths(capture)[0], key="truth")
    start = time.perf_counter()
    samples, _ = load_samples(robot, [capture], None)
    obs = detect_observations(samples, robot)[0][HEAD_CAMERA]
    detected = time.perf_counter() - start
    start = time.perf_counter()
    fit = fit_observations(robot, obs, options)
    fitted = time.perf_counter() - start
    z = np.abs(fit.solution.values - fit.params.values_from(truth)) / fit.solution.std
    rot, trans = camera_pose_errors(robot, fit.corrections, truth)
    head = fit.solution.blocks[0]
    line = (
        f"{name:8s} seed {seed}: camera {np.rad2deg(rot.max()):.4f} deg / {trans.max() * 1000:.2f} mm (max over "
        f"head range), max |z| {z.max():.2f}, rms {head.rms_before:.1f} -> {head.rms_after:.3f}"
        f" px, outliers left out: {int(head.outlier_samples.sum())} sample(s), "
        f"{len(head.outlier_views)} tag view(s)"
    )
    if name == "leg":
        rng = np.random.default_rng(seed)
        soles = [link_position_errors(robot, s, fit.corrections, truth, 500, rng).max() for s in ("r_sole", "l_sole")]
        line += f", soles max {max(soles) * 1000:.2f} mm"
    return line + f" [simulate {simulated:.1f} s, read+detect {detected:.1f} s, fit {fitted:.2f} s]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--binning", type=int, default=1)
    parser.add_argument("--scenarios", nargs="*", default=list(SCENARIOS))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenarios:
            for seed in range(args.seeds):
                print(run(name, seed, args.binning, Path(tmp)), flush=True)


if __name__ == "__main__":
    main()
