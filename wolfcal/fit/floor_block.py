"""Floor blocks: the head camera sees tags lying flat on the floor while the robot stands on it.

The floor is the plane of the standing soles (`evaluate.ground.floor_frames`: origin midway between the soles, z
along their mean z axis). Each floor tag lies face up on it at an unknown place: T_floor_tag = Trans(x, y, thickness)
@ Rz(yaw), unknowns `floor.tag<id>.x|y|yaw` [m, rad] of the block (started from the nominal model's ray through the
first view's corners). Residual per corner [px]: project(K, D, T_camera_base(q) @ T_base_floor(q) @ T_floor_tag @
p_corner) + inset * d_corner - u_detected, divided by max(1, REFERENCE_EDGE_PX / apparent edge). The corners of
small, strongly foreshortened far tags come out of the detector biased inward (up to ~1 px at 4 m): so a tag seen
small counts as much as one seen REFERENCE_EDGE_PX wide, no more, and that bias is one more unknown of the block,
`floor.corner_inset` [px]: every edge of a tag view moved inward by it at REFERENCE_EDGE_PX apparent edge, by
inset * REFERENCE_EDGE_PX / edge above (d_corner: `vision.corner_bias.inset_directions`), so that it does not read
as a smaller, farther tag and a tilted floor. Height and tilt of every tag come from the standing soles, so the
block measures the camera relative to the floor through the standing legs. Besides whole views (`FIT_VIEW_PX`), single
corners far off are left out (`unit_rule`, `outliers.FLOOR_CORNER_PX`, as the measured ground error leaves them out).

`SoleClosure`: both standing soles lie on the floor. Residual per floor sample [m]: the height of each sole's origin
above the other sole's plane (2 numbers) and the tilt between the soles' z axes as a displacement at SOLE_LEVER_M
(2 numbers). Derivatives are analytic: the soles' and the camera's twists (`wolfcal.robot.derivatives`) and the floor
frame's twist through its means and normalisations (`wolfcal.robot.floor.floor_frame_twists`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.config import PriorConfig
from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block, FittedBlock, Linearization, held_joint_groups
from wolfcal.fit.options import NOISE_FLOOR_PX
from wolfcal.fit.tag_report import tag_view_report
from wolfcal.geometry import invert_transform, tag_corners
from wolfcal.observations import Observations
from wolfcal.outliers import FIT_VIEW_PX, FLOOR_CORNER_PX, SOLE_CLOSURE_M
from wolfcal.projection import BEHIND_CAMERA_PX, pixel_jacobian
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.derivatives import ChainDerivatives, cross, point_motion
from wolfcal.robot.floor import floor_frame_twists, floor_frames
from wolfcal.robot.parameters import Parameter, ParameterSet
from wolfcal.robot.robot import Robot
from wolfcal.robot.stances import SOLE_LEVER_M, STANDING_RULE, off_plane, sole_gaps
from wolfcal.vision.corner_bias import (
    CORNER_INSET,
    REFERENCE_EDGE_PX,
    apparent_edges,
    edge_normals,
    inset_directions,
    small_view_weight,
)

PLACE_PRIOR_M = 10.0  # weak priors of a floor tag's place: the data decide it [m]
YAW_PRIOR_RAD = 10.0  # [rad]
INSET_PRIOR_PX = 1.0  # prior of the corner detector's inward bias at REFERENCE_EDGE_PX [px]


def _poses(robot: Robot, q: np.ndarray, model: Corrections) -> tuple[np.ndarray, np.ndarray]:
    """T_camera_floor (S, 4, 4) and the sole poses in the base frame (K, S, 4, 4) under a model."""
    frame, soles = robot.config.head_camera().frame, list(robot.config.floor_config().soles)
    poses = robot.model.link_poses(q, [frame, *soles], model, base=robot.config.base_link)
    sole_poses = np.stack([poses[s] for s in soles])
    return invert_transform(poses[frame]) @ floor_frames(sole_poses), sole_poses


@dataclass
class StandingChain:
    """The soles and the camera at one parameter vector, in the chain's root frame, with their twists."""

    T_root_soles: np.ndarray  # (K, S, 4, 4)
    twists_soles: np.ndarray  # (K, S, J + P, 6): joint readings first, then chain parameters
    T_root_camera: np.ndarray  # (S, 4, 4)
    twists_camera: np.ndarray  # (S, J + P, 6)


