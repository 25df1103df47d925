"""What stands on and around a field in a simulated view: goals, other robots, a ball, shadows, people and walls
beyond the border strip, and the light. Field frame as in `wolfcal.field.model` [m]."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wolfcal.field.model import FieldDimensions

BORDER_STRIP = 1.0  # carpet beyond the touch and goal lines [m] (RoboCup: at least 1 m)
GOAL_WIDTH = 2.6  # between the posts' centres [m]
GOAL_HEIGHT = 1.2
POST_RADIUS = 0.05
WARM_LIGHT = (0.35, 0.9, 1.6)  # BGR gains of a hall's warm light seen without white balance: white looks yellow


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in the field frame (its lower and upper corner [m]) of one colour (BGR, 0-255)."""

    low: np.ndarray  # (3,)
    high: np.ndarray  # (3,)
    color: tuple[float, float, float]


@dataclass(frozen=True)
class Scene:
    """Everything a field view shows besides the carpet and its lines."""

    boxes: list[Box] = field(default_factory=list)  # goal posts and bars, robots, people, walls
    ball: tuple[np.ndarray, float] | None = None  # centre (3,) [m] and radius [m]
    shadows: list[tuple[np.ndarray, float]] = field(default_factory=list)  # ground discs: centre (2,), radius [m]
    light_gradient: np.ndarray = field(default_factory=lambda: np.zeros(2))  # relative brightness change per m
    colour_cast: tuple[float, float, float] = (1.0, 1.0, 1.0)  # BGR gains of the light on everything


def goal_boxes(dims: FieldDimensions) -> list[Box]:
    """Both goals: two posts and a crossbar each, white; the net as a grey back wall."""
    white = (235.0, 235.0, 235.0)
    net = (150.0, 150.0, 150.0)
    boxes = []
    for side in (-1.0, 1.0):
        x = side * dims.length / 2
        for y in (-GOAL_WIDTH / 2, GOAL_WIDTH / 2):
            boxes.append(
                Box(
                    np.array([x - POST_RADIUS, y - POST_RADIUS, 0.0]),
                    np.array([x + POST_RADIUS, y + POST_RADIUS, GOAL_HEIGHT]),
                    white,
                )
            )
        boxes.append(
            Box(
                np.array([x - POST_RADIUS, -GOAL_WIDTH / 2, GOAL_HEIGHT - 2 * POST_RADIUS]),
                np.array([x + POST_RADIUS, GOAL_WIDTH / 2, GOAL_HEIGHT]),
                white,
            )
        )
        back = x + side * 0.6
        boxes.append(
            Box(
                np.array([min(back, back + side * 0.02), -GOAL_WIDTH / 2, 0.0]),
                np.array([max(back, back + side * 0.02), GOAL_WIDTH / 2, GOAL_HEIGHT]),
                net,
            )
        )
    return boxes


def cluttered_scene(dims: FieldDimensions, rng: np.random.Generator, robots: int = 2, people: int = 6) -> Scene:
    """Goals, `robots` other robots (dark bodies with white parts) standing on the field, a ball, their shadows,
    people and walls beyond the border strip, and uneven light."""
    hx, hy = dims.length / 2, dims.width / 2
    boxes = goal_boxes(dims)
    shadows = []
    for _ in range(robots):
        centre = rng.uniform([-hx + 1.0, -hy + 0.5], [hx - 1.0, hy - 0.5])
        body = (40.0, 40.0, 45.0)
        boxes.append(Box(np.array([*(centre - [0.1, 0.15]), 0.3]), np.array([*(centre + [0.1, 0.15]), 0.8]), body))
        for leg in (-0.08, 0.08):
            boxes.append(
                Box(
                    np.array([centre[0] - 0.05, centre[1] + leg - 0.04, 0.0]),
                    np.array([centre[0] + 0.05, centre[1] + leg + 0.04, 0.3]),
                    (225.0, 225.0, 225.0),
                )
            )
        shadows.append((centre + [0.15, 0.1], 0.35))
    for _ in range(people):
        side = rng.choice([-1.0, 1.0])
        along = rng.uniform(-hx - 1.0, hx + 1.0)
        across = side * (hy + BORDER_STRIP + rng.uniform(0.3, 1.5))
        b, g, r = (float(c) for c in rng.uniform(20, 255, 3))
        boxes.append(
            Box(np.array([along - 0.25, across - 0.15, 0.0]), np.array([along + 0.25, across + 0.15, 1.75]), (b, g, r))
        )
    wall = hy + BORDER_STRIP + 2.5
    end = hx + BORDER_STRIP + 2.5
    boxes += [
        Box(np.array([-end, wall, 0.0]), np.array([end, wall + 0.1, 4.0]), (180.0, 190.0, 200.0)),
        Box(np.array([-end, -wall - 0.1, 0.0]), np.array([end, -wall, 4.0]), (170.0, 180.0, 175.0)),
        Box(np.array([end, -wall, 0.0]), np.array([end + 0.1, wall, 4.0]), (190.0, 185.0, 170.0)),
        Box(np.array([-end - 0.1, -wall, 0.0]), np.array([-end, wall, 4.0]), (160.0, 170.0, 190.0)),
    ]
    ball_place = rng.uniform([-hx + 0.5, -hy + 0.5], [hx - 0.5, hy - 0.5])
    return Scene(
        boxes=boxes,
        ball=(np.array([*ball_place, 0.075]), 0.075),
        shadows=shadows,
        light_gradient=rng.uniform(-0.04, 0.04, 2),
    )
