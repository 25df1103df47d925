"""Samples -> Observations per camera: detect the configured tags in every image (all cores, cached) and stack the
corners. Images of capture files are streamed from the file as detection goes (bounded memory, none read when the
cache holds the file's detections).

One `Observations` per camera name ('head' or an external camera's name), holding the samples in which that camera
saw at least one configured tag, with those samples' joint readings, stamps and sources. All images of one camera
must share one set of intrinsics (one camera, one resolution).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.io.samples import Sample, SampleImage, encoded_images
from wolfcal.observations import Observations
from wolfcal.robot.robot import Robot
from wolfcal.vision.cache import DetectorSettings, detect_by_source
from wolfcal.vision.found_tags import FoundTags

# Share of a camera's images without any configured tag above which a warning asks to check the tags: a few such
# images (blur, a tag just out of view) are normal, and the per-camera sample counts already show them.
NO_TAG_WARNING_SHARE = 0.25

Families = dict[str, set[int]]  # tag family -> configured ids


def _check_one_camera(name: str, images: list[SampleImage]) -> CameraModel:
    """The intrinsics all images of one camera share; a clear error when they differ."""
    keys = {(c.width, c.height, tuple(c.K.ravel()), tuple(c.D)) for c in (i.camera for i in images)}
    if len(keys) > 1:
        sizes = sorted({f"{w}x{h}" for w, h, _, _ in keys})
        raise WolfcalError(
            f"the images of camera '{name}' use different intrinsics or resolutions ({', '.join(sizes)}) in "
            f"{', '.join(sorted({i.source for i in images}))}; fit captures of one camera setting together "
            "(for the head camera, --intrinsics FILE uses one camera_info for all)"
        )
    return images[0].camera


# A tag on a link whose shortest edge in the image is under this share of its longest is seen more than about 70 deg
# off its axis (the visibility rule of planning and simulation allows 60): its refined corners come out biased by
# tenths of a pixel (rendered views of the torso tag at 72 deg: 0.43 px on average, against 0.07 px for the foot
# tags), which its many corners would pass on to the camera's pose. Such views are left out. Floor tags are seen at
# a grazing angle by design and are measured by the floor block's own rules.
GRAZING_EDGE_RATIO = 0.35


def facing_views(ids: np.ndarray, corners: np.ndarray, floor_ids: Iterable[int]) -> np.ndarray:
    """(V,) bool: the views (tag `ids` (V,), `corners` (V, 4, 2) [px]) to keep: every floor tag, and tags on links
    seen at no more than GRAZING_EDGE_RATIO foreshortening."""
    edges = np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2)
    facing = edges.min(axis=1) >= GRAZING_EDGE_RATIO * edges.max(axis=1)
    return facing | np.isin(ids, list(floor_ids))


def _stack(name: str, robot: Robot, samples: list[Sample], views: FoundTags, camera: CameraModel) -> Observations:
    """Observations of the samples (all with detections, `views` of their images in the same order) of one
    camera: the views `facing_views` keeps, and the samples that keep one."""
    counts, ids, corners = views.arrays()
    floor_ids = robot.config.floor.tag_ids if robot.config.floor is not None else []
    keep = facing_views(ids, corners, floor_ids)
    sample_of_view = np.repeat(np.arange(len(samples)), counts)[keep]
    kept_samples, sample_index = np.unique(sample_of_view, return_inverse=True)
    samples = [samples[k] for k in kept_samples]
    names = robot.joint_names
    return Observations.of_views(
        list(names),
        np.stack([s.joint_positions(names) for s in samples]),
        np.array([s.stamp_ns for s in samples], dtype=np.int64),
        [s.source for s in samples],
        camera,
        sample_index.ravel(),
        ids[keep].copy(),
        corners[keep].copy(),
        name,
        np.array([s.images[name].span for s in samples], dtype=np.int64),
    )


def detect_observations(
    samples: list[Sample],
    robot: Robot,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    cameras: Iterable[str] | None = None,
) -> tuple[dict[str, Observations], list[str]]:
    """Detect tags in every image of every sample (of the given `cameras` only, default all) -> Observations per
    camera name, and warnings (images without any configured tag are left out and said so). WolfcalError when no
    camera saw any configured tag."""
    if not samples:
        raise WolfcalError("no samples to detect tags in")
    wanted = None if cameras is None else set(cameras)
    for sample in samples:  # every joint of the robot read in every sample, before any image is decoded
        sample.joint_positions(robot.joint_names)
    families: Families = {}
    floor_tags = robot.config.floor.tags if robot.config.floor is not None else ()
    for family, tag_id in [(t.family, t.id) for t in robot.config.tags] + [(t.family, t.id) for t in floor_tags]:
        families.setdefault(family, set()).add(tag_id)  # tags on links and tags lying on the floor
    jobs = [(s, n) for s in samples for n in s.images if wanted is None or n in wanted]  # one per image
    if not jobs:
        raise WolfcalError(f"no images of camera(s) {', '.join(sorted(wanted or []))} in the samples")
    models = {name: _check_one_camera(name, [s.images[name] for s, n in jobs if n == name])
              for name in dict.fromkeys(n for _, n in jobs)}  # fmt: skip
    found = detect_by_source(
        [s.source for s, _ in jobs], [s.stamp_ns for s, _ in jobs],
        lambda ks: encoded_images(jobs[k][0].images[jobs[k][1]] for k in ks),
        [n for _, n in jobs], DetectorSettings.of(families), progress,
        labels=lambda k: f"{jobs[k][0].source}: the {jobs[k][1]} image at t={jobs[k][0].stamp_ns} ns",
        workers=workers,
    )  # fmt: skip
    counts = found.arrays()[0]
    observations: dict[str, Observations] = {}
    warnings = []
    for name, camera in models.items():
        rows = [k for k, (_, n) in enumerate(jobs) if n == name]
        seen = [k for k in rows if counts[k]]
        if len(rows) - len(seen) > NO_TAG_WARNING_SHARE * len(rows):  # a few are normal: the counts say so
            warnings.append(
                f"{len(rows) - len(seen)} of {len(rows)} image(s) of camera '{name}' show no configured tag and are "
                f"not used; check that the tags are in view and sharp, and the tag ids and families of "
                f"{robot.config.path}"
            )
        if seen:
            observations[name] = _stack(name, robot, [jobs[k][0] for k in seen], found.take(seen), camera)
    if not observations:
        ids = ", ".join(f"{t.family} id {t.id}" for t in robot.config.tags)
        sources = ", ".join(sorted({s.source for s in samples}))
        raise WolfcalError(
            f"{sources}: no configured tag ({ids}) was detected in any of the {len(jobs)} image(s); check the "
            f"tags of {robot.config.path} and that the images are sharp and show the tags"
        )
    return observations, warnings


def observations_of(observations: dict[str, Observations], camera: str, sources: Iterable[object]) -> Observations:
    """The Observations of one camera; a clear error naming the captures when that camera saw no tag in them."""
    if camera not in observations:
        seen = ", ".join(f"'{n}'" for n in observations) or "no camera"
        raise WolfcalError(
            f"{', '.join(map(str, sources))}: camera '{camera}' saw no configured tag in these captures (tags were "
            f"seen by {seen}); give captures in which it sees the tags"
        )
    return observations[camera]
