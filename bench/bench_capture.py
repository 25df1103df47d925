"""Time per sample of a scripted capture: the 20 poses of configs/wolfgang/poses.yaml against the bus emulator and
the simulated camera (binning 4), from the moment the robot has come to rest to the sample on disk (fsynced).

Run: `python bench/bench_capture.py [--velocity RAD_S] [--settle S]`.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console

from wolfcal.capture.gating import GateSettings
from wolfcal.capture.pipeline import CaptureOptions, run_capture
from wolfcal.config import load_robot_config
from wolfcal.hardware.emulator import EmulatorProcess, spec_from_config

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--velocity", type=float, default=3.0, help="profile velocity of the moves [rad/s]")
    parser.add_argument("--settle", type=float, default=0.3, help="stillness window [s]")
    args = parser.parse_args()
    config = load_robot_config(ROBOT)
    with tempfile.TemporaryDirectory() as folder, EmulatorProcess(spec_from_config(config)) as emu:
        options = CaptureOptions(
            robot=ROBOT,
            out=Path(folder) / "bench.mcap",
            camera="sim",
            port=emu.port,
            poses=ROBOT / "poses.yaml",
            velocity=args.velocity,
            gates=GateSettings(settle_s=args.settle),
        )
        start = time.perf_counter()
        summary = run_capture(options, Console(quiet=True))
        total = time.perf_counter() - start
    rest = np.array(summary.rest_to_sample_s)
    print(
        f"{summary.samples} samples in {total:.1f} s (moves at {args.velocity} rad/s, settle {args.settle} s); "
        f"rest -> sample on disk: median {np.median(rest):.2f} s, max {rest.max():.2f} s"
    )


if __name__ == "__main__":
    main()
