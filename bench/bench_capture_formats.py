"""The same captures written two ways (e.g. deflated and stored pngs), side by side: first-run `wolfcal fit` processes
in alternated pairs, the reader's costs, and the capture writer's cost per sample.

Run: python bench/bench_capture_formats.py OLD_DIR NEW_DIR [--pairs 4] [--names sim_400_b4_all_s400.mcap ...].
OLD_DIR and NEW_DIR hold captures of the same names, e.g. `bench_table.py`'s cache folder before and after a change
of the capture format (`bench_table.py --captures NEW_DIR` makes them). Prints, per capture name:
1. first run (fresh detection cache) of a whole `wolfcal fit` process on each, alternated, `--pairs` times: wall and
   CPU [s] (children's user + system), with the load average;
2. CPU [s] of reading the capture (`read_capture`), streaming its images (`encoded_images`) and hashing the file for
   the detection cache (`hash_file`), best of 3;
and the capture writer (`CaptureWriter.add_sample`: encode, write, fsync) on 12 images of the 2048x1536 capture of
NEW_DIR, with images encoded as wolfcal does now and as deflated pngs (level 1, as before): wall and CPU [ms] per
sample, file size per sample [MB].
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

import wolfcal.io.writer as writer_module
from wolfcal.camera.camera_info import load_camera_info
from wolfcal.config import load_robot_config
from wolfcal.io.reader import read_capture
from wolfcal.io.samples import encoded_images
from wolfcal.observations import HEAD_CAMERA
from wolfcal.vision.cache import hash_file

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
FREE = {"sim_24_b1_none_s1.mcap": ["--free", "camera"]}  # else a leg fit
NAMES = ["sim_24_b1_none_s1.mcap", "sim_400_b4_all_s400.mcap", "sim_1000_b4_all_s1000.mcap"]


def fit_process(path: Path) -> tuple[float, float]:
    """(wall, CPU) [s] of a first-run `wolfcal fit` process on `path`."""
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        command = [sys.executable, "-c", "from wolfcal.cli import app; app()", "fit", str(path), "--robot",
                   str(CONFIG), *FREE.get(path.name, ["--free", "leg"]), "--out", out, "--force"]  # fmt: skip
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True, env={**os.environ, "WOLFCAL_CACHE_DIR": cache})
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def reading(path: Path) -> tuple[float, float, float]:
    """Best-of-3 CPU [s]: read_capture, streaming the images, hashing the file."""
    config = load_robot_config(CONFIG)
    best = np.full(3, np.inf)
    for _ in range(3):
        start = time.process_time()
        capture = read_capture(path, config)
        read = time.process_time()
        sum(len(data) for data in encoded_images(s.images[HEAD_CAMERA] for s in capture.samples))
        stream = time.process_time()
        hash_file(path)
        best = np.minimum(best, [read - start, stream - read, time.process_time() - stream])
    return best[0], best[1], best[2]


def writing(path: Path) -> None:
    """The capture writer per sample with wolfcal's encoding and with deflated pngs."""
    config = load_robot_config(CONFIG)
    camera = load_camera_info(config.camera.intrinsics)
    samples = read_capture(path, config).samples[:12]
    images = [cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
              for data in encoded_images(s.images[HEAD_CAMERA] for s in samples)]  # fmt: skip
    now = writer_module.encode_image

    def deflated(image: np.ndarray, image_format: str) -> tuple[bytes, str]:
        return cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])[1].tobytes(), "mono8; png compressed mono8"

    print(f"\ncapture writer, {len(images)} samples of {path.name} (encode, write, fsync per sample)")
    try:
        for _ in range(2):
            for label, encode in (("deflated png (before)", deflated), ("wolfcal's png (now)", now)):
                writer_module.encode_image = encode  # type: ignore[assignment]
                with tempfile.TemporaryDirectory() as folder:
                    out = Path(folder) / "capture.mcap"
                    wall, cpu = time.perf_counter(), time.process_time()
                    with writer_module.CaptureWriter(out, config, {HEAD_CAMERA: (camera, (1, 1))}) as writer:
                        for sample, image in zip(samples, images):
                            writer.add_sample(sample.stamp_ns, sample.joint_names, sample.positions, None,
                                              {HEAD_CAMERA: image})  # fmt: skip
                    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
                    size = out.stat().st_size / len(images) / 1e6
                print(f"  {label:22s} {1e3 * wall / len(images):6.1f} ms wall {1e3 * cpu / len(images):6.1f} ms CPU "
                      f"{size:.2f} MB per sample")  # fmt: skip
    finally:
        writer_module.encode_image = now


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path)
    parser.add_argument("new", type=Path)
    parser.add_argument("--pairs", type=int, default=4)
    parser.add_argument("--names", nargs="+", default=NAMES)
    args = parser.parse_args()
    for name in args.names:
        folders = {"old": args.old, "new": args.new}
        runs: dict[str, list[tuple[float, float]]] = {"old": [], "new": []}
        loads = []
        for k in range(args.pairs):
            for label in ("old", "new") if k % 2 == 0 else ("new", "old"):
                runs[label].append(fit_process(folders[label] / name))
            loads.append(os.getloadavg()[0])
        print(f"\n{name}: first-run `wolfcal fit` processes, {args.pairs} alternated pairs, load average "
              f"{min(loads):.1f}-{max(loads):.1f}")  # fmt: skip
        for label, folder in folders.items():
            wall = [w for w, _ in runs[label]]
            cpu = [c for _, c in runs[label]]
            read, stream, hashed = reading(folder / name)
            print(f"  {label} ({folder}, {(folder / name).stat().st_size / 1e6:.0f} MB): wall "
                  f"{' '.join(f'{w:.2f}' for w in wall)} s (median {np.median(wall):.2f}), CPU "
                  f"{' '.join(f'{c:.2f}' for c in cpu)} s (median {np.median(cpu):.2f}); reading {read:.3f} s, "
                  f"streaming the images {stream:.3f} s, hashing {hashed:.3f} s CPU")  # fmt: skip
    writing(args.new / "sim_24_b1_none_s1.mcap")


if __name__ == "__main__":
    main()
