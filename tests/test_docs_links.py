"""The docs' anchored links resolve and every page's heading anchors are unique.

docs/estimation.md links into docs/estimation-history.md by anchor; write-ups move between the
two at every session's end, so a renamed or moved heading must not leave a link dangling.
Anchors are GitHub's: the heading's text lower-cased, every character but letters, digits,
``_``, ``-`` and spaces dropped, spaces turned into ``-``.
"""

from __future__ import annotations

import re
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((PROJECT_ROOT / "docs").glob("*.md")) + [PROJECT_ROOT / "README.md"]
LINK = re.compile(r"\]\(([^)#\s]*)#([^)\s]+)\)")


def anchor(heading_text: str) -> str:
    """GitHub's anchor of a heading's text."""
    return re.sub(r"[^\w\- ]", "", heading_text.strip().lower()).replace(" ", "-")


def heading_anchors(page: Path) -> list[str]:
    """The anchors of a page's headings in order (fenced code blocks skipped)."""
    anchors, fenced = [], False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and re.match(r"#{1,6} ", line):
            anchors.append(anchor(line.lstrip("#")))
    return anchors


def test_the_anchor_rule_matches_githubs_on_this_projects_headings() -> None:
    assert anchor("RMSE / own CRLB where it is missed (crlb14)") == (
        "rmse--own-crlb-where-it-is-missed-crlb14"
    )
    assert anchor("The dynamic filter (issue 10): `estimation/dynamic/`") == (
        "the-dynamic-filter-issue-10-estimationdynamic"
    )


def test_every_pages_heading_anchors_are_unique() -> None:
    duplicates = {}
    for page in PAGES:
        anchors = heading_anchors(page)
        repeated = sorted({a for a in anchors if anchors.count(a) > 1})
        if repeated:
            duplicates[page.name] = repeated
    assert not duplicates, duplicates


def test_every_anchored_link_in_the_docs_resolves() -> None:
    anchors = {page.resolve(): set(heading_anchors(page)) for page in PAGES}
    broken = []
    for page in PAGES:
        for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
            for target, fragment in LINK.findall(line):
                destination = (page.parent / target).resolve() if target else page.resolve()
                if destination in anchors and fragment not in anchors[destination]:
                    broken.append(f"{page.name}:{number} -> {target}#{fragment}")
    assert not broken, broken
