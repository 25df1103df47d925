"""Reading YAML input files with errors that name the file and say what to do."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from wolfcal.errors import WolfcalError


def read_yaml(path: Path, what: str, hint: str = "") -> Any:
    """Parse the YAML file `path` (a `what`, e.g. "camera_info file"); missing or malformed -> WolfcalError."""
    if not path.is_file():
        raise WolfcalError(f"{path}: {what} not found" + (f" ({hint})" if hint else ""))
    try:
        return yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise WolfcalError(f"{path}: not valid YAML ({exc})") from None
