"""Start-up speed in one place (docs/design.md §2, docs/app.md "command-line start-up"): a
CLI verb module (``app/cli/cmd_*.py``) binds the services and records its verbs call at its
top with ``railval.core.lazy`` (``x_service = lazy.module("railval.app.services.x")``), so
no verb function imports railval modules in its body — read with ``ast``, checked against a
planted violation. ``railval --help`` and a verb still load only what they use
(tests/test_cli_startup.py).

The one function-body import left is the optional demo seed (``cmd_app.seed_demo``), which
answers an ``ImportError`` with a sentence.

Over all of app/ (issue 42), in-function imports stay under a ceiling that only comes down, and
every file that still holds some is listed in :data:`REMAINING` with its number and reason.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: ``file::function`` allowed a function-body railval import, and why
ALLOWED = {"app/cli/cmd_app.py::seed_demo": "guarded by `except ImportError` (optional demo)"}


def body_imports(path: Path, root: Path = ROOT) -> list[str]:
    """``file::function:line module`` of every railval import inside a function body."""
    rel = str(path.relative_to(root))
    out = []
    for fn in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        for node in ast.walk(fn):
            modules = ([node.module or ""] if isinstance(node, ast.ImportFrom)
                       else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
            for m in modules:
                if (m == "railval" or m.startswith("railval.")) \
                        and f"{rel}::{fn.name}" not in ALLOWED:
                    out.append(f"{rel}::{fn.name}:{node.lineno} {m}")
    return sorted(set(out))


def verb_modules(root: Path = ROOT) -> list[Path]:
    return sorted((root / "app" / "cli").glob("cmd_*.py"))


def test_verb_functions_import_no_railval_module_in_their_body():
    found = [x for p in verb_modules() for x in body_imports(p)]
    assert found == [], "bind these at the module's top with railval.core.lazy:\n" + "\n".join(found)


def test_every_verb_module_binds_its_services_lazily():
    for path in verb_modules():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        top = [n for n in tree.body if isinstance(n, ast.ImportFrom)
               and (n.module or "").startswith("railval.app.services")]
        assert top == [], f"{path.name}: a service imported at the top loads it for every verb"


def test_the_rule_finds_a_planted_body_import(tmp_path):
    (tmp_path / "app" / "cli").mkdir(parents=True)
    planted = tmp_path / "app" / "cli" / "cmd_planted.py"
    planted.write_text(textwrap.dedent("""
        import argparse

        def cmd_x(args):
            import json
            from railval.app.services.overview import validation
            return validation(args.db)

        def seed_demo(database):
            import railval.app.services.synth
        """), encoding="utf-8")
    assert body_imports(planted, tmp_path) == [
        "app/cli/cmd_planted.py::cmd_x:6 railval.app.services.overview",
        "app/cli/cmd_planted.py::seed_demo:10 railval.app.services.synth"]  # only cmd_app's is allowed
    assert [p.name for p in verb_modules(tmp_path)] == ["cmd_planted.py"]


# -- in-function imports in app/ (issue 42): a ceiling that only comes down -----------------
#: in-function ``import`` statements in app/ (every module, railval or not). 357 at first; 317
#: after the imports of modules already loaded by their importer moved to the tops; 177 after
#: app/bench, app/cli, app/services and app/*.py bound the rest at their tops (a plain import
#: where the module is loaded with its importer or light, else ``railval.core.lazy``); 125 after
#: the diagnosis, team and workshop benchmarks did the same; 83 after the workshop's web handlers;
#: 1 after the Panel app's entrance and pages (25), the diagnosis services, batch, sessions and
#: the jobs and report states (31) and the workshop services and benchmark (26): only the
#: optional demo seed's guarded import is left. Never raise it.
FUNCTION_IMPORT_CEILING = 1

#: every file that still imports in a function body: file → (statements, why). The sum is the
#: ceiling; a file not listed here, or holding more than its number, fails
#: :func:`test_every_remaining_function_import_is_listed_with_its_reason`.
REMAINING: dict[str, tuple[int, str]] = {
    "app/cli/cmd_app.py": (1, "seed_demo: the optional demo seed, `except ImportError` (ALLOWED)"),
}


def function_imports(root: Path = ROOT) -> list[str]:
    """``file:line statement`` of every import statement inside a function body in app/."""
    out = []
    for path in sorted((root / "app").rglob("*.py")):
        rel = str(path.relative_to(root))
        tree = ast.parse(path.read_text(encoding="utf-8"))
        seen: set[int] = set()
        for fn in ast.walk(tree):
            if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                for node in ast.walk(fn):
                    if isinstance(node, ast.Import | ast.ImportFrom) and id(node) not in seen:
                        seen.add(id(node))  # a nested function's import counted once
                        out.append(f"{rel}:{node.lineno} {ast.unparse(node)}")
    return out


def beyond_remaining(root: Path = ROOT, remaining: dict = REMAINING) -> dict[str, tuple[int, int]]:
    """file → (in-function imports found, number listed) of every file holding more than
    :data:`REMAINING` lists for it."""
    per_file: dict[str, int] = {}
    for x in function_imports(root):
        per_file[x.split(":", 1)[0]] = per_file.get(x.split(":", 1)[0], 0) + 1
    return {f: (n, remaining.get(f, (0, ""))[0]) for f, n in per_file.items()
            if n > remaining.get(f, (0, ""))[0]}


def test_every_remaining_function_import_is_listed_with_its_reason():
    assert beyond_remaining() == {}, (
        "in-function imports beyond REMAINING (file: found, listed): move them to the module's "
        "top or bind them with railval.core.lazy")
    assert sum(n for n, _ in REMAINING.values()) == FUNCTION_IMPORT_CEILING
    assert all(why for _, why in REMAINING.values())


def test_function_imports_in_app_stay_under_the_ceiling():
    found = function_imports()
    assert len(found) <= FUNCTION_IMPORT_CEILING, (
        f"{len(found)} in-function imports in app/ (ceiling {FUNCTION_IMPORT_CEILING}): import "
        "at the module's top, or bind with railval.core.lazy where start-up matters")


def test_the_function_import_count_sees_a_planted_import(tmp_path):
    (tmp_path / "app" / "services").mkdir(parents=True)
    (tmp_path / "app" / "services" / "planted.py").write_text(textwrap.dedent("""
        import json

        def f():
            import os

            def g():
                from railval.db import repo
                return repo
            return os, g

        class C:
            def m(self):
                import numpy as np
                return np
        """), encoding="utf-8")
    assert function_imports(tmp_path) == ["app/services/planted.py:5 import os",
                                          "app/services/planted.py:8 from railval.db import repo",
                                          "app/services/planted.py:14 import numpy as np"]
    # a file not in REMAINING, and a listed file holding one more than its number
    assert beyond_remaining(tmp_path) == {"app/services/planted.py": (3, 0)}
    assert beyond_remaining(tmp_path, {"app/services/planted.py": (2, "why")}) == {
        "app/services/planted.py": (3, 2)}
    assert beyond_remaining(tmp_path, {"app/services/planted.py": (3, "why")}) == {}
