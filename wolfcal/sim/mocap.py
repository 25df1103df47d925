"""`wolfcal simulate --system mocap`: a motion-capture session of a robot on its stand, with known truth.

The legs (every joint between the base and a marker's link) move through `samples` random poses: `MOVE_S` of smooth
motion, then `HOLD_S` still. Joint states and marker frames stream at `RATE_HZ`. Writes
- FILE.mcap: a ROS 2 recording with sensor_msgs/msg/JointState (the config's joint_states_topic) and
  mocap4r2_msgs/msg/Markers (markers.topic, positions in metres, labelled by name);
- FILE.c3d: the same marker frames in millimetres (invalid points: residual -1), its clock starting at its first
  frame: t_recording = t_file + offset (offset in the truth);
- FILE.truth.yaml / FILE.truth.urdf: encoder offsets, marker mounts, the base pose in the mocap frame, the C3D clock
  offset, and each still pose's reflected markers.
Per still pose and marker, occlusion and reflections last the whole hold (a pose hides a marker or makes a
reflection); noise is drawn per frame.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import yaml
from mcap_ros2.writer import Writer as Ros2Writer

from wolfcal.atomic import write_bytes_atomic, write_text_atomic
from wolfcal.encoders import encoder_readings
from wolfcal.errors import WolfcalError
from wolfcal.geometry import transform_from_xyz_rpy
from wolfcal.io.msgdefs import JOINT_STATE, MARKERS, MSGDEFS, stamp_dict
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.ranges import sampling_bounds
from wolfcal.robot.robot import Robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.sim.mocap_scene import MocapNoise, true_marker_positions

RATE_HZ = 100.0
MOVE_S, HOLD_S = 1.0, 1.5
START_NS = 1_700_000_000_000_000_000


def mocap_bounds(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) per joint [rad]: joints between the base and the markers' links within the config's mocap
    sampling ranges (`wolfcal.robot.ranges`); the others stay at 0 (clipped to their limits)."""
    moving = set(robot.actuated_joints_to([m.link for m in robot.config.marker_config().entries]))
    lo, hi = sampling_bounds(robot, "mocap")
    for k, name in enumerate(robot.joint_names):
        if name not in moving:
            joint = robot.model.joints[name]
            lo[k] = hi[k] = float(np.clip(0.0, joint.lower, joint.upper))
    return lo, hi


