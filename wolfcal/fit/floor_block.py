"""Floor blocks: the head camera sees tags lying flat on the floor while the robot stands on it.

The floor is the plane of the standing soles (`evaluate.ground.floor_frames`: origin midway between the soles, z
along their mean z axis). Each floor tag lies face up on it at an unknown place: T_floor_tag = Trans(x, y, thickness)
@ Rz(yaw), unknowns `floor.tag<id>.x|y|yaw` [m, rad] of the block (started from the nominal model's ray through the
first view's corners). Residual per corner [px]: project(K, D, T_camera_base(q) @ T_base_floor(q) @ T_floor_tag @
p_corner) - u_detected, divided by max(1, REFERENCE_EDGE_PX / apparent edge): the corners of small, strongly
foreshortened far tags come out of the detector biased inward (up to ~1 px at 4 m), so a tag seen small counts as
much as one seen REFERENCE_EDGE_PX wide, no more. Height and tilt of every tag come from the standing soles, so the
block measures the camera relative to the floor through the standing legs.

`SoleClosure`: both standing soles lie on the floor. Residual per floor sample [m]: the height of each sole's origin
above the other sole's plane (2 numbers) and the tilt between the soles' z axes as a displacement at SOLE_LEVER_M
(2 numbers). Derivatives with respect to the chain and the joint readings are central differences of the forward
kinematics (the floor frame is a normalised mean of two poses).
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block, Linearization
from wolfcal.geometry import invert_transform
from wolfcal.observations import Observations
from wolfcal.outliers import FIT_VIEW_PX, SOLE_CLOSURE_M
from wolfcal.projection import BEHIND_CAMERA_PX, pixel_jacobian
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import floor_frames
from wolfcal.robot.parameters import Parameter, ParameterSet
from wolfcal.robot.robot import Robot
from wolfcal.vision.tags import tag_corners

REFERENCE_EDGE_PX = 40.0  # apparent tag edge [px] below which a floor tag's corners are down-weighted
PLACE_PRIOR_M = 10.0  # weak priors of a floor tag's place: the data decide it [m]
YAW_PRIOR_RAD = 10.0  # [rad]
SOLE_LEVER_M = 0.1  # a tilt between the soles counts as the displacement it makes at this distance [m]
STEP = 1e-6  # central-difference step [SI]


def _poses(robot: Robot, q: np.ndarray, model: Corrections) -> tuple[np.ndarray, np.ndarray]:
    """T_camera_floor (S, 4, 4) and the sole poses in the base frame (K, S, 4, 4) under a model."""
    frame, soles = robot.config.head_camera().frame, list(robot.config.floor_config().soles)
    poses = robot.model.link_poses(q, [frame, *soles], model, base=robot.config.base_link)
    sole_poses = np.stack([poses[s] for s in soles])
    return invert_transform(poses[frame]) @ floor_frames(sole_poses), sole_poses


def _chain_and_joint_derivatives(f, robot: Robot, q: np.ndarray, chain: ParameterSet, values: np.ndarray,
                                 fixed: Corrections) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """f(q, model) -> (N, D) at the values, its derivatives (N, D, P) by the chain values and (N, D, J) by q."""
    def model(v: np.ndarray) -> Corrections:
        return chain.corrections(v).plus(fixed)

    y = f(q, model(values))
    d_chain = np.empty(y.shape + (len(values),))
    for i in range(len(values)):
        step = np.zeros(len(values))
        step[i] = STEP
        d_chain[..., i] = (f(q, model(values + step)) - f(q, model(values - step))) / (2 * STEP)
    base = model(values)
    d_q = np.empty(y.shape + (q.shape[1],))
    for j in range(q.shape[1]):
        step = np.zeros(q.shape[1])
        step[j] = STEP
        d_q[..., j] = (f(q + step, base) - f(q - step, base)) / (2 * STEP)
    return y, d_chain, d_q


class FloorBlock(Block):
    """Corners of the floor tags the head camera saw while the robot stood; see the module docstring."""

    system, unit, dim = "floor", "px", 2
    outlier_rule = FIT_VIEW_PX

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
        self.weight = 1.0 / np.maximum(1.0, REFERENCE_EDGE_PX / self._apparent_edge())
        self.nuisance = self._place_parameters()

    def _apparent_edge(self) -> np.ndarray:
        """(M,) mean edge length of each corner's tag view in the image [px]."""
        ring = np.full((len(self.view_labels), 4, 2), np.nan)
        ring[self.view_of_unit, self.obs.corner_index] = self.obs.uv
        lengths = np.linalg.norm(ring - np.roll(ring, 1, axis=1), axis=2)  # (V, 4), NaN next to a missing corner
        known = np.isfinite(lengths)
        edge = np.where(known.any(axis=1), np.where(known, lengths, 0.0).sum(axis=1) / np.maximum(known.sum(axis=1), 1),
                        REFERENCE_EDGE_PX)
        return edge[self.view_of_unit]

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
        x, y, yaw = place.reshape(-1, 3)[self.tag_col].T
        c, s = np.cos(yaw), np.sin(yaw)
        px, py = self.p_tag[:, 0], self.p_tag[:, 1]
        p = np.stack([x + c * px - s * py, y + s * px + c * py, self.height], axis=1)
        d = np.zeros((len(p), 3, 3))
        d[:, 0, 0] = d[:, 1, 1] = 1.0
        d[:, 0, 2], d[:, 1, 2] = -s * px - c * py, c * px - s * py
        return p, d

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        p_floor, dp_place = self._floor_points(local_values)
        s = self.sample_of_unit

        def per_sample(q: np.ndarray, model: Corrections) -> np.ndarray:
            return _poses(self.robot, q, model)[0].reshape(len(q), 16)

        T, dT_chain, dT_q = _chain_and_joint_derivatives(per_sample, self.robot, self.q_measured, chain,
                                                        chain_values, self.fixed)  # fmt: skip
        T, dT_chain, dT_q = T.reshape(-1, 4, 4)[s], dT_chain.reshape(-1, 4, 4, len(chain_values))[s], \
            dT_q.reshape(-1, 4, 4, self.q_measured.shape[1])[s]
        p_camera = np.einsum("mij,mj->mi", T[:, :3, :3], p_floor) + T[:, :3, 3]
        dp_chain = np.einsum("mijp,mj->mip", dT_chain[:, :3, :3], p_floor) + dT_chain[:, :3, 3]
        dp_q = np.einsum("mijq,mj->miq", dT_q[:, :3, :3], p_floor) + dT_q[:, :3, 3]
        dp_local = T[:, :3, :3] @ dp_place
        D = pixel_jacobian(self.obs.camera, p_camera) * self.weight[:, None, None]
        residual = (self.obs.camera.project(p_camera) - self.obs.uv) * self.weight[:, None]
        bad = ~np.all(np.isfinite(residual), axis=1) | ~np.all(np.isfinite(D), axis=(1, 2))
        residual[bad] = BEHIND_CAMERA_PX
        D[bad] = 0.0
        return Linearization(
            residual=residual, jac_chain=D @ dp_chain, jac_local=D @ dp_local,
            local_cols=3 * self.tag_col[:, None] + np.arange(3), joint_sensitivity=D @ dp_q,
        )  # fmt: skip


