"""Validation of a stored configuration: database → EN 14363 processing → DynoTRAIN verdict.

:func:`validate_configuration` reads the campaign (sections, vehicle) and both sides of the
comparison from the database, processes them with :mod:`railval.core.en14363` and judges them with
:func:`railval.core.validation.validate`.

Results cache
-------------
Processing a section of one source (the measurement or a configuration) is cached in the
database table ``result_cache`` (:func:`railval.db.repo.cache_get` / :func:`railval.db.repo.cache_put`) under

    sha256(PROCESSING_VERSION, CACHE_FORM, filter order, section id, evaluated range, fs, n,
           distance-axis hash, sorted (channel, content hash) of the recording)

and holds the section's values (with the values under the alternative readings of the open
definitions and the supplementary values) as one float64 block behind a JSON layout of the
keys, which the main process parses once per distinct layout
(:func:`railval.core.en14363.pack_values`). Content hashes are read first, no blob touched
(:func:`railval.db.repo.signal_hashes`; one validation reads them with the seals,
:func:`railval.db.repo.seal_rows_many`, on SQLite from a covering index); only sections whose
key is not cached are loaded and processed. So the measured side is processed once per campaign and filter order,
and a new configuration costs only its own signals. Any change of samples, distance axis,
evaluated range, filter order or processing code changes the key.

The key is :func:`railval.core.en14363.section_cache_key`, the cached form
:func:`railval.core.en14363.pack_values`. :func:`railval.core.validation.validate_signalsets` is
the same pipeline for in-memory :class:`~railval.core.types.SignalSet` objects (simulation and
calibration loops without the database).

The campaign and configuration names are resolved once at the entrance
(:func:`railval.db.repo.resolve`); the references travel down to every query.

Length: the one-configuration and the many-configurations paths (chunks, workers, seals
checked while processing, verdicts as soon as a configuration is complete) are one pipeline
sharing the cache keys, the chunk task and the verdict; kept in one module so that they
cannot drift apart (tests/test_validation_pipeline.py compares them).
"""

from __future__ import annotations

import contextlib
import gc
import os
import threading
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sqlalchemy.orm import Session

from railval.core import lazy
from railval.core.errors import InvalidParameter
from railval.core.processing import DEFAULT_ORDER, check_order
from railval.core.stages import collect, in_context, stage
from railval.core.stages import current as current_stages
from railval.core.types import SectionInfo
from railval.core.workers import row_threads, thread_count
from railval.db import repo
from railval.db.engine import connect

if TYPE_CHECKING:
    from railval.core.validation import ValidationResult

# the EN 14363 processing and the verdict load numba and scipy.signal: imported when the first
# section is processed, so that an unknown campaign or configuration is answered at once
en14363 = lazy.module("railval.core.en14363")
pack_values = lazy.function("railval.core.en14363", "pack_values")
section_cache_key = lazy.function("railval.core.en14363", "section_cache_key")
unpack_values = lazy.function("railval.core.en14363", "unpack_values")
source_warnings = lazy.function("railval.core.validation", "source_warnings")
validate = lazy.function("railval.core.validation", "validate")

#: sections read per query while the previous chunks are processed
_PIPELINE_CHUNK = 4
#: share of the chunks of a run on worker processes collected before the seal check and the
#: first verdict (:class:`_Collector`)
_SEAL_HOLD = 0.8
#: threads that decode and process the chunks of one source at once (each with its share of
#: the row threads): decoding one chunk overlaps the Python parts of the EN chain of another
_PIPELINE_THREADS = 2


def source_cache_keys(session: Session, campaign, config: str | repo.ConfigRef | None,
                      sections: Sequence[SectionInfo], *, order: int = DEFAULT_ORDER
                      ) -> dict[str, str]:
    """section id → result-cache key of every recorded section of one source, read from the
    stored content hashes only (no blob is decoded)."""
    hashes = repo.signal_hashes(session, campaign, config)
    meta = repo.recording_meta(session, campaign, config)
    by_id = {s.id: s for s in sections}
    return {sid: section_cache_key(by_id[sid], meta[sid][1], meta[sid][2], meta[sid][0],
                                   hashes.get(sid, {}), order)
            for sid in meta if sid in by_id}


