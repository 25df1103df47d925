"""YAML in and out: input files with errors that name the file and say what to do; output with the C emitter.

PyYAML's C bindings (libyaml: `CSafeLoader`, `CSafeDumper`) are used where PyYAML was built with them, the
pure-Python ones otherwise; same safe subset, same output. The C emitter writes a large file like an
intrinsics report's detections.yaml about 10x faster (bench/bench_detection.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

try:
    from yaml import CSafeDumper as _Dumper
    from yaml import CSafeLoader as _Loader
except ImportError:  # PyYAML without libyaml
    from yaml import SafeDumper as _Dumper  # type: ignore[assignment]
    from yaml import SafeLoader as _Loader  # type: ignore[assignment]

from wolfcal.errors import WolfcalError


def dump_yaml(data: Any, **options: Any) -> str:
    """`yaml.safe_dump(data, **options)` with the C emitter where available."""
    return yaml.dump(data, Dumper=_Dumper, **options)


def load_yaml(text: str) -> Any:
    """`yaml.safe_load(text)` with the C parser where available (raises yaml.YAMLError)."""
    return yaml.load(text, Loader=_Loader)


def read_yaml(path: Path, what: str, hint: str = "") -> Any:
    """Parse the YAML file `path` (a `what`, e.g. "camera_info file"); missing or malformed -> WolfcalError."""
    if not path.is_file():
        raise WolfcalError(f"{path}: {what} not found" + (f" ({hint})" if hint else ""))
    try:
        return load_yaml(path.read_text())
    except yaml.YAMLError as exc:
        raise WolfcalError(f"{path}: not valid YAML ({exc})") from None
