"""`wolfcal intrinsics` against a plain OpenCV script (bench/opencv_intrinsics.py) on the same 50 images at
1920x1080, side by side in one run: each as a fresh process (start-up and imports included, as a user runs
them), alternating, 3 rounds; prints the median wall time of each and their ratio (target <= 1.2).

Run: python bench/bench_intrinsics_speed.py [--rounds 3]. The rendered images are cached in the temp folder
(bench/bench_intrinsics.py makes the same ones).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_intrinsics import rendered  # noqa: E402

HERE = Path(__file__).resolve().parent


def timed(command: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    _, _, paths = rendered(1920, 1080, 50, seed=2)
    folder = str(paths[0].parent)
    with tempfile.TemporaryDirectory() as out:
        wolfcal = [sys.executable, "-c", "from wolfcal.cli import app; app()", "intrinsics", folder, "--board", "9x6",
                   "--square", "0.025", "--out", str(Path(out) / "camera_info.yaml"), "--force"]  # fmt: skip
        plain = [sys.executable, str(HERE / "opencv_intrinsics.py"), folder, "--board", "9x6", "--square", "0.025"]
        times: dict[str, list[float]] = {"wolfcal intrinsics": [], "plain OpenCV script": []}
        for _ in range(args.rounds):
            times["plain OpenCV script"].append(timed(plain))
            times["wolfcal intrinsics"].append(timed(wolfcal))
    medians = {name: float(np.median(t)) for name, t in times.items()}
    for name, t in times.items():
        print(f"{name:22s} {medians[name]:.2f} s wall (median of {args.rounds}: {', '.join(f'{x:.2f}' for x in t)})")
    print(f"ratio wolfcal / plain OpenCV: {medians['wolfcal intrinsics'] / medians['plain OpenCV script']:.2f} "
          "(target <= 1.2)")  # fmt: skip


if __name__ == "__main__":
    main()
