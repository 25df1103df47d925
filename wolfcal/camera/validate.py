"""The one check of camera intrinsics wherever they are read (camera_info YAML files and CameraInfo messages):
errors name the file (and topic) and the field, and say what a valid value looks like."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wolfcal.camera.model import MODELS, CameraModel
from wolfcal.errors import WolfcalError

# field names of the two sources, for messages
YAML_FIELDS = {
    "width": "image_width",
    "height": "image_height",
    "K": "camera_matrix.data",
    "D": "distortion_coefficients.data",
    "model": "distortion_model",
}
MESSAGE_FIELDS = {"width": "width", "height": "height", "K": "k", "D": "d", "model": "distortion_model"}
_K_NAMES = ("fx", "skew", "cx", "0", "fy", "cy", "0", "0", "1")


def numbers(where: str, field: str, values) -> np.ndarray:
    try:
        array = np.asarray(values if values is not None else [], dtype=float).ravel()
    except (TypeError, ValueError):
        raise WolfcalError(f"{where}: '{field}' must be a list of numbers, found {values!r}") from None
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise WolfcalError(f"{where}: '{field}[{bad[0]}]' is {array[bad[0]]}, not a finite number")
    return array


def _size(where: str, field: str, value) -> int:
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    ok = ok or (isinstance(value, float) and value.is_integer())
    if not ok or int(value) <= 0:
        raise WolfcalError(f"{where}: '{field}' must be a positive whole number of pixels, found {value!r}")
    return int(value)


def checked_camera(
    where: str,
    width,
    height,
    K: Sequence[float],
    D: Sequence[float],
    model: str,
    fields: dict[str, str],
    name: str = "camera",
) -> CameraModel:
    """A CameraModel from raw intrinsics, or a WolfcalError naming `where` and the field that is wrong."""
    if model not in MODELS:
        raise WolfcalError(
            f"{where}: '{fields['model']}' {model!r} is not one of {', '.join(MODELS)}; "
            "use a supported model (or pass --intrinsics FILE with one)"
        )
    width, height = _size(where, fields["width"], width), _size(where, fields["height"], height)
    k = numbers(where, fields["K"], K)
    if k.size != 9:
        raise WolfcalError(f"{where}: '{fields['K']}' must hold the 9 numbers of a 3x3 matrix, found {k.size}")
    for index in (0, 4):
        if k[index] <= 0:
            raise WolfcalError(
                f"{where}: '{fields['K']}[{index}]' ({_K_NAMES[index]}) is {k[index]:g}; a focal length must be "
                "positive (pixels); calibrate the camera (`wolfcal intrinsics`)"
            )
    if k[3] != 0 or k[6] != 0 or k[7] != 0 or k[8] != 1:
        raise WolfcalError(
            f"{where}: '{fields['K']}' must be [fx, skew, cx, 0, fy, cy, 0, 0, 1] (row-major), found "
            f"{[float(v) for v in k]}"
        )
    for index, size, axis in ((2, width, fields["width"]), (5, height, fields["height"])):
        if not 0 <= k[index] <= size:
            raise WolfcalError(
                f"{where}: '{fields['K']}[{index}]' ({_K_NAMES[index]}) = {k[index]:g} px lies outside the "
                f"{width}x{height} image of '{axis}'; the matrix and the image size do not belong together"
            )
    d = numbers(where, fields["D"], D)
    expected = MODELS[model]
    if d.size > expected and np.any(d[expected:] != 0):
        raise WolfcalError(f"{where}: '{fields['D']}' has {d.size} coefficients, the {model} model has {expected}")
    return CameraModel(width, height, k.reshape(3, 3), d[:expected], model, name)


def check_image_size(
    where: str,
    fields: dict[str, str],
    camera: CameraModel,
    size: tuple[int, int],
    advice: str = "pass --intrinsics FILE calibrated for these images",
) -> None:
    """The images (`size` = width, height) must be the intrinsics' size, or that size binned (or enlarged) by one
    whole factor in both axes; anything else is an error naming the size fields and saying `advice`."""
    (cw, ch), (w, h) = (camera.width, camera.height), size
    if any(a % b == 0 and c % d == 0 and a // b == c // d for a, b, c, d in ((cw, w, ch, h), (w, cw, h, ch))):
        return
    why = "another aspect ratio" if abs(w * ch - h * cw) > 0.01 * w * ch else "not a whole binning factor"
    raise WolfcalError(
        f"{where}: '{fields['width']}'/'{fields['height']}' say {cw}x{ch} px, the images are {w}x{h} px ({why}); "
        f"{advice}"
    )
