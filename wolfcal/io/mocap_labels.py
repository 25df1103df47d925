"""The robot config's marker names matched to the labels a motion-capture source writes.

A file labels a marker as its system names it: `Subject:Marker` (Vicon Nexus), `Asset:Marker` (Motive), or the bare
name (a ROS 2 Markers topic, many C3D writers). A configured name matches the label equal to it; failing that, the
one label whose part after the last ':' equals it (the short name). Two or more such labels (`Box:Marker1`,
`Left:Marker1`) make the short name ambiguous: an error lists them, and the config must name the marker in full.
Each label serves at most one configured name.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from wolfcal.errors import WolfcalError


@dataclass
class LabelMatch:
    found: list[str]  # configured names found in the source, in config order
    columns: list[int]  # (len(found),) column of each in the source's labels
    missing: list[str]  # configured names not in the source, in config order
    extra: list[str]  # labels of the source that no configured name matched, in column order


def short_name(label: str) -> str:
    """The marker name without its subject or asset prefix: 'robot:r_foot_fl' -> 'r_foot_fl'."""
    return label.rsplit(":", 1)[-1].strip()


def match_names(path: Path | str, names: list[str], labels: list[str]) -> LabelMatch:
    """Match configured `names` to a source's `labels` (rules of the module docstring)."""
    found: list[str] = []
    columns: list[int] = []
    missing: list[str] = []
    for name in names:
        if name in labels:
            column = labels.index(name)
        else:
            candidates = [i for i, label in enumerate(labels) if short_name(label) == name]
            if len(candidates) > 1:
                listed = ", ".join(repr(labels[i]) for i in candidates)
                raise WolfcalError(
                    f"{path}: the robot config's marker {name!r} matches {len(candidates)} labels "
                    f"({listed}); name it in full in 'markers.list' (e.g. {labels[candidates[0]]!r})"
                )
            if not candidates:
                missing.append(name)
                continue
            column = candidates[0]
        if column in columns:
            other = found[columns.index(column)]
            raise WolfcalError(
                f"{path}: the robot config's markers {other!r} and {name!r} both match the label "
                f"{labels[column]!r}; give each marker its own name"
            )
        found.append(name)
        columns.append(column)
    extra = [label for i, label in enumerate(labels) if i not in set(columns)]
    return LabelMatch(found, columns, missing, extra)