def source_values(session: Session, campaign, config: str | None, sections: Sequence[SectionInfo],
                  *, order: int = DEFAULT_ORDER, stats: dict | None = None,
                  while_processing=None) -> dict[str, en14363.SectionValues]:
    """Processed values of every section of one source (``config=None``: the measurement),
    from the result cache where possible. ``stats`` (optional dict) receives
    ``{"cached": n, "computed": n}``. ``while_processing()`` (optional) runs in this thread
    once every blob is read, while the sections are processed; when it raises, the
    remaining sections are dropped and nothing is cached."""
    with stage("database"):
        camp, conf = repo.resolve(session, campaign, config)
        source = conf if config is not None else None
        by_id = {s.id: s for s in sections}
        keys = source_cache_keys(session, camp, source, sections, order=order)
        cached = repo.cache_get_many(session, list(keys.values()))
    with stage("cache_unpack"):
        out = {sid: unpack_values(sid, cached[k]) for sid, k in keys.items() if k in cached}
    missing = [sid for sid in keys if sid not in out]
    if missing:
        done = _read_and_process(session, camp, [(source, missing)], by_id, order,
                                 while_processing)
        new: dict[str, bytes] = {}
        for (_src, sid), (vals, packed) in done.items():
            new[keys[sid]] = packed
            out[sid] = vals
        with stage("database"):
            repo.cache_put_many(session, new)
    elif while_processing is not None:
        while_processing()
    if stats is not None:
        stats.update({"cached": len(keys) - len(missing), "computed": len(missing)})
    return out


def _pipeline_chunks(todo: Sequence[tuple[Any, list[str]]]) -> list[tuple[Any, list[str]]]:
    """The sections to process, ``todo`` = [(source, section ids)] in order, cut into chunks
    of one source of :data:`_PIPELINE_CHUNK` sections, the remainder last (17 sections:
    4 + 4 + 4 + 4 + 1 — the small last chunk shortens the tail where one thread waits)."""
    return [(source, sids[i:i + _PIPELINE_CHUNK])
            for source, sids in todo for i in range(0, len(sids), _PIPELINE_CHUNK)]


