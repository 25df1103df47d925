"""A motion-capture session of the strider robot (tests/data/strider: another robot file and marker layout) that
wolfcal did not generate: true poses by yourdfpy's forward kinematics, joint states and mocap4r2 Markers written with
mcap_ros2 and this folder's own message definitions, the C3D file written by ezc3d.

The legs go through still poses (MOVE_S of smooth motion, then HOLD_S still). Joint states at 100 Hz, quantised to
4096 ticks per turn, read as q_measured = q_true - offset; markers at 120 Hz with 0.3 mm noise per axis, marker mounts
off their configured places by 1 mm each. Per still pose, 3 % of the markers are occluded and 1 % are a reflection
2-20 mm from the marker, for the whole hold. Files:
- markers.mcap: joint states and Markers [m] on one clock;
- joints.mcap: the same joint states alone, and markers.c3d: the marker frames [mm], starting `c3d_offset_s` into
  the recording (t_recording = t_file + offset, t_recording in seconds of the recording's stamps).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
import yourdfpy
from mcap_ros2.writer import Writer as Ros2Writer
from mocap_recordings import JOINT_STATE_DEF, MARKERS_DEF, T0, write_c3d

from wolfcal.config import load_robot_config

STRIDER = Path(__file__).resolve().parent / "data" / "strider"
JOINT_HZ, MARKER_HZ = 100.0, 120.0
MOVE_S, HOLD_S = 1.0, 1.5
TICK = 2 * np.pi / 4096  # [rad]
RANGES = {
    "hip_yaw": (-0.3, 0.3),
    "hip_roll": (-0.3, 0.3),
    "hip_pitch": (-1.0, 0.3),
    "knee": (0.2, 1.6),
    "ankle_pitch": (-0.8, 0.6),
    "ankle_roll": (-0.35, 0.35),
}  # true angles of the still poses [rad]


@dataclass
class Session:
    folder: Path
    joint_names: list[str]
    offsets: dict[str, float]  # q_true = q_measured + offset [rad]
    mounts: dict[str, np.ndarray]  # true marker offset from its configured place, link frame [m]
    q_true: np.ndarray  # (N, J) still poses [rad]
    q_measured: np.ndarray  # (N, J) their readings [rad]
    reflections: set[tuple[int, str]]  # (still pose, marker)
    occluded: set[tuple[int, str]]
    c3d_offset_s: float

    def sole_poses(self, offsets: dict[str, float] | None) -> dict[str, np.ndarray]:
        """T_pelvis_sole (N, 4, 4) of each sole at the still poses: at the true angles (offsets None) or at the
        readings plus `offsets`, by yourdfpy's forward kinematics."""
        if offsets is None:
            q = self.q_true
        else:
            q = self.q_measured + np.array([offsets.get(j, 0.0) for j in self.joint_names])
        return {sole: fk(q, self.joint_names, sole) for sole in ("l_sole", "r_sole")}


def urdf() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(STRIDER / "strider.urdf"), load_meshes=False, build_collision_scene_graph=False)


def fk(q: np.ndarray, joint_names: list[str], link: str, model: yourdfpy.URDF | None = None) -> np.ndarray:
    """T_pelvis_link (N, 4, 4) at angles q (N, J): yourdfpy's joints (origin, axis) composed along the chain."""
    model = model or urdf()
    child = {j.child: j for j in model.robot.joints}
    chain = []
    while link in child:
        chain.append(child[link])
        link = child[link].parent
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4))
    for joint in reversed(chain):
        T = T @ (joint.origin if joint.origin is not None else np.eye(4))
        if joint.type == "revolute":
            angle = q[:, joint_names.index(joint.name)]
            T = T @ _rotation(np.asarray(joint.axis, dtype=float), angle)
    return T


