"""The floor fit's corner-inset unknown: directions on known quads, and a known inward bias put into synthetic floor
corners is found again (the other-tags robot of test_floor_fit, floor tags 0.12-0.2 m at 1-4 m)."""

import numpy as np
import pytest
from conftest import OTHER_CAMERA, robot_with_floor_tags

from wolfcal.fit.floor_block import REFERENCE_EDGE_PX, FloorBlock
from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.sim.floor import simulate_floor
from wolfcal.sim.simulate import offset_joints
from wolfcal.sim.truth import TruthSpec, random_truth
from wolfcal.vision.corner_bias import apparent_edges, edge_normals, inset_directions
from wolfcal.vision.outline import mean_side

CAMERA = OTHER_CAMERA


def test_inset_directions_move_both_edges_inward_by_one_pixel():
    square = np.array([[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]])
    assert np.allclose(inset_directions(square)[0], [[1, 1], [-1, 1], [-1, -1], [1, -1]])
    trapezoid = np.array([[[0.0, 0.0], [40.0, 0.0], [30.0, 8.0], [10.0, 8.0]]])  # a floor tag seen at a grazing angle
    moved = trapezoid + inset_directions(trapezoid)
    for k in range(4):  # each edge's line moved inward by exactly 1 px
        a, b = trapezoid[0, k], trapezoid[0, (k + 1) % 4]
        n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
        n *= np.sign(n @ (trapezoid[0].mean(axis=0) - a))
        assert np.allclose([(moved[0, k] - a) @ n, (moved[0, (k + 1) % 4] - a) @ n], 1.0)
    assert np.all(inset_directions(np.where(np.arange(4)[None, :, None] == 2, np.nan, square)) == 0.0)


@pytest.mark.slow
def test_apparent_edge_is_the_mean_of_the_known_sides():
    trapezoid = np.array([[0.0, 0.0], [40.0, 0.0], [30.0, 8.0], [10.0, 8.0]])  # sides 40, sqrt(164), 20, sqrt(164)
    views = np.stack([trapezoid, trapezoid, trapezoid, trapezoid])
    views[1, 2] = np.nan  # the two sides at corner 2 unknown: 40 and sqrt(164) remain
    views[2, [0, 2]] = np.nan  # every side touches a missing corner
    views[3] = np.nan
    side = np.sqrt(164.0)
    assert np.allclose(mean_side(views), [(60.0 + 2 * side) / 4, (40.0 + side) / 2, np.nan, np.nan], equal_nan=True)
    assert np.allclose(apparent_edges(views), [(60.0 + 2 * side) / 4, (40.0 + side) / 2, REFERENCE_EDGE_PX,
                                               REFERENCE_EDGE_PX])  # fmt: skip


def test_fit_finds_a_known_corner_inset(tmp_path):
    robot = robot_with_floor_tags(tmp_path)
    rng = np.random.default_rng(2)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, "head")), rng)
    floor = simulate_floor(robot, CAMERA, truth, 30, rng).obs
    block = FloorBlock(robot, floor)
    inset = 0.8  # [px] at REFERENCE_EDGE_PX
    pixels = np.linalg.solve(block.normals, block.inward[..., None])[..., 0]  # block.inward: along the edge normals
    floor.uv += inset * pixels  # the detector's bias, shrinking as 1/edge above the reference edge
    assert np.abs(block.inward).max() > 0.5 and REFERENCE_EDGE_PX > 0
    fit = fit_observations(robot, floor, FitOptions(free="head_camera"))
    found = fit.solution.values[fit.params.names.index("floor.corner_inset")]
    std = fit.solution.std[fit.params.names.index("floor.corner_inset")]
    assert abs(found - inset) < max(3 * std, 0.1), (found, std)


def test_edge_normals_measure_a_corner_by_its_distance_from_the_two_edges():
    """A flat, sheared view (a far floor tag): a corner slid 3 px along one edge is 0 px from that edge's line and
    3 sin(angle) px from the other's; the inset's directions read as 1 px from both lines."""
    ring = np.array([[[100.0, 100.0], [140.0, 104.0], [150.0, 112.0], [110.0, 108.0]]])
    N = edge_normals(ring)[0]  # (4, 2, 2): next edge, previous edge
    along = ring[0, 1] - ring[0, 0]
    slide = 3.0 * along / np.linalg.norm(along)  # corner 1 along the edge from corner 0
    assert abs(N[1, 1] @ slide) < 1e-12
    other = ring[0, 2] - ring[0, 1]
    sine = abs(along[0] * other[1] - along[1] * other[0]) / np.linalg.norm(along) / np.linalg.norm(other)
    assert np.isclose(abs(N[1, 0] @ slide), 3.0 * sine)
    assert np.allclose(np.einsum("cij,cj->ci", N, inset_directions(ring)[0]), 1.0)
    square = np.array([[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]])
    normals = edge_normals(square)[0]
    assert np.allclose(np.abs(normals), np.round(np.abs(normals)))  # the image axes: pixels unchanged in size
    assert np.allclose(np.linalg.norm(normals, axis=-1), 1.0)
