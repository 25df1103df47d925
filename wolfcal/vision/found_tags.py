"""The tags found in many images, kept as three flat arrays instead of a dict of small arrays per image.

A long recording gives thousands of images with a few tags each; as {tag id: (4, 2) array} per image that is a dict
and an array object per tag, allocated as the detection goes and kept to the end, between the detection's image
buffers. `FoundTags` keeps per image the number of tags, and per tag (a view: one tag in one image) its id and
corners, in typed arrays that grow in place; an image's dict is made only when asked for (`views[i]`).
"""

from __future__ import annotations

from array import array
from collections.abc import Iterable, Iterator

import numpy as np

Detections = dict[int, np.ndarray]  # tag id -> (4, 2) corners [px], aruco order, OpenCV pixel centres


class FoundTags:
    """Per image, the tags found: `counts` (N,) tags per image, `ids` (V,) and `corners` (V, 4, 2) [px] of the
    views, image after image, ids ascending within an image. Reads like a list of `Detections` (one per image)."""

    def __init__(self) -> None:
        self._counts, self._ids, self._corners = array("q"), array("q"), array("d")

    @classmethod
    def of(cls, detections: Iterable[Detections]) -> FoundTags:
        """Each image's detections appended as they come (the dicts and their arrays can go at once)."""
        views = cls()
        for found in detections:
            views.append(found)
        return views

    @classmethod
    def from_arrays(cls, counts: np.ndarray, ids: np.ndarray, corners: np.ndarray) -> FoundTags:
        """From `counts` (N,), `ids` (V,) and `corners` (V, 4, 2) [px] laid out image after image (as `arrays`
        gives them); within an image the views are put in ascending id order."""
        counts = np.asarray(counts, dtype=np.int64)
        image = np.repeat(np.arange(len(counts)), counts)
        order = np.lexsort((np.asarray(ids), image))
        views = cls()
        views._counts.frombytes(counts.tobytes())
        views._ids.frombytes(np.ascontiguousarray(ids, dtype=np.int64)[order].tobytes())
        views._corners.frombytes(np.ascontiguousarray(corners, dtype=np.float64).reshape(-1, 4, 2)[order].tobytes())
        return views

    def append(self, found: Detections) -> None:
        """One image's {tag id: (4, 2) corners [px]}."""
        self._counts.append(len(found))
        for tag_id in sorted(found):
            self._ids.append(int(tag_id))
            self._corners.frombytes(np.ascontiguousarray(found[tag_id], dtype=np.float64).reshape(8).tobytes())

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(counts (N,) int64, ids (V,) int64, corners (V, 4, 2) float64 [px]): views of the storage (read only
        while nothing is appended)."""
        return (np.frombuffer(self._counts, np.int64), np.frombuffer(self._ids, np.int64),
                np.frombuffer(self._corners, np.float64).reshape(-1, 4, 2))  # fmt: skip

    def starts(self) -> np.ndarray:
        """(N + 1,) index of each image's first view, then the number of views."""
        return np.concatenate([[0], np.cumsum(np.frombuffer(self._counts, np.int64))])

    def take(self, images: Iterable[int] | np.ndarray) -> FoundTags:
        """The views of the given images, in that order."""
        images = np.asarray(images, dtype=np.int64).reshape(-1)
        counts, ids, corners = self.arrays()
        starts = self.starts()
        picked = counts[images]
        first = np.concatenate([[0], np.cumsum(picked)[:-1]]).astype(np.int64)  # each picked image's first view
        view = np.repeat(starts[images] - first, picked) + np.arange(int(picked.sum()))  # in this storage
        return FoundTags.from_arrays(picked, ids[view], corners[view])

    @classmethod
    def concat(cls, parts: Iterable[FoundTags]) -> FoundTags:
        """The images of each part, part after part."""
        views = cls()
        for part in parts:
            views._counts.extend(part._counts)
            views._ids.extend(part._ids)
            views._corners.extend(part._corners)
        return views

    def __len__(self) -> int:
        return len(self._counts)

    def __getitem__(self, image: int) -> Detections:
        """Image `image`'s {tag id: (4, 2) corners [px]} (copies)."""
        if not -len(self) <= image < len(self):
            raise IndexError(image)
        starts = self.starts()
        image %= len(self)
        return self._detections(int(starts[image]), int(starts[image + 1]))

    def __iter__(self) -> Iterator[Detections]:
        starts = self.starts().tolist()
        for a, b in zip(starts[:-1], starts[1:]):
            yield self._detections(a, b)

    def _detections(self, a: int, b: int) -> Detections:
        """{tag id: (4, 2) corners [px]} (copies) of views a to b (one image's)."""
        _, ids, corners = self.arrays()
        return {int(t): corners[k].copy() for k, t in zip(range(a, b), ids[a:b])}
