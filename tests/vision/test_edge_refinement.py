"""The vectorised edge refinement gives the corners of the per-edge reference loop it replaced."""

from __future__ import annotations

import numpy as np
import pytest
from edge_reference import _refine_edges as reference_refine
from test_tag_detection import CAMERA, FACING, SIZE, random_view, tag_target, truth

from wolfcal.geometry import make_transform
from wolfcal.vision import edges
from wolfcal.vision.edges import edge_offsets, refine_edges
from wolfcal.vision.render import render_targets
from wolfcal.vision.tags import _detector, _found, _to_gray, detect_tags, tag_cells


@pytest.mark.parametrize("camera", [CAMERA, CAMERA.scaled(0.25, 0.25, 512, 384)], ids=["full", "binned"])
def test_vectorised_refinement_equals_the_reference(camera, monkeypatch):
    """Same starting corners (aruco's), same image: the corners agree to 1e-6 px, for large and small tags (every
    profile on its own and two iterations, as the reference loop does them)."""
    monkeypatch.setattr(edges, "PROFILES", 10**6)
    monkeypatch.setattr(edges, "SETTLED", 0.0)
    rng = np.random.default_rng(7)
    compared = 0
    for _ in range(6):
        T = random_view(camera, rng)
        image = render_targets(camera, [tag_target("tag36h11", 3, T)], noise_sigma=2.0, rng=rng)
        corners, ids, _ = _detector("tag36h11", "edges").detectMarkers(_to_gray(image))
        img = image.astype(np.float32)
        for c in corners:
            start = np.asarray(c, float).reshape(4, 2)
            expected = reference_refine(img, start, tag_cells("tag36h11"))
            np.testing.assert_allclose(refine_edges(img, start, tag_cells("tag36h11")), expected, atol=1e-6)
            assert np.linalg.norm(expected - truth(camera, T), axis=1).max() < 1.0  # a real refinement
            compared += 1
    assert compared >= 5


def test_tags_refined_together_get_the_corners_they_get_alone(monkeypatch):
    """Three tags of different sizes (cells of 27, 15 and 5 px) in one image, refined in one call (padded grids):
    each tag's corners are those of refining it alone."""
    rng = np.random.default_rng(11)
    views = [make_transform(FACING, [x, y, z]) for x, y, z in ((-0.25, -0.1, 0.5), (0.0, 0.1, 0.9), (0.5, 0.0, 2.6))]
    image = render_targets(CAMERA, [tag_target("tag36h11", i, T) for i, T in enumerate(views)], noise_sigma=2.0,
                           rng=rng)  # fmt: skip
    corners, ids, _ = _detector("tag36h11", "edges").detectMarkers(_to_gray(image))
    assert sorted(ids.ravel()) == [0, 1, 2]
    img = image.astype(np.float32)
    start = np.stack([np.asarray(c, float).reshape(4, 2) for c in corners])
    together = refine_edges(img, start, tag_cells("tag36h11"))
    alone = np.stack([refine_edges(img, c, tag_cells("tag36h11")) for c in start])
    np.testing.assert_allclose(together, alone, atol=1e-9)
    monkeypatch.setattr(edges, "TAGS_PER_PASS", 2)  # in passes of tags of similar size
    np.testing.assert_allclose(refine_edges(img, start, tag_cells("tag36h11")), alone, atol=1e-9)
    for tag_id, found in zip(ids.ravel(), together):
        assert np.linalg.norm(found - truth(CAMERA, views[tag_id]), axis=1).max() < 0.3


def test_refinement_in_a_crop_equals_the_whole_image():
    """detect_tags refines in a float32 crop around an image's tags (`_tags_crop`): the same corners as refining the
    same starts in the whole image (to float32 rounding of the sample points), for a large tag (cells of 27 px), a
    small one, and one whose profiles reach past the image border (crop clipped there)."""
    rng = np.random.default_rng(13)
    views = [make_transform(FACING, [x, y, z]) for x, y, z in ((-0.25, -0.1, 0.5), (0.5, 0.0, 2.6))]
    ray = np.ravel(CAMERA.unproject(np.array([3.0, 800.0])))  # a tag's left edge 3 px inside the image
    views.append(make_transform(FACING, [ray[0] / ray[2] * 0.6 + SIZE / 2, ray[1] / ray[2] * 0.6 - SIZE / 2, 0.6]))
    image = render_targets(CAMERA, [tag_target("tag36h11", i, T) for i, T in enumerate(views)], noise_sigma=2.0,
                           rng=rng)  # fmt: skip
    found = _found(image, "tag36h11", None, "edges")
    assert sorted(found) == [0, 1, 2]
    assert 1.0 < found[2][:, 0].min() < 5.0  # by the border
    start = np.stack([found[k] for k in range(3)])
    whole = refine_edges(image.astype(np.float32), start, tag_cells("tag36h11"))
    cropped = detect_tags(image)
    np.testing.assert_allclose(np.stack([cropped[k] for k in range(3)]), whole, atol=2e-4)
    for tag_id, corners in cropped.items():
        assert np.linalg.norm(corners - truth(CAMERA, views[tag_id]), axis=1).max() < 0.3


