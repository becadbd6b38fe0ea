"""Review plots of a workshop rendered once, in parallel, by content (docs/workshops.md
"One fixed scaling", "Rendering speed").

Each review plot is drawn once with matplotlib's Agg backend
(:mod:`railval.app.services.workshop_canvas`: the look, the reusable figures, the PNG writer)
and stored as PNG bytes with its render parameters and SHA-256; reviewers are served exactly
those bytes and cannot rescale them. The same inputs give byte-identical files.

This module decides what is drawn where: :data:`STYLE` and :data:`RENDER_VERSION` (stored with
every plot), the content key of a plot (:func:`content_key`: the SHA-256 of everything that
decides its pixels), and :func:`render_many`, which renders a workshop's plots on a pool of
:data:`RENDER_WORKERS` processes and plots of identical content once — within a workshop and,
through a bounded cache (:data:`CACHE_BYTES`), across the workshops this process creates.
The pool starts either when the plots are known (:func:`pool_context`: forked after
:func:`~railval.app.services.workshop_canvas.warm` from a quiet main thread, else from the
``forkserver``) or, by :func:`early_pool`, before their signals are read: its workers then
import the renderer and draw their first figures while this process reads and filters
(docs/workshops.md "Workers started before the signals are read"). The workers end with
their parent (:mod:`railval.core.workers`). This module does not import the plotting
backend: a process that hands the drawing to its workers never loads it.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import matplotlib
import numpy as np

from railval.app.scales import MEASURED_COLOR, SIM_COLORS
from railval.app.services.batch import FORKSERVER_PRELOAD, start_context
from railval.core import lazy
from railval.core.workers import exit_with_parent, keep_freed_memory
from railval.core.workshop import Scale

#: the drawing (matplotlib's figures and the Agg backend), imported where plots are drawn
CANVAS = "railval.app.services.workshop_canvas"
render_png = lazy.function(CANVAS, "render_png")
warm = lazy.function(CANVAS, "warm")

#: how the stored PNG bytes are made (stored with each plot's render parameters and part of
#: :func:`content_key`): 1 — the whole figure drawn per plot, matplotlib's PNG writer (RGBA,
#: zlib level 6); 2 — the static parts drawn once per scale and labels and restored,
#: :func:`encode_png` (RGB, Up filter, zlib level 1). The pixels of 1 and 2 are identical;
#: 3 — the title on up to three lines and the axes narrowed to hold it and the last x tick label
#: (:data:`STYLE` ``margins``; 1 and 2 cut long titles and that label at the figure's edge).
RENDER_VERSION = 3

#: the look of every review plot (stored with each plot's render parameters)
STYLE: dict[str, Any] = {
    "width_in": 10.0,
    "height_in": 5.6,
    "dpi": 100,
    "font": "DejaVu Sans",
    "font_size": 12,
    "title_size": 13,
    "measurement": {"label": "measurement", "color": MEASURED_COLOR, "linewidth": 1.2, "zorder": 2},
    "simulation": {"label": "simulation", "color": SIM_COLORS[0], "linewidth": 1.1, "zorder": 3},
    "legend": "upper right",
    "grid_color": "#d9d9d9",
    #: the axes within the figure: room above for a title of up to three lines, right of the
    #: axes for the half of the last x tick label that lies beyond it
    "margins": {"left": 0.09, "right": 0.96, "top": 0.86, "bottom": 0.11},
}


# ------------------------------------------------------------------------- many plots
def _default_workers() -> int:
    env = os.environ.get("RAILVAL_RENDER_WORKERS", "").strip()
    if env.isdigit() and int(env) >= 1:
        return int(env)
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    return max(1, min(2, cores))


#: processes rendering one workshop's plots (``$RAILVAL_RENDER_WORKERS``, default: the cores
#: this process may use, at most 2 — the deployment's machines have 2); 1: in this process
RENDER_WORKERS = _default_workers()
#: fewer plots to render than this are rendered in this process (a pool costs time to start)
POOL_MIN_PLOTS = 16
#: plots handed to a worker at once
CHUNK = 4
#: PNG bytes kept by content key in this process, across workshops (oldest dropped first)
CACHE_BYTES = 64 * 1024 * 1024
_CACHE: OrderedDict[str, bytes] = OrderedDict()
_CACHE_LOCK = threading.Lock()


@dataclass(frozen=True)
class PlotSpec:
    """Everything that decides one review plot's pixels."""

    x_meas: np.ndarray
    y_meas: np.ndarray
    x_sim: np.ndarray
    y_sim: np.ndarray
    scale: Scale
    title: str
    x_label: str
    y_label: str


