"""Simulated standing recordings for the IMU: the robot stands on a flat floor and goes through stances that turn
and tilt its torso, holding each; joint states and sensor_msgs/msg/Imu stream with their own stamps.

Truth: encoder offsets of the leg joints (`--offsets`), the IMU's mount error (roll and pitch, `MOUNT_SIGMA_RAD`
each), the accelerometer's constant bias (a random direction, size uniform up to `bias` [m/s^2]). Stances: the
config's `imu.stances`, else `tilted_stances` (from a floor stance with bent knees, the torso turned and tilted by up
to TILT_RAD with both soles where they stand under the nominal model). True joint angles are the stances
(readings = true angle minus the true offset, quantised). At each stamp the IMU measures the specific force
g * (floor normal in the IMU frame, true model) + bias + white noise (`accel_noise` per axis) and the gyro the
torso's rate of turn + noise; the linear acceleration of the moving torso is left out (those messages are not still).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from mcap_ros2.writer import Writer as Ros2Writer

from wolfcal.atomic import output_set, write_text_atomic
from wolfcal.encoders import encoder_readings
from wolfcal.errors import WolfcalError
from wolfcal.geometry import log_so3
from wolfcal.io.imu import StandingSamples
from wolfcal.io.msgdefs import IMU, JOINT_STATE, MSGDEFS, stamp_dict
from wolfcal.io.truth import truth_paths
from wolfcal.outputs import check_outputs
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import moved_stance
from wolfcal.robot.imu_mount import imu_config, imu_joint, true_gravity
from wolfcal.robot.robot import Robot
from wolfcal.robot.stances import STANDING_RULE, off_plane, sole_gaps, stance_readings
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.yamlfile import dump_yaml

if TYPE_CHECKING:
    from wolfcal.camera.model import CameraModel
    from wolfcal.sim.simulate import SimOptions

GRAVITY = 9.80665  # [m/s^2]
MOUNT_SIGMA_RAD = 0.03  # true mount error per axis (roll, pitch) [rad]
TILT_RAD = 0.15  # torso tilt of the generated stances [rad]
TURN_RAD = 0.3  # torso turn of the generated stances [rad]
START_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True)
class ImuSimOptions:
    accel_noise: float = 0.03  # white noise per axis and message [m/s^2]
    bias: float = 0.03  # largest size of the constant bias [m/s^2]
    gyro_noise: float = 0.003  # [rad/s]
    move_s: float = 1.5  # motion between stances [s]
    hold_s: float = 3.0  # still time per stance [s]
    joint_rate_hz: float = 100.0
    imu_rate_hz: float = 200.0


def tilted_stances(robot: Robot) -> np.ndarray:
    """(K, J) readings [rad] of standing stances that turn and tilt the torso (module docstring): from the config's
    first stance with bent knees (`floor.stances`, else `floor.check_stances`, else `floor.standing`), turned by
    +-TURN_RAD, tilted by +-TILT_RAD in roll and pitch, and both; the soles where they stand (`moved_stance`)."""
    floor = robot.config.floor_config("the standing stances start from the config's floor stances")
    bent = (floor.stances or floor.check_stances or (floor.standing,))[0]
    t, u = TILT_RAD, TURN_RAD
    rotations = [
        (0, 0, 0),
        (t, 0, 0),
        (-t, 0, 0),
        (0, t, 0),
        (0, -t, 0),
        (0, 0, u),
        (0, 0, -u),
        (t, t, 0),
        (-t, -t, 0),
        (t, -t, u),
        (-t, t, -u),
        (0.7 * t, 0.7 * t, 0.7 * u),
    ]
    stances = [moved_stance(robot, bent, (0.0, 0.0, 0.0, *r)) for r in rotations]
    return stance_readings(stances, robot.model)


def imu_stances(robot: Robot) -> np.ndarray:
    """(K, J) readings of the stances a standing recording goes through: `imu.stances` (each checked: movable
    joints of the URDF, both soles on one plane under the nominal model), else `tilted_stances`."""
    config = imu_config(robot)
    if not config.stances:
        return tilted_stances(robot)
    for i, stance in enumerate(config.stances):
        unknown = [j for j in stance if j not in robot.joint_names]
        if unknown:
            raise WolfcalError(
                f"{robot.config.path}: 'imu.stances[{i}]' names {', '.join(unknown)}, not movable "
                f"joints of {robot.config.urdf}"
            )
    q = stance_readings(config.stances, robot.model)
    soles = list(robot.config.floor_config("standing stances need 'floor.soles'").soles)[:2]
    poses = robot.model.link_poses(q, soles, base=robot.config.base_link)
    tilt, gap, bad = off_plane(sole_gaps(np.stack([poses[s] for s in soles])))
    if bad.any():
        i = int(np.argmax(bad))
        raise WolfcalError(
            f"{robot.config.path}: 'imu.stances[{i}]' is not a standing pose: the soles are "
            f"{np.rad2deg(tilt[i]):.1f} deg and {gap[i] * 100:.1f} cm from one plane under the nominal "
            f"model ({STANDING_RULE})"
        )
    return q


def imu_truth(robot: Robot, offset_joints: tuple[str, ...], rng: np.random.Generator, offset_rms: float = 0.025,
              base: Corrections | None = None) -> Corrections:  # fmt: skip
    """True corrections: `base` (e.g. a camera scenario's truth) with offsets of `offset_joints` drawn when it has
    none, and the IMU's mount error (roll, pitch) added."""
    truth = base or Corrections(offsets={j: float(rng.normal(0.0, offset_rms)) for j in offset_joints})
    mount = np.zeros(6)
    mount[3:5] = rng.normal(0.0, MOUNT_SIGMA_RAD, 2)
    return Corrections(dict(truth.offsets), {**truth.frames, imu_joint(robot): mount}, dict(truth.tags))


def standing_samples_direct(
    robot: Robot,
    truth: Corrections,
    q_true: np.ndarray,
    bias: np.ndarray,
    rng: np.random.Generator,
    options: ImuSimOptions = ImuSimOptions(),
) -> StandingSamples:
    """In-memory still periods (no file) of the stances q_true (S, J): what `wolfcal.io.imu` would read from a
    recording of them (readings quantised, the accelerometer's noise averaged over a hold)."""
    n_imu = true_gravity(robot, truth, q_true)[0]
    n_messages = int((options.hold_s - 0.9) * options.imu_rate_hz)
    noise = rng.normal(0.0, options.accel_noise / np.sqrt(n_messages), n_imu.shape)
    return StandingSamples(
        joint_names=robot.joint_names, q_measured=encoder_readings(q_true, truth.offset_vector(robot.joint_names)),
        accel=GRAVITY * n_imu + bias + noise, scatter=np.full(len(q_true), options.accel_noise),
        n_messages=np.full(len(q_true), n_messages), stamps_ns=START_NS + np.arange(len(q_true)) * 10**9,
        sources=["simulated"] * len(q_true),
    )  # fmt: skip


def random_bias(size: float, rng: np.random.Generator) -> np.ndarray:
    """A constant accelerometer bias: a random direction, size uniform in [0, size] [m/s^2]."""
    direction = rng.normal(size=3)
    return direction / np.linalg.norm(direction) * rng.uniform(0.0, size)


def write_standing_recording(path: Path, robot: Robot, truth: Corrections, q_stances: np.ndarray, bias: np.ndarray,
                             rng: np.random.Generator, options: ImuSimOptions = ImuSimOptions()) -> None:  # fmt: skip
    """A ROS 2 recording (mcap_ros2) of the robot going through the true stances (K, J), holding each."""
    offsets = truth.offset_vector(robot.joint_names)
    period = options.move_s + options.hold_s
    total = period * len(q_stances)

    def q_at(t: np.ndarray) -> np.ndarray:
        k = np.minimum((t // period).astype(int), len(q_stances) - 1)
        phase = np.minimum((t - k * period) / options.move_s, 1.0)
        previous = q_stances[np.maximum(k - 1, 0)]
        return previous + (q_stances[k] - previous) * (0.5 * (1.0 - np.cos(np.pi * phase)))[:, None]

    t_imu = np.arange(0.0, total, 1.0 / options.imu_rate_hz)
    n_imu, R = true_gravity(robot, truth, q_at(t_imu))
    accel = GRAVITY * n_imu + bias + rng.normal(0.0, options.accel_noise, n_imu.shape)
    turn = log_so3(np.swapaxes(R[:-1], 1, 2) @ R[1:]) * options.imu_rate_hz  # rate of turn, IMU frame [rad/s]
    gyro = np.concatenate([turn, turn[-1:]]) + rng.normal(0.0, options.gyro_noise, n_imu.shape)
    t_joint = np.arange(0.0, total, 1.0 / options.joint_rate_hz)
    readings = encoder_readings(q_at(t_joint), offsets)
    frame, topic = imu_config(robot).frame, imu_config(robot).topic
    events = sorted([(t, 0, i) for i, t in enumerate(t_joint)] + [(t + 0.0013, 1, i) for i, t in enumerate(t_imu)])
    no_orientation = [-1.0] + [0.0] * 8  # orientation absent (REP 145)
    covariance = [options.accel_noise**2, 0, 0, 0, options.accel_noise**2, 0, 0, 0, options.accel_noise**2]
    with path.open("wb") as handle:
        writer = Ros2Writer(handle)
        joint_schema = writer.register_msgdef(JOINT_STATE, MSGDEFS[JOINT_STATE])
        imu_schema = writer.register_msgdef(IMU, MSGDEFS[IMU])
        for t, kind, i in events:
            stamp = START_NS + int(round(t * 1e9))
            if kind == 0:
                message = {"header": {"stamp": stamp_dict(stamp), "frame_id": ""}, "name": robot.joint_names,
                           "position": readings[i].tolist(), "velocity": [], "effort": []}  # fmt: skip
                writer.write_message(robot.config.joint_states_topic, joint_schema, message, log_time=stamp)
                continue
            a, w = accel[i], gyro[i]
            message = {
                "header": {"stamp": stamp_dict(stamp), "frame_id": frame},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}, "orientation_covariance": no_orientation,
                "angular_velocity": {"x": w[0], "y": w[1], "z": w[2]}, "angular_velocity_covariance": [0.0] * 9,
                "linear_acceleration": {"x": a[0], "y": a[1], "z": a[2]},
                "linear_acceleration_covariance": covariance,
            }  # fmt: skip
            writer.write_message(topic, imu_schema, message, log_time=stamp)
        writer.finish()


def simulate_imu(robot: Robot, out: Path, options: SimOptions, camera: CameraModel | None,
                 say: Callable[[str], None], force: bool, inputs: list[Path]) -> Corrections:  # fmt: skip
    """The registry's simulator (`wolfcal simulate --system imu`): FILE.mcap, a standing recording of `samples`
    holds (the stances in turn), FILE.truth.yaml (true offsets, mount, bias) and FILE.truth.urdf."""
    from wolfcal.robot.corrections import load_corrections
    from wolfcal.sim.simulate import offset_joints

    check_outputs([out, *truth_paths(out)], force, inputs)
    rng = np.random.default_rng(options.seed)
    imu = ImuSimOptions()
    truth = imu_truth(robot, offset_joints(robot, options.offsets), rng, options.truth.offset_rms)
    bias = random_bias(imu.bias, rng)
    if options.truth_file is not None:  # a held-out recording of the same robot
        truth = load_corrections(options.truth_file, key="truth")
        bias = np.array(load_corrections_bias(options.truth_file))
    stances = imu_stances(robot)
    q_true = stances[np.arange(options.samples) % len(stances)]
    with output_set():
        write_standing_recording(out, robot, truth, q_true, bias, rng, imu)
        truth_yaml, truth_urdf = truth_paths(out)
        data = {
            "truth": truth.to_dict(),
            "imu_bias_m_s2": [float(v) for v in bias],
            "imu": asdict(imu),
            "samples": options.samples,
            "seed": options.seed,
            "system": "imu",
            "meaning": "offsets: q_true = q_measured + offset [rad]; frames: origin_new = origin * "
            "Trans(x,y,z) * Exp(rx,ry,rz) [m, rad]; imu_bias_m_s2: the accelerometer's constant bias, IMU frame",
        }
        write_text_atomic(truth_yaml, dump_yaml(data, sort_keys=False))
        write_calibrated_urdf(robot.config.urdf, robot.model, truth, truth_urdf)
    say(
        f"wrote {out} ({options.samples} stances held {imu.hold_s:.1f} s), {truth_paths(out)[0]}, {truth_paths(out)[1]}"
    )
    return truth


def load_corrections_bias(path: Path) -> list[float]:
    """The true accelerometer bias of a simulation's FILE.truth.yaml [m/s^2] (zero when it has none)."""
    from wolfcal.yamlfile import read_yaml

    data = read_yaml(path, "simulation truth", "give the .truth.yaml written beside a simulated recording")
    return list(data.get("imu_bias_m_s2", [0.0, 0.0, 0.0])) if isinstance(data, dict) else [0.0, 0.0, 0.0]
