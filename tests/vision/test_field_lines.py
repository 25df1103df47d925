"""Field lines: the field model's geometry, rendered views and the line detector against the views' truth."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.errors import WolfcalError
from wolfcal.field.detect import detect_line_points
from wolfcal.field.ground import expected_line_width, ground_points, ground_step
from wolfcal.field.model import (
    ADULTSIZE,
    KIDSIZE,
    distance_to_lines,
    field_dimensions,
    field_lines,
    mirrored_pose,
    nearest_line_normal,
)
from wolfcal.field.quality import detection_quality
from wolfcal.field.render import motion_kernel, pixel_rays, render_field_view
from wolfcal.field.scene import WARM_LIGHT, Scene, cluttered_scene
from wolfcal.geometry import transform_points

CAMERA = load_camera_info(Path(__file__).resolve().parents[2] / "configs" / "wolfgang" / "basler_acA2040.yaml")


def looking(x: float, y: float, z: float, yaw: float, pitch: float) -> np.ndarray:
    """T_field_camera of an optical frame at (x, y, z) looking along `yaw`, pitched down by `pitch` [rad]."""
    forward = np.array([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), -np.sin(pitch)])
    right = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
    T = np.eye(4)
    T[:3, :3] = np.column_stack([right, np.cross(forward, right), forward])
    T[:3, 3] = [x, y, z]
    return T


def test_the_markings_lie_where_the_rules_put_them() -> None:
    lines = field_lines(KIDSIZE)
    on_lines = np.array([[0.0, 0.0], [0.75, 0.0], [4.5, 2.9], [-3.0, 0.0], [3.5, 1.5], [2.5, -2.5], [0.0, -0.75]])
    assert np.allclose(distance_to_lines(lines, on_lines), 0.0, atol=1e-12)
    off = np.array([[1.0, 1.0], [-3.0, 0.2], [4.4, 0.0]])  # 0.66 m from the circle, 0.15 from the mark's arm, 0.1
    assert np.allclose(distance_to_lines(lines, off), [np.sqrt(2) - 0.75, 0.15, 0.1])
    distance, normal, index = nearest_line_normal(lines, np.array([[4.4, 0.0], [0.8, 0.0]]))  # goal line: along +y
    assert np.allclose(distance, [0.1, 0.05]) and np.allclose(normal, [[-1.0, 0.0], [1.0, 0.0]])
    assert np.allclose(lines.segments[index[0]], [[4.5, -3.0], [4.5, 3.0]]) and index[1] == len(lines.segments)
    assert mirrored_pose(-3.0, 0.5, 0.2) == pytest.approx((3.0, -0.5, 0.2 - np.pi))
    assert field_lines(ADULTSIZE).circle_radius == 1.5


def test_impossible_dimensions_are_refused_naming_the_key() -> None:
    values = {name: getattr(KIDSIZE, name) for name in KIDSIZE.__dataclass_fields__}
    assert field_dimensions(values, "robot.yaml: field.dimensions") == KIDSIZE
    with pytest.raises(WolfcalError, match="field.dimensions.*goal area must be narrower"):
        field_dimensions({**values, "goal_area_width": 6.0}, "robot.yaml: field.dimensions")
    with pytest.raises(WolfcalError, match="line_width is -0.05"):
        field_dimensions({**values, "line_width": -0.05}, "robot.yaml: field.dimensions")
    with pytest.raises(WolfcalError, match="missing key.*penalty_mark_size"):
        field_dimensions({k: v for k, v in values.items() if k != "penalty_mark_size"}, "robot.yaml: field.dimensions")


def test_pixels_meet_the_ground_where_the_camera_sees_it() -> None:
    camera = CAMERA.binned(4)
    T = looking(-3.0, 0.2, 0.6, 0.3, 0.4)
    field_points = np.array([[-1.0, 0.5, 0.0], [0.0, 1.5, 0.0], [-2.0, -0.3, 0.0]])
    uv = camera.project(transform_points(np.linalg.inv(T), field_points))
    assert np.allclose(ground_points(camera, T, uv), field_points[:, :2], atol=1e-6)


def test_lines_are_found_in_a_cluttered_view_and_nothing_else() -> None:
    """A 512x384 view from a standing robot with goals, two robots, a ball, shadows, people and walls beyond the
    border strip, uneven light, noise and a 2 px motion blur: most points lie on a line, most of the lines crossed by
    the scan are found, and the points lie within a fraction of a pixel of the line centres."""
    camera = CAMERA.binned(4)
    rng = np.random.default_rng(4)
    scene = cluttered_scene(KIDSIZE, rng)
    T = looking(-3.0, 0.0, 0.6, 0.0, 0.35)
    view = render_field_view(camera, T, KIDSIZE, scene, rng, noise_sigma=3.0, blur_px=2.0)
    points = detect_line_points(view.image, expected_line_width(camera, T, KIDSIZE.line_width), step=4)
    quality = detection_quality(points, view.line_mask, camera, T, field_lines(KIDSIZE), step=4, max_run_px=12)
    assert quality.points > 200
    assert quality.precision > 0.9, quality
    assert quality.recall > 0.8, quality
    assert np.median(quality.centre_error_px) < 0.6


def test_a_view_of_the_sky_shows_no_lines() -> None:
    camera = CAMERA.binned(4)
    rng = np.random.default_rng(0)
    view = render_field_view(
        camera, looking(-3.0, 0.0, 0.6, 0.0, -0.6), KIDSIZE, Scene(), rng, rays_camera=pixel_rays(camera)
    )
    assert not view.line_mask.any()
    assert len(detect_line_points(view.image).uv) == 0


@pytest.mark.parametrize("length", [1.5, 2.0, 3.0, 4.0])
def test_motion_blur_keeps_a_line_in_place(length):
    """A horizontal motion blur of any length smears a vertical line symmetrically: its centroid stays put (an even
    box anchored on a pixel would move it by half a pixel)."""
    row = np.zeros(41)
    row[18:22] = 1.0  # centred on 19.5
    kernel = motion_kernel(length)[0]
    blurred = np.convolve(row, kernel, mode="same")
    assert abs(kernel.sum() - 1.0) < 1e-6 and np.allclose(kernel, kernel[::-1])
    assert abs(blurred @ np.arange(41) / blurred.sum() - 19.5) < 1e-6


def test_lines_are_found_under_a_warm_light() -> None:
    """The cluttered view under a hall's warm light seen without white balance (lines look yellow, more saturated
    than the turf): white is judged against the local turf's own colour, so the lines are still found, and few
    points lie off the lines. Far lines thinner than half a pixel leave no truth pixels but are still seen, so the
    points are also judged by their distance to the nearest true line centre."""
    camera = CAMERA.binned(4)
    rng = np.random.default_rng(4)
    scene = dataclasses.replace(cluttered_scene(KIDSIZE, rng), colour_cast=WARM_LIGHT)
    T = looking(-3.0, 0.0, 0.6, 0.0, 0.35)
    view = render_field_view(camera, T, KIDSIZE, scene, rng, noise_sigma=3.0, blur_px=2.0)
    line_pixels = view.image[view.line_mask].astype(float)
    assert np.median(line_pixels[:, 2] - line_pixels[:, 0]) > 100  # the cast holds: red far above blue on a line
    points = detect_line_points(view.image, expected_line_width(camera, T, KIDSIZE.line_width), step=4)
    quality = detection_quality(points, view.line_mask, camera, T, field_lines(KIDSIZE), step=4, max_run_px=12)
    assert quality.points > 200
    assert quality.precision > 0.8, quality
    assert quality.recall > 0.8, quality
    assert np.median(quality.centre_error_px) < 0.6
    ground = ground_points(camera, T, points.uv)
    off_px = distance_to_lines(field_lines(KIDSIZE), ground) / np.nanmin(ground_step(camera, T, points.uv), axis=1)
    assert np.mean(~(off_px <= 2.0)) < 0.15, np.mean(~(off_px <= 2.0))
