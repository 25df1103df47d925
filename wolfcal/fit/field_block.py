"""Field blocks: the head camera sees the white lines of a RoboCup field while the robot stands on it.

The robot stands with both soles on the field; its floor frame (`robot.floor.floor_frames`: origin midway between
the standing soles, z up) lies on the field at an unknown place: T_field_floor = Trans(x, y, 0) @ Rz(yaw), the
block's own unknowns `field_pose.x|y|yaw` [m, m, rad] (one place per capture file: `field_pose@k.` with several),
started from a search around the config's `field.robot_at` (`wolfcal.field.place`). Each detected line point's
ray meets the floor at a ground point; its residual is the distance of that point from the nearest field line
(`wolfcal.field.model`, the association redone at every linearisation), divided by the ground length of one pixel
across that line at that place under the nominal model, so it reads in pixels and far points count as near ones.

Each marking's place is an unknown too, with a prior of MARKING_PRIOR_M (`line<k>.offset`, `circle.x|y|radius`): an
error that every view of one marking repeats (paint off the field's dimensions, a line on the edge of two mowing
stripes read a little toward the brighter one) is not averaged out by more views, and the robot's place, which
the markings' places share, is known only as well as they are.

The noise model below does not name all the detector does (a view off as a whole by more than its readings'
rounding, a line on a mowing stripe's edge read off near the robot): each reported std is the larger of the formal
one and a grouped jackknife's over the views (`wolfcal.fit.jackknife.RULE`), as the held-out check's.

What lines alone cannot tell: the camera's height against the scale of what it sees (only the lines' perspective
holds it), and its yaw against the robot's yaw on the field (both turn every view alike); the summary names such
pairs from the correlations. The field's point symmetry is handled before the fit (`wolfcal.field.place`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wolfcal.field.ground import ground_gradient
from wolfcal.field.model import FieldLines, line_offset_normal, nearest_line_normal
from wolfcal.field.observations import FieldObservations
from wolfcal.field.place import far_places
from wolfcal.field.selection import line_stretches, lines_seen, points_used
from wolfcal.fit.blocks import Block, FittedBlock, Linearization, held_joint_groups
from wolfcal.fit.floor_block import standing_chain
from wolfcal.fit.jackknife import RULE
from wolfcal.outliers import OutlierRule
from wolfcal.projection import BEHIND_CAMERA_PX
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.derivatives import cross
from wolfcal.robot.floor import camera_in_floor, floor_frame_twists, floor_frames
from wolfcal.robot.parameters import Parameter, ParameterSet
from wolfcal.robot.robot import Robot

PLACE_PRIOR_M = 0.3  # how far the robot may stand from `field.robot_at` [m]
YAW_PRIOR_RAD = 0.2  # [rad] (about 10 deg)
# how far a marking's detected centre may lie from where the field's dimensions put it, the same in every view of it:
# the paint's place, and the detector's lean toward the brighter of two mowing stripes whose edge a line lies on [m]
MARKING_PRIOR_M = 0.01
LINE_BIAS_PX = 0.3  # a line's points in one view share the detector's error across that line (blur, shading) [px]
VIEW_RULE = OutlierRule(4.0, 3.0)  # a view whose points are off by 4x the median view's and 3 px is left out
LINE_POINT_RULE = OutlierRule(4.0, 2.0)  # and a single point (a robot's leg, the ball) off by 2 px of a view kept


def field_pose_names(n_placements: int) -> list[str]:
    """The prefix of each placement's unknowns: 'field_pose', or 'field_pose@1', 'field_pose@2', ..."""
    return ["field_pose"] if n_placements == 1 else [f"field_pose@{k + 1}" for k in range(n_placements)]


