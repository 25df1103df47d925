"""Peak memory of `wolfcal fit` on long plain ROS 2 recordings: 600 and 6000 frames at 2048x1536.

Run: python bench/bench_stream.py [--frames 600,6000] [--keep DIR]. Generates the recordings in a temporary
folder, then runs `wolfcal fit --free camera --no-cache` on each in a child process and prints its peak
resident memory (ru_maxrss of the child), wall and CPU time, the number of samples used and the load average
(the machine may be shared); then the targets: the largest peak under 500 MB and within 10 % of the smallest.

The recordings: the head camera at 10 Hz, joint states of all 20 joints at 100 Hz, no CameraInfo (the config's
intrinsics). The robot holds a pose for 2 s, then moves to the next in 1 s, cycling through 12 poses; about half of
the frames are still (kept). The poses are simulated without encoder offsets, which `--free camera` could not fit
(with offsets on every joint the fit left 6.5 px RMS and 255 tag views out). Rendering 6000 distinct 2048x1536
frames would take most of an hour here, so each pose is rendered once (`wolfcal simulate`, true geometry); each
still frame is that render plus its own image noise (sigma `NOISE_SIGMA` gray levels: a crop at a random offset of
one large noise field), encoded as jpeg (quality 95), as a camera gives; frames in motion (never kept) reuse the
render's jpeg. Frames that repeat one image exactly would leave the fit no scatter between the frames of a pose to
tell the pixel noise from (it then stays at its floor and the fit warns).
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
from mcap_ros2.writer import Writer as Ros2Writer

from wolfcal.config import load_robot_config
from wolfcal.io.msgdefs import COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS, stamp_dict
from wolfcal.io.reader import read_capture
from wolfcal.observations import HEAD_CAMERA
from wolfcal.sim.simulate import SimOptions, simulate_capture

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
POSES = 12
CAMERA_HZ, JOINT_HZ = 10, 100
HOLD_S, MOVE_S = 2.0, 1.0
T0 = 1_700_000_000_000_000_000  # [ns]
NOISE_SIGMA = 2.0  # [gray levels] per-frame image noise of the still frames
NOISE_MARGIN = 96  # [px] the noise field's margin: 9216 offsets of the per-frame crops (one per still frame)


def render_poses(folder: Path) -> tuple[list[str], np.ndarray, list[np.ndarray], list[bytes]]:
    """Joint names, measured readings (POSES, J) [rad], images and their jpeg bytes of POSES simulated still
    poses."""
    capture_path = folder / "poses.mcap"
    options = SimOptions(samples=POSES, seed=5)  # no encoder offsets: what `--free camera` can fit
    simulate_capture(CONFIG, capture_path, options, say=lambda _: None, force=True)
    capture = read_capture(capture_path, load_robot_config(CONFIG))
    names = capture.samples[0].joint_names
    q = np.stack([s.positions for s in capture.samples])
    images = [s.images[HEAD_CAMERA].decode() for s in capture.samples]
    return names, q, images, [jpeg(image) for image in images]


def jpeg(image: np.ndarray) -> bytes:
    return cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()


class FrameNoise:
    """Image noise of one frame: a crop of one large Gaussian field at an offset not used before."""

    def __init__(self, shape: tuple[int, ...], seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.shape = shape
        big = (shape[0] + NOISE_MARGIN, shape[1] + NOISE_MARGIN, *shape[2:])
        self.field = rng.normal(0.0, NOISE_SIGMA, big).astype(np.float32)
        self.offsets = iter(rng.permutation(NOISE_MARGIN * NOISE_MARGIN).tolist())

    def add(self, image: np.ndarray) -> np.ndarray:
        dy, dx = divmod(next(self.offsets), NOISE_MARGIN)
        noise = self.field[dy : dy + self.shape[0], dx : dx + self.shape[1]]
        return np.clip(image + noise, 0, 255).astype(np.uint8)


def joint_state_at(t: float, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Positions [rad], velocities [rad/s] at time t [s] and the pose whose image the camera sees."""
    period = HOLD_S + MOVE_S
    k, phase_t = divmod(t, period)
    a, b = int(k) % len(q), (int(k) + 1) % len(q)
    if phase_t < HOLD_S:
        return q[a], np.zeros(q.shape[1]), a
    s = (phase_t - HOLD_S) / MOVE_S
    blend = (1 - np.cos(np.pi * s)) / 2
    velocity = (q[b] - q[a]) * np.pi / (2 * MOVE_S) * np.sin(np.pi * s)
    return q[a] + blend * (q[b] - q[a]), velocity, a


