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
* no module in ``db/`` above :data:`MAX_DB_LINES` lines;
* services are the only door to the database: no module of ``app/pages``, ``app/workshop_web``
  or ``app/cli``, nor the sign-in's HTTP side ``app/auth.py``, imports ``railval.db`` (the one exception: ``connect`` of
  ``railval.db.engine``, which turns the ``--db`` URL a verb is given into the connection it
  hands to a service; it runs no query of its own);
* ``app/report.py`` imports nothing of ``app/state`` (the report is built from results, not
  from page state), and ``app/state`` imports no Panel widgets (``panel``, ``bokeh``);
* no function longer than :data:`MAX_FUNCTION_LINES` lines in ``core/``, ``db/`` or ``app/``
  (the numba kernel ``core/sim/kernel.py::run_kernel`` and the migration scripts excepted);
* no ``x.get(key, y.get(…))`` fallback chain in ``app/`` (results are read as typed fields);
* no compiled (numba) function calls a compiled function of another module: numba's on-disk
  cache keys a kernel to its own file and compiles its callees into it, so a change in a
  callee of another file would leave the caller's cached code stale (core/en_kernels.py);
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
MAX_DB_LINES = 700
MAX_FUNCTION_LINES = 80
#: functions exempt from the length cap: the numba kernel is one loop the JIT compiles whole
FUNCTION_LENGTH_EXEMPT = {"core/sim/kernel.py::run_kernel"}
#: the packages whose modules reach the database only through ``railval.app.services``
DOOR_PACKAGES = ("railval.app.pages", "railval.app.workshop_web", "railval.app.cli",
                 "railval.app.auth")
#: ``from railval.db.engine import connect`` is allowed there (see the module docstring)
DOOR_EXCEPTION = ("railval.db.engine", frozenset({"connect"}))
UI_LIBRARIES = ("panel", "param", "bokeh", "holoviews")
#: UI libraries that draw (``param`` alone is the state classes' base)
WIDGET_LIBRARIES = ("panel", "bokeh", "holoviews")
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
    ``from package import submodule`` names the submodule. A deferred import
    (``lazy.function("railval.x", "f")``, ``lazy.module("railval.x")``, railval.core.lazy)
    counts as an import of its module: deferring a load does not change the layering."""
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
        elif _is_lazy(node):
            yield node.args[0].value, node.lineno


def _is_lazy(node: ast.AST) -> bool:
    """``lazy.function("railval.x", "f")`` or ``lazy.module("railval.x")`` (railval.core.lazy)."""
    return (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
            and isinstance(node.func.value, ast.Name) and node.func.value.id == "lazy"
            and node.func.attr in ("function", "module") and bool(node.args)
            and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str))


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


# -- services are the only door; report and state; module and function size -------------------

def _rel(path: Path) -> str:
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return path.name


def _enclosing(tree: ast.AST) -> dict[int, str]:
    """line → qualified name of the innermost function or class holding it."""
    out: dict[int, str] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}.{child.name}" if prefix else child.name
                for line in range(child.lineno, (child.end_lineno or child.lineno) + 1):
                    out[line] = name
                visit(child, name)
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def database_imports(name: str, path: Path) -> list[str]:
    """``file::function imports module`` for every import of ``railval.db`` in a module
    (:data:`DOOR_EXCEPTION` allowed), relative imports resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    where = _enclosing(tree)
    allowed_from, allowed_names = DOOR_EXCEPTION
    out = []
    for imported, line in _imports(name, path):
        if not (imported == "railval.db" or imported.startswith("railval.db.")):
            continue
        node = next(n for n in ast.walk(tree) if getattr(n, "lineno", None) == line and (
            isinstance(n, (ast.Import, ast.ImportFrom)) or _is_lazy(n)))
        if (isinstance(node, ast.ImportFrom) and imported == allowed_from
                and {a.name for a in node.names} <= allowed_names):
            continue
        if (_is_lazy(node) and node.func.attr == "function" and imported == allowed_from
                and len(node.args) > 1 and getattr(node.args[1], "value", None) in allowed_names):
            continue  # lazy.function("railval.db.engine", "connect")
        out.append(f"{_rel(path)}::{where.get(line, '<module>')} imports {imported}")
    return out


def forbidden_imports(name: str, path: Path, forbidden: tuple[str, ...]) -> list[str]:
    """``file:line imports module`` for every import of one of ``forbidden`` (or below it)."""
    return [f"{_rel(path)}:{line} imports {imported}" for imported, line in _imports(name, path)
            if any(imported == f or imported.startswith(f + ".") for f in forbidden)]


