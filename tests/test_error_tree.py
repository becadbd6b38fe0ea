"""One exception tree (core/errors.py): every exception class defined in railval's modules
derives from :class:`railval.core.errors.RailvalError`, and ``IntegrityError`` names one
class only (the seal check's, db/integrity.py).

The sources are read with ``ast``: a class is an exception when one of its bases is a
builtin exception, an exception class of another library (resolved through the module's
``import`` lines) or an exception class of railval (resolved across every module by name).
"""

from __future__ import annotations

import ast
import builtins
import importlib
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FOLDERS = ("core", "db", "app")


def _sources() -> dict[str, str]:
    """Repository path → source text of every ``.py`` of the package folders."""
    return {str(p.relative_to(ROOT)): p.read_text(encoding="utf-8")
            for folder in FOLDERS for p in sorted((ROOT / folder).rglob("*.py"))}


def _imported_names(tree: ast.Module) -> dict[str, str]:
    """Local name → ``module.attribute`` of the module's ``from … import …`` lines."""
    out = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                out[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return out


def _external_exception(dotted: str) -> bool:
    """``module.attribute`` outside railval names an exception class."""
    module, _, attr = dotted.rpartition(".")
    if not module or module.startswith("railval"):
        return False
    try:
        obj = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError):
        return False
    return isinstance(obj, type) and issubclass(obj, BaseException)


def exception_classes(sources: dict[str, str]) -> dict[str, list[str]]:
    """``path::Class`` → base names, for every class of ``sources`` that is an exception."""
    classes: dict[str, list[tuple[str, list[str], dict[str, str]]]] = {}
    for path, text in sources.items():
        tree = ast.parse(text, filename=path)
        imports = _imported_names(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                bases = [ast.unparse(b).rpartition(".")[2] for b in node.bases]
                full = [imports.get(ast.unparse(b), ast.unparse(b)) for b in node.bases]
                classes.setdefault(node.name, []).append((path, bases, dict(zip(bases, full))))

    def is_exception(name: str, seen: frozenset[str] = frozenset()) -> bool:
        if name in seen:
            return False
        if name in classes:
            return any(is_exception(b, seen | {name}) or _external_exception(full.get(b, ""))
                       for _, bases, full in classes[name] for b in bases)
        obj = getattr(builtins, name, None)
        return isinstance(obj, type) and issubclass(obj, BaseException)

    return {f"{path}::{name}": bases for name, defs in classes.items()
            for path, bases, _ in defs if is_exception(name)}


def violations(sources: dict[str, str]) -> list[str]:
    """Exception classes whose chain of railval bases does not reach ``RailvalError``."""
    found = exception_classes(sources)
    by_name: dict[str, list[list[str]]] = {}
    for key, bases in found.items():
        by_name.setdefault(key.rpartition("::")[2], []).append(bases)

    def rooted(name: str, seen: frozenset[str] = frozenset()) -> bool:
        if name == "RailvalError":
            return True
        if name in seen or name not in by_name:
            return False
        return all(any(rooted(b, seen | {name}) for b in bases) for bases in by_name[name])

    return sorted(key for key in found
                  if not key.endswith("::RailvalError") and not rooted(key.rpartition("::")[2]))


def test_every_railval_exception_derives_from_railval_error():
    sources = _sources()
    found = exception_classes(sources)
    # the walk sees the tree (a broken walk would find nothing and pass)
    for known in ("core/errors.py::InvalidSignal", "db/integrity.py::IntegrityError",
                  "db/codec.py::BlobError", "db/checks.py::RecordingProblem",
                  "app/services/signoff.py::SignoffRefused", "core/roles.py::PermissionDenied"):
        assert known in found, known
    assert violations(sources) == []


def test_a_new_exception_outside_the_tree_is_found():
    sources = _sources()
    planted = dict(sources)
    planted["db/planted.py"] = "class Foo(Exception):\n    pass\n"
    planted["app/planted.py"] = ("from sqlalchemy.exc import SQLAlchemyError\n\n\n"
                                 "class Bar(SQLAlchemyError):\n    pass\n\n\n"
                                 "class Baz(Bar):\n    pass\n")
    planted["core/planted.py"] = ("from railval.core.errors import InvalidSignal\n\n\n"
                                  "class Fine(InvalidSignal):\n    pass\n")
    assert violations(planted) == ["app/planted.py::Bar", "app/planted.py::Baz",
                                   "db/planted.py::Foo"]


def test_one_class_is_named_integrity_error():
    found = exception_classes(_sources())
    assert [k for k in found if k.endswith("::IntegrityError")] == ["db/integrity.py::IntegrityError"]
    from railval.core.errors import RailvalError
    from railval.db.integrity import IntegrityError
    assert issubclass(IntegrityError, RailvalError)


def undrawn(sources: dict[str, str]) -> list[str]:
    """``file::Class`` of every railval exception the tree drawn in core/errors.py's docstring
    does not name (with its file, unless it is a class of core/errors.py itself)."""
    doc = ast.get_docstring(ast.parse(sources["core/errors.py"])) or ""
    lines = doc.splitlines()
    out = []
    for key in exception_classes(sources):
        path, _, name = key.partition("::")
        drawn = [x for x in lines if re.search(rf"\b{re.escape(name)}\b", x)]
        if not drawn or (path != "core/errors.py" and not any(path in x for x in drawn)):
            out.append(key)
    return sorted(out)


def test_the_tree_in_core_errors_names_every_exception():
    assert undrawn(_sources()) == []


def test_an_exception_missing_from_the_drawn_tree_is_found():
    planted = dict(_sources())
    planted["db/planted.py"] = ("from railval.core.errors import RailvalError\n\n\n"
                                "class Planted(RailvalError):\n    pass\n")
    assert undrawn(planted) == ["db/planted.py::Planted"]
