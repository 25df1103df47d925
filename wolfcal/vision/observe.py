"""Samples -> Observations: detect the configured tags in every image (all cores, cached) and stack the corners."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.io.samples import Sample
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.robot.robot import Robot
from wolfcal.vision.cache import DetectorSettings, detect_by_source


def detect_observations(
    samples: list[Sample],
    robot: Robot,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[Observations, list[str]]:
    """Detect tags in all samples; samples without any configured tag are left out (and said so)."""
    if not samples:
        raise WolfcalError("no samples to detect tags in")
    cameras = {(s.camera.width, s.camera.height, tuple(s.camera.K.ravel()), tuple(s.camera.D)) for s in samples}
    if len(cameras) > 1:
        raise WolfcalError(
            "the captures use different camera intrinsics or resolutions; fit captures of one camera together "
            "(or pass --intrinsics FILE to use one camera_info for all)"
        )
    names = robot.joint_names
    q = np.stack([s.joint_positions(names) for s in samples])
    families: dict[str, set[int]] = {}
    for tag in robot.config.tags:
        families.setdefault(tag.family, set()).add(tag.id)
    detections = detect_by_source(
        [s.source for s in samples], [s.stamp_ns for s in samples], lambda i: samples[i].image_data,
        f"{HEAD_CAMERA} {robot.config.camera.topic}", DetectorSettings.of(families), progress,
        labels=lambda i: f"{samples[i].source}: the sample at t={samples[i].stamp_ns} ns", workers=workers,
    )  # fmt: skip
    warnings = []
    empty = [i for i, d in enumerate(detections) if not d]
    if empty:
        warnings.append(f"{len(empty)} of {len(samples)} sample(s) show no configured tag and are not used")
    keep = [i for i, d in enumerate(detections) if d]
    if not keep:
        ids = ", ".join(f"{t.family} id {t.id}" for t in robot.config.tags)
        sources = ", ".join(sorted({s.source for s in samples}))
        raise WolfcalError(
            f"{sources}: no configured tag ({ids}) was detected in any of the {len(samples)} image(s); check the "
            f"tags of {robot.config.path} and that the images are sharp and show the tags"
        )
    sample_index, tag_ids, corner_index, uv = [], [], [], []
    for new_index, i in enumerate(keep):
        for tag_id, corners in sorted(detections[i].items()):
            sample_index.append(np.full(4, new_index))
            tag_ids.append(np.full(4, tag_id))
            corner_index.append(np.arange(4))
            uv.append(corners)
    obs = Observations(
        joint_names=list(names),
        q_measured=q[keep],
        stamps_ns=np.array([samples[i].stamp_ns for i in keep], dtype=np.int64),
        sources=[samples[i].source for i in keep],
        camera=samples[keep[0]].camera,
        sample_index=np.concatenate(sample_index),
        tag_ids=np.concatenate(tag_ids),
        corner_index=np.concatenate(corner_index),
        uv=np.concatenate(uv).astype(float),
    )
    return obs, warnings
