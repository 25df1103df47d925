"""IMU block: gravity in the IMU frame while the robot stands still with both soles flat on the floor.

Standing still, the accelerometer measures the specific force f = g n + b + noise [m/s^2] in the IMU frame: g along
the floor's normal n (up) and the accelerometer's constant bias b. The kinematics predicts n from the joint readings
(plus the fitted offsets): the mean z axis of the standing soles (config `floor.soles`, as the floor frame takes it),
turned into the IMU frame through the IMU's fixed joint (its mount correction `imu.rx`, `imu.ry`, `wolfcal.robot.
imu_mount`). Residual per still period s [rad]: the two tangent components E_s^T p of the predicted direction
p = v / |v| (v: the predicted specific force, below) at the measured direction m_s = f_s / |f_s| (E_s: two unit
vectors orthogonal to m_s, fixed by the data; g_s = |f_s|): the angle between measured and predicted gravity, split
in two (its sine, within 0.05 % below 3 deg).

The bias b is the block's own unknown, `imu.bias_x|y|z` [m/s^2], with the configured bias level as its prior
(`imu.bias`). While the soles are flat a bias across gravity (x, y) cannot be told from a tilt of the mount: both
turn the measured direction, by b/g, the same way in every stance a standing robot can take (they part only by the
cosine of the torso's tilt, 1 % at 8 deg, far below what the joint readings' rounding moves). So it enters as exactly
that turn, v = g (I + [beta]x) n + b_z e_z with beta = (-b_y, b_x, 0) / g: the data fix mount + bias, the priors
split them, the fit reports the pair as moving together, and the mount's std carries the bias's share. (Fitted as
the exact f = g n + b, that 1 % lets the readings' rounding move the split by up to a prior's width.) b_z, along
gravity, shows as an error that grows with the torso's tilt and is estimated. The bias is not deployed: the mount
the fit reports is the effective one (true mount plus the bias's turn), which is what a team's offsets hold.
A turn of the mount about the IMU's z axis (`imu.rz`) leaves gravity unchanged while the torso stands upright: it is
not estimated. Outlier unit: one still period (a bump or a step); noise: estimated from the data like the other
blocks, within NOISE_MIN_RAD .. NOISE_MAX_RAD. Derivatives are analytic (`wolfcal.robot.derivatives`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import Block, FittedBlock, Linearization
from wolfcal.geometry import exp_so3, matrix_to_rpy, skew
from wolfcal.io.imu import StandingSamples, read_standing, topics_of
from wolfcal.io.msgdefs import IMU
from wolfcal.outliers import OutlierRule
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.derivatives import ChainDerivatives, cross
from wolfcal.robot.imu_mount import IMU_KEY, imu_config, imu_joint
from wolfcal.robot.parameters import Parameter, ParameterSet
from wolfcal.robot.robot import Robot

if TYPE_CHECKING:
    from wolfcal.fit.options import FitOptions

# One still period is left out when its whitened residual is 4x the median period's and its angle per axis is
# above 0.2 deg: a bump or a step while the robot was thought to stand.
IMU_PERIOD_RAD = OutlierRule(factor=4.0, floor=float(np.deg2rad(0.2)))
NOISE_MIN_RAD = 1e-5  # the averaged accelerometer of a few seconds' still period [rad per axis]
NOISE_MAX_RAD = 0.05
NOISE_START_RAD = 1e-3  # [rad], before it is estimated
BIAS_NAMES = ("imu.bias_x", "imu.bias_y", "imu.bias_z")


def tangent_basis(m: np.ndarray) -> np.ndarray:
    """(S, 3, 2) two unit vectors orthogonal to each unit vector m (S, 3) and to each other (right-handed with m)."""
    helper = np.where(np.abs(m[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    e1 = helper - np.sum(helper * m, axis=1, keepdims=True) * m
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return np.stack([e1, np.cross(m, e1)], axis=2)


class ImuBlock(Block):
    """Gravity measured by the IMU in still periods of a standing robot; see the module docstring."""

    name = system = "imu"
    unit, unit_name, dim = "rad", "still period", 2
    outlier_rule = IMU_PERIOD_RAD
    noise_min, noise_max, noise_start = NOISE_MIN_RAD, NOISE_MAX_RAD, NOISE_START_RAD

    def __init__(self, robot: Robot, samples: StandingSamples, fixed: Corrections | None = None) -> None:
        self.robot, self.samples, self.fixed = robot, samples, fixed or Corrections()
        self.link, self.joint = imu_config(robot).frame, imu_joint(robot)
        self.soles = list(robot.config.floor_config("the IMU's gravity is the standing soles' normal: "
                                                    "add 'floor.soles'").soles)  # fmt: skip
        self.q_measured = samples.q_measured
        n = samples.n_samples
        self.sample_of_unit = self.view_of_unit = np.arange(n)
        self.view_labels = [(s, -1) for s in range(n)]
        self.g = np.linalg.norm(samples.accel, axis=1)  # (S,) [m/s^2]
        self.m = samples.accel / self.g[:, None]  # (S, 3) measured direction, IMU frame
        self.E = tangent_basis(self.m)  # (S, 3, 2)
        bias = imu_config(robot).bias
        self.nuisance = ParameterSet([Parameter(name, "imu_bias", "imu", i, "m/s^2", bias)
                                      for i, name in enumerate(BIAS_NAMES)])  # fmt: skip

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        corrections = chain.corrections(chain_values).plus(self.fixed)
        d = ChainDerivatives(self.robot, self.q_measured, corrections, chain, [self.link, *self.soles], [])
        z = np.stack([d.T_root[s][:, :3, 2] for s in self.soles])  # (K, S, 3) the soles' normals, root frame
        total = z.sum(axis=0)
        size = np.linalg.norm(total, axis=1)
        n_root = total / size[:, None]  # (S, 3)
        R = d.T_root[self.link][:, :3, :3]  # (S, 3, 3) R_root_imu
        n_imu = np.einsum("sji,sj->si", R, n_root)
        bx, by, bz = np.asarray(local_values, dtype=float)[:3]
        # (S, 3, 3): v = M n_imu + bz e_z, the bias's x, y parts as the turn (-b_y, b_x, 0) / g they make upright
        M = self.g[:, None, None] * np.eye(3) + skew(np.array([-by, bx, 0.0]))[None]
        v = np.einsum("sij,sj->si", M, n_imu) + np.array([0.0, 0.0, bz])
        length = np.linalg.norm(v, axis=1)
        p = v / length[:, None]
        residual = np.einsum("sik,si->sk", self.E, p)
        E_P = np.einsum("sik,sij->skj", self.E, np.eye(3)[None] - p[:, :, None] * p[:, None, :]) / length[:, None, None]

        def through(twists: list[np.ndarray], imu: np.ndarray) -> np.ndarray:
            """(S, 2, C) d(residual) from the soles' twists (K of (S, C, 6)) and the IMU's (S, C, 6)."""
            ds = sum(cross(t[..., 3:], zk[:, None, :]) for t, zk in zip(twists, z))  # (S, C, 3)
            dn = (ds - np.sum(ds * n_root[:, None, :], axis=2, keepdims=True) * n_root[:, None, :]) / size[
                :, None, None
            ]
            dn_imu = np.einsum("sji,scj->sci", R, dn - cross(imu[..., 3:], n_root[:, None, :]))
            return np.einsum("skj,sji,sci->skc", E_P, M, dn_imu)

        jac_chain = through([d.twist_p(s) for s in self.soles], d.twist_p(self.link))
        sensitivity = through([d.twist_q(s) for s in self.soles], d.twist_q(self.link))
        e_x, e_y, e_z = np.eye(3)
        dv_bias = np.stack([cross(e_y, n_imu), -cross(e_x, n_imu), np.broadcast_to(e_z, n_imu.shape)], axis=2)
        jac_bias = np.einsum("skj,sjb->skb", E_P, dv_bias)  # (S, 2, 3)
        return Linearization(
            residual=residual,
            jac_chain=jac_chain,
            jac_local=jac_bias,
            local_cols=np.tile(np.arange(3), (len(p), 1)),
            joint_sensitivity=sensitivity,
        )

    def report(self, fitted: FittedBlock) -> dict:
        """The common entry (`Block.report`) in degrees, with each still period's file, time, gravity error before
        and after, the accelerometer's scatter, the fitted bias and what gravity cannot determine."""
        b, samples = fitted.result, self.samples
        deg = float(np.rad2deg(1.0))
        periods = [{
            "index": i, "source": Path(samples.sources[i]).name, "stamp_ns": int(samples.stamps_ns[i]),
            "rms_before_deg": round(float(b.sample_rms_before[i]) * deg, 5),
            "rms_after_deg": round(float(b.sample_rms_after[i]) * deg, 5),
            "accel_scatter_m_s2": round(float(samples.scatter[i]), 5), "n_messages": int(samples.n_messages[i]),
            "outlier": bool(b.outlier_samples[i]),
        } for i in range(samples.n_samples)]  # fmt: skip
        return {
            "name": b.name, "system": b.system, "unit": "deg", "imu_frame": self.link, "urdf_joint": self.joint,
            "rms_meaning": "per-axis RMS of the angle between measured and predicted gravity (two tangent "
            "components per still period) in deg, inlier periods",
            "rms_before_deg": round(b.rms_before * deg, 5), "rms_after_deg": round(b.rms_after * deg, 5),
            "max_after_deg": round(b.max_after * deg, 5), "noise_sigma_deg": round(b.sigma * deg, 6),
            "mount": self._mount(fitted),
            "bias_m_s2": [round(float(v), 5) for v in fitted.local_values[:3]],
            "bias_meaning": "the accelerometer's constant bias in the IMU frame [m/s^2]: not deployed; while the "
            "soles are flat it cannot be told from a tilt of the mount (see the correlations), so the mount "
            "reported is the effective one and its std includes the bias's share (prior imu.bias)",
            "not_determined": ["imu.rz: a turn about the IMU's z axis leaves gravity unchanged while the robot "
                               "stands; held at the nominal mount"],
            "n_samples": samples.n_samples, "n_outlier_samples": int(np.sum(b.outlier_samples)),
            "n_outlier_views": len(b.outlier_views), "n_units_used": b.n_units,
            "notes": list(samples.notes), "samples": periods,
        }  # fmt: skip

    def _mount(self, fitted: FittedBlock) -> dict:
        """The fitted mount correction as roll, pitch, yaw [rad] of R_nominal_fitted = Rz(yaw) Ry(pitch) Rx(roll)
        (the IMU frame as fitted, in the nominal IMU frame: what a deploy file's IMU offsets hold)."""
        rotation = np.zeros(3)
        for p, value in zip(fitted.chain.parameters, fitted.chain_values):
            if p.kind == "frame" and p.target == self.joint and p.component >= 3:
                rotation[p.component - 3] += value
        roll, pitch, yaw = (float(v) for v in matrix_to_rpy(exp_so3(rotation)))
        return {"roll": roll, "pitch": pitch, "yaw": yaw, "yaw_determined": False,
                "meaning": "R_nominal_fitted = Rz(yaw) Ry(pitch) Rx(roll) [rad]: the fitted IMU frame in the "
                "nominal one (the URDF joint's origin times this rotation); the effective mount, the "
                "accelerometer's bias across gravity included; std: parameters imu.rx, imu.ry"}  # fmt: skip

    @staticmethod
    def summary_lines(entry: dict) -> list[str]:
        return [
            f"{entry['name']}: {entry['n_samples']} still period(s) ({entry['n_outlier_samples']} left out as "
            f"outliers), gravity error RMS (per axis): {entry['rms_before_deg']:.3f} deg before -> "
            f"{entry['rms_after_deg']:.3f} deg after (max {entry['max_after_deg']:.3f} deg)",
            "  imu.rz (yaw of the mount) is not determined by gravity: held at the nominal mount",
        ]


