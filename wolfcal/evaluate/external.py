"""Held-out evaluation of external-camera captures: how well a model predicts what a tripod camera saw.

Each held-out capture is its own placement: its camera pose is estimated with the chain held at the judged model
(the present calibration, else the nominal URDF, "before"; the calibration "after"), so only the model's chain is
judged. Figures per camera:
- reprojection RMS per axis [px] of the corners of the fit's tags (inlier views), and the max corner distance;
- the study's tag-grid metric on each foot tag relative to the torso tag [mm]: T_torso_tag_foot_tag measured by PnP
  of both tags in the same image against the model's prediction; mean distance of a 5 x 4 grid on the foot tag;
- with a simulator's truth beside the captures: the position error of the feet (`Robot.feet`: the config's
  `floor.soles`, else the links of the leg tags) relative to the torso [mm], max over random leg configurations.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.accuracy import link_position_errors
from wolfcal.evaluate.metrics import tag_grid
from wolfcal.fit.camera_block import CameraBlock, placements
from wolfcal.fit.problem import Problem
from wolfcal.fit.solver import solve
from wolfcal.geometry import invert_transform
from wolfcal.observations import Observations
from wolfcal.projection import tag_pose_from_corners
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot


def _reprojection(robot: Robot, obs: Observations, model: Corrections) -> dict:
    """Per-axis RMS and max corner distance [px] with each placement's pose fitted and the chain held at `model`."""
    placement, names = placements(obs, moving=False)
    block = CameraBlock(robot, obs, obs.observed_tag_ids, True, placement, names, fixed=model)
    problem = Problem(ParameterSet([]), [block], [robot.config.priors.pixel_noise], robot.config.priors.encoder_noise)
    b = solve(problem).blocks[0]
    return {"rms_px": round(b.rms_after, 4), "max_px": round(b.max_after, 4), "outlier_views": len(b.outlier_views)}


def foot_tag_grid_mm(robot: Robot, obs: Observations, model: Corrections) -> list[float]:
    """Per sample with the torso tag and a foot tag fully seen: mean grid distance [mm] of each foot tag."""
    fixed = [t for t in obs.observed_tag_ids if robot.off_the_legs(robot.config.tag(t).link)]
    moving = [t for t in obs.observed_tag_ids if t not in fixed]
    if not fixed or not moving:
        return []
    out = []
    base = robot.config.base_link
    for s in range(obs.n_samples):
        found = {t: tag_pose_from_corners(robot, obs, s, t) for t in fixed + moving}
        measured = {t: T for t, T in found.items() if T is not None}
        ref = next((t for t in fixed if t in measured), None)
        if ref is None:
            continue
        for t in moving:
            if t not in measured:
                continue
            links = [robot.config.tag(ref).link, robot.config.tag(t).link]
            poses = robot.model.link_poses(obs.q_measured[s : s + 1], links, model, base=base)
            T_ref = poses[links[0]][0] @ robot.T_link_tag(ref, model)
            T_tag = poses[links[1]][0] @ robot.T_link_tag(t, model)
            predicted = invert_transform(T_ref) @ T_tag
            seen = invert_transform(measured[ref]) @ measured[t]
            grid = tag_grid(robot.config.tag(t).size)
            d = (grid @ predicted[:3, :3].T + predicted[:3, 3]) - (grid @ seen[:3, :3].T + seen[:3, 3])
            out.append(float(np.mean(np.linalg.norm(d, axis=1)) * 1000))
    return out


def external_metrics(
    robot: Robot,
    observations: dict[str, Observations],
    fitted: Corrections,
    truth: Corrections | None,
    say: Callable[[str], None],
    before: Corrections | None = None,
) -> dict:
    """Before (`before`, default the nominal URDF) / after figures of every external camera's held-out views (see
    the module docstring)."""
    if not observations:
        raise WolfcalError("the held-out captures hold no external-camera views of the fit's tags")
    out: dict = {"meaning": __doc__.split("\n\n", 1)[1].strip(), "cameras": {}}
    models = {"before": before if before is not None else Corrections(), "after": fitted}
    for name, obs in observations.items():
        say(f"external camera {name}: fitting each placement's pose with the chain held, before and after ...")
        rows = {}
        for label, model in models.items():
            grid = foot_tag_grid_mm(robot, obs, model)
            rows[label] = {
                **_reprojection(robot, obs, model),
                "tag_grid_mm_mean": round(float(np.mean(grid)), 3) if grid else None,
                "tag_grid_mm_std": round(float(np.std(grid)), 3) if grid else None,
            }
        out["cameras"][name] = {"n_samples": obs.n_samples, **rows}
    if truth is not None and robot.feet:
        rng = np.random.default_rng(0)
        out["sole_error_mm"] = {
            label: {s: round(float(link_position_errors(robot, s, m, truth, 300, rng).max() * 1000), 3)
                    for s in robot.feet}
            for label, m in models.items()
        }  # fmt: skip
    return out
