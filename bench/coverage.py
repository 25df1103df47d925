"""The `recordings` part: uncertainty on continuous recordings: do the reported standard deviations cover the true
error? A plain ROS 2 recording (wolfcal/sim/recording.py: 14 still poses, 2.5 s each at 10 Hz images, so about 20
kept frames per pose, 1 s of motion in between) of the Wolfgang head camera (binned images, barrel distortion, image
noise), read by wolfcal's reader, tags detected, averaged per still span as `wolfcal fit` does, fitted; per seed the
largest and median |z| = |estimate - truth| / reported std over the free parameters, and chi-square per parameter
(sum z^2 / P, about 1 when the reported covariance is right).
Per preset over the seeds: max and median |z|, chi-square per parameter, how many |z| beyond 3.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.robot import load_robot
from wolfcal.sim.recording import RecordingOptions, simulate_recording
from wolfcal.spans import still_span_observations
from wolfcal.vision.observe import detect_observations

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


def z_scores(robot, truth, path: Path, free: str):
    """(fit, |z| per free parameter) of a fit of the recording, as `wolfcal fit` makes it (one sample per still
    span)."""
    samples, _ = load_samples(robot, [path], None)
    options = FitOptions(free=free)
    obs = still_span_observations(robot.config, detect_observations(samples, robot)[0])[HEAD_CAMERA]
    fit = fit_observations(robot, obs, options)
    z = np.abs(fit.solution.values - fit.params.values_from(truth)) / fit.solution.std
    return fit, z


def recordings(seeds: int, binning: int, say, presets: tuple[str, ...] = ("head_camera", "camera")) -> dict:
    """Per preset and seed a simulated recording (14 poses) read, detected and fitted: frames kept, max and median
    |z|, chi2/P, noise and RMS after [px]; per preset the same over the seeds."""
    rows: list[dict] = []
    zs: dict[str, list[np.ndarray]] = {free: [] for free in presets}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            for free in presets:
                path = Path(tmp) / f"recording_{seed}_{free}.mcap"
                offsets = "head" if free == "head_camera" else "none"  # true errors only where the preset frees them
                robot = load_robot(CONFIG)
                truth = simulate_recording(robot, path, 14, offsets, binning, RecordingOptions(seed=seed))
                fit, z = z_scores(robot, truth, path, free)
                block = fit.solution.blocks[0]
                zs[free].append(z)
                figures = {"max_z": z.max(), "median_z": np.median(z), "chi2_per_p": np.mean(z**2)}
                spans = fit.blocks[0].obs.span_frames
                frames = len(fit.blocks[0].q_measured) if spans is None else int(spans.frames_of_sample.sum())
                rows.append({"seed": seed, "free": free, "frames": frames, "noise_px": block.sigma,
                             "rms_after_px": block.rms_after, **{k: float(v) for k, v in figures.items()}})  # fmt: skip
                say(f"recordings seed {seed} --free {free}: max |z| {z.max():.2f}, chi2/P {np.mean(z**2):.2f}")
    summary = {}
    for free, parts in zs.items():
        z = np.concatenate(parts)
        summary[free] = {"max_z": float(z.max()), "median_z": float(np.median(z)), "chi2_per_p": float(np.mean(z**2)),
                         "beyond_3": int(np.sum(z > 3)), "numbers": int(z.size)}  # fmt: skip
    return {"seeds": seeds, "binning": binning, "rows": rows, "summary": summary}
