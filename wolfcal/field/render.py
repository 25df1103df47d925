"""Rendered views of a RoboCup field through a distorted camera, with the truth of which pixels show a line.

Every pixel's ray (from `CameraModel.unproject`, distortion included) is traced in the field frame: the carpet
(the plane z = 0 within the border strip: green turf with mowing stripes, grain and uneven light; white markings
centred on the model's lines), the hall floor beyond it, and the scene's boxes and ball, whichever the ray meets
first. Line edges are anti-aliased by the pixel's footprint on the ground; the scene's colour cast (a warm light
seen without white balance) scales every channel. Pixels follow OpenCV (centre of the
top-left pixel at (0, 0)).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.field.model import FieldDimensions, distance_to_lines, field_lines
from wolfcal.field.scene import BORDER_STRIP, Box, Scene

TURF = np.array([45.0, 135.0, 55.0])  # BGR
LINE = np.array([235.0, 238.0, 235.0])
HALL_FLOOR = np.array([95.0, 105.0, 120.0])
CEILING = np.array([200.0, 200.0, 205.0])


@dataclass(frozen=True)
class FieldView:
    """A rendered view: the image and, per pixel, whether it shows a line marking (truth for detection)."""

    image: np.ndarray  # (H, W, 3) uint8 BGR
    line_mask: np.ndarray  # (H, W) bool: the nearest surface is the carpet and at least half the pixel is line


def pixel_rays(camera: CameraModel) -> np.ndarray:
    """Every pixel's ray (H * W, 3) in the optical frame (z = 1), row-major: unprojected once per camera."""
    uv = np.stack(np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float)), axis=-1)
    return camera.unproject(uv.reshape(-1, 2))


def render_field_view(
    camera: CameraModel,
    T_field_camera: np.ndarray,
    dims: FieldDimensions,
    scene: Scene,
    rng: np.random.Generator,
    noise_sigma: float = 3.0,
    blur_px: float = 0.0,
    rays_camera: np.ndarray | None = None,
) -> FieldView:
    """Render what a camera at `T_field_camera` (optical frame -> field frame) sees.

    `noise_sigma`: Gaussian image noise [grey levels]; `blur_px`: length of a horizontal motion blur [px] (0: none);
    `rays_camera`: `pixel_rays(camera)`, when several views of one camera are rendered.
    """
    h, w = camera.height, camera.width
    rays = (pixel_rays(camera) if rays_camera is None else rays_camera) @ T_field_camera[:3, :3].T  # field frame
    origin = T_field_camera[:3, 3]
    distance = np.full(len(rays), np.inf)
    color = np.tile(CEILING, (len(rays), 1))
    down = rays[:, 2] < -1e-9
    s = np.where(down, -origin[2] / np.where(down, rays[:, 2], -1.0), np.inf)
    ground = origin[None, :2] + s[:, None] * rays[:, :2]
    distance[down] = s[down]
    carpet_extent = np.array([dims.length / 2 + BORDER_STRIP, dims.width / 2 + BORDER_STRIP])
    on_carpet = down & np.all(np.abs(ground) <= carpet_extent, axis=1)
    color[down & ~on_carpet] = HALL_FLOOR
    coverage = np.zeros(len(rays))
    if on_carpet.any():
        turf, coverage[on_carpet] = _carpet(dims, ground[on_carpet], _footprint(ground, s, h, w)[on_carpet], scene, rng)
        color[on_carpet] = turf
    T_camera_field = np.linalg.inv(T_field_camera)
    for box in scene.boxes:
        candidates = _pixels_near(camera, T_camera_field, box)
        if candidates is None:
            continue
        hit = np.full(len(rays), np.inf)
        hit[candidates] = _hit_box(origin, rays[candidates], box)
        nearer = hit < distance
        distance[nearer], color[nearer], coverage[nearer] = hit[nearer], _shade_box(box, rays[nearer]), 0.0
    if scene.ball is not None:
        centre, radius = scene.ball
        near_ball = _pixels_near(camera, T_camera_field, Box(centre - radius, centre + radius, (0.0, 0.0, 0.0)))
        hit, ball_color = np.full(len(rays), np.inf), np.zeros((len(rays), 3))
        if near_ball is not None:
            hit[near_ball], ball_color[near_ball] = _hit_ball(origin, rays[near_ball], centre, radius)
        nearer = hit < distance
        distance[nearer], color[nearer], coverage[nearer] = hit[nearer], ball_color[nearer], 0.0
    image = color.reshape(h, w, 3) * np.asarray(scene.colour_cast)
    if blur_px > 0.0:
        image = cv2.filter2D(image.astype(np.float32), -1, motion_kernel(blur_px))
    image = image + rng.normal(0.0, noise_sigma, image.shape)
    return FieldView(np.clip(image, 0, 255).astype(np.uint8), (coverage >= 0.5).reshape(h, w))


