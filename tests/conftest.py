"""Shared fixtures: the default Wolfgang robot and its head camera (2048x1536, strong barrel distortion)."""

from pathlib import Path

import pytest

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.robot.robot import load_robot

WOLFGANG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


@pytest.fixture(scope="session")
def robot():
    return load_robot(WOLFGANG)


@pytest.fixture(scope="session")
def camera():
    """2048x1536, plumb_bob with k1 = -0.286 (the Wolfgang's Basler camera)."""
    return load_camera_info(WOLFGANG / "basler_acA2040.yaml")
