"""The signal rows of a validation's evidence: the result-cache keys made from their content
hashes (no blob read) and the seal checks made on them, for
:mod:`railval.app.services.validation`.

A cache key is :func:`railval.core.en14363.section_cache_key` of a section's recording
(evaluated range, fs, n, distance-axis hash, sorted channel content hashes, filter order);
a seal is checked as :func:`railval.db.repo.require_sealed` checks it without blobs
(:func:`railval.db.repo.seal_problems`). A row read with the blobs must be the row the key
and the seal check were made from (:class:`SameRows`), else
:class:`railval.db.integrity.IntegrityError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy.orm import Session

from railval.core import lazy
from railval.core.processing import DEFAULT_ORDER
from railval.core.stages import stage
from railval.core.types import SectionInfo
from railval.db import repo
from railval.db.integrity import IntegrityError

section_cache_key = lazy.function("railval.core.en14363", "section_cache_key")


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


def keys_from_rows(rows: tuple[list, dict], sources: list[tuple[str | None, int | None]],
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


def _require_seals(database, plan) -> None:
    """The seals of every configuration's evidence and of the measurement (checked once), as
    :func:`railval.app.services.validation.validate_configuration` checks them
    (:func:`railval.db.repo.require_sealed` without reading blobs)."""
    with stage("database"), database.session() as session:
        repo.require_sealed_many(session, plan.name, plan.names, blobs=False,
                                   rows=plan.evidence)


class SealCheck:
    """The seals of the stored signals of every verdict, checked once before the first verdict as
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

    def __init__(self, database, plan) -> None:
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


def check_row_seals(session: Session, camp, conf, rows: tuple[list, dict]) -> None:
    """The check of :func:`railval.db.repo.require_sealed` without blobs — every seal of
    the measurement's and the configuration's signals — on the rows ``rows`` read for the
    cache keys (:func:`railval.db.repo.seal_rows_many`) instead of reading them again. On a
    problem the full check runs and raises its error (should it find none, the problems
    found here are raised in the same form)."""
    recs, by_rec = rows
    problems = repo.seal_problems(session, camp)
    found = (problems([r for r in recs if r[2] is None], by_rec)
             + problems([r for r in recs if r[2] is not None], by_rec))
    if found:
        repo.require_sealed(session, camp, conf, blobs=False)
        repo.raise_problems(conf, found)


class SameRows:
    """``on_read`` of :func:`railval.app.services.validation_exec.read_and_process` for a
    validation whose cache keys and seal check come from signal rows read before the blobs
    (:func:`railval.app.services.validation.validate_configuration`):
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
                raise IntegrityError(
                    f"campaign {self.camp.name!r}: section {sid}, {chan or 'distance_m'} of "
                    f"the stored signals of {self.conf.name!r} changed while it was validated; "
                    "nothing was cached — validate again")
