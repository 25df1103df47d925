"""Detection and intrinsics speed, side by side with their references, in one run on this machine.

Run: python bench/bench_detection.py [--views N] [--quick] [--before REV]. Prints:
1. per-image tag detection [ms] at 512x384 and 2048x1536 (one tag of 0.08 m at 0.3-1.2 m, noise sigma 2, as in
   bench/bench_vision.py): OpenCV's bare detector, wolfcal before (the per-edge refinement loop, kept in
   tests/edge_reference.py) and after (vectorised), and the corner error [px] median / 95th percentile of both;
   then the CPU per image, one thread, split into decoding the png, OpenCV's detector and the refinement (in tasks
   of `task_size` images, as the workers run it); with --before REV (a git revision) also the refinement of
   wolfcal/vision/edges.py at REV on the same tags, and the largest difference of its corners [px]; with
   --capture FILE (only this part) the same split on a capture's own images, beside the fit's detection of them
   on all cores (and with --before the refinement at REV on them);
2. a capture's worth of png images (stored, as wolfcal's captures hold them) decoded and detected on all cores:
   serial, threads, worker processes (wolfcal.vision.batch), against the floor: decoding plus OpenCV's bare marker
   detector on all cores;
3. the detection cache: first run (hash + detect + write) and second run (hash + read), and the cost of
   hashing a 100 MB file;
4. `wolfcal intrinsics` against a plain OpenCV script (bench/opencv_intrinsics.py) as whole processes: 50
   rendered 1920x1080 boards (wall and CPU time, RMS, focal length against the truth) and OpenCV's real sample
   photographs of two cameras (tests/data/opencv_samples: RMS and focal length, with OpenCV's published values);
5. import times of the command line and of the fit path (python -X importtime).
Times are medians of a few repetitions; on a shared machine quote the ratios.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
import types
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "bench"), str(ROOT / "tests")]

from bench_intrinsics import BOARD, rendered  # noqa: E402
from bench_vision import BINNED, FULL, render_views  # noqa: E402
from edge_reference import _refine_edges as refine_before  # noqa: E402
from opencv_intrinsics import calibrate as plain_calibrate  # noqa: E402

from wolfcal.intrinsics.pipeline import IntrinsicsOptions, run_intrinsics  # noqa: E402
from wolfcal.io.images import encode_image  # noqa: E402
from wolfcal.vision import cache, tags  # noqa: E402
from wolfcal.vision.batch import _refined, cpu_count, detect_encoded, task_size  # noqa: E402
from wolfcal.vision.tags import PendingTags, _detector, _found, _to_gray, detect_tags, tag_cells  # noqa: E402

FAMILY = "tag36h11"


def median_time(function, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def interleaved(functions: dict, repeat: int = 5, clock=time.perf_counter) -> dict[str, float]:
    """Median seconds (of `clock`) of each function, run in turn (A B C A B C ...) so a shared machine's drift hits
    all."""
    times: dict[str, list[float]] = {name: [] for name in functions}
    for _ in range(repeat):
        for name, function in functions.items():
            start = clock()
            function()
            times[name].append(clock() - start)
    return {name: float(np.median(t)) for name, t in times.items()}


def detect_before(image: np.ndarray) -> dict[int, np.ndarray]:
    """detect_tags as it was: aruco + the per-edge refinement loop."""
    gray = _to_gray(image)
    corners, ids, _ = _detector(FAMILY, "edges").detectMarkers(gray)
    img = gray.astype(np.float32)
    out = {}
    for tag_id, c in zip(np.asarray(ids).ravel() if ids is not None else [], corners):
        out[int(tag_id)] = refine_before(img, np.asarray(c, float).reshape(4, 2), tag_cells(FAMILY))
    return out


def per_image(views_by_camera: dict) -> None:
    print("\n1. per-image detection, one process [ms/image]; corner error [px] median / p95")
    for label, views in views_by_camera.items():
        _per_image_row(label, views)


def _per_image_row(label: str, views: list) -> None:
    images = [image for _, image, _ in views]
    t = interleaved({
        "bare": lambda: [detect_tags(im, FAMILY, refine="none") for im in images],
        "before": lambda: [detect_before(im) for im in images],
        "after": lambda: [detect_tags(im, FAMILY) for im in images],
    })  # fmt: skip
    bare, before, after = (t[k] / len(images) for k in ("bare", "before", "after"))
    errors = {}
    for name, detect in (("before", detect_before), ("after", lambda im: detect_tags(im, FAMILY))):
        e = [np.linalg.norm(detect(im)[tag] - truth, axis=1) for tag, im, truth in views if tag in detect(im)]
        errors[name] = np.concatenate(e)
    print(f"  {label:10s} bare detector {1e3 * bare:6.1f}   before {1e3 * before:6.1f}   after {1e3 * after:6.1f}"
          f"   (before/after {before / after:.1f}x; refinement {1e3 * (before - bare):.1f} -> "
          f"{1e3 * (after - bare):.1f})")  # fmt: skip
    for name, e in errors.items():
        print(f"  {'':10s} {name:6s} corner error median {np.median(e):.4f}  p95 {np.percentile(e, 95):.4f}")


def edges_at(revision: str) -> types.ModuleType:
    """wolfcal/vision/edges.py as it was at git `revision`, as a module of its own."""
    source = subprocess.run(["git", "-C", str(ROOT), "show", f"{revision}:wolfcal/vision/edges.py"],
                            capture_output=True, text=True, check=True).stdout  # fmt: skip
    module = types.ModuleType(f"edges_at_{revision}")
    sys.modules[module.__name__] = module  # dataclasses look their module up
    exec(compile(source, f"{revision}:wolfcal/vision/edges.py", "exec"), module.__dict__)
    return module


def _refine_passes(grays: list, found: list, edges: types.ModuleType | None = None, family: str = FAMILY) -> list:
    """The refinement as a fit runs it, of OpenCV's tags of `family` `found` in `grays` (each tag's crop, then
    consecutive images' tags in passes: `wolfcal.vision.batch._refined`), with `edges`' refine_tags if given."""
    now = tags.refine_tags
    if edges is not None:
        tags.refine_tags = edges.refine_tags
    try:
        cells = tag_cells(family)
        pending = [PendingTags({family: f}, {family: [tags._tags_crop(g, c[None], cells) for c in f.values()]})
                   for g, f in zip(grays, found)]  # fmt: skip
        return list(_refined(pending))
    finally:
        tags.refine_tags = now


def cpu_split(views_by_camera: dict, before: str | None, repeat: int) -> None:
    """Per-image CPU [ms], one thread: decode, OpenCV's detector, refinement (now and at git `before`)."""
    print("\n1b. CPU per image, one thread [ms CPU/image]: decode (png -> gray) + OpenCV detector + refinement")
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    old = edges_at(before) if before else None
    try:
        for label, views in views_by_camera.items():
            data = [encode_image(im, "png")[0] for _, im, _ in views]  # as captures store them
            grays = [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_GRAYSCALE) for d in data]
            found = [_found(g, FAMILY, None, "edges") for g in grays]
            size = task_size(data[0], processes=False)
            functions = {
                "decode": lambda: [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_GRAYSCALE) for d in data],  # noqa: B023
                "detector": lambda: [_found(g, FAMILY, None, "edges") for g in grays],  # noqa: B023
                "refinement": lambda: _refine_passes(grays, found),  # noqa: B023
            }
            if old is not None:
                functions["refinement before"] = lambda: _refine_passes(grays, found, old)  # noqa: B023
            t = {k: 1e3 * v / len(data) for k, v in interleaved(functions, repeat, time.process_time).items()}
            n_tags = sum(len(f) for f in found) / len(data)
            total = t["decode"] + t["detector"] + t["refinement"]
            line = (f"  {label:10s} ({n_tags:.1f} tags/image, {size} per task) decode {t['decode']:5.2f} + detector "
                    f"{t['detector']:5.2f} + refinement {t['refinement']:5.2f} = {total:5.2f}")  # fmt: skip
            if old is not None:
                before_total = total - t["refinement"] + t["refinement before"]
                now, then = _refine_passes(grays, found), _refine_passes(grays, found, old)
                diff = max(np.abs(a[k] - b[k]).max() for a, b in zip(now, then) for k in a)
                line += (f"; refinement at {before} {t['refinement before']:5.2f} (total {before_total:5.2f}, "
                         f"{before_total / total:.2f}x; refinement {t['refinement before'] / t['refinement']:.2f}x; "
                         f"corners differ by at most {diff:.1e} px)")  # fmt: skip
            print(line)
    finally:
        cv2.setNumThreads(threads)


