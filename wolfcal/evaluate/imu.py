"""The IMU's held-out check: the gravity error [deg] of standing recordings the fit did not use, before (the nominal
model) and after (the fitted corrections: mount and leg offsets).

Gravity error of a still period: the angle between the measured specific force's direction (IMU frame) and the
standing soles' normal turned into the IMU frame by the model (`wolfcal.fit.imu_block`), the fitted bias left out:
what the deployed model gives the robot's own state estimation. The verdict: deploy when the RMS after is below the
RMS before. `evaluate_held_out` is the registry's evaluator (`wolfcal.fit.systems`): `wolfcal evaluate --capture`
with standing recordings only (no camera topic) is judged here; metrics.json and report.md are written, and the
deploy files when the verdict allows.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wolfcal.atomic import output_set, write_text_atomic
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.provenance import provenance
from wolfcal.io.imu import StandingSamples, read_standing, topics_of
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import floor_frames
from wolfcal.robot.imu_mount import imu_config
from wolfcal.robot.robot import Robot

if TYPE_CHECKING:
    from wolfcal.fit.result import FitResult

MEANING = (
    "angle between the measured gravity direction (the accelerometer's mean over a still period, IMU frame) "
    "and the standing soles' normal in the IMU frame under the model [deg]; RMS and max over the periods"
)


def gravity_errors(robot: Robot, samples: StandingSamples, model: Corrections) -> np.ndarray:
    """(S,) gravity error of each still period under `model` [deg] (module docstring)."""
    link, soles = imu_config(robot).frame, list(robot.config.floor_config().soles)
    poses = robot.model.link_poses(samples.q_measured, [link, *soles], model, base=robot.config.base_link)
    T_base_floor = floor_frames(np.stack([poses[s] for s in soles]))
    n_imu = np.einsum("sji,sj->si", poses[link][:, :3, :3], T_base_floor[:, :3, 2])
    m = samples.accel / np.linalg.norm(samples.accel, axis=1, keepdims=True)
    return np.rad2deg(np.arccos(np.clip(np.einsum("si,si->s", m, n_imu), -1.0, 1.0)))


def _figures(errors: np.ndarray) -> dict:
    return {"rms_deg": round(float(np.sqrt(np.mean(errors**2))), 4), "max_deg": round(float(errors.max()), 4)}


def evaluate_held_out(fit_dir: Path, result: FitResult, robot: Robot, captures: list[Path], out_dir: Path,
                      deploy_worse: bool, say: Callable[[str], None], present: object = None,
                      limits: object = None) -> dict | None:  # fmt: skip
    """The IMU check when every capture is a standing recording (IMU topic, no camera topic); None otherwise (the
    camera evaluation judges them). Returns metrics.json's content; a WolfcalError when they are the fit's own
    (the check needs held-out recordings). `present` and `limits` (the registry's evaluator arguments) are not
    used: before is the nominal model, and the check has no ground error."""
    from wolfcal.evaluate.deploy import write_or_withhold_deploy_files  # the deploy files' writer

    if "imu" not in robot.config.sections or not captures:
        return None
    config = imu_config(robot)
    cameras = {robot.config.camera_topics(name)[0] for name in robot.config.camera_names}
    topics = [set(topics_of(Path(c))) for c in captures]
    if not all(config.topic in t and not cameras & t for t in topics):
        return None
    if {str(Path(c).resolve()) for c in captures} <= set(result.captures):
        raise WolfcalError(
            f"{', '.join(map(str, captures))}: the IMU is checked on standing recordings the fit did "
            "not use (no cross-validation over still periods): give one with --capture"
        )
    samples = read_standing([Path(c) for c in captures], robot.config.joint_states_topic, config.topic,
                            robot.joint_names)  # fmt: skip
    before, after = gravity_errors(robot, samples, Corrections()), gravity_errors(robot, samples, result.corrections)
    worse = float(np.sqrt(np.mean(after**2))) >= float(np.sqrt(np.mean(before**2)))
    refusal = (
        (
            f"the held-out gravity error is not smaller after the fit ({_figures(after)['rms_deg']} deg RMS "
            f"against {_figures(before)['rms_deg']} deg before)"
        )
        if worse
        else None
    )
    metrics: dict = {
        **provenance(robot, fit_dir, result.free),
        "mode": "held-out", "captures": [str(Path(c).resolve()) for c in captures], "system": "imu",
        "n_samples": samples.n_samples, "meaning": MEANING,
        "before": _figures(before), "after": _figures(after),
        "samples": [{"source": Path(samples.sources[i]).name, "stamp_ns": int(samples.stamps_ns[i]),
                     "before_deg": round(float(before[i]), 4), "after_deg": round(float(after[i]), 4)}
                    for i in range(samples.n_samples)],
        "notes": samples.notes,
    }  # fmt: skip
    lines = [f"# IMU held-out check ({samples.n_samples} still periods)", "", MEANING, "",
             "| | RMS [deg] | max [deg] |", "|---|---|---|",
             f"| before | {metrics['before']['rms_deg']} | {metrics['before']['max_deg']} |",
             f"| after | {metrics['after']['rms_deg']} | {metrics['after']['max_deg']} |", ""]  # fmt: skip
    out_dir.mkdir(parents=True, exist_ok=True)
    with output_set():
        metrics["deploy"] = write_or_withhold_deploy_files(robot, result.corrections, out_dir, refusal, deploy_worse)
        write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=1))
        write_text_atomic(out_dir / "report.md", "\n".join(lines + [refusal or "Verdict: deploy."]) + "\n")
    say(
        f"imu: gravity error on {samples.n_samples} held-out still period(s): {metrics['before']['rms_deg']} deg "
        f"RMS before -> {metrics['after']['rms_deg']} deg after (max {metrics['after']['max_deg']} deg)"
    )
    say(refusal or "verdict: deploy")
    return metrics
