"""Pair the frames of a recording with its joint states while the file is read, keeping a bounded window of states.

Messages arrive in the file's order (MCAP log time); pairing goes by header stamps, which need not follow it (an
image stamped at exposure and logged after its transport, a publisher's late batch). The bound assumed: a message's
header stamp is at most `DISORDER_NS` below the largest stamp (of joint states and images) read before it. Then a
frame at stamp s is final once the largest stamp read is more than `DISORDER_NS` past s + `STILL_WINDOW_NS`: every
joint state within +-`STILL_WINDOW_NS` of s has been read. Frames are paired in batches (`pair_frame`, the rule of
`wolfcal.io.recording`) on the states of the window, which holds every state that pairing on the whole log would
look at, so the results are the same; states older than any frame still to pair are dropped. Memory then holds about
`DISORDER_NS` + 2 `STILL_WINDOW_NS` of joint states (3 s), whatever the length.

A file that breaks the bound (a message stamped too far back, or a joint first published after frames were paired)
raises `Disorder`: the reader then reads it again with `disorder_ns=None`, which pairs every frame on the whole log
at the end (memory of the joint states as before). Capture files (one joint state with the stamp of each sample's
images) are recognised as before: every image's stamp is a joint state's, and there are as many joint states as
image stamps; their frames are paired by exact stamp. Until a frame without a joint state of its stamp shows the
file is not one, nothing is paired or dropped (see `FramePairer`).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wolfcal.io.recording import (
    STILL_WINDOW_NS,
    JointLog,
    JointSeries,
    JointStates,
    Paired,
    pair_exact,
    pair_frame,
)

DISORDER_NS = 2_000_000_000  # [ns] how far back of the stamps read so far a message's header stamp may lie
BATCH_NS = 500_000_000  # [ns] frames are paired when the stamps read have advanced by this much


class Disorder(Exception):
    """The file's stamps are further out of order than `DISORDER_NS`: pair it on the whole log."""


@dataclass(slots=True)
class PairedFrame:
    """What pairing decided for one frame of one camera (the frame's header data is the caller's `item`)."""

    camera: str
    stamp: int  # [ns] header stamp
    item: object  # the caller's data on the frame (e.g. its image header)
    result: Paired | str | None  # the paired readings or why not; None: not paired (not an image, or `bad_stamp`)
    bad_stamp: bool  # a joint state with this stamp was left out (non-finite positions)


@dataclass
class Pairing:
    """The outcome of a whole file: frames in the order they were paired, whether it is a capture file (frames
    paired by exact stamp, else by the recording rule), the joint names (every joint with finite readings, in order
    of first appearance) and the non-finite readings."""

    frames: list[PairedFrame]
    exact: bool
    names: list[str]
    messages: int  # joint-state messages read
    bad_messages: int  # of them, with a NaN or infinite position
    bad_joints: Counter[str]  # joint -> number of non-finite positions