def capture_split(path: Path, robot_dir: Path, repeat: int, before: str | None = None) -> None:
    """Per-image CPU [ms] on a capture's own images: one thread, decode + OpenCV's detector (wolfcal's settings and
    the bare default) + refinement, beside the fit's detection as it runs (`detect_encoded`, threads on all
    cores, tasks of `task_size`): what the scheduling adds is the difference. With `before` (a git revision) also
    the refinement of wolfcal/vision/edges.py at that revision on the same tasks, and the largest difference of
    its corners [px]."""
    from wolfcal.fit.pipeline import load_samples
    from wolfcal.io.samples import encoded_images
    from wolfcal.observations import HEAD_CAMERA
    from wolfcal.robot.robot import load_robot

    robot = load_robot(robot_dir)
    samples, _ = load_samples(robot, [path], None)
    data = list(encoded_images(s.images[HEAD_CAMERA] for s in samples if HEAD_CAMERA in s.images))
    families: dict[str, set[int]] = {}
    floor_tags = robot.config.floor.tags if robot.config.floor is not None else ()
    for tag in [*robot.config.tags, *floor_tags]:
        families.setdefault(tag.family, set()).add(tag.id)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        grays = [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_GRAYSCALE) for d in data]
        found = {f: [_found(g, f, ids, "edges") for g in grays] for f, ids in families.items()}
        size = task_size(data[0], processes=False)
        bare = {f: cv2.aruco.ArucoDetector(tags._dictionary(f)) for f in families}
        functions = {
            "decode": lambda: [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_GRAYSCALE) for d in data],
            "detector": lambda: [_found(g, f, ids, "edges") for g in grays for f, ids in families.items()],
            "bare detector": lambda: [bare[f].detectMarkers(g) for g in grays for f in families],
            "refinement": lambda: [_refine_passes(grays, found[f], family=f) for f in families],
        }
        old = edges_at(before) if before else None
        if old is not None:
            functions["refinement before"] = lambda: [_refine_passes(grays, found[f], old, f) for f in families]

        def as_in_the_fit(workers: int) -> None:  # OpenCV's own threads as the fit leaves them
            cv2.setNumThreads(threads)
            detect_encoded(data, families, workers=workers)
            cv2.setNumThreads(1)

        functions["fit, 1 thread"] = lambda: as_in_the_fit(1)
        functions["fit"] = lambda: as_in_the_fit(cpu_count())
        t = {k: 1e3 * v / len(data) for k, v in interleaved(functions, repeat, time.process_time).items()}
    finally:
        cv2.setNumThreads(threads)
    n_tags = sum(len(x) for per in found.values() for x in per) / len(data)
    total = t["decode"] + t["detector"] + t["refinement"]
    height, width = grays[0].shape
    print(f"  {path.name}: {len(data)} images at {width}x{height}, {n_tags:.2f} tags/image, {size} per task: decode "
          f"{t['decode']:.2f} + detector {t['detector']:.2f} (bare default {t['bare detector']:.2f}) + refinement "
          f"{t['refinement']:.2f} = {total:.2f} ms CPU/image on one thread; the fit's detection on one thread "
          f"{t['fit, 1 thread']:.2f} ({t['fit, 1 thread'] / total:.2f}x), on {cpu_count()} threads {t['fit']:.2f} "
          f"({t['fit'] / total:.2f}x)")
    if old is not None:
        now, then = ([tag for f in families for tag in _refine_passes(grays, found[f], e, f)] for e in (None, old))
        diff = max((np.abs(a[k] - b[k]).max() for a, b in zip(now, then) for k in a), default=0.0)
        print(f"    refinement at {before} {t['refinement before']:.2f} ms CPU/image "
              f"({t['refinement before'] / t['refinement']:.2f}x now's); corners differ by at most {diff:.1e} px")


