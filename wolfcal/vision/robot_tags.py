"""The AprilTags `wolfcal tags` prints: by default the robot config's own, each at its configured edge and family.

The config's tags (`tags:`, on the robot's links) and floor tags (`floor.tags:`) are what a team has to print, so
they are the default; `--ids`, `--size` and `--family` narrow or override them. A tag id the config does not list
takes the given --size (it has no configured one) and family 36h11. Tags of one family and size share pages; each
group is laid out by `printing.tag_sheets` on --paper, by default on the first of DEFAULT_PAPERS that holds a tag of
the group (the floor tags of 16 cm need A3).
"""

from __future__ import annotations

from pathlib import Path

from wolfcal.config import RobotConfig, load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.vision.printing import Sheet, parse_ids, tag_sheets

DEFAULT_FAMILY = "36h11"  # for ids the robot config does not list
DEFAULT_PAPERS = ("a4", "a3", "fit")  # without --paper: the first that holds a tag of the group


def configured_tags(config: RobotConfig) -> dict[int, tuple[str, float]]:
    """Tag id -> (family as `aruco_dictionary` names it, e.g. '36h11'; edge of the black square [m]) of every tag
    the robot config lists: on its links, then on the floor."""
    tags = {t.id: (t.family, t.size) for t in config.tags}
    if config.floor is not None:
        tags |= {t.id: (t.family, t.size) for t in config.floor.tags}
    return {tag_id: (family.removeprefix("tag"), size) for tag_id, (family, size) in tags.items()}


def tag_groups(
    configured: dict[int, tuple[str, float]],
    ids: list[int] | None,
    size: float | None,
    family: str | None,
    where: str = "the robot config",
) -> list[tuple[str, float, list[int]]]:
    """(family, edge [m], ids) groups to print, in the order the ids come: `ids` (default: every configured id),
    each at `size` / `family` when given, else at its configured one; WolfcalError for an id without a size."""
    chosen = ids if ids is not None else sorted(configured)
    if not chosen:
        raise WolfcalError(f"{where} lists no tags; give the tags to print with --ids and --size")
    unsized = [i for i in chosen if size is None and i not in configured]
    if unsized:
        raise WolfcalError(f"--ids: {where} does not list tag(s) {', '.join(map(str, unsized))}; give their edge "
                           "with --size [m]")  # fmt: skip
    groups: dict[tuple[str, float], list[int]] = {}
    for tag_id in chosen:
        own_family, own_size = configured.get(tag_id, (DEFAULT_FAMILY, 0.0))
        key = (own_family if family is None else family, own_size if size is None else size)
        groups.setdefault(key, []).append(tag_id)
    return [(fam, edge, group) for (fam, edge), group in groups.items()]


def robot_tag_sheets(
    robot: Path, ids: str | None, size: float | None, family: str | None, paper: str | None
) -> list[Sheet]:
    """The pages of `wolfcal tags`: the tags of the robot config at `robot` (read only when needed), narrowed by
    the ids text ('42-44,50'), edge `size` [m] and `family` when given; on `paper`, or by default on the first of
    DEFAULT_PAPERS that holds them."""
    wanted = parse_ids(ids) if ids is not None else None
    needs_config = wanted is None or size is None or family is None
    config = load_robot_config(robot) if needs_config else None
    configured = configured_tags(config) if config is not None else {}
    where = str(config.path) if config is not None else "the robot config"
    groups = tag_groups(configured, wanted, size, family, where)
    return [sheet for fam, edge, group in groups for sheet in _group_sheets(fam, edge, group, paper)]


def _group_sheets(family: str, size: float, ids: list[int], paper: str | None) -> list[Sheet]:
    if paper is not None:
        return tag_sheets(family, ids, size, paper)
    *smaller, largest = DEFAULT_PAPERS
    for candidate in smaller:
        try:
            return tag_sheets(family, ids, size, candidate)
        except WolfcalError:  # does not fit (any other problem is raised again by the last paper)
            continue
    return tag_sheets(family, ids, size, largest)
