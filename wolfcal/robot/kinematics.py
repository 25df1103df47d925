"""URDF -> kinematic tree with forward kinematics vectorised over samples.

Joint values follow the URDF: revolute/continuous rotate about `axis` [rad], prismatic translate along it [m];
T_parent_child(q) = origin @ Delta(frame correction) @ Motion(axis, q + offset). Poses returned are `T_base_link`
(N, 4, 4) for the chosen base link. Corrections (encoder offsets, frame corrections, tag mounts) come as a
`Corrections` object, so the same code serves the nominal model, a fit in progress and a simulator's truth.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lxml import etree

from wolfcal.errors import WolfcalError
from wolfcal.geometry import invert_transform, skew, transform_from_twist_params, transform_from_xyz_rpy
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.urdf_xml import read_urdf_xml

ACTUATED_TYPES = ("revolute", "continuous", "prismatic")


@dataclass
class Walk:
    """The poses one forward-kinematics pass visits, all in the root frame (N, 4, 4) [m]."""

    T_root_link: dict[str, np.ndarray]  # every link on the walked paths
    T_root_origin: dict[str, np.ndarray]  # per walked joint: its <origin> frame, before the frame correction
    T_root_frame: dict[str, np.ndarray]  # per walked joint: after the frame correction, before the joint's motion


@dataclass(frozen=True)
class JointModel:
    name: str
    type: str  # 'fixed' | 'revolute' | 'continuous' | 'prismatic'
    parent: str
    child: str
    T_parent_origin: np.ndarray  # (4, 4) the URDF <origin>
    axis: np.ndarray  # (3,) unit axis in the joint frame
    lower: float = -np.inf
    upper: float = np.inf
    mimic: tuple[str, float, float] | None = None  # (master joint, multiplier, offset)
    in_urdf: bool = True  # False: a fixed frame the robot config adds (a body-axes camera's optical frame, a sole)

    @property
    def actuated(self) -> bool:
        return self.type in ACTUATED_TYPES and self.mimic is None


class KinematicModel:
    """A tree of joints; `actuated_joint_names` fixes the column order of joint-value arrays."""

    def __init__(self, joints: Iterable[JointModel], name: str = "robot", source: str = "URDF"):
        self.name = name
        self.source = source
        self.joints: dict[str, JointModel] = {j.name: j for j in joints}
        self.joint_to_child: dict[str, JointModel] = {}
        for joint in self.joints.values():
            if joint.child in self.joint_to_child:
                raise WolfcalError(f"{source}: link '{joint.child}' has two parent joints")
            self.joint_to_child[joint.child] = joint
        parents = {j.parent for j in self.joints.values()}
        children = set(self.joint_to_child)
        roots = sorted(parents - children) or sorted(children)[:1]
        if len(roots) != 1:
            raise WolfcalError(f"{source}: the URDF must form one tree, found roots {', '.join(roots)}")
        self.root = roots[0]
        self.links = parents | children
        _check_mimics(self.joints, source)
        self.actuated_joint_names = [j.name for j in self.joints.values() if j.actuated]
        self._column = {n: i for i, n in enumerate(self.actuated_joint_names)}
        # Per joint, the last joint values and their motion: a fit walks the same readings again at every step, and
        # the motion changes only when the joint's offset does.
        self._last_motion: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    @classmethod
    def from_urdf(cls, path: str | Path) -> KinematicModel:
        """Parse the joints of a URDF (links' geometry and meshes are not read).

        Read with `read_urdf_xml`, not a general URDF library: yourdfpy imports a mesh library and took 0.65 s
        of every short run to import; the tests check this reading against yourdfpy's."""
        path = Path(path)
        if not path.is_file():
            raise WolfcalError(f"{path}: URDF not found")
        robot = read_urdf_xml(path).getroot()
        joints = [_joint(path, element) for element in robot.findall("joint")]
        if not joints:
            raise WolfcalError(f"{path}: the URDF has no joints")
        return cls(joints, name=robot.get("name", "robot"), source=str(path))

    def with_frames(self, frames: Iterable[tuple[str, str, np.ndarray]]) -> KinematicModel:
        """This model with fixed frames added: (name, parent link, T_parent_frame (4, 4)) each, joined by a fixed
        joint of the same name that is not in the URDF (`JointModel.in_urdf` False). A WolfcalError when a name is
        taken or a parent is not a link."""
        added = []
        for name, parent, T in frames:
            if name in self.links or name in self.joints:
                raise WolfcalError(f"{self.source}: the URDF already has a link or joint named '{name}'")
            self.require_link(parent, self.source)
            added.append(JointModel(name, "fixed", parent, name, np.asarray(T, float), np.array([1.0, 0.0, 0.0]),
                                    in_urdf=False))  # fmt: skip
        return KinematicModel([*self.joints.values(), *added], self.name, self.source)

    def urdf_joint_of(self, joint: str) -> str:
        """The URDF joint a correction of `joint` is written to: itself, or for a frame the config added, the URDF
        joint above it (`urdf_parent_joint`)."""
        model = self.joints[joint]
        return joint if model.in_urdf else self.urdf_parent_joint(model.parent).name

    def urdf_parent_joint(self, link: str) -> JointModel:
        """The joint of the URDF above `link`: its parent joint, or for a frame the config added, the URDF joint above
        the link it hangs from."""
        joint = self.parent_joint(link)
        while not joint.in_urdf:
            joint = self.parent_joint(joint.parent)
        return joint

    # --- structure ------------------------------------------------------------------------------------------
    def require_link(self, link: str, where: str) -> None:
        if link not in self.links:
            raise WolfcalError(f"{where}: link/frame '{link}' is not in the URDF {self.source}")

    def path_from_root(self, link: str) -> list[JointModel]:
        """Joints from the root down to `link`, root first."""
        self.require_link(link, self.source)
        path = []
        while link != self.root:
            joint = self.joint_to_child[link]
            path.append(joint)
            link = joint.parent
        return path[::-1]

    def joints_between(self, link_a: str, link_b: str) -> list[JointModel]:
        """Joints on the path between two links (in no particular direction), excluding the shared part."""
        path_a, path_b = self.path_from_root(link_a), self.path_from_root(link_b)
        common = 0
        while common < min(len(path_a), len(path_b)) and path_a[common].name == path_b[common].name:
            common += 1
        return path_a[common:][::-1] + path_b[common:]

    def parent_joint(self, link: str) -> JointModel:
        self.require_link(link, self.source)
        if link not in self.joint_to_child:
            raise WolfcalError(f"{self.source}: link '{link}' is the root and has no parent joint")
        return self.joint_to_child[link]

    def column(self, joint: str) -> int:
        return self._column[joint]

    # --- forward kinematics -------------------------------------------------------------------------------
    def joint_values(self, joint: JointModel, q: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """(N,) model-side value of one joint from measured q (N, J) and offsets (J,)."""
        if joint.mimic is not None:
            master, multiplier, offset = joint.mimic
            col = self._column[master]
            return multiplier * (q[:, col] + offsets[col]) + offset
        col = self._column[joint.name]
        return q[:, col] + offsets[col]

    def link_poses(
        self,
        q: np.ndarray,
        links: Iterable[str],
        corrections: Corrections | None = None,
        base: str | None = None,
    ) -> dict[str, np.ndarray]:
        """T_base_link (N, 4, 4) for each requested link, from measured joint values q (N, J) [rad or m]."""
        links = list(links)
        base = base or self.root
        walk = self.walk(q, links + [base], corrections)
        T_root_base = walk.T_root_link[base]
        if base == self.root:
            return {link: walk.T_root_link[link] for link in links}
        T_base_root = invert_transform(T_root_base)
        return {link: T_base_root @ walk.T_root_link[link] for link in links}

    def walk(self, q: np.ndarray, links: Iterable[str], corrections: Corrections | None = None) -> Walk:
        """One forward-kinematics pass from the root to `links`: every link pose on the way, T_root_link
        (N, 4, 4), and every joint's frame before and after its frame correction (see `Walk`)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if q.shape[1] != len(self.actuated_joint_names):
            raise ValueError(f"q has {q.shape[1]} columns, the model has {len(self.actuated_joint_names)} joints")
        corrections = corrections or Corrections()
        offsets = corrections.offset_vector(self.actuated_joint_names)
        n = q.shape[0]
        walk = Walk({self.root: np.broadcast_to(np.eye(4), (n, 4, 4))}, {}, {})
        for link in links:
            for joint in self.path_from_root(link):
                if joint.child in walk.T_root_link:
                    continue
                T_root_origin = walk.T_root_link[joint.parent] @ joint.T_parent_origin
                delta = corrections.frames.get(joint.name)
                T_root_frame = T_root_origin if delta is None else T_root_origin @ transform_from_twist_params(delta)
                walk.T_root_origin[joint.name] = T_root_origin
                walk.T_root_frame[joint.name] = T_root_frame
                if joint.actuated or joint.mimic is not None:
                    T_root_frame = T_root_frame @ self._motion_at(joint, self.joint_values(joint, q, offsets))
                walk.T_root_link[joint.child] = T_root_frame
        return walk

    def _motion_at(self, joint: JointModel, values: np.ndarray) -> np.ndarray:
        """`_motion`, reused when the joint's values are those of the previous call (the array is not to be
        changed in place)."""
        last = self._last_motion.get(joint.name)
        if last is not None and last[0].shape == values.shape and np.array_equal(last[0], values):
            return last[1]
        motion = self._motion(joint, values)
        self._last_motion[joint.name] = (values.copy(), motion)
        return motion

    @staticmethod
    def _motion(joint: JointModel, values: np.ndarray) -> np.ndarray:
        """(N, 4, 4) motion of a joint by `values` (N,) about/along its axis, in the joint frame."""
        out = np.zeros((len(values), 4, 4))
        out[:, 3, 3] = 1.0
        if joint.type == "prismatic":
            out[:, :3, :3] = np.eye(3)
            out[:, :3, 3] = values[:, None] * joint.axis
            return out
        # Rodrigues with the fixed unit axis: R = I + sin(q) K + (1 - cos(q)) K^2.
        K = skew(joint.axis)
        out[:, :3, :3] = np.eye(3) + np.sin(values)[:, None, None] * K + (1.0 - np.cos(values))[:, None, None] * (K @ K)
        return out


def _check_mimics(joints: dict[str, JointModel], source: str) -> None:
    """Every mimic joint must follow a movable joint of the URDF that is not a mimic joint itself."""
    for joint in joints.values():
        if joint.mimic is None:
            continue
        master = joints.get(joint.mimic[0])
        if master is None or not master.actuated:
            why = "is not in the URDF" if master is None else "is not a movable joint without <mimic>"
            raise WolfcalError(
                f"{source}: joint '{joint.name}' mimics joint '{joint.mimic[0]}', which {why}; fix the <mimic "
                f"joint=...> of '{joint.name}' to name a movable joint of this URDF"
            )


def _numbers(path: Path, joint: str, element: etree._Element | None, key: str, default: list[float]) -> np.ndarray:
    """The attribute `key` of `element` as a 3-vector (`default` when either is absent)."""
    text = None if element is None else element.get(key)
    if text is None:
        return np.array(default, dtype=float)
    try:
        values = np.array([float(v) for v in text.split()])
    except ValueError:
        values = np.array([])
    if values.shape != (3,) or not np.all(np.isfinite(values)):
        tag = "?" if element is None else element.tag
        raise WolfcalError(f"{path}: joint '{joint}': {tag} {key}=\"{text}\" must be three numbers")
    return values


def _number(path: Path, joint: str, element: etree._Element, key: str, default: float) -> float:
    text = element.get(key)
    try:
        return default if text is None else float(text)
    except ValueError:
        raise WolfcalError(f"{path}: joint '{joint}': {element.tag} {key}=\"{text}\" is not a number") from None


def _joint(path: Path, element: etree._Element) -> JointModel:
    """One <joint> element -> JointModel (URDF defaults: identity origin, axis x, no limits, mimic 1x + 0)."""
    name = element.get("name")
    kind = element.get("type")
    parent, child = element.find("parent"), element.find("child")
    if not name or not kind or parent is None or child is None or not parent.get("link") or not child.get("link"):
        raise WolfcalError(
            f"{path}: cannot read the URDF (joint '{name}' lacks its name, type, <parent link> or <child link>)"
        )
    origin = element.find("origin")
    T_parent_origin = transform_from_xyz_rpy(
        _numbers(path, name, origin, "xyz", [0.0, 0.0, 0.0]), _numbers(path, name, origin, "rpy", [0.0, 0.0, 0.0])
    )
    axis = _numbers(path, name, element.find("axis"), "xyz", [1.0, 0.0, 0.0])
    norm = np.linalg.norm(axis)
    if kind in ACTUATED_TYPES and norm < 1e-12:
        raise WolfcalError(f"{path}: joint '{name}' has a zero axis")
    lower, upper = -np.inf, np.inf
    limit = element.find("limit")
    if kind in ("revolute", "prismatic") and limit is not None:
        lower, upper = _number(path, name, limit, "lower", -np.inf), _number(path, name, limit, "upper", np.inf)
    mimic = None
    if (tag := element.find("mimic")) is not None:
        mimic = (str(tag.get("joint")), _number(path, name, tag, "multiplier", 1.0),
                 _number(path, name, tag, "offset", 0.0))  # fmt: skip
    return JointModel(name, kind, parent.get("link"), child.get("link"), T_parent_origin, axis / max(norm, 1e-12),
                      lower, upper, mimic)  # fmt: skip