def motion_kernel(length_px: float) -> np.ndarray:
    """(1, 2K + 1) horizontal box blur of `length_px` [px] centred on the pixel: each tap weighs the overlap of its
    pixel [k - 1/2, k + 1/2] with [-length/2, length/2], so the blurred image keeps its place (an even box anchored
    on a pixel would shift it by half a pixel)."""
    half = max(length_px, 1.0) / 2
    k = np.arange(-np.ceil(half - 0.5), np.ceil(half - 0.5) + 1)
    weights = np.clip(np.minimum(k + 0.5, half) - np.maximum(k - 0.5, -half), 0.0, None)
    return (weights / weights.sum()).astype(np.float32)[None]


def _footprint(ground: np.ndarray, s: np.ndarray, h: int, w: int) -> np.ndarray:
    """Ground size of each pixel [m]: the larger step to the neighbouring pixels' ground points."""
    g = np.where(np.isfinite(s)[:, None], ground, np.nan).reshape(h, w, 2)
    du = np.linalg.norm(np.diff(g, axis=1, append=g[:, -1:] * 2 - g[:, -2:-1]), axis=-1)
    dv = np.linalg.norm(np.diff(g, axis=0, append=g[-1:] * 2 - g[-2:-1]), axis=-1)
    return np.nan_to_num(np.maximum(du, dv), nan=1.0).reshape(-1)


def _carpet(
    dims: FieldDimensions, points: np.ndarray, footprint: np.ndarray, scene: Scene, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Colour (N, 3) and line coverage (N,) of carpet points (N, 2) [m] with ground footprints (N,) [m]."""
    lines = field_lines(dims)
    distance = distance_to_lines(lines, points)
    coverage = np.clip(0.5 + (lines.line_width / 2 - distance) / np.maximum(footprint, 1e-6), 0.0, 1.0)
    stripes = 1.0 + 0.06 * np.sign(np.sin(np.pi * points[:, 0] / 0.5))
    grain = 1.0 + 0.05 * rng.standard_normal(len(points))
    light = 1.0 + points @ scene.light_gradient
    shade = np.ones(len(points))
    for centre, radius in scene.shadows:
        shade *= np.where(np.linalg.norm(points - centre, axis=1) < radius, 0.6, 1.0)
    base = TURF[None] * (stripes * grain)[:, None]
    colour = (base * (1 - coverage[:, None]) + LINE[None] * coverage[:, None]) * (light * shade)[:, None]
    return colour, coverage


def _hit_box(origin: np.ndarray, rays: np.ndarray, box: Box) -> np.ndarray:
    """Ray parameter (N,) of each ray's first hit on the box (slab method); inf where it misses."""
    safe = np.where(np.abs(rays) > 1e-12, rays, 1e-12)
    t1 = (box.low[None] - origin[None]) / safe
    t2 = (box.high[None] - origin[None]) / safe
    near = np.minimum(t1, t2).max(axis=1)
    far = np.maximum(t1, t2).min(axis=1)
    return np.where((far >= near) & (near > 1e-6), near, np.inf)


def _pixels_near(camera: CameraModel, T_camera_field: np.ndarray, box: Box) -> np.ndarray | None:
    """Indices of the pixels (row-major) that the box can cover: the pixel box of its corners, with a margin for
    distortion bending its edges; all pixels when a corner lies behind the camera; None when none can."""
    corners = np.array(
        [
            [x, y, z]
            for x in (box.low[0], box.high[0])
            for y in (box.low[1], box.high[1])
            for z in (box.low[2], box.high[2])
        ]
    )
    p = corners @ T_camera_field[:3, :3].T + T_camera_field[:3, 3]
    if (p[:, 2] <= 0.05).all():
        return None
    if (p[:, 2] <= 0.05).any():
        return np.arange(camera.width * camera.height)
    uv = camera.project(p)
    margin = 4.0
    u0, v0 = np.floor(uv.min(axis=0) - margin).astype(int)
    u1, v1 = np.ceil(uv.max(axis=0) + margin).astype(int)
    u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, camera.width - 1), min(v1, camera.height - 1)
    if u0 > u1 or v0 > v1:
        return None
    rows, cols = np.mgrid[v0 : v1 + 1, u0 : u1 + 1]
    return (rows * camera.width + cols).ravel()


def _shade_box(box: Box, rays: np.ndarray) -> np.ndarray:
    """A box's colour, a little darker on faces turned from the light above."""
    return np.tile(np.asarray(box.color, float), (len(rays), 1)) * (0.85 + 0.15 * np.abs(rays[:, 2:3]))


def _hit_ball(origin: np.ndarray, rays: np.ndarray, centre: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameter (N,) of the first hit on the ball and its colour there (white with dark patches)."""
    norm = np.linalg.norm(rays, axis=1)
    d = rays / norm[:, None]
    oc = origin - centre
    b = d @ oc
    disc = b**2 - (oc @ oc - radius**2)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    hit = np.where((disc > 0) & (t > 1e-6), t / norm, np.inf)
    surface = origin[None] + (t[:, None] * d) - centre[None]
    patch = (np.sign(surface[:, 0]) * np.sign(surface[:, 1]) * np.sign(surface[:, 2])) > 0
    colour = np.where(patch[:, None], 40.0, 235.0) * np.ones((1, 3))
    return hit, colour
