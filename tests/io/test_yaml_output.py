"""Fast YAML output: the C emitter writes what the Python one writes; detections.yaml loads to its data."""

from __future__ import annotations

import numpy as np
import yaml

import wolfcal.yamlfile
from wolfcal.intrinsics.detect import Detection, Failure
from wolfcal.intrinsics.report import detections_yaml
from wolfcal.yamlfile import dump_yaml, dump_yaml_pieces, load_yaml


def test_dump_yaml_equals_safe_dump():
    data = {"a": [1.5, -2e-7, None, True], "b": {"name": "x: y", "nested": [[1, 2], {"k": "é"}]}, "c": 1e300}
    assert dump_yaml(data, sort_keys=False, width=200) == yaml.safe_dump(data, sort_keys=False, width=200)
    assert load_yaml(dump_yaml(data)) == data


def test_dump_yaml_pieces_write_the_same_text(monkeypatch):
    """Lists split at every size, under mappings and list items, long strings folded at several widths."""
    rng = np.random.default_rng(1)

    def item(i: int) -> dict:
        return {"name": "word " * int(rng.integers(1, 40)), "index": i, "rows": [{"a": float(rng.normal()),
                "b": "long " * int(rng.integers(1, 30)), "c": []} for _ in range(int(rng.integers(0, 5)))],
                "pairs": [[1, 2], {}], "flag": bool(i % 2)}  # fmt: skip

    data = {
        "title": "x: y",
        "blocks": [{"name": "b", "samples": [item(i) for i in range(7)]}, 5, "z"],
        "samples": [item(i) for i in range(9)],
        "empty": [],
        "nested": {"deep": {"list": [item(0), 3]}},
    }
    for items in (1, 2, 3, 256):
        monkeypatch.setattr(wolfcal.yamlfile, "PIECE_ITEMS", items)
        for width in (40, 80, 120):
            pieces = list(dump_yaml_pieces(data, sort_keys=False, width=width))
            assert "".join(pieces) == dump_yaml(data, sort_keys=False, width=width)
            assert len(pieces) > 1 or items == 256  # nothing longer than 256 items: one piece
    assert load_yaml("".join(dump_yaml_pieces(data, sort_keys=False))) == data


def test_detections_yaml_loads_to_the_views_and_failures():
    rng = np.random.default_rng(0)
    views = [
        Detection(f'view {i} "quoted": back\\\\slash é.png', rng.uniform(0, 1900, (54, 2)), np.arange(54), (1920, 1080))
        for i in range(3)
    ]
    failures = [Failure("a: b.png", "no 9x6 checkerboard found\n'x'"), Failure("- c", "#")]
    rows = [{"name": v.name, "image_size": [1920, 1080], "ids": list(range(54))} for v in views]
    for row, v in zip(rows, views, strict=True):
        row["corners"] = np.round(v.corners, 4).tolist()
    expected = {
        "views": rows,
        "failures": [{"name": f.name, "reason": f.reason} for f in failures],
    }
    assert yaml.safe_load(detections_yaml(views, failures)) == expected
    assert yaml.safe_load(detections_yaml([], [])) == {"views": [], "failures": []}
