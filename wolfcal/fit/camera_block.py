"""Camera blocks: tag corners seen by the head camera or by an external camera, in pixels.

Residual per corner: project(K, D, p_camera) - u_detected [px], p_camera the corner in the camera's optical frame:
- head camera: T_camera_tag = T_root_camera^-1 @ T_root_tag(q + offsets), both through the robot's chain;
- external camera: T_camera_tag = T_base_camera^-1 @ T_base_tag(q + offsets), with T_base_camera an unknown of the
  block: one per placement (capture file) or one per sample (a moving camera), as Trans(x, y, z) @ Exp(rx, ry, rz)
  [m, rad], named `<camera>.x ...` (or `<camera>@<n>.x ...`), started from PnP of the tags it sees.
Derivatives are analytic (`wolfcal.robot.derivatives`) except d(pixel)/d(point), a 3-point central difference of
the camera model per corner.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from wolfcal.config import PriorConfig
from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block, FittedBlock, Linearization
from wolfcal.fit.options import NOISE_FLOOR_PX
from wolfcal.fit.tag_report import tag_view_report
from wolfcal.geometry import (
    exp_so3,
    invert_transform,
    log_so3,
    right_jacobian_so3,
    skew,
)
from wolfcal.observations import Observations
from wolfcal.outliers import FIT_VIEW_PX
from wolfcal.projection import BEHIND_CAMERA_PX, corner_points, pixel_jacobian, tag_pose_from_corners
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.derivatives import ChainDerivatives, cross, tag_key
from wolfcal.robot.parameters import COMPONENTS, Parameter, ParameterSet
from wolfcal.robot.robot import Robot

POSE_PRIOR_M = 1.0  # weak priors of an external camera's pose: the data decide it [m]
POSE_PRIOR_RAD = 1.0  # [rad]
# Samples linearised at a time: bounds the per-sample poses and twists and the per-corner twists of a long
# recording; a few hundred keep numpy's per-call overhead small
CHUNK_SAMPLES = 512


class CameraBlock(Block):
    """Corners of the tags one camera saw; see the module docstring."""

    unit, unit_name, dim = "px", "corner", 2
    outlier_rule = FIT_VIEW_PX
    noise_min, noise_max = NOISE_FLOOR_PX, 50.0  # the floor is the fit's setting (`FitOptions.noise_floor_px`)

    def __init__(
        self,
        robot: Robot,
        obs: Observations,
        tag_ids: list[int],
        external: bool = False,
        placement_of_sample: np.ndarray | None = None,
        placement_names: list[str] | None = None,
        fixed: Corrections | None = None,
    ) -> None:
        self.robot, self.obs, self.tag_ids, self.external = robot, obs, list(tag_ids), external
        self.fixed = fixed or Corrections()  # corrections held fixed under the free ones (e.g. a model under test)
        self.camera_name = obs.camera_name
        self.system = "external" if external else "head"
        self.name = f"external camera {self.camera_name}" if external else "head camera"
        self.tag_col, self.p_tag = corner_points(robot, obs, self.tag_ids)  # (M,), (M, 3) corner in its tag frame [m]
        self.sample_of_unit = obs.sample_index
        self.q_measured = obs.q_measured
        views, self.view_of_unit = obs.views()
        self.view_labels = [(int(s), int(t)) for s, t in views]
        # (S,) placement of each sample: the external camera's pose it was taken from (the head camera: all 0)
        self.placement_of_sample = np.zeros(obs.n_samples, dtype=int)
        if external:
            self.viewer = robot.config.base_link
            self.placement_of_sample = np.asarray(placement_of_sample, dtype=int)
            self.nuisance = self._pose_parameters(placement_names or [self.camera_name])
        else:
            self.viewer = robot.config.head_camera().frame
            self.nuisance = ParameterSet([])

    def shared_labels(self) -> np.ndarray:
        """(U,) shared detection error of each corner: a tag seen again and again from the same place gives the
        detector the same picture, so its corner errors repeat instead of averaging out. For an external camera,
        corners of tags fixed to the base share one error per (placement, tag, corner); for any camera, the frames
        taken at one still pose (identical joint readings) share one per (pose, tag, corner)."""
        key = self.noise_groups()  # the still pose of each corner
        fixed = np.zeros(self.n_units, dtype=bool)
        if self.external:
            tag_fixed = np.array([self.robot.fixed_to_base(self.robot.config.tag(t).link) for t in self.tag_ids])
            fixed = tag_fixed[self.tag_col]
            key = np.where(fixed, self.placement_of_sample[self.sample_of_unit], key)
        _, labels = np.unique(
            np.stack([fixed, key, self.tag_col, self.obs.corner_index], axis=1), axis=0, return_inverse=True
        )
        return labels.ravel()

    def unit_frames(self) -> np.ndarray | None:
        """The frames averaged into each corner of still-span observations (`Observations.span_frames`)."""
        return None if self.obs.span_frames is None else self.obs.span_frames.frames

    def unit_scatter(self) -> np.ndarray | None:
        """Their scatter about each corner's mean [px^2] (`Observations.span_frames`)."""
        return None if self.obs.span_frames is None else self.obs.span_frames.scatter

    def start_noise(self, priors: PriorConfig) -> float:
        """The configured corner detection noise (`priors.pixel_noise`) [px]."""
        return priors.pixel_noise

    def report(self, fitted: FittedBlock) -> dict:
        return tag_view_report(self, fitted)

    # --- the external camera's pose ----------------------------------------------------------------------------
    def _pose_parameters(self, names: list[str]) -> ParameterSet:
        init = initial_camera_poses(self.robot, self.obs, self.placement_of_sample, len(names), self.fixed)
        params = []
        for k, name in enumerate(names):
            values = np.concatenate([init[k][:3, 3], log_so3(init[k][:3, :3])])
            params += [
                Parameter(
                    f"{name}.{c}",
                    "pose",
                    name,
                    i,
                    "m" if i < 3 else "rad",
                    POSE_PRIOR_M if i < 3 else POSE_PRIOR_RAD,
                    float(values[i]),
                )
                for i, c in enumerate(COMPONENTS)
            ]
        return ParameterSet(params)

    # --- predictions and derivatives ---------------------------------------------------------------------------
    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        """Residuals and derivatives of every corner, computed over at most CHUNK_SAMPLES samples at a time (the
        per-sample poses and twists, and the per-corner twists, of a long recording are never in memory at once;
        each corner's numbers are the same as in one pass)."""
        corrections: Corrections = chain.corrections(chain_values).plus(self.fixed)
        n_samples = len(self.q_measured)
        if n_samples <= CHUNK_SAMPLES:
            return self._linearize_samples(corrections, chain, local_values, 0, n_samples)
        m, d, n_joints = self.n_units, self.dim, self.q_measured.shape[1]
        local = self.external  # an external camera's pose: 6 unknowns per corner
        out = Linearization(np.empty((m, d)), np.empty((m, d, len(chain))), np.empty((m, d, 6)) if local else None,
                            np.empty((m, 6), dtype=int) if local else None, np.empty((m, d, n_joints)))  # fmt: skip
        for first in range(0, n_samples, CHUNK_SAMPLES):
            end = min(first + CHUNK_SAMPLES, n_samples)
            part = self._linearize_samples(corrections, chain, local_values, first, end)
            units = (self.sample_of_unit >= first) & (self.sample_of_unit < end)
            for f in fields(Linearization):
                if getattr(part, f.name) is not None:
                    getattr(out, f.name)[units] = getattr(part, f.name)
        return out

    def _linearize_samples(
        self, corrections: Corrections, chain: ParameterSet, local_values: np.ndarray, first: int, end: int
    ) -> Linearization:
        """`linearize` for the corners of samples first..end-1 (in the order of the block's units)."""
        units = slice(None) if (first, end) == (0, len(self.q_measured)) else (
            (self.sample_of_unit >= first) & (self.sample_of_unit < end))  # fmt: skip
        d = ChainDerivatives(self.robot, self.q_measured[first:end], corrections, chain, [self.viewer], self.tag_ids)
        s, t = self.sample_of_unit[units] - first, self.tag_col[units]
        keys = [tag_key(tag) for tag in self.tag_ids]
        T_root_tag = np.stack([d.T_root[k] for k in keys])[t, s]  # (M, 4, 4)
        p_root = np.einsum("mij,mj->mi", T_root_tag[:, :3, :3], self.p_tag[units]) + T_root_tag[:, :3, 3]
        T_root_viewer = d.T_root[self.viewer][s]
        R_viewer_root = np.swapaxes(T_root_viewer[:, :3, :3], 1, 2)
        p_view = np.einsum("mij,mj->mi", R_viewer_root, p_root - T_root_viewer[:, :3, 3])
        jac_local = local_cols = None
        R_camera_root = R_viewer_root
        if self.external:
            k = self.placement_of_sample[self.sample_of_unit[units]]
            p_view, R_camera_base, jac_local, local_cols = self._through_camera_pose(local_values, k, p_view)
            R_camera_root = R_camera_base @ R_viewer_root
        camera = self.obs.camera
        uv = camera.project(p_view)
        D = pixel_jacobian(camera, p_view)
        residual = uv - self.obs.uv[units]
        bad = ~np.all(np.isfinite(residual), axis=1) | ~np.all(np.isfinite(D), axis=(1, 2))
        residual[bad] = BEHIND_CAMERA_PX
        D[bad] = 0.0
        # d(pixel)/d(twist (v0, w) [root frame]) of each corner: a twist moves the point by v0 + w x p_root
        # (`point_motion`), and a . (w x p) = w . (p x a) for each row a of d(pixel)/d(p_root)
        D_root = D @ R_camera_root  # (M, 2, 3)
        D_twist = np.concatenate([D_root, cross(p_root[:, None, :], D_root)], axis=2)  # (M, 2, 6)
        # the tag's twists relative to the viewer's per view (one tag in one sample): a view's corners share them
        views, first_unit, view_of_unit = np.unique(self.view_of_unit[units], return_index=True, return_inverse=True)
        view_tag, view_sample = t[first_unit], s[first_unit]
        n_units = len(view_of_unit)
        regular = n_units == 4 * len(views) and np.array_equal(view_of_unit, np.arange(n_units) // 4)

        def chain_rule(joints: bool, width: int) -> np.ndarray:
            """(M, 2, width) d(pixel)/d(the joint readings or the chain parameters) from each tag's twists relative
            to the viewer's (`ChainDerivatives.relative`: only the columns that do not cancel; the others are 0)."""
            out = np.zeros((n_units, 2, width))
            per_view = out.reshape(len(views), 8, width) if regular else out
            for col, key in enumerate(keys):
                cols, relative = d.relative(key, self.viewer, joints)  # (C,), (S, 6, C)
                if not len(cols):
                    continue
                if regular:  # each view's four corners in a row (whole tags): one product per view
                    mine = np.flatnonzero(view_tag == col)
                    part = D_twist.reshape(len(views), 8, 6)[mine] @ relative[view_sample[mine]]  # (n, 8, C)
                else:
                    mine = np.flatnonzero(t == col)
                    part = D_twist[mine] @ relative[s[mine]]  # (n, 2, C)
                per_view[mine[:, None], :, cols] = np.swapaxes(part, 1, 2)
            return out

        return Linearization(
            residual=residual,
            jac_chain=chain_rule(False, len(chain)),
            jac_local=None if jac_local is None else D @ jac_local,
            local_cols=local_cols,
            joint_sensitivity=chain_rule(True, len(self.robot.joint_names)),
        )

    def _through_camera_pose(self, pose_values: np.ndarray, k: np.ndarray, p_base: np.ndarray):
        """Points in the external camera's frame from those in the base frame, the rotation R_camera_base (M, 3, 3)
        and the points' derivatives by the camera's pose; `k` (M,): the placement of each corner."""
        pose = pose_values.reshape(-1, 6)[k]  # (M, 6) T_base_camera as (x, y, z, rx, ry, rz)
        R_camera_base = np.swapaxes(exp_so3(pose[:, 3:]), 1, 2)
        p_camera = np.einsum("mij,mj->mi", R_camera_base, p_base - pose[:, :3])
        jac_local = np.concatenate([-R_camera_base, skew(p_camera) @ right_jacobian_so3(pose[:, 3:])], axis=2)
        local_cols = 6 * k[:, None] + np.arange(6)
        return p_camera, R_camera_base, jac_local, local_cols


def placements(obs: Observations, moving: bool) -> tuple[np.ndarray, list[str]]:
    """Placement of each sample of an external camera and the placements' names: one per capture file (in the
    order of the files), or one per sample of a moving camera."""
    if moving:
        return np.arange(obs.n_samples), [f"{obs.camera_name}@s{i + 1}" for i in range(obs.n_samples)]
    files = list(dict.fromkeys(obs.sources))
    index = np.array([files.index(s) for s in obs.sources], dtype=int)
    if len(files) == 1:
        return index, [obs.camera_name]
    return index, [f"{obs.camera_name}@{k + 1}" for k in range(len(files))]


def initial_camera_poses(
    robot: Robot,
    obs: Observations,
    placement_of_sample: np.ndarray,
    n_placements: int,
    model: Corrections | None = None,
) -> list[np.ndarray]:
    """T_base_camera (4, 4) per placement from PnP of the tags on links the legs do not move (`Robot.off_the_legs`:
    the torso tag, also behind waist joints), each placed by the model `model` at the sample's readings; median over
    the placement's views; a clear error for a placement in which no such tag was seen."""
    fixed = [t for t in obs.observed_tag_ids if robot.off_the_legs(robot.config.tag(t).link)]
    links = list(dict.fromkeys(robot.config.tag(t).link for t in fixed))
    poses = []
    for k in range(n_placements):
        candidates = []
        for s in np.flatnonzero(placement_of_sample == k):
            T_base_link = robot.model.link_poses(obs.q_measured[s : s + 1], links, model, base=robot.config.base_link)
            for t in fixed:
                T_camera_tag = tag_pose_from_corners(robot, obs, int(s), t)
                if T_camera_tag is not None:
                    T_base_tag = T_base_link[robot.config.tag(t).link][0] @ robot.T_link_tag(t, model)
                    candidates.append(T_base_tag @ invert_transform(T_camera_tag))
        if not candidates:
            sources = sorted({obs.sources[s] for s in np.flatnonzero(placement_of_sample == k)})
            fixed_ids = [tg.id for tg in robot.config.tags if robot.off_the_legs(tg.link)]
            raise WolfcalError(
                f"{', '.join(sources)}: external camera '{obs.camera_name}' never saw a tag on a link the legs do "
                "not move "
                f"({'tag ' + ', '.join(map(str, fixed_ids)) if fixed_ids else 'none is configured'}) in this "
                "placement, so its pose cannot be found; capture poses in which the torso tag is in view"
            )
        stack = np.stack(candidates)
        t_med = np.median(stack[:, :3, 3], axis=0)
        best = int(np.argmin(np.linalg.norm(stack[:, :3, 3] - t_med, axis=1)))
        T = stack[best].copy()
        T[:3, 3] = t_med
        poses.append(T)
    return poses
