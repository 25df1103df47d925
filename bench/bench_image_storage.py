"""How capture images are stored: size on disk, encode CPU (at capture time) and decode CPU (every fit), per image.

Run: python bench/bench_image_storage.py [--images 24]. Renders captures with the simulator (noise sigma 2, the
default, 0.7 and 0 gray levels; 512x384 and 2048x1536) into a temporary folder, and a photo-like image made from the
noise-free render: its tags on a smooth background (a low-pass random field and a gradient) with sensor noise of 0.7
gray levels, which deflate compresses more like a real camera image than the simulator's flat background. Each image
is encoded as png in several ways and decoded to 8-bit gray as the fit does (`cv2.imdecode`, one thread); every
variant is lossless (checked). Prints size [KB], encode and decode CPU [ms] per image (best of 3 passes) and the
raw size; "stored, unfiltered (now)" is `wolfcal.io.images.encode_image`, what captures hold.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from wolfcal.config import load_robot_config
from wolfcal.io.images import encode_image
from wolfcal.io.reader import read_capture
from wolfcal.io.samples import encoded_images
from wolfcal.observations import HEAD_CAMERA
from wolfcal.sim.simulate import SimOptions, simulate_capture

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
PNG_VARIANTS = {
    "deflate 1 (before)": [cv2.IMWRITE_PNG_COMPRESSION, 1],
    "deflate 1 unfiltered": [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE],
    "deflate 1 rle": [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE],
    "stored, filtered": [cv2.IMWRITE_PNG_COMPRESSION, 0],
}


def _png(params: list[int]) -> Callable[[np.ndarray], bytes]:
    return lambda image: cv2.imencode(".png", image, params)[1].tobytes()


VARIANTS: dict[str, Callable[[np.ndarray], bytes]] = {
    **{name: _png(params) for name, params in PNG_VARIANTS.items()},
    "stored, unfiltered (now)": lambda image: encode_image(image, "png")[0],  # what captures hold
}


def rendered(folder: Path, images: int, binning: int, noise: float) -> list[np.ndarray]:
    """Gray images of a simulated capture (leg fit poses, seed 3)."""
    path = folder / f"n{noise}_b{binning}.mcap"
    options = SimOptions(samples=images, seed=3, binning=binning, offsets="all", noise_sigma=noise)
    simulate_capture(CONFIG, path, options, say=lambda _: None, force=True)
    capture = read_capture(path, load_robot_config(CONFIG))
    encoded = encoded_images(s.images[HEAD_CAMERA] for s in capture.samples)
    return [cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE) for data in encoded]


def photo_like(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The tags of a noise-free render on a smooth textured background, with sensor noise 0.7 gray levels."""
    height, width = image.shape
    field = cv2.GaussianBlur(rng.normal(0.0, 1.0, (height, width)).astype(np.float32), (0, 0), width / 40)
    background = 110 + 60 * field / field.std() + 30 * np.linspace(-1, 1, width)[None, :]
    tags = np.abs(image.astype(float) - np.median(image)) > 3
    out = np.where(tags, image, background) + rng.normal(0.0, 0.7, image.shape)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def best_cpu(function, repeat: int = 3) -> float:
    best = np.inf
    for _ in range(repeat):
        start = time.process_time()
        function()
        best = min(best, time.process_time() - start)
    return best


def measure(label: str, images: list[np.ndarray]) -> None:
    height, width = images[0].shape
    print(f"\n{label}, {width}x{height}, {len(images)} images; raw pixels {height * width / 1e3:.0f} KB")
    for name, encode_one in VARIANTS.items():
        encoded = [np.frombuffer(encode_one(image), np.uint8) for image in images]
        for data, image in zip(encoded, images):
            assert np.array_equal(cv2.imdecode(data, cv2.IMREAD_GRAYSCALE), image), f"{name} is not lossless"
        encode = best_cpu(lambda e=encode_one: [e(image) for image in images]) / len(images)
        decode = best_cpu(lambda e=encoded: [cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) for data in e]) / len(images)
        size = np.mean([len(data) for data in encoded])
        print(f"  {name:26s} {size / 1e3:6.0f} KB  encode {1e3 * encode:6.2f} ms  decode {1e3 * decode:6.2f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=24, help="images per resolution and noise level")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as folder:
        for binning in (4, 1):
            count = args.images if binning == 4 else max(2, args.images // 4)
            for noise in (2.0, 0.7, 0.0):
                images = rendered(Path(folder), count, binning, noise)
                measure(f"simulated, noise {noise:g} gray levels", images)
                if noise == 0.0:
                    measure("photo-like (smooth background, noise 0.7)", [photo_like(im, rng) for im in images])


if __name__ == "__main__":
    main()
