"""The repository's documentation stands on its own: every ``docs/design.md §n`` citation in
code and docs names a section that exists, and every document the README links exists."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SOURCES = [p for folder in ("app", "core", "db", "tests", "docs", "deploy")
           for p in (ROOT / folder).rglob("*") if p.suffix in {".py", ".md"}] + [ROOT / "README.md"]


def _design_sections() -> set[str]:
    text = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
    return set(re.findall(r"^## (§\d+)\b", text, flags=re.M))


def test_design_citations_name_existing_sections():
    sections = _design_sections()
    assert {f"§{i}" for i in range(1, 10)} <= sections
    dangling = []
    for path in SOURCES:
        for m in re.finditer(r"docs/design\.md (§\d+)", path.read_text(encoding="utf-8")):
            if m.group(1) not in sections:
                dangling.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
    assert not dangling, dangling


def test_readme_links_resolve():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    links = re.findall(r"\]\(((?:docs|deploy)/[^)#]+)\)", readme)
    assert "docs/design.md" in links
    missing = [link for link in links if not (ROOT / link).exists()]
    assert not missing, missing