def long_functions(path: Path, limit: int = MAX_FUNCTION_LINES) -> dict[str, int]:
    """``file::qualified.name`` → lines, for every function (methods and nested functions
    too) longer than ``limit`` lines from its ``def`` to its last line."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                qual = f"{prefix}.{child.name}" if prefix else child.name
                if not isinstance(child, ast.ClassDef):
                    n = (child.end_lineno or child.lineno) - child.lineno + 1
                    if n > limit:
                        out[f"{_rel(path)}::{qual}"] = n
                visit(child, qual)
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def _in(name: str, packages: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in packages)


def test_services_are_the_only_door_to_the_database():
    found = [v for n, p in MODULES.items() if _in(n, DOOR_PACKAGES)
             for v in database_imports(n, p)]
    assert found == [], ("pages, workshop pages, CLI verbs and the sign-in handlers call "
                         "railval.app.services")


def test_door_rule_fails_on_a_planted_violation(tmp_path):
    bad = tmp_path / "planted.py"
    bad.write_text("from railval.db.engine import connect\n"
                   "def verb(args):\n"
                   "    from railval.db import users\n"
                   "    from railval.db.engine import connect, acting_as\n"
                   "    return users, connect, acting_as\n", encoding="utf-8")
    found = database_imports("railval.app.cli.planted", bad)
    assert found == ["planted.py::verb imports railval.db.users",
                     "planted.py::verb imports railval.db.engine"]
    rel = tmp_path / "pkg" / "mod.py"
    rel.parent.mkdir()
    rel.write_text("from ...db import repo\n", encoding="utf-8")
    assert database_imports("railval.app.pages.mod", rel) == ["mod.py::<module> imports railval.db.repo"]


def test_report_imports_no_page_state():
    found = forbidden_imports("railval.app.report", MODULES["railval.app.report"], ("railval.app.state",))
    assert found == []


def test_state_imports_no_panel_widgets():
    found = [v for n, p in MODULES.items() if n.startswith("railval.app.state")
             for v in forbidden_imports(n, p, ("panel", "bokeh"))]
    assert found == []


def test_import_rules_fail_on_planted_violations(tmp_path):
    bad = tmp_path / "report.py"
    bad.write_text("import panel as pn\n\ndef f():\n    from railval.app.state.dashboard import x\n",
                   encoding="utf-8")
    assert forbidden_imports("railval.app.report", bad, ("railval.app.state",)) == [
        "report.py:4 imports railval.app.state.dashboard"]
    assert forbidden_imports("railval.app.state.planted", bad, ("panel", "bokeh")) == [
        "report.py:1 imports panel"]
    deferred = tmp_path / "deferred.py"
    deferred.write_text("from railval.core import lazy\n\n"
                        "f = lazy.function('railval.db.repo', 'get_campaign')\n", encoding="utf-8")
    assert forbidden_imports("railval.core.planted", deferred, ("railval.db",)) == [
        "deferred.py:3 imports railval.db.repo"]


def test_db_modules_are_at_most_700_lines():
    sizes = {_rel(p): p.read_text(encoding="utf-8").count("\n")
             for n, p in MODULES.items() if n.startswith("railval.db") and "migrations" not in p.parts}
    over = {k for k, v in sizes.items() if v > MAX_DB_LINES}
    assert sizes and over == set(), {k: sizes[k] for k in over}


def test_functions_are_at_most_80_lines():
    found: dict[str, int] = {}
    for path in MODULES.values():
        if "migrations" in path.relative_to(ROOT).parts:
            continue
        found.update(long_functions(path))
    over = {k: v for k, v in found.items() if k not in FUNCTION_LENGTH_EXEMPT}
    assert over == {}, f"functions above {MAX_FUNCTION_LINES} lines: split them by step"
    assert FUNCTION_LENGTH_EXEMPT <= set(found), "an exempt function is short now: drop the exemption"


def test_size_rules_fail_on_planted_violations(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    bad = tmp_path / "long.py"
    bad.write_text(f"class A:\n    def short(self):\n        return 1\n\n"
                   f"    def long(self):\n{body.replace(chr(10), chr(10) + '    ').replace('    x0', '        x0', 1)}\n"
                   f"\ndef ok():\n    return 2\n", encoding="utf-8")
    assert long_functions(bad) == {"long.py::A.long": MAX_FUNCTION_LINES + 1}
    assert long_functions(bad, limit=MAX_FUNCTION_LINES + 1) == {}
    big = tmp_path / "big.py"
    big.write_text("x = 1\n" * (MAX_DB_LINES + 1), encoding="utf-8")
    assert big.read_text(encoding="utf-8").count("\n") > MAX_DB_LINES


def get_fallback_chains(path: Path) -> list[str]:
    """``file:line`` of every ``x.get(key, y.get(…))``: a guessed key with a fallback key hides a
    renamed field (results reach views as typed objects, docs/design.md §2)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))

    def is_get(node: ast.AST) -> bool:
        return (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "get")

    return [f"{_rel(path)}:{n.lineno}" for n in ast.walk(tree)
            if is_get(n) and len(n.args) == 2 and is_get(n.args[1])]


