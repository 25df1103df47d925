"""Shared fixtures: the default Wolfgang robot and its head camera (2048x1536, strong barrel distortion)."""

import os
from pathlib import Path

import pytest

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.robot.robot import load_robot

WOLFGANG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


@pytest.fixture(scope="session", autouse=True)
def detection_cache_dir(tmp_path_factory):
    """Tests never read or write the user's detection cache: one temporary cache folder for the session."""
    folder = tmp_path_factory.mktemp("detection-cache")
    previous = os.environ.get("WOLFCAL_CACHE_DIR")
    os.environ["WOLFCAL_CACHE_DIR"] = str(folder)
    yield folder
    if previous is None:
        os.environ.pop("WOLFCAL_CACHE_DIR", None)
    else:
        os.environ["WOLFCAL_CACHE_DIR"] = previous


@pytest.fixture(scope="session")
def robot():
    return load_robot(WOLFGANG)


@pytest.fixture(scope="session")
def camera():
    """2048x1536, plumb_bob with k1 = -0.286 (the Wolfgang's Basler camera)."""
    return load_camera_info(WOLFGANG / "basler_acA2040.yaml")