def standing_chain(robot: Robot, q: np.ndarray, chain: ParameterSet, values: np.ndarray,
                    fixed: Corrections) -> StandingChain:  # fmt: skip
    """Poses and twists of the soles and the head camera for readings q (S, J) under the chain's values."""
    frame, soles = robot.config.head_camera().frame, list(robot.config.floor_config().soles)
    d = ChainDerivatives(robot, q, chain.corrections(values).plus(fixed), chain, [frame, *soles], [])

    def twists(link: str) -> np.ndarray:
        return np.concatenate([d.twist_q(link), d.twist_p(link)], axis=1)

    return StandingChain(np.stack([d.T_root[s] for s in soles]), np.stack([twists(s) for s in soles]),
                          d.T_root[frame], twists(frame))  # fmt: skip


class FloorBlock(Block):
    """Corners of the floor tags the head camera saw while the robot stood; see the module docstring."""

    system, unit, unit_name, dim = "floor", "px", "corner", 2
    outlier_rule = FIT_VIEW_PX
    unit_rule = FLOOR_CORNER_PX
    noise_min, noise_max = NOISE_FLOOR_PX, 50.0  # the floor is the fit's setting (`FitOptions.noise_floor_px`)

    def __init__(self, robot: Robot, obs: Observations, fixed: Corrections | None = None) -> None:
        self.robot, self.obs, self.fixed = robot, obs, fixed or Corrections()
        self.name, self.camera_name = "floor", obs.camera_name
        floor = robot.config.floor_config()
        self.tag_ids = obs.observed_tag_ids
        column = {t: i for i, t in enumerate(self.tag_ids)}
        self.tag_col = np.array([column[int(t)] for t in obs.tag_ids], dtype=int)
        corners = np.stack([tag_corners(floor.tag(t).size) for t in self.tag_ids])
        self.p_tag = corners[self.tag_col, obs.corner_index]  # (M, 3) corner in its tag frame [m]
        self.height = np.array([floor.tag(t).thickness for t in self.tag_ids])[self.tag_col]
        self.sample_of_unit, self.q_measured = obs.sample_index, obs.q_measured
        views, view_of_unit = np.unique(np.stack([obs.sample_index, obs.tag_ids], axis=1), axis=0, return_inverse=True)
        self.view_of_unit = view_of_unit.ravel()
        self.view_labels = [(int(s), int(t)) for s, t in views]
        edge = self._apparent_edge()
        self.weight = small_view_weight(edge)
        self.normals = edge_normals(self._rings())[self.view_of_unit, obs.corner_index]  # (M, 2, 2)
        # (M, 2) d(detected corner)/d(inset) [px/px] along the corner's edge normals: the inset at REFERENCE_EDGE_PX,
        # shrinking as 1/edge above
        inward = self._inward() * np.minimum(1.0, REFERENCE_EDGE_PX / edge)[:, None]
        self.inward = np.einsum("mij,mj->mi", self.normals, inward)
        self.nuisance = self._place_parameters() + ParameterSet(
            [Parameter(CORNER_INSET, "floor", "floor", 0, "px", INSET_PRIOR_PX)]
        )

    def joint_reading_groups(self) -> np.ndarray:
        """The standing legs hold one pose in every floor sample: their readings' error is shared by all."""
        return held_joint_groups(self.q_measured, self.sample_of_unit)

    def start_noise(self, priors: PriorConfig) -> float:
        """The configured corner detection noise (`priors.pixel_noise`) [px]."""
        return priors.pixel_noise

    def report(self, fitted: FittedBlock) -> dict:
        return tag_view_report(self, fitted)

    def _rings(self) -> np.ndarray:
        """(V, 4, 2) the detected corners of each view [px], NaN where one is missing."""
        ring = np.full((len(self.view_labels), 4, 2), np.nan)
        ring[self.view_of_unit, self.obs.corner_index] = self.obs.uv
        return ring

    def _apparent_edge(self) -> np.ndarray:
        """(M,) mean edge length of each corner's tag view in the image [px]."""
        return apparent_edges(self._rings())[self.view_of_unit]

    def _inward(self) -> np.ndarray:
        """(M, 2) `corner_bias.inset_directions` of each detected corner's view [px/px]."""
        return inset_directions(self._rings())[self.view_of_unit, self.obs.corner_index]

    def _place_parameters(self) -> ParameterSet:
        """x, y, yaw of each floor tag, started where the nominal model's rays through its first view meet the
        floor (mean of the corners; yaw from the first edge)."""
        T_camera_floor, _ = _poses(self.robot, self.q_measured, self.fixed)
        camera = self.obs.camera
        rays = camera.unproject(self.obs.uv)  # (M, 3) in the optical frame
        T_floor_camera = invert_transform(T_camera_floor)[self.sample_of_unit]
        d = np.einsum("mij,mj->mi", T_floor_camera[:, :3, :3], rays)
        o = T_floor_camera[:, :3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.height - o[:, 2]) / d[:, 2]
        hit = o + t[:, None] * d
        params = []
        for k, tag_id in enumerate(self.tag_ids):
            first = min(s for s, t_ in self.view_labels if t_ == tag_id)
            rows = np.flatnonzero((self.tag_col == k) & (self.sample_of_unit == first))
            rows = rows[np.argsort(self.obs.corner_index[rows])]
            points = hit[rows, :2]
            centre = points.mean(axis=0) if np.all(np.isfinite(points)) else np.array([2.0, 0.0])
            edge = points[1] - points[0] if len(rows) >= 2 else np.array([1.0, 0.0])
            yaw = float(np.arctan2(edge[1], edge[0])) if np.all(np.isfinite(edge)) else 0.0
            for i, (c, value) in enumerate(zip(("x", "y", "yaw"), (*centre, yaw))):
                params.append(Parameter(f"floor.tag{tag_id}.{c}", "floor", f"floor.tag{tag_id}", i,
                                        "m" if i < 2 else "rad", PLACE_PRIOR_M if i < 2 else YAW_PRIOR_RAD,
                                        float(value)))  # fmt: skip
        return ParameterSet(params)

    def _floor_points(self, place: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M, 3) corners on the floor [m] and their derivatives (M, 3, 3) by the corner's tag's x, y, yaw."""
        x, y, yaw = place[: 3 * len(self.tag_ids)].reshape(-1, 3)[self.tag_col].T
        c, s = np.cos(yaw), np.sin(yaw)
        px, py = self.p_tag[:, 0], self.p_tag[:, 1]
        p = np.stack([x + c * px - s * py, y + s * px + c * py, self.height], axis=1)
        d = np.zeros((len(p), 3, 3))
        d[:, 0, 0] = d[:, 1, 1] = 1.0
        d[:, 0, 2], d[:, 1, 2] = -s * px - c * py, c * px - s * py
        return p, d

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        p_floor, dp_place = self._floor_points(local_values)
        s, n_joints = self.sample_of_unit, self.q_measured.shape[1]
        c = standing_chain(self.robot, self.q_measured, chain, chain_values, self.fixed)
        T_root_floor = floor_frames(c.T_root_soles)[s]  # (M, 4, 4)
        twist = floor_frame_twists(c.T_root_soles, c.twists_soles)[s] - c.twists_camera[s]  # floor against camera
        p_root = np.einsum("mij,mj->mi", T_root_floor[:, :3, :3], p_floor) + T_root_floor[:, :3, 3]
        R_camera_root = np.swapaxes(c.T_root_camera[s, :3, :3], 1, 2)
        p_camera = np.einsum("mij,mj->mi", R_camera_root, p_root - c.T_root_camera[s, :3, 3])
        dp = R_camera_root @ point_motion(twist, p_root)  # (M, 3, J + P)
        dp_q, dp_chain = dp[..., :n_joints], dp[..., n_joints:]
        dp_local = R_camera_root @ T_root_floor[:, :3, :3] @ dp_place
        N = self.normals * self.weight[:, None, None]  # pixels to weighted distances from the edges' lines
        D = N @ pixel_jacobian(self.obs.camera, p_camera)
        n_places = 3 * len(self.tag_ids)
        inset = local_values[n_places]
        offset = self.obs.camera.project(p_camera) - self.obs.uv
        residual = np.einsum("mij,mj->mi", N, offset) + inset * self.inward * self.weight[:, None]
        bad = ~np.all(np.isfinite(residual), axis=1) | ~np.all(np.isfinite(D), axis=(1, 2))
        residual[bad] = BEHIND_CAMERA_PX
        D[bad] = 0.0
        jac_local = np.concatenate([D @ dp_local, (self.inward * self.weight[:, None])[:, :, None]], axis=2)
        local_cols = np.concatenate([3 * self.tag_col[:, None] + np.arange(3), np.full((len(residual), 1), n_places)],
                                    axis=1)  # fmt: skip
        return Linearization(
            residual=residual, jac_chain=D @ dp_chain, jac_local=jac_local, local_cols=local_cols,
            joint_sensitivity=D @ dp_q,
        )  # fmt: skip


def sole_disagreement(robot: Robot, q: np.ndarray, model: Corrections) -> np.ndarray:
    """(S, 4) how far the standing soles are from one plane: heights of the second sole's origin above the first's
    plane and of the first above the second's [m], and the tilt between their z axes (x, y in the first sole's
    frame) times SOLE_LEVER_M [m]. Needs two soles."""
    _, sole_poses = _poses(robot, q, model)
    return sole_gaps(sole_poses)


def _disagreement_derivatives(sole_poses: np.ndarray, twists: np.ndarray) -> np.ndarray:
    """(S, 4, C) derivatives of `sole_gaps` by the columns of the soles' twists (2, S, C, 6)."""
    (a, b), (ta, tb) = sole_poses, twists
    o_a, o_b, z_a, z_b = a[:, None, :3, 3], b[:, None, :3, 3], a[:, None, :3, 2], b[:, None, :3, 2]
    do_a, do_b = ta[..., :3] + cross(ta[..., 3:], o_a), tb[..., :3] + cross(tb[..., 3:], o_b)  # (S, C, 3)
    dz_a, dz_b = cross(ta[..., 3:], z_a), cross(tb[..., 3:], z_b)
    dh_ab = np.sum(dz_a * (o_b - o_a) + z_a * (do_b - do_a), axis=-1)
    dh_ba = np.sum(dz_b * (o_a - o_b) + z_b * (do_a - do_b), axis=-1)
    dz_b_in_a = np.einsum("sji,scj->sci", a[:, :3, :3], cross(tb[..., 3:] - ta[..., 3:], z_b))
    return np.stack([dh_ab, dh_ba, SOLE_LEVER_M * dz_b_in_a[..., 0], SOLE_LEVER_M * dz_b_in_a[..., 1]], axis=1)