def timeline(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame times [s], true angles (F, J) and the still pose index of each frame (-1 while moving)."""
    n_pose = int(round((MOVE_S + HOLD_S) * RATE_HZ))
    t = np.arange(len(poses) * n_pose) / RATE_HZ
    k = np.minimum((t // (MOVE_S + HOLD_S)).astype(int), len(poses) - 1)
    phase = t - k * (MOVE_S + HOLD_S)
    s = np.clip(phase / MOVE_S, 0, 1)
    s = 0.5 - 0.5 * np.cos(np.pi * s)  # smooth start and stop
    previous = poses[np.maximum(k - 1, 0)]
    q = previous + (poses[k] - previous) * s[:, None]
    return t, q, np.where(phase >= MOVE_S, k, -1)


def simulate_mocap(robot: Robot, out: Path, samples: int, seed: int, truth: Corrections,
                   noise: MocapNoise = MocapNoise(), say: Callable[[str], None] = print) -> dict:  # fmt: skip
    """Write the files of the module docstring (outputs already checked); returns the truth dict."""
    if robot.config.markers is None:
        raise WolfcalError(f"{robot.config.path}: --system mocap needs 'markers:' in the robot config")
    rng = np.random.default_rng(seed)
    markers = robot.config.markers.entries
    mounts = rng.normal(size=(len(markers), 3))
    mounts *= noise.mount_sigma / np.linalg.norm(mounts, axis=1, keepdims=True)  # each mount off by mount_sigma
    T_mocap_base = transform_from_xyz_rpy(
        rng.uniform(-1, 1, 3) + [0, 0, 0.8], [*rng.normal(0, 0.05, 2), rng.uniform(-np.pi, np.pi)]
    )
    lo, hi = mocap_bounds(robot)
    poses = rng.uniform(lo, hi, (samples, len(lo)))
    t, q_true, pose_of_frame = timeline(poses)
    p = true_marker_positions(robot, q_true, truth, mounts, T_mocap_base) + rng.normal(
        0, noise.sigma, (len(t), len(markers), 3)
    )
    u = rng.uniform(size=(samples + 1, len(markers)))  # per still pose (last row: while moving)
    occluded = u < noise.occluded
    reflected = (u >= noise.occluded) & (u < noise.occluded + noise.reflections)
    direction = rng.normal(size=(samples + 1, len(markers), 3))
    direction *= rng.uniform(*noise.reflection_range, (samples + 1, len(markers), 1)) / np.linalg.norm(
        direction, axis=2, keepdims=True
    )
    occluded[-1], reflected[-1] = False, False
    row = np.where(pose_of_frame >= 0, pose_of_frame, samples)
    p += np.where(reflected[row][..., None], direction[row], 0.0)
    p[occluded[row]] = np.nan
    p[rng.uniform(size=p.shape[:2]) < 0.002] = np.nan  # brief dropouts
    q_read = encoder_readings(q_true, truth.offset_vector(robot.joint_names))
    _write_recording(robot, out, t, q_read, p)
    first = int(np.searchsorted(t, rng.uniform(0.3, 0.8)))  # the C3D starts this late in the recording
    c3d_path = out.with_suffix(".c3d")
    write_bytes_atomic(c3d_path, c3d_bytes([m.name for m in markers], p[first:] * 1000.0))
    offset_s = START_NS / 1e9 + float(t[first])
    data = {
        "truth": truth.to_dict(),
        "meaning": "offsets: q_true = q_measured + offset [rad]; marker_mounts: true offset of each marker from its "
        "configured place in its link [m]; T_mocap_base: p_mocap = T @ p_base [m]; c3d_clock_offset_s: "
        "t_recording = t_file + offset [s]",
        "system": "mocap", "samples": samples, "seed": seed,
        "noise": {"sigma_m": noise.sigma, "occluded": noise.occluded, "reflections": noise.reflections},
        "marker_mounts": {m.name: [float(v) for v in mounts[k]] for k, m in enumerate(markers)},
        "T_mocap_base": [[float(v) for v in r] for r in T_mocap_base],
        "c3d_clock_offset_s": offset_s,
        "reflections": [{"pose": int(s), "marker": markers[k].name} for s, k in zip(*np.nonzero(reflected[:-1]))],
    }  # fmt: skip
    write_text_atomic(out.with_name(out.stem + ".truth.yaml"), yaml.safe_dump(data, sort_keys=False))
    write_calibrated_urdf(robot.config.urdf, robot.model, truth, out.with_name(out.stem + ".truth.urdf"))
    say(f"wrote {out} ({len(t)} frames, {samples} still poses), {c3d_path} and the truth beside them")
    return data


def _write_recording(robot: Robot, out: Path, t: np.ndarray, q_read: np.ndarray, p: np.ndarray) -> None:
    """JointState and Markers messages at every frame, stamped on one clock."""
    import io

    buffer = io.BytesIO()
    writer = Ros2Writer(buffer)
    schemas = {name: writer.register_msgdef(name, MSGDEFS[name]) for name in (JOINT_STATE, MARKERS)}
    names = robot.config.marker_config().names
    for i, ti in enumerate(t):
        stamp = START_NS + int(round(ti * 1e9))
        header = {"stamp": stamp_dict(stamp), "frame_id": ""}
        writer.write_message(robot.config.joint_states_topic, schemas[JOINT_STATE], {
            "header": header, "name": robot.joint_names, "position": [float(v) for v in q_read[i]],
            "velocity": [], "effort": []}, log_time=stamp, publish_time=stamp)  # fmt: skip
        seen = [k for k in range(len(names)) if np.all(np.isfinite(p[i, k]))]
        writer.write_message(robot.config.marker_config().topic, schemas[MARKERS], {
            "header": {"stamp": stamp_dict(stamp), "frame_id": "mocap"}, "frame_number": i,
            "markers": [{"id_type": 0, "marker_index": k, "marker_name": names[k], "translation": {
                "x": float(p[i, k, 0]), "y": float(p[i, k, 1]), "z": float(p[i, k, 2])}} for k in seen],
        }, log_time=stamp, publish_time=stamp)  # fmt: skip
    writer.finish()
    write_bytes_atomic(out, buffer.getvalue())


def c3d_bytes(labels: list[str], xyz_mm: np.ndarray) -> bytes:
    """A C3D file (float points in mm at RATE_HZ, written by ezc3d) of positions (F, K, 3) [mm]; NaN points are
    written invalid (residual -1)."""
    import os
    import tempfile

    from wolfcal.io.mocap_c3d import import_ezc3d

    ezc3d = import_ezc3d("writing the session's C3D file")

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [RATE_HZ]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    points = np.ones((4, len(labels), len(xyz_mm)))
    points[:3] = np.transpose(xyz_mm, (2, 1, 0))
    c["data"]["points"] = points
    handle, scratch = tempfile.mkstemp(suffix=".c3d")
    os.close(handle)
    try:
        c.write(scratch)
        return Path(scratch).read_bytes()
    finally:
        os.unlink(scratch)
