"""Analytic first derivatives of forward kinematics: how points on links move when joints or parameters change.

Every small change of a joint reading or a free parameter moves the links below it rigidly. That motion is a
spatial twist in the root frame, (v0, w): a point x [m, root frame] moves by dx = v0 + w x x per unit change.
`ChainDerivatives` gathers, for each link (and each tag mounted on a link), the twists of every joint column
(S, J, 6) and of every chain parameter (S, P, 6). A point seen from a viewer frame then moves by
R_root_viewer^T [(twist of the point's frame - twist of the viewer's frame) at the point]: parameters above both
cancel. One forward-kinematics pass gives all of it; no residual is evaluated per parameter.
"""

from __future__ import annotations

import numpy as np

from wolfcal.geometry import right_jacobian_so3
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.kinematics import JointModel, Walk
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (broadcast), without np.cross's overhead."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def tag_key(tag_id: int) -> str:
    """The key of a tag's frame among the links in `ChainDerivatives`."""
    return f"tag:{tag_id}"


def _motion_twists(joints: list[JointModel], T_root_frames: list[np.ndarray]) -> list[np.ndarray]:
    """(S, 6) spatial twist (v0, w) of one unit of each joint's motion, from the joints' frames T_root_frame
    (S, 4, 4); all joints in one pass."""
    if not joints:
        return []
    frames = np.stack(T_root_frames)  # (K, S, 4, 4)
    R, a = frames[:, :, :3, :3], np.stack([j.axis for j in joints])[:, None, None, :]  # (K, S, 3, 3), (K, 1, 1, 3)
    axis = R[..., 0] * a[..., 0] + R[..., 1] * a[..., 1] + R[..., 2] * a[..., 2]  # (K, S, 3): faster than einsum
    prismatic = np.array([j.type == "prismatic" for j in joints])[:, None, None]
    v0 = np.where(prismatic, axis, cross(frames[:, :, :3, 3], axis))
    return list(np.concatenate([v0, np.where(prismatic, 0.0, axis)], axis=2))


