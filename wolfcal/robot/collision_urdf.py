"""The URDF's `<collision>` geometry as capsule segments that bound it (read with the project's strict URDF parser).

Per `<collision>` element, in its link's frame [m]:
- cylinder: its axis, radius as given; sphere: a point with its radius;
- box: the segment along its longest edge (full length) with radius half the diagonal of the other two edges, so the
  capsule contains the box;
- mesh (`filename` relative to the URDF, `file://`, or `package://NAME/...` looked up in the URDF's folder and its
  parents): the same capsule around the mesh's oriented bounding box (its vertices, scaled by `scale`; trimesh
  reads STL, OBJ, PLY, DAE). A mesh is bounded, not modelled: a long bent link is fattened to its box.
"""

from __future__ import annotations

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


def box_capsule(T_link_box: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Capsule (start, end in the link frame, radius) containing a box of edges `size` (3,) centred at T_link_box."""
    k = int(np.argmax(size))
    half = 0.5 * size[k] * T_link_box[:3, k]
    return T_link_box[:3, 3] - half, T_link_box[:3, 3] + half, 0.5 * float(np.linalg.norm(np.delete(size, k)))


def mesh_path(urdf: Path, filename: str) -> Path:
    """The file a mesh's `filename` names; a clear error when it is not found."""
    if filename.startswith("file://"):
        tries = [Path(filename[len("file://"):])]
    elif filename.startswith("package://"):
        package, _, rest = filename[len("package://"):].partition("/")
        folders = [urdf.resolve().parent, *urdf.resolve().parents]
        tries = [f / package / rest for f in folders] + [f / rest for f in folders]
    else:
        tries = [urdf.parent / filename]
    for path in tries:
        if path.is_file():
            return path
    raise WolfcalError(f"{urdf}: collision mesh '{filename}' not found (looked at {tries[0]}); put the mesh there, or "
                       "replace it by a box, cylinder or sphere")  # fmt: skip


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


def urdf_collision_segments(urdf: str | Path) -> list[Segment]:
    """Bounding capsules of every `<collision>` of the URDF (see the module docstring); empty when it has none."""
    urdf = Path(urdf)
    segments: list[Segment] = []
    for link in read_urdf_xml(urdf).getroot().iter("link"):
        for collision in link.iter("collision"):
            origin = collision.find("origin")
            T = np.eye(4) if origin is None else transform_from_xyz_rpy(
                _numbers(urdf, origin, "xyz", 3, "0 0 0"), _numbers(urdf, origin, "rpy", 3, "0 0 0"))  # fmt: skip
            geometry = collision.find("geometry")
            shape = None if geometry is None or not len(geometry) else geometry[0]
            name = link.get("name", "?")
            if shape is None:
                raise WolfcalError(f"{urdf}: link '{name}' has a <collision> without geometry")
            if shape.tag == "cylinder":
                half = 0.5 * _numbers(urdf, shape, "length", 1)[0] * T[:3, 2]
                a, b, radius = T[:3, 3] - half, T[:3, 3] + half, _numbers(urdf, shape, "radius", 1)[0]
            elif shape.tag == "sphere":
                a, b, radius = T[:3, 3], T[:3, 3], _numbers(urdf, shape, "radius", 1)[0]
            elif shape.tag == "box":
                a, b, radius = box_capsule(T, _numbers(urdf, shape, "size", 3))
            elif shape.tag == "mesh":
                path = mesh_path(urdf, shape.get("filename", ""))
                T_mesh_box, size = mesh_box(urdf, path, _numbers(urdf, shape, "scale", 3, "1 1 1"))
                a, b, radius = box_capsule(T @ T_mesh_box, size)
            else:
                raise WolfcalError(f"{urdf}: link '{name}': <collision> geometry <{shape.tag}> is not a URDF shape")
            segments.append((name, np.asarray(a, float), np.asarray(b, float), float(radius)))
    return segments
