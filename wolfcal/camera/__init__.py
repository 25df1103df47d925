"""Camera intrinsics: models, projection with distortion, camera_info YAML I/O."""

from wolfcal.camera.model import CameraModel

__all__ = ["CameraModel"]
