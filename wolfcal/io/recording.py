"""Pair camera frames with joint states and keep only still frames.

In a capture file a sample's joint state has exactly the stamp of its image. A plain ROS 2 recording has
continuous joint states (50-100 Hz) and images (a few Hz) with their own stamps; a frame is used only if,
for every joint:
- a joint state lies within `PAIR_TOLERANCE_NS` of the image stamp (the nearest gives the sample's angle);
- the joint was still: over its states within +-`STILL_WINDOW_NS` of the image (spanning at least half of
  that window) its position changed by at most one encoder tick (2 pi / 4096 rad); where the states are too
  sparse to span it, every reported |velocity| in the window must be at most `STILL_VELOCITY`.
Joint states are kept per joint, so recordings in which several publishers share the topic (e.g. legs and
head on separate messages) pair too.

Still spans: the kept frames of one camera that follow each other with no frame left out between them and whose
joint readings all lie within one encoder tick of each other (per joint) form one still span (`still_spans`): one
still pose seen again and again. A fit of a recording averages each span's corners into one sample
(`wolfcal.spans`).

Several cameras: each camera's frames are paired and tested on their own; kept frames of different cameras whose
stamps lie within `SAMPLE_TOLERANCE_NS` of the group's first frame form one sample (one frame per camera), others
are separate samples. In a capture file the frames of one sample share one stamp exactly.
"""

from __future__ import annotations

from array import array
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from wolfcal.encoders import RAD_PER_TICK

PAIR_TOLERANCE_NS = 20_000_000  # 20 ms: a joint moving at STILL_VELOCITY turns by < 1/2 tick in this time
STILL_WINDOW_NS = 250_000_000  # +-0.25 s around the image
ENCODER_TICK = RAD_PER_TICK  # [rad] Dynamixel resolution
STILL_VELOCITY = 0.03  # [rad/s] about one Dynamixel velocity unit (0.229 rpm = 0.024 rad/s)
SAMPLE_TOLERANCE_NS = 20_000_000  # 20 ms: frames of different cameras this close form one sample (recordings)


@dataclass(frozen=True)
class JointSeries:
    """Time series of one joint, sorted by time; velocities are NaN where a message reported none."""

    times: np.ndarray  # (N,) int64 [ns]
    positions: np.ndarray  # (N,) [rad]
    velocities: np.ndarray  # (N,) [rad/s]


class JointLog:
    """JointState messages as they are read, kept compactly: per distinct list of joint names, the stamps [ns],
    positions [rad] and velocities [rad/s] in flat typed arrays (8 bytes a number), not as Python objects.
    Velocities are NaN where a message reported none."""

    def __init__(self) -> None:
        self._groups: dict[tuple[str, ...], tuple[array, array, array]] = {}
        self.count = 0  # messages added

    def add(self, stamp: int, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float]) -> None:
        """One message; names beyond the positions given are ignored."""
        n = min(len(names), len(positions))
        stamps, qs, vs = self._groups.setdefault(tuple(names[:n]), (array("q"), array("d"), array("d")))
        stamps.append(stamp)
        qs.extend(positions[:n])
        vs.extend(velocities[:n] if len(velocities) == len(names) else [np.nan] * n)
        self.count += 1

    def drop_before(self, stamp: int) -> None:
        """Forget the messages stamped before `stamp` [ns] (`count` still counts them; name lists stay known)."""
        for names, (stamps, qs, vs) in self._groups.items():
            times = np.frombuffer(stamps, np.int64)
            keep = times >= stamp
            if keep.all():
                continue
            shape = (len(stamps), len(names))
            self._groups[names] = (
                array("q", times[keep].tobytes()),
                array("d", np.frombuffer(qs).reshape(shape)[keep].tobytes()),
                array("d", np.frombuffer(vs).reshape(shape)[keep].tobytes()),
            )

    def groups(self) -> list[tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]]:
        """(names, stamps (N,) [ns], positions (N, J) [rad], velocities (N, J) [rad/s]) per distinct name list,
        in order of first appearance (views of the log's arrays)."""
        out = []
        for names, (stamps, qs, vs) in self._groups.items():
            shape = (len(stamps), len(names))
            out.append((names, np.frombuffer(stamps, np.int64), np.frombuffer(qs).reshape(shape),
                        np.frombuffer(vs).reshape(shape)))  # fmt: skip
        return out


