"""The examples in the docstrings of ``railval.core`` run, and give what they show.

Every module under ``core/`` whose source holds a ``>>>`` example is imported and its
examples are run with :mod:`doctest` (each module's namespace, plus ``np`` for numpy)."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import numpy as np
import pytest

CORE = Path(__file__).resolve().parent.parent / "core"


def _modules_with_examples() -> list[str]:
    out = []
    for path in sorted(CORE.rglob("*.py")):
        if ">>>" in path.read_text(encoding="utf-8"):
            rel = path.relative_to(CORE).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            out.append(".".join(["railval.core", *parts]))
    return out


MODULES = _modules_with_examples()


def test_core_has_docstring_examples():
    assert "railval.core.review.rasch" in MODULES
    assert "railval.core.metrics.sprague_geers" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    tests = [t for t in finder.find(module, name, globs={**vars(module), "np": np}) if t.examples]
    assert tests, f"{name}: no docstring example found although its source holds '>>>'"
    for t in tests:
        runner.run(t)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} docstring examples failed"
