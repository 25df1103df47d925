"""Uncertainty on continuous recordings: do the reported standard deviations cover the true error?

A plain ROS 2 recording (wolfcal/sim/recording.py: 14 still poses, 2.5 s each at 10 Hz images, so about 20 kept
frames per pose, 1 s of motion in between) of the Wolfgang head camera (binned images, barrel distortion, image
noise), read by wolfcal's reader, tags detected, fitted; per seed the largest and median
|z| = |estimate - truth| / reported std over the free parameters, and chi-square per parameter (sum z^2 / P,
about 1 when the reported covariance is right).
Run: python bench/bench_recordings.py [--seeds 5] [--free head_camera camera] [--flicker 0.0] [--verbose]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.robot import load_robot
from wolfcal.sim.recording import RecordingOptions, simulate_recording
from wolfcal.vision.observe import detect_observations

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


def z_scores(robot, truth, path: Path, free: str):
    """(fit, |z| per free parameter) of a fit of the recording."""
    samples, _ = load_samples(robot, [path], None)
    obs = detect_observations(samples, robot)[0][HEAD_CAMERA]
    fit = fit_observations(robot, obs, FitOptions(free=free))
    z = np.abs(fit.solution.values - fit.params.values_from(truth)) / fit.solution.std
    return fit, z


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--poses", type=int, default=14)
    parser.add_argument("--binning", type=int, default=4)
    parser.add_argument("--flicker", type=float, default=0.0, help="encoder reading noise [ticks]")
    parser.add_argument("--free", nargs="+", default=["head_camera", "camera"])
    parser.add_argument("--verbose", action="store_true", help="print |z| of every parameter")
    args = parser.parse_args()
    summary = {free: [] for free in args.free}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            for free in args.free:
                path = Path(tmp) / f"recording_{seed}_{free}.mcap"
                start = time.perf_counter()
                # the head joints' offsets are true errors only where the preset frees them
                offsets = "head" if free == "head_camera" else "none"
                robot = load_robot(CONFIG)
                truth = simulate_recording(
                    robot, path, args.poses, offsets, args.binning, RecordingOptions(flicker=args.flicker, seed=seed)
                )
                simulated = time.perf_counter() - start
                start = time.perf_counter()
                fit, z = z_scores(robot, truth, path, free)
                block = fit.solution.blocks[0]
                summary[free].append(z)
                worst = int(np.argmax(z))
                print(
                    f"seed {seed} --free {free:11s}: {len(fit.blocks[0].q_measured)} frames, "
                    f"max |z| {z.max():.2f} ({fit.params.names[worst]}), median |z| {np.median(z):.2f}, "
                    f"chi2/P {np.mean(z**2):.2f}, noise {block.sigma:.3f} px, rms {block.rms_after:.3f} px "
                    f"[sim {simulated:.0f} s, read+detect+fit {time.perf_counter() - start:.0f} s]",
                    flush=True,
                )
                if args.verbose:
                    for name, value in zip(fit.params.names, z):
                        print(f"    {name:28s} |z| {value:.2f}")
    for free, zs in summary.items():
        z = np.concatenate(zs)
        print(
            f"--free {free}: over {len(zs)} seeds max |z| {z.max():.2f}, median |z| {np.median(z):.2f}, "
            f"chi2/P {np.mean(z**2):.2f}, {int(np.sum(z > 3))} of {z.size} beyond 3 std"
        )


if __name__ == "__main__":
    main()