@dataclass(frozen=True)
class JointStates:
    names: list[str]  # every joint seen, in order of first appearance
    series: dict[str, JointSeries]

    @classmethod
    def from_messages(
        cls, messages: Iterable[tuple[int, Sequence[str], Sequence[float], Sequence[float]]]
    ) -> JointStates:
        """From (stamp_ns, names, positions, velocities) per JointState message; empty velocities allowed."""
        log = JointLog()
        for message in messages:
            log.add(*message)
        return cls.from_log(log)

    @classmethod
    def from_log(cls, log: JointLog, keep: list[np.ndarray] | None = None) -> JointStates:
        """From a JointLog; `keep`: per group of `log.groups()`, a (N,) mask of the messages to use. A joint
        of one group whose messages are all kept and in time order (the usual recording) gets views of the log's
        arrays, not copies (memory on long recordings)."""
        columns: dict[str, tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]] = {}
        for k, (names, stamps, qs, vs) in enumerate(log.groups()):
            if keep is not None and not keep[k].all():
                stamps, qs, vs = stamps[keep[k]], qs[keep[k]], vs[keep[k]]
            for j, name in enumerate(names):
                times, positions, velocities = columns.setdefault(name, ([], [], []))
                times.append(stamps)
                positions.append(qs[:, j])
                velocities.append(vs[:, j])
        series = {}
        for name, (times, positions, velocities) in columns.items():
            if len(times) == 1 and np.all(times[0][1:] >= times[0][:-1]):
                series[name] = JointSeries(times[0], positions[0], velocities[0])
                continue
            t = np.concatenate(times)
            order = np.argsort(t, kind="stable")
            series[name] = JointSeries(t[order], np.concatenate(positions)[order], np.concatenate(velocities)[order])
        return cls([n for n, s in series.items() if len(s.times)], {n: s for n, s in series.items() if len(s.times)})

    def held_readings(self, t0: int, t1: int, names: Sequence[str] | None = None) -> np.ndarray | None:
        """(J,) per-joint median reading over [t0, t1] [ns] of the joints `names` (default: all, in `self.names`'
        order) [rad]; None when a joint moved more than one encoder tick or has no state in that span."""
        q = []
        for name in self.names if names is None else names:
            s = self.series[name]
            a, b = np.searchsorted(s.times, t0), np.searchsorted(s.times, t1, side="right")
            if b <= a or np.ptp(s.positions[a:b]) > ENCODER_TICK + 1e-9:
                return None
            q.append(float(np.median(s.positions[a:b])))
        return np.array(q)


@dataclass(frozen=True, slots=True)
class Paired:
    positions: np.ndarray  # (J,) in the order of JointStates.names [rad]
    velocities: np.ndarray | None  # (J,) [rad/s]; None unless every joint reported one


def pair_frame(states: JointStates, stamp_ns: int) -> Paired | str:
    """Joint angles for the frame at `stamp_ns` of a recording, or the reason the frame is not used: the nearest
    state within the tolerance, and the stillness test of the module docstring. A capture file's frames: `pair_exact`.
    """
    positions, velocities = [], []
    worst: tuple[float, str] | None = None  # (ticks moved, joint) of the joint that moved most
    for name in states.names:
        s = states.series[name]
        i = int(np.searchsorted(s.times, stamp_ns))
        candidates = [j for j in (i - 1, i) if 0 <= j < len(s.times)]
        j = min(candidates, key=lambda c: abs(int(s.times[c]) - stamp_ns)) if candidates else -1
        dt = abs(int(s.times[j]) - stamp_ns) if candidates else None
        if dt is None or dt > PAIR_TOLERANCE_NS:
            nearest = (
                f"nearest {dt / 1e6:.0f} ms away"
                if dt is not None and dt <= STILL_WINDOW_NS
                else (f"none within {STILL_WINDOW_NS / 1e6:.0f} ms")
            )  # what a window of +-STILL_WINDOW_NS tells
            return f"no joint state of {name} within {PAIR_TOLERANCE_NS / 1e6:.0f} ms ({nearest})"
        positions.append(s.positions[j])
        velocities.append(s.velocities[j])
        lo = int(np.searchsorted(s.times, stamp_ns - STILL_WINDOW_NS, side="left"))
        hi = int(np.searchsorted(s.times, stamp_ns + STILL_WINDOW_NS, side="right"))
        if s.times[hi - 1] - s.times[lo] >= STILL_WINDOW_NS:
            ticks = float(np.ptp(s.positions[lo:hi])) / ENCODER_TICK
            if ticks > 1 + 1e-6 and (worst is None or ticks > worst[0]):
                worst = (ticks, name)
            continue
        v = s.velocities[lo:hi]
        v = v[np.isfinite(v)]
        if not len(v):
            return (
                f"too few joint states of {name} around the image to tell whether it was still "
                f"(need states over +-{STILL_WINDOW_NS / 1e9:.2f} s, or velocities)"
            )
        if np.max(np.abs(v)) > STILL_VELOCITY:
            return f"{name} was turning at {np.max(np.abs(v)):.3f} rad/s (still: <= {STILL_VELOCITY} rad/s)"
    if worst is not None:
        return f"not still: {worst[1]} moved {worst[0]:.1f} encoder ticks within +-{STILL_WINDOW_NS / 1e9:.2f} s"
    v = np.asarray(velocities)
    return Paired(np.asarray(positions), v if np.all(np.isfinite(v)) else None)


