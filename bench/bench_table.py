"""Issue 13's table in one run: wolfcal side by side with the bare detector and a naive reference solver.

Run: python bench/bench_table.py [--views 30] [--parts camera,leg,large,accuracy] [--captures DIR]. Simulated
captures are cached in the temp folder, or DIR (the first run renders them: about 1-2 minutes; after a change of
how captures are written, give a fresh DIR to compare); each fit gets a fresh detection cache folder.
Prints, with units:
1. End to end (`run_fit` in this process: read, detect, solve, uncertainty, write) on 2048x1536 captures, camera
   fit of 24 samples and leg fit of 40: first run (no cache) wall and CPU, the median of FIRST_RUNS runs each with
   a fresh cache folder (and the very first of them, which also pays the process's first-call costs); the floor
   (reading the images, decoding them and OpenCV's bare aruco detector on all cores; the median of FIRST_RUNS, each
   run right after a first run, and the median of the pairs' ratios); the naive reference in CPU (the same
   detection's CPU + the naive solve's CPU, bench/naive_reference.py); the second run (cache), in this process (the
   median of SECOND_RUNS runs) and as a whole `wolfcal fit` process. The ratios are taken between medians: one run
   of 0.5-1 s varies by +-15 % on this machine even when it is idle, and its speed drifts by more between minutes.
2. The solve alone (`fit_observations` on the same detections) vs the naive solve, CPU.
3. Leg fits of 400 and 1000 samples at 512x384 (2048x1536 binned 4x4), end to end, first run: wall and CPU, in
   this process and as a `wolfcal fit` process (start-up and imports included), each the median of PROCESS_RUNS
   runs with a fresh cache, with the range; the solve alone; the load average (the machine may be shared).
4. Detection accuracy (median, 95th percentile corner error [px]) on bench/bench_vision.py's rendered views,
   next to the figures that bench printed before (README).
BLAS runs on one thread, as in the `wolfcal` command. Each capture is read once before its figures are taken, so
that every figure finds it in the page cache (as after a capture): a cold read from a slow disk (26 MB/s on the
machine the figures were taken on) would add seconds of waiting to whichever run came first.
"""

from __future__ import annotations

import os

for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ThreadPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_vision import BINNED, FULL, accuracy, render_views  # noqa: E402
from naive_reference import naive_solve, predicted  # noqa: E402

from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples, run_fit  # noqa: E402
from wolfcal.io.samples import encoded_images  # noqa: E402
from wolfcal.observations import HEAD_CAMERA  # noqa: E402
from wolfcal.projection import predict_corners  # noqa: E402
from wolfcal.robot.corrections import Corrections  # noqa: E402
from wolfcal.robot.robot import load_robot  # noqa: E402
from wolfcal.sim.simulate import SimOptions, simulate_capture  # noqa: E402
from wolfcal.vision.batch import cpu_count  # noqa: E402
from wolfcal.vision.cache import cache_enabled  # noqa: E402
from wolfcal.vision.observe import detect_observations  # noqa: E402

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
CACHE = Path(tempfile.gettempdir()) / "wolfcal_bench_table"
PARTS = ("camera", "leg", "large", "accuracy")
SECOND_RUNS = 3  # cached runs after the first, in process
FIRST_RUNS = 5  # no-cache runs in process (and floors) of the 2048x1536 captures
PROCESS_RUNS = 3  # no-cache runs of the large captures, in process and as a process
README_ACCURACY = {"2048x1536": (0.02, 0.13), "512x384": (0.04, 0.13)}  # median, p95 [px] before issue 13


def quiet(_: str) -> None:
    pass


def capture(folder: Path, samples: int, binning: int, offsets: str, seed: int) -> Path:
    """A simulated capture, made in `folder` when it is not there yet."""
    path = folder / f"sim_{samples}_b{binning}_{offsets}_s{seed}.mcap"
    if not path.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        simulate_capture(CONFIG, path, SimOptions(samples=samples, seed=seed, binning=binning, offsets=offsets),
                         say=quiet, force=True)  # fmt: skip
        print(f"  (simulated {path.name} in {time.perf_counter() - start:.0f} s)")
    return path


