"""Edit a URDF's text in place: set attributes of a joint's <origin> or <calibration>, add them when missing, and
keep every other byte of the file as it was (comments, line endings, quoting, <transmission>, <gazebo>, meshes).

Only the `<joint>` elements that are direct children of `<robot>` are the robot's joints; a `<joint name=...>` inside
`<transmission>` or `<gazebo>` is not one and is never touched. The text must already have been checked as a URDF
(`read_urdf_xml`): this module only finds where elements start and end.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

# Markup of an XML document, one token per match: comments, CDATA, processing instructions and the DOCTYPE are
# skipped whole; an end tag gives its name (group 1); a start or empty tag its name (2), attributes (3) and '/' (4).
_TOKEN = re.compile(
    r"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<!DOCTYPE(?:[^>\[]|\[.*?\])*>"
    r"|</\s*([^\s>]+)\s*>"
    r"|<([^\s/>!?]+)((?:\s+[^\s=/>]+\s*=\s*(?:\"[^\"]*\"|'[^']*'))*)\s*(/?)>",
    re.S,
)


@dataclass
class Element:
    """Where one element lies in the text: its start tag [start, start_end), and the end of the whole element."""

    tag: str
    start: int
    start_end: int
    end: int
    name: str | None = None  # its name="..." attribute
    children: list[Element] = field(default_factory=list)  # direct child elements

    def child(self, tag: str) -> Element | None:
        return next((c for c in self.children if c.tag == tag), None)


def robot_joints(text: str) -> dict[str, Element]:
    """The `<joint>` elements that are direct children of `<robot>`, by name, each with its direct children."""
    stack: list[Element] = []
    joints: dict[str, Element] = {}
    for match in _TOKEN.finditer(text):
        end_name, start_name, attributes, empty = match.groups()
        if end_name is not None:
            element = stack.pop()
            element.end = match.end()
            _finish(element, stack, joints)
        elif start_name is not None:
            name = _attribute(attributes, "name")
            element = Element(start_name, match.start(), match.end(), match.end(), name)
            if empty:
                _finish(element, stack, joints)
            else:
                stack.append(element)
    return joints


def _finish(element: Element, stack: list[Element], joints: dict[str, Element]) -> None:
    """Attach a closed element to its parent; record it when it is a joint directly under the root."""
    if stack:
        stack[-1].children.append(element)
    if len(stack) == 1 and element.tag == "joint" and element.name is not None:
        joints[element.name] = element


def _attribute(attributes: str, key: str) -> str | None:
    found = re.search(rf"(?:^|\s){re.escape(key)}\s*=\s*(\"([^\"]*)\"|'([^']*)')", attributes)
    if found is None:
        return None
    return found.group(2) if found.group(2) is not None else found.group(3)


def set_attributes(start_tag: str, values: dict[str, str]) -> str:
    """A start tag's text with each attribute of `values` set (replaced in place, or appended before '>')."""
    for key, value in values.items():
        found = re.search(rf"(\s{re.escape(key)}\s*=\s*)(\"[^\"]*\"|'[^']*')", start_tag)
        if found is not None:
            start_tag = f'{start_tag[: found.start(2)]}"{value}"{start_tag[found.end(2) :]}'
        else:
            close = len(start_tag) - (2 if start_tag.endswith("/>") else 1)
            start_tag = f'{start_tag[:close].rstrip()} {key}="{value}"{start_tag[close:]}'
    return start_tag


@dataclass
class JointEdit:
    """What to write into one joint: attributes of its <origin> and of its <calibration> (None: leave it)."""

    origin: dict[str, str] | None = None
    calibration: dict[str, str] | None = None


def apply_joint_edits(text: str, edits: dict[str, JointEdit]) -> str:
    """`text` with the edits made to the robot's joints of those names (all must exist: KeyError otherwise).
    A missing <origin> is added as the joint's first child, a missing <calibration> as its last, indented like
    the joint's other children and with the file's own line ending."""
    joints = robot_joints(text)
    newline = "\r\n" if "\r\n" in text else "\n"
    pieces: list[tuple[int, int, str]] = []  # (start, end, replacement), not overlapping
    for name, edit in edits.items():
        joint = joints[name]
        indent = _child_indent(text, joint)
        for tag, values, first in (("origin", edit.origin, True), ("calibration", edit.calibration, False)):
            if values is None:
                continue
            child = joint.child(tag)
            if child is not None:
                pieces.append(
                    (child.start, child.start_end, set_attributes(text[child.start : child.start_end], values))
                )
                continue
            element = set_attributes(f"<{tag}/>", values)
            if first:
                pieces.append((joint.start_end, joint.start_end, f"{newline}{indent}{element}"))
                continue
            close = text.rindex("<", joint.start, joint.end)  # the joint's end tag
            if _line_indent(text, close) or text[close - 1 : close] == "\n":  # the end tag begins its own line
                line_start = text.rfind("\n", 0, close) + 1
                pieces.append((line_start, line_start, f"{indent}{element}{newline}"))
            else:
                pieces.append((close, close, element))
    for start, end, replacement in sorted(pieces, reverse=True):
        text = text[:start] + replacement + text[end:]
    return text


def _line_indent(text: str, position: int) -> str:
    """The spaces and tabs from the start of the line of `position` up to it (empty when other text precedes)."""
    line_start = text.rfind("\n", 0, position) + 1
    prefix = text[line_start:position]
    return prefix if prefix.strip(" \t") == "" else ""


def _child_indent(text: str, joint: Element) -> str:
    """How the joint's children are indented (its own indent plus two spaces when it has none on their own line)."""
    for child in joint.children:
        indent = _line_indent(text, child.start)
        if indent:
            return indent
    return _line_indent(text, joint.start) + "  "
