"""The `compare` part: the study's comparison table on one simulated Wolfgang session with every measurement
system (`wolfcal compare`).

One truth (0.025 rad rms encoder offsets on the legs and head, the simulator's camera-mount error); per system a
capture to fit on and a held-out one: head camera (16 + 10 samples, 1024x768 binned images) plus 20 held-out floor
samples (floor tags 0.5-5 m away), external tripod camera (20 + 10 samples), motion capture (25 + 12 still poses,
0.3 mm noise, 3 % occluded, 1 % reflections, mounts off 1 mm). Fits: head camera `--free camera`, head camera
`--free leg`, external camera `--free leg`, motion capture `--free leg`. Prints the table (mean ± std per column in
its unit; ground: error ± 1-sigma) and the decision per seed, then each calibration's ratio to "before" per column
over the seeds.
Per seed the table and the decision; per calibration and column the ratio to before over the seeds.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from wolfcal.cli import app

WOLFGANG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
FITS = {"head_camera": ["head_fit.mcap", "--free", "camera"],
        "head_leg": ["head_fit.mcap", "--free", "leg"],
        "external_leg": ["external_fit.mcap", "--system", "external", "--free", "leg"],
        "mocap_leg": ["mocap_fit.mcap", "--system", "mocap", "--free", "leg"]}  # fmt: skip
HELD_OUT = ["head_test.mcap", "floor_test.mcap", "external_test.mcap", "mocap_test.mcap"]


def session(d: Path, seed: int) -> None:
    """Simulate the captures and fit each calibration of the module docstring into folder d."""
    robot = ["--robot", str(WOLFGANG)]
    truth = ["--truth", str(d / "head_fit.truth.yaml")]
    s = 10 * seed
    steps = [
        ["simulate", "--out", str(d / "head_fit.mcap"), "--samples", "16", "--binning", "2", "--seed", str(s + 1),
         "--offsets", "all"],
        ["simulate", "--out", str(d / "head_test.mcap"), "--samples", "10", "--binning", "2", "--seed", str(s + 2),
         *truth],
        ["simulate", "--out", str(d / "floor_test.mcap"), "--samples", "20", "--binning", "2", "--seed", str(s + 3),
         "--floor", *truth],
        ["simulate", "--out", str(d / "external_fit.mcap"), "--system", "external", "--samples", "20", "--seed",
         str(s + 4), *truth],
        ["simulate", "--out", str(d / "external_test.mcap"), "--system", "external", "--samples", "10", "--seed",
         str(s + 5), *truth],
        ["simulate", "--out", str(d / "mocap_fit.mcap"), "--system", "mocap", "--samples", "25", "--seed",
         str(s + 6), *truth],
        ["simulate", "--out", str(d / "mocap_test.mcap"), "--system", "mocap", "--samples", "12", "--seed",
         str(s + 7), *truth],
        *[["fit", str(d / args[0]), *args[1:], "--out", str(d / name)] for name, args in FITS.items()],
    ]  # fmt: skip
    for step in steps:
        t = time.perf_counter()
        result = CliRunner().invoke(app, [*step, *robot])
        if result.exit_code != 0:
            raise SystemExit(f"{' '.join(step)}:\n{result.output}")
        print(
            f"  {step[0]} {Path(step[2] if step[0] == 'simulate' else step[-1]).name}: {time.perf_counter() - t:.0f} s",
            flush=True,
        )


def compare(d: Path) -> dict:
    result = CliRunner().invoke(app, ["compare", *(str(d / name) for name in FITS),
                                      *(a for f in HELD_OUT for a in ("--capture", str(d / f))),
                                      "--out", str(d / "report"), "--force"])  # fmt: skip
    if result.exit_code != 0:
        raise SystemExit(result.output)
    return json.loads((d / "report" / "metrics.json").read_text())


def compare_systems(seeds: int, say) -> dict:
    """Per seed the table (calibration -> column -> mean and std in the column's unit) and the decision's message;
    per calibration and column the ratio to "before" (mean and max over the seeds)."""
    ratios: dict[str, dict[str, list[float]]] = {}
    tables, columns = [], []
    for seed in range(seeds):
        with tempfile.TemporaryDirectory() as tmp:
            session(Path(tmp), seed)
            metrics = compare(Path(tmp))
        columns = [{"key": c["key"], "title": c["title"], "unit": c["unit"]} for c in metrics["columns"]]
        before = metrics["table"]["before (input URDF)"]
        for label, row in metrics["table"].items():
            for c in columns:
                cell = row[c["key"]]
                if label != "before (input URDF)" and cell["mean"] is not None and before[c["key"]]["mean"]:
                    ratios.setdefault(label, {}).setdefault(c["key"], []).append(
                        cell["mean"] / before[c["key"]]["mean"]
                    )
        tables.append({"seed": seed, "table": metrics["table"], "decision": metrics["decision"]["message"]})
        say(f"compare seed {seed}: {metrics['decision']['message']}")
    return {
        "seeds": seeds,
        "columns": columns,
        "tables": tables,
        "ratio_to_before": {
            label: {k: {"mean": float(np.mean(v)), "max": float(np.max(v))} for k, v in by_column.items()}
            for label, by_column in ratios.items()
        },
    }
