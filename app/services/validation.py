"""Validation of a stored configuration: database → EN 14363 processing → DynoTRAIN verdict.

:func:`validate_configuration` reads the campaign (sections, vehicle) and both sides of the
comparison from the database, processes them with :mod:`core.en14363` and judges them with
:func:`core.validation.validate`.

Results cache
-------------
Processing a section of one source (the measurement or a configuration) is cached in the
database table ``result_cache`` (:func:`db.repo.cache_get` / :func:`db.repo.cache_put`) under

    sha256(PROCESSING_VERSION, filter order, section id, evaluated range, fs, n,
           distance-axis hash, sorted (channel, content hash) of the recording)

and holds the section's values as JSON. Content hashes are read first
(:func:`db.repo.signal_hashes`, no blob is touched); only sections whose key is not cached are
loaded and processed. So the measured side is processed once per campaign and filter order,
and a new configuration costs only its own signals. Any change of samples, distance axis,
evaluated range, filter order or processing code changes the key.

:func:`evaluate_signalsets` is the same pipeline for in-memory :class:`~core.types.SignalSet`
objects (simulation and calibration loops without the database); the pure-core entry
point is :func:`core.validation.validate` on already processed values.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from core import en14363
from core.filters import DEFAULT_ORDER
from core.types import SectionInfo, SignalSet
from core.validation import ValidationResult, validate

#: sections per bulk cache read (SQL IN list)
_CACHE_CHUNK = 500


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

    (Adapter: :mod:`db.repo` exposes channel hashes but not the distance-axis hash.)
    """
    from db.models import Configuration, Recording, Section

    q = (select(Section.section_id, Recording.distance_sha256, Recording.fs, Recording.n)
         .join(Section, Recording.section_id == Section.id)
         .where(Section.campaign_id == campaign_id))
    if config is None:
        q = q.where(Recording.configuration_id.is_(None))
    else:
        q = q.join(Configuration, Recording.configuration_id == Configuration.id).where(
            Configuration.name == config, Configuration.campaign_id == campaign_id)
    return {sid: (sha, float(fs), int(n)) for sid, sha, fs, n in session.execute(q)}


def _cache_get_many(session: Session, keys: Sequence[str]) -> dict[str, bytes]:
    """Bulk read of the result cache (one query per chunk instead of one per key)."""
    from db.models import ResultCache

    out: dict[str, bytes] = {}
    for i in range(0, len(keys), _CACHE_CHUNK):
        chunk = list(keys[i:i + _CACHE_CHUNK])
        for k, v in session.execute(select(ResultCache.key, ResultCache.value)
                                    .where(ResultCache.key.in_(chunk))):
            out[k] = bytes(v)
    return out


def _pack(values: en14363.SectionValues) -> bytes:
    return json.dumps({"values": [[q, p, float(v)] for (q, p), v in values.items()],
                       "warnings": values.warnings}, allow_nan=False).encode()


def _unpack(section_id: str, blob: bytes) -> en14363.SectionValues:
    doc = json.loads(blob)
    return en14363.SectionValues(section_id, {(q, p): v for q, p, v in doc["values"]},
                                 warnings=doc["warnings"])


def source_values(session: Session, campaign, config: str | None, sections: Sequence[SectionInfo],
                  *, order: int = DEFAULT_ORDER,
                  stats: dict | None = None) -> dict[str, en14363.SectionValues]:
    """Processed values of every section of one source (``config=None``: the measurement),
    from the result cache where possible. ``stats`` (optional dict) receives
    ``{"cached": n, "computed": n}``."""
    from db import repo

    camp = repo.get_campaign(session, campaign)
    hashes = repo.signal_hashes(session, camp, config)
    meta = _recording_meta(session, camp.id, config)
    by_id = {s.id: s for s in sections}
    keys = {sid: section_cache_key(by_id[sid], meta[sid][1], meta[sid][2], meta[sid][0],
                                   hashes.get(sid, {}), order)
            for sid in meta if sid in by_id}
    cached = _cache_get_many(session, list(keys.values()))
    out = {sid: _unpack(sid, cached[k]) for sid, k in keys.items() if k in cached}
    missing = [sid for sid in keys if sid not in out]
    if missing:
        sets = repo.load_signalsets(session, camp, config, sections=missing)
        computed = en14363.evaluate_batch([sets[s] for s in missing],
                                          [by_id[s] for s in missing], order=order)
        for sid, vals in zip(missing, computed, strict=True):
            repo.cache_put(session, keys[sid], _pack(vals))
            out[sid] = vals
    if stats is not None:
        stats.update({"cached": len(keys) - len(missing), "computed": len(missing)})
    return out


def _warnings(label: str, values: Mapping[str, en14363.SectionValues]) -> list[str]:
    return [f"{label}: {w}" for sid in sorted(values) for w in values[sid].warnings]


def validate_configuration(session: Session, campaign_name: str, config_name: str, *,
                           order: int = DEFAULT_ORDER, n_boot: int = 1000,
                           seed: int = 0) -> ValidationResult:
    """Validate configuration ``config_name`` of ``campaign_name`` against the measurement.

    ``order``: Butterworth prototype order of both filters; ``n_boot``/``seed``: bootstrap of
    the normalised values. The result's ``info`` records how many sections of each side
    came from the cache. Raises :class:`core.errors.NotFound` for unknown names.
    """
    from db import repo

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

    ``vehicle``: :class:`core.validation.Vehicle` or a mapping with ``kind``,
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
