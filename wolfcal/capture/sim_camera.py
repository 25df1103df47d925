"""The `sim` camera source of `wolfcal capture`: renders the simulated robot as the bus emulator holds it.

The head camera at its true kinematics, or an external camera (`external=NAME`) from its placement in the emulator's
truth file (`external_cameras.<NAME>.T_base_camera`, as `wolfcal simulate --system external` writes it), else from
`DEFAULT_PLACEMENT`: 1.2 m in front of base_link, 0.5 m above it, looking at the legs. The head camera also sees the
floor tags at their true places when the truth file has them (`floor_tags`, as `wolfcal simulate --floor` writes it).
With `field` (a field capture) the head camera sees the robot config's field instead (`sim.field_scene`), the robot
standing at its true place there: the truth file's `field_pose` (as `wolfcal simulate --system field` writes it),
else exactly at `field.robot_at`. With `field_check` (the held-out field views) it stands at `field.check_at`, off
from it as far as the truth's place is off from `field.robot_at` (x, y and yaw alike).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.capture.field import field_place
from wolfcal.hardware.emulator import load_truth, read_true_angles, truth_file_of
from wolfcal.io.truth import load_external_truth, load_field_pose, load_floor_places
from wolfcal.placement import TARGET_BASE, look_at
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.sim.field_scene import FieldSimScene
from wolfcal.sim.scene import SimScene

DEFAULT_PLACEMENT = look_at(np.array([1.2, 0.0, 0.5]), TARGET_BASE)  # (4, 4) T_base_camera


class SimCamera:
    """Renders the robot as the bus emulators on `ports` hold it (true angles, true frames and tags; the truth file
    of the first emulator that has one), or with `field` the field it stands on (module docstring)."""

    def __init__(self, robot: Robot, ports: list[str], camera: CameraModel, seed: int = 0, external: str | None = None,
                 field: bool = False, field_check: bool = False):  # fmt: skip
        self.name, self.ports, self.robot = "sim", ports, robot
        self._read = read_true_angles
        truth_path = truth_file_of(ports)
        truth = load_truth(Path(truth_path)) if truth_path else Corrections()
        T_base_camera, floor_places = None, None
        if external is None and truth_path:
            floor_places = load_floor_places(Path(truth_path))
        if external is not None:
            placements = load_external_truth(Path(truth_path)) if truth_path else {}
            T_base_camera = placements.get(external, DEFAULT_PLACEMENT)
        self.scene: SimScene | FieldSimScene
        if field and external is None:
            config = robot.config.field_config("the simulated camera renders the field the robot stands on")
            pose = load_field_pose(Path(truth_path)) if truth_path else None
            pose = np.asarray(config.robot_at, float) if pose is None else pose
            if field_check:
                pose = np.asarray(field_place(robot, check=True), float) + pose - np.asarray(config.robot_at, float)
            self.scene = FieldSimScene(robot, truth, camera, config.dimensions, pose, seed=seed)
        else:
            self.scene = SimScene(robot, truth, camera, seed=seed, T_base_camera=T_base_camera,
                                  floor_places=floor_places)  # fmt: skip

    def grab(self) -> np.ndarray:
        angles: dict[str, float] = {}
        for port in self.ports:
            angles.update(self._read(port)[0])
        q_true = np.array([angles.get(n, 0.0) for n in self.robot.joint_names])
        return self.scene.render_true(q_true)

    def close(self) -> None:
        pass
