"""Where the time of a request goes: wall seconds per named stage (decode, filter,
statistics, aggregation, bootstrap, database …), for the benchmarks (``railval bench
dynotrain`` prints the split, docs/validation.md, Throughput).

A caller that wants the split runs its work inside ``with collect() as stages:``; code on
the way marks its parts with ``with stage("decode"):``. Without a collector ``stage`` does
nothing but look up a context variable. Stages nest: a stage's time excludes the time of the
stages inside it (``aggregation`` does not count the ``bootstrap`` it runs). Work handed to a
thread carries the collector along when submitted with :func:`in_context`; times of parallel
threads add up (CPU-like seconds, not elapsed time).
"""

from __future__ import annotations

import contextvars
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager


class Stages:
    """Accumulated self-time per stage name, in s (thread-safe)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._lock = threading.Lock()

    def add(self, name: str, seconds: float) -> None:
        with self._lock:
            self.seconds[name] = self.seconds.get(name, 0.0) + seconds

    def merge(self, seconds: dict[str, float]) -> None:
        for name, value in seconds.items():
            self.add(name, value)


_CURRENT: contextvars.ContextVar[tuple[Stages, list] | None] = contextvars.ContextVar(
    "railval_stages", default=None)


@contextmanager
def collect() -> Iterator[Stages]:
    """Collect the stage times of the work done inside the block (this thread and threads
    started with :func:`in_context`)."""
    stages = Stages()
    token = _CURRENT.set((stages, [0.0]))
    try:
        yield stages
    finally:
        _CURRENT.reset(token)


def current() -> Stages | None:
    """The active collector, or None."""
    cur = _CURRENT.get()
    return cur[0] if cur is not None else None


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Time the block as stage ``name`` (minus the stages nested in it) when a collector is
    active."""
    cur = _CURRENT.get()
    if cur is None:
        yield
        return
    stages, _ = cur
    children = [0.0]
    token = _CURRENT.set((stages, children))
    t0 = time.perf_counter()
    try:
        yield
    finally:
        elapsed = time.perf_counter() - t0
        _CURRENT.reset(token)
        stages.add(name, elapsed - children[0])
        cur[1][0] += elapsed  # the enclosing stage does not count this time as its own


def in_context(fn):
    """``fn`` bound to a copy of this thread's context (so a worker thread reports into the
    active collector): ``pool.submit(in_context(fn), *args)``."""
    ctx = contextvars.copy_context()

    def fresh(*args, **kwargs):
        cur = _CURRENT.get()
        if cur is not None:  # the thread's stages nest in no stage of the submitting thread
            _CURRENT.set((cur[0], [0.0]))
        return fn(*args, **kwargs)

    def run(*args, **kwargs):
        return ctx.run(fresh, *args, **kwargs)
    return run
