"""The robot's body as capsules: self-collision and line of sight, vectorised over configurations.

Capsules (`Capsule`, from `wolfcal.robot.collision_sources`) of links joined by fixed joints form one body. Body
pairs never checked: those the kinematics rule out (`wolfcal.robot.collision_pairs`: joined by one joint, or the
outer bodies of a two-axis joint), those of the config's `collision_ignore:` link pairs, and whole body pairs that
come closer than REST_CLEARANCE_M in the rest pose (`rest_pose:`, others 0), where the robot stands without harm
(MoveIt's "Default" rule; said once in `notes`). Checks go body pair by body pair: a pair whose bounding spheres
are far enough apart needs no capsule distance. Joint values are readings of the nominal model [rad]; lengths in
metres, in the root frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.robot.collision_pairs import adjacent_bodies, bodies
from wolfcal.robot.robot import Robot

REST_CLEARANCE_M = 0.005  # bodies closer than this in the rest pose are never checked against each other [m]
CHECK_BLOCK = 2_000_000  # (configuration, capsule pair) distances computed at a time by `CollisionModel.scan`
EXACT_BELOW_M = 0.05  # capsule pairs whose bounding spheres are further apart need no exact distance [m]


@dataclass(frozen=True)
class Capsule:
    link: str
    body: int  # index of the rigid body (links joined by fixed joints)
    a_link: np.ndarray  # (3,) segment start in the link frame [m]
    b_link: np.ndarray  # (3,) segment end in the link frame [m]
    radius: float  # [m]


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """(...) shortest distance between segments p0-p1 and q0-q1 ((..., 3) each, broadcast) [m] (closest points of
    two segments, Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e = np.sum(d1 * d1, -1), np.sum(d2 * d2, -1)
    b, c, f = np.sum(d1 * d2, -1), np.sum(d1 * r, -1), np.sum(d2 * r, -1)
    tiny = 1e-18
    denom = a * e - b * b
    s = np.where(denom > tiny, np.clip((b * f - c * e) / np.maximum(denom, tiny), 0.0, 1.0), 0.0)
    s = np.where(e > tiny, s, np.where(a > tiny, np.clip(-c / np.maximum(a, tiny), 0.0, 1.0), 0.0))  # q a point
    t = np.where(e > tiny, (b * s + f) / np.maximum(e, tiny), 0.0)
    s = np.where(t < 0.0, np.where(a > tiny, np.clip(-c / np.maximum(a, tiny), 0.0, 1.0), 0.0), s)
    s = np.where(t > 1.0, np.where(a > tiny, np.clip((b - c) / np.maximum(a, tiny), 0.0, 1.0), 0.0), s)
    t = np.clip(t, 0.0, 1.0)
    gap = (p0 + d1 * s[..., None]) - (q0 + d2 * t[..., None])
    return np.linalg.norm(gap, axis=-1)


class CollisionModel:
    """Capsules of a robot's links and the body pairs to check; see the module docstring."""

    def __init__(self, robot: Robot, capsules: list[Capsule], source: str, rest: np.ndarray,
                 warnings: list[str] | None = None) -> None:  # fmt: skip
        self.robot, self.capsules, self.source = robot, capsules, source
        self.warnings = list(warnings or [])  # geometry left out (collision meshes not found), to be said once
        self.notes: list[str] = []  # pairs never checked because they touch at rest, to be said once
        self.body_of_link = bodies(robot)
        self.links = sorted({c.link for c in capsules})
        self._of_link = {link: np.array([k for k, c in enumerate(capsules) if c.link == link]) for link in self.links}
        self._a_link = np.array([c.a_link for c in capsules]).reshape(-1, 3)  # (C, 3) [m]
        self._b_link = np.array([c.b_link for c in capsules]).reshape(-1, 3)
        self.radius = np.array([c.radius for c in capsules])
        self.body = np.array([c.body for c in capsules])
        i, j = np.triu_indices(len(capsules), k=1)
        keep = self.body[i] != self.body[j]
        adjacent = adjacent_bodies(robot, self.body_of_link, set(self.body.tolist()), rest)
        for a, b in robot.config.planning.collision_ignore:  # the config's pairs, as an SRDF's disable_collisions
            adjacent |= {(self.body_of_link[a], self.body_of_link[b]), (self.body_of_link[b], self.body_of_link[a])}
        keep &= ~np.array([(self.body[a], self.body[b]) in adjacent for a, b in zip(i, j)], dtype=bool)
        self.pairs = np.stack([i[keep], j[keep]], axis=1)
        rest_distance = self._pair_clearance(np.atleast_2d(rest))[0]
        body_pair = self.body[self.pairs].min(axis=1) * (len(self.body) + 1) + self.body[self.pairs].max(axis=1)
        touching = np.isin(body_pair, body_pair[rest_distance < REST_CLEARANCE_M])  # whole body pairs
        rest_pairs = sorted({self.link_pair(int(k)) for k in np.flatnonzero(rest_distance < REST_CLEARANCE_M)})
        if rest_pairs:
            self.notes.append(f"{len(rest_pairs)} link pairs closer than {REST_CLEARANCE_M * 1000:.0f} mm in the "
                              "rest pose are not checked against each other (parts built to touch, or bounds "
                              "wider than the parts): " + ", ".join(f"{a}/{b}" for a, b in rest_pairs))  # fmt: skip
        self.pairs, self.rest_distance = self.pairs[~touching], rest_distance[~touching]
        self.pair_group = np.unique(body_pair[~touching], return_inverse=True)[1].reshape(-1)  # (pairs,) body pair
        self.group_bodies = np.array([self.body[self.pairs[self.pair_group == g][0]] for g in range(
            int(self.pair_group.max()) + 1)]) if len(self.pairs) else np.zeros((0, 2), int)  # fmt: skip
        self._sphere_link, self._sphere_centre, self._sphere_radius = self._body_spheres(rest)

    def link_pair(self, k: int) -> tuple[str, str]:
        """The links (a, b) of checked capsule pair k, in name order."""
        a, b = self.capsules[self.pairs[k, 0]].link, self.capsules[self.pairs[k, 1]].link
        return (a, b) if a <= b else (b, a)

    def segments(self, q: np.ndarray, links: list[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Capsule segment ends (N, C, 3) each, in the root frame, for joint readings q (N, J); with `links`, only
        their capsules are placed (the others are NaN)."""
        links = self.links if links is None else links
        poses = self.robot.model.link_poses(np.atleast_2d(q), links)
        n = len(np.atleast_2d(q))
        a, b = np.full((n, len(self.capsules), 3), np.nan), np.full((n, len(self.capsules), 3), np.nan)
        for link in links:
            k = self._of_link[link]
            R, t = poses[link][:, :3, :3], poses[link][:, None, :3, 3]
            a[:, k] = np.swapaxes(R @ self._a_link[k].T, 1, 2) + t
            b[:, k] = np.swapaxes(R @ self._b_link[k].T, 1, 2) + t
        return a, b

    def pairs_moved_by(self, joints: list[str]) -> np.ndarray:
        """(pairs,) bool over the checked pairs: some of `joints` lies on the chain between the pair's two links, so
        their distance changes with it (the other pairs keep theirs whatever these joints do)."""
        names, model = set(joints), self.robot.model
        moved = [any(joint.name in names for joint in model.joints_between(self.capsules[self.pairs[k, 0]].link,
                                                                           self.capsules[self.pairs[k, 1]].link))
                 for k in (np.flatnonzero(self.pair_group == g)[0] for g in range(len(self.group_bodies)))]  # fmt: skip
        return np.array(moved, dtype=bool)[self.pair_group] if len(self.pairs) else np.zeros(0, dtype=bool)

    def _pair_clearance(self, q: np.ndarray, which: np.ndarray | None = None) -> np.ndarray:
        """(N, pairs) surface distance of each checked capsule pair (negative: overlap) [m]: exact below EXACT_BELOW_M,
        above it a lower bound (from the distance of the segments' midpoints), enough for every threshold used;
        `which` ((pairs,) bool) keeps some pairs only."""
        a, b = self.segments(q)
        return self._distances(a, b, self.pairs if which is None else self.pairs[which])

    def _distances(self, a: np.ndarray, b: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """(N, len(pairs)) surface distances of capsule pairs (K, 2) with segment ends a, b (N, C, 3) [m]; see
        `_pair_clearance`."""
        i, j = pairs[:, 0], pairs[:, 1]
        mid, half = 0.5 * (a + b), 0.5 * np.linalg.norm(b - a, axis=2)
        d = np.linalg.norm(mid[:, i] - mid[:, j], axis=2) - half[:, i] - half[:, j] - self.radius[i] - self.radius[j]
        n, k = np.nonzero(d < EXACT_BELOW_M)
        ik, jk = i[k], j[k]
        d[n, k] = segment_distance(a[n, ik], b[n, ik], a[n, jk], b[n, jk]) - self.radius[ik] - self.radius[jk]
        return d

    def clearance(self, q: np.ndarray, which: np.ndarray | None = None) -> np.ndarray:
        """(N,) smallest surface distance between checked bodies [m] (negative: they overlap), over the pairs
        `which` ((pairs,) bool, e.g. from `pairs_moved_by`) or all."""
        d = self._pair_clearance(q, which)
        return d.min(axis=1) if d.shape[1] else np.full(len(d), np.inf)

    def _body_spheres(self, rest: np.ndarray) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Per body (index as `body`): the link its sphere is fixed to, the centre in that link's frame (B, 3) and
        the radius (B,) [m] of a sphere containing all of the body's capsules (for `scan`'s first test)."""
        n = int(self.body.max()) + 1 if len(self.body) else 0
        a, b = (x[0] for x in self.segments(np.atleast_2d(rest)))
        poses = self.robot.model.link_poses(np.atleast_2d(rest), self.links)
        links, centres, radii = [""] * n, np.zeros((n, 3)), np.zeros(n)
        for k in set(self.body.tolist()):
            members = np.flatnonzero(self.body == k)
            ends = np.concatenate([a[members], b[members]])
            centre = 0.5 * (ends.min(axis=0) + ends.max(axis=0))
            reach = np.maximum(np.linalg.norm(a[members] - centre, axis=1), np.linalg.norm(b[members] - centre, axis=1))
            links[k] = self.capsules[members[0]].link
            T = poses[links[k]][0]
            centres[k], radii[k] = T[:3, :3].T @ (centre - T[:3, 3]), float(np.max(reach + self.radius[members]))
        return links, centres, radii

    def _centres(self, q: np.ndarray) -> np.ndarray:
        """(N, B, 3) centres of the bodies' bounding spheres in the root frame [m] at readings q (N, J)."""
        q = np.atleast_2d(q)
        poses = self.robot.model.link_poses(q, sorted(set(self._sphere_link) - {""}))
        centre = np.zeros((len(q), len(self._sphere_link), 3))
        for k, link in enumerate(self._sphere_link):
            if link:
                centre[:, k] = poses[link][:, :3, :3] @ self._sphere_centre[k] + poses[link][:, :3, 3]
        return centre

    def scan(self, q: np.ndarray, clearance_m: float, which: np.ndarray | None = None,
             stop_at_first: bool = True) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """(free (N,) bool: `clearance(q, which) >= clearance_m`, close (N, groups) bool: body pair g closer than
        clearance_m), found by body pairs, the closest in the rest pose first: a body pair whose bounding spheres
        are far enough apart needs no capsule distance; with stop_at_first a configuration is dropped at its first
        body pair that is too close (its later entries in `close` stay False)."""
        mask = np.ones(len(self.pairs), bool) if which is None else which
        groups = np.unique(self.pair_group[mask])
        bodies = set(self.group_bodies[groups].ravel().tolist())
        a, b = self.segments(q, [link for link in self.links if self.body_of_link[link] in bodies])
        centre = self._centres(q)
        rest_order = [float(self.rest_distance[self.pair_group == g].min()) for g in groups]
        mid, reach = 0.5 * (a + b), 0.5 * np.linalg.norm(b - a, axis=2) + self.radius  # (N, C) [m]
        free, close = np.ones(len(a), dtype=bool), np.zeros((len(a), len(self.group_bodies)), dtype=bool)
        for g in groups[np.argsort(rest_order, kind="stable")]:
            rows = np.flatnonzero(free) if stop_at_first else np.arange(len(a))
            i, j = self.group_bodies[g]
            gap = np.linalg.norm(centre[rows, i] - centre[rows, j], axis=1) - self._sphere_radius[[i, j]].sum()
            rows = rows[gap < clearance_m]
            ci, cj = np.flatnonzero(self.body == i), np.flatnonzero(self.body == j)
            step = max(1, CHECK_BLOCK // (len(ci) * len(cj)))
            for start in range(0, len(rows), step):
                chunk = rows[start : start + step]
                # capsules that reach the other body's sphere, then every pair of those: its exact distance
                rows_i, rows_j = np.ix_(chunk, ci), np.ix_(chunk, cj)
                near_i = (np.linalg.norm(mid[rows_i] - centre[chunk, j, None], axis=2) - reach[rows_i]
                          < clearance_m + self._sphere_radius[j])  # fmt: skip
                near_j = (np.linalg.norm(mid[rows_j] - centre[chunk, i, None], axis=2) - reach[rows_j]
                          < clearance_m + self._sphere_radius[i])  # fmt: skip
                n, x, y = np.nonzero(near_i[:, :, None] & near_j[:, None, :])
                rn, ki, kj = chunk[n], ci[x], cj[y]
                bound = np.linalg.norm(mid[rn, ki] - mid[rn, kj], axis=1) - reach[rn, ki] - reach[rn, kj]
                rn, ki, kj = rn[bound < clearance_m], ki[bound < clearance_m], kj[bound < clearance_m]
                d = segment_distance(a[rn, ki], b[rn, ki], a[rn, kj], b[rn, kj]) - self.radius[ki] - self.radius[kj]
                hit = np.unique(rn[d < clearance_m])
                free[hit], close[hit, g] = False, True
        return free, close

    def collision_free(self, q: np.ndarray, clearance_m: float, which: np.ndarray | None = None) -> np.ndarray:
        """(N,) bool: `clearance(q, which) >= clearance_m` (`scan`)."""
        return self.scan(q, clearance_m, which)[0]

    def most_colliding(self, q: np.ndarray, clearance_m: float) -> tuple[str, str, float] | None:
        """The link pair closer than clearance_m in the most of the configurations q (N, J), and that share; None
        when every configuration is free."""
        close = self.scan(q, clearance_m, stop_at_first=False)[1]
        if not close.any():
            return None
        g = int(np.argmax(close.sum(axis=0)))
        members = np.flatnonzero(self.pair_group == g)
        k = members[int(np.argmin(self.rest_distance[members]))]
        return (*self.link_pair(k), float(close[:, g].mean()))

    def rejection_hint(self, q: np.ndarray, clearance_m: float) -> str:
        """Why the model rejects the configurations q (N, J): the link pair too close in most of them and how to
        change the model; empty when none is rejected."""
        worst = self.most_colliding(q, clearance_m)
        if worst is None:
            return ""
        a, b, share = worst
        return (
            f"the collision model (capsules from {self.source}) puts {a} and {b} closer than "
            f"{clearance_m * 1000:.0f} mm in {share:.0%} of the poses drawn; if these parts cannot touch on the "
            f"robot, give 'collision_radii:' in {self.robot.config.path} (capsules between joint origins that "
            f"replace the URDF's <collision>), or 'collision_ignore: [[{a}, {b}]]' there to never check this "
            "pair (as an SRDF's disable_collisions)"
        )

    def colliding_pair(self, q: np.ndarray) -> tuple[str, str] | None:
        """The links of the closest overlapping pair at one configuration q (J,), or None."""
        d = self._pair_clearance(np.atleast_2d(q))[0]
        if not len(d) or d.min() >= 0:
            return None
        i, j = self.pairs[int(np.argmin(d))]
        return self.capsules[i].link, self.capsules[j].link

    def blocked(self, q: np.ndarray, origin: np.ndarray, points: np.ndarray, skip_bodies: np.ndarray) -> np.ndarray:
        """(N, K) bool: the straight line from `origin` (N, 3) to `points` (N, K, 3) (root frame [m]) passes
        through a capsule; capsules of the bodies in skip_bodies (K, B) (-1: none) are ignored. Bodies whose
        bounding sphere the line misses are not looked at further."""
        a, b = self.segments(q)
        centre = self._centres(q)
        start = np.broadcast_to(origin[:, None, :], points.shape)
        out = np.zeros(points.shape[:2], dtype=bool)
        for k in set(self.body.tolist()):
            near = segment_distance(start, points, centre[:, None, k], centre[:, None, k]) < self._sphere_radius[k]
            near &= ~np.any(skip_bodies == k, axis=1)[None]
            n, p = np.nonzero(near & ~out)
            if not len(n):
                continue
            members = np.flatnonzero(self.body == k)
            d = segment_distance(start[n, p][:, None], points[n, p][:, None], a[n][:, members], b[n][:, members])
            hit = np.any(d < self.radius[members], axis=1)
            out[n[hit], p[hit]] = True
        return out
