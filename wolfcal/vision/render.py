"""Anti-aliased rendering of planar textured targets (tags, checkerboards, ChArUco boards) through a
distorted camera.

Frames and units: `T_camera_target` maps points of the target frame into the camera's optical frame
(z forward, x right, y down) [m]. The texture lies in the target's z = 0 plane, centred on the target origin:
texture columns run along +x, texture row 0 is at +y (the top of the printed image), so an aruco/AprilTag
texture maps onto the aruco tag frame (x right, y up, z out of the printed face). Pixels follow OpenCV: the
centre of the top-left pixel is (0, 0).

A pixel is the mean of `supersample` x `supersample` sub-pixel points, each shaded with the nearest texel of
the nearest target its ray hits. Textures are crisp cells, so the mean approximates the pixel's area
coverage (a box filter): an edge lands where the geometry puts it, with no half-pixel shift. Rays come from
`CameraModel.unproject` (distortion included): exact on a grid every 8 px, cubic interpolation to the pixel
corners (< 1e-5 px error), bilinear interpolation inside a pixel (< 3e-4 px error at the corners of a
strongly distorted 2048x1536 image). Only pixels whose corners see different grey values (or targets), and
their 8 neighbours (for a corner of a region poking into a pixel), are supersampled; the others lie inside
one uniform region and take its value. So texture features must be at least ~1 px wide in the image to be
rendered (anything readable is).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.geometry import transform_points

_OUTLINE_SAMPLES = 64  # points per target edge when bounding its (curved) image
_CHUNK = 1 << 19  # rays shaded at once (bounds memory for targets that fill the image)


@dataclass(frozen=True)
class PlanarTarget:
    """A flat target: `texture` (h, w) uint8 spans `width_m` x `height_m` [m], centred on its origin."""

    T_camera_target: np.ndarray  # (4, 4)
    texture: np.ndarray  # (h, w) uint8; row 0 at +y, column 0 at -x
    width_m: float
    height_m: float


def _outline(target: PlanarTarget) -> np.ndarray:
    """(4 * _OUTLINE_SAMPLES, 3) points on the target's border, target frame [m]."""
    hw, hh = target.width_m / 2, target.height_m / 2
    t = np.linspace(0.0, 1.0, _OUTLINE_SAMPLES, endpoint=False)
    corners = np.array([[-hw, hh], [hw, hh], [hw, -hh], [-hw, -hh], [-hw, hh]])
    pts = np.concatenate([a + t[:, None] * (b - a) for a, b in zip(corners[:-1], corners[1:], strict=True)])
    return np.column_stack([pts, np.zeros(len(pts))])


def _pixel_box(camera: CameraModel, target: PlanarTarget) -> tuple[int, int, int, int] | None:
    """Pixel box [u0, u1) x [v0, v1) holding the target's image, clipped to the image; None if not visible."""
    p = transform_points(np.asarray(target.T_camera_target, float), _outline(target))
    in_front = p[:, 2] > 1e-6
    if not in_front.any():
        return None
    size = np.array([camera.width, camera.height], float)
    uv = camera.project(p) if in_front.all() else np.full((1, 2), np.nan)
    if np.isfinite(uv).all():  # clipped before the cast: a border point far off-axis can lie at 1e30 px
        u0, v0 = np.clip(np.floor(uv.min(axis=0)) - 1, 0, size).astype(int)
        u1, v1 = np.clip(np.ceil(uv.max(axis=0)) + 2, 0, size).astype(int)
    else:  # the plane crosses the camera plane, or the lens model overflows: test every pixel
        u0, v0, u1, v1 = 0, 0, camera.width, camera.height
    if u0 >= u1 or v0 >= v1:
        return None
    return int(u0), int(u1), int(v0), int(v1)


