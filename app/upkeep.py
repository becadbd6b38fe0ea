"""What keeps a serving process lean while sessions come and go (docs/app.md, "Memory after
sessions close", "Sessions that close"): the deployment's allocator (:data:`SERVE_ENV`), the
start-up's objects frozen before the first session (:func:`freeze_startup_objects`), the heap
collected and trimmed after a wave of closed sessions (:func:`release_memory`)."""

from __future__ import annotations

import ctypes
import gc
from typing import Any

from tornado.ioloop import IOLoop

#: Environment of a served app process, set by the deployment files (deploy/systemd/railval@.service,
#: deploy/compose.yaml) and the team topology (app/bench/topology.py). ``PYTHONMALLOC=malloc``
#: (Python docs, "Command line and environment": PYTHONMALLOC) hands Python's small objects to
#: glibc malloc instead of pymalloc: a Panel session on its first page is ≈ 14 000 small objects
#: (≈ 1.5 MiB of param and Bokeh properties, 60–150 B each) spread over pymalloc's 1 MiB arenas (CPython Objects/obmalloc.c,
#: ARENA_BITS 20), and an arena goes back to the system only when every object in it is
#: free, which long-lived objects allocated in between prevent; glibc's ``malloc_trim`` returns
#: every free page instead. Measured (docs/app.md, "Memory after sessions close"): 10 sessions
#: closed returned 85 % of their memory instead of 7 %, for ≈ 9 MiB more at start.
SERVE_ENV: dict[str, str] = {"PYTHONMALLOC": "malloc"}


def freeze_startup_objects() -> None:
    """Collect the start-up's garbage, then move every object alive now — the modules, classes
    and registries of Panel, Bokeh, pandas, SciPy and railval, ≈ 340 000 objects the collector
    tracks — to the collector's permanent generation (``gc.freeze``, Python docs, "gc — Garbage
    Collector interface"): they live as long as the process anyway. A full collection then walks
    only what sessions allocate: Panel runs one after sessions are destroyed
    (``panel/io/document.py``, ``_garbage_collect``) and :func:`release_memory` one per wave of
    closed sessions, each ≈ 0.13 s of the server's CPU over the whole heap (docs/app.md,
    "Sessions that close"); the interpreter's own full collections become as cheap. Called once,
    before the server accepts a session, so no session's objects are frozen."""
    gc.collect()
    gc.freeze()


#: a trim is scheduled and has not run yet (sessions closing together share one trim)
_trim_pending = False


def _trim() -> None:
    global _trim_pending
    _trim_pending = False
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: nothing to trim
        pass


def release_memory(session_context: Any) -> None:
    """When a Bokeh session is destroyed: shortly afterwards (once its document is released)
    collect reference cycles and hand the freed heap back to the operating system (glibc
    ``malloc_trim(0)``, which since glibc 2.8 releases free pages anywhere in the heap, man 3
    malloc_trim); without it a process's resident memory stays at its peak after sessions close
    (holoviz/panel #8189). It returns the sessions' memory only when Python's objects live in
    glibc's heap (:data:`SERVE_ENV`); under pymalloc the freed arenas stay with the process and
    are reused by the next sessions (bokeh/bokeh #11477)."""
    global _trim_pending
    if _trim_pending:  # one trim after a wave of closed sessions, not one per session (8
        return         # sessions closing together cost 7.8 s of the server's time, docs/app.md)
    try:
        IOLoop.current().call_later(2.0, _trim)
        _trim_pending = True
    except RuntimeError:  # no event loop (tests calling it directly)
        _trim()