def _floor_one(data: bytes) -> None:
    gray = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    _detector(FAMILY, "none").detectMarkers(_to_gray(gray))


def all_cores(views_by_camera: dict, copies: int) -> dict[str, list[bytes]]:
    cores = cpu_count()
    print(f"\n2. decode + detect a capture's png images on all {cores} cores [ms/image]")
    encoded = {}
    for label, views in views_by_camera.items():
        data = [encode_image(im, "png")[0] for _, im, _ in views]  # as captures store them
        encoded[label] = (data * copies)[: max(len(data), 48)]
        _all_cores_row(label, encoded[label], cores)
    return encoded


def _all_cores_row(label: str, data: list[bytes], cores: int) -> None:
    n = len(data)
    start = time.perf_counter()
    detect_encoded(data, {FAMILY: None}, processes=True)
    first = (time.perf_counter() - start) / n
    with ThreadPoolExecutor(cores) as pool:
        t = interleaved({
            "floor threads": lambda: list(pool.map(_floor_one, data)),
            "floor serial": lambda: [_floor_one(d) for d in data],  # OpenCV's own threads
            "one thread": lambda: detect_encoded(data, {FAMILY: None}, workers=1),
            "threads": lambda: detect_encoded(data, {FAMILY: None}),
            "processes": lambda: detect_encoded(data, {FAMILY: None}, processes=True),
        }, repeat=3)  # fmt: skip
    t = {k: v / n for k, v in t.items()}
    floor = min(t["floor threads"], t["floor serial"])
    print(f"  {label:10s} {n} images: floor (decode + bare detector, all cores) {1e3 * floor:5.1f} | wolfcal: one "
          f"thread {1e3 * t['one thread']:5.1f}, threads (default) {1e3 * t['threads']:5.1f}, processes "
          f"{1e3 * t['processes']:5.1f} (first call, with pool start-up, {1e3 * first:5.1f})")  # fmt: skip
    print(f"  {'':10s} threads / floor {t['threads'] / floor:.2f}x, processes / floor {t['processes'] / floor:.2f}x, "
          f"one thread / floor in one thread {t['one thread'] / t['floor serial']:.2f}x")  # fmt: skip