class SoleClosure(Block):
    """Both standing soles on one plane, once per floor sample; see the module docstring."""

    name, system, unit, unit_name, dim = "sole closure", "floor", "m", "sample", 4
    outlier_rule = SOLE_CLOSURE_M
    noise_min, noise_max = 1e-5, 0.1
    noise_start = 1e-3  # [m], before it is estimated

    def __init__(self, robot: Robot, obs: Observations, fixed: Corrections | None = None) -> None:
        self.robot, self.obs, self.fixed = robot, obs, fixed or Corrections()
        self.tag_ids: list[int] = []
        self.camera_name = obs.camera_name
        self.q_measured = obs.q_measured
        self.sample_of_unit = np.arange(obs.n_samples)
        self.view_of_unit = np.arange(obs.n_samples)
        self.view_labels = [(s, -1) for s in range(obs.n_samples)]
        self.nuisance = ParameterSet([])

    def joint_reading_groups(self) -> np.ndarray:
        """The standing legs hold one pose in every floor sample: their readings' error is shared by all."""
        return held_joint_groups(self.q_measured, self.sample_of_unit)

    def report(self, fitted: FittedBlock) -> dict:
        return tag_view_report(self, fitted)

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        c = standing_chain(self.robot, self.q_measured, chain, chain_values, self.fixed)
        d = _disagreement_derivatives(c.T_root_soles, c.twists_soles)
        n_joints = self.q_measured.shape[1]
        return Linearization(
            residual=sole_gaps(c.T_root_soles),
            jac_chain=d[..., n_joints:],
            jac_local=None,
            local_cols=None,
            joint_sensitivity=d[..., :n_joints],
        )