def timed(fn):
    wall, cpu = time.perf_counter(), time.process_time()
    result = fn()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def median_run(runs: list[tuple[float, float]], by: int = 1) -> tuple[float, float]:
    """The (wall, CPU) run with the median CPU time (by=1) or wall time (by=0)."""
    return sorted(runs, key=lambda run: run[by])[len(runs) // 2]


def spread(runs: list[tuple[float, float]], which: int) -> str:
    """'lo-hi' of the runs' wall (which=0) or CPU (which=1) times [s]."""
    values = [run[which] for run in runs]
    return f"{min(values):.2f}-{max(values):.2f}"


def fresh_fit_run(path: Path, options: FitOptions) -> tuple[float, float]:
    """(wall, CPU) [s] of a first run: `run_fit` with a fresh, empty detection cache folder."""
    with tempfile.TemporaryDirectory() as cache_dir:
        return fit_run(path, options, Path(cache_dir))


def fit_run(path: Path, options: FitOptions, cache_dir: Path) -> tuple[float, float]:
    """(wall, CPU) [s] of `run_fit` with the detection cache in `cache_dir`."""
    os.environ["WOLFCAL_CACHE_DIR"] = str(cache_dir)
    with tempfile.TemporaryDirectory() as out:
        _, wall, cpu = timed(lambda: run_fit([path], CONFIG, Path(out), options, say=quiet, force=True))
    return wall, cpu


def floor(path: Path) -> tuple[float, float]:
    """(wall, CPU) [s] of reading + decoding every image and OpenCV's bare aruco detector, on all cores."""
    robot = load_robot(CONFIG)
    samples, _ = load_samples(robot, [path], None)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)

    def detect(data: bytes) -> int:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
        ids = cv2.aruco.ArucoDetector(dictionary).detectMarkers(image)[1]
        return 0 if ids is None else len(ids)

    start, cpu = time.perf_counter(), time.process_time()
    with ThreadPoolExecutor(cpu_count()) as pool:
        list(pool.map(detect, encoded_images(s.images[HEAD_CAMERA] for s in samples)))
    return time.perf_counter() - start, time.process_time() - cpu


def process_run(path: Path, free: list[str], cache_dir: Path) -> tuple[float, float]:
    """(wall, CPU) [s] of a whole `wolfcal fit` process (start-up and imports included) with the cache in
    `cache_dir`."""
    with tempfile.TemporaryDirectory() as out:
        command = [sys.executable, "-c", "from wolfcal.cli import app; app()", "fit", str(path), "--robot",
                   str(CONFIG), *free, "--out", out, "--force"]  # fmt: skip
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        env = {**os.environ, "WOLFCAL_CACHE_DIR": str(cache_dir)}
        subprocess.run(command, check=True, capture_output=True, env=env)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def warm(path: Path) -> None:
    """Read the file once, so that the runs timed after find it in the page cache."""
    with path.open("rb") as file:
        while file.read(1 << 24):
            pass