def content_key(spec: PlotSpec) -> str:
    """SHA-256 of the plot's data (dtype, shape and bytes of the four arrays), scale, texts,
    :data:`STYLE`, the matplotlib version and :data:`RENDER_VERSION`: equal keys give equal PNG bytes."""
    h = hashlib.sha256()
    for a in (spec.x_meas, spec.y_meas, spec.x_sim, spec.y_sim):
        arr = np.ascontiguousarray(a)
        h.update(f"{arr.dtype.str}{arr.shape}".encode())
        h.update(arr.tobytes())
    h.update(json.dumps([spec.scale.to_dict(), spec.title, spec.x_label, spec.y_label, STYLE,
                         matplotlib.__version__, RENDER_VERSION], sort_keys=True, default=str).encode())
    return h.hexdigest()


def _render_chunk(specs: list[PlotSpec], render: Callable[..., bytes] | None = None) -> list[bytes]:
    """A worker's task: render ``specs`` in order (with :func:`render_png`, or ``render``)."""
    render = render_png if render is None else render
    return [render(s.x_meas, s.y_meas, s.x_sim, s.y_sim, s.scale, title=s.title,
                   x_label=s.x_label, y_label=s.y_label) for s in specs]


#: the renderer :func:`serial_renderer` puts in place of the pool and the cache (None: none)
_SERIAL: Callable[..., bytes] | None = None


@contextmanager
def serial_renderer(render: Callable[..., bytes]) -> Iterator[None]:
    """While the block runs, :func:`render_many` renders every plot with ``render`` (the
    signature of :func:`render_png`), one after the other in the calling thread, neither
    reading nor filling the cache — the benchmark's legacy way (``railval bench workshop
    --create-only``: a figure made for every plot, :func:`railval.app.bench.bench_workshop.legacy_png`)."""
    global _SERIAL
    saved, _SERIAL = _SERIAL, render
    try:
        yield
    finally:
        _SERIAL = saved


def _cached(key: str) -> bytes | None:
    with _CACHE_LOCK:
        png = _CACHE.get(key)
        if png is not None:
            _CACHE.move_to_end(key)
        return png


def _remember(key: str, png: bytes) -> None:
    with _CACHE_LOCK:
        _CACHE[key] = png
        _CACHE.move_to_end(key)
        total = sum(len(v) for v in _CACHE.values())
        while total > CACHE_BYTES and len(_CACHE) > 1:
            total -= len(_CACHE.popitem(last=False)[1])


def clear_cache() -> None:
    """Forget the PNG bytes kept across workshops (benchmarks measure without them)."""
    with _CACHE_LOCK:
        _CACHE.clear()


def render_many(specs: Sequence[PlotSpec], progress: Callable[[int, int], None] | None = None,
                *, workers: int | None = None, pool: ProcessPoolExecutor | None = None) -> list[bytes]:
    """PNG bytes of every spec, in order, the same as :func:`render_png` of each.

    Identical specs (:func:`content_key`) are rendered once and plots rendered earlier in
    this process come from the cache; the rest are rendered on ``pool`` (started before, by
    :func:`early_pool`) or on ``workers`` processes started now (default
    :data:`RENDER_WORKERS`), in chunks of :data:`CHUNK`. ``progress(done, total)`` is called
    in the calling thread as plots are ready (``total`` = ``len(specs)``)."""
    total = len(specs)
    if _SERIAL is not None:  # serial_renderer: no pool, no cache
        out_serial = []
        for i in range(0, total, CHUNK):
            out_serial += _render_chunk(list(specs[i:i + CHUNK]), _SERIAL)
            if progress is not None:
                progress(len(out_serial), total)
        return out_serial
    keys = [content_key(s) for s in specs]
    out: dict[str, bytes] = {}
    todo: dict[str, PlotSpec] = {}
    for k, s in zip(keys, specs, strict=True):
        png = out.get(k) or _cached(k)
        if png is not None:
            out[k] = png
        elif k not in todo:
            todo[k] = s

    def report() -> None:
        if progress is not None:
            progress(sum(1 for k in keys if k in out), total)
    report()  # rendering starts (plots found in the cache counted)
    n_workers = RENDER_WORKERS if workers is None else max(1, workers)
    chunks = _chunks_by_background(todo, n_workers)
    for ks, pngs in _run_chunks(chunks, todo, n_workers, pool):
        for k, png in zip(ks, pngs, strict=True):
            out[k] = png
            _remember(k, png)
        report()
    return [out[k] for k in keys]


def background_key(spec: PlotSpec) -> tuple[str, str, str]:
    """What a plot's static part depends on (its scale and axis labels): plots of one key
    share the background a canvas draws once (``workshop_canvas._Canvas._background``)."""
    return json.dumps(spec.scale.to_dict(), sort_keys=True), spec.x_label, spec.y_label


