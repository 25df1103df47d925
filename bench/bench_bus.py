"""Sync-read rate of the Wolfgang's 20 servos through the real dynamixel-sdk against the bus emulator on a
pty.

Run: `python bench/bench_bus.py [--reads N]`. Prints reads per second (position + velocity of all servos per
read). A real bus at 1 Mbaud is bounded by its USB latency timer (set it to 1 ms), not by this code.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from wolfcal.config import load_robot_config
from wolfcal.hardware.bus import DynamixelBus
from wolfcal.hardware.emulator import EmulatorProcess, spec_from_config

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--reads", type=int, default=2000)
    args = parser.parse_args()
    config = load_robot_config(ROBOT)
    with EmulatorProcess(spec_from_config(config)) as emu, DynamixelBus(config.servos, emu.port) as bus:
        bus.ping_all()
        durations = []
        for _ in range(args.reads):
            start = time.perf_counter()
            bus.read_state()
            durations.append(time.perf_counter() - start)
    d = np.array(durations) * 1e3
    print(
        f"sync read of {len(bus.ids)} servos (position + velocity), {args.reads} reads: "
        f"{1e3 / d.mean():.0f} Hz; per read median {np.median(d):.2f} ms, p99 {np.percentile(d, 99):.2f} ms, "
        f"max {d.max():.2f} ms"
    )


if __name__ == "__main__":
    main()
