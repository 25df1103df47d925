"""Motion-capture block: markers on links, measured in 3D by a motion-capture system, in metres.

Residual per measured marker m of sample s: p_mocap - p_measured [m], with
p_mocap = T_mocap_base @ T_base_link(q_s + offsets) @ (xyz_m + mount_m):
- T_mocap_base, the robot's base pose in the motion-capture frame, is an unknown of the block: one per marker
  source (the robot stood on its stand through one recording) or one per sample (`moving`), as
  Trans(x, y, z) @ Exp(rx, ry, rz) [m, rad], named `mocap.x ...` (`mocap@<n>.x ...` with several), started from a
  rigid registration (Kabsch) of the torso markers (markers on links fixed to the base) under the nominal model;
- mount_m, the marker's offset from its configured (nominal) place in its link frame, is an unknown of the block
  with a prior of `MOUNT_PRIOR_M` per axis, named `marker.<name>.x|y|z`: 3D-printed mounts differ from CAD.
Each marker has its own noise level (`noise_classes`; the solver estimates it robustly, with a floor).
The outlier unit is one marker in one sample: a reflection or a swapped label is left out alone. Derivatives are
analytic (`wolfcal.robot.derivatives`).
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block, FittedBlock, Linearization
from wolfcal.fit.mocap_result import mocap_block_dict
from wolfcal.geometry import exp_so3, log_so3, right_jacobian_so3, rigid_registration, skew
from wolfcal.markers import MarkerObservations
from wolfcal.outliers import MOCAP_MARKER_M
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.derivatives import ChainDerivatives, point_motion
from wolfcal.robot.parameters import COMPONENTS, Parameter, ParameterSet
from wolfcal.robot.robot import Robot

MOUNT_PRIOR_M = 0.001  # marker mounts: 3D-printed parts differ from CAD by about a millimetre [m]
POSE_PRIOR_M = 10.0  # weak priors of the base pose in the mocap frame: the data decide it [m]
POSE_PRIOR_RAD = 3.0  # [rad]
MIN_TORSO_MARKERS = 3
MOCAP_NOISE_START_M = 0.0003  # starting noise level per axis [m] before it is estimated


class MocapBlock(Block):
    """Markers measured by motion capture; see the module docstring."""

    system, unit, unit_name, dim = "mocap", "m", "marker", 3
    outlier_rule = MOCAP_MARKER_M
    name = "motion capture"
    noise_min, noise_max, noise_start = 1e-5, 0.1, MOCAP_NOISE_START_M

    def __init__(
        self, robot: Robot, obs: MarkerObservations, moving: bool = False, fixed: Corrections | None = None
    ) -> None:
        self.robot, self.obs, self.moving = robot, obs, moving
        self.fixed = fixed or Corrections()
        self.base = robot.config.base_link
        markers = [robot.config.marker_config().marker(n) for n in obs.marker_names]
        self.links = list(dict.fromkeys(m.link for m in markers))
        self.link_col = np.array([self.links.index(m.link) for m in markers], dtype=int)  # (K,)
        self.xyz_link = np.array([m.xyz for m in markers], dtype=float)  # (K, 3) nominal [m]
        self.on_base = np.array([robot.fixed_to_base(m.link) for m in markers])  # (K,)
        self.sample_of_unit = obs.sample_index
        self.q_measured = obs.q_measured
        self.view_of_unit = np.arange(len(obs.sample_index))
        self.view_labels = [(int(s), int(k)) for s, k in zip(obs.sample_index, obs.marker_index)]
        self.placement_of_sample, self.placement_names = self._placements()
        init = self.initial_base_poses()
        pose_params = []
        for name, T in zip(self.placement_names, init):
            values = np.concatenate([T[:3, 3], log_so3(T[:3, :3])])
            pose_params += [
                Parameter(f"{name}.{c}", "mocap_pose", name, i, "m" if i < 3 else "rad",
                          POSE_PRIOR_M if i < 3 else POSE_PRIOR_RAD, float(values[i]))
                for i, c in enumerate(COMPONENTS)
            ]  # fmt: skip
        mounts = [Parameter(f"marker.{n}.{c}", "marker", n, i, "m", MOUNT_PRIOR_M)
                  for n in obs.marker_names for i, c in enumerate("xyz")]  # fmt: skip
        self.nuisance = ParameterSet(pose_params + mounts)
        self.n_pose = 6 * len(self.placement_names)

    def noise_classes(self) -> np.ndarray:
        """(U,) one noise level per marker: a marker seen at a grazing angle or through a reflection-prone spot is
        noisier than the others."""
        return self.obs.marker_index

    def report(self, fitted: FittedBlock) -> dict:
        return mocap_block_dict(
            self.obs, self.placement_names, self.view_labels, fitted.result, fitted.local_values, fitted.residual
        )

    @property
    def marker_names(self) -> list[str]:
        return self.obs.marker_names

    def _placements(self) -> tuple[np.ndarray, list[str]]:
        """Base pose of each sample: one per marker source, or one per sample when the robot moved."""
        if self.moving:
            return np.arange(self.obs.n_samples), [f"mocap@s{i + 1}" for i in range(self.obs.n_samples)]
        sources = list(dict.fromkeys(self.obs.sources))
        index = np.array([sources.index(s) for s in self.obs.sources], dtype=int)
        return index, ["mocap"] if len(sources) == 1 else [f"mocap@{k + 1}" for k in range(len(sources))]

    # --- the base pose in the mocap frame ------------------------------------------------------------------
    def _nominal_base_points(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rows (M,) of `samples` and where the nominal model puts their markers in the base frame (M, 3) [m]."""
        obs = self.obs
        rows = np.flatnonzero(np.isin(obs.sample_index, samples))
        poses = self.robot.model.link_poses(obs.q_measured, self.links, self.fixed, base=self.base)
        k = obs.marker_index[rows]
        T = np.stack([poses[link] for link in self.links])[self.link_col[k], obs.sample_index[rows]]
        return rows, np.einsum("mij,mj->mi", T[:, :3, :3], self.xyz_link[k]) + T[:, :3, 3]

    def initial_base_poses(self) -> list[np.ndarray]:
        """T_mocap_base (4, 4) per placement: Kabsch registration of the torso markers (per marker the median of its
        measurements, so that a reflection cannot pull it), or, for a per-sample pose without three torso markers,
        of all markers of the sample under the nominal model. A clear error when it cannot be found."""
        obs, poses = self.obs, []
        for p, name in enumerate(self.placement_names):
            samples = np.flatnonzero(self.placement_of_sample == p)
            rows, p_base = self._nominal_base_points(samples)
            torso = self.on_base[obs.marker_index[rows]]
            keys = obs.marker_index[rows] if not self.moving else np.arange(len(rows))
            if len(np.unique(keys[torso])) >= MIN_TORSO_MARKERS:
                use = torso
            elif self.moving and len(rows) >= MIN_TORSO_MARKERS:
                use = np.ones(len(rows), dtype=bool)
            else:
                seen = sorted({obs.marker_names[k] for k in obs.marker_index[rows][torso]})
                sources = sorted({obs.sources[s] for s in samples})
                raise WolfcalError(
                    f"{', '.join(sources)}: only {len(seen)} torso marker(s) ({', '.join(seen) or 'none'}) were ever "
                    f"measured for base pose {name}; the robot's pose in the motion-capture frame needs at least "
                    f"{MIN_TORSO_MARKERS} markers on links fixed to the base: check the marker names in the robot "
                    "config's 'markers:' and that the torso markers are visible"
                )
            a, b = [], []
            for key in np.unique(keys[use]):
                sel = use & (keys == key)
                a.append(np.median(obs.xyz[rows[sel]], axis=0))
                b.append(np.median(p_base[sel], axis=0))
            poses.append(rigid_registration(np.array(b), np.array(a)))
        return poses

    # --- predictions and derivatives -----------------------------------------------------------------------
    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        corrections: Corrections = chain.corrections(chain_values).plus(self.fixed)
        d = ChainDerivatives(self.robot, self.q_measured, corrections, chain, self.links + [self.base], [])
        s, k = self.sample_of_unit, self.obs.marker_index
        lc = self.link_col[k]
        mounts = local_values[self.n_pose :].reshape(-1, 3)
        T_root_link = np.stack([d.T_root[link] for link in self.links])[lc, s]  # (M, 4, 4)
        p_root = np.einsum("mij,mj->mi", T_root_link[:, :3, :3], self.xyz_link[k] + mounts[k]) + T_root_link[:, :3, 3]
        dp_p = point_motion(np.stack([d.twist_p(link) for link in self.links])[lc, s] - d.twist_p(self.base)[s], p_root)
        dp_q = point_motion(np.stack([d.twist_q(link) for link in self.links])[lc, s] - d.twist_q(self.base)[s], p_root)
        T_root_base = d.T_root[self.base][s]
        R_base_root = np.swapaxes(T_root_base[:, :3, :3], 1, 2)
        p_base = np.einsum("mij,mj->mi", R_base_root, p_root - T_root_base[:, :3, 3])
        placement = self.placement_of_sample[s]
        pose = local_values[: self.n_pose].reshape(-1, 6)[placement]  # (M, 6) T_mocap_base as (x, y, z, rx, ry, rz)
        R_mocap_base = exp_so3(pose[:, 3:])
        R = R_mocap_base @ R_base_root  # (M, 3, 3) root -> mocap rotation
        p_mocap = np.einsum("mij,mj->mi", R_mocap_base, p_base) + pose[:, :3]
        jac_pose = np.concatenate(
            [np.broadcast_to(np.eye(3), R.shape), -R_mocap_base @ skew(p_base) @ right_jacobian_so3(pose[:, 3:])],
            axis=2,
        )
        jac_mount = R @ T_root_link[:, :3, :3]
        local_cols = np.concatenate([6 * placement[:, None] + np.arange(6),
                                     self.n_pose + 3 * k[:, None] + np.arange(3)], axis=1)  # fmt: skip
        return Linearization(
            residual=p_mocap - self.obs.xyz,
            jac_chain=R @ dp_p,
            jac_local=np.concatenate([jac_pose, jac_mount], axis=2),
            local_cols=local_cols,
            joint_sensitivity=R @ dp_q,
        )
