"""Still samples from motion capture: marker trajectories + joint states -> `MarkerObservations`.

Sources: a ROS 2 recording holding both the joint states and mocap4r2_msgs/msg/Markers (one clock), or a motion-capture
file (C3D, Motive / Vicon CSV; `mocap_files`) with the joint states in a ROS 2 recording of the same session, whose
clocks differ by an offset: t_recording = t_file + offset [s] (t_file: seconds since the file's first frame). The
offset is given or estimated (`mocap_clock`).

Stillness test for markers (raw positions carry ~0.3 mm noise per axis at 100+ Hz and the odd reflection, so
frame-to-frame jumps say nothing): a frame is still when, for every marker measured in the window of
+-`STILL_WINDOW_S` around it, the per-axis medians of the window's first and second halves differ by at most
`STILL_DRIFT_M` (a median of 25 frames at 0.3 mm noise varies by ~0.08 mm; a reflection in a few frames does not move
it). A still period is a run of still frames at least `MIN_STILL_S` long; its sample is the per-marker median
over the period (a marker measured in fewer than half of its frames is absent), and the joint readings are the
per-joint median of the joint states in the period, which must themselves be still (every joint within one encoder
tick over the period). One sample per still period.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.io.mcapfile import check_mcap
from wolfcal.io.mocap_labels import match_names
from wolfcal.io.mocap_trajectories import USE_INDEX, MarkerTrajectories
from wolfcal.io.msgdefs import header_stamp_ns
from wolfcal.io.recording import JointStates
from wolfcal.markers import MarkerObservations

STILL_WINDOW_S = 0.25  # half-width of the stillness window [s]
STILL_DRIFT_M = 0.0005  # largest change of a marker's half-window medians in a still frame [m]
MIN_STILL_S = 0.5  # shortest still period that makes a sample [s]
EDGE_S = 0.1  # trimmed from both ends of a still period before its median is taken [s]


def read_recording(
    path: Path, config: RobotConfig, with_markers: bool
) -> tuple[JointStates, MarkerTrajectories | None]:
    """Joint states (config `joint_states_topic`) and, with `with_markers`, the Markers topic of a ROS 2 recording."""
    check_mcap(path)
    joints, frames = [], []
    topics = [config.joint_states_topic] + ([config.marker_config().topic] if with_markers else [])
    try:
        with path.open("rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            for _, channel, message, msg in reader.iter_decoded_messages(topics=topics):
                stamp = header_stamp_ns(msg.header, message.log_time)
                if channel.topic == config.joint_states_topic:
                    joints.append((stamp, list(msg.name), list(msg.position), list(msg.velocity)))
                else:
                    frames.append(
                        (
                            stamp,
                            [
                                (
                                    m.marker_name if m.id_type != USE_INDEX else str(m.marker_index),
                                    (m.translation.x, m.translation.y, m.translation.z),
                                )
                                for m in msg.markers
                            ],
                        )
                    )
    except WolfcalError:
        raise
    except Exception as exc:  # the mcap libraries raise many types for damaged files
        raise WolfcalError(f"{path}: cannot read the recording ({type(exc).__name__}: {exc})") from None
    if not joints:
        raise WolfcalError(
            f"{path}: no joint states on {config.joint_states_topic} (robot config 'joint_states_topic')"
        )
    states = JointStates.from_messages(joints)
    if not with_markers:
        return states, None
    if not frames:
        raise WolfcalError(
            f"{path}: no mocap4r2_msgs/msg/Markers on {config.marker_config().topic} (robot config "
            "'markers.topic'); give the motion-capture file with --mocap FILE"
        )
    labels = list(dict.fromkeys(name for _, markers in frames for name, _ in markers))
    column = {n: i for i, n in enumerate(labels)}
    frames.sort(key=lambda f: f[0])
    xyz = np.full((len(frames), len(labels), 3), np.nan)
    for i, (_, markers) in enumerate(frames):
        for name, p in markers:
            xyz[i, column[name]] = p
    times = np.array([f[0] for f in frames], dtype=np.int64)
    return states, MarkerTrajectories(
        path, times, labels, xyz, file_clock=False, format="ROS 2 recording (mocap4r2_msgs/msg/Markers)"
    )


def match_labels(traj: MarkerTrajectories, config: RobotConfig) -> tuple[list[str], list[int], list[str]]:
    """(configured names found, their columns in traj, labels no configured name matched); `mocap_labels` rules;
    a clear error when none is found."""
    names = config.marker_config().names
    match = match_names(traj.path, names, traj.labels)
    if not match.found:
        raise WolfcalError(
            f"{traj.path}: none of the robot config's marker names ({', '.join(names[:4])}, ...) is in the data "
            f"(labels found: {', '.join(match.extra[:8]) or 'none'}); name the markers in 'markers.list' as the "
            "motion-capture system labels them (with or without the 'Subject:' prefix)"
        )
    return match.found, match.columns, sorted(match.extra)


def still_frames(times_ns: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """(F,) bool: the stillness test of the module docstring, over frames (F,) with positions (F, K, 3) [m]."""
    n = len(times_ns)
    half = STILL_WINDOW_S * 1e9
    lo = np.searchsorted(times_ns, times_ns - half, side="left")
    hi = np.searchsorted(times_ns, times_ns + half, side="right")
    still = np.zeros(n, dtype=bool)
    for i in range(n):  # windows of ~50 frames: one vectorised median pair per frame
        if times_ns[hi[i] - 1] - times_ns[lo[i]] < 1.5 * half:
            continue  # window cut by the start or end of the data
        d = np.abs(nanmedian(xyz[lo[i] : i + 1]) - nanmedian(xyz[i : hi[i]]))
        still[i] = bool(np.all(d[np.isfinite(d)] <= STILL_DRIFT_M)) and np.isfinite(d).any()
    return still


def nanmedian(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """np.nanmedian without the warning for all-NaN slices (they give NaN: a marker not measured)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(x, axis=axis)


