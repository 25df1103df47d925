"""Tag rendering speed and corner accuracy of `detect_tags` on rendered images (truth: projected tag corners).

Run: python bench/bench_vision.py [--views N]. Prints render times, then for each camera (2048x1536 with
strong barrel distortion, and the same lens binned 4x4 to 512x384) and each corner refinement the corner
error |detected - camera.project(T_camera_tag @ corner)| [px, Euclidean per corner]: median, 95th
percentile, max, and the share of tags detected. Views: tag36h11 of 0.08 m at 0.3-1.2 m, tilted up to 50
deg, anywhere in the image, noise sigma 2 grey levels, rendered at the default 4x4 supersampling; also with
a Gaussian blur of sigma 1 px (a soft lens), and rendered at 16x16 (less aliasing in the truth: this is the
detector's own error). Finally the rendering-convention check: a large frontal tag at 16x16 supersampling,
no noise, where the mean signed corner error must be ~0 (a half-pixel convention error would show as 0.5
px).
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.geometry import exp_so3, make_transform, tag_corners, transform_points
from wolfcal.vision.render import PlanarTarget, render_targets
from wolfcal.vision.tags import REFINEMENTS, detect_tags, tag_texture, tag_texture_width

FAMILY, SIZE = "tag36h11", 0.08
FULL = CameraModel(
    2048,
    1536,
    np.array([[1336.2, 0, 1015.8], [0, 1334.4, 727.0], [0, 0, 1]]),
    np.array([-0.28595, 0.081479, -0.000093, -0.00032, 0.0]),
)
BINNED = FULL.scaled(0.25, 0.25, 512, 384)


def random_view(camera: CameraModel, rng: np.random.Generator, tilt_deg: float = 50.0) -> np.ndarray:
    """T_camera_tag: tag at 0.3-1.2 m facing the camera, tilted up to `tilt_deg`, fully inside the image."""
    tex = tag_texture(FAMILY, 0)
    width = tag_texture_width(FAMILY, SIZE, tex)
    while True:
        uv = rng.uniform([0, 0], [camera.width - 1, camera.height - 1])
        ray = camera.unproject(uv)
        ray /= np.linalg.norm(ray)
        z = -ray  # tag normal towards the camera
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])  # x right, y up (optical y is down), z towards the camera
        R = R @ exp_so3(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))
        axis = rng.normal(size=2)
        axis = np.array([*axis / np.linalg.norm(axis), 0.0])
        R = R @ exp_so3(axis * np.deg2rad(rng.uniform(0, tilt_deg)))
        T = make_transform(R, ray * rng.uniform(0.3, 1.2) / ray[2])
        outline = transform_points(T, tag_corners(width))
        if camera.in_image(camera.project(outline), margin=2).all():
            return T


def render_views(
    camera: CameraModel, n: int, seed: int, supersample: int = 4
) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """n images of one random tag each -> (tag id, image, true corners (4, 2))."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        tag_id = int(rng.integers(0, 30))
        tex = tag_texture(FAMILY, tag_id)
        width = tag_texture_width(FAMILY, SIZE, tex)
        T = random_view(camera, rng)
        target = PlanarTarget(T, tex, width, width)
        image = render_targets(camera, [target], supersample=supersample, noise_sigma=2.0, rng=rng)
        out.append((tag_id, image, camera.project(transform_points(T, tag_corners(SIZE)))))
    return out


def accuracy(views: list, refine: str, blur: float = 0.0) -> tuple[np.ndarray, float, float]:
    """Corner errors [px] over `views` (optionally Gaussian-blurred by `blur` px), detection rate, s/image."""
    errors, found = [], 0
    t0 = time.perf_counter()
    for tag_id, image, truth in views:
        if blur > 0:
            image = cv2.GaussianBlur(image, (0, 0), blur)
        det = detect_tags(image, FAMILY, refine=refine)
        if tag_id in det:
            found += 1
            errors.append(np.linalg.norm(det[tag_id] - truth, axis=1))
    dt = (time.perf_counter() - t0) / len(views)
    return np.concatenate(errors) if errors else np.array([np.nan]), found / len(views), dt


def bench_render() -> None:
    rng = np.random.default_rng(1)
    tex = tag_texture(FAMILY, 3)
    for label, depth in (("2 tags ~300 px", 0.36), ("2 tags ~100 px", 1.1)):
        width = tag_texture_width(FAMILY, SIZE, tex)
        targets = [
            PlanarTarget(make_transform(np.diag([1.0, -1.0, -1.0]), [x, 0.05, depth]), tex, width, width)
            for x in (-0.2 * depth, 0.25 * depth)
        ]
        render_targets(FULL, targets, noise_sigma=2.0, rng=rng)  # warm-up
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            render_targets(FULL, targets, noise_sigma=2.0, rng=rng)
            times.append(time.perf_counter() - t0)
        print(f"render 2048x1536, {label}, supersample 4: median {1e3 * np.median(times):.0f} ms")


def bench_convention() -> None:
    tex = tag_texture(FAMILY, 7)
    width = tag_texture_width(FAMILY, SIZE, tex)
    for camera, label in ((FULL, "2048x1536"), (BINNED, "512x384")):
        biases = []
        for x, y in ((0.0, 0.0), (0.013, -0.021), (-0.031, 0.007)):
            T = make_transform(np.diag([1.0, -1.0, -1.0]), [x, y, 0.35 if camera is FULL else 0.2])
            target = PlanarTarget(T, tex, width, width)
            image = render_targets(camera, [target], background=128.0, supersample=16)
            det = detect_tags(image, FAMILY)[7]
            biases.append(det - camera.project(transform_points(T, tag_corners(SIZE))))
        b = np.concatenate(biases)
        print(
            f"convention check {label}: mean signed error u {b[:, 0].mean():+.4f} "
            f"v {b[:, 1].mean():+.4f} px, max |error| {np.abs(b).max():.4f} px"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=60)
    args = parser.parse_args()
    bench_render()
    bench_convention()
    for camera, label in ((FULL, "2048x1536"), (BINNED, "512x384 (binned)")):
        views = render_views(camera, args.views, seed=11)
        fine = render_views(camera, args.views, seed=11, supersample=16)  # the same views, less aliasing
        print(f"\n{label}: {args.views} views, corner error [px]")
        rows = [(refine, 0.0, views) for refine in REFINEMENTS] + [("edges", 1.0, views), ("subpix", 1.0, views)]
        rows += [("edges", 0.0, fine), ("subpix", 0.0, fine)]
        for refine, blur, images in rows:
            subset = images[:25] if refine == "apriltag" else images  # ~1 s per full-resolution image
            err, rate, dt = accuracy(subset, refine, blur)
            name = refine + (f" + blur {blur:g} px" if blur else "") + (" supersample 16" if images is fine else "")
            if len(subset) < len(views):
                name += f" ({len(subset)} views)"
            print(
                f"  {name:28s} median {np.median(err):.3f}  p95 {np.percentile(err, 95):.3f}  "
                f"max {np.max(err):.3f}  detected {100 * rate:.0f}%  {1e3 * dt:.1f} ms/image"
            )


if __name__ == "__main__":
    main()
