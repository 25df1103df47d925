"""Motion-capture files and recordings written by independent writers for the tests: C3D by ezc3d, Markers and
joint-state recordings by mcap_ros2 with the message definition text written here."""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
from mcap_ros2.writer import Writer as Ros2Writer

T0 = 1_700_000_000_000_000_000

RATE = 100.0
HEADER_DEFS = """================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""  # the definitions a message with a std_msgs/Header carries after its own, as ros2 writes them
MARKERS_DEF = (
    """std_msgs/Header header
uint32 frame_number
mocap4r2_msgs/Marker[] markers
"""
    + HEADER_DEFS
    + """================================================================================
MSG: mocap4r2_msgs/Marker
int8 USE_NAME=0
int8 USE_INDEX=1
int8 USE_BOTH=2
int8 id_type
int32 marker_index
string marker_name
geometry_msgs/Point translation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
"""
)
JOINT_STATE_DEF = (
    """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
"""
    + HEADER_DEFS
)


def session(n_poses: int = 4, seed: int = 0):
    """A toy session: one joint angle per frame (moves 1 s, holds 1.5 s) and three markers that follow it
    (positions [m], 0.3 mm noise)."""
    rng = np.random.default_rng(seed)
    targets = rng.uniform(-0.5, 0.5, n_poses)
    t = np.arange(int(n_poses * 2.5 * RATE)) / RATE
    k = np.minimum((t // 2.5).astype(int), n_poses - 1)
    s = np.clip((t - 2.5 * k) / 1.0, 0, 1)
    q = np.where(k > 0, targets[k - 1], 0.0) + (targets[k] - np.where(k > 0, targets[k - 1], 0.0)) * s
    p = np.stack([np.column_stack([np.cos(q) * r, np.sin(q) * r, np.full_like(q, 0.1 * r)]) for r in (0.2, 0.3, 0.4)],
                 axis=1) + rng.normal(0, 0.0003, (len(t), 3, 3))  # fmt: skip
    return t, q, p


def write_c3d(path: Path, labels: list[str], xyz_mm: np.ndarray, units: str = "mm", rate: float = RATE) -> None:
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    points = np.ones((4, len(labels), len(xyz_mm)))
    points[:3] = np.transpose(xyz_mm, (2, 1, 0))  # NaN points: ezc3d writes them invalid (residual -1)
    c["data"]["points"] = points
    c.write(str(path))


def write_markers_recording(path: Path, t: np.ndarray, joints: dict[str, np.ndarray], labels: list[str],
                            xyz_m: np.ndarray | None, by_index: bool = False) -> None:  # fmt: skip
    with path.open("wb") as handle:
        writer = Ros2Writer(handle)
        js = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_DEF)
        mk = writer.register_msgdef("mocap4r2_msgs/msg/Markers", MARKERS_DEF)
        for i, ti in enumerate(t):
            stamp = T0 + int(round(ti * 1e9))
            header = {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9}, "frame_id": ""}
            writer.write_message(
                "/joint_states",
                js,
                {
                    "header": header,
                    "name": list(joints),
                    "position": [float(v[i]) for v in joints.values()],
                    "velocity": [],
                    "effort": [],
                },
                log_time=stamp,
            )
            if xyz_m is None:
                continue
            markers = [{"id_type": 1 if by_index else 0, "marker_index": k, "marker_name": "" if by_index else name,
                        "translation": dict(zip("xyz", map(float, xyz_m[i, k])))}
                       for k, name in enumerate(labels) if np.all(np.isfinite(xyz_m[i, k]))]  # fmt: skip
            writer.write_message(
                "/mocap/markers", mk, {"header": header, "frame_number": i, "markers": markers}, log_time=stamp
            )
        writer.finish()