def test_no_key_fallback_chains_in_the_app():
    found = [v for n, p in MODULES.items() if n.startswith("railval.app")
             for v in get_fallback_chains(p)]
    assert found == [], "read the result object's field, not a guessed key with a fallback"


def test_key_fallback_rule_fails_on_a_planted_chain(tmp_path):
    bad = tmp_path / "page.py"
    bad.write_text("def f(cov):\n    return cov.get('ok', cov.get('holds', False)), cov.get('n', 0)\n",
                   encoding="utf-8")
    assert get_fallback_chains(bad) == ["page.py:2"]


def _compiled(tree: ast.AST) -> set[str]:
    """Names of the functions of a module compiled by numba (``@numba.njit``/``@njit``/``@jit``)."""
    return {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)
            and any(re.search(r"\b(njit|jit)\b", ast.unparse(d)) for d in n.decorator_list)}


def cross_module_kernel_calls(modules: dict[str, Path]) -> list[str]:
    """``path:line caller -> module.callee`` for every call of a compiled function of another
    railval module from inside a compiled function (by imported name or module alias)."""
    trees = {name: ast.parse(path.read_text(encoding="utf-8")) for name, path in modules.items()}
    kernels = {name: _compiled(tree) for name, tree in trees.items()}
    found = []
    for name, tree in trees.items():
        names, aliases = {}, {}
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom) and n.module in trees:
                names.update({a.asname or a.name: (n.module, a.name) for a in n.names})
            elif isinstance(n, ast.ImportFrom) and n.module:
                aliases.update({a.asname or a.name: f"{n.module}.{a.name}" for a in n.names
                                if f"{n.module}.{a.name}" in trees})
            elif isinstance(n, ast.Import):
                aliases.update({a.asname or a.name: a.name for a in n.names if a.name in trees})
        for fn in (n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)
                   and n.name in kernels[name]):
            for call in (c for c in ast.walk(fn) if isinstance(c, ast.Call)):
                f = call.func
                target = (names.get(f.id) if isinstance(f, ast.Name) else
                          (aliases[f.value.id], f.attr) if isinstance(f, ast.Attribute)
                          and isinstance(f.value, ast.Name) and f.value.id in aliases else None)
                if target and target[0] != name and target[1] in kernels.get(target[0], ()):
                    found.append(f"{_rel(modules[name])}:{call.lineno} {fn.name} -> "
                                 f"{target[0]}.{target[1]}")
    return found


def test_compiled_functions_call_no_compiled_function_of_another_module():
    assert cross_module_kernel_calls(MODULES) == [], (
        "keep a numba kernel and the compiled functions it calls in one file "
        "(core/en_kernels.py): numba's cache would keep a stale copy of the callee")


def test_kernel_call_rule_fails_on_a_planted_call(tmp_path):
    a = tmp_path / "a.py"
    a.write_text("import numba\n\n@numba.njit(cache=True)\ndef inner(x):\n    return x\n",
                 encoding="utf-8")
    b = tmp_path / "b.py"
    b.write_text("import numba\nfrom railval.core.a import inner\nfrom railval.core import a\n\n"
                 "@numba.njit(cache=True)\ndef outer(x):\n    return inner(x) + a.inner(x)\n\n"
                 "def plain(x):\n    return inner(x)\n", encoding="utf-8")
    found = cross_module_kernel_calls({"railval.core.a": a, "railval.core.b": b})
    assert [f.split(" ", 1)[1] for f in found] == ["outer -> railval.core.a.inner"] * 2