def _frame_twists(T_root_origin: np.ndarray, T_root_frame: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """(S, 6, 6) spatial twists of the six parameters (x, y, z, rx, ry, rz) of a frame correction
    Delta = Trans(x, y, z) @ Exp(rx, ry, rz) placed after T_root_origin (giving T_root_frame), at value `delta`."""
    n = len(T_root_origin)
    out = np.zeros((n, 6, 6))
    out[:, :3, :3] = np.swapaxes(T_root_origin[:, :3, :3], 1, 2)  # translation i moves along origin axis i
    w = T_root_frame[:, :3, :3] @ right_jacobian_so3(delta[3:])  # (S, 3, 3): column i = w of rotation param i
    w = np.swapaxes(w, 1, 2)  # (S, 3 params, 3)
    out[:, 3:, 3:] = w
    out[:, 3:, :3] = cross(T_root_frame[:, None, :3, 3], w)
    return out


class ChainDerivatives:
    """Poses and twists of the links and tags that a set of observations needs, at one set of readings q (S, J).

    Parameters of kind 'offset', 'frame' and 'tag' are chain parameters; others (e.g. an external camera's pose)
    have zero twist here and are handled by the measurement block that owns them.
    """

    def __init__(
        self,
        robot: Robot,
        q: np.ndarray,
        corrections: Corrections,
        params: ParameterSet,
        links: list[str],
        tag_ids: list[int],
    ) -> None:
        self.robot, self.params = robot, params
        model = robot.model
        tag_links = [robot.config.tag(t).link for t in tag_ids]
        walk: Walk = model.walk(q, list(dict.fromkeys(links + tag_links)), corrections)
        self.T_root: dict[str, np.ndarray] = dict(walk.T_root_link)
        n, n_joints, n_params = len(np.atleast_2d(q)), len(robot.joint_names), len(params)
        # Per walked joint: (columns it moves with their multipliers, its unit motion twist).
        joint_q: dict[str, list[tuple[int, np.ndarray]]] = {}
        joint_p: dict[str, list[tuple[int, np.ndarray]]] = {}
        offset_cols = {p.target: i for i, p in enumerate(params.parameters) if p.kind == "offset"}
        frame_cols: dict[str, list[int]] = {}
        for i, p in enumerate(params.parameters):
            if p.kind == "frame":
                frame_cols.setdefault(p.target, []).append(i)
        moving = [model.joints[name] for name in walk.T_root_frame
                  if model.joints[name].actuated or model.joints[name].mimic is not None]  # fmt: skip
        unit_twists = dict(zip([j.name for j in moving],
                               _motion_twists(moving, [walk.T_root_frame[j.name] for j in moving])))  # fmt: skip
        for name, T_root_frame in walk.T_root_frame.items():
            joint = model.joints[name]
            q_terms, p_terms = [], []
            if name in unit_twists:
                master, multiplier = (joint.name, 1.0) if joint.mimic is None else (joint.mimic[0], joint.mimic[1])
                twist = unit_twists[name] if multiplier == 1.0 else multiplier * unit_twists[name]
                q_terms.append((model.column(master), twist))
                if master in offset_cols:
                    p_terms.append((offset_cols[master], twist))
            if name in frame_cols:
                delta = corrections.frames.get(name, np.zeros(6))
                twists = _frame_twists(walk.T_root_origin[name], T_root_frame, delta)
                p_terms += [(i, twists[:, params.parameters[i].component]) for i in frame_cols[name]]
            joint_q[name], joint_p[name] = q_terms, p_terms
        # Per link and tag key: the (column, twist (S, 6)) terms of the joints from the root down, in path order; the
        # dense twists (`twist_q`, `twist_p`) and the relative ones (`relative`) are sums of them, made when asked.
        self._n, self._width = n, {True: n_joints, False: n_params}
        self._terms: dict[bool, dict[str, list[tuple[int, np.ndarray]]]] = {True: {}, False: {}}
        for link in dict.fromkeys(links + tag_links):
            path = model.path_from_root(link)
            self._terms[True][link] = [term for joint in path for term in joint_q.get(joint.name, [])]
            self._terms[False][link] = [term for joint in path for term in joint_p.get(joint.name, [])]
        for tag_id, link in zip(tag_ids, tag_links):
            key = tag_key(tag_id)
            T_root_mount = self.T_root[link] @ robot.T_link_tag(tag_id)
            self.T_root[key] = self.T_root[link] @ robot.T_link_tag(tag_id, corrections)
            terms = list(self._terms[False][link])
            cols = [i for i, p in enumerate(params.parameters) if p.kind == "tag" and int(p.target) == tag_id]
            if cols:
                twists = _frame_twists(T_root_mount, self.T_root[key], corrections.tags.get(tag_id, np.zeros(6)))
                terms += [(i, twists[:, params.parameters[i].component]) for i in cols]
            self._terms[True][key], self._terms[False][key] = self._terms[True][link], terms
        self._dense: dict[tuple[bool, str], np.ndarray] = {}

    def twist_q(self, frame: str) -> np.ndarray:
        """(S, J, 6) twists of the joint readings for a link or tag key."""
        return self._twists(True, frame)

    def twist_p(self, frame: str) -> np.ndarray:
        """(S, P, 6) twists of the chain parameters for a link or tag key."""
        return self._twists(False, frame)

    def _twists(self, joints: bool, frame: str) -> np.ndarray:
        if (joints, frame) not in self._dense:
            out = np.zeros((self._n, self._width[joints], 6))
            for col, twist in self._terms[joints][frame]:
                out[:, col] += twist
            self._dense[joints, frame] = out
        return self._dense[joints, frame]

    def relative(self, frame: str, viewer: str, joints: bool) -> tuple[np.ndarray, np.ndarray]:
        """The twists of `frame` less those of `viewer` (how the frame moves relative to the viewer) of the joint
        readings (`joints`) or of the chain parameters, only in the columns where they do not cancel: the columns
        (C,) and the twists (S, 6, C) (axes ordered for d(pixel)/d(twist) @ twists). The numbers of
        twist_q/p(frame) - twist_q/p(viewer) in those columns, the other columns of which are exactly 0 (the same
        joints above both); without the (S, J or P, 6) arrays of every frame, most of whose columns are 0."""
        mine, theirs = _by_column(self._terms[joints][frame]), _by_column(self._terms[joints][viewer])
        cols = [c for c in sorted(mine.keys() | theirs.keys())
                if len(mine.get(c, [])) != len(theirs.get(c, []))
                or any(a is not b for a, b in zip(mine.get(c, []), theirs.get(c, [])))]  # fmt: skip
        out = np.empty((self._n, 6, len(cols)))
        for k, c in enumerate(cols):
            a, b = _summed(mine.get(c, [])), _summed(theirs.get(c, []))
            if a is None and b is not None:
                out[:, :, k] = -b
            elif a is not None:
                out[:, :, k] = a if b is None else a - b
        return np.array(cols, dtype=int), out


def _by_column(terms: list[tuple[int, np.ndarray]]) -> dict[int, list[np.ndarray]]:
    """The twists of each column, in the terms' order."""
    out: dict[int, list[np.ndarray]] = {}
    for col, twist in terms:
        out.setdefault(col, []).append(twist)
    return out


def _summed(twists: list[np.ndarray]) -> np.ndarray | None:
    """Their sum in order (as the dense arrays add them up: the same numbers), None for none."""
    if not twists:
        return None
    total = twists[0].copy()
    for twist in twists[1:]:
        total += twist
    return total


def point_motion(twists: np.ndarray, p_root: np.ndarray) -> np.ndarray:
    """(M, 3, K) motion of points p_root (M, 3) [m, root frame] under twists (M, K, 6)."""
    dp = twists[:, :, :3] + cross(twists[:, :, 3:], p_root[:, None, :])
    return np.swapaxes(dp, 1, 2)
