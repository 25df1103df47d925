"""Tag textures, detection accuracy against rendered truth, and the renderer's pixel convention."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.geometry import exp_so3, make_transform, tag_corners, transform_points
from wolfcal.vision.render import PlanarTarget, motion_blur, render_targets
from wolfcal.vision.tags import FAMILIES, detect_tags, tag_texture, tag_texture_width

SIZE = 0.08
CAMERA = CameraModel(
    2048,
    1536,
    np.array([[1336.2, 0, 1015.8], [0, 1334.4, 727.0], [0, 0, 1]]),
    np.array([-0.28595, 0.081479, -0.000093, -0.00032, 0.0]),
)
PINHOLE = CameraModel(320, 240, np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]]), np.zeros(5))
FACING = np.diag([1.0, -1.0, -1.0])  # tag frame -> optical frame: tag x right, y up, z towards the camera


def tag_target(family: str, tag_id: int, T_camera_tag: np.ndarray, size: float = SIZE) -> PlanarTarget:
    texture = tag_texture(family, tag_id)
    width = tag_texture_width(family, size, texture)
    return PlanarTarget(T_camera_tag, texture, width, width)


def truth(camera: CameraModel, T_camera_tag: np.ndarray, size: float = SIZE) -> np.ndarray:
    return camera.project(transform_points(T_camera_tag, tag_corners(size)))


def random_view(camera: CameraModel, rng: np.random.Generator) -> np.ndarray:
    """T_camera_tag at 0.3-1.2 m, tilted up to 50 deg, turned at random in plane, fully inside the image."""
    while True:
        ray = camera.unproject(rng.uniform([0, 0], [camera.width - 1, camera.height - 1]))
        z = -ray / np.linalg.norm(ray)
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z]) @ exp_so3(np.array([0, 0, rng.uniform(-np.pi, np.pi)]))
        axis = rng.normal(size=2)
        R = R @ exp_so3(np.array([*axis / np.linalg.norm(axis), 0.0]) * np.deg2rad(rng.uniform(0, 50)))
        T = make_transform(R, ray * rng.uniform(0.3, 1.2))
        if camera.in_image(truth(camera, T, SIZE * 1.25), margin=2).all():  # quiet zone inside too
            return T


def test_tag_corners_aruco_order():
    expected = [[-0.05, 0.05, 0], [0.05, 0.05, 0], [0.05, -0.05, 0], [-0.05, -0.05, 0]]
    np.testing.assert_allclose(tag_corners(0.1), expected)


def test_texture_layout_and_size():
    texture = tag_texture("tag36h11", 0, border_cells=2)
    assert texture.shape == (12, 12) and texture.dtype == np.uint8
    assert (texture[:2] == 255).all() and (texture[2, 2:10] == 0).all()  # quiet zone, then the black border
    assert tag_texture_width("tag36h11", 0.08, texture) == pytest.approx(0.12)
    with pytest.raises(WolfcalError):
        tag_texture("tag36h11", 587)
    with pytest.raises(WolfcalError):
        tag_texture("tag99h1", 0)


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_texture_orientation_matches_aruco(family):
    """Upscaled texture, no renderer: corner 0 is the top-left of the black square (OpenCV pixel centres)."""
    scale, border = 20, 2
    texture = tag_texture(family, 3, border)
    image = cv2.resize(texture, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    side = (tag_texture(family, 3, 0).shape[0]) * scale
    lo, hi = border * scale - 0.5, border * scale + side - 0.5  # black square edges in pixel coordinates
    expected = np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi]])
    found = detect_tags(image, family)
    assert set(found) == {3}
    np.testing.assert_allclose(found[3], expected, atol=0.05)


@pytest.mark.parametrize("turn", [0.0, np.pi / 2, np.pi, -np.pi / 2])
def test_rendered_tag_corner_order(turn):
    T = make_transform(FACING @ exp_so3(np.array([0, 0, turn])), [0.0, 0.0, 0.4])
    image = render_targets(PINHOLE, [tag_target("tag36h11", 5, T)], rng=np.random.default_rng(0))
    found = detect_tags(image)
    np.testing.assert_allclose(found[5], truth(PINHOLE, T), atol=0.1)


def test_rendering_is_exact():
    """Large frontal tags, 16x supersampling, no noise: corners match the projection (no half-pixel shift)."""
    errors = []
    for x, y in [(0.0, 0.0), (0.013, -0.021), (-0.031, 0.007)]:
        T = make_transform(FACING, [x, y, 0.35])
        image = render_targets(CAMERA, [tag_target("tag36h11", 7, T)], background=128.0, supersample=16)
        errors.append(detect_tags(image)[7] - truth(CAMERA, T))
    errors = np.concatenate(errors)
    assert np.abs(errors.mean(axis=0)).max() < 0.02
    assert np.abs(errors).max() < 0.05


@pytest.mark.parametrize("camera", [CAMERA, CAMERA.scaled(0.25, 0.25, 512, 384)], ids=["full", "binned"])
def test_corner_accuracy_on_random_views(camera):
    rng = np.random.default_rng(42)
    errors = []
    for _ in range(8):
        tag_id = int(rng.integers(0, 50))
        T = random_view(camera, rng)
        image = render_targets(camera, [tag_target("tag36h11", tag_id, T)], noise_sigma=2.0, rng=rng)
        found = detect_tags(image, "tag36h11")
        if tag_id in found:
            errors.append(np.linalg.norm(found[tag_id] - truth(camera, T), axis=1))
    assert len(errors) >= 6
    assert np.median(np.concatenate(errors)) <= 0.2


def test_ids_filter_duplicates_and_empty():
    rng = np.random.default_rng(1)
    left, right = make_transform(FACING, [-0.06, 0, 0.5]), make_transform(FACING, [0.06, 0, 0.5])
    one, two = tag_target("tag36h11", 1, left), tag_target("tag36h11", 2, right)
    image = render_targets(PINHOLE, [one, two], rng=rng)
    assert set(detect_tags(image)) == {1, 2}
    assert set(detect_tags(image, ids={2, 9})) == {2}
    assert detect_tags(image, "tag25h9") == {}
    assert detect_tags(cv2.cvtColor(image, cv2.COLOR_GRAY2BGR), ids={1}).keys() == {1}
    twins = render_targets(PINHOLE, [one, tag_target("tag36h11", 1, right)], rng=rng)
    assert detect_tags(twins) == {}  # ambiguous
    assert detect_tags(render_targets(PINHOLE, [], noise_sigma=2.0, rng=rng)) == {}
    x = (-3.0 - PINHOLE.cx) / PINHOLE.fx * 0.5 + SIZE / 2
    cut = make_transform(FACING, [x, 0, 0.5])  # left corners 3 px outside the image (aruco still finds it)
    np.testing.assert_allclose(truth(PINHOLE, cut)[[0, 3], 0], -3.0)
    assert detect_tags(render_targets(PINHOLE, [tag_target("tag36h11", 1, cut)], rng=rng)) == {}


def test_small_tags_above_the_outline_limit_are_found():
    """Frontal tags of 14 and 20 px side (outline 56 and 80 px, above MIN_TAG_PERIMETER_PX) in a 320x240 image."""
    from wolfcal.vision.tags import MIN_TAG_PERIMETER_PX

    rng = np.random.default_rng(5)
    for side in (14.0, 20.0):
        assert 4 * side > MIN_TAG_PERIMETER_PX
        T = make_transform(FACING, [0.01, -0.02, PINHOLE.fx * SIZE / side])
        image = render_targets(PINHOLE, [tag_target("tag36h11", 3, T)], noise_sigma=1.0, rng=rng)
        found = detect_tags(image)
        assert set(found) == {3}
        assert np.abs(found[3] - truth(PINHOLE, T)).max() < 0.5


def half_plane(edge_u: float, z: float = 1.0) -> PlanarTarget:
    """A frontal target, black for x < 0 and white for x > 0, whose boundary projects onto column `edge_u`."""
    x = (edge_u - PINHOLE.cx) / PINHOLE.fx * z
    return PlanarTarget(make_transform(FACING, [x, 0.0, z]), np.array([[0, 255]], np.uint8), 4.0, 4.0)


@pytest.mark.parametrize(("edge_u", "value"), [(100.0, 128), (100.25, 64), (99.75, 191)])
def test_renderer_pixel_convention(edge_u, value):
    """The boundary at u = 100 (OpenCV: the centre of pixel column 100) makes that column 50% grey."""
    image = render_targets(PINHOLE, [half_plane(edge_u)], background=np.full((240, 320), 77.0))
    assert (image[:, 100] == value).all()
    assert (image[:, :99] == 0).all() and (image[:, 102:] == 255).all()


def test_nearest_target_wins_and_behind_camera_is_not_drawn():
    background = np.full((240, 320), 77.0)
    white = np.full((1, 1), 255, np.uint8)
    near = PlanarTarget(make_transform(FACING, [0, 0, 1.0]), np.zeros((1, 1), np.uint8), 0.2, 0.2)
    far = PlanarTarget(make_transform(FACING, [0, 0, 2.0]), white, 1.0, 1.0)
    image = render_targets(PINHOLE, [far, near], background=background)
    assert image[120, 160] == 0 and image[120, 100] == 255 and image[5, 5] == 77
    behind = PlanarTarget(make_transform(np.diag([1.0, 1.0, 1.0]), [0, 0, -1.0]), white, 1.0, 1.0)
    assert (render_targets(PINHOLE, [behind], background=background) == 77).all()
    beside = PlanarTarget(make_transform(FACING, [5.0, 0, 1.0]), white, 1.0, 1.0)  # out of view
    assert (render_targets(PINHOLE, [beside], background=background) == 77).all()


def test_motion_blur_spreads_along_its_direction():
    image = np.zeros((41, 41), np.uint8)
    image[20, 20] = 255
    horizontal = motion_blur(image, 9.0, 0.0)
    assert (horizontal[20, 16:25] > 0).all() and horizontal[20, 10] == 0 and horizontal[15, 20] == 0
    vertical = motion_blur(image, 9.0, np.pi / 2)
    assert (vertical[16:25, 20] > 0).all() and vertical[20, 15] == 0


def test_a_plane_reaching_the_camera_plane_is_rendered_without_an_overflowing_pixel_box():
    """A floor-like plane whose near edge lies just in front of the camera: its border projects to ~1e29 px under
    the lens model, which an integer pixel box cannot hold (NumPy's 'invalid value encountered in cast', and the
    plane was dropped from the image). It is rendered, without a warning, where it is seen: the image's bottom."""
    R_camera_target = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # target y along the view, its normal up
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R_camera_target, [0.0, 0.3, 2.0 + 2e-6]  # 4 m deep: from 2e-6 m to 4 m ahead
    white = np.full((8, 8), 255, np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        image = render_targets(
            CAMERA, [PlanarTarget(T, white, 4.0, 4.0)], background=np.full((1536, 2048), 60.0), supersample=1
        )
    assert image[-10:, CAMERA.width // 2].min() == 255  # the floor below the centre
    assert image[10, CAMERA.width // 2] == 60  # the sky above it stays background