def end_to_end(label: str, path: Path, options: FitOptions, free: list[str]) -> None:
    robot = load_robot(CONFIG)
    warm(path)
    firsts, floors = [], []
    for _ in range(FIRST_RUNS):  # in turn, so that the machine's drift (up to 1.6x here) falls on both alike
        firsts.append(fresh_fit_run(path, options))
        floors.append(floor(path))
    first_wall, first_cpu = median_run(firsts)
    pair_wall = np.median([f[0] / b[0] for f, b in zip(firsts, floors)])
    pair_cpu = np.median([f[1] / b[1] for f, b in zip(firsts, floors)])
    with tempfile.TemporaryDirectory() as cache_dir:
        fit_run(path, options, Path(cache_dir))
        seconds = sorted((fit_run(path, options, Path(cache_dir)) for _ in range(SECOND_RUNS)), key=lambda r: r[1])
        second_wall, second_cpu = seconds[len(seconds) // 2]  # the median in CPU: one run of 0.1-0.2 s is noisy
        process_wall, process_cpu = process_run(path, free, Path(cache_dir))
    bare, bare_cpu = median_run(floors)
    with cache_enabled(False):  # the detection's own cost, the naive reference uses the same detections
        samples, _ = load_samples(robot, [path], None)
        (observations, _), _, detect_cpu = timed(lambda: detect_observations(samples, robot))
    fit, solve_wall, solve_cpu = timed(lambda: fit_observations(robot, observations, options))
    obs = fit.observations[HEAD_CAMERA]
    check = np.nanmax(np.abs(predicted(robot, obs, Corrections()) - predict_corners(robot, obs, Corrections())))
    _, naive_wall, naive_cpu = timed(lambda: naive_solve(robot, obs, fit.chain, robot.config.priors.pixel_noise))
    naive_total = detect_cpu + naive_cpu
    print(f"\n{label}: {obs.n_samples} samples with tags, {len(obs.uv)} corners, {len(fit.chain)} unknowns "
          f"(naive model = wolfcal's to {check:.1e} px)")  # fmt: skip
    print(f"  first run      {first_wall:6.2f} s wall, {first_cpu:6.2f} s CPU (no cache; median of {FIRST_RUNS} runs, "
          f"{spread(firsts, 1)} s CPU, {spread(firsts, 0)} s wall; the process's first {firsts[0][1]:.2f} s CPU, "
          f"{firsts[0][0]:.2f} s wall)")
    print(f"  floor          {bare:6.2f} s wall, {bare_cpu:6.2f} s CPU (read + decode + bare aruco, {cpu_count()} "
          f"threads; median of {FIRST_RUNS}, {spread(floors, 1)} s CPU) -> first run {first_wall / bare:.2f}x the "
          f"floor in wall (target <= 1.3), {first_cpu / bare_cpu:.2f}x in CPU; median of the {FIRST_RUNS} pairs' "
          f"ratios {pair_wall:.2f}x wall, {pair_cpu:.2f}x CPU")
    print(f"  naive reference {naive_total:6.2f} s CPU (detection {detect_cpu:.2f} + naive solve {naive_cpu:.2f}) "
          f"-> wolfcal {naive_total / first_cpu:.1f}x faster in CPU (target >= 3)")
    print(f"  second run     {second_wall:6.2f} s wall, {second_cpu:6.2f} s CPU (cache; median of {SECOND_RUNS} runs, "
          f"{seconds[0][1]:.2f}-{seconds[-1][1]:.2f} s CPU) -> {naive_total / second_cpu:.1f}x faster than the naive "
          f"reference in CPU (target >= 20)")
    print(f"  solve alone    {solve_wall:6.2f} s wall, {solve_cpu:6.2f} s CPU; naive solve {naive_wall:.2f} s wall, "
          f"{naive_cpu:.2f} s CPU -> {naive_cpu / solve_cpu:.1f}x (target >= 10)")
    print(f"  second run as a `wolfcal fit` process (start-up and imports included) {process_wall:.2f} s wall, "
          f"{process_cpu:.2f} s CPU -> {naive_total / process_cpu:.1f}x")


def large_leg_fit(path: Path, limit: float) -> None:
    options = FitOptions(free="leg", side="both")
    robot = load_robot(CONFIG)
    warm(path)
    load = os.getloadavg()[0]
    runs = [fresh_fit_run(path, options) for _ in range(PROCESS_RUNS)]
    wall, cpu = median_run(runs, by=0)  # the target is wall time
    with cache_enabled(False):
        samples_read, _ = load_samples(robot, [path], None)
        observations, _ = detect_observations(samples_read, robot)
    _, solve_wall, solve_cpu = timed(lambda: fit_observations(robot, observations, options))
    processes = []
    for _ in range(PROCESS_RUNS):
        with tempfile.TemporaryDirectory() as cache_dir:
            processes.append(process_run(path, ["--free", "leg"], Path(cache_dir)))
    process_wall, process_cpu = median_run(processes, by=0)
    print(f"  {len(samples_read):4d} samples: {wall:.2f} s wall ({cpu:.2f} s CPU) in this process, "
          f"{process_wall:.2f} s wall ({process_cpu:.2f} s CPU) as a `wolfcal fit` process (target < {limit:g} s "
          f"wall; medians of {PROCESS_RUNS} first runs, {spread(runs, 0)} s and {spread(processes, 0)} s wall); the "
          f"solve alone {solve_wall:.2f} s wall ({solve_cpu:.2f} s CPU); load average {load:.1f} -> "
          f"{os.getloadavg()[0]:.1f}")


def detection_accuracy(views: int) -> None:
    print(f"\ndetection accuracy, {views} rendered views per camera, corner error [px] (before: README)")
    for camera, label in ((FULL, "2048x1536"), (BINNED, "512x384")):
        err, rate, _ = accuracy(render_views(camera, views, seed=11), "edges")
        median, p95 = README_ACCURACY[label]
        print(f"  {label:10s} median {np.median(err):.4f} (before {median:.2f})  p95 {np.percentile(err, 95):.4f} "
              f"(before {p95:.2f})  detected {100 * rate:.0f}%")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=30)
    parser.add_argument("--parts", default=",".join(PARTS), help=f"comma-separated subset of {', '.join(PARTS)}")
    parser.add_argument("--captures", type=Path, default=CACHE,
                        help="folder of the simulated captures (made there when missing)")
    args = parser.parse_args()
    folder = args.captures
    parts = args.parts.split(",")
    print(f"issue 13 table, {cpu_count()} cores, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if "camera" in parts:
        camera_capture = capture(folder, 24, 1, "none", seed=1)
        end_to_end("camera fit, 24 samples at 2048x1536", camera_capture, FitOptions(free="camera"),
                   ["--free", "camera"])
    if "leg" in parts:
        leg_capture = capture(folder, 40, 1, "all", seed=2)
        end_to_end("leg fit, 40 samples at 2048x1536", leg_capture, FitOptions(free="leg", side="both"),
                   ["--free", "leg", "--side", "both"])
    if "large" in parts:
        print("\nleg fit at 512x384, end to end, first run (no cache)")
        large_leg_fit(capture(folder, 400, 4, "all", seed=400), 2.0)
        large_leg_fit(capture(folder, 1000, 4, "all", seed=1000), 5.0)
    if "accuracy" in parts:
        detection_accuracy(args.views)
    print(f"load average at the end {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
