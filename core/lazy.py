"""Deferred imports: a module or a function that is loaded when it is first used.

The command line starts a verb without the libraries its work may never reach (scipy.signal,
scipy.stats, pandas, numba, the plotting libraries): ``railval signoff list`` reads records,
``railval workshop analyse`` looks its workshop up first, and an answer that needs no filter
must not wait ~1 s for scipy.signal and numba to load. A service module whose top level names
a heavy function binds it with :func:`function` instead of ``from … import …``; a module that
uses a heavy library as a namespace binds it with :func:`module`. Nothing is imported until
the name is called or an attribute is read; then the real import runs once (the ordinary
``importlib.import_module``, with its own lock) and the proxy forwards to what it loaded.

Unlike :class:`importlib.util.LazyLoader`, neither proxy enters ``sys.modules`` before the
import really happens, so ``"scipy.signal" in sys.modules`` keeps telling whether the library
was loaded (tests/test_cli_startup.py relies on that), and an import error surfaces at the
first use with the module's own traceback.

Examples
--------
>>> from railval.core import lazy
>>> fmean = lazy.function("statistics", "fmean")
>>> fmean([1.0, 2.0, 4.0]) * 3
7.0
>>> json = lazy.module("json")
>>> json.dumps([1])
'[1]'
"""

from __future__ import annotations

import importlib
import types
from typing import Any


class LazyModule(types.ModuleType):
    """A stand-in for the module ``name``, imported when one of its attributes is first read
    (PEP 562's ``__getattr__``, applied to a whole module)."""

    def __init__(self, name: str):
        super().__init__(name, f"deferred import of {name} (railval.core.lazy)")
        self.__dict__["_lazy_target"] = None

    def _load(self) -> types.ModuleType:
        target = self.__dict__["_lazy_target"]
        if target is None:
            target = importlib.import_module(self.__name__)
            self.__dict__["_lazy_target"] = target
        return target

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__") and attr.endswith("__"):
            raise AttributeError(attr)  # copy/pickle/inspect probe dunders: stay unloaded
        return getattr(self._load(), attr)

    def __dir__(self) -> list[str]:
        return dir(self._load())

    def __repr__(self) -> str:
        state = "loaded" if self.__dict__["_lazy_target"] is not None else "not loaded"
        return f"<lazy module {self.__name__!r} ({state})>"


class LazyFunction:
    """A stand-in for ``module.attr`` (a function or another callable), imported on the first
    call and called through from then on."""

    __slots__ = ("_module", "_attr", "_target")

    def __init__(self, module: str, attr: str):
        self._module, self._attr = module, attr
        self._target = None

    def _load(self):
        if self._target is None:
            self._target = getattr(importlib.import_module(self._module), self._attr)
        return self._target

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self._load()(*args, **kwargs)

    def __getattr__(self, attr: str) -> Any:  # __doc__, __wrapped__, py_func, …
        return getattr(self._load(), attr)

    def __reduce__(self):  # sent to a worker process: re-bound there, imported on its call
        return (LazyFunction, (self._module, self._attr))

    def __repr__(self) -> str:
        return f"<lazy function {self._module}.{self._attr}>"


def module(name: str) -> LazyModule:
    """The module ``name`` (``"scipy.stats"``), imported on first attribute access."""
    return LazyModule(name)


def function(module_name: str, attr: str) -> LazyFunction:
    """The callable ``attr`` of ``module_name``, imported on its first call."""
    return LazyFunction(module_name, attr)