def test_corner_by_the_image_border_keeps_its_estimate():
    """A tag whose corners sit on the border: unmeasurable edges leave those corners where they were."""
    image = np.full((60, 60), 255.0, np.float32)
    image[:30, :30] = 0.0  # a black square in the top-left corner, its outer edges on the image border
    start = np.array([[0.0, 0.0], [29.7, 0.0], [29.7, 29.7], [0.0, 29.7]])
    refined = refine_edges(image, start, 8)
    np.testing.assert_allclose(refined[0], start[0])  # both edges of corner 0 lie on the border
    assert abs(refined[2, 0] - 29.5) < 0.05 and abs(refined[2, 1] - 29.5) < 0.05  # the free corner is found


def test_edge_offsets_of_a_box_filtered_step():
    """A pixel-integrated step at +0.3 px is found at +0.3 px (area method), per profile dark/light levels."""
    t = np.arange(-3.0, 3.01, 0.25)
    edge = 0.3
    profile = np.clip(t - edge + 0.5, 0.0, 1.0)  # box filter of width 1 px
    profiles = np.stack([20 + 200 * profile, 50 + 100 * profile])
    found = edge_offsets(profiles, t, np.array([20.0, 50.0]), np.array([220.0, 150.0]), 2.0)
    np.testing.assert_allclose(found, edge, atol=0.01)


def test_binned_profiles_and_settled_tags_keep_the_corners(monkeypatch):
    """Large tags (cells of 12-40 px: 100-200 profiles an edge, averaged in bins; most settled after one iteration)
    get the corners of every profile on its own and two iterations to 0.05 px, and the truth to 0.15 px."""
    rng = np.random.default_rng(5)
    views = [make_transform(FACING, [x, y, z]) for x, y, z in ((-0.2, -0.1, 0.3), (0.1, 0.1, 0.5), (0.3, -0.05, 0.9))]
    image = render_targets(CAMERA, [tag_target("tag36h11", i, T) for i, T in enumerate(views)], noise_sigma=2.0,
                           rng=rng)  # fmt: skip
    found = _found(image, "tag36h11", None, "edges")
    assert sorted(found) == [0, 1, 2]
    start = np.stack([found[k] for k in range(3)])
    img = image.astype(np.float32)
    binned = refine_edges(img, start, tag_cells("tag36h11"))
    monkeypatch.setattr(edges, "PROFILES", 10**6)
    monkeypatch.setattr(edges, "SETTLED", 0.0)
    every = refine_edges(img, start, tag_cells("tag36h11"))
    assert np.abs(binned - every).max() < 0.05
    assert 0.0 < np.abs(binned - every).max()  # the bins are used
    for tag_id, corners in enumerate(binned):
        assert np.linalg.norm(corners - truth(CAMERA, views[tag_id]), axis=1).max() < 0.15


def test_tags_of_several_images_in_any_order_get_the_same_corners():
    """Tags of two images refined in one pass get the same corners whether each image's tags come in a row (its
    edges a slice of the pass) or interleaved (its edges picked out), and each image's corners are its own."""
    rng = np.random.default_rng(17)
    first = [make_transform(FACING, [x, y, z]) for x, y, z in ((-0.25, -0.1, 0.5), (0.3, 0.1, 1.2))]
    second = [make_transform(FACING, [x, y, z]) for x, y, z in ((0.2, -0.1, 0.7), (-0.3, 0.1, 2.0))]
    images, starts = [], []
    for views in (first, second):
        image = render_targets(CAMERA, [tag_target("tag36h11", i, T) for i, T in enumerate(views)], noise_sigma=2.0,
                               rng=rng)  # fmt: skip
        found = _found(image, "tag36h11", None, "edges")
        assert sorted(found) == [0, 1]
        images.append(image.astype(np.float32))
        starts.append(np.stack([found[0], found[1]]))
    cells = tag_cells("tag36h11")
    in_a_row = edges.refine_tags(images, np.array([0, 0, 1, 1]), np.concatenate(starts), cells)
    mixed = np.stack([starts[1][0], starts[0][0], starts[1][1], starts[0][1]])
    interleaved = edges.refine_tags(images, np.array([1, 0, 1, 0]), mixed, cells)
    np.testing.assert_allclose(interleaved[[1, 3, 0, 2]], in_a_row, atol=1e-9)
    for views, image_of in ((first, 0), (second, 1)):
        for tag_id, T in enumerate(views):
            assert np.linalg.norm(in_a_row[2 * image_of + tag_id] - truth(CAMERA, T), axis=1).max() < 0.3
