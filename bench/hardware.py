"""The hardware parts: the servo bus and a scripted capture, both against the Protocol 2.0 bus emulator on a pty
(the real dynamixel-sdk on the host side)."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from common import CONFIG


def bus(reads: int, say) -> dict:
    """Sync reads (position + velocity) of the Wolfgang's servos: reads per second, per-read median, 99th
    percentile and max [ms]. A real bus at 1 Mbaud is bounded by its USB latency timer (set it to 1 ms)."""
    from wolfcal.config import load_robot_config
    from wolfcal.hardware.bus import DynamixelBus
    from wolfcal.hardware.emulator import EmulatorProcess, spec_from_config

    config = load_robot_config(CONFIG)
    with EmulatorProcess(spec_from_config(config)) as emulator, DynamixelBus(config.servos, emulator.port) as servos:
        servos.ping_all()
        durations = []
        for _ in range(reads):
            start = time.perf_counter()
            servos.read_state()
            durations.append(time.perf_counter() - start)
        n_servos = len(servos.ids)
    d = np.array(durations) * 1e3  # [ms]
    out = {
        "servos": n_servos,
        "reads": reads,
        "rate_hz": float(1e3 / d.mean()),
        "median_ms": float(np.median(d)),
        "p99_ms": float(np.percentile(d, 99)),
        "max_ms": float(d.max()),
    }
    say(f"bus: {n_servos} servos, {out['rate_hz']:.0f} reads/s, median {out['median_ms']:.2f} ms")
    return out


def capture(velocity: float, settle: float, say) -> dict:
    """A scripted capture of the config's poses (poses.yaml) against the emulator and the simulated camera (binning
    4): samples, wall time [s], and the time from the robot at rest to the sample on disk (fsynced) [s]."""
    from rich.console import Console

    from wolfcal.capture.gating import GateSettings
    from wolfcal.capture.pipeline import CaptureOptions, run_capture
    from wolfcal.config import load_robot_config
    from wolfcal.hardware.emulator import EmulatorProcess, spec_from_config

    config = load_robot_config(CONFIG)
    with tempfile.TemporaryDirectory() as folder, EmulatorProcess(spec_from_config(config)) as emulator:
        options = CaptureOptions(
            robot=CONFIG,
            out=Path(folder) / "bench.mcap",
            camera="sim",
            port=emulator.port,
            poses=CONFIG / "poses.yaml",
            velocity=velocity,
            gates=GateSettings(settle_s=settle),
        )
        start = time.perf_counter()
        summary = run_capture(options, Console(quiet=True))
        wall = time.perf_counter() - start
    rest = np.array(summary.rest_to_sample_s)
    out = {
        "samples": summary.samples,
        "velocity_rad_s": velocity,
        "settle_s": settle,
        "wall": wall,
        "rest_to_sample_median_s": float(np.median(rest)),
        "rest_to_sample_max_s": float(rest.max()),
    }
    say(f"capture: {summary.samples} samples in {wall:.1f} s, rest -> sample median {np.median(rest):.2f} s")
    return out