def cached(encoded: dict[str, list[bytes]]) -> None:
    print("\n3. detection cache (one capture file, one camera)")
    with tempfile.TemporaryDirectory() as folder:
        os.environ["WOLFCAL_CACHE_DIR"] = str(Path(folder) / "cache")
        settings = cache.DetectorSettings.of({FAMILY: None})
        for label, data in encoded.items():
            path = Path(folder) / f"{label}.mcap"
            path.write_bytes(b"".join(data))
            stamps = list(range(len(data)))
            start = time.perf_counter()
            first = cache.cached_detect(path, "head", stamps, iter(data), settings)
            miss = time.perf_counter() - start
            hit = median_time(lambda: cache.cached_detect(path, "head", stamps, iter(()), settings))  # noqa: B023
            again = cache.cached_detect(path, "head", stamps, [], settings)
            same = all(a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
                       for a, b in zip(first, again))  # fmt: skip
            print(f"  {label:10s} {len(data)} images, {path.stat().st_size / 1e6:.0f} MB: first run {miss:.2f} s, "
                  f"second run {1e3 * hit:.0f} ms ({miss / hit:.0f}x faster; same detections: {same})")  # fmt: skip
        big = Path(folder) / "big.bin"
        big.write_bytes(os.urandom(100_000_000))
        seconds = median_time(lambda: cache.content_digest(big))
        print(f"  the content digest (XXH3-128) of a 100 MB file (in the page cache): {1e3 * seconds:.0f} ms")


