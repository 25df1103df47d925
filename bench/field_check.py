"""The `field_check` part: the ground error measured on held-out field views against the true one.

Per seed: a rendered field capture at `field.robot_at` (-3, 0, 0) is fitted (`--system field --free camera`); a
second one of the same true camera with the robot near `field.check_at` (-1.5, 1, 0.5) is held out (seed + 1000),
and the ground error at 4.5 m is measured from it (`evaluate.field_ground`, no truth) for three models: the fitted
camera (after), the nominal one (before) and the fitted one tilted by `tilt_mrad` about the optical x axis (an
error near the verdict's 5 cm limit). Reported per seed and model: the true ground error (`evaluate.ground` against
the simulator's truth), the measured one with its 1 sigma (the larger of the formal and the jackknife's, both
given) [m], whether they agree within 2 cm + 2 sigma, and the smallest share of information the camera's mount
parameters got from the held-out views. A seed whose fitted-on capture the field fit refuses is said and skipped.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from field import QUIET, field_robot

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.field_ground import measured_field_ground
from wolfcal.evaluate.ground import ground_errors
from wolfcal.field.observe import field_observations
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import run_fit
from wolfcal.fit.result import load_result
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import load_robot
from wolfcal.sim.simulate import SimOptions, simulate_capture

DISTANCE_M = 4.5
CHECK_AT = {"x": -1.5, "y": 1.0, "yaw": 0.5}
AGREE_M = 0.02  # a measurement agrees when within this + 2 sigma of the true ground error [m]


def one_seed(seed: int, views: int, tilt: float, folder: Path) -> list[dict]:
    """Per model (after, before, tilted) the true and measured ground error at DISTANCE_M of one seed."""
    robot_path = field_robot(folder, CHECK_AT)
    fitted_on, check = folder / f"field{seed}.mcap", folder / f"check{seed}.mcap"
    simulate_capture(robot_path, fitted_on, SimOptions(samples=views, seed=seed, binning=4, system="field"), None,
                     say=QUIET, force=True)  # fmt: skip
    truth_file = folder / f"field{seed}.truth.yaml"
    simulate_capture(robot_path, check, SimOptions(samples=views, seed=seed + 1000, binning=4, system="field",
                                                   floor_check=True, truth_file=truth_file), None,
                     say=QUIET, force=True)  # fmt: skip
    run_fit([fitted_on], robot_path, folder / f"fit{seed}", FitOptions(free="camera", system="field"), None,
            say=QUIET, force=True)  # fmt: skip
    robot = load_robot(robot_path)
    after = load_result(folder / f"fit{seed}").corrections
    mount = after.frames[robot.camera_joint] + np.array([0, 0, 0, tilt, 0, 0])
    models = {"after": after, "before": Corrections(), "tilted": Corrections(frames={robot.camera_joint: mount})}
    obs = field_observations(robot, [check], QUIET, check=True)
    measured = measured_field_ground(robot, obs, models, (DISTANCE_M,), QUIET)
    true = ground_errors(robot, obs.camera, load_corrections(truth_file, key="truth"), models, (DISTANCE_M,))[0]
    share = min(c["data_share"] for c in measured["camera"].values())
    out = []
    for name in models:
        row = measured["models"][name]["rows"][0]
        true_m = true["models"][name]["error_m"]
        agrees = abs(row["error_m"] - true_m) <= AGREE_M + 2 * row["std_m"]
        out.append({"seed": seed, "model": name, "true_m": true_m, "measured_m": row["error_m"],
                    "std_m": row["std_m"], "formal_m": row["formal_std_m"], "jackknife_m": row["jackknife_std_m"],
                    "agrees": bool(agrees), "data_share": share})  # fmt: skip
    return out


def field_check(seeds: int, views: int, say, tilt_mrad: float = 1.5) -> dict:
    """The rows of `one_seed` for seeds 0 .. seeds-1 (or why the fit refused a seed's capture), and how many of
    the measurements agree with the truth."""
    rows: list[dict] = []
    refused: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            try:
                mine = one_seed(seed, views, tilt_mrad / 1000, Path(tmp))
            except WolfcalError as error:  # the field fit refused its fitted-on capture: nothing to judge
                refused.append({"seed": seed, "refused": str(error)})
                say(f"field check seed {seed}: the fit refused its capture")
                continue
            rows += mine
            say(f"field check seed {seed}: " + "; ".join(
                f"{r['model']} true {100 * r['true_m']:.1f} cm, measured {100 * r['measured_m']:.1f} +- "
                f"{100 * r['std_m']:.2f} cm{'' if r['agrees'] else ' (NO)'}" for r in mine))  # fmt: skip
    agree = sum(r["agrees"] for r in rows)
    return {"seeds": seeds, "views": views, "tilt_mrad": tilt_mrad, "distance_m": DISTANCE_M, "agree_m": AGREE_M,
            "rows": rows, "refused": refused, "agree": agree, "measured": len(rows)}  # fmt: skip
