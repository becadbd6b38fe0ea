"""CLI verb ``bench``: run a benchmark module and print its figures.

``railval bench`` lists the benchmarks; ``railval bench NAME [options] [--json]`` runs
``app/bench/bench_NAME.py``. A benchmark module exposes ``run(args) -> dict`` (the figures:
name → number, string or nested dict) and optionally ``add_arguments(parser)`` for its own
options and a module docstring (first line shown in the list).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil

from railval.app import bench as bench_package
from railval.app.cli import emit_json
from railval.core.errors import NotFound


def available() -> dict[str, str]:
    """Benchmark name → first docstring line, from the ``railval.app.bench.bench_*`` modules."""
    out = {}
    for info in sorted(pkgutil.iter_modules(bench_package.__path__), key=lambda m: m.name):
        if info.name.startswith("bench_"):
            out[info.name[len("bench_"):]] = info.name
    return out


def _load(name: str):
    names = available()
    if name not in names:
        raise NotFound(f"benchmark {name!r} not found; available: {', '.join(names) or '(none)'}")
    return importlib.import_module(f"railval.app.bench.{names[name]}")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench", help="run a benchmark (app/bench/bench_NAME.py); no NAME lists them",
        description="Run a benchmark and print its figures. Benchmark options follow NAME.",
    )
    p.add_argument("name", metavar="NAME", nargs="?", help="benchmark name")
    p.add_argument("--json", action="store_true", help="print the figures as one JSON document")
    p.add_argument("options", nargs=argparse.REMAINDER, help="options of the benchmark")
    p.set_defaults(func=cmd_bench)


def cmd_bench(args: argparse.Namespace) -> int:
    if not args.name:
        for name, module in available().items():
            doc = (importlib.import_module(f"railval.app.bench.{module}").__doc__ or "").strip()
            print(f"{name:20s} {doc.splitlines()[0] if doc else ''}")
        return 0
    module = _load(args.name)
    parser = argparse.ArgumentParser(prog=f"railval bench {args.name}",
                                     description=(module.__doc__ or "").strip() or None)
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    if hasattr(module, "add_arguments"):
        module.add_arguments(parser)
    bench_args = parser.parse_args(args.options)
    bench_args.db = getattr(args, "db", None)
    figures = module.run(bench_args)
    if args.json or bench_args.json:
        emit_json({"benchmark": args.name, "figures": figures})
    else:
        print(format_table(figures))
    return 0


def _flatten(doc: dict, prefix: str = "") -> list[tuple[str, object]]:
    rows: list[tuple[str, object]] = []
    for key, value in doc.items():
        if isinstance(value, dict):
            rows += _flatten(value, f"{prefix}{key}.")
        else:
            rows.append((f"{prefix}{key}", value))
    return rows


def format_table(figures: dict) -> str:
    """Two aligned columns ``figure  value``; nested dicts become dotted names."""
    rows = _flatten(figures)
    width = max((len(k) for k, _ in rows), default=0)
    lines = []
    for key, value in rows:
        text = f"{value:.4g}" if isinstance(value, float) else str(value)
        lines.append(f"{key:<{width}}  {text}")
    return "\n".join(lines)
