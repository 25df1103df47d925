"""The URDF's `<collision>` geometry as capsule segments that bound it (read with the project's strict URDF parser).

Per `<collision>` element, in its link's frame [m]:
- cylinder: its axis, radius as given; capsule (urdfdom's `<capsule radius length>`): the same, `length` being the
  part between the caps; sphere: a point with its radius;
- box: capsules along its longest edge (full length) over strips of its middle edge, radius half the diagonal of a
  strip's cross-section, so that their union contains the box (`box_capsules`);
- mesh (`filename` relative to the URDF, `file://`, or `package://NAME/...` looked up in the URDF's folder and its
  parents): the capsules of the mesh's oriented bounding box (its vertices, scaled by `scale`; trimesh reads STL,
  OBJ, PLY, DAE). A mesh is bounded, not modelled: a long bent link is fattened to its box. Published robot
  descriptions often reference meshes they do not ship: a mesh not found is skipped and reported, never an error.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lxml import etree

from wolfcal.errors import WolfcalError
from wolfcal.geometry import transform_from_xyz_rpy
from wolfcal.robot.urdf_xml import read_urdf_xml

Segment = tuple[str, np.ndarray, np.ndarray, float]  # link, start (3,), end (3,) in the link frame [m], radius [m]


def _numbers(urdf: Path, element: etree._Element, key: str, count: int, default: str | None = None) -> np.ndarray:
    text = element.get(key, default)
    try:
        values = np.array([float(v) for v in (text or "").split()])
    except ValueError:
        values = np.array([])
    if values.shape != (count,) or not np.all(np.isfinite(values)):
        raise WolfcalError(f"{urdf}: <{element.tag} {key}=\"{text}\"> (line {element.sourceline}) must be "
                           f"{count} number{'s' if count > 1 else ''}")  # fmt: skip
    return values


BOX_SLACK_M = 0.003  # a box is covered by capsules reaching at most about this far beyond its thinnest faces [m]
BOX_STRIPS_MAX = 8  # capsules per box at most


def box_capsules(T_link_box: np.ndarray, size: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Capsules (start, end in the link frame, radius) whose union contains a box of edges `size` (3,) centred at
    T_link_box: the box is cut across its middle edge into strips; each strip's capsule runs along the longest edge
    (full length) with radius half the diagonal of the strip's cross-section. Strips are added until the capsules
    reach at most BOX_SLACK_M beyond the thinnest faces (at most BOX_STRIPS_MAX), so a plate is not bounded by one
    capsule as thick as it is wide."""
    long, mid, thin = np.argsort(size)[::-1]
    width, depth = float(size[mid]), float(size[thin])
    n = 1
    while n < BOX_STRIPS_MAX and 0.5 * np.hypot(width / n, depth) - 0.5 * depth > BOX_SLACK_M:
        n += 1
    half = 0.5 * size[long] * T_link_box[:3, long]
    radius = 0.5 * float(np.hypot(width / n, depth))
    out = []
    for k in range(n):
        centre = T_link_box[:3, 3] + ((k + 0.5) / n - 0.5) * width * T_link_box[:3, mid]
        out.append((centre - half, centre + half, radius))
    return out


def mesh_path(urdf: Path, filename: str) -> Path | None:
    """The file a mesh's `filename` names, or None when it is not found."""
    if filename.startswith("file://"):
        tries = [Path(filename[len("file://") :])]
    elif filename.startswith("package://"):
        package, _, rest = filename[len("package://") :].partition("/")
        folders = [urdf.resolve().parent, *urdf.resolve().parents]
        tries = [f / package / rest for f in folders] + [f / rest for f in folders]
    else:
        tries = [urdf.parent / filename]
    return next((path for path in tries if path.is_file()), None)


def mesh_box(urdf: Path, path: Path, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T_mesh_box (4, 4), edges (3,)) of the oriented bounding box of a mesh file's scaled vertices [m]."""
    import trimesh  # slow to import: only a URDF with collision meshes needs it

    try:
        mesh = trimesh.load(str(path), force="mesh")
        vertices = np.array(getattr(mesh, "vertices", []), dtype=np.float64).reshape(-1, 3) * scale
    except Exception as exc:  # trimesh raises many kinds for unreadable files
        raise WolfcalError(f"{urdf}: cannot read collision mesh {path} ({exc}); give an STL, OBJ, PLY or DAE") from None
    if len(vertices) < 1 or not np.all(np.isfinite(vertices)):
        raise WolfcalError(f"{urdf}: collision mesh {path} has no vertices")
    T, extents = trimesh.bounds.oriented_bounds(vertices)  # T moves the points into the box frame
    return np.linalg.inv(T), np.asarray(extents, dtype=float)


@dataclass
class UrdfCollision:
    segments: list[Segment]  # bounding capsules of every <collision> whose geometry could be read
    missing_meshes: dict[str, list[str]]  # mesh filename as written -> links whose <collision> names it (skipped)


def _segments(urdf: Path, name: str, T: np.ndarray, shape: etree._Element) -> list[Segment] | None:
    """Capsules of one <collision> shape of link `name` placed at T (link frame); None for a mesh not found."""
    if shape.tag in ("cylinder", "capsule"):  # capsule (urdfdom): `length` of the part between the two caps
        half = 0.5 * _numbers(urdf, shape, "length", 1)[0] * T[:3, 2]
        capsules = [(T[:3, 3] - half, T[:3, 3] + half, _numbers(urdf, shape, "radius", 1)[0])]
    elif shape.tag == "sphere":
        capsules = [(T[:3, 3], T[:3, 3], _numbers(urdf, shape, "radius", 1)[0])]
    elif shape.tag == "box":
        capsules = box_capsules(T, _numbers(urdf, shape, "size", 3))
    elif shape.tag == "mesh":
        path = mesh_path(urdf, shape.get("filename", ""))
        if path is None:
            return None
        T_mesh_box, size = mesh_box(urdf, path, _numbers(urdf, shape, "scale", 3, "1 1 1"))
        capsules = box_capsules(T @ T_mesh_box, size)
    else:
        raise WolfcalError(f"{urdf}: link '{name}': <collision> geometry <{shape.tag}> is not a URDF shape")
    return [(name, np.asarray(a, float), np.asarray(b, float), float(r)) for a, b, r in capsules]


def urdf_collision(urdf: str | Path) -> UrdfCollision:
    """Bounding capsules of every `<collision>` of the URDF (see the module docstring) and the collision meshes that
    were not found (their <collision> is skipped); no segments when it has no <collision>."""
    urdf = Path(urdf)
    out = UrdfCollision([], {})
    for link in read_urdf_xml(urdf).getroot().findall("link"):
        name = link.get("name", "?")
        for collision in link.findall("collision"):
            origin = collision.find("origin")
            T = np.eye(4) if origin is None else transform_from_xyz_rpy(
                _numbers(urdf, origin, "xyz", 3, "0 0 0"), _numbers(urdf, origin, "rpy", 3, "0 0 0"))  # fmt: skip
            geometry = collision.find("geometry")
            if geometry is None or not len(geometry):
                raise WolfcalError(f"{urdf}: link '{name}' has a <collision> without geometry")
            shape = geometry[0]
            segments = _segments(urdf, name, T, shape)
            if segments is None:
                out.missing_meshes.setdefault(shape.get("filename", ""), []).append(name)
            else:
                out.segments += segments
    return out