def write_recording(
    path: Path, frames: int, names: list[str], q: np.ndarray, images: list[np.ndarray], jpegs: list[bytes]
) -> None:
    config = load_robot_config(CONFIG)
    noise = FrameNoise(images[0].shape)
    duration = frames / CAMERA_HZ
    with path.open("wb") as handle:
        writer = Ros2Writer(handle, compression=None)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        events = [(i / JOINT_HZ, 0, i) for i in range(int(duration * JOINT_HZ))]
        events += [(0.003 + i / CAMERA_HZ, 1, i) for i in range(frames)]
        for t, kind, _ in sorted(events):
            stamp = T0 + int(round(t * 1e9))
            header = {"stamp": stamp_dict(stamp), "frame_id": ""}
            position, velocity, pose = joint_state_at(t, q)
            if kind == 0:
                message = {"header": header, "name": names, "position": position.tolist(),
                           "velocity": velocity.tolist(), "effort": []}  # fmt: skip
                writer.write_message(config.joint_states_topic, schemas[JOINT_STATE], message, log_time=stamp)
            else:
                still = not np.any(velocity)
                data = jpeg(noise.add(images[pose])) if still else jpegs[pose]
                message = {"header": header, "format": "jpeg", "data": data}
                writer.write_message(config.camera.topic, schemas[COMPRESSED_IMAGE], message, log_time=stamp)
        writer.finish()


def run_fit(recording: Path, out: Path) -> tuple[float, float, float, str]:
    """(peak RSS of the child [MB], wall [s], CPU [s], its 'head camera: ...' line)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    before, cpu = usage.ru_maxrss, usage.ru_utime + usage.ru_stime
    start = time.perf_counter()
    command = [sys.executable, "-c", "from wolfcal.cli import app; app()", "fit", str(recording), "--robot",
               str(CONFIG), "--free", "camera", "--out", str(out), "--no-cache", "--force"]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"fit failed:\n{done.stdout}\n{done.stderr}")
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    if usage.ru_maxrss <= before:
        print("note: this child's peak is not above an earlier child's; run one size per process")
    line = next((x for x in done.stdout.splitlines() if x.startswith("head camera:")), "")
    return usage.ru_maxrss / 1024, wall, usage.ru_utime + usage.ru_stime - cpu, line


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", default="600,6000")
    parser.add_argument("--keep", type=Path, default=None, help="folder for the recordings (default: temporary)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temp:
        folder = args.keep or Path(temp)
        folder.mkdir(parents=True, exist_ok=True)
        names, q, images, jpegs = render_poses(folder)
        print(f"{POSES} poses rendered at 2048x1536, jpeg {np.mean([len(j) for j in jpegs]) / 1e6:.2f} MB each")
        peaks = []
        for frames in (int(f) for f in args.frames.split(",")):
            path = folder / f"recording_{frames}.mcap"
            if not path.exists():
                start = time.perf_counter()
                write_recording(path, frames, names, q, images, jpegs)
                print(f"wrote {path.name}: {path.stat().st_size / 1e9:.2f} GB in {time.perf_counter() - start:.0f} s")
            # one child per size: ru_maxrss of RUSAGE_CHILDREN is the largest child's so far
            measure = [sys.executable, __file__, "--measure", str(path)]
            load = os.getloadavg()[0]
            child = subprocess.run(measure, capture_output=True, text=True, check=True)
            peak, wall, cpu, line = child.stdout.split(";", 3)
            peaks.append(float(peak))
            print(f"{path.name}: peak RSS {float(peak):.0f} MB, {float(wall):.1f} s wall, {float(cpu):.1f} s CPU "
                  f"(load average {load:.1f} -> {os.getloadavg()[0]:.1f}); {line.strip()}")  # fmt: skip
        if len(peaks) > 1:
            print(f"largest peak {max(peaks):.0f} MB (target < 500 MB), {max(peaks) / min(peaks):.2f}x the smallest "
                  "(target <= 1.10)")  # fmt: skip


def measure(path: Path) -> None:
    """One size in its own process (ru_maxrss of RUSAGE_CHILDREN keeps the largest child's peak)."""
    with tempfile.TemporaryDirectory() as out:
        peak, wall, cpu, line = run_fit(path, Path(out))
    print(f"{peak};{wall};{cpu};{line}")


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--measure":
        measure(Path(sys.argv[2]))
    else:
        main()
