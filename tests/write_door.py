"""The static half of the one write door (docs/design.md §2, "One write door"), read with
``ast`` (nothing is imported or run).

A unit of work is a *write session* when it is opened as ``X.session(write=…)`` with a
``write`` that is not the constant ``False``, as ``X.write_session(…)``, or as
``session_of(…, write=…)``; every other ``X.session(…)``, ``X.read_session(…)`` or
``session_of(…)`` is a read session, which the database refuses to write in
(``railval.db.engine``). :func:`writes_in_read_sessions` lists every write found in the body
of a read session's ``with`` block:

* a *write primitive* on the session — ``.add``, ``.add_all``, ``.delete``, ``.merge``,
  ``.flush``, ``.bulk_save_objects``, ``.bulk_insert_mappings``, ``.bulk_update_mappings``, or
  ``.execute`` of an ``insert``/``update``/``delete`` construct or of ``text("INSERT …")``
  (also ``UPDATE``, ``DELETE``, ``CREATE``, ``DROP``, ``ALTER``), or a bulk ``.update``/``.delete``
  of a legacy ``s.query(…)`` chain;
* a call that hands the session to a *session writer*: a function of ``core/``, ``db/``,
  ``app/`` or ``tools/`` that does one of the above on a session it was given (its parameter
  named ``s``/``session`` or annotated ``Session``), or hands it on to another session writer
  — found as a fixed point over the call graph, calls resolved through each module's imports
  (``from railval.db import users`` → ``users.create_user``; ``from railval.db.users import
  create_user``; a function of the same module by its bare name).

What it cannot see — an ORM attribute assigned in a read session and flushed at commit — the
database refuses at run time (``WriteInReadSession``), so the tests catch it where they run.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: repository folder → installed package
FOLDERS = {"core": "railval.core", "db": "railval.db", "app": "railval.app", "tools": "tools"}
PRIMITIVES = frozenset({"add", "add_all", "delete", "merge", "flush", "bulk_save_objects",
                        "bulk_insert_mappings", "bulk_update_mappings"})
CONSTRUCTS = frozenset({"insert", "update", "delete"})
SQL_WRITE = re.compile(r"\s*(INSERT|UPDATE|DELETE|CREATE|DROP|ALTER)\b", re.IGNORECASE)
SESSION_NAMES = frozenset({"s", "session"})


@dataclass(frozen=True)
class Module:
    name: str
    #: the file, relative to the source root
    path: Path
    tree: ast.Module
    #: local name → dotted target (a module or ``module.function``)
    aliases: dict[str, str]


def module_name(path: Path, root: Path = ROOT) -> str:
    rel = path.relative_to(root)
    package = FOLDERS.get(rel.parts[0], rel.parts[0])
    parts = [p for p in rel.with_suffix("").parts[1:] if p != "__init__"]
    return ".".join([package, *parts])


def _aliases(name: str, tree: ast.Module, is_package: bool) -> dict[str, str]:
    out: dict[str, str] = {}
    base = name.split(".") if is_package else name.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                out[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[:len(base) - node.level + 1]
                source = ".".join(anchor + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for a in node.names:
                out[a.asname or a.name] = f"{source}.{a.name}"
    return out


def load(paths: Iterable[Path], root: Path = ROOT) -> dict[str, Module]:
    """Parse ``paths`` (files under ``root``) into :class:`Module` by installed name."""
    out = {}
    for path in paths:
        name = module_name(path, root)
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        out[name] = Module(name, path.relative_to(root), tree,
                           _aliases(name, tree, path.name == "__init__.py"))
    return out


def source_modules(root: Path = ROOT) -> dict[str, Module]:
    return load((p for folder in FOLDERS for p in sorted((root / folder).rglob("*.py"))), root)


def _functions(tree: ast.AST) -> Iterator[ast.FunctionDef | ast.AsyncFunctionDef]:
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            yield node


def _session_params(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> set[str]:
    args = [*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs]
    return {a.arg for a in args if a.arg in SESSION_NAMES
            or (a.annotation is not None and "Session" in ast.unparse(a.annotation))}


def _target(mod: Module, func: ast.expr) -> str | None:
    """The dotted name a call's function resolves to through the module's imports."""
    if isinstance(func, ast.Name):
        return mod.aliases.get(func.id, f"{mod.name}.{func.id}")
    if isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name):
        owner = mod.aliases.get(func.value.id)
        return f"{owner}.{func.attr}" if owner else None
    return None


def _names(node: ast.AST) -> set[str]:
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}


def _session_of_receiver(value: ast.expr) -> str | None:
    """``s`` for a receiver ``s`` or ``s.connection()`` (the session's own connection)."""
    if isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute) \
            and value.func.attr == "connection":
        value = value.func.value
    return value.id if isinstance(value, ast.Name) else None