class FramePairer:
    """Feed joint states and frames in file order (`add_joints`, `add_frame`), then `finish`.

    `disorder_ns`: the bound on the stamps' disorder (module docstring); None keeps every joint state and pairs
    every frame at the end (the whole log). While every final frame has a joint state of its own stamp, the file
    may be a capture file (small: one joint state per sample): nothing is dropped or paired until `finish` decides;
    the first final frame without one makes it a recording, paired from then on as it is read."""

    def __init__(self, disorder_ns: int | None = DISORDER_NS) -> None:
        self.disorder_ns = disorder_ns
        self._log = JointLog()  # the window; every message while disorder_ns is None or the file may be a capture
        self._names: dict[str, None] = {}  # every joint, in order of first appearance of its message's name list
        self._lists: dict[tuple[str, ...], bool] = {}  # each list of names seen: whether a message of it was finite
        self._finite: set[str] = set()  # joints with a message whose positions are all finite
        self._top: int | None = None  # largest stamp read [ns]
        self._paired_at: int | None = None  # `_top` when frames were last paired
        self._pending: list[tuple[str, int, object, bool]] = []  # (camera, stamp, item, pair it) not yet paired
        self._frames: list[PairedFrame] = []
        self._names_used: list[str] | None = None  # the names the frames were paired with so far
        self._capture: _CaptureTest | None = _CaptureTest()  # None once the file is known to be a recording
        self._bad = 0
        self._bad_joints: Counter[str] = Counter()

    def add_joints(
        self, stamp: int, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float]
    ) -> None:
        """One JointState message (header stamp [ns], as `JointLog.add`)."""
        self._check_order(stamp)
        n = min(len(names), len(positions))
        key = tuple(names[:n])
        if key not in self._lists:  # a new list of names: its joints in order of first appearance
            self._lists[key] = False
            for name in key:
                self._names.setdefault(name, None)
        if all(map(math.isfinite, positions[:n])):
            if not self._lists[key]:
                self._finite.update(key)
                self._lists[key] = True
        else:
            self._bad += 1
            self._bad_joints.update(name for name, q in zip(key, positions) if not math.isfinite(q))
        self._log.add(stamp, names, positions, velocities)
        if self._capture is not None:
            self._capture.add(stamp, joint=True)
        self._advance(stamp)

    def add_frame(self, camera: str, stamp: int, item: object, pair: bool = True) -> None:
        """One image of `camera` at header `stamp` [ns]; `pair=False` for one that is not an image (its stamp still
        counts in telling a capture file)."""
        self._check_order(stamp)
        self._pending.append((camera, stamp, item, pair))
        if self._capture is not None:
            self._capture.add(stamp, joint=False)
        self._advance(stamp)

    def finish(self) -> Pairing:
        """Pair the frames left; `Disorder` when a joint appeared after frames were paired without it."""
        capture = self._capture is not None and self._capture.is_capture(self._log.count)
        self._pair(self._pending, exact=capture)
        self._pending = []
        names = self._pairing_names()
        bad_joints = Counter({n: self._bad_joints[n] for n in self._names if self._bad_joints[n]})
        return Pairing(self._frames, capture, names, self._log.count, self._bad, bad_joints)

    def _pairing_names(self) -> list[str]:
        """Every joint with a finite message, in order of first appearance; `Disorder` when that is not the list
        the frames were paired with so far (a joint first published after frames were paired)."""
        names = [n for n in self._names if n in self._finite]
        if self._names_used is not None and self._names_used != names:
            raise Disorder("a joint was first published after frames were paired")
        return names

    def _check_order(self, stamp: int) -> None:
        if self.disorder_ns is not None and self._top is not None and stamp < self._top - self.disorder_ns:
            raise Disorder(f"a message stamped {(self._top - stamp) / 1e9:.3f} s before one read earlier")

    def _advance(self, stamp: int) -> None:
        """Pair the frames that became final, drop the joint states no frame to come can use."""
        if self._top is not None and stamp <= self._top:
            return
        self._top = stamp
        if self.disorder_ns is None:
            return
        if self._paired_at is not None and stamp - self._paired_at < BATCH_NS:
            return
        self._paired_at = stamp
        horizon = stamp - self.disorder_ns  # no message to come is stamped before this
        if self._capture is not None:
            if self._capture.holds(horizon):
                return  # may be a capture file: keep everything until `finish`
            self._capture = None
        ready = [p for p in self._pending if p[1] + STILL_WINDOW_NS < horizon]
        if ready:
            self._pending = [p for p in self._pending if p[1] + STILL_WINDOW_NS >= horizon]
            self._pair(ready, exact=False)
        oldest = min([horizon, *(p[1] for p in self._pending)])
        self._log.drop_before(oldest - STILL_WINDOW_NS)

    def _pair(self, frames: list[tuple[str, int, object, bool]], exact: bool) -> None:
        """`pair_frame` of each frame on the window's states (all the joints seen so far, finite messages only)."""
        if not frames:
            return
        groups = self._log.groups()
        keep = [np.isfinite(qs).all(axis=1) for _, _, qs, _ in groups]
        window = JointStates.from_log(self._log, keep)
        names = self._pairing_names()
        self._names_used = names
        none = JointSeries(np.empty(0, np.int64), np.empty(0), np.empty(0))
        states = JointStates(names, {n: window.series.get(n, none) for n in names})
        bad = np.concatenate([g[1][~k] for g, k in zip(groups, keep)]) if groups else np.empty(0, np.int64)
        stamps = np.array([stamp for _, stamp, _, _ in frames], dtype=np.int64)
        bad_stamps = np.isin(stamps, bad)
        used = [pair and not bad_stamp for (_, _, _, pair), bad_stamp in zip(frames, bad_stamps)]
        if exact:  # a capture file: every frame at once
            paired = iter(pair_exact(states, stamps[used]))
            results = [next(paired) if use else None for use in used]
        else:
            results = [pair_frame(states, int(stamp)) if use else None for stamp, use in zip(stamps, used)]
        for (camera, stamp, item, _), result, bad_stamp in zip(frames, results, bad_stamps):
            self._frames.append(PairedFrame(camera, stamp, item, result, bool(bad_stamp)))


class _CaptureTest:
    """Whether the stamps read fit a capture file: one joint state per image stamp, i.e. every image's stamp is a joint
    state's and every joint state's an image's. A stamp is checked once it is final (no message to come is stamped
    before it), so only the last `DISORDER_NS` of stamps wait."""

    def __init__(self) -> None:
        self.stamps: tuple[set[int], set[int]] = (set(), set())  # (joint states', images') [ns]
        self.waiting: tuple[list[int], list[int]] = ([], [])

    def add(self, stamp: int, joint: bool) -> None:
        self.stamps[not joint].add(stamp)
        self.waiting[not joint].append(stamp)

    def holds(self, horizon: float) -> bool:
        """Whether each stamp before `horizon` [ns] has its counterpart (an image's a joint state's and back)."""
        for kind in (0, 1):
            others, waiting = self.stamps[1 - kind], self.waiting[kind]
            if any(s < horizon and s not in others for s in waiting):
                return False
            waiting[:] = [s for s in waiting if s >= horizon]
        return True

    def is_capture(self, joint_messages: int) -> bool:
        """At the end of the file: every stamp has its counterpart, one joint-state message per image stamp."""
        return self.holds(float("inf")) and joint_messages == len(self.stamps[1])