def imu_fit_blocks(robot: Robot, captures: list[Path], options: FitOptions,
                   say) -> tuple[list[Block], list[Path]]:  # fmt: skip
    """The registry's fit builder: the IMU block of the captures that hold IMU messages on `imu.topic`, when
    --free names the imu preset (or --system imu); and the captures no camera reads (no image topic of the config).
    Without the preset the IMU's data would be fitted with its mount held at the nominal one: a standing recording
    (IMU data, no images) is then refused with the --free that takes it in."""
    wanted = "imu" in options.presets or options.system == "imu"
    if not wanted and IMU_KEY not in robot.config.sections:
        return [], []
    config = imu_config(robot, "--free imu and --system imu need the IMU's link and topic")
    cameras = {robot.config.camera_topics(name)[0] for name in robot.config.camera_names}
    topics = {Path(c): _topics(Path(c), strict=wanted) for c in captures}
    with_imu = [c for c, found in topics.items() if config.topic in found]
    alone = [c for c in with_imu if not cameras & topics[c]]
    if not wanted:
        if alone:
            raise WolfcalError(
                f"{', '.join(map(str, alone))}: IMU data without images; the IMU joins the fit with "
                f"--free {options.free},imu (or --free imu)"
            )
        return [], []
    if options.chain_preset in (None, "camera", "head_camera") and "imu" not in options.presets:
        raise WolfcalError(
            f"--system imu with --free {options.free}: gravity cannot inform the camera; use --free imu "
            "(the mount), --free leg (the legs, the mount known) or --free leg,imu"
        )
    imu_joint(robot)  # a clear error for an IMU link the URDF lacks or moves, before any file is read
    if not with_imu:
        raise WolfcalError(
            f"{', '.join(map(str, captures))}: no {IMU} messages on {config.topic} (robot config "
            "'imu.topic'); give a standing recording (`wolfcal capture --standing`)"
        )
    samples = read_standing(with_imu, robot.config.joint_states_topic, config.topic, robot.joint_names)
    say(
        f"imu: {samples.n_samples} still period(s) from {len(with_imu)} recording(s)"
        + "".join(f"; {note}" for note in samples.notes)
    )
    return [ImuBlock(robot, samples)], alone


def _topics(path: Path, strict: bool) -> set[str]:
    """The file's topics; a file that cannot be read gives none unless `strict` (then its error): without the imu
    preset the camera reader reports it."""
    try:
        return set(topics_of(path))
    except WolfcalError:
        if strict:
            raise
        return set()
