"""Validation of a stored configuration: database → EN 14363 processing → DynoTRAIN verdict.

:func:`validate_configuration` reads the campaign (sections, vehicle) and both sides of the
comparison from the database, processes them with :mod:`railval.core.en14363` and judges them with
:func:`railval.core.validation.validate`.

Results cache
-------------
Processing a section of one source (the measurement or a configuration) is cached in the
database table ``result_cache`` (:func:`railval.db.repo.cache_get` / :func:`railval.db.repo.cache_put`) under

    sha256(PROCESSING_VERSION, filter order, section id, evaluated range, fs, n,
           distance-axis hash, sorted (channel, content hash) of the recording)

and holds the section's values as JSON (with the values under the alternative readings of
the open definitions and the supplementary values). Content hashes are read first
(:func:`railval.db.repo.signal_hashes`, no blob is touched); only sections whose key is not cached are
loaded and processed. So the measured side is processed once per campaign and filter order,
and a new configuration costs only its own signals. Any change of samples, distance axis,
evaluated range, filter order or processing code changes the key.

:func:`evaluate_signalsets` is the same pipeline for in-memory :class:`~railval.core.types.SignalSet`
objects (simulation and calibration loops without the database); the pure-core entry
point is :func:`railval.core.validation.validate` on already processed values.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from railval.core import en14363
from railval.core.filters import DEFAULT_ORDER, check_order
from railval.core.types import SectionInfo, SignalSet
from railval.core.validation import ValidationResult, validate

#: sections per bulk cache read (SQL IN list)
_CACHE_CHUNK = 500
#: sections read per query while the previous chunk is processed
_PIPELINE_CHUNK = 4


def section_cache_key(section: SectionInfo, fs: float, n: int, distance_sha: str,
                      channel_hashes: Mapping[str, str], order: int) -> str:
    """Cache key of one section of one source (see module docstring)."""
    h = hashlib.sha256()
    parts = [en14363.PROCESSING_VERSION, f"order={int(order)}", f"section={section.id}",
             f"eval={section.eval_start_m!r}:{section.eval_end_m!r}", f"fs={float(fs)!r}",
             f"n={int(n)}", f"distance={distance_sha}"]
    parts += [f"{c}={channel_hashes[c]}" for c in sorted(channel_hashes)]
    h.update("\n".join(parts).encode())
    return "en14363:" + h.hexdigest()


def _recording_meta(session: Session, campaign_id: int,
                    config: str | None) -> dict[str, tuple[str, float, int]]:
    """section id → (distance-axis hash, fs, n) of the source's recordings, no blobs read.

    (Adapter: :mod:`railval.db.repo` exposes channel hashes but not the distance-axis hash.)
    """
    from railval.db.models import Configuration, Recording, Section

    q = (select(Section.section_id, Recording.distance_sha256, Recording.fs, Recording.n)
         .join(Section, Recording.section_id == Section.id)
         .where(Section.campaign_id == campaign_id))
    if config is None:
        q = q.where(Recording.configuration_id.is_(None))
    else:
        q = q.join(Configuration, Recording.configuration_id == Configuration.id).where(
            Configuration.name == config, Configuration.campaign_id == campaign_id)
    return {sid: (sha, float(fs), int(n)) for sid, sha, fs, n in session.execute(q)}


def source_cache_keys(session: Session, campaign, config: str | None,
                      sections: Sequence[SectionInfo], *, order: int = DEFAULT_ORDER
                      ) -> dict[str, str]:
    """section id → result-cache key of every recorded section of one source, read from the
    stored content hashes only (no blob is decoded)."""
    from railval.db import repo

    camp = repo.get_campaign(session, campaign)
    hashes = repo.signal_hashes(session, camp, config)
    meta = _recording_meta(session, camp.id, config)
    by_id = {s.id: s for s in sections}
    return {sid: section_cache_key(by_id[sid], meta[sid][1], meta[sid][2], meta[sid][0],
                                   hashes.get(sid, {}), order)
            for sid in meta if sid in by_id}


def _cache_get_many(session: Session, keys: Sequence[str]) -> dict[str, bytes]:
    """Bulk read of the result cache (one query per chunk instead of one per key)."""
    from railval.db.models import ResultCache

    out: dict[str, bytes] = {}
    for i in range(0, len(keys), _CACHE_CHUNK):
        chunk = list(keys[i:i + _CACHE_CHUNK])
        for k, v in session.execute(select(ResultCache.key, ResultCache.value)
                                    .where(ResultCache.key.in_(chunk))):
            out[k] = bytes(v)
    return out


def _pack(values: en14363.SectionValues) -> bytes:
    return json.dumps({
        "values": [[q, p, float(v)] for (q, p), v in values.items()],
        "warnings": values.warnings,
        "alternatives": {rid: [[q, p, float(v) if np.isfinite(v) else None]
                               for (q, p), v in vals.items()]
                         for rid, vals in values.alternatives.items()},
        "supplementary": [[q, p, float(v)] for (q, p), v in values.supplementary.items()],
    }, allow_nan=False).encode()


def _unpack(section_id: str, blob: bytes) -> en14363.SectionValues:
    doc = json.loads(blob)
    alts = {rid: {(q, p): (float("nan") if v is None else v) for q, p, v in vals}
            for rid, vals in doc.get("alternatives", {}).items()}
    return en14363.SectionValues(section_id, {(q, p): v for q, p, v in doc["values"]},
                                 warnings=doc["warnings"], alternatives=alts,
                                 supplementary={(q, p): v for q, p, v in
                                                doc.get("supplementary", [])})


def source_values(session: Session, campaign, config: str | None, sections: Sequence[SectionInfo],
                  *, order: int = DEFAULT_ORDER,
                  stats: dict | None = None) -> dict[str, en14363.SectionValues]:
    """Processed values of every section of one source (``config=None``: the measurement),
    from the result cache where possible. ``stats`` (optional dict) receives
    ``{"cached": n, "computed": n}``."""
    from railval.db import repo

    camp = repo.get_campaign(session, campaign)
    by_id = {s.id: s for s in sections}
    keys = source_cache_keys(session, camp, config, sections, order=order)
    cached = _cache_get_many(session, list(keys.values()))
    out = {sid: _unpack(sid, cached[k]) for sid, k in keys.items() if k in cached}
    missing = [sid for sid in keys if sid not in out]
    if missing:
        # pipeline: this thread reads the blobs of chunk k+1 (the caller's session stays in
        # this thread) while a worker thread decodes and processes chunk k. Decoding in the
        # worker, not here, avoids thousands of GIL hand-overs between the two threads
        # (every inflate and plane copy releases the GIL), which doubled the decode time.
        from concurrent.futures import ThreadPoolExecutor

        chunks = [missing[i:i + _PIPELINE_CHUNK] for i in range(0, len(missing), _PIPELINE_CHUNK)]
        pending = []
        with ThreadPoolExecutor(max_workers=1) as pool:
            for chunk in chunks:
                decode = repo.fetch_signalsets(session, camp, config, sections=chunk)
                pending.append((chunk, pool.submit(_decode_and_evaluate, decode,
                                                   [by_id[s] for s in chunk], order)))
            new: dict[str, bytes] = {}
            for chunk, fut in pending:
                for sid, vals in zip(chunk, fut.result(), strict=True):
                    new[keys[sid]] = _pack(vals)
                    out[sid] = vals
        repo.cache_put_many(session, new)
    if stats is not None:
        stats.update({"cached": len(keys) - len(missing), "computed": len(missing)})
    return out


def _decode_and_evaluate(decode, sections: list[SectionInfo],
                         order: int) -> list[en14363.SectionValues]:
    sets = decode()
    return en14363.evaluate_batch([sets[s.id] for s in sections], sections, order=order)


def _evaluate_chunk(db_or_url, campaign: str, config: str | None,
                    sections: list[SectionInfo], order: int) -> list[bytes]:
    """Worker task: load and process some sections of one source; returns packed values.
    ``db_or_url``: a :class:`railval.db.engine.Database` (in-process) or its URL (worker process)."""
    from railval.db import repo

    database = _worker_database(db_or_url) if isinstance(db_or_url, str) else db_or_url
    with database.session() as session:
        sets = repo.load_signalsets(session, campaign, config, sections=[s.id for s in sections])
    vals = en14363.evaluate_batch([sets[s.id] for s in sections], sections, order=order)
    return [_pack(v) for v in vals]


_WORKER_DB: dict[str, Any] = {}


def _worker_database(url: str):
    if url not in _WORKER_DB:
        from railval.db.engine import connect

        _WORKER_DB[url] = connect(url)
    return _WORKER_DB[url]


def validate_configurations(database, campaign_name: str, configs: Sequence[str] | None = None,
                            *, order: int = DEFAULT_ORDER, n_boot: int = 1000, seed: int = 0,
                            workers: int = 1, chunk_sections: int = 8,
                            progress=None) -> dict[str, ValidationResult]:
    """Validate many configurations (default: all) of a campaign; the DynoTRAIN-scale path.

    ``database``: a :class:`railval.db.engine.Database`. Sections not in the result cache are
    processed in chunks of ``chunk_sections`` sections of one source, by ``workers``
    processes (each opens its own connection), then written to the cache by this process.
    ``progress(stage, fraction, info)`` is called after every chunk.
    """
    from concurrent.futures import ProcessPoolExecutor

    from railval.db import repo

    check_order(order)
    with database.session() as session:
        camp = repo.get_campaign(session, campaign_name)
        name = camp.name
        sections = repo.section_infos(session, camp)
        vehicle = repo.vehicle_info(session, camp)
        names = ([c.name for c in repo.list_configurations(session, camp)] if configs is None
                 else [repo.get_configuration(session, camp, c).name for c in configs])
        by_id = {s.id: s for s in sections}
        keys: dict[tuple[str | None, str], str] = {}
        for source in [None, *names]:
            hashes = repo.signal_hashes(session, camp, source)
            meta = _recording_meta(session, camp.id, source)
            for sid, (dsha, fs, n) in meta.items():
                if sid in by_id:
                    keys[(source, sid)] = section_cache_key(by_id[sid], fs, n, dsha,
                                                            hashes.get(sid, {}), order)
        cached = _cache_get_many(session, list(keys.values()))
    values: dict[str | None, dict[str, en14363.SectionValues]] = {s: {} for s in [None, *names]}
    todo: dict[str | None, list[str]] = {}
    for (source, sid), key in keys.items():
        if key in cached:
            values[source][sid] = _unpack(sid, cached[key])
        else:
            todo.setdefault(source, []).append(sid)
    chunks = [(source, sids[i:i + chunk_sections]) for source, sids in todo.items()
              for i in range(0, len(sids), chunk_sections)]
    computed: dict[tuple[str | None, str], bytes] = {}

    def collect(chunk, packed):
        source, sids = chunk
        for sid, blob in zip(sids, packed, strict=True):
            computed[(source, sid)] = blob
            values[source][sid] = _unpack(sid, blob)
        if progress is not None:
            progress("processing sections", len(computed) / max(1, sum(map(len, todo.values()))),
                     {"done": len(computed)})

    if workers > 1 and len(chunks) > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [(c, pool.submit(_evaluate_chunk, database.url, name, c[0],
                                       [by_id[s] for s in c[1]], order)) for c in chunks]
            for chunk, fut in futures:
                collect(chunk, fut.result())
    else:
        for chunk in chunks:
            collect(chunk, _evaluate_chunk(database, name, chunk[0],
                                           [by_id[s] for s in chunk[1]], order))
    if computed:
        with database.session() as session:
            repo.cache_put_many(session, {keys[k]: blob for k, blob in computed.items()})
    measured = values[None]
    out = {}
    for cname in names:
        warnings = _warnings("measurement", measured) + _warnings(f"configuration {cname}",
                                                                  values[cname])
        res = validate(measured, values[cname], sections, vehicle, n_boot=n_boot, seed=seed,
                       warnings=warnings)
        res.info.update({"campaign": name, "configuration": cname, "filter_order": order})
        out[cname] = res
    return out


def _warnings(label: str, values: Mapping[str, en14363.SectionValues]) -> list[str]:
    return [f"{label}: {w}" for sid in sorted(values) for w in values[sid].warnings]


def validate_configuration(session: Session, campaign_name: str, config_name: str, *,
                           order: int = DEFAULT_ORDER, n_boot: int = 1000,
                           seed: int = 0) -> ValidationResult:
    """Validate configuration ``config_name`` of ``campaign_name`` against the measurement.

    ``order``: Butterworth prototype order of both filters; ``n_boot``/``seed``: bootstrap of
    the normalised values. The result's ``info`` records how many sections of each side
    came from the cache. Raises :class:`railval.core.errors.NotFound` for unknown names.
    """
    from railval.db import repo

    check_order(order)
    camp = repo.get_campaign(session, campaign_name)
    repo.get_configuration(session, camp, config_name)
    sections = repo.section_infos(session, camp)
    vehicle = repo.vehicle_info(session, camp)
    m_stats: dict[str, int] = {}
    s_stats: dict[str, int] = {}
    measured = source_values(session, camp, None, sections, order=order, stats=m_stats)
    simulated = source_values(session, camp, config_name, sections, order=order, stats=s_stats)
    warnings = _warnings("measurement", measured) + _warnings(f"configuration {config_name}",
                                                              simulated)
    result = validate(measured, simulated, sections, vehicle, n_boot=n_boot, seed=seed,
                      warnings=warnings)
    result.info.update({"campaign": camp.name, "configuration": config_name,
                        "filter_order": order,
                        "sections_measured": m_stats, "sections_simulated": s_stats})
    return result


def evaluate_signalsets(measured: Mapping[str, SignalSet], simulated: Mapping[str, SignalSet],
                        sections: Sequence[SectionInfo], vehicle: Any, *,
                        order: int = DEFAULT_ORDER, n_boot: int = 1000,
                        seed: int = 0) -> ValidationResult:
    """Validate in-memory signal sets (no database): section id → SignalSet on each side.

    ``vehicle``: :class:`railval.core.validation.Vehicle` or a mapping with ``kind``,
    ``secondary_suspension``, ``Q0_kN``. Sections missing on either side are skipped (and
    show up in the coverage).
    """
    secs = [s for s in sections if s.id in measured or s.id in simulated]
    values = {}
    for label, sets in (("measurement", measured), ("simulation", simulated)):
        use = [s for s in secs if s.id in sets]
        res = en14363.evaluate_batch([sets[s.id] for s in use], use, order=order)
        values[label] = {s.id: v for s, v in zip(use, res, strict=True)}
    warnings = (_warnings("measurement", values["measurement"])
                + _warnings("simulation", values["simulation"]))
    return validate(values["measurement"], values["simulation"], sections, vehicle,
                    n_boot=n_boot, seed=seed, warnings=warnings)
