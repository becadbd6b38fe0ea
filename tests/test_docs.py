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


# A repository path as the docs write it: a top-level folder of the repository, then at least
# one more component (``app/pages/``, ``core/diagnosis.py``, ``tests/test_docs.py::name``).
_PATH = re.compile(r"(?<![\w./-])((?:app|core|db|tests|tools|deploy|docs|static|\.ci)/[\w./*-]*[\w*/])")


def _named_paths(text: str) -> set[str]:
    paths = set()
    for m in _PATH.finditer(text):
        path = m.group(1).split("::")[0].rstrip("/.")
        if "*" in path or "<" in path:
            continue
        paths.add(path)
    return paths


def _exists(path: str) -> bool:
    """A path named in prose exists as file or folder; ``tests/factories`` also counts as the
    module ``tests/factories.py``, and ``db/repo.delete_campaign`` names a function of
    ``db/repo.py``."""
    if (ROOT / path).exists() or (ROOT / f"{path}.py").exists():
        return True
    module, dot, _attribute = path.rpartition(".")  # ``db/repo.store_configuration``
    return bool(dot) and "/" in module and (ROOT / f"{module}.py").exists()


def test_every_repository_path_named_in_the_docs_exists():
    missing = []
    for doc in sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]:
        for path in sorted(_named_paths(doc.read_text(encoding="utf-8"))):
            if not _exists(path):
                missing.append(f"{doc.relative_to(ROOT)}: {path}")
    assert not missing, "docs name paths that do not exist:\n" + "\n".join(missing)


def test_the_docs_path_check_catches_a_missing_path():
    assert _named_paths("see `app/workshop_web.py` and core/diagnosis.py.") == {
        "app/workshop_web.py", "core/diagnosis.py"}
    assert not _exists("app/workshop_web.py")
    assert _exists("tests/factories")
    assert _exists("db/repo.delete_campaign") and not _exists("db/nothere.delete_campaign")