class FieldBlock(Block):
    """Line points of the field seen while the robot stood; see the module docstring."""

    name, system, unit, unit_name, dim = "field", "field", "px", "line point", 1
    outlier_rule, unit_rule = VIEW_RULE, LINE_POINT_RULE
    # the noise level starts at, and each line's shared detection error in a view is at least, LINE_BIAS_PX
    noise_min, noise_max, noise_start = 0.05, 20.0, LINE_BIAS_PX

    def __init__(self, robot: Robot, obs: FieldObservations, lines: FieldLines, fixed: Corrections | None = None,
                 weighted_at: Corrections | None = None, shared_lines: bool = True,
                 marking_places: bool = True, jackknife_groups: int = 0, held_lines: bool = False) -> None:  # fmt: skip
        """Own unknowns: the robot's place per placement (`field_pose_names`), then the place of every marking,
        shared by every view and placement: a straight line's offset along its normal
        (`line<k>.offset`, k its row in `lines.segments`) and the centre circle's centre and radius (`circle.x|y`,
        `circle.radius`) [m]; `marking_places` False: the markings held where the field's dimensions put them.
        `weighted_at`: the model whose pixel scale on the ground weighs the points and whose nearest lines choose
        them (default: `fixed`, the nominal model); a solve with the block starts there too (`Block.chain_start`):
        a start degrees off, with the points weighted for a camera where it should be, can settle on other lines.
        `reweighted` gives a block weighted and started at a fit's solution.
        `shared_lines` False: no error shared by a line's points (`shared_labels`), a cheaper noise model for a
        first solve that only finds where to weigh the points. `jackknife_groups` > 0: the reported std checked
        against a jackknife over that many groups of views (`wolfcal.fit.jackknife`). `held_lines`: each point
        kept on the line nearest it where the block is weighted (`line_of_unit`), not the nearest at each
        linearisation: a point near two lines (a corner, a line's end) that changes its line changes its
        residual by a jump (the pixel scale across the two differs), and the solve may stop at another of the
        many such steps of the cost, by up to half a standard deviation."""
        self.robot, self.lines, self.fixed = robot, lines, fixed or Corrections()
        self.shared_lines, self.jackknife_groups, self.held_lines = shared_lines, jackknife_groups, held_lines
        self.jackknife_ratio: dict[str, float] = {}
        self.detected = obs  # every point found; the block uses those on lines seen by enough of them
        model = self.weighted_at = weighted_at or self.fixed
        self.chain_start = weighted_at
        T_floor_camera = camera_in_floor(robot, obs.q_measured, model)[0]
        line = lines_seen(obs, lines, T_floor_camera[obs.sample_index])
        keep = points_used(obs.sample_index, line)
        self.point_of_unit = np.flatnonzero(keep)  # (U,) each unit's point in `detected`
        if not keep.all():
            obs, line = obs.only_points(keep), line[keep]
            T_floor_camera = camera_in_floor(robot, obs.q_measured, model)[0]
        self.obs, self.line_of_unit = obs, line
        self.stretch_of_unit = line_stretches(obs.sample_index, line, obs.uv)
        self.tag_ids: list[int] = []
        self.camera_name = "head"
        self.q_measured = obs.q_measured
        self.sample_of_unit = obs.sample_index
        self.view_of_unit = obs.sample_index  # a view is one image; its points are left out one by one too
        self.view_labels = [(s, -1) for s in range(obs.n_samples)]
        self.placement_of_unit = obs.placement[obs.sample_index]
        self.rays = obs.camera.unproject(obs.uv)  # (M, 3) in the optical frame
        self.ground_gradient = ground_gradient(obs.camera, T_floor_camera[obs.sample_index], obs.uv)
        names = field_pose_names(len(obs.starts))
        places = [Parameter(f"{name}.{c}", "field", name, i, "m" if i < 2 else "rad",
                            PLACE_PRIOR_M if i < 2 else YAW_PRIOR_RAD, float(obs.starts[k, i]))
                  for k, name in enumerate(names) for i, c in enumerate(("x", "y", "yaw"))]  # fmt: skip
        # every marking's place is an unknown, seen or not: a point's nearest marking may change as the estimate
        # moves, and one held at its nominal place would pin the robot's place, which the markings' places share
        self.marking_places = marking_places
        marking_names = [*(f"line{k}.offset" for k in range(len(lines.segments))), "circle.x", "circle.y",
                         "circle.radius"] if marking_places else []  # fmt: skip
        self.nuisance = ParameterSet(places + [Parameter(name, "marking", name.split(".")[0], i, "m", MARKING_PRIOR_M)
                                               for i, name in enumerate(marking_names)])  # fmt: skip

    def reweighted(self, chain: ParameterSet, values: np.ndarray, jackknife_groups: int = 0) -> FieldBlock:
        """The same points weighted at a solution (chain values, then this block's own), starting there: the pixel
        scale on the ground changes steeply with the camera's pitch, so weights taken at a nominal model several
        degrees off misstate how far each point is off in the image. Each point is held on its nearest line there
        (`held_lines`)."""
        obs = replace(self.detected, starts=self.places(values[len(chain) :]))
        model = chain.corrections(values[: len(chain)]).plus(self.fixed)
        return FieldBlock(self.robot, obs, self.lines, self.fixed, weighted_at=model,
                          marking_places=self.marking_places, jackknife_groups=jackknife_groups,
                          held_lines=True)  # fmt: skip

    @property
    def n_samples(self) -> int:
        return self.detected.n_samples

    def without_samples(self, keep: np.ndarray) -> FieldBlock:
        """The views where keep (S,) is True (of every view found, `detected`), weighted and started alike
        (`wolfcal.fit.jackknife.Replicable`)."""
        return FieldBlock(self.robot, self.detected.only_samples(keep), self.lines, self.fixed,
                          weighted_at=self.weighted_at, shared_lines=self.shared_lines,
                          marking_places=self.marking_places, held_lines=self.held_lines)  # fmt: skip

    def units_in(self, part: Block, keep: np.ndarray) -> np.ndarray:
        """(U_part,) this block's unit of each unit of `part` (`without_samples(keep)`): the points a view uses do
        not depend on the other views."""
        assert isinstance(part, FieldBlock)
        points = np.flatnonzero(np.asarray(keep, bool)[self.detected.sample_index])[part.point_of_unit]
        units = np.searchsorted(self.point_of_unit, points)
        assert np.array_equal(self.point_of_unit[units], points), "a view's points do not depend on the others"
        return units

    def places(self, local_values: np.ndarray) -> np.ndarray:
        """(P, 3) the robot's place per placement (x, y [m], yaw [rad]) from the block's own unknowns (L,)."""
        return local_values[: 3 * len(self.obs.starts)].reshape(-1, 3)

    def shared_labels(self) -> np.ndarray:
        """(U,) the points of one stretch of a line in one view share the detector's error across that line (its
        width, blur and shading, and the line's sub-pixel phase against the scan lines, which drifts along it):
        one label per (view, line, stretch) where the block was weighted (none without `shared_lines`)."""
        if not self.shared_lines:
            return np.full(self.n_units, -1)
        _, labels = np.unique(np.stack([self.sample_of_unit, self.line_of_unit, self.stretch_of_unit], axis=1),
                              axis=0, return_inverse=True)  # fmt: skip
        return labels.ravel()

    def joint_reading_groups(self) -> np.ndarray:
        """The standing legs hold one pose in every field sample: their readings' error is shared by all."""
        return held_joint_groups(self.q_measured, self.sample_of_unit)

    def report(self, fitted: FittedBlock) -> dict:
        entry = super().report(fitted)
        names = field_pose_names(len(self.obs.starts))
        poses = self.places(fitted.local_values)
        entry["field_poses"] = {
            name: {"x_m": round(float(x), 5), "y_m": round(float(y), 5), "yaw_rad": round(float(yaw), 6)}
            for name, (x, y, yaw) in zip(names, poses)
        }
        entry["n_line_points"] = len(self.obs.uv)
        marking_names = self.nuisance.names[3 * len(poses) :]
        entry["marking_places_m"] = {name: round(float(v), 5) for name, v in
                                     zip(marking_names, fitted.local_values[3 * len(poses) :])}  # fmt: skip
        entry["notes"] = far_places(self.obs, names, poses)
        if self.jackknife_ratio:
            shown = [*fitted.chain.names, *self.nuisance.names[: 3 * len(poses)]]
            entry["std_rule"] = RULE
            entry["jackknife_over_formal_std"] = {name: round(self.jackknife_ratio[name], 3) for name in shown}
        return entry

    @staticmethod
    def summary_lines(entry: dict) -> list[str]:
        """The common lines (`Block.summary_lines`), counting line points and their RMS across the lines, and the
        markings' places (`marking_places_m`: the parameter list of the summary leaves them out)."""
        lines = Block.summary_lines(entry)
        lines = [lines[0].replace("corners used", "line points used"),
                 lines[1].replace("reprojection RMS", "distance from the lines")]  # fmt: skip
        places = entry.get("marking_places_m") or {}
        if places:
            name = max(places, key=lambda n: abs(places[n]))
            lines.append(f"  markings' places ({len(places)} unknowns, prior {1000 * MARKING_PRIOR_M:.0f} mm, in "
                         f"result.yaml): largest {name} {1000 * places[name]:+.1f} mm")  # fmt: skip
        ratios = entry.get("jackknife_over_formal_std") or {}
        if ratios:
            name = max(ratios, key=lambda n: ratios[n])
            lines.append(f"  std: the larger of the formal one and a jackknife's over groups of the views (largest "
                         f"jackknife / formal: {name} {ratios[name]:.2f})")  # fmt: skip
        return [*lines, *(f"  warning: {note}" for note in entry.get("notes", []))]

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        s, k = self.sample_of_unit, self.placement_of_unit
        n_joints = self.q_measured.shape[1]
        c = standing_chain(self.robot, self.q_measured, chain, chain_values, self.fixed)
        T_root_floor = floor_frames(c.T_root_soles)[s]  # (M, 4, 4)
        twist = floor_frame_twists(c.T_root_soles, c.twists_soles)[s] - c.twists_camera[s]  # floor against camera
        R_root_camera, t_root_camera = c.T_root_camera[s, :3, :3], c.T_root_camera[s, :3, 3]
        d_root = np.einsum("mij,mj->mi", R_root_camera, self.rays)
        R_floor_root = np.swapaxes(T_root_floor[:, :3, :3], 1, 2)
        o = np.einsum("mij,mj->mi", R_floor_root, t_root_camera - T_root_floor[:, :3, 3])  # camera in the floor
        d = np.einsum("mij,mj->mi", R_floor_root, d_root)
        # the floor moves against the camera by `twist`: the ray moves against the floor by its opposite
        do = -np.einsum("mij,mcj->mci", R_floor_root, twist[..., :3] + cross(twist[..., 3:], t_root_camera[:, None]))
        dd = -np.einsum("mij,mcj->mci", R_floor_root, cross(twist[..., 3:], d_root[:, None]))
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = -o[:, 2] / d[:, 2]  # ray length to the floor
            g = o[:, :2] + scale[:, None] * d[:, :2]  # (M, 2) ground point in the floor frame [m]
            dg = (
                do[..., :2]
                - (do[..., 2:3] / d[:, None, 2:3]) * d[:, None, :2]
                + scale[:, None, None] * (dd[..., :2] - dd[..., 2:3] * d[:, None, :2] / d[:, None, 2:3])
            )
        x, y, yaw = self.places(local_values)[k].T
        cos, sin = np.cos(yaw), np.sin(yaw)
        R = np.stack([np.stack([cos, -sin], -1), np.stack([sin, cos], -1)], axis=1)  # (M, 2, 2) floor -> field
        turned = np.einsum("mij,mj->mi", R, g)
        p = turned + np.stack([x, y], axis=1)
        if self.held_lines:
            marking = self.line_of_unit
            offset, normal = line_offset_normal(self.lines, p, marking)
        else:
            offset, normal, marking = nearest_line_normal(self.lines, p)
        known = np.full(len(p), self.marking_places)
        column = 3 * len(self.obs.starts) + marking if self.marking_places else np.zeros(len(p), int)  # 1st unknown
        on_circle = marking == len(self.lines.segments)
        placed = known & on_circle  # from the circle's fitted centre and radius
        offset = offset - np.where(known & ~on_circle, local_values[column], 0.0)
        centre = np.zeros((int(on_circle.sum()), 2))
        centre[placed[on_circle]] = local_values[column[placed, None] + np.arange(2)]
        radius = np.linalg.norm(p[on_circle] - centre, axis=1)
        normal[on_circle] = (p[on_circle] - centre) / radius[:, None]
        offset[on_circle] = radius - self.lines.circle_radius
        offset[placed] -= local_values[column[placed] + 2]
        A = R @ self.ground_gradient  # (M, 2, 2) d(field point)/d(pixel), held at the nominal model's
        m = np.einsum("mji,mj->mi", A, normal)  # how far across the line one pixel step moves [m/px]
        weight = 1.0 / np.maximum(np.linalg.norm(m, axis=1), 1e-9)  # [px/m]
        residual = (offset * weight)[:, None]
        grad = weight[:, None] * normal  # d(residual)/d(field point) [px/m]
        if on_circle.any():  # the circle's normal turns with the point, and the weight with it
            n = normal[on_circle]
            Am = np.einsum("mij,mj->mi", A[on_circle], m[on_circle])
            across = Am - np.einsum("mi,mi->m", n, Am)[:, None] * n
            grad[on_circle] -= (offset[on_circle] * weight[on_circle] ** 3 / radius)[:, None] * across
        dp = np.einsum("mij,mcj->mci", R, dg)  # (M, J + P, 2) field-point motion per column
        d_columns = np.einsum("mi,mci->mc", grad, dp)
        dp_dyaw = np.stack([-turned[:, 1], turned[:, 0]], axis=1)
        # the weight turns with the robot too: A = R(yaw) G
        dA_dyaw = np.stack([np.stack([-sin, -cos], -1), np.stack([cos, -sin], -1)], axis=1) @ self.ground_gradient
        dm_dyaw = np.einsum("mji,mj->mi", dA_dyaw, normal)
        dweight_dyaw = -(weight**3) * np.einsum("mi,mi->m", m, dm_dyaw)
        d_yaw = np.einsum("mi,mi->m", grad, dp_dyaw) + offset * dweight_dyaw
        d_marking = np.zeros((len(p), 3))  # a line's offset; the circle's centre (x, y) and radius
        d_marking[:, 0] = -weight * known
        d_marking[placed] = np.column_stack([-grad[placed], -weight[placed]])
        jac_local = np.concatenate([np.stack([grad[:, 0], grad[:, 1], d_yaw], axis=1), d_marking], axis=1)[:, None]
        bad = ~(np.isfinite(residual[:, 0]) & (scale > 0) & np.all(np.isfinite(d_columns), axis=1))
        residual[bad], d_columns[bad], jac_local[bad] = BEHIND_CAMERA_PX, 0.0, 0.0
        local_cols = np.concatenate(
            [3 * k[:, None] + np.arange(3), column[:, None] + np.where(placed[:, None], np.arange(3), 0)], axis=1
        )
        return Linearization(residual=residual, jac_chain=d_columns[:, None, n_joints:], jac_local=jac_local,
                             local_cols=local_cols, joint_sensitivity=d_columns[:, None, :n_joints])  # fmt: skip
