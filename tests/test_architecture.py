"""The architecture of docs/design.md held against the source, read with ``ast`` (nothing is
imported or run):

* ``railval.core`` is pure computation: it imports neither ``railval.db`` nor ``railval.app``
  nor storage/UI libraries; ``railval.db`` does not import ``railval.app``; the services of
  ``railval.app.services`` import no UI library;
* no import loop among railval's modules (every import counts, also those inside functions);
* no module in ``app/`` above :data:`MAX_APP_LINES` lines unless its docstring says why
  (a paragraph starting ``Length:``);
* no module in ``core/`` above :data:`MAX_CORE_LINES` lines (no exception: split by concept);
* the views: ``app/report.py``, ``app/audit_report.py``, ``app/pdf.py`` and the view model
  ``app/views.py`` import neither ``app/state`` (pages and the report read the same view
  model) nor ``railval.db`` (data comes through ``app/services``); the view model imports no
  UI library; ``app/state`` imports no Panel/Bokeh/HoloViews (``param`` is its base) and
  reaches the database only through ``app/services`` (no ``railval.db`` import);
* no function above :data:`MAX_FUNCTION_LINES` lines outside :data:`LONG_FUNCTIONS` (the
  numba kernel and functions still to be split: the list only shrinks);
* every package folder (a folder with ``__init__.py``) is installed (pyproject's package list);
* no file cites documents that are not in the repository.
"""

from __future__ import annotations

import ast
import itertools
import re
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: repository folder → installed package
FOLDERS = {"core": "railval.core", "db": "railval.db", "app": "railval.app"}
MAX_APP_LINES = 500
MAX_CORE_LINES = 700
MAX_FUNCTION_LINES = 80
UI_LIBRARIES = ("panel", "param", "bokeh", "holoviews")
#: UI libraries that draw (``param`` alone is the state classes' base)
WIDGET_LIBRARIES = ("panel", "bokeh", "holoviews")
#: functions longer than MAX_FUNCTION_LINES today (file, function); remove an entry when it is
#: split — the test fails when a listed function has become short, so the list stays true
LONG_FUNCTIONS = {
    ("core/sim/kernel.py", "run_kernel"),  # the numba kernel: one compiled loop
    ("core/diagnosis/engine.py", "diagnose_evidence"),
    ("core/sim/model.py", "assemble"),
    ("core/sim/synth.py", "build_campaign"),
    ("db/migrations/versions/0001_initial_schema.py", "upgrade"),
    ("db/migrations/versions/0003_users_audit.py", "upgrade"),
    ("app/bench/bench_team.py", "run"),
    ("app/services/audit_checks.py", "_check_signoffs"),
    ("app/services/diagnosis_evidence.py", "rank_causes"),
    ("app/services/workshops.py", "create"),
}
STORAGE_LIBRARIES = ("sqlalchemy", "alembic")


def _modules() -> dict[str, Path]:
    """Installed module name → source file, for every ``.py`` of the source folders."""
    out = {}
    for folder, package in FOLDERS.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT / folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            out[".".join([package, *parts])] = path
    return out


MODULES = _modules()


def _is_package(name: str) -> bool:
    return MODULES.get(name, Path()).name == "__init__.py"


