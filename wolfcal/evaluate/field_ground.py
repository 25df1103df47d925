"""The measured ground error: held-out field views (the robot placed elsewhere on the field), without truth.

The held-out views' line points are fitted by the field block (`wolfcal.fit.field_block`) with the robot's own
field pose free (x, y, yaw, unknown: started from the place search around `field.check_at`, else `field.robot_at`)
and the head camera's mount free around the model to deploy (its other corrections held; the fit's noise model,
robust loss and priors), then again around that solution: the camera the views ask for, C, with its covariance
(6, 6). It does not depend on the model judged (the priors' share is a few per mille, `data_share`), so it serves
every one. The ground error of a judged model M at a distance D is `evaluate.ground`'s with C as the reference: the
robot stands in `floor.standing` with its head aimed by C at a ball D m away on the floor (bearings -30, 0, +30
deg), the ball's pixel under C is put on the floor through M: the worst bearing's distance [m], and its 1 sigma [m]:
the sqrt of the trace of that offset's covariance, the larger of the one propagated from C's and the grouped
jackknife's over the views (`jackknife_mounts`).

What is measured and what is not. The field pose takes any error that turns or shifts every view alike on the
ground: a turn about the vertical (a HeadPan offset, the body turned on its soles) moves a ball at D sideways by D
times the angle, and a shift of the whole robot; neither is measured, and neither is in the 1 sigma. A turn or
shift of the camera's mount is not of that kind: the head's tilt and pan change where it moves each view, so views
over several head angles tell it from the robot's place (each mount parameter gets nearly all its information from
the views, `data_share`). What moves far ground points, the camera's pitch and roll against the floor and its
height, is measured. A tilt of the whole robot on its soles (leg offsets) is measured only as far as a turn of the
camera's mount stands in for it. The standing legs read the same encoder ticks in every held-out view: the noise
model holds their shared rounding, so it is in the 1 sigma (and the fit's views, taken in the same stance, round
alike: the measurement cannot see what that rounding biased in the fit, beyond its 1 sigma).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.evaluate.ground import ball_views, ground_point
from wolfcal.field.model import FieldLines, field_lines
from wolfcal.field.observations import FieldObservations
from wolfcal.fit.field_block import FieldBlock
from wolfcal.fit.jackknife import jackknife_covariance, view_groups
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import Fit, fit_observations
from wolfcal.geometry import invert_transform
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor
from wolfcal.robot.parameters import build_parameter_set
from wolfcal.robot.robot import Robot

CAMERA_PRESET = "camera"  # the correction the held-out views are asked for: the head camera's mount (6)
STEP = 1e-6  # central-difference step of the landing offset's derivatives [m, rad]


def asked_camera(robot: Robot, obs: FieldObservations, lines: FieldLines, model: Corrections,
                 weighted_at: Corrections | None = None, held_lines: bool = False) -> Fit:  # fmt: skip
    """The field fit of the held-out views with the camera's mount free around `model`'s (`model`'s other
    corrections held) and the field pose free; the points weighted at `weighted_at` (default: `model`), each held
    on its nearest line there with `held_lines` (`FieldBlock`: for a fit weighted at a solution). The
    markings are held where the field's dimensions put them: freed, their 25 places trade against the camera's
    pitch and height across one placement's views and the measurement's 1 sigma grows 2-3x, to where a dozen views
    no longer see an error of the verdict's limit; the detector's lean on them is a few mm."""
    chain = build_parameter_set(robot, CAMERA_PRESET, {"head": []})
    block = FieldBlock(robot, obs, lines, fixed=chain.held(model), weighted_at=weighted_at or model,
                       marking_places=False, held_lines=held_lines)  # fmt: skip
    options = FitOptions(free=CAMERA_PRESET, system="field", current=model)
    return fit_observations(robot, {}, options, own_blocks=[block])


def measured_field_ground(robot: Robot, obs: FieldObservations, models: dict[str, Corrections],
                          distances: tuple[float, ...], say: Callable[[str], None],
                          around: str = "after") -> dict:  # fmt: skip
    """Per model: per distance the measured ground error [m] (None: the ball lies above the model's horizon) with
    its 1 sigma [m] and worst bearing [deg]. The views are fitted with the camera's mount free around the model
    `around` (its prior centred there), then again weighted and centred at that solution, each point held on its
    nearest line there (started far off, a fit may settle elsewhere: the point-to-line associations and the points
    left out differ; and a point that changes its line moves the cost by a step, on which a solve, or a jackknife
    replicate started at the solution, may stop): the camera they ask for
    serves every judged model. Also that camera's mount (camera.x|y|z|rx|ry|rz [m, rad], with std and data share),
    the robot's field pose per placement (capture file: `field_pose`, or `field_pose@k` with several; x, y [m],
    yaw [rad], with std) and the views' and line points' count."""
    lines = field_lines(robot.config.field_config().dimensions)
    say(f"fitting the held-out field views: the robot's place and the camera's mount (around the model {around}) ...")
    first = asked_camera(robot, obs, lines, models[around])
    obs = replace(obs, starts=_places(first))
    fit = asked_camera(robot, obs, lines, first.corrections, held_lines=True)
    obs = replace(obs, starts=_places(fit))
    say("fitting again with each group of held-out views left out ...")
    replicates = jackknife_mounts(robot, obs, lines, fit.corrections)
    out = _asked_entry(fit)
    out.update(views=obs.n_samples, line_points=len(obs.uv))
    covariance = fit.solution.uncertainty.covariance[: len(fit.chain), : len(fit.chain)]
    out["models"] = {name: {"rows": [_ground_row(robot, obs.camera, model, fit.corrections, covariance, replicates, d)
                                     for d in distances]} for name, model in models.items()}  # fmt: skip
    return out


def jackknife_mounts(robot: Robot, obs: FieldObservations, lines: FieldLines,
                     model: Corrections) -> np.ndarray | None:  # fmt: skip
    """(G, 6) the camera's mount the views ask for around `model` (weighted there) with each of G groups of views
    left out (`wolfcal.fit.jackknife.view_groups`); None with fewer than 3 views."""
    if obs.n_samples < 3:
        return None
    groups = view_groups(obs.n_samples)
    mounts = []
    for g in np.unique(groups):
        fit = asked_camera(robot, obs.only_samples(groups != g), lines, model, held_lines=True)
        mounts.append(fit.corrections.frames[robot.camera_joint])
    return np.stack(mounts)


def _places(fit: Fit) -> np.ndarray:
    """(P, 3) the robot's field pose per placement at the fit's solution (`FieldBlock.places`)."""
    (block,) = fit.blocks
    assert isinstance(block, FieldBlock)
    return block.places(fit.solution.values[len(fit.chain) :])


def _asked_entry(fit: Fit) -> dict:
    """The camera's mount the views ask for and the robot's field pose per placement, with std (and data share)."""
    n = len(fit.chain)
    values, u = fit.solution.values, fit.solution.uncertainty
    names = fit.params.names
    poses: dict[str, dict] = {}  # per placement ('field_pose', or 'field_pose@k' with several): x, y, yaw
    for i in range(n, n + 3 * len(_places(fit))):
        placement, component = names[i].rsplit(".", 1)
        poses.setdefault(placement, {})[component] = {"value": float(values[i]), "std": float(u.std[i])}
    return {
        "camera": {names[i]: {"value": float(values[i]), "std": float(u.std[i]), "data_share": float(u.data_share[i])}
                   for i in range(n)},
        "field_pose": poses,
    }  # fmt: skip


def _ground_row(robot: Robot, camera: CameraModel, model: Corrections, asked: Corrections, covariance: np.ndarray,
                replicates: np.ndarray | None, distance: float) -> dict:  # fmt: skip
    """The ground error of `model` at `distance` against the camera the views ask for (`asked`, its mount's
    covariance (6, 6), its jackknife `replicates` (G, 6) or None): worst bearing; its 1 sigma [m], the larger of
    the formal one (propagated from the covariance: holds the errors all views share, the standing legs' rounding)
    and the jackknife's (the offset at each replicate: holds what differs from view to view), both given."""
    joint = robot.camera_joint
    mount = asked.frames.get(joint, np.zeros(6))
    best: dict = {"distance_m": distance, "error_m": None, "std_m": None, "formal_std_m": None,
                  "jackknife_std_m": None, "worst_bearing_deg": None}  # fmt: skip
    for view in ball_views(robot, camera, asked, distance):  # the head aimed by `asked`, held for the derivatives
        q, ball, bearing = view["q"], view["ball"], view["bearing"]

        def offset(m: np.ndarray, q: np.ndarray = q, ball: np.ndarray = ball) -> np.ndarray:
            return landing_offset(robot, camera, model, replace(asked, frames={**asked.frames, joint: m}), q, ball)

        error = float(np.linalg.norm(offset(mount)))
        if not np.isfinite(error):  # the ball lies above the model's horizon
            return {"distance_m": distance, "error_m": None, "std_m": None, "worst_bearing_deg": None}
        if best["error_m"] is None or error > best["error_m"]:
            J = np.stack([(offset(mount + h) - offset(mount - h)) / (2 * STEP) for h in STEP * np.eye(6)], axis=1)
            formal = float(np.sqrt(np.trace(J @ covariance @ J.T)))
            jackknife = _jackknife_std(offset, replicates)
            best.update(error_m=error, std_m=max(formal, jackknife), formal_std_m=formal, jackknife_std_m=jackknife,
                        worst_bearing_deg=float(np.rad2deg(bearing)))  # fmt: skip
    return best


def _jackknife_std(offset: Callable[[np.ndarray], np.ndarray], replicates: np.ndarray | None) -> float:
    """sqrt of the trace of the grouped jackknife's covariance [m] of a landing offset over the mounts `replicates`
    (G, 6); 0 without, inf when a replicate puts the ball above the horizon."""
    if replicates is None:
        return 0.0
    values = np.array([offset(m) for m in replicates])
    if not np.all(np.isfinite(values)):
        return float("inf")
    return float(np.sqrt(np.trace(jackknife_covariance(values))))


def landing_offset(robot: Robot, camera: CameraModel, model: Corrections, reference: Corrections, q: np.ndarray,
                   ball: np.ndarray) -> np.ndarray:  # fmt: skip
    """(2,) where `model` puts a ball lying at `ball` (3,) on the floor (floor frame [m]) less where it lies, the
    ball seen by `reference`'s camera at the readings q (J,) [m]; NaN when the model puts it above its horizon."""
    T_floor_camera, _ = camera_in_floor(robot, q[None], reference)
    uv = camera.project((invert_transform(T_floor_camera[0]) @ np.append(ball, 1.0))[:3])
    return ground_point(robot, q, model, uv, camera)[:2] - ball[:2]
