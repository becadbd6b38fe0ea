"""How a validation's sections are processed: the execution machinery of
:mod:`railval.app.services.validation` (what a caller asks for lives there).

* the pipeline of one process (:func:`read_and_process`): this thread reads the blobs of the
  next chunk while :data:`_PIPELINE_THREADS` threads decode and process earlier ones;
* the chunks of a run over many configurations (:func:`source_chunks`) processed on a Dask
  scheduler, on worker processes (forked, kernels warmed before the fork, each worker's
  glibc heap kept between chunks), on threads of this process or serially
  (:func:`process_chunks`);
* the garbage collector's passes kept off the heap alive at the start of a validation
  (:func:`heap_frozen`; Python docs of :mod:`gc`, ``gc.freeze``).

Nothing here decides a verdict or touches the result cache: the chunk tasks return packed
values (:func:`railval.core.en14363.pack_values`), stage seconds and the seals read with
the blobs, which the caller checks (:mod:`railval.app.services.validation_rows`).
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import os
import threading
from collections import deque
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from typing import Any

import numpy as np
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session

from railval.core import lazy
from railval.core.stages import collect, in_context, stage
from railval.core.types import BODY_POSITIONS, WHEEL_POSITIONS, SectionInfo, SignalSet
from railval.core.workers import pool_kwargs, row_threads, thread_count
from railval.db import codec, repo
from railval.db.engine import connect

#: deferred (railval.core.lazy): the process-pool executor (Dask) only for a run with a
#: scheduler
BatchExecutor = lazy.function("railval.app.services.batch", "BatchExecutor")

# the EN 14363 processing loads numba and scipy.signal: imported when the first section is
# processed
en14363 = lazy.module("railval.core.en14363")
pack_values = lazy.function("railval.core.en14363", "pack_values")

#: sections read per query while the previous chunks are processed
PIPELINE_CHUNK = 4
#: threads that decode and process the chunks of one source at once (each with its share of
#: the row threads): decoding one chunk overlaps the Python parts of the EN chain of another
_PIPELINE_THREADS = 2


def _pipeline_chunks(todo: Sequence[tuple[Any, list[str]]]) -> list[tuple[Any, list[str]]]:
    """The sections to process, ``todo`` = [(source, section ids)] in order, cut into chunks
    of one source of :data:`PIPELINE_CHUNK` sections, the remainder last (17 sections:
    4 + 4 + 4 + 4 + 1 — the small last chunk shortens the tail where one thread waits)."""
    return [(source, sids[i:i + PIPELINE_CHUNK])
            for source, sids in todo for i in range(0, len(sids), PIPELINE_CHUNK)]


def read_and_process(session: Session, camp, todo: Sequence[tuple[Any, list[str]]],
                      by_id: dict[str, SectionInfo], order: int, while_processing=None,
                      on_read=None
                      ) -> dict[tuple[Any, str], tuple[en14363.SectionValues, bytes]]:
    """Read, decode and process the sections ``todo`` = [(source ref or None, section ids)]
    of one or more sources as one pipeline: (source, section id) → (values, packed values).

    This thread reads the blobs of the next chunk (the caller's session stays in this
    thread) while :data:`_PIPELINE_THREADS` threads decode and process earlier ones — the
    chunks of every source in one pool, so the second source's first chunks overlap the
    first source's last. Decoding in those threads, not here, avoids thousands of GIL
    hand-overs with this thread (every inflate and plane copy releases the GIL); two of them
    overlap one chunk's decode with the Python parts of another's EN chain.
    ``while_processing()`` runs once every chunk is read (here, while the threads
    process); ``on_read(decode)`` after each chunk is read (``decode`` of
    :func:`railval.db.repo.fetch_signalsets`); when either raises, the remaining chunks are
    dropped."""
    chunks = _pipeline_chunks(todo)
    threads = min(_PIPELINE_THREADS, len(chunks))
    row = max(1, thread_count() // threads)
    pending = []
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="railval-chunk") as pool:
        try:
            for source, chunk in chunks:
                with stage("database"):
                    decode = repo.fetch_signalsets(session, camp, source, sections=chunk,
                                                   verify=True)
                    if on_read is not None:
                        on_read(decode)
                pending.append((source, chunk, pool.submit(
                    in_context(_decode_and_evaluate), decode, [by_id[s] for s in chunk],
                    order, row)))
            if while_processing is not None:
                while_processing()
            out = {}
            for source, chunk, fut in pending:
                for sid, vals in zip(chunk, fut.result(), strict=True):
                    with stage("cache_pack"):
                        out[(source, sid)] = (vals, pack_values(vals))
        except BaseException:
            pool.shutdown(cancel_futures=True)
            raise
    return out


def _decode_and_evaluate(decode, sections: list[SectionInfo], order: int,
                         row: int | None = None) -> list[en14363.SectionValues]:
    """Decode one chunk's blobs and process its sections; ``row``: row threads of the
    decode and the compiled kernels (:func:`railval.core.workers.row_threads`; None: the
    process's). A chunk thread of the pipeline decodes its blobs on its own share: two
    chunk threads decoding at once with the shared row thread were three threads taking
    turns at the GIL for every inflate."""
    with row_threads(row) if row else contextlib.nullcontext():
        with stage("decode"):
            signalsets = decode()
        values = en14363.evaluate_present(signalsets, sections, order=order)
    return [values[s.id] for s in sections]


def _evaluate_chunk(db_or_url, campaign: str, config: str | None,
                    sections: list[SectionInfo], order: int,
                    threads: int | None = None) -> tuple[list[bytes], dict, list]:
    """Worker task: load and process some sections of one source; returns packed values,
    the seconds per stage it spent (:mod:`railval.core.stages`) and the signal rows it read
    with their seals (``seals`` of :func:`railval.db.repo.fetch_signalsets`), which the
    main process checks (:class:`railval.app.services.validation_rows.SealCheck`) instead of
    reading them again.
    ``db_or_url``: a :class:`railval.db.engine.Database` (in-process) or its URL (worker
    process); ``threads``: row threads of the EN chain in this worker process (the workers
    share the cores, so each takes its part instead of all of them)."""
    if threads:
        os.environ["RAILVAL_THREADS"] = str(threads)
    with collect() as stages:
        if isinstance(db_or_url, str) and not _WORKER_SETUP:
            _worker_process_setup()
        if isinstance(db_or_url, str) and not _WORKER_WARM:
            with stage("worker_start"):
                _warm_kernels(order)
        with stage("database"):
            database = _worker_database(db_or_url) if isinstance(db_or_url, str) else db_or_url
        with database.session() as session:
            with stage("database"):
                decode = repo.fetch_signalsets(session, campaign, config,
                                               sections=[s.id for s in sections], verify=True,
                                               seals=True)
            vals = _decode_and_evaluate(decode, sections, order)
        with stage("cache_pack"):
            packed = [pack_values(v) for v in vals]
    return packed, stages.seconds, decode.seals


def _evaluate_chunk_task(args: tuple) -> list[bytes]:
    """:func:`_evaluate_chunk` for an executor's ``map`` (one argument)."""
    return _evaluate_chunk(*args)


_WORKER_DB: dict[str, Any] = {}
#: filter orders this process has warmed up with (:func:`_warm_kernels`; the compiled kernels
#: are the same for every order, so one is enough)
_WORKER_WARM: set[int] = set()
#: load the kernels in this process before forking the worker processes (once, instead of
#: once per worker)
_WARM_BEFORE_FORK = True


def _warm_kernels(order: int) -> None:
    """Load the compiled kernels of the EN chain in this process (numba's on-disk cache,
    ≈ 0.25 s) by processing one small synthetic section: in the main process before it forks
    the workers (they inherit them), or in a worker that came without them (Dask); timed as
    the stage ``worker_start`` by ``railval bench dynotrain``."""
    n, fs = 2000, 500.0
    t = np.arange(n) / fs
    noise = np.random.default_rng(0).standard_normal(n)
    channels = {f"{k}_{p}": noise + (75.0 if k == "Q" else 0.0)
                for p in WHEEL_POSITIONS for k in ("Y", "Q")}
    channels |= {f"{k}_cb_{b}": 0.3 * noise for b in BODY_POSITIONS for k in ("ay", "az")}
    en14363.evaluate_batch([SignalSet(fs, t, 25.0 * t, channels)],
                           [SectionInfo("warm-up", 0.0, 0.0, 90.0, 1, 10.0, 90.0)], order=order)
    codec.decode(*codec.encode(noise))  # the codec's kernel (db/codec_planes.py)
    _WORKER_WARM.add(order)


#: :func:`_worker_process_setup` has run in this process
_WORKER_SETUP: list[bool] = []
#: a worker process keeps freed heap memory up to this many bytes for its next chunk
#: (glibc ``M_TRIM_THRESHOLD``) and serves allocations below ``_WORKER_MMAP_BYTES`` from
#: the heap (``M_MMAP_THRESHOLD``)
_WORKER_TRIM_BYTES = 256 << 20
_WORKER_MMAP_BYTES = 4 << 20


def _worker_process_setup() -> None:
    """Once per worker process (one that reads the database by URL: a process of the pool,
    or a Dask worker): it reads every blob once, so

    * the verified-array cache (:data:`railval.db.codec.VERIFIED`) is turned off — every
      read is still hashed and checked, but the blobs are not kept for a second read that
      never comes (kept, each chunk's 15–20 MB of blobs came from fresh memory: ≈ 12 000
      page faults and ≈ 0.02 CPU-s per DynoTRAIN source);
    * glibc keeps the freed heap for the next chunk instead of returning it to the kernel
      (``mallopt``; without it each chunk's blobs were faulted in again). Not glibc: skipped.
    """
    codec.VERIFIED.limit_bytes = 0
    codec.VERIFIED.clear()
    try:
        mallopt = ctypes.CDLL(None).mallopt
        mallopt(-1, _WORKER_TRIM_BYTES)  # M_TRIM_THRESHOLD
        mallopt(-3, _WORKER_MMAP_BYTES)  # M_MMAP_THRESHOLD
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        pass
    _WORKER_SETUP.append(True)


def _worker_database(url: str):
    if url not in _WORKER_DB:
        _WORKER_DB[url] = connect(url)
    return _WORKER_DB[url]



def source_chunks(todo: dict[str | None, list[str]], chunk_sections: int
            ) -> list[tuple[str | None, list[str]]]:
    """The sections still to process as chunks of one source, the measurement first (every
    verdict needs it), each source cut into near-equal parts of at most ``chunk_sections``
    sections (17 sections by 8: 6 + 6 + 5, not 8 + 8 + 1)."""
    out = []
    for source in sorted(todo, key=lambda s: s is not None):
        sids = todo[source]
        parts = -(-len(sids) // max(1, chunk_sections))
        out += [(source, sids[k * len(sids) // parts:(k + 1) * len(sids) // parts])
                for k in range(parts)]
    return out


def _thread_chunk(decode, sections: list[SectionInfo], order: int,
                  row: int) -> tuple[list[bytes], dict, list]:
    """Thread task: decode and process one chunk read by the calling thread, with ``row`` row
    threads for the compiled kernels; stage times go to the caller's collector."""
    vals = _decode_and_evaluate(decode, sections, order, row)
    with stage("cache_pack"):
        packed = [pack_values(v) for v in vals]
    return packed, {}, decode.seals


_FROZEN_LOCK = threading.Lock()
#: nesting depth of :func:`heap_frozen` in this process (validations of several threads)
_FROZEN_DEPTH = [0]


@contextlib.contextmanager
def heap_frozen():
    """The objects alive on entry are left out of the garbage collector's passes until the
    outermost of these contexts ends (``gc.freeze``/``gc.unfreeze``, Python docs of
    :mod:`gc`). A run creates many short-lived containers, so the collector runs a few hundred
    times; in a fresh process one or two of its full passes walked every object of the
    imported libraries (≈ 0.2 CPU-s of the 46-configuration run's main process, measured with
    ``gc.callbacks``), and a collection in a forked worker writes to every object's header,
    copying the shared pages. Nested and concurrent uses unfreeze only when the last ends."""
    with _FROZEN_LOCK:
        if _FROZEN_DEPTH[0] == 0:
            gc.freeze()
        _FROZEN_DEPTH[0] += 1
    try:
        yield
    finally:
        with _FROZEN_LOCK:
            _FROZEN_DEPTH[0] -= 1
            if _FROZEN_DEPTH[0] == 0:
                gc.unfreeze()


def process_chunks(database, plan, chunks: list[tuple[str | None, list[str]]], order: int,
             workers: int, scheduler, collect_chunk, backend: str = "processes") -> None:
    """Process the chunks on the chosen back end: a Dask scheduler, ``workers`` processes,
    ``workers`` threads of this process (``backend="threads"``) or this process alone;
    ``collect_chunk(chunk, (packed values, stage seconds))`` per chunk, in chunk order."""
    by_id = {s.id: s for s in plan.sections}
    if scheduler is not None and chunks:
        url = make_url(database.url).set(password=None).render_as_string(hide_password=False)
        with BatchExecutor(scheduler) as ex:
            packed = ex.map(_evaluate_chunk_task, [(url, plan.name, c[0],
                                                    [by_id[s] for s in c[1]], order)
                                                   for c in chunks])
        for chunk, blobs in zip(chunks, packed, strict=True):
            collect_chunk(chunk, blobs)
    elif workers > 1 and len(chunks) > 1 and backend == "threads":
        _process_threads(database, plan, chunks, order, workers, collect_chunk)
    elif workers > 1 and len(chunks) > 1:
        threads = max(1, thread_count() // workers)
        if _WARM_BEFORE_FORK and not _WORKER_WARM:
            # loaded once here, the kernels come with the fork to every worker
            with stage("worker_start"):
                _warm_kernels(order)
        # the forked workers share this process's memory copy-on-write; a full garbage
        # collection here (or there) writes to every object's header and copies the whole
        # heap (0.1-0.2 s per collection): the objects alive now (the kernels just loaded
        # too) are frozen for the pool's lifetime (Python docs, gc.freeze; see heap_frozen)
        with heap_frozen(), ProcessPoolExecutor(max_workers=workers, **pool_kwargs()) as pool:
            futures = [(c, pool.submit(_evaluate_chunk, database.url, plan.camp,
                                       plan.ref(c[0]), [by_id[s] for s in c[1]], order,
                                       threads))
                       for c in chunks]
            try:
                for chunk, fut in futures:
                    with stage("main_idle"):
                        done = fut.result()
                    collect_chunk(chunk, done)
            except BaseException:  # e.g. a broken seal: the remaining chunks are moot
                pool.shutdown(cancel_futures=True)
                raise
    else:
        for chunk in chunks:
            collect_chunk(chunk, _evaluate_chunk(database, plan.camp, plan.ref(chunk[0]),
                                                 [by_id[s] for s in chunk[1]], order))


def _process_threads(database, plan, chunks: list[tuple[str | None, list[str]]],
                     order: int, workers: int, collect_chunk) -> None:
    """``workers`` threads of this process decode and process the chunks (the compiled
    kernels release the GIL) while this thread reads the blobs of the next chunks (at most
    ``workers + 1`` read ahead) and collects the finished ones."""
    by_id = {s.id: s for s in plan.sections}
    row = max(1, thread_count() // workers)
    pending: deque = deque()

    def collect_first():
        chunk, fut = pending.popleft()
        with stage("main_idle"):
            done = fut.result()
        collect_chunk(chunk, done)

    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="railval-chunk") as pool:
        for chunk in chunks:
            # a session per read: the collector opens its own (seals) between the reads
            with stage("database"), database.session() as session:
                decode = repo.fetch_signalsets(session, plan.camp, plan.ref(chunk[0]),
                                               sections=chunk[1], verify=True, seals=True)
            pending.append((chunk, pool.submit(in_context(_thread_chunk), decode,
                                               [by_id[s] for s in chunk[1]], order, row)))
            while len(pending) > workers + 1 or (pending and pending[0][1].done()):
                collect_first()
        while pending:
            collect_first()