def sole_disagreement(robot: Robot, q: np.ndarray, model: Corrections) -> np.ndarray:
    """(S, 4) how far the standing soles are from one plane: heights of the second sole's origin above the first's
    plane and of the first above the second's [m], and the tilt between their z axes (x, y in the first sole's
    frame) times SOLE_LEVER_M [m]. Needs two soles."""
    _, sole_poses = _poses(robot, q, model)
    a, b = sole_poses[0], sole_poses[1]
    h_ab = np.einsum("si,si->s", a[:, :3, 2], b[:, :3, 3] - a[:, :3, 3])
    h_ba = np.einsum("si,si->s", b[:, :3, 2], a[:, :3, 3] - b[:, :3, 3])
    z_b_in_a = np.einsum("sji,sj->si", a[:, :3, :3], b[:, :3, 2])
    return np.stack([h_ab, h_ba, SOLE_LEVER_M * z_b_in_a[:, 0], SOLE_LEVER_M * z_b_in_a[:, 1]], axis=1)


class SoleClosure(Block):
    """Both standing soles on one plane, once per floor sample; see the module docstring."""

    name, system, unit, dim = "sole closure", "floor", "m", 4
    outlier_rule = SOLE_CLOSURE_M

    def __init__(self, robot: Robot, obs: Observations, fixed: Corrections | None = None) -> None:
        self.robot, self.obs, self.fixed = robot, obs, fixed or Corrections()
        self.tag_ids: list[int] = []
        self.camera_name = obs.camera_name
        self.q_measured = obs.q_measured
        self.sample_of_unit = np.arange(obs.n_samples)
        self.view_of_unit = np.arange(obs.n_samples)
        self.view_labels = [(s, -1) for s in range(obs.n_samples)]
        self.nuisance = ParameterSet([])

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        r, d_chain, d_q = _chain_and_joint_derivatives(lambda q, m: sole_disagreement(self.robot, q, m), self.robot,
                                                       self.q_measured, chain, chain_values, self.fixed)  # fmt: skip
        return Linearization(residual=r, jac_chain=d_chain, jac_local=None, local_cols=None, joint_sensitivity=d_q)


MAX_SOLE_TILT_RAD = float(np.deg2rad(10.0))  # standing soles further from one plane under the nominal model are
MAX_SOLE_GAP_M = 0.03  # not a standing pose (bad input)


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
    gap = sole_disagreement(robot, obs.q_measured, Corrections())
    tilt = np.arcsin(np.clip(np.linalg.norm(gap[:, 2:], axis=1) / SOLE_LEVER_M, 0.0, 1.0))
    bad = np.flatnonzero((tilt > MAX_SOLE_TILT_RAD) | (np.abs(gap[:, :2]).max(axis=1) > MAX_SOLE_GAP_M))
    if bad.size:
        s = int(bad[0])
        raise WolfcalError(
            f"{obs.sources[s]}: {bad.size} floor sample(s) not in a standing pose (sample {s}: soles "
            f"{np.rad2deg(tilt[s]):.1f} deg and {np.abs(gap[s, :2]).max() * 100:.1f} cm from one plane under the "
            "nominal model; at most 10 deg and 3 cm): floor samples need both soles flat on the floor"
        )
