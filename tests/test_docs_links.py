"""Every reference in the user's pages resolves: relative links and cited repository paths in
README.md and docs/*.md (CHANGELOG.md: its links only), and the docs/*.md pages the code cites,
all exist.

A cited path is a backticked word that starts with one of the repository's top-level folders
(``labkit/sim/scheme.py``, ``docs/model.md``, ``tests/data/...``); words with a placeholder
(``*``, ``<``, ``NAME``, ``...``) are patterns, not paths, and are left alone.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from clihelpers import REPO

PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
HISTORY = [REPO / "CHANGELOG.md"]            # names files as they were: its links must resolve, not its paths
TOP = sorted(p.name for p in REPO.iterdir() if p.is_dir() and not p.name.startswith(".") and p.name != "build"
             and not p.name.endswith(".egg-info")) + [".ci"]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
TOPS = "|".join(re.escape(t) for t in TOP)
CITED = re.compile(rf"`((?:{TOPS})/[^`\s]*)`")
PLACEHOLDER = re.compile(r"[*<>{}]|\.\.\.|\b[A-Z]{2,}\b")


def _links(page: Path) -> list[str]:
    text = page.read_text(encoding="utf-8")
    out = []
    for target in LINK.findall(text):
        if re.match(r"^[a-z]+:", target) or target.startswith("#"):
            continue
        out.append(target.split("#")[0])
    return out


@pytest.mark.parametrize("page", PAGES + HISTORY, ids=lambda p: p.name)
def test_relative_links_resolve(page):
    missing = [t for t in _links(page) if not (page.parent / t).exists()]
    assert not missing, f"{page.relative_to(REPO)} links to missing files: {missing}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_cited_paths_exist(page):
    cited = [c.rstrip(".,:;)") for c in CITED.findall(page.read_text(encoding="utf-8"))]
    missing = [c for c in cited if not PLACEHOLDER.search(c) and not (REPO / c.split("::")[0]).exists()]
    assert not missing, f"{page.relative_to(REPO)} cites paths that do not exist: {missing}"


def test_docs_cited_by_the_code_exist():
    cites: dict[str, list[str]] = {}
    for folder in ("labkit", "drivers", "analysis", "tests", "bench"):
        for src in (REPO / folder).rglob("*.py"):
            for doc in re.findall(r"(?<![\w/.])((?:\.\./)*(?:shared/)?docs/[\w.-]+\.md)", src.read_text("utf-8")):
                cites.setdefault(doc, []).append(str(src.relative_to(REPO)))
    missing = {d: where for d, where in cites.items() if d.startswith(("../", "shared/")) or not (REPO / d).exists()}
    assert not missing, f"the code cites docs that are not in the repository: {missing}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_pages_carry_no_issue_numbers_or_dated_history(page):
    """The docs describe labkit as it is; what changed when is CHANGELOG.md's."""
    text = page.read_text(encoding="utf-8")
    months = "January|February|March|April|May|June|July|August|September|October|November|December"
    found = re.findall(rf"\bissue \d+\b|\b\d{{1,2}} (?:{months})\b|\b(?:{months}) 20\d\d\b|\b20\d\d-\d\d-\d\d\b",
                       text)
    assert not found, f"{page.relative_to(REPO)}: {found}"