def still_periods(times_ns: np.ndarray, still: np.ndarray) -> list[tuple[int, int]]:
    """(first, last + 1) frame index of each run of still frames at least MIN_STILL_S long, edges trimmed."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    out = []
    for a, b in zip(edges[::2], edges[1::2]):
        t0, t1 = times_ns[a] + EDGE_S * 1e9, times_ns[b - 1] - EDGE_S * 1e9
        if t1 - t0 >= MIN_STILL_S * 1e9 - 2 * EDGE_S * 1e9:
            a2, b2 = np.searchsorted(times_ns, t0), np.searchsorted(times_ns, t1, side="right")
            if b2 > a2:
                out.append((int(a2), int(b2)))
    return out


def marker_samples(traj: MarkerTrajectories, states: JointStates, config: RobotConfig, joint_names: list[str],
                   offset_s: float) -> MarkerObservations:  # fmt: skip
    """One sample per still period of the markers in which the joints were still too; `offset_s` maps the
    trajectories' clock to the recording's (t_recording = t_traj + offset)."""
    names, columns, unknown = match_labels(traj, config)
    xyz = traj.xyz[:, columns]
    missing = [j for j in joint_names if j not in states.series]
    if missing:
        raise WolfcalError(f"{traj.path}: the joint states lack {', '.join(missing[:5])}; record every joint")
    still = still_frames(traj.times_ns, xyz)
    q: list[np.ndarray] = []
    stamps: list[int] = []
    sample_rows: list[int] = []
    marker_rows: list[int] = []
    points: list[np.ndarray] = []
    shift = int(round(offset_s * 1e9))
    for a, b in still_periods(traj.times_ns, still):
        reading = states.held_readings(int(traj.times_ns[a]) + shift, int(traj.times_ns[b - 1]) + shift)
        if reading is None:
            continue
        block = xyz[a:b]
        seen = np.sum(np.all(np.isfinite(block), axis=2), axis=0)  # (K,)
        median = nanmedian(block)
        for k in np.flatnonzero(seen >= 0.5 * (b - a)):
            sample_rows.append(len(q))
            marker_rows.append(int(k))
            points.append(median[k])
        q.append(reading[[states.names.index(j) for j in joint_names]])
        stamps.append((int(traj.times_ns[a]) + int(traj.times_ns[b - 1])) // 2 + shift)
    if not q:
        raise WolfcalError(
            f"{traj.path}: no period in which the markers and the joints were both still; hold each "
            f"pose at least {MIN_STILL_S + 2 * STILL_WINDOW_S:.1f} s"
            + ("; or the clock offset is wrong (--mocap-offset)" if traj.file_clock else "")
        )
    return MarkerObservations(
        joint_names=list(joint_names), q_measured=np.array(q), stamps_ns=np.array(stamps, dtype=np.int64),
        sources=[str(traj.path)] * len(q), marker_names=names, sample_index=np.array(sample_rows, dtype=int),
        marker_index=np.array(marker_rows, dtype=int), xyz=np.array(points).reshape(-1, 3),
        clock_offsets_s={str(traj.path): offset_s} if traj.file_clock else {}, unknown_names=unknown,
    )  # fmt: skip
