"""The true joint angles [rad] the emulator shares with the simulated camera, which renders the robot as it really
is: a small memory-mapped file beside an info JSON (joint names, truth YAML path, emulator pid), both named after
the pty."""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError


def state_paths(port: str) -> tuple[Path, Path]:
    """(angles file, info JSON) where the emulator serving `port` publishes its true joint angles."""
    name = os.path.realpath(port).strip("/").replace("/", "-")
    folder = Path(tempfile.gettempdir()) / "wolfcal-emulator"
    return folder / f"{name}.bin", folder / f"{name}.json"


class TrueStatePublisher:
    """Writes the true joint angles to the memory-mapped file (seqlock: slot 0 counts writes, odd while writing)."""

    def __init__(self, port: str, joints: list[str], truth_path: str | None):
        self.bin_path, self.json_path = state_paths(port)
        self.bin_path.parent.mkdir(parents=True, exist_ok=True)
        self.joints = joints
        self.json_path.write_text(json.dumps({"joints": joints, "truth": truth_path, "pid": os.getpid()}))
        self.array = np.lib.format.open_memmap(self.bin_path, mode="w+", dtype=np.float64, shape=(len(joints) + 1,))

    def publish(self, angles: dict[str, float]) -> None:
        self.array[0] += 1
        self.array[1:] = [angles[j] for j in self.joints]
        self.array[0] += 1

    def close(self) -> None:
        """Remove both files."""
        for path in (self.bin_path, self.json_path):
            path.unlink(missing_ok=True)


def read_true_angles(port: str) -> tuple[dict[str, float], str | None]:
    """The true joint angles [rad] and truth YAML path published by the emulator serving `port`."""
    bin_path, json_path = state_paths(port)
    if not json_path.is_file():
        raise WolfcalError(
            f"{port}: no `wolfcal emulate` serves this port (no {json_path}); the 'sim' camera needs the emulator"
        )
    info = json.loads(json_path.read_text())
    try:
        os.kill(info["pid"], 0)
    except ProcessLookupError:
        raise WolfcalError(f"{port}: the emulator that served this port (pid {info['pid']}) has ended") from None
    array = np.load(bin_path, mmap_mode="r")
    for _ in range(100):
        seq = array[0]
        values = np.array(array[1:])
        if seq % 2 == 0 and array[0] == seq:
            break
        time.sleep(0.0005)
    return dict(zip(info["joints"], values.tolist(), strict=True)), info["truth"]


def truth_file_of(ports: Iterable[str]) -> str | None:
    """The truth YAML path of the first emulator serving one of `ports` that has one (None: none has)."""
    return next((path for path in (read_true_angles(port)[1] for port in ports) if path), None)
