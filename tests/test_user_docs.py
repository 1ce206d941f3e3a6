"""The user docs stay a user's: short, in the site's navigation, and free of the lab record (which lives under
``docs/studies/``)."""

from __future__ import annotations

import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
NOT_USER = ("api.md", "changelog.md")
"""Pages outside the word budget: the API reference (from the docstrings) and the changelog."""
WORD_BUDGET = 20_000


def user_pages() -> list[Path]:
    return [p for p in sorted(DOCS.rglob("*.md")) if p.parent == DOCS and p.name not in NOT_USER]


def words(path: Path) -> int:
    return len(path.read_text().split())


def nav_files(entries) -> list[str]:
    out = []
    for entry in entries:
        value = next(iter(entry.values())) if isinstance(entry, dict) else entry
        out.extend(nav_files(value) if isinstance(value, list) else [value])
    return out


def test_the_user_pages_fit_the_word_budget():
    counts = {p.name: words(p) for p in user_pages()}
    total = sum(counts.values())
    assert total <= WORD_BUDGET, f"user pages total {total:,} words > {WORD_BUDGET:,}: {counts}"


def test_every_page_is_in_the_navigation():
    class Loader(yaml.SafeLoader):
        pass

    Loader.add_multi_constructor("", lambda loader, suffix, node: None)  # mkdocs' !!python/name tags
    nav = set(nav_files(yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=Loader)["nav"]))
    pages = {str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md")}
    assert pages - nav == set(), f"pages missing from mkdocs.yml's nav: {sorted(pages - nav)}"
    assert nav - pages == set(), f"nav entries with no page: {sorted(nav - pages)}"


def test_the_user_pages_keep_no_lab_record():
    """No historical figures, issue numbers or superseded snapshots on a user page: those are the studies'."""
    lab = re.compile(r"^\{\{ historical |\bissues? \d+|(?<![\w/])#\d+\b|_before[_.]|_old[_.]|_without[_.]")
    found = [f"{p.name}:{i}: {line.strip()[:100]}" for p in user_pages()
             for i, line in enumerate(p.read_text().splitlines(), 1) if lab.search(line)]
    assert not found, "lab record on user pages:\n" + "\n".join(found)
