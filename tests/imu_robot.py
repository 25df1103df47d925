"""A Wolfgang robot whose IMU is another board: the URDF gains an `imu_board` link on the torso (a fixed joint turned
90 deg about z, as a board mounted sideways), the robot config's `imu:` names it."""

from __future__ import annotations

from pathlib import Path

import yaml
from conftest import WOLFGANG

from wolfcal.robot.robot import Robot, load_robot

IMU_LINK = """  <link name="imu_board"/>
  <joint name="imu_board_joint" type="fixed">
    <origin xyz="0.01 0.0 0.11" rpy="0 0 1.5708"/>
    <parent link="torso"/>
    <child link="imu_board"/>
  </joint>
"""


def robot_with_imu(folder: Path, imu: dict | None = None, urdf_extra: str = IMU_LINK, **changes) -> Robot:
    """Wolfgang's config with `imu:` (default {frame: imu_board, topic: /imu/data}) and the URDF with `urdf_extra`
    added, written to `folder` and loaded; `changes` replace top-level config keys."""
    text = (WOLFGANG / "wolfgang.urdf").read_text()
    (folder / "robot.urdf").write_text(text.replace("</robot>", urdf_extra + "</robot>"))
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = "robot.urdf"
    for camera in [data["camera"], *data["external_cameras"]]:
        camera["intrinsics"] = str((WOLFGANG / camera["intrinsics"]).resolve())
    data["imu"] = imu if imu is not None else {"frame": "imu_board", "topic": "/imu/data"}
    data.update(changes)
    (folder / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return load_robot(folder / "robot.yaml")
