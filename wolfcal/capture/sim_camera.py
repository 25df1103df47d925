"""The `sim` camera source of `wolfcal capture`: renders the simulated robot as the bus emulator holds it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.hardware.emulator import load_truth, read_true_angles
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.sim.scene import SimScene


class SimCamera:
    """Renders the robot as the bus emulator on `port` holds it (true angles, true frames and tags)."""

    def __init__(self, robot: Robot, port: str, camera: CameraModel, seed: int = 0):
        self.name, self.port, self.robot = "sim", port, robot
        self._read = read_true_angles
        _, truth_path = read_true_angles(port)
        truth = load_truth(Path(truth_path)) if truth_path else Corrections()
        self.scene = SimScene(robot, truth, camera, seed=seed)

    def grab(self) -> np.ndarray:
        angles, _ = self._read(self.port)
        q_true = np.array([angles.get(n, 0.0) for n in self.robot.joint_names])
        return self.scene.render_true(q_true)

    def close(self) -> None:
        pass