def _chunks_by_background(todo: dict[str, PlotSpec], workers: int) -> list[list[str]]:
    """The plots to render as tasks: the plots of one background together (a worker draws a
    background once for all of them, instead of every worker drawing every background — 17
    backgrounds of 41 ms each on the 120 demo plots), a group longer than a fair share
    (``len(todo) / (2·workers)``, at least :data:`CHUNK`) cut into parts of that size; the
    largest first, so that the last tasks are short and the workers end together. A plot's
    pixels do not depend on what its canvas drew before (tests/test_workshop_jobs.py), so
    the order changes no byte."""
    groups: dict[tuple[str, str, str], list[str]] = {}
    for k, spec in todo.items():
        groups.setdefault(background_key(spec), []).append(k)
    size = max(CHUNK, math.ceil(len(todo) / (2 * max(1, workers))))
    chunks = [g[i:i + size] for g in groups.values() for i in range(0, len(g), size)]
    return sorted(chunks, key=len, reverse=True)  # stable: equal sizes keep the plots' order


def _run_chunks(chunks: list[list[str]], todo: dict[str, PlotSpec], workers: int,
                pool: ProcessPoolExecutor | None = None):
    """Yield ``(keys, PNG bytes)`` of each chunk as it is ready: on ``pool`` when given (and
    there is something to render), in this thread for one worker or few plots, else on a
    process pool started for this call."""
    if pool is not None and chunks:
        yield from _on_pool(pool, chunks, todo)
        return
    if workers <= 1 or len(todo) < POOL_MIN_PLOTS:
        for ks in chunks:
            yield ks, _render_chunk([todo[k] for k in ks])
        return
    ctx = pool_context()
    with ProcessPoolExecutor(max_workers=min(workers, len(chunks)), mp_context=ctx,
                             initializer=_render_worker, initargs=(os.getpid(),)) as started:
        yield from _on_pool(started, chunks, todo)


def _on_pool(pool: ProcessPoolExecutor, chunks: list[list[str]], todo: dict[str, PlotSpec]):
    futures = {pool.submit(_render_chunk, [todo[k] for k in ks]): ks for ks in chunks}
    for f in as_completed(futures):
        yield futures[f], f.result()


def _render_worker(parent: int) -> None:
    """A worker of the pool :func:`render_many` starts: ends with its parent and keeps the
    memory it frees for the next plot (:func:`railval.core.workers.keep_freed_memory`)."""
    exit_with_parent(parent)
    keep_freed_memory()


def _start_worker(parent: int) -> None:
    """A worker of :func:`early_pool`: ends with its parent, keeps the memory it frees for
    the next plot (:func:`railval.core.workers.keep_freed_memory`), then imports the drawing
    and makes its figures (:func:`~railval.app.services.workshop_canvas.warm`)."""
    _render_worker(parent)
    warm()


def _started() -> int:
    return os.getpid()


@contextmanager
def early_pool(planned: int, *, workers: int | None = None) -> Iterator[ProcessPoolExecutor | None]:
    """A render pool started now, for ``planned`` plots whose signals are still to be read:
    its workers start at once (forked from a quiet main thread before this process imports
    the plotting backend, else from the ``forkserver``) and each imports the drawing and makes
    its figures while this process reads and filters — work that otherwise waits for the
    reading to end. Yields None where :func:`render_many` would render in this process (one
    worker, fewer than :data:`POOL_MIN_PLOTS` plots, :func:`serial_renderer`); the pool is
    shut down when the block ends (tasks not started are cancelled)."""
    n = RENDER_WORKERS if workers is None else max(1, workers)
    n = min(n, math.ceil(planned / CHUNK))
    if _SERIAL is not None or n <= 1 or planned < POOL_MIN_PLOTS:
        yield None
        return
    ctx = start_context()
    if ctx.get_start_method() != "fork":
        ctx.set_forkserver_preload([*FORKSERVER_PRELOAD, CANVAS])
    pool = ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_start_worker,
                               initargs=(os.getpid(),))
    try:
        for _ in range(n):  # every worker starts now (a forked pool starts them all at once)
            pool.submit(_started)
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def pool_context():
    """How the render pool of :func:`render_many` starts its workers when the plots are known
    (:func:`railval.app.services.batch.start_context`):
    from a quiet main thread (the CLI, the bench) ``fork`` — after :func:`warm`, so every
    worker starts with matplotlib imported, this thread's two figures made and their glyph
    bitmaps kept instead of importing, making and rasterising them again; otherwise (the
    server's job threads) ``forkserver``, which imports this module (and matplotlib) once
    for all the workers it starts, when this process starts it."""
    ctx = start_context()
    if ctx.get_start_method() == "fork":
        warm()
    else:
        ctx.set_forkserver_preload([*FORKSERVER_PRELOAD, CANVAS])
    return ctx


def render_parameters(kind: Mapping[str, Any], scale: Scale, *, scaling: str, title: str,
                      x_label: str, y_label: str, extra: Mapping[str, Any]) -> dict[str, Any]:
    """The JSON stored with a plot: everything that decides its pixels."""
    return {"kind": kind["id"], "domain": kind["domain"], "scaling": scaling,
            "scale": scale.to_dict(), "title": title, "x_label": x_label, "y_label": y_label,
            "style": STYLE, "matplotlib": matplotlib.__version__, "render_version": RENDER_VERSION,
            **dict(extra)}
