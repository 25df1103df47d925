"""Do the head camera's detections agree with the configured camera axes (`camera.axes`)?

A tag the camera saw lies in front of it: z > 0 in its optical frame. Under the nominal model, a few degrees or
centimetres off, every seen tag's centre should be in front. When most are behind, the camera link's axes are most
likely not what `camera.axes` says: an 'optical' link (z forward) configured as 'body' (x forward) or the reverse.
The other convention's forward axis in the configured optical frame: for 'optical' configured, the body link's x
is the optical x axis (z forward of a body link = its x); for 'body' configured, an optical link's z is the added
optical frame's -y.
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.observations import Observations
from wolfcal.robot.robot import Robot

OTHER = {"optical": "body", "body": "optical"}


def forward_depths(robot: Robot, obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """(V,) depth [m] of each seen tag's centre along the configured camera's forward axis and along the other
    convention's (module docstring), under the nominal model at the views' readings."""
    views, _ = obs.views()
    depth, other = np.empty(len(views)), np.empty(len(views))
    for tag_id in np.unique(views[:, 1]):
        rows = np.flatnonzero(views[:, 1] == tag_id)
        _, T_camera_tag = robot.camera_and_tag_poses(obs.q_measured[views[rows, 0]], [int(tag_id)])
        p = T_camera_tag[:, 0, :3, 3]  # (n, 3) tag centre in the configured optical frame [m]
        depth[rows] = p[:, 2]
        other[rows] = p[:, 0] if robot.config.head_camera().axes == "optical" else -p[:, 1]
    return depth, other


def check_camera_axes(robot: Robot, obs: Observations) -> None:
    """A WolfcalError naming the config when most tags the head camera saw lie behind it under the nominal model,
    saying which convention the data point to."""
    depth, other = forward_depths(robot, obs)
    behind, total = int(np.sum(depth <= 0)), len(depth)
    if total == 0 or 2 * behind <= total:
        return
    axes = robot.config.head_camera().axes
    in_front_other = int(np.sum(other > 0))
    where = f"{robot.config.path}: 'camera.axes' is {axes!r} but {behind} of {total} tags project behind the camera"
    if 2 * in_front_other > total:
        raise WolfcalError(
            f"{where}; the data fit {OTHER[axes]!r} ({in_front_other} of {total} in front): set 'camera.axes: "
            f"{OTHER[axes]}' (optical: z forward, x right, y down; body: x forward, y left, z up)"
        )
    raise WolfcalError(
        f"{where}, under either convention; check 'camera.frame' ({robot.config.head_camera().urdf_frame}), the "
        "tags' links and that the joint readings belong to this robot"
    )
