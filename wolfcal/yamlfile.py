"""YAML in and out: input files with errors that name the file and say what to do; output with the C emitter.

PyYAML's C bindings (libyaml: `CSafeLoader`, `CSafeDumper`) are used where PyYAML was built with them, the
pure-Python ones otherwise; same safe subset, same output, and the C emitter writes a large file like an
intrinsics report's detections.yaml many times faster. `dump_yaml_pieces` gives the same
text in small pieces (a long fit's result.yaml without the whole document's node tree in memory).
"""

from __future__ import annotations

from collections.abc import Iterator
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


# Items of a long list dumped in one call by `dump_yaml_pieces`: the emitter's node tree of a few hundred items (a
# few hundred KB) instead of the whole document's (about 20 bytes of memory per byte of output)
PIECE_ITEMS = 256


def dump_yaml_pieces(data: Any, width: int = 80, **options: Any) -> Iterator[str]:
    """`dump_yaml(data, width=width, **options)` in pieces whose concatenation is the same text, for a mapping in
    block style (the default): lists longer than PIECE_ITEMS, at any depth under mappings and list items, are dumped
    PIECE_ITEMS items at a time; anything else in one call. Same text because PyYAML writes a mapping's list
    without indentation, so a piece dumped alone and indented by its depth is what the whole dump writes (its line
    width reduced by that indentation: lines fold at the same columns)."""
    if isinstance(data, dict) and data and _large(data):
        yield from _mapping_pieces(data, 0, width, options)
    else:
        yield dump_yaml(data, width=width, **options)


def _large(value: Any) -> bool:
    """Whether `dump_yaml_pieces` splits something inside `value`."""
    if isinstance(value, dict):
        return any(_large(v) for v in value.values())
    if isinstance(value, list):
        return len(value) > PIECE_ITEMS or any(_large(v) for v in value)
    return False


def _indented(data: Any, indent: int, width: int, options: dict[str, Any]) -> str:
    text = dump_yaml(data, width=width - indent, **options)
    return text if indent == 0 else "".join(" " * indent + line for line in text.splitlines(keepends=True))


def _mapping_pieces(data: dict, indent: int, width: int, options: dict[str, Any]) -> Iterator[str]:
    """A block mapping's entries at `indent`, each large list or mapping value in pieces."""
    for key, value in data.items():
        if isinstance(value, list) and value and _large(value):
            header = _indented({key: [None]}, indent, width, options)  # 'key:' and a placeholder item
            yield header[: header.rindex("\n", 0, -1) + 1]
            yield from _list_pieces(value, indent, width, options)
        elif isinstance(value, dict) and value and _large(value):
            header = _indented({key: {None: None}}, indent, width, options)
            yield header[: header.rindex("\n", 0, -1) + 1]
            yield from _mapping_pieces(value, indent + 2, width, options)
        else:
            yield _indented({key: value}, indent, width, options)


def _list_pieces(items: list, indent: int, width: int, options: dict[str, Any]) -> Iterator[str]:
    """A block sequence's items ('- ' at `indent`): runs of small items PIECE_ITEMS at a time; a large mapping
    item entry by entry (its first line starts with the dash)."""
    run: list[Any] = []
    for item in items:
        if isinstance(item, dict) and item and _large(item):
            if run:
                yield _indented(run, indent, width, options)
                run = []
            pieces = _mapping_pieces(item, indent + 2, width, options)
            first = next(pieces)
            yield first[:indent] + "- " + first[indent + 2 :]
            yield from pieces
        else:
            run.append(item)
            if len(run) == PIECE_ITEMS:
                yield _indented(run, indent, width, options)
                run = []
    if run:
        yield _indented(run, indent, width, options)


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