def check_floor_samples(robot: Robot, obs: Observations) -> None:
    """Bad floor input, as a WolfcalError naming the files: a floor tag never seen twice, or a sample whose legs are
    not standing (soles more than 10 deg or 3 cm from one plane under the nominal model)."""
    sources = ", ".join(dict.fromkeys(obs.sources))
    views = np.unique(np.stack([obs.sample_index, obs.tag_ids], axis=1), axis=0)
    seen = {t: int(np.sum(views[:, 1] == t)) for t in obs.observed_tag_ids}
    once = [t for t, n in seen.items() if n < 2]
    if once:
        raise WolfcalError(
            f"{sources}: floor tag(s) {', '.join(map(str, once))} seen in only one sample; a floor tag's place is "
            "unknown, so it needs at least two views: capture more head angles that show it, or remove it"
        )
    if len(robot.config.floor_config().soles) < 2:
        return
    tilt, gap, not_standing = off_plane(sole_disagreement(robot, obs.q_measured, Corrections()))
    bad = np.flatnonzero(not_standing)
    if bad.size:
        s = int(bad[0])
        raise WolfcalError(
            f"{obs.sources[s]}: {bad.size} floor sample(s) not in a standing pose (sample {s}: soles "
            f"{np.rad2deg(tilt[s]):.1f} deg and {gap[s] * 100:.1f} cm from one plane under the nominal model; "
            f"{STANDING_RULE}): floor samples need both soles flat on the floor"
        )