def _read_and_process(session: Session, camp, todo: Sequence[tuple[Any, list[str]]],
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
    main process checks (:class:`_SealCheck`) instead of reading them again.
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
    import numpy as np

    from railval.core.types import BODY_POSITIONS, WHEEL_POSITIONS, SignalSet

    n, fs = 2000, 500.0
    t = np.arange(n) / fs
    noise = np.random.default_rng(0).standard_normal(n)
    channels = {f"{k}_{p}": noise + (75.0 if k == "Q" else 0.0)
                for p in WHEEL_POSITIONS for k in ("Y", "Q")}
    channels |= {f"{k}_cb_{b}": 0.3 * noise for b in BODY_POSITIONS for k in ("ay", "az")}
    en14363.evaluate_batch([SignalSet(fs, t, 25.0 * t, channels)],
                           [SectionInfo("warm-up", 0.0, 0.0, 90.0, 1, 10.0, 90.0)], order=order)
    from railval.db import codec

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
    from railval.db import codec

    codec.VERIFIED.limit_bytes = 0
    codec.VERIFIED.clear()
    try:
        import ctypes

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


@dataclass
class _Plan:
    """What a validation of several configurations reads before processing: the campaign,
    its sections and vehicle, the configurations' lineage provenance, the result-cache key
    of every (source, section) and the values found in the cache (``todo``: the sections of
    each source still to process)."""

    name: str
    sections: list[SectionInfo]
    vehicle: dict
    names: list[str]
    provenance: dict[str, dict]
    keys: dict[tuple[str | None, str], str]
    values: dict[str | None, dict[str, en14363.SectionValues]]
    todo: dict[str | None, list[str]]
    #: signal rows with their seals for :func:`_require_seals` (None: it reads them)
    evidence: tuple | None = None
    #: the campaign and the configurations resolved (:func:`_plan`)
    camp: repo.CampaignRef | None = None
    refs: dict[str, repo.ConfigRef] | None = None
    #: the signal rows the keys come from, without seals (:func:`_plan_keys`)
    rows: tuple | None = None

    def ref(self, source: str | None) -> repo.ConfigRef | None:
        """The reference of a source (``None``: the measurement)."""
        return None if source is None else self.refs[source]


def _plan(database, campaign_name: str, configs: Sequence[str] | None,
          order: int) -> _Plan:
    """Resolve names and read the result cache; no blob is read (the seals are checked by
    :class:`_SealCheck` before the first verdict)."""
    with stage("database"), database.session() as session:
        camp, _ = repo.resolve(session, campaign_name)
        # the rows stay referenced: the lineages below find them in the session (by id)
        conf_rows = repo.list_configurations(session, camp)
        refs = {c.name: repo.ConfigRef(camp, c.id, c.name) for c in conf_rows}
        names = (list(refs) if configs is None
                 else [c if isinstance(c, str) and c in refs
                       else repo.resolve(session, camp, c)[1].name for c in configs])
        sections = repo.section_infos(session, camp)
        keys, rows = _plan_keys(session, camp, [refs[c] for c in names], sections, order)
        plan = _Plan(camp.name, sections, repo.vehicle_info(session, camp), names,
                     {c: calibration_provenance(session, camp, refs[c]) for c in names}, keys,
                     {s: {} for s in [None, *names]}, {}, camp=camp,
                     refs={c: refs[c] for c in names}, rows=rows)
        cached = repo.cache_get_many(session, list(keys.values()))
    with stage("cache_unpack"):
        for (source, sid), key in keys.items():
            if key in cached:
                plan.values[source][sid] = unpack_values(sid, cached[key])
            else:
                plan.todo.setdefault(source, []).append(sid)
    return plan


def _plan_keys(session: Session, camp, refs: list, sections: Sequence[SectionInfo],
               order: int) -> tuple[dict[tuple[str | None, str], str], tuple]:
    """(source, section id) → result-cache key of the measurement (source ``None``) and of
    the configurations ``refs`` — :func:`source_cache_keys` for every source at once — and
    the signal rows they come from (:func:`railval.db.repo.hash_rows_many`: the content
    hashes without the seals, on SQLite from the indexes alone — no blob's overflow chain
    is walked before the workers start; :func:`_require_seals` reads and checks the seals
    while they process)."""
    rows = repo.hash_rows_many(session, camp, [r.id for r in refs])
    return _keys_from_rows(rows, [(None, None), *((r.name, r.id) for r in refs)], sections,
                           order), rows


def _keys_from_rows(rows: tuple[list, dict], sources: list[tuple[str | None, int | None]],
                    sections: Sequence[SectionInfo], order: int
                    ) -> dict[tuple[str | None, str], str]:
    """(source name, section id) → result-cache key (:func:`section_cache_key`, as
    :func:`source_cache_keys` makes it) of the sources ``[(name, configuration id or None
    for the measurement)]``, from their signal rows ``rows`` (the form of
    :func:`railval.db.repo.seal_rows_many`)."""
    recs, by_rec = rows
    per_source: dict[int | None, list] = {}
    for rec in recs:
        per_source.setdefault(rec[2], []).append(rec)
    by_id = {s.id: s for s in sections}
    keys: dict[tuple[str | None, str], str] = {}
    for name, cid in sources:
        for rid, sid, _cid, dsha, fs, _t0, n in per_source.get(cid, ()):
            if sid in by_id:
                hashes = {ch: sha for ch, _id, sha, _seal in by_rec.get(rid, ())}
                keys[(name, sid)] = section_cache_key(by_id[sid], float(fs), int(n), dsha,
                                                      hashes, order)
    return keys


def _require_seals(database, plan: _Plan) -> None:
    """The seals of every configuration's evidence and of the measurement (checked once), as
    :func:`validate_configuration` checks them (:func:`railval.db.repo.require_evidence`
    without reading blobs)."""
    with stage("database"), database.session() as session:
        repo.require_evidence_many(session, plan.name, plan.names, blobs=False,
                                   rows=plan.evidence)


class _SealCheck:
    """The seals of the evidence of every verdict, checked once before the first verdict as
    :func:`_require_seals` checks them, but from the signal rows the chunks read where it
    can (``add``: the seals :func:`railval.db.repo.fetch_signalsets` read with the blobs)
    instead of a second walk of the signal table (on SQLite the seal lies after the blob:
    reading it walks the blob's overflow chain, ≈ 0.3 CPU-s for a DynoTRAIN run). A source
    whose every row of the plan came with a chunk, with the same content hashes, is checked
    from those; the others (cached sources, sources not read yet) are read by
    :func:`railval.db.repo.seal_rows_many`, one query. Every seal is checked
    (:func:`railval.db.repo.seal_problems`), the measurement's once. On a problem the full
    check :func:`_require_seals` runs first and raises the same error as before; should it
    find none, the problems found here are raised, in the same form."""

    def __init__(self, database, plan: _Plan) -> None:
        self.database, self.plan = database, plan
        self.read: dict[tuple[int, str], tuple[str, str | None]] = {}

    def add(self, seals: list) -> None:
        for rid, chan, sha, seal in seals:
            self.read[(rid, chan)] = (sha, seal)

    def _sealed(self, recs: list, by_rec: dict) -> dict | None:
        """recording id → the plan's rows with the seals the chunks read, or None when one
        is missing or its content hash differs."""
        out = {}
        for rec in recs:
            rows = []
            for name, cid, sha, _none in by_rec.get(rec[0], ()):
                got = self.read.get((rec[0], name))
                if got is None or got[0] != sha:
                    return None
                rows.append((name, cid, sha, got[1]))
            out[rec[0]] = rows
        return out

    def __call__(self) -> None:
        plan = self.plan
        if plan.rows is None:  # pragma: no cover - every plan has its rows
            _require_seals(self.database, plan)
            return
        recs, by_rec = plan.rows
        per_source: dict[int | None, list] = {}
        for rec in recs:
            per_source.setdefault(rec[2], []).append(rec)
        ids = [None, *(plan.refs[c].id for c in plan.names)]
        sealed: dict[int | None, dict] = {}
        unread = []
        for src in ids:
            got = self._sealed(per_source.get(src, []), by_rec)
            if got is None:
                unread.append(src)
            else:
                sealed[src] = got
        self.read = {}
        with stage("database"), self.database.session() as session:
            problems = repo.seal_problems(session, plan.camp)
            if unread:
                _r, rows = repo.seal_rows_many(session, plan.camp,
                                               [s for s in unread if s is not None],
                                               measurement=None in unread)
                for src in unread:
                    sealed[src] = {rec[0]: rows.get(rec[0], []) for rec in per_source.get(src, [])}
            measured = problems(per_source.get(None, []), sealed[None])
            bad = [(c, problems(per_source.get(plan.refs[c].id, []), sealed[plan.refs[c].id]))
                   for c in plan.names]
        if measured or any(p for _c, p in bad):
            _require_seals(self.database, plan)  # raises the error of the full check
            for c, p in bad:
                repo.raise_problems(c, measured + p)


def _chunks(todo: dict[str | None, list[str]], chunk_sections: int
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
#: nesting depth of :func:`_heap_frozen` in this process (validations of several threads)
_FROZEN_DEPTH = [0]


@contextlib.contextmanager
def _heap_frozen():
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


def _process(database, plan: _Plan, chunks: list[tuple[str | None, list[str]]], order: int,
             workers: int, scheduler, collect_chunk, backend: str = "processes") -> None:
    """Process the chunks on the chosen back end: a Dask scheduler, ``workers`` processes,
    ``workers`` threads of this process (``backend="threads"``) or this process alone;
    ``collect_chunk(chunk, (packed values, stage seconds))`` per chunk, in chunk order."""
    by_id = {s.id: s for s in plan.sections}
    if scheduler is not None and chunks:
        from sqlalchemy.engine import make_url

        from railval.app.services.batch import BatchExecutor

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
        from railval.core.workers import pool_kwargs

        threads = max(1, thread_count() // workers)
        if _WARM_BEFORE_FORK and not _WORKER_WARM:
            # loaded once here, the kernels come with the fork to every worker
            with stage("worker_start"):
                _warm_kernels(order)
        # the forked workers share this process's memory copy-on-write; a full garbage
        # collection here (or there) writes to every object's header and copies the whole
        # heap (0.1-0.2 s per collection): the objects alive now (the kernels just loaded
        # too) are frozen for the pool's lifetime (Python docs, gc.freeze; see _heap_frozen)
        with _heap_frozen(), ProcessPoolExecutor(max_workers=workers, **pool_kwargs()) as pool:
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


def _process_threads(database, plan: _Plan, chunks: list[tuple[str | None, list[str]]],
                     order: int, workers: int, collect_chunk) -> None:
    """``workers`` threads of this process decode and process the chunks (the compiled
    kernels release the GIL) while this thread reads the blobs of the next chunks (at most
    ``workers + 1`` read ahead) and collects the finished ones."""
    from collections import deque

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


class _Collector:
    """Receives the processed chunks (``collect_chunk``): unpacks them into the plan's values,
    keeps the packed form for the cache and judges every configuration as soon as its values
    and the measurement's are complete, while the remaining chunks are being processed."""

    def __init__(self, plan: _Plan, order: int, n_boot: int, seed: int, progress,
                 check_seals=None, chunks: int = 0, hold_fraction: float = 0.0) -> None:
        self.plan, self.order, self.n_boot, self.seed = plan, order, n_boot, seed
        self.progress, self.check_seals = progress, check_seals
        self.outer = current_stages()
        self.remaining = {s: len(v) for s, v in plan.todo.items()}
        self.n_todo = max(1, sum(self.remaining.values()))
        self.computed: dict[tuple[str | None, str], bytes] = {}
        self.verdicts: dict[str, ValidationResult] = {}
        #: chunks collected; the seal check (and so the first verdict) waits for ``hold``
        #: of the ``chunks`` chunks: the seals of the sources read by then come with their
        #: chunks (:class:`_SealCheck`), only the others are read from the database; the
        #: verdicts waiting meanwhile are given while the last chunks are processed
        self.collected, self.hold = 0, int(-(-chunks * hold_fraction // 1))
        #: the measured side's columns, built at the first verdict and reused by the others
        #: (``memo`` of :func:`railval.core.validation.validate`)
        self.memo: dict = {}

    def __call__(self, chunk, done) -> None:
        packed, seconds, *seals = done
        if self.outer is not None and seconds:
            self.outer.merge(seconds)
        source, sids = chunk
        if seals and self.check_seals is not None:
            self.check_seals.add(seals[0])
        with stage("cache_unpack"):
            for sid, blob in zip(sids, packed, strict=True):
                self.computed[(source, sid)] = blob
                self.plan.values[source][sid] = unpack_values(sid, blob)
        self.remaining[source] -= len(sids)
        self.collected += 1
        if self.progress is not None:
            self.progress("processing sections", len(self.computed) / self.n_todo,
                          {"done": len(self.computed)})
        self.judge_ready()

    def judge_ready(self) -> None:
        """Judge every configuration whose sections (and the measurement's) are all here."""
        if self.remaining.get(None, 0):
            return
        plan = self.plan
        if self.check_seals is not None and self.collected < self.hold:
            return  # the verdicts wait for the seal check (see __init__)
        for cname in plan.names:
            if cname in self.verdicts or self.remaining.get(cname, 0):
                continue
            if self.check_seals is not None:  # once, before the first verdict
                self.check_seals()
                self.check_seals = None
            stats = {s: {"cached": len(plan.values[s]) - len(plan.todo.get(s, [])),
                         "computed": len(plan.todo.get(s, []))} for s in (None, cname)}
            self.verdicts[cname] = _verdict(
                plan.values[None], plan.values[cname], plan.sections, plan.vehicle,
                self.n_boot, self.seed,
                {"campaign": plan.name, "configuration": cname, "filter_order": self.order,
                 "sections_measured": stats[None], "sections_simulated": stats[cname],
                 **plan.provenance[cname]}, memo=self.memo)


def validate_configurations(database, campaign_name: str, configs: Sequence[str] | None = None,
                            *, order: int = DEFAULT_ORDER, n_boot: int = 1000, seed: int = 0,
                            workers: int = 1, chunk_sections: int = 8,
                            scheduler: str | None = None, progress=None,
                            check_seals: bool = True,
                            backend: str = "processes") -> dict[str, ValidationResult]:
    """Validate many configurations (default: all) of a campaign; the DynoTRAIN-scale path.

    The same pipeline as :func:`validate_configuration` — seals of the evidence checked
    (``check_seals``; before the first verdict, by this process while the workers process,
    the measurement's once, from the seals the chunks read with the blobs where it can:
    :class:`_SealCheck`), result cache, EN chain, :func:`_verdict` — with the sections
    not in the cache processed in chunks of at most ``chunk_sections`` sections of one
    source (:func:`_chunks`, the measurement first) by ``workers`` processes (each opens its
    own connection; ``backend="threads"``: ``workers`` threads of this process, which reads
    the blobs), then written to the cache by this process. Each configuration is judged as
    soon as its values are complete, while the other chunks are processed. ``database``: a
    :class:`railval.db.engine.Database`. ``progress(stage, fraction, info)`` is called after
    every chunk. ``scheduler``: a Dask scheduler address whose workers process the chunks
    instead (they read the database with the URL without its password and take the password
    from their own ``RAILVAL_DB_PASSWORD``/``_FILE`` setting — nothing secret crosses the
    Dask link).
    """
    check_order(order)
    if backend not in ("processes", "threads"):
        raise InvalidParameter(f"backend must be 'processes' or 'threads', got {backend!r}")
    with _heap_frozen():
        return _validate_configurations(database, campaign_name, configs, order, n_boot, seed,
                                        workers, chunk_sections, scheduler, progress,
                                        check_seals, backend)


def _validate_configurations(database, campaign_name, configs, order, n_boot, seed, workers,
                             chunk_sections, scheduler, progress, check_seals,
                             backend) -> dict[str, ValidationResult]:
    """:func:`validate_configurations` with its arguments checked and the heap frozen."""
    plan = _plan(database, campaign_name, configs, order)
    chunks = _chunks(plan.todo, chunk_sections)
    # the process workers' chunks do not wait for this process: it may hold the verdicts
    # (and the seal check) until most chunks are in; the threads back end reads the blobs
    # here, between the verdicts, so it checks at the first verdict
    hold = _SEAL_HOLD if backend == "processes" and workers > 1 and scheduler is None else 0.0
    collector = _Collector(plan, order, n_boot, seed, progress,
                           _SealCheck(database, plan) if check_seals else None,
                           len(chunks), hold)
    _process(database, plan, chunks, order, workers, scheduler, collector, backend)
    if collector.computed:
        with stage("database"), database.session(write=True) as session:
            repo.cache_put_many(session, {plan.keys[k]: blob
                                          for k, blob in collector.computed.items()})
    collector.judge_ready()  # nothing was to be processed: every value came from the cache
    return {cname: collector.verdicts[cname] for cname in plan.names}


def _verdict(measured, simulated, sections, vehicle, n_boot: int, seed: int,
             info: dict, memo: dict | None = None) -> ValidationResult:
    """The DynoTRAIN verdict on the processed values of both sides
    (:func:`railval.core.validation.validate`), with the sources' warnings and ``info``;
    ``memo``: kept across the verdicts on one measurement (``validate``'s)."""
    warnings = (source_warnings("measurement", measured)
                + source_warnings(f"configuration {info['configuration']}", simulated))
    with stage("aggregation"):
        result = validate(measured, simulated, sections, vehicle, n_boot=n_boot, seed=seed,
                          warnings=warnings, memo=memo)
    result.info.update(info)
    return result


def calibration_provenance(session: Session, campaign, config: str | repo.ConfigRef) -> dict:
    """Whether a verdict on configuration ``config`` is in-sample — the one place that decides
    it for the dashboard, the report, the sign-off and ``railval validate --json``: it, or one
    of its ancestors, has parameters fitted on sections of this campaign
    (``Configuration.calibration``: by a calibration, or taken from a diagnosis that fitted
    them on every section, ``fitted_by: "diagnosis"``), so a verdict over all sections
    includes the sections the fit used. Returns ``in_sample``, ``calibrated_in`` (the fitted
    configurations of the lineage), ``fitted_by`` (configuration → ``calibration`` or
    ``diagnosis``), ``fit_sections`` and ``held_out_sections`` (union over the lineage;
    held-out = never fitted to) and ``held_out_check``: how to judge the fit on sections it
    has not seen ("" when not in-sample; :func:`held_out_check`)."""
    from railval.db import repo

    fitted: set[str] = set()
    held: set[str] = set()
    calibrated, fitted_by, parents, effects = [], {}, {}, {}
    prev = None
    for conf in repo.lineage(session, campaign, config):
        rec = conf.calibration or {}
        if rec:
            calibrated.append(conf.name)
            fitted_by[conf.name] = str(rec.get("fitted_by") or "calibration")
            parents[conf.name] = prev
            effects[conf.name] = sorted({p if p.startswith("model.") else p.split(".", 1)[0]
                                         for p in rec.get("parameters") or []})
            fitted |= set(rec.get("fit_sections") or [])
            held |= set(rec.get("held_out_sections") or [])
        prev = conf.name
    held -= fitted
    out = {"in_sample": bool(fitted), "calibrated_in": calibrated, "fitted_by": fitted_by,
           "fit_sections": sorted(fitted), "held_out_sections": sorted(held)}
    name = campaign if isinstance(campaign, str) else getattr(campaign, "name", str(campaign))
    out["held_out_check"] = held_out_check(name, out, parents, effects) if fitted else ""
    return out


def held_out_check(campaign: str, prov: dict, parents: dict[str, str | None],
                   effects: dict[str, list[str]] | None = None) -> str:
    """How to check an in-sample configuration on sections its fit did not use (plain text
    for every view): with held-out sections, the calibration's held-out verdict; when every
    section was used, that no held-out check is possible for this configuration and the
    calibration with a split (``railval calibrate --split``: one section per zone held out,
    :func:`railval.core.diagnosis.zone_folds`) that gives one. ``effects``: per fitted
    configuration, the effects (or ``model.NAME``) whose parameters were fitted."""
    held = prov["held_out_sections"]
    if held:
        return (f"held-out check: sections {', '.join(held)} were not used for the fit; the "
                "calibration's held-out verdict on them is the independent test (shown on the "
                "Diagnose page after the calibration, printed by railval calibrate)")
    last = prov["calibrated_in"][-1]
    parent = parents.get(last) or "PARENT"
    how = ("its parameters were taken from a diagnosis that fitted them on every section"
           if prov["fitted_by"].get(last) == "diagnosis" else "its calibration used every section")
    named = " ".join(f"--effect {e}" for e in (effects or {}).get(last) or []) or "--effect EFFECT"
    return (f"no held-out check is possible for this configuration: {how}. To get one, calibrate "
            f"{parent} with a split — railval calibrate {campaign} --config {parent} {named} "
            "--as NEW --split (Diagnose page: tick 'Hold out one section per zone', then "
            "'Add, calibrate & re-simulate')")


def validate_configuration(session: Session, campaign_name: str, config: str, *,
                           order: int = DEFAULT_ORDER, n_boot: int = 1000,
                           seed: int = 0, check_seals: bool = True) -> ValidationResult:
    """Validate configuration ``config`` of ``campaign_name`` against the measurement.

    ``order``: Butterworth prototype order of both filters; ``n_boot``/``seed``: bootstrap of
    the normalised values. The result's ``info`` records how many sections of each side
    came from the cache. Both sides' signal rows (content hashes and seals, no blob) are
    read first, by two queries (:func:`railval.db.repo.seal_rows_many`); the cache keys
    come from them and are looked up at once; the sections of both sides not in the cache
    are read, decoded and processed as one pipeline (:func:`_read_and_process`, the
    measurement's chunks first), every blob row read checked against those rows
    (:class:`_SameRows`). The seals of both sides' signals are checked on the same rows
    (as :func:`railval.db.repo.require_evidence` without blobs checks them) before the
    verdict, while the sections are processed: a signal changed outside railval raises
    :class:`railval.db.integrity.IntegrityError` instead of giving a verdict (and nothing
    is cached). Raises :class:`railval.core.errors.NotFound` for unknown names. The heap
    alive on entry is left out of the garbage collector's passes meanwhile
    (:func:`_heap_frozen`: a full pass over a server's heap took ≈ 0.1 s).
    """
    check_order(order)
    with _heap_frozen():
        return _validate_configuration(session, campaign_name, config, order, n_boot, seed,
                                       check_seals)


def _validate_configuration(session: Session, campaign_name: str, config: str, order: int,
                            n_boot: int, seed: int, check_seals: bool) -> ValidationResult:
    """:func:`validate_configuration` with the order checked and the heap frozen."""
    with stage("database"):
        camp, conf = repo.resolve(session, campaign_name, config)
        sections = repo.section_infos(session, camp)
        # both sources' signal rows (content hashes and seals, no blob) read once: the cache
        # keys come from them now, the seals are checked on them while the sections are
        # processed, and the blobs read later must carry the same hashes (_SameRows)
        rows = repo.seal_rows_many(session, camp, [conf.id])
        keys = _keys_from_rows(rows, [(None, None), (conf.name, conf.id)], sections, order)
        cached = repo.cache_get_many(session, list(keys.values()))
    values: dict[str | None, dict[str, en14363.SectionValues]] = {None: {}, conf.name: {}}
    todo: dict[str | None, list[str]] = {None: [], conf.name: []}
    with stage("cache_unpack"):
        for (source, sid), key in keys.items():
            if key in cached:
                values[source][sid] = unpack_values(sid, cached[key])
            else:
                todo[source].append(sid)
    later: dict[str, Any] = {}

    def meanwhile() -> None:  # while the sections are processed: what only the verdict needs
        with stage("database"):
            later["vehicle"] = repo.vehicle_info(session, camp)
            later["provenance"] = calibration_provenance(session, camp, config)
            if check_seals:
                _check_seals(session, camp, conf, rows)

    if todo[None] or todo[conf.name]:
        # one pipeline over both sources (the measurement first): its last chunks overlap
        # the configuration's first; the seals are checked while the chunks are processed
        by_id = {s.id: s for s in sections}
        done = _read_and_process(session, camp, [(src, todo[name]) for src, name in
                                                 ((None, None), (conf, conf.name))
                                                 if todo[name]],
                                 by_id, order, meanwhile, _SameRows(camp, conf, rows))
        new: dict[str, bytes] = {}
        for (src, sid), (vals, packed) in done.items():
            name = None if src is None else conf.name
            values[name][sid] = vals
            new[keys[(name, sid)]] = packed
        with stage("database"):
            repo.cache_put_many(session, new)
    else:
        meanwhile()  # every value came from the cache
    stats = {name: {"cached": len(values[name]) - len(todo[name]),
                    "computed": len(todo[name])} for name in (None, conf.name)}
    return _verdict(values[None], values[conf.name], sections, later["vehicle"], n_boot, seed,
                    {"campaign": camp.name, "configuration": conf.name, "filter_order": order,
                     "sections_measured": stats[None], "sections_simulated": stats[conf.name],
                     **later["provenance"]})


def _check_seals(session: Session, camp, conf, rows: tuple[list, dict]) -> None:
    """The check of :func:`railval.db.repo.require_evidence` without blobs — every seal of
    the measurement's and the configuration's signals — on the rows ``rows`` read for the
    cache keys (:func:`railval.db.repo.seal_rows_many`) instead of reading them again. On a
    problem the full check runs and raises its error (should it find none, the problems
    found here are raised in the same form)."""
    recs, by_rec = rows
    problems = repo.seal_problems(session, camp)
    found = (problems([r for r in recs if r[2] is None], by_rec)
             + problems([r for r in recs if r[2] is not None], by_rec))
    if found:
        repo.require_evidence(session, camp, conf, blobs=False)
        repo.raise_problems(conf, found)


class _SameRows:
    """``on_read`` of :func:`_read_and_process` for a validation whose cache keys and seal
    check come from signal rows read before the blobs (:func:`_validate_configuration`):
    every row read with the blobs must be one of those, with the same content hash (and,
    for a distance axis, the same fs, t0 and n), else the values computed would be cached
    under a key they do not belong to and judged on evidence whose seals were not checked.
    A row changed in between (the configuration stored again meanwhile) raises
    :class:`railval.db.integrity.IntegrityError` and nothing is cached."""

    def __init__(self, camp, conf, rows: tuple[list, dict]) -> None:
        recs, by_rec = rows
        self.camp, self.conf = camp, conf
        self.expected: dict[tuple[int, str | None], Any] = {
            (rid, None): (dsha, fs, t0, n) for rid, _sid, _cid, dsha, fs, t0, n in recs}
        for rid, signals in by_rec.items():
            for chan, _cid, sha, _seal in signals:
                self.expected[(rid, chan)] = sha

    def __call__(self, decode) -> None:
        expected = self.expected
        for rid, sid, chan, sha, fs, t0, n in decode.read:
            got = sha if chan is not None else (sha, fs, t0, n)
            if expected.get((rid, chan)) != got:
                from railval.db.integrity import IntegrityError

                raise IntegrityError(
                    f"campaign {self.camp.name!r}: section {sid}, {chan or 'distance_m'} of "
                    f"the evidence of {self.conf.name!r} changed while it was validated; "
                    "nothing was cached — validate again")
