"""Measurements that run in a child process on the source tree first on its PYTHONPATH (see
`common.run_child`).

python child.py fit CAPTURE ROBOT CACHE_DIR: `run_fit --free camera` in this process: once with a throw-away
cache (the process's first-call costs: imports, OpenCV's start), then a first run with the empty cache
CACHE_DIR and a second run that finds the detections there; prints their wall and CPU times [s] as JSON.
python child.py floor CAPTURE: reading every image of the capture with mcap's reader, decoding it to gray and
OpenCV's bare aruco detector (tag36h11) on all cores, once to warm up, then timed; prints wall and CPU [s].
Only entry points both an older and this tree have are used (`run_fit`, `FitOptions`).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path


def _timed(work) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    work()
    return time.perf_counter() - wall, time.process_time() - cpu


def fit(capture: Path, robot: Path, cache: Path) -> dict:
    from wolfcal.fit.pipeline import FitOptions, run_fit

    with tempfile.TemporaryDirectory() as scratch:

        def once(cache_dir: Path) -> tuple[float, float]:
            os.environ["WOLFCAL_CACHE_DIR"] = str(cache_dir)
            out = Path(scratch) / "out"
            return _timed(
                lambda: run_fit([capture], robot, out, FitOptions(free="camera"), say=lambda _: None, force=True)
            )

        once(Path(scratch) / "warm-up")
        first = once(cache)
        cached = once(cache)
    return {"first_wall": first[0], "first_cpu": first[1], "cached_wall": cached[0], "cached_cpu": cached[1]}


def floor(capture: Path) -> dict:
    import cv2
    import numpy as np
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)

    def detect(data: bytes) -> int:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
        ids = cv2.aruco.ArucoDetector(dictionary).detectMarkers(image)[1]
        return 0 if ids is None else len(ids)

    def run() -> None:
        with capture.open("rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            images = (
                bytes(m.data)
                for s, _, _, m in reader.iter_decoded_messages()
                if s is not None and s.name == "sensor_msgs/msg/CompressedImage"
            )
            with ThreadPoolExecutor(len(os.sched_getaffinity(0))) as pool:
                list(pool.map(detect, images))

    run()
    wall, cpu = _timed(run)
    return {"floor_wall": wall, "floor_cpu": cpu}


if __name__ == "__main__":
    kind, args = sys.argv[1], [Path(a) for a in sys.argv[2:]]
    print(json.dumps(fit(*args) if kind == "fit" else floor(*args)))