def _imports(name: str, path: Path) -> Iterator[tuple[str, int]]:
    """(imported module, line) of every import statement in a module, relative imports resolved;
    ``from package import submodule`` names the submodule."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = name if _is_package(name) else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            subs = [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in MODULES]
            if subs:
                yield from ((s, node.lineno) for s in subs)
                if len(subs) < len(node.names):
                    yield base, node.lineno
            else:
                yield base, node.lineno


def _railval_target(imported: str) -> str | None:
    """The railval module an import loads (its nearest existing module), None outside railval."""
    parts = imported.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in MODULES:
            return candidate
        parts.pop()
    return None


def import_graph() -> dict[str, dict[str, int]]:
    """railval module → {railval module it imports: first line of that import}."""
    graph: dict[str, dict[str, int]] = {}
    for name, path in MODULES.items():
        edges = graph.setdefault(name, {})
        for imported, line in _imports(name, path):
            target = _railval_target(imported)
            if target is not None and target != name:
                edges.setdefault(target, line)
    return graph


def find_cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """One cycle per strongly connected component of more than one module (Tarjan's algorithm),
    each as a closed path ``[a, b, …, a]``."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def strongconnect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                components.append(comp)

    for v in sorted(graph):
        if v not in index:
            strongconnect(v)
    cycles = []
    for comp in components:
        members = set(comp)
        start = min(comp)
        # breadth-first search for the shortest way back to ``start`` inside the component
        prev: dict[str, str] = {}
        frontier = [start]
        found = None
        while frontier and found is None:
            nxt = []
            for v in frontier:
                for w in sorted(graph.get(v, {})):
                    if w == start:
                        found = v
                        break
                    if w in members and w not in prev:
                        prev[w] = v
                        nxt.append(w)
                if found:
                    break
            frontier = nxt
        path = [start]
        v = found
        while v is not None and v != start:
            path.append(v)
            v = prev.get(v)
        cycles.append([start, *reversed(path[1:]), start])
    return cycles


def _describe(cycle: list[str], graph: dict[str, dict[str, int]]) -> str:
    return " → ".join(f"{a} (line {graph[a][b]})" for a, b in itertools.pairwise(cycle)) + f" → {cycle[-1]}"


def _module_violations(name: str, path: Path, forbidden: tuple[str, ...]) -> list[str]:
    """``file:line imports X`` for every import of ``name`` (source ``path``) that loads a
    module of ``forbidden`` (or one below it)."""
    where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
    return [f"{where}:{line} imports {imported}" for imported, line in _imports(name, path)
            if any(imported == f or imported.startswith(f + ".") for f in forbidden)]


def _violations(prefix: str, forbidden: tuple[str, ...],
                modules: dict[str, Path] | None = None) -> list[str]:
    out = []
    for name, path in (MODULES if modules is None else modules).items():
        if name != prefix and not name.startswith(prefix + "."):
            continue
        out += _module_violations(name, path, forbidden)
    return out


def test_core_is_pure_computation():
    assert _violations("railval.core", ("railval.db", "railval.app", *STORAGE_LIBRARIES, *UI_LIBRARIES)) == []


def test_db_does_not_import_the_app():
    assert _violations("railval.db", ("railval.app", *UI_LIBRARIES)) == []


def test_services_import_no_ui_library():
    assert _violations("railval.app.services", UI_LIBRARIES) == []


#: (module prefix, forbidden imports) of the views' rules (docs/design.md §2)
VIEW_RULES = (
    # the report takes one colour palette from Bokeh's palettes (data, no widget)
    ("railval.app.report", ("railval.app.state", "railval.app.pages", "railval.db", "panel", "holoviews")),
    ("railval.app.audit_report", ("railval.app.state", "railval.app.pages", "railval.db", *WIDGET_LIBRARIES)),
    ("railval.app.pdf", ("railval.app.state", "railval.app.pages", "railval.db", *WIDGET_LIBRARIES)),
    ("railval.app.views", ("railval.app.state", "railval.app.pages", "railval.db", *UI_LIBRARIES)),
    ("railval.app.state", (*WIDGET_LIBRARIES, "railval.app.pages", "railval.db")),
)


@pytest.mark.parametrize(("prefix", "forbidden"), VIEW_RULES, ids=[r[0] for r in VIEW_RULES])
def test_views_state_and_report_keep_their_layers(prefix, forbidden):
    assert _violations(prefix, forbidden) == []


@pytest.mark.parametrize(("prefix", "planted"), [
    ("railval.app.state", "import panel as pn\n"),
    ("railval.app.state", "from railval.db import repo\n"),
    ("railval.app.state", "def f():\n    from bokeh.models import Div\n"),
    ("railval.app.report", "from railval.app.state.dashboard import DashboardState\n"),
    ("railval.app.report", "def f():\n    from railval.db import repo\n"),
    ("railval.app.views", "import param\n"),
])
def test_view_rules_fail_on_a_planted_violation(tmp_path, prefix, planted):
    forbidden = dict(VIEW_RULES)[prefix]
    path = tmp_path / "planted.py"
    path.write_text('"""planted"""\n' + planted, encoding="utf-8")
    name = prefix + ".planted" if prefix == "railval.app.state" else prefix
    found = _violations(prefix, forbidden, {name: path})
    assert len(found) == 1 and "planted.py:" in found[0]


def long_functions(folders: tuple[str, ...] = ("core", "db", "app"),
                   limit: int = MAX_FUNCTION_LINES) -> dict[tuple[str, str], int]:
    """(file, function) → lines of every function or method longer than ``limit``."""
    out = {}
    for folder in folders:
        for path in sorted((ROOT / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    n = node.end_lineno - node.lineno + 1
                    if n > limit:
                        out[(str(path.relative_to(ROOT)), node.name)] = n
    return out


def test_functions_are_at_most_80_lines():
    found = long_functions()
    assert {k: v for k, v in found.items() if k not in LONG_FUNCTIONS} == {}, \
        f"functions over {MAX_FUNCTION_LINES} lines: split them by step"
    assert sorted(LONG_FUNCTIONS - set(found)) == [], "split already: remove from LONG_FUNCTIONS"


def test_function_length_cap_finds_a_long_function():
    found = long_functions(("tests",), limit=40)
    assert ("tests/test_architecture.py", "find_cycles") in found


def test_no_import_loop():
    graph = import_graph()
    assert sum(len(e) for e in graph.values()) > 100  # the graph was read (railval imports railval)
    cycles = find_cycles(graph)
    assert [_describe(c, graph) for c in cycles] == []


def test_cycle_finder_reports_a_loop():
    graph = {"a": {"b": 3}, "b": {"c": 7}, "c": {"a": 1}, "d": {"a": 2}}
    assert find_cycles(graph) == [["a", "b", "c", "a"]]
    assert _describe(["a", "b", "c", "a"], graph) == "a (line 3) → b (line 7) → c (line 1) → a"
    assert find_cycles({"a": {"b": 1}, "b": {}}) == []


def test_relative_and_submodule_imports_resolve(tmp_path):
    name = "railval.app.state.compare"
    targets = {_railval_target(i) for i, _ in _imports(name, MODULES[name])}
    assert "railval.app.state.app" in targets and "railval.core.types" in targets


@pytest.mark.parametrize("name", sorted(n for n in MODULES if n.startswith("railval.app")))
def test_app_modules_are_small_or_say_why(name):
    path = MODULES[name]
    text = path.read_text(encoding="utf-8")
    lines = text.count("\n")
    if lines > MAX_APP_LINES:
        doc = ast.get_docstring(ast.parse(text)) or ""
        assert re.search(r"^Length:\s*\S", doc, re.MULTILINE), (
            f"{path.relative_to(ROOT)} has {lines} lines (> {MAX_APP_LINES}); split it or state why "
            "in a docstring paragraph starting 'Length:'")


def test_core_modules_are_at_most_700_lines():
    long = {str(p.relative_to(ROOT)): p.read_text(encoding="utf-8").count("\n")
            for n, p in MODULES.items() if n.startswith("railval.core")}
    assert long and not {k: v for k, v in long.items() if v > MAX_CORE_LINES}, \
        {k: v for k, v in long.items() if v > MAX_CORE_LINES}


def test_every_package_folder_is_installed():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    folders = {n for n in MODULES if _is_package(n)}
    assert sorted(folders - listed) == [], "package folders missing from pyproject [tool.setuptools] packages"
    assert sorted(listed - folders) == [], "pyproject lists packages that have no folder"


#: citations of documents that are not in the repository (written in pieces so this file does
#: not match itself)
OUTSIDE = re.compile("|".join([r"\bDESIGN(\.md|\s*§)", r"\bSTYLE(\.md|\s+habit)", "NOTES" + "-stack",
                               r"\.\./" + "shared"]))
TEXT_SUFFIXES = {".py", ".md", ".toml", ".ini", ".mako", ".html", ".css", ".sh", ".cfg", ".txt", ".yml", ".yaml"}


def test_no_citation_of_documents_outside_the_repository():
    skip = {".git", ".venv", "node_modules", "test-artifacts", ".ruff_cache"}
    hits = []
    for path in ROOT.rglob("*"):
        rel = path.relative_to(ROOT)
        if any(p in skip or p.endswith(".egg-info") for p in rel.parts) or not path.is_file():
            continue
        if path.suffix not in TEXT_SUFFIXES and path.parent.name != ".ci":
            continue
        for i, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if OUTSIDE.search(line):
                hits.append(f"{rel}:{i}: {line.strip()[:100]}")
    assert hits == []
