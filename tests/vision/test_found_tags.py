"""FoundTags (wolfcal.vision.found_tags): the detections of many images kept as flat arrays, read back as the dicts
the detector gave, on real detections of rendered views."""

from __future__ import annotations

import numpy as np
import pytest
from test_tag_detection import CAMERA, random_view, tag_target

from wolfcal.vision.found_tags import FoundTags
from wolfcal.vision.render import render_targets
from wolfcal.vision.tags import detect_tags

BINNED = CAMERA.scaled(0.25, 0.25, 512, 384)


@pytest.fixture(scope="module")
def detections() -> list[dict[int, np.ndarray]]:
    """Detections of 6 rendered 512x384 images: tags 5 and 3 (in that order in the dict), one tag, none."""
    rng = np.random.default_rng(11)
    out = []
    for k in range(6):
        ids = [5, 3] if k % 3 == 0 else [4] if k % 3 == 1 else []
        tags = [tag_target("tag36h11", t, random_view(BINNED, rng)) for t in ids]
        image = render_targets(BINNED, tags, noise_sigma=2.0, rng=rng)
        found = detect_tags(image, "tag36h11", {3, 4, 5})
        out.append({t: found[t] for t in sorted(found, reverse=True)})  # ids descending: FoundTags sorts them
    assert [len(d) for d in out] == [2, 1, 0, 2, 1, 0]  # what the test relies on: several tags, one, none
    return out


def assert_same(a, b) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert sorted(x) == sorted(y)
        for tag in x:
            assert np.array_equal(x[tag], y[tag])  # bitwise


def test_views_read_back_as_the_detections_and_lay_out_by_image_then_id(detections):
    views = FoundTags.of(detections)
    assert_same(list(views), detections)
    assert_same([views[k] for k in range(len(views))], detections)
    assert_same([views[-1]], [detections[-1]])
    counts, ids, corners = views.arrays()
    assert counts.tolist() == [2, 1, 0, 2, 1, 0]
    assert ids.tolist() == [3, 5, 4, 3, 5, 4]
    assert np.array_equal(corners[0], detections[0][3]) and np.array_equal(corners[1], detections[0][5])
    with pytest.raises(IndexError):
        views[6]


def test_take_concat_and_from_arrays_keep_each_images_views(detections):
    views = FoundTags.of(detections)
    picked = [4, 0, 2, 0]
    assert_same(list(views.take(picked)), [detections[k] for k in picked])
    assert_same(list(views.take([])), [])
    both = FoundTags.concat([views.take([1, 2]), views.take([3])])
    assert_same(list(both), [detections[1], detections[2], detections[3]])
    counts, ids, corners = views.arrays()
    reversed_within = np.array([1, 0, 2, 4, 3, 5])  # each image's views in descending id order
    again = FoundTags.from_arrays(counts, ids[reversed_within], corners[reversed_within])
    assert_same(list(again), detections)
    assert again.arrays()[1].tolist() == ids.tolist()