def _query_root(value: ast.expr) -> str | None:
    """``s`` for a legacy query chain ``s.query(…).filter_by(…)…`` (its bulk update/delete)."""
    while isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute):
        if value.func.attr == "query" and isinstance(value.func.value, ast.Name):
            return value.func.value.id
        value = value.func.value
    return None


def _is_write_construct(expr: ast.expr, bound: dict[str, list[ast.expr]] | None = None) -> bool:
    """An ``insert``/``update``/``delete`` construct or a writing SQL text, also through a
    name assigned one in the same block (``stmt = insert(T)…; s.execute(stmt)``)."""
    if isinstance(expr, ast.Name) and bound and expr.id in bound:
        return any(_is_write_construct(v) for v in bound[expr.id])
    for n in ast.walk(expr):
        if isinstance(n, ast.Call):
            f = n.func
            fname = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
            if fname in CONSTRUCTS:
                return True
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and SQL_WRITE.match(n.value):
            return True
    return False


def write_kind(call: ast.expr) -> str | None:
    """``"write"``, ``"read"`` or None: what unit of work ``call`` (a ``with`` item) opens."""
    if not isinstance(call, ast.Call):
        return None
    f = call.func
    fname = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
    if fname == "write_session":
        return "write"
    if fname not in ("session", "read_session", "session_of"):
        return None
    if fname == "session_of" and not isinstance(f, ast.Name):
        return None
    if fname in ("session", "read_session") and not isinstance(f, ast.Attribute):
        return None
    for kw in call.keywords:
        if kw.arg == "write" and not (isinstance(kw.value, ast.Constant) and kw.value.value is False):
            return "write" if fname != "read_session" else "read"
    return "read"


def _canonical(target: str | None, modules: dict[str, Module]) -> str | None:
    """Follow re-exports: ``railval.db.repo.cache_put`` → ``railval.db.cache.cache_put``."""
    for _ in range(5):
        if target is None or "." not in target:
            return target
        owner, name = target.rsplit(".", 1)
        again = modules[owner].aliases.get(name) if owner in modules else None
        if again is None or again == target:
            return target
        target = again
    return target


def _writes(mod: Module, body: Iterable[ast.AST], names: set[str], writers: set[str],
            modules: dict[str, Module]) -> Iterator[tuple[int, str]]:
    """Writes through the sessions ``names`` in ``body`` (write sessions nested in it skipped)."""
    stack = list(body)
    bound: dict[str, list[ast.expr]] = {}
    for n in ast.walk(ast.Module(body=list(body), type_ignores=[])):
        if isinstance(n, ast.Assign):
            for t in n.targets:
                if isinstance(t, ast.Name):
                    bound.setdefault(t.id, []).append(n.value)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.With | ast.AsyncWith) and any(
                write_kind(i.context_expr) == "write" for i in node.items):
            continue  # a write session of its own: its writes are through the door
        if isinstance(node, ast.Call):
            f = node.func
            owner = _session_of_receiver(f.value) if isinstance(f, ast.Attribute) else None
            if isinstance(f, ast.Attribute) and f.attr in ("update", "delete"):
                root = _query_root(f.value)
                if root in names:
                    yield node.lineno, f"{root}.query(…).{f.attr}(…)"
            if owner in names:
                if f.attr in PRIMITIVES or (f.attr == "execute" and node.args
                                            and _is_write_construct(node.args[0], bound)):
                    yield node.lineno, f"{owner}.{f.attr}(…)"
            target = _canonical(_target(mod, f), modules)
            passed = set().union(*(_names(a) for a in [*node.args, *(k.value for k in node.keywords)]))
            if target in writers and passed & names:
                yield node.lineno, f"{target}({', '.join(sorted(passed & names))}, …)"
        stack.extend(ast.iter_child_nodes(node))


def session_writers(modules: dict[str, Module]) -> set[str]:
    """Every function (``module.function``) that writes through a session it is given."""
    fns = [(m, fn) for m in modules.values() for fn in _functions(m.tree)
           if fn in m.tree.body or isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef)]
    writers: set[str] = set()
    while True:
        found = {f"{m.name}.{fn.name}" for m, fn in fns
                 if (params := _session_params(fn))
                 and next(_writes(m, fn.body, params, writers, modules), None) is not None}
        if found <= writers:
            return writers
        writers |= found


def writes_in_read_sessions(modules: dict[str, Module],
                            writers: set[str] | None = None) -> list[str]:
    """``path:line: write`` for every write found in the body of a read session's block."""
    writers = session_writers(modules) if writers is None else writers
    out = []
    for mod in modules.values():
        for node in ast.walk(mod.tree):
            if not isinstance(node, ast.With | ast.AsyncWith):
                continue
            names = {i.optional_vars.id for i in node.items
                     if write_kind(i.context_expr) == "read"
                     and isinstance(i.optional_vars, ast.Name)}
            if names:
                out += [f"{mod.path}:{line}: {what} in a read session"
                        for line, what in _writes(mod, node.body, names, writers, modules)]
    return sorted(set(out))