def pair_exact(states: JointStates, stamps_ns: np.ndarray) -> list[Paired | str]:
    """A capture file's frames at `stamps_ns` (N,) [ns], all at once: for each, the joint states stamped exactly like
    it (the first of equal stamps), or why it has none (the first joint, in the order of `states.names`, without a
    state of its stamp). No stillness test: the capture decided that the robot was still."""
    n = len(stamps_ns)
    positions = np.empty((n, len(states.names)))
    velocities = np.empty((n, len(states.names)))
    missing = np.full(n, -1)  # per frame, the first joint without a state of its stamp
    for k, name in reversed(list(enumerate(states.names))):
        s = states.series[name]
        i = np.searchsorted(s.times, stamps_ns)
        at = np.minimum(i, len(s.times) - 1)
        found = (i < len(s.times)) & (s.times[at] == stamps_ns) if len(s.times) else np.zeros(n, bool)
        missing[~found] = k
        if len(s.times):
            positions[:, k] = s.positions[at]
            velocities[:, k] = s.velocities[at]
    finite = np.all(np.isfinite(velocities), axis=1).tolist()
    return [
        f"no joint state of {states.names[m]} with the image's stamp" if m >= 0
        else Paired(positions[f], velocities[f] if finite[f] else None)
        for f, m in enumerate(missing)
    ]  # fmt: skip


def group_by_stamp(stamps: Sequence[int], cameras: Sequence[str], tolerance_ns: int) -> list[list[int]]:
    """Indices of frames grouped into samples: in stamp order, a frame joins the current group when it is within
    `tolerance_ns` of the group's first frame and its camera is not in the group yet."""
    order = np.argsort(np.asarray(stamps, dtype=np.int64), kind="stable")
    groups: list[list[int]] = []
    for i in (int(k) for k in order):
        group = groups[-1] if groups else None
        if (
            group is not None
            and stamps[i] - stamps[group[0]] <= tolerance_ns
            and cameras[i] not in {cameras[j] for j in group}
        ):
            group.append(i)
        else:
            groups.append([i])
    return groups


def still_spans(readings: Sequence[np.ndarray | None]) -> list[int]:
    """Still span of each frame of one camera, in stamp order: `readings` holds each frame's joint readings (J,)
    [rad], or None for a frame that was not kept (it ends the span before it). A frame joins the current span when
    the frame before it was kept and each joint's readings over the span, its own included, stay within one encoder
    tick; spans are numbered 0, 1, ... in order; -1 for frames not kept."""
    out: list[int] = []
    span, low, high = -1, None, None
    previous_kept = False
    for q in readings:
        if q is None:
            out.append(-1)
            previous_kept = False
            continue
        if previous_kept and low is not None and high is not None:
            new_low, new_high = np.minimum(low, q), np.maximum(high, q)
            if np.all(new_high - new_low <= ENCODER_TICK + 1e-9):
                low, high = new_low, new_high
                out.append(span)
                continue
        span, low, high = span + 1, q, q
        out.append(span)
        previous_kept = True
    return out
