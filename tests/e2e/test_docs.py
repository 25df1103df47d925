"""The user documentation stays true to the command line: every command has a page, and every option of a command is
explained on its page; the README stays a short user's page."""

import re
from pathlib import Path
from typing import Any

import pytest
import typer.main

from wolfcal.cli import app

ROOT = Path(__file__).resolve().parents[2]
COMMAND_PAGES = ROOT / "docs" / "commands"
PAGE_OF = {"board": "targets", "tags": "targets"}  # commands documented together


def commands() -> dict[str, Any]:
    """The app's commands by name, as typer builds them (its command objects carry `params` with `opts`)."""
    return dict(typer.main.get_command(app).commands)  # type: ignore[attr-defined]


@pytest.mark.parametrize("name", sorted(commands()))
def test_every_option_of_a_command_is_on_its_page(name: str) -> None:
    page = COMMAND_PAGES / f"{PAGE_OF.get(name, name)}.md"
    assert page.exists(), f"`wolfcal {name}` has no page: write {page.relative_to(ROOT)}"
    text = page.read_text()
    options = [opt for param in commands()[name].params for opt in param.opts if opt.startswith("--")]
    missing = [opt for opt in options if f"`{opt}`" not in text and f"{opt} " not in text]
    assert not missing, f"{page.relative_to(ROOT)} does not explain {missing}"


def test_every_command_page_is_listed_in_the_overview() -> None:
    overview = (COMMAND_PAGES / "index.md").read_text()
    for name in commands():
        assert f"`{name}`" in overview, f"docs/commands/index.md does not list `{name}`"


def test_the_readme_is_short_and_speaks_to_users() -> None:
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    assert "pip install . && wolfcal demo" in text
    assert "pip install '.[test]' && python -m pytest" in text


def test_shipped_text_does_not_speak_of_how_it_was_developed() -> None:
    """Docs, README and docstrings describe the tool, not its history: no issue numbers or work-log words."""
    pattern = re.compile(r"\bissues? \d+\b|\(#\d+\)|\bthis session\b|\bhelper session\b", re.IGNORECASE)
    files = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "wolfcal").rglob("*.py"))]
    offenders = [
        f"{path.relative_to(ROOT)}: {m.group(0)}" for path in files for m in pattern.finditer(path.read_text())
    ]
    assert not offenders, offenders
