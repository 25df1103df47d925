"""The bench harness: run the measurements, write their figures as JSON (`bench/report.py` makes the docs'
tables).

    python bench/run.py [--parts fit,stream,detection,intrinsics,seeds] [--out bench/results.json]
                        [--before PATH] [--rounds 3] [--frames 600,6000] [--stream-binning 4]

Parts: `fit` (the 24-sample 2048x1536 camera fit: first run and cached run against reading + decoding +
OpenCV's bare detector on all cores), `stream` (peak memory of `wolfcal fit` on plain recordings of 600 and
6000 frames), `detection` (corner accuracy on rendered views), `intrinsics` (`wolfcal intrinsics` against
plain OpenCV), `seeds` (simulated fits against the truth over seeds). `--before PATH`: a folder holding an
older `wolfcal` package; `fit` and `stream` then run on both, alternating which goes first. Results of the
parts run are merged into the JSON file (other parts' results are kept). Generated inputs are kept in the temp
folder (`common.DATA`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's wolfcal for generating inputs

from common import ROOT, start_spawner  # noqa: E402
from quality import detection, intrinsics, seeds  # noqa: E402
from targets import fit_speed, stream_memory, targets  # noqa: E402

PARTS = ("fit", "stream", "detection", "intrinsics", "seeds")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--parts", default=",".join(PARTS), help="comma-separated, of " + ", ".join(PARTS))
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results.json")
    parser.add_argument("--before", type=Path, default=None, help="a folder holding an older wolfcal package")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of the fit part (each tree once a round)")
    parser.add_argument("--stream-rounds", type=int, default=1)
    parser.add_argument("--frames", default="600,6000", help="recording lengths of the stream part")
    parser.add_argument("--stream-binning", type=int, default=4, help="1: 2048x1536 frames; 4: 512x384")
    parser.add_argument("--views", type=int, default=20, help="rendered views per camera of the detection part")
    parser.add_argument("--seeds", type=int, default=3, help="seeds of the intrinsics and seeds parts")
    parser.add_argument("--binning", type=int, default=4, help="image binning of the seeds part")
    args = parser.parse_args()
    start_spawner()  # before anything large is loaded: see `common.start_spawner`
    parts = [p for p in args.parts.split(",") if p]
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        parser.error(f"unknown part(s) {', '.join(unknown)}; choose from {', '.join(PARTS)}")
    trees = {"after": ROOT}
    if args.before is not None:
        if not (args.before / "wolfcal" / "__init__.py").is_file():
            parser.error(f"--before {args.before}: holds no wolfcal package")
        trees = {"before": args.before.resolve(), "after": ROOT}

    def say(line: str) -> None:
        print(line, flush=True)

    results = json.loads(args.out.read_text()) if args.out.is_file() else {}
    for part in parts:
        start = time.perf_counter()
        if part == "fit":
            results["fit"] = fit_speed(trees, args.rounds, say)
        elif part == "stream":
            frames = [int(n) for n in args.frames.split(",")]
            results["stream"] = stream_memory(trees, frames, args.stream_binning, args.stream_rounds, say)
        elif part == "detection":
            results["detection"] = detection(args.views, say)
        elif part == "intrinsics":
            results["intrinsics"] = intrinsics(args.seeds, say)
        else:
            results["seeds"] = seeds(args.seeds, args.binning, say)
        results[part]["seconds"] = time.perf_counter() - start
        results[part]["taken"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        results[part]["load_average"] = os.getloadavg()[0]
    results["targets"] = targets(results)
    results["machine"] = {
        "cores": len(os.sched_getaffinity(0)),
        "python": platform.python_version(),
        "processor": platform.processor() or platform.machine(),
    }
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    say(f"wrote {args.out}")


if __name__ == "__main__":
    main()