def _run(command: list[str]) -> tuple[float, float, str]:
    """Wall and CPU seconds of a whole process, and its output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return wall, cpu, done.stdout


def intrinsics(repeat: int) -> None:
    print("\n4. `wolfcal intrinsics` vs a plain OpenCV script (bench/opencv_intrinsics.py, 11x11 window)")
    camera, _, paths = rendered(1920, 1080, 50, seed=2)
    folder = str(paths[0].parent)
    with tempfile.TemporaryDirectory() as out:
        ours = [sys.executable, "-m", "wolfcal.cli", "intrinsics", folder, "--board", "9x6", "--square", "0.025",
                "--out", f"{out}/camera_info.yaml"]  # fmt: skip
        plain = [sys.executable, str(ROOT / "bench" / "opencv_intrinsics.py"), folder]
        runs: dict[str, list] = {"wolfcal": [], "plain": []}
        for _ in range(repeat):  # alternate, so drift of a shared machine hits both alike
            runs["wolfcal"].append(_run(ours))
            runs["plain"].append(_run(plain))
        wall = {k: float(np.median([r[0] for r in v])) for k, v in runs.items()}
        cpu = {k: float(np.median([r[1] for r in v])) for k, v in runs.items()}
        fx_ours = float(re.search(r"fx = ([\d.]+)", runs["wolfcal"][-1][2]).group(1))
        rms_ours = float(re.search(r"RMS per point ([\d.]+)", runs["wolfcal"][-1][2]).group(1))
        fx_plain = float(re.search(r"fx ([\d.]+)", runs["plain"][-1][2]).group(1))
        rms_plain = float(re.search(r"RMS per point ([\d.]+)", runs["plain"][-1][2]).group(1))
    print(f"  50 rendered 1920x1080 boards (true fx {camera.fx:.2f}), whole process, median of {repeat}:")
    for name, rms, fx in (("wolfcal", rms_ours, fx_ours), ("plain", rms_plain, fx_plain)):
        print(f"    {name:8s} wall {wall[name]:.2f} s, CPU {cpu[name]:.2f} s, RMS {rms:.3f} px, fx {fx:.2f}")
    print(f"    wolfcal / plain: wall {wall['wolfcal'] / wall['plain']:.2f}x, CPU {cpu['wolfcal'] / cpu['plain']:.2f}x")
    photos = ROOT / "tests" / "data" / "opencv_samples"
    print("  real photographs (OpenCV's samples, 13 views of each camera, 640x480): per-point RMS [px], fx fy [px]")
    for name in ("left", "right"):
        files = sorted(photos.glob(f"{name}*.jpg"))
        with tempfile.TemporaryDirectory() as out:
            result = run_intrinsics([str(f) for f in files], BOARD, Path(out) / "c.yaml", IntrinsicsOptions(),
                                    say=lambda s: None)  # fmt: skip
        c = result.camera
        print(f"    {name:5s} wolfcal            RMS {result.rms_per_point:.3f}  fx {c.fx:.2f} "
              f"+- {result.std['fx']:.2f}  fy {c.fy:.2f} +- {result.std['fy']:.2f}")  # fmt: skip
        for win in (5, 11):
            p = plain_calibrate(files, 9, 6, 0.025, win)
            print(f"    {name:5s} plain {2 * win + 1}x{2 * win + 1} window  RMS {p['rms_per_point']:.3f}  "
                  f"fx {p['fx']:.2f}  fy {p['fy']:.2f}")  # fmt: skip
    print("    left  OpenCV's published (left_intrinsics.yml, fixed aspect ratio) RMS 0.393  fx = fy 535.92")


def import_times(repeat: int) -> None:
    print(f"\n5. import time [ms] (python -X importtime, cumulative, median of {repeat})")
    for module in ("wolfcal.cli", "wolfcal.fit.pipeline", "wolfcal.evaluate.pipeline", "wolfcal.intrinsics.pipeline"):
        values = []
        for _ in range(repeat):
            done = subprocess.run([sys.executable, "-X", "importtime", "-c", f"import {module}"],
                                  capture_output=True, text=True, check=True)  # fmt: skip
            line = [x for x in done.stderr.splitlines() if x.rstrip().endswith(f"| {module}")][-1]
            values.append(int(line.split("|")[1]) / 1e3)
        print(f"  {module:30s} {np.median(values):6.0f}")
    wall = float(np.median([_run([sys.executable, "-m", "wolfcal.cli", "--help"])[0] for _ in range(repeat)]))
    print(f"  `wolfcal --help` whole process: {1e3 * wall:.0f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=40, help="rendered views per camera")
    parser.add_argument("--quick", action="store_true", help="fewer views and repetitions")
    parser.add_argument("--before", help="git revision whose refinement (wolfcal/vision/edges.py) to time beside "
                        "(with --only-split or --capture)")
    parser.add_argument("--only-split", action="store_true", help="only part 1b (the CPU split)")
    parser.add_argument("--capture", type=Path, action="append", default=[],
                        help="only the CPU split on this capture's head-camera images (repeatable), beside the "
                             "fit's detection of them on all cores")  # fmt: skip
    parser.add_argument("--robot", type=Path, default=ROOT / "configs" / "wolfgang", help="robot config of --capture")
    args = parser.parse_args()
    views = 12 if args.quick else args.views
    repeat = 1 if args.quick else 3
    print(f"{cpu_count()} cores; OpenCV {cv2.__version__}; load average {os.getloadavg()[0]:.1f}")
    if args.capture:
        print("\n1c. CPU per image of captures [ms CPU/image]: one thread split, and the fit's detection on all cores")
        for path in args.capture:
            capture_split(path, args.robot, 3 if args.quick else 5, args.before)
        return
    by_camera = {"512x384": render_views(BINNED, views, seed=11), "2048x1536": render_views(FULL, views, seed=11)}
    if args.only_split:
        cpu_split(by_camera, args.before, 5 if args.quick else 9)
        return
    per_image(by_camera)
    cpu_split(by_camera, args.before, 5 if args.quick else 9)
    encoded = all_cores(by_camera, copies=max(1, 48 // views + 1))
    cached(encoded)
    intrinsics(repeat)
    import_times(repeat)


if __name__ == "__main__":
    main()