def _rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(N, 4, 4) rotations by `angle` (N,) about the unit `axis` (Rodrigues)."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(4)[None].repeat(len(angle), axis=0)
    R[:, :3, :3] = np.eye(3) + np.sin(angle)[:, None, None] * K + (1 - np.cos(angle))[:, None, None] * (K @ K)
    return R


def _header(stamp: int) -> dict:
    return {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9}, "frame_id": "vicon"}


def write_session(folder: Path, seed: int, n_poses: int = 25) -> Session:
    """Write the files of the module docstring into `folder`; returns the truth."""
    rng = np.random.default_rng(seed)
    config = load_robot_config(STRIDER)
    model = urdf()
    joints = list(model.actuated_joint_names)
    names = list(config.marker_config().names)
    markers = config.marker_config().entries
    offsets = {j: float(rng.normal(0, 0.025)) for j in joints}
    directions = rng.normal(size=(len(names), 3))
    mounts = directions / np.linalg.norm(directions, axis=1, keepdims=True) * 0.001
    lo = np.array([RANGES[j[2:]][0] for j in joints])
    hi = np.array([RANGES[j[2:]][1] for j in joints])
    poses = rng.uniform(lo, hi, (n_poses, len(joints)))
    yaw = rng.uniform(-np.pi, np.pi)
    T_mocap_pelvis = np.eye(4)
    T_mocap_pelvis[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
    T_mocap_pelvis[:3, 3] = [*rng.uniform(-1.5, 1.5, 2), 0.75]

    def q_at(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """True angles (F, J) at times t [s] and the still pose of each time (-1 while moving)."""
        k = np.minimum((t // (MOVE_S + HOLD_S)).astype(int), n_poses - 1)
        phase = t - k * (MOVE_S + HOLD_S)
        s = 0.5 - 0.5 * np.cos(np.pi * np.clip(phase / MOVE_S, 0, 1))
        previous = np.where(k[:, None] > 0, poses[np.maximum(k - 1, 0)], 0.0)
        return previous + (poses[k] - previous) * s[:, None], np.where(phase >= MOVE_S, k, -1)

    duration = n_poses * (MOVE_S + HOLD_S)
    t_joint = np.arange(int(duration * JOINT_HZ)) / JOINT_HZ
    t_marker = np.arange(int(duration * MARKER_HZ)) / MARKER_HZ
    q_joint, _ = q_at(t_joint)
    q_read = np.round((q_joint - np.array([offsets[j] for j in joints])) / TICK) * TICK
    q_marker, still = q_at(t_marker)
    # marker positions: one forward-kinematics pass per still pose, one per frame while moving
    p = np.empty((len(t_marker), len(names), 3))
    links = sorted({m.link for m in markers})
    for k in range(-1, n_poses):
        frames = np.flatnonzero(still == k)
        if not len(frames):
            continue
        q = q_marker[frames] if k < 0 else poses[k][None]
        T = {link: T_mocap_pelvis @ fk(q, joints, link, model) for link in links}
        for m, marker in enumerate(markers):
            T_link = T[marker.link]
            xyz = np.asarray(marker.xyz) + mounts[m]
            p[frames, m] = np.einsum("nij,j->ni", T_link[:, :3, :3], xyz) + T_link[:, :3, 3]
    p += rng.normal(0, 0.0003, p.shape)
    pairs = rng.permutation(n_poses * len(names))
    n_occluded, n_reflected = round(0.03 * len(pairs)), max(round(0.01 * len(pairs)), 1)
    occluded = {(int(i // len(names)), names[i % len(names)]) for i in pairs[:n_occluded]}
    reflections = {(int(i // len(names)), names[i % len(names)]) for i in pairs[n_occluded : n_occluded + n_reflected]}
    for pose, name in reflections:
        direction = rng.normal(size=3)
        p[still == pose, names.index(name)] += direction / np.linalg.norm(direction) * rng.uniform(0.002, 0.02)
    for pose, name in occluded:
        p[still == pose, names.index(name)] = np.nan

    with (folder / "markers.mcap").open("wb") as handle, (folder / "joints.mcap").open("wb") as joints_only:
        writer, alone = Ros2Writer(handle), Ros2Writer(joints_only)
        js, mk, js_alone = (writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_DEF),
                            writer.register_msgdef("mocap4r2_msgs/msg/Markers", MARKERS_DEF),
                            alone.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_DEF))  # fmt: skip
        events = sorted([(t, 0, i) for i, t in enumerate(t_joint)] + [(t, 1, i) for i, t in enumerate(t_marker)])
        for t, kind, i in events:
            stamp = T0 + int(round(t * 1e9))
            if kind == 0:
                message = {"header": _header(stamp), "name": joints, "position": q_read[i].tolist(), "velocity": [],
                           "effort": []}  # fmt: skip
                writer.write_message(config.joint_states_topic, js, message, log_time=stamp)
                alone.write_message(config.joint_states_topic, js_alone, message, log_time=stamp)
                continue
            seen = [m for m in range(len(names)) if np.all(np.isfinite(p[i, m]))]
            writer.write_message(config.marker_config().topic, mk, {
                "header": _header(stamp), "frame_number": i, "markers": [
                    {"id_type": 0, "marker_index": m, "marker_name": names[m],
                     "translation": dict(zip("xyz", map(float, p[i, m])))} for m in seen]}, log_time=stamp)  # fmt: skip
        writer.finish()
        alone.finish()
    first = int(rng.integers(30, 90))  # the C3D file starts this many marker frames into the recording
    write_c3d(folder / "markers.c3d", names, p[first:] * 1000.0, rate=MARKER_HZ)
    return Session(
        folder=folder, joint_names=joints, offsets=offsets, mounts=dict(zip(names, mounts)), q_true=poses,
        q_measured=np.round((poses - np.array([offsets[j] for j in joints])) / TICK) * TICK,
        reflections=reflections, occluded=occluded, c3d_offset_s=T0 / 1e9 + first / MARKER_HZ,
    )  # fmt: skip


def sole_errors(session: Session, fitted: dict[str, float]) -> tuple[float, float]:
    """Largest sole position [mm] and rotation [deg] error over the still poses and both soles."""
    true, model = session.sole_poses(None), session.sole_poses(fitted)
    mm, deg = 0.0, 0.0
    for sole in true:
        E = np.linalg.inv(true[sole]) @ model[sole]
        mm = max(mm, float(np.max(np.linalg.norm(E[:, :3, 3], axis=1))) * 1000)
        cos = np.clip((np.trace(E[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)
        deg = max(deg, float(np.rad2deg(np.max(np.arccos(cos)))))
    return mm, deg


def mount_rotation(session: Session, side: str) -> float:
    """The rotation [rad] about the ankle-roll axis (x of the foot frame, through its origin) that best explains the
    true mount errors m_k of the foot's markers (r_k in the foot frame): sum((a x r_k) . m_k) / sum(|a x r_k|^2).
    The ankle roll is the foot's last joint, so an offset error rotates the foot by a fixed rotation in its own
    frame: the markers cannot tell it from this rotation of their mounts."""
    config = load_robot_config(STRIDER)
    a = np.array([1.0, 0.0, 0.0])
    moves = [
        (np.cross(a, m.xyz), session.mounts[m.name]) for m in config.marker_config().entries if m.link == f"{side}_foot"
    ]
    return float(sum(u @ m for u, m in moves) / sum(u @ u for u, _ in moves))


def known_mounts_config(session: Session, folder: Path) -> Path:
    """A copy of the strider config whose marker places are the true ones (nominal + mount)."""
    data = yaml.safe_load((STRIDER / "robot.yaml").read_text())
    data["urdf"] = str(STRIDER / data["urdf"])
    for m in data["markers"]["list"]:
        m["xyz"] = [float(v) for v in np.add(m["xyz"], session.mounts[m["name"]])]
    path = folder / "known_mounts.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path