def _shade(target: PlanarTarget, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays (..., 3) with z = 1 -> depth z [m] of the hit (inf where the target is missed), texel value."""
    T = np.asarray(target.T_camera_target, float)
    R, t = T[:3, :3], T[:3, 3]
    normal = R[:, 2]
    denom = rays @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(np.abs(denom) > 1e-12, (normal @ t) / denom, -1.0)
    local = depth[..., None] * (rays @ R) - t @ R  # R^T (p - t): points in the target frame
    h, w = target.texture.shape
    col = np.floor((local[..., 0] / target.width_m + 0.5) * w)
    row = np.floor((0.5 - local[..., 1] / target.height_m) * h)
    hit = (depth > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    texel = np.where(hit, row * w + col, 0).astype(np.int64)
    return np.where(hit, depth, np.inf), target.texture.ravel()[texel].astype(float)


def _nearest(targets: list[PlanarTarget], rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays (..., 3) -> (key of what is seen: target index * 2^16 + grey value, -1 for nothing; grey value)."""
    depth = np.full(rays.shape[:-1], np.inf)
    key = np.full(rays.shape[:-1], -1, dtype=np.int64)
    value = np.zeros(rays.shape[:-1])
    for i, target in enumerate(targets):
        d, val = _shade(target, rays)
        nearer = d < depth
        depth[nearer], value[nearer] = d[nearer], val[nearer]
        key[nearer] = (i << 16) + np.rint(val[nearer]).astype(np.int64)
    return key, value


def _cubic_weights(x: np.ndarray, step: float) -> np.ndarray:
    """(len(x), nodes) 4-point Lagrange weights of increasing positions x on nodes x[0] - step + k * step."""
    s = (x - x[0]) / step + 1.0
    i = np.floor(s).astype(int)
    t = s - i
    W = np.zeros((len(x), i.max() + 3))
    rows = np.arange(len(x))
    W[rows, i - 1] = -t * (t - 1) * (t - 2) / 6
    W[rows, i] = (t + 1) * (t - 1) * (t - 2) / 2
    W[rows, i + 1] = -(t + 1) * t * (t - 2) / 2
    W[rows, i + 2] = (t + 1) * t * (t - 1) / 6
    return W


def _unproject_grid(camera: CameraModel, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rays (len(v), len(u), 3), z = 1, through the regular pixel grid u x v.

    Exact unprojection on a grid 8 times coarser, cubic interpolation in between: the undistortion is smooth, the
    error is < 1e-5 px even at the corners of a strongly distorted 2048x1536 image, at a small share of the cost.
    """
    step = 8.0
    Wu, Wv = _cubic_weights(u, step), _cubic_weights(v, step)
    nodes_u = u[0] + step * (np.arange(Wu.shape[1]) - 1)
    nodes_v = v[0] + step * (np.arange(Wv.shape[1]) - 1)
    coarse = camera.unproject(np.stack(np.meshgrid(nodes_u, nodes_v), axis=-1))
    xy = [Wv @ coarse[..., c] @ Wu.T for c in range(2)]
    return np.stack([*xy, np.ones_like(xy[0])], axis=-1)


def _render_box(
    camera: CameraModel,
    targets: list[PlanarTarget],
    background: np.ndarray,
    image: np.ndarray,
    box: tuple[int, int, int, int],
    n: int,
) -> None:
    """Shade the pixels of `box` (u0, u1, v0, v1) of `image` in place, over `background`, with n x n
    sub-points in the pixels whose corners see different grey values (and their neighbours)."""
    u0, u1, v0, v1 = box
    corner_rays = _unproject_grid(camera, np.arange(u0, u1 + 1) - 0.5, np.arange(v0, v1 + 1) - 0.5)
    key, value = _nearest(targets, corner_rays)
    same = (key[:-1, :-1] == key[1:, :-1]) & (key[:-1, :-1] == key[:-1, 1:]) & (key[:-1, :-1] == key[1:, 1:])
    mixed = cv2.dilate((~same).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    region, behind = image[v0:v1, u0:u1], background[v0:v1, u0:u1]
    region[~mixed] = np.where(key[:-1, :-1] >= 0, value[:-1, :-1], behind)[~mixed]
    f = (np.arange(n) + 0.5) / n  # sub-point positions inside a pixel, from its top-left corner
    fy, fx = f[:, None, None], f[None, :, None]
    mixed_v, mixed_u = np.nonzero(mixed)
    step = max(1, _CHUNK // (n * n))
    for start in range(0, len(mixed_v), step):
        rv, ru = mixed_v[start : start + step], mixed_u[start : start + step]
        c00, c01 = corner_rays[rv, ru][:, None, None], corner_rays[rv, ru + 1][:, None, None]
        c10, c11 = corner_rays[rv + 1, ru][:, None, None], corner_rays[rv + 1, ru + 1][:, None, None]
        rays = (1 - fy) * ((1 - fx) * c00 + fx * c01) + fy * ((1 - fx) * c10 + fx * c11)  # (P, n, n, 3)
        sub_key, sub_value = _nearest(targets, rays)
        sub_value = np.where(sub_key >= 0, sub_value, behind[rv, ru][:, None, None])
        region[rv, ru] = sub_value.mean(axis=(1, 2))


def _boxes_overlap(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]


def _background(camera: CameraModel, level: float, rng: np.random.Generator) -> np.ndarray:
    """(H, W) float image: `level` plus a faint low-frequency pattern (4 random waves of 2-5 grey each)."""
    step = 16  # the pattern is smooth: evaluate it on a coarse grid and upsample
    v, u = np.mgrid[0 : camera.height // step + 2, 0 : camera.width // step + 2].astype(float) * step
    coarse = np.full(u.shape, float(level))
    scale = max(camera.width, camera.height)
    for _ in range(4):
        kx, ky = rng.uniform(-3.0, 3.0, 2) * 2 * np.pi / scale
        coarse += rng.uniform(2.0, 5.0) * np.sin(kx * u + ky * v + rng.uniform(0, 2 * np.pi))
    size = (coarse.shape[1] * step, coarse.shape[0] * step)
    fine = cv2.resize(coarse, size, interpolation=cv2.INTER_LINEAR)
    return fine[: camera.height, : camera.width].copy()


def render_targets(
    camera: CameraModel,
    targets: Sequence[PlanarTarget],
    background: float | np.ndarray = 128,
    supersample: int = 4,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Gray uint8 (H, W) image of `targets` seen by `camera`; the nearest target wins where they overlap.

    `background` is a grey level (a faint low-frequency pattern is added) or a full (H, W) image used as is.
    `noise_sigma` [grey levels] adds Gaussian noise before rounding. `rng` draws the background pattern and
    the noise (default: a fresh unseeded generator).
    """
    rng = np.random.default_rng() if rng is None else rng
    if np.ndim(background) == 0:
        behind = _background(camera, float(background), rng)
    else:
        behind = np.asarray(background, dtype=float)
        if behind.shape != (camera.height, camera.width):
            raise ValueError(f"background shape {behind.shape} != image {(camera.height, camera.width)}")
    image = behind.copy()
    visible = [(tg, box) for tg in targets if (box := _pixel_box(camera, tg)) is not None]
    for _, box in visible:
        overlapping = [tg for tg, other in visible if _boxes_overlap(box, other)]  # nearest target wins
        _render_box(camera, overlapping, behind, image, box, int(supersample))
    if noise_sigma > 0:
        image += noise_sigma * rng.standard_normal(image.shape, dtype=np.float32)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def motion_blur(image: np.ndarray, length_px: float, angle_rad: float) -> np.ndarray:
    """Blur `image` along a line of `length_px` [px] at `angle_rad` (0 = along +u, positive towards +v)."""
    length = max(float(length_px), 1.0)
    size = int(np.ceil(length)) | 1
    kernel = np.zeros((size, size), np.float32)
    c = size // 2
    d = np.array([np.cos(angle_rad), np.sin(angle_rad)])
    steps = np.linspace(-length / 2, length / 2, 4 * size)
    pts = np.rint(c + steps[:, None] * d).astype(int).clip(0, size - 1)
    np.add.at(kernel, (pts[:, 1], pts[:, 0]), 1.0)
    kernel /= kernel.sum()
    return cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REPLICATE)
